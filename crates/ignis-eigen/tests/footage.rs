//! Footage at its own quality (issue 14): automatic framing at the clips' own resolution
//! (a wide sheet of fire, a tall flame, clips of different sizes), no flame pixel lost by
//! the framing, no rotation of a sheet, output at the source size, and the candle mask
//! bounds on `candle.mp4` when the footage is present.

use ignis_core::{RgbaFrame, Size};
use ignis_eigen::mask::{static_fraction, value8, Isolate, STATIC_LIT};
use ignis_eigen::pose::ClipPose;
use ignis_eigen::preprocess::{frame_mask, preprocess_frame};
use ignis_eigen::render::{loop_plan, render_plan_with, RenderOptions, SyntheticSources};
use ignis_eigen::scenario::{ColourMode, Look};
use ignis_eigen::synthetic::{synthetic_frame, FlameStyle, SyntheticParams};
use ignis_eigen::train::{train, ClipInput, ClipSpec, NoProgress, TrainParams};
use ignis_eigen::transition::Transition;
use ignis_eigen::{EigenfireDb, PreprocessParams};
use ignis_eigen::{FrameList, SyntheticFootage};
use std::path::Path;

fn synth(style: FlameStyle, w: u32, h: u32, frames: usize) -> SyntheticParams {
    SyntheticParams {
        size: Size::new(w, h).unwrap(),
        frames,
        style,
        seed: 3,
    }
}

fn input(name: &str, p: SyntheticParams) -> ClipInput<'static> {
    ClipInput::new(ClipSpec::new(name), SyntheticFootage::new(p, 30.0))
}

/// Default settings (automatic frame and training size), rotation asked for, few pose
/// samples and a small training size so the test stays cheap.
fn pre() -> PreprocessParams {
    let mut p = PreprocessParams::default();
    p.pose.rotate = true;
    p.pose_samples = 4;
    p.train_pixels = 1200;
    p
}

fn grey_look() -> Look {
    Look {
        mode: ColourMode::Grey,
        tint: ignis_core::colour::Tint::Solid([1.0, 0.42, 0.08]),
        tint_from_footage: true,
        threshold: ignis_eigen::colour::THESIS_THRESHOLD,
        bloom: None,
        smoke: None,
        matte: true,
        fast_path: true,
        originals: Default::default(),
        masks: Default::default(),
        mask_mode: ignis_eigen::colour::MaskMode::Add,
    }
}

fn render(
    db: &EigenfireDb,
    clip: &str,
    range: std::ops::Range<usize>,
    size: Option<Size>,
) -> Vec<RgbaFrame> {
    let opts = RenderOptions {
        size,
        from_database: false,
        batch: None,
    };
    render_with(db, clip, range, &grey_look(), &opts)
}

/// A loop of `range` of `clip` rendered with `look` and `opts`.
fn render_with(
    db: &EigenfireDb,
    clip: &str,
    range: std::ops::Range<usize>,
    look: &Look,
    opts: &RenderOptions,
) -> Vec<RgbaFrame> {
    let (plan, _) = loop_plan(db, clip, range, Transition::Auto, 8, 0).unwrap();
    let mut out = Vec::new();
    render_plan_with(
        db,
        &plan,
        look,
        opts,
        &mut SyntheticSources,
        &mut |f| {
            out.push(f);
            Ok(())
        },
        &mut |_| {},
    )
    .unwrap();
    out
}

fn train_db(dir: &Path, clips: &[ClipInput<'_>]) -> EigenfireDb {
    let tp = TrainParams {
        pack_size: 8,
        ..Default::default()
    };
    let out = dir.join("fire.db");
    train(clips, &pre(), &tp, &out, &mut NoProgress).unwrap();
    EigenfireDb::open(&out).unwrap()
}

/// Every pixel of the source the mask keeps (the flame) is non-zero at the same place
/// in the pre-processed frame: the framing lost nothing and moved nothing.
fn assert_no_flame_pixel_lost(f: &RgbaFrame, pose: &ClipPose, p: &PreprocessParams) {
    let pr = preprocess_frame(f, pose, p);
    assert_eq!(pr.frame.size(), f.size());
    assert_eq!(pr.angle, 0.0, "a sheet of fire is never rotated");
    let m = frame_mask(f, p, pose.isolate).mask;
    let (w, h) = (f.width(), f.height());
    let lum = f.luminance();
    let mut flame = 0;
    for y in 0..h {
        for x in 0..w {
            if m.get_pixel(x, y)[0] > 0 {
                flame += 1;
                let g = pr.frame.get(x, y);
                assert!(g > 0.0, "flame pixel ({x}, {y}) lost");
                assert!(
                    (g - lum.get(x, y)).abs() < 1e-6,
                    "flame pixel ({x}, {y}) changed"
                );
            }
        }
    }
    assert!(flame > 100, "the mask found the flame ({flame} px)");
}

/// Original colouring with bloom, smoke and the matte: every per-frame layer the footage
/// path makes.
fn original_look() -> Look {
    Look {
        mode: ColourMode::Original,
        bloom: Some(ignis_core::post::BloomParams::default()),
        smoke: Some(ignis_eigen::colour::SmokeParams::default()),
        ..grey_look()
    }
}

fn render_batched(db: &EigenfireDb, clip: &str, batch: Option<usize>) -> Vec<RgbaFrame> {
    let opts = RenderOptions {
        size: None,
        from_database: false,
        batch,
    };
    render_with(db, clip, 1..11, &original_look(), &opts)
}

/// Training stores every frame's pre-processing mask; rendering reads it back instead of
/// making it again: it is the mask the pipeline makes for that source frame, exactly.
#[test]
fn stored_masks_are_the_pipeline_masks() {
    let t = tempfile::tempdir().unwrap();
    let p = synth(FlameStyle::Candle, 90, 160, 12);
    let db = train_db(t.path(), &[input("tall", p.clone())]);
    let c = db.clip("tall").unwrap();
    assert!(c.mask_file.is_some());
    assert!(db.verify().is_empty(), "{:?}", db.verify());
    let pre = &db.manifest().preprocess;
    for row in 0..db.n_frames() {
        let (_, f) = db.row_origin(row).unwrap();
        let frame = synthetic_frame(&p, f).unwrap();
        let want = frame_mask(&frame, pre, c.pose.isolate).mask;
        assert_eq!(db.source_mask(row).unwrap().unwrap(), want, "row {row}");
    }
    // A corrupt mask file is a database error naming it, not a panic or a wrong frame.
    let mf = t
        .path()
        .join("fire.db")
        .join(&c.mask_file.as_ref().unwrap().file);
    let mut b = std::fs::read(&mf).unwrap();
    let last = b.len() - 1;
    b[last] ^= 0x5a;
    std::fs::write(&mf, b).unwrap();
    let db = EigenfireDb::open(&t.path().join("fire.db")).unwrap();
    let e = db.source_mask(0).unwrap_err().to_string();
    assert!(
        e.contains("masks/tall.rle") && e.contains("checksum"),
        "{e}"
    );
}

/// Streaming in batches changes nothing: one frame at a time, small batches, the default
/// and the whole plan at once give the same bytes (a wide sheet: whole-pixel shifts; a
/// tall flame: pose rotation, resampled).
#[test]
fn batched_render_equals_unbatched_byte_for_byte() {
    for (name, p) in [
        ("sheet", synth(FlameStyle::Campfire, 160, 90, 12)),
        ("tall", synth(FlameStyle::Candle, 90, 160, 12)),
    ] {
        let t = tempfile::tempdir().unwrap();
        let db = train_db(t.path(), &[input(name, p)]);
        let whole = render_batched(&db, name, Some(1000));
        assert!(!whole.is_empty());
        for b in [Some(1), Some(3), None] {
            let got = render_batched(&db, name, b);
            assert_eq!(got.len(), whole.len());
            for (i, (a, w)) in got.iter().zip(&whole).enumerate() {
                let same = a.size() == w.size()
                    && a.data()
                        .iter()
                        .flatten()
                        .zip(w.data().iter().flatten())
                        .all(|(x, y)| x.to_bits() == y.to_bits());
                assert!(same, "{name}: frame {i} differs with batch {b:?}");
            }
        }
    }
}

#[test]
fn wide_sheet_and_tall_flame_at_their_own_size() {
    let t = tempfile::tempdir().unwrap();
    // A wide 640x360 sheet of fire (the campfire style's bed of tongues).
    let wide = synth(FlameStyle::Campfire, 640, 360, 12);
    let db = train_db(t.path(), &[input("sheet", wide.clone())]);
    let m = db.manifest();
    assert_eq!(m.frame_size, Size::new(640, 360).unwrap());
    assert!(
        m.train_size.width > m.train_size.height,
        "training keeps the aspect: {}",
        m.train_size
    );
    assert!(m.framing.contains("640x360"), "{}", m.framing);
    let c = db.clip("sheet").unwrap();
    assert_eq!(c.pose.scale, 1.0);
    for i in 0..db.n_frames() {
        assert_eq!(db.angle(i), 0.0, "the sheet is not rotated (row {i})");
    }
    let frames = render(&db, "sheet", 1..11, None);
    assert!(frames
        .iter()
        .all(|f| f.size() == Size::new(640, 360).unwrap()));
    let p = &m.preprocess;
    for tf in [0, 7] {
        assert_no_flame_pixel_lost(&synthetic_frame(&wide, tf).unwrap(), &c.pose, p);
    }
    // A database frame shows the source frame's grey where the flame is: the frame
    // pre-processed with its stored mask voted with its neighbours' (the render's matte).
    let (plan, _) = loop_plan(&db, "sheet", 1..11, Transition::Auto, 8, 0).unwrap();
    let (first, row) = match &plan.frames[0].source {
        ignis_eigen::transition::FrameRef::Db(r) => (db.row_origin(*r).unwrap().1, *r),
        other => panic!("the loop starts with a database frame, not {other:?}"),
    };
    let src = synthetic_frame(&wide, first).unwrap();
    let votes = ignis_eigen::animate::matte_vote_rows(&db, row)
        .map(|r| db.source_mask(r).unwrap().expect("stored mask"));
    let voted = ignis_eigen::mask::majority3(&votes[0], &votes[1], &votes[2]);
    let pr = ignis_eigen::preprocess::source_grey_with_mask(&src, &voted, &c.pose, p);
    let diff: f32 = pr
        .grey
        .data()
        .iter()
        .zip(frames[0].data())
        .map(|(a, b)| (a - b[0]).abs())
        .fold(0.0, f32::max);
    assert!(
        diff < 1e-4,
        "first loop frame is source frame {first} itself (max diff {diff})"
    );

    // A tall 180x320 flame.
    let t2 = tempfile::tempdir().unwrap();
    let tall = synth(FlameStyle::Candle, 180, 320, 12);
    let db = train_db(t2.path(), &[input("tall", tall.clone())]);
    assert_eq!(db.manifest().frame_size, Size::new(180, 320).unwrap());
    let frames = render(&db, "tall", 1..11, None);
    assert!(frames
        .iter()
        .all(|f| f.size() == Size::new(180, 320).unwrap()));
    let c = db.clip("tall").unwrap();
    let f = synthetic_frame(&tall, 4).unwrap();
    let pr = preprocess_frame(&f, &c.pose, &db.manifest().preprocess);
    assert_eq!(pr.frame.size(), Size::new(180, 320).unwrap());
}

#[test]
fn clips_of_different_sizes_render_at_their_own_size_or_a_common_one() {
    let t = tempfile::tempdir().unwrap();
    let wide = synth(FlameStyle::Campfire, 160, 90, 10);
    let tall = synth(FlameStyle::Candle, 60, 120, 10);
    let db = train_db(t.path(), &[input("wide", wide), input("tall", tall)]);
    // The common frame holds both at scale 1.
    assert_eq!(db.manifest().frame_size, Size::new(160, 120).unwrap());
    let w = render(&db, "wide", 1..9, None);
    assert!(w.iter().all(|f| f.size() == Size::new(160, 90).unwrap()));
    let tl = render(&db, "tall", 1..9, None);
    assert!(tl.iter().all(|f| f.size() == Size::new(60, 120).unwrap()));
    let common = Size::new(128, 96).unwrap();
    for clip in ["wide", "tall"] {
        let f = render(&db, clip, 1..9, Some(common));
        assert!(f.iter().all(|f| f.size() == common));
    }
    // Bad sizes are errors, not panics.
    let (plan, _) = loop_plan(&db, "wide", 1..9, Transition::Auto, 8, 0).unwrap();
    for bad in [
        Size {
            width: 0,
            height: 0,
        },
        Size {
            width: 100_000,
            height: 10,
        },
    ] {
        let e = render_plan_with(
            &db,
            &plan,
            &grey_look(),
            &RenderOptions {
                size: Some(bad),
                from_database: false,
                batch: None,
            },
            &mut SyntheticSources,
            &mut |_| Ok(()),
            &mut |_| {},
        )
        .unwrap_err()
        .to_string();
        assert!(e.contains("size"), "{e}");
    }
}

/// The candle mask bounds of issue 14 on `candle.mp4`: on each checked frame where the
/// flame's bright core (linear grey ≥ 0.8) exists, the default mask covers ≥ 95 % of the
/// core and its area is at most 3× the core dilated by 10 px; with `isolate_lit_islands`
/// the mask outside the dilated core (lit wax, not flame) stays small. Checks every 8th frame of
/// the whole clip (IGNIS_MASK_STRIDE / IGNIS_MASK_END change that; `IGNIS_MASK_STRIDE=1`
/// checks every frame, about a minute and a half on 2 cores).
#[test]
fn candle_mask_covers_the_flame_not_the_jar() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/candle.mp4");
    if !path.exists() || !ignis_media::ffmpeg_available() {
        eprintln!("skipped: ../shared/data/candle.mp4 or ffmpeg not present");
        return;
    }
    let env = |k: &str, d: usize| {
        std::env::var(k)
            .ok()
            .and_then(|v| v.parse().ok())
            .unwrap_or(d)
    };
    let (stride, end) = (env("IGNIS_MASK_STRIDE", 8).max(1), env("IGNIS_MASK_END", 0));
    let opts = ignis_media::ReadOptions {
        range: Some(ignis_media::FrameRange::frames(
            0,
            (end > 0).then_some(end as u64),
        )),
        ..Default::default()
    };
    let frames: Vec<RgbaFrame> = ignis_media::open(&path, &opts)
        .unwrap()
        .enumerate()
        .filter(|(i, _)| i % stride == 0)
        .map(|(_, f)| f.unwrap())
        .collect();
    let mut p = PreprocessParams::default();
    assert_eq!(p.mask.isolate, Isolate::Auto);
    if let Some(t) = std::env::var("IGNIS_MASK_TOL")
        .ok()
        .and_then(|v| v.parse().ok())
    {
        p.mask.isolate_edge_tolerance = t;
    }
    // The automatic decision, as training makes it (from a sample of the frames).
    let values: Vec<Vec<u8>> = frames.iter().map(value8).collect();
    let st = static_fraction(&values, p.mask.isolate_floor);
    assert!(
        st > STATIC_LIT,
        "candle.mp4 has lit surroundings (static fraction {st:.2})"
    );
    let d = candle_mask_stats(&frames, &p, stride);
    eprintln!("default: {checked} frames: worst area ratio {:.2} (goal <= 3), worst core cover {:.1}% (goal >= 95%); mask outside the dilated core: mean {:.2}, {} frames above 0.25", d.worst_ratio, d.worst_cover * 100.0, d.mean_away, d.far, checked = d.checked);
    assert!(d.checked > 0);
    assert!(
        d.worst_ratio <= 3.0,
        "mask area {:.2}x the dilated core",
        d.worst_ratio
    );
    assert!(
        d.worst_cover >= 0.95,
        "core covered {:.1}%",
        d.worst_cover * 100.0
    );
    // With `isolate_lit_islands` the wax glowing through the jar is dropped: the mask
    // outside the dilated core is at most a quarter of the dilated core on 9 frames in
    // 10 and 0.15 of it on average (with the default, about half the frames exceed a
    // quarter: the wax is kept). Not asserted: the core cover, which counts the wax as
    // flame on the frames where it glows at grey >= 0.8.
    p.mask.isolate_lit_islands = true;
    let l = candle_mask_stats(&frames, &p, stride);
    eprintln!("isolate_lit_islands: worst area ratio {:.2}, worst core cover {:.1}%; mask outside the dilated core: mean {:.2} (goal <= 0.15), worst {:.2}, {} of {} frames above 0.25 (goal <= 10%)", l.worst_ratio, l.worst_cover * 100.0, l.mean_away, l.worst_away, l.far, l.checked);
    assert!(
        l.mean_away <= 0.15 && l.far * 10 <= l.checked,
        "mask outside the dilated core: mean {:.2}, {} of {} frames above 0.25",
        l.mean_away,
        l.far,
        l.checked
    );
}

/// What [`candle_mask_covers_the_flame_not_the_jar`] measures over its frames.
struct MaskStats {
    checked: usize,
    worst_ratio: f64,
    worst_cover: f64,
    /// Mask pixels outside the dilated core over the dilated core's pixels.
    mean_away: f64,
    worst_away: f64,
    /// Frames where that exceeds 0.25.
    far: usize,
}

/// The issue-14 measures of the isolated mask on every frame where the bright core
/// (linear grey >= 0.8) exists, and the mask outside the core dilated by 10 px (lit
/// surroundings, not flame).
fn candle_mask_stats(frames: &[RgbaFrame], p: &PreprocessParams, stride: usize) -> MaskStats {
    let mut s = MaskStats {
        checked: 0,
        worst_ratio: 0.0,
        worst_cover: 1.0,
        mean_away: 0.0,
        worst_away: 0.0,
        far: 0,
    };
    for (i, f) in frames.iter().enumerate() {
        let lum = f.luminance();
        let core = image::GrayImage::from_fn(f.width(), f.height(), |x, y| {
            image::Luma([if lum.get(x, y) >= 0.8 { 255 } else { 0 }])
        });
        let core_px = core.pixels().filter(|p| p[0] > 0).count();
        if core_px == 0 {
            continue;
        }
        let dil = imageproc::morphology::dilate(&core, imageproc::distance_transform::Norm::L2, 10);
        let dil_px = dil.pixels().filter(|p| p[0] > 0).count();
        let m = frame_mask(f, p, true).mask;
        let area = m.pixels().filter(|p| p[0] > 0).count();
        let covered = core
            .pixels()
            .zip(m.pixels())
            .filter(|(c, m)| c[0] > 0 && m[0] > 0)
            .count();
        let outside = m
            .pixels()
            .zip(dil.pixels())
            .filter(|(m, d)| m[0] > 0 && d[0] == 0)
            .count();
        let ratio = area as f64 / dil_px as f64;
        let cover = covered as f64 / core_px as f64;
        let away = outside as f64 / dil_px as f64;
        eprintln!("frame {}: mask {area} px, core {core_px} px (dilated {dil_px}): ratio {ratio:.2}, core covered {:.1}%, outside the dilated core {away:.2}", i * stride, cover * 100.0);
        s.worst_ratio = s.worst_ratio.max(ratio);
        s.worst_cover = s.worst_cover.min(cover);
        s.worst_away = s.worst_away.max(away);
        s.mean_away += away;
        s.far += (away > 0.25) as usize;
        s.checked += 1;
    }
    s.mean_away /= s.checked.max(1) as f64;
    s
}

/// Issue 15 §2: a scenario joining `candle.mp4` to `campfire.mp4` with the
/// motion-compensated morph, measured on the written frames (metric frames of
/// `ignis_core::loopq`). Goal: worst step across the join ≤ 1.5× the footage's median
/// step and ghost ≥ 0.8. Where the goal is not reached the numbers are printed and the
/// morph must at least beat the hard cut (one step from the last candle frame to the first
/// campfire frame). Cheap: 40 frames of each clip at 96×96 (campfire's centre square).
#[test]
fn morph_join_between_two_clips_measured_on_the_written_frames() {
    use ignis_core::loopq::{ghost, median, metric_frame_rgba, sharpness, steps};
    use ignis_eigen::scenario::Scenario;
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    let (candle, campfire) = (data.join("candle.mp4"), data.join("campfire.mp4"));
    if !candle.exists() || !campfire.exists() || !ignis_media::ffmpeg_available() {
        eprintln!("skipped: ../shared/data/{{candle,campfire}}.mp4 or ffmpeg not present");
        return;
    }
    let side = Size::new(96, 96).unwrap();
    let read = |p: &Path, crop: Option<ignis_media::Rect>| -> Vec<RgbaFrame> {
        let opts = ignis_media::ReadOptions {
            range: Some(ignis_media::FrameRange::frames(0, Some(40))),
            crop,
            scale: Some(side),
        };
        ignis_media::open(p, &opts)
            .unwrap()
            .map(|f| f.unwrap())
            .collect()
    };
    let a = read(&candle, None);
    let b = read(
        &campfire,
        Some(ignis_media::Rect {
            x: 210,
            y: 0,
            width: 540,
            height: 540,
        }),
    );
    assert_eq!((a.len(), b.len()), (40, 40));
    let t = tempfile::tempdir().unwrap();
    let clips = [
        ClipInput::new(
            ClipSpec::new("candle"),
            FrameList::new("candle.mp4", &a, 30.0),
        ),
        ClipInput::new(
            ClipSpec::new("campfire"),
            FrameList::new("campfire.mp4", &b, 25.0),
        ),
    ];
    let p = PreprocessParams {
        pose_samples: 4,
        train_pixels: 1200,
        ..Default::default()
    };
    let tp = TrainParams {
        pack_size: 8,
        store_frames: true,
        ..Default::default()
    };
    let dbp = t.path().join("fire.db");
    train(&clips, &p, &tp, &dbp, &mut NoProgress).unwrap();
    let db = EigenfireDb::open(&dbp).unwrap();
    let motions = "database = \"fire.db\"\nsequence = [\"a\", \"b\"]\n\n[motions.a]\nclip = \"candle\"\nstart = 0\nend = 30\n\n[motions.b]\nclip = \"campfire\"\nstart = 10\nend = 40\n";
    let render = |method: &str| {
        let file = t.path().join("scene.toml");
        std::fs::write(
            &file,
            format!("{motions}\n[transition]\nmethod = {method}\n"),
        )
        .unwrap();
        let s = Scenario::from_file(&file).unwrap();
        let plan = s.plan(&db, &mut NoProgress).unwrap();
        let mut out = Vec::new();
        render_plan_with(
            &db,
            &plan,
            &grey_look(),
            &RenderOptions::default(),
            &mut SyntheticSources,
            &mut |f| {
                out.push(metric_frame_rgba(&f, [0.0; 3]));
                Ok(())
            },
            &mut |_| {},
        )
        .unwrap();
        // An automatic morph count is chosen again from the rendered frames.
        let fixed = plan.morphs.iter().all(|r| r.fixed);
        assert!(!fixed || out.len() == plan.frames.len());
        (plan, out)
    };
    // Worst step across a morph join over the footage's median step (steps inside the
    // two motions), the hard cut's step on the same scale, and the join ghost: each
    // in-between's sharpness over the straight line between its endpoints' sharpness
    // (the ghost compares a frame with its ±15 neighbours, which across two clips
    // of different sharpness measures the clips, not the join).
    let measure = |plan: &ignis_eigen::scenario::Plan, frames: &[ignis_core::GrayFrame]| {
        let run = &plan.morphs[0];
        // In-betweens written: the plan's count or the renderer's choice.
        let len = frames.len() + run.len - plan.frames.len();
        let (from, to) = (run.start - 1, run.start + len);
        let st = steps(frames, false).unwrap();
        let mut body: Vec<f64> = st[..from].iter().chain(&st[to..]).copied().collect();
        let med = median(&mut body);
        let worst = st[from..to].iter().copied().fold(0.0, f64::max) / med;
        let cut = ignis_core::loopq::rms_diff(&frames[from], &frames[to]) / med;
        let sharp: Vec<f64> = frames.iter().map(sharpness).collect();
        let join_ghost = (run.start..to)
            .map(|i| {
                let t = (i - from) as f64 / (to - from) as f64;
                sharp[i] / (sharp[from] + t * (sharp[to] - sharp[from]))
            })
            .fold(f64::INFINITY, f64::min);
        (worst, cut, ghost(&sharp), join_ghost, len)
    };
    let mut by_n = Vec::new();
    for n in [3usize, 5, 8] {
        let (plan, frames) = render(&format!("\"morph\"\nframes = {n}"));
        assert_eq!(plan.morphs[0].len, n);
        let (worst, _, _, jg, written) = measure(&plan, &frames);
        assert_eq!(written, n, "a count the scenario fixed is kept");
        eprintln!("morph frames = {n}: worst step {worst:.2}× median, join ghost {jg:.2}");
        by_n.push(worst);
    }
    assert!(
        by_n.windows(2).all(|w| w[1] < w[0]),
        "more in-betweens, smaller steps: {by_n:?}"
    );
    let (plan, frames) = render("\"morph\"");
    let j = &plan.joins[0].join;
    assert_eq!(j.method, "morph", "{}", j.why);
    assert_eq!(plan.morphs.len(), 1);
    let (worst, cut, (g, g_at), jg, n) = measure(&plan, &frames);
    // The same join as auto chooses it.
    let (auto_plan, auto_frames) = render("\"auto\"");
    let aj = &auto_plan.joins[0].join;
    eprintln!(
        "candle → campfire, automatic morph ({n} frames): worst step {worst:.2}× the footage's median step (hard cut {cut:.2}×), ghost {g:.2} at frame {g_at}, join ghost {jg:.2}\n  {}\n  auto: {} ({} frames): {}",
        j.why,
        aj.method,
        aj.frames.len(),
        aj.why
    );
    if aj.method == "morph" {
        let (aw, _, _, _, _) = measure(&auto_plan, &auto_frames);
        assert!(
            aw < cut,
            "auto's morph ({aw:.2}) beats the hard cut ({cut:.2})"
        );
    }
    if worst <= 1.5 && g >= 0.8 {
        eprintln!("transition goal reached");
    } else {
        eprintln!(
            "transition goal NOT reached (worst step {worst:.2} ≤ 1.5 and ghost {g:.2} ≥ 0.8 asked)"
        );
        assert!(
            worst < cut,
            "the morph ({worst:.2}) beats the hard cut ({cut:.2})"
        );
    }
}

/// A render's footage opener over one MP4; `linear` hides the 8-bit frames (the trait's
/// default `source_frames_at`), as any non-8-bit decoder would.
struct Mp4Sources {
    path: std::path::PathBuf,
    linear: bool,
}

/// [`ignis_eigen::MediaFootage`] with only the linear-frame methods.
struct LinearOnly(ignis_eigen::MediaFootage);

impl ignis_eigen::Footage for LinearOnly {
    fn info(&self) -> &ignis_eigen::FootageInfo {
        self.0.info()
    }
    fn frames(&self, start: usize) -> ignis_eigen::Result<ignis_eigen::footage::Frames<'_>> {
        self.0.frames(start)
    }
    fn frames_at(&self, indices: &[usize]) -> ignis_eigen::Result<Vec<Option<RgbaFrame>>> {
        self.0.frames_at(indices)
    }
}

impl ignis_eigen::FootageOpener for Mp4Sources {
    fn open(
        &mut self,
        _clip: &ignis_eigen::ClipEntry,
        _path: Option<&Path>,
    ) -> ignis_eigen::Result<Box<dyn ignis_eigen::Footage + '_>> {
        let m = ignis_eigen::MediaFootage::open(&self.path)?;
        Ok(if self.linear {
            Box::new(LinearOnly(m))
        } else {
            Box::new(m)
        })
    }
}

/// A 1080-wide MP4 clip rendered with original colouring, bloom and alpha (the 8-bit
/// path: frames kept as sRGB bytes, the feather's blur at half resolution) gives the
/// same bytes with 1 and 3 threads, and the same bytes as from the footage in linear
/// light.
#[test]
fn mp4_render_is_the_same_at_any_thread_count_and_from_linear_frames() {
    let t = tempfile::tempdir().unwrap();
    let path = t.path().join("fire.mp4");
    let p = synth(FlameStyle::Campfire, 1080, 608, 8);
    let mut w = ignis_media::create(&path, p.size, &Default::default()).unwrap();
    for i in 0..p.frames {
        w.push(&synthetic_frame(&p, i).unwrap()).unwrap();
    }
    w.finish().unwrap();
    let mut spec = ClipSpec::new("fire");
    spec.path = Some(path.clone());
    let clip = ClipInput::new(spec, ignis_eigen::MediaFootage::open(&path).unwrap());
    let db = train_db(t.path(), &[clip]);
    let (plan, _) = loop_plan(&db, "fire", 1..7, Transition::Auto, 8, 0).unwrap();
    let look = Look {
        smoke: None,
        ..original_look()
    };
    let run = |threads: usize, linear: bool| -> Vec<Vec<u32>> {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let mut out = Vec::new();
        let mut src = Mp4Sources {
            path: path.clone(),
            linear,
        };
        pool.install(|| {
            render_plan_with(
                &db,
                &plan,
                &look,
                &RenderOptions::default(),
                &mut src,
                &mut |f| {
                    assert_eq!(f.size(), p.size);
                    out.push(f.data().iter().flatten().map(|v| v.to_bits()).collect());
                    Ok(())
                },
                &mut |_| {},
            )
        })
        .unwrap();
        out
    };
    let one = run(1, false);
    assert!(!one.is_empty());
    assert!(one == run(3, false), "thread count changed the frames");
    assert!(one == run(2, true), "8-bit frames differ from linear ones");
}

/// A lamp in the shot (a steady warm-white box away from the fire, coloured enough that
/// the colourless-part rule keeps it: only the still-light rule tells it from fire) is found as a still light
/// over the clip and left out of every stored mask, while the fire stays in; with
/// `still_lights = false` the lamp is in the masks (what every clip got before).
#[test]
fn a_still_lamp_is_left_out_of_the_masks() {
    let sp = synth(FlameStyle::Campfire, 160, 120, 48);
    let (lx, ly, lw, lh) = (136u32, 6u32, 14u32, 10u32);
    let frames: Vec<RgbaFrame> = (0..sp.frames)
        .map(|t| {
            let mut f = synthetic_frame(&sp, t).unwrap();
            for y in ly..ly + lh {
                for x in lx..lx + lw {
                    f.data_mut()[(y * 160 + x) as usize] = [1.0, 0.7, 0.35, 1.0];
                }
            }
            f
        })
        .collect();
    let t = tempfile::tempdir().unwrap();
    let masks = |still: bool| {
        let mut p = PreprocessParams {
            train_pixels: 1200,
            ..Default::default()
        };
        p.mask.still_lights = still;
        let dbp = t.path().join(format!("fire-{still}.db"));
        let clips = [ClipInput::new(
            ClipSpec::new("c"),
            FrameList::new("lamp", &frames, 30.0),
        )];
        train(&clips, &p, &TrainParams::default(), &dbp, &mut NoProgress).unwrap();
        let db = EigenfireDb::open(&dbp).unwrap();
        let c = db.clip("c").unwrap();
        let ms: Vec<image::GrayImage> = (c.first_row..c.first_row + c.frames)
            .map(|r| db.source_mask(r).unwrap().expect("stored masks"))
            .collect();
        (c.pose, ms)
    };
    let lamp = |m: &image::GrayImage| {
        (ly..ly + lh)
            .flat_map(|y| (lx..lx + lw).map(move |x| (x, y)))
            .filter(|&(x, y)| m.get_pixel(x, y)[0] > 0)
            .count()
    };
    let fire = |m: &image::GrayImage| {
        m.enumerate_pixels()
            .filter(|(x, _, p)| *x < 120 && p[0] > 0)
            .count()
    };
    let (pose, with) = masks(true);
    let boxes = pose.still_lights.boxes().to_vec();
    assert_eq!(boxes.len(), 1, "one still light: {boxes:?}");
    let [x0, y0, x1, y1] = boxes[0];
    assert!(
        x0 <= lx && y0 <= ly && x1 >= lx + lw && y1 >= ly + lh,
        "{boxes:?}"
    );
    assert!(x0 >= 120, "the box stays off the fire: {boxes:?}");
    let (_, without) = masks(false);
    for (k, (a, b)) in with.iter().zip(&without).enumerate() {
        assert_eq!(lamp(a), 0, "frame {k}: the lamp is out of the mask");
        assert!(
            lamp(b) > 0,
            "frame {k}: without still lights the lamp is in"
        );
        assert!(fire(a) > 0, "frame {k}: the fire is kept");
        // The fire itself is masked alike with and without (within a few edge pixels).
        let (fa, fb) = (fire(a) as f64, fire(b) as f64);
        assert!((fa - fb).abs() <= 0.05 * fb, "frame {k}: fire {fa} vs {fb}");
    }
}

/// Still lights on real footage (when `../shared/data` and ffmpeg are present): none on
/// `candle.mp4`, `campfire.mp4` and `fireball.mp4` (their flames, cores, embers and lit
/// surroundings all flicker or lie beside what does), and on `campfire.mp4` with a white
/// box painted into a corner of every sample, exactly that box. Samples every 20th frame
/// (24 of them), at half size: what training's planning pass sees, more cheaply.
#[test]
fn still_lights_on_the_dev_clips() {
    use ignis_eigen::still::still_lights;
    let data = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    if !data.join("campfire.mp4").exists() || !ignis_media::ffmpeg_available() {
        eprintln!("skipped: ../shared/data clips or ffmpeg not present");
        return;
    }
    let samples = |name: &str, size: Size| -> Vec<RgbaFrame> {
        let opts = ignis_media::ReadOptions {
            range: None,
            crop: None,
            scale: Some(size),
        };
        ignis_media::open(&data.join(name), &opts)
            .unwrap()
            .step_by(20)
            .take(24)
            .map(|f| f.unwrap())
            .collect()
    };
    let floor = PreprocessParams::default().mask.isolate_floor;
    for (name, w, h) in [
        ("candle.mp4", 240, 240),
        ("campfire.mp4", 480, 270),
        ("fireball.mp4", 640, 360),
    ] {
        let frames = samples(name, Size::new(w, h).unwrap());
        assert!(frames.len() >= 20, "{name}: {} samples", frames.len());
        let values: Vec<Vec<u8>> = frames.iter().map(value8).collect();
        let s = still_lights(&values, w, h, floor);
        assert!(s.is_empty(), "{name}: no still lights, found {s:?}");
        if name == "campfire.mp4" {
            let mut lamp = values.clone();
            for v in &mut lamp {
                for y in 10..30 {
                    v[y * w as usize + 10..y * w as usize + 40].fill(250);
                }
            }
            let s = still_lights(&lamp, w, h, floor);
            assert_eq!(s.boxes().len(), 1, "{s:?}");
            let [x0, y0, x1, y1] = s.boxes()[0];
            assert!(
                x0 <= 10 && y0 <= 10 && x1 >= 40 && y1 >= 30 && x1 < 100 && y1 < 100,
                "{s:?}"
            );
        }
    }
}

/// The rows whose masks vote on a row's matte: its neighbours inside its own clip when the
/// clip holds consecutive source frames (the clip's ends vote with themselves, a vote
/// never reaches into the next clip); a clip trained with a stride has its own mask alone.
#[test]
fn matte_votes_stay_inside_consecutive_frames_of_one_clip() {
    use ignis_eigen::animate::matte_vote_rows;
    let t = tempfile::tempdir().unwrap();
    let mut strided = ClipSpec::new("b");
    strided.stride = 2;
    let clips = [
        input("a", synth(FlameStyle::Candle, 48, 64, 6)),
        ClipInput::new(
            strided,
            SyntheticFootage::new(synth(FlameStyle::Candle, 48, 64, 10), 30.0),
        ),
    ];
    let db = train_db(t.path(), &clips);
    let (a, b) = (db.clip("a").unwrap().clone(), db.clip("b").unwrap().clone());
    assert_eq!((a.frames, b.stride), (6, 2));
    let a0 = a.first_row;
    assert_eq!(matte_vote_rows(&db, a0), [a0, a0, a0 + 1]);
    assert_eq!(matte_vote_rows(&db, a0 + 3), [a0 + 2, a0 + 3, a0 + 4]);
    assert_eq!(matte_vote_rows(&db, a0 + 5), [a0 + 4, a0 + 5, a0 + 5]);
    for r in b.first_row..b.first_row + b.frames {
        assert_eq!(matte_vote_rows(&db, r), [r; 3], "strided row {r}");
    }
}

/// With a fixed common frame the clip is framed from its masks' extents: a lamp found as a
/// still light is measured out of them again (the planning pass rescans), so the clip is
/// placed and scaled as the same fire without the lamp; with the search off the lamp
/// widens the extents and the fire is framed differently.
#[test]
fn a_still_lamp_does_not_move_the_framing() {
    let sp = synth(FlameStyle::Campfire, 160, 120, 48);
    let clip = |lamp: bool| -> Vec<RgbaFrame> {
        (0..sp.frames)
            .map(|t| {
                let mut f = synthetic_frame(&sp, t).unwrap();
                if lamp {
                    for y in 6..16u32 {
                        for x in 136..150u32 {
                            f.data_mut()[(y * 160 + x) as usize] = [1.0, 0.7, 0.35, 1.0];
                        }
                    }
                }
                f
            })
            .collect()
    };
    let t = tempfile::tempdir().unwrap();
    let pose = |frames: &[RgbaFrame], still: bool, name: &str| {
        let mut p = PreprocessParams {
            train_pixels: 1200,
            ..Default::default()
        };
        p.pose.frame_size = Some(Size::new(80, 60).unwrap());
        p.mask.still_lights = still;
        let dbp = t.path().join(format!("{name}.db"));
        let clips = [ClipInput::new(
            ClipSpec::new("c"),
            FrameList::new(name, frames, 30.0),
        )];
        train(&clips, &p, &TrainParams::default(), &dbp, &mut NoProgress).unwrap();
        EigenfireDb::open(&dbp).unwrap().clip("c").unwrap().pose
    };
    let (with_lamp, plain) = (clip(true), clip(false));
    let clean = pose(&plain, true, "plain");
    let found = pose(&with_lamp, true, "lamp");
    let ignored = pose(&with_lamp, false, "lamp-kept");
    assert!(clean.still_lights.is_empty() && !found.still_lights.is_empty());
    let close = |a: f32, b: f32| (a - b).abs() <= 0.02 * b.abs().max(1.0);
    assert!(
        close(found.scale, clean.scale) && close(found.fuel_x, clean.fuel_x),
        "framed as the fire alone: {found:?} vs {clean:?}"
    );
    assert!(
        !close(ignored.scale, clean.scale) || !close(ignored.fuel_x, clean.fuel_x),
        "the lamp moves the framing when it is kept: {ignored:?} vs {clean:?}"
    );
}

/// Training measures each clip's own flame colour: an orange synthetic fire reads as
/// orange, the same fire with red and blue swapped (a blue gas flame) as blue.
#[test]
fn training_measures_the_flames_own_colour() {
    let sp = synth(FlameStyle::Candle, 96, 128, 24);
    let orange: Vec<RgbaFrame> = (0..sp.frames)
        .map(|t| synthetic_frame(&sp, t).unwrap())
        .collect();
    let blue: Vec<RgbaFrame> = orange
        .iter()
        .map(|f| {
            let mut b = f.clone();
            for p in b.data_mut() {
                p.swap(0, 2);
            }
            b
        })
        .collect();
    let t = tempfile::tempdir().unwrap();
    let clips = [
        ClipInput::new(ClipSpec::new("orange"), FrameList::new("o", &orange, 30.0)),
        ClipInput::new(ClipSpec::new("blue"), FrameList::new("b", &blue, 30.0)),
    ];
    let db = train_db(t.path(), &clips);
    let colour = |name: &str| db.clip(name).unwrap().flame_colour.unwrap();
    let (o, b) = (colour("orange"), colour("blue"));
    assert_eq!(
        o[0], 1.0,
        "orange flame: red is the brightest channel, {o:?}"
    );
    assert!(o[2] < 0.5 * o[0], "orange flame: little blue, {o:?}");
    assert_eq!(
        b[2], 1.0,
        "blue flame: blue is the brightest channel, {b:?}"
    );
    assert!(b[0] < 0.5 * b[2], "blue flame: little red, {b:?}");
    // The swap swaps the measured colour: the same pixels were measured.
    // The swap swaps the measured colour (the HSV mask, being hue-dependent, keeps
    // slightly different pixels of the blue flame).
    assert!(
        (o[0] - b[2]).abs() < 0.02 && (o[2] - b[0]).abs() < 0.02,
        "{o:?} {b:?}"
    );
}

/// Original colouring tints the bloom with the clip's flame colour unless the look sets
/// its own tint: the glow of an orange synthetic fire is orange by default and blue when
/// a scenario asks for a blue tint.
#[test]
fn the_bloom_takes_the_clips_flame_colour_unless_a_tint_is_set() {
    let t = tempfile::tempdir().unwrap();
    let db = train_db(
        t.path(),
        &[input("fire", synth(FlameStyle::Campfire, 128, 96, 16))],
    );
    assert!(db.clip("fire").unwrap().flame_colour.is_some());
    let opts = RenderOptions {
        size: None,
        from_database: false,
        batch: None,
    };
    let blue = ignis_core::colour::Tint::Solid([0.1, 0.3, 1.0]);
    let look = |from_footage: bool| Look {
        tint: blue.clone(),
        tint_from_footage: from_footage,
        smoke: None,
        ..original_look()
    };
    let footage = render_with(&db, "fire", 2..6, &look(true), &opts);
    let tinted = render_with(&db, "fire", 2..6, &look(false), &opts);
    let (mut differ, mut footage_red, mut tinted_blue) = (0, 0, 0);
    for (a, b) in footage.iter().zip(&tinted) {
        for (p, q) in a.data().iter().zip(b.data()) {
            if p != q {
                differ += 1;
                footage_red += usize::from(p[0] > p[2]);
                tinted_blue += usize::from(q[2] > q[0]);
            }
        }
    }
    assert!(
        differ > 500,
        "the tint reaches the glow ({differ} pixels differ)"
    );
    // Where the footage's own colour outweighs the glow, either render's pixel is the
    // footage's: allow 1 % such pixels.
    assert!(
        100 * footage_red >= 99 * differ,
        "the footage's glow is red: {footage_red} of {differ}"
    );
    assert!(
        100 * tinted_blue >= 99 * differ,
        "the set tint's glow is blue: {tinted_blue} of {differ}"
    );
}
