//! Times the motion-compensated morph eigen joins render with, on a 1080p frame pair:
//! the flow at `render::MORPH_FLOW_SIDE` and one detail-preserving in-between
//! (`animate::morph::inbetween_rgba`), beside the plain morph (`ignis_flow::morph_rgba`)
//! on the same flow, in one run. Two synthetic campfire frames 3 apart.
//!
//! `cargo run --release -p ignis-eigen --example morph_1080p [reps]`

use ignis_core::{RgbaFrame, Size};
use ignis_eigen::animate::morph;
use ignis_eigen::synthetic::{synthetic_frame, FlameStyle, SyntheticParams};
use ignis_flow::FlowField;
use std::time::Instant;

type Morph<'a> = dyn Fn(&RgbaFrame, &RgbaFrame, &FlowField, &FlowField) -> RgbaFrame + 'a;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let reps: usize = std::env::args()
        .nth(1)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(15)
        .max(1);
    let p = SyntheticParams {
        size: Size::new(1920, 1080)?,
        frames: 8,
        style: FlameStyle::Campfire,
        seed: 5,
    };
    let (a, b) = (synthetic_frame(&p, 2)?, synthetic_frame(&p, 5)?);
    let fp = ignis_flow::FlowParams {
        max_side: ignis_eigen::render::MORPH_FLOW_SIDE,
        ..Default::default()
    };
    let flows = |a: &RgbaFrame, b: &RgbaFrame| ignis_flow::flow_pair_reduced_rgba(a, b, &fp);
    // Stages of one pair (after a warm-up pair).
    for _ in 0..2 {
        let t = Instant::now();
        let (fw, bw) = flows(&a, &b)?;
        let t2 = t.elapsed();
        let (m, stages) = morph::inbetween_rgba_stages(&a, &b, &fw, &bw, 0.5);
        std::hint::black_box(m);
        let passes: Vec<String> = stages.iter().map(|(n, d)| format!("{n} {d:.1?}")).collect();
        eprintln!(
            "stages (one pair): luma + flow {t2:.1?}, in-between {:.1?} ({})",
            t.elapsed() - t2,
            passes.join(", ")
        );
    }
    let detail: &Morph<'_> = &|a, b, fw, bw| morph::inbetween_rgba(a, b, fw, bw, 0.5);
    let plain: &Morph<'_> = &|a, b, fw, bw| {
        ignis_flow::morph_rgba(a, b, fw, bw, 0.5).expect("frames of one size, t in 0..=1")
    };
    let mut medians = Vec::new();
    for (name, f) in [
        ("detail-preserving in-between", detail),
        ("plain morph", plain),
    ] {
        let mut wall = Vec::new();
        let cpu0 = cpu_s();
        for _ in 0..reps {
            let t = Instant::now();
            let (fw, bw) = flows(&a, &b)?;
            std::hint::black_box(f(&a, &b, &fw, &bw));
            wall.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let cpu = (cpu_s() - cpu0) * 1e3 / reps as f64;
        wall.sort_by(f64::total_cmp);
        let med = wall[wall.len() / 2];
        println!(
            "1080p morph (flow at {} px + {name}): median {med:.1} ms, min {:.1} ms, CPU {cpu:.1} ms per pair, {} threads",
            ignis_eigen::render::MORPH_FLOW_SIDE,
            wall[0],
            rayon::current_num_threads()
        );
        medians.push(med);
    }
    println!(
        "detail-preserving / plain: {:.2}x (median); goal <= 50 ms: {}",
        medians[0] / medians[1],
        if medians[0] <= 50.0 { "met" } else { "not met" }
    );
    if let Ok(l) = std::fs::read_to_string("/proc/loadavg") {
        println!("load average: {}", l.trim());
    }
    Ok(())
}

/// Process CPU seconds (user + system) from /proc/self/stat.
fn cpu_s() -> f64 {
    let s = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let f: Vec<&str> = s
        .rsplit(')')
        .next()
        .unwrap_or("")
        .split_whitespace()
        .collect();
    let tick = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (tick(11) + tick(12)) / 100.0
}
