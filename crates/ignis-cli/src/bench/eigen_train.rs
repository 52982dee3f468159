//! `ignis bench eigen-train`: snapshot PCA of synthetic flame frames up to the thesis' size
//! (M = 2,197 frames of 410×670), and the randomized path, with time and peak memory.

use ignis_pca::{
    fit_streaming, synthetic_flames, Keep, MatSource, Method, Pca, PcaOptions, StreamingOptions,
};
use serde_json::{json, Value};
use std::time::Instant;

/// A `kB` field of /proc/self/status in bytes (Linux; `None` elsewhere).
fn status_bytes(field: &str) -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let kb: u64 = s
        .lines()
        .find(|l| l.starts_with(field))?
        .split_whitespace()
        .nth(1)?
        .parse()
        .ok()?;
    Some(kb * 1024)
}

/// Peak resident set size of this process (VmHWM), bytes.
fn peak_rss() -> Option<u64> {
    status_bytes("VmHWM:")
}

/// Current resident set size (VmRSS), bytes.
fn rss() -> Option<u64> {
    status_bytes("VmRSS:")
}

/// CPU time (user + system) of this process so far, seconds, from /proc/self/stat (clock ticks
/// assumed 100 Hz, the Linux default). On a shared machine wall time overstates our cost;
/// `cpu_s / threads` is what the run would take with the cores to itself (if it scaled).
fn cpu_seconds() -> f64 {
    let Ok(s) = std::fs::read_to_string("/proc/self/stat") else {
        return f64::NAN;
    };
    // Fields after the ")" that closes the command name: state is field 3, utime 14, stime 15.
    let rest = s.rsplit_once(')').map(|(_, r)| r).unwrap_or("");
    let f: Vec<&str> = rest.split_whitespace().collect();
    let tick = |i: usize| {
        f.get(i)
            .and_then(|v| v.parse::<f64>().ok())
            .unwrap_or(f64::NAN)
    };
    (tick(11) + tick(12)) / 100.0
}

/// Resets VmHWM to the current RSS (Linux ≥ 4.0; silently ignored elsewhere).
fn reset_peak() {
    let _ = std::fs::write("/proc/self/clear_refs", "5");
}

/// Snapshot fit of `m` synthetic frames, end to end: generate, centre, Gram, eigen, components,
/// weights of all frames.
fn snapshot_run(w: usize, h: usize, m: usize) -> Value {
    reset_peak();
    let base = rss().unwrap_or(0);
    let gen = synthetic_flames(w, h, 7);
    let t0 = Instant::now();
    let a = gen.data_matrix(m);
    let gen_s = t0.elapsed().as_secs_f64();
    let data_bytes = ignis_pca::memory::data_bytes(w * h, m);
    let t1 = Instant::now();
    let c1 = cpu_seconds();
    let (pca, weights, ph) = Pca::fit_snapshot_timed(a, Keep::All).expect("snapshot fit");
    let fit_s = t1.elapsed().as_secs_f64();
    let fit_cpu_s = cpu_seconds() - c1;
    eprintln!("snapshot {m}x{w}x{h}: generate {gen_s:.2} s, fit {fit_s:.2} s ({ph:?})");
    let peak = peak_rss().unwrap_or(0);
    // Projection throughput: project 64 freshly generated frames with one GEMM.
    let probe_m = 64.min(m);
    let probe = gen.data_matrix(probe_m);
    let t2 = Instant::now();
    let w2 = pca.project_all(probe.as_ref());
    let proj_s = t2.elapsed().as_secs_f64();
    // Weights from the fit equal projections of the training frames: check the first frames.
    let mut max_diff = 0.0f32;
    let mut max_w = 0.0f32;
    for j in 0..probe_m {
        for i in 0..pca.n_components() {
            max_diff = max_diff.max((w2[(i, j)] - weights[(i, j)]).abs());
            max_w = max_w.max(weights[(i, j)].abs());
        }
    }
    let k = pca.n_components();
    json!({
        "name": format!("snapshot pca {m}x{w}x{h}"),
        "frames": m, "pixels": w * h, "components": k,
        "data_matrix_bytes": data_bytes,
        "generate_s": gen_s,
        "fit_and_weights_s": fit_s,
        "fit_and_weights_cpu_s": fit_cpu_s,
        "phases_s": { "centre": ph.centre, "gram": ph.gram, "eigen": ph.eigen, "components_and_weights": ph.components },
        "total_s": gen_s + fit_s,
        "peak_rss_bytes": peak,
        "peak_rss_over_data": peak.saturating_sub(base) as f64 / data_bytes as f64,
        "project_64_frames_s": proj_s,
        "project_per_frame_ms": 1e3 * proj_s / probe_m as f64,
        "weights_vs_projection_max_rel_diff": max_diff / max_w.max(1e-30),
        "components_for_95pct": pca.count_for_variance(0.95),
        "components_for_99pct": pca.count_for_variance(0.99),
        "top_eigenvalues": pca.eigenvalues.iter().take(5).collect::<Vec<_>>(),
    })
}

/// Randomized (k = 100) vs snapshot top eigenvalues on the same data.
fn randomized_run(w: usize, h: usize, m: usize, k: usize) -> Value {
    reset_peak();
    let gen = synthetic_flames(w, h, 7);
    let a = gen.data_matrix(m);
    let method = Method::Randomized {
        k,
        oversample: 10,
        power_iters: 2,
        seed: 1,
    };
    let t0 = Instant::now();
    let c0 = cpu_seconds();
    let r = Pca::fit(
        a.as_ref(),
        &PcaOptions {
            method,
            ..Default::default()
        },
    )
    .expect("randomized fit");
    let rand_s = t0.elapsed().as_secs_f64();
    let rand_cpu_s = cpu_seconds() - c0;
    let t1 = Instant::now();
    let s = fit_streaming(
        &mut MatSource { data: a.as_ref() },
        k,
        &StreamingOptions {
            seed: 1,
            ..Default::default()
        },
    )
    .expect("streaming fit");
    let stream_s = t1.elapsed().as_secs_f64();
    let peak = peak_rss().unwrap_or(0);
    let exact = Pca::fit_owned(
        a,
        &PcaOptions {
            keep: Keep::Count(k),
            ..Default::default()
        },
    )
    .expect("exact fit");
    let rel = |p: &Pca| {
        p.eigenvalues
            .iter()
            .zip(&exact.eigenvalues)
            .map(|(a, b)| ((a - b) / b).abs())
            .fold(0.0f64, f64::max)
    };
    let rel_top = |p: &Pca, t: usize| {
        p.eigenvalues
            .iter()
            .zip(&exact.eigenvalues)
            .take(t)
            .map(|(a, b)| ((a - b) / b).abs())
            .fold(0.0f64, f64::max)
    };
    json!({
        "name": format!("randomized pca k{k} {m}x{w}x{h}"),
        "frames": m, "pixels": w * h, "k": k, "oversample": 10, "power_iters": 2,
        "randomized_in_memory_s": rand_s,
        "streaming_in_memory_source_s": stream_s,
        "peak_rss_bytes": peak,
        "max_rel_eigenvalue_err_top_k": rel(&r),
        "randomized_in_memory_cpu_s": rand_cpu_s,
        "max_rel_eigenvalue_err_top_10": rel_top(&r, 10),
        "max_rel_eigenvalue_err_top_k_half": rel_top(&r, k / 2),
        "streaming_max_rel_eigenvalue_err_top_k": rel(&s),
    })
}

/// Headline figures as one JSON object. `quick` uses small frames (about a second); the full run
/// is the thesis size (M = 2,197 frames of 410×670) plus 500 and 1,000 frames and the randomized
/// path for k = 100 — a few minutes and ≈ 2.5 GB of memory.
pub fn figures(quick: bool) -> Value {
    let threads = rayon::current_num_threads();
    let (w, h, sizes, rk): (usize, usize, Vec<usize>, usize) = if quick {
        (82, 134, vec![100, 200, 439], 20)
    } else {
        (410, 670, vec![500, 1000, 2197], 100)
    };
    let m_max = *sizes.last().expect("sizes");
    let runs: Vec<Value> = sizes.iter().map(|&m| snapshot_run(w, h, m)).collect();
    let rand = randomized_run(w, h, m_max, rk);
    json!({
        "bench": "eigen-train",
        "quick": quick,
        "threads": threads,
        "goal": "snapshot PCA + weights of all 2197x410x670 frames <= 30 s, peak RSS <= 1.5x data matrix",
        "snapshot": runs,
        "randomized": rand,
    })
}
