//! `ignis bench flow`: dense optical flow and the motion-compensated morph.

use anyhow::{Context, Result};

/// `ignis bench flow`: the speed goals of `ignis-flow` on synthetic pairs, and how well
/// the motion-compensated mid frame predicts the real middle frame of the shared footage
/// (when `../shared/data` is present) against the plain 50/50 blend.
pub fn figures(quick: bool) -> Result<serde_json::Value> {
    use serde_json::json;
    let p = ignis_flow::FlowParams::default();
    let mut out = serde_json::Map::new();
    out.insert("threads".into(), rayon::current_num_threads().into());
    // Wall-clock figures scale with how busy the machine is; say how busy it was.
    if let Ok(l) = std::fs::read_to_string("/proc/loadavg") {
        if let Some(one) = l
            .split_whitespace()
            .next()
            .and_then(|v| v.parse::<f64>().ok())
        {
            out.insert("load_average_1min".into(), one.into());
        }
    }
    out.insert(
        "params".into(),
        json!({"max_side": p.max_side, "patch": p.patch, "stride": p.stride,
               "finest_scale": p.finest_scale, "iterations": p.iterations,
               "refine_iterations": p.refine_iterations}),
    );
    for t in ignis_flow::bench::figures(quick, &process_cpu_ms)? {
        out.insert(
            t.name.into(),
            json!({"size": t.size.to_string(), "median_ms": t.median_ms, "min_ms": t.min_ms,
                   "cpu_ms": t.cpu_ms, "goal_ms": t.goal_ms, "goal_met": t.goal_met(),
                   "mean_error_px": t.mean_error_px}),
        );
    }
    let starts: &[u64] = if quick {
        &[100]
    } else {
        &[30, 100, 200, 300, 400]
    };
    let mut rows = Vec::new();
    for clip in ["candle.mp4", "campfire.mp4", "fireball.mp4"] {
        let Some(path) = crate::demo::shared_data(clip) else {
            continue;
        };
        for &s in starts {
            let opts = ignis_media::ReadOptions {
                range: Some(ignis_media::FrameRange::frames(s, Some(s + 3))),
                ..Default::default()
            };
            let fr: Vec<ignis_core::RgbaFrame> = ignis_media::open(&path, &opts)?
                .collect::<std::result::Result<_, _>>()
                .with_context(|| format!("decoding {}", path.display()))?;
            if fr.len() < 3 {
                continue;
            }
            let e = ignis_flow::bench::mid_frame_error(&fr[0], &fr[1], &fr[2], &p)?;
            rows.push(json!({"clip": clip, "frames": format!("{s}..{}", s + 3),
                             "morph_mae": e.morph_mae, "blend_mae": e.blend_mae,
                             "ratio": e.ratio()}));
        }
    }
    if rows.is_empty() {
        out.insert(
            "morph_vs_blend".into(),
            "skipped: ../shared/data not found".into(),
        );
    } else {
        out.insert("morph_vs_blend".into(), rows.into());
    }
    Ok(out.into())
}

/// CPU time of this process (all threads), in ms.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
pub fn process_cpu_ms() -> Option<f64> {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec for the duration of the call.
    let r = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    (r == 0).then(|| ts.tv_sec as f64 * 1e3 + ts.tv_nsec as f64 / 1e6)
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
pub fn process_cpu_ms() -> Option<f64> {
    None
}
