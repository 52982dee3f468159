//! `ignis bench export`: does motion-vector frame blending help? Each case renders (or
//! decodes) an animation at twice the exported frame rate, writes every other frame as a
//! flipbook with motion vectors (through the same writer and flow as `--motion-vectors`),
//! reads the sheets back, and rebuilds each dropped frame at blend 0.5 with the engines'
//! motion-vector blend (`ignis_media::write::motion::mv_blend`, the formula of `engines/`)
//! and with a plain cross-fade. Error: mean absolute difference from the true dropped frame
//! in 8-bit sRGB levels of the colour composited over black. Each row also reports the same
//! vectors on unquantised colour, and a variant whose vectors come from flows to the true
//! in-between frames (marked `uses_in_between_frame`). A `diagnosis` per row separates the
//! causes: vector quantisation, gating, flow resolution, the generator's own motion, and a
//! per-pixel best-velocity bound (what one velocity shared by both key frames could reach
//! with this blend). Generators that know their motion (the moving texture, classic, the
//! learned flame: [`ignis_learned::model_motion`], the volumetric fire:
//! [`ignis_volume::model_motion()`], with `model_flow`, `model_noise` and `model_lattice`
//! beside it) add it to the diagnosis as `model`.
//! Two further variants show where one vector per frame falls short: forward/backward
//! pairs per key interval (`*_pairwise`, two sheets' worth), and one vector per key frame
//! chosen per pixel among the forward, reversed backward, central and zero vectors by the
//! true in-between frames (`*_chosen`, storable; held out at t = 0.25 / 0.75). The learned
//! row's sheet is written as `ignis learned synth --motion-vectors` writes it (the model's
//! vectors chosen that way, [`crate::learned::ModelMotion`]), and the volume rows' as `ignis
//! volume render --motion-vectors` writes them (vectors from the flows of each in-between
//! frame the renderer draws to its two key frames, chosen by the in-between frames,
//! [`crate::inbetween::InBetween`]); the footage and classic rows' as `ignis loop` / `ignis
//! classic --every 2 --motion-vectors` write them (the same choice by the frames left
//! out), each with the gated flow's
//! vectors beside it for comparison; every row's vectors are also read as an engine may filter them
//! (`filtered`: bilinear between pixel centres, mip level 1).

use crate::global::Global;
use crate::output::flow_source;
use anyhow::{Context, Result};
use ignis_core::{RgbaFrame, Size};
use ignis_media::write::motion::{linear_blend, mv_blend};
use ignis_media::{FlipbookOptions, MotionSource, ReadOptions, WriteOptions};
use serde_json::json;
use std::time::Instant;

/// One motion vector per pixel, `[dx, dy]` in pixels.
type Field = Vec<[f32; 2]>;

/// What a generator knows of its own motion, for the diagnosis.
#[derive(Default)]
struct Known<'a> {
    /// Named velocities, one field per key frame.
    velocities: Vec<(&'a str, Vec<Field>)>,
    /// Named (`model`, …): per key interval, the forward motion (from the earlier key
    /// frame's pixels) and the backward motion (from the later one's).
    pairs: Vec<(&'a str, Vec<(Field, Field)>)>,
}

impl Known<'_> {
    /// Only velocities, named `model`.
    fn model(velocities: Vec<Field>) -> Self {
        Known {
            velocities: vec![("model", velocities)],
            pairs: Vec::new(),
        }
    }
}

/// Goal: motion-vector blend error at least 30% below the cross-fade's.
const GOAL_REDUCTION: f64 = 0.30;
/// Goal: a 64-frame 256² flipbook with motion vectors, in seconds.
const GOAL_FLIPBOOK_S: f64 = 2.0;

fn error(a: &RgbaFrame, b: &RgbaFrame) -> f64 {
    use ignis_core::palette::linear_to_srgb;
    let mut sum = 0.0;
    for (p, q) in a.data().iter().zip(b.data()) {
        for c in 0..3 {
            let x = linear_to_srgb((p[c] * p[3]).clamp(0.0, 1.0));
            let y = linear_to_srgb((q[c] * q[3]).clamp(0.0, 1.0));
            sum += ((x - y) * 255.0).abs() as f64;
        }
    }
    sum / (a.data().len() * 3) as f64
}

/// Mean error of both blends over the dropped frames, `(motion-vector, plain)`.
fn blend_errors(keys: &[RgbaFrame], mv: &[Vec<[f32; 2]>], truth: &[RgbaFrame]) -> (f64, f64) {
    let pairs = keys.len() - 1;
    let (mut e_mv, mut e_plain) = (0.0, 0.0);
    for k in 0..pairs {
        let m = mv_blend(&keys[k], &keys[k + 1], &mv[k], &mv[k + 1], 0.5);
        let l = linear_blend(&keys[k], &keys[k + 1], 0.5);
        e_mv += error(&m, &truth[2 * k + 1]);
        e_plain += error(&l, &truth[2 * k + 1]);
    }
    (e_mv / pairs as f64, e_plain / pairs as f64)
}

fn r3(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

/// `{mv_blend_error, plain_blend_error, error_reduction}` of one variant.
fn figures_of((e_mv, e_plain): (f64, f64)) -> serde_json::Value {
    json!({
        "mv_blend_error": r3(e_mv),
        "plain_blend_error": r3(e_plain),
        "error_reduction": r3(1.0 - e_mv / e_plain.max(1e-12)),
    })
}

/// Velocities from flows to the true in-between frames (half steps): frame k's vector is
/// `F(k → mid_k) − F(k → mid_k−1)`, one-sided (doubled) at the ends.
fn in_between_vectors(frames: &[RgbaFrame]) -> Result<Vec<Vec<[f32; 2]>>> {
    let p = ignis_flow::VectorParams::default();
    let n = frames.len().div_ceil(2);
    let half = |k: usize, j: usize| -> Result<Vec<[f32; 2]>> {
        Ok(
            ignis_flow::motion_vector_pair(&frames[2 * k], &frames[j], &p)?
                .0
                .into_vec(),
        )
    };
    (0..n)
        .map(|k| {
            let ahead = (k + 1 < n).then(|| half(k, 2 * k + 1)).transpose()?;
            let behind = (k > 0).then(|| half(k, 2 * k - 1)).transpose()?;
            Ok(match (ahead, behind) {
                (Some(f), Some(b)) => f
                    .iter()
                    .zip(&b)
                    .map(|(f, b)| [f[0] - b[0], f[1] - b[1]])
                    .collect(),
                (Some(f), None) => f.iter().map(|f| [2.0 * f[0], 2.0 * f[1]]).collect(),
                (None, Some(b)) => b.iter().map(|b| [-2.0 * b[0], -2.0 * b[1]]).collect(),
                (None, None) => unreachable!("at least two key frames"),
            })
        })
        .collect()
}

/// Exports `frames[0::2]` with motion vectors, rebuilds the odd frames, returns the row.
fn case(
    name: &str,
    frames: &[RgbaFrame],
    dir: &std::path::Path,
    known: Known,
    motion: MotionSource,
) -> Result<serde_json::Value> {
    let kept: Vec<RgbaFrame> = frames.iter().step_by(2).cloned().collect();
    let path = dir.join(format!("{name}.png"));
    let opts = WriteOptions {
        loop_: false,
        flipbook: FlipbookOptions {
            padding: 2,
            motion: Some(motion.clone()),
            ..Default::default()
        },
        ..Default::default()
    };
    let mut w = ignis_media::create(&path, kept[0].size(), &opts)?;
    for f in &kept {
        w.push(f)?;
    }
    w.finish()
        .with_context(|| format!("writing {}", path.display()))?;
    let fb = ignis_media::read_flipbook(&path.with_extension("json"))?;
    let mv = fb.motion.context("the flipbook has no motion vectors")?;
    let sheet = blend_errors(&fb.frames, &mv, frames);
    let reduction = 1.0 - sheet.0 / sheet.1.max(1e-12);
    let change =
        kept.windows(2).map(|p| error(&p[0], &p[1])).sum::<f64>() / (kept.len() - 1) as f64;
    let mid = in_between_vectors(frames)?;
    let mut row = figures_of(sheet);
    let extra = json!({
        "case": name,
        "size": kept[0].size().to_string(),
        "dropped_frames": kept.len() - 1,
        "key_frame_change": r3(change),
        "motion_vector_scale": fb.meta.motion_vectors.map(|m| m.scale),
        "goal_met": reduction >= GOAL_REDUCTION,
        "exact_colour": figures_of(blend_errors(&kept, &mv, frames)),
        "in_between_flow": {
            "uses_in_between_frame": true,
            "sheet": figures_of(blend_errors(&fb.frames, &mid, frames)),
            "exact_colour": figures_of(blend_errors(&kept, &mid, frames)),
        },
        "filtered": filtered(&fb.frames, &mv, frames),
        "diagnosis": diagnosis(&kept, frames, &mv, known)?,
    });
    if let (Some(r), serde_json::Value::Object(e)) = (row.as_object_mut(), extra) {
        r.extend(e);
    }
    if let Some((source, _)) = motion.description() {
        // what the flow would have written, for comparison (unquantised)
        row["motion_source"] = json!(source);
        // the generator chose its vectors on the frames this row rebuilds: say so, and
        // where the figures on frames it did not see are
        row["in_sample"] = json!(
            "the vectors were chosen per pixel on the dropped frames themselves (the exporter renders them); held_out_t gives blends at t = 0.25 / 0.75 on frames not used for the choice"
        );
        let flow = gated_velocities(&fb.frames)?;
        row["flow_sheet"] = figures_of(blend_errors(&fb.frames, &flow, frames));
        row["flow_filtered"] = filtered(&fb.frames, &flow, frames);
    }
    Ok(row)
}

/// The classic fire `ignis classic --size 160x120` renders by default (6-px cells,
/// puffing), and the 1999 article's fire exactly (`--cell 1 --puff 0`: pixel-level
/// noise), both with seed 7.
fn classic_params(article: bool) -> Result<ignis_classic::ClassicParams> {
    let size = Size::new(160, 120)?;
    let base = ignis_classic::ClassicParams {
        size,
        seed: 7,
        cell: crate::classic::default_cell(size),
        ..ignis_classic::ClassicParams::preset()
    };
    Ok(if article {
        ignis_classic::ClassicParams {
            cell: 1,
            puff: 0.0,
            ..base
        }
    } else {
        base
    })
}

/// Classic frames (one step each) and the model's velocity per key frame (two steps), in
/// output pixels (a buffer cell is `cell` pixels).
fn classic(
    n: usize,
    params: &ignis_classic::ClassicParams,
) -> Result<(Vec<RgbaFrame>, Vec<Field>)> {
    let [vx, vy] = ignis_classic::motion::velocity_per_step(params);
    let c = params.cell as f32;
    let model = vec![vec![[2.0 * c * vx, 2.0 * c * vy]; params.size.pixels()]; n.div_ceil(2)];
    let mut fire = ignis_classic::ClassicFire::new(params.clone())?;
    let palette = ignis_core::Palette::preset("classic")?;
    for _ in 0..60 {
        fire.step();
    }
    let frames = (0..n)
        .map(|_| {
            fire.step();
            fire.rgba(&palette)
        })
        .collect();
    Ok((frames, model))
}

/// The motion source `--every 2 --motion-vectors` gives `frames` written every other one
/// (`ignis loop`, `ignis classic`): the vectors chosen by the frames left out.
fn left_out_source(frames: &[RgbaFrame]) -> MotionSource {
    let source = crate::inbetween::InBetween::new(false);
    source.start_row();
    for mid in frames.iter().skip(1).step_by(2) {
        source.record(mid.clone());
    }
    source.source()
}

/// `n` frames of a volume preset at `rate` times its frame rate, 128², and what the model
/// knows of their motion with key frames every `step`-th frame
/// ([`ignis_volume::model_motion()`]): each key frame's velocity (central over its
/// neighbouring key frames, one-sided at the ends) as `model`, and per key interval the
/// forward and backward motion.
fn volume(
    n: usize,
    preset: ignis_volume::Preset,
    rate: f32,
    step: usize,
) -> Result<(Vec<RgbaFrame>, Known<'static>)> {
    let mut scene = ignis_volume::FireScene::preset(preset).with_size(Size::new(128, 128)?);
    scene.fps *= rate;
    let mut anim = scene.animator()?;
    let (frames, poses): (Vec<RgbaFrame>, Vec<ignis_volume::Pose>) = (0..n)
        .map(|_| Ok(anim.next_frame_with_pose().map(|(f, p)| (f.image, p))?))
        .collect::<Result<Vec<_>>>()?
        .into_iter()
        .unzip();
    let keys: Vec<&ignis_volume::Pose> = poses.iter().step_by(step).collect();
    let mut known = Known::default();
    for ((name, _), (velocities, pairs)) in VOLUME_FOLLOW.iter().zip(volume_motion(&scene, &keys)?)
    {
        known.velocities.push((name, velocities));
        known.pairs.push((name, pairs));
    }
    Ok((frames, known))
}

/// The volume rows' model motions ([`ignis_volume::Follow`]), by name: `model_flow` the
/// model's own optical flow (the displaced profile each sample shows), `model` a fixed
/// spatial noise coordinate (the lattice and the scroll), `model_noise` the noise's
/// least-changing track through its time axis too, `model_lattice` the lattice alone.
const VOLUME_FOLLOW: [(&str, ignis_volume::Follow); 4] = [
    ("model_flow", ignis_volume::Follow::Flow),
    ("model", ignis_volume::Follow::Scroll),
    ("model_noise", ignis_volume::Follow::Noise),
    ("model_lattice", ignis_volume::Follow::Lattice),
];

/// The model motions ([`VOLUME_FOLLOW`]) of a volume scene between its key frames'
/// poses, per kind: each key frame's velocity (central over its neighbouring key frames,
/// one-sided at the ends), and per key interval the forward and backward motion.
#[allow(clippy::type_complexity)]
fn volume_motion(
    scene: &ignis_volume::FireScene,
    keys: &[&ignis_volume::Pose],
) -> Result<Vec<(Vec<Field>, Vec<(Field, Field)>)>> {
    let kinds = VOLUME_FOLLOW.len();
    // per kind, per key frame: its motion to the next and to the previous key frame
    let mut ahead = vec![Vec::new(); kinds];
    let mut behind = vec![Vec::new(); kinds];
    for (k, pose) in keys.iter().enumerate() {
        let (next, prev) = (keys.get(k + 1), k.checked_sub(1).map(|j| &keys[j]));
        let mut to = Vec::new();
        for (_, follow) in VOLUME_FOLLOW {
            to.extend(next.map(|&p| (p, follow)));
            to.extend(prev.map(|&p| (p, follow)));
        }
        let mut m = ignis_volume::model_motion(scene, pose, &to)?.into_iter();
        for i in 0..kinds {
            ahead[i].push(next.and_then(|_| m.next()));
            behind[i].push(prev.and_then(|_| m.next()));
        }
    }
    (0..kinds)
        .map(|i| {
            let velocities = ahead[i]
                .iter()
                .zip(&behind[i])
                .map(|(a, b)| {
                    ignis_media::write::motion::frame_velocity(a.as_deref(), b.as_deref())
                        .context("at least two key frames")
                })
                .collect::<Result<Vec<_>>>()?;
            let pairs = (0..keys.len() - 1)
                .map(|k| {
                    let f = ahead[i][k].clone().context("a forward motion")?;
                    let b = behind[i][k + 1].clone().context("a backward motion")?;
                    Ok((f, b))
                })
                .collect::<Result<Vec<_>>>()?;
            Ok((velocities, pairs))
        })
        .collect()
}

/// The learned row ([`learned`] at twice the model's rate, `n` frames, with its model
/// motion) and its held-out blends (at four times the rate).
fn learned_case(
    g: &Global,
    quick: bool,
    n: usize,
    dir: &std::path::Path,
) -> Result<(serde_json::Value, serde_json::Value)> {
    let (model, trained_on) = learned_model(g, quick, crate::demo::shared_data("candle.mp4"))?;
    let (frames, warps) = learned(&model, n, 2.0)?;
    let size = frames[0].size();
    let known = Known {
        velocities: vec![
            (
                "model",
                model_velocities(&model.shape, &warps, size, (2, 2)),
            ),
            (
                "model_half_steps",
                model_velocities(&model.shape, &warps, size, (2, 1)),
            ),
        ],
        pairs: vec![("model", model_pairs(&model.shape, &warps, size, 2))],
    };
    let mut row = case(
        "learned",
        &frames,
        dir,
        known,
        cli_model_source(&model, n.div_ceil(2))?,
    )?;
    row["trained_on"] = json!(trained_on);
    let (frames, warps) = learned(&model, 2 * n - 1, 4.0)?;
    let known = Known {
        velocities: vec![(
            "model",
            model_velocities(&model.shape, &warps, size, (4, 4)),
        )],
        pairs: vec![("model", model_pairs(&model.shape, &warps, size, 4))],
    };
    Ok((row, held_out(&frames, known)?))
}

/// The learned row's model: `candle.mp4` trained as `bench realism` trains it, or without
/// the footage the synthetic clip `bench learned` trains on, so the row exists anyway.
fn learned_model(
    g: &Global,
    quick: bool,
    candle: Option<std::path::PathBuf>,
) -> Result<(ignis_learned::FlameModel, &'static str)> {
    if let Some(clip) = candle {
        return Ok((super::realism::candle_model(g, &clip, quick)?, "candle.mp4"));
    }
    let clip = ignis_learned::synthetic::flame_clip(Size::new(256, 256)?, 100, 1);
    let p = ignis_learned::TrainParams {
        em: ignis_learned::EmParams {
            seed: 1,
            ..Default::default()
        },
        ..Default::default()
    };
    let mut model = ignis_learned::train(clip, &p, &mut ignis_core::progress::NoProgress)?.model;
    // the synthetic clip's oscillators are defined at 30 frames per second
    model.summary.fps = Some(30.0);
    Ok((
        model,
        "synthetic clip (ignis_learned::synthetic, candle.mp4 not found)",
    ))
}

/// The motion source `ignis learned synth --motion-vectors` gives a one-shot flipbook of
/// the `keys` frames [`learned`] renders at the model's rate (the key frames of the
/// learned row): the same recording ([`crate::learned::ModelMotion`]: warps, in-between
/// frames from [`ignis_learned::Synthesiser::between_into`]) and the same choice.
fn cli_model_source(model: &ignis_learned::FlameModel, keys: usize) -> Result<MotionSource> {
    let fps = model
        .summary
        .fps
        .context("the learned model has no frame rate")?;
    let mut synth = ignis_learned::Synthesiser::new_at(model, Default::default(), 1, Some(fps))?;
    synth.skip(LEARNED_WARM_UP.round() as u64);
    let palette = ignis_core::Palette::preset("candle")?;
    let size = Size::new(128, 128)?;
    let motion = crate::learned::ModelMotion::new(&model.shape, false);
    motion.start_row();
    let mut grey = ignis_core::GrayFrame::new(size);
    for k in 0..keys {
        synth.next_frame_into(&mut grey);
        motion.record(
            &mut synth,
            size,
            k + 1 < keys,
            |f: &mut ignis_core::GrayFrame| palette.apply(f),
        );
    }
    Ok(motion.source())
}

/// The motion source `ignis volume render --preset P --no-loop --motion-vectors` gives a
/// one-shot flipbook of the `keys` frames [`volume`] renders at twice the scene's rate
/// (every other one: the key frames of the volume rows): the in-between frames rendered by
/// [`ignis_volume::Animator::frame_between`] and the vectors chosen by them
/// ([`crate::inbetween::InBetween`]).
fn cli_volume_source(preset: ignis_volume::Preset, keys: usize) -> Result<MotionSource> {
    let scene = ignis_volume::FireScene::preset(preset).with_size(Size::new(128, 128)?);
    let mut anim = scene.animator()?;
    let motion = crate::inbetween::InBetween::new(false);
    motion.start_row();
    for k in 0..keys {
        anim.next_frame()?;
        if motion.wants(k + 1 < keys) {
            motion.record(anim.frame_between(0.5)?.image);
        }
    }
    Ok(motion.source())
}

/// How an engine may sample the vector sheet: `bilinear`, the blend evaluated half-way
/// between pixel centres (vectors, key frames and the true frame all bilinear there: the
/// most a half-texel offset mixes neighbouring vectors), and `mip1`, the vector sheet
/// box-averaged 2×2 and upsampled bilinearly (a minified sprite), at pixel centres.
fn filtered(keys: &[RgbaFrame], mv: &[Field], truth: &[RgbaFrame]) -> serde_json::Value {
    json!({
        "bilinear": figures_of(offset_blend_errors(keys, mv, truth)),
        "mip1": figures_of(blend_errors(keys, &mip1(mv, keys[0].size()), truth)),
    })
}

/// A field as a frame (`[dx, dy, 0, 0]`), so it can be sampled bilinearly.
fn field_frame(f: &[[f32; 2]], size: Size) -> RgbaFrame {
    let px = f.iter().map(|v| [v[0], v[1], 0.0, 0.0]).collect();
    RgbaFrame::from_vec(size, px).expect("one vector per pixel")
}

/// Each field box-averaged 2×2 (edge pixels repeated for odd sides) and upsampled
/// bilinearly to `size` again.
fn mip1(mv: &[Field], size: Size) -> Vec<Field> {
    use ignis_media::write::motion::sample_bilinear;
    let (w, h) = (size.width as usize, size.height as usize);
    let (mw, mh) = (w.div_ceil(2), h.div_ceil(2));
    let small = Size::new(mw as u32, mh as u32).expect("half a valid size");
    mv.iter()
        .map(|f| {
            let at = |x: usize, y: usize| f[y.min(h - 1) * w + x.min(w - 1)];
            let down: Field = (0..mw * mh)
                .map(|i| {
                    let (x, y) = (2 * (i % mw), 2 * (i / mw));
                    let q = [at(x, y), at(x + 1, y), at(x, y + 1), at(x + 1, y + 1)];
                    [0, 1].map(|c| 0.25 * q.iter().map(|v| v[c]).sum::<f32>())
                })
                .collect();
            let m = field_frame(&down, small);
            (0..w * h)
                .map(|i| {
                    let (x, y) = ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
                    let p = sample_bilinear(&m, 0.5 * x, 0.5 * y);
                    [p[0], p[1]]
                })
                .collect()
        })
        .collect()
}

/// [`blend_errors`] with the blend evaluated half-way between pixel centres (see
/// [`filtered`]).
fn offset_blend_errors(keys: &[RgbaFrame], mv: &[Field], truth: &[RgbaFrame]) -> (f64, f64) {
    use ignis_media::write::motion::sample_bilinear;
    let size = keys[0].size();
    let w = size.width as usize;
    let pairs = keys.len() - 1;
    let (mut e_mv, mut e_plain) = (0.0, 0.0);
    for k in 0..pairs {
        let (a, b) = (&keys[k], &keys[k + 1]);
        let (fa, fb) = (field_frame(&mv[k], size), field_frame(&mv[k + 1], size));
        let (mut m, mut l, mut t) = (a.clone(), a.clone(), a.clone());
        for i in 0..size.pixels() {
            let (x, y) = ((i % w) as f32 + 1.0, (i / w) as f32 + 1.0);
            let (u, v) = (sample_bilinear(&fa, x, y), sample_bilinear(&fb, x, y));
            let p = sample_bilinear(a, x - 0.5 * u[0], y - 0.5 * u[1]);
            let q = sample_bilinear(b, x + 0.5 * v[0], y + 0.5 * v[1]);
            let (p0, q0) = (sample_bilinear(a, x, y), sample_bilinear(b, x, y));
            m.data_mut()[i] = [0, 1, 2, 3].map(|c| 0.5 * (p[c] + q[c]));
            l.data_mut()[i] = [0, 1, 2, 3].map(|c| 0.5 * (p0[c] + q0[c]));
            t.data_mut()[i] = sample_bilinear(&truth[2 * k + 1], x, y);
        }
        e_mv += error(&m, &t);
        e_plain += error(&l, &t);
    }
    (e_mv / pairs as f64, e_plain / pairs as f64)
}

/// Process steps the learned row skips first (from the model's last training states).
const LEARNED_WARM_UP: f64 = 30.0;

/// `n` frames of the learned flame at `rate` times the model's frame rate, 128², as
/// `ignis learned synth --fps` renders them (the process at the footage's rate, each frame
/// the state at its own time: [`ignis_learned::Synthesiser::new_at`]; seed 1, the `candle`
/// palette), after [`LEARNED_WARM_UP`] steps, and the warp each frame was drawn with.
fn learned(
    model: &ignis_learned::FlameModel,
    n: usize,
    rate: f64,
) -> Result<(Vec<RgbaFrame>, Vec<ignis_learned::Warp>)> {
    let fps = model
        .summary
        .fps
        .context("the learned model has no frame rate")?
        * rate;
    let mut synth = ignis_learned::Synthesiser::new_at(model, Default::default(), 1, Some(fps))?;
    synth.skip((LEARNED_WARM_UP * rate).round() as u64);
    let palette = ignis_core::Palette::preset("candle")?;
    let size = Size::new(128, 128)?;
    let mut grey = ignis_core::GrayFrame::new(size);
    let (mut frames, mut warps) = (Vec::new(), Vec::new());
    for _ in 0..n {
        synth.next_frame_into(&mut grey);
        frames.push(palette.apply(&grey));
        warps.push(synth.warp(size));
    }
    Ok((frames, warps))
}

/// The learned flame's own motion ([`ignis_learned::model_motion`]) as a velocity over one
/// key interval for each key frame (every `step`-th of `warps`): from the model motion to
/// the frames `reach` on either side, `(ahead − behind) · step / (2 · reach)`, one-sided at
/// the ends. `reach = step` is the convention of classic's `model` and the flipbook
/// writer (neighbouring key frames); a smaller reach uses in-between times, which the
/// model knows without rendering them.
fn model_velocities(
    p: &ignis_learned::ShapeParams,
    warps: &[ignis_learned::Warp],
    size: Size,
    (step, reach): (usize, usize),
) -> Vec<Field> {
    let k = step as f32 / reach as f32;
    let motion = |i: usize, j: usize| -> Field {
        let m = ignis_learned::model_motion(p, &warps[i], &warps[j], size);
        m.into_iter().map(|v| [v[0] * k, v[1] * k]).collect()
    };
    let last = (warps.len() - 1) / step * step;
    (0..=last)
        .step_by(step)
        .map(|i| {
            let ahead = (i + step <= last).then(|| motion(i, i + reach));
            let behind = (i > 0).then(|| motion(i, i - reach));
            ignis_media::write::motion::frame_velocity(ahead.as_deref(), behind.as_deref())
                .expect("at least two key frames")
        })
        .collect()
}

/// The learned flame's model motion over each key interval (key frames every `step`-th
/// of `warps`): forward from the earlier key frame, backward from the later.
fn model_pairs(
    p: &ignis_learned::ShapeParams,
    warps: &[ignis_learned::Warp],
    size: Size,
    step: usize,
) -> Vec<(Field, Field)> {
    let m = |i: usize, j: usize| ignis_learned::model_motion(p, &warps[i], &warps[j], size);
    (0..(warps.len() - 1) / step)
        .map(|k| (m(step * k, step * k + step), m(step * k + step, step * k)))
        .collect()
}

fn footage(name: &str, n: usize) -> Result<Option<Vec<RgbaFrame>>> {
    let Some(path) = crate::demo::shared_data(name) else {
        return Ok(None);
    };
    let opts = ReadOptions {
        range: Some(ignis_media::FrameRange::frames(100, Some(100 + n as u64))),
        scale: Some(Size::new(256, 144)?),
        ..Default::default()
    };
    let frames = ignis_media::open(&path, &opts)?
        .collect::<std::result::Result<Vec<_>, _>>()
        .with_context(|| format!("decoding {}", path.display()))?;
    Ok(Some(frames))
}

/// The table: one row per case, plus the flow and flipbook timings.
pub fn figures(g: &Global, quick: bool) -> Result<serde_json::Value> {
    let n: usize = if quick { 9 } else { 25 };
    let dir = tempfile::tempdir()?;
    let mut rows = Vec::new();
    let sp = g.spinner("exporting at half rate and rebuilding the dropped frames");
    // A textured picture moving 1.5 px right and 1 px up per frame: the blend's
    // reference case (its motion is exactly what motion vectors describe).
    let shift: Vec<RgbaFrame> = (0..n)
        .map(|i| {
            let d = [1.5 * i as f32, -(i as f32)];
            ignis_flow::bench::texture(Size::new(128, 128).unwrap(), 3, d, 1.5).to_rgba()
        })
        .collect();
    let truth = vec![vec![[1.5f32 * 2.0, -2.0]; 128 * 128]; n.div_ceil(2)];
    rows.push(case(
        "moving-texture",
        &shift,
        dir.path(),
        Known::model(truth),
        flow_source(),
    )?);
    let mut held = serde_json::Map::new();
    // as `ignis classic --size 160x120 --every 2 --motion-vectors` writes them (with
    // `--cell 1 --puff 0` for the article's fire)
    for (name, article) in [("classic", false), ("classic-article", true)] {
        let params = classic_params(article)?;
        let (frames, model) = classic(n, &params)?;
        let source = left_out_source(&frames);
        rows.push(case(
            name,
            &frames,
            dir.path(),
            Known::model(model),
            source,
        )?);
        held.insert(
            name.into(),
            held_out(&classic(2 * n - 1, &params)?.0, Known::default())?,
        );
    }
    for p in [ignis_volume::Preset::Candle, ignis_volume::Preset::Campfire] {
        let name = format!("volume-{}", p.name());
        let (frames, known) = volume(n, p, 2.0, 2)?;
        let source = cli_volume_source(p, n.div_ceil(2))?;
        rows.push(case(&name, &frames, dir.path(), known, source)?);
        let (frames, known) = volume(2 * n - 1, p, 4.0, 4)?;
        held.insert(name, held_out(&frames, known)?);
    }
    let (row, held_learned) = learned_case(g, quick, n, dir.path())?;
    rows.push(row);
    held.insert("learned".into(), held_learned);
    let mut skipped = Vec::new();
    for clip in ["candle.mp4", "campfire.mp4"] {
        match footage(clip, n)? {
            Some(frames) => {
                // as `ignis loop --every 2 --motion-vectors` writes them: the vectors
                // chosen by the source frames left out
                rows.push(case(
                    clip,
                    &frames,
                    dir.path(),
                    Known::default(),
                    left_out_source(&frames),
                )?);
                if let Some(f) = footage(clip, 2 * n - 1)? {
                    held.insert(clip.to_string(), held_out(&f, Known::default())?);
                }
            }
            None => skipped.push(format!("{clip}: ../shared/data not found")),
        }
    }
    // A 64-frame 256² flipbook with motion vectors, end to end.
    let scene = ignis_volume::FireScene::preset(ignis_volume::Preset::Candle)
        .with_size(Size::new(256, 256)?);
    let mut anim = scene.animator()?;
    let frames: Vec<RgbaFrame> = (0..64)
        .map(|_| Ok(anim.next_frame()?.image))
        .collect::<Result<_>>()?;
    let path = dir.path().join("timed.png");
    let opts = WriteOptions {
        flipbook: FlipbookOptions {
            motion: Some(flow_source()),
            ..Default::default()
        },
        ..Default::default()
    };
    let c0 = super::flow::process_cpu_ms();
    let t = Instant::now();
    let mut w = ignis_media::create(&path, frames[0].size(), &opts)?;
    for f in &frames {
        w.push(f)?;
    }
    w.finish()?;
    let flipbook_s = t.elapsed().as_secs_f64();
    // CPU time of all threads: on a busy machine wall time overstates the cost.
    let cpu_since = |c0: Option<f64>| match (c0, super::flow::process_cpu_ms()) {
        (Some(a), Some(b)) => Some(((b - a) / 1000.0 * 1000.0).round() / 1000.0),
        _ => None,
    };
    let flipbook_cpu_s = cpu_since(c0);
    // The same loop as `ignis volume render --preset candle --size 256x256 --frames 64
    // --motion-vectors -o x.png` writes it: a loop, each frame's in-between frame rendered
    // and the vectors chosen by them; timed: the extra renders and the writer.
    let mut anim = scene.looping_animator(64)?;
    let looped: Vec<RgbaFrame> = (0..64)
        .map(|_| Ok(anim.next_frame()?.image))
        .collect::<Result<_>>()?;
    let c0 = super::flow::process_cpu_ms();
    let t = Instant::now();
    let motion = crate::inbetween::InBetween::new(true);
    motion.start_row();
    let mut anim = scene.looping_animator(64)?;
    for _ in 0..64 {
        anim.skip(1);
        motion.record(anim.frame_between(0.5)?.image);
    }
    let opts = WriteOptions {
        loop_: true,
        flipbook: FlipbookOptions {
            motion: Some(motion.source()),
            ..Default::default()
        },
        ..Default::default()
    };
    let mut w = ignis_media::create(&dir.path().join("timed-loop.png"), looped[0].size(), &opts)?;
    for f in &looped {
        w.push(f)?;
    }
    w.finish()?;
    let in_between_s = t.elapsed().as_secs_f64();
    let in_between_cpu_s = cpu_since(c0);
    let load = std::fs::read_to_string("/proc/loadavg")
        .ok()
        .and_then(|l| l.split_whitespace().next()?.parse::<f64>().ok());
    let flow: Vec<serde_json::Value> =
        ignis_flow::bench::figures(quick, &super::flow::process_cpu_ms)?
            .iter()
            .filter(|t| t.name.starts_with("flow_"))
            .map(|t| {
                json!({
                    "case": t.name,
                    "size": t.size.to_string(),
                    "median_ms": (t.median_ms * 10.0).round() / 10.0,
                    "goal_ms": t.goal_ms,
                    "goal_met": t.goal_met(),
                })
            })
            .collect();
    sp.finish_and_clear();
    Ok(json!({
        "threads": rayon::current_num_threads(),
        "metric": "mean |error| vs the true dropped frame, 8-bit sRGB levels, colour over black",
        "variants": {
            "headline": "the vectors --motion-vectors writes, on the 8-bit colour sheet read back: image-only vectors (ignis_flow::motion_vector_pair velocities), except for the learned row, whose sheet is written as `ignis learned synth --motion-vectors` writes it (motion_source: the model's motion chosen per pixel by the rendered in-between frames), the footage rows, written as `ignis loop --every 2 --motion-vectors` writes them (the same choice by the source frames left out), the classic rows, written as `ignis classic --size 160x120 --every 2 --motion-vectors` writes them (the same choice by the steps left out; classic-article: with --cell 1 --puff 0, the 1999 article's per-pixel fire), and the volume rows, written as `ignis volume render --motion-vectors` writes them (motion_source: vectors from the flows of each in-between frame the renderer draws, ignis_volume::Animator::frame_between, to its two key frames, chosen per pixel by the in-between frames, on the key frames as the 8-bit sheet holds them: mid_flow_chosen); flow_sheet: the gated flow's vectors on the same frames, for comparison",
            "filtered": "the headline's vectors sampled as an engine may: bilinear (blend evaluated half-way between pixel centres, vectors, key frames and true frame bilinear there) and mip1 (vector sheet box-averaged 2x2 and upsampled bilinearly); flow_filtered: the same for the flow's vectors on the learned row",
            "exact_colour": "the same vectors on the unquantised key frames (what the --hdr EXR colour sheet gives): separates the 8-bit sheet's rounding from the blend",
            "in_between_flow": "velocities from flows key -> true in-between frames (uses the dropped frames: possible only when the exporter has them, e.g. decimated footage or a generator rendered at twice the rate); vectors unquantised",
            "key_frame_change": "mean |error| between consecutive key frames: how much there is to blend",
            "held_out_t": "error_reduction at blends t = 0.25 / 0.5 / 0.75 with key frames every 4th frame (footage: every 4th source frame), default vs loose gating (gated_mip1: the default's vectors read at mip level 1, see filtered), raw_flow_chosen and mid_flow_chosen (chosen on the t = 0.5 frames only, so t = 0.25 / 0.75 are held out; mid_flow_chosen is what the volume rows' sheets hold), and for the learned flame model, model_chosen (what `ignis learned synth --motion-vectors` writes; model_chosen_mip1 read at mip level 1) and model_pairwise; the volume rows the same for each of their model motions (model, model_flow, model_noise, model_lattice: see diagnosis), none of which the volume sheet uses (it holds mid_flow_chosen); vectors unquantised: checks a change on frames it was not tuned on",
            "diagnosis": "error_reduction of other vectors on the unquantised key frames: gated_sheet_16bit (the sheet's vectors read back), gated_unquantised (the same before 16-bit encoding), raw_flow / raw_flow_full_res (ungated DIS velocities, finest pyramid level 1 / 0), raw_flow_halved, gated_loose (consistency 8 px, explained 0.05), model (the generator's own motion: exact shift for the texture, ignis_classic::motion for classic, ignis_learned::model_motion for the learned flame: its texture attached to the flame's canonical coordinates; ignis_volume::model_motion for the volume rows: a fixed noise coordinate carried by the lattice and the scroll, emission-weighted over each pixel's samples; model_noise: the noise's least-changing track through its time axis instead; model_lattice: the lattice alone; model_flow: the model's own optical flow, the least-squares shift that keeps each sample's displaced-profile brightness, plus the lattice's motion; central over the neighbouring key frames), model_half_steps (learned: the same from the model's motion to the in-between times, known without rendering them), raw_flow_pairwise / model_pairwise (not one vector per frame: each dropped frame blended with the forward motion for the earlier key frame and the reversed backward motion for the later, from the raw flow / the learned model: what a forward and a backward sheet would give), raw_flow_chosen / model_chosen (uses the in-between frames: one vector per key frame and pixel, storable in a sheet, chosen among none / forward / reversed backward / central so that the blends at 0.5 err least against the true in-between frames, exactly over the run of key frames), mid_flow_chosen (the same choice among none / the vector that brings the key frame half-way to the in-between frame after it / the one for the frame before it / their mean, from DIS flows of each in-between frame to its two key frames, at the output pixel: crate::inbetween::mid_pairs), best_per_pixel_bound (per dropped pixel the best single velocity within 4 px for both key frames, chosen by looking at the true frame: a bound for vectors shared by the two key frames, not for the chosen ones, which give each key frame its own)",
        },
        "goal_error_reduction": GOAL_REDUCTION,
        "blend": rows,
        "held_out_t": held,
        "skipped": skipped,
        "flipbook_64x256_mv_s": (flipbook_s * 1000.0).round() / 1000.0,
        "flipbook_64x256_mv_cpu_s": flipbook_cpu_s,
        "load_average_1min": load,
        "flipbook_64x256_loop_in_between": {
            "what": "ignis volume render --preset candle --size 256x256 --frames 64 --motion-vectors (a loop; vectors chosen by the in-between frames): the 64 in-between renders and the writer, not the 64 frames themselves",
            "s": (in_between_s * 1000.0).round() / 1000.0,
            "cpu_s": in_between_cpu_s,
        },
        "flipbook_goal_s": GOAL_FLIPBOOK_S,
        "flipbook_goal_met": flipbook_s <= GOAL_FLIPBOOK_S,
        "flow": flow,
    }))
}

/// Frame `k`'s velocity from the flows of each pair `(k → k+1, k+1 → k)`: the mean of its
/// forward and reversed backward motion, one side at the ends (as the flipbook writer).
fn velocities(pairs: &[(Field, Field)]) -> Vec<Field> {
    let n = pairs.len() + 1;
    (0..n)
        .map(|k| {
            let ahead = (k < pairs.len()).then(|| &pairs[k].0);
            let behind = (k > 0).then(|| &pairs[k - 1].1);
            ignis_media::write::motion::frame_velocity(
                ahead.map(Vec::as_slice),
                behind.map(Vec::as_slice),
            )
            .expect("at least two key frames")
        })
        .collect()
}

/// Velocities from the plain (ungated) flow at `finest` pyramid level.
fn raw_velocities(keys: &[RgbaFrame], finest: u32) -> Result<Vec<Vec<[f32; 2]>>> {
    Ok(velocities(&flow_pairs(keys, finest)?))
}

/// Mean error at blend 0.5 over the dropped frames with a pair of vector fields per key
/// interval (`pairs[k]`: forward from key `k`, backward from key `k + 1`): the earlier
/// key frame moved by the forward motion, the later by the reversed backward one. What a
/// forward and a backward sheet per frame would give; the engines' blend stores one.
fn pairwise_error(keys: &[RgbaFrame], pairs: &[(Field, Field)], truth: &[RgbaFrame]) -> f64 {
    let n = keys.len() - 1;
    (0..n)
        .map(|k| {
            let (f, b) = &pairs[k];
            let back: Field = b.iter().map(|v| [-v[0], -v[1]]).collect();
            error(
                &mv_blend(&keys[k], &keys[k + 1], f, &back, 0.5),
                &truth[2 * k + 1],
            )
        })
        .sum::<f64>()
        / n as f64
}

/// The plain (ungated) flows of each key pair at `finest` pyramid level, `(k → k+1, k+1 → k)`.
fn flow_pairs(keys: &[RgbaFrame], finest: u32) -> Result<Vec<(Field, Field)>> {
    let p = ignis_flow::FlowParams {
        finest_scale: finest,
        ..Default::default()
    };
    keys.windows(2)
        .map(|w| {
            let (f, b) =
                ignis_flow::flow_pair(&ignis_flow::luma(&w[0]), &ignis_flow::luma(&w[1]), &p)?;
            Ok((f.into_vec(), b.into_vec()))
        })
        .collect()
}

/// Gated velocities ([`ignis_flow::motion_vector_pair`]) unquantised.
fn gated_velocities(keys: &[RgbaFrame]) -> Result<Vec<Vec<[f32; 2]>>> {
    gated_with(keys, &ignis_flow::VectorParams::default())
}

fn gated_with(keys: &[RgbaFrame], p: &ignis_flow::VectorParams) -> Result<Vec<Vec<[f32; 2]>>> {
    let pairs = keys
        .windows(2)
        .map(|w| {
            let (f, b) = ignis_flow::motion_vector_pair(&w[0], &w[1], p)?;
            Ok((f.into_vec(), b.into_vec()))
        })
        .collect::<Result<Vec<_>>>()?;
    Ok(velocities(&pairs))
}

/// Lower bound of the blend's error: per dropped pixel, the best velocity on a 0.25 px grid
/// within ±`r` px (the same vector for both key frames), chosen by looking at the truth.
fn best_per_pixel(keys: &[RgbaFrame], truth: &[RgbaFrame], r: f32) -> f64 {
    use ignis_core::palette::linear_to_srgb;
    use ignis_media::write::motion::sample_bilinear;
    use rayon::prelude::*;
    let steps = (r / 0.25).round() as i32;
    let enc =
        |p: [f32; 4]| [0, 1, 2].map(|c| linear_to_srgb((p[c] * p[3]).clamp(0.0, 1.0)) * 255.0);
    let mut total = 0.0;
    for k in 0..keys.len() - 1 {
        let (a, b, t) = (&keys[k], &keys[k + 1], &truth[2 * k + 1]);
        let w = a.width() as usize;
        let sum: f64 = t
            .data()
            .par_iter()
            .enumerate()
            .map(|(i, &q)| {
                let want = enc(q);
                let (x, y) = ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
                let mut best = f32::MAX;
                for sy in -steps..=steps {
                    for sx in -steps..=steps {
                        let (u, v) = (sx as f32 * 0.25, sy as f32 * 0.25);
                        let p = sample_bilinear(a, x - u * 0.5, y - v * 0.5);
                        let n = sample_bilinear(b, x + u * 0.5, y + v * 0.5);
                        let m = [0, 1, 2, 3].map(|c| 0.5 * (p[c] + n[c]));
                        let got = enc(m);
                        let e = (0..3).map(|c| (got[c] - want[c]).abs()).sum::<f32>();
                        best = best.min(e);
                    }
                }
                best as f64 / 3.0
            })
            .sum();
        total += sum / t.data().len() as f64;
    }
    total / (keys.len() - 1) as f64
}

/// Per-case diagnosis on the unquantised key frames at blend 0.5: which vectors help.
fn diagnosis(
    keys: &[RgbaFrame],
    truth: &[RgbaFrame],
    sheet_mv: &[Vec<[f32; 2]>],
    known: Known,
) -> Result<serde_json::Value> {
    let plain = blend_errors(
        keys,
        &vec![vec![[0.0; 2]; keys[0].size().pixels()]; keys.len()],
        truth,
    )
    .1;
    let red = |mv: &[Vec<[f32; 2]>]| r3(1.0 - blend_errors(keys, mv, truth).0 / plain.max(1e-12));
    let raw_pairs = flow_pairs(keys, 1)?;
    let raw1 = velocities(&raw_pairs);
    let max_v = raw1
        .iter()
        .flatten()
        .map(|v| v[0].abs().max(v[1].abs()))
        .fold(0f32, f32::max);
    let mut d = json!({
        "plain_error": r3(plain),
        "gated_sheet_16bit": red(sheet_mv),
        "gated_unquantised": red(&gated_velocities(keys)?),
        "raw_flow": red(&raw1),
        "raw_flow_full_res": red(&raw_velocities(keys, 0)?),
        "max_raw_velocity_px": r3(max_v as f64),
        "best_per_pixel_bound": r3(1.0 - best_per_pixel(keys, truth, 4.0) / plain.max(1e-12)),
    });
    let half: Vec<Vec<[f32; 2]>> = raw1
        .iter()
        .map(|f| f.iter().map(|v| [v[0] * 0.5, v[1] * 0.5]).collect())
        .collect();
    d["raw_flow_halved"] = json!(red(&half));
    let loose = ignis_flow::VectorParams {
        consistency_px: 8.0,
        explained: 0.05,
        ..Default::default()
    };
    d["gated_loose"] = json!(red(&gated_with(keys, &loose)?));
    let pair_red =
        |pairs: &[(Field, Field)]| r3(1.0 - pairwise_error(keys, pairs, truth) / plain.max(1e-12));
    d["raw_flow_pairwise"] = json!(pair_red(&raw_pairs));
    let mids: Vec<&RgbaFrame> = truth.iter().skip(1).step_by(2).collect();
    d["raw_flow_chosen"] = json!(red(&ignis_media::write::motion::chosen_velocities(
        keys, &mids, &raw_pairs
    )));
    let mid_pairs = crate::inbetween::mid_pairs(keys, &mids).map_err(anyhow::Error::msg)?;
    d["mid_flow_chosen"] = json!(red(&ignis_media::write::motion::chosen_velocities(
        keys, &mids, &mid_pairs
    )));
    for (name, m) in known.velocities {
        d[name] = json!(red(&m));
    }
    for (name, p) in known.pairs {
        d[format!("{name}_pairwise")] = json!(pair_red(&p));
        d[format!("{name}_chosen")] = json!(red(&ignis_media::write::motion::chosen_velocities(
            keys, &mids, &p
        )));
    }
    Ok(d)
}

/// Held-out blends: key frames every 4th of `frames`, the three frames between each pair
/// rebuilt at t = 0.25, 0.5, 0.75 with the writer's default vectors and with looser gating
/// (so a change tuned at t = 0.5 on every other frame is checked on frames it never saw),
/// and with what the generator knows of its motion (`known`, at this key spacing): its
/// velocities, and its forward/backward pairs as `model_pairwise`.
fn held_out(frames: &[RgbaFrame], known: Known) -> Result<serde_json::Value> {
    let keys: Vec<RgbaFrame> = frames.iter().step_by(4).cloned().collect();
    let loose = ignis_flow::VectorParams {
        consistency_px: 8.0,
        explained: 0.05,
        ..Default::default()
    };
    // per key interval, the vectors of its earlier and of its later key frame
    let intervals = |mv: Vec<Field>| -> Vec<(Field, Field)> {
        mv.windows(2)
            .map(|w| (w[0].clone(), w[1].clone()))
            .collect()
    };
    // chosen on the t = 0.5 frames only: t = 0.25 and 0.75 are held out
    let mids: Vec<&RgbaFrame> = (0..keys.len() - 1).map(|k| &frames[4 * k + 2]).collect();
    let gated = gated_velocities(&keys)?;
    let mut sets: Vec<(String, Vec<(Field, Field)>)> = vec![
        ("gated_mip1".into(), intervals(mip1(&gated, keys[0].size()))),
        ("gated".into(), intervals(gated)),
        ("gated_loose".into(), intervals(gated_with(&keys, &loose)?)),
        (
            "raw_flow_chosen".into(),
            intervals(ignis_media::write::motion::chosen_velocities(
                &keys,
                &mids,
                &flow_pairs(&keys, 1)?,
            )),
        ),
        (
            "mid_flow_chosen".into(),
            intervals(ignis_media::write::motion::chosen_velocities(
                &keys,
                &mids,
                &crate::inbetween::mid_pairs(&keys, &mids).map_err(anyhow::Error::msg)?,
            )),
        ),
    ];
    sets.extend(
        known
            .velocities
            .into_iter()
            .map(|(n, v)| (n.to_string(), intervals(v))),
    );
    for (name, pairs) in known.pairs {
        let chosen = ignis_media::write::motion::chosen_velocities(&keys, &mids, &pairs);
        // the chosen sheet read at mip level 1: does switching between candidates survive?
        sets.push((
            format!("{name}_chosen_mip1"),
            intervals(mip1(&chosen, keys[0].size())),
        ));
        sets.push((format!("{name}_chosen"), intervals(chosen)));
        let reversed = |b: Field| b.into_iter().map(|v| [-v[0], -v[1]]).collect();
        let pairs = pairs.into_iter().map(|(f, b)| (f, reversed(b))).collect();
        sets.push((format!("{name}_pairwise"), pairs));
    }
    let mut out = serde_json::Map::new();
    for (name, mv) in &sets {
        let mut per_t = serde_json::Map::new();
        for (j, t) in [0.25f32, 0.5, 0.75].into_iter().enumerate() {
            let (mut e_mv, mut e_plain) = (0.0, 0.0);
            for (k, (prev, next)) in mv.iter().enumerate() {
                let truth = &frames[4 * k + j + 1];
                e_mv += error(&mv_blend(&keys[k], &keys[k + 1], prev, next, t), truth);
                e_plain += error(&linear_blend(&keys[k], &keys[k + 1], t), truth);
            }
            per_t.insert(format!("t{t}"), json!(r3(1.0 - e_mv / e_plain.max(1e-12))));
        }
        out.insert(name.to_string(), serde_json::Value::Object(per_t));
    }
    Ok(serde_json::Value::Object(out))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Warps of a flame whose placement moves `dx` px right per frame.
    fn sliding(n: usize, dx: f64) -> Vec<ignis_learned::Warp> {
        (0..n)
            .map(|i| ignis_learned::Warp {
                shape: ignis_learned::Shape {
                    path: vec![0.0; 10],
                    width: vec![0.5; 10],
                    height: 0.1,
                },
                place: ignis_learned::Placement {
                    cx: 40.0 + dx * i as f64,
                    cy: 30.0,
                    tilt: 0.0,
                },
                frame_height: 64.0,
            })
            .collect()
    }

    /// A key frame's model velocity spans one key interval (two frames here), whether taken
    /// from the neighbouring key frames or the in-between ones, ends included; the pairs
    /// hold the forward and backward motion of each interval.
    #[test]
    fn model_velocities_span_one_key_interval() {
        let p = ignis_learned::ShapeParams::default();
        let size = Size::new(64, 48).unwrap();
        let warps = sliding(7, 1.5);
        for reach in [2, 1] {
            let v = model_velocities(&p, &warps, size, (2, reach));
            assert_eq!(v.len(), 4);
            for f in &v {
                assert_eq!(f.len(), size.pixels());
                assert!(f
                    .iter()
                    .all(|m| (m[0] - 3.0).abs() < 1e-3 && m[1].abs() < 1e-3));
            }
        }
        let pairs = model_pairs(&p, &warps, size, 2);
        assert_eq!(pairs.len(), 3);
        for (f, b) in &pairs {
            assert!(f.iter().all(|m| (m[0] - 3.0).abs() < 1e-3));
            assert!(b.iter().all(|m| (m[0] + 3.0).abs() < 1e-3));
        }
    }

    /// Without footage the learned row trains the synthetic clip, whose rate is known, so
    /// it renders at twice the rate too.
    #[test]
    fn the_learned_row_exists_without_footage() {
        let g = Global { quiet: true };
        let (model, source) = learned_model(&g, true, None).unwrap();
        assert!(source.starts_with("synthetic"), "{source}");
        assert_eq!(model.summary.fps, Some(30.0));
        let (frames, warps) = learned(&model, 3, 2.0).unwrap();
        assert_eq!((frames.len(), warps.len()), (3, 3));
        assert!(frames.iter().all(|f| f.data().iter().any(|p| p[3] > 0.0)));
    }

    /// The learned row renders at twice the model's rate as `--fps` does: every other frame
    /// is the model-rate frame, and the frames between are new states, not copies.
    #[test]
    fn the_learned_row_doubles_the_rate_with_new_frames() {
        let model = ignis_learned::synthetic::small_model(2);
        let (twice, warps) = learned(&model, 5, 2.0).unwrap();
        let (once, _) = learned(&model, 3, 1.0).unwrap();
        assert_eq!(warps.len(), 5);
        for j in 0..3 {
            assert_eq!(twice[2 * j].data(), once[j].data(), "key frame {j}");
        }
        for j in 0..2 {
            assert_ne!(twice[2 * j + 1].data(), twice[2 * j].data());
            assert_ne!(twice[2 * j + 1].data(), twice[2 * j + 2].data());
        }
        // the key frames' warps differ: the flame moves
        assert_ne!(warps[0], warps[2]);
    }
}
