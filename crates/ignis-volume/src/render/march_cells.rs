//! Finding one fire's samples in a tile cell by cell: per candidate cell, the slices of
//! every pixel's ray inside the cell's visible part are inverted [`CHORD_LANES`] at a time
//! with the cell's certified chord inverse, and one rule per shared face gives each sample
//! to exactly one cell. For lattices whose cells all have a certified inverse
//! ([`per_cell_ok`]: every Table 1 lattice).

use super::bin::Candidate;
use super::march_ray::{in_unit_cylinder, local_tol, slab, MAX_RANGES};
use super::tile::{FrameRenderer, Scratch};
use super::{FireInstance, RenderStats, CELL_TEX_TOL};
use crate::lattice::{add, scale, Lattice, CHORD_LANES, V3};

/// How far beyond its end faces (in `s`, as a multiple of the certified inverse's error
/// bound in `s`) a sample may lie and still be assigned to a cell by
/// [`FrameRenderer::march_cells`]; see [`FrameRenderer::owns`].
pub(super) const OWNER_SLACK: f32 = 8.0;

/// Whether [`FrameRenderer::march_cells`] may find this lattice's samples: every cell has a
/// certificate (nearly affine, so the certified chord inverse answers), and neighbouring
/// cells are of similar thickness across their shared face (the rows `∇s` of their
/// centres' inverse Jacobians differ in length by less than 1.5×, so by less than 2×
/// anywhere on the face), which the face rule of [`FrameRenderer::owns`] relies on.
pub(super) fn per_cell_ok(lattice: &Lattice) -> bool {
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

pub(super) fn norm64(v: [f64; 3]) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// Up to [`CHORD_LANES`] candidate samples of one cell ([`FrameRenderer::march_cells`]): world
/// positions, pixels and slices.
#[derive(Default)]
pub(super) struct SampleBatch {
    pub(super) p: [[f32; CHORD_LANES]; 3],
    pub(super) pix: [u16; CHORD_LANES],
    pub(super) k: [i64; CHORD_LANES],
    pub(super) n: usize,
}

impl FrameRenderer<'_, '_> {
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
    /// [`FrameRenderer::owns`] — exactly one cell claims a sample near a shared face. Samples
    /// behind a pixel's `best_k` are skipped. With [`RenderParams::count_coverage`], a
    /// pixel that gave no sample is then marched ray by ray ([`FrameRenderer::cover`]) until one
    /// sample is known to lie in a cell, to count it as covered (those samples are not
    /// visible and are not kept).
    ///
    /// Long on purpose (~100 lines): the per-cell loop is the renderer's hottest path and is
    /// kept in one body so the cell, row and batch state stay in registers.
    #[inline(always)]
    pub(super) fn march_cells(
        &self,
        fire: &FireInstance,
        group: &[Candidate],
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
        self.tile_directions([x0, y0, x1, y1], out);
        out.hit.clear();
        out.hit.resize(n, false);
        let o = self.camera.position;
        let spacing = self.params.slice_spacing;
        let tol = local_tol(fire, CELL_TEX_TOL);
        for cand in group {
            let (cx0, cx1) = (
                cand.pixel_rect[0].max(x0 as i32),
                cand.pixel_rect[1].min(x1 as i32 - 1),
            );
            let (cy0, cy1) = (
                cand.pixel_rect[2].max(y0 as i32),
                cand.pixel_rect[3].min(y1 as i32 - 1),
            );
            if cand.visible_min[0] > cand.visible_max[0] {
                continue; // nothing of this cell can be visible
            }
            if cx0 > cx1 || cy0 > cy1 {
                // its pixel rectangle misses this tile (its edge lies beyond a frame
                // edge that is not a multiple of the tile); `row_pixels` needs cx0 ≤ cx1 + 2
                continue;
            }
            let j = cand.cell as usize;
            let mut batch = SampleBatch::default();
            for y in cy0..cy1 + 1 {
                let Some((rx0, rx1)) = self.row_pixels(cand, y, cx0, cx1) else {
                    continue;
                };
                // The part of the cell that can be visible is convex, so the pixels of a
                // row whose rays meet it are consecutive: after the first miss that follows
                // a hit the row is done.
                let mut met = false;
                for x in rx0..rx1 + 1 {
                    let p = (y as u32 - y0) as usize * tw + (x as u32 - x0) as usize;
                    let (d, inv) = (out.dirs[p], out.invs[p]);
                    let Some((b0, b1)) = slab(inv, cand.visible_min, cand.visible_max) else {
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

    /// Per pixel of tile `[x0, y0, x1, y1)`, row by row: the ray direction `D` scaled to
    /// `D · forward = 1` (into `out.dirs`) and its reciprocal (into `out.invs`).
    #[inline(always)]
    fn tile_directions(&self, [x0, y0, x1, y1]: [u32; 4], out: &mut Scratch) {
        out.dirs.clear();
        out.invs.clear();
        for y in y0..y1 {
            for x in x0..x1 {
                let [sx, sy] = self.screen(x, y);
                let d = add(self.forward, add(scale(self.right, sx), scale(self.up, sy)));
                out.dirs.push(d);
                out.invs.push([1.0 / d[0], 1.0 / d[1], 1.0 / d[2]]);
            }
        }
    }

    /// The pixels `x0 ..= x1` of row `y` within `cx0 ..= cx1` whose rays can meet the
    /// cylinder of `cand`'s affine disc (with a pixel to spare); `None` if none can.
    #[inline(always)]
    fn row_pixels(&self, cand: &Candidate, y: i32, cx0: i32, cx1: i32) -> Option<(i32, i32)> {
        let Some(disc) = &cand.disc else {
            return Some((cx0, cx1));
        };
        let (lo, hi) = disc.row_span(
            self.forward,
            self.right,
            self.up,
            self.screen(0, y as u32)[1],
        )?;
        let px = |sx: f64| {
            (sx / (self.tan * self.aspect) as f64 + 1.0) * 0.5 * self.params.size.width as f64 - 0.5
        };
        let lim = |v: f64| v.clamp(cx0 as f64 - 1.0, cx1 as f64 + 1.0) as i32;
        Some((
            cx0.max(lim(px(lo).floor() - 1.0)),
            cx1.min(lim(px(hi).ceil() + 1.0)),
        ))
    }

    /// Inverts a batch of candidate samples of cell `j` ([`FrameRenderer::march_cells`]) and keeps
    /// those the cell claims ([`FrameRenderer::owns`]) and that lie in the unit cylinder.
    #[inline(always)]
    pub(super) fn claim(
        &self,
        fire: &FireInstance,
        j: usize,
        batch: &SampleBatch,
        tol: V3,
        avx2: bool,
        stats: &mut RenderStats,
        out: &mut Scratch,
    ) {
        let cell = &fire.lattice.cells()[j];
        #[cfg(target_arch = "x86_64")]
        let (ls, ok) = if avx2 {
            // SAFETY: `avx2` is true only in the AVX2 build on CPUs with AVX2 (`FrameRenderer::tile`).
            unsafe { cell.inverse_certified_lanes_avx2(&batch.p, tol) }
        } else {
            cell.inverse_certified_lanes(&batch.p, tol)
        };
        #[cfg(not(target_arch = "x86_64"))]
        let (ls, ok) = cell.inverse_certified_lanes(&batch.p, tol);
        // The common case for all lanes at once (straight-line code over the lanes): a
        // certified lane inside the cell's sides and clear of its end faces by the band of
        // `FrameRenderer::owns` (which then answers `true` without computing anything more).
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
        out.slice.extend_from_slice(&ks[..kept]);
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
    pub(super) fn owns(&self, fire: &FireInstance, j: usize, s: f32, p: V3, tol: V3) -> bool {
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
}

/// Cell `j`'s local height `s` of `p` as [`FrameRenderer::owns`] decides faces with: the certified
/// chord inverse from the centre, else Newton's method from the chord guess, else
/// `−∞` (then `p` counts as below the face). A pure function of `(j, p)`.
pub(super) fn canonical_s(fire: &FireInstance, j: usize, p: V3, tol: V3) -> f32 {
    let c = &fire.lattice.cells()[j];
    c.inverse_chord_certified(p, tol)
        .or_else(|| c.inverse(p, c.chord_guess(p)))
        .map_or(f32::NEG_INFINITY, |l| l[2])
}
