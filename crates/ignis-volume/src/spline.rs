//! The centre curve: an open uniform B-spline with a radius per control point.
//!
//! Source: fuller-procedural-volumetric-fire.txt §3, eq. (3)–(6). Control points are
//! `[x, y, z, r]`: the radius is the curve's "fourth dimension" (§3.1) and is interpolated
//! by the same basis functions.

use crate::error::{Result, VolumeError};

/// An open uniform (clamped) B-spline over `t ∈ [0, 1]`.
#[derive(Clone, Debug, PartialEq)]
pub struct BSpline {
    degree: usize,
    points: Vec<[f32; 4]>,
    knots: Vec<f64>,
}

/// The knot vector of eq. (3) for `n` control points of degree `p` (`n + p + 1` knots).
pub fn open_uniform_knots(n: usize, p: usize) -> Vec<f64> {
    (0..n + p + 1)
        .map(|i| {
            if i <= p {
                0.0
            } else if i < n {
                (i - p) as f64 / (n - p) as f64
            } else {
                1.0
            }
        })
        .collect()
}

/// Most control points of one curve.
pub const MAX_POINTS: usize = 1024;
/// Largest control-point coordinate, world units.
pub const MAX_COORD: f32 = 1e6;
/// Largest fire radius, world units (a unit-radius fire is the usual scale).
pub const MAX_RADIUS: f32 = 1e4;

impl BSpline {
    /// A curve of `degree ≥ 1` through `points` (`[x, y, z, radius]`); needs at least
    /// `degree + 1` points and non-negative finite radii.
    pub fn new(points: Vec<[f32; 4]>, degree: usize) -> Result<BSpline> {
        if degree == 0 || degree > 7 {
            return Err(VolumeError::bad(
                "degree",
                format!("{degree}; use 1 to 7 (3 is cubic)"),
            ));
        }
        if points.len() < degree + 1 {
            return Err(VolumeError::bad(
                "points",
                format!(
                    "{} control points for degree {degree}; need at least {}",
                    points.len(),
                    degree + 1
                ),
            ));
        }
        if points.len() > MAX_POINTS {
            return Err(VolumeError::bad(
                "points",
                format!(
                    "{} control points; at most {MAX_POINTS} (the lattice has at most 4096 levels)",
                    points.len()
                ),
            ));
        }
        for (i, p) in points.iter().enumerate() {
            if p[..3].iter().any(|v| v.abs() > MAX_COORD) || p[3] > MAX_RADIUS {
                return Err(VolumeError::bad(
                    format!("points[{i}]"),
                    format!(
                        "{p:?}: coordinates must be within ±{MAX_COORD:e} and the radius at most \
                         {MAX_RADIUS:e} world units (a unit-radius fire is the usual scale)"
                    ),
                ));
            }
            if p.iter().any(|v| !v.is_finite()) {
                return Err(VolumeError::bad(
                    format!("points[{i}]"),
                    "must be finite numbers",
                ));
            }
            if p[3] < 0.0 {
                return Err(VolumeError::bad(
                    format!("points[{i}].radius"),
                    format!("{} is negative", p[3]),
                ));
            }
        }
        let knots = open_uniform_knots(points.len(), degree);
        Ok(BSpline {
            degree,
            points,
            knots,
        })
    }

    pub fn degree(&self) -> usize {
        self.degree
    }
    pub fn points(&self) -> &[[f32; 4]] {
        &self.points
    }
    pub fn knots(&self) -> &[f64] {
        &self.knots
    }

    /// All basis functions `N_{i,p}(t)`, `i = 0..n` (eq. 4–5, with 0/0 = 0). At `t = 1`
    /// the last non-empty knot span is closed so the curve ends at its last point.
    pub fn basis(&self, t: f64) -> Vec<f64> {
        basis_of(&self.knots, self.points.len(), self.degree, t)
    }

    /// `C(t)` (eq. 6): position and radius.
    pub fn eval(&self, t: f32) -> [f32; 4] {
        self.eval_with_basis(&self.basis(t as f64))
    }

    /// `C(t)` from the basis at `t` ([`BSpline::basis`], `n` values): the same value as
    /// [`BSpline::eval`] at that `t`, for callers that evaluate many curves of the same
    /// knots at the same parameters (the lattice's arc-length table).
    pub fn eval_with_basis(&self, b: &[f64]) -> [f32; 4] {
        let mut out = [0.0f64; 4];
        for (w, p) in b.iter().zip(&self.points) {
            for c in 0..4 {
                out[c] += w * p[c] as f64;
            }
        }
        out.map(|v| v as f32)
    }

    /// `C'(t)`: the derivative (velocity) of position and radius.
    pub fn derivative(&self, t: f32) -> [f32; 4] {
        let (n, p) = (self.points.len(), self.degree);
        let b = basis_of(&self.knots, n, p - 1, t as f64);
        // b has n entries for degree p-1 on the same knot vector; N_{i+1,p-1} is b[i+1].
        let mut out = [0.0f64; 4];
        for i in 0..n - 1 {
            let den = self.knots[i + p + 1] - self.knots[i + 1];
            if den <= 0.0 {
                continue;
            }
            let w = p as f64 / den * b[i + 1];
            for (c, o) in out.iter_mut().enumerate() {
                *o += w * (self.points[i + 1][c] - self.points[i][c]) as f64;
            }
        }
        out.map(|v| v as f32)
    }
}

/// The `n` basis functions of degree `p` at `t` (Cox–de Boor). Only the `p + 1` functions
/// over the span holding `t` can be non-zero, so only they are computed (the curve's
/// evaluation is on every lattice build's path, a few hundred times per frame); the rest
/// stay `+0.0`, which is what the full recursion ([`basis_of_all`]) gives them too, so the
/// result is the same bit for bit (tested).
fn basis_of(knots: &[f64], n: usize, p: usize, t: f64) -> Vec<f64> {
    let m = knots.len() - 1; // number of spans
    let t = t.clamp(0.0, 1.0);
    // the span holding t; at t = 1 the last non-empty one (as the full recursion closes it)
    let span = if t >= 1.0 {
        (0..m).rev().find(|&i| knots[i] < knots[i + 1])
    } else {
        (0..m).find(|&i| knots[i] <= t && t < knots[i + 1])
    };
    let Some(span) = span else {
        // no span holds t (NaN): the full recursion, whatever it makes of it
        return basis_of_all(knots, n, p, t);
    };
    let mut nb = vec![0.0f64; m];
    nb[span] = 1.0;
    for q in 1..=p {
        if m <= q {
            break;
        }
        for i in span.saturating_sub(q)..=span.min(m - q - 1) {
            nb[i] = cox_de_boor(knots, &nb, q, i, t);
        }
    }
    nb.truncate(n.max(1));
    nb.resize(n, 0.0);
    nb
}

/// Basis function `i` of degree `q` at `t` from `nb`, those of degree `q − 1`.
#[inline(always)]
fn cox_de_boor(knots: &[f64], nb: &[f64], q: usize, i: usize, t: f64) -> f64 {
    let d1 = knots[i + q] - knots[i];
    let d2 = knots[i + q + 1] - knots[i + 1];
    let a = if d1 > 0.0 {
        (t - knots[i]) / d1 * nb[i]
    } else {
        0.0
    };
    let b = if d2 > 0.0 {
        (knots[i + q + 1] - t) / d2 * nb[i + 1]
    } else {
        0.0
    };
    a + b
}

/// [`basis_of`] by the full recursion over every span (the form of eq. 4; the reference
/// for [`basis_of`], and its answer when no span holds `t`).
fn basis_of_all(knots: &[f64], n: usize, p: usize, t: f64) -> Vec<f64> {
    let m = knots.len() - 1; // number of spans
    let t = t.clamp(0.0, 1.0);
    let mut nb: Vec<f64> = (0..m)
        .map(|i| {
            if knots[i] <= t && t < knots[i + 1] {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    if t >= 1.0 {
        // close the last non-empty span
        if let Some(i) = (0..m).rev().find(|&i| knots[i] < knots[i + 1]) {
            nb[i] = 1.0;
        }
    }
    for q in 1..=p {
        for i in 0..m - q {
            nb[i] = cox_de_boor(knots, &nb, q, i, t);
        }
    }
    nb.truncate(n.max(1));
    nb.resize(n, 0.0);
    nb
}

#[cfg(test)]
mod tests {
    use super::*;

    fn curve() -> BSpline {
        BSpline::new(
            vec![
                [0.0, 0.0, 0.0, 1.0],
                [0.5, 0.2, 1.0, 0.8],
                [-0.3, 0.1, 2.0, 0.6],
                [0.2, -0.4, 3.0, 0.4],
                [1.0, 0.0, 3.5, 0.1],
            ],
            3,
        )
        .unwrap()
    }

    #[test]
    fn knots_follow_eq3() {
        assert_eq!(
            open_uniform_knots(5, 3),
            vec![0.0, 0.0, 0.0, 0.0, 0.5, 1.0, 1.0, 1.0, 1.0]
        );
    }

    /// The basis over the span alone equals the full recursion bit for bit: every degree,
    /// short and long curves, at and between the knots, at the ends, and one degree lower
    /// on the same knots ([`BSpline::derivative`]).
    #[test]
    fn span_basis_equals_the_full_recursion() {
        for p in 1..=7 {
            for n in [p + 1, p + 2, 5, 9, 40] {
                if n < p + 1 {
                    continue;
                }
                let knots = open_uniform_knots(n, p);
                let mut ts: Vec<f64> = (0..=997).map(|k| k as f64 / 997.0).collect();
                ts.extend(knots.iter().flat_map(|&k| [k, k.next_up(), k.next_down()]));
                ts.extend([-0.5, 1.5, f64::NAN]);
                for t in ts {
                    // degree p, and p − 1 on the same knots (as the derivative uses them)
                    for q in [p, p - 1] {
                        let fast = basis_of(&knots, n, q, t);
                        let full = basis_of_all(&knots, n, q, t);
                        let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                        assert_eq!(bits(&fast), bits(&full), "p {p}, q {q}, n {n}, t {t}");
                    }
                }
            }
        }
    }

    #[test]
    fn partition_of_unity() {
        let c = curve();
        for k in 0..=200 {
            let t = k as f64 / 200.0;
            let s: f64 = c.basis(t).iter().sum();
            assert!((s - 1.0).abs() < 1e-12, "t={t} sum={s}");
            assert!(c.basis(t).iter().all(|&b| b >= -1e-15));
        }
    }

    #[test]
    fn end_points_interpolated() {
        let c = curve();
        for d in 1..=4 {
            let pts = c.points()[..].to_vec();
            let s = BSpline::new(pts.clone(), d).unwrap();
            let (a, b) = (s.eval(0.0), s.eval(1.0));
            for k in 0..4 {
                assert!((a[k] - pts[0][k]).abs() < 1e-6);
                assert!((b[k] - pts[4][k]).abs() < 1e-6);
            }
        }
    }

    #[test]
    fn derivative_is_continuous_and_matches_differences() {
        let c = curve();
        // across the interior knot t = 0.5 and elsewhere
        for &t in &[0.1f32, 0.3, 0.5, 0.7, 0.9] {
            let (l, r) = (c.derivative(t - 1e-4), c.derivative(t + 1e-4));
            for k in 0..4 {
                assert!((l[k] - r[k]).abs() < 5e-3, "t={t} {l:?} {r:?}");
            }
            let h = 1e-3;
            let (a, b) = (c.eval(t - h), c.eval(t + h));
            let d = c.derivative(t);
            for k in 0..4 {
                assert!(((b[k] - a[k]) / (2.0 * h) - d[k]).abs() < 2e-2, "t={t}");
            }
        }
    }

    #[test]
    fn rejects_bad_input() {
        let e = BSpline::new(vec![[0.0; 4]; 3], 3).unwrap_err().to_string();
        assert!(e.contains("points") && e.contains("at least 4"), "{e}");
        let e = BSpline::new(vec![[0.0, 0.0, 0.0, -1.0]; 4], 3)
            .unwrap_err()
            .to_string();
        assert!(e.contains("radius"), "{e}");
    }
}
