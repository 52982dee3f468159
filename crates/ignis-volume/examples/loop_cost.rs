//! Looping against plain rendering, in process CPU time as well as wall time (wall time
//! swings by ±30 % on a shared machine): `cargo run --release -p ignis-volume --example
//! loop_cost [repeats]`. Renders each case's frames plain, looping, and looping at uniform
//! loop times (no preview: [`LoopTiming::UNIFORM`]), in turn, and prints the medians, so
//! the overhead splits into the looping frames' own and the preview's. Figures go in
//! `benches/README.md`.

use ignis_core::Size;
use ignis_volume::{FireScene, LoopTiming, Preset};
use std::time::Instant;

/// User + system CPU seconds of this process so far (Linux `/proc/self/stat`; `None`
/// elsewhere).
fn cpu_seconds() -> Option<f64> {
    let stat = std::fs::read_to_string("/proc/self/stat").ok()?;
    // fields after the command name, which is in parentheses
    let rest = &stat[stat.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    let ticks = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}

/// CPU and wall seconds of `frames` frames: plain (`timing` `None`) or looping.
fn run(scene: &FireScene, frames: u32, timing: Option<LoopTiming>) -> (f64, f64) {
    let (c0, t0) = (cpu_seconds().unwrap_or(0.0), Instant::now());
    let mut a = match timing {
        Some(t) => scene.looping_animator_with(frames, t).expect("valid"),
        None => scene.animator().expect("valid"),
    };
    for _ in 0..frames {
        a.next_frame().expect("renders");
    }
    (
        cpu_seconds().unwrap_or(0.0) - c0,
        t0.elapsed().as_secs_f64(),
    )
}

/// CPU seconds to build the looping animator alone (its simulation run-ahead and the
/// preview that times its frames).
fn setup_cost(scene: &FireScene, frames: u32) -> f64 {
    let c0 = cpu_seconds().unwrap_or(0.0);
    for _ in 0..3 {
        scene.looping_animator(frames).expect("valid");
    }
    (cpu_seconds().unwrap_or(0.0) - c0) / 3.0
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn main() {
    let repeats: usize = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(3);
    for (p, side, frames) in [
        (Preset::Torch, 256, 48),
        (Preset::Campfire, 256, 48),
        (Preset::Torch, 512, 64),
    ] {
        let scene = FireScene::preset(p).with_size(Size::new(side, side).expect("valid"));
        let timings = [None, Some(LoopTiming::DEFAULT), Some(LoopTiming::UNIFORM)];
        let mut res = [(); 3].map(|_| [Vec::new(), Vec::new()]);
        for _ in 0..repeats {
            for (i, t) in timings.into_iter().enumerate() {
                let (cpu, wall) = run(&scene, frames, t);
                res[i][0].push(cpu);
                res[i][1].push(wall);
            }
        }
        let [[pc, pw], [lc, lw], [uc, _]] = res.map(|r| r.map(median));
        let setup = setup_cost(&scene, frames);
        println!(
            "{} {side}² ×{frames}: plain CPU {pc:.2} s (wall {pw:.2}), looping CPU {lc:.2} s \
             (wall {lw:.2}); CPU overhead {:+.1} % (of which {setup:.3} s setting up the loop); \
             uniform-time looping CPU {uc:.2} s ({:+.1} %)",
            p.name(),
            100.0 * (lc / pc - 1.0),
            100.0 * (uc / pc - 1.0)
        );
    }
}
