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
//! Performance: only the part of each cell where a sample can be visible is marched
//! ([`visible_parts`]: the profile columns within reach of the cell's heights for any
//! turbulence within its proven bound; a skipped sample's alpha is exactly zero); the rest
//! of a ray only when [`RenderParams::count_coverage`] asks, until the pixel is known to be
//! covered. Cells are binned into 16×16-pixel
//! tiles by their projected bounding boxes
//! (empty tiles cost nothing; boxes are stored inline for the per-pixel slab tests, and a
//! pixel outside a cell's projected rectangle skips that cell's slab test), rayon runs over
//! tiles with per-worker scratch buffers. On x86-64 CPUs with AVX2 the tile renderer runs
//! as an AVX2 build of the same code (runtime dispatch in `Ctx::tile`; bit-identical
//! output, tested). Per tile and fire, the samples are found first; then they are shaded
//! in bulk; then they are added up per pixel.
//! - Finding samples cell by cell ([`Ctx::march_cells`], for a lattice whose cells all
//!   have a certified inverse, [`per_cell_ok`] — every Table 1 lattice): per candidate
//!   cell, the slices of every pixel's ray inside the part of the cell that can be visible
//!   become candidates, which are inverted eight at a time with the cell's certified chord
//!   iteration ([`crate::lattice::Cell::inverse_certified_lanes`], to [`CELL_TEX_TOL`]);
//!   one rule per shared face ([`Ctx::owns`]) gives each sample to exactly one cell.
//! - Otherwise, ray by ray (and, in the per-cell case, for the coverage of pixels that
//!   found no visible sample): along a ray the global lattice coordinates
//!   `(a, b, level + s)` are extrapolated from the previous two samples (for the second sample, from the ray's
//!   step mapped by the cell's inverse Jacobian), which gives the cell and a close guess;
//!   a ray's first sample starts from a chord step from the cell centre (moving to the
//!   neighbouring cell while that step says the point lies there).
//!   [`crate::lattice::Cell::inverse_certified`] finishes with chord steps using the cell
//!   centre's inverse Jacobian and accepts an iterate only with a proven error bound of
//!   [`INVERSE_TEX_TOL`] in texture space (the contraction constant of the chord map is
//!   bounded per cell when the lattice is built; nearly affine cells — all of the Table 1
//!   fire's — qualify). It answers for practically every sample of the Table 1 scene;
//!   otherwise [`crate::lattice::Cell::inverse_tracked`] takes over (chord steps with the
//!   inverse Jacobian of the ray's last Newton solve, or Newton's method). An iterate that
//!   lies well beyond an end face of the lattice (`s` < 0 in the bottom cell or > 1 in the
//!   top one, by 0.05 plus its would-be error bound) ends the search: such a sample is
//!   outside the fire whatever the exact inverse.
//! - Shading (`Ctx::shade_batched`): samples are put in slice-then-pixel order (so the
//!   eight of a batch mostly share their noise cells; [`crate::noise::avx2`] then
//!   broadcasts the cells' gradients); the turbulence runs [`LANES`] samples at a time
//!   through the structure-of-arrays noise ([`crate::noise::NoiseKind::eval_lanes_cached`],
//!   equal to the scalar noise value for value; the permutation hashes of the noise cells
//!   are memoised per worker), octave by octave, and a sample leaves the batch as soon as
//!   the proven noise bound shows that no remaining octave can move its profile look-up
//!   into the lit part of the profile column (its alpha is then exactly zero).
//!
//! [`RenderParams::exact_inverse`] selects the reference path instead: the older
//! chord-then-Newton inverse to 1e-5 from the cell centre and the scalar [`shade`] per
//! sample. The shading of the two paths is identical for identical samples (tested); the
//! images differ only through the inverse, by < 1e-4 per channel (tested; ≤ 6e-5
//! measured). Per pixel the result does not depend on the thread count, so output bytes
//! are deterministic.
//!
//! Output convention ([`render`]): linear-light HDR, **premultiplied** — `rgb` is the light
//! emitted towards the camera (as if blended additively onto black) and `a` the
//! accumulated opacity in `0..=1`. [`finish`] applies bloom and converts to the straight
//! alpha every Ignis frame uses.

use crate::error::{Result, VolumeError};
use crate::lattice::{add, cross, dot, normalize, scale, sub, Lattice, Track, CHORD_LANES, V3};
use crate::mapping::{
    kernel, loop_mix, noise_position, noise_scale, profile_uv, radial_u, shade, shade_looped,
    LoopMix, NoiseParams,
};
use crate::noise::{NoiseCache, LANES};
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
    /// The reference path: invert every sample's cell map with the chord-then-Newton
    /// method from the cell centre ([`crate::lattice::Cell::inverse_fast`], steps down to
    /// 1e-5) and shade each sample with the scalar [`shade`], instead of the tracked
    /// chord/Newton inverse and the batched noise. The reference for a GPU parity check;
    /// the fast path differs from it by < 1e-4 per channel (tested; ≤ 6e-5 measured).
    /// Default false.
    pub exact_inverse: bool,
    /// Also count [`RenderStats::covered_pixels`]: march the rest of every ray that found
    /// no visible sample until one sample is known to lie in a cell. That work adds
    /// nothing to the image (those samples have zero alpha; about 7% of a Table 1 frame),
    /// so it is off by default and `covered_pixels` is then 0.
    pub count_coverage: bool,
    /// A seamless loop: the length of the loop in seconds (`frames / fps`), or `None`.
    /// The noise is then periodic in time with this period ([`LoopMix`]), so a frame at
    /// `time + loop_period` equals the one at `time`. Default `None`.
    pub loop_period: Option<f32>,
}

impl RenderParams {
    /// The loop mix of a fire with this noise at scene time `time` (seconds).
    fn mix(&self, noise: &NoiseParams, time: f32) -> Option<LoopMix> {
        self.loop_period
            .map(|p| loop_mix(time * noise.time_scale, p * noise.time_scale))
    }

    pub fn validate(&self) -> Result<()> {
        if let Some(p) = self.loop_period {
            if !(p > 0.0 && p.is_finite()) {
                return Err(VolumeError::bad(
                    "loop_period",
                    format!("{p}; a loop must last a positive number of seconds"),
                ));
            }
        }
        if !(self.slice_spacing > 0.0 && self.slice_spacing.is_finite()) {
            return Err(VolumeError::bad(
                "render.slice_spacing",
                format!(
                    "{}; must be > 0 (the paper uses 0.2 for a unit-radius fire)",
                    self.slice_spacing
                ),
            ));
        }
        if let Blend::Tint(t) = self.blend {
            if !t
                .iter()
                .all(|c| c.is_finite() && (0.0..=1000.0).contains(c))
            {
                return Err(VolumeError::bad(
                    "render.blend",
                    format!("tint {t:?}: each of R, G, B must be a number in 0..=1000, e.g. tint:0.3,0.5,1"),
                ));
            }
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
    /// would run the shader on); counted only with [`RenderParams::count_coverage`], else 0.
    pub covered_pixels: u64,
    /// Samples found inside a cell. The fast path marches only the parts of cells where a
    /// sample can be visible (plus, per pixel, what it takes to find `covered_pixels` when
    /// counting them), so it counts fewer than [`RenderParams::exact_inverse`], which
    /// marches every slice.
    pub samples: u64,
    /// Of those, the samples inside the unit cylinder (handed to the shading).
    pub shaded: u64,
}

const TILE: u32 = 16;

/// Most samples (estimated before marching: for every cell, the pixels its projection
/// covers times its bounding box's diagonal over the slice spacing) one frame may take;
/// past it [`render`] refuses with [`VolumeError::LimitExceeded`] instead of running for
/// hours. 2·10⁹ is ~50× a Table 1 frame at 1920×1080.
pub const MAX_SAMPLES: f64 = 2e9;
/// Most (tile, cell) candidates one frame may bin (each ~100 bytes: 3·10⁷ ≈ 3 GB).
pub const MAX_CANDIDATES: u64 = 30_000_000;

/// Error bound, per texture coordinate, of the fast path's certified chord inverse
/// ([`crate::lattice::Cell::inverse_certified`]) against the exact inverse: proven in
/// exact arithmetic; `f32` rounding of the residual adds < 1e-6 (the test
/// `certified_inverse_error_bound` checks ≤ this + 2e-6 against an `f64` inverse).
/// Texture space: `x, y ∈ [−1, 1]` across the fire, `z ∈ [0, 1]` along it.
pub const INVERSE_TEX_TOL: f32 = 3e-5;
/// Error bound, per texture coordinate, of the certified inverse in [`Ctx::march_cells`]:
/// a quarter of [`INVERSE_TEX_TOL`]. The chord iteration there starts from the cell
/// centre rather than from a prediction along the ray, so the iterate it accepts is
/// usually close to its bound; the tighter bound costs about one more step (vectorised).
pub const CELL_TEX_TOL: f32 = 0.25 * INVERSE_TEX_TOL;
/// How far beyond its end faces (in `s`, as a multiple of the certified inverse's error
/// bound in `s`) a sample may lie and still be assigned to a cell by
/// [`Ctx::march_cells`]; see [`Ctx::owns`].
const OWNER_SLACK: f32 = 8.0;
/// Cells kept per ray and fire for finding the entry cell (more are ignored).
const MAX_RANGES: usize = 64;

/// A tile's candidate cell, with its bounding box inline so the per-pixel slab tests read
/// contiguous memory.
#[derive(Clone, Copy, Debug)]
struct Cand {
    fire: u32,
    cell: u32,
    /// The cell's bounding box, relative to the camera position (as the slab tests use it).
    min: V3,
    max: V3,
    /// Bounding box of the part of the cell that can be visible ([`visible_parts`]),
    /// relative to the camera; empty (`vmin > vmax`) when none can be.
    vmin: V3,
    vmax: V3,
    /// The tighter description of that part for a nearly affine cell.
    disc: Option<Disc>,
    /// Pixel rectangle `[x0, x1] × [y0, y1]` (inclusive) containing the cell's projection,
    /// with a pixel of margin: rays of other pixels cannot meet the cell (it lies in the
    /// convex hull of its corners, whose projection is inside this rectangle), so their
    /// slab test is skipped.
    px: [i32; 4],
}

/// Renders `fires` seen from `camera` at noise time `time` (seconds). Returns a
/// premultiplied HDR frame (see the module docs) and work counters.
pub fn render(
    fires: &[FireInstance],
    camera: &Camera,
    params: &RenderParams,
    time: f32,
) -> Result<(RgbaFrame, RenderStats)> {
    render_with(fires, camera, params, time, true)
}

/// [`render`], with the AVX2 build of the tile renderer allowed (`simd`) or not.
fn render_with(
    fires: &[FireInstance],
    camera: &Camera,
    params: &RenderParams,
    time: f32,
    simd: bool,
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
    let mut bins: Vec<Vec<Cand>> = vec![Vec::new(); (tx * ty) as usize];
    let (mut est_samples, mut candidates) = (0f64, 0u64);
    let too_much = |what: String| {
        VolumeError::LimitExceeded(format!(
            "{what}; raise render.slice_spacing (the paper uses 0.2 for a unit-radius fire), \
             shrink the fire (radius, points, lifetime) or the output size"
        ))
    };
    for (fi, f) in fires.iter().enumerate() {
        let visible = visible_parts(
            f,
            camera.position,
            params.exact_inverse,
            params.mix(&f.noise, time),
        );
        for (ci, c) in f.lattice.cells().iter().enumerate() {
            let vis = visible[ci];
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
            // the pixels whose centre may see the cell, and their tiles
            let px = if behind {
                [i32::MIN, i32::MAX, i32::MIN, i32::MAX]
            } else {
                let clamp = |v: f32| v.clamp(-1e9, 1e9) as i64;
                [
                    clamp((lo[0] - 1.0).floor()),
                    clamp((hi[0] + 1.0).ceil()),
                    clamp((lo[1] - 1.0).floor()),
                    clamp((hi[1] + 1.0).ceil()),
                ]
                .map(|v| v.clamp(-(1 << 30), 1 << 30) as i32)
            };
            let (x0, x1, y0, y1) = if behind {
                (0, tx as i64 - 1, 0, ty as i64 - 1)
            } else {
                (
                    (px[0] as i64).div_euclid(TILE as i64),
                    (px[1] as i64).div_euclid(TILE as i64),
                    (px[2] as i64).div_euclid(TILE as i64),
                    (px[3] as i64).div_euclid(TILE as i64),
                )
            };
            let (cx0, cx1) = (px[0].max(0) as f64, (px[1] as f64).min(w as f64));
            let (cy0, cy1) = (px[2].max(0) as f64, (px[3] as f64).min(h as f64));
            let covered = if behind {
                w as f64 * h as f64
            } else {
                (cx1 - cx0).max(0.0) * (cy1 - cy0).max(0.0)
            };
            let d = sub(c.max, c.min);
            let diag = (dot(d, d) as f64).sqrt();
            est_samples += covered * (diag / params.slice_spacing as f64).ceil();
            if !(est_samples <= MAX_SAMPLES) {
                return Err(too_much(format!(
                    "a frame needs more than {MAX_SAMPLES:e} samples (slice spacing {}, {} cells)",
                    params.slice_spacing,
                    f.lattice.cells().len()
                )));
            }
            let ntiles = ((y1.min(ty as i64 - 1) - y0.max(0) + 1).max(0)
                * (x1.min(tx as i64 - 1) - x0.max(0) + 1).max(0)) as u64;
            candidates += ntiles;
            if candidates > MAX_CANDIDATES {
                return Err(too_much(format!(
                    "a frame needs more than {MAX_CANDIDATES} tile candidates ({} cells)",
                    f.lattice.cells().len()
                )));
            }
            for y in y0.max(0)..=y1.min(ty as i64 - 1) {
                for x in x0.max(0)..=x1.min(tx as i64 - 1) {
                    bins[(y as u32 * tx + x as u32) as usize].push(Cand {
                        fire: fi as u32,
                        cell: ci as u32,
                        min: sub(c.min, camera.position),
                        max: sub(c.max, camera.position),
                        vmin: sub(vis.min, camera.position),
                        vmax: sub(vis.max, camera.position),
                        disc: vis.disc,
                        px,
                    });
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
        simd,
        per_cell: fires
            .iter()
            .map(|f| !params.exact_inverse && per_cell_ok(f.lattice))
            .collect(),
    };
    let tiles: Vec<(Vec<[f32; 4]>, RenderStats)> = (0..tx * ty)
        .into_par_iter()
        .map(|t| {
            let cands = &bins[t as usize];
            if cands.is_empty() {
                return (Vec::new(), RenderStats::default());
            }
            SCRATCH.with(|s| match s.try_borrow_mut() {
                Ok(mut scratch) => ctx.tile(t % tx, t / tx, cands, &mut scratch),
                // (not reached: a tile starts no parallel work that could render here)
                Err(_) => ctx.tile(t % tx, t / tx, cands, &mut Scratch::default()),
            })
        })
        .collect();
    let mut stats = RenderStats::default();
    for (_, s) in &tiles {
        stats.covered_pixels += s.covered_pixels;
        stats.samples += s.samples;
        stats.shaded += s.shaded;
    }
    // the tiles into the frame, a band of tile rows per task (empty tiles stay zero)
    let mut data = vec![[0.0f32; 4]; size.pixels()];
    data.par_chunks_mut((TILE * w) as usize)
        .zip(tiles.par_chunks(tx as usize))
        .for_each(|(band, row)| {
            for (i, (buf, _)) in row.iter().enumerate() {
                if buf.is_empty() {
                    continue;
                }
                let x0 = i * TILE as usize;
                let tw = (TILE as usize).min(w as usize - x0);
                for (r, chunk) in buf.chunks_exact(tw).enumerate() {
                    let start = r * w as usize + x0;
                    band[start..start + tw].copy_from_slice(chunk);
                }
            }
        });
    Ok((RgbaFrame::from_vec(size, data)?, stats))
}

/// `rem[o]`: a bound on `|Σ_{i ≥ o} gain^i · noise|` (the octaves from `o` on), with a
/// relative margin for rounding; `rem[octaves] = 0`.
fn turbulence_bounds(noise: &NoiseParams) -> [f32; 9] {
    let mut rem = [0.0f32; 9];
    let b = noise.kind.bound() as f64;
    let g = (noise.gain as f64).abs();
    let mut acc = 0.0f64;
    for o in (0..(noise.octaves as usize).min(8)).rev() {
        acc += b * g.powi(o as i32);
        rem[o] = (acc * (1.0 + 1e-4)) as f32;
    }
    rem
}

/// Where a lattice cell can hold a visible sample (see [`visible_parts`]).
#[derive(Clone, Copy, Debug)]
struct Visible {
    /// World bounding box of that part; empty (`min > max`) if there is none.
    min: V3,
    max: V3,
    /// For a nearly affine cell, a tighter description (used instead of the box).
    disc: Option<Disc>,
}

/// The part of a nearly affine cell where a visible sample can lie, through the cell's
/// affine inverse model ([`crate::lattice::Cell::affine_inverse`]): with
/// `(x_a, x_b, x_s) = M (p − F(c))` (`l − ½` up to the model's error),
/// `x_a² + x_b² ≤ r2` and `|x_s| ≤ h`. All in `f64`.
#[derive(Clone, Copy, Debug)]
struct Disc {
    /// Rows of `M`.
    m: [[f64; 3]; 3],
    /// `M (o − F(c))` for the camera position `o`.
    alpha: [f64; 3],
    r2: f64,
    h: f64,
}

impl Disc {
    /// The ray parameter interval (`t ≥ 1e-4`, slightly widened) in which the camera ray
    /// with direction `d` is in the region, if not empty: `x(t) = alpha + t M d`, one
    /// linear and one quadratic inequality in `t`.
    #[inline(always)]
    fn interval(&self, d: V3) -> Option<(f32, f32)> {
        let d = d.map(f64::from);
        let b = self.m.map(|r| r[0] * d[0] + r[1] * d[1] + r[2] * d[2]);
        let a = self.alpha;
        let (mut lo, mut hi) = (1e-4f64, f64::INFINITY);
        // Reciprocals instead of divisions (two fewer of those slow operations): their
        // relative error of ~1e-16 is far below the final widening.
        if b[2] != 0.0 {
            let inv = 1.0 / b[2];
            let (t0, t1) = ((-self.h - a[2]) * inv, (self.h - a[2]) * inv);
            lo = lo.max(t0.min(t1));
            hi = hi.min(t0.max(t1));
            if lo > hi {
                return None; // the ray misses the slab in s: no square root needed
            }
        } else if a[2].abs() > self.h {
            return None;
        }
        let qa = b[0] * b[0] + b[1] * b[1];
        let qb = a[0] * b[0] + a[1] * b[1];
        let qc = a[0] * a[0] + a[1] * a[1] - self.r2;
        if qa > 0.0 {
            let disc = qb * qb - qa * qc;
            if disc < 0.0 {
                return None;
            }
            let sq = disc.sqrt();
            let inv = 1.0 / qa;
            lo = lo.max((-qb - sq) * inv);
            hi = hi.min((-qb + sq) * inv);
        } else if qc > 0.0 {
            return None;
        }
        if lo > hi || hi.is_nan() {
            return None;
        }
        let m = 1e-6 * (1.0 + hi.abs());
        Some(((lo - m) as f32, (hi + m) as f32))
    }

    /// The pixel row whose rays have directions `d = fw + sx · rt + sy · up` (the camera
    /// basis): the interval of `sx` outside which a ray misses the region's infinite
    /// elliptic cylinder `x_a² + x_b² ≤ r2` — `None` if every ray of the row does. Along
    /// the row `M d = b₀ + sx b₁`; the line `alpha + t M d` comes within the cylinder when
    /// `(A × B)² ≤ r2 |B|²` (`A`, `B` the `a, b` parts of `alpha`, `M d`, the condition
    /// [`Disc::interval`]'s discriminant tests), a quadratic `Q(sx) ≤ 0`. When `Q` opens
    /// upwards that is the interval between its roots; otherwise no bound is given
    /// (`±∞`; e.g. the camera inside the cylinder).
    ///
    /// First, the whole row: its rays lie in the plane through `alpha` spanned by `b₀` and
    /// `b₁`, with normal `N = b₀ × b₁`, which meets the region (the cylinder between
    /// `x_s = ±h`, centred at 0) only if `|N · alpha| ≤ √r2 |N_ab| + h |N_s|` (the
    /// region's support in direction `N`); else `None`. This rejects the rows that cross
    /// the cell's height band only outside the cylinder.
    ///
    /// Rounding matters only where a ray grazes the region, whose radius and height have
    /// margins (1e-3) over the visible part's: such rays hold no visible sample.
    #[inline(always)]
    fn row_span(&self, fw: V3, rt: V3, up: V3, sy: f32) -> Option<(f64, f64)> {
        let m = &self.m;
        let row = |v: V3| {
            [0, 1, 2].map(|i| m[i][0] * v[0] as f64 + m[i][1] * v[1] as f64 + m[i][2] * v[2] as f64)
        };
        let (f, u, b1) = (row(fw), row(up), row(rt));
        let b0 = [0, 1, 2].map(|i| f[i] + sy as f64 * u[i]);
        let a = self.alpha;
        let n = [
            b0[1] * b1[2] - b0[2] * b1[1],
            b0[2] * b1[0] - b0[0] * b1[2],
            b0[0] * b1[1] - b0[1] * b1[0],
        ];
        let reach = self.r2.sqrt() * n[0].hypot(n[1]) + self.h * n[2].abs();
        if (n[0] * a[0] + n[1] * a[1] + n[2] * a[2]).abs() > reach * (1.0 + 1e-9) {
            return None;
        }
        let (c0, c1) = (a[0] * b0[1] - a[1] * b0[0], a[0] * b1[1] - a[1] * b1[0]);
        let qa = c1 * c1 - self.r2 * (b1[0] * b1[0] + b1[1] * b1[1]);
        let qb = c0 * c1 - self.r2 * (b0[0] * b1[0] + b0[1] * b1[1]);
        let qc = c0 * c0 - self.r2 * (b0[0] * b0[0] + b0[1] * b0[1]);
        if qa.is_nan() || qa <= 0.0 {
            return Some((f64::NEG_INFINITY, f64::INFINITY));
        }
        let disc = qb * qb - qa * qc;
        if disc < 0.0 {
            return None;
        }
        let sq = disc.sqrt();
        Some(((-qb - sq) / qa, (-qb + sq) / qa))
    }

    /// Whether world point `p` is in the region (for tests).
    #[cfg(test)]
    fn contains(&self, p: V3, o: V3) -> bool {
        let q = [0, 1, 2].map(|i| p[i] as f64 - o[i] as f64);
        let x = [0, 1, 2]
            .map(|r| self.alpha[r] + self.m[r].iter().zip(q).map(|(m, q)| m * q).sum::<f64>());
        x[0] * x[0] + x[1] * x[1] <= self.r2 && x[2].abs() <= self.h
    }
}

/// Per lattice cell of `fire`, where a sample can be visible — or, when `full`, the whole
/// cell's box. `camera` is the camera position.
///
/// A sample at texture height `z` and radius `u` is shaded only if the profile column at
/// `u` has some alpha within reach of `z` for a turbulence within its proven bound
/// ([`Window`] with no octave summed yet; otherwise its alpha is exactly zero and it adds
/// nothing to any blend), and only if `u ≤ 1`. Over the cell's height range that holds
/// only for `u ≤ reach`. The box: the trilinear image of the sub-square
/// `|tex_x|, |tex_y| ≤ reach` lies in the convex hull of its 8 corners, whose bounding box
/// it is. The disc, for nearly affine cells: a visible sample has `l ∈ [0, 1]³` and
/// `√((a − ½)² + (b − ½)²) ≤ reach / 2`, so its affine estimate lies within the model's
/// error of that. Margins far above the inverse's error ([`INVERSE_TEX_TOL`]) and `f32`
/// rounding keep every sample the shading would keep.
///
/// Both extend [`OWNER_SLACK`] beyond the cell's end faces in `s` (`s ∈ [−σ, 1 + σ]`), so
/// they also hold every sample the per-cell march ([`Ctx::march_cells`]) assigns to the
/// cell (whose computed `s` may be off by the certified inverse's error).
///
/// `mix`: a looping render's [`LoopMix`], whose turbulence is bounded by `(a + b)` times
/// the bound of one copy.
fn visible_parts(
    fire: &FireInstance,
    camera: V3,
    full: bool,
    mix: Option<LoopMix>,
) -> Vec<Visible> {
    let cells = fire.lattice.cells();
    let whole = |c: &crate::lattice::Cell| Visible {
        min: c.min,
        max: c.max,
        disc: None,
    };
    let noise = &fire.noise;
    if full {
        return cells.iter().map(whole).collect();
    }
    let turbulent = noise.octaves > 0 && noise.stability != 0.0;
    let r = if turbulent {
        turbulence_bounds(noise)[0] * mix.map_or(1.0, |m| m.a + m.b)
    } else {
        0.0
    };
    let profile = fire.profile;
    let w = profile.width();
    let n = cells.len();
    let sigma = OWNER_SLACK * n as f32 * INVERSE_TEX_TOL;
    cells
        .iter()
        .enumerate()
        .map(|(j, c)| {
            // the cell's texture heights, with a margin for rounding
            let z0 = j as f32 / n as f32 - 1e-3;
            let z1 = (j + 1) as f32 / n as f32 + 1e-3;
            let k = if turbulent {
                kernel(z1, noise.stability)
            } else {
                0.0
            };
            let eps = 2e-4 * (1.0 + k * r);
            let (vlo, vhi) = (z0 - k * r - eps, z1 + k * r + eps);
            // the last profile column (`u ∈ [i, i + 1) / (w − 1)`) with alpha in reach
            let last = (0..w - 1).rev().find(|&i| {
                let u = (i as f32 + 0.5) / (w - 1) as f32;
                profile
                    .v_support(u)
                    .is_some_and(|[lo, hi]| hi >= vlo && lo <= vhi)
            });
            let Some(i) = last else {
                return Visible {
                    min: [f32::INFINITY; 3],
                    max: [f32::NEG_INFINITY; 3],
                    disc: None,
                };
            };
            let reach = ((i + 1) as f32 / (w - 1) as f32).min(1.0) + 2e-3;
            let disc = c.affine_inverse().map(|aff| {
                let rel = [0, 1, 2].map(|i| camera[i] as f64 - aff.centre[i]);
                let radius = 0.5 * reach as f64 + aff.err[0].hypot(aff.err[1]) + 1e-3;
                Disc {
                    m: aff.m,
                    alpha: aff.m.map(|r| r[0] * rel[0] + r[1] * rel[1] + r[2] * rel[2]),
                    r2: radius * radius,
                    h: 0.5 + sigma as f64 + aff.err[2] + 1e-3,
                }
            });
            let reach = reach.min(1.0);
            let (a0, a1) = (0.5 - 0.5 * reach, 0.5 + 0.5 * reach);
            let mut lo = [f32::INFINITY; 3];
            let mut hi = [f32::NEG_INFINITY; 3];
            for corner in 0..8 {
                let l = [
                    if corner & 1 == 0 { a0 } else { a1 },
                    if corner & 2 == 0 { a0 } else { a1 },
                    (corner >> 2) as f32 * (1.0 + 2.0 * sigma) - sigma,
                ];
                let q = c.forward(l);
                for a in 0..3 {
                    lo[a] = lo[a].min(q[a]);
                    hi[a] = hi[a].max(q[a]);
                }
            }
            for a in 0..3 {
                let m = 1e-4 * (1.0 + lo[a].abs().max(hi[a].abs()));
                lo[a] -= m;
                hi[a] += m;
            }
            Visible {
                min: lo,
                max: hi,
                disc,
            }
        })
        .collect()
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
    /// Use the AVX2 build of the tile renderer when the CPU has it (same results).
    simd: bool,
    /// Per fire: find its samples cell by cell ([`Ctx::march_cells`]) rather than ray by
    /// ray ([`per_cell_ok`]).
    per_cell: Vec<bool>,
}

/// Whether [`Ctx::march_cells`] may find this lattice's samples: every cell has a
/// certificate (nearly affine, so the certified chord inverse answers), and neighbouring
/// cells are of similar thickness across their shared face (the rows `∇s` of their
/// centres' inverse Jacobians differ in length by less than 1.5×, so by less than 2×
/// anywhere on the face), which the face rule of [`Ctx::owns`] relies on.
fn per_cell_ok(lattice: &Lattice) -> bool {
    let cells = lattice.cells();
    let grad_s = |c: &crate::lattice::Cell| c.affine_inverse().map(|a| norm64(a.m[2]));
    let mut prev: Option<f64> = None;
    for c in cells {
        let Some(g) = grad_s(c) else {
            return false;
        };
        if !(g > 0.0 && g.is_finite()) {
            return false;
        }
        if let Some(p) = prev {
            if !(g < 1.5 * p && p < 1.5 * g) {
                return false;
            }
        }
        prev = Some(g);
    }
    true
}

fn norm64(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// The ray parameter interval `(t0, t1)` (with `t0 ≥ 1e-4`) in which the ray `o + t d`
/// (`inv` = `1/d` per axis) is inside the box `o + [min, max]`, if not empty.
#[inline(always)]
fn slab(inv: V3, min: V3, max: V3) -> Option<(f32, f32)> {
    let mut t0 = 1e-4f32;
    let mut t1 = f32::INFINITY;
    for a in 0..3 {
        let x = min[a] * inv[a];
        let y = max[a] * inv[a];
        let (x, y) = if x < y { (x, y) } else { (y, x) };
        if x.is_nan() || y.is_nan() {
            continue;
        }
        t0 = t0.max(x);
        t1 = t1.min(y);
    }
    (t0 <= t1).then_some((t0, t1))
}

/// A pixel's ray being marched (see [`Ctx::march`]).
struct Ray<'r> {
    o: V3,
    d: V3,
    /// `d · forward`: sample `k` is at `o + d · k · spacing / cosf`.
    cosf: f32,
    /// The candidate cells the ray meets, with its parameter interval in each.
    ranges: &'r [(u32, f32, f32)],
    /// Next slice index, and the last one.
    k: i64,
    k1: i64,
    /// The slices that may meet a visible part of a cell ([`visible_parts`]); empty if
    /// `.0 > .1`.
    visible: (i64, i64),
    pix: u16,
    covered: bool,
    /// While tracking, `g` is the last sample's global lattice coordinates
    /// `(a, b, level + s)` and `dg` their change per sample: consecutive samples are
    /// predicted by linear extrapolation (the map is smooth across cell faces), so the
    /// cell is known and one or two Newton steps usually suffice.
    tracking: bool,
    g: V3,
    dg: Option<V3>,
    /// Inverse Jacobian of the last Newton solve, for the chord steps.
    m: Track,
    /// Local-coordinate tolerance of the certified chord steps: [`INVERSE_TEX_TOL`] in
    /// texture space (`tex_x = 2a − 1`, `tex_z = (j + s)/cells`).
    tol: V3,
}

thread_local! {
    /// Each rendering thread's working arrays, kept from tile to tile and frame to frame
    /// (rayon's threads live on), so a warm renderer allocates nothing per sample or tile.
    static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// One fire's samples in one tile, in march order (pixel by pixel, front to back), plus
/// the working arrays of the batched shading. Reused from tile to tile (no allocation per
/// sample or per tile once warm).
#[derive(Default)]
struct Scratch {
    /// Pixel index within the tile.
    pix: Vec<u16>,
    /// Slice index (depth) of the sample, for the cartoon blend.
    k: Vec<i64>,
    /// Texture coordinates.
    tex: Vec<V3>,
    /// Straight-alpha colour of each sample (after shading).
    col: Vec<[f32; 4]>,
    /// Batched noise: the samples still in play.
    act: Vec<Live>,
    /// Sample indices ordered by slice, then pixel (see `Ctx::shade_batched`), and the
    /// counting sort's buckets.
    order: Vec<u32>,
    buckets: Vec<u32>,
    /// Memoised permutation hashes of the noise cells met so far.
    noise_cache: NoiseCache,
    /// Per-cell march ([`Ctx::march_cells`]): per pixel of the tile, the scaled ray
    /// direction and its reciprocal and whether a sample was found.
    dirs: Vec<V3>,
    invs: Vec<V3>,
    hit: Vec<bool>,
}

/// Up to [`CHORD_LANES`] candidate samples of one cell ([`Ctx::march_cells`]): world
/// positions, pixels and slices.
#[derive(Default)]
struct Batch {
    p: [[f32; CHORD_LANES]; 3],
    pix: [u16; CHORD_LANES],
    k: [i64; CHORD_LANES],
    n: usize,
}

/// A sample whose noise is still being summed.
#[derive(Clone, Copy, Debug)]
struct Live {
    /// Index into the sample arrays.
    idx: u32,
    /// Noise-space position (eq. 11 + 13) but for `w`, which is the same for every sample
    /// of a fire (`time · frequency + offset`).
    p: [f32; 3],
    /// Partial turbulence sum.
    sum: f32,
    /// A looping render's second copy of the noise ([`LoopMix`]): its `z` (its `x`, `y`
    /// are `p`'s) and its partial sum. Unused otherwise.
    pz2: f32,
    sum2: f32,
    /// `u` (eq. 12), `tex_z` and the kernel `f(tex_z)` (eq. 13).
    u: f32,
    z: f32,
    kern: f32,
    /// The turbulence values that can make the sample visible ([`Window`]).
    win: Window,
}

/// The turbulence values `t` for which a sample's profile look-up `v = z + kern · t`
/// (eq. 12–13) can have non-zero alpha: `v` in the column's visible range `[lo, hi]`
/// ([`FireProfile::v_support`]), i.e. `kern · t ∈ [lo − z, hi − z]`, here widened by a
/// margin of `2e-4 · (1 + 2 kern B)` in `v` (`B` the bound on the whole turbulence,
/// which bounds `|sum| + rem` at every octave; far above the `f32` rounding of `v` and
/// of these few operations), so a sample whose turbulence range misses the window is
/// certain to get zero alpha. A negative kernel gets no window (no culling); a NaN one
/// culls the sample, whose `v` (NaN) gives zero alpha anyway.
#[derive(Clone, Copy, Debug)]
struct Window {
    min: f32,
    max: f32,
}

impl Window {
    #[inline(always)]
    fn new(z: f32, kern: f32, [lo, hi]: [f32; 2], bound: f32) -> Window {
        if kern < 0.0 {
            return Window {
                min: f32::NEG_INFINITY,
                max: f32::INFINITY,
            };
        }
        let eps = 2e-4 * (1.0 + 2.0 * kern * bound);
        Window {
            min: lo - eps - z,
            max: hi + eps - z,
        }
    }

    /// Whether a turbulence within `rem` of `sum` can lie in the window of a sample with
    /// kernel `kern` (`false` is certain).
    #[inline(always)]
    fn reachable(&self, kern: f32, sum: f32, rem: f32) -> bool {
        kern * (sum + rem) >= self.min && kern * (sum - rem) <= self.max
    }
}

impl Ctx<'_, '_> {
    /// Renders one tile: [`Ctx::tile_impl`], compiled for AVX2 when the CPU has it.
    ///
    /// The AVX2 build runs the very same `f32` operations (Rust never fuses a multiply and
    /// an add on its own, so enabling the FMA unit changes no result), only with wider
    /// registers: the 8-lane noise fits one register per lane vector instead of two, and
    /// `floor` is an instruction rather than a library call. The output is bit for bit the
    /// same on either path (tested).
    fn tile(
        &self,
        tx: u32,
        ty: u32,
        cands: &[Cand],
        scratch: &mut Scratch,
    ) -> (Vec<[f32; 4]>, RenderStats) {
        #[cfg(target_arch = "x86_64")]
        if self.simd && std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU supports AVX2 (checked just above).
            return unsafe { self.tile_avx2(tx, ty, cands, scratch) };
        }
        self.tile_impl(tx, ty, cands, scratch, false)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn tile_avx2(
        &self,
        tx: u32,
        ty: u32,
        cands: &[Cand],
        scratch: &mut Scratch,
    ) -> (Vec<[f32; 4]>, RenderStats) {
        self.tile_impl(tx, ty, cands, scratch, true)
    }

    /// `avx2`: the CPU has AVX2 and this is the AVX2 build (the noise then uses
    /// [`crate::noise::avx2`]).
    #[inline(always)]
    fn tile_impl(
        &self,
        tx: u32,
        ty: u32,
        cands: &[Cand],
        scratch: &mut Scratch,
        avx2: bool,
    ) -> (Vec<[f32; 4]>, RenderStats) {
        let mut stats = RenderStats::default();
        if cands.is_empty() {
            return (Vec::new(), stats);
        }
        let size = self.params.size;
        let (x0, y0) = (tx * TILE, ty * TILE);
        let (x1, y1) = ((x0 + TILE).min(size.width), (y0 + TILE).min(size.height));
        let tw = (x1 - x0) as usize;
        let n = tw * (y1 - y0) as usize;
        let mut acc = vec![[0.0f32; 4]; n];
        let mut covered = vec![false; n];
        // Cartoon: slice index of the pixel's nearest opaque sample so far (i64::MAX = none).
        let mut best_k = vec![i64::MAX; n];
        let mut ranges = [(0u32, 0.0f32, 0.0f32); MAX_RANGES];
        // Candidates are grouped by fire (binning order). Per fire: find the samples (per
        // cell for a fire whose cells all have a certified inverse, else ray by ray), shade
        // them all (the noise in batches), then add them up per pixel.
        let mut i = 0;
        while i < cands.len() {
            let fi = cands[i].fire;
            let start = i;
            while i < cands.len() && cands[i].fire == fi {
                i += 1;
            }
            let group = &cands[start..i];
            let fire = &self.fires[fi as usize];
            scratch.pix.clear();
            scratch.k.clear();
            scratch.tex.clear();
            if self.per_cell[fi as usize] {
                self.march_cells(
                    fire,
                    group,
                    [x0, y0, x1, y1],
                    &best_k,
                    &mut covered,
                    &mut ranges,
                    avx2,
                    &mut stats,
                    scratch,
                );
            } else {
                for y in y0..y1 {
                    for x in x0..x1 {
                        let p = (y - y0) as usize * tw + (x - x0) as usize;
                        covered[p] |= self.march(
                            fire,
                            group,
                            x,
                            y,
                            best_k[p],
                            p as u16,
                            &mut ranges,
                            &mut stats,
                            scratch,
                        );
                    }
                }
            }
            if self.params.exact_inverse {
                self.shade_reference(fire, scratch);
            } else {
                self.shade_batched(fire, scratch, avx2);
            }
            let gain = self.params.intensity * self.params.slice_spacing;
            for s in 0..scratch.pix.len() {
                let p = scratch.pix[s] as usize;
                let c = scratch.col[s];
                let a = &mut acc[p];
                match self.params.blend {
                    Blend::Additive => {
                        let e = gain * c[3];
                        *a = [a[0] + c[0] * e, a[1] + c[1] * e, a[2] + c[2] * e, a[3] + e];
                    }
                    Blend::Tint(tc) => {
                        let lum = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
                        let e = gain * c[3] * lum;
                        *a = [
                            a[0] + tc[0] * e,
                            a[1] + tc[1] * e,
                            a[2] + tc[2] * e,
                            a[3] + gain * c[3],
                        ];
                    }
                    Blend::Cartoon => {
                        // the nearest opaque sample along the ray, over this fire and the
                        // earlier ones (a pixel has at most one sample per slice and fire;
                        // the march already dropped samples behind an earlier fire's hit)
                        if c[3] >= 0.5 && scratch.k[s] < best_k[p] {
                            best_k[p] = scratch.k[s];
                            *a = [c[0], c[1], c[2], 1.0];
                        }
                    }
                }
            }
        }
        if self.params.count_coverage {
            stats.covered_pixels += covered.iter().filter(|&&c| c).count() as u64;
        }
        for a in &mut acc {
            a[3] = a[3].min(1.0);
        }
        (acc, stats)
    }

    /// Marches pixel `(x, y)`'s ray through one fire's candidate cells and appends its
    /// samples inside the unit cylinder (texture coordinates) to `out`; samples at slice
    /// index `best_k` or beyond are skipped. Returns whether any sample was inside a cell.
    #[inline(always)]
    fn march(
        &self,
        fire: &FireInstance,
        group: &[Cand],
        x: u32,
        y: u32,
        best_k: i64,
        pix: u16,
        ranges: &mut [(u32, f32, f32); MAX_RANGES],
        stats: &mut RenderStats,
        out: &mut Scratch,
    ) -> bool {
        let Some(mut ray) = self.ray(group, x, y, best_k, pix, ranges, true) else {
            return false;
        };
        ray.tol = local_tol(fire, INVERSE_TEX_TOL);
        // the slices that may be visible, then (when counting coverage) the others only
        // until one sample is known to lie inside a cell (their alpha is zero)
        let (k0, k1) = (ray.k, ray.k1);
        let (v0, v1) = ray.visible;
        let rest = if v0 <= v1 {
            ray.k1 = v1;
            ray.k = v0;
            while ray.k <= ray.k1 {
                self.sample(fire, &mut ray, stats, out);
            }
            [(k0, v0 - 1), (v1 + 1, k1)]
        } else {
            [(k0, k1), (1, 0)]
        };
        if !self.params.count_coverage {
            return ray.covered;
        }
        for (a, b) in rest {
            (ray.k, ray.k1, ray.tracking) = (a, b, false);
            while !ray.covered && ray.k <= ray.k1 {
                self.sample(fire, &mut ray, stats, out);
            }
        }
        ray.covered
    }

    /// Pixel `(x, y)`'s centre on the image plane at unit distance: the ray through it has
    /// direction `forward + sx · right + sy · up`.
    #[inline(always)]
    fn screen(&self, x: u32, y: u32) -> [f32; 2] {
        let size = self.params.size;
        [
            ((x as f32 + 0.5) / size.width as f32 * 2.0 - 1.0) * self.tan * self.aspect,
            (1.0 - (y as f32 + 0.5) / size.height as f32 * 2.0) * self.tan,
        ]
    }

    /// Finds one fire's samples in tile `[x0, y0, x1, y1)` cell by cell, for a lattice
    /// that passes [`per_cell_ok`] (the fast path's common case).
    ///
    /// A pixel's ray is `o + z D` with `D · forward = 1`, so slice `k` is at `z = k ·
    /// spacing`. Per candidate cell and pixel, the slices within the part of the cell that
    /// can be visible (the affine disc and the visible box of [`visible_parts`], both with
    /// [`OWNER_SLACK`]) become candidate samples; they are inverted [`CHORD_LANES`] at a
    /// time with the cell's certified chord inverse
    /// ([`crate::lattice::Cell::inverse_certified_lanes`]; Newton's method for the rare
    /// lane it does not certify), and a sample is kept if it lies in the cell by
    /// [`Ctx::owns`] — exactly one cell claims a sample near a shared face. Samples
    /// behind a pixel's `best_k` are skipped. With [`RenderParams::count_coverage`], a
    /// pixel that gave no sample is then marched ray by ray ([`Ctx::cover`]) until one
    /// sample is known to lie in a cell, to count it as covered (those samples are not
    /// visible and are not kept).
    #[inline(always)]
    fn march_cells(
        &self,
        fire: &FireInstance,
        group: &[Cand],
        [x0, y0, x1, y1]: [u32; 4],
        best_k: &[i64],
        covered: &mut [bool],
        ranges: &mut [(u32, f32, f32); MAX_RANGES],
        avx2: bool,
        stats: &mut RenderStats,
        out: &mut Scratch,
    ) {
        let tw = (x1 - x0) as usize;
        let n = tw * (y1 - y0) as usize;
        out.dirs.clear();
        out.invs.clear();
        for y in y0..y1 {
            for x in x0..x1 {
                let [sx, sy] = self.screen(x, y);
                let d = add(self.fw, add(scale(self.rt, sx), scale(self.up, sy)));
                out.dirs.push(d);
                out.invs.push([1.0 / d[0], 1.0 / d[1], 1.0 / d[2]]);
            }
        }
        out.hit.clear();
        out.hit.resize(n, false);
        let o = self.camera.position;
        let spacing = self.params.slice_spacing;
        let tol = local_tol(fire, CELL_TEX_TOL);
        for cand in group {
            let (cx0, cx1) = (cand.px[0].max(x0 as i32), cand.px[1].min(x1 as i32 - 1));
            let (cy0, cy1) = (cand.px[2].max(y0 as i32), cand.px[3].min(y1 as i32 - 1));
            if cand.vmin[0] > cand.vmax[0] {
                continue; // nothing of this cell can be visible
            }
            let j = cand.cell as usize;
            let mut batch = Batch::default();
            for y in cy0..cy1 + 1 {
                // the row's pixels that can meet the disc's cylinder (with a pixel to spare)
                let (rx0, rx1) = match &cand.disc {
                    Some(disc) => {
                        let Some((lo, hi)) =
                            disc.row_span(self.fw, self.rt, self.up, self.screen(0, y as u32)[1])
                        else {
                            continue;
                        };
                        let px = |sx: f64| {
                            (sx / (self.tan * self.aspect) as f64 + 1.0)
                                * 0.5
                                * self.params.size.width as f64
                                - 0.5
                        };
                        let lim = |v: f64| v.clamp(cx0 as f64 - 1.0, cx1 as f64 + 1.0) as i32;
                        (
                            cx0.max(lim(px(lo).floor() - 1.0)),
                            cx1.min(lim(px(hi).ceil() + 1.0)),
                        )
                    }
                    None => (cx0, cx1),
                };
                // The part of the cell that can be visible is convex, so the pixels of a
                // row whose rays meet it are consecutive: after the first miss that follows
                // a hit the row is done.
                let mut met = false;
                for x in rx0..rx1 + 1 {
                    let p = (y as u32 - y0) as usize * tw + (x as u32 - x0) as usize;
                    let (d, inv) = (out.dirs[p], out.invs[p]);
                    let Some((b0, b1)) = slab(inv, cand.vmin, cand.vmax) else {
                        if met {
                            break;
                        }
                        continue;
                    };
                    let (z0, z1) = match &cand.disc {
                        Some(disc) => match disc.interval(d) {
                            Some((t0, t1)) => (t0.max(b0), t1.min(b1)),
                            None => {
                                if met {
                                    break;
                                }
                                continue;
                            }
                        },
                        None => (b0, b1),
                    };
                    met = true;
                    let ka = (z0 / spacing).ceil() as i64;
                    let kb = ((z1 / spacing).floor() as i64).min(best_k[p].saturating_sub(1));
                    // (`kb < i64::MAX`: it is at most `best_k − 1`)
                    for k in ka..kb + 1 {
                        let z = k as f32 * spacing;
                        let l = batch.n;
                        for a in 0..3 {
                            batch.p[a][l] = o[a] + z * d[a];
                        }
                        batch.pix[l] = p as u16;
                        batch.k[l] = k;
                        batch.n += 1;
                        if batch.n == CHORD_LANES {
                            self.claim(fire, j, &batch, tol, avx2, stats, out);
                            batch.n = 0;
                        }
                    }
                }
            }
            if batch.n > 0 {
                // the unused lanes repeat a real point (their results are ignored)
                for l in batch.n..CHORD_LANES {
                    for a in 0..3 {
                        batch.p[a][l] = batch.p[a][0];
                    }
                }
                self.claim(fire, j, &batch, tol, avx2, stats, out);
            }
        }
        // coverage of the pixels without a sample, ray by ray
        for p in 0..n {
            if out.hit[p] {
                covered[p] = true;
            } else if self.params.count_coverage && !covered[p] {
                let (x, y) = (x0 + (p % tw) as u32, y0 + (p / tw) as u32);
                covered[p] = self.cover(fire, group, x, y, best_k[p], ranges, stats, out);
            }
        }
    }

    /// Inverts a batch of candidate samples of cell `j` ([`Ctx::march_cells`]) and keeps
    /// those the cell claims ([`Ctx::owns`]) and that lie in the unit cylinder.
    #[inline(always)]
    fn claim(
        &self,
        fire: &FireInstance,
        j: usize,
        batch: &Batch,
        tol: V3,
        avx2: bool,
        stats: &mut RenderStats,
        out: &mut Scratch,
    ) {
        let cell = &fire.lattice.cells()[j];
        #[cfg(target_arch = "x86_64")]
        let (ls, ok) = if avx2 {
            // SAFETY: `avx2` is true only in the AVX2 build on CPUs with AVX2 (`Ctx::tile`).
            unsafe { cell.inverse_certified_lanes_avx2(&batch.p, tol) }
        } else {
            cell.inverse_certified_lanes(&batch.p, tol)
        };
        #[cfg(not(target_arch = "x86_64"))]
        let (ls, ok) = cell.inverse_certified_lanes(&batch.p, tol);
        // The common case for all lanes at once (straight-line code over the lanes): a
        // certified lane inside the cell's sides and clear of its end faces by the band of
        // `Ctx::owns` (which then answers `true` without computing anything more).
        let last = fire.lattice.cells().len() - 1;
        let band = 0.5 * OWNER_SLACK * tol[2];
        let s_lo = if j == 0 { 0.0 } else { band };
        let s_hi = if j == last { 1.0 } else { 1.0 - band };
        let mut clear = [false; CHORD_LANES];
        let mut tex = [[0.0f32; 3]; CHORD_LANES];
        let mut inside = [false; CHORD_LANES];
        for l in 0..CHORD_LANES {
            let lv = [ls[0][l], ls[1][l], ls[2][l]];
            clear[l] = ok[l]
                & (lv[0] >= 0.0)
                & (lv[0] <= 1.0)
                & (lv[1] >= 0.0)
                & (lv[1] <= 1.0)
                & (lv[2] >= s_lo)
                & (lv[2] <= s_hi);
            tex[l] = fire.lattice.tex_of(j, lv);
            inside[l] = in_unit_cylinder(tex[l]);
        }
        let (mut pix, mut ks, mut texs) = (
            [0u16; CHORD_LANES],
            [0i64; CHORD_LANES],
            [[0.0f32; 3]; CHORD_LANES],
        );
        let (mut kept, mut samples) = (0, 0);
        for l in 0..batch.n {
            let (t, lit) = if clear[l] {
                (tex[l], inside[l])
            } else {
                // the rest: an uncertified lane (Newton's method), or near an end face
                let pt = [batch.p[0][l], batch.p[1][l], batch.p[2][l]];
                let lv = if ok[l] {
                    [ls[0][l], ls[1][l], ls[2][l]]
                } else {
                    match cell.inverse(pt, cell.chord_guess(pt)) {
                        Some(lv) => lv,
                        None => continue,
                    }
                };
                let lateral = (0.0..=1.0).contains(&lv[0]) && (0.0..=1.0).contains(&lv[1]);
                if !(lateral && self.owns(fire, j, lv[2], pt, tol)) {
                    continue;
                }
                let t = fire.lattice.tex_of(j, lv);
                (t, in_unit_cylinder(t))
            };
            out.hit[batch.pix[l] as usize] = true;
            samples += 1;
            if lit {
                pix[kept] = batch.pix[l];
                ks[kept] = batch.k[l];
                texs[kept] = t;
                kept += 1;
            }
        }
        stats.samples += samples;
        stats.shaded += kept as u64;
        out.pix.extend_from_slice(&pix[..kept]);
        out.k.extend_from_slice(&ks[..kept]);
        out.tex.extend_from_slice(&texs[..kept]);
    }

    /// Whether cell `j` of `fire` holds the sample at `p` with (certified or Newton)
    /// local height `s`, as far as its end faces go: `0 ≤ s` at the bottom of the lattice
    /// and `s ≤ 1` at its top; between cells `j` and `j + 1` the face is decided by cell
    /// `j + 1`'s canonical inverse ([`canonical_s`]`(j + 1, p) ≥ 0` means above), the same
    /// computation whichever cell asks, so no sample is claimed twice or dropped.
    ///
    /// Away from a face, `s` settles it: both inverses are within `tol[2]` of the exact
    /// ones (the certificate), the exact heights of the two cells have opposite signs
    /// about the face and scale by the ratio of the cells' thicknesses there (within 2×,
    /// [`per_cell_ok`]), so `s ≤ 1 − 4 tol` in cell `j` implies the canonical
    /// `s_{j+1} < 0` (and `s ≥ 4 tol` in cell `j + 1` implies `s_j > 1` for the
    /// canonical-by-`j + 1` rule); only within that band is [`canonical_s`] computed.
    /// A claimed sample has an exact `s` in `[−tol, 1 + 2 tol]`, inside the parts of the
    /// cell marched ([`OWNER_SLACK`]).
    #[inline(always)]
    fn owns(&self, fire: &FireInstance, j: usize, s: f32, p: V3, tol: V3) -> bool {
        let last = fire.lattice.cells().len() - 1;
        let band = 0.5 * OWNER_SLACK * tol[2];
        let above_bottom = if j == 0 {
            s >= 0.0
        } else if s >= band {
            true
        } else if s < -band {
            false
        } else {
            canonical_s(fire, j, p, tol) >= 0.0
        };
        let below_top = if j == last {
            s <= 1.0
        } else if s <= 1.0 - band {
            true
        } else if s > 1.0 + band {
            false
        } else {
            canonical_s(fire, j + 1, p, tol) < 0.0
        };
        above_bottom && below_top
    }

    /// Marches pixel `(x, y)`'s ray through one fire's cells only until a sample is
    /// known to lie inside a cell (then the pixel is covered); keeps no sample.
    #[inline(always)]
    fn cover(
        &self,
        fire: &FireInstance,
        group: &[Cand],
        x: u32,
        y: u32,
        best_k: i64,
        ranges: &mut [(u32, f32, f32); MAX_RANGES],
        stats: &mut RenderStats,
        out: &mut Scratch,
    ) -> bool {
        let Some(mut ray) = self.ray(group, x, y, best_k, 0, ranges, false) else {
            return false;
        };
        ray.tol = local_tol(fire, INVERSE_TEX_TOL);
        let n0 = out.pix.len();
        while !ray.covered && ray.k <= ray.k1 {
            self.sample(fire, &mut ray, stats, out);
        }
        stats.shaded -= (out.pix.len() - n0) as u64;
        out.pix.truncate(n0);
        out.k.truncate(n0);
        out.tex.truncate(n0);
        ray.covered
    }

    /// Sets up pixel `(x, y)`'s ray: direction, the candidate cells it meets (with their
    /// ray intervals, kept in `ranges`), its slice range and, `with_visible`, the slices
    /// that may be visible (else none); `None` if it meets no cell.
    #[inline(always)]
    fn ray<'r>(
        &self,
        group: &[Cand],
        x: u32,
        y: u32,
        best_k: i64,
        pix: u16,
        ranges: &'r mut [(u32, f32, f32); MAX_RANGES],
        with_visible: bool,
    ) -> Option<Ray<'r>> {
        let [sx, sy] = self.screen(x, y);
        let d =
            normalize(add(self.fw, add(scale(self.rt, sx), scale(self.up, sy)))).unwrap_or(self.fw);
        let o = self.camera.position;
        let cosf = dot(d, self.fw);
        let inv = [1.0 / d[0], 1.0 / d[1], 1.0 / d[2]];
        let spacing = self.params.slice_spacing;
        // March the union of the cells' ray intervals front to back and walk from cell to
        // cell with the local `s`.
        let mut nr = 0;
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        let (xi, yi) = (x as i32, y as i32);
        let (mut vlo, mut vhi) = (f32::INFINITY, f32::NEG_INFINITY);
        for cell in group {
            if xi < cell.px[0] || xi > cell.px[1] || yi < cell.px[2] || yi > cell.px[3] {
                continue;
            }
            let Some((t0, t1)) = slab(inv, cell.min, cell.max) else {
                continue;
            };
            lo = lo.min(t0);
            hi = hi.max(t1);
            if nr < ranges.len() {
                ranges[nr] = (cell.cell, t0, t1);
                nr += 1;
            }
            if !with_visible || cell.vmin[0] > cell.vmax[0] {
                continue; // not asked for, or nothing of this cell can be visible
            }
            let part = match &cell.disc {
                Some(disc) => disc.interval(d),
                None => slab(inv, cell.vmin, cell.vmax),
            };
            if let Some((t0, t1)) = part {
                vlo = vlo.min(t0);
                vhi = vhi.max(t1);
            }
        }
        if nr == 0 {
            return None;
        }
        let k0 = (lo * cosf / spacing).ceil() as i64;
        let k1 = ((hi * cosf / spacing).floor() as i64).min(best_k.saturating_sub(1));
        let visible = if vlo <= vhi {
            (
                ((vlo * cosf / spacing).ceil() as i64).max(k0),
                ((vhi * cosf / spacing).floor() as i64).min(k1),
            )
        } else {
            (1, 0)
        };
        Some(Ray {
            o,
            d,
            cosf,
            ranges: &ranges[..nr],
            k: k0,
            k1,
            visible,
            pix,
            covered: false,
            tracking: false,
            g: [0.5; 3],
            dg: None,
            m: Track::default(),
            tol: [0.0; 3],
        })
    }

    /// Takes ray `r`'s next sample (slice `r.k`) and advances it: finds the sample's cell
    /// and local coordinates and appends it to `out` if it lies inside the unit cylinder.
    #[inline(always)]
    fn sample(&self, fire: &FireInstance, r: &mut Ray, stats: &mut RenderStats, out: &mut Scratch) {
        let k = r.k;
        r.k += 1;
        let exact = self.params.exact_inverse;
        let cells = fire.lattice.cells();
        let last = cells.len() - 1;
        let t = k as f32 * self.params.slice_spacing / r.cosf;
        let p = add(r.o, scale(r.d, t));
        let (mut j, mut guess) = if r.tracking {
            let pred = match r.dg {
                Some(dl) => add(r.g, dl),
                None => r.g,
            };
            let lv = pred[2].clamp(0.0, cells.len() as f32);
            let j = (lv as usize).min(last);
            (j, [pred[0], pred[1], lv - j as f32])
        } else {
            match r.ranges.iter().find(|q| q.1 <= t && t <= q.2) {
                Some(q) => {
                    r.dg = None;
                    let j = q.0 as usize;
                    // the reference path keeps its original start (GPU parity)
                    if exact {
                        (j, [0.5; 3])
                    } else {
                        // the chord step from the centre, moving to the neighbouring cell
                        // while it says the point lies there (nearly affine cells: the
                        // step is accurate, so this saves a failed solve)
                        let mut j = j;
                        let mut q = cells[j].chord_guess(p);
                        for _ in 0..4 {
                            let hop = q[2].floor();
                            if !((hop < 0.0 && j > 0) || (hop >= 1.0 && j < last)) {
                                break;
                            }
                            j = (j as i64 + hop as i64).clamp(0, last as i64) as usize;
                            q = cells[j].chord_guess(p);
                        }
                        (j, [q[0], q[1], q[2].clamp(-0.5, 1.5)])
                    }
                }
                None => return,
            }
        };
        let tol = r.tol;
        let mut found = None;
        for _ in 0..6 {
            let l = if exact {
                cells[j].inverse_fast(p, guess)
            } else {
                match cells[j].inverse_certified(p, guess, tol) {
                    Ok(l) => Some(l),
                    // beyond an end of the lattice: outside whatever the exact inverse
                    Err(Some(l)) if (j == 0 && l[2] < 0.0) || (j == last && l[2] > 1.0) => Some(l),
                    Err(_) => cells[j].inverse_tracked(p, guess, &mut r.m),
                }
            };
            let Some(l) = l else {
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
            r.tracking = false;
            return;
        };
        let ng = [l[0], l[1], j as f32 + l[2]];
        r.dg = if r.tracking {
            Some(sub(ng, r.g))
        } else if exact {
            None
        } else {
            // no previous sample yet: the ray's step mapped by the inverse Jacobian at the
            // cell centre (the affine part of the map), a first-order prediction
            Some(cells[j].local_direction(scale(r.d, self.params.slice_spacing / r.cosf)))
        };
        r.g = ng;
        r.tracking = true;
        if !(l[0] >= 0.0 && l[0] <= 1.0 && l[1] >= 0.0 && l[1] <= 1.0 && l[2] >= 0.0 && l[2] <= 1.0)
        {
            return;
        }
        r.covered = true;
        stats.samples += 1;
        let tex = fire.lattice.tex_of(j, l);
        if !in_unit_cylinder(tex) {
            return;
        }
        stats.shaded += 1;
        out.pix.push(r.pix);
        out.k.push(k);
        out.tex.push(tex);
    }

    /// Shades every collected sample with [`shade`], one by one: the reference.
    fn shade_reference(&self, fire: &FireInstance, s: &mut Scratch) {
        let time = self.time * fire.noise.time_scale;
        let mix = self.params.mix(&fire.noise, self.time);
        s.col.clear();
        s.col.extend(s.tex.iter().map(|&tex| {
            let (radius, length) = (fire.lattice.radius_at(tex[2]), fire.lattice.length());
            let Some(m) = mix else {
                return shade(
                    tex,
                    radius,
                    length,
                    time,
                    &fire.noise,
                    fire.offset,
                    fire.profile,
                );
            };
            shade_looped(
                tex,
                radius,
                length,
                m,
                &fire.noise,
                fire.offset,
                fire.profile,
            )
        }));
    }

    /// Shades every collected sample exactly as [`shade`] does, but with the turbulence
    /// evaluated [`LANES`] samples at a time and only while it can still matter.
    ///
    /// The turbulence only moves the profile look-up vertically: `v = tex_z + f(tex_z)·t`
    /// (eq. 12–13). With `|noise| ≤ B` ([`NoiseKind::bound`], proven), the octaves not yet
    /// added change `t` by at most `B · Σ |gain|^i` over them. So before the first octave
    /// and after each one, a sample whose possible `v` range misses the profile column's
    /// visible range ([`FireProfile::v_support`]) is certain to get zero alpha — and a
    /// zero-alpha sample adds exactly nothing to any blend — so its remaining octaves are
    /// skipped. Samples that stay in play get the same turbulence value as the scalar
    /// [`crate::noise::turbulence`] (same operations, same order), hence the same colour.
    ///
    /// `avx2`: the CPU has AVX2 (only passed as `true` from the AVX2 build of the tile
    /// renderer); the noise then runs [`crate::noise::avx2`], which gives the same values.
    #[inline(always)]
    fn shade_batched(&self, fire: &FireInstance, s: &mut Scratch, avx2: bool) {
        let noise = &fire.noise;
        let n = s.tex.len();
        s.col.clear();
        s.col.resize(n, [0.0; 4]);
        if noise.octaves == 0 || noise.stability == 0.0 {
            // no turbulence: nothing to batch
            for (c, &tex) in s.col.iter_mut().zip(&s.tex) {
                let [u, v] = profile_uv(tex, 0.0, noise.stability);
                *c = if fire.profile.column_empty(u) {
                    [0.0; 4]
                } else {
                    fire.profile.sample(u, v)
                };
            }
            return;
        }
        let mix = self.params.mix(noise, self.time);
        // the first copy's noise time; a loop's second copy is a whole loop behind, and
        // the pair's turbulence `a·sum + b·sum2` is bounded by `(a + b)` times one's
        let (time, time2, wa, wb) = match mix {
            Some(m) => (m.time, m.time - m.period, m.a, m.b),
            None => (self.time * noise.time_scale, 0.0, 1.0, 0.0),
        };
        // a loop's second copy costs nothing while its weight is zero (`a = 1` exactly)
        let looped = mix.is_some_and(|m| m.b != 0.0);
        let turb = |a: &Live| {
            if looped {
                wa * a.sum + wb * a.sum2
            } else {
                a.sum
            }
        };
        let length = fire.lattice.length();
        let profile = fire.profile;
        let octaves = noise.octaves as usize;
        let mut rem = turbulence_bounds(noise);
        if looped {
            rem = rem.map(|r| r * (wa + wb));
        }
        let uniform = fire.lattice.uniform_radius();
        // the `w` of every sample's noise position (it depends on neither `tex` nor the
        // radius)
        let wscale = noise_scale(1.0, length, noise.frequency);
        let pw = noise_position([0.0; 3], time, wscale, fire.offset)[3];
        let pw2 = noise_position([0.0; 3], time2, wscale, fire.offset)[3];
        slice_order(&s.k, &mut s.buckets, &mut s.order);
        let act = &mut s.act;
        act.clear();
        for &i in &s.order {
            let tex = s.tex[i as usize];
            let u = radial_u(tex);
            let Some([lo, hi]) = profile.v_support(u) else {
                continue; // empty column: transparent whatever the noise
            };
            let z = tex[2];
            let kern = kernel(z, noise.stability);
            let win = Window::new(z, kern, [lo, hi], rem[0]);
            if !win.reachable(kern, 0.0, rem[0]) {
                continue;
            }
            let radius = uniform.unwrap_or_else(|| fire.lattice.radius_at(z));
            let scale = noise_scale(radius, length, noise.frequency);
            let [px, py, pz, _] = noise_position(tex, time, scale, fire.offset);
            let pz2 = if looped {
                noise_position(tex, time2, scale, fire.offset)[2]
            } else {
                0.0
            };
            act.push(Live {
                idx: i,
                p: [px, py, pz],
                sum: 0.0,
                pz2,
                sum2: 0.0,
                u,
                z,
                kern,
                win,
            });
        }
        // turbulence (eq. 9), octave by octave, as `turbulence` computes it
        let mut amp = 1.0f32;
        let mut f = 1.0f32;
        for o in 0..octaves {
            for batch in act.chunks_mut(LANES) {
                let mut q = [[pw * f; LANES]; 4];
                for (l, live) in batch.iter().enumerate() {
                    for (qa, pa) in q.iter_mut().zip(live.p) {
                        qa[l] = pa * f;
                    }
                }
                let val = lanes_noise(noise.kind, &q, &mut s.noise_cache, avx2);
                for (live, v) in batch.iter_mut().zip(val) {
                    live.sum += amp * v;
                }
                if looped {
                    q[3] = [pw2 * f; LANES];
                    for (l, live) in batch.iter().enumerate() {
                        q[2][l] = live.pz2 * f;
                    }
                    let val = lanes_noise(noise.kind, &q, &mut s.noise_cache, avx2);
                    for (live, v) in batch.iter_mut().zip(val) {
                        live.sum2 += amp * v;
                    }
                }
            }
            amp *= noise.gain;
            f *= noise.lacunarity;
            if o + 1 < octaves {
                let r = rem[o + 1];
                act.retain(|a| a.win.reachable(a.kern, turb(a), r));
            }
        }
        for live in act.iter() {
            // `profile_uv` of the sample, from the values computed above
            let v = live.z + live.kern * turb(live);
            s.col[live.idx as usize] = profile.sample(live.u, v);
        }
    }
}

/// `radial_u(tex) ≤ 1` (or NaN) without waiting for the square root: a correctly rounded
/// `sqrt(q)` exceeds 1 exactly when `q ≥ 1 + 2⁻²²`, i.e. `q > 1 + 2⁻²³`.
#[inline(always)]
fn in_unit_cylinder(tex: V3) -> bool {
    let q = tex[0] * tex[0] + tex[1] * tex[1];
    q.is_nan() || q <= 1.0 + f32::EPSILON
}

/// A texture-space tolerance as per-component local-coordinate tolerances of `fire`'s
/// cells (`tex_x = 2a − 1`, `tex_z = (j + s) / cells`).
fn local_tol(fire: &FireInstance, tex_tol: f32) -> V3 {
    let cells = fire.lattice.cells().len() as f32;
    [0.5 * tex_tol, 0.5 * tex_tol, cells * tex_tol]
}

/// Cell `j`'s local height `s` of `p` as [`Ctx::owns`] decides faces with: the certified
/// chord inverse from the centre, else Newton's method from the chord guess, else
/// `−∞` (then `p` counts as below the face). A pure function of `(j, p)`.
fn canonical_s(fire: &FireInstance, j: usize, p: V3, tol: V3) -> f32 {
    let c = &fire.lattice.cells()[j];
    c.inverse_chord_certified(p, tol)
        .or_else(|| c.inverse(p, c.chord_guess(p)))
        .map_or(f32::NEG_INFINITY, |l| l[2])
}

/// One octave of noise on [`LANES`] points, with the AVX2 build when `avx2` (the caller
/// guarantees the CPU has it); the same values either way.
#[inline(always)]
fn lanes_noise(
    kind: crate::noise::NoiseKind,
    q: &[[f32; LANES]; 4],
    cache: &mut NoiseCache,
    avx2: bool,
) -> [f32; LANES] {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` is true only on CPUs with AVX2 (see `Ctx::tile`).
        return unsafe { crate::noise::avx2::eval_lanes_cached(kind, q, cache) };
    }
    let _ = avx2;
    kind.eval_lanes_cached(q, cache)
}

/// Orders sample indices by slice index `k` (stable, so by pixel within a slice): a
/// counting sort. Neighbouring pixels' samples on one slice are close in noise space, so
/// consecutive samples then mostly share their noise cell, which the lanes noise exploits.
/// Falls back to march order when the slices span an unusually wide range.
fn slice_order(k: &[i64], buckets: &mut Vec<u32>, order: &mut Vec<u32>) {
    order.clear();
    if k.is_empty() {
        return;
    }
    let (lo, hi) = k
        .iter()
        .fold((i64::MAX, i64::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    let span = (hi - lo) as usize + 1;
    if span > 1 << 16 {
        order.extend(0..k.len() as u32);
        return;
    }
    buckets.clear();
    buckets.resize(span + 1, 0);
    for &v in k {
        buckets[(v - lo) as usize + 1] += 1;
    }
    for b in 1..=span {
        buckets[b] += buckets[b - 1];
    }
    order.resize(k.len(), 0);
    for (i, &v) in k.iter().enumerate() {
        let slot = &mut buckets[(v - lo) as usize];
        order[*slot as usize] = i as u32;
        *slot += 1;
    }
}

/// The post pipeline: bloom on the premultiplied HDR frame (skipped when
/// `bloom.passes == 0`), then conversion to straight alpha with
/// `a' = clamp(max(a, max(r, g, b)), 0, 1)` and `rgb' = rgb / a'` — so compositing the
/// result "over" a background adds the fire's light to it where it is faint.
pub fn finish(premultiplied: &RgbaFrame, bloom: &BloomParams) -> Result<RgbaFrame> {
    let straight = |p: &[f32; 4]| {
        let a = p[3].max(p[0]).max(p[1]).max(p[2]).clamp(0.0, 1.0);
        if a > 0.0 {
            [p[0] / a, p[1] / a, p[2] / a, a]
        } else {
            [0.0; 4]
        }
    };
    const CHUNK: usize = 4096;
    if bloom.passes > 0 {
        let mut f = bloom_rgba(premultiplied, bloom)?;
        f.data_mut()
            .par_chunks_mut(CHUNK)
            .for_each(|c| c.iter_mut().for_each(|p| *p = straight(p)));
        Ok(f)
    } else {
        let data = premultiplied
            .data()
            .par_iter()
            .with_min_len(CHUNK)
            .map(straight)
            .collect();
        Ok(RgbaFrame::from_vec(premultiplied.size(), data)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{BSpline, FireScene, NoiseKind, Preset};

    /// Renders the first frame of `scene` (all fires) with and without `exact_inverse`.
    fn fast_and_exact(
        scene: &FireScene,
        time: f32,
        loop_period: Option<f32>,
    ) -> [(RgbaFrame, RenderStats); 2] {
        let mut anim = scene.animator().unwrap();
        let (pts, _) = anim.step();
        let lats: Vec<Lattice> = pts
            .iter()
            .zip(&scene.fires)
            .map(|(p, f)| {
                Lattice::build(&BSpline::new(p.clone(), f.degree).unwrap(), scene.lattice).unwrap()
            })
            .collect();
        let inst: Vec<FireInstance> = lats
            .iter()
            .zip(&scene.fires)
            .enumerate()
            .map(|(i, (lat, f))| FireInstance {
                lattice: lat,
                profile: &f.profile,
                noise: f.noise,
                offset: scene.offset(i),
            })
            .collect();
        let mut params = scene.render_params();
        params.loop_period = loop_period;
        assert!(!params.exact_inverse);
        params.count_coverage = true;
        let fast = render(&inst, &scene.camera, &params, time).unwrap();
        params.exact_inverse = true;
        let exact = render(&inst, &scene.camera, &params, time).unwrap();
        [fast, exact]
    }

    fn max_difference(a: &RgbaFrame, b: &RgbaFrame) -> (f32, f32) {
        let mut worst = 0.0f32;
        let mut peak = 0.0f32;
        for (a, b) in a.data().iter().zip(b.data()) {
            for k in 0..4 {
                worst = worst.max((a[k] - b[k]).abs());
                peak = peak.max(b[k].abs());
            }
        }
        (worst, peak)
    }

    /// The fast path (predicted Newton / chord inverse, batched noise, octave skipping)
    /// against the reference path (`exact_inverse`: chord-then-Newton from the cell centre
    /// to 1e-5, every sample shaded by the scalar `shade`). The shading is identical for
    /// identical samples (see `batched_shading_equals_scalar_shading`), so what remains is
    /// the inverse's accuracy (the certified inverse's texture coordinates are within
    /// [`INVERSE_TEX_TOL`] of the exact ones): measured ≤ 6e-5 per channel against
    /// peaks ≥ 1 (Table 1 scenes, lattice 35 and 135, all noises, cartoon blend, two bent
    /// presets; 7.2e-5 of the peak on the brightly exposed torch); the limit is 1e-4 of the
    /// peak (at least 1), just above, so a regression shows.
    #[test]
    fn fast_path_matches_exact_within_tolerance() {
        let small = Size::new(96, 72).unwrap();
        let mut scenes = Vec::new();
        for lattice in [35usize, 135] {
            for (kind, octaves) in [(NoiseKind::Perlin3, 2), (NoiseKind::Perlin4, 3)] {
                scenes.push(FireScene::table1(kind, octaves, lattice).with_size(small));
            }
        }
        let mut mn = FireScene::table1(NoiseKind::Mnoise, 1, 35).with_size(small);
        mn.blend = Blend::Cartoon;
        scenes.push(mn);
        for p in [Preset::Campfire, Preset::Torch] {
            // the bent lattices with moderate noise: the presets' own detailed noise turns
            // the same texture-coordinate error into up to 3e-4 of the peak
            let mut s = FireScene::preset(p).with_size(Size::new(64, 64).unwrap());
            s.fires.iter_mut().for_each(|f| f.noise.stability = 0.45);
            scenes.push(s);
        }
        // the Table 1 lattices take the per-cell march
        for lattice in [35usize, 135] {
            let scene = FireScene::table1(NoiseKind::Perlin4, 3, lattice);
            let mut anim = scene.animator().unwrap();
            let (pts, _) = anim.step();
            let lat = Lattice::build(&BSpline::new(pts[0].clone(), 3).unwrap(), lattice).unwrap();
            assert!(per_cell_ok(&lat), "lattice {lattice}");
        }
        // and every scene looping (two noise copies mixed) at a time near the mix's middle
        let runs = scenes
            .iter()
            .map(|s| (s, None))
            .chain(scenes.iter().map(|s| (s, Some(1.3f32))));
        for (i, (scene, loop_period)) in runs.enumerate() {
            let [(fast, sf), (exact, se)] = fast_and_exact(scene, 0.5, loop_period);
            assert!(se.covered_pixels > 200, "scene {i}: {se:?}");
            let (worst, peak) = max_difference(&fast, &exact);
            println!("scene {i}: max difference {worst:.2e}, peak {peak:.3}");
            assert!(peak > 0.1, "scene {i}: peak {peak}");
            // relative to the peak: exposure scales the inverse's error with the image
            assert!(
                worst < 1e-4 * peak.max(1.0),
                "scene {i}: max difference {worst} (peak {peak})"
            );
            let dc = sf.covered_pixels.abs_diff(se.covered_pixels);
            assert!(dc * 100 <= se.covered_pixels, "scene {i}: {sf:?} vs {se:?}");
        }
    }

    /// The per-cell march gives every sample to exactly one cell, also where a pixel
    /// row's samples lie on the faces between cells: a straight upright fire with levels
    /// every 0.1 and a horizontal camera ray at a level's height (the middle row of an odd
    /// image), against the ray-by-ray reference. A sample counted twice or dropped would
    /// change its pixel by about `intensity · spacing · alpha` (≥ 1e-2 here).
    #[test]
    fn per_cell_march_claims_samples_on_faces_once() {
        use crate::{FireSpec, Motion};
        for (lattice, kind) in [(31usize, NoiseKind::Perlin4), (121, NoiseKind::Perlin3)] {
            let mut scene =
                FireScene::table1(kind, 2, lattice).with_size(Size::new(75, 61).unwrap());
            scene.fires[0] = FireSpec {
                noise: scene.fires[0].noise,
                ..FireSpec::new(Motion::Static(vec![
                    [0.0, 0.0, 0.0, 1.0],
                    [0.0, 0.0, 1.0, 1.0],
                    [0.0, 0.0, 2.0, 1.0],
                    [0.0, 0.0, 3.0, 1.0],
                ]))
            };
            scene.camera = Camera {
                position: [0.0, -7.0, 1.5],
                target: [0.0, 0.0, 1.5],
                fov: 40.0,
            };
            let mut anim = scene.animator().unwrap();
            let (pts, _) = anim.step();
            let lat = Lattice::build(&BSpline::new(pts[0].clone(), 3).unwrap(), lattice).unwrap();
            assert!(per_cell_ok(&lat));
            let [(fast, sf), (exact, se)] = fast_and_exact(&scene, 0.3, None);
            let (worst, peak) = max_difference(&fast, &exact);
            assert!(peak > 0.1 && se.shaded > 1000, "{se:?}");
            assert!(worst < 1e-4, "lattice {lattice}: max difference {worst}");
            // the middle row (on a face) has samples, and the same number as the reference
            let row = |f: &RgbaFrame| f.data()[30 * 75..31 * 75].iter().map(|p| p[3]).sum::<f32>();
            assert!(row(&exact) > 1.0);
            assert!((row(&fast) - row(&exact)).abs() < 1e-3);
            assert!(sf.covered_pixels.abs_diff(se.covered_pixels) * 100 <= se.covered_pixels);
        }
    }

    /// The square-root-free cylinder test (`in_unit_cylinder`) agrees with
    /// `radial_u(tex) ≤ 1`.
    #[test]
    fn squared_radius_test_matches_radial_u() {
        let mut q = 0.999_f32;
        while q < 1.001 {
            let tex = [q.sqrt(), 0.0, 0.5];
            let exact = radial_u([tex[0], tex[1], 0.0]) > 1.0;
            let fast = !in_unit_cylinder(tex);
            assert_eq!(exact, fast, "{q}");
            q = f32::from_bits(q.to_bits() + 1);
        }
        for bits in (1.0f32 - 1e-3).to_bits()..(1.0f32 + 1e-3).to_bits() {
            let s = f32::from_bits(bits);
            assert_eq!(s.sqrt() > 1.0, s > 1.0 + f32::EPSILON, "{s}");
        }
    }

    /// The AVX2 build of the tile renderer and the baseline build give the same bytes
    /// (both paths, additive and cartoon blends).
    #[test]
    fn simd_build_matches_baseline_build() {
        let mut scenes = vec![
            FireScene::table1(NoiseKind::Perlin4, 3, 35).with_size(Size::new(80, 60).unwrap()),
            FireScene::table1(NoiseKind::Perlin3, 3, 135).with_size(Size::new(80, 60).unwrap()),
            FireScene::preset(Preset::Campfire).with_size(Size::new(64, 64).unwrap()),
        ];
        let mut mn =
            FireScene::table1(NoiseKind::Mnoise, 1, 35).with_size(Size::new(64, 48).unwrap());
        mn.blend = Blend::Cartoon;
        scenes.push(mn);
        for scene in &scenes {
            let mut anim = scene.animator().unwrap();
            let (pts, _) = anim.step();
            let lats: Vec<Lattice> = pts
                .iter()
                .zip(&scene.fires)
                .map(|(p, f)| {
                    Lattice::build(&BSpline::new(p.clone(), f.degree).unwrap(), scene.lattice)
                        .unwrap()
                })
                .collect();
            let inst: Vec<FireInstance> = lats
                .iter()
                .zip(&scene.fires)
                .enumerate()
                .map(|(i, (lat, f))| FireInstance {
                    lattice: lat,
                    profile: &f.profile,
                    noise: f.noise,
                    offset: scene.offset(i),
                })
                .collect();
            let mut params = scene.render_params();
            for exact in [false, true] {
                params.exact_inverse = exact;
                let a = render_with(&inst, &scene.camera, &params, 0.7, true).unwrap();
                let b = render_with(&inst, &scene.camera, &params, 0.7, false).unwrap();
                assert_eq!(a.1, b.1);
                assert!(a.1.shaded > 100);
                for (x, y) in a.0.data().iter().zip(b.0.data()) {
                    assert_eq!(x.map(f32::to_bits), y.map(f32::to_bits));
                }
            }
        }
    }

    /// The batched shading (lanes noise, octaves skipped only where the alpha is provably
    /// zero) gives the very same colour as `shade` for every sample, and every sample with
    /// some alpha lies in the part of its cell the fast path marches (`visible_parts`).
    #[test]
    fn batched_shading_equals_scalar_shading_and_culls_only_invisible_samples() {
        let mut scenes = Vec::new();
        for kind in [NoiseKind::Perlin3, NoiseKind::Perlin4, NoiseKind::Mnoise] {
            scenes.push(FireScene::table1(kind, 3, 35).with_size(Size::new(64, 48).unwrap()));
        }
        for p in Preset::ALL {
            scenes.push(FireScene::preset(p).with_size(Size::new(48, 48).unwrap()));
        }
        let mut calm = FireScene::table1(NoiseKind::Perlin4, 0, 35);
        calm = calm.with_size(Size::new(64, 48).unwrap());
        scenes.push(calm);
        for scene in &scenes {
            let mut anim = scene.animator().unwrap();
            let (pts, _) = anim.step();
            let f = &scene.fires[0];
            let lat = Lattice::build(
                &BSpline::new(pts[0].clone(), f.degree).unwrap(),
                scene.lattice,
            )
            .unwrap();
            let inst = [FireInstance {
                lattice: &lat,
                profile: &f.profile,
                noise: f.noise,
                offset: scene.offset(0),
            }];
            let params = scene.render_params();
            let (fw, rt, up) = scene.camera.basis();
            let size = params.size;
            let ctx = Ctx {
                fires: &inst,
                camera: &scene.camera,
                params: &params,
                fw,
                rt,
                up,
                tan: (scene.camera.fov.to_radians() * 0.5).tan(),
                aspect: size.width as f32 / size.height as f32,
                time: 1.25,
                simd: true,
                per_cell: vec![false],
            };
            // every sample of the whole image in one batch
            let cands: Vec<Cand> = lat
                .cells()
                .iter()
                .enumerate()
                .map(|(i, c)| Cand {
                    fire: 0,
                    cell: i as u32,
                    min: sub(c.min, scene.camera.position),
                    max: sub(c.max, scene.camera.position),
                    vmin: sub(c.min, scene.camera.position),
                    vmax: sub(c.max, scene.camera.position),
                    disc: None,
                    px: [i32::MIN, i32::MAX, i32::MIN, i32::MAX],
                })
                .collect();
            let mut s = Scratch::default();
            let mut ranges = [(0u32, 0.0f32, 0.0f32); MAX_RANGES];
            let mut stats = RenderStats::default();
            for y in 0..size.height {
                for x in 0..size.width {
                    ctx.march(
                        &inst[0],
                        &cands,
                        x,
                        y,
                        i64::MAX,
                        0,
                        &mut ranges,
                        &mut stats,
                        &mut s,
                    );
                }
            }
            assert!(s.tex.len() > 300, "{stats:?}");
            ctx.shade_reference(&inst[0], &mut s);
            let reference = s.col.clone();
            // every visible sample lies in its cell's visible box (what the fast path
            // marches)
            let visible = visible_parts(&inst[0], scene.camera.position, false, None);
            let n = lat.cells().len();
            let mut discs = 0;
            for (tex, c) in s.tex.iter().zip(&reference) {
                if c[3] <= 0.0 {
                    continue;
                }
                let p = lat.forward(*tex);
                let j = ((tex[2] * n as f32) as usize).min(n - 1);
                let inside = |j: usize| {
                    let v = &visible[j];
                    let in_box = (0..3).all(|a| p[a] >= v.min[a] && p[a] <= v.max[a]);
                    match &v.disc {
                        Some(d) => in_box && d.contains(p, scene.camera.position),
                        None => in_box,
                    }
                };
                discs += visible[j].disc.is_some() as usize;
                assert!(
                    inside(j) || (j > 0 && inside(j - 1)),
                    "visible sample at {tex:?} outside the visible part of cell {j}"
                );
                // and its ray's screen position within the row span of its cell's disc
                // (`march_cells` widens that by a pixel, ≈ 4e-3 in `sx` here)
                let d = sub(p, scene.camera.position);
                let z = dot(d, ctx.fw);
                let (sx, sy) = ((dot(d, ctx.rt) / z) as f64, dot(d, ctx.up) / z);
                let spans = |j: usize| match &visible[j].disc {
                    Some(disc) => disc
                        .row_span(ctx.fw, ctx.rt, ctx.up, sy)
                        .is_some_and(|(lo, hi)| lo - 1e-4 <= sx && sx <= hi + 1e-4),
                    None => true,
                };
                assert!(
                    spans(j) || (j > 0 && spans(j - 1)),
                    "visible sample at {tex:?} outside the row span of cell {j}"
                );
            }
            // nearly every visible sample was checked against a disc too
            let lit = reference.iter().filter(|c| c[3] > 0.0).count();
            assert!(
                discs * 10 >= lit * 9,
                "{discs} of {lit} in cells with a disc"
            );
            let visible = reference.iter().filter(|c| c[3] > 0.0).count();
            assert!(visible > 100 && visible < reference.len());
            #[cfg(target_arch = "x86_64")]
            let builds = [false, std::arch::is_x86_feature_detected!("avx2")];
            #[cfg(not(target_arch = "x86_64"))]
            let builds = [false];
            for avx2 in builds {
                ctx.shade_batched(&inst[0], &mut s, avx2);
                for (i, (a, b)) in s.col.iter().zip(&reference).enumerate() {
                    assert!(
                        a == b,
                        "sample {i} at {:?}: {a:?} vs {b:?} ({avx2})",
                        s.tex[i]
                    );
                }
            }
        }
    }
}
