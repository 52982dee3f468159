//! Flipbooks: every frame on one sprite-sheet PNG, left to right, top to bottom, starting
//! top-left (the layout Unity's Texture Sheet Animation, Unreal's SubUV and Godot's
//! particle animation expect), plus a JSON sidecar next to it (`fire.png` → `fire.json`).
//!
//! Each cell is the frame plus `padding` pixels on every side, filled by repeating the
//! frame's edge pixels ("bleeding") so texture filtering and mipmaps do not pull in
//! neighbouring frames. Cells after the last frame are transparent black.
//!
//! The PNG is 8-bit sRGB. Alpha is `straight` by default; `premultiplied` multiplies
//! colour by alpha in linear light before sRGB encoding (what an sRGB texture sampled with
//! `One, OneMinusSrcAlpha` blending needs).

use std::io::Write;
use std::path::{Path, PathBuf};

use ignis_core::frame::MAX_PIXELS;
use ignis_core::loopq::LoopQuality;
use ignis_core::{RgbaFrame, Size};

use super::{encode_png, temp_file_for, Sink, WriteOptions};
use crate::convert;
use crate::error::{MediaError, Result};

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

/// Sprite-sheet layout. `Default`: near-square grid, no padding, straight alpha.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FlipbookOptions {
    /// Columns; `None` = `ceil(sqrt(frames))` (or from `rows`).
    pub columns: Option<u32>,
    /// Rows; `None` = `ceil(frames / columns)`.
    pub rows: Option<u32>,
    /// Pixels of edge bleed around each frame, inside its cell (default 0).
    pub padding: u32,
    /// Straight or premultiplied colour in the PNG (default straight).
    pub alpha: AlphaMode,
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
    /// Bleed pixels on each side of each frame; a cell is `frame + 2 * padding` wide/high.
    pub padding: u32,
    /// `"straight"` or `"premultiplied"`.
    pub alpha: AlphaMode,
    /// Always `"row-major, top-left first"`.
    pub order: String,
    /// Always `"srgb"` (8-bit sRGB-encoded colour; alpha is linear).
    pub color_space: String,
    /// Seam and ghost of the sheet's frames played as a loop, measured on the frames
    /// written ([`ignis_core::loopq`]); present when `loop` is true.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub loop_quality: Option<LoopQuality>,
}

/// A flipbook read back by [`read_flipbook`]: its sidecar and its frames (linear light,
/// straight alpha, whatever the sheet's alpha mode).
#[derive(Clone, Debug)]
pub struct Flipbook {
    pub meta: FlipbookMeta,
    pub frames: Vec<RgbaFrame>,
}

pub(crate) fn grid(n: u32, opts: &FlipbookOptions) -> Result<(u32, u32)> {
    let div_ceil = |a: u32, b: u32| a.div_ceil(b.max(1));
    let (c, r) = match (opts.columns, opts.rows) {
        (Some(0), _) | (_, Some(0)) => {
            return Err(MediaError::bad("flipbook", "columns and rows must be ≥ 1"))
        }
        (Some(c), Some(r)) => (c, r),
        (Some(c), None) => (c, div_ceil(n, c)),
        (None, Some(r)) => (div_ceil(n, r), r),
        (None, None) => {
            let c = (n as f64).sqrt().ceil() as u32;
            (c.max(1), div_ceil(n, c.max(1)))
        }
    };
    if (c as u64) * (r as u64) < n as u64 {
        return Err(MediaError::bad(
            "flipbook",
            format!(
                "{c} columns × {r} rows hold {} frames, but there are {n}",
                c as u64 * r as u64
            ),
        ));
    }
    Ok((c, r.max(1)))
}

pub(crate) struct FlipbookSink {
    path: PathBuf,
    size: Size,
    opts: FlipbookOptions,
    fps: f64,
    loop_: bool,
    loop_quality: Option<LoopQuality>,
    /// Each frame as 8-bit sRGB RGBA in the sheet's alpha mode.
    frames: Vec<Vec<u8>>,
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
        Ok(FlipbookSink {
            path: path.to_path_buf(),
            size,
            opts: opts.flipbook,
            fps: opts.fps,
            loop_: opts.loop_,
            loop_quality: None,
            frames: Vec::new(),
        })
    }

    fn cell(&self) -> (u32, u32) {
        (
            self.size.width + 2 * self.opts.padding,
            self.size.height + 2 * self.opts.padding,
        )
    }
}

impl Sink for FlipbookSink {
    fn set_loop_quality(&mut self, quality: LoopQuality) {
        self.loop_quality = Some(quality);
    }

    fn push(&mut self, frame: &RgbaFrame) -> Result<()> {
        let (cw, ch) = self.cell();
        let area = (self.frames.len() as u64 + 1) * cw as u64 * ch as u64;
        if area > MAX_PIXELS {
            return Err(MediaError::LimitExceeded(format!(
                "a flipbook of {} frames of {cw}x{ch} cells exceeds {MAX_PIXELS} pixels; use fewer or smaller frames",
                self.frames.len() + 1
            )));
        }
        let bytes = match self.opts.alpha {
            AlphaMode::Straight => convert::to_srgba8(frame),
            AlphaMode::Premultiplied => {
                let mut pre = frame.clone();
                convert::premultiply(&mut pre);
                convert::to_srgba8(&pre)
            }
        };
        self.frames.push(bytes);
        Ok(())
    }

    fn finish(self: Box<Self>) -> Result<Vec<PathBuf>> {
        let n = self.frames.len() as u32;
        let (cols, rows) = grid(n, &self.opts)?;
        let (cw, ch) = self.cell();
        let sheet = Size::new(cols * cw, rows * ch).map_err(|e| {
            MediaError::LimitExceeded(format!(
                "flipbook sheet of {cols}×{rows} cells of {cw}x{ch}: {e}"
            ))
        })?;
        let (w, h, p) = (
            self.size.width as usize,
            self.size.height as usize,
            self.opts.padding as usize,
        );
        let sw = sheet.width as usize;
        let mut pixels = vec![0u8; sheet.pixels() * 4];
        for (i, f) in self.frames.iter().enumerate() {
            let (ox, oy) = (
                (i % cols as usize) * cw as usize,
                (i / cols as usize) * ch as usize,
            );
            for cy in 0..ch as usize {
                let sy = cy.saturating_sub(p).min(h - 1);
                let dst_row = (oy + cy) * sw + ox;
                for cx in 0..cw as usize {
                    let sx = cx.saturating_sub(p).min(w - 1);
                    let s = (sy * w + sx) * 4;
                    let d = (dst_row + cx) * 4;
                    pixels[d..d + 4].copy_from_slice(&f[s..s + 4]);
                }
            }
        }
        let json_path = self.path.with_extension("json");
        let meta = FlipbookMeta {
            image: self
                .path
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default(),
            frame_width: self.size.width,
            frame_height: self.size.height,
            columns: cols,
            rows,
            frame_count: n,
            fps: self.fps,
            loop_: self.loop_,
            padding: self.opts.padding,
            alpha: self.opts.alpha,
            order: "row-major, top-left first".into(),
            color_space: "srgb".into(),
            loop_quality: self.loop_quality,
        };
        let png_tmp = temp_file_for(&self.path)?;
        {
            let mut w = std::io::BufWriter::new(png_tmp.as_file());
            encode_png(&mut w, sheet, &pixels)
                .map_err(|e| MediaError::encode(&self.path, e.to_string()))?;
            w.flush().map_err(|e| MediaError::io(png_tmp.path(), e))?;
        }
        let json_tmp = temp_file_for(&json_path)?;
        {
            let mut w = std::io::BufWriter::new(json_tmp.as_file());
            serde_json::to_writer_pretty(&mut w, &meta)
                .map_err(|e| MediaError::encode(&json_path, e.to_string()))?;
            w.write_all(b"\n")
                .and_then(|_| w.flush())
                .map_err(|e| MediaError::io(json_tmp.path(), e))?;
        }
        // PNG and JSON as one unit (a journal completes an interrupted commit).
        super::commit_temps(
            &super::parent_dir(&self.path),
            vec![(png_tmp, self.path.clone()), (json_tmp, json_path.clone())],
        )?;
        Ok(vec![self.path.clone(), json_path])
    }
}

/// Reads a flipbook back from its JSON sidecar: the metadata and every frame (linear
/// light, straight alpha; a premultiplied sheet is un-premultiplied).
pub fn read_flipbook(json_path: &Path) -> Result<Flipbook> {
    // Complete a PNG + JSON commit a killed writer left half done.
    ignis_core::tempfiles::recover_and_clean(&super::parent_dir(json_path));
    let text = std::fs::read(json_path).map_err(|e| MediaError::io(json_path, e))?;
    let meta: FlipbookMeta = serde_json::from_slice(&text)
        .map_err(|e| MediaError::decode(json_path, None, format!("not a flipbook sidecar: {e}")))?;
    let image_path = super::parent_dir(json_path).join(&meta.image);
    let sheet = crate::read::read_image(&image_path)?;
    let fw = meta.frame_width;
    let fh = meta.frame_height;
    let (cw, ch) = (
        fw as u64 + 2 * meta.padding as u64,
        fh as u64 + 2 * meta.padding as u64,
    );
    let fits = fw > 0
        && fh > 0
        && meta.columns as u64 * cw <= sheet.width() as u64
        && meta.rows as u64 * ch <= sheet.height() as u64
        && meta.frame_count as u64 <= meta.columns as u64 * meta.rows as u64;
    if !fits {
        return Err(MediaError::decode(
            json_path,
            None,
            format!(
                "the sidecar describes {}×{} cells of {fw}x{fh} + {} padding, which do not fit the {} sheet",
                meta.columns,
                meta.rows,
                meta.padding,
                sheet.size()
            ),
        ));
    }
    let size = Size::new(fw, fh)?;
    let mut frames = Vec::with_capacity(meta.frame_count as usize);
    for i in 0..meta.frame_count as u64 {
        let x0 = (i % meta.columns as u64) * cw + meta.padding as u64;
        let y0 = (i / meta.columns as u64) * ch + meta.padding as u64;
        let rect = crate::read::Rect {
            x: x0 as u32,
            y: y0 as u32,
            width: fw,
            height: fh,
        };
        let mut f = convert::crop(&sheet, &rect);
        if meta.alpha == AlphaMode::Premultiplied {
            convert::unpremultiply(&mut f);
        }
        debug_assert_eq!(f.size(), size);
        frames.push(f);
    }
    Ok(Flipbook { meta, frames })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grids() {
        let d = FlipbookOptions::default();
        assert_eq!(grid(16, &d).unwrap(), (4, 4));
        assert_eq!(grid(10, &d).unwrap(), (4, 3));
        assert_eq!(grid(1, &d).unwrap(), (1, 1));
        assert_eq!(
            grid(
                10,
                &FlipbookOptions {
                    columns: Some(8),
                    ..d
                }
            )
            .unwrap(),
            (8, 2)
        );
        assert_eq!(
            grid(10, &FlipbookOptions { rows: Some(2), ..d }).unwrap(),
            (5, 2)
        );
        assert!(grid(
            10,
            &FlipbookOptions {
                rows: Some(2),
                columns: Some(2),
                ..d
            }
        )
        .is_err());
    }
}
