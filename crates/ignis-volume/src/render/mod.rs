//! The CPU renderer: view-aligned slicing with additive blending, done as ray marching.
//!
//! Source: fuller-procedural-volumetric-fire.txt §4.1, Figures 10–11. The GPU slices each
//! lattice cell with planes perpendicular to the view direction and adds the shaded
//! slices. Here every pixel's ray meets those planes (depths `k · slice_spacing` along the
//! camera's forward axis) inside the cells it crosses; each sample is mapped to texture
//! coordinates by inverting its cell's trilinear map ([`crate::lattice::Cell`]) and shaded
//! with [`crate::mapping::shade`] — what the slicing computes, up to the GPU's linear
//! (rather than trilinear) interpolation inside a cell.
//!
//! Output ([`render`]): linear-light HDR, **premultiplied** (`rgb` the light emitted towards
//! the camera, `a` the accumulated opacity in `0..=1`); [`finish`] applies bloom and
//! converts to the straight alpha every Ignis frame uses. Per pixel the result does not
//! depend on the thread count, nor on whether the AVX2 build runs (tested).
//!
//! A frame goes through these files:
//! - `camera.rs`: the pinhole camera.
//! - `visible.rs`: per cell, the part where a sample can be visible (a sample elsewhere
//!   has exactly zero alpha, so the fast paths skip it).
//! - `bin.rs`: cells binned into 16×16-pixel tiles by their projected boxes; rayon runs
//!   over the tiles.
//! - `tile.rs`: one tile, fire by fire: find the samples, shade them, blend them.
//! - `march_cells.rs`: finding samples cell by cell, eight inverted at a time with the
//!   certified chord inverse (lattices whose cells all have one: every Table 1 lattice).
//! - `march_ray.rs`: finding samples ray by ray with a predicted inverse (other lattices,
//!   and [`RenderParams::count_coverage`]).
//! - `shade.rs`: shading in batches: the noise 8 samples at a time,
//!   a sample dropped once the remaining octaves provably cannot make it visible.
//! - `blend.rs`: the additive, cartoon and tint blends. `finish.rs`: bloom, straight alpha.
//! - **`reference.rs`: the reference path** ([`RenderParams::exact_inverse`]): the plain
//!   per-ray march of every slice with the chord-then-Newton inverse from each cell's
//!   centre, and the scalar [`crate::mapping::shade`] per sample. The fast paths are tested
//!   against it (`tests.rs`): identical shading for identical samples, images within 1e-4
//!   per channel.

mod bin;
mod blend;
mod camera;
mod finish;
mod march_cells;
mod march_ray;
mod reference;
mod shade;
#[cfg(test)]
mod tests;
mod tile;
mod visible;

pub use blend::Blend;
pub use camera::Camera;
pub use finish::finish;
pub(crate) use finish::preview_metric;

use crate::error::{Result, VolumeError};
use crate::lattice::{Lattice, V3};
use crate::mapping::{loop_mix, periodic_loop, LoopMix, NoiseParams, PeriodicLoop};
use crate::profile::FireProfile;
use bin::bin_cells;
use ignis_core::{RgbaFrame, Size};
use march_cells::per_cell_ok;
use rayon::prelude::*;
use serde::Serialize;
use tile::{FrameRenderer, Scratch, SCRATCH};

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
    /// The reference path (`render/reference.rs`): march every slice of every ray, invert
    /// each sample's cell map with the chord-then-Newton method from the cell centre
    /// (steps down to 1e-5) and shade each sample with the scalar
    /// [`crate::mapping::shade`], instead of the certified inverses and the batched noise. The reference for a GPU parity check;
    /// the fast path differs from it by < 1e-4 per channel (tested; see
    /// `benches/README.md` for the measured difference).
    /// Default false.
    pub exact_inverse: bool,
    /// Also count [`RenderStats::covered_pixels`]: march the rest of every ray that found
    /// no visible sample until one sample is known to lie in a cell. That work adds
    /// nothing to the image (those samples have zero alpha; see `benches/README.md`),
    /// so it is off by default and `covered_pixels` is then 0.
    pub count_coverage: bool,
    /// A seamless loop: the length of the loop in seconds (`frames / fps`), or `None`.
    /// The noise is then periodic in time with this period ([`PeriodicLoop`], or
    /// [`LoopMix`] where the lattice cannot wrap), so a frame at
    /// `time + loop_period` equals the one at `time`. Default `None`.
    pub loop_period: Option<f32>,
}

impl RenderParams {
    /// A looping render's periodic noise for `fire` at scene time `time` (seconds), where
    /// its noise can be periodic ([`PeriodicLoop`]).
    pub(crate) fn periodic(&self, fire: &FireInstance, time: f32) -> Option<PeriodicLoop> {
        let ts = fire.noise.time_scale;
        let p = self.loop_period?;
        periodic_loop(time * ts, p * ts, &fire.noise, fire.scroll_length())
    }

    /// The loop mix of `fire` at scene time `time` (seconds): a looping render's fallback
    /// where the noise cannot be periodic ([`RenderParams::periodic`]).
    pub(crate) fn mix(&self, fire: &FireInstance, time: f32) -> Option<LoopMix> {
        let ts = fire.noise.time_scale;
        if self.periodic(fire, time).is_some() {
            return None;
        }
        self.loop_period.map(|p| loop_mix(time * ts, p * ts))
    }

    /// Checks the loop period, slice spacing, tint and intensity.
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
    /// World units the noise scrolls up per unit of noise time
    /// ([`crate::mapping::scroll_time`]); `None` = the lattice's own length, as in the
    /// paper. An animation gives each fire a fixed one so the scroll keeps its speed
    /// while the fire's length changes.
    pub scroll_length: Option<f32>,
}

impl FireInstance<'_> {
    /// The scroll length in use: [`FireInstance::scroll_length`] or the lattice's length.
    pub fn scroll_length(&self) -> f32 {
        self.scroll_length.unwrap_or_else(|| self.lattice.length())
    }
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

/// Side of the square pixel tiles the frame is rendered in, one rayon task each.
const TILE: u32 = 16;

/// Most samples (estimated before marching: for every cell, the pixels its projection
/// covers times its bounding box's diagonal over the slice spacing) one frame may take;
/// past it [`render`] refuses with [`VolumeError::LimitExceeded`] instead of running for
/// hours. 2·10⁹ is ~50× a Table 1 frame at 1920×1080.
pub const MAX_SAMPLES: f64 = 2e9;
/// Most (tile, cell) candidates one frame may bin (each ~100 bytes: 3·10⁷ ≈ 3 GB).
pub const MAX_CANDIDATES: u64 = 30_000_000;

/// Error bound, per texture coordinate, of the fast path's certified chord inverse
/// (`Cell::inverse_certified`) against the exact inverse: proven in
/// exact arithmetic; `f32` rounding of the residual adds < 1e-6 (the test
/// `certified_inverse_error_bound` checks ≤ this + 2e-6 against an `f64` inverse).
/// Texture space: `x, y ∈ [−1, 1]` across the fire, `z ∈ [0, 1]` along it.
pub(crate) const INVERSE_TEX_TOL: f32 = 3e-5;
/// Error bound, per texture coordinate, of the certified inverse in [`FrameRenderer::march_cells`]:
/// a quarter of [`INVERSE_TEX_TOL`]. The chord iteration there starts from the cell
/// centre rather than from a prediction along the ray, so the iterate it accepts is
/// usually close to its bound; the tighter bound costs about one more step (vectorised).
pub(crate) const CELL_TEX_TOL: f32 = 0.25 * INVERSE_TEX_TOL;

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
    let (renderer, bins) = prepare(fires, camera, params, time, simd)?;
    let size = params.size;
    let w = size.width;
    let (tx, ty) = (w.div_ceil(TILE), size.height.div_ceil(TILE));
    let tiles: Vec<(Vec<[f32; 4]>, RenderStats)> = (0..tx * ty)
        .into_par_iter()
        .map(|t| {
            let cands = &bins[t as usize];
            if cands.is_empty() {
                return (Vec::new(), RenderStats::default());
            }
            SCRATCH.with(|s| match s.try_borrow_mut() {
                Ok(mut scratch) => renderer.tile(t % tx, t / tx, cands, &mut scratch),
                // (not reached: a tile starts no parallel work that could render here)
                Err(_) => renderer.tile(t % tx, t / tx, cands, &mut Scratch::default()),
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

/// Checks the camera and settings, bins the cells into tiles and sets up the frame's
/// renderer (shared by [`render`] and [`reference_sums`]).
fn prepare<'a, 'b>(
    fires: &'a [FireInstance<'b>],
    camera: &'a Camera,
    params: &'a RenderParams,
    time: f32,
    simd: bool,
) -> Result<(FrameRenderer<'a, 'b>, Vec<Vec<bin::Candidate>>)> {
    camera.validate()?;
    params.validate()?;
    let (w, h) = (params.size.width, params.size.height);
    let (forward, right, up) = camera.basis();
    let tan = camera.half_height(params.size);
    let aspect = w as f32 / h as f32;
    let bins = bin_cells(
        fires,
        camera,
        params,
        time,
        [forward, right, up],
        tan,
        aspect,
    )?;
    let renderer = FrameRenderer {
        fires,
        camera,
        params,
        forward,
        right,
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
    Ok((renderer, bins))
}

/// Per pixel (row-major), the sum over the samples of the reference path
/// ([`RenderParams::exact_inverse`], whatever `params` says) of `f(fire, tex, colour)`:
/// the fire's index, the sample's texture coordinates and its shaded straight-alpha
/// colour. What [`crate::model_motion`] weighs each sample's velocity with; the image
/// itself is not made. Deterministic at any thread count (each pixel's samples are summed
/// in march order within its tile).
pub(crate) fn reference_sums<const N: usize>(
    fires: &[FireInstance],
    camera: &Camera,
    params: &RenderParams,
    time: f32,
    f: &(dyn Fn(usize, V3, [f32; 4]) -> [f32; N] + Sync),
) -> Result<Vec<[f32; N]>> {
    let params = RenderParams {
        exact_inverse: true,
        count_coverage: false,
        ..*params
    };
    let (renderer, bins) = prepare(fires, camera, &params, time, false)?;
    let (w, h) = (params.size.width, params.size.height);
    let tx = w.div_ceil(TILE);
    let tiles: Vec<Vec<[f32; N]>> = (0..bins.len() as u32)
        .into_par_iter()
        .map(|t| {
            let mut scratch = Scratch::default();
            renderer.tile_sums(t % tx, t / tx, &bins[t as usize], &mut scratch, f)
        })
        .collect();
    let mut out = vec![[0.0f32; N]; params.size.pixels()];
    for (t, buf) in tiles.iter().enumerate() {
        let (x0, y0) = ((t as u32 % tx) * TILE, (t as u32 / tx) * TILE);
        let tw = TILE.min(w - x0) as usize;
        for (i, v) in buf.iter().enumerate() {
            let (x, y) = (x0 as usize + i % tw, y0 as usize + i / tw);
            if y < h as usize {
                out[y * w as usize + x] = *v;
            }
        }
    }
    Ok(out)
}
