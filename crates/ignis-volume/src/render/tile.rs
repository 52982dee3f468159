//! One tile of the frame: per fire, find its samples (cell by cell, ray by ray or by the
//! reference march), shade them, blend them into the tile's pixels.

use super::bin::Candidate;
use super::blend::blend_samples;
use super::march_ray::MAX_RANGES;
use super::shade::LiveSample;
use super::{Camera, FireInstance, RenderParams, RenderStats, TILE};
use crate::lattice::V3;
use crate::noise::NoiseCache;

/// What every tile of one frame shares: the fires, the camera and its basis, the settings.
/// Its methods, spread over this module's files, render the tiles.
pub(super) struct FrameRenderer<'a, 'b> {
    pub(super) fires: &'a [FireInstance<'b>],
    pub(super) camera: &'a Camera,
    pub(super) params: &'a RenderParams,
    /// The camera's forward, right and up unit vectors ([`Camera::basis`]).
    pub(super) forward: V3,
    pub(super) right: V3,
    pub(super) up: V3,
    /// `tan(fov / 2)` and the image's width over its height.
    pub(super) tan: f32,
    pub(super) aspect: f32,
    /// Noise time, seconds.
    pub(super) time: f32,
    /// Use the AVX2 build of the tile renderer when the CPU has it (same results).
    pub(super) simd: bool,
    /// Per fire: find its samples cell by cell ([`FrameRenderer::march_cells`]) rather than ray by
    /// ray ([`per_cell_ok`]).
    pub(super) per_cell: Vec<bool>,
}

thread_local! {
    /// Each rendering thread's working arrays, kept from tile to tile and frame to frame
    /// (rayon's threads live on), so a warm renderer allocates nothing per sample or tile.
    pub(super) static SCRATCH: std::cell::RefCell<Scratch> = std::cell::RefCell::new(Scratch::default());
}

/// One fire's samples in one tile, in march order (pixel by pixel, front to back), plus
/// the working arrays of the batched shading. Reused from tile to tile (no allocation per
/// sample or per tile once warm).
#[derive(Default)]
pub(super) struct Scratch {
    /// Pixel index within the tile.
    pub(super) pix: Vec<u16>,
    /// Slice index (depth) of the sample, for the cartoon blend.
    pub(super) slice: Vec<i64>,
    /// Texture coordinates.
    pub(super) tex: Vec<V3>,
    /// Straight-alpha colour of each sample (after shading).
    pub(super) col: Vec<[f32; 4]>,
    /// Batched noise: the samples still in play.
    pub(super) live: Vec<LiveSample>,
    /// Sample indices ordered by slice, then pixel (see `FrameRenderer::shade_batched`), and the
    /// counting sort's buckets.
    pub(super) order: Vec<u32>,
    pub(super) buckets: Vec<u32>,
    /// Memoised permutation hashes of the noise cells met so far.
    pub(super) noise_cache: NoiseCache,
    /// Per-cell march ([`FrameRenderer::march_cells`]): per pixel of the tile, the scaled ray
    /// direction and its reciprocal and whether a sample was found.
    pub(super) dirs: Vec<V3>,
    pub(super) invs: Vec<V3>,
    pub(super) hit: Vec<bool>,
}

impl FrameRenderer<'_, '_> {
    /// Renders one tile: [`FrameRenderer::tile_impl`], compiled for AVX2 when the CPU has it.
    ///
    /// The AVX2 build runs the very same `f32` operations (Rust never fuses a multiply and
    /// an add on its own, so enabling the FMA unit changes no result), only with wider
    /// registers: the 8-lane noise fits one register per lane vector instead of two, and
    /// `floor` is an instruction rather than a library call. The output is bit for bit the
    /// same on either path (tested).
    pub(super) fn tile(
        &self,
        tx: u32,
        ty: u32,
        cands: &[Candidate],
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
    pub(super) unsafe fn tile_avx2(
        &self,
        tx: u32,
        ty: u32,
        cands: &[Candidate],
        scratch: &mut Scratch,
    ) -> (Vec<[f32; 4]>, RenderStats) {
        self.tile_impl(tx, ty, cands, scratch, true)
    }

    /// `avx2`: the CPU has AVX2 and this is the AVX2 build (the noise then uses
    /// [`crate::noise::avx2`]).
    #[inline(always)]
    pub(super) fn tile_impl(
        &self,
        tx: u32,
        ty: u32,
        cands: &[Candidate],
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
        // cell for a fire whose cells all have a certified inverse, else ray by ray; the
        // reference path marches every slice), shade them all (the noise in batches), then
        // add them up per pixel.
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
            scratch.slice.clear();
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
                        let (k, pix) = (best_k[p], p as u16);
                        let (r, st) = (&mut ranges, &mut stats);
                        covered[p] |= if self.params.exact_inverse {
                            self.march_reference(fire, group, x, y, k, pix, r, st, scratch)
                        } else {
                            self.march(fire, group, x, y, k, pix, r, st, scratch)
                        };
                    }
                }
            }
            if self.params.exact_inverse {
                self.shade_reference(fire, scratch);
            } else {
                self.shade_batched(fire, scratch, avx2);
            }
            blend_samples(
                self.params.blend,
                self.params.intensity * self.params.slice_spacing,
                scratch,
                &mut acc,
                &mut best_k,
            );
        }
        if self.params.count_coverage {
            stats.covered_pixels += covered.iter().filter(|&&c| c).count() as u64;
        }
        for a in &mut acc {
            a[3] = a[3].min(1.0);
        }
        (acc, stats)
    }

    /// Pixel `(x, y)`'s centre on the image plane at unit distance: the ray through it has
    /// direction `forward + sx · right + sy · up`.
    #[inline(always)]
    pub(super) fn screen(&self, x: u32, y: u32) -> [f32; 2] {
        let size = self.params.size;
        [
            ((x as f32 + 0.5) / size.width as f32 * 2.0 - 1.0) * self.tan * self.aspect,
            (1.0 - (y as f32 + 0.5) / size.height as f32 * 2.0) * self.tan,
        ]
    }
}
