//! Finding one fire's samples ray by ray: along a pixel's ray the global lattice
//! coordinates `(a, b, level + s)` are extrapolated from the previous samples, which gives
//! the cell and a close guess for its certified chord inverse (or the tracked
//! chord/Newton inverse where that does not certify). Used for lattices the per-cell march
//! does not take, and for the coverage count ([`super::RenderParams::count_coverage`]).

use super::bin::Candidate;
use super::tile::{FrameRenderer, Scratch};
use super::{FireInstance, RenderStats, INVERSE_TEX_TOL};
use crate::lattice::{add, dot, normalize, scale, sub, Cell, Track, V3};

/// Cells kept per ray and fire for finding the entry cell (more are ignored).
pub(super) const MAX_RANGES: usize = 64;

/// The ray parameter interval `(t0, t1)` (with `t0 ≥ 1e-4`) in which the ray `o + t d`
/// (`inv` = `1/d` per axis) is inside the box `o + [min, max]`, if not empty.
#[inline(always)]
pub(super) fn slab(inv: V3, min: V3, max: V3) -> Option<(f32, f32)> {
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

/// A pixel's ray being marched (see [`FrameRenderer::march`]).
pub(super) struct Ray<'r> {
    pub(super) origin: V3,
    pub(super) dir: V3,
    /// `dir · forward`: sample `k` is at `origin + dir · k · spacing / cos_forward`.
    pub(super) cos_forward: f32,
    /// The candidate cells the ray meets, with its parameter interval in each.
    pub(super) ranges: &'r [(u32, f32, f32)],
    /// Next slice index `k`, and the last one.
    pub(super) slice: i64,
    pub(super) last_slice: i64,
    /// The slices that may meet a visible part of a cell ([`visible_parts`]); empty if
    /// `.0 > .1`.
    pub(super) visible: (i64, i64),
    pub(super) pix: u16,
    pub(super) covered: bool,
    /// While tracking, `coords` is the last sample's global lattice coordinates
    /// `(a, b, level + s)` and `coords_step` their change per sample: consecutive samples are
    /// predicted by linear extrapolation (the map is smooth across cell faces), so the
    /// cell is known and one or two Newton steps usually suffice.
    pub(super) tracking: bool,
    pub(super) coords: V3,
    pub(super) coords_step: Option<V3>,
    /// Inverse Jacobian of the last Newton solve, for the chord steps.
    pub(super) track: Track,
    /// Local-coordinate tolerance of the certified chord steps: [`INVERSE_TEX_TOL`] in
    /// texture space (`tex_x = 2a − 1`, `tex_z = (j + s)/cells`).
    pub(super) tol: V3,
}

impl FrameRenderer<'_, '_> {
    /// Marches pixel `(x, y)`'s ray through one fire's candidate cells and appends its
    /// samples inside the unit cylinder (texture coordinates) to `out`; samples at slice
    /// index `best_k` or beyond are skipped. Returns whether any sample was inside a cell.
    #[inline(always)]
    pub(super) fn march(
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
        let Some(mut ray) = self.ray(group, x, y, best_k, pix, ranges, true) else {
            return false;
        };
        ray.tol = local_tol(fire, INVERSE_TEX_TOL);
        // the slices that may be visible, then (when counting coverage) the others only
        // until one sample is known to lie inside a cell (their alpha is zero)
        let (k0, k1) = (ray.slice, ray.last_slice);
        let (v0, v1) = ray.visible;
        let rest = if v0 <= v1 {
            ray.last_slice = v1;
            ray.slice = v0;
            while ray.slice <= ray.last_slice {
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
            (ray.slice, ray.last_slice, ray.tracking) = (a, b, false);
            while !ray.covered && ray.slice <= ray.last_slice {
                self.sample(fire, &mut ray, stats, out);
            }
        }
        ray.covered
    }

    /// Marches pixel `(x, y)`'s ray through one fire's cells only until a sample is
    /// known to lie inside a cell (then the pixel is covered); keeps no sample.
    #[inline(always)]
    pub(super) fn cover(
        &self,
        fire: &FireInstance,
        group: &[Candidate],
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
        while !ray.covered && ray.slice <= ray.last_slice {
            self.sample(fire, &mut ray, stats, out);
        }
        stats.shaded -= (out.pix.len() - n0) as u64;
        out.pix.truncate(n0);
        out.slice.truncate(n0);
        out.tex.truncate(n0);
        ray.covered
    }

    /// Sets up pixel `(x, y)`'s ray: direction, the candidate cells it meets (with their
    /// ray intervals, kept in `ranges`), its slice range and, `with_visible`, the slices
    /// that may be visible (else none); `None` if it meets no cell.
    #[inline(always)]
    pub(super) fn ray<'r>(
        &self,
        group: &[Candidate],
        x: u32,
        y: u32,
        best_k: i64,
        pix: u16,
        ranges: &'r mut [(u32, f32, f32); MAX_RANGES],
        with_visible: bool,
    ) -> Option<Ray<'r>> {
        let [sx, sy] = self.screen(x, y);
        let d = normalize(add(
            self.forward,
            add(scale(self.right, sx), scale(self.up, sy)),
        ))
        .unwrap_or(self.forward);
        let o = self.camera.position;
        let cos_forward = dot(d, self.forward);
        let inv = [1.0 / d[0], 1.0 / d[1], 1.0 / d[2]];
        let spacing = self.params.slice_spacing;
        // March the union of the cells' ray intervals front to back and walk from cell to
        // cell with the local `s`.
        let mut nr = 0;
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        let (xi, yi) = (x as i32, y as i32);
        let (mut vlo, mut vhi) = (f32::INFINITY, f32::NEG_INFINITY);
        for cell in group {
            if xi < cell.pixel_rect[0]
                || xi > cell.pixel_rect[1]
                || yi < cell.pixel_rect[2]
                || yi > cell.pixel_rect[3]
            {
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
            if !with_visible || cell.visible_min[0] > cell.visible_max[0] {
                continue; // not asked for, or nothing of this cell can be visible
            }
            let part = match &cell.disc {
                Some(disc) => disc.interval(d),
                None => slab(inv, cell.visible_min, cell.visible_max),
            };
            if let Some((t0, t1)) = part {
                vlo = vlo.min(t0);
                vhi = vhi.max(t1);
            }
        }
        if nr == 0 {
            return None;
        }
        let k0 = (lo * cos_forward / spacing).ceil() as i64;
        let k1 = ((hi * cos_forward / spacing).floor() as i64).min(best_k.saturating_sub(1));
        let visible = if vlo <= vhi {
            (
                ((vlo * cos_forward / spacing).ceil() as i64).max(k0),
                ((vhi * cos_forward / spacing).floor() as i64).min(k1),
            )
        } else {
            (1, 0)
        };
        Some(Ray {
            origin: o,
            dir: d,
            cos_forward,
            ranges: &ranges[..nr],
            slice: k0,
            last_slice: k1,
            visible,
            pix,
            covered: false,
            tracking: false,
            coords: [0.5; 3],
            coords_step: None,
            track: Track::default(),
            tol: [0.0; 3],
        })
    }

    /// Takes ray `r`'s next sample (slice `r.slice`) and advances it: finds the sample's cell
    /// and local coordinates and appends it to `out` if it lies inside the unit cylinder.
    #[inline(always)]
    pub(super) fn sample(
        &self,
        fire: &FireInstance,
        r: &mut Ray,
        stats: &mut RenderStats,
        out: &mut Scratch,
    ) {
        let cells = fire.lattice.cells();
        let last = cells.len() - 1;
        // entering a cell: the chord step from the centre, moving to the neighbouring cell
        // while it says the point lies there (nearly affine cells: the step is accurate, so
        // this saves a failed solve)
        let enter = |mut j: usize, p: V3| {
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
        };
        let Some((k, p, j, guess)) = self.start_sample(cells, r, enter) else {
            return;
        };
        let tol = r.tol;
        let track = &mut r.track;
        let found = locate(
            cells,
            j,
            guess,
            |j, p, guess| {
                match cells[j].inverse_certified(p, guess, tol) {
                    Ok(l) => Some(l),
                    // beyond an end of the lattice: outside whatever the exact inverse
                    Err(Some(l)) if (j == 0 && l[2] < 0.0) || (j == last && l[2] > 1.0) => Some(l),
                    Err(_) => cells[j].inverse_tracked(p, guess, track),
                }
            },
            p,
        );
        // no previous sample yet: the ray's step mapped by the inverse Jacobian at the cell
        // centre (the affine part of the map), a first-order prediction
        let step = scale(r.dir, self.params.slice_spacing / r.cos_forward);
        finish_sample(
            fire,
            r,
            k,
            found,
            |j| Some(cells[j].local_direction(step)),
            stats,
            out,
        );
    }

    /// Advances ray `r` to its next slice and returns the slice `k`, the sample's position
    /// `p` and where to start inverting: the previous sample's extrapolated coordinates
    /// while tracking, else `enter(candidate cell, p)` on entering a candidate range. `None`
    /// between candidate ranges.
    #[inline(always)]
    pub(super) fn start_sample(
        &self,
        cells: &[Cell],
        r: &mut Ray,
        enter: impl FnOnce(usize, V3) -> (usize, V3),
    ) -> Option<(i64, V3, usize, V3)> {
        let k = r.slice;
        r.slice += 1;
        let last = cells.len() - 1;
        let t = k as f32 * self.params.slice_spacing / r.cos_forward;
        let p = add(r.origin, scale(r.dir, t));
        let (j, guess) = if r.tracking {
            let pred = match r.coords_step {
                Some(dl) => add(r.coords, dl),
                None => r.coords,
            };
            let lv = pred[2].clamp(0.0, cells.len() as f32);
            let j = (lv as usize).min(last);
            (j, [pred[0], pred[1], lv - j as f32])
        } else {
            let q = r.ranges.iter().find(|q| q.1 <= t && t <= q.2)?;
            r.coords_step = None;
            enter(q.0 as usize, p)
        };
        Some((k, p, j, guess))
    }
}

/// Inverts `p` starting in cell `j` from `guess`, hopping to the neighbouring cell (at most
/// six times) while the local coordinates say the point lies there: the cell and its local
/// coordinates, or `None` when `inverse` fails.
#[inline(always)]
pub(super) fn locate(
    cells: &[Cell],
    mut j: usize,
    mut guess: V3,
    mut inverse: impl FnMut(usize, V3, V3) -> Option<V3>,
    p: V3,
) -> Option<(usize, V3)> {
    let last = cells.len() - 1;
    for _ in 0..6 {
        let l = inverse(j, p, guess)?;
        let step = l[2].floor();
        if (step < 0.0 && j > 0) || (step >= 1.0 && j < last) {
            let nj = (j as i64 + step as i64).clamp(0, last as i64) as usize;
            guess = [l[0], l[1], (l[2] - (nj as f32 - j as f32)).clamp(0.0, 1.0)];
            j = nj;
            continue;
        }
        return Some((j, l));
    }
    None
}

/// Ends ray `r`'s sample at slice `k`: when `found` (cell, local coordinates) the ray
/// tracks from it (the step from the previous sample, or `first_step(cell)` for the first)
/// and the sample is kept ([`keep_sample`]); otherwise the ray stops tracking.
#[inline(always)]
pub(super) fn finish_sample(
    fire: &FireInstance,
    r: &mut Ray,
    k: i64,
    found: Option<(usize, V3)>,
    first_step: impl FnOnce(usize) -> Option<V3>,
    stats: &mut RenderStats,
    out: &mut Scratch,
) {
    let Some((j, l)) = found else {
        r.tracking = false;
        return;
    };
    let ng = [l[0], l[1], j as f32 + l[2]];
    r.coords_step = if r.tracking {
        Some(sub(ng, r.coords))
    } else {
        first_step(j)
    };
    r.coords = ng;
    r.tracking = true;
    keep_sample(fire, r, k, j, l, stats, out);
}

/// Ray `r`'s sample at slice `k`, with local coordinates `l` in cell `j`: if it lies in
/// the cell, the pixel is covered; if also in the unit cylinder, it is appended to `out`.
#[inline(always)]
pub(super) fn keep_sample(
    fire: &FireInstance,
    r: &mut Ray,
    k: i64,
    j: usize,
    l: V3,
    stats: &mut RenderStats,
    out: &mut Scratch,
) {
    if !(l[0] >= 0.0 && l[0] <= 1.0 && l[1] >= 0.0 && l[1] <= 1.0 && l[2] >= 0.0 && l[2] <= 1.0) {
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
    out.slice.push(k);
    out.tex.push(tex);
}

/// `radial_u(tex) ≤ 1` (or NaN) without waiting for the square root: a correctly rounded
/// `sqrt(q)` exceeds 1 exactly when `q ≥ 1 + 2⁻²²`, i.e. `q > 1 + 2⁻²³`.
#[inline(always)]
pub(super) fn in_unit_cylinder(tex: V3) -> bool {
    let q = tex[0] * tex[0] + tex[1] * tex[1];
    q.is_nan() || q <= 1.0 + f32::EPSILON
}

/// A texture-space tolerance as per-component local-coordinate tolerances of `fire`'s
/// cells (`tex_x = 2a − 1`, `tex_z = (j + s) / cells`).
pub(super) fn local_tol(fire: &FireInstance, tex_tol: f32) -> V3 {
    let cells = fire.lattice.cells().len() as f32;
    [0.5 * tex_tol, 0.5 * tex_tol, cells * tex_tol]
}
