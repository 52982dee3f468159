//! `ignis-eigen`: Eigenfires I — pre-processing of fire footage, the Eigenfire database,
//! and its analysis.
//!
//! Source: /work/shared/seeds/eigenfires-thesis.txt, chapter 3 (pre-processing), chapter 4
//! (Eigenfires, weights, thresholds, reconstruction, packs) and §7.1–7.3 (speed-up
//! tricks: training on resized frames while keeping full-resolution pre-processed frames).
//!
//! Data flow, one folder per stage of the thesis: [`Footage`] (frames from anywhere, linear
//! RGBA) → [`preprocess`] (ch. 3: `mask` → `contour` → `hermite` → `pose` → grayscale,
//! [`GrayFrame`]) → [`train`] (data matrix → `ignis_pca`) → [`db`] (ch. 4: manifest + `.npy`
//! files, written by `db::DbWriter`) → [`analysis`] and [`plot`]; [`transition`] (§5.1:
//! low-pass, Direct Bridging, End Growing) → [`animate`] (§5.2, ch. 6: `scenario` → plan →
//! `render` with `colour`, and `loops`).
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
/// The synthetic benchmark database and figures behind `ignis bench eigen-animate` and the
/// criterion bench `benches/animate.rs` (both need it); not part of the API.
#[doc(hidden)]
pub mod bench;
pub mod db;
pub mod error;
pub mod footage;
pub mod plot;
pub mod preprocess;
pub mod report;
pub mod synthetic;
pub mod train;
pub mod transition;

// The thesis's stages live in folders (`preprocess/` ch. 3, `db/` ch. 4, `transition/` §5.1,
// `animate/` §5.2 and ch. 6); their parts stay reachable at the crate root as before.
pub use animate::{colour, loops, render, scenario};
pub use preprocess::{contour, hermite, mask, pose, still};

pub use analysis::ESelect;
pub use db::{ClipEntry, EigenfireDb, Manifest, Thresholds};
pub use error::{EigenError, Result};
#[cfg(feature = "media")]
pub use footage::MediaFootage;
pub use footage::{Footage, FootageInfo, FootageOpener, FrameList, SyntheticFootage};
pub use preprocess::PreprocessParams;
pub use report::{JoinReport, LoopReport};
pub use train::{train, ClipInput, ClipSpec, NoProgress, Progress, TrainConfig, TrainParams};
