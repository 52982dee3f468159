//! **The reference path** ([`super::RenderParams::exact_inverse`]), which the fast paths
//! are tested against (`tests.rs`): every slice of every pixel's ray, the cell's map
//! inverted by the chord-then-Newton method from the cell centre to 1e-5
//! ([`crate::lattice::Cell::inverse_fast`]), every sample shaded by the scalar
//! [`shade`] / [`shade_looped`]. Kept plain on purpose: it is the renderer to read first,
//! and what a GPU port is checked against.

use super::bin::Candidate;
use super::march_ray::{finish_sample, locate, Ray, MAX_RANGES};
use super::tile::{FrameRenderer, Scratch};
use super::TILE;
use super::{FireInstance, RenderStats};
use crate::lattice::V3;
use crate::mapping::{shade, shade_looped, shade_periodic};

impl FrameRenderer<'_, '_> {
    /// Marches pixel `(x, y)`'s ray through one fire's candidate cells, every slice from
    /// the first cell it enters to the last it leaves (before slice `best_k`), and appends
    /// its samples inside the unit cylinder (texture coordinates) to `out`. Returns whether
    /// any sample was inside a cell.
    pub(super) fn march_reference(
        &self,
        fire: &FireInstance,
        group: &[Candidate],
        x: u32,
        y: u32,
        best_k: i64,
        pix: u16,
        ranges: &mut [(u32, f32, f32); MAX_RANGES],
        stats: &mut RenderStats,
        out: &mut Scratch,
    ) -> bool {
        let Some(mut ray) = self.ray(group, x, y, best_k, pix, ranges, false) else {
            return false;
        };
        while ray.slice <= ray.last_slice {
            self.sample_reference(fire, &mut ray, stats, out);
        }
        ray.covered
    }

    /// Takes ray `r`'s next sample (slice `r.slice`): its cell and local coordinates by
    /// [`crate::lattice::Cell::inverse_fast`], from the cell centre on entering a cell and
    /// from the previous sample's extrapolated coordinates after that, moving to the
    /// neighbouring cell while the inverse says the point lies there.
    fn sample_reference(
        &self,
        fire: &FireInstance,
        r: &mut Ray,
        stats: &mut RenderStats,
        out: &mut Scratch,
    ) {
        let cells = fire.lattice.cells();
        let Some((k, p, j, guess)) = self.start_sample(cells, r, |j, _| (j, [0.5; 3])) else {
            return;
        };
        let found = locate(
            cells,
            j,
            guess,
            |j, p, guess| cells[j].inverse_fast(p, guess),
            p,
        );
        finish_sample(fire, r, k, found, |_| None, stats, out);
    }

    /// One tile of [`super::reference_sums`]: per pixel of the tile (row-major within it),
    /// the sum of `f(fire, tex, colour)` over its reference-path samples; empty when the
    /// tile has no candidate cells.
    pub(super) fn tile_sums<const N: usize>(
        &self,
        tx: u32,
        ty: u32,
        cands: &[Candidate],
        scratch: &mut Scratch,
        f: &(dyn Fn(usize, V3, [f32; 4]) -> [f32; N] + Sync),
    ) -> Vec<[f32; N]> {
        if cands.is_empty() {
            return Vec::new();
        }
        let size = self.params.size;
        let (x0, y0) = (tx * TILE, ty * TILE);
        let (x1, y1) = ((x0 + TILE).min(size.width), (y0 + TILE).min(size.height));
        let tw = (x1 - x0) as usize;
        let mut acc = vec![[0.0f32; N]; tw * (y1 - y0) as usize];
        let mut ranges = [(0u32, 0.0f32, 0.0f32); MAX_RANGES];
        let mut stats = RenderStats::default();
        let mut i = 0;
        while i < cands.len() {
            let fi = cands[i].fire;
            let start = i;
            while i < cands.len() && cands[i].fire == fi {
                i += 1;
            }
            let fire = &self.fires[fi as usize];
            scratch.pix.clear();
            scratch.slice.clear();
            scratch.tex.clear();
            for y in y0..y1 {
                for x in x0..x1 {
                    let p = ((y - y0) as usize * tw + (x - x0) as usize) as u16;
                    let (r, st) = (&mut ranges, &mut stats);
                    self.march_reference(fire, &cands[start..i], x, y, i64::MAX, p, r, st, scratch);
                }
            }
            self.shade_reference(fire, scratch);
            for s in 0..scratch.pix.len() {
                let v = f(fi as usize, scratch.tex[s], scratch.col[s]);
                let a = &mut acc[scratch.pix[s] as usize];
                for c in 0..N {
                    a[c] += v[c];
                }
            }
        }
        acc
    }

    /// Shades every collected sample with [`shade`], one by one: the reference.
    pub(super) fn shade_reference(&self, fire: &FireInstance, s: &mut Scratch) {
        let time = self.time * fire.noise.time_scale;
        let mix = self.params.mix(fire, self.time);
        let periodic = self.params.periodic(fire, self.time);
        s.col.clear();
        s.col.extend(s.tex.iter().map(|&tex| {
            let radius = fire.lattice.radius_at(tex[2]);
            let length = [fire.lattice.length(), fire.scroll_length()];
            if let Some(pl) = periodic {
                return shade_periodic(
                    tex,
                    radius,
                    length[0],
                    pl,
                    &fire.noise,
                    fire.offset,
                    fire.profile,
                );
            }
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
}
