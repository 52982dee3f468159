//! Animation from an Eigenfire database: loops (§5.1) and synthesised flames (§5.2).
//!
//! Source: eigenfires-thesis.txt §5.1 (motion transition, "producing loop"), §5.2
//! (creating new flames by setting Eigenfire weights by hand) and §7.1.2 (rendering
//! database frames from the stored pre-processed frames instead of reconstructing them).
//!
//! This module joins [`crate::transition`] (which works on weight vectors only) to an
//! opened [`EigenfireDb`]: it builds the [`WeightSpace`] of a database, turns a clip range
//! plus a [`Join`] back to its start into a list of grey frames, and reconstructs frames
//! from edited weights.
//!
//! Conventions:
//! - Clip ranges are **source frame numbers** (as `--frame` of `reconstruct`), converted
//!   to training rows through the clip's start and stride.
//! - Distances (recognition and seam ratio) use the database's E for detection.
//! - Frames are linear grey values, not clamped (a palette clamps when colouring).

pub mod colour;
pub mod loops;
pub mod morph;
pub mod render;
pub mod scenario;

use rayon::prelude::*;
use std::collections::HashMap;
use std::ops::Range;

use ignis_core::GrayFrame;

use crate::db::EigenfireDb;
use crate::error::{EigenError, Result};
use crate::report::LoopReport;
use crate::transition::{
    self, ClipSpan, FrameRef, Join, LowPassParams, RecognitionParams, Transition, TransitionError,
    WeightSpace,
};

/// The clips of `db` as spans of training rows (what [`WeightSpace`] calls clips).
pub fn clip_spans(db: &EigenfireDb) -> Vec<ClipSpan> {
    db.clips()
        .iter()
        .map(|c| ClipSpan {
            name: c.name.clone(),
            start: c.first_row,
            len: c.frames,
        })
        .collect()
}

impl<'a> WeightSpace<'a> {
    /// The weight space of `db`: its M×k weights (borrowed from the map, no copy) and one
    /// span per clip. Fails on a database without frames or Eigenfires.
    pub fn from_db(db: &'a EigenfireDb) -> Result<WeightSpace<'a>> {
        let (m, k) = (db.n_frames(), db.n_components());
        if m == 0 || k == 0 {
            return Err(EigenError::Database {
                db: db.path().to_path_buf(),
                file: "manifest.json".into(),
                reason: format!(
                    "has {m} frames and {k} Eigenfires; a loop needs at least one of each"
                ),
            });
        }
        Ok(WeightSpace::new(db.weights_row_major(), k, clip_spans(db))?)
    }
}

/// Recognition settings for `db`: its E for detection, everything else default.
pub fn recognition_params(db: &EigenfireDb) -> RecognitionParams {
    RecognitionParams {
        e_detect: db.manifest().e_detect,
        ..Default::default()
    }
}

/// The database rows whose stored pre-processing masks vote on row `row`'s matte
/// ([`crate::mask::majority3`]): the row before, the row, the row after — when they are
/// consecutive source frames of the row's clip (trained with stride 1); at the clip's ends
/// the row itself stands in for the missing neighbour (its own mask wins the vote). A
/// clip trained with a stride, or a row outside every clip, has its own mask alone
/// (`[row; 3]`): frames a stride apart are not the same moment of the flame.
pub fn matte_vote_rows(db: &EigenfireDb, row: usize) -> [usize; 3] {
    match db.row_origin(row) {
        Some((c, _)) if c.stride == 1 && c.frames > 0 => {
            let last = c.first_row + c.frames - 1;
            [
                row.saturating_sub(1).max(c.first_row),
                row,
                (row + 1).min(last),
            ]
        }
        _ => [row; 3],
    }
}

/// The matte masks of database rows `rows` as the footage render uses them: each row's
/// stored pre-processing mask voted with its neighbours' ([`matte_vote_rows`],
/// [`crate::mask::majority3`]), so a mask that collapses or flares on a single frame does
/// not flash — the matte the footage render and `ignis loop` write. Each stored mask is decoded once; rows whose
/// database stores no mask are absent (the caller makes one from the footage).
pub fn voted_masks(db: &EigenfireDb, rows: &[usize]) -> Result<HashMap<usize, image::GrayImage>> {
    let votes: Vec<(usize, [usize; 3])> =
        rows.iter().map(|&r| (r, matte_vote_rows(db, r))).collect();
    let mut need: Vec<usize> = votes.iter().flat_map(|v| v.1).collect();
    need.sort_unstable();
    need.dedup();
    let decoded: Vec<Result<Option<image::GrayImage>>> =
        need.par_iter().map(|&r| db.source_mask(r)).collect();
    let mut masks = HashMap::with_capacity(need.len());
    for (&r, m) in need.iter().zip(decoded) {
        if let Some(m) = m? {
            masks.insert(r, m);
        }
    }
    Ok(votes
        .into_par_iter()
        .filter_map(|(r, [a, b, c])| {
            let own = masks.get(&b)?;
            let get = |j: usize| masks.get(&j).unwrap_or(own);
            Some((r, crate::mask::majority3(get(a), own, get(c))))
        })
        .collect())
}

/// Of database rows `rows`, those whose matte ([`voted_masks`]) keys out every pixel:
/// frames the footage render writes fully transparent. Rows whose database stores no mask
/// are not reported. Decoded in runs of 32 rows (consecutive rows share their votes'
/// masks), so the memory stays bounded for long scenarios.
pub fn keyed_out_rows(db: &EigenfireDb, rows: &[usize]) -> Result<Vec<usize>> {
    let mut out = Vec::new();
    for run in rows.chunks(32) {
        let masks = voted_masks(db, run)?;
        out.extend(run.iter().copied().filter(|r| {
            masks
                .get(r)
                .is_some_and(|m| m.as_raw().iter().all(|&v| v == 0))
        }));
    }
    Ok(out)
}

/// Training rows of clip `clip` whose source frame lies in `range` (source frame numbers).
pub fn clip_rows(db: &EigenfireDb, clip: &str, range: Range<usize>) -> Result<Range<usize>> {
    let c = db.clip(clip)?;
    let last = c.start + c.frames.saturating_sub(1) * c.stride;
    if range.start >= range.end {
        return Err(EigenError::bad(
            "range",
            format!("{}..{} is empty", range.start, range.end),
        ));
    }
    if range.start < c.start || range.start > last {
        return Err(EigenError::bad(
            "range",
            format!(
                "{}..{} starts outside clip `{clip}`, whose training frames are {}..={last}",
                range.start, range.end, c.start
            ),
        ));
    }
    let first = (range.start - c.start).div_ceil(c.stride);
    let end = (range.end - c.start).div_ceil(c.stride).min(c.frames);
    if end <= first {
        return Err(EigenError::bad(
            "range",
            format!(
                "{}..{} holds no training frame of clip `{clip}` (every {} from {})",
                range.start, range.end, c.stride, c.start
            ),
        ));
    }
    Ok(c.first_row + first..c.first_row + end)
}

/// Seam ratio of a plain cut from the end of `rows` back to its start (no transition
/// frames): what [`Join::seam_ratio`] is to be compared with.
pub fn plain_cut_ratio(db: &EigenfireDb, rows: Range<usize>) -> Result<f64> {
    let space = WeightSpace::from_db(db)?;
    space.check_range("range", &rows)?;
    let rec = recognition_params(db);
    let e = rec.e_detect(&space);
    Ok(transition::join_seam(&space, &rows, &rows, &[], (0, 0), e))
}

/// Parses a method name: `auto`, `end-growing`, `direct` (direct bridging) or `low-pass`.
pub fn parse_method(s: &str) -> Result<Transition> {
    Ok(match s {
        "auto" => Transition::Auto,
        "end-growing" => Transition::EndGrowing { max_steps: 40 },
        "direct" | "direct-bridging" => Transition::DirectBridging { steps: None },
        "low-pass" => Transition::LowPass(LowPassParams::default()),
        other => {
            return Err(EigenError::bad(
                "method",
                format!("unknown method `{other}`; choose auto, end-growing, direct or low-pass"),
            ))
        }
    })
}

/// Whether every clip of `db` has its pre-processed frames stored (§7.1.2 fast path).
pub(crate) fn has_stored_frames(db: &EigenfireDb) -> bool {
    !db.clips().is_empty() && db.clips().iter().all(|c| c.frames_file.is_some())
}

/// Finds a loop of clip `clip` over source frames `range`: the rows (moved inwards by up
/// to `search` training frames each end, see [`best_loop`]), the join back to the start
/// with `method`, a plain cut's seam ratio for comparison and `e_render` clamped to the
/// usable Eigenfires. What [`render_loop`] and [`crate::render::loop_plan`] render.
pub fn find_loop(
    db: &EigenfireDb,
    clip: &str,
    range: Range<usize>,
    method: &Transition,
    e_render: usize,
    search: usize,
) -> Result<LoopReport> {
    let requested = clip_rows(db, clip, range.clone())?;
    let space = WeightSpace::from_db(db)?;
    let rec = recognition_params(db);
    let (rows, join) = best_loop(&space, requested.clone(), search, method, &rec)?;
    let e = rec.e_detect(&space);
    let plain_cut = transition::join_seam(&space, &requested, &requested, &[], (0, 0), e);
    let c = db.clip(clip)?;
    let used = c.start + (rows.start - c.first_row) * c.stride
        ..c.start + (rows.end - c.first_row) * c.stride;
    // Body: the range without the frames the transition replaces. A low-pass join over a
    // range shorter than its kernel may replace everything.
    let body = loop_body(&rows, &join);
    if body.is_empty() && join.frames.is_empty() {
        return Err(EigenError::bad(
            "range",
            "the loop has no frames left (the transition replaced the whole range); use a longer range",
        ));
    }
    Ok(LoopReport {
        clip: clip.to_string(),
        requested: range,
        used,
        search,
        body_frames: body.len(),
        rows,
        join,
        plain_cut,
        e_render: e_render.clamp(1, db.usable_components().max(1)),
        e_render_requested: e_render,
    })
}

/// The rows of a loop over `rows` that `join` keeps: without its [`Join::trim_t2`] first
/// and [`Join::trim_t1`] last frames.
pub fn loop_body(rows: &Range<usize>, join: &Join) -> Range<usize> {
    let start = rows.start + join.trim_t2;
    start..rows.end.saturating_sub(join.trim_t1).max(start)
}

/// Renders a loop of clip `clip` over source frames `range` (see [`find_loop`]): the
/// range's frames without those the transition replaces, followed by the transition back
/// to the start, so that playing the result repeatedly loops. Synthetic frames are
/// reconstructed with the report's E. Database frames are the stored pre-processed frames
/// when the database has them (§7.1.2; every frame is then at the pre-processed size,
/// reconstructions being resized to it), else reconstructions at the training size.
pub fn render_loop(
    db: &EigenfireDb,
    clip: &str,
    range: Range<usize>,
    method: Transition,
    e_render: usize,
    search: usize,
) -> Result<(Vec<GrayFrame>, LoopReport)> {
    let report = find_loop(db, clip, range, &method, e_render, search)?;
    let e = report.e_render;
    let stored = has_stored_frames(db);
    let size = if stored {
        db.manifest().frame_size
    } else {
        db.train_size()
    };
    let render_weights = |wv: &[f32]| -> Result<GrayFrame> {
        let f = db.reconstruct(wv, e)?;
        Ok(crate::pose::resize(&f, size))
    };
    let render_row = |r: usize| -> Result<GrayFrame> {
        if stored {
            if let Some((c, frame)) = db.row_origin(r) {
                return db.preprocessed_frame(&c.name, frame);
            }
        }
        render_weights(&db.frame_weights(r))
    };
    let mut out = Vec::with_capacity(report.frames());
    for r in loop_body(&report.rows, &report.join) {
        out.push(render_row(r)?);
    }
    for f in &report.join.frames {
        out.push(match f {
            FrameRef::Db(r) => render_row(*r)?,
            FrameRef::Weights(wv) => render_weights(wv)?,
        });
    }
    Ok((out, report))
}

/// How many candidate loop points [`best_loop`] joins with the full method.
const LOOP_CANDIDATES: usize = 6;

/// A loop over `rows` whose first and last frames may each move inwards by up to
/// `search` frames (0 = exactly `rows`), choosing the loop points like video textures do:
/// footage is not equally calm everywhere (on `candle.mp4` about a fifth of consecutive
/// steps exceed 1.5× the median), and the seam ratio counts the footage on both sides of
/// the seam. Every (start, end) pair is ranked by the plain cut's seam ratio (cheap: no
/// transition), the best [`LOOP_CANDIDATES`] are joined with `method`, and the join with
/// the smallest seam ratio wins (ties: the least trimmed). Deterministic.
pub fn best_loop(
    space: &WeightSpace,
    rows: Range<usize>,
    search: usize,
    method: &Transition,
    rec: &RecognitionParams,
) -> std::result::Result<(Range<usize>, Join), TransitionError> {
    if search == 0 {
        return Ok((
            rows.clone(),
            transition::make_loop(space, rows, method, rec)?,
        ));
    }
    space.check_range("range", &rows)?;
    // Keep at least half of the range (and never less than 2 frames).
    let search = search.min(rows.len().saturating_sub(2) / 4);
    let e = rec.e_detect(space);
    let mut cands: Vec<(f64, usize, Range<usize>)> = Vec::new();
    for a in 0..=search {
        for b in 0..=search {
            let r = rows.start + a..rows.end - b;
            let cost = transition::join_seam(space, &r, &r, &[], (0, 0), e);
            cands.push((cost, a + b, r));
        }
    }
    cands.sort_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)));
    let mut best: Option<(Range<usize>, Join, usize)> = None;
    let mut last_err = None;
    for (_, trimmed, r) in cands.into_iter().take(LOOP_CANDIDATES) {
        match transition::make_loop(space, r.clone(), method, rec) {
            Ok(j) => {
                let better = best.as_ref().is_none_or(|(_, bj, bt)| {
                    j.seam_ratio < bj.seam_ratio || (j.seam_ratio == bj.seam_ratio && trimmed < *bt)
                });
                if better {
                    best = Some((r, j, trimmed));
                }
            }
            Err(e) => last_err = Some(e),
        }
    }
    match best {
        Some((r, j, _)) => Ok((r, j)),
        None => Err(last_err.expect("at least one candidate was tried")),
    }
}

/// Parses weight edits `2=12000,3=-5000` (Eigenfire index = weight; spaces allowed).
/// Fails naming the first malformed item.
pub fn parse_weight_edits(s: &str) -> Result<Vec<(usize, f32)>> {
    let mut out = Vec::new();
    for item in s.split(',').map(str::trim).filter(|i| !i.is_empty()) {
        let bad = |why: &str| {
            EigenError::bad(
                "weights",
                format!("`{item}`: {why} (expected INDEX=VALUE, e.g. 2=12000)"),
            )
        };
        let (i, v) = item.split_once('=').ok_or_else(|| bad("no `=`"))?;
        let i: usize = i
            .trim()
            .parse()
            .map_err(|_| bad("the Eigenfire index is not a whole number ≥ 0"))?;
        let v: f32 = v
            .trim()
            .parse()
            .map_err(|_| bad("the weight is not a number"))?;
        if !v.is_finite() {
            return Err(bad("the weight is not finite"));
        }
        out.push((i, v));
    }
    if out.is_empty() {
        return Err(EigenError::bad(
            "weights",
            format!("`{s}` holds no INDEX=VALUE item"),
        ));
    }
    Ok(out)
}

/// Synthesises a flame (§5.2): starts from the mean (all weights zero) or from the weights
/// of clip `from.0`'s source frame `from.1`, sets the weights in `edits` (Eigenfire index,
/// 0-based, = value) and reconstructs with the first `max(e, largest edited index + 1)`
/// Eigenfires. An index at or above the database's (usable) Eigenfire count is an error.
pub fn synth(
    db: &EigenfireDb,
    from: Option<(&str, usize)>,
    edits: &[(usize, f32)],
    e: usize,
) -> Result<GrayFrame> {
    let k = db.n_components();
    let usable = db.usable_components();
    let mut w = match from {
        None => vec![0.0f32; k],
        Some((clip, frame)) => db.frame_weights(db.frame_index(clip, frame)?),
    };
    let mut e = e;
    for &(i, v) in edits {
        if i >= usable {
            return Err(EigenError::bad(
                "weights",
                format!(
                    "Eigenfire index {i} is out of range: the database has {usable} usable Eigenfires (0..{usable}){}",
                    if usable < k { format!(" of {k} stored") } else { String::new() }
                ),
            ));
        }
        if !v.is_finite() {
            return Err(EigenError::bad(
                "weights",
                format!("weight of Eigenfire {i} is not finite"),
            ));
        }
        w[i] = v;
        e = e.max(i + 1);
    }
    db.reconstruct(&w, e.min(usable))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::train::{synthetic_clips, train, NoProgress, TrainParams};
    use crate::PreprocessParams;
    use ignis_core::Size;

    fn tiny_db(dir: &std::path::Path, store_frames: bool) -> EigenfireDb {
        let clips = synthetic_clips(Size::new(48, 64).unwrap(), 30, 7);
        let mut pre = PreprocessParams::with_sizes(
            Size::new(40, 64).unwrap(),
            Some(Size::new(20, 32).unwrap()),
        );
        pre.pose_samples = 6;
        let tp = TrainParams {
            pack_size: 8,
            store_frames,
            ..Default::default()
        };
        let out = dir.join("fire.db");
        train(&clips, &pre, &tp, &out, &mut NoProgress).unwrap();
        EigenfireDb::open(&out).unwrap()
    }

    #[test]
    fn loop_length_and_seam() {
        let dir = tempfile::tempdir().unwrap();
        let db = tiny_db(dir.path(), true);
        let range = 2..26;
        let rows = clip_rows(&db, "candle", range.clone()).unwrap();
        assert_eq!(rows.len(), 24);
        let plain = plain_cut_ratio(&db, rows.clone()).unwrap();
        for method in ["auto", "direct", "low-pass", "end-growing"] {
            let m = parse_method(method).unwrap();
            let (frames, join) = match render_loop(&db, "candle", range.clone(), m, 10, 0) {
                Ok((f, r)) => (f, r.join),
                // End Growing may legitimately find no path on a tiny database.
                Err(e) if method == "end-growing" => {
                    assert!(e.to_string().contains("no transition"), "{e}");
                    continue;
                }
                Err(e) => panic!("{method}: {e}"),
            };
            assert_eq!(
                frames.len(),
                rows.len() - join.trim_t1 - join.trim_t2 + join.frames.len(),
                "{method}"
            );
            assert!(
                join.seam_ratio.is_finite() && join.seam_ratio >= 0.0,
                "{method}"
            );
            // Stored frames: everything at the pre-processed size.
            assert!(frames.iter().all(|f| f.size() == db.manifest().frame_size));
            if method == "auto" {
                assert!(
                    join.seam_ratio <= plain + 1e-9,
                    "auto {} > plain cut {plain}: {}",
                    join.seam_ratio,
                    join.why
                );
            }
        }
        // Without stored frames: reconstructions at the training size.
        let dir2 = tempfile::tempdir().unwrap();
        let db2 = tiny_db(dir2.path(), false);
        let (frames, report) =
            render_loop(&db2, "campfire", 0..20, Transition::Auto, 5, 0).unwrap();
        let (join, used) = (report.join, report.used);
        assert_eq!(used, 0..20);
        assert_eq!(
            frames.len(),
            20 - join.trim_t1 - join.trim_t2 + join.frames.len()
        );
        assert!(frames.iter().all(|f| f.size() == db2.train_size()));
        // Bad ranges and clips.
        for (clip, r) in [("candle", 5..5), ("candle", 40..50), ("nope", 0..10)] {
            assert!(render_loop(&db, clip, r, Transition::Auto, 5, 0).is_err());
        }
        assert!(parse_method("sideways").is_err());
    }

    #[test]
    fn synth_mean_and_edits() {
        let dir = tempfile::tempdir().unwrap();
        let db = tiny_db(dir.path(), false);
        let mean = db.mean();
        let s = synth(&db, None, &[], 10).unwrap();
        assert_eq!(s.data(), mean.data());
        // An edit on component 0 moves the image along Eigenfire 0 only.
        let u0 = db.eigenfire_vec(0).unwrap().into_owned();
        let u1 = db.eigenfire_vec(1).unwrap().into_owned();
        let s = synth(&db, None, &[(0, 2.5)], 1).unwrap();
        let d: Vec<f32> = s
            .data()
            .iter()
            .zip(mean.data())
            .map(|(a, b)| a - b)
            .collect();
        let dot = |a: &[f32], b: &[f32]| {
            a.iter()
                .zip(b)
                .map(|(x, y)| *x as f64 * *y as f64)
                .sum::<f64>()
        };
        let p0 = dot(&d, &u0) / dot(&u0, &u0);
        let p1 = dot(&d, &u1) / dot(&u1, &u1);
        assert!((p0 - 2.5).abs() < 1e-3, "projection on Eigenfire 0: {p0}");
        assert!(p1.abs() < 1e-3, "projection on Eigenfire 1: {p1}");
        // From a database frame with no edits = its reconstruction.
        let row = db.frame_index("candle", 3).unwrap();
        let s = synth(&db, Some(("candle", 3)), &[], 6).unwrap();
        assert_eq!(
            s.data(),
            db.reconstruct(&db.frame_weights(row), 6).unwrap().data()
        );
        // Bad index and bad source frame.
        let k = db.n_components();
        let e = synth(&db, None, &[(k, 1.0)], 5).unwrap_err().to_string();
        assert!(e.contains(&format!("index {k}")), "{e}");
        assert!(synth(&db, Some(("candle", 999)), &[], 5).is_err());
    }

    #[test]
    fn parse_edits() {
        assert_eq!(
            parse_weight_edits("2=12000, 3=-5000").unwrap(),
            vec![(2, 12000.0), (3, -5000.0)]
        );
        for (s, bad) in [
            ("2=abc", "2=abc"),
            ("x=1", "x=1"),
            ("1=2,3", "`3`"),
            ("-1=4", "-1=4"),
            ("1=inf", "1=inf"),
        ] {
            let e = parse_weight_edits(s).unwrap_err().to_string();
            assert!(e.contains(bad), "{s}: {e}");
        }
        assert!(parse_weight_edits(" , ").is_err());
    }
}
