//! How smooth a loop's speed is: `cargo run --release -p ignis-volume --example
//! loop_speed -- [frames] [samples_per_frame] [seeds]` (defaults 48, 4, 2). For each
//! preset and seed, renders a 64-px loop of `frames` frames at `samples_per_frame` uniform
//! loop times per frame (the scene's fps multiplied by that, so the loop lasts as long;
//! a simulated fire then steps `samples_per_frame` times finer), measures the step of one
//! frame, `d(t, t + 1)` (RMS difference of metric frames, `ignis_core::loopq`), at every
//! sample, and prints its coefficient of variation and the share of its variance in the
//! harmonics up to `h` cycles per loop. A re-timing that fits a smooth time warp to a few
//! dozen preview samples (instead of a preview at two samples per frame) would need most
//! of the variance in the first few harmonics. Figures go in `benches/README.md`.

use ignis_core::{loopq, GrayFrame, Size};
use ignis_volume::{FireScene, LoopTiming, Preset};

/// Share of the variance of the periodic sequence `x` in each harmonic `0..=len/2`
/// (index = cycles per sequence; entry 0 is 0).
fn power_shares(x: &[f64]) -> Vec<f64> {
    let len = x.len();
    let mean = x.iter().sum::<f64>() / len as f64;
    let mut pw = vec![0.0; len / 2 + 1];
    for (h, p) in pw.iter_mut().enumerate().skip(1) {
        let (mut c, mut s) = (0.0, 0.0);
        for (j, v) in x.iter().enumerate() {
            let ph = std::f64::consts::TAU * (h * j) as f64 / len as f64;
            c += (v - mean) * ph.cos();
            s += (v - mean) * ph.sin();
        }
        *p = c * c + s * s;
    }
    let total: f64 = pw.iter().sum();
    pw.iter()
        .map(|p| p / total.max(f64::MIN_POSITIVE))
        .collect()
}

/// Metric frames of a 64-px loop of `frames` frames at `k` samples per frame.
fn samples(p: Preset, seed: u64, frames: u32, k: u32) -> Vec<GrayFrame> {
    let mut s = FireScene::preset(p).with_size(Size::new(64, 64).expect("size"));
    s.seed = seed;
    s.fps *= k as f32;
    let mut a = s
        .looping_animator_with(frames * k, LoopTiming::UNIFORM)
        .expect("valid");
    (0..frames * k)
        .map(|_| loopq::metric_frame_rgba(&a.next_frame().expect("renders").image, [0.0; 3]))
        .collect()
}

fn main() {
    let arg = |i: usize, d: u32| -> u32 {
        std::env::args()
            .nth(i)
            .and_then(|a| a.parse().ok())
            .unwrap_or(d)
    };
    let (frames, k, seeds) = (arg(1, 48), arg(2, 4).max(1), arg(3, 2));
    let cuts = [4usize, 8, 12, 16, 24];
    println!("{frames} frames, {k} samples per frame; share of the step's variance in harmonics ≤ {cuts:?}");
    for p in Preset::ALL {
        for seed in 1..=u64::from(seeds) {
            let m = samples(p, seed, frames, k);
            let n = m.len();
            let steps: Vec<f64> = (0..n)
                .map(|j| loopq::rms_diff(&m[j], &m[(j + k as usize) % n]))
                .collect();
            let mean = steps.iter().sum::<f64>() / n as f64;
            let sd = (steps.iter().map(|s| (s - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
            let shares = power_shares(&steps);
            let upto: Vec<String> = cuts
                .iter()
                .map(|&h| format!("{:.2}", shares[..=h.min(n / 2)].iter().sum::<f64>()))
                .collect();
            println!(
                "{:9} seed {seed}: step CV {:.3}; variance up to each cut: {}",
                p.name(),
                sd / mean,
                upto.join(" / ")
            );
        }
    }
}
