//! Times the motion-compensated morph eigen joins render with, on a 1080p frame pair:
//! the flow at `render::MORPH_FLOW_SIDE` and one detail-preserving in-between
//! (`animate::morph::inbetween_rgba`). Two synthetic campfire frames 3 apart.
//!
//! `cargo run --release -p ignis-eigen --example morph_1080p [reps]`

use ignis_core::Size;
use ignis_eigen::synthetic::{synthetic_frame, FlameStyle, SyntheticParams};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let reps: usize = std::env::args()
        .nth(1)
        .map(|s| s.parse())
        .transpose()?
        .unwrap_or(15);
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
    {
        let t = Instant::now();
        let (la, lb) = rayon::join(|| ignis_flow::luma(&a), || ignis_flow::luma(&b));
        let t1 = t.elapsed();
        let (fw, bw) = ignis_flow::flow_pair_reduced(&la, &lb, &fp)?;
        let t2 = t.elapsed();
        let (wa, wb) = rayon::join(
            || ignis_flow::warp_rgba(&a, &fw, -0.5),
            || ignis_flow::warp_rgba(&b, &bw, -0.5),
        );
        let t3 = t.elapsed();
        let m = ignis_eigen::animate::morph::detail_blend_rgba(&wa, &wb, 0.5);
        let t4 = t.elapsed();
        std::hint::black_box(m);
        eprintln!(
            "stages (one pair): luma {t1:?}, flow {:?}, warps {:?}, detail-preserving blend {:?}",
            t2 - t1,
            t3 - t2,
            t4 - t3
        );
    }
    let mut wall = Vec::new();
    let cpu0 = cpu_s();
    for _ in 0..reps {
        let t = Instant::now();
        let (la, lb) = rayon::join(|| ignis_flow::luma(&a), || ignis_flow::luma(&b));
        let (fw, bw) = ignis_flow::flow_pair_reduced(&la, &lb, &fp)?;
        let m = ignis_eigen::animate::morph::inbetween_rgba(&a, &b, &fw, &bw, 0.5);
        std::hint::black_box(m);
        wall.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let cpu = (cpu_s() - cpu0) * 1e3 / reps as f64;
    wall.sort_by(f64::total_cmp);
    println!(
        "1080p morph (flow at {} px + detail-preserving in-between): median {:.1} ms, min {:.1} ms, CPU {:.1} ms per pair, {} threads",
        ignis_eigen::render::MORPH_FLOW_SIDE,
        wall[wall.len() / 2],
        wall[0],
        cpu,
        rayon::current_num_threads()
    );
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
