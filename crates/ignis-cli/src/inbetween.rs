//! Motion vectors chosen by rendered in-between frames, for generators that can render a
//! frame at any time between two of theirs (the volumetric fire,
//! [`ignis_volume::Animator::frame_between`]) and for footage loops written every other
//! frame (`ignis loop --every 2`, whose left-out frames are the in-between ones).
//!
//! Fire is mostly not motion: the engines' flipbook blend moves each of two neighbouring
//! frames along its own stored vector, and the image flow's one vector per frame (the
//! velocity, gated by consistency) rebuilds a volumetric fire's dropped frames only 5–6 %
//! better than a cross-fade. A generator that can render the frame half-way between two
//! of its frames knows what the blend should give there. The flows from each in-between
//! frame to its two key frames give, at every pixel, the vector that makes each half of
//! the blend land on the in-between frame ([`mid_pairs`]); per pixel of each frame, one of
//! four vectors (none, the one for its blend with the next frame, the one for its blend
//! with the previous frame, their mean) is kept, whichever makes the blends at 0.5 closest
//! to the rendered in-between frames
//! ([`ignis_media::write::motion::chosen_velocities`], exact over the whole loop).
//! Measured in `ignis bench export` (the volume and footage rows;
//! `crates/ignis-flow/benches/README.md`).

use ignis_core::Size;
use ignis_media::write::motion::Field;
use ignis_media::{MotionSource, RgbaFrame};
use std::sync::{Arc, Mutex};

/// The JSON's `motion_vectors.source` for vectors chosen by in-between frames.
pub(crate) const SOURCE: &str =
    "optical flow (DIS) from each rendered in-between frame to its two frames, chosen per pixel by the in-between frames";

/// Motion vectors chosen per pixel by the in-between frames a generator renders: gathered
/// while the frames are rendered ([`InBetween::record`]), given to the writer as a
/// [`MotionSource`] ([`InBetween::source`]).
pub(crate) struct InBetween {
    looped: bool,
    /// Per loop (row of the sheet): the in-between frame after each of its frames.
    rows: Arc<Mutex<Vec<Vec<RgbaFrame>>>>,
}

impl InBetween {
    /// `looped`: the sheet is a loop (its last frame blends into its first, so that
    /// interval needs an in-between frame too).
    pub(crate) fn new(looped: bool) -> InBetween {
        InBetween {
            looped,
            rows: Default::default(),
        }
    }

    /// Whether the frame after the last of a row needs an in-between frame (`more`:
    /// another frame of the row follows).
    pub(crate) fn wants(&self, more: bool) -> bool {
        more || self.looped
    }

    /// A new loop (row of the sheet) begins.
    pub(crate) fn start_row(&self) {
        self.rows.lock().expect("not poisoned").push(Vec::new());
    }

    /// The in-between frame after the row's latest frame (what [`Self::wants`] asked for).
    pub(crate) fn record(&self, mid: RgbaFrame) {
        let mut rows = self.rows.lock().expect("not poisoned");
        rows.last_mut().expect("start_row first").push(mid);
    }

    /// The motion source for the writer.
    pub(crate) fn source(&self) -> MotionSource {
        let (rows, looped) = (self.rows.clone(), self.looped);
        let direction = if looped {
            "velocity at frame k's pixels: per pixel none, the vector that brings frame k half-way to the in-between frame after it, the one that brings it half-way to the in-between frame before it, or their mean (wrapping within each loop), whichever makes the blends at 0.5 closest to the rendered in-between frames"
        } else {
            "velocity at frame k's pixels: per pixel none, the vector that brings frame k half-way to the in-between frame after it, the one that brings it half-way to the in-between frame before it, or their mean (one side only at the first and last frame), whichever makes the blends at 0.5 closest to the rendered in-between frames"
        };
        MotionSource::velocities(
            move |r, frames| {
                let rows = rows.lock().map_err(|_| "a render thread panicked")?;
                let mids = rows
                    .get(r)
                    .ok_or("no in-between frames were recorded for this loop")?;
                chosen(frames, mids, looped)
            },
            SOURCE,
            direction,
        )
    }
}

/// The chosen velocities of one row's `frames` with the in-between frames `mids`.
fn chosen(
    frames: &[RgbaFrame],
    mids: &[RgbaFrame],
    looped: bool,
) -> Result<Vec<Vec<[f32; 2]>>, String> {
    let n = frames.len();
    let intervals = if looped { n } else { n.saturating_sub(1) };
    if n < 2 || mids.len() < intervals {
        return Err(format!(
            "{n} frames, but {} in-between frames were rendered for them",
            mids.len()
        ));
    }
    let size: Size = frames[0].size();
    if mids.iter().any(|m| m.size() != size) {
        return Err("in-between frames of another size than the frames".into());
    }
    let mids: Vec<&RgbaFrame> = mids[..intervals].iter().collect();
    let pairs = mid_pairs(frames, &mids)?;
    Ok(ignis_media::write::motion::chosen_velocities(
        frames, &mids, &pairs,
    ))
}

/// Per interval `k`, the vectors at each pixel `x` that make each half of the blend at
/// 0.5 land on the in-between frame there: `mid(x) ≈ key_k(x + F(x))` (the flow from the
/// in-between frame to the earlier key frame) is matched by `key_k` sampled at
/// `x − 0.5·v`, so `v = −2F`; likewise for the later key frame sampled at `x + 0.5·v`,
/// returned as its "backward" vector `−v` (the shape
/// [`ignis_media::write::motion::chosen_velocities`] takes).
pub(crate) fn mid_pairs(
    frames: &[RgbaFrame],
    mids: &[&RgbaFrame],
) -> Result<Vec<(Field, Field)>, String> {
    let n = frames.len();
    let p = ignis_flow::FlowParams::default();
    use rayon::prelude::*;
    let grey: Vec<_> = frames.par_iter().map(ignis_flow::luma).collect();
    let doubled = |f: ignis_flow::FlowField| -> Field {
        f.into_vec()
            .into_iter()
            .map(|v| [-2.0 * v[0], -2.0 * v[1]])
            .collect()
    };
    mids.par_iter()
        .enumerate()
        .map(|(k, m)| {
            let g = ignis_flow::luma(m);
            let to_earlier = ignis_flow::flow(&g, &grey[k], &p).map_err(|e| e.to_string())?;
            let to_later =
                ignis_flow::flow(&g, &grey[(k + 1) % n], &p).map_err(|e| e.to_string())?;
            Ok((doubled(to_earlier), doubled(to_later)))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use ignis_media::write::motion::{linear_blend, mv_blend};
    use ignis_media::{FlipbookOptions, WriteOptions};

    /// Mean |difference| of two frames composited over black, in 8-bit sRGB levels.
    fn error(a: &RgbaFrame, b: &RgbaFrame) -> f64 {
        let enc = |p: [f32; 4]| {
            [0, 1, 2].map(|c| ignis_core::palette::linear_to_srgb((p[c] * p[3]).clamp(0.0, 1.0)))
        };
        let sum: f64 = a
            .data()
            .iter()
            .zip(b.data())
            .map(|(&p, &q)| {
                let (p, q) = (enc(p), enc(q));
                (0..3).map(|c| f64::from((p[c] - q[c]).abs())).sum::<f64>()
            })
            .sum();
        255.0 * sum / (3 * a.data().len()) as f64
    }

    /// A looping volumetric flipbook written with the chosen vectors, read back from its
    /// 8-bit colour and 16-bit vector sheets, rebuilds the in-between frames (the loop's
    /// wrap included) with the engines' blend clearly better than a cross-fade does, and
    /// better than the gated flow's vectors on the same frames.
    #[test]
    fn chosen_vectors_rebuild_the_in_between_frames() {
        let scene = ignis_volume::FireScene::preset(ignis_volume::Preset::Candle)
            .with_size(Size::new(64, 64).unwrap());
        let n = 8;
        let mut anim = scene.looping_animator(n as u32).unwrap();
        let motion = InBetween::new(true);
        motion.start_row();
        let (mut frames, mut mids) = (Vec::new(), Vec::new());
        for _ in 0..n {
            frames.push(anim.next_frame().unwrap().image);
            let mid = anim.frame_between(0.5).unwrap().image;
            motion.record(mid.clone());
            mids.push(mid);
        }
        let dir = tempfile::tempdir().unwrap();
        let errors = |source: MotionSource, name: &str| {
            let path = dir.path().join(name);
            let opts = WriteOptions {
                loop_: true,
                flipbook: FlipbookOptions {
                    motion: Some(source),
                    ..Default::default()
                },
                ..Default::default()
            };
            let mut w = ignis_media::create(&path, frames[0].size(), &opts).unwrap();
            for f in &frames {
                w.push(f).unwrap();
            }
            w.finish().unwrap();
            let fb = ignis_media::read_flipbook(&path.with_extension("json")).unwrap();
            let mv = fb.motion.unwrap();
            let (mut e_mv, mut e_plain) = (0.0, 0.0);
            for k in 0..n {
                let j = (k + 1) % n;
                let (a, b) = (&fb.frames[k], &fb.frames[j]);
                e_mv += error(&mv_blend(a, b, &mv[k], &mv[j], 0.5), &mids[k]);
                e_plain += error(&linear_blend(a, b, 0.5), &mids[k]);
            }
            (e_mv, e_plain)
        };
        let (chosen, plain) = errors(motion.source(), "chosen.png");
        let (flow, plain_again) = errors(crate::output::flow_source(), "flow.png");
        assert_eq!(plain, plain_again);
        eprintln!(
            "in-between errors: chosen {:.4}, gated flow {:.4}, cross-fade {:.4}",
            chosen / n as f64,
            flow / n as f64,
            plain / n as f64
        );
        assert!(chosen < 0.8 * plain, "chosen {chosen}, cross-fade {plain}");
        assert!(chosen < flow, "chosen {chosen}, gated flow {flow}");
    }
}
