//! The CPU renderer: view-aligned slicing with additive blending, done as ray marching.
//!
//! Source: fuller-procedural-volumetric-fire.txt §4.1, Figure 10–11. The GPU version slices
//! each lattice cell with planes perpendicular to the view direction at even spacing and
//! adds the shaded slices. Here every pixel's ray is intersected with those same planes
//! (depths `k · slice_spacing` along the camera's forward axis), restricted to the lattice
//! cells the ray crosses; each sample is mapped to unit-volume texture coordinates by
//! inverting that cell's trilinear map ([`crate::lattice::Cell::inverse`]) and shaded with
//! [`crate::mapping::shade`]. This is exactly what the slicing computes, up to the GPU's
//! linear (rather than trilinear) interpolation inside a cell.
//!
//! Performance: cells are binned into 16×16-pixel tiles by their projected bounding boxes
//! (empty tiles cost nothing), rayon runs over tiles, samples outside the unit cylinder or
//! in empty profile columns skip the noise. Per pixel the result does not depend on the
//! thread count, so output bytes are deterministic.
//!
//! Output convention ([`render`]): linear-light HDR, **premultiplied** — `rgb` is the light
//! emitted towards the camera (as if blended additively onto black) and `a` the
//! accumulated opacity in `0..=1`. [`finish`] applies bloom and converts to the straight
//! alpha every Ignis frame uses.

use crate::error::{Result, VolumeError};
use crate::lattice::{add, cross, dot, normalize, scale, sub, Lattice, V3};
use crate::mapping::{radial_u, shade, NoiseParams};
use crate::profile::FireProfile;
use ignis_core::post::{bloom_rgba, BloomParams};
use ignis_core::{RgbaFrame, Size};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// A pinhole camera; world `z` is up.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Camera {
    /// Eye position, world units. Default `[0, −7, 1.5]`.
    pub position: [f32; 3],
    /// Point looked at. Default `[0, 0, 1.5]`.
    pub target: [f32; 3],
    /// Vertical field of view, degrees (0, 170). Default 40.
    pub fov: f32,
}

impl Default for Camera {
    fn default() -> Self {
        Camera {
            position: [0.0, -7.0, 1.5],
            target: [0.0, 0.0, 1.5],
            fov: 40.0,
        }
    }
}

impl Camera {
    /// Checks the field of view and that position ≠ target and the view is not vertical.
    pub fn validate(&self) -> Result<()> {
        if !(self.fov > 0.0 && self.fov < 170.0) {
            return Err(VolumeError::bad(
                "camera.fov",
                format!("{} degrees; use (0, 170)", self.fov),
            ));
        }
        let f = normalize(sub(self.target, self.position))
            .ok_or_else(|| VolumeError::bad("camera.target", "must differ from camera.position"))?;
        if normalize(cross(f, [0.0, 0.0, 1.0])).is_none() {
            return Err(VolumeError::bad(
                "camera.target",
                "the view must not be exactly vertical (z is up)",
            ));
        }
        Ok(())
    }

    /// Forward, right and up unit vectors.
    fn basis(&self) -> (V3, V3, V3) {
        let f = normalize(sub(self.target, self.position)).unwrap_or([0.0, 1.0, 0.0]);
        let r = normalize(cross(f, [0.0, 0.0, 1.0])).unwrap_or([1.0, 0.0, 0.0]);
        let u = cross(r, f);
        (f, r, u)
    }
}

/// How samples are combined (§4.1, Figure 11).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Blend {
    /// Emissive: every sample adds `rgb · a`. The paper's default.
    #[default]
    Additive,
    /// Opaque, hand-drawn look: the nearest sample with `a ≥ 0.5` gives the pixel's colour.
    Cartoon,
    /// Additive with the profile's colour replaced by this linear RGB times its luminance.
    Tint([f32; 3]),
}

/// Renderer settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderParams {
    /// Output size in pixels.
    pub size: Size,
    /// Distance between view-aligned slices, world units (> 0). Paper: 0.2.
    pub slice_spacing: f32,
    /// How samples combine.
    pub blend: Blend,
    /// Emission per unit length: each sample contributes `intensity · slice_spacing · rgb·a`,
    /// so brightness does not depend on the spacing (`intensity = 1/spacing` is the paper's
    /// plain per-slice sum). Default 2.5.
    pub intensity: f32,
}

impl RenderParams {
    pub fn validate(&self) -> Result<()> {
        if !(self.slice_spacing > 0.0 && self.slice_spacing.is_finite()) {
            return Err(VolumeError::bad(
                "render.slice_spacing",
                format!(
                    "{}; must be > 0 (the paper uses 0.2 for a unit-radius fire)",
                    self.slice_spacing
                ),
            ));
        }
        if !(self.intensity >= 0.0 && self.intensity.is_finite()) {
            return Err(VolumeError::bad(
                "render.intensity",
                "must be a finite number ≥ 0",
            ));
        }
        Ok(())
    }
}

/// One fire ready to draw at one instant.
#[derive(Clone, Copy, Debug)]
pub struct FireInstance<'a> {
    pub lattice: &'a Lattice,
    pub profile: &'a FireProfile,
    pub noise: NoiseParams,
    /// Per-instance noise offset (eq. 13).
    pub offset: [f32; 4],
}

/// Work counters of one frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize)]
pub struct RenderStats {
    /// Pixels whose ray has at least one sample inside a lattice cell (the pixels a GPU
    /// would run the shader on).
    pub covered_pixels: u64,
    /// Samples inside a cell.
    pub samples: u64,
    /// Samples inside the unit cylinder with a non-empty profile column (noise evaluated).
    pub shaded: u64,
}

const TILE: u32 = 16;

/// Renders `fires` seen from `camera` at noise time `time` (seconds). Returns a
/// premultiplied HDR frame (see the module docs) and work counters.
pub fn render(
    fires: &[FireInstance],
    camera: &Camera,
    params: &RenderParams,
    time: f32,
) -> Result<(RgbaFrame, RenderStats)> {
    camera.validate()?;
    params.validate()?;
    let size = params.size;
    let (w, h) = (size.width, size.height);
    let (fw, rt, up) = camera.basis();
    let tan = (camera.fov.to_radians() * 0.5).tan();
    let aspect = w as f32 / h as f32;
    let (tx, ty) = (w.div_ceil(TILE), h.div_ceil(TILE));
    // bin cells into tiles
    let mut bins: Vec<Vec<(u32, u32)>> = vec![Vec::new(); (tx * ty) as usize];
    for (fi, f) in fires.iter().enumerate() {
        for (ci, c) in f.lattice.cells().iter().enumerate() {
            let mut lo = [f32::INFINITY; 2];
            let mut hi = [f32::NEG_INFINITY; 2];
            let mut behind = false;
            for k in 0..8 {
                let q = [
                    if k & 1 == 0 { c.min[0] } else { c.max[0] },
                    if k & 2 == 0 { c.min[1] } else { c.max[1] },
                    if k & 4 == 0 { c.min[2] } else { c.max[2] },
                ];
                let rel = sub(q, camera.position);
                let z = dot(rel, fw);
                if z <= 1e-3 {
                    behind = true;
                    break;
                }
                let sx = (dot(rel, rt) / (z * tan * aspect) + 1.0) * 0.5 * w as f32;
                let sy = (1.0 - dot(rel, up) / (z * tan)) * 0.5 * h as f32;
                lo = [lo[0].min(sx), lo[1].min(sy)];
                hi = [hi[0].max(sx), hi[1].max(sy)];
            }
            let (x0, x1, y0, y1) = if behind {
                (0, tx as i64 - 1, 0, ty as i64 - 1)
            } else {
                (
                    ((lo[0] - 1.0).floor() as i64).div_euclid(TILE as i64),
                    ((hi[0] + 1.0).ceil() as i64).div_euclid(TILE as i64),
                    ((lo[1] - 1.0).floor() as i64).div_euclid(TILE as i64),
                    ((hi[1] + 1.0).ceil() as i64).div_euclid(TILE as i64),
                )
            };
            for y in y0.max(0)..=y1.min(ty as i64 - 1) {
                for x in x0.max(0)..=x1.min(tx as i64 - 1) {
                    bins[(y as u32 * tx + x as u32) as usize].push((fi as u32, ci as u32));
                }
            }
        }
    }
    let ctx = Ctx {
        fires,
        camera,
        params,
        fw,
        rt,
        up,
        tan,
        aspect,
        time,
    };
    let tiles: Vec<(Vec<[f32; 4]>, RenderStats)> = (0..tx * ty)
        .into_par_iter()
        .map(|t| ctx.tile(t % tx, t / tx, &bins[t as usize]))
        .collect();
    let mut data = vec![[0.0f32; 4]; size.pixels()];
    let mut stats = RenderStats::default();
    for (t, (buf, s)) in tiles.into_iter().enumerate() {
        stats.covered_pixels += s.covered_pixels;
        stats.samples += s.samples;
        stats.shaded += s.shaded;
        if buf.is_empty() {
            continue;
        }
        let (x0, y0) = ((t as u32 % tx) * TILE, (t as u32 / tx) * TILE);
        let tw = TILE.min(w - x0) as usize;
        for (row, chunk) in buf.chunks_exact(tw).enumerate() {
            let start = (y0 as usize + row) * w as usize + x0 as usize;
            data[start..start + tw].copy_from_slice(chunk);
        }
    }
    Ok((RgbaFrame::from_vec(size, data)?, stats))
}

struct Ctx<'a, 'b> {
    fires: &'a [FireInstance<'b>],
    camera: &'a Camera,
    params: &'a RenderParams,
    fw: V3,
    rt: V3,
    up: V3,
    tan: f32,
    aspect: f32,
    time: f32,
}

impl Ctx<'_, '_> {
    fn tile(&self, tx: u32, ty: u32, cands: &[(u32, u32)]) -> (Vec<[f32; 4]>, RenderStats) {
        let mut stats = RenderStats::default();
        if cands.is_empty() {
            return (Vec::new(), stats);
        }
        let size = self.params.size;
        let (x0, y0) = (tx * TILE, ty * TILE);
        let (x1, y1) = ((x0 + TILE).min(size.width), (y0 + TILE).min(size.height));
        let mut buf = Vec::with_capacity(((x1 - x0) * (y1 - y0)) as usize);
        for y in y0..y1 {
            for x in x0..x1 {
                buf.push(self.pixel(x, y, cands, &mut stats));
            }
        }
        (buf, stats)
    }

    #[inline]
    fn pixel(&self, x: u32, y: u32, cands: &[(u32, u32)], stats: &mut RenderStats) -> [f32; 4] {
        let size = self.params.size;
        let sx = ((x as f32 + 0.5) / size.width as f32 * 2.0 - 1.0) * self.tan * self.aspect;
        let sy = (1.0 - (y as f32 + 0.5) / size.height as f32 * 2.0) * self.tan;
        let d =
            normalize(add(self.fw, add(scale(self.rt, sx), scale(self.up, sy)))).unwrap_or(self.fw);
        let o = self.camera.position;
        let cosf = dot(d, self.fw);
        let inv = [1.0 / d[0], 1.0 / d[1], 1.0 / d[2]];
        let spacing = self.params.slice_spacing;
        let gain = self.params.intensity * spacing;
        let mut acc = [0.0f32; 4];
        let mut best_k = i64::MAX;
        let mut covered = false;
        // Candidates are grouped by fire (binning order); per fire, march the union of the
        // cells' ray intervals front to back and walk from cell to cell with the local `s`.
        let mut ranges: [(u32, f32, f32); 64] = [(0, 0.0, 0.0); 64];
        let mut i = 0;
        while i < cands.len() {
            let fi = cands[i].0;
            let fire = &self.fires[fi as usize];
            let cells = fire.lattice.cells();
            let mut nr = 0;
            let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
            while i < cands.len() && cands[i].0 == fi {
                let ci = cands[i].1;
                i += 1;
                let cell = &cells[ci as usize];
                let mut t0 = 1e-4f32;
                let mut t1 = f32::INFINITY;
                for a in 0..3 {
                    let x = (cell.min[a] - o[a]) * inv[a];
                    let y = (cell.max[a] - o[a]) * inv[a];
                    let (x, y) = if x < y { (x, y) } else { (y, x) };
                    if x.is_nan() || y.is_nan() {
                        continue;
                    }
                    t0 = t0.max(x);
                    t1 = t1.min(y);
                }
                if t0 > t1 {
                    continue;
                }
                lo = lo.min(t0);
                hi = hi.max(t1);
                if nr < ranges.len() {
                    ranges[nr] = (ci, t0, t1);
                    nr += 1;
                }
            }
            if nr == 0 {
                continue;
            }
            let ranges = &ranges[..nr];
            let last = cells.len() - 1;
            let k0 = (lo * cosf / spacing).ceil() as i64;
            let k1 = ((hi * cosf / spacing).floor() as i64).min(best_k - 1);
            let mut cur: Option<usize> = None;
            let mut guess = [0.5f32; 3];
            // local-coordinate change per sample in the current cell, to extrapolate guesses
            let mut delta: Option<[f32; 3]> = None;
            for k in k0..=k1 {
                let t = k as f32 * spacing / cosf;
                let p = add(o, scale(d, t));
                let mut j = match cur {
                    Some(j) => j,
                    None => match ranges.iter().find(|r| r.1 <= t && t <= r.2) {
                        Some(r) => {
                            guess = [0.5; 3];
                            delta = None;
                            r.0 as usize
                        }
                        None => continue,
                    },
                };
                let start = (j, guess);
                if let Some(dl) = delta {
                    guess = [guess[0] + dl[0], guess[1] + dl[1], guess[2] + dl[2]];
                }
                let mut found = None;
                for _ in 0..6 {
                    let Some(l) = cells[j].inverse_fast(p, guess) else {
                        break;
                    };
                    let step = l[2].floor();
                    if (step < 0.0 && j > 0) || (step >= 1.0 && j < last) {
                        let nj = (j as i64 + step as i64).clamp(0, last as i64) as usize;
                        guess = [l[0], l[1], (l[2] - (nj as f32 - j as f32)).clamp(0.0, 1.0)];
                        j = nj;
                        continue;
                    }
                    found = Some(l);
                    break;
                }
                let Some(l) = found else {
                    cur = None;
                    continue;
                };
                delta = (start.0 == j)
                    .then(|| [l[0] - start.1[0], l[1] - start.1[1], l[2] - start.1[2]]);
                cur = Some(j);
                guess = l;
                if !(l[0] >= 0.0
                    && l[0] <= 1.0
                    && l[1] >= 0.0
                    && l[1] <= 1.0
                    && l[2] >= 0.0
                    && l[2] <= 1.0)
                {
                    continue;
                }
                covered = true;
                stats.samples += 1;
                let tex = fire.lattice.tex_of(j, l);
                if radial_u(tex) > 1.0 {
                    continue;
                }
                stats.shaded += 1;
                let c = shade(
                    tex,
                    fire.lattice.radius_at(tex[2]),
                    fire.lattice.length(),
                    self.time * fire.noise.time_scale,
                    &fire.noise,
                    fire.offset,
                    fire.profile,
                );
                match self.params.blend {
                    Blend::Additive => {
                        let e = gain * c[3];
                        acc = [
                            acc[0] + c[0] * e,
                            acc[1] + c[1] * e,
                            acc[2] + c[2] * e,
                            acc[3] + e,
                        ];
                    }
                    Blend::Tint(tc) => {
                        let lum = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
                        let e = gain * c[3] * lum;
                        acc = [
                            acc[0] + tc[0] * e,
                            acc[1] + tc[1] * e,
                            acc[2] + tc[2] * e,
                            acc[3] + gain * c[3],
                        ];
                    }
                    Blend::Cartoon => {
                        if c[3] >= 0.5 {
                            best_k = k;
                            acc = [c[0], c[1], c[2], 1.0];
                            break;
                        }
                    }
                }
            }
        }
        if covered {
            stats.covered_pixels += 1;
        }
        acc[3] = acc[3].min(1.0);
        acc
    }
}

/// The post pipeline: bloom on the premultiplied HDR frame (skipped when
/// `bloom.passes == 0`), then conversion to straight alpha with
/// `a' = clamp(max(a, max(r, g, b)), 0, 1)` and `rgb' = rgb / a'` — so compositing the
/// result "over" a background adds the fire's light to it where it is faint.
pub fn finish(premultiplied: &RgbaFrame, bloom: &BloomParams) -> Result<RgbaFrame> {
    let mut f = if bloom.passes > 0 {
        bloom_rgba(premultiplied, bloom)?
    } else {
        premultiplied.clone()
    };
    for p in f.data_mut() {
        let a = p[3].max(p[0]).max(p[1]).max(p[2]).clamp(0.0, 1.0);
        if a > 0.0 {
            *p = [p[0] / a, p[1] / a, p[2] / a, a];
        } else {
            *p = [0.0; 4];
        }
    }
    Ok(f)
}
