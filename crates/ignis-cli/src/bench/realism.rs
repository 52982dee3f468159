//! `ignis bench realism`: does each generator's fire look like fire? Issue 16 §2's two
//! measures ([`ignis_core::realism`]) on every volume preset, the classic fire and a learned
//! flame trained from `candle.mp4`, against the puffing law `1.5/√D` (±25 %) and the spectral
//! slope measured, with the same code, on the real footage of that kind (±0.3).

use crate::global::Global;
use anyhow::{Context, Result};
use ignis_core::realism::{self, display_luma, median_slope, puffing_frequency};
use ignis_core::{GrayFrame, RgbaFrame, Size};
use ignis_volume::{FireScene, Preset};
use serde_json::{json, Value};
use std::path::Path;

/// Seconds of animation the flicker is measured over, and the frame rate of the renders.
const SECONDS: f64 = 10.0;
const FPS: f64 = 60.0;
/// Width the flicker series is measured at (region sums do not need more).
const FLICKER_WIDTH: u32 = 128;
/// Frames, spread over the render, whose spectral slopes are averaged (median).
const SLOPE_FRAMES: usize = 8;
/// Flicker tolerance (fraction of the law) and slope tolerance (absolute).
const FLICKER_TOL: f64 = 0.25;
const SLOPE_TOL: f64 = 0.3;

/// The footage each kind of fire is compared with.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    Candle,
    Campfire,
}

impl Kind {
    fn clip(self) -> &'static str {
        match self {
            Kind::Candle => "candle.mp4",
            Kind::Campfire => "campfire.mp4",
        }
    }
}

/// Flicker and median slope of a clip, reading at most `max_frames` frames.
fn measure_footage(path: &Path, max_frames: Option<u64>) -> Result<(realism::Flicker, f64, f64)> {
    let reader = ignis_media::open(
        path,
        &ignis_media::ReadOptions {
            range: max_frames.map(|m| ignis_media::FrameRange::frames(0, Some(m))),
            ..Default::default()
        },
    )
    .with_context(|| format!("reading {}", path.display()))?;
    let fps = reader.info().fps;
    let total = match (reader.info().frame_count, max_frames) {
        (Some(n), Some(m)) => n.min(m),
        (Some(n), None) => n,
        (None, m) => m.unwrap_or(300),
    };
    let every = (total as usize / SLOPE_FRAMES).max(1);
    let mut series = Vec::new();
    let mut sharp = Vec::new();
    for (i, f) in reader.enumerate() {
        let f = f.with_context(|| format!("decoding {}", path.display()))?;
        let luma = display_luma(&f, [0.0; 3]);
        if i % every == every / 2 && sharp.len() < SLOPE_FRAMES {
            sharp.push(luma.clone());
        }
        series.push(realism::reduce(luma, FLICKER_WIDTH));
    }
    let flicker = realism::flicker(&series, fps)?;
    let slope = median_slope(&sharp)?;
    Ok((flicker, slope, fps))
}

/// Measures a generator: `frame(i, small)` renders frame `i` of an animation at `fps`,
/// small (for the flicker series) or full size (for the slopes).
fn measure(
    frames: usize,
    fps: f64,
    mut frame: impl FnMut(usize, bool) -> Result<RgbaFrame>,
) -> Result<(realism::Flicker, f64)> {
    let mut series = Vec::with_capacity(frames);
    for i in 0..frames {
        series.push(realism::reduce(
            display_luma(&frame(i, true)?, [0.0; 3]),
            FLICKER_WIDTH,
        ));
    }
    let flicker = realism::flicker(&series, fps)?;
    let sharp: Vec<GrayFrame> = (0..SLOPE_FRAMES)
        .map(|k| {
            frame((2 * k + 1) * frames / (2 * SLOPE_FRAMES), false)
                .map(|f| display_luma(&f, [0.0; 3]))
        })
        .collect::<Result<_>>()?;
    Ok((flicker, median_slope(&sharp)?))
}

fn row(
    name: &str,
    diameter: f64,
    flicker: &realism::Flicker,
    slope: f64,
    reference: Option<(Kind, f64)>,
) -> Value {
    let law = puffing_frequency(diameter);
    let flicker_ok = (flicker.hz - law).abs() <= FLICKER_TOL * law;
    let mut v = json!({
        "name": name,
        "diameter_m": diameter,
        "flicker_hz": round(flicker.hz, 2),
        "flicker_law_hz": round(law, 2),
        "flicker_ratio": round(flicker.hz / law, 3),
        "flicker_peak": round(flicker.peak_ratio, 1),
        "flicker_pass": flicker_ok,
        "slope": round(slope, 3),
    });
    if let Some((kind, r)) = reference {
        v["slope_footage"] = kind.clip().into();
        v["slope_reference"] = round(r, 3).into();
        v["slope_diff"] = round(slope - r, 3).into();
        v["slope_pass"] = ((slope - r).abs() <= SLOPE_TOL).into();
        v["pass"] = (flicker_ok && (slope - r).abs() <= SLOPE_TOL).into();
    }
    v
}

fn round(x: f64, digits: i32) -> f64 {
    let p = 10f64.powi(digits);
    (x * p).round() / p
}

pub fn bench(g: &Global, quick: bool) -> Result<Value> {
    let frames = if quick { 120 } else { (SECONDS * FPS) as usize };
    let max_footage = quick.then_some(120);
    // references from the footage, with the same measurement
    let mut refs: Vec<(Kind, f64)> = Vec::new();
    let mut footage = Vec::new();
    for kind in [Kind::Candle, Kind::Campfire] {
        match crate::demo::shared_data(kind.clip()) {
            Some(p) => {
                let sp = g.spinner(&format!("measuring {}", kind.clip()));
                let (f, slope, fps) = measure_footage(&p, max_footage)?;
                sp.finish_and_clear();
                g.say(format!(
                    "  {}: flicker {:.2} Hz (peak {:.1}), slope {slope:.2}",
                    kind.clip(),
                    f.hz,
                    f.peak_ratio
                ));
                refs.push((kind, slope));
                footage.push(json!({
                    "clip": kind.clip(),
                    "fps": fps,
                    "flicker_hz": round(f.hz, 2),
                    "flicker_peak": round(f.peak_ratio, 1),
                    "slope": round(slope, 3),
                }));
            }
            None => {
                footage.push(json!({"clip": kind.clip(), "skipped": "not found in ../shared/data"}))
            }
        }
    }
    let reference = |k: Kind| refs.iter().find(|r| r.0 == k).copied();
    let mut rows = Vec::new();
    let (small, big) = if quick { (64, 256) } else { (96, 512) };
    for preset in Preset::ALL {
        let kind = match preset {
            Preset::Torch | Preset::Candle => Kind::Candle,
            Preset::Campfire | Preset::Wall => Kind::Campfire,
        };
        let mut scene = FireScene::preset(preset);
        scene.fps = FPS as f32;
        let diameter = f64::from(scene.diameter);
        let lo = scene.clone().with_size(Size::new(small, small)?);
        let hi = scene.with_size(Size::new(big, big)?);
        let mut a_lo = lo.animator()?;
        let bar = g.progress(frames as u64, &format!("volume {}", preset.name()));
        let (f, slope) = measure(frames, FPS, |i, small| {
            if small {
                bar.inc(1);
                Ok(a_lo.next_frame()?.image)
            } else {
                let mut a = hi.animator()?;
                a.skip(i as u64);
                Ok(a.next_frame()?.image)
            }
        })?;
        bar.finish_and_clear();
        let r = row(
            &format!("volume {}", preset.name()),
            diameter,
            &f,
            slope,
            reference(kind),
        );
        g.say(format!("  {r}"));
        rows.push(r);
    }
    // the classic fire (its preset, classic palette), played at the bench's frame rate
    {
        let params = ignis_classic::ClassicParams {
            seed: 1,
            fps: FPS as f32,
            ..ignis_classic::ClassicParams::preset()
        };
        let diameter = f64::from(params.diameter);
        let mut fire = ignis_classic::ClassicFire::new(params)?;
        let palette = ignis_core::Palette::preset("classic")?;
        // the CLI's default warm-up, so the flames have reached their height
        for _ in 0..60 {
            fire.step();
        }
        // the slopes' frames are taken from the same run: keep every frame's image small
        // enough (320x200) to hold the whole run
        let mut images = Vec::with_capacity(frames);
        for _ in 0..frames {
            fire.step();
            images.push(fire.gray());
        }
        let (f, slope) = measure(frames, FPS, |i, _| Ok(palette.apply(&images[i])))?;
        let r = row("classic", diameter, &f, slope, reference(Kind::Campfire));
        g.say(format!("  {r}"));
        rows.push(r);
    }
    match crate::demo::shared_data("candle.mp4") {
        Some(p) => {
            let r = learned_row(g, &p, quick, reference(Kind::Candle))?;
            g.say(format!("  {r}"));
            rows.push(r);
        }
        None => rows.push(
            json!({"name": "learned candle", "skipped": "candle.mp4 not found in ../shared/data"}),
        ),
    }
    let all = rows.iter().all(|r| r["pass"].as_bool().unwrap_or(false));
    Ok(json!({
        "bench": "realism",
        "quick": quick,
        "seconds": frames as f64 / FPS,
        "fps": FPS,
        "footage": footage,
        "generators": rows,
        "goal": "flicker within ±25% of 1.5/√D Hz; spectral slope within ±0.3 of the footage's",
        "goal_met": all,
    }))
}

/// A candle flame's diameter, metres (the learned flame from `candle.mp4`).
pub const CANDLE_DIAMETER: f64 = 0.02;

/// A learned flame trained from `candle.mp4` as the demo trains it (the flame cropped out of
/// its glass, the wax glow below a black level), synthesised at [`FPS`] like every row (the
/// process steps at the footage's rate, resampled in time for the output) and at the scale
/// `ignis learned synth` chooses by default ([`ignis_learned::fit_scale`]).
fn learned_row(
    g: &Global,
    clip: &Path,
    quick: bool,
    reference: Option<(Kind, f64)>,
) -> Result<Value> {
    let model = candle_model(g, clip, quick)?;
    let fps = FPS;
    let frames = (SECONDS * fps) as usize;
    let frames = if quick { frames.min(120) } else { frames };
    let palette = ignis_core::Palette::preset("candle")?;
    let size = Size::new(256, 256)?;
    // framed as `ignis learned synth` frames it by default (its tall states inside)
    let mut controls = ignis_learned::Controls::default();
    controls.scale = ignis_learned::fit_scale(&model, &controls, size)?;
    let mut synth = ignis_learned::Synthesiser::new_at(&model, controls, 1, Some(fps))?;
    let mut images = Vec::with_capacity(frames);
    for _ in 0..frames {
        let mut f = GrayFrame::new(size);
        synth.next_frame_into(&mut f);
        images.push(f);
    }
    let (f, slope) = measure(frames, fps, |i, _| Ok(palette.apply(&images[i])))?;
    Ok(row("learned candle", CANDLE_DIAMETER, &f, slope, reference))
}

/// The learned candle of [`learned_row`] (also `bench export`'s learned row): `candle.mp4`
/// trained as the demo trains it (the flame cropped out of its glass, the wax glow below
/// a black level); `quick` trains fewer particles and iterations.
pub(super) fn candle_model(
    g: &Global,
    clip: &Path,
    quick: bool,
) -> Result<ignis_learned::FlameModel> {
    let dir = tempfile::tempdir().context("creating a temporary directory")?;
    let model_path = dir.path().join("candle.flame");
    let clip_s = clip.to_string_lossy().into_owned();
    let model_s = model_path.to_string_lossy().into_owned();
    let mut argv = vec![
        "train",
        &clip_s,
        "-o",
        &model_s,
        "--range",
        "0..300",
        "--crop",
        "190,200,100,130",
        "--black-level",
        "0.7",
        "--keep-multiple",
    ];
    if quick {
        argv.extend(["--particles", "50", "--max-iterations", "5"]);
    }
    let a = crate::parse_sub::<crate::learned::TrainArgs>(&argv)?;
    let sp = g.spinner("training a learned flame on candle.mp4");
    let model = crate::learned::train(&a, &Global { quiet: true })?;
    sp.finish_and_clear();
    Ok(model)
}
