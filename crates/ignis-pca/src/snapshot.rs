//! Exact PCA: the snapshot method and the covariance method.
//!
//! Source: eigenfires-thesis.txt §4.2, eq. (15)–(17). The thesis forms L = AᵀA (M×M) because
//! M < N, takes its eigenvectors vₗ and builds the eigenfires as uₗ = A vₗ. We normalise:
//! ‖A v‖² = vᵀ AᵀA v = s, so uₗ = A vₗ / √sₗ is a unit vector, and λₗ = sₗ / M (eq. 13).
//!
//! Precision of the Gram matrix: the data is `f32` and the products run as `f32` faer GEMMs
//! (SIMD, twice the throughput of `f64` and no `f64` copy of a 2.4 GB matrix), but only over row
//! blocks of [`GRAM_BLOCK`] pixels; each block's M×M result is added into an `f64` Gram. The
//! rounding error of a block is then that of a 2,048-term `f32` dot product (≈ 1e-6 relative),
//! and it does not grow with N as a single 274,700-term `f32` accumulation would. The M×M
//! eigendecomposition runs in `f64` (cheap: M ≤ a few thousand).
//!
//! Memory: the components overwrite the centred data in place, row block by row block (each
//! block of A is read whole into a b×k GEMM result before its first k columns are overwritten),
//! so no second N×M buffer exists; afterwards the matrix is truncated to N×k.

use faer::diag::Diag;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::evd;
use faer::linalg::matmul::triangular::{self, BlockStructure};
use faer::{Accum, Mat, MatRef, Par};
use rayon::prelude::*;

use crate::{check_finite_mean, column_mean, fix_signs, resolve_keep, Keep, Pca, PcaError};

/// Pixels per row block for the Gram matrix and the component products.
pub(crate) const GRAM_BLOCK: usize = 2048;

/// Eigenvalues below this fraction of the largest are numerically zero for f32 data.
pub(crate) fn zero_tol(largest: f64) -> f64 {
    largest * 10.0 * f32::EPSILON as f64
}

/// Centres `a` in place: A ← A − Ψ 1ᵀ (a rank-1 GEMM). Returns Ψ.
pub(crate) fn centre_in_place(a: &mut Mat<f32>) -> Result<Vec<f32>, PcaError> {
    let (n, m) = (a.nrows(), a.ncols());
    let mean = column_mean(a.as_ref());
    check_finite_mean(&mean)?;
    let ones = Mat::<f32>::full(1, m, 1.0);
    crate::rows_gemm(
        a.as_mut(),
        Accum::Add,
        MatRef::from_column_major_slice(&mean, n, 1),
        ones.as_ref(),
        -1.0f32,
    );
    Ok(mean)
}

/// Row-block groups of [`gram_lower`]: a fixed number, so the sums do not depend on the
/// thread count. Each holds an M×M f64 accumulator while the Gram is summed; two keep that
/// within the snapshot method's workspace ([`crate::memory`]) and the two cores of a
/// modest machine busy, the grouping its two-thread runs always had.
pub(crate) const GRAM_GROUPS: usize = 2;

/// Lower triangle of AᵀA (M×M, f64), from f32 GEMMs over row blocks. The row blocks are split
/// into at most [`GRAM_GROUPS`] contiguous ranges, each summed in order into its own f64
/// accumulator (M²·8 bytes each) on rayon's pool, and the ranges' sums are added in order:
/// the same additions in the same order at any thread count. (With one range per thread, as
/// before, a two-thread Gram could differ from a one-thread one in its last bits wherever
/// the f64 sums of the f32 blocks rounded.)
pub(crate) fn gram_lower(a: MatRef<'_, f32>) -> Mat<f64> {
    let (n, m) = (a.nrows(), a.ncols());
    let blocks = n.div_ceil(GRAM_BLOCK);
    let groups = GRAM_GROUPS.min(blocks).max(1);
    let add_lower = |x: &mut Mat<f64>, y: &Mat<f64>| {
        for j in 0..m {
            for (p, q) in x.col_as_slice_mut(j)[j..]
                .iter_mut()
                .zip(&y.col_as_slice(j)[j..])
            {
                *p += *q;
            }
        }
    };
    let sums: Vec<Mat<f64>> = (0..groups)
        .into_par_iter()
        .map(|gi| {
            let mut g = Mat::<f64>::zeros(m, m);
            let mut blk = Mat::<f32>::zeros(m, m);
            for bi in (gi * blocks / groups)..((gi + 1) * blocks / groups) {
                let r0 = bi * GRAM_BLOCK;
                let rows = a.subrows(r0, GRAM_BLOCK.min(n - r0));
                triangular::matmul(
                    blk.as_mut(),
                    BlockStructure::TriangularLower,
                    Accum::Replace,
                    rows.transpose(),
                    BlockStructure::Rectangular,
                    rows,
                    BlockStructure::Rectangular,
                    1.0f32,
                    Par::Seq,
                );
                // Add the lower triangle into the f64 Gram (an f32→f64 accumulation, which
                // faer has no kernel for).
                for j in 0..m {
                    let gc = &mut g.col_as_slice_mut(j)[j..];
                    for (x, y) in gc.iter_mut().zip(&blk.col_as_slice(j)[j..]) {
                        *x += *y as f64;
                    }
                }
            }
            g
        })
        .collect();
    let mut sums = sums.into_iter();
    let mut g = sums.next().unwrap_or_else(|| Mat::zeros(m, m));
    for y in sums {
        add_lower(&mut g, &y);
    }
    g
}

/// Descending (eigenvalue, eigenvector index) pairs of a symmetric matrix given by its lower
/// triangle, dropping numerically zero ones and keeping at most `max_k`.
fn sorted_eigen(g: &Mat<f64>, max_k: usize) -> Result<(Vec<f64>, Mat<f64>), PcaError> {
    let (s, u) = self_adjoint_evd_seq(g)?;
    let s = s.column_vector();
    let n = s.nrows();
    let largest = if n > 0 { s[n - 1].max(0.0) } else { 0.0 };
    let tol = zero_tol(largest);
    let mut vals = Vec::new();
    let mut idx = Vec::new();
    for i in (0..n).rev() {
        if vals.len() == max_k || s[i].is_nan() || s[i] <= tol {
            break;
        }
        vals.push(s[i]);
        idx.push(i);
    }
    let v = Mat::<f64>::from_fn(u.nrows(), idx.len(), |r, c| u[(r, idx[c])]);
    Ok((vals, v))
}

/// The eigendecomposition of a symmetric matrix given by its lower triangle (eigenvalues
/// ascending, eigenvectors as columns), computed sequentially. faer's `self_adjoint_eigen`
/// splits its tridiagonalisation by the global parallelism (rayon's current thread count)
/// above a few hundred rows, and the split changes the rounding: a database trained on two
/// threads differed from one trained on one in the last bits of every eigenvalue and weight.
/// Sequential, the result does not depend on the caller's thread count; the M×M problem is
/// small beside the Gram matrix and the components.
fn self_adjoint_evd_seq(g: &Mat<f64>) -> Result<(Diag<f64>, Mat<f64>), PcaError> {
    let n = g.nrows();
    let mut u = Mat::<f64>::zeros(n, n);
    let mut s = Diag::<f64>::zeros(n);
    let par = Par::Seq;
    let scratch = evd::self_adjoint_evd_scratch::<f64>(
        n,
        evd::ComputeEigenvectors::Yes,
        par,
        Default::default(),
    );
    evd::self_adjoint_evd(
        g.as_ref(),
        s.as_mut(),
        Some(u.as_mut()),
        par,
        MemStack::new(&mut MemBuffer::new(scratch)),
        Default::default(),
    )
    .map_err(|e| {
        PcaError::Numerical(format!(
            "eigendecomposition failed: {e:?} (NaN or infinite input?)"
        ))
    })?;
    Ok((s, u))
}

/// Snapshot PCA, consuming `a` (N×M) and reusing its buffer for the components.
/// Returns the PCA and the training weights (k×M).
pub(crate) fn snapshot_in_place(a: Mat<f32>, keep: Keep) -> Result<(Pca, Mat<f32>), PcaError> {
    snapshot_in_place_timed(a, keep).map(|(p, w, _)| (p, w))
}

/// Wall time of each phase of a snapshot fit ([`crate::Pca::fit_snapshot_timed`]), seconds.
#[derive(Clone, Copy, Debug, Default)]
pub struct SnapshotPhases {
    pub centre: f64,
    pub gram: f64,
    pub eigen: f64,
    pub components: f64,
}

pub(crate) fn snapshot_in_place_timed(
    mut a: Mat<f32>,
    keep: Keep,
) -> Result<(Pca, Mat<f32>, SnapshotPhases), PcaError> {
    let (n, m) = (a.nrows(), a.ncols());
    let mut ph = SnapshotPhases::default();
    let t = std::time::Instant::now();
    let mean = centre_in_place(&mut a)?;
    ph.centre = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let g = gram_lower(a.as_ref());
    ph.gram = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();
    let trace: f64 = (0..m).map(|i| g[(i, i)]).sum();
    let total_variance = trace / m as f64;
    let max_k = (m - 1).min(n);
    let (s, v) = sorted_eigen(&g, max_k)?;
    drop(g);
    let eig: Vec<f64> = s.iter().map(|x| x / m as f64).collect();
    let k = resolve_keep(keep, &eig, total_variance);

    // W = V Λ^{-1/2} (f32, M×k); weights Ω = √S Vᵀ (k×M).
    let w = Mat::<f32>::from_fn(m, k, |r, c| (v[(r, c)] / s[c].sqrt()) as f32);
    let mut weights = Mat::<f32>::from_fn(k, m, |r, c| (v[(c, r)] * s[r].sqrt()) as f32);
    drop(v);
    ph.eigen = t.elapsed().as_secs_f64();
    let t = std::time::Instant::now();

    // Components U = A W, written over A block by block (blocks in parallel, each with a b×k
    // scratch; each block is read whole by its GEMM before its first k columns are overwritten).
    a.as_mut().par_row_chunks_mut(GRAM_BLOCK).for_each_init(
        || Mat::<f32>::zeros(GRAM_BLOCK.min(n), k),
        |tmp, mut chunk| {
            let b = chunk.nrows();
            let mut t = tmp.as_mut().subrows_mut(0, b);
            faer::linalg::matmul::matmul(
                t.as_mut(),
                Accum::Replace,
                chunk.as_ref(),
                w.as_ref(),
                1.0f32,
                Par::Seq,
            );
            chunk.as_mut().subcols_mut(0, k).copy_from(t.as_ref());
        },
    );
    a.truncate(n, k);
    fix_signs(&mut a, Some(&mut weights));
    ph.components = t.elapsed().as_secs_f64();
    let pca = Pca {
        mean,
        components: a,
        eigenvalues: eig[..k].to_vec(),
        total_variance,
        n_samples: m,
    };
    Ok((pca, weights, ph))
}

/// Covariance-method PCA (N×N eigendecomposition); for M > N. Does not modify `data`.
pub(crate) fn covariance(data: MatRef<'_, f32>, keep: Keep) -> Result<Pca, PcaError> {
    let (n, m) = (data.nrows(), data.ncols());
    let mut a = data.to_owned();
    let mean = centre_in_place(&mut a)?;
    // C·M = A Aᵀ = (Aᵀ)ᵀ Aᵀ: the Gram of the transposed matrix, blocked over frames.
    let g = gram_lower(a.as_ref().transpose());
    drop(a);
    let trace: f64 = (0..n).map(|i| g[(i, i)]).sum();
    let total_variance = trace / m as f64;
    let max_k = (m - 1).min(n);
    let (s, v) = sorted_eigen(&g, max_k)?;
    let eig: Vec<f64> = s.iter().map(|x| x / m as f64).collect();
    let k = resolve_keep(keep, &eig, total_variance);
    let mut u = Mat::<f32>::from_fn(n, k, |r, c| v[(r, c)] as f32);
    fix_signs(&mut u, None);
    Ok(Pca {
        mean,
        components: u,
        eigenvalues: eig[..k].to_vec(),
        total_variance,
        n_samples: m,
    })
}
