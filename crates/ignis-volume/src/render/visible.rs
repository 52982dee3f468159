//! Where in each lattice cell a sample can be visible: a sample elsewhere gets exactly zero
//! alpha (the profile column has no alpha within reach of its height for any turbulence
//! within the noise's proven bound), so the fast paths march only these parts.

use super::march_cells::OWNER_SLACK;
use super::{FireInstance, INVERSE_TEX_TOL};
use crate::lattice::V3;
use crate::mapping::{kernel, LoopMix, NoiseParams};

/// `rem[o]`: a bound on `|Σ_{i ≥ o} gain^i · noise|` (the octaves from `o` on), with a
/// relative margin for rounding; `rem[octaves] = 0`.
pub(super) fn turbulence_bounds(noise: &NoiseParams) -> [f32; 9] {
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
pub(super) struct VisiblePart {
    /// World bounding box of that part; empty (`min > max`) if there is none.
    pub(super) min: V3,
    pub(super) max: V3,
    /// For a nearly affine cell, a tighter description (used instead of the box).
    pub(super) disc: Option<AffineDisc>,
}

/// The part of a nearly affine cell where a visible sample can lie, through the cell's
/// affine inverse model ([`crate::lattice::Cell::affine_inverse`]): with
/// `(x_a, x_b, x_s) = M (p − F(c))` (`l − ½` up to the model's error),
/// `x_a² + x_b² ≤ r2` and `|x_s| ≤ h`. All in `f64`.
#[derive(Clone, Copy, Debug)]
pub(super) struct AffineDisc {
    /// Rows of `M`.
    pub(super) m: [[f64; 3]; 3],
    /// `M (o − F(c))` for the camera position `o`.
    pub(super) alpha: [f64; 3],
    pub(super) r2: f64,
    pub(super) h: f64,
}

impl AffineDisc {
    /// The ray parameter interval (`t ≥ 1e-4`, slightly widened) in which the camera ray
    /// with direction `d` is in the region, if not empty: `x(t) = alpha + t M d`, one
    /// linear and one quadratic inequality in `t`.
    #[inline(always)]
    pub(super) fn interval(&self, d: V3) -> Option<(f32, f32)> {
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

    /// The pixel row whose rays have directions `d = forward + sx · right + sy · up` (the camera
    /// basis): the interval of `sx` outside which a ray misses the region's infinite
    /// elliptic cylinder `x_a² + x_b² ≤ r2` — `None` if every ray of the row does. Along
    /// the row `M d = b₀ + sx b₁`; the line `alpha + t M d` comes within the cylinder when
    /// `(A × B)² ≤ r2 |B|²` (`A`, `B` the `a, b` parts of `alpha`, `M d`, the condition
    /// [`AffineDisc::interval`]'s discriminant tests), a quadratic `Q(sx) ≤ 0`. When `Q` opens
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
    pub(super) fn row_span(&self, forward: V3, right: V3, up: V3, sy: f32) -> Option<(f64, f64)> {
        let m = &self.m;
        let row = |v: V3| {
            [0, 1, 2].map(|i| m[i][0] * v[0] as f64 + m[i][1] * v[1] as f64 + m[i][2] * v[2] as f64)
        };
        let (f, u, b1) = (row(forward), row(up), row(right));
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
    pub(super) fn contains(&self, p: V3, o: V3) -> bool {
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
/// ([`TurbulenceWindow`] with no octave summed yet; otherwise its alpha is exactly zero and it adds
/// nothing to any blend), and only if `u ≤ 1`. Over the cell's height range that holds
/// only for `u ≤ reach`. The box: the trilinear image of the sub-square
/// `|tex_x|, |tex_y| ≤ reach` lies in the convex hull of its 8 corners, whose bounding box
/// it is. The disc, for nearly affine cells: a visible sample has `l ∈ [0, 1]³` and
/// `√((a − ½)² + (b − ½)²) ≤ reach / 2`, so its affine estimate lies within the model's
/// error of that. Margins far above the inverse's error ([`INVERSE_TEX_TOL`]) and `f32`
/// rounding keep every sample the shading would keep.
///
/// Both extend [`OWNER_SLACK`] beyond the cell's end faces in `s` (`s ∈ [−σ, 1 + σ]`), so
/// they also hold every sample the per-cell march ([`FrameRenderer::march_cells`]) assigns to the
/// cell (whose computed `s` may be off by the certified inverse's error).
///
/// `mix`: a looping render's [`LoopMix`], whose turbulence is bounded by `(a + b)` times
/// the bound of one copy.
pub(super) fn visible_parts(
    fire: &FireInstance,
    camera: V3,
    full: bool,
    mix: Option<LoopMix>,
) -> Vec<VisiblePart> {
    let cells = fire.lattice.cells();
    let whole = |c: &crate::lattice::Cell| VisiblePart {
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
                return VisiblePart {
                    min: [f32::INFINITY; 3],
                    max: [f32::NEG_INFINITY; 3],
                    disc: None,
                };
            };
            let reach = ((i + 1) as f32 / (w - 1) as f32).min(1.0) + 2e-3;
            let disc = c.affine_inverse().map(|aff| {
                let rel = [0, 1, 2].map(|i| camera[i] as f64 - aff.centre[i]);
                let radius = 0.5 * reach as f64 + aff.err[0].hypot(aff.err[1]) + 1e-3;
                AffineDisc {
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
            VisiblePart {
                min: lo,
                max: hi,
                disc,
            }
        })
        .collect()
}
