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

/// Runs of each loop case, alternating (the fastest counts).
const REPEATS: usize = 21;

/// The cost of an `n`-frame seamless loop of `params` against the plain animation, each as
/// `ignis classic` renders it (warm-up 60 frames; the loop solved and re-timed to even
/// steps), both drawing the same number of frames through the palette.
fn loop_case(params: ClassicParams, n: u32) -> Result<serde_json::Value> {
    let palette = ignis_core::Palette::preset("classic")?;
    let cap = (16 * n as u64)
        .max(40 * params.size.height as u64)
        .max(4000);
    // alternating runs, so both cases see the same load; on a loaded machine a run of a
    // few milliseconds also measures the other processes, which only ever add time: the
    // least run of each counts, wall clock and CPU time (every thread of the process,
    // rayon's included), with the median CPU time beside it
    let mut wall: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
    let mut cpu: [Vec<f64>; 2] = [Vec::new(), Vec::new()];
    let (mut settled, mut solve_steps) = (0, None);
    for (i, looping) in [false, true]
        .into_iter()
        .cycle()
        .take(2 * REPEATS)
        .enumerate()
    {
        let i = i % 2;
        let t = Instant::now();
        let c = super::flow::process_cpu_ms();
        let mut fire = if looping {
            ClassicFire::new_looping(params.clone(), n)?
        } else {
            ClassicFire::new(params.clone())?
        };
        settled = fire.settle_loop(60, cap).unwrap_or(cap);
        if looping {
            fire.even_loop_steps(&palette, [0.0; 3]);
            solve_steps = fire.loop_solve_steps();
        }
        for _ in 0..n {
            fire.step_par();
            std::hint::black_box(fire.rgba(&palette));
        }
        wall[i].push(t.elapsed().as_secs_f64());
        if let (Some(a), Some(b)) = (c, super::flow::process_cpu_ms()) {
            cpu[i].push((b - a) / 1e3);
        }
    }
    let least = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
    let (plain, looping) = (least(&wall[0]), least(&wall[1]));
    let ms = |s: f64| (s * 1e4).round() / 1e1;
    let ratio = |a: f64, b: f64| ((a / b - 1.0) * 1000.0).round() / 1000.0;
    let mut out = serde_json::json!({
        "case": format!(
            "{} (cells of {} px, puff {}), {n} frames through the palette",
            params.size, params.cell, params.puff
        ),
        "plain_ms": ms(plain),
        "looping_ms": ms(looping),
        "settle_frames": settled,
        "solve_steps_per_row": solve_steps.map(|s| (s * 10.0).round() / 10.0),
        "timing": format!("least of {REPEATS} alternating runs each, wall clock"),
        "overhead": ratio(looping, plain),
        "goal_overhead": 0.1,
    });
    if cpu.iter().all(|c| c.len() == REPEATS) {
        let [mut p, mut l] = cpu;
        let median = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let (pm, lm) = (median(&mut p), median(&mut l));
        let (pl, ll) = (least(&p), least(&l));
        out["plain_cpu_ms"] = ms(pl).into();
        out["looping_cpu_ms"] = ms(ll).into();
        out["cpu_overhead"] = ratio(ll, pl).into();
        out["plain_cpu_median_ms"] = ms(pm).into();
        out["looping_cpu_median_ms"] = ms(lm).into();
        out["cpu_median_overhead"] = ratio(lm, pm).into();
        out["cpu_timing"] =
            "CPU time of the process (every thread, CLOCK_PROCESS_CPUTIME_ID) per run: least and median of the same runs".into();
    }
    Ok(out)
}
