//! Principal component analysis of fire videos ("Eigenfires").
//!
//! Source: /work/shared/seeds/eigenfires-thesis.txt §4.2, eq. (12)–(17) (mean fire Ψ, covariance
//! C = A Aᵀ, the M×M snapshot matrix L = Aᵀ A, eigenfires u = A v), §4.3 eq. (18) (weights
//! Ω = uᵀ (I − Ψ)), §4.8 eq. (22) (reconstruction Ψ + Σ ωᵢ uᵢ), §7.1/§7.3 (sizes: M = 2,197 frames
//! of N = 410×670 = 274,700 pixels; the PCA time and memory limit of the thesis' implementation).
//!
//! Conventions and deliberate departures from the paper:
//! - The data matrix is N pixels × M frames, `f32`, column-major (`faer::Mat<f32>`): one column is
//!   one frame in whatever pixel order the caller uses (ignis frames are row-major, row 0 = top).
//!   Values are whatever the caller put in (ignis uses linear-light luminance).
//! - Eigenvalues are variances along each component with the paper's 1/M normalisation (eq. 13),
//!   not the unbiased 1/(M−1); `total_variance` uses the same normalisation, so
//!   `explained_variance_ratio` does not depend on the choice.
//! - The paper keeps M−1 eigenfires. We keep at most min(M−1, N) and additionally drop directions
//!   whose eigenvalue is below `10·ε_f32·λ₁` (numerically zero for `f32` data: their directions
//!   are noise and would break orthonormality).
//! - Each component's sign is fixed so that its entry of largest magnitude is positive, which makes
//!   every method (snapshot, covariance, randomized, streaming) return the same signs.
//! - The snapshot Gram matrix is formed with `f32` faer GEMMs over row blocks of 2,048 pixels whose
//!   results are accumulated in `f64` (see snapshot.rs for why).

use std::path::PathBuf;

use faer::{Mat, MatRef, Par};

pub mod memory;
pub mod npy;
mod randomized;
mod snapshot;
mod synthetic;

pub use memory::{alloc_data_matrix, available_bytes, required_bytes};
pub use randomized::{fit_streaming, BlockSource, MatSource, NpySource, StreamingOptions};
pub use snapshot::SnapshotPhases;
pub use synthetic::{synthetic_flames, SyntheticFlames};

/// Errors of the PCA crate, split by who is at fault.
#[derive(Debug, thiserror::Error)]
pub enum PcaError {
    /// A parameter or input shape is invalid (the caller's fault).
    #[error("bad parameter `{name}`: {reason}")]
    BadParameter { name: &'static str, reason: String },
    /// The computation would need more memory than is available. Raised before allocating.
    #[error(
        "not enough memory: needs {} but only {} is available; {hint}",
        memory::human_bytes(*needed),
        memory::human_bytes(*available)
    )]
    LimitExceeded {
        needed: u64,
        available: u64,
        hint: String,
    },
    /// Reading or writing a file failed.
    #[error("I/O error on {}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file is not in a format we read (say what would be supported).
    #[error("unsupported file {}: {reason}", path.display())]
    Unsupported { path: PathBuf, reason: String },
    /// The eigen/singular value decomposition did not converge (e.g. NaN or infinite input).
    #[error("numerical failure: {0}")]
    Numerical(String),
}

/// How many components to retain.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub enum Keep {
    /// Every meaningful component (at most min(M−1, N), see the module docs).
    #[default]
    All,
    /// The first `n` components (fewer if fewer exist). `n` must be ≥ 1.
    Count(usize),
    /// The fewest components whose explained variance is ≥ this fraction, in (0, 1].
    Variance(f64),
}

/// Which algorithm computes the decomposition.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Method {
    /// `Snapshot` when M ≤ N (video: always), `Covariance` otherwise.
    #[default]
    Auto,
    /// Thesis eq. (16)–(17): eigendecomposition of the M×M Gram matrix Aᵀ A, then u = A v / √s.
    /// Cost ≈ 2·N·M² (Gram, half of it) + 2·N·M·k (components) flops; memory ≈ the data matrix
    /// (centred and turned into the components in place by [`Pca::fit_owned`]) + 3·M²·8 bytes.
    Snapshot,
    /// Eigendecomposition of the N×N covariance A Aᵀ; for few pixels and many frames.
    Covariance,
    /// Randomized range finder (Halko, Martinsson & Tropp 2011, alg. 4.4 + 5.1) for the top `k`
    /// components: sketch size `k + oversample`, `power_iters` subspace iterations, Gaussian test
    /// matrix from `ignis_core::Rng::new(seed)`. Never copies the whole data matrix (blocks of 64
    /// frames are copied and centred on the fly), so memory is ≈ N·(k+oversample)·4·3 bytes on top of the data.
    Randomized {
        k: usize,
        oversample: usize,
        power_iters: usize,
        seed: u64,
    },
}

/// Options of [`Pca::fit`].
#[derive(Clone, Debug, PartialEq, Default)]
pub struct PcaOptions {
    /// Components to retain. Default [`Keep::All`].
    pub keep: Keep,
    /// Algorithm. Default [`Method::Auto`].
    pub method: Method,
    /// Memory budget in bytes for the workspace the fit allocates; `None` (default) = what the
    /// machine reports available (`/proc/meminfo` MemAvailable, capped by the cgroup limit).
    pub memory_limit: Option<u64>,
}

/// A fitted PCA: mean fire Ψ and eigenfires.
#[derive(Clone, Debug)]
pub struct Pca {
    /// Ψ, eq. (12): the mean frame, length N.
    pub mean: Vec<f32>,
    /// N×k, orthonormal columns (the eigenfires), sorted by eigenvalue, largest first.
    pub components: Mat<f32>,
    /// k variances along each component (1/M normalisation, eq. 13), descending.
    pub eigenvalues: Vec<f64>,
    /// Total variance of the data, Σ‖Φₙ‖²/M (the sum of all eigenvalues, retained or not).
    pub total_variance: f64,
    /// M, the number of frames fitted.
    pub n_samples: usize,
}

pub(crate) fn bad(name: &'static str, reason: impl Into<String>) -> PcaError {
    PcaError::BadParameter {
        name,
        reason: reason.into(),
    }
}

impl PcaOptions {
    fn validate(&self) -> Result<(), PcaError> {
        match self.keep {
            Keep::Count(0) => return Err(bad("keep", "Keep::Count(0) keeps no component")),
            Keep::Variance(f) if !(f > 0.0 && f <= 1.0) => {
                return Err(bad(
                    "keep",
                    format!("Keep::Variance({f}) must be in (0, 1]"),
                ))
            }
            _ => {}
        }
        if let Method::Randomized { k, .. } = self.method {
            if k == 0 {
                return Err(bad("method", "Randomized { k: 0 } computes no component"));
            }
        }
        Ok(())
    }

    fn resolved_method(&self, n: usize, m: usize) -> Method {
        match self.method {
            Method::Auto if m > n => Method::Covariance,
            Method::Auto => Method::Snapshot,
            other => other,
        }
    }
}

fn check_shape(n: usize, m: usize) -> Result<(), PcaError> {
    if m == 0 {
        return Err(bad("data", "zero frames (the data matrix has no columns)"));
    }
    if n == 0 {
        return Err(bad("data", "zero pixels (the data matrix has no rows)"));
    }
    Ok(())
}

impl Pca {
    /// Fits a PCA to `data` (N pixels × M frames). The data is not modified; the snapshot and
    /// covariance methods work on a centred copy (checked against the memory budget first), the
    /// randomized method centres blocks of 64 frames on the fly and never copies the whole matrix. Use [`Pca::fit_owned`] to save the
    /// copy.
    pub fn fit(data: MatRef<'_, f32>, opts: &PcaOptions) -> Result<Pca, PcaError> {
        opts.validate()?;
        let (n, m) = (data.nrows(), data.ncols());
        check_shape(n, m)?;
        let method = opts.resolved_method(n, m);
        match method {
            Method::Randomized { .. } => {
                memory::check(
                    memory::workspace_bytes(n, m, &method),
                    opts.memory_limit,
                    n,
                    m,
                )?;
                randomized::fit_in_memory(data, &method, opts.keep)
            }
            _ => {
                // The copy plus the workspace.
                memory::check(required_bytes(n, m, &method), opts.memory_limit, n, m)?;
                Pca::fit_owned(data.to_owned(), opts)
            }
        }
    }

    /// Like [`Pca::fit`] but consumes the data matrix and, for the snapshot method, centres it and
    /// turns it into the components in place, so peak memory stays ≈ the data matrix + O(M²).
    pub fn fit_owned(data: Mat<f32>, opts: &PcaOptions) -> Result<Pca, PcaError> {
        Self::fit_owned_with_weights(data, opts).map(|(pca, _)| pca)
    }

    /// The snapshot fit of [`Pca::fit_owned_with_weights`] (all components: `keep`), timing
    /// each phase (for `ignis bench eigen-train`).
    pub fn fit_snapshot_timed(
        data: Mat<f32>,
        keep: Keep,
    ) -> Result<(Pca, Mat<f32>, SnapshotPhases), PcaError> {
        check_shape(data.nrows(), data.ncols())?;
        snapshot::snapshot_in_place_timed(data, keep)
    }

    /// [`Pca::fit_owned`] that also returns the weights Ω (eq. 18) of every training frame,
    /// k×M, for free: with u = A v/√s, Uᵀ A = √S Vᵀ, so no second pass over the data is needed.
    pub fn fit_owned_with_weights(
        data: Mat<f32>,
        opts: &PcaOptions,
    ) -> Result<(Pca, Mat<f32>), PcaError> {
        opts.validate()?;
        let (n, m) = (data.nrows(), data.ncols());
        check_shape(n, m)?;
        let method = opts.resolved_method(n, m);
        memory::check(
            memory::workspace_bytes(n, m, &method),
            opts.memory_limit,
            n,
            m,
        )?;
        match method {
            Method::Snapshot | Method::Auto => snapshot::snapshot_in_place(data, opts.keep),
            Method::Covariance => {
                let pca = snapshot::covariance(data.as_ref(), opts.keep)?;
                let w = pca.project_all(data.as_ref());
                Ok((pca, w))
            }
            Method::Randomized { .. } => {
                let pca = randomized::fit_in_memory(data.as_ref(), &method, opts.keep)?;
                let w = pca.project_all(data.as_ref());
                Ok((pca, w))
            }
        }
    }

    /// Saves the model into the folder `dir` (created if missing) as four `.npy` files numpy can
    /// open: `mean.npy` (f32, N), `components.npy` (f32, N×k, Fortran order), `eigenvalues.npy`
    /// (f64, k) and `stats.npy` (f64, [total_variance, n_samples]). Each file is written atomically.
    pub fn save(&self, dir: &std::path::Path) -> Result<(), PcaError> {
        std::fs::create_dir_all(dir).map_err(|source| PcaError::Io {
            path: dir.to_owned(),
            source,
        })?;
        npy::write_f32(&dir.join("mean.npy"), &self.mean, &[self.mean.len()], false)?;
        npy::write_mat_f32(&dir.join("components.npy"), self.components.as_ref())?;
        npy::write_f64(
            &dir.join("eigenvalues.npy"),
            &self.eigenvalues,
            &[self.eigenvalues.len()],
            false,
        )?;
        npy::write_f64(
            &dir.join("stats.npy"),
            &[self.total_variance, self.n_samples as f64],
            &[2],
            false,
        )
    }

    /// Loads a model written by [`Pca::save`], checking that the files agree in size.
    pub fn load(dir: &std::path::Path) -> Result<Pca, PcaError> {
        let (mean, _) = npy::read_f32(&dir.join("mean.npy"))?;
        let cpath = dir.join("components.npy");
        let components = npy::read_mat_f32(&cpath)?;
        let (eigenvalues, _) = npy::read_f64(&dir.join("eigenvalues.npy"))?;
        let spath = dir.join("stats.npy");
        let (stats, _) = npy::read_f64(&spath)?;
        if components.nrows() != mean.len() || components.ncols() != eigenvalues.len() {
            return Err(PcaError::Unsupported {
                path: cpath,
                reason: format!(
                    "components are {}×{} but mean has {} pixels and there are {} eigenvalues",
                    components.nrows(),
                    components.ncols(),
                    mean.len(),
                    eigenvalues.len()
                ),
            });
        }
        let [total_variance, n_samples] = stats[..] else {
            return Err(PcaError::Unsupported {
                path: spath,
                reason: "need exactly [total_variance, n_samples]".into(),
            });
        };
        Ok(Pca {
            mean,
            components,
            eigenvalues,
            total_variance,
            n_samples: n_samples as usize,
        })
    }

    /// N, the number of pixels per frame.
    pub fn n_pixels(&self) -> usize {
        self.mean.len()
    }

    /// k, the number of retained components.
    pub fn n_components(&self) -> usize {
        self.components.ncols()
    }

    /// Weights Ω of one frame, eq. (18): ωᵢ = uᵢᵀ (I − Ψ). Length k.
    ///
    /// # Panics
    /// If `frame.len() != N` (a programmer error: the frame size is fixed by the fit).
    pub fn project(&self, frame: &[f32]) -> Vec<f32> {
        assert_eq!(frame.len(), self.n_pixels(), "frame length must equal N");
        let f = MatRef::from_column_major_slice(frame, frame.len(), 1);
        let mut w = self.project_all(f);
        let k = w.nrows();
        (0..k).map(|i| std::mem::take(&mut w[(i, 0)])).collect()
    }

    /// [`Pca::project`] for untrusted input: a frame of the wrong length is an error, not a panic.
    pub fn try_project(&self, frame: &[f32]) -> Result<Vec<f32>, PcaError> {
        if frame.len() != self.n_pixels() {
            return Err(bad(
                "frame",
                format!(
                    "has {} pixels but the model was fitted on {}",
                    frame.len(),
                    self.n_pixels()
                ),
            ));
        }
        Ok(self.project(frame))
    }

    /// Weights of every column of `data` (N×M'), k×M': Uᵀ data − (Uᵀ Ψ) 1ᵀ, one GEMM.
    ///
    /// # Panics
    /// If `data.nrows() != N`.
    pub fn project_all(&self, data: MatRef<'_, f32>) -> Mat<f32> {
        assert_eq!(data.nrows(), self.n_pixels(), "data rows must equal N");
        let mut w = at_b(self.components.as_ref(), data);
        let mean = MatRef::from_column_major_slice(&self.mean, self.mean.len(), 1);
        let um = at_b(self.components.as_ref(), mean);
        let ones = Mat::<f32>::full(1, data.ncols(), 1.0);
        faer::linalg::matmul::matmul(
            w.as_mut(),
            faer::Accum::Add,
            um.as_ref(),
            ones.as_ref(),
            -1.0f32,
            Par::Seq,
        );
        w
    }

    /// Reconstruction, eq. (22): Ψ + Σ_{i<e} ωᵢ uᵢ, using the first `e` weights (`e` is clamped to
    /// `min(k, weights.len())`).
    pub fn reconstruct(&self, weights: &[f32], e: usize) -> Vec<f32> {
        let mut out = vec![0.0f32; self.n_pixels()];
        self.reconstruct_into(weights, e, &mut out);
        out
    }

    /// [`Pca::reconstruct`] into a caller-provided buffer of length N, for real-time use: no
    /// output allocation; the GEMV runs as sequential faer kernels over 4,096-pixel row chunks on
    /// rayon's pool.
    ///
    /// # Panics
    /// If `out.len() != N`.
    pub fn reconstruct_into(&self, weights: &[f32], e: usize, out: &mut [f32]) {
        assert_eq!(out.len(), self.n_pixels(), "output length must equal N");
        out.copy_from_slice(&self.mean);
        let e = e.min(self.n_components()).min(weights.len());
        if e == 0 {
            return;
        }
        let n = out.len();
        let dst = faer::MatMut::from_column_major_slice_mut(out, n, 1);
        let w = MatRef::from_column_major_slice(&weights[..e], e, 1);
        rows_gemm(
            dst,
            faer::Accum::Add,
            self.components.as_ref().subcols(0, e),
            w,
            1.0f32,
        );
    }

    /// Keeps only the first `k` components (no-op if `k ≥` the current count).
    pub fn truncate(&mut self, k: usize) {
        if k < self.n_components() {
            let n = self.components.nrows();
            self.components.truncate(n, k);
            self.eigenvalues.truncate(k);
        }
    }

    /// Fraction of the total variance explained by each retained component.
    pub fn explained_variance_ratio(&self) -> Vec<f64> {
        if self.total_variance <= 0.0 {
            return vec![0.0; self.eigenvalues.len()];
        }
        self.eigenvalues
            .iter()
            .map(|l| l / self.total_variance)
            .collect()
    }

    /// The fewest leading components whose cumulative explained variance is ≥ `frac` (clamped to
    /// the retained count; at least 1 when any component exists).
    pub fn count_for_variance(&self, frac: f64) -> usize {
        count_for_variance(&self.eigenvalues, self.total_variance, frac)
    }
}

pub(crate) fn count_for_variance(eigenvalues: &[f64], total: f64, frac: f64) -> usize {
    if eigenvalues.is_empty() {
        return 0;
    }
    let target = frac * total;
    let mut acc = 0.0;
    for (i, l) in eigenvalues.iter().enumerate() {
        acc += l;
        // Small slack so that frac = 1 is reached despite rounding in the sum.
        if acc >= target * (1.0 - 1e-12) {
            return i + 1;
        }
    }
    eigenvalues.len()
}

/// Number of components to keep from `available` (sorted, nonzero) eigenvalues.
pub(crate) fn resolve_keep(keep: Keep, eigenvalues: &[f64], total: f64) -> usize {
    let avail = eigenvalues.len();
    match keep {
        Keep::All => avail,
        Keep::Count(n) => n.min(avail),
        Keep::Variance(f) => count_for_variance(eigenvalues, total, f),
    }
}

/// Flips each column of `u` (and the matching row of `w`, if given) so that the entry of largest
/// magnitude of the column is positive.
pub(crate) fn fix_signs(u: &mut Mat<f32>, w: Option<&mut Mat<f32>>) {
    use rayon::prelude::*;
    let flips: Vec<bool> = u
        .as_mut()
        .par_col_iter_mut()
        .map(|mut col| {
            let mut best = 0.0f32;
            let mut best_abs = -1.0f32;
            for x in col.as_mut().iter() {
                if x.abs() > best_abs {
                    best_abs = x.abs();
                    best = *x;
                }
            }
            let flip = best < 0.0;
            if flip {
                for x in col.iter_mut() {
                    *x = -*x;
                }
            }
            flip
        })
        .collect();
    if let Some(w) = w {
        for (i, &f) in flips.iter().enumerate() {
            if f {
                for x in w.as_mut().row_mut(i).iter_mut() {
                    *x = -*x;
                }
            }
        }
    }
}

/// Mean of the columns (Ψ, eq. 12) via one GEMV, f32.
pub(crate) fn column_mean(data: MatRef<'_, f32>) -> Vec<f32> {
    let (n, m) = (data.nrows(), data.ncols());
    let mut mean = vec![0.0f32; n];
    let ones = Mat::<f32>::full(m, 1, 1.0);
    rows_gemm(
        faer::MatMut::from_column_major_slice_mut(&mut mean, n, 1),
        faer::Accum::Replace,
        data,
        ones.as_ref(),
        1.0 / m as f32,
    );
    mean
}

/// Row ranges [`at_b`] splits K into, at most: a fixed number (not one per thread, as before:
/// the partial products' f32 sum then depended on the thread count), enough for the cores of
/// a workstation; each holds a p×q partial product.
const AT_B_GROUPS: usize = 8;

/// `aᵀ b` for tall `a` (K×p) and `b` (K×q): K (the pixels) is split into contiguous ranges of
/// at least 8,192 rows, at most [`AT_B_GROUPS`], each a sequential faer GEMM on rayon's pool,
/// and the p×q partial products are added in order. faer's GEMM does not split K across
/// threads (figures: `benches/README.md`).
pub(crate) fn at_b(a: MatRef<'_, f32>, b: MatRef<'_, f32>) -> Mat<f32> {
    use rayon::prelude::*;
    const MIN_ROWS: usize = 8192;
    let (k, p, q) = (a.nrows(), a.ncols(), b.ncols());
    assert_eq!(k, b.nrows());
    let groups = AT_B_GROUPS.min(k.div_ceil(MIN_ROWS)).max(1);
    let parts: Vec<Mat<f32>> = (0..groups)
        .into_par_iter()
        .map(|g| {
            let r0 = g * k / groups;
            let r1 = (g + 1) * k / groups;
            let mut acc = Mat::<f32>::zeros(p, q);
            faer::linalg::matmul::matmul(
                acc.as_mut(),
                faer::Accum::Replace,
                a.subrows(r0, r1 - r0).transpose(),
                b.subrows(r0, r1 - r0),
                1.0f32,
                Par::Seq,
            );
            acc
        })
        .collect();
    let mut parts = parts.into_iter();
    let first = parts.next().unwrap_or_else(|| Mat::zeros(p, q));
    parts.fold(first, |x, y| x + y)
}

/// `dst ← accum(dst) + alpha·lhs·rhs` for a tall `lhs` (and `dst`), split into row chunks that
/// run as sequential faer GEMMs on rayon's pool.
///
/// Parallelism policy of this crate: every faer product runs with `Par::Seq` inside rayon tasks
/// that we split ourselves (row chunks here, pixel ranges in [`at_b`], row blocks for the Gram
/// and the components). faer's own `Par::Rayon` mode hands work to its spin-waiting worker pool,
/// which burns the CPU on a loaded machine while rayon's idle workers sleep
/// (`benches/README.md`).
/// The M×M eigendecomposition runs sequentially and the thin sketches' QR/SVD on a one-thread
/// pool: faer splits those by the thread count, and the split changes the rounding. Every
/// reduction over blocks adds a fixed grouping in a fixed order, so a fit's bits do not
/// depend on the thread count (tests `in_memory_fits_do_not_depend_on_the_thread_count`,
/// `streaming_fit_does_not_depend_on_the_thread_count`).
pub(crate) fn rows_gemm(
    dst: faer::MatMut<'_, f32>,
    accum: faer::Accum,
    lhs: MatRef<'_, f32>,
    rhs: MatRef<'_, f32>,
    alpha: f32,
) {
    use rayon::prelude::*;
    const CHUNK: usize = 4096;
    assert_eq!(dst.nrows(), lhs.nrows());
    let n = dst.nrows();
    if n <= CHUNK {
        faer::linalg::matmul::matmul(dst, accum, lhs, rhs, alpha, Par::Seq);
        return;
    }
    dst.par_row_chunks_mut(CHUNK)
        .enumerate()
        .for_each(|(c, d)| {
            let r0 = c * CHUNK;
            let len = d.nrows();
            faer::linalg::matmul::matmul(d, accum, lhs.subrows(r0, len), rhs, alpha, Par::Seq);
        });
}

/// Any NaN or infinity in the data shows up in the column mean (∞ − ∞ = NaN), so checking Ψ is
/// a free finiteness check of the whole data matrix.
pub(crate) fn check_finite_mean(mean: &[f32]) -> Result<(), PcaError> {
    match mean.iter().position(|x| !x.is_finite()) {
        Some(i) => Err(bad(
            "data",
            format!("contains NaN or infinite values (pixel row {i})"),
        )),
        None => Ok(()),
    }
}

/// Σ‖aⱼ − Ψ‖² accumulated in f64 (the squares are cheap; this is a reduction, not a matrix op).
pub(crate) fn centred_sq_norm(data: MatRef<'_, f32>, mean: &[f32]) -> f64 {
    use rayon::prelude::*;
    data.par_col_iter()
        .map(|col| {
            col.iter()
                .zip(mean)
                .map(|(x, m)| {
                    let d = (*x - *m) as f64;
                    d * d
                })
                .sum::<f64>()
        })
        .sum()
}

#[cfg(test)]
mod unit {
    use super::*;

    #[test]
    fn count_for_variance_thresholds() {
        let ev = [5.0, 3.0, 1.5, 0.5];
        assert_eq!(count_for_variance(&ev, 10.0, 0.5), 1);
        assert_eq!(count_for_variance(&ev, 10.0, 0.8), 2);
        assert_eq!(count_for_variance(&ev, 10.0, 0.81), 3);
        assert_eq!(count_for_variance(&ev, 10.0, 1.0), 4);
        // Total larger than the retained sum (truncated model): clamp to what is there.
        assert_eq!(count_for_variance(&ev, 20.0, 1.0), 4);
        assert_eq!(count_for_variance(&[], 1.0, 0.5), 0);
    }

    #[test]
    fn resolve_keep_variants() {
        let ev = [5.0, 3.0, 2.0];
        assert_eq!(resolve_keep(Keep::All, &ev, 10.0), 3);
        assert_eq!(resolve_keep(Keep::Count(2), &ev, 10.0), 2);
        assert_eq!(resolve_keep(Keep::Count(9), &ev, 10.0), 3);
        assert_eq!(resolve_keep(Keep::Variance(0.75), &ev, 10.0), 2);
    }

    #[test]
    fn auto_method_picks_by_shape() {
        let o = PcaOptions::default();
        assert_eq!(o.resolved_method(100, 10), Method::Snapshot);
        assert_eq!(o.resolved_method(10, 100), Method::Covariance);
    }

    #[test]
    fn signs_make_largest_entry_positive() {
        let mut u = Mat::<f32>::from_fn(3, 2, |i, j| [[0.1, -0.9], [-0.8, 0.3], [0.2, 0.1]][i][j]);
        let mut w = Mat::<f32>::from_fn(2, 1, |i, _| i as f32 + 1.0);
        fix_signs(&mut u, Some(&mut w));
        assert_eq!(u[(1, 0)], 0.8);
        assert_eq!(u[(0, 1)], 0.9);
        assert_eq!((w[(0, 0)], w[(1, 0)]), (-1.0, -2.0));
    }

    #[test]
    fn mean_and_centring() {
        let mut a = Mat::<f32>::from_fn(2, 4, |i, j| (i * 10 + j) as f32);
        let mean = snapshot::centre_in_place(&mut a).unwrap();
        assert_eq!(mean, vec![1.5, 11.5]);
        assert_eq!(a[(0, 0)], -1.5);
        assert_eq!(a[(1, 3)], 1.5);
    }
}
