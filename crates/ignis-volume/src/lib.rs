//! `ignis-volume`: real-time procedural volumetric fire, after Fuller, Krishnan, Mahrous,
//! Hamann & Joy, "Real-time Procedural Volumetric Fire" (I3D 2007) — the CPU renderer.
//!
//! Data flow: a [`FireProfile`] (any RGBA image, or the built-in one) is swept around `z`
//! into the unit fire volume (eq. 1–2); a B-spline centre curve with a radius per control
//! point ([`BSpline`], eq. 3–6), moved by a script or a particle simulation
//! ([`motion`], eq. 7–8), defines a [`Lattice`] of hexahedral cells (§3.1); the renderer
//! ([`render()`]) marches view-aligned slices through the cells, inverts each cell's
//! trilinear map to texture coordinates and applies the noise mapping ([`mapping`],
//! eq. 9–14); [`render::finish`] runs the `ignis-core` bloom. [`FireScene`] ties it all
//! together (fire files, presets) and [`Animator`] produces frames; a seamless loop's
//! motion and the constant-speed timing of its frames are in [`looping`]; a frame's motion on
//! screen, from the model (for motion-vector flipbooks), is [`model_motion()`].
//!
//! **Invariants:** this crate reads no image or video files (profile images come in as
//! [`ignis_core::RgbaFrame`]; `ignis-cli` loads and writes them via `ignis-media`); all
//! randomness comes from the scene's `seed`; output bytes do not depend on the number of
//! threads; frames are linear light. The per-sample mapping ([`mapping`]) is kept in small
//! pure functions so a future GPU renderer can be checked against this one.

pub mod error;
pub mod lattice;
pub mod looping;
pub mod mapping;
pub mod model_motion;
pub mod motion;
pub mod noise;
pub mod profile;
pub mod render;
pub mod scene;
mod scene_file;
pub mod spline;

pub use error::{Result, VolumeError};
pub use lattice::{Cell, Lattice, Puff};
pub use looping::LoopTiming;
pub use mapping::NoiseParams;
pub use model_motion::{model_motion, Follow};
pub use motion::{Collision, Keyframe, Obstacle, ParticleSim, Script, SimParams};
pub use noise::NoiseKind;
pub use profile::FireProfile;
pub use render::{finish, render, Blend, Camera, FireInstance, RenderParams, RenderStats};
pub use scene::{Animator, FireScene, FireSpec, Frame, Motion, Pose, Preset};
pub use spline::BSpline;
