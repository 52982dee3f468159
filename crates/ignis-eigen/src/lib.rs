//! `ignis-eigen`: Eigenfires I — pre-processing of fire footage, the Eigenfire database,
//! and its analysis.
//!
//! Source: /work/shared/seeds/eigenfires-thesis.txt, chapter 3 (pre-processing), chapter 4
//! (Eigenfires, weights, thresholds, reconstruction, packs) and §7.1–7.3 (speed-up
//! tricks: training on resized frames while keeping full-resolution pre-processed frames).
//!
//! Data flow: [`Footage`] (frames from anywhere, linear RGBA) →
//! [`preprocess`] (mask → contours → Hermite → pose → grayscale, [`GrayFrame`]) → data
//! matrix → `ignis_pca` → [`db`] (manifest + `.npy` files) → [`analysis`] and [`plot`].
//!
//! **Invariant:** this crate knows nothing of video codecs or clap: frames come in through
//! [`Footage`] (`MediaFootage`, behind the `media` feature, wraps `ignis-media`); it
//! converts nothing to 8-bit sRGB
//! except the plots `plotters` draws. The PCA itself lives in `ignis-pca`. All randomness
//! (synthetic footage) comes from an explicit `seed`.
//!
//! [`GrayFrame`]: ignis_core::GrayFrame

pub mod analysis;
pub mod animate;
pub mod bench;
pub mod colour;
pub mod contour;
pub mod db;
pub mod error;
pub mod footage;
pub mod hermite;
pub mod loops;
pub mod mask;
pub mod plot;
pub mod pose;
pub mod preprocess;
pub mod render;
pub mod report;
pub mod scenario;
pub mod synthetic;
pub mod train;
pub mod transition;

pub use analysis::ESelect;
pub use db::{ClipEntry, EigenfireDb, Manifest, Thresholds};
pub use error::{EigenError, Result};
#[cfg(feature = "media")]
pub use footage::MediaFootage;
pub use footage::{Footage, FootageInfo, FootageOpener, FrameList, SyntheticFootage};
pub use preprocess::PreprocessParams;
pub use report::{JoinReport, LoopReport};
pub use train::{train, ClipInput, ClipSpec, NoProgress, Progress, TrainConfig, TrainParams};
