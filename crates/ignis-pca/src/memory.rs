//! Memory accounting: say how big the data matrix and the workspace are before allocating.
//!
//! Source: eigenfires-thesis.txt §7.3 (the training stage's memory bound the number of frames).
//! A fit is refused with [`PcaError::LimitExceeded`] before any large allocation when the budget
//! (`PcaOptions::memory_limit` or what the machine reports available) is too small.

use faer::Mat;

use crate::snapshot::{GRAM_BLOCK, GRAM_GROUPS};
use crate::{Method, PcaError};

const F32: u64 = 4;
const F64: u64 = 8;

/// Bytes a data matrix of `n`×`m` f32 plus `method`'s workspace need (what [`crate::Pca::fit`]
/// needs on top of the data it is given, or [`crate::Pca::fit_owned`] in total).
/// `Method::Auto` is resolved as the fit would resolve it.
pub fn required_bytes(n: usize, m: usize, method: &Method) -> u64 {
    data_bytes(n, m).saturating_add(workspace_bytes(n, m, method))
}

/// Bytes of an `n`×`m` f32 matrix.
pub fn data_bytes(n: usize, m: usize) -> u64 {
    (n as u64).saturating_mul(m as u64).saturating_mul(F32)
}

/// Bytes the method allocates besides the data matrix itself.
pub(crate) fn workspace_bytes(n: usize, m: usize, method: &Method) -> u64 {
    let (n64, m64) = (n as u64, m as u64);
    let method = match method {
        Method::Auto if m > n => Method::Covariance,
        Method::Auto => Method::Snapshot,
        other => *other,
    };
    let sq = |x: u64| x.saturating_mul(x);
    match method {
        // The larger of: while the Gram is summed, one f64 accumulator and one f32 block
        // per group of row blocks; after, Gram f64 + eigenvectors f64 + eigen scratch (≈ one
        // more M² f64) + selected eigenvectors + W f32 + weights f32. Then the b×k block + Ψ.
        Method::Snapshot | Method::Auto => sq(m64)
            .saturating_mul((GRAM_GROUPS as u64 * (F64 + F32)).max(4 * F64 + 3 * F32))
            .saturating_add((GRAM_BLOCK as u64).min(n64).saturating_mul(m64) * F32)
            .saturating_add(n64 * F32),
        // Centred copy + the larger of the Gram's groups (as above, N×N) and N² Gram f64 +
        // eigenvectors + scratch + components f32.
        Method::Covariance => data_bytes(n, m).saturating_add(
            sq(n64)
                .saturating_mul((GRAM_GROUPS as u64 * (F64 + F32)).max(3 * F64 + 2 * F32))
                .saturating_add(n64 * F32),
        ),
        // Y, Q, product buffers (N×l, three of them), M×l sketches, l×M B, SVD of B.
        Method::Randomized { k, oversample, .. } => {
            let l = (k.saturating_add(oversample)).min(n.min(m)) as u64;
            (n64.saturating_mul(l).saturating_mul(3 * F32))
                .saturating_add(m64.saturating_mul(l).saturating_mul(4 * F32))
                .saturating_add(sq(l).saturating_mul(2 * F32))
                .saturating_add(n64 * 2 * F32)
        }
    }
}

/// Bytes this process may still allocate: `MemAvailable` from /proc/meminfo, capped by the cgroup
/// v2 limit (`memory.max − memory.current`) when one is set. `u64::MAX` when unknown.
pub fn available_bytes() -> u64 {
    let mut avail = u64::MAX;
    if let Ok(s) = std::fs::read_to_string("/proc/meminfo") {
        if let Some(kb) = s
            .lines()
            .find(|l| l.starts_with("MemAvailable:"))
            .and_then(|l| l.split_whitespace().nth(1))
            .and_then(|v| v.parse::<u64>().ok())
        {
            avail = kb.saturating_mul(1024);
        }
    }
    let read = |p: &str| {
        std::fs::read_to_string(p)
            .ok()
            .and_then(|s| s.trim().parse::<u64>().ok())
    };
    if let (Some(max), Some(cur)) = (
        read("/sys/fs/cgroup/memory.max"),
        read("/sys/fs/cgroup/memory.current"),
    ) {
        avail = avail.min(max.saturating_sub(cur));
    }
    avail.min(address_space_left())
}

/// Address space this process may still map under `RLIMIT_AS` (`ulimit -v`): the soft
/// limit minus the current `VmSize`; `u64::MAX` when unlimited or unknown. Past it every
/// allocation fails, whatever memory the machine has free.
pub fn address_space_left() -> u64 {
    #[cfg(unix)]
    {
        let mut r = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        // SAFETY: `r` is a valid rlimit to fill.
        if unsafe { libc::getrlimit(libc::RLIMIT_AS, &mut r) } != 0
            || r.rlim_cur == libc::RLIM_INFINITY
        {
            return u64::MAX;
        }
        let used = std::fs::read_to_string("/proc/self/status")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("VmSize:"))
                    .and_then(|l| l.split_whitespace().nth(1))
                    .and_then(|v| v.parse::<u64>().ok())
            })
            .map_or(0, |kb| kb.saturating_mul(1024));
        // `rlim_t` is u64 here but not on every unix (i64 on FreeBSD), so the cast stays.
        #[allow(clippy::unnecessary_cast)]
        let limit = r.rlim_cur as u64;
        limit.saturating_sub(used)
    }
    #[cfg(not(unix))]
    {
        u64::MAX
    }
}

/// Refuses `needed` bytes when over the budget.
pub(crate) fn check(needed: u64, limit: Option<u64>, n: usize, m: usize) -> Result<(), PcaError> {
    let available = limit.unwrap_or_else(available_bytes);
    if needed > available {
        return Err(PcaError::LimitExceeded {
            needed,
            available,
            hint: format!(
                "a {n}×{m} f32 data matrix is {}; use fewer frames, crop or scale the frames, \
                 Method::Randomized for the top components, or the streaming path \
                 ignis_pca::fit_streaming, which reads frames from disk in blocks",
                human_bytes(data_bytes(n, m))
            ),
        });
    }
    Ok(())
}

/// Allocates a zeroed N×M f32 data matrix after checking that it and `method`'s workspace fit in
/// `memory_limit` (or the available memory). Never allocates when refusing.
pub fn alloc_data_matrix(
    n: usize,
    m: usize,
    method: &Method,
    memory_limit: Option<u64>,
) -> Result<Mat<f32>, PcaError> {
    if n == 0 || m == 0 {
        return Err(crate::bad(
            "data",
            "a data matrix needs ≥ 1 pixel and ≥ 1 frame",
        ));
    }
    check(required_bytes(n, m, method), memory_limit, n, m)?;
    Ok(Mat::zeros(n, m))
}

/// "2.41 GB"-style size (decimal units).
pub fn human_bytes(b: u64) -> String {
    let b = b as f64;
    if b >= 1e12 {
        format!("{:.2} TB", b / 1e12)
    } else if b >= 1e9 {
        format!("{:.2} GB", b / 1e9)
    } else if b >= 1e6 {
        format!("{:.1} MB", b / 1e6)
    } else {
        format!("{b:.0} B")
    }
}
