//! Natural cubic spline through sparse samples (the interpolation of §3.1's shape
//! parameters).

/// Evaluates the natural cubic spline through `(xs[i], ys[i])` (`xs` strictly increasing)
/// at each of `at`, writing into `out`. Outside `[xs[0], xs[last]]` the end values are held
/// (a flame's path and width do not extrapolate well).
pub fn natural_cubic(xs: &[f64], ys: &[f64], at: &[f64], out: &mut [f64]) {
    debug_assert!(xs.len() == ys.len() && at.len() == out.len() && !xs.is_empty());
    SplinePlan::new(xs, at).eval(ys, out);
}

/// The natural cubic spline for many `ys` at the same knots `xs` and points `at`: where
/// each point falls and its interpolation weights are worked out once
/// ([`SplinePlan::new`]), so an evaluation is the tridiagonal solve (second derivatives,
/// Thomas algorithm, natural ends) and a few products per point. [`natural_cubic`] is a
/// plan used once; the loop timing keeps one per model for its thousands of renders.
#[derive(Clone, Debug, Default)]
pub(crate) struct SplinePlan {
    xs: Vec<f64>,
    at: Vec<f64>,
    points: Vec<PlanPoint>,
    c: Vec<f64>,
    r: Vec<f64>,
    m2: Vec<f64>,
}

/// Where a point of a [`SplinePlan`] falls: before the first knot, after the last, or in
/// segment `seg` with `natural_cubic`'s weights `a`, `b`, `a³ − a`, `b³ − b` and length `h`.
#[derive(Clone, Copy, Debug)]
enum PlanPoint {
    First,
    Last,
    In {
        seg: usize,
        a: f64,
        b: f64,
        ca: f64,
        cb: f64,
        h: f64,
    },
}

impl SplinePlan {
    /// The plan for knots `xs` (strictly increasing, at least one) and points `at`.
    pub(crate) fn new(xs: &[f64], at: &[f64]) -> SplinePlan {
        let n = xs.len();
        let mut seg = 0;
        let points = at
            .iter()
            .map(|&x| {
                if n == 1 || x <= xs[0] {
                    return PlanPoint::First;
                }
                if x >= xs[n - 1] {
                    return PlanPoint::Last;
                }
                if x < xs[seg] {
                    seg = 0;
                }
                while x > xs[seg + 1] {
                    seg += 1;
                }
                let h = xs[seg + 1] - xs[seg];
                let (a, b) = ((xs[seg + 1] - x) / h, (x - xs[seg]) / h);
                PlanPoint::In {
                    seg,
                    a,
                    b,
                    ca: a * a * a - a,
                    cb: b * b * b - b,
                    h,
                }
            })
            .collect();
        SplinePlan {
            xs: xs.to_vec(),
            at: at.to_vec(),
            points,
            c: vec![0.0; n],
            r: vec![0.0; n],
            m2: vec![0.0; n],
        }
    }

    /// [`natural_cubic`]`(xs, ys, at, out)` for the plan's `xs` and `at`.
    pub(crate) fn eval(&mut self, ys: &[f64], out: &mut [f64]) {
        let (xs, n) = (&self.xs, self.xs.len());
        debug_assert!(ys.len() == n && out.len() == self.at.len());
        let (c, r, m2) = (&mut self.c, &mut self.r, &mut self.m2);
        m2.iter_mut().for_each(|v| *v = 0.0);
        if n > 2 {
            for i in 1..n - 1 {
                let (h0, h1) = (xs[i] - xs[i - 1], xs[i + 1] - xs[i]);
                let a = h0;
                let b = 2.0 * (h0 + h1);
                let rhs = 6.0 * ((ys[i + 1] - ys[i]) / h1 - (ys[i] - ys[i - 1]) / h0);
                let den = b - a * c[i - 1];
                c[i] = h1 / den;
                r[i] = (rhs - a * r[i - 1]) / den;
            }
            for i in (1..n - 1).rev() {
                m2[i] = r[i] - c[i] * m2[i + 1];
            }
        }
        for (o, p) in out.iter_mut().zip(&self.points) {
            *o = match *p {
                PlanPoint::First => ys[0],
                PlanPoint::Last => ys[n - 1],
                PlanPoint::In {
                    seg,
                    a,
                    b,
                    ca,
                    cb,
                    h,
                } => {
                    a * ys[seg] + b * ys[seg + 1] + (ca * m2[seg] + cb * m2[seg + 1]) * h * h / 6.0
                }
            };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn interpolates_knots_and_lines_exactly() {
        let xs = [0.0, 1.0, 2.5, 4.0];
        let ys = [1.0, 3.0, 6.0, 9.0]; // 1 + 2x exactly
        let at = [0.0, 0.5, 1.0, 2.0, 3.3, 4.0, 5.0];
        let mut out = [0.0; 7];
        natural_cubic(&xs, &ys, &at, &mut out);
        for (x, o) in at.iter().zip(out) {
            let want = 1.0 + 2.0 * x.min(4.0);
            assert!((o - want).abs() < 1e-9, "{x}: {o} vs {want}");
        }
    }

    /// A plan used again for other `ys` gives a fresh plan's values (`natural_cubic`) bit
    /// for bit, for points before, on, between and after the knots, increasing or not, and
    /// for one and two knots.
    #[test]
    fn plan_equals_natural_cubic() {
        let cases: [(&[f64], &[f64]); 3] = [
            (
                &[-1.0, -0.2, 0.5, 1.1, 2.0, 3.5],
                &[0.7, -0.4, 1.3, 0.2, 0.9, -1.1],
            ),
            (&[0.0, 1.0], &[2.0, -1.0]),
            (&[0.3], &[1.5]),
        ];
        let at: Vec<f64> = (0..40)
            .map(|i| -1.5 + 0.13 * i as f64)
            .chain([0.5, -0.2, 3.5, 9.0, -7.0, 1.1])
            .collect();
        for (xs, ys) in cases {
            let mut plan = SplinePlan::new(xs, &at);
            let (mut want, mut got) = (vec![0.0; at.len()], vec![0.0; at.len()]);
            natural_cubic(xs, ys, &at, &mut want);
            for scale in [1.0, -2.5] {
                let ys: Vec<f64> = ys.iter().map(|y| y * scale).collect();
                natural_cubic(xs, &ys, &at, &mut want);
                plan.eval(&ys, &mut got);
                for (w, g) in want.iter().zip(&got) {
                    assert_eq!(w.to_bits(), g.to_bits(), "{xs:?}: {g} vs {w}");
                }
            }
        }
    }
}
