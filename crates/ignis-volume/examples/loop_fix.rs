//! How many frames a looping render renders again to fix its long steps, and the steps
//! before and after: `cargo run --release -p ignis-volume --example loop_fix -- SIZE SEEDS
//! STEP WRAP [FRAMES...]` (defaults 48, 2, the default bounds ×100: 115 105, frames 20 24
//! 30 36). Per preset, seed and length: the
//! uniform-time and re-timed worst wrap / largest step (÷ the loop's median step, as
//! written frames are measured) and the frames rendered again. Figures go in
//! `benches/README.md`.

use ignis_core::{loopq, Size};
use ignis_volume::{FireScene, LoopTiming, Preset};

/// (wrap, largest step) ÷ median, and the re-renders, of a loop rendered with `timing`.
fn figures(s: &FireScene, frames: u32, timing: LoopTiming) -> (f64, f64, usize) {
    let mut a = s.looping_animator_with(frames, timing).expect("valid");
    let metric: Vec<_> = (0..frames)
        .map(|_| loopq::metric_frame_rgba(&a.next_frame().expect("renders").image, [0.0; 3]))
        .collect();
    let steps = loopq::steps(&metric, true).expect("same sizes");
    let med = loopq::median(&mut steps.clone());
    let max = steps.iter().cloned().fold(0.0, f64::max) / med;
    (steps[steps.len() - 1] / med, max, a.loop_rerenders())
}

fn main() {
    let args: Vec<u32> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let side = args.first().copied().unwrap_or(48);
    let seeds = args.get(1).copied().unwrap_or(2);
    let timing = LoopTiming {
        step_bound: f64::from(args.get(2).copied().unwrap_or(115)) / 100.0,
        wrap_bound: f64::from(args.get(3).copied().unwrap_or(105)) / 100.0,
        ..LoopTiming::DEFAULT
    };
    let lengths = if args.len() > 4 { args[4..].to_vec() } else { vec![20, 24, 30, 36] };
    let mut total = (0usize, 0u32);
    for p in Preset::ALL {
        let (mut worst_u, mut worst) = ((0.0f64, 0.0f64), (0.0f64, 0.0f64));
        for seed in 1..=u64::from(seeds) {
            for &n in &lengths {
                let mut s = FireScene::preset(p).with_size(Size::new(side, side).expect("size"));
                s.seed = seed;
                let (uw, um, _) = figures(&s, n, LoopTiming::UNIFORM);
                let (w, m, again) = figures(&s, n, timing);
                println!(
                    "{:9} seed {seed} ×{n}: uniform {uw:.3} / {um:.3}, re-timed {w:.3} / {m:.3}, {again} rendered again",
                    p.name()
                );
                worst_u = (worst_u.0.max(uw), worst_u.1.max(um));
                worst = (worst.0.max(w), worst.1.max(m));
                total = (total.0 + again, total.1 + n);
            }
        }
        println!(
            "{:9} worst: uniform {:.3} / {:.3}, re-timed {:.3} / {:.3}",
            p.name(),
            worst_u.0,
            worst_u.1,
            worst.0,
            worst.1
        );
    }
    println!(
        "rendered again: {} of {} frames ({:.1} %)",
        total.0,
        total.1,
        100.0 * total.0 as f64 / f64::from(total.1)
    );
}
