//! **The reference path** ([`super::RenderParams::exact_inverse`]), which the fast paths
//! are tested against (`tests.rs`): every slice of every pixel's ray, the cell's map
//! inverted by the chord-then-Newton method from the cell centre to 1e-5
//! ([`crate::lattice::Cell::inverse_fast`]), every sample shaded by the scalar
//! [`shade`] / [`shade_looped`]. Kept plain on purpose: it is the renderer to read first,
//! and what a GPU port is checked against.

use super::bin::Candidate;
use super::march_ray::{keep_sample, Ray, MAX_RANGES};
use super::tile::{FrameRenderer, Scratch};
use super::{FireInstance, RenderStats};
use crate::lattice::{add, scale, sub};
use crate::mapping::{shade, shade_looped};

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
        let k = r.slice;
        r.slice += 1;
        let cells = fire.lattice.cells();
        let last = cells.len() - 1;
        let t = k as f32 * self.params.slice_spacing / r.cos_forward;
        let p = add(r.origin, scale(r.dir, t));
        let (mut j, mut guess) = if r.tracking {
            let pred = match r.coords_step {
                Some(dl) => add(r.coords, dl),
                None => r.coords,
            };
            let lv = pred[2].clamp(0.0, cells.len() as f32);
            let j = (lv as usize).min(last);
            (j, [pred[0], pred[1], lv - j as f32])
        } else {
            match r.ranges.iter().find(|q| q.1 <= t && t <= q.2) {
                Some(q) => {
                    r.coords_step = None;
                    (q.0 as usize, [0.5; 3])
                }
                None => return,
            }
        };
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
            r.tracking = false;
            return;
        };
        let ng = [l[0], l[1], j as f32 + l[2]];
        r.coords_step = if r.tracking {
            Some(sub(ng, r.coords))
        } else {
            None
        };
        r.coords = ng;
        r.tracking = true;
        keep_sample(fire, r, k, j, l, stats, out);
    }

    /// Shades every collected sample with [`shade`], one by one: the reference.
    pub(super) fn shade_reference(&self, fire: &FireInstance, s: &mut Scratch) {
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
}
