//! A deterministic synthetic "candle" clip for tests, benchmarks and the demo, so nothing
//! external is needed to train a model.
//!
//! Not from the paper: a teardrop flame whose height, sway, width and brightness follow
//! four independent damped oscillators (AR(2) processes with poles at radius 0.93 and
//! 1.5–4 Hz at 30 frames/s), all driven by `ignis_core::Rng::new(seed)`. Linear light,
//! black background, base at 82% of the frame height.

use ignis_core::{GrayFrame, Rng, Size};

/// A small model trained quickly on [`flame_clip`] (96², 30 frames, 40 particles, 3 EM
/// iterations, all seeded by `seed`), its rate set to the clip's 30 frames per second: for
/// tests and examples that need a trained model, not a good one.
pub fn small_model(seed: u64) -> crate::FlameModel {
    let clip = flame_clip(Size::new(96, 96).expect("a valid size"), 30, seed);
    let p = crate::TrainParams {
        em: crate::EmParams {
            particles: 40,
            max_iterations: 3,
            seed,
            ..crate::EmParams::default()
        },
        ..crate::TrainParams::default()
    };
    let mut model = crate::train(clip, &p, &mut ignis_core::progress::NoProgress)
        .expect("the synthetic clip trains")
        .model;
    // the clip's oscillators are defined at 30 frames per second
    model.summary.fps = Some(30.0);
    model
}

/// `frames` frames of a flickering flame of `size`, determined by `seed`.
pub fn flame_clip(size: Size, frames: usize, seed: u64) -> Vec<GrayFrame> {
    let drivers = drivers(frames, seed);
    (0..frames).map(|t| flame_frame(size, drivers[t])).collect()
}

/// The four latent processes (height, sway, width, brightness), unit-ish variance.
fn drivers(frames: usize, seed: u64) -> Vec<[f64; 4]> {
    let mut rng = Rng::new(seed);
    let freqs = [1.7, 2.9, 3.7, 2.3];
    let r: f64 = 0.93;
    let mut st = [[0.0f64; 2]; 4];
    // Warm up so the clip starts in the stationary regime.
    let mut out = Vec::with_capacity(frames);
    for t in 0..frames + 100 {
        let mut x = [0.0; 4];
        for (i, s) in st.iter_mut().enumerate() {
            let w = 2.0 * std::f64::consts::PI * freqs[i] / 30.0;
            let v = 2.0 * r * w.cos() * s[0] - r * r * s[1] + 0.25 * rng.normal();
            s[1] = s[0];
            s[0] = v;
            x[i] = v;
        }
        if t >= 100 {
            out.push(x);
        }
    }
    out
}

fn flame_frame(size: Size, d: [f64; 4]) -> GrayFrame {
    let (w, h) = (size.width as f64, size.height as f64);
    let base = (0.5 * w, 0.82 * h);
    let len = 0.5 * h * (1.0 + 0.12 * d[0]);
    let sway = 0.10 * d[1];
    let half = 0.075 * h * (1.0 + 0.08 * d[2]);
    let bright = 1.0 + 0.06 * d[3];
    GrayFrame::from_fn(size, |x, y| {
        let (px, py) = (x as f64 + 0.5, y as f64 + 0.5);
        let t = (base.1 - py) / len;
        if !(-0.2..=1.0).contains(&t) {
            return 0.0;
        }
        let tc = t.max(0.0);
        let centre = base.0 + len * sway * tc * tc;
        let wdt = half * (1.0 - tc).powf(0.7) * (tc + 0.12).sqrt() + 1e-3;
        let across = (-((px - centre) / wdt).powi(2)).exp();
        let along = if t < 0.0 {
            (-(t / 0.06).powi(2)).exp()
        } else {
            1.0 - 0.45 * tc
        };
        (bright * across * along) as f32
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clip_is_deterministic_and_lit() {
        let s = Size::new(48, 48).unwrap();
        let a = flame_clip(s, 5, 1);
        assert_eq!(a, flame_clip(s, 5, 1));
        assert_ne!(a, flame_clip(s, 5, 2));
        assert!(a.iter().all(|f| f.max() > 0.5));
    }
}
