//! Natural cubic spline through sparse samples (the interpolation of §3.1's shape
//! parameters).

/// Evaluates the natural cubic spline through `(xs[i], ys[i])` (`xs` strictly increasing)
/// at each of `at`, writing into `out`. Outside `[xs[0], xs[last]]` the end values are held
/// (a flame's path and width do not extrapolate well).
pub fn natural_cubic(xs: &[f64], ys: &[f64], at: &[f64], out: &mut [f64]) {
    let n = xs.len();
    debug_assert!(n == ys.len() && at.len() == out.len() && n >= 1);
    if n == 1 {
        out.iter_mut().for_each(|o| *o = ys[0]);
        return;
    }
    // Second derivatives by the tridiagonal (Thomas) algorithm, natural ends.
    let mut m2 = vec![0.0; n];
    if n > 2 {
        let mut c = vec![0.0; n];
        let mut r = vec![0.0; n];
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
    let mut seg = 0;
    for (o, &x) in out.iter_mut().zip(at) {
        if x <= xs[0] {
            *o = ys[0];
            continue;
        }
        if x >= xs[n - 1] {
            *o = ys[n - 1];
            continue;
        }
        if x < xs[seg] {
            seg = 0;
        }
        while x > xs[seg + 1] {
            seg += 1;
        }
        let h = xs[seg + 1] - xs[seg];
        let (a, b) = ((xs[seg + 1] - x) / h, (x - xs[seg]) / h);
        *o = a * ys[seg]
            + b * ys[seg + 1]
            + ((a * a * a - a) * m2[seg] + (b * b * b - b) * m2[seg + 1]) * h * h / 6.0;
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
}
