//! A cheap synthetic flame generator for benchmarks and tests (`ignis bench eigen-train`,
//! the criterion benches).
//!
//! The thesis' training set (§7.1): M = 2,197 frames of 410×670 = 274,700 pixels. The footage is
//! not in the repo, so the benchmark builds flame-like frames: a few tongues (smooth bumps that
//! narrow with height, sway and flicker with time) plus a little per-pixel noise. Frames depend
//! smoothly on a handful of parameters, so the PCA spectrum decays like a real fire's, with a
//! flat noise floor.

use faer::Mat;
use ignis_core::Rng;
use rayon::prelude::*;

/// Parameters of one flame tongue.
#[derive(Clone, Debug)]
struct Tongue {
    x0: f32,
    width: f32,
    height: f32,
    sway: f32,
    freq: [f32; 3],
    phase: [f32; 3],
    gain: f32,
}

/// Deterministic synthetic flame frames (linear luminance in [0, ~1.5], row 0 = top, row-major).
#[derive(Clone, Debug)]
pub struct SyntheticFlames {
    pub width: usize,
    pub height: usize,
    pub seed: u64,
    tongues: Vec<Tongue>,
}

/// The generator of `width`×`height` frames for `seed`.
pub fn synthetic_flames(width: usize, height: usize, seed: u64) -> SyntheticFlames {
    let mut rng = Rng::new(seed);
    let w = width as f64;
    let h = height as f64;
    let tongues = (0..6)
        .map(|_| Tongue {
            x0: rng.uniform(0.3 * w, 0.7 * w) as f32,
            width: rng.uniform(0.06 * w, 0.16 * w) as f32,
            height: rng.uniform(0.45 * h, 0.9 * h) as f32,
            sway: rng.uniform(0.02 * w, 0.08 * w) as f32,
            freq: [
                rng.uniform(0.05, 0.25) as f32,
                rng.uniform(0.1, 0.4) as f32,
                rng.uniform(0.01, 0.05) as f32,
            ],
            phase: [
                rng.uniform(0.0, std::f64::consts::TAU) as f32,
                rng.uniform(0.0, std::f64::consts::TAU) as f32,
                rng.uniform(0.0, std::f64::consts::TAU) as f32,
            ],
            gain: rng.uniform(0.4, 1.0) as f32,
        })
        .collect();
    SyntheticFlames {
        width,
        height,
        seed,
        tongues,
    }
}

impl SyntheticFlames {
    /// Pixels per frame.
    pub fn n_pixels(&self) -> usize {
        self.width * self.height
    }

    /// Writes frame `t` (row-major, length width·height) into `out`.
    pub fn frame_into(&self, t: usize, out: &mut [f32]) {
        assert_eq!(out.len(), self.n_pixels());
        let tf = t as f32;
        let mut noise = Rng::derive(self.seed, t as u64 + 1);
        // Per-frame tongue state.
        let state: Vec<(f32, f32, f32, f32)> = self
            .tongues
            .iter()
            .map(|g| {
                let flick = 1.0 + 0.25 * (g.freq[0] * tf + g.phase[0]).sin();
                let cx = g.x0 + g.sway * (g.freq[2] * tf + g.phase[2]).sin();
                (
                    cx,
                    g.height * flick,
                    g.gain * flick,
                    g.freq[1] * tf + g.phase[1],
                )
            })
            .collect();
        for (row, line) in out.chunks_exact_mut(self.width).enumerate() {
            let y = (self.height - row) as f32; // height above the bottom
            line.fill(0.0);
            for (g, &(cx, h, gain, ph)) in self.tongues.iter().zip(&state) {
                if y >= h {
                    continue;
                }
                let rel = y / h;
                let half = g.width * (1.0 - rel).sqrt() + 1.0;
                let c = cx + g.sway * rel * (0.03 * y - ph).sin();
                let amp = gain * (1.0 - rel);
                let x_lo = ((c - half).floor().max(0.0)) as usize;
                let x_hi = ((c + half).ceil().min(self.width as f32)) as usize;
                let inv = 1.0 / half;
                for (x, v) in line.iter_mut().enumerate().take(x_hi).skip(x_lo) {
                    let d = (x as f32 - c) * inv;
                    let b = (1.0 - d * d).max(0.0);
                    *v += amp * b * b;
                }
            }
            for v in line.iter_mut() {
                *v += 0.01 * noise.f32();
            }
        }
    }

    /// An N×M data matrix of frames `0..m` (generated in parallel, one frame per column).
    pub fn data_matrix(&self, m: usize) -> Mat<f32> {
        let mut a = Mat::<f32>::zeros(self.n_pixels(), m);
        self.fill(a.as_mut(), 0);
        a
    }

    /// Fills the columns of `a` with frames `first..first + a.ncols()`.
    pub fn fill(&self, a: faer::MatMut<'_, f32>, first: usize) {
        a.par_col_iter_mut().enumerate().for_each(|(j, col)| {
            let col = col
                .try_as_col_major_mut()
                .expect("columns of a Mat are contiguous");
            self.frame_into(first + j, col.as_slice_mut());
        });
    }
}
