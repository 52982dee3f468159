//! `ignis-learned`: learning flames from video and synthesising new ones in real time.
//!
//! Source: stich-magnor-learning-flames.txt (Stich & Magnor, "Learning Flames").
//!
//! - [`moments`]: geometric moments up to order 3 and the global normalisation (§3.1).
//! - [`shape`]: slices, path/width, the normalised image and the inverse warp (§3.1).
//! - [`model`]: training (normalisation → eigenflames with `ignis-pca` → ARP) and the
//!   versioned model file (§3, §4).
//! - [`arp`], [`em`]: the auto-regressive process and its EM/condensation learning (§4).
//! - [`synth`]: seeded, steerable synthesis (§4.3, §5.1).
//! - [`synthetic`]: a deterministic synthetic flame clip to train on without footage.
//!
//! **Invariant:** pure library — frames in, frames out; the only file it touches is the
//! model file. All randomness comes from an explicit `seed`. Pixels are linear light.

pub mod arp;
pub mod em;
pub mod error;
pub mod model;
pub mod moments;
pub mod shape;
pub mod spline;
pub mod synth;
pub mod synthetic;

pub use arp::{Arp, Stabilised};
pub use em::{learn, EmParams, EmReport, Learned};
pub use error::{LearnedError, Result};
pub use model::{
    train, FitSummary, FlameModel, TrainParams, Training, MODEL_VERSION, STAGE_EM, STAGE_NORMALISE,
};
pub use moments::{Moments, Pose};
pub use shape::{Placement, Shape, ShapeParams};
pub use synth::{fit_scale, model_motion, Controls, Synthesiser, Warp, Wind};

use ignis_core::GrayFrame;

/// Peak signal-to-noise ratio of `test` against `reference`, in dB, with the reference's
/// maximum as the peak (linear light values). Infinite for identical frames.
pub fn psnr(reference: &GrayFrame, test: &GrayFrame) -> f64 {
    let n = reference.data().len().max(1) as f64;
    let mse = reference
        .data()
        .iter()
        .zip(test.data())
        .map(|(&a, &b)| ((a - b) as f64).powi(2))
        .sum::<f64>()
        / n;
    let peak = reference.max().max(1e-12) as f64;
    10.0 * (peak * peak / mse).log10()
}
