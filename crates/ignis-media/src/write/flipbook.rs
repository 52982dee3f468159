//! Flipbooks: every frame on one sprite-sheet PNG, left to right, top to bottom, starting
//! top-left (the layout Unity's Texture Sheet Animation, Unreal's SubUV and Godot's
//! particle animation expect), plus a JSON sidecar next to it (`fire.png` → `fire.json`),
//! and on request sheets of the same layout beside it: motion vectors (`fire.mv.png`,
//! [`super::motion`]), heat (`fire.heat.png`) and HDR colour (`fire.exr`).
//!
//! Each cell is the frame plus padding on every side, filled by repeating the frame's
//! edge pixels ("extruded") so texture filtering and mipmaps do not pull in neighbouring
//! frames. Cells after the last frame are transparent black (zero motion, zero heat).
//!
//! The grid is chosen to waste the fewest cells within `max_size` (sheets no more than 4:1
//! unless nothing else fits); `pot` makes both sheet sides powers of two (power-of-two
//! grids, the extra pixels going into the padding); `fit_frames` fills the wasted cells by
//! resampling the animation in time (linear cross-fade between neighbouring frames; the
//! fps is raised so the duration is unchanged; the JSON's `retimed` reports it).
//! `variants = N` lays N loops (pushed one after another) as the N rows of the sheet,
//! each row its own loop (Unity's Single Row mode).
//!
//! The PNG is 8-bit sRGB. Alpha is `straight` by default; `premultiplied` multiplies
//! colour by alpha in linear light before sRGB encoding (what an sRGB texture sampled with
//! `One, OneMinusSrcAlpha` blending needs). Motion and heat sheets are 16-bit linear; the
//! EXR is linear `f32`, premultiplied (the OpenEXR convention).

use std::io::Write;
use std::path::{Path, PathBuf};

use ignis_core::frame::{MAX_PIXELS, MAX_SIDE};
use ignis_core::loopq::LoopQuality;
use ignis_core::{RgbaFrame, Size};

use super::engine::{self, Engine};
use super::motion::{self, MotionSource};
use super::{encode_png, temp_file_for, Sink, WriteOptions};
use crate::convert;
use crate::error::{MediaError, Result};
use crate::read::Rect;
use ignis_core::atomic::AtomicFile;

/// How colour relates to alpha in a flipbook sheet.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AlphaMode {
    /// Colour independent of alpha (PNG's own convention).
    #[default]
    Straight,
    /// Colour already multiplied by alpha (in linear light).
    Premultiplied,
}

/// Sprite-sheet layout and extra sheets. `Default`: fewest-waste grid, no padding,
/// straight alpha, generic engine, colour sheet only.
#[derive(Clone, Debug, PartialEq)]
pub struct FlipbookOptions {
    /// Columns; `None` = chosen (fewest wasted cells).
    pub columns: Option<u32>,
    /// Rows; `None` = chosen (or from `columns`).
    pub rows: Option<u32>,
    /// Pixels of edge bleed around each frame, inside its cell (default 0; engine presets
    /// raise it to their minimum).
    pub padding: u32,
    /// Straight or premultiplied colour in the PNG (default straight).
    pub alpha: AlphaMode,
    /// Engine preset: motion-vector orientation, minimum padding and the JSON's
    /// `engine_settings` ([`Engine`]). Default generic.
    pub engine: Engine,
    /// Largest sheet side in pixels (default: no limit beyond 16384).
    pub max_size: Option<u32>,
    /// Power-of-two sheet sides (default false).
    pub pot: bool,
    /// Fill every cell of the grid by resampling the animation in time (default false).
    pub fit_frames: bool,
    /// Number of loops laid as rows (default 1; 0 is an error).
    pub variants: u32,
    /// Write a motion-vector sheet (`x.mv.png`) from this flow (default none).
    pub motion: Option<MotionSource>,
    /// Write a heat sheet (`x.heat.png`, 16-bit grey luminance, linear; default false).
    pub heat: bool,
    /// Write an HDR colour sheet (`x.exr`, linear f32 premultiplied; default false).
    pub hdr: bool,
    /// The frames were rendered smaller than the source to fit the sheet limit
    /// ([`fit_frame`]); recorded in the JSON's `scaled_from` (default none).
    pub scaled_from: Option<ScaledFrom>,
    /// Crop every frame to the box the animation ever shows ([`visible_box`]), so no
    /// texture is spent on pixels that are transparent in every frame; recorded in the
    /// JSON's `trimmed` (default false).
    pub trim: bool,
}

impl Default for FlipbookOptions {
    fn default() -> Self {
        FlipbookOptions {
            columns: None,
            rows: None,
            padding: 0,
            alpha: AlphaMode::Straight,
            engine: Engine::Generic,
            max_size: None,
            pot: false,
            fit_frames: false,
            variants: 1,
            motion: None,
            heat: false,
            hdr: false,
            scaled_from: None,
            trim: false,
        }
    }
}

/// Where a trimmed flipbook's frames ([`FlipbookOptions::trim`]) lie in the frames as
/// rendered: the frame is the box `x..x + frame_width`, `y..y + frame_height` (pixels, +y
/// down) of a `from_width` × `from_height` frame. An engine keeps a sprite's pivot where it
/// was by offsetting the quad by that box's centre minus the full frame's centre.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Trimmed {
    pub from_width: u32,
    pub from_height: u32,
    pub x: u32,
    pub y: u32,
}

/// The box (`x, y, width, height`) holding every pixel that any of `frames` (all of
/// `size`) shows — alpha that is not 0 in 8 bits — and a transparent pixel around it where
/// the frame has room (so filtering at the crop's edge reads transparency, as it did in the
/// full frame). `None` when nothing is visible or the box is the whole frame.
pub fn visible_box(frames: &[RgbaFrame], size: Size) -> Option<(u32, u32, u32, u32)> {
    let (w, h) = (size.width, size.height);
    let (mut x0, mut y0, mut x1, mut y1) = (u32::MAX, u32::MAX, 0u32, 0u32);
    let shown = |p: &[f32; 4]| p[3] * 255.0 >= 0.5;
    for f in frames {
        for (y, row) in f.data().chunks_exact(w as usize).enumerate() {
            let y = y as u32;
            if let (Some(first), Some(last)) =
                (row.iter().position(shown), row.iter().rposition(shown))
            {
                x0 = x0.min(first as u32);
                x1 = x1.max(last as u32);
                y0 = y0.min(y);
                y1 = y1.max(y);
            }
        }
    }
    if x0 == u32::MAX {
        return None;
    }
    let (x0, y0) = (x0.saturating_sub(1), y0.saturating_sub(1));
    let (x1, y1) = ((x1 + 1).min(w - 1), (y1 + 1).min(h - 1));
    let b = (x0, y0, x1 - x0 + 1, y1 - y0 + 1);
    (b != (0, 0, w, h)).then_some(b)
}

/// Why a flipbook's cells are smaller than the source frames: the size the frames were
/// scaled down from (aspect kept) so that the grid fits the sheet limit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ScaledFrom {
    /// The source frame size.
    pub width: u32,
    pub height: u32,
    /// The sheet limit the cells were fitted to: the largest side (`--max-size`, default
    /// [`MAX_SIDE`]) and the largest pixel count ([`MAX_PIXELS`]).
    pub max_size: u32,
    pub max_pixels: u64,
}

/// The motion-vector sheet's description in the JSON.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MotionMeta {
    /// File name of the 16-bit RGB PNG, relative to the JSON.
    pub image: String,
    /// Strength: a channel value `v` (0..1) is the motion `(v * 2 - 1) * scale`, in
    /// tile-UV units (fractions of one cell's width / height) per frame.
    pub scale: f32,
    /// 16-bit code of zero motion (32768; 128 in 8 bits).
    pub neutral: u16,
    /// `"up"`: green grows with the engine's `v` upwards (image up); `"down"`: image down.
    pub green: String,
    /// Always `"linear"` (import with sRGB off, uncompressed).
    pub color_space: String,
    /// What the vectors are.
    pub direction: String,
    /// Where they come from when not from the optical flow between the written frames
    /// (absent: the flow), e.g. a generator's model motion.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub source: Option<String>,
}

/// A linear data sheet (heat) in the JSON.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct HeatMeta {
    /// File name of the 16-bit grey PNG, relative to the JSON.
    pub image: String,
    /// Linear luminance (of the premultiplied colour) that grey 1.0 stands for.
    pub scale: f32,
    /// Always `"linear"`.
    pub color_space: String,
}

/// How the animation was resampled in time to fill the grid.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Retime {
    /// Frames (per variant) before.
    pub from_frames: u32,
    /// Fps before (the JSON's `fps` is the new rate: same duration).
    pub from_fps: f64,
}

/// The JSON sidecar of a flipbook.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FlipbookMeta {
    /// File name of the sheet, relative to the JSON file.
    pub image: String,
    /// Size of one frame without padding, in pixels.
    pub frame_width: u32,
    pub frame_height: u32,
    pub columns: u32,
    pub rows: u32,
    pub frame_count: u32,
    pub fps: f64,
    #[serde(rename = "loop")]
    pub loop_: bool,
    /// Bleed pixels on each side of each frame (the smallest, when `pot` adds more).
    pub padding: u32,
    /// `"straight"` or `"premultiplied"`.
    pub alpha: AlphaMode,
    /// Always `"row-major, top-left first"`.
    pub order: String,
    /// Always `"srgb"` (8-bit sRGB-encoded colour; alpha is linear).
    pub color_space: String,
    /// Cell size in pixels (frame + padding); the sheet is `columns × rows` cells.
    #[serde(default)]
    pub cell_width: u32,
    #[serde(default)]
    pub cell_height: u32,
    /// Where the frame starts inside its cell (= `padding` unless `pot` widened the cell).
    #[serde(default)]
    pub frame_x: u32,
    #[serde(default)]
    pub frame_y: u32,
    /// Loops laid as rows (1 = one animation over the whole sheet).
    #[serde(default = "one")]
    pub variants: u32,
    /// The engine preset the sheet was written for.
    #[serde(default)]
    pub engine: Engine,
    /// The engine's own parameter names and values (see README's engine table).
    #[serde(default, skip_serializing_if = "serde_json::Value::is_null")]
    pub engine_settings: serde_json::Value,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub motion_vectors: Option<MotionMeta>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heat: Option<HeatMeta>,
    /// File name of the HDR EXR colour sheet (linear f32, premultiplied), if written.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hdr_image: Option<String>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub retimed: Option<Retime>,
    /// Present when the frames were rendered smaller than the source to fit the sheet
    /// limit: the source size and the limit (the cell size is `frame_width` ×
    /// `frame_height`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scaled_from: Option<ScaledFrom>,
    /// Present when the frames were trimmed to what the animation shows: where the
    /// `frame_width` × `frame_height` frames lie in the frames as rendered.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trimmed: Option<Trimmed>,
    /// Seam and ghost of the sheet's frames played as a loop, measured on the frames
    /// written ([`ignis_core::loopq`]); present when `loop` is true.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loop_quality: Option<LoopQuality>,
    /// With `variants` > 1 and `loop`: each row's seam and ghost played as its own loop,
    /// measured on the sheet's frames (row order).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub variant_loop_quality: Option<Vec<LoopQuality>>,
}

fn one() -> u32 {
    1
}

/// A flipbook read back by [`read_flipbook`]: its sidecar, its frames (linear light,
/// straight alpha, whatever the sheet's alpha mode) and, when the sheet has them, each
/// frame's forward motion in pixels (+y down, whatever the engine's green convention).
#[derive(Clone, Debug)]
pub struct Flipbook {
    pub meta: FlipbookMeta,
    pub frames: Vec<RgbaFrame>,
    pub motion: Option<Vec<Vec<[f32; 2]>>>,
}

/// Where the cells are on a sheet.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    pub columns: u32,
    pub rows: u32,
    pub cell_width: u32,
    pub cell_height: u32,
    /// Offset of the frame inside its cell.
    pub frame_x: u32,
    pub frame_y: u32,
    pub sheet_width: u32,
    pub sheet_height: u32,
}

impl Layout {
    fn cells(&self) -> u64 {
        self.columns as u64 * self.rows as u64
    }
}

/// The layout of `n` frames (per variant: `n / variants`) of `frame` size and the frame
/// count after retiming (= `n` unless `fit_frames` fills wasted cells).
pub fn plan_layout(n: u32, frame: Size, opts: &FlipbookOptions) -> Result<(Layout, u32)> {
    let v = opts.variants;
    if v == 0 {
        return Err(MediaError::bad(
            "variants",
            "0 variants: use 1 for one animation, or N ≥ 2 for N loops as rows",
        ));
    }
    if n == 0 {
        return Err(MediaError::bad(
            "frames",
            "a flipbook needs at least one frame",
        ));
    }
    let max = opts.max_size.unwrap_or(MAX_SIDE).min(MAX_SIDE);
    if max == 0 {
        return Err(MediaError::bad("max-size", "must be ≥ 1 pixel, e.g. 4096"));
    }
    let pad = opts.padding.max(opts.engine.conventions().min_padding);
    let (cw, ch) = (
        frame.width as u64 + 2 * pad as u64,
        frame.height as u64 + 2 * pad as u64,
    );
    let make = |c: u32, r: u32| -> Option<Layout> {
        let (mut sw, mut sh) = (c as u64 * cw, r as u64 * ch);
        if opts.pot {
            if !c.is_power_of_two() || !r.is_power_of_two() {
                return None;
            }
            sw = sw.next_power_of_two();
            sh = sh.next_power_of_two();
        }
        if sw > max as u64 || sh > max as u64 || sw * sh > MAX_PIXELS {
            return None;
        }
        let (cellw, cellh) = ((sw / c as u64) as u32, (sh / r as u64) as u32);
        Some(Layout {
            columns: c,
            rows: r,
            cell_width: cellw,
            cell_height: cellh,
            frame_x: (cellw - frame.width) / 2,
            frame_y: (cellh - frame.height) / 2,
            sheet_width: sw as u32,
            sheet_height: sh as u32,
        })
    };
    let too_big =
        |what: String| {
            // Cells that fit by the sides, and by the sheet's pixel cap (which --max-size does
            // not raise).
            let by_side = (max as u64 / cw) * (max as u64 / ch);
            let by_area = MAX_PIXELS / (cw * ch).max(1);
            MediaError::LimitExceeded(format!(
            "{what} of {}x{} frames (+{pad} padding per side) do not fit a {max}x{max} sheet{} \
             of at most {MAX_PIXELS} pixels (at most {} cells fit); use fewer or smaller frames \
             (--size), less padding{}",
            frame.width,
            frame.height,
            if opts.pot { " with power-of-two sides" } else { "" },
            by_side.min(by_area),
            if by_side < by_area && max < MAX_SIDE {
                " or a larger --max-size"
            } else {
                ", or write a frame sequence (`-o dir/%04d.png`)"
            },
        ))
        };
    if v > 1 {
        if opts.columns.is_some() || opts.rows.is_some() {
            return Err(MediaError::bad(
                "variants",
                "variants set the grid (one row per loop); drop --columns / --rows",
            ));
        }
        if !n.is_multiple_of(v) {
            return Err(MediaError::bad(
                "variants",
                format!("{n} frames do not split into {v} loops of equal length"),
            ));
        }
        let per = n / v;
        let cols = if opts.pot && opts.fit_frames {
            per.next_power_of_two()
        } else {
            per
        };
        let l = make(cols, v).ok_or_else(|| too_big(format!("{v} rows of {cols} cells")))?;
        return Ok((l, cols * v));
    }
    let layout = match (opts.columns, opts.rows) {
        (Some(0), _) | (_, Some(0)) => {
            return Err(MediaError::bad("flipbook", "columns and rows must be ≥ 1"))
        }
        (Some(c), Some(r)) => {
            if (c as u64) * (r as u64) < n as u64 {
                return Err(MediaError::bad(
                    "flipbook",
                    format!(
                        "{c} columns × {r} rows hold {} frames, but there are {n}",
                        c as u64 * r as u64
                    ),
                ));
            }
            make(c, r).ok_or_else(|| too_big(format!("{c}×{r} cells")))?
        }
        (Some(c), None) => {
            let r = n.div_ceil(c);
            let r = if opts.pot { r.next_power_of_two() } else { r };
            make(c, r).ok_or_else(|| too_big(format!("{c}×{r} cells")))?
        }
        (None, Some(r)) => {
            let c = n.div_ceil(r);
            let c = if opts.pot { c.next_power_of_two() } else { c };
            make(c, r).ok_or_else(|| too_big(format!("{c}×{r} cells")))?
        }
        (None, None) => {
            // Fewest wasted cells (sheets over 4:1 only when nothing else fits); among
            // those the squarest sheet, then the wider one.
            let mut best: Option<((bool, u64, u64, u32), Layout)> = None;
            let mut c = 1u32;
            // more columns than fit the side never lay out (so a huge `n` costs nothing)
            let most = (max as u64 / cw.max(1)).min(n as u64) as u32;
            while c <= most {
                let r = n.div_ceil(c);
                let r = if opts.pot { r.next_power_of_two() } else { r };
                if let Some(l) = make(c, r) {
                    let waste = l.cells() - n as u64;
                    let (a, b) = (l.sheet_width as u64, l.sheet_height as u64);
                    let long = a.max(b) > 4 * a.min(b);
                    let skew = a.max(b) * 1000 / a.min(b);
                    let key = (long, waste, skew, u32::MAX - c);
                    if best.as_ref().is_none_or(|(k, _)| key < *k) {
                        best = Some((key, l));
                    }
                }
                c = if opts.pot { c * 2 } else { c + 1 };
            }
            best.map(|b| b.1)
                .ok_or_else(|| too_big(format!("{n} cells")))?
        }
    };
    let m = if opts.fit_frames {
        layout.cells() as u32
    } else {
        n
    };
    Ok((layout, m))
}

/// Shortest side, in pixels, a frame scaled to fit the sheet may have: below it a cell no
/// longer shows the fire's structure, so [`fit_frame`] refuses instead of writing it.
pub const MIN_FIT_SIDE: u32 = 16;

/// The sheet limit of `opts`: the largest side (`max_size`, at most [`MAX_SIDE`]) and the
/// largest pixel count ([`MAX_PIXELS`]).
pub fn sheet_limit(opts: &FlipbookOptions) -> (u32, u64) {
    (opts.max_size.unwrap_or(MAX_SIDE).min(MAX_SIDE), MAX_PIXELS)
}

/// `frame` scaled so its longer side is `long` pixels, aspect kept (the other side
/// rounded, at least 1).
fn scaled_to(frame: Size, long: u32) -> Size {
    let (big, small) = (frame.width.max(frame.height), frame.width.min(frame.height));
    let other = ((small as u64 * long as u64 + big as u64 / 2) / big as u64).max(1) as u32;
    let (w, h) = if frame.width >= frame.height {
        (long, other)
    } else {
        (other, long)
    };
    Size::new(w, h).expect("no larger than a valid size")
}

/// The largest size no larger than `frame` scaled to `long` whose cell pitch (the frame
/// plus `pad` on both sides) is a multiple of 4 on both axes, so block-compressed
/// textures (BC/DXT, ASTC 4×4, ETC) never code two cells in one 4×4 block and nothing
/// bleeds across cells. Of the longer sides `long`, `long − 1`, … `long − 15`, each with
/// both sides rounded down to whole blocks, the first within 0.25 % of `frame`'s aspect
/// wins, else the closest, so the aspect moves by well under 1 % for cells of a few
/// hundred pixels.
/// Sides of 4 pixels or less stay as they are.
fn block_aligned(frame: Size, long: u32, pad: u32) -> Size {
    let align = |v: u32| {
        let down = (v + 2 * pad) % 4;
        if v > 4 && down < v {
            v - down
        } else {
            v
        }
    };
    let aspect = frame.width as f64 / frame.height as f64;
    let mut best: Option<(f64, Size)> = None;
    for l in (long.saturating_sub(15).max(1)..=long).rev() {
        let s = scaled_to(frame, l);
        let a = Size::new(align(s.width), align(s.height)).expect("no larger than a valid size");
        let err = ((a.width as f64 / a.height as f64) / aspect - 1.0).abs();
        if err <= 0.0025 {
            return a;
        }
        if best.is_none_or(|(e, _)| err < e - 1e-12) {
            best = Some((err, a));
        }
    }
    best.map_or(scaled_to(frame, long), |(_, a)| a)
}

/// The frame size at which `n` frames fit one sheet with `opts` (grid, padding, engine
/// preset, `pot`, `max_size`): `frame` itself when its cells fit, otherwise the largest
/// size with the same aspect (the longer side found by bisection; fitting is monotone in
/// the size), shrunk by up to 3 pixels per side to whole 4×4 compression blocks
/// per cell (`block_aligned`), and the [`ScaledFrom`] to record. Refused (`LimitExceeded`, naming the fixes)
/// when even cells whose shorter side is [`MIN_FIT_SIDE`] pixels do not fit.
pub fn fit_frame(
    n: u32,
    frame: Size,
    opts: &FlipbookOptions,
) -> Result<(Size, Option<ScaledFrom>)> {
    let fits = |s: Size| match plan_layout(n, s, opts) {
        Ok(_) => Ok(true),
        Err(MediaError::LimitExceeded(_)) => Ok(false),
        Err(e) => Err(e),
    };
    if fits(frame)? {
        return Ok((frame, None));
    }
    let (max, max_pixels) = sheet_limit(opts);
    let long = frame.width.max(frame.height);
    // Invariant: `lo` fits (or is 0), `hi` does not.
    let (mut lo, mut hi) = (0u32, long);
    while hi - lo > 1 {
        let mid = lo + (hi - lo) / 2;
        if fits(scaled_to(frame, mid))? {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let pad = opts.padding.max(opts.engine.conventions().min_padding);
    let best = (lo > 0).then(|| block_aligned(frame, lo, pad));
    match best {
        Some(s) if s.width.min(s.height) >= MIN_FIT_SIDE.min(frame.width.min(frame.height)) => {
            Ok((
                s,
                Some(ScaledFrom {
                    width: frame.width,
                    height: frame.height,
                    max_size: max,
                    max_pixels,
                }),
            ))
        }
        _ => Err(MediaError::LimitExceeded(format!(
            "{n} frames of {}x{} do not fit a {max}x{max} sheet{} even as cells whose shorter \
             side is {MIN_FIT_SIDE} pixels{}; raise --max-size, use fewer frames (or fewer \
             --columns/--rows, less --padding), or write a frame sequence (`-o dir/%04d.png`)",
            frame.width,
            frame.height,
            if opts.pot {
                " with power-of-two sides"
            } else {
                ""
            },
            match best {
                Some(s) => format!(" (they would be {}x{})", s.width, s.height),
                None => String::new(),
            }
        ))),
    }
}

/// Resamples one loop (or one-shot animation) of `frames` to `m` frames by cross-fading
/// neighbours: a loop keeps its period (frame `j` at time `j·n/m`, wrapping), a one-shot
/// keeps its first and last frames.
pub fn retime(frames: &[RgbaFrame], m: usize, loop_: bool) -> Vec<RgbaFrame> {
    let n = frames.len();
    if n == m || n == 0 {
        return frames.to_vec();
    }
    (0..m)
        .map(|j| {
            let t = if loop_ {
                j as f64 * n as f64 / m as f64
            } else if m > 1 {
                j as f64 * (n - 1) as f64 / (m - 1) as f64
            } else {
                0.0
            };
            let i0 = (t.floor() as usize).min(n - 1);
            let a = (t - i0 as f64) as f32;
            let i1 = if loop_ {
                (i0 + 1) % n
            } else {
                (i0 + 1).min(n - 1)
            };
            if a <= 1e-6 {
                frames[i0].clone()
            } else {
                motion::linear_blend(&frames[i0], &frames[i1], a)
            }
        })
        .collect()
}

/// Copies `frame` (w×h values) into cell `index` of `sheet`, extruding its edges.
fn place<T: Copy>(sheet: &mut [T], l: &Layout, index: usize, frame: &[T], w: usize, h: usize) {
    let (c, sw) = (l.columns as usize, l.sheet_width as usize);
    let (ox, oy) = (
        (index % c) * l.cell_width as usize,
        (index / c) * l.cell_height as usize,
    );
    let (fx, fy) = (l.frame_x as usize, l.frame_y as usize);
    for cy in 0..l.cell_height as usize {
        let sy = cy.saturating_sub(fy).min(h - 1);
        let dst = (oy + cy) * sw + ox;
        let src = &frame[sy * w..sy * w + w];
        for cx in 0..l.cell_width as usize {
            sheet[dst + cx] = src[cx.saturating_sub(fx).min(w - 1)];
        }
    }
}

pub(crate) struct FlipbookSink {
    path: PathBuf,
    size: Size,
    opts: FlipbookOptions,
    fps: f64,
    loop_: bool,
    loop_quality: Option<LoopQuality>,
    /// The background the loop metrics composite over (the writer's).
    background: [f32; 3],
    /// Every pushed frame, linear light, straight alpha.
    frames: Vec<RgbaFrame>,
}

impl FlipbookSink {
    pub(crate) fn new(path: &Path, size: Size, opts: &WriteOptions) -> Result<FlipbookSink> {
        if path
            .extension()
            .is_none_or(|e| !e.eq_ignore_ascii_case("png"))
        {
            return Err(MediaError::bad(
                "path",
                format!("a flipbook is a .png file, not {}", path.display()),
            ));
        }
        // Checks the options (grid, variants, max-size) before any frame is made.
        if opts.flipbook.columns == Some(0) || opts.flipbook.rows == Some(0) {
            return Err(MediaError::bad("flipbook", "columns and rows must be ≥ 1"));
        }
        plan_layout(
            opts.flipbook.variants.max(1),
            size,
            &FlipbookOptions {
                columns: None,
                rows: None,
                fit_frames: false,
                ..opts.flipbook.clone()
            },
        )
        .map_err(|e| match e {
            MediaError::LimitExceeded(m) => {
                MediaError::LimitExceeded(format!("even one frame: {m}"))
            }
            e => e,
        })?;
        if opts.flipbook.variants == 0 {
            return Err(MediaError::bad(
                "variants",
                "0 variants: use 1 for one animation, or N ≥ 2 for N loops as rows",
            ));
        }
        Ok(FlipbookSink {
            path: path.to_path_buf(),
            size,
            opts: opts.flipbook.clone(),
            fps: opts.fps,
            loop_: opts.loop_,
            loop_quality: None,
            background: opts.background,
            frames: Vec::new(),
        })
    }

    fn side_path(&self, suffix: &str) -> PathBuf {
        let stem = self
            .path
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        self.path.with_file_name(format!("{stem}{suffix}"))
    }

    /// Forward motion of every frame of `frames` (one loop per row), in pixels (+y down).
    fn motion(
        &self,
        src: &MotionSource,
        frames: &[RgbaFrame],
        per: usize,
    ) -> Result<Vec<Vec<[f32; 2]>>> {
        if per < 2 {
            return Err(MediaError::bad(
                "motion-vectors",
                format!(
                    "motion vectors need at least two frames per loop, but the sheet has {per}; \
                     render more frames or drop --motion-vectors"
                ),
            ));
        }
        let check = |f: Vec<[f32; 2]>| -> Result<Vec<[f32; 2]>> {
            if f.len() != self.size.pixels() {
                return Err(MediaError::encode(
                    &self.path,
                    format!(
                        "the motion source gave {} vectors for {} pixels",
                        f.len(),
                        self.size.pixels()
                    ),
                ));
            }
            let ok = |v: f32| if v.is_finite() { v } else { 0.0 };
            Ok(f.into_iter().map(|[dx, dy]| [ok(dx), ok(dy)]).collect())
        };
        let mut out = Vec::with_capacity(frames.len());
        let flow = match &src.0 {
            motion::Source::Flow(flow) => flow,
            motion::Source::Velocities { f, .. } => {
                // the generator sees its frames as the 8-bit colour sheet holds them (what
                // an engine's blend samples), e.g. to choose vectors by blending them
                let alpha = self.opts.alpha;
                let held: Vec<RgbaFrame> = {
                    use rayon::prelude::*;
                    frames.par_iter().map(|f| as_held(alpha, f)).collect()
                };
                for (r, row) in held.chunks(per).enumerate() {
                    let given = f(r, row).map_err(|e| {
                        MediaError::encode(&self.path, format!("motion vectors: {e}"))
                    })?;
                    if given.len() != row.len() {
                        return Err(MediaError::encode(
                            &self.path,
                            format!(
                                "the generator gave motion vectors for {} frames of {}",
                                given.len(),
                                row.len()
                            ),
                        ));
                    }
                    for v in given {
                        out.push(check(v)?);
                    }
                }
                return Ok(out);
            }
        };
        for row in frames.chunks(per) {
            // Pair k joins frame k to k+1 (the last one wraps to 0 in a loop).
            let pairs = if self.loop_ { per } else { per - 1 };
            let mut fwd = Vec::with_capacity(pairs);
            let mut bwd = Vec::with_capacity(pairs);
            for k in 0..pairs {
                let (f, b) = flow(&row[k], &row[(k + 1) % per])
                    .map_err(|e| MediaError::encode(&self.path, format!("optical flow: {e}")))?;
                fwd.push(check(f)?);
                bwd.push(check(b)?);
            }
            // Frame k's velocity: the mean of its forward motion and its reversed backward
            // motion; the ends of a one-shot have one side only.
            for k in 0..per {
                let ahead = (k < pairs).then(|| &fwd[k]);
                let behind = (k > 0 || self.loop_).then(|| &bwd[(k + pairs - 1) % pairs]);
                let mv = super::motion::frame_velocity(
                    ahead.map(Vec::as_slice),
                    behind.map(Vec::as_slice),
                )
                .expect("per >= 2: every frame has a neighbour");
                out.push(mv);
            }
        }
        Ok(out)
    }
}

/// Encodes a sheet into a hidden temporary file next to `path`.
fn encode_temp(
    path: &Path,
    encode: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::result::Result<(), String>,
) -> Result<AtomicFile> {
    let mut tmp = temp_file_for(path)?;
    encode(tmp.writer()).map_err(|e| MediaError::encode(path, e))?;
    Ok(tmp)
}

/// Moves every file of a flipbook into place as one unit (a journal completes an
/// interrupted commit on the next run; see `ignis_core::atomic::commit_all`).
fn commit(files: Vec<AtomicFile>) -> Result<Vec<PathBuf>> {
    let paths: Vec<PathBuf> = files.iter().map(|f| f.target().to_path_buf()).collect();
    super::commit_temps(files)?;
    Ok(paths)
}

/// `frame` as the 8-bit sRGB colour sheet holds it, read back as [`read_flipbook`]
/// reads it (straight alpha, linear).
fn as_held(alpha: AlphaMode, frame: &RgbaFrame) -> RgbaFrame {
    match alpha {
        AlphaMode::Straight => convert::from_srgba8(frame.size(), &convert::to_srgba8(frame)),
        AlphaMode::Premultiplied => {
            let mut pre = frame.clone();
            convert::premultiply(&mut pre);
            let mut back = convert::from_srgba8(frame.size(), &convert::to_srgba8(&pre));
            convert::unpremultiply(&mut back);
            back
        }
    }
}

/// A sheet filled with `background` with every frame's pixels (`pixels(frame)`, `w × h`
/// row-major) placed in its cell; each row of cells is filled in parallel (the same at
/// any thread count).
fn sheet_of<S: Sync, T: Copy + Send + Sync>(
    l: &Layout,
    frames: &[S],
    background: T,
    w: usize,
    h: usize,
    pixels: impl Fn(&S) -> Vec<T> + Sync,
) -> Vec<T> {
    use rayon::prelude::*;
    let mut sheet = vec![background; l.sheet_width as usize * l.sheet_height as usize];
    let c = l.columns as usize;
    let band = l.cell_height as usize * l.sheet_width as usize;
    sheet
        .par_chunks_mut(band)
        .enumerate()
        .for_each(|(r, cells)| {
            for (k, f) in frames.iter().enumerate().skip(r * c).take(c) {
                // Index within the band: the cell's column, row 0.
                place(cells, l, k % c, &pixels(f), w, h);
            }
        });
    sheet
}

/// A 16-bit PNG sheet encoded into a temporary beside `path`.
fn png16_temp(
    path: &Path,
    l: &Layout,
    data: &[u16],
    color: image::ExtendedColorType,
) -> Result<AtomicFile> {
    encode_temp(path, |wr| {
        png16(wr, l.sheet_width, l.sheet_height, data, color)
    })
}

fn png16(
    w: &mut impl Write,
    width: u32,
    height: u32,
    data: &[u16],
    color: image::ExtendedColorType,
) -> std::result::Result<(), String> {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    use image::ImageEncoder;
    let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_ne_bytes()).collect();
    PngEncoder::new_with_quality(w, CompressionType::Fast, FilterType::Adaptive)
        .write_image(&bytes, width, height, color)
        .map_err(|e| e.to_string())
}

impl Sink for FlipbookSink {
    fn set_loop_quality(&mut self, quality: LoopQuality) {
        self.loop_quality = Some(quality);
    }

    fn push(&mut self, frame: &RgbaFrame) -> Result<()> {
        let (cw, ch) = (
            self.size.width as u64 + 2 * self.opts.padding as u64,
            self.size.height as u64 + 2 * self.opts.padding as u64,
        );
        let area = (self.frames.len() as u64 + 1) * cw * ch;
        if area > MAX_PIXELS {
            return Err(MediaError::LimitExceeded(format!(
                "a flipbook sheet holds at most {MAX_PIXELS} pixels: {} frames of {cw}x{ch} cells fit, this animation has more; write a frame sequence (`-o dir/%04d.png`), or fewer or smaller frames",
                MAX_PIXELS / (cw * ch)
            )));
        }
        self.frames.push(frame.clone());
        Ok(())
    }

    fn finish(self: Box<Self>) -> Result<Vec<PathBuf>> {
        let n = self.frames.len() as u32;
        // --trim: the cells hold only the box the animation ever shows (the frames are
        // cropped after the motion, which is measured on the frames as rendered)
        let trim = self
            .opts
            .trim
            .then(|| visible_box(&self.frames, self.size))
            .flatten();
        let size = match trim {
            Some((_, _, w, h)) => Size::new(w, h)?,
            None => self.size,
        };
        let (layout, m) = plan_layout(n, size, &self.opts)?;
        let v = self.opts.variants as usize;
        let per_in = n as usize / v;
        let per = m as usize / v;
        let mut frames: std::borrow::Cow<[RgbaFrame]> = if m == n {
            std::borrow::Cow::Borrowed(&self.frames)
        } else {
            self.frames
                .chunks(per_in)
                .flat_map(|row| retime(row, per, self.loop_))
                .collect()
        };
        let fps = self.fps * per as f64 / per_in as f64;
        let retimed = (m != n).then_some(Retime {
            from_frames: per_in as u32,
            from_fps: self.fps,
        });
        // Each variant row's wrap, measured on the frames the sheet holds.
        let variant_loop_quality = (v > 1 && self.loop_).then(|| {
            frames
                .chunks(per)
                .filter_map(|row| {
                    let metric: Vec<_> = row
                        .iter()
                        .map(|f| ignis_core::loopq::metric_frame_rgba(f, self.background))
                        .collect();
                    ignis_core::loopq::loop_quality(&metric).ok()
                })
                .collect::<Vec<_>>()
        });
        // The motion first: the flow is the slow part and can fail.
        let mut motion = match &self.opts.motion {
            Some(src) => Some(self.motion(src, &frames, per)?),
            None => None,
        };
        if let Some((x, y, width, height)) = trim {
            let rect = crate::read::Rect {
                x,
                y,
                width,
                height,
            };
            frames = frames
                .iter()
                .map(|f| crate::convert::crop(f, &rect))
                .collect::<Vec<_>>()
                .into();
            if let Some(mv) = motion.as_mut() {
                for f in mv.iter_mut() {
                    *f = crate::convert::crop_values(f, self.size.width, &rect);
                }
            }
        }
        let (w, h) = (size.width as usize, size.height as usize);
        let sheet_size = Size::new(layout.sheet_width, layout.sheet_height)?;
        let name_of = |p: &Path| {
            p.file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default()
        };
        let mut files = Vec::new();

        // Colour.
        let colour = sheet_of(&layout, &frames, [0u8; 4], w, h, |f| {
            let bytes = match self.opts.alpha {
                AlphaMode::Straight => convert::to_srgba8(f),
                AlphaMode::Premultiplied => {
                    let mut pre = f.clone();
                    convert::premultiply(&mut pre);
                    convert::to_srgba8(&pre)
                }
            };
            bytes
                .chunks_exact(4)
                .map(|c| [c[0], c[1], c[2], c[3]])
                .collect()
        });
        files.push(encode_temp(&self.path, |wr| {
            encode_png(wr, sheet_size, colour.as_flattened()).map_err(|e| e.to_string())
        })?);
        drop(colour);

        // Motion vectors.
        let mut mv_meta = None;
        if let Some(mv) = &motion {
            // Tile-UV units: the engines add the offset to a UV spanning one cell.
            let (cw, ch) = (layout.cell_width as f32, layout.cell_height as f32);
            let vsign = if self.opts.engine.conventions().v_up {
                -1.0
            } else {
                1.0
            };
            let to_uv = |[dx, dy]: [f32; 2]| [dx / cw, vsign * dy / ch];
            let max_abs = mv
                .iter()
                .flatten()
                .map(|&p| {
                    let [u, v] = to_uv(p);
                    u.abs().max(v.abs())
                })
                .fold(0f32, f32::max);
            let scale = motion::mv_scale_for(max_abs);
            let n0 = motion::MV_NEUTRAL;
            let sheet = sheet_of(&layout, mv, [n0, n0, 0u16], w, h, |f| {
                f.iter()
                    .map(|&p| {
                        let [u, v] = to_uv(p);
                        [
                            motion::encode_mv16(u, scale),
                            motion::encode_mv16(v, scale),
                            0,
                        ]
                    })
                    .collect()
            });
            let path = self.side_path(".mv.png");
            let flat: Vec<u16> = sheet.iter().flatten().copied().collect();
            files.push(png16_temp(
                &path,
                &layout,
                &flat,
                image::ExtendedColorType::Rgb16,
            )?);
            mv_meta = Some(MotionMeta {
                image: name_of(&path),
                scale,
                neutral: n0,
                green: if self.opts.engine.conventions().v_up { "up" } else { "down" }.into(),
                color_space: "linear".into(),
                direction: match self.opts.motion.as_ref().and_then(|m| m.description()) {
                    Some((_, d)) => d,
                    None if self.loop_ => {
                    "velocity at frame k's pixels: the mean of the motion k to k+1 and the reversed motion k to k-1, wrapping within each loop"
                    }
                    None => {
                    "velocity at frame k's pixels: the mean of the motion k to k+1 and the reversed motion k to k-1 (one side only at the first and last frame)"
                    }
                }
                .into(),
                source: self
                    .opts
                    .motion
                    .as_ref()
                    .and_then(|m| m.description())
                    .map(|(s, _)| s.to_string()),
            });
        }

        // Heat: luminance of the premultiplied colour, linear.
        let mut heat_meta = None;
        if self.opts.heat {
            let lum: Vec<Vec<f32>> = frames
                .iter()
                .map(|f| {
                    f.data()
                        .iter()
                        .map(|p| (0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]) * p[3])
                        .map(|v| if v.is_finite() { v.max(0.0) } else { 0.0 })
                        .collect()
                })
                .collect();
            let scale = lum.iter().flatten().fold(0f32, |a, &b| a.max(b)).max(1e-6);
            let sheet = sheet_of(&layout, &lum, 0u16, w, h, |f| {
                f.iter()
                    .map(|&v| (v / scale * 65535.0).round().clamp(0.0, 65535.0) as u16)
                    .collect()
            });
            let path = self.side_path(".heat.png");
            files.push(png16_temp(
                &path,
                &layout,
                &sheet,
                image::ExtendedColorType::L16,
            )?);
            heat_meta = Some(HeatMeta {
                image: name_of(&path),
                scale,
                color_space: "linear".into(),
            });
        }

        // HDR colour: linear f32, premultiplied.
        let mut hdr_image = None;
        if self.opts.hdr {
            let sheet = sheet_of(&layout, &frames, [0f32; 4], w, h, |f| {
                let mut pre = f.clone();
                convert::premultiply(&mut pre);
                pre.data().to_vec()
            });
            let path = self.path.with_extension("exr");
            let flat: Vec<f32> = sheet.iter().flatten().copied().collect();
            let img = image::Rgba32FImage::from_raw(layout.sheet_width, layout.sheet_height, flat)
                .ok_or_else(|| MediaError::encode(&path, "sheet buffer size"))?;
            // `write_to` needs Seek, which the temporary's BufWriter<File> provides.
            files.push(encode_temp(&path, |wr| {
                image::DynamicImage::ImageRgba32F(img)
                    .write_to(wr, image::ImageFormat::OpenExr)
                    .map_err(|e| e.to_string())
            })?);
            hdr_image = Some(name_of(&path));
        }

        let json_path = self.path.with_extension("json");
        let engine_settings = engine::settings(
            self.opts.engine,
            &engine::SettingsInput {
                columns: layout.columns,
                rows: layout.rows,
                frames: m,
                fps,
                loop_: self.loop_,
                variants: self.opts.variants,
                alpha: self.opts.alpha,
                mv_scale: mv_meta.as_ref().map(|mm| mm.scale),
            },
        );
        let meta = FlipbookMeta {
            image: name_of(&self.path),
            frame_width: size.width,
            frame_height: size.height,
            columns: layout.columns,
            rows: layout.rows,
            frame_count: m,
            fps,
            loop_: self.loop_,
            padding: layout.frame_x.min(layout.frame_y),
            alpha: self.opts.alpha,
            order: "row-major, top-left first".into(),
            color_space: "srgb".into(),
            cell_width: layout.cell_width,
            cell_height: layout.cell_height,
            frame_x: layout.frame_x,
            frame_y: layout.frame_y,
            variants: self.opts.variants,
            engine: self.opts.engine,
            engine_settings,
            motion_vectors: mv_meta,
            heat: heat_meta,
            hdr_image,
            retimed,
            scaled_from: self.opts.scaled_from,
            trimmed: trim.map(|(x, y, _, _)| Trimmed {
                from_width: self.size.width,
                from_height: self.size.height,
                x,
                y,
            }),
            // Measured on the pushed frames; a retimed or multi-variant sheet plays other
            // frames, so the figure would not describe it.
            loop_quality: if m == n && v == 1 {
                self.loop_quality
            } else {
                None
            },
            variant_loop_quality,
        };
        files.push(encode_temp(&json_path, |wr| {
            serde_json::to_writer_pretty(&mut *wr, &meta).map_err(|e| e.to_string())?;
            wr.write_all(b"\n").map_err(|e| e.to_string())
        })?);
        commit(files)
    }
}

/// Reads only a flipbook's JSON sidecar.
pub fn read_flipbook_meta(json_path: &Path) -> Result<FlipbookMeta> {
    // Complete a commit of a flipbook's files that a killed writer left half done.
    ignis_core::tempfiles::recover_and_clean(&super::parent_dir(json_path));
    parse_sidecar(json_path)
}

/// The JSON file at `json_path` (a bounded read of a regular file) parsed as a flipbook
/// sidecar, with nothing else done: what probing a source reads.
pub(crate) fn parse_sidecar(json_path: &Path) -> Result<FlipbookMeta> {
    let text =
        ignis_core::textfile::read_text(json_path).map_err(|e| MediaError::io(json_path, e))?;
    serde_json::from_str(&text).map_err(|e| {
        MediaError::decode(
            json_path,
            None,
            format!("not an Ignis flipbook sidecar ({e})"),
        )
    })
}

/// A flipbook's sheet, decoded, and where its frames lie on it: the frames are cut out one
/// at a time ([`Cells::frame`]), so reading a sheet as footage holds the sheet only.
pub(crate) struct Cells {
    pub(crate) meta: FlipbookMeta,
    sheet: RgbaFrame,
    size: Size,
    /// Cell size and the frame's offset inside its cell.
    cell: (u64, u64, u64, u64),
}

/// The cell size and the frame's offset inside its cell that `meta` gives, once checked
/// against a sheet of `sheet` size (`json_path` names the sidecar in the error).
pub(crate) fn checked_cells(
    meta: &FlipbookMeta,
    sheet: Size,
    json_path: &Path,
) -> Result<(u64, u64, u64, u64)> {
    let (fw, fh) = (meta.frame_width, meta.frame_height);
    // Sidecars written before cells were recorded: cell = frame + 2 × padding.
    let (cw, ch, fx, fy) = if meta.cell_width == 0 {
        (
            fw as u64 + 2 * meta.padding as u64,
            fh as u64 + 2 * meta.padding as u64,
            meta.padding as u64,
            meta.padding as u64,
        )
    } else {
        (
            meta.cell_width as u64,
            meta.cell_height as u64,
            meta.frame_x as u64,
            meta.frame_y as u64,
        )
    };
    let fits = fw > 0
        && fh > 0
        && meta.columns > 0
        && fx + fw as u64 <= cw
        && fy + fh as u64 <= ch
        && (meta.columns as u64).saturating_mul(cw) <= sheet.width as u64
        && (meta.rows as u64).saturating_mul(ch) <= sheet.height as u64
        && meta.frame_count as u64 <= meta.columns as u64 * meta.rows as u64;
    if !fits {
        return Err(MediaError::decode(
            json_path,
            None,
            format!(
                "the sidecar describes {}×{} cells of {cw}x{ch} holding {fw}x{fh} frames, which do not fit the {} sheet",
                meta.columns, meta.rows, sheet
            ),
        ));
    }
    Ok((cw, ch, fx, fy))
}

impl Cells {
    /// Reads the sidecar at `json_path` and decodes its sheet.
    pub(crate) fn open(json_path: &Path) -> Result<Cells> {
        let meta = read_flipbook_meta(json_path)?;
        let sheet = crate::read::read_image(&super::parent_dir(json_path).join(&meta.image))?;
        let cell = checked_cells(&meta, sheet.size(), json_path)?;
        let size = Size::new(meta.frame_width, meta.frame_height)?;
        Ok(Cells {
            meta,
            sheet,
            size,
            cell,
        })
    }

    /// Size of one frame.
    pub(crate) fn size(&self) -> Size {
        self.size
    }

    /// Where frame `i` lies on the sheet.
    fn rect(&self, i: u64) -> Rect {
        let (cw, ch, fx, fy) = self.cell;
        let columns = self.meta.columns as u64;
        Rect {
            x: ((i % columns) * cw + fx) as u32,
            y: ((i / columns) * ch + fy) as u32,
            width: self.meta.frame_width,
            height: self.meta.frame_height,
        }
    }

    /// Frame `i` (linear light, straight alpha: a premultiplied sheet is un-premultiplied).
    pub(crate) fn frame(&self, i: u64) -> RgbaFrame {
        let mut f = convert::crop(&self.sheet, &self.rect(i));
        if self.meta.alpha == AlphaMode::Premultiplied {
            convert::unpremultiply(&mut f);
        }
        debug_assert_eq!(f.size(), self.size());
        f
    }
}

/// Reads a flipbook back from its JSON sidecar: the metadata, every frame (linear light,
/// straight alpha; a premultiplied sheet is un-premultiplied) and the motion vectors when
/// the sheet has them (pixels, +y down).
pub fn read_flipbook(json_path: &Path) -> Result<Flipbook> {
    let cells = Cells::open(json_path)?;
    let frames: Vec<RgbaFrame> = (0..cells.meta.frame_count as u64)
        .map(|i| cells.frame(i))
        .collect();
    let (meta, sheet, (cw, ch, _, _)) = (&cells.meta, &cells.sheet, cells.cell);
    let (fw, fh) = (meta.frame_width, meta.frame_height);
    let size = cells.size();
    let dir = super::parent_dir(json_path);
    let motion = match &meta.motion_vectors {
        None => None,
        Some(mm) => {
            let path = dir.join(&mm.image);
            let img = image::open(&path)
                .map_err(|e| MediaError::decode(&path, None, e.to_string()))?
                .into_rgb16();
            if img.width() != sheet.width() || img.height() != sheet.height() {
                return Err(MediaError::decode(
                    &path,
                    None,
                    "the motion-vector sheet's size differs from the colour sheet's",
                ));
            }
            let vsign = if mm.green == "up" { -1.0 } else { 1.0 };
            let mut all = Vec::with_capacity(frames.len());
            for i in 0..meta.frame_count as u64 {
                let r = cells.rect(i);
                let mut f = Vec::with_capacity(size.pixels());
                for y in r.y..r.y + fh {
                    for x in r.x..r.x + fw {
                        let p = img.get_pixel(x, y).0;
                        f.push([
                            motion::decode_mv16(p[0], mm.scale) * cw as f32,
                            vsign * motion::decode_mv16(p[1], mm.scale) * ch as f32,
                        ]);
                    }
                }
                all.push(f);
            }
            Some(all)
        }
    };
    Ok(Flipbook {
        meta: cells.meta,
        frames,
        motion,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(n: u32, o: &FlipbookOptions) -> Result<(u32, u32)> {
        let s = Size::new(10, 10).unwrap();
        plan_layout(n, s, o).map(|(l, _)| (l.columns, l.rows))
    }

    #[test]
    fn grids() {
        let d = FlipbookOptions::default();
        assert_eq!(grid(16, &d).unwrap(), (4, 4));
        assert_eq!(grid(10, &d).unwrap(), (5, 2)); // no wasted cell
        assert_eq!(grid(61, &d).unwrap(), (9, 7)); // 2 wasted: 61×1 is too long
        assert_eq!(grid(1, &d).unwrap(), (1, 1));
        let c8 = FlipbookOptions {
            columns: Some(8),
            ..d.clone()
        };
        assert_eq!(grid(10, &c8).unwrap(), (8, 2));
        let r2 = FlipbookOptions {
            rows: Some(2),
            ..d.clone()
        };
        assert_eq!(grid(10, &r2).unwrap(), (5, 2));
        let both = FlipbookOptions {
            rows: Some(2),
            columns: Some(2),
            ..d.clone()
        };
        assert!(grid(10, &both).is_err());
    }

    #[test]
    fn max_size_pot_and_fit() {
        let s = Size::new(30, 20).unwrap();
        let o = FlipbookOptions {
            max_size: Some(128),
            padding: 1,
            ..Default::default()
        };
        // 32×22 cells: 4 columns × 5 rows fit 128×110.
        let (l, m) = plan_layout(20, s, &o).unwrap();
        assert_eq!((l.columns, l.rows, m), (4, 5, 20));
        assert!(matches!(
            plan_layout(21, s, &o),
            Err(MediaError::LimitExceeded(_))
        ));
        let pot = FlipbookOptions {
            pot: true,
            ..o.clone()
        };
        let (l, _) = plan_layout(7, s, &pot).unwrap();
        assert!(l.sheet_width.is_power_of_two() && l.sheet_height.is_power_of_two());
        assert!(l.columns.is_power_of_two() && l.rows.is_power_of_two());
        assert_eq!(l.cell_width * l.columns, l.sheet_width);
        assert!(l.cell_width >= 32 && l.cell_height >= 22);
        let fit = FlipbookOptions {
            fit_frames: true,
            ..pot
        };
        let (l, m) = plan_layout(7, s, &fit).unwrap();
        assert_eq!(m as u64, l.cells());
        let v0 = FlipbookOptions {
            variants: 0,
            ..Default::default()
        };
        assert!(matches!(
            plan_layout(8, s, &v0),
            Err(MediaError::BadParameter {
                name: "variants",
                ..
            })
        ));
        let v3 = FlipbookOptions {
            variants: 3,
            ..Default::default()
        };
        assert_eq!(grid(12, &v3).unwrap(), (4, 3));
        assert!(grid(10, &v3).is_err());
    }

    #[test]
    fn retime_keeps_period_and_ends() {
        let s = Size::new(1, 1).unwrap();
        let f: Vec<RgbaFrame> = (0..4)
            .map(|i| RgbaFrame::filled(s, [i as f32, 0.0, 0.0, 1.0]))
            .collect();
        let r = retime(&f, 8, true);
        let v: Vec<f32> = r.iter().map(|x| x.get(0, 0)[0]).collect();
        assert_eq!(v, [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0, 1.5]);
        let r = retime(&f, 7, false);
        let v: Vec<f32> = r.iter().map(|x| x.get(0, 0)[0]).collect();
        assert_eq!(v, [0.0, 0.5, 1.0, 1.5, 2.0, 2.5, 3.0]);
    }

    /// Frames that fit keep their size; frames that do not get the largest size with the
    /// same aspect that fits (one pixel more on the long side does not), with padding,
    /// power-of-two sheets and a fixed column count; a limit too small is refused.
    #[test]
    fn fit_frame_is_the_largest_that_fits() {
        let hd = Size::new(1920, 1080).unwrap();
        let (s, why) = fit_frame(20, hd, &FlipbookOptions::default()).unwrap();
        assert_eq!((s, why), (hd, None));
        let cases = [
            FlipbookOptions::default(),
            FlipbookOptions {
                max_size: Some(8192),
                padding: 3,
                ..Default::default()
            },
            FlipbookOptions {
                max_size: Some(4096),
                pot: true,
                engine: Engine::Unreal,
                ..Default::default()
            },
            FlipbookOptions {
                max_size: Some(8192),
                columns: Some(4),
                ..Default::default()
            },
        ];
        for opts in cases {
            let (s, why) = fit_frame(97, hd, &opts).unwrap();
            let why = why.expect("97 full-HD cells fit no sheet");
            assert_eq!((why.width, why.height), (1920, 1080));
            assert!(
                (s.width as f64 / s.height as f64 - 16.0 / 9.0).abs() < 0.01,
                "{s}"
            );
            let (l, m) = plan_layout(97, s, &opts).unwrap();
            assert_eq!(m, 97);
            let (max, px) = sheet_limit(&opts);
            assert!(l.sheet_width <= max && l.sheet_height <= max);
            assert!(l.sheet_width as u64 * l.sheet_height as u64 <= px);
            let pad = opts.padding.max(opts.engine.conventions().min_padding);
            assert_eq!(
                (s.width + 2 * pad) % 4,
                0,
                "{s}: cell pitch not whole blocks"
            );
            assert_eq!(
                (s.height + 2 * pad) % 4,
                0,
                "{s}: cell pitch not whole blocks"
            );
            // Largest but for the block alignment (at most 15 + 3 pixels on the long side).
            let bigger = scaled_to(hd, s.width + 19);
            assert!(plan_layout(97, bigger, &opts).is_err(), "{bigger} fits too");
        }
        let tiny = FlipbookOptions {
            max_size: Some(100),
            ..Default::default()
        };
        match fit_frame(97, hd, &tiny) {
            Err(MediaError::LimitExceeded(m)) => assert!(m.contains("raise --max-size"), "{m}"),
            other => panic!("{other:?}"),
        }
    }

    /// Too many cells for the sheet's pixel cap (not its sides): the message counts the
    /// cells the cap allows and does not offer a larger --max-size, which would not help.
    #[test]
    fn the_pixel_cap_is_counted_in_the_refusal() {
        let hd = Size::new(1280, 720).unwrap();
        match plan_layout(103, hd, &FlipbookOptions::default()) {
            Err(MediaError::LimitExceeded(m)) => {
                let fit = MAX_PIXELS / (1280 * 720);
                assert!(m.contains(&format!("at most {fit} cells fit")), "{m}");
                assert!(!m.contains("--max-size"), "{m}");
                assert!(m.contains("frame sequence"), "{m}");
            }
            other => panic!("{other:?}"),
        }
        let small = FlipbookOptions {
            max_size: Some(4096),
            ..Default::default()
        };
        match plan_layout(103, hd, &small) {
            Err(MediaError::LimitExceeded(m)) => {
                assert!(m.contains("at most 15 cells fit"), "{m}");
                assert!(m.contains("a larger --max-size"), "{m}");
            }
            other => panic!("{other:?}"),
        }
    }
}
