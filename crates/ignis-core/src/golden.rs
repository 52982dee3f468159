//! Golden float images for the workspace's tests (imageproc's `truth/` style): a test
//! renders a tiny frame and compares it, channel by channel, with a stored one within a
//! stated maximum absolute error. A rendering change larger than that fails the test.
//!
//! File format (`.f32`, written by [`write_rgba`]): the ASCII header
//! `IGNIS-F32 <width> <height> 4\n`, then `width · height · 4` little-endian `f32`
//! values, rows top to bottom, `[r, g, b, a]` per pixel. Readable with numpy:
//! `np.fromfile(path, '<f4', offset=len(header)).reshape(h, w, 4)`.
//!
//! [`check_rgba`] with `UPDATE_GOLDEN=1` in the environment (re)writes the golden and
//! passes; a missing golden is written and reported as a failure (check it, then re-run).

use crate::{RgbaFrame, Size};
use std::path::Path;

/// The header's first word.
const MAGIC: &str = "IGNIS-F32";
/// Largest golden accepted (pixels): goldens are meant to be tiny.
const MAX_PIXELS: usize = 1 << 20;

/// Why a golden comparison failed.
#[derive(Debug, thiserror::Error)]
pub enum GoldenError {
    /// The golden file could not be read or written.
    #[error("golden {path}: {source}")]
    Io {
        path: String,
        #[source]
        source: std::io::Error,
    },
    /// The file is not a golden image of this format.
    #[error("golden {path}: {reason}; delete it and re-run with UPDATE_GOLDEN=1")]
    Format { path: String, reason: String },
    /// The golden was missing; it has been written from the current output.
    #[error("golden {path} was missing and has been written; check it and re-run")]
    Written { path: String },
    /// The frame differs from the golden.
    #[error(
        "golden {path}: {what}; if the change is intended, re-run with UPDATE_GOLDEN=1 and \
         look at the new golden"
    )]
    Mismatch { path: String, what: String },
}

/// Writes `frame` as a golden image (see the module docs), atomically.
pub fn write_rgba(path: &Path, frame: &RgbaFrame) -> Result<(), GoldenError> {
    let header = format!("{MAGIC} {} {} 4\n", frame.width(), frame.height());
    let mut bytes = Vec::with_capacity(header.len() + frame.data().len() * 16);
    bytes.extend_from_slice(header.as_bytes());
    for px in frame.data() {
        for c in px {
            bytes.extend_from_slice(&c.to_le_bytes());
        }
    }
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| io_error(path, e))?;
    }
    crate::atomic::write_bytes(path, &bytes).map_err(|e| io_error(path, e))
}

/// Reads a golden image written by [`write_rgba`].
pub fn read_rgba(path: &Path) -> Result<RgbaFrame, GoldenError> {
    let bytes = std::fs::read(path).map_err(|e| io_error(path, e))?;
    let bad = |reason: String| GoldenError::Format {
        path: path.display().to_string(),
        reason,
    };
    let end = bytes
        .iter()
        .take(64)
        .position(|&b| b == b'\n')
        .ok_or_else(|| bad("no header line".into()))?;
    let header = std::str::from_utf8(&bytes[..end]).map_err(|_| bad("header not text".into()))?;
    let fields: Vec<&str> = header.split(' ').collect();
    let dims = match fields.as_slice() {
        [MAGIC, w, h, "4"] => w.parse::<u32>().ok().zip(h.parse::<u32>().ok()),
        _ => None,
    };
    let (w, h) = dims.ok_or_else(|| bad(format!("header {header:?} is not `{MAGIC} W H 4`")))?;
    let size = Size::new(w, h).map_err(|e| bad(e.to_string()))?;
    if size.pixels() > MAX_PIXELS {
        return Err(bad(format!("{w}×{h} is larger than a golden may be")));
    }
    let body = &bytes[end + 1..];
    if body.len() != size.pixels() * 16 {
        return Err(bad(format!(
            "{} data bytes for {w}×{h}×4 f32 (expected {})",
            body.len(),
            size.pixels() * 16
        )));
    }
    let data = body
        .chunks_exact(16)
        .map(|px| {
            std::array::from_fn(|c| f32::from_le_bytes(px[4 * c..4 * c + 4].try_into().unwrap()))
        })
        .collect();
    RgbaFrame::from_vec(size, data).map_err(|e| bad(e.to_string()))
}

/// The largest absolute difference between two frames of one size, over every channel of
/// every pixel, and where it is (`x`, `y`, channel). A NaN on either side counts as an
/// infinite difference unless both are NaN.
pub fn max_abs_difference(a: &RgbaFrame, b: &RgbaFrame) -> (f32, (u32, u32, usize)) {
    let mut worst = (0.0f32, (0, 0, 0));
    let w = a.width().max(1);
    for (i, (p, q)) in a.data().iter().zip(b.data()).enumerate() {
        for c in 0..4 {
            let d = match (p[c].is_nan(), q[c].is_nan()) {
                (true, true) => 0.0,
                (false, false) => (p[c] - q[c]).abs(),
                _ => f32::INFINITY,
            };
            if d > worst.0 {
                worst = (d, (i as u32 % w, i as u32 / w, c));
            }
        }
    }
    worst
}

/// Compares `frame` with the golden at `path`: passes when every channel of every pixel is
/// within `max_abs` of it. Returns the largest difference found. With `UPDATE_GOLDEN` set
/// the golden is rewritten from `frame` first; a missing golden is written and reported
/// as [`GoldenError::Written`].
pub fn check_rgba(path: &Path, frame: &RgbaFrame, max_abs: f32) -> Result<f32, GoldenError> {
    let update = std::env::var_os("UPDATE_GOLDEN").is_some_and(|v| !v.is_empty() && v != "0");
    compare(path, frame, max_abs, update)
}

/// [`check_rgba`] with the update switch as an argument.
fn compare(path: &Path, frame: &RgbaFrame, max_abs: f32, update: bool) -> Result<f32, GoldenError> {
    if update || !path.exists() {
        write_rgba(path, frame)?;
        if !update {
            return Err(GoldenError::Written {
                path: path.display().to_string(),
            });
        }
    }
    let golden = read_rgba(path)?;
    let mismatch = |what: String| GoldenError::Mismatch {
        path: path.display().to_string(),
        what,
    };
    if golden.size() != frame.size() {
        return Err(mismatch(format!(
            "size {}×{} but the golden is {}×{}",
            frame.width(),
            frame.height(),
            golden.width(),
            golden.height()
        )));
    }
    let (worst, (x, y, c)) = max_abs_difference(frame, &golden);
    if !(worst <= max_abs) {
        return Err(mismatch(format!(
            "max abs difference {worst:e} > tolerance {max_abs:e}, at pixel ({x}, {y}) \
             channel {c}: {} vs golden {}",
            frame.get(x, y)[c],
            golden.get(x, y)[c]
        )));
    }
    Ok(worst)
}

fn io_error(path: &Path, source: std::io::Error) -> GoldenError {
    GoldenError::Io {
        path: path.display().to_string(),
        source,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame() -> RgbaFrame {
        let size = Size::new(5, 3).unwrap();
        let data = (0..15)
            .map(|i| [i as f32 * 0.25, -1.5, 1e-7 * i as f32, f32::MAX])
            .collect();
        RgbaFrame::from_vec(size, data).unwrap()
    }

    #[test]
    fn round_trip_and_tolerance() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("g.f32");
        let f = frame();
        write_rgba(&path, &f).unwrap();
        let back = read_rgba(&path).unwrap();
        assert_eq!(back.size(), f.size());
        for (a, b) in back.data().iter().zip(f.data()) {
            assert_eq!(a.map(f32::to_bits), b.map(f32::to_bits));
        }
        assert_eq!(compare(&path, &f, 0.0, false).unwrap(), 0.0);
        // a change within the tolerance passes, beyond it fails and names the pixel
        let mut g = f.clone();
        g.set(3, 2, [3.25 + 1e-3, -1.5, 0.0, f32::MAX]);
        let ok = compare(&path, &g, 2e-3, false).unwrap();
        assert!((ok - 1e-3).abs() < 1e-5, "{ok}");
        let err = compare(&path, &g, 1e-4, false).unwrap_err().to_string();
        assert!(err.contains("pixel (3, 2) channel 0"), "{err}");
        // NaN against a number fails
        g.set(0, 0, [f32::NAN, -1.5, 0.0, f32::MAX]);
        assert!(compare(&path, &g, 1.0, false).is_err());
    }

    #[test]
    fn bad_files_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("g.f32");
        for bytes in [
            &b"IGNIS-F32 2 2 4\n0123"[..],
            b"P6 2 2 4\n",
            b"IGNIS-F32 99999999 99999999 4\n",
            b"no newline",
        ] {
            std::fs::write(&path, bytes).unwrap();
            let err = read_rgba(&path).unwrap_err();
            assert!(matches!(err, GoldenError::Format { .. }), "{err}");
        }
        let missing = dir.path().join("missing.f32");
        assert!(matches!(
            read_rgba(&missing).unwrap_err(),
            GoldenError::Io { .. }
        ));
        // a missing golden is written, and the check fails
        let f = frame();
        let err = compare(&missing, &f, 0.0, false).unwrap_err();
        assert!(matches!(err, GoldenError::Written { .. }), "{err}");
        assert_eq!(compare(&missing, &f, 0.0, false).unwrap(), 0.0);
    }
}
