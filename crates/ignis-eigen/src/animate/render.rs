//! Rendering a scenario's [`Plan`]: grey frames (§7.1.2 fast path or reconstruction with
//! weight edits), bloom (§6.2), colouring (original — Algorithm 2 with smoke §6.3 and
//! custom masks §6.4 —, synthetic §6.1.2, palette, grey) and the alpha matte.
//!
//! Source: eigenfires-thesis.txt chapter 6 and §7.1.2. The per-pixel rules live in
//! [`crate::colour`] and `ignis_core::post`; this module fetches the layers (original
//! footage warped onto the pre-processed frames, smoke, masks) and runs the pipeline.

use std::borrow::Cow;
use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::Arc;

use ignis_core::colour::{synthetic_colour, Tint};
use ignis_core::post::bloom;
use ignis_core::{GrayFrame, RgbaFrame, Size};
use rayon::prelude::*;

use crate::animate::has_stored_frames;
use crate::colour::{
    original_colouring_matted, original_colouring_src_then, synthetic_smoke, warp_rgba, AlphaMatte,
    Destination, MaskMode, OriginalColour,
};
use crate::db::{ClipEntry, EigenfireDb};
use crate::error::{EigenError, Result};
use crate::scenario::{ColourMode, Look, Plan, PlanFrame};
use crate::transition::FrameRef;

use crate::footage::SourceFrame;
/// Where rendering reads footage: [`crate::footage::SyntheticSources`] for Ignis's own
/// clips, the CLI's opener over `ignis-media` for real footage.
pub use crate::footage::{FootageOpener, SyntheticSources};

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

/// Largest output side [`check_output_size`] accepts.
pub const MAX_OUTPUT_SIDE: u32 = 8192;
/// Largest output frame [`check_output_size`] accepts (pixels).
pub const MAX_OUTPUT_PIXELS: usize = 8192 * 4608;

/// Checks a requested output size (`--size`): both sides at least 1 (and even sides are
/// up to the writer) and within [`MAX_OUTPUT_SIDE`] / [`MAX_OUTPUT_PIXELS`].
pub fn check_output_size(s: Size) -> Result<()> {
    if s.width == 0 || s.height == 0 {
        return Err(EigenError::bad(
            "size",
            format!("{s} has a zero side; give WIDTHxHEIGHT with both at least 1 (e.g. 1280x720), or leave --size out for the source size"),
        ));
    }
    if s.width > MAX_OUTPUT_SIDE || s.height > MAX_OUTPUT_SIDE || s.pixels() > MAX_OUTPUT_PIXELS {
        return Err(EigenError::bad(
            "size",
            format!("{s} is beyond the limits (each side at most {MAX_OUTPUT_SIDE}, at most {MAX_OUTPUT_PIXELS} pixels in all); give a smaller --size"),
        ));
    }
    Ok(())
}

/// Options of [`render_plan_with`].
#[derive(Clone, Debug, Default)]
pub struct RenderOptions {
    /// Output size; `None` = [`output_view`]'s size (the source clip's own size).
    pub size: Option<Size>,
    /// Never read source footage for the grey frames: database frames are the stored
    /// pre-processed frames or reconstructions (`--from-database`). Original colouring
    /// still reads the footage; choose another colouring with it.
    pub from_database: bool,
    /// Frames rendered together (their footage frames and layers are what is held in
    /// memory); `None` = [`default_batch`]. The output does not depend on it.
    pub batch: Option<usize>,
}

/// Frames per batch by default: three per worker thread (enough to keep every thread
/// busy), 4 to 16.
pub fn default_batch() -> usize {
    (3 * rayon::current_num_threads()).clamp(4, 16)
}

/// A rectangle of the common frame, in frame pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct View {
    pub x: u32,
    pub y: u32,
    pub w: u32,
    pub h: u32,
}

/// The clips a plan shows (those of its database frames; every clip when it has none).
fn plan_clips<'a>(db: &'a EigenfireDb, plan: &Plan) -> Vec<&'a ClipEntry> {
    let mut names: Vec<&ClipEntry> = Vec::new();
    for f in &plan.frames {
        if let FrameRef::Db(r) = &f.source {
            if let Some((c, _)) = db.row_origin(*r) {
                if !names.iter().any(|n| n.name == c.name) {
                    names.push(c);
                }
            }
        }
    }
    if names.is_empty() {
        names = db.clips().iter().collect();
    }
    names
}

/// The part of the common frame `clip` occupies.
pub fn clip_view(db: &EigenfireDb, clip: &ClipEntry) -> View {
    let mut pp = db.manifest().preprocess.pose.clone();
    pp.frame_size = Some(db.manifest().frame_size);
    let (x, y, w, h) = crate::pose::clip_rect(clip.source_size, &clip.pose, &pp);
    View { x, y, w, h }
}

/// What [`render_plan_with`] shows and its default size: when every clip of the plan
/// occupies the same part of the common frame at scale 1 (automatic framing), that part
/// at the clip's own source size (a single-clip database: the source frame exactly);
/// else the whole common frame.
pub fn output_view(db: &EigenfireDb, plan: &Plan) -> (View, Size) {
    let clips = plan_clips(db, plan);
    let f = db.manifest().frame_size;
    let full = View {
        x: 0,
        y: 0,
        w: f.width,
        h: f.height,
    };
    let Some(first) = clips.first() else {
        return (full, f);
    };
    // A fixed common frame (the thesis's 410x670) scales its clips: its frames are the
    // pre-processed frames themselves (§7.1.2), shown whole.
    if clips.iter().any(|c| c.pose.scale != 1.0) {
        return (full, f);
    }
    let v = clip_view(db, first);
    if clips
        .iter()
        .all(|c| clip_view(db, c) == v && c.source_size == first.source_size)
    {
        (v, first.source_size)
    } else {
        (full, f)
    }
}

/// Size of the frames [`render_plan`] writes by default (see [`output_view`]).
pub fn output_size(db: &EigenfireDb, plan: &Plan) -> Size {
    output_view(db, plan).1
}

/// `src` (a frame-space image at any resolution: the common frame or the training size)
/// cut to `view` and brought to `out`: an exact crop, then an area resize when `src` is at
/// the frame's resolution; bilinear sampling otherwise (reconstructions).
fn view_gray(src: &GrayFrame, frame: Size, view: View, out: Size) -> GrayFrame {
    if src.size() == frame {
        let w = frame.width as usize;
        let crop = if view.x == 0 && view.y == 0 && view.w == frame.width && view.h == frame.height
        {
            src.clone()
        } else {
            let d = src.data();
            GrayFrame::from_fn(
                Size {
                    width: view.w,
                    height: view.h,
                },
                |u, v| d[(view.y + v) as usize * w + (view.x + u) as usize],
            )
        };
        return crate::pose::resize(&crop, out);
    }
    let kx = src.width() as f32 / frame.width as f32;
    let ky = src.height() as f32 / frame.height as f32;
    let (sx, sy) = (
        view.w as f32 / out.width as f32,
        view.h as f32 / out.height as f32,
    );
    GrayFrame::from_fn(out, |u, v| {
        let x = (view.x as f32 + (u as f32 + 0.5) * sx) * kx - 0.5;
        let y = (view.y as f32 + (v as f32 + 0.5) * sy) * ky - 0.5;
        crate::pose::bilinear(
            src,
            x.clamp(0.0, src.width() as f32 - 1.0),
            y.clamp(0.0, src.height() as f32 - 1.0),
        )
    })
}

/// [`view_gray`] for colour frames at the frame's resolution.
fn view_rgba(src: RgbaFrame, frame: Size, view: View, out: Size) -> RgbaFrame {
    let src = if view.x == 0 && view.y == 0 && view.w == frame.width && view.h == frame.height {
        src
    } else {
        let w = frame.width as usize;
        let d = src.data();
        let data = (0..view.h as usize)
            .flat_map(|v| {
                let row = (view.y as usize + v) * w + view.x as usize;
                d[row..row + view.w as usize].iter().copied()
            })
            .collect();
        RgbaFrame::from_vec(
            Size {
                width: view.w,
                height: view.h,
            },
            data,
        )
        .expect("view inside the frame")
    };
    resize_rgba(src, out)
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

/// Layers per database row, in the output view.
#[derive(Default)]
struct Layers {
    /// Shared with the decoded frame when the warp is the identity (no copy; 8-bit
    /// footage stays 8-bit).
    original: HashMap<usize, Arc<SourceFrame>>,
    smoke: HashMap<usize, RgbaFrame>,
    mask: HashMap<usize, GrayFrame>,
    /// The pre-processed frame made from the source footage (§7.1.2) and its matte.
    grey: HashMap<usize, (GrayFrame, GrayFrame)>,
}

/// The layers of one database row (see [`Layers`]).
#[derive(Default)]
struct FrameLayers {
    original: Option<Arc<SourceFrame>>,
    smoke: Option<RgbaFrame>,
    grey: Option<(GrayFrame, GrayFrame)>,
}

/// When a source frame of `clip` (at pose angle `angle`) goes to the output by a
/// whole-pixel shift alone — scale 1, no rotation, a whole-pixel offset and the view shown
/// at its own size —, that shift `(dx, dy)`: output `(u, v)` = source `(u − dx, v − dy)`,
/// black outside the source. Exactly what the warp, the crop and the (identity) resize do
/// on such frames, without resampling.
fn shift_only(
    clip: &ClipEntry,
    angle: f32,
    pose_p: &crate::pose::PoseParams,
    geo: Geometry,
) -> Option<(i64, i64)> {
    if geo.out.width != geo.view.w || geo.out.height != geo.view.h {
        return None;
    }
    let (ox, oy) = crate::pose::whole_pixel_offset(&clip.pose, angle, pose_p)?;
    Some((ox - geo.view.x as i64, oy - geo.view.y as i64))
}

/// `data` (a `src`-sized image) shifted by `(dx, dy)` into an `out`-sized one (see
/// [`shift_only`]); returned as it is when nothing moves.
fn shift_pixels<T: Copy + Default + Send + Sync>(
    data: Vec<T>,
    src: Size,
    out: Size,
    (dx, dy): (i64, i64),
) -> Vec<T> {
    if (dx, dy) == (0, 0) && src == out {
        return data;
    }
    let (sw, sh, ow) = (src.width as i64, src.height as i64, out.width as usize);
    let mut o = vec![T::default(); out.pixels()];
    o.par_chunks_mut(ow).enumerate().for_each(|(v, row)| {
        let sy = v as i64 - dy;
        if sy < 0 || sy >= sh {
            return;
        }
        // Output columns u with 0 <= u - dx < sw.
        let u0 = dx.max(0).min(ow as i64) as usize;
        let u1 = (sw + dx).clamp(0, ow as i64) as usize;
        if u0 < u1 {
            let s0 = (sy * sw + u0 as i64 - dx) as usize;
            row[u0..u1].copy_from_slice(&data[s0..s0 + (u1 - u0)]);
        }
    });
    o
}

fn shift_rgba(f: RgbaFrame, out: Size, d: (i64, i64)) -> RgbaFrame {
    let src = f.size();
    RgbaFrame::from_vec(out, shift_pixels(f.into_vec(), src, out, d)).expect("out-sized")
}

fn shift_gray(g: GrayFrame, out: Size, d: (i64, i64)) -> GrayFrame {
    let src = g.size();
    GrayFrame::from_vec(out, shift_pixels(g.into_vec(), src, out, d)).expect("out-sized")
}

/// Where the layers go: the common frame, the view of it and the output size.
#[derive(Clone, Copy)]
pub(crate) struct Geometry {
    frame: Size,
    view: View,
    out: Size,
}

/// Loads the originals, smoke images, custom masks and source-made grey frames that
/// the rows `colour_rows` (colouring) and `grey_rows` (grey frames from the footage)
/// need, one clip at a time, reading only those source frames.
// Long on purpose: per clip it decides which source frames to read, reads them once and
// derives every layer from the same decoded frame; split, the frames would be passed
// around or read twice.
fn load_layers(
    db: &EigenfireDb,
    colour_rows: &[usize],
    grey_rows: &[usize],
    look: &Look,
    geo: Geometry,
    sources: &mut dyn FootageOpener,
) -> Result<Layers> {
    let mut layers = Layers::default();
    let want_original = matches!(look.mode, ColourMode::Original);
    let mut pose_p = db.manifest().preprocess.pose.clone();
    pose_p.frame_size = Some(geo.frame);
    let pre = &db.manifest().preprocess;
    let mut uniq: Vec<usize> = colour_rows.iter().chain(grey_rows).copied().collect();
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
        let shift = |r: usize| shift_only(clip, db.angle(r), &pose_p, geo);
        let warp_c = |f: &Arc<SourceFrame>, r: usize| match shift(r) {
            Some(d) if d == (0, 0) && f.size() == geo.out => Arc::clone(f),
            Some(d) => Arc::new(SourceFrame::Linear(shift_rgba(
                f.to_linear().into_owned(),
                geo.out,
                d,
            ))),
            None => Arc::new(SourceFrame::Linear(view_rgba(
                warp_rgba(&f.to_linear(), &clip.pose, db.angle(r), &pose_p),
                geo.frame,
                geo.view,
                geo.out,
            ))),
        };
        let warp_g = |g: GrayFrame, r: usize| match shift(r) {
            Some(d) => shift_gray(g, geo.out, d),
            None => view_gray(
                &crate::pose::warp(&g, &clip.pose, db.angle(r), &pose_p),
                geo.frame,
                geo.view,
                geo.out,
            ),
        };
        let is_colour = |r: usize| want_original && colour_rows.contains(&r);
        let is_grey = |r: usize| grey_rows.contains(&r);
        // The frame, and for smoke its next frame (the previous at the clip's end).
        let neighbour = |f: usize| {
            if f + 1 < clip.end {
                f + 1
            } else {
                f.saturating_sub(1)
            }
        };
        let mut need: Vec<usize> = mine
            .iter()
            .filter(|m| is_colour(m.0) || is_grey(m.0))
            .map(|m| m.1)
            .collect();
        if look.smoke.is_some() {
            need.extend(
                mine.iter()
                    .filter(|m| is_colour(m.0))
                    .map(|m| neighbour(m.1)),
            );
        }
        need.sort_unstable();
        need.dedup();
        if !need.is_empty() {
            let path = look.originals.get(&clip.name).map(PathBuf::as_path);
            let got = sources.open(clip, path)?.source_frames_at(&need)?;
            let by_frame: HashMap<usize, Arc<SourceFrame>> = need
                .iter()
                .zip(got)
                .filter_map(|(&f, g)| g.map(|g| (f, Arc::new(g))))
                .collect();
            let shown = || path.map_or(clip.source.clone(), |p| p.display().to_string());
            let work: Vec<(usize, usize)> = mine
                .iter()
                .copied()
                .filter(|&(r, _)| is_colour(r) || is_grey(r))
                .collect();
            for &(_, f) in &work {
                let cur = by_frame.get(&f).ok_or_else(|| {
                    EigenError::clip(
                        &clip.name,
                        format!("rendering needs frame {f} of {}, which it does not have; give the clip's footage under [originals] (or --relink)", shown()),
                    )
                })?;
                if cur.size() != clip.source_size {
                    return Err(EigenError::clip(
                        &clip.name,
                        format!(
                            "frame {f} of {} is {}, the database was trained on {}; give the original footage",
                            shown(),
                            cur.size(),
                            clip.source_size
                        ),
                    ));
                }
            }
            // The footage is the training footage: each grey frame is made with the mask
            // training stored for it, voted with its neighbours' (see [`super::voted_masks`]).
            let voted = match path {
                None => {
                    let grey: Vec<usize> =
                        work.iter().map(|w| w.0).filter(|&r| is_grey(r)).collect();
                    super::voted_masks(db, &grey)?
                }
                Some(_) => HashMap::new(),
            };
            // Every frame's layers at once (the pre-processing of one frame is mostly
            // sequential; frames are independent).
            let made: Vec<Result<FrameLayers>> = work
                .par_iter()
                .map(|&(r, f)| {
                    let cur = &by_frame[&f];
                    let mut fl = FrameLayers::default();
                    if is_grey(r) {
                        // The (voted) mask training made for this very frame, else one
                        // made now (footage replaced under [originals], older databases).
                        let sg = match voted.get(&r) {
                            Some(m)
                                if (m.width(), m.height())
                                    == (cur.size().width, cur.size().height) =>
                            {
                                crate::preprocess::source_grey_with_mask_src(
                                    cur, m, &clip.pose, pre,
                                )
                            }
                            _ => crate::preprocess::source_grey(&cur.to_linear(), &clip.pose, pre),
                        };
                        fl.grey = Some((warp_g(sg.grey, r), warp_g(sg.matte, r)));
                    }
                    if is_colour(r) {
                        let cur_w = warp_c(cur, r);
                        if let Some(sp) = &look.smoke {
                            if let Some(next) = by_frame.get(&neighbour(f)) {
                                let next_w = warp_c(next, r);
                                fl.smoke = Some(synthetic_smoke(
                                    &cur_w.to_linear(),
                                    &next_w.to_linear(),
                                    sp,
                                )?);
                            }
                        }
                        fl.original = Some(cur_w);
                    }
                    Ok(fl)
                })
                .collect();
            for (&(r, _), fl) in work.iter().zip(made) {
                let fl = fl?;
                if let Some(g) = fl.grey {
                    layers.grey.insert(r, g);
                }
                if let Some(s) = fl.smoke {
                    layers.smoke.insert(r, s);
                }
                if let Some(o) = fl.original {
                    layers.original.insert(r, o);
                }
            }
        }
        if let Some(mp) = look.masks.get(&clip.name) {
            let need: Vec<(usize, usize)> = mine
                .iter()
                .copied()
                .filter(|m| colour_rows.contains(&m.0))
                .collect();
            let frames: Vec<usize> = need.iter().map(|m| m.1).collect();
            let got = sources.open(clip, Some(mp))?.frames_at(&frames)?;
            for (&(r, _), g) in need.iter().zip(got) {
                if let Some(g) = g {
                    layers.mask.insert(r, warp_g(g.luminance(), r));
                }
            }
        }
    }
    Ok(layers)
}

/// [`render_plan_with`] with the default options (source size, footage read).
pub fn render_plan(
    db: &EigenfireDb,
    plan: &Plan,
    look: &Look,
    sources: &mut dyn FootageOpener,
    sink: &mut dyn FnMut(RgbaFrame) -> Result<()>,
    progress: &mut dyn FnMut(usize),
) -> Result<()> {
    render_plan_with(
        db,
        plan,
        look,
        &RenderOptions::default(),
        sources,
        sink,
        progress,
    )
}

/// Renders `plan` with `look` at the size of [`output_view`] (or `opts.size`): grey frame
/// — for an unedited database frame when `look.fast_path`, the pre-processed original
/// (§7.1.2): the stored frame, or the source footage's frame pre-processed again at its
/// own resolution; else a reconstruction with `plan.e_render` Eigenfires and the frame's
/// weight edits, upsampled, with the fine detail of the nearest footage frame where the
/// footage is read (so real and synthetic frames are equally sharp) —, bloom (§6.2),
/// colouring (original, Algorithm 2 with smoke and custom masks; synthetic; palette;
/// grey) and the alpha matte (the grey frame and its bloom, limited to the
/// pre-processing mask's feathered matte on frames made from the footage). Frames go to
/// `sink` in order; `progress(done)` counts them. Footage is read per batch of
/// `opts.batch` frames, in order (no whole-clip copy). The result does not depend on the
/// thread count or the batch size.
pub fn render_plan_with(
    db: &EigenfireDb,
    plan: &Plan,
    look: &Look,
    opts: &RenderOptions,
    sources: &mut dyn FootageOpener,
    sink: &mut dyn FnMut(RgbaFrame) -> Result<()>,
    progress: &mut dyn FnMut(usize),
) -> Result<()> {
    let geo = geometry(db, plan, opts)?;
    let ctx = super::morph::Ctx {
        db,
        plan,
        look,
        opts,
        geo,
    };
    super::morph::render_with_morphs(&ctx, sources, sink, progress).map(|_| ())
}

/// Where `plan`'s frames are cut from and the size they are written at (checked).
pub(crate) fn geometry(db: &EigenfireDb, plan: &Plan, opts: &RenderOptions) -> Result<Geometry> {
    let frame = db.manifest().frame_size;
    let (view, default_size) = output_view(db, plan);
    let out = opts.size.unwrap_or(default_size);
    check_output_size(out)?;
    Ok(Geometry { frame, view, out })
}

/// Longest side of the flow's working size for morph joins (full-resolution frames are
/// morphed with the flow upsampled from it).
pub const MORPH_FLOW_SIDE: u32 = 384;

/// Renders `frames` (no morph runs among them) of `plan` into `sink`, in order.
// Long on purpose: per batch it chooses each frame's grey source (footage, stored
// frame or reconstruction) and the layers they share, then finishes them in parallel
// ([`finish_frame`]); the per-frame rules are closures over that shared batch state.
#[allow(clippy::too_many_arguments)]
pub(crate) fn render_frames(
    db: &EigenfireDb,
    plan: &Plan,
    all_frames: &[PlanFrame],
    look: &Look,
    opts: &RenderOptions,
    geo: Geometry,
    sources: &mut dyn FootageOpener,
    sink: &mut dyn FnMut(RgbaFrame) -> Result<()>,
) -> Result<()> {
    let Geometry { frame, view, out } = geo;
    let stored = has_stored_frames(db);
    let original = matches!(look.mode, ColourMode::Original);
    let needs_rows = original || !look.masks.is_empty();
    let rows: Vec<usize> = if needs_rows {
        all_frames
            .iter()
            .map(|f| colour_row(db, f, plan.e_detect))
            .collect()
    } else {
        Vec::new()
    };
    let k = db.n_components();
    let unedited_db = |f: &PlanFrame| -> Option<usize> {
        match (&f.source, f.edits.is_empty() && look.fast_path) {
            (FrameRef::Db(r), true) => Some(*r),
            _ => None,
        }
    };
    // §7.1.2 from the stored pre-processed frame.
    let stored_frame = |f: &PlanFrame| -> Option<(String, usize)> {
        if !stored {
            return None;
        }
        unedited_db(f).and_then(|r| db.row_origin(r).map(|(c, fr)| (c.name.clone(), fr)))
    };
    // §7.1.2 from the footage itself.
    let from_source = |f: &PlanFrame| -> Option<usize> {
        if stored || opts.from_database {
            return None;
        }
        unedited_db(f)
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
    let batch = opts.batch.unwrap_or_else(default_batch).max(1);
    for start in (0..all_frames.len()).step_by(batch) {
        let end = (start + batch).min(all_frames.len());
        let frames = &all_frames[start..end];
        let colour_rows: Vec<usize> = if needs_rows {
            rows[start..end].to_vec()
        } else {
            Vec::new()
        };
        // Reconstructions borrow the fine detail of their nearest footage frame.
        let mut grey_rows: Vec<usize> = frames.iter().filter_map(&from_source).collect();
        if !stored && !opts.from_database {
            for (j, f) in frames.iter().enumerate() {
                if from_source(f).is_none() && stored_frame(f).is_none() {
                    grey_rows.push(if needs_rows {
                        rows[start + j]
                    } else {
                        colour_row(db, f, plan.e_detect)
                    });
                }
            }
        }
        let layers = if needs_rows || !grey_rows.is_empty() {
            load_layers(db, &colour_rows, &grey_rows, look, geo, sources)?
        } else {
            Layers::default()
        };
        // Grey frames: from the footage, stored, or reconstructed.
        let slow: Vec<&PlanFrame> = frames
            .iter()
            .filter(|f| from_source(f).is_none() && stored_frame(f).is_none())
            .collect();
        let ws: Vec<Vec<f32>> = slow.iter().map(|f| weights_of(f)).collect();
        let refs: Vec<&[f32]> = ws.iter().map(Vec::as_slice).collect();
        // One product per frame: a product over several frames sums in an order that
        // depends on how many there are, and the output must not depend on the batch.
        let recon: Vec<Result<Vec<GrayFrame>>> = refs
            .par_iter()
            .map(|w| db.reconstruct_batch(std::slice::from_ref(w), plan.e_render))
            .collect();
        let mut recon = recon
            .into_iter()
            .collect::<Result<Vec<_>>>()?
            .into_iter()
            .flatten();
        // Each frame's grey, its footage matte (frames made from the footage) and, for a
        // reconstruction, the matte of the footage frame it is coloured from (its copy
        // mask is made in the parallel pass below, not held for the whole batch).
        let mut greys: Vec<(Cow<GrayFrame>, Option<&GrayFrame>, Option<&GrayFrame>)> =
            Vec::with_capacity(frames.len());
        for (j, f) in frames.iter().enumerate() {
            if let Some(r) = from_source(f) {
                let (g, m) = &layers.grey[&r];
                greys.push((Cow::Borrowed(g), Some(m), None));
            } else if let Some((clip, fr)) = stored_frame(f) {
                let g = db.preprocessed_frame(&clip, fr)?;
                greys.push((Cow::Owned(view_gray(&g, frame, view, out)), None, None));
            } else {
                let r = recon.next().expect("one reconstruction per slow frame");
                let mut g = view_gray(&r, frame, view, out);
                let near = if needs_rows {
                    rows[start + j]
                } else {
                    colour_row(db, f, plan.e_detect)
                };
                let mut near_matte = None;
                if let Some((real, m)) = layers.grey.get(&near) {
                    add_detail(&mut g, real, db.train_size(), geo);
                    near_matte = Some(m).filter(|m| original && g.size() == m.size());
                }
                greys.push((Cow::Owned(g), None, near_matte));
            }
        }
        let batch: Vec<Result<RgbaFrame>> = greys
            .into_par_iter()
            .enumerate()
            .map(|(j, (g, m, near_matte))| {
                let row = if original {
                    Some(rows[start + j])
                } else {
                    None
                };
                let tint = frame_tint(db, look, row);
                let copy = near_matte.map(|nm| copy_mask(&g, nm));
                finish_frame(&g, m, copy.as_ref(), row, look, &tint, &layers)
            })
            .collect();
        for f in batch {
            sink(f?)?;
        }
    }
    Ok(())
}

/// The tint of a frame coloured from database row `row`: in original colouring, the
/// row's clip's own flame colour where the look takes it from the footage and training
/// measured one; otherwise the look's tint.
fn frame_tint<'a>(db: &EigenfireDb, look: &'a Look, row: Option<usize>) -> Cow<'a, Tint> {
    let footage = look.tint_from_footage && matches!(look.mode, ColourMode::Original);
    match row.and_then(|r| db.row_origin(r)) {
        Some((clip, _)) if footage => match clip.flame_colour {
            Some(c) => Cow::Owned(Tint::Solid(c)),
            None => Cow::Borrowed(&look.tint),
        },
        _ => Cow::Borrowed(&look.tint),
    }
}

/// Bloom (§6.2), colouring and the alpha matte of one grey frame: `row` is the database
/// row whose layers colour it (original colouring), `matte` the pre-processing matte of a
/// frame made from the footage, `tint` the bloom's (or synthetic colouring's) tint.
fn finish_frame(
    grey: &GrayFrame,
    matte: Option<&GrayFrame>,
    copy: Option<&GrayFrame>,
    row: Option<usize>,
    look: &Look,
    tint: &Tint,
    layers: &Layers,
) -> Result<RgbaFrame> {
    if let (ColourMode::Original, Some(r), Some(b), Tint::Solid(tint)) =
        (&look.mode, row, &look.bloom, tint)
    {
        // The common case in one pass: the bloom's full-resolution rows, the solid tint,
        // Algorithm 2 and the alpha matte made band by band (the same values as the
        // general path below, without a bloom frame or a second pass for the matte).
        // (The colouring checks the footage matte's size.)
        let rows = ignis_core::post::bloom_rows(grey, b)?;
        let alpha = if look.matte {
            AlphaMatte::Glow(matte)
        } else {
            AlphaMatte::Opaque
        };
        let smoke = layers.smoke.get(&r);
        let params = OriginalColour {
            threshold: look.threshold,
            smoke: smoke.is_some(),
        };
        return original_colouring_matted(
            grey,
            &layers.original[&r],
            Destination::SolidTintRows(&rows, *tint),
            smoke,
            custom_mask(layers, r, look, copy),
            &params,
            alpha,
        );
    }
    let bloomed = match &look.bloom {
        Some(b) => Some(bloom(grey, b)?),
        None => None,
    };
    let lit = bloomed.as_ref().unwrap_or(grey);
    let mut out = match (&look.mode, row) {
        (ColourMode::Grey, _) => lit.to_rgba(),
        (ColourMode::Palette(p), _) => p.apply(lit),
        (ColourMode::Synthetic, _) => synthetic_colour(lit, tint)?,
        (ColourMode::Original, None) => {
            return Err(EigenError::bad(
                "colour",
                "original colouring needs the frame's database row",
            ))
        }
        (ColourMode::Original, Some(r)) => {
            // The tinted bloom is the destination; a solid tint is made band by band
            // inside the colouring (the same values, no frame of them held).
            let image = match (&bloomed, tint) {
                (Some(b), tint) if !matches!(tint, Tint::Solid(_)) => {
                    Some(synthetic_colour(b, tint)?)
                }
                _ => None,
            };
            let dest = match (&bloomed, tint, &image) {
                (_, _, Some(i)) => Destination::Image(i),
                (Some(b), Tint::Solid(c), None) => Destination::SolidTint(b, *c),
                _ => Destination::Empty,
            };
            let smoke = layers.smoke.get(&r);
            let params = OriginalColour {
                threshold: look.threshold,
                smoke: smoke.is_some(),
            };
            // The alpha matte is applied to each band as it is coloured.
            if look.matte {
                check_matte(grey, lit, grey.size(), matte)?;
            }
            let w = grey.width().max(1) as usize;
            return original_colouring_src_then(
                grey,
                &layers.original[&r],
                dest,
                smoke,
                custom_mask(layers, r, look, copy),
                &params,
                &|start, band| matte_band(band, start, w, grey, lit, matte, look.matte),
            );
        }
    };
    apply_matte(&mut out, grey, lit, matte, look.matte)?;
    Ok(out)
}

/// Algorithm 2's mask of a frame coloured from row `r`: the scenario's custom mask for
/// it (§6.4), else a reconstruction's `copy` mask ([`copy_mask`]) in place of its grey
/// image, else none (the grey image is the mask).
fn custom_mask<'a>(
    layers: &'a Layers,
    r: usize,
    look: &Look,
    copy: Option<&'a GrayFrame>,
) -> Option<(&'a GrayFrame, MaskMode)> {
    match layers.mask.get(&r) {
        Some(m) => Some((m, look.mask_mode)),
        None => copy.map(|c| (c, MaskMode::Replace)),
    }
}

/// The mask by which Algorithm 2 copies a reconstructed frame's colours from the footage
/// frame it is coloured from: its grey image where that frame shows flame (its
/// pre-processing `matte`), 0 elsewhere. A reconstruction (a transition's frame, a blend
/// of weights) has light where the footage frame has none — a low-pass blend of two
/// clips, PCA's ringing — and copying the footage there drew its background (a candle's
/// glass, a campfire's dark logs) as flame; there the frame is coloured like the glow.
fn copy_mask(grey: &GrayFrame, matte: &GrayFrame) -> GrayFrame {
    let d = grey
        .data()
        .iter()
        .zip(matte.data())
        .map(|(&g, &m)| g * m.clamp(0.0, 1.0));
    GrayFrame::from_vec(grey.size(), d.collect()).expect("the grey frame's size")
}

/// The sizes [`apply_matte`] needs: the grey frame, its bloom, the coloured frame
/// (`out`) and the matte alike.
fn check_matte(
    grey: &GrayFrame,
    lit: &GrayFrame,
    out: Size,
    matte: Option<&GrayFrame>,
) -> Result<()> {
    if grey.size() != lit.size()
        || out != grey.size()
        || matte.is_some_and(|m| m.size() != grey.size())
    {
        return Err(EigenError::bad(
            "matte",
            format!(
                "the grey frame ({}), its bloom ({}), the coloured frame ({out}) and the matte differ in size",
                grey.size(),
                lit.size(),
            ),
        ));
    }
    Ok(())
}

/// [`apply_matte`]'s rule on one row of pixels starting at pixel index `at`.
fn matte_row(
    row: &mut [[f32; 4]],
    at: usize,
    grey: &GrayFrame,
    lit: &GrayFrame,
    matte: Option<&GrayFrame>,
    on: bool,
) {
    if !on {
        row.iter_mut().for_each(|px| px[3] = 1.0);
        return;
    }
    let span = at..at + row.len();
    let (g, l) = (&grey.data()[span.clone()], &lit.data()[span.clone()]);
    match matte {
        Some(m) => {
            let m = &m.data()[span];
            for (((px, &a), &b), &mv) in row.iter_mut().zip(g).zip(l).zip(m) {
                px[3] = (a + b).clamp(0.0, 1.0).max(mv.min(px[3]));
            }
        }
        None => {
            for ((px, &a), &b) in row.iter_mut().zip(g).zip(l) {
                px[3] = (a + b).clamp(0.0, 1.0);
            }
        }
    }
}

/// [`matte_row`] on each row (`w` pixels) of a band of rows starting at pixel index `at`.
fn matte_band(
    band: &mut [[f32; 4]],
    at: usize,
    w: usize,
    grey: &GrayFrame,
    lit: &GrayFrame,
    matte: Option<&GrayFrame>,
    on: bool,
) {
    for (j, row) in band.chunks_mut(w).enumerate() {
        matte_row(row, at + j * w, grey, lit, matte, on);
    }
}

/// The alpha of a finished frame: `ignis_core::post::alpha_matte(grey, lit)`, where the
/// frame was made from the footage at least the colouring's alpha limited to the
/// pre-processing `matte`; opaque when `on` is false. Rows in parallel, no frame-sized
/// temporary.
fn apply_matte(
    out: &mut RgbaFrame,
    grey: &GrayFrame,
    lit: &GrayFrame,
    matte: Option<&GrayFrame>,
    on: bool,
) -> Result<()> {
    if on {
        check_matte(grey, lit, out.size(), matte)?;
    }
    let w = out.width().max(1) as usize;
    out.data_mut()
        .par_chunks_mut(w)
        .enumerate()
        .for_each(|(y, row)| matte_row(row, y * w, grey, lit, matte, on));
    Ok(())
}

/// Detail transfer for a reconstructed frame: adds the fine detail of `real` (a
/// pre-processed footage frame at the output size) that the training resolution cannot
/// hold — `real` minus `real` brought to the training resolution and back — so a
/// reconstruction is as sharp as the footage frames around it. The detail is weighted by
/// the reconstruction's own brightness (no detail where it has no flame).
fn add_detail(g: &mut GrayFrame, real: &GrayFrame, train: Size, geo: Geometry) {
    if real.size() != g.size() {
        return;
    }
    // The training frame covers the whole common frame; the view's share of it.
    let tw =
        ((train.width as f32 * geo.view.w as f32 / geo.frame.width as f32).round() as u32).max(1);
    let th =
        ((train.height as f32 * geo.view.h as f32 / geo.frame.height as f32).round() as u32).max(1);
    let small = crate::pose::resize(
        real,
        Size {
            width: tw,
            height: th,
        },
    );
    let back = crate::pose::resize(&small, real.size());
    for ((o, &r), &b) in g.data_mut().iter_mut().zip(real.data()).zip(back.data()) {
        let w = (*o * 4.0).clamp(0.0, 1.0);
        *o = (*o + w * (r - b)).max(0.0);
    }
}

/// The plan of a seamless loop of `clip` over source frames `range` (what
/// [`crate::animate::render_loop`] renders, see [`crate::animate::find_loop`]): the
/// range's frames without those the transition replaces, then the transition back to the
/// start. Returns the plan and the loop's report.
pub fn loop_plan(
    db: &EigenfireDb,
    clip: &str,
    range: std::ops::Range<usize>,
    method: crate::transition::Transition,
    e_render: usize,
    search: usize,
) -> Result<(Plan, crate::report::LoopReport)> {
    let report = crate::animate::find_loop(db, clip, range, &method, e_render, search)?;
    let join = &report.join;
    let frames: Vec<PlanFrame> = crate::animate::loop_body(&report.rows, join)
        .map(FrameRef::Db)
        .chain(join.frames.iter().cloned())
        .map(|source| PlanFrame {
            source,
            edits: Vec::new(),
        })
        .collect();
    let plan = Plan {
        frames,
        morphs: Vec::new(),
        joins: Vec::new(),
        wrap_seam: join.seam_ratio,
        worst_step: join.seam_ratio,
        e_render: report.e_render,
        e_render_requested: e_render,
        e_detect: db.manifest().e_detect,
        loops: true,
    };
    Ok((plan, report))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::colour::original_colouring_then;

    /// `apply_matte` is `ignis_core::post::alpha_matte`, limited by the footage matte as
    /// `max(alpha, min(matte, colour alpha))`, bit for bit; opaque when off; sizes checked.
    #[test]
    fn apply_matte_is_the_alpha_matte_rule() {
        let sz = Size {
            width: 13,
            height: 7,
        };
        let f =
            |k: f32| GrayFrame::from_fn(sz, move |x, y| ((x * 7 + y * 3) as f32 * k).sin().abs());
        let (grey, lit, matte) = (f(0.3), f(0.7), f(1.1));
        let col = RgbaFrame::from_vec(
            sz,
            (0..sz.pixels())
                .map(|i| [0.1, 0.2, 0.3, (i % 5) as f32 * 0.2])
                .collect(),
        )
        .unwrap();
        let a = ignis_core::post::alpha_matte(&grey, &lit).unwrap();
        for m in [None, Some(&matte)] {
            let mut out = col.clone();
            apply_matte(&mut out, &grey, &lit, m, true).unwrap();
            for (i, px) in out.data().iter().enumerate() {
                let want = match m {
                    Some(m) => a.data()[i].max(m.data()[i].min(col.data()[i][3])),
                    None => a.data()[i],
                };
                assert_eq!(px[3].to_bits(), want.to_bits());
                assert_eq!(px[..3], col.data()[i][..3]);
            }
        }
        let mut out = col.clone();
        apply_matte(&mut out, &grey, &lit, None, false).unwrap();
        assert!(out.data().iter().all(|p| p[3] == 1.0));
        let small = GrayFrame::new(Size {
            width: 3,
            height: 2,
        });
        assert!(apply_matte(&mut col.clone(), &grey, &lit, Some(&small), true).is_err());
    }

    /// The matte applied band by band inside the colouring (what `finish_frame` does for
    /// original colouring) equals colouring the whole frame, then `apply_matte`, bit for
    /// bit: several bands of rows, solid-tinted bloom, with and without the footage matte.
    #[test]
    fn matte_in_the_colouring_bands_equals_the_matte_after() {
        let sz = Size {
            width: 13,
            height: 41,
        };
        let f =
            |k: f32| GrayFrame::from_fn(sz, move |x, y| ((x * 7 + y * 3) as f32 * k).sin().abs());
        let (grey, lit, matte) = (f(0.013), f(0.7), f(1.1));
        let orig = RgbaFrame::from_vec(
            sz,
            (0..sz.pixels())
                .map(|i| [0.1, (i % 3) as f32 * 0.4, 0.3, (i % 5) as f32 * 0.2])
                .collect(),
        )
        .unwrap();
        let p = OriginalColour::default();
        let dest = || Destination::SolidTint(&lit, [1.0, 0.5, 0.2]);
        let w = sz.width as usize;
        for m in [None, Some(&matte)] {
            for on in [true, false] {
                let mut want =
                    crate::colour::original_colouring_to(&grey, &orig, dest(), None, None, &p)
                        .unwrap();
                apply_matte(&mut want, &grey, &lit, m, on).unwrap();
                let got =
                    original_colouring_then(&grey, &orig, dest(), None, None, &p, &|at, band| {
                        matte_band(band, at, w, &grey, &lit, m, on)
                    })
                    .unwrap();
                let bits = |f: &RgbaFrame| {
                    f.data()
                        .iter()
                        .flatten()
                        .map(|v| v.to_bits())
                        .collect::<Vec<_>>()
                };
                assert_eq!(bits(&got), bits(&want));
            }
        }
    }

    /// A reconstruction coloured from a footage frame copies the footage only where that
    /// frame shows flame (its matte, [`copy_mask`]): where the reconstruction has light the
    /// footage frame lacks (blue "glass" there), it takes the glow's colour instead of the
    /// glass's, which Algorithm 2 alone copies; inside the matte it is unchanged.
    #[test]
    fn a_reconstruction_copies_the_footage_only_where_it_shows_flame() {
        let sz = Size {
            width: 24,
            height: 16,
        };
        let grey = GrayFrame::from_fn(sz, |_, _| 0.05);
        let matte = GrayFrame::from_fn(sz, |x, _| if x < 12 { 1.0 } else { 0.0 });
        let px = |i: usize| match i % 24 < 12 {
            true => [0.9, 0.5, 0.1, 1.0],
            false => [0.1, 0.2, 0.9, 1.0],
        };
        let orig = RgbaFrame::from_vec(sz, (0..sz.pixels()).map(px).collect()).unwrap();
        let mut layers = Layers::default();
        let orig = crate::footage::SourceFrame::Linear(orig);
        layers.original.insert(3, Arc::new(orig));
        let (look, tint) = (Look::default(), Tint::Solid([1.0, 0.42, 0.08]));
        let copy = copy_mask(&grey, &matte);
        let finish = |copy| finish_frame(&grey, None, copy, Some(3), &look, &tint, &layers);
        let (new, old) = (finish(Some(&copy)).unwrap(), finish(None).unwrap());
        let at = |f: &RgbaFrame, x: usize| f.data()[8 * 24 + x];
        assert_eq!(at(&new, 3), at(&old, 3), "inside the matte: as before");
        let (n, o) = (at(&new, 20), at(&old, 20));
        assert!(o[2] > o[0], "Algorithm 2 alone copies the glass: {o:?}");
        assert!(n[0] > n[2] && n[3] > 0.0, "{n:?} is not the glow's colour");
    }

    /// `shift_pixels` is the per-pixel rule of `shift_only`: output (u, v) = source
    /// (u − dx, v − dy), zero outside; for shifts in every direction, in and out of range.
    #[test]
    fn shift_pixels_matches_the_per_pixel_rule() {
        let src = Size {
            width: 7,
            height: 5,
        };
        let data: Vec<f32> = (0..src.pixels()).map(|i| i as f32 + 1.0).collect();
        for out in [
            src,
            Size {
                width: 9,
                height: 4,
            },
        ] {
            for d in [(0, 0), (2, -1), (-3, 2), (8, 0), (0, -6), (-9, -9)] {
                let got = shift_pixels(data.clone(), src, out, d);
                for v in 0..out.height as i64 {
                    for u in 0..out.width as i64 {
                        let (sx, sy) = (u - d.0, v - d.1);
                        let want = if sx >= 0 && sy >= 0 && sx < 7 && sy < 5 {
                            data[(sy * 7 + sx) as usize]
                        } else {
                            0.0
                        };
                        assert_eq!(
                            got[(v * out.width as i64 + u) as usize],
                            want,
                            "{d:?} {u},{v}"
                        );
                    }
                }
            }
        }
    }
}
