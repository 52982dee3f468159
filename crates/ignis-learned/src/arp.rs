//! The auto-regressive process that drives the flame parameters.
//!
//! Source: stich-magnor-learning-flames.txt §4, eq. (2):
//! `x_t = Σ_{k=1..K} A_k x_{t−k} + d + B w_t`, `w_t ~ N(0, I)`.
//!
//! `B` is stored lower-triangular (the Cholesky factor of the process covariance
//! `B Bᵀ`), which loses nothing: only `B Bᵀ` is identifiable from data.

use crate::error::{LearnedError, Result};
use faer::Mat;
use ignis_core::Rng;
use serde::{Deserialize, Serialize};

/// An ARP of order `K` on `dim`-dimensional states (eq. 2).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Arp {
    /// `A_1 … A_K`, each `dim × dim`, row-major.
    pub a: Vec<Vec<f64>>,
    /// The offset `d` (length `dim`).
    pub d: Vec<f64>,
    /// The noise weighting `B` (`dim × dim`, row-major, lower triangular).
    pub b: Vec<f64>,
}

/// What [`Arp::stabilise`] did to an unstable process.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Stabilised {
    /// Spectral radius of the companion matrix before.
    pub before: f64,
    /// Spectral radius after (the requested maximum).
    pub after: f64,
}

impl Arp {
    /// Checks the shapes and builds a process.
    pub fn new(a: Vec<Vec<f64>>, d: Vec<f64>, b: Vec<f64>) -> Result<Arp> {
        let n = d.len();
        if n == 0 || a.is_empty() {
            return Err(LearnedError::bad(
                "arp",
                "needs order ≥ 1 and dimension ≥ 1",
            ));
        }
        if a.iter().any(|ak| ak.len() != n * n) || b.len() != n * n {
            return Err(LearnedError::bad(
                "arp",
                format!("A_k and B must be {n}×{n}"),
            ));
        }
        if a.iter()
            .flatten()
            .chain(&d)
            .chain(&b)
            .any(|v| !v.is_finite())
        {
            return Err(LearnedError::bad("arp", "coefficients must be finite"));
        }
        Ok(Arp { a, d, b })
    }

    /// Order `K`.
    pub fn order(&self) -> usize {
        self.a.len()
    }

    /// State dimension.
    pub fn dim(&self) -> usize {
        self.d.len()
    }

    /// `A_k` (1-based `k` as in the paper) as a faer matrix.
    pub fn a_mat(&self, k: usize) -> Mat<f64> {
        let n = self.dim();
        Mat::from_fn(n, n, |i, j| self.a[k - 1][i * n + j])
    }

    /// `B` as a faer matrix.
    pub fn b_mat(&self) -> Mat<f64> {
        let n = self.dim();
        Mat::from_fn(n, n, |i, j| self.b[i * n + j])
    }

    /// The companion matrix (`nK × nK`) of the deterministic part.
    pub fn companion(&self) -> Mat<f64> {
        let (n, k) = (self.dim(), self.order());
        Mat::from_fn(n * k, n * k, |i, j| {
            if i < n {
                self.a[j / n][i * n + j % n]
            } else if i - n == j {
                1.0
            } else {
                0.0
            }
        })
    }

    /// Largest eigenvalue modulus of the companion matrix; `< 1` means the process is stable.
    pub fn spectral_radius(&self) -> Result<f64> {
        let ev = self
            .companion()
            .eigenvalues()
            .map_err(|e| LearnedError::Numerical(format!("companion eigenvalues: {e:?}")))?;
        Ok(ev.iter().map(|z| z.norm()).fold(0.0, f64::max))
    }

    /// If the spectral radius is at least `max_radius` (< 1), scales `A_k` by `r^k` with
    /// `r = max_radius / radius`, which scales every companion eigenvalue by exactly `r`.
    pub fn stabilise(&mut self, max_radius: f64) -> Result<Option<Stabilised>> {
        let rho = self.spectral_radius()?;
        if rho < max_radius {
            return Ok(None);
        }
        // `d` is left alone here; `em::learn` re-centres it on the data mean afterwards.
        let r = max_radius / rho;
        for (k, ak) in self.a.iter_mut().enumerate() {
            let s = r.powi(k as i32 + 1);
            ak.iter_mut().for_each(|v| *v *= s);
        }
        Ok(Some(Stabilised {
            before: rho,
            after: self.spectral_radius()?,
        }))
    }

    /// The stationary mean `(I − Σ A_k)⁻¹ d`, if it exists.
    pub fn stationary_mean(&self) -> Option<Vec<f64>> {
        let n = self.dim();
        let mut m = Mat::<f64>::identity(n, n);
        for k in 1..=self.order() {
            m -= self.a_mat(k);
        }
        let rhs = Mat::from_fn(n, 1, |i, _| self.d[i]);
        let lu = m.partial_piv_lu();
        use faer::prelude::Solve;
        let x = lu.solve(&rhs);
        let v: Vec<f64> = (0..n).map(|i| x[(i, 0)]).collect();
        v.iter().all(|x| x.is_finite()).then_some(v)
    }

    /// One step: `hist[0] = x_{t−1}, hist[1] = x_{t−2}, …`; writes `x_t` into `out`.
    /// `noise` must hold `dim` scratch values.
    pub fn step(&self, hist: &[&[f64]], rng: &mut Rng, noise: &mut [f64], out: &mut [f64]) {
        let n = self.dim();
        for w in noise.iter_mut() {
            *w = rng.normal();
        }
        out.copy_from_slice(&self.d);
        for (ak, x) in self.a.iter().zip(hist) {
            for i in 0..n {
                let row = &ak[i * n..(i + 1) * n];
                out[i] += row.iter().zip(x.iter()).map(|(a, b)| a * b).sum::<f64>();
            }
        }
        for (i, o) in out.iter_mut().enumerate() {
            let row = &self.b[i * n..i * n + i + 1];
            *o += row
                .iter()
                .zip(noise.iter())
                .map(|(a, b)| a * b)
                .sum::<f64>();
        }
    }

    /// Simulates `len` steps after the `K` initial states `init` (oldest first), seeded.
    /// Returns only the new states.
    pub fn simulate(&self, init: &[Vec<f64>], len: usize, seed: u64) -> Result<Vec<Vec<f64>>> {
        let (n, k) = (self.dim(), self.order());
        if init.len() < k || init.iter().any(|x| x.len() != n) {
            return Err(LearnedError::bad(
                "init",
                format!("needs {k} initial states of length {n}"),
            ));
        }
        let mut rng = Rng::new(seed);
        let mut all: Vec<Vec<f64>> = init[init.len() - k..].to_vec();
        let mut noise = vec![0.0; n];
        for _ in 0..len {
            let t = all.len();
            let hist: Vec<&[f64]> = (1..=k).map(|j| all[t - j].as_slice()).collect();
            let mut x = vec![0.0; n];
            self.step(&hist, &mut rng, &mut noise, &mut x);
            all.push(x);
        }
        Ok(all.split_off(k))
    }
}

impl Arp {
    /// A seamless loop: `len` new states after `init` (`K` states, oldest first), sampled
    /// from the process *conditioned on ending where it started* — the last `K` states
    /// equal `init` — so the states played in a loop follow each other, across the seam
    /// too, exactly as the process's own steps do (the step from the last state to the
    /// first is the process's step from `init` to the first).
    ///
    /// Exact for this linear-Gaussian process, by Matheron's rule (the Kalman bridge in
    /// one pass): with the companion state `z_t = (x_t, …, x_{t−K+1})`,
    /// `z_{t+1} = F z_t + c + G w_t`, sample freely (`z̃`), then correct every state by
    /// `Cov(z_t, z_N) Cov(z_N)⁻¹ (z_0 − z̃_N)`. `Cov(z_N) = P_N` comes from
    /// `P_{t+1} = F P_t Fᵀ + G Gᵀ`; the corrections from two vector recursions,
    /// `μ_N = P_N⁻¹ r`, `μ_t = Fᵀ μ_{t+1}` and `δ_{t+1} = F δ_t + G Gᵀ μ_{t+1}`, `δ_0 = 0`.
    /// Costs `len` products of `nK × nK` matrices on top of the free sample.
    ///
    /// Fails if `len` is below `max(2, K)` or the bridge's covariance is singular.
    pub fn simulate_loop(&self, init: &[Vec<f64>], len: usize, seed: u64) -> Result<Vec<Vec<f64>>> {
        let (n, k) = (self.dim(), self.order());
        if len < k.max(2) {
            return Err(LearnedError::bad(
                "loop",
                format!(
                    "{len} frame(s) cannot loop a process of order {k}; ask for at least {} frames",
                    k.max(2)
                ),
            ));
        }
        let mut xs = self.simulate(init, len, seed)?;
        let m = n * k;
        let f = self.companion();
        let mut q = Mat::<f64>::zeros(m, m);
        {
            let b = self.b_mat();
            let bbt = &b * b.transpose();
            for i in 0..n {
                for j in 0..n {
                    q[(i, j)] = bbt[(i, j)];
                }
            }
        }
        let mut p = step_covariance(&f, &q, len);
        // r = z_0 − z̃_N, newest first
        let init = &init[init.len() - k..];
        let r = Mat::from_fn(m, 1, |i, _| {
            let (lag, c) = (i / n, i % n);
            init[k - 1 - lag][c] - xs[len - 1 - lag][c]
        });
        let ridge = 1e-12 * (0..m).map(|i| p[(i, i)]).sum::<f64>() / m as f64;
        for i in 0..m {
            p[(i, i)] += ridge;
        }
        use faer::prelude::Solve;
        let mut mu = p.partial_piv_lu().solve(&r);
        if (0..m).any(|i| !mu[(i, 0)].is_finite()) {
            return Err(LearnedError::Numerical(
                "the loop's bridge covariance is singular".into(),
            ));
        }
        // μ_t for t = N … 1 (μ_N first), then δ forwards
        let mut mus = Vec::with_capacity(len);
        mus.push(mu.clone());
        for _ in 1..len {
            mu = f.transpose() * &mu;
            mus.push(mu.clone());
        }
        mus.reverse(); // mus[t - 1] = μ_t
        let mut delta = Mat::<f64>::zeros(m, 1);
        for (t, x) in xs.iter_mut().enumerate() {
            delta = &f * &delta + &q * &mus[t];
            for (c, v) in x.iter_mut().enumerate() {
                *v += delta[(c, 0)];
            }
        }
        Ok(xs)
    }
}

/// `Σ_{i<len} Fⁱ Q Fⁱᵀ`: the covariance of the companion state `len` steps after a known
/// start, by doubling (`S_{a+b} = S_a + Fᵃ S_b Fᵃᵀ`) in `O(log len)` matrix products
/// instead of `len` — the loop bridge's cost would otherwise grow with the loop's length.
fn step_covariance(f: &Mat<f64>, q: &Mat<f64>, len: usize) -> Mat<f64> {
    let m = f.nrows();
    let (mut acc, mut acc_pow) = (Mat::<f64>::zeros(m, m), Mat::<f64>::identity(m, m));
    let (mut s, mut fm) = (q.clone(), f.clone());
    let mut n = len;
    while n > 0 {
        if n & 1 == 1 {
            acc = &acc + &acc_pow * &s * acc_pow.transpose();
            acc_pow = &acc_pow * &fm;
        }
        n >>= 1;
        if n > 0 {
            s = &s + &fm * &s * fm.transpose();
            fm = &fm * &fm;
        }
    }
    acc
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ar2() -> Arp {
        Arp::new(
            vec![vec![1.2, 0.0, 0.1, 0.5], vec![-0.5, 0.0, 0.0, -0.2]],
            vec![0.1, -0.2],
            vec![0.3, 0.0, 0.05, 0.2],
        )
        .unwrap()
    }

    #[test]
    fn doubled_step_covariance_equals_the_recursion() {
        let a = ar2();
        let f = a.companion();
        let q = Mat::from_fn(4, 4, |i, j| if i == j { 0.3 + 0.1 * i as f64 } else { 0.0 });
        for len in [0usize, 1, 2, 3, 7, 64, 100] {
            let mut p = Mat::<f64>::zeros(4, 4);
            for _ in 0..len {
                p = &f * &p * f.transpose() + &q;
            }
            let d = step_covariance(&f, &q, len);
            for i in 0..4 {
                for j in 0..4 {
                    assert!((p[(i, j)] - d[(i, j)]).abs() <= 1e-12 * (1.0 + p[(i, j)].abs()));
                }
            }
        }
    }

    #[test]
    fn companion_radius_matches_scalar_roots() {
        // Scalar AR(2) x_t = 1.2 x_{t-1} − 0.5 x_{t-2}: roots of z² − 1.2 z + 0.5, |z| = √0.5.
        let a = Arp::new(vec![vec![1.2], vec![-0.5]], vec![0.0], vec![1.0]).unwrap();
        assert!((a.spectral_radius().unwrap() - 0.5f64.sqrt()).abs() < 1e-9);
    }

    #[test]
    fn stabilise_pulls_inside_unit_circle() {
        let mut a = Arp::new(vec![vec![1.5], vec![-0.2]], vec![0.0], vec![1.0]).unwrap();
        let s = a.stabilise(0.98).unwrap().expect("was unstable");
        assert!(s.before >= 1.0);
        assert!((a.spectral_radius().unwrap() - 0.98).abs() < 1e-9);
        assert!(ar2().clone().stabilise(0.98).unwrap().is_none());
    }

    #[test]
    fn simulate_is_deterministic() {
        let a = ar2();
        let init = vec![vec![0.0, 0.0], vec![0.0, 0.0]];
        assert_eq!(
            a.simulate(&init, 50, 3).unwrap(),
            a.simulate(&init, 50, 3).unwrap()
        );
        assert_ne!(
            a.simulate(&init, 50, 3).unwrap(),
            a.simulate(&init, 50, 4).unwrap()
        );
    }

    /// The bridge ends exactly where it started (its last K states are `init`), and its
    /// steps look like the free process's: the seam step is no different from the others
    /// on average over many seeds.
    #[test]
    fn loop_returns_to_its_start() {
        let a = ar2();
        let init = vec![vec![0.4, -0.3], vec![0.1, 0.2]];
        for len in [2usize, 5, 40] {
            let xs = a.simulate_loop(&init, len, 9).unwrap();
            assert_eq!(xs.len(), len);
            assert!((xs[len - 1][0] - init[1][0]).abs() < 1e-9, "{len}");
            assert!((xs[len - 1][1] - init[1][1]).abs() < 1e-9, "{len}");
            assert!((xs[len - 2][0] - init[0][0]).abs() < 1e-9, "{len}");
            assert!((xs[len - 2][1] - init[0][1]).abs() < 1e-9, "{len}");
        }
        assert!(a.simulate_loop(&init, 1, 9).is_err());
        // mean squared step across the seam (last → first, i.e. init[1] → x_1 after the
        // loop closes) vs mean squared step inside, over many seeds
        let (mut seam, mut inside, mut n_in) = (0.0, 0.0, 0usize);
        let len = 24;
        for seed in 0..400 {
            let xs = a.simulate_loop(&init, len, seed).unwrap();
            let d = |p: &[f64], q: &[f64]| (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2);
            seam += d(&xs[len - 1], &xs[0]);
            for w in xs.windows(2) {
                inside += d(&w[0], &w[1]);
                n_in += 1;
            }
        }
        let ratio = (seam / 400.0) / (inside / n_in as f64);
        assert!(
            (0.6..1.4).contains(&ratio),
            "seam/inside mean squared step {ratio}"
        );
    }
}
