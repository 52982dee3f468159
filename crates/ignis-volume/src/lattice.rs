//! The deformation lattice around the centre curve.
//!
//! Source: fuller-procedural-volumetric-fire.txt §3.1 and Figure 9. For each control point
//! `P_i` the curve's velocity `V_i` and normal `N_i` are sampled at `t = i/(n−1)`; a square
//! of side `2r_i` centred on `P_i`, in the plane normal to `V_i` and aligned to `N_i`, gives
//! the `i`-th control points of four corner curves. The centre curve is sampled `c` times
//! by arc length; the same `t` values on the corner curves give `c` levels of four corners,
//! i.e. `c − 1` hexahedral cells.
//!
//! Departures from the paper:
//! - `N_i` is a rotation-minimising (parallel-transported) normal rather than the Frenet
//!   normal, which is undefined on straight pieces and flips at inflections; this is what
//!   "aligned to the normals to reduce twist" needs.
//! - Texture coordinates are `(x, y, z)` with `z = level/(c−1)` the height (eq. 11–13 use
//!   `tex_z` as the height), `x, y ∈ {−1, 1}` from the corner curve.
//! - The GPU interpolates texture coordinates across triangles; the CPU renderer instead
//!   inverts each cell's trilinear map (Newton), which is the exact inverse of the forward
//!   map [`Cell::forward`].
//!
//! Inverting a cell's map (world point → local coordinates), plain first:
//! - [`Cell::inverse`]: Newton's method from a guess; the public one.
//! - `inverse_fast`: chord steps with the centre's inverse Jacobian, then Newton; the
//!   renderer's reference path (`render/reference.rs`).
//! - `inverse_certified` (one point from a guess) and `inverse_certified_lanes` (eight
//!   points from the centre; `inverse_chord_certified` is one point with the same bits,
//!   `inverse_certified_lanes_avx2` the same bits with AVX2 intrinsics): chord steps
//!   accepted only with a proven error bound; the fast paths' inverse.
//! - `inverse_tracked`: chord steps with the Jacobian of a ray's last Newton solve, else
//!   Newton; where the certified one gives no answer.
//!
//! All but [`Cell::inverse`] are the renderer's (crate-private). The tests check them
//! against an `f64` Newton inverse (`inverse_undoes_forward`,
//! `certified_inverse_error_bound`) and the AVX2 lanes against the portable ones, bit for
//! bit.

use crate::error::{Result, VolumeError};
use crate::spline::BSpline;

pub(crate) type V3 = [f32; 3];

/// Points per call of [`Cell::inverse_certified_lanes`].
pub(crate) const CHORD_LANES: usize = 8;

#[inline(always)]
pub(crate) fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
#[inline(always)]
pub(crate) fn add(a: V3, b: V3) -> V3 {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}
#[inline(always)]
pub(crate) fn scale(a: V3, s: f32) -> V3 {
    [a[0] * s, a[1] * s, a[2] * s]
}
#[inline(always)]
pub(crate) fn dot(a: V3, b: V3) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
#[inline(always)]
pub(crate) fn cross(a: V3, b: V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
#[inline(always)]
pub(crate) fn norm(a: V3) -> f32 {
    dot(a, a).sqrt()
}
pub(crate) fn normalize(a: V3) -> Option<V3> {
    let n = norm(a);
    (n > 1e-12 && n.is_finite()).then(|| scale(a, 1.0 / n))
}

/// Texture-space corners of a square: index bit 0 → x = ±1, bit 1 → y = ±1.
const CORNER_XY: [[f32; 2]; 4] = [[-1.0, -1.0], [1.0, -1.0], [-1.0, 1.0], [1.0, 1.0]];

/// One lattice section: a hexahedron with a trilinear map from `(a, b, s) ∈ [0, 1]³` to
/// world space (`a = (x+1)/2`, `b = (y+1)/2`, `s` the fraction between its two levels).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cell {
    /// Polynomial coefficients: `P = k0 + k1 a + k2 b + k3 s + k4 ab + k5 as + k6 bs + k7 abs`.
    k: [V3; 8],
    /// World-space bounding box (the hull of the 8 corners contains the cell).
    pub min: V3,
    pub max: V3,
    /// Level index of the bottom face.
    pub level: usize,
    /// Inverse Jacobian at the cell centre (rows), for the chord-method inverse.
    jinv: [V3; 3],
    /// `(|k4| + |k5| + |k6| + 4|k7|) / 4`: bounds the second-order remainder of the map,
    /// `|F(l + Δ) − F(l) − J(l) Δ| ≤ nonlin · ‖Δ‖₁²` for `l` in the unit cube and
    /// `‖Δ‖₁ ≤ 1`, which tells [`Cell::inverse_predicted`] when one Newton step suffices.
    nonlin: f32,
    /// World position of the cell centre, `forward([½, ½, ½])`.
    centre: V3,
    /// `k` padded to four components (the 4th zero), for [`Cell::forward4`].
    k4: [[f32; 4]; 8],
    /// The certificate of [`Cell::inverse_certified`], when the cell is nearly affine.
    cert: Option<Certificate>,
}

/// What [`Cell::inverse_certified`] needs: the centre's inverse Jacobian `M` and the
/// error-propagation matrices of the chord iteration `G(l) = l − M (F(l) − p)` on the box
/// [`Cell::CERT_BOX`] (all 3×3, stored as columns padded to four lanes).
///
/// `K ≥ |I − M J(l)|` entry by entry for every `l` in the box (`J` the Jacobian of the
/// trilinear map `F`); `Q = K (I − K)⁻¹`, which exists and is ≥ 0 because the spectral
/// radius of `K` is below 1 (checked when the cell is built: for the non-negative `K`,
/// `(I − K)⁻¹ ≥ 0` holds exactly when it is).
#[derive(Clone, Copy, Debug, PartialEq)]
struct Certificate {
    m: [[f32; 4]; 3],
    q: [[f32; 4]; 3],
    /// `F(c)`, the world position of the centre `c = (½, ½, ½)`.
    centre: V3,
    /// `M w` for the nonlinear terms of the map about the centre: with `x = l − c`,
    /// `F(l) = F(c) + J(c) x + x_a x_b w4 + x_a x_s w5 + x_b x_s w6 + x_a x_b x_s w7`
    /// (`w4 = k4 + ½k7`, `w5 = k5 + ½k7`, `w6 = k6 + ½k7`, `w7 = k7`), so the chord map
    /// is `G(l) = l − M (F(l) − p) = c + M (p − F(c)) − Σ (products of x) · M w`.
    n: [[f32; 4]; 4],
}

/// See [`Cell::affine_inverse`]: `l ≈ ½ + M (p − centre)` within `err` per component.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct AffineInverse {
    /// Rows of `M`, the inverse Jacobian at the cell centre.
    pub m: [[f64; 3]; 3],
    /// World position of the cell centre.
    pub centre: [f64; 3],
    /// Bound on the model's error in `a`, `b`, `s` for points of the cell.
    pub err: [f64; 3],
}

/// What a ray carries from one [`Cell::inverse_tracked`] to the next: the inverse
/// Jacobian of its last Newton solve, as columns padded to four lanes (`None` before the
/// first solve or after a failed one).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Track {
    m: Option<[[f32; 4]; 3]>,
}

impl Cell {
    /// A cell from its 8 corners, indexed `ia + 2 ib + 4 is`.
    pub fn from_corners(c: [V3; 8], level: usize) -> Cell {
        let k0 = c[0];
        let k1 = sub(c[1], c[0]);
        let k2 = sub(c[2], c[0]);
        let k3 = sub(c[4], c[0]);
        let k4 = add(sub(c[3], c[1]), sub(c[0], c[2]));
        let k5 = add(sub(c[5], c[1]), sub(c[0], c[4]));
        let k6 = add(sub(c[6], c[2]), sub(c[0], c[4]));
        let k7 = sub(
            add(add(c[7], c[1]), add(c[2], c[4])),
            add(add(c[3], c[5]), add(c[6], c[0])),
        );
        let mut min = c[0];
        let mut max = c[0];
        for p in &c[1..] {
            for i in 0..3 {
                min[i] = min[i].min(p[i]);
                max[i] = max[i].max(p[i]);
            }
        }
        let mut cell = Cell {
            k: [k0, k1, k2, k3, k4, k5, k6, k7],
            min,
            max,
            level,
            jinv: [[0.0; 3]; 3],
            nonlin: (norm(k4) + norm(k5) + norm(k6) + 4.0 * norm(k7)) / 4.0,
            centre: [0.0; 3],
            k4: [k0, k1, k2, k3, k4, k5, k6, k7].map(|v| [v[0], v[1], v[2], 0.0]),
            cert: None,
        };
        cell.centre = cell.forward([0.5; 3]);
        let (ja, jb, js) = cell.jacobian([0.5; 3]);
        let det = dot(ja, cross(jb, js));
        if det.abs() > 1e-20 && det.is_finite() {
            let inv = 1.0 / det;
            // rows of J⁻¹ are the cross products of the columns divided by det
            cell.jinv = [
                scale(cross(jb, js), inv),
                scale(cross(js, ja), inv),
                scale(cross(ja, jb), inv),
            ];
            cell.cert = cell.certificate();
        }
        cell
    }

    /// Builds the [`Certificate`] from the centre's inverse Jacobian `M = jinv`, or `None`
    /// when the chord iteration is not a strong enough contraction on [`Cell::CERT_BOX`].
    ///
    /// With `l = c + (α, β, σ)`, `c = (½, ½, ½)`, the Jacobian columns of the trilinear map
    /// are, exactly,
    /// `J_a(l) − J_a(c) = β (k4 + ½k7) + σ (k5 + ½k7) + βσ k7`,
    /// `J_b(l) − J_b(c) = α (k4 + ½k7) + σ (k6 + ½k7) + ασ k7`,
    /// `J_s(l) − J_s(c) = α (k5 + ½k7) + β (k6 + ½k7) + αβ k7`,
    /// and `I − M J(l) = −M (J(l) − J(c))` since `M = J(c)⁻¹`. On the box `|α|, |β|, |σ| ≤ h`,
    /// so e.g. `|(I − M J(l))_{r,a}| ≤ h |M(k4 + ½k7)|_r + h |M(k5 + ½k7)|_r + h² |M k7|_r`:
    /// that is `K`, plus `|I − M J(c)|` since the stored `M` is `J(c)⁻¹` rounded to `f32`.
    /// Computed in `f64` and rounded up by a relative 1e-3 plus 1e-6 (far above the
    /// rounding of these few products).
    fn certificate(&self) -> Option<Certificate> {
        let h = 0.5 + Self::CERT_BOX as f64;
        let k = self.k.map(|v| v.map(|x| x as f64));
        let m = self.jinv.map(|r| r.map(|x| x as f64));
        let mv = |v: [f64; 3]| -> [f64; 3] {
            let mut o = [0.0; 3];
            for (r, row) in m.iter().enumerate() {
                o[r] = (row[0] * v[0] + row[1] * v[1] + row[2] * v[2]).abs();
            }
            o
        };
        let half7 = |v: [f64; 3]| {
            [
                v[0] + 0.5 * k[7][0],
                v[1] + 0.5 * k[7][1],
                v[2] + 0.5 * k[7][2],
            ]
        };
        let (u4, u5, u6, u7) = (mv(half7(k[4])), mv(half7(k[5])), mv(half7(k[6])), mv(k[7]));
        // columns a, b, s: the two first-order terms of each
        let cols = [(u4, u5), (u4, u6), (u5, u6)];
        // `M` is `J(c)⁻¹` rounded to `f32`: add `|I − M J(c)|` (a few 1e-7) to be exact
        let jc = [
            [0usize, 1, 4, 5], // J_a(c) = k1 + ½k4 + ½k5 + ¼k7
            [0, 2, 4, 6],      // J_b(c) = k2 + ½k4 + ½k6 + ¼k7
            [0, 3, 5, 6],      // J_s(c) = k3 + ½k5 + ½k6 + ¼k7
        ]
        .map(|[_, a, b, c]| {
            [0, 1, 2].map(|i| k[a][i] + 0.5 * (k[b][i] + k[c][i]) + 0.25 * k[7][i])
        });
        let mut kk = [[0.0f64; 3]; 3]; // kk[r][c]
        for (c, (x, y)) in cols.iter().enumerate() {
            for r in 0..3 {
                let mj: f64 = (0..3).map(|i| m[r][i] * jc[c][i]).sum();
                let e = (if r == c { 1.0 } else { 0.0 } - mj).abs();
                let v = h * x[r] + h * y[r] + h * h * u7[r] + e;
                kk[r][c] = v * (1.0 + 1e-3) + 1e-6;
            }
        }
        // (I − K)⁻¹ by cofactors; must be finite and ≥ 0 (spectral radius of K < 1)
        let a = [
            [1.0 - kk[0][0], -kk[0][1], -kk[0][2]],
            [-kk[1][0], 1.0 - kk[1][1], -kk[1][2]],
            [-kk[2][0], -kk[2][1], 1.0 - kk[2][2]],
        ];
        let c0 = [
            a[1][1] * a[2][2] - a[1][2] * a[2][1],
            a[1][2] * a[2][0] - a[1][0] * a[2][2],
            a[1][0] * a[2][1] - a[1][1] * a[2][0],
        ];
        let det = a[0][0] * c0[0] + a[0][1] * c0[1] + a[0][2] * c0[2];
        if !(det > 0.0 && det.is_finite()) {
            return None;
        }
        let mut inv = [[0.0f64; 3]; 3];
        for (i, row) in inv.iter_mut().enumerate() {
            for (j, v) in row.iter_mut().enumerate() {
                // inv[i][j] = cofactor(j, i) / det
                let (r1, r2) = ((j + 1) % 3, (j + 2) % 3);
                let (c1, c2) = ((i + 1) % 3, (i + 2) % 3);
                *v = (a[r1][c1] * a[r2][c2] - a[r1][c2] * a[r2][c1]) / det;
            }
        }
        // useful only for a clear contraction: (I − K)⁻¹ close to I
        if !inv.iter().flatten().all(|&v| v >= 0.0 && v.is_finite())
            || (0..3).any(|i| inv[i][i] > Self::CERT_MAX_GAIN)
        {
            return None;
        }
        // Q = K (I − K)⁻¹, rounded up
        let mut q = [[0.0f32; 4]; 3]; // columns
        for r in 0..3 {
            for c in 0..3 {
                let v: f64 = (0..3).map(|t| kk[r][t] * inv[t][c]).sum();
                q[c][r] = (v * (1.0 + 1e-3) + 1e-9) as f32;
            }
        }
        let mut mc = [[0.0f32; 4]; 3];
        for (c, col) in mc.iter_mut().enumerate() {
            for (r, row) in self.jinv.iter().enumerate() {
                col[r] = row[c];
            }
        }
        let mw = |v: [f64; 3]| -> [f32; 4] {
            let mut o = [0.0f32; 4];
            for (r, row) in m.iter().enumerate() {
                o[r] = (row[0] * v[0] + row[1] * v[1] + row[2] * v[2]) as f32;
            }
            o
        };
        let n = [mw(half7(k[4])), mw(half7(k[5])), mw(half7(k[6])), mw(k[7])];
        Some(Certificate {
            m: mc,
            q,
            centre: self.centre,
            n,
        })
    }

    /// A conservative affine model of the inverse map, for culling: every point
    /// `p = F(l)` of the cell (`l ∈ [0, 1]³`) has `|l − ½ − M (p − F(c))| ≤ err` per
    /// component, with `M` the inverse Jacobian at the centre `c = (½, ½, ½)`.
    ///
    /// From the expansion about the centre (see `Certificate`),
    /// `M (F(l) − F(c)) = M J(c) x + M N(x)` with `x = l − c`, `|x| ≤ ½` and
    /// `N(x) = x_a x_b w4 + x_a x_s w5 + x_b x_s w6 + x_a x_b x_s w7`, so the error is at most
    /// `½ |I − M J(c)| 1 + ¼ (|M w4| + |M w5| + |M w6|) + ⅛ |M w7|` (all in `f64` from the
    /// cell's exact `f32` coefficients, rounded up). `None` for a cell without a
    /// [`Certificate`]: not nearly affine, the bound would be of no use.
    pub(crate) fn affine_inverse(&self) -> Option<AffineInverse> {
        self.cert.as_ref()?;
        let k = self.k.map(|v| v.map(|x| x as f64));
        let comb = |w: &[(usize, f64)]| -> [f64; 3] {
            [0, 1, 2].map(|i| w.iter().map(|&(j, f)| f * k[j][i]).sum())
        };
        let centre = comb(&[
            (0, 1.0),
            (1, 0.5),
            (2, 0.5),
            (3, 0.5),
            (4, 0.25),
            (5, 0.25),
            (6, 0.25),
            (7, 0.125),
        ]);
        // Jacobian columns at the centre
        let ja = comb(&[(1, 1.0), (4, 0.5), (5, 0.5), (7, 0.25)]);
        let jb = comb(&[(2, 1.0), (4, 0.5), (6, 0.5), (7, 0.25)]);
        let js = comb(&[(3, 1.0), (5, 0.5), (6, 0.5), (7, 0.25)]);
        let cross = |a: [f64; 3], b: [f64; 3]| {
            [
                a[1] * b[2] - a[2] * b[1],
                a[2] * b[0] - a[0] * b[2],
                a[0] * b[1] - a[1] * b[0],
            ]
        };
        let dot = |a: [f64; 3], b: [f64; 3]| a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
        let det = dot(ja, cross(jb, js));
        if !(det.abs() > 1e-30 && det.is_finite()) {
            return None;
        }
        let m = [cross(jb, js), cross(js, ja), cross(ja, jb)].map(|r| r.map(|v| v / det));
        let absm = |v: [f64; 3]| [0, 1, 2].map(|r| dot(m[r], v).abs());
        let w4 = absm(comb(&[(4, 1.0), (7, 0.5)]));
        let w5 = absm(comb(&[(5, 1.0), (7, 0.5)]));
        let w6 = absm(comb(&[(6, 1.0), (7, 0.5)]));
        let w7 = absm(k[7]);
        let cols = [ja, jb, js];
        let err = [0, 1, 2].map(|r| {
            let id: f64 = (0..3)
                .map(|c| (dot(m[r], cols[c]) - if r == c { 1.0 } else { 0.0 }).abs())
                .sum();
            let e = 0.5 * id + 0.25 * (w4[r] + w5[r] + w6[r]) + 0.125 * w7[r];
            e * (1.0 + 1e-6) + 1e-9
        });
        Some(AffineInverse { m, centre, err })
    }

    /// Half-margin of the box `[−CERT_BOX, 1 + CERT_BOX]³` (local coordinates) on which
    /// the [`Certificate`] bounds the chord iteration.
    const CERT_BOX: f32 = 0.25;

    /// Largest diagonal entry of `(I − K)⁻¹` for which a cell gets a [`Certificate`]
    /// (beyond it the chord steps would rarely be accepted anyway).
    const CERT_MAX_GAIN: f64 = 2.0;

    /// Whether the cell has a [`Certificate`] (nearly affine: [`Cell::inverse_certified`]
    /// can answer).
    #[cfg(test)]
    fn certified(&self) -> bool {
        self.cert.is_some()
    }

    /// Chord steps `l ← G(l) = l − M (F(l) − p)` from `guess` with the centre's inverse
    /// Jacobian `M`, each with a proven error bound; returns `Ok` with the first iterate
    /// whose bound is within `tol` (per local component), or `Err` when there is no
    /// certificate, the bound is not met within 3 steps, or the box below leaves `D` —
    /// then the caller uses another method. In the last case `Err(Some(l))` reports an
    /// uncertified iterate lying well beyond a face `s = 0` or `s = 1` (by 0.05 plus the
    /// bound it would have), which the renderer uses to stop at the ends of the lattice.
    ///
    /// It runs in the centred form `G(l) = c + M (p − F(c)) − M N(l − c)` (see
    /// `Certificate`): the same map, with the product by `M` done once per point.
    ///
    /// The bound (componentwise, `|·|` of vectors taken entry by entry): on the box `D`,
    /// `|G(x) − G(y)| ≤ K |x − y|` (mean value theorem: `G(x) − G(y) = (I − M J̄)(x − y)`
    /// with `J̄` the mean of `J` on the segment, and `K` bounds `|I − M J|` on `D`). Let
    /// `δ = l − G(l)` be a step and `ρ = (I − K)⁻¹ |δ| = |δ| + Q |δ|`. If the box
    /// `B = {x : |x − l| ≤ ρ}` lies in `D`, then `G` maps `B` into itself
    /// (`|G(x) − l| ≤ K ρ + |δ| = ρ`), so `B` holds a fixed point `l*` (Brouwer), which is
    /// the only one in `D` (two would satisfy `|l* − l**| ≤ K |l* − l**|`, impossible for
    /// a non-zero vector since `(I − K)⁻¹ ≥ 0`), and `F(l*) = p` since `M` is invertible.
    /// Then `|G(l) − l*| ≤ K |l − l*| ≤ K ρ = Q |δ|`: the accepted iterate is within
    /// `Q |δ| ≤ tol` of the exact inverse, in exact arithmetic. In `f32`, `p − F(c)` is
    /// rounded (≈ 1e-7 relative to the coordinates), which adds about `|M| · 1e-7 · |p|` —
    /// below 1e-6 in `a, b` and 1e-5 in `s` for the Table 1 lattice, i.e. ≲ 5e-7 in
    /// texture space (the test `certified_inverse_error_bound` checks the total against
    /// an `f64` inverse).
    #[inline(always)]
    pub(crate) fn inverse_certified(
        &self,
        p: V3,
        guess: V3,
        tol: V3,
    ) -> std::result::Result<V3, Option<V3>> {
        let Some(c) = self.cert.as_ref() else {
            return Err(None);
        };
        // G(l) = c + q − M N(l − c) (see `Certificate`): q depends on p only
        let mut q = [0.0f32; 4];
        {
            let d = [p[0] - c.centre[0], p[1] - c.centre[1], p[2] - c.centre[2]];
            for (i, qi) in q.iter_mut().enumerate() {
                *qi = c.m[0][i] * d[0] + c.m[1][i] * d[1] + c.m[2][i] * d[2];
            }
        }
        let mut x = [guess[0] - 0.5, guess[1] - 0.5, guess[2] - 0.5, 0.0];
        for _ in 0..3 {
            let (ab, as_, bs) = (x[0] * x[1], x[0] * x[2], x[1] * x[2]);
            let abs = ab * x[2];
            let n = &c.n;
            let mut nx = [0.0f32; 4];
            let mut ad = [0.0f32; 4];
            for i in 0..4 {
                // the new iterate, as an offset from the centre
                nx[i] = q[i] - ((ab * n[0][i] + as_ * n[1][i]) + (bs * n[2][i] + abs * n[3][i]));
                ad[i] = (x[i] - nx[i]).abs();
            }
            let mut err = [0.0f32; 4];
            for (i, e) in err.iter_mut().enumerate() {
                *e = c.q[0][i] * ad[0] + c.q[1][i] * ad[1] + c.q[2][i] * ad[2];
            }
            // the box B around l (radius ρ = |δ| + Q|δ|) must lie in D (NaN fails too)
            let mut inside = true;
            let mut ok = true;
            for i in 0..3 {
                let rho = ad[i] + err[i];
                inside &=
                    x[i] - rho >= -(0.5 + Self::CERT_BOX) && x[i] + rho <= 0.5 + Self::CERT_BOX;
                ok &= err[i] <= tol[i];
            }
            x = nx;
            if !inside {
                // no certificate; but a point well beyond this cell's faces in `s` (the
                // iterate outside by 0.05 plus the error bound it would have were the
                // contraction to extend that far) is reported as such
                let l = [x[0] + 0.5, x[1] + 0.5, x[2] + 0.5];
                let far = 0.05 + err[2];
                return Err((l[2] < -far || l[2] > 1.0 + far).then_some(l));
            }
            if ok {
                return Ok([x[0] + 0.5, x[1] + 0.5, x[2] + 0.5]);
            }
        }
        Err(None)
    }

    /// [`Cell::inverse_certified`] on [`CHORD_LANES`] points at once, each started from
    /// the chord step from the centre (`l₀ − ½ = M (p − F(c))`, exact for an affine
    /// cell): the same iteration and the same proven acceptance test, lane by lane.
    /// Returns the local coordinates and, per lane, whether the bound was met (`false`:
    /// no certificate, not met within 3 steps, or the box left `D`; that lane's
    /// coordinates are then meaningless). A lane's result depends on its own point only,
    /// so [`Cell::inverse_chord_certified`] (one point) gives the same bits.
    #[inline(always)]
    pub(crate) fn inverse_certified_lanes(
        &self,
        p: &[[f32; CHORD_LANES]; 3],
        tol: V3,
    ) -> ([[f32; CHORD_LANES]; 3], [bool; CHORD_LANES]) {
        const L: usize = CHORD_LANES;
        let mut done = [false; L];
        let Some(c) = self.cert.as_ref() else {
            return ([[0.0; L]; 3], done);
        };
        let mut q = [[0.0f32; L]; 3];
        for (i, qi) in q.iter_mut().enumerate() {
            for l in 0..L {
                let d = [
                    p[0][l] - c.centre[0],
                    p[1][l] - c.centre[1],
                    p[2][l] - c.centre[2],
                ];
                qi[l] = c.m[0][i] * d[0] + c.m[1][i] * d[1] + c.m[2][i] * d[2];
            }
        }
        let mut x = q;
        let mut out = [[0.0f32; L]; 3];
        let mut live = [true; L];
        let lim = 0.5 + Self::CERT_BOX;
        for _ in 0..3 {
            let mut next_live = [false; L];
            for l in 0..L {
                let (xa, xb, xs) = (x[0][l], x[1][l], x[2][l]);
                let (ab, as_, bs) = (xa * xb, xa * xs, xb * xs);
                let abs = ab * xs;
                let n = &c.n;
                let mut nx = [0.0f32; 3];
                let mut ad = [0.0f32; 3];
                for i in 0..3 {
                    nx[i] =
                        q[i][l] - ((ab * n[0][i] + as_ * n[1][i]) + (bs * n[2][i] + abs * n[3][i]));
                    ad[i] = (x[i][l] - nx[i]).abs();
                }
                let mut inside = true;
                let mut ok = true;
                for i in 0..3 {
                    let err = c.q[0][i] * ad[0] + c.q[1][i] * ad[1] + c.q[2][i] * ad[2];
                    let rho = ad[i] + err;
                    inside &= x[i][l] - rho >= -lim && x[i][l] + rho <= lim;
                    ok &= err <= tol[i];
                }
                let accept = live[l] && inside && ok;
                for i in 0..3 {
                    if accept {
                        out[i][l] = nx[i] + 0.5;
                    }
                    if live[l] {
                        x[i][l] = nx[i];
                    }
                }
                done[l] |= accept;
                next_live[l] = live[l] && inside && !ok;
            }
            live = next_live;
            if !live.iter().any(|&v| v) {
                break;
            }
        }
        (out, done)
    }

    /// [`Cell::inverse_certified_lanes`] written with AVX2 intrinsics (LLVM keeps the
    /// portable version's per-lane conditional updates scalar): the same `f32` operations
    /// in the same order, lane by lane, so the same bits (tested).
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    #[inline]
    pub(crate) unsafe fn inverse_certified_lanes_avx2(
        &self,
        p: &[[f32; CHORD_LANES]; 3],
        tol: V3,
    ) -> ([[f32; CHORD_LANES]; 3], [bool; CHORD_LANES]) {
        use std::arch::x86_64::*;
        const L: usize = CHORD_LANES;
        let Some(c) = self.cert.as_ref() else {
            return ([[0.0; L]; 3], [false; L]);
        };
        let set = |v: f32| _mm256_set1_ps(v);
        let mul = |a, b| _mm256_mul_ps(a, b);
        let add = |a, b| _mm256_add_ps(a, b);
        let sub = |a, b| _mm256_sub_ps(a, b);
        let d = [0, 1, 2].map(|a| sub(_mm256_loadu_ps(p[a].as_ptr()), set(c.centre[a])));
        let q = [0, 1, 2].map(|i| {
            add(
                add(mul(set(c.m[0][i]), d[0]), mul(set(c.m[1][i]), d[1])),
                mul(set(c.m[2][i]), d[2]),
            )
        });
        let sign = set(-0.0);
        let (lim, nlim, half) = (
            set(0.5 + Self::CERT_BOX),
            set(-(0.5 + Self::CERT_BOX)),
            set(0.5),
        );
        let mut x = q;
        let mut out = [_mm256_setzero_ps(); 3];
        let mut live = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
        let mut done = _mm256_setzero_ps();
        let n = &c.n;
        for _ in 0..3 {
            let ab = mul(x[0], x[1]);
            let (as_, bs) = (mul(x[0], x[2]), mul(x[1], x[2]));
            let abs = mul(ab, x[2]);
            let nx = [0, 1, 2].map(|i| {
                sub(
                    q[i],
                    add(
                        add(mul(ab, set(n[0][i])), mul(as_, set(n[1][i]))),
                        add(mul(bs, set(n[2][i])), mul(abs, set(n[3][i]))),
                    ),
                )
            });
            let ad = [0, 1, 2].map(|i| _mm256_andnot_ps(sign, sub(x[i], nx[i])));
            let mut inside = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
            let mut ok = inside;
            for i in 0..3 {
                let err = add(
                    add(mul(set(c.q[0][i]), ad[0]), mul(set(c.q[1][i]), ad[1])),
                    mul(set(c.q[2][i]), ad[2]),
                );
                let rho = add(ad[i], err);
                let lo = _mm256_cmp_ps::<_CMP_GE_OQ>(sub(x[i], rho), nlim);
                let hi = _mm256_cmp_ps::<_CMP_LE_OQ>(add(x[i], rho), lim);
                inside = _mm256_and_ps(inside, _mm256_and_ps(lo, hi));
                ok = _mm256_and_ps(ok, _mm256_cmp_ps::<_CMP_LE_OQ>(err, set(tol[i])));
            }
            let accept = _mm256_and_ps(live, _mm256_and_ps(inside, ok));
            for i in 0..3 {
                out[i] = _mm256_blendv_ps(out[i], add(nx[i], half), accept);
                x[i] = _mm256_blendv_ps(x[i], nx[i], live);
            }
            done = _mm256_or_ps(done, accept);
            live = _mm256_and_ps(live, _mm256_andnot_ps(ok, inside));
            if _mm256_movemask_ps(live) == 0 {
                break;
            }
        }
        let mut res = [[0.0f32; L]; 3];
        for i in 0..3 {
            _mm256_storeu_ps(res[i].as_mut_ptr(), out[i]);
        }
        let bits = _mm256_movemask_ps(done);
        (res, std::array::from_fn(|l| bits & (1 << l) != 0))
    }

    /// [`Cell::inverse_certified_lanes`] for one point: within `tol` of the exact inverse
    /// (proven) or `None`. The same bits as the lanes version gives for `p`.
    pub(crate) fn inverse_chord_certified(&self, p: V3, tol: V3) -> Option<V3> {
        let (l, ok) = self.inverse_certified_lanes(
            &[
                [p[0]; CHORD_LANES],
                [p[1]; CHORD_LANES],
                [p[2]; CHORD_LANES],
            ],
            tol,
        );
        ok[0].then_some([l[0][0], l[1][0], l[2][0]])
    }

    /// Jacobian columns d/da, d/db, d/ds at local coordinates `l`.
    #[inline(always)]
    fn jacobian(&self, l: V3) -> (V3, V3, V3) {
        let [a, b, s] = l;
        let k = &self.k;
        let mut ja = [0.0; 3];
        let mut jb = [0.0; 3];
        let mut js = [0.0; 3];
        for i in 0..3 {
            ja[i] = k[1][i] + b * k[4][i] + s * k[5][i] + b * s * k[7][i];
            jb[i] = k[2][i] + a * k[4][i] + s * k[6][i] + a * s * k[7][i];
            js[i] = k[3][i] + a * k[5][i] + b * k[6][i] + a * b * k[7][i];
        }
        (ja, jb, js)
    }

    /// Like [`Cell::inverse`] but first tries the chord method (the centre's inverse
    /// Jacobian, exact in one step for an affine cell, cheap for nearly affine ones), and
    /// falls back to Newton's method.
    #[inline(always)]
    pub(crate) fn inverse_fast(&self, p: V3, guess: V3) -> Option<V3> {
        let mut l = guess;
        let m = &self.jinv;
        for _ in 0..4 {
            let f = sub(self.forward(l), p);
            let d = [dot(m[0], f), dot(m[1], f), dot(m[2], f)];
            l = [l[0] - d[0], l[1] - d[1], l[2] - d[2]];
            if d[0].abs() + d[1].abs() + d[2].abs() < 1e-5 {
                return Some(l);
            }
            if !l.iter().all(|v| v.abs() < 1e3) {
                break;
            }
        }
        self.inverse(p, guess)
    }

    /// The renderer's inverse for a good `guess` (extrapolated from the previous ray
    /// samples): Newton's method with the exact Jacobian, stopping once a step is below
    /// [`Cell::FAST_STEP`] — convergence is quadratic, so the error left is of the order of
    /// the step squared (≪ 1e-4) — or once the error bound after the step is below
    /// [`Cell::NEWTON_TOL`]. `None` when it does not converge.
    ///
    /// The bound: Newton's error after a step `δ` from `l` is `J(l)⁻¹ R` with `R` the
    /// second-order Taylor remainder of the trilinear map, `|R| ≤ nonlin · ‖Δ‖₁²` (`Δ` the
    /// distance to the root, ≈ `δ`), so `|error| ≤ ‖J(l)⁻¹‖_F · nonlin · δ²`. For the
    /// nearly affine cells of a gently bent fire `nonlin` is small and the first step is
    /// already accurate, which saves the confirming second step.
    #[inline(always)]
    #[cfg(test)]
    fn inverse_predicted(&self, p: V3, guess: V3) -> Option<V3> {
        match self.newton(p, guess) {
            Ok((l, _)) => Some(l),
            Err(true) => self.inverse_fast(p, guess),
            Err(false) => None,
        }
    }

    /// [`Cell::inverse_predicted`] along a ray: `track` carries the inverse Jacobian from
    /// the last Newton solve on this ray (this cell or a neighbour: the lattice map is
    /// continuous, so its Jacobian changes little). With it, up to three chord steps
    /// `l ← l − m (F(l) − p)` (a forward evaluation and a 3×3 product each, about a third
    /// of a Newton step) are tried. The chord iteration contracts by `κ = ‖I − m J‖`; a
    /// step is accepted when it is below [`Cell::CHORD_STEP`] and less than half the
    /// previous one (so `κ < ½` is observed, and the error left is below the step). When
    /// the steps do not shrink fast enough, Newton runs from `guess` and refreshes `m`
    /// (or clears it when it falls back to the chord-from-centre method).
    #[inline(always)]
    pub(crate) fn inverse_tracked(&self, p: V3, guess: V3, track: &mut Track) -> Option<V3> {
        if let Some(mc) = &track.m {
            let p4 = [p[0], p[1], p[2], 0.0];
            let mut l = [guess[0], guess[1], guess[2], 0.0];
            let mut prev = f32::INFINITY;
            for _ in 0..3 {
                let fw = self.forward4([l[0], l[1], l[2]]);
                let mut d = [0.0f32; 4];
                for i in 0..4 {
                    d[i] = fw[i] - p4[i];
                }
                let mut dd = [0.0f32; 4];
                for i in 0..4 {
                    dd[i] = mc[0][i] * d[0] + mc[1][i] * d[1] + mc[2][i] * d[2];
                }
                for i in 0..4 {
                    l[i] -= dd[i];
                }
                let step = dd[0].abs() + dd[1].abs() + dd[2].abs();
                if step < Self::CHORD_STEP && step < 0.5 * prev {
                    return Some([l[0], l[1], l[2]]);
                }
                let shrinking = step < 0.25 * prev; // false for NaN too
                if !shrinking && prev.is_finite() {
                    break;
                }
                prev = step;
            }
        }
        match self.newton(p, guess) {
            Ok((l, jinv)) => {
                // columns of J⁻¹, padded to four lanes
                let mut mc = [[0.0f32; 4]; 3];
                for (c, col) in mc.iter_mut().enumerate() {
                    for (r, row) in jinv.iter().enumerate() {
                        col[r] = row[c];
                    }
                }
                track.m = Some(mc);
                Some(l)
            }
            Err(fallback) => {
                track.m = None;
                if fallback {
                    self.inverse_fast(p, guess)
                } else {
                    None
                }
            }
        }
    }

    /// [`Cell::forward`] with the 3 components padded to 4 (the 4th is 0), arranged so the
    /// components are computed side by side in one vector register.
    #[inline(always)]
    fn forward4(&self, l: V3) -> [f32; 4] {
        let [a, b, s] = l;
        let (ab, as_, bs) = (a * b, a * s, b * s);
        let abs = ab * s;
        let k = &self.k4;
        let mut p = [0.0; 4];
        // summed as a tree (depth 3) rather than left to right (depth 7): the chord
        // iteration is a chain of dependent operations, so latency is what counts
        for i in 0..4 {
            p[i] = ((k[0][i] + a * k[1][i]) + (b * k[2][i] + s * k[3][i]))
                + ((ab * k[4][i] + as_ * k[5][i]) + (bs * k[6][i] + abs * k[7][i]));
        }
        p
    }

    /// Acceptance threshold of the chord step in [`Cell::inverse_tracked`] (sum of |step|,
    /// local units).
    const CHORD_STEP: f32 = 1e-4;

    /// The Newton iteration of [`Cell::inverse_predicted`]: the root and the inverse
    /// Jacobian at the last iterate, or `Err(true)` when it did not settle in 6 steps
    /// (try the slower method) and `Err(false)` when it diverged or hit a singular point.
    #[inline(always)]
    fn newton(&self, p: V3, guess: V3) -> std::result::Result<(V3, [V3; 3]), bool> {
        let mut l = guess;
        for _ in 0..6 {
            let [a, b, s] = l;
            let f = sub(self.forward(l), p);
            let (ja, jb, js) = self.jacobian(l);
            // rows of det · J⁻¹
            let r0 = cross(jb, js);
            let r1 = cross(js, ja);
            let r2 = cross(ja, jb);
            let det = dot(ja, r0);
            if det.abs() < 1e-20 || !det.is_finite() {
                return Err(false);
            }
            let inv = 1.0 / det;
            let da = dot(f, r0) * inv;
            let db = dot(f, r1) * inv;
            let ds = dot(f, r2) * inv;
            l = [a - da, b - db, s - ds];
            let jinv = || [scale(r0, inv), scale(r1, inv), scale(r2, inv)];
            let step = da.abs() + db.abs() + ds.abs();
            if step < Self::FAST_STEP {
                return Ok((l, jinv()));
            }
            if step < 0.5 {
                // ‖J⁻¹‖_F² · (nonlin · step²)² < tol², with 1.5× slack on ‖Δ‖ ≈ step
                let jinv2 = (dot(r0, r0) + dot(r1, r1) + dot(r2, r2)) * inv * inv;
                let e = self.nonlin * 2.25 * step * step;
                if jinv2 * e * e < Self::NEWTON_TOL * Self::NEWTON_TOL {
                    return Ok((l, jinv()));
                }
            }
            if !l.iter().all(|v| v.abs() < 1e3) {
                return Err(false);
            }
        }
        Err(true)
    }

    /// A first guess of the local coordinates of `p` with no history: one chord step from
    /// the centre (exact for an affine cell). Not clamped; it may lie outside the cell.
    #[inline(always)]
    pub(crate) fn chord_guess(&self, p: V3) -> V3 {
        let f = sub(p, self.centre);
        let m = &self.jinv;
        [0.5 + dot(m[0], f), 0.5 + dot(m[1], f), 0.5 + dot(m[2], f)]
    }

    /// The local-coordinate change `J(c)⁻¹ v` of a world displacement `v` at the centre
    /// (exact for an affine cell).
    #[inline(always)]
    pub(crate) fn local_direction(&self, v: V3) -> V3 {
        let m = &self.jinv;
        [dot(m[0], v), dot(m[1], v), dot(m[2], v)]
    }

    /// Acceptance threshold of [`Cell::inverse_predicted`] (sum of |step| in local units).
    const FAST_STEP: f32 = 1e-3;

    /// Error bound (local units) below which [`Cell::inverse_predicted`] accepts a step.
    const NEWTON_TOL: f32 = 1e-5;

    /// World position of local coordinates `(a, b, s)`.
    #[inline(always)]
    pub fn forward(&self, l: V3) -> V3 {
        let [a, b, s] = l;
        let k = &self.k;
        let mut p = [0.0; 3];
        for i in 0..3 {
            p[i] = k[0][i]
                + a * k[1][i]
                + b * k[2][i]
                + s * k[3][i]
                + a * b * k[4][i]
                + a * s * k[5][i]
                + b * s * k[6][i]
                + a * b * s * k[7][i];
        }
        p
    }

    /// Local coordinates of world point `p` by Newton's method from `guess`; `None` when it
    /// does not converge (far outside a strongly bent cell). The result may lie outside
    /// `[0, 1]³`: the caller decides membership.
    #[inline(always)]
    pub fn inverse(&self, p: V3, guess: V3) -> Option<V3> {
        let mut l = guess;
        for _ in 0..8 {
            let [a, b, s] = l;
            let f = sub(self.forward(l), p);
            let (ja, jb, js) = self.jacobian(l);
            let det = dot(ja, cross(jb, js));
            if det.abs() < 1e-20 || !det.is_finite() {
                return None;
            }
            let inv = 1.0 / det;
            // Cramer's rule for J d = f
            let da = dot(f, cross(jb, js)) * inv;
            let db = dot(ja, cross(f, js)) * inv;
            let ds = dot(ja, cross(jb, f)) * inv;
            l = [a - da, b - db, s - ds];
            // Newton converges quadratically: after a step this small the error is ~1e-8.
            if da.abs() + db.abs() + ds.abs() < 1e-4 {
                return Some(l);
            }
            if l.iter().any(|v| v.abs() > 1e3 || !v.is_finite()) {
                return None;
            }
        }
        // accept if the residual is small even without the step criterion
        (norm(sub(self.forward(l), p)) < 1e-4).then_some(l)
    }
}

/// Settings for building a lattice.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LatticeParams {
    /// Number of levels `c` (the paper's lattice resolution), ≥ 2. Default 35.
    pub resolution: usize,
}

impl Default for LatticeParams {
    fn default() -> Self {
        LatticeParams { resolution: 35 }
    }
}

/// The lattice around one fire at one instant.
#[derive(Clone, Debug, PartialEq)]
pub struct Lattice {
    /// `c` levels of four corners, indexed as [`CORNER_XY`].
    levels: Vec<[V3; 4]>,
    /// Radius of the centre curve at each level (eq. 10's horizontal noise scale).
    radii: Vec<f32>,
    cells: Vec<Cell>,
    /// Arc length of the centre curve (eq. 10's vertical noise scale).
    length: f32,
    /// Union of the cells' bounding boxes.
    pub min: V3,
    pub max: V3,
}

/// The four corner curves of the lattice around `curve` (§3.1): per control point, a
/// square of side `2r` in the plane normal to the curve's velocity, aligned to its
/// parallel-transported normal; its corners become the corner curves' control points.
fn corner_curves(curve: &BSpline) -> Result<Vec<BSpline>> {
    let pts = curve.points();
    let n = pts.len();
    // frames at t = i/(n-1), parallel transported
    let mut corner_pts: [Vec<[f32; 4]>; 4] = Default::default();
    let mut prev_n: Option<V3> = None;
    let mut prev_v: V3 = [0.0, 0.0, 1.0];
    for (i, p) in pts.iter().enumerate() {
        let t = i as f32 / (n - 1) as f32;
        let d = curve.derivative(t);
        let v = normalize([d[0], d[1], d[2]]).unwrap_or(prev_v);
        let nrm = match prev_n {
            None => {
                // world x projected onto the plane normal to v (y if v ∥ x)
                let r = if v[0].abs() < 0.9 {
                    [1.0, 0.0, 0.0]
                } else {
                    [0.0, 1.0, 0.0]
                };
                normalize(sub(r, scale(v, dot(r, v)))).unwrap_or([1.0, 0.0, 0.0])
            }
            Some(pn) => normalize(sub(pn, scale(v, dot(pn, v)))).unwrap_or(pn),
        };
        let bin = normalize(cross(v, nrm)).unwrap_or([0.0, 1.0, 0.0]);
        prev_n = Some(nrm);
        prev_v = v;
        let r = p[3];
        for (k, xy) in CORNER_XY.iter().enumerate() {
            let off = add(scale(nrm, xy[0] * r), scale(bin, xy[1] * r));
            corner_pts[k].push([p[0] + off[0], p[1] + off[1], p[2] + off[2], r]);
        }
    }
    corner_pts
        .into_iter()
        .map(|cp| BSpline::new(cp, curve.degree()))
        .collect()
}

/// Puffing (Cetegen & Ahmed 1993) as a wave on a lattice: the flame necks and bulges
/// where a wave travelling up the flame passes, `radius · (1 − a · e(h) · sin(φ − 2π h))`
/// at height `h ∈ [0, 1]` (arc length over the curve's), with `a` the amplitude, `φ` the
/// phase (advancing `2π f t` at the puffing frequency `f`) and `e(h) = h` growing from
/// nothing at the base. One wavelength spans the flame, so a neck forms at the base, rises
/// and pinches the tip once a cycle, and the brightness of the flame's upper half swings at
/// `f`. Why a travelling wave rather than the whole flame stretching in step: a standing
/// oscillation changes the image by `|cos φ|` per frame (fast through the middle, still at
/// the turns), so the frame-to-frame steps of a loop spread by ±40 %; a travelling wave
/// moves every part of the flame in turn, and the image changes by about the same amount
/// every frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Puff {
    /// Relative amplitude `a` of the radius swing, `0..=0.5` (so the radius stays ≥ half).
    pub amplitude: f32,
    /// Phase `φ` in radians.
    pub phase: f32,
}

impl Puff {
    /// The radius factor at height `h ∈ [0, 1]`.
    pub fn factor(&self, h: f32) -> f32 {
        let h = h.clamp(0.0, 1.0);
        1.0 - self.amplitude * h * (self.phase - std::f32::consts::TAU * h).sin()
    }
}

/// Most basis values [`arc_basis`] keeps per table (64 K: 512 KB).
const ARC_BASIS_MAX: usize = 1 << 16;

/// An arc-length basis table ([`arc_basis`]) and its key: (points, degree, samples).
type ArcBasis = ((usize, usize, usize), std::rc::Rc<[f64]>);

thread_local! {
    /// [`arc_basis`]'s tables, most recent first.
    static ARC_BASIS: std::cell::RefCell<Vec<ArcBasis>> =
        const { std::cell::RefCell::new(Vec::new()) };
}

/// The basis of `curve` at the `dense + 1` parameters `k / dense` of the arc-length table
/// ([`Lattice::build_puffed`]), `n` values per parameter: the same for every curve of the
/// same number of points and degree (the knots depend on nothing else), so an animation
/// computes it once per thread rather than once per fire and frame (it was most of a
/// lattice build). `None` past [`ARC_BASIS_MAX`] values (the caller evaluates directly).
fn arc_basis(curve: &BSpline, dense: usize) -> Option<std::rc::Rc<[f64]>> {
    let n = curve.points().len();
    if (dense + 1).saturating_mul(n) > ARC_BASIS_MAX {
        return None;
    }
    let key = (n, curve.degree(), dense);
    ARC_BASIS.with(|c| {
        let mut c = c.borrow_mut();
        if let Some(i) = c.iter().position(|(k, _)| *k == key) {
            let hit = c.remove(i);
            c.insert(0, hit);
        } else {
            let table: std::rc::Rc<[f64]> = (0..=dense)
                .flat_map(|k| curve.basis((k as f32 / dense as f32) as f64))
                .collect();
            c.insert(0, (key, table));
            c.truncate(8);
        }
        Some(c[0].1.clone())
    })
}

impl Lattice {
    /// Builds the lattice of §3.1 around `curve` with `resolution` levels.
    pub fn build(curve: &BSpline, resolution: usize) -> Result<Lattice> {
        Lattice::build_puffed(curve, resolution, None)
    }

    /// [`Lattice::build`] with each level's square (and radius) scaled about the curve by
    /// `puff`'s factor at the level's height ([`Puff`]).
    pub fn build_puffed(curve: &BSpline, resolution: usize, puff: Option<Puff>) -> Result<Lattice> {
        if !(2..=4096).contains(&resolution) {
            return Err(VolumeError::bad(
                "render.lattice",
                format!("{resolution}; use 2 to 4096"),
            ));
        }
        let corners = corner_curves(curve)?;
        // arc-length table of the centre curve
        let dense = (resolution * 16).max(256);
        let mut ts = Vec::with_capacity(dense + 1);
        let mut lens = Vec::with_capacity(dense + 1);
        let table = arc_basis(curve, dense);
        let n = curve.points().len();
        let at = |k: usize, t: f32| match &table {
            Some(b) => curve.eval_with_basis(&b[k * n..(k + 1) * n]),
            None => curve.eval(t),
        };
        let mut last = at(0, 0.0);
        let mut acc = 0.0f64;
        for k in 0..=dense {
            let t = k as f32 / dense as f32;
            let p = at(k, t);
            acc += norm(sub([p[0], p[1], p[2]], [last[0], last[1], last[2]])) as f64;
            last = p;
            ts.push(t);
            lens.push(acc);
        }
        let total = acc;
        let t_at = |s: f64| -> f32 {
            if total <= 0.0 {
                return (s as f32).clamp(0.0, 1.0);
            }
            let target = s * total;
            let k = lens.partition_point(|&l| l < target).clamp(1, dense);
            let (l0, l1) = (lens[k - 1], lens[k]);
            let f = if l1 > l0 {
                ((target - l0) / (l1 - l0)) as f32
            } else {
                0.0
            };
            ts[k - 1] + f * (ts[k] - ts[k - 1])
        };
        let mut levels = Vec::with_capacity(resolution);
        let mut radii = Vec::with_capacity(resolution);
        for j in 0..resolution {
            let t = if total > 0.0 {
                t_at(j as f64 / (resolution - 1) as f64)
            } else {
                j as f32 / (resolution - 1) as f32
            };
            let mut lv = [[0.0; 3]; 4];
            for (k, c) in corners.iter().enumerate() {
                let q = c.eval(t);
                lv[k] = [q[0], q[1], q[2]];
            }
            let mut r = curve.eval(t)[3];
            if let Some(p) = puff.filter(|p| p.amplitude != 0.0) {
                let f = p.factor(j as f32 / (resolution - 1) as f32);
                // the corners' mean is the curve's point (their offsets cancel)
                let c = scale(add(add(lv[0], lv[1]), add(lv[2], lv[3])), 0.25);
                lv = lv.map(|q| add(c, scale(sub(q, c), f)));
                r *= f;
            }
            levels.push(lv);
            radii.push(r);
        }
        let cells: Vec<Cell> = (0..resolution - 1)
            .map(|j| {
                let (lo, hi) = (levels[j], levels[j + 1]);
                Cell::from_corners([lo[0], lo[1], lo[2], lo[3], hi[0], hi[1], hi[2], hi[3]], j)
            })
            .collect();
        let mut min = [f32::INFINITY; 3];
        let mut max = [f32::NEG_INFINITY; 3];
        for c in &cells {
            for i in 0..3 {
                min[i] = min[i].min(c.min[i]);
                max[i] = max[i].max(c.max[i]);
            }
        }
        Ok(Lattice {
            levels,
            radii,
            cells,
            length: total as f32,
            min,
            max,
        })
    }

    pub fn cells(&self) -> &[Cell] {
        &self.cells
    }
    /// The four corners of each level.
    pub fn levels(&self) -> &[[V3; 4]] {
        &self.levels
    }
    /// Number of levels `c`.
    pub fn resolution(&self) -> usize {
        self.levels.len()
    }
    /// Arc length of the centre curve.
    pub fn length(&self) -> f32 {
        self.length
    }
    /// Centre-curve radius at texture height `tex_z` (linear between levels).
    #[inline(always)]
    pub fn radius_at(&self, tex_z: f32) -> f32 {
        let c = self.levels.len();
        let x = (tex_z.clamp(0.0, 1.0)) * (c - 1) as f32;
        // (`x ∈ [0, c − 1]`, or NaN → 0 either way: the cheaper conversion via `i32`)
        let j = (x as i32 as usize).min(c - 2);
        let f = x - j as f32;
        self.radii[j] + f * (self.radii[j + 1] - self.radii[j])
    }

    /// The radius, when it is the same at every level: then [`Lattice::radius_at`] returns
    /// exactly it everywhere (`r + f · 0 = r`).
    pub fn uniform_radius(&self) -> Option<f32> {
        let r = self.radii[0];
        (r.is_finite() && self.radii.iter().all(|&x| x == r)).then_some(r)
    }

    /// Texture coordinates of local coordinates `l` in cell `j`.
    #[inline(always)]
    pub fn tex_of(&self, j: usize, l: V3) -> V3 {
        [
            2.0 * l[0] - 1.0,
            2.0 * l[1] - 1.0,
            (j as f32 + l[2]) / (self.levels.len() - 1) as f32,
        ]
    }

    /// World position of texture coordinates `tex` (`x, y ∈ [−1, 1]`, `z ∈ [0, 1]`).
    pub fn forward(&self, tex: V3) -> V3 {
        let c = self.levels.len();
        let x = tex[2].clamp(0.0, 1.0) * (c - 1) as f32;
        let j = (x as usize).min(c - 2);
        self.cells[j].forward([(tex[0] + 1.0) * 0.5, (tex[1] + 1.0) * 0.5, x - j as f32])
    }

    /// Texture coordinates of world point `p`, if it lies inside the lattice.
    pub fn inverse(&self, p: V3) -> Option<V3> {
        const EPS: f32 = 1e-4;
        for (j, c) in self.cells.iter().enumerate() {
            if (0..3).any(|i| p[i] < c.min[i] - EPS || p[i] > c.max[i] + EPS) {
                continue;
            }
            if let Some(l) = c.inverse(p, [0.5, 0.5, 0.5]) {
                if l.iter().all(|&v| (-EPS..=1.0 + EPS).contains(&v)) {
                    return Some(self.tex_of(j, l));
                }
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Puffing scales each level's square and radius about the curve by the wave's factor
    /// (none at the base), leaves the curve where it is, and at amplitude 0 is no puffing.
    #[test]
    fn puffing_scales_levels_about_the_curve() {
        let c = bent();
        let plain = Lattice::build(&c, 21).unwrap();
        let still = Puff {
            amplitude: 0.0,
            phase: 1.0,
        };
        assert_eq!(Lattice::build_puffed(&c, 21, Some(still)).unwrap(), plain);
        let p = Puff {
            amplitude: 0.4,
            phase: 0.7,
        };
        let puffed = Lattice::build_puffed(&c, 21, Some(p)).unwrap();
        assert_eq!(puffed.length(), plain.length());
        for j in 0..21 {
            let h = j as f32 / 20.0;
            let f = p.factor(h);
            assert!((0.6..=1.4).contains(&f));
            let (a, b) = (plain.levels()[j], puffed.levels()[j]);
            let mid = |l: [V3; 4]| scale(add(add(l[0], l[1]), add(l[2], l[3])), 0.25);
            assert!(norm(sub(mid(a), mid(b))) < 1e-5, "level {j} moved");
            let (ra, rb) = (norm(sub(a[0], mid(a))), norm(sub(b[0], mid(b))));
            assert!((rb - f * ra).abs() < 1e-4, "level {j}: {rb} vs {f} · {ra}");
            assert!((puffed.radius_at(h) - f * plain.radius_at(h)).abs() < 1e-5);
        }
        assert_eq!(p.factor(0.0), 1.0);
        // the wave travels: a later phase puts the same factor higher up
        let later = Puff {
            phase: p.phase + 0.5,
            ..p
        };
        let dh = 0.5 / std::f32::consts::TAU;
        let s = |q: Puff, h: f32| (1.0 - q.factor(h)) / h;
        assert!((s(later, 0.6 + dh) - s(p, 0.6)).abs() < 1e-5);
    }

    fn bent() -> BSpline {
        BSpline::new(
            vec![
                [0.0, 0.0, 0.0, 1.0],
                [0.3, 0.1, 1.0, 0.9],
                [0.9, -0.2, 2.0, 0.6],
                [1.5, 0.2, 2.6, 0.3],
            ],
            3,
        )
        .unwrap()
    }

    /// The arc-length table's cached basis gives every curve of the same points and
    /// degree exactly what evaluating it directly gives, and a table too large to keep is
    /// not kept.
    #[test]
    fn cached_arc_basis_evaluates_as_the_curve() {
        let other = BSpline::new(
            bent()
                .points()
                .iter()
                .map(|p| [p[0] * 1.7 - 0.2, p[1] + 0.3, p[2] * 0.8, p[3] * 0.5])
                .collect(),
            3,
        )
        .unwrap();
        for curve in [bent(), other] {
            for dense in [256, 560, 1024] {
                let table = arc_basis(&curve, dense).unwrap();
                let n = curve.points().len();
                for k in 0..=dense {
                    let t = k as f32 / dense as f32;
                    let got = curve.eval_with_basis(&table[k * n..(k + 1) * n]);
                    assert_eq!(
                        got.map(f32::to_bits),
                        curve.eval(t).map(f32::to_bits),
                        "t {t}"
                    );
                }
            }
        }
        assert!(arc_basis(&bent(), ARC_BASIS_MAX).is_none());
    }

    #[test]
    fn inverse_undoes_forward() {
        let lat = Lattice::build(&bent(), 35).unwrap();
        let mut rng = ignis_core::Rng::new(3);
        for _ in 0..500 {
            let tex = [
                rng.uniform(-0.98, 0.98) as f32,
                rng.uniform(-0.98, 0.98) as f32,
                rng.uniform(0.01, 0.99) as f32,
            ];
            let p = lat.forward(tex);
            let back = lat.inverse(p).expect("inside");
            // the renderer's chord-method inverse agrees
            let j = ((tex[2] * 34.0) as usize).min(33);
            let l = lat.cells()[j].inverse_fast(p, [0.5; 3]).expect("converges");
            let t2 = lat.tex_of(j, l);
            for k in 0..3 {
                assert!((t2[k] - tex[k]).abs() < 1e-4, "fast {tex:?} -> {t2:?}");
            }
            // and so does the predicted (Newton) inverse, from the centre or a nearby guess
            let near = [
                (tex[0] + 1.0) * 0.5 + 0.03,
                (tex[1] + 1.0) * 0.5 - 0.02,
                0.5,
            ];
            for guess in [[0.5; 3], near] {
                let l = lat.cells()[j]
                    .inverse_predicted(p, guess)
                    .expect("converges");
                let t3 = lat.tex_of(j, l);
                for k in 0..3 {
                    assert!((t3[k] - tex[k]).abs() < 1e-4, "predicted {tex:?} -> {t3:?}");
                }
            }
            for k in 0..3 {
                assert!((back[k] - tex[k]).abs() < 1e-4, "{tex:?} -> {back:?}");
            }
        }
    }

    /// Newton's method in `f64` on the cell's coefficients: the exact inverse.
    fn inverse_f64(c: &Cell, p: V3, guess: V3) -> [f64; 3] {
        let k = c.k.map(|v| v.map(|x| x as f64));
        let p = p.map(|x| x as f64);
        let mut l = guess.map(|x| x as f64);
        for _ in 0..50 {
            let [a, b, s] = l;
            let mut f = [0.0; 3];
            let mut j = [[0.0; 3]; 3]; // j[i] = row i: d/da, d/db, d/ds
            for i in 0..3 {
                f[i] = k[0][i]
                    + a * k[1][i]
                    + b * k[2][i]
                    + s * k[3][i]
                    + a * b * k[4][i]
                    + a * s * k[5][i]
                    + b * s * k[6][i]
                    + a * b * s * k[7][i]
                    - p[i];
                j[i] = [
                    k[1][i] + b * k[4][i] + s * k[5][i] + b * s * k[7][i],
                    k[2][i] + a * k[4][i] + s * k[6][i] + a * s * k[7][i],
                    k[3][i] + a * k[5][i] + b * k[6][i] + a * b * k[7][i],
                ];
            }
            let det = j[0][0] * (j[1][1] * j[2][2] - j[1][2] * j[2][1])
                - j[0][1] * (j[1][0] * j[2][2] - j[1][2] * j[2][0])
                + j[0][2] * (j[1][0] * j[2][1] - j[1][1] * j[2][0]);
            let col = |m: [[f64; 3]; 3], c: usize, v: [f64; 3]| {
                let mut m = m;
                for i in 0..3 {
                    m[i][c] = v[i];
                }
                m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
                    - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
                    + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
            };
            for (c, lc) in l.iter_mut().enumerate() {
                *lc -= col(j, c, f) / det;
            }
        }
        l
    }

    /// The certified chord inverse is within its stated bound of the exact (`f64`)
    /// inverse whenever it answers: per texture coordinate ≤ `tol` (1e-5, the renderer's
    /// 3e-5, and a looser 1e-3 to exercise larger steps) plus 2e-6 for the `f32` rounding
    /// of the residual; checked on random points of a bent lattice and of the Table 1 fire
    /// with random guesses from 1e-4 to 0.3 away from the root.
    #[test]
    fn certified_inverse_error_bound() {
        let table1 = BSpline::new(
            vec![
                [0.0, 0.0, 0.0, 1.0],
                [0.0, 0.0, 1.0, 1.0],
                [0.2, 0.0, 2.0, 1.0],
                [0.4, 0.0, 3.0, 1.0],
            ],
            3,
        )
        .unwrap();
        let mut rng = ignis_core::Rng::new(17);
        for (curve, res) in [
            (bent(), 35usize),
            (table1.clone(), 35),
            (table1, 135),
            (bent(), 12),
        ] {
            let lat = Lattice::build(&curve, res).unwrap();
            let n = lat.cells().len();
            let certified = lat.cells().iter().filter(|c| c.certified()).count();
            let mut answered = 0;
            let mut worst = 0.0f64;
            for round in 0..20_000 {
                let tex_tol = [1e-5f32, 3e-5, 1e-3][round % 3];
                let tol = [0.5 * tex_tol, 0.5 * tex_tol, n as f32 * tex_tol];
                let j = rng.uniform(0.0, n as f64) as usize % n;
                let c = &lat.cells()[j];
                let l = [0; 3].map(|_| rng.uniform(-0.2, 1.2) as f32);
                let p = c.forward(l);
                let size = 10f64.powf(rng.uniform(-4.0, -0.5)) as f32;
                let guess = [0; 3].map(|i| l[i] + size * rng.uniform(-1.0, 1.0) as f32);
                let exact = inverse_f64(c, p, l);
                if let Ok(got) = c.inverse_certified(p, guess, tol) {
                    answered += 1;
                    // texture-space errors: x, y = 2a − 1, 2b − 1; z = (j + s)/n
                    let e = [
                        2.0 * (got[0] as f64 - exact[0]).abs(),
                        2.0 * (got[1] as f64 - exact[1]).abs(),
                        (got[2] as f64 - exact[2]).abs() / n as f64,
                    ];
                    for (k, e) in e.iter().enumerate() {
                        assert!(
                            *e <= tex_tol as f64 + 2e-6,
                            "cell {j} coordinate {k}: error {e:e} > {tex_tol:e} (guess {guess:?}, root {exact:?})"
                        );
                        worst = worst.max(*e / (tex_tol as f64 + 2e-6));
                    }
                }
            }
            println!("{res} levels: {certified}/{n} cells certified, {answered} answers, worst error / bound {worst:.3}");
            assert!(answered > 1_000, "{answered}");
        }
    }

    /// The AVX2 lanes inverse gives the portable one's bits, lane by lane (certified or
    /// not), on random points in and around the cells of a bent lattice.
    #[cfg(target_arch = "x86_64")]
    #[test]
    fn avx2_lanes_inverse_equals_portable() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            println!("skipped: this CPU has no AVX2");
            return;
        }
        #[target_feature(enable = "avx2")]
        unsafe fn avx2(c: &Cell, p: &[[f32; 8]; 3], tol: V3) -> ([[f32; 8]; 3], [bool; 8]) {
            c.inverse_certified_lanes_avx2(p, tol)
        }
        let lat = Lattice::build(&bent(), 35).unwrap();
        let n = lat.cells().len();
        let mut rng = ignis_core::Rng::new(5);
        let (mut certified, mut refused) = (0, 0);
        for round in 0..4000 {
            let c = &lat.cells()[round % n];
            let tex_tol = [1e-5f32, 7.5e-6, 1e-3][round % 3];
            let tol = [0.5 * tex_tol, 0.5 * tex_tol, n as f32 * tex_tol];
            let mut p = [[0.0f32; 8]; 3];
            for l in 0..8 {
                let spread = if round % 4 == 0 { 2.0 } else { 0.3 };
                let q = c.forward([0; 3].map(|_| rng.uniform(-spread, 1.0 + spread) as f32));
                for (axis, v) in p.iter_mut().zip(q) {
                    axis[l] = v;
                }
            }
            // SAFETY: AVX2 was detected above.
            let (la, oa) = unsafe { avx2(c, &p, tol) };
            let (lp, op) = c.inverse_certified_lanes(&p, tol);
            assert_eq!(oa, op, "round {round}");
            for l in 0..8 {
                if op[l] {
                    certified += 1;
                    for a in 0..3 {
                        assert_eq!(la[a][l].to_bits(), lp[a][l].to_bits(), "round {round}");
                    }
                } else {
                    refused += 1;
                }
            }
        }
        assert!(
            certified > 10_000 && refused > 1_000,
            "{certified} {refused}"
        );
    }

    /// The affine model's error bound holds at random points of every certified cell.
    #[test]
    fn affine_inverse_error_bound() {
        let mut rng = ignis_core::Rng::new(29);
        for (curve, res) in [(bent(), 35usize), (bent(), 12)] {
            let lat = Lattice::build(&curve, res).unwrap();
            let mut checked = 0;
            let mut worst = 0.0f64;
            for c in lat.cells() {
                let Some(aff) = c.affine_inverse() else {
                    continue;
                };
                for _ in 0..300 {
                    let l = [0; 3].map(|_| rng.uniform(0.0, 1.0) as f32);
                    let p = c.forward(l);
                    for (r, &lr) in l.iter().enumerate() {
                        let est = 0.5
                            + (0..3)
                                .map(|i| aff.m[r][i] * (p[i] as f64 - aff.centre[i]))
                                .sum::<f64>();
                        let e = (est - lr as f64).abs();
                        // `p` is rounded to f32: allow for that (≈ 1e-7 · |M| · |p|)
                        assert!(e <= aff.err[r] + 1e-5, "error {e} > bound {}", aff.err[r]);
                        worst = worst.max(e / (aff.err[r] + 1e-5));
                    }
                    checked += 1;
                }
            }
            println!("{res} levels: {checked} points, worst error / bound {worst:.3}");
            assert!(checked > 1000);
        }
    }

    #[test]
    fn straight_curve_gives_boxes_of_side_2r() {
        let c = BSpline::new(
            vec![
                [0.0, 0.0, 0.0, 0.5],
                [0.0, 0.0, 1.0, 0.5],
                [0.0, 0.0, 2.0, 0.5],
                [0.0, 0.0, 3.0, 0.5],
            ],
            3,
        )
        .unwrap();
        let lat = Lattice::build(&c, 10).unwrap();
        assert!((lat.length() - 3.0).abs() < 1e-3);
        for (j, lv) in lat.levels().iter().enumerate() {
            let z = 3.0 * j as f32 / 9.0;
            for (k, p) in lv.iter().enumerate() {
                assert!((p[0] - 0.5 * CORNER_XY[k][0]).abs() < 1e-5);
                assert!((p[1] - 0.5 * CORNER_XY[k][1]).abs() < 1e-5);
                assert!((p[2] - z).abs() < 2e-3, "level {j}: {} vs {z}", p[2]);
            }
        }
    }
}
