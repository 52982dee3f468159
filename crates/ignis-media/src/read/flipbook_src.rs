//! An Ignis flipbook (a sprite sheet and its JSON sidecar) read as footage: its frames in
//! order at its own frame rate, so a flipbook can be previewed as a video (`ignis convert
//! loop.png -o loop.mp4`), described (`ignis info`) or looped again like any clip.
//!
//! A sheet is read as a flipbook when the JSON beside it (same name, `.json`) is a flipbook
//! sidecar naming that sheet; the sidecar itself may be given instead. Any other image is
//! one still, as before.

use std::path::{Path, PathBuf};

use ignis_core::RgbaFrame;

use super::{sequence, Decoder, FrameSource, Probed, SourceInfo};
use crate::error::{MediaError, Result};
use crate::write::flipbook::{checked_cells, parse_sidecar, Cells, FlipbookMeta};

/// The sidecar of the sheet `sheet`, when the JSON beside it describes it.
pub(crate) fn sidecar_of_sheet(sheet: &Path) -> Option<(PathBuf, FlipbookMeta)> {
    let json = sheet.with_extension("json");
    if json == sheet || !std::fs::metadata(&json).is_ok_and(|m| m.is_file()) {
        return None;
    }
    let meta = parse_sidecar(&json).ok()?;
    let name = sheet.file_name()?.to_str()?;
    (meta.image == name).then_some((json, meta))
}

/// A flipbook's sheet and sidecar when `path` is either (for fingerprinting a source).
pub(crate) fn files(path: &Path) -> Option<Vec<PathBuf>> {
    if let Some((json, _)) = sidecar_of_sheet(path) {
        return Some(vec![path.to_path_buf(), json]);
    }
    if !std::fs::metadata(path).is_ok_and(|m| m.is_file()) {
        return None;
    }
    let mut magic = [0u8; 16];
    let n = std::io::Read::read(&mut std::fs::File::open(path).ok()?, &mut magic).ok()?;
    if !looks_like_json(&magic[..n]) {
        return None;
    }
    let meta = parse_sidecar(path).ok()?;
    let sheet = ignis_core::atomic::parent_dir(path).join(&meta.image);
    Some(vec![sheet, path.to_path_buf()])
}

/// Whether `magic`, a file's first bytes, can start a JSON object.
pub(crate) fn looks_like_json(magic: &[u8]) -> bool {
    magic
        .iter()
        .find(|b| !b.is_ascii_whitespace())
        .is_some_and(|&b| b == b'{')
}

/// Probes the sidecar `json` given as the source `path`.
pub(crate) fn probe_sidecar(path: &Path) -> Result<Probed> {
    let meta = parse_sidecar(path).map_err(|e| match e {
        MediaError::Decode { msg, .. } => MediaError::decode(
            path,
            None,
            format!(
                "{msg}; footage is a video, an image, a flipbook, a directory of frames or a \
                 pattern such as frames/%04d.png"
            ),
        ),
        other => other,
    })?;
    let sheet = ignis_core::atomic::parent_dir(path).join(&meta.image);
    probe(path, &sheet, path, meta)
}

/// The flipbook whose sheet is `sheet` and sidecar `json`, given as `path`.
pub(crate) fn probe(path: &Path, sheet: &Path, json: &Path, meta: FlipbookMeta) -> Result<Probed> {
    let sheet_size = sequence::dimensions(sheet)?;
    checked_cells(&meta, sheet_size, json)?;
    let size = ignis_core::Size::new(meta.frame_width, meta.frame_height)
        .map_err(|e| MediaError::decode(json, None, e.to_string()))?;
    if meta.frame_count == 0 {
        return Err(MediaError::decode(
            json,
            None,
            "the flipbook holds no frames",
        ));
    }
    if !(meta.fps > 0.0 && meta.fps.is_finite() && meta.fps <= 1000.0) {
        return Err(MediaError::decode(
            json,
            None,
            format!("the sidecar's fps is {}; it must be in (0, 1000]", meta.fps),
        ));
    }
    let rows = if meta.variants > 1 {
        format!(", {} loops as rows", meta.variants)
    } else {
        String::new()
    };
    let codec = format!(
        "ignis flipbook ({} frames in {}x{} cells of the {sheet_size} sheet{rows})",
        meta.frame_count, meta.columns, meta.rows
    );
    Ok(Probed::Flipbook(
        SourceInfo {
            size,
            fps: meta.fps,
            frame_count: Some(meta.frame_count as u64),
            codec,
            decoder: Decoder::Flipbook,
            path: path.to_path_buf(),
            anamorphic: None,
            rate_stated: true,
        },
        json.to_path_buf(),
    ))
}

/// The frames of a flipbook from `start` on, cut from its decoded sheet one at a time.
pub(crate) struct FlipbookSource {
    cells: Cells,
    next: u64,
}

impl FlipbookSource {
    pub(crate) fn start(json: &Path, start: u64) -> Result<FlipbookSource> {
        Ok(FlipbookSource {
            cells: Cells::open(json)?,
            next: start,
        })
    }
}

impl FrameSource for FlipbookSource {
    fn next_frame(&mut self) -> Option<Result<RgbaFrame>> {
        if self.next >= self.cells.meta.frame_count as u64 {
            return None;
        }
        let f = self.cells.frame(self.next);
        self.next += 1;
        Some(Ok(f))
    }
}
