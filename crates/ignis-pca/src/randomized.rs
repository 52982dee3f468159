//! Randomized PCA for the top k components, in memory or streamed from disk in blocks of frames.
//!
//! Source: Halko, Martinsson & Tropp, "Finding structure with randomness" (SIAM Review 2011),
//! alg. 4.4 (randomized subspace iteration) and 5.1 (direct SVD), applied to the centred data
//! matrix A − Ψ1ᵀ of eigenfires-thesis.txt §4.2 eq. (15). Not in the thesis: it is how a clip too
//! large for the snapshot method's N×M matrix (§7.3) is still analysed.
//!
//! The data is only ever touched one block of frames (columns) at a time, so the same code serves
//! an in-memory matrix ([`MatSource`]), a memory-mapped `.npy` file ([`NpySource`]) or any reader
//! ([`BlockSource`]). Passes over the data: one for the mean, one for the sketch Y = AΩ and the
//! total variance, two per power iteration (Z = orth(AᵀQ), then Y = AZ) and one for the
//! projection B = QᵀA: 7 with the default 2 power iterations.
//! Blocks are centred explicitly once Ψ is known (an implicit A Ω − Ψ(1ᵀΩ) would cancel
//! catastrophically in f32 when the mean dominates). The products over all pixels (AᵀQ, QᵀA)
//! split the pixel dimension across rayon threads (see `at_b` in lib.rs) and the orthonormal
//! bases come from sequential Householder QRs (see `orth`).
//!
//! Accuracy (bench, 2,197 synthetic frames, k = 100, oversample 10, 2 power iterations): top 10
//! eigenvalues within ~1e-5 of the exact ones; those near the noise floor (index ≳ 50) are
//! underestimated by up to ~50 % — more `power_iters` or `oversample` tighten them.

use faer::{Accum, Mat, MatRef};
use ignis_core::Rng;

use crate::npy::MmapF32;
use crate::snapshot::zero_tol;
use crate::{bad, fix_signs, memory, resolve_keep, Keep, Method, Pca, PcaError};

/// A source of frames for [`fit_streaming`]: N pixels per frame, M frames, read in blocks.
pub trait BlockSource {
    /// N, pixels per frame.
    fn n_pixels(&self) -> usize;
    /// M, number of frames.
    fn n_frames(&self) -> usize;
    /// Reads frames `start..start + out.ncols()` (fewer at the end) into the columns of `out`
    /// (N×b) and returns how many were read.
    fn read_block(&mut self, start: usize, out: &mut Mat<f32>) -> Result<usize, PcaError>;
}

/// [`BlockSource`] over an in-memory N×M matrix.
pub struct MatSource<'a> {
    pub data: MatRef<'a, f32>,
}

impl BlockSource for MatSource<'_> {
    fn n_pixels(&self) -> usize {
        self.data.nrows()
    }
    fn n_frames(&self) -> usize {
        self.data.ncols()
    }
    fn read_block(&mut self, start: usize, out: &mut Mat<f32>) -> Result<usize, PcaError> {
        let b = out.ncols().min(self.data.ncols().saturating_sub(start));
        out.as_mut()
            .subcols_mut(0, b)
            .copy_from(self.data.subcols(start, b));
        Ok(b)
    }
}

/// [`BlockSource`] over a memory-mapped `.npy` f32 file whose frames are contiguous: shape (N, M)
/// in Fortran order or (M, N) in C order. Pages are read by the OS on demand, so the file may be
/// larger than memory.
pub struct NpySource {
    map: MmapF32,
    n: usize,
    m: usize,
}

impl NpySource {
    /// Opens `path`; see the type docs for the accepted layouts.
    pub fn open(path: &std::path::Path) -> Result<NpySource, PcaError> {
        let map = crate::npy::mmap_f32(path)?;
        let shape = map.header().shape.clone();
        let (n, m) = match (shape.as_slice(), map.header().fortran_order) {
            ([n, m], true) => (*n, *m),
            ([m, n], false) => (*n, *m),
            ([n], _) => (*n, 1),
            _ => {
                return Err(PcaError::Unsupported {
                    path: path.to_owned(),
                    reason: format!(
                        "shape {shape:?}: need a 2-D array (N, M) in Fortran order or (M, N) in C order"
                    ),
                })
            }
        };
        Ok(NpySource { map, n, m })
    }
}

impl BlockSource for NpySource {
    fn n_pixels(&self) -> usize {
        self.n
    }
    fn n_frames(&self) -> usize {
        self.m
    }
    fn read_block(&mut self, start: usize, out: &mut Mat<f32>) -> Result<usize, PcaError> {
        let b = out.ncols().min(self.m.saturating_sub(start));
        let s = self.map.as_slice();
        let src =
            MatRef::from_column_major_slice(&s[start * self.n..(start + b) * self.n], self.n, b);
        out.as_mut().subcols_mut(0, b).copy_from(src);
        Ok(b)
    }
}

/// Options of [`fit_streaming`].
#[derive(Clone, Debug, PartialEq)]
pub struct StreamingOptions {
    /// Extra sketch columns beyond k (accuracy of the k-th component). Default 10.
    pub oversample: usize,
    /// Subspace iterations, one pass over the data each; 2 suffices for decaying spectra. Default 2.
    pub power_iters: usize,
    /// Seed of the Gaussian test matrix (`ignis_core::Rng`). Default 0.
    pub seed: u64,
    /// Frames per block read from the source. Default 64 (N×64×4 bytes: 70 MB at 410×670).
    pub block_frames: usize,
    /// Components to retain out of the k computed. Default [`Keep::All`].
    pub keep: Keep,
    /// Memory budget in bytes; `None` = available memory.
    pub memory_limit: Option<u64>,
}

impl Default for StreamingOptions {
    fn default() -> Self {
        StreamingOptions {
            oversample: 10,
            power_iters: 2,
            seed: 0,
            block_frames: 64,
            keep: Keep::All,
            memory_limit: None,
        }
    }
}

/// Top-`k` PCA of a source too large for memory: a randomized range finder reading the frames in
/// blocks, in `2·power_iters + 3` passes. Memory ≈ N·(k + oversample)·12 + N·block_frames·4 bytes.
pub fn fit_streaming(
    src: &mut dyn BlockSource,
    k: usize,
    opts: &StreamingOptions,
) -> Result<Pca, PcaError> {
    if k == 0 {
        return Err(bad("k", "k = 0 computes no component"));
    }
    if opts.block_frames == 0 {
        return Err(bad("block_frames", "must be ≥ 1"));
    }
    if let Keep::Count(0) = opts.keep {
        return Err(bad("keep", "Keep::Count(0) keeps no component"));
    }
    if let Keep::Variance(f) = opts.keep {
        if !(f > 0.0 && f <= 1.0) {
            return Err(bad(
                "keep",
                format!("Keep::Variance({f}) must be in (0, 1]"),
            ));
        }
    }
    let (n, m) = (src.n_pixels(), src.n_frames());
    if m == 0 {
        return Err(bad("data", "zero frames"));
    }
    if n == 0 {
        return Err(bad("data", "zero pixels"));
    }
    let method = Method::Randomized {
        k,
        oversample: opts.oversample,
        power_iters: opts.power_iters,
        seed: opts.seed,
    };
    let block = opts.block_frames.min(m);
    memory::check(
        memory::workspace_bytes(n, m, &method).saturating_add(memory::data_bytes(n, block)),
        opts.memory_limit,
        n,
        m,
    )?;
    run(src, &method, block, opts.keep)
}

/// In-memory randomized fit (no copy of the data: blocks of 64 frames are centred on the fly).
pub(crate) fn fit_in_memory(
    data: MatRef<'_, f32>,
    method: &Method,
    keep: Keep,
) -> Result<Pca, PcaError> {
    let mut src = MatSource { data };
    run(&mut src, method, 64.min(data.ncols()), keep)
}

/// Reads every block, centres it and hands it to `f(first_frame, block)`.
fn for_each_block(
    src: &mut dyn BlockSource,
    buf: &mut Mat<f32>,
    mean: Option<&[f32]>,
    mut f: impl FnMut(usize, MatRef<'_, f32>),
) -> Result<(), PcaError> {
    let (n, m) = (src.n_pixels(), src.n_frames());
    let mut start = 0;
    while start < m {
        let got = src.read_block(start, buf)?;
        if got == 0 || got > buf.ncols() {
            return Err(bad(
                "source",
                format!(
                    "read_block({start}) returned {got} frames for a block of {}",
                    buf.ncols()
                ),
            ));
        }
        if let Some(mean) = mean {
            let ones = Mat::<f32>::full(1, got, 1.0);
            crate::rows_gemm(
                buf.as_mut().subcols_mut(0, got),
                Accum::Add,
                MatRef::from_column_major_slice(mean, n, 1),
                ones.as_ref(),
                -1.0f32,
            );
        }
        f(start, buf.as_ref().subcols(0, got));
        start += got;
    }
    Ok(())
}

/// Prints the time since the previous call when `IGNIS_PCA_DEBUG` is set (diagnostics only).
fn debug_time(what: &str) {
    use std::sync::Mutex;
    static LAST: Mutex<Option<std::time::Instant>> = Mutex::new(None);
    if std::env::var_os("IGNIS_PCA_DEBUG").is_some() {
        let mut last = LAST.lock().unwrap_or_else(|e| e.into_inner());
        let now = std::time::Instant::now();
        if let Some(t) = *last {
            eprintln!("ignis-pca: {what}: {:.2} s", (now - t).as_secs_f64());
        }
        *last = Some(now);
    }
}

/// Orthonormal basis of the columns of a tall `y` (thin Q of a Householder QR), run with
/// `Par::Seq`: `y.qr()` uses faer's global parallelism, whose spin-waiting pool is many times
/// slower on a loaded machine (`benches/README.md`).
fn orth(y: &Mat<f32>) -> Mat<f32> {
    use faer::dyn_stack::{MemBuffer, MemStack};
    use faer::linalg::householder as hh;
    use faer::linalg::qr::no_pivoting::factor;
    let (m, n) = y.shape();
    let size = m.min(n);
    let par = faer::Par::Seq;
    let bs = factor::recommended_block_size::<f32>(m, n);
    let mut qr = y.clone();
    let mut coeff = Mat::<f32>::zeros(bs, size);
    factor::qr_in_place(
        qr.as_mut(),
        coeff.as_mut(),
        par,
        MemStack::new(&mut MemBuffer::new(factor::qr_in_place_scratch::<f32>(
            m,
            n,
            bs,
            par,
            Default::default(),
        ))),
        Default::default(),
    );
    // Householder basis: unit lower trapezoid (as faer's `Qr` stores it).
    let mut basis = qr.as_mut().subcols_mut(0, size);
    for j in 0..size {
        for i in 0..j {
            basis[(i, j)] = 0.0;
        }
        basis[(j, j)] = 1.0;
    }
    let mut q = Mat::<f32>::identity(m, size);
    hh::apply_block_householder_sequence_on_the_left_in_place_with_conj(
        qr.as_ref().subcols(0, size),
        coeff.as_ref(),
        faer::Conj::No,
        q.as_mut(),
        par,
        MemStack::new(&mut MemBuffer::new(
            hh::apply_block_householder_sequence_on_the_left_in_place_scratch::<f32>(m, bs, size),
        )),
    );
    debug_time("orth");
    q
}

fn run(
    src: &mut dyn BlockSource,
    method: &Method,
    block: usize,
    keep: Keep,
) -> Result<Pca, PcaError> {
    let Method::Randomized {
        k,
        oversample,
        power_iters,
        seed,
    } = *method
    else {
        unreachable!("run() is only called with Method::Randomized");
    };
    let (n, m) = (src.n_pixels(), src.n_frames());
    let l = (k + oversample).min(n).min(m).max(1);
    let mut buf = Mat::<f32>::zeros(n, block);
    debug_time("start");

    // Pass 1: mean Ψ (f64 accumulation of per-block f32 GEMVs).
    let mut sum = vec![0.0f64; n];
    {
        let mut part = Mat::<f32>::zeros(n, 1);
        for_each_block(src, &mut buf, None, |_, a| {
            let ones = Mat::<f32>::full(a.ncols(), 1, 1.0);
            crate::rows_gemm(part.as_mut(), Accum::Replace, a, ones.as_ref(), 1.0f32);
            for (s, p) in sum.iter_mut().zip(part.col_as_slice(0)) {
                *s += *p as f64;
            }
        })?;
    }
    let mean: Vec<f32> = sum.iter().map(|s| (s / m as f64) as f32).collect();
    drop(sum);
    crate::check_finite_mean(&mean)?;

    // Pass 2: Y = A Ω with a Gaussian Ω (M×l); total variance.
    let mut rng = Rng::new(seed);
    let mut omega = Mat::<f32>::zeros(m, l);
    for j in 0..l {
        for x in omega.col_as_slice_mut(j) {
            *x = rng.normal() as f32;
        }
    }
    let zeros = vec![0.0f32; n];
    let mut y = Mat::<f32>::zeros(n, l);
    let mut total = 0.0f64;
    for_each_block(src, &mut buf, Some(&mean), |s, a| {
        crate::rows_gemm(
            y.as_mut(),
            Accum::Add,
            a,
            omega.as_ref().subrows(s, a.ncols()),
            1.0f32,
        );
        total += crate::centred_sq_norm(a, &zeros);
    })?;
    drop(omega);
    debug_time("mean + sketch");

    // Power iterations (alg. 4.4): Z = orth(Aᵀ Q), Y = A Z — two passes each. Orthonormalising
    // between A and Aᵀ matters in f32: Y = A Aᵀ Q in one go squares the condition number and the
    // directions below √ε·σ₁ drown in rounding (measured: only ~20 of 100 survived).
    for _ in 0..power_iters {
        let q = orth(&y);
        let mut z = Mat::<f32>::zeros(m, l);
        for_each_block(src, &mut buf, Some(&mean), |s, a| {
            z.as_mut()
                .subrows_mut(s, a.ncols())
                .copy_from(crate::at_b(a, q.as_ref()));
        })?;
        drop(q);
        debug_time("Z = A^T Q pass");
        let z = orth(&z);
        y.fill(0.0);
        for_each_block(src, &mut buf, Some(&mean), |s, a| {
            crate::rows_gemm(
                y.as_mut(),
                Accum::Add,
                a,
                z.as_ref().subrows(s, a.ncols()),
                1.0f32,
            );
        })?;
    }
    debug_time("Y = A Z pass");

    // Final pass: B = Qᵀ A (l×M).
    let q = orth(&y);
    drop(y);
    let mut bmat = Mat::<f32>::zeros(l, m);
    for_each_block(src, &mut buf, Some(&mean), |s, a| {
        bmat.as_mut()
            .subcols_mut(s, a.ncols())
            .copy_from(crate::at_b(a, q.as_ref()).transpose());
    })?;
    drop(buf);
    debug_time("projection B = Q^T A");

    // faer's SVD splits its work by the global parallelism (rayon's current thread count),
    // and the split changes the rounding: run it on a one-thread pool so the result does
    // not depend on the caller's thread count (the sketch is small: k × N).
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .map_err(|e| PcaError::Numerical(format!("cannot start a thread pool: {e}")))?;
    let svd = one
        .install(|| bmat.thin_svd())
        .map_err(|e| PcaError::Numerical(format!("SVD failed: {e:?} (NaN or infinite input?)")))?;
    let sv = svd.S().column_vector();
    let largest = if sv.nrows() > 0 {
        (sv[0] as f64).powi(2)
    } else {
        0.0
    };
    let tol = zero_tol(largest);
    let max_k = k.min(m - 1).min(n);
    let eig: Vec<f64> = (0..sv.nrows())
        .map(|i| (sv[i] as f64).powi(2))
        .take_while(|s| *s > tol)
        .take(max_k)
        .map(|s| s / m as f64)
        .collect();
    let total_variance = total / m as f64;
    let kk = resolve_keep(keep, &eig, total_variance);
    let mut u = Mat::<f32>::zeros(n, kk);
    crate::rows_gemm(
        u.as_mut(),
        Accum::Replace,
        q.as_ref(),
        svd.U().subcols(0, kk),
        1.0f32,
    );
    fix_signs(&mut u, None);
    Ok(Pca {
        mean,
        components: u,
        eigenvalues: eig[..kk].to_vec(),
        total_variance,
        n_samples: m,
    })
}
