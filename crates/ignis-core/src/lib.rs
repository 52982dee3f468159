//! `ignis-core`: the pieces every Ignis generator shares.
//!
//! - [`frame`]: [`GrayFrame`] (linear luminance, `f32`) and [`RgbaFrame`]
//!   (linear-light RGBA, `f32`, straight alpha), [`Size`] with allocation limits.
//! - [`palette`]: intensity → colour ramps (transfer functions) and presets.
//! - [`colour`]: synthetic HLS colouring (eigenfires-thesis §6.1.2).
//! - [`post`]: bloom (§6.2) and the alpha matte (§6.2).
//! - [`loopq`]: seam and ghost, the loop/transition quality measured on written frames.
//! - [`rng`]: the seeded RNG every generator uses.
//! - [`tempfiles`]: names of writers' hidden temporaries and removal of stale ones.
//! - [`atomic`]: the one atomic file write (temporary beside the target, sync, rename).
//! - [`progress`]: the one progress-reporting trait the libraries take.
//! - [`golden`]: golden float images for tests (stored frames compared within a tolerance).
//! - [`realism`]: flicker frequency and spectral slope, measured on renders and footage alike.
//! - [`stream`]: per-frame work on a decoded stream, in parallel and in stream order.
//! - [`textfile`]: the bounded, non-blocking read of the text files a user names.
//!
//! **Invariant:** this crate knows no file formats (it only names, writes atomically and
//! removes the writers' temporaries: [`tempfiles`], [`atomic`], and reads text with a
//! bound: [`textfile`]; the one exception is the raw float layout of the tests' goldens,
//! [`golden`]), codecs, clap or GPUs. Pixel data is linear light everywhere; only
//! `ignis-media` converts to 8-bit sRGB.

pub mod atomic;
pub mod colour;
pub mod error;
pub mod fireblend;
pub mod frame;
pub mod golden;
pub mod loopq;
pub mod palette;
pub mod post;
pub mod progress;
pub mod realism;
pub mod rng;
pub mod stream;
pub mod tempfiles;
pub mod textfile;

pub use error::{CoreError, Result};
pub use frame::{GrayFrame, RgbaFrame, Size};
pub use palette::Palette;
pub use rng::Rng;
