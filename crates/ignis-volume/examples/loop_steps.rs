//! Steps of looping renders over seeds and loop lengths, measured as written frames are
//! (`ignis_core::loopq` metric frames): `cargo run --release -p ignis-volume --example
//! loop_steps -- [size] [preview_width] [samples_per_frame] [seeds] [lengths]` (defaults
//! 48, the default [`LoopTiming`], 4, `20,24,30,36`; samples 0 = uniform loop times).
//! Prints per preset the worst wrap and the worst largest step (÷ the loop's median step)
//! over seeds `1..=seeds` × the loop lengths, the mean coefficient of variation of the
//! steps, and the time taken. Figures go in `benches/README.md`.

use ignis_core::{loopq, Size};
use ignis_volume::{FireScene, LoopTiming, Preset};
use std::time::Instant;

fn main() {
    let arg = |i: usize, d: u32| -> u32 {
        std::env::args()
            .nth(i)
            .and_then(|a| a.parse().ok())
            .unwrap_or(d)
    };
    let side = arg(1, 48);
    let timing = LoopTiming {
        preview_width: arg(2, LoopTiming::DEFAULT.preview_width),
        samples_per_frame: arg(3, LoopTiming::DEFAULT.samples_per_frame),
    };
    let lengths: Vec<u32> = std::env::args()
        .nth(5)
        .unwrap_or_else(|| "20,24,30,36".into())
        .split(',')
        .map(|l| l.parse().expect("lengths: comma-separated frame counts"))
        .collect();
    println!("{side}x{side}, {timing:?}, lengths {lengths:?}");
    for p in Preset::ALL {
        let (mut wrap, mut max, mut cv, mut loops) = (0.0f64, 0.0f64, 0.0f64, 0u32);
        let t0 = Instant::now();
        for seed in 1..=u64::from(arg(4, 4)) {
            for &frames in &lengths {
                let mut s = FireScene::preset(p).with_size(Size::new(side, side).expect("size"));
                s.seed = seed;
                let mut a = s.looping_animator_with(frames, timing).expect("valid");
                let metric: Vec<_> = (0..frames)
                    .map(|_| {
                        let f = a.next_frame().expect("renders");
                        loopq::metric_frame_rgba(&f.image, [0.0; 3])
                    })
                    .collect();
                let steps = loopq::steps(&metric, true).expect("same sizes");
                let med = loopq::median(&mut steps.clone());
                wrap = wrap.max(steps[steps.len() - 1] / med);
                max = max.max(steps.iter().cloned().fold(0.0, f64::max) / med);
                let mean = steps.iter().sum::<f64>() / steps.len() as f64;
                let var = steps.iter().map(|s| (s - mean).powi(2)).sum::<f64>();
                cv += (var / steps.len() as f64).sqrt() / mean;
                loops += 1;
            }
        }
        println!(
            "{:9} worst wrap {wrap:.3}, worst max step {max:.3}, mean step CV {:.3}  ({:.1} s)",
            p.name(),
            cv / f64::from(loops.max(1)),
            t0.elapsed().as_secs_f64()
        );
    }
}
