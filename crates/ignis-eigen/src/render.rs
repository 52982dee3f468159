//! Rendering a scenario's [`Plan`]: grey frames (§7.1.2 fast path or reconstruction with
//! weight edits), bloom (§6.2), colouring (original — Algorithm 2 with smoke §6.3 and
//! custom masks §6.4 —, synthetic §6.1.2, palette, grey) and the alpha matte.
//!
//! Source: eigenfires-thesis.txt chapter 6 and §7.1.2. The per-pixel rules live in
//! [`crate::colour`] and `ignis_core::post`; this module fetches the layers (original
//! footage warped onto the pre-processed frames, smoke, masks) and runs the pipeline.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use ignis_core::colour::synthetic_colour;
use ignis_core::post::{alpha_matte, bloom};
use ignis_core::{GrayFrame, RgbaFrame, Size};
use rayon::prelude::*;

use crate::animate::has_stored_frames;
use crate::colour::{original_colouring, synthetic_smoke, warp_rgba, OriginalColour};
use crate::db::{ClipEntry, EigenfireDb};
use crate::error::{EigenError, Result};
use crate::scenario::{ColourMode, Look, Plan, PlanFrame};
use crate::synthetic::{parse_source_name, synthetic_frame, SyntheticParams};
use crate::transition::FrameRef;

/// Reads source frames for original colouring (§6.1.1), synthetic smoke (§6.3) and custom
/// masks (§6.4). The CLI implements it over `ignis-media`; [`SyntheticSources`] covers the
/// clips Ignis draws itself.
pub trait SourceFrames {
    /// Source frames `frames` (ascending, distinct source frame numbers) of `path`, or of
    /// the clip's recorded source when `path` is `None`, at their own size. An entry is
    /// `None` when the source has no such frame (e.g. a mask sequence that stops early).
    fn read(
        &mut self,
        clip: &ClipEntry,
        path: Option<&Path>,
        frames: &[usize],
    ) -> Result<Vec<Option<RgbaFrame>>>;
}

/// [`SourceFrames`] for clips whose source is `synthetic:<style>:seed=<n>` (the clips of
/// [`crate::train::synthetic_clips`]): frames are drawn again, identical to training.
/// Any other source is an error naming the clip.
#[derive(Clone, Copy, Debug, Default)]
pub struct SyntheticSources;

impl SyntheticSources {
    /// The synthetic clip parameters of `clip`, if its source is synthetic.
    pub fn params(clip: &ClipEntry) -> Option<SyntheticParams> {
        let (style, seed) = parse_source_name(&clip.source)?;
        Some(SyntheticParams {
            size: clip.source_size,
            frames: clip.end,
            style,
            seed,
        })
    }
}

impl SourceFrames for SyntheticSources {
    fn read(
        &mut self,
        clip: &ClipEntry,
        path: Option<&Path>,
        frames: &[usize],
    ) -> Result<Vec<Option<RgbaFrame>>> {
        let p = match (path, Self::params(clip)) {
            (None, Some(p)) => p,
            _ => {
                return Err(EigenError::clip(
                    &clip.name,
                    format!(
                        "cannot read {} here (only Ignis's synthetic clips can be redrawn without a media reader)",
                        path.map_or(clip.source.clone(), |p| p.display().to_string())
                    ),
                ))
            }
        };
        frames
            .iter()
            .map(|&t| {
                if t < p.frames {
                    Ok(Some(synthetic_frame(&p, t)?))
                } else {
                    Ok(None)
                }
            })
            .collect()
    }
}

/// Resizes every channel of `src` to `size` (area average when shrinking, as
/// [`crate::pose::resize`]); returns `src` itself when it already has that size.
pub fn resize_rgba(src: RgbaFrame, size: Size) -> RgbaFrame {
    if src.size() == size {
        return src;
    }
    let chans: Vec<GrayFrame> = (0..4)
        .map(|c| {
            let g = GrayFrame::from_vec(src.size(), src.data().iter().map(|p| p[c]).collect())
                .expect("same size");
            crate::pose::resize(&g, size)
        })
        .collect();
    let data = (0..size.pixels())
        .map(|i| [0, 1, 2, 3].map(|c| chans[c].data()[i]))
        .collect();
    RgbaFrame::from_vec(size, data).expect("same size")
}

/// Size of the frames [`render_plan`] writes: the pre-processed frame size when every
/// clip has its stored frames (§7.1.2), else the training size.
pub fn output_size(db: &EigenfireDb) -> Size {
    if has_stored_frames(db) {
        db.manifest().frame_size
    } else {
        db.train_size()
    }
}

/// The database row whose original footage colours `f`: the row itself, or for synthetic
/// weights (low-pass morphs) the nearest row on the first `e` weights.
fn colour_row(db: &EigenfireDb, f: &PlanFrame, e: usize) -> usize {
    match &f.source {
        FrameRef::Db(r) => *r,
        FrameRef::Weights(w) => {
            let wm = db.weights();
            let e = e.min(w.len()).min(wm.ncols());
            (0..wm.nrows())
                .map(|i| {
                    let d: f64 = (0..e).map(|c| ((wm[(i, c)] - w[c]) as f64).powi(2)).sum();
                    (d, i)
                })
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .map_or(0, |x| x.1)
        }
    }
}

/// Colour layers per database row, warped onto the pre-processed frames.
#[derive(Default)]
struct Layers {
    original: HashMap<usize, RgbaFrame>,
    smoke: HashMap<usize, RgbaFrame>,
    mask: HashMap<usize, GrayFrame>,
}

/// Loads the originals, smoke images and custom masks the plan needs, one clip at a time.
fn load_layers(
    db: &EigenfireDb,
    rows: &[usize],
    look: &Look,
    size: Size,
    sources: &mut dyn SourceFrames,
) -> Result<Layers> {
    let mut layers = Layers::default();
    let want_original = matches!(look.mode, ColourMode::Original);
    let pose_p = &db.manifest().preprocess.pose;
    let mut uniq: Vec<usize> = rows.to_vec();
    uniq.sort_unstable();
    uniq.dedup();
    for clip in db.clips() {
        let mine: Vec<(usize, usize)> = uniq
            .iter()
            .filter_map(|&r| match db.row_origin(r) {
                Some((c, f)) if c.name == clip.name => Some((r, f)),
                _ => None,
            })
            .collect();
        if mine.is_empty() {
            continue;
        }
        let warp = |f: &RgbaFrame, r: usize| {
            resize_rgba(warp_rgba(f, &clip.pose, db.angle(r), pose_p), size)
        };
        if want_original {
            // The frame, and for smoke its next frame (the previous at the clip's end).
            let neighbour = |f: usize| {
                if f + 1 < clip.end {
                    f + 1
                } else {
                    f.saturating_sub(1)
                }
            };
            let mut need: Vec<usize> = mine.iter().map(|m| m.1).collect();
            if look.smoke.is_some() {
                need.extend(mine.iter().map(|m| neighbour(m.1)));
            }
            need.sort_unstable();
            need.dedup();
            let path = look.originals.get(&clip.name).map(PathBuf::as_path);
            let got = sources.read(clip, path, &need)?;
            let by_frame: HashMap<usize, RgbaFrame> = need
                .iter()
                .zip(got)
                .filter_map(|(&f, g)| g.map(|g| (f, g)))
                .collect();
            let shown = || path.map_or(clip.source.clone(), |p| p.display().to_string());
            for &(r, f) in &mine {
                let cur = by_frame.get(&f).ok_or_else(|| {
                    EigenError::clip(
                        &clip.name,
                        format!("original colouring needs frame {f} of {}, which it does not have; give the clip's footage under [originals]", shown()),
                    )
                })?;
                let cur_w = warp(cur, r);
                if let Some(sp) = &look.smoke {
                    let nf = neighbour(f);
                    if let Some(next) = by_frame.get(&nf) {
                        let s = synthetic_smoke(&cur_w, &warp(next, r), sp)?;
                        layers.smoke.insert(r, s);
                    }
                }
                layers.original.insert(r, cur_w);
            }
        }
        if let Some(mp) = look.masks.get(&clip.name) {
            let need: Vec<usize> = mine.iter().map(|m| m.1).collect();
            let got = sources.read(clip, Some(mp), &need)?;
            for (&(r, _), g) in mine.iter().zip(got) {
                if let Some(g) = g {
                    layers.mask.insert(r, warp(&g, r).luminance());
                }
            }
        }
    }
    Ok(layers)
}

/// Renders `plan` with `look`: grey frame (the stored pre-processed frame for an unedited
/// database frame when `look.fast_path`, §7.1.2; else a reconstruction with
/// `plan.e_render` Eigenfires and the frame's weight edits), bloom (§6.2), colouring
/// (original, Algorithm 2 with smoke and custom masks; synthetic; palette; grey) and the
/// alpha matte. Frames go to `sink` in order; `progress(done)` counts them. Frames are
/// rendered in parallel batches; the result does not depend on the thread count.
pub fn render_plan(
    db: &EigenfireDb,
    plan: &Plan,
    look: &Look,
    sources: &mut dyn SourceFrames,
    sink: &mut dyn FnMut(RgbaFrame) -> Result<()>,
    progress: &mut dyn FnMut(usize),
) -> Result<()> {
    let size = output_size(db);
    let stored = has_stored_frames(db);
    let needs_rows = matches!(look.mode, ColourMode::Original) || !look.masks.is_empty();
    let rows: Vec<usize> = if needs_rows {
        plan.frames
            .iter()
            .map(|f| colour_row(db, f, plan.e_detect))
            .collect()
    } else {
        Vec::new()
    };
    let layers = if needs_rows {
        load_layers(db, &rows, look, size, sources)?
    } else {
        Layers::default()
    };
    let k = db.n_components();
    // §7.1.2: an unedited database frame is the stored pre-processed frame.
    let stored_frame = |f: &PlanFrame| -> Option<(String, usize)> {
        match (&f.source, f.edits.is_empty() && look.fast_path && stored) {
            (FrameRef::Db(r), true) => db.row_origin(*r).map(|(c, fr)| (c.name.clone(), fr)),
            _ => None,
        }
    };
    // The weights to reconstruct a frame from: its own (or the morph's), edits applied.
    let weights_of = |f: &PlanFrame| -> Vec<f32> {
        let mut w = match &f.source {
            FrameRef::Db(r) => db.frame_weights(*r),
            FrameRef::Weights(w) => w.clone(),
        };
        w.resize(k, 0.0);
        for &(i, v, s) in &f.edits {
            if i < w.len() {
                w[i] += s * (v - w[i]);
            }
        }
        w
    };
    // Grey frames of a batch: stored frames read directly, the rest reconstructed in one
    // matrix product (`reconstruct_batch`).
    let greys_of = |range: std::ops::Range<usize>| -> Result<Vec<GrayFrame>> {
        let frames = &plan.frames[range];
        let fast: Vec<Option<(String, usize)>> = frames.iter().map(stored_frame).collect();
        let ws: Vec<Vec<f32>> = frames
            .iter()
            .zip(&fast)
            .filter(|(_, s)| s.is_none())
            .map(|(f, _)| weights_of(f))
            .collect();
        let refs: Vec<&[f32]> = ws.iter().map(Vec::as_slice).collect();
        let mut recon = if refs.is_empty() {
            Vec::new()
        } else {
            db.reconstruct_batch(&refs, plan.e_render)?
        }
        .into_iter();
        fast.into_iter()
            .map(|s| match s {
                Some((clip, frame)) => db.preprocessed_frame(&clip, frame),
                None => Ok(crate::pose::resize(
                    &recon.next().expect("one reconstruction per slow frame"),
                    size,
                )),
            })
            .collect()
    };
    let render_one = |i: usize, grey: GrayFrame| -> Result<RgbaFrame> {
        let bloomed = match &look.bloom {
            Some(b) => Some(bloom(&grey, b)?),
            None => None,
        };
        let lit = bloomed.as_ref().unwrap_or(&grey);
        let mut out = match &look.mode {
            ColourMode::Grey => lit.to_rgba(),
            ColourMode::Palette(p) => p.apply(lit),
            ColourMode::Synthetic => synthetic_colour(lit, &look.tint)?,
            ColourMode::Original => {
                let r = rows[i];
                let dest = match &bloomed {
                    Some(b) => Some(synthetic_colour(b, &look.tint)?),
                    None => None,
                };
                let smoke = layers.smoke.get(&r);
                let params = OriginalColour {
                    threshold: look.threshold,
                    smoke: smoke.is_some(),
                };
                original_colouring(
                    &grey,
                    &layers.original[&r],
                    dest.as_ref(),
                    smoke,
                    layers.mask.get(&r).map(|m| (m, look.mask_mode)),
                    &params,
                )?
            }
        };
        if look.matte {
            let a = alpha_matte(&grey, lit)?;
            for (px, &av) in out.data_mut().iter_mut().zip(a.data()) {
                px[3] = av;
            }
        } else {
            out.data_mut().iter_mut().for_each(|px| px[3] = 1.0);
        }
        Ok(out)
    };
    const BATCH: usize = 16;
    let mut done = 0;
    for start in (0..plan.frames.len()).step_by(BATCH) {
        let end = (start + BATCH).min(plan.frames.len());
        let greys = greys_of(start..end)?;
        let batch: Vec<Result<RgbaFrame>> = greys
            .into_par_iter()
            .enumerate()
            .map(|(j, g)| render_one(start + j, g))
            .collect();
        for f in batch {
            sink(f?)?;
            done += 1;
            progress(done);
        }
    }
    Ok(())
}
