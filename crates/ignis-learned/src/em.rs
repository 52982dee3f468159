//! Learning the ARP by Expectation–Maximisation with the condensation algorithm.
//!
//! Source: stich-magnor-learning-flames.txt §4.1 (EM with condensation), §4.2
//! (initialisation), §5 (stopping rule); North & Blake 2000 (smoothing by particle
//! history).
//!
//! Model: hidden states follow the ARP of eq. (2), and the fitted flame parameters are
//! noisy observations of them, `y_t = x_t + v_t`, `v_t ~ N(0, diag(r))`.
//!
//! - **Initialisation (§4.2):** each parameter is standardised to zero mean and unit
//!   deviation; `A_k⁰` are diagonal, fitted per parameter by least squares on the data
//!   (treated as noise-free); `d⁰ = 0`; `B⁰ = I` (the standard deviations, which are 1
//!   after standardising). The learned process is rescaled to the original units at the end.
//! - **E-step:** a particle filter with `N_c` particles. *Departure:* instead of sampling
//!   from the dynamics and weighting by the observation (plain condensation), each step
//!   samples from `p(x_t | x_{t−1..t−K}, y_t)` and resamples by `p(y_t | x_{t−1..t−K})`
//!   (the "fully adapted" filter; both are Gaussian here). Plain condensation with 200
//!   particles in 26 dimensions collapses onto one particle per step; this variant
//!   estimates the same expectations with far lower variance. Smoothing is North &
//!   Blake's: every particle keeps its history, and the window `x_{t−K..t}` is read off
//!   the ancestry of the particles alive at `t + lag` (a fixed lag bounds path degeneracy).
//! - **M-step:** maximum likelihood of `[A_1 … A_K d]` by least squares on the smoothed
//!   second moments (solved with faer's Cholesky), `B Bᵀ` from the residual covariance,
//!   and the observation noise from the smoothed residuals.
//! - **Stopping (§5):** when the likelihood has not increased for `patience` (3)
//!   consecutive iterations; the best model seen is returned.
//! - **Stability:** if the learned companion matrix has spectral radius ≥ `max_radius`,
//!   the process is pulled back inside the unit circle ([`Arp::stabilise`]) and the report
//!   says so.

use crate::arp::{Arp, Stabilised};
use crate::error::{LearnedError, Result};
use faer::linalg::matmul::matmul;
use faer::{Accum, Mat, Par, Side};
use ignis_core::Rng;
use serde::{Deserialize, Serialize};

/// Settings of [`learn`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EmParams {
    /// ARP order `K`, 1..=8. Default 2 (§5).
    pub order: usize,
    /// Number of condensation particles `N_c`, 10..=100000. Default 200 (§5).
    pub particles: usize,
    /// Upper bound on EM iterations, ≥ 1. Default 60.
    pub max_iterations: usize,
    /// Stop when the likelihood has not increased for this many iterations. Default 3 (§5).
    pub patience: usize,
    /// Initial observation-noise deviation, in units of each parameter's deviation,
    /// `0 < v < 1`. Default 0.1.
    pub obs_noise: f64,
    /// Floor of the learned observation-noise deviation (same units). Default 0.02.
    pub min_obs_noise: f64,
    /// Fixed smoothing lag in steps (North & Blake history smoothing). Default 20.
    pub smoothing_lag: usize,
    /// Largest spectral radius accepted for the companion matrix, `< 1`. Default 0.995.
    pub max_radius: f64,
    /// Seed of the particle filter.
    pub seed: u64,
}

impl Default for EmParams {
    fn default() -> Self {
        EmParams {
            order: 2,
            particles: 200,
            max_iterations: 60,
            patience: 3,
            obs_noise: 0.1,
            min_obs_noise: 0.02,
            smoothing_lag: 20,
            max_radius: 0.995,
            seed: 0,
        }
    }
}

impl EmParams {
    pub fn validate(&self) -> Result<()> {
        if !(1..=8).contains(&self.order) {
            return Err(LearnedError::bad(
                "order",
                format!("{} is outside 1..=8", self.order),
            ));
        }
        if !(10..=100_000).contains(&self.particles) {
            return Err(LearnedError::bad(
                "particles",
                format!("{} is outside 10..=100000", self.particles),
            ));
        }
        if self.max_iterations == 0 || self.patience == 0 {
            return Err(LearnedError::bad(
                "max_iterations",
                "iterations and patience must be ≥ 1",
            ));
        }
        if !(self.obs_noise > 0.0 && self.obs_noise < 1.0 && self.min_obs_noise > 0.0) {
            return Err(LearnedError::bad(
                "obs_noise",
                "must be in (0, 1), and its floor > 0",
            ));
        }
        if !(self.max_radius > 0.0 && self.max_radius < 1.0) {
            return Err(LearnedError::bad("max_radius", "must be in (0, 1)"));
        }
        Ok(())
    }
}

/// What happened during learning.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EmReport {
    /// Log-likelihood `log p(y_K … y_{T−1} | y_0 … y_{K−1})` of the model at the start of
    /// each iteration (standardised units; index 0 is the §4.2 initial model).
    pub log_likelihood: Vec<f64>,
    /// Index into `log_likelihood` of the returned model.
    pub best_iteration: usize,
    /// Learned observation-noise deviation per parameter (original units).
    pub obs_noise: Vec<f64>,
    /// Companion spectral radius of the returned process.
    pub spectral_radius: f64,
    /// Set when the learned process was unstable and had to be pulled back.
    pub stabilised: Option<Stabilised>,
}

/// A learned process and how learning went.
#[derive(Clone, Debug)]
pub struct Learned {
    pub arp: Arp,
    pub report: EmReport,
}

/// Parameters of the process in standardised units during EM.
#[derive(Clone)]
struct Lambda {
    /// `[A_1 … A_K]`, `n × nK`.
    a: Mat<f64>,
    d: Vec<f64>,
    /// Process covariance `B Bᵀ`.
    q: Mat<f64>,
    /// Observation-noise variances.
    r: Vec<f64>,
}

/// Learns an ARP from a parameter series (`series[t]` = parameters of frame `t`, all the
/// same length). Each E-step is one step of `progress`'s current stage, reported with its
/// log-likelihood (as the value `"log-likelihood"` and as a message).
pub fn learn(
    series: &[Vec<f64>],
    p: &EmParams,
    progress: &mut dyn ignis_core::progress::Progress,
) -> Result<Learned> {
    p.validate()?;
    let (t_len, k) = (series.len(), p.order);
    if t_len < k + 2 {
        return Err(LearnedError::Unsupported(format!(
            "{t_len} frames of parameters; an ARP of order {k} needs at least {} (K + 2)",
            k + 2
        )));
    }
    let n = series[0].len();
    if n == 0
        || series
            .iter()
            .any(|x| x.len() != n || x.iter().any(|v| !v.is_finite()))
    {
        return Err(LearnedError::bad(
            "series",
            "every step must have the same, non-zero number of finite values",
        ));
    }
    // Standardise (§4.2).
    let mean: Vec<f64> = (0..n)
        .map(|i| series.iter().map(|x| x[i]).sum::<f64>() / t_len as f64)
        .collect();
    let std: Vec<f64> = (0..n)
        .map(|i| {
            let v = series.iter().map(|x| (x[i] - mean[i]).powi(2)).sum::<f64>() / t_len as f64;
            if v > 1e-20 {
                v.sqrt()
            } else {
                1.0
            }
        })
        .collect();
    let y = Mat::from_fn(t_len, n, |t, i| (series[t][i] - mean[i]) / std[i]);

    let mut lam = initial(&y, p)?;
    let mut best = (f64::NEG_INFINITY, lam.clone(), 0usize);
    let mut lls = Vec::new();
    let mut since_best = 0;
    for it in 0..p.max_iterations {
        let mut rng = Rng::derive(p.seed, it as u64);
        let (ll, g, resid) = e_step(&y, &lam, p, &mut rng)?;
        progress.inc(1);
        progress.value("log-likelihood", ll);
        progress.message(&format!("EM iteration {it:>3}: log-likelihood {ll:.3}"));
        lls.push(ll);
        if ll > best.0 {
            best = (ll, lam.clone(), it);
            since_best = 0;
        } else {
            since_best += 1;
            if since_best >= p.patience {
                break;
            }
        }
        if it + 1 < p.max_iterations {
            lam = m_step(&g, &resid, n, k, t_len - k, p)?;
        }
    }
    let (_, lam, best_iteration) = best;

    // Back to original units: x = μ + S z.
    let mut a_orig = Vec::with_capacity(k);
    let mut sum_a = vec![0.0; n * n];
    for kk in 0..k {
        let ak: Vec<f64> = (0..n * n)
            .map(|ij| {
                let (i, j) = (ij / n, ij % n);
                std[i] * lam.a[(i, kk * n + j)] / std[j]
            })
            .collect();
        sum_a.iter_mut().zip(&ak).for_each(|(s, a)| *s += a);
        a_orig.push(ak);
    }
    let d_orig: Vec<f64> = (0..n)
        .map(|i| {
            std[i] * lam.d[i] + mean[i] - (0..n).map(|j| sum_a[i * n + j] * mean[j]).sum::<f64>()
        })
        .collect();
    let l = chol(&lam.q)?;
    let b_orig: Vec<f64> = (0..n * n)
        .map(|ij| std[ij / n] * l[(ij / n, ij % n)])
        .collect();
    let mut arp = Arp::new(a_orig, d_orig, b_orig)?;
    let stabilised = arp.stabilise(p.max_radius)?;
    if stabilised.is_some() {
        // Keep the stationary mean at the data mean after shrinking A.
        let mut sum_a = vec![0.0; n * n];
        for ak in &arp.a {
            sum_a.iter_mut().zip(ak).for_each(|(s, a)| *s += a);
        }
        arp.d = (0..n)
            .map(|i| mean[i] - (0..n).map(|j| sum_a[i * n + j] * mean[j]).sum::<f64>())
            .collect();
    }
    let spectral_radius = arp.spectral_radius()?;
    let obs_noise = (0..n).map(|i| lam.r[i].sqrt() * std[i]).collect();
    Ok(Learned {
        arp,
        report: EmReport {
            log_likelihood: lls,
            best_iteration,
            obs_noise,
            spectral_radius,
            stabilised,
        },
    })
}

/// §4.2: diagonal `A_k` by per-parameter least squares, `d = 0`, `B = I`.
fn initial(y: &Mat<f64>, p: &EmParams) -> Result<Lambda> {
    let (t_len, n, k) = (y.nrows(), y.ncols(), p.order);
    let mut a = Mat::<f64>::zeros(n, n * k);
    for i in 0..n {
        let mut g = Mat::<f64>::zeros(k, k);
        let mut h = Mat::<f64>::zeros(k, 1);
        for t in k..t_len {
            for u in 0..k {
                h[(u, 0)] += y[(t, i)] * y[(t - 1 - u, i)];
                for v in 0..k {
                    g[(u, v)] += y[(t - 1 - u, i)] * y[(t - 1 - v, i)];
                }
            }
        }
        let ridge = 1e-6 * (t_len as f64);
        for u in 0..k {
            g[(u, u)] += ridge;
        }
        let llt = g
            .llt(Side::Lower)
            .map_err(|e| LearnedError::Numerical(format!("initial AR fit: {e:?}")))?;
        use faer::prelude::Solve;
        let c = llt.solve(&h);
        for u in 0..k {
            a[(i, u * n + i)] = c[(u, 0)];
        }
    }
    Ok(Lambda {
        a,
        d: vec![0.0; n],
        q: Mat::identity(n, n),
        r: vec![p.obs_noise * p.obs_noise; n],
    })
}

/// Cholesky factor (lower) of a symmetric positive (semi)definite matrix, adding jitter
/// to the diagonal until it factors.
fn chol(m: &Mat<f64>) -> Result<Mat<f64>> {
    let n = m.nrows();
    let scale = (0..n)
        .map(|i| m[(i, i)].abs())
        .fold(0.0, f64::max)
        .max(1e-12);
    let mut jitter = 0.0;
    for _ in 0..12 {
        let mut s = Mat::from_fn(n, n, |i, j| 0.5 * (m[(i, j)] + m[(j, i)]));
        for i in 0..n {
            s[(i, i)] += jitter;
        }
        if let Ok(llt) = s.llt(Side::Lower) {
            return Ok(llt.L().to_owned());
        }
        jitter = if jitter == 0.0 {
            1e-10 * scale
        } else {
            jitter * 10.0
        };
    }
    Err(LearnedError::Numerical(
        "covariance is not positive definite".into(),
    ))
}

/// The E-step: fully adapted particle filter with history smoothing. Returns the
/// log-likelihood, the smoothed second-moment matrix `Σ_t E[z_t z_tᵀ]` of
/// `z_t = [x_t, x_{t−1}, …, x_{t−K}, 1]`, and `Σ_t E[(y_t − x_t)²]` per parameter.
fn e_step(
    y: &Mat<f64>,
    lam: &Lambda,
    p: &EmParams,
    rng: &mut Rng,
) -> Result<(f64, Mat<f64>, Vec<f64>)> {
    let (t_len, n, k, np) = (y.nrows(), y.ncols(), p.order, p.particles);
    // Predictive covariance of y given the history, S = Q + R, and the optimal proposal
    // x ~ N(m + G (y − m), Σ*), G = Q S⁻¹, Σ* = Q − G Q.
    let mut s = lam.q.clone();
    for i in 0..n {
        s[(i, i)] += lam.r[i];
    }
    let ls = chol(&s)?;
    let logdet: f64 = 2.0 * (0..n).map(|i| ls[(i, i)].ln()).sum::<f64>();
    let llt = s
        .llt(Side::Lower)
        .map_err(|e| LearnedError::Numerical(format!("S = Q + R: {e:?}")))?;
    use faer::prelude::Solve;
    let gt = llt.solve(&lam.q); // S⁻¹ Q = Gᵀ
    let mut sig = lam.q.clone();
    matmul(&mut sig, Accum::Add, gt.transpose(), &lam.q, -1.0, Par::Seq);
    let lp = chol(&sig)?;
    let norm_const = -0.5 * (logdet + n as f64 * (2.0 * std::f64::consts::PI).ln());

    let mut xs: Vec<Mat<f64>> = Vec::with_capacity(t_len);
    let mut anc: Vec<Vec<usize>> = Vec::with_capacity(t_len);
    // First K states: the observation plus observation noise (flat prior).
    for t in 0..k {
        xs.push(Mat::from_fn(np, n, |_, i| {
            y[(t, i)] + lam.r[i].sqrt() * rng.normal()
        }));
        anc.push((0..np).collect());
    }
    let mut h = Mat::from_fn(np, n * k, |pi, c| xs[k - 1 - c / n][(pi, c % n)]);
    let mut m = Mat::<f64>::zeros(np, n);
    let mut e = Mat::<f64>::zeros(n, np);
    let mut prop = Mat::<f64>::zeros(np, n);
    let mut xi = Mat::<f64>::zeros(np, n);
    let mut lw = vec![0.0; np];
    let mut ll = 0.0;
    for t in k..t_len {
        // Predictive means m = H Aᵀ + d.
        matmul(&mut m, Accum::Replace, &h, lam.a.transpose(), 1.0, Par::Seq);
        for pi in 0..np {
            for i in 0..n {
                m[(pi, i)] += lam.d[i];
                e[(i, pi)] = y[(t, i)] - m[(pi, i)];
            }
        }
        // Proposal means m + (y − m) Gᵀ, computed before whitening e.
        prop.copy_from(&m);
        matmul(&mut prop, Accum::Add, e.transpose(), &gt, 1.0, Par::Seq);
        ls.solve_lower_triangular_in_place(&mut e);
        let mut maxw = f64::NEG_INFINITY;
        for (pi, w) in lw.iter_mut().enumerate() {
            let q: f64 = (0..n).map(|i| e[(i, pi)] * e[(i, pi)]).sum();
            *w = norm_const - 0.5 * q;
            maxw = maxw.max(*w);
        }
        let sum: f64 = lw.iter().map(|w| (w - maxw).exp()).sum();
        if !sum.is_finite() || sum <= 0.0 {
            return Err(LearnedError::Numerical(format!(
                "particle weights vanished at step {t}"
            )));
        }
        ll += maxw + (sum / np as f64).ln();
        // Systematic resampling.
        let mut idx = Vec::with_capacity(np);
        let u0 = rng.f64() / np as f64;
        let (mut c, mut j) = ((lw[0] - maxw).exp() / sum, 0usize);
        for pi in 0..np {
            let u = u0 + pi as f64 / np as f64;
            while u > c && j + 1 < np {
                j += 1;
                c += (lw[j] - maxw).exp() / sum;
            }
            idx.push(j);
        }
        // Propagate: x = proposal mean of the ancestor + L* ξ.
        for pi in 0..np {
            for i in 0..n {
                xi[(pi, i)] = rng.normal();
            }
        }
        let mut x = Mat::from_fn(np, n, |pi, i| prop[(idx[pi], i)]);
        matmul(&mut x, Accum::Add, &xi, lp.transpose(), 1.0, Par::Seq);
        let old = h.clone();
        for pi in 0..np {
            for i in 0..n {
                h[(pi, i)] = x[(pi, i)];
            }
            for c in n..n * k {
                h[(pi, c)] = old[(idx[pi], c - n)];
            }
        }
        xs.push(x);
        anc.push(idx);
    }

    // Smoothing statistics from particle histories, accumulated in blocks.
    let dz = n * (k + 1) + 1;
    let mut g = Mat::<f64>::zeros(dz, dz);
    let mut resid = vec![0.0; n];
    let block_steps = (4096 / np).max(1);
    let mut t0 = k;
    while t0 < t_len {
        let t1 = (t0 + block_steps).min(t_len);
        let mut z = Mat::<f64>::zeros((t1 - t0) * np, dz);
        for t in t0..t1 {
            let s_ref = (t + p.smoothing_lag).min(t_len - 1);
            for pi in 0..np {
                let mut j = pi;
                for tau in (t + 1..=s_ref).rev() {
                    j = anc[tau][j];
                }
                let row = (t - t0) * np + pi;
                for lag in 0..=k {
                    if lag > 0 {
                        j = anc[t - lag + 1][j];
                    }
                    for i in 0..n {
                        z[(row, lag * n + i)] = xs[t - lag][(j, i)];
                    }
                }
                z[(row, dz - 1)] = 1.0;
                for (i, r) in resid.iter_mut().enumerate() {
                    *r += (y[(t, i)] - z[(row, i)]).powi(2) / np as f64;
                }
            }
        }
        matmul(
            &mut g,
            Accum::Add,
            z.transpose(),
            &z,
            1.0 / np as f64,
            Par::Seq,
        );
        t0 = t1;
    }
    Ok((ll, g, resid))
}

/// The M-step: maximum-likelihood `[A d]`, `Q = B Bᵀ` and `r` from smoothed moments.
fn m_step(
    g: &Mat<f64>,
    resid: &[f64],
    n: usize,
    k: usize,
    count: usize,
    p: &EmParams,
) -> Result<Lambda> {
    let pd = n * k + 1;
    let sxx = g.submatrix(0, 0, n, n).to_owned();
    let sphix = g.submatrix(n, 0, pd, n).to_owned();
    let sphiphi = g.submatrix(n, n, pd, pd).to_owned();
    // A small ridge keeps the normal equations solvable when there are about as many
    // frames as regressors (26·K + 1) or a parameter is constant; it is raised tenfold
    // until the Cholesky factorisation succeeds.
    let mut ridge = 1e-4 * count as f64;
    let llt = loop {
        let mut s = sphiphi.clone();
        for i in 0..pd {
            s[(i, i)] += ridge;
        }
        match s.llt(Side::Lower) {
            Ok(l) => break l,
            Err(e) if ridge > 1e3 * count as f64 => {
                return Err(LearnedError::Numerical(format!(
                    "M-step normal equations: {e:?}"
                )))
            }
            Err(_) => ridge *= 10.0,
        }
    };
    use faer::prelude::Solve;
    let theta_t = llt.solve(&sphix); // pd × n
    let mut q = sxx;
    matmul(
        &mut q,
        Accum::Add,
        theta_t.transpose(),
        &sphix,
        -1.0,
        Par::Seq,
    );
    let inv = 1.0 / count as f64;
    let q = Mat::from_fn(n, n, |i, j| {
        0.5 * (q[(i, j)] + q[(j, i)]) * inv + if i == j { 1e-9 } else { 0.0 }
    });
    let a = Mat::from_fn(n, n * k, |i, c| theta_t[(c, i)]);
    let d = (0..n).map(|i| theta_t[(pd - 1, i)]).collect();
    let floor = p.min_obs_noise * p.min_obs_noise;
    let r = resid.iter().map(|v| (v * inv).max(floor)).collect();
    Ok(Lambda { a, d, q, r })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn too_few_steps_is_a_clear_error() {
        let s = vec![vec![1.0, 2.0]; 3];
        let err = learn(
            &s,
            &EmParams::default(),
            &mut ignis_core::progress::NoProgress,
        )
        .unwrap_err();
        assert!(err.to_string().contains("at least 4"), "{err}");
    }

    #[test]
    fn constant_parameters_do_not_break_learning() {
        let mut rng = Rng::new(1);
        let s: Vec<Vec<f64>> = (0..60).map(|_| vec![rng.normal(), 3.0]).collect();
        let p = EmParams {
            particles: 50,
            max_iterations: 5,
            ..EmParams::default()
        };
        let l = learn(&s, &p, &mut ignis_core::progress::NoProgress).unwrap();
        assert!(l.report.spectral_radius < 1.0);
    }
}
