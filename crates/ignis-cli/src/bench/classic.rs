//! `ignis bench classic`: the classic fire's kernels per pixel at 1080p, one thread and
//! rayon, and the cost of a seamless loop against the plain animation (the preset and the
//! article's per-pixel fire).

use anyhow::Result;
use ignis_classic::{ClassicFire, ClassicParams, Kernel};
use ignis_core::Size;
use std::time::Instant;

/// Headline figures: ns per pixel per frame at 1920×1080 for each kernel, one thread and
/// rayon (per buffer pixel: rows of black sky above the flames are skipped).
pub fn figures(quick: bool) -> Result<serde_json::Value> {
    let size = Size::new(1920, 1080)?;
    let frames = if quick { 5 } else { 200 };
    let mut out = serde_json::Map::new();
    out.insert("size".into(), "1920x1080".into());
    out.insert("threads".into(), rayon::current_num_threads().into());
    out.insert(
        "per_pixel".into(),
        "ns per buffer pixel of a 1080p fire 20 frames after a cold start: the black sky \
         above the flames is not burnt (the same bytes), so this is not per burnt pixel"
            .into(),
    );
    for kernel in [Kernel::Article, Kernel::Buffered] {
        let mut fire = ClassicFire::new(ClassicParams {
            size,
            fade: 1,
            kernel,
            seed: 1,
            ..Default::default()
        })?;
        for _ in 0..20 {
            fire.step();
        }
        for par in [false, true] {
            let t = Instant::now();
            for _ in 0..frames {
                if par {
                    fire.step_par()
                } else {
                    fire.step()
                }
            }
            let ns = t.elapsed().as_secs_f64() * 1e9 / (frames as f64 * size.pixels() as f64);
            let name = format!(
                "{}_{}_ns_per_pixel",
                format!("{kernel:?}").to_lowercase(),
                if par { "rayon" } else { "1thread" }
            );
            out.insert(name, ((ns * 1000.0).round() / 1000.0).into());
        }
    }
    // a seamless loop of 120 frames at 320×200 (settling included) against the plain
    // animation with the CLI's default warm-up, both drawn through the palette as a render
    // does: the preset `ignis classic` renders by default, and the article's per-pixel fire
    let loop_frames = if quick { 24 } else { 120 };
    let base = ClassicParams {
        size: Size::new(320, 200)?,
        seed: 1,
        ..ClassicParams::preset()
    };
    let mut case = loop_case(base.clone(), loop_frames)?;
    case["article"] = loop_case(
        ClassicParams {
            cell: 1,
            puff: 0.0,
            ..base
        },
        loop_frames,
    )?;
    out.insert("loop".into(), case);
    Ok(serde_json::Value::Object(out))
}

/// Runs of each loop case (the fastest counts).
const REPEATS: usize = 15;

/// The cost of an `n`-frame seamless loop of `params` against the plain animation, each as
/// `ignis classic` renders it (warm-up 60 frames; the loop settled until its buffer repeats
/// and re-timed to even steps).
fn loop_case(params: ClassicParams, n: u32) -> Result<serde_json::Value> {
    let palette = ignis_core::Palette::preset("classic")?;
    let cap = (16 * n as u64)
        .max(40 * params.size.height as u64)
        .max(4000);
    // the best of several alternating runs: on a loaded machine a single run of a few
    // milliseconds measures the other processes
    let mut times = [f64::INFINITY; 2];
    // and the CPU time of all runs of each (every thread of the process): steadier than
    // the wall clock when other processes share the cores
    let mut cpu = [0u64; 2];
    let mut settled = 0;
    for (i, looping) in [false, true]
        .into_iter()
        .cycle()
        .take(2 * REPEATS)
        .enumerate()
    {
        let i = i % 2;
        let t = Instant::now();
        let c = process_cpu_ns();
        let mut fire = if looping {
            ClassicFire::new_looping(params.clone(), n)?
        } else {
            ClassicFire::new(params.clone())?
        };
        settled = fire.settle_loop(60, cap).unwrap_or(cap);
        if looping {
            fire.even_loop_steps(&palette, [0.0; 3]);
        }
        for _ in 0..n {
            fire.step_par();
            std::hint::black_box(fire.rgba(&palette));
        }
        times[i] = times[i].min(t.elapsed().as_secs_f64());
        if let (Some(a), Some(b)) = (c, process_cpu_ns()) {
            cpu[i] += b.saturating_sub(a);
        }
    }
    let cpu_ms = |c: u64| (c as f64 / REPEATS as f64 / 1e5).round() / 10.0;
    Ok(serde_json::json!({
        "case": format!(
            "{} (cells of {} px, puff {}), {n} frames through the palette",
            params.size, params.cell, params.puff
        ),
        "plain_ms": (times[0] * 1e4).round() / 10.0,
        "looping_ms": (times[1] * 1e4).round() / 10.0,
        "settle_frames": settled,
        "timing": format!("best of {REPEATS} alternating runs each, wall clock"),
        "overhead": ((times[1] / times[0] - 1.0) * 1000.0).round() / 1000.0,
        "plain_cpu_ms": cpu_ms(cpu[0]),
        "looping_cpu_ms": cpu_ms(cpu[1]),
        "cpu_overhead": if cpu[0] > 0 {
            ((cpu[1] as f64 / cpu[0] as f64 - 1.0) * 1000.0).round() / 1000.0
        } else {
            f64::NAN
        },
        "cpu_timing": "CPU time of every thread, mean of the same runs (Linux; 0 elsewhere)",
        "goal_overhead": 0.1,
    }))
}

/// CPU time so far of every thread of this process, ns (the first field of each thread's
/// `/proc/self/task/*/schedstat`); `None` where that is not available.
fn process_cpu_ns() -> Option<u64> {
    let mut total = 0u64;
    for task in std::fs::read_dir("/proc/self/task").ok()? {
        let stat = std::fs::read_to_string(task.ok()?.path().join("schedstat")).ok()?;
        total += stat.split_whitespace().next()?.parse::<u64>().ok()?;
    }
    Some(total)
}
