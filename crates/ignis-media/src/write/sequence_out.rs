//! PNG (8-bit sRGB, straight alpha) and EXR (linear f32, premultiplied) sequences.
//!
//! A directory destination is filled with `0000.png`, `0001.png`, … (or `.exr`); a pattern
//! destination `frames/f_%04d.png` numbers from 0 the same way (or from
//! [`super::WriteOptions::first_frame`]).

use std::io::Write;
use std::path::{Path, PathBuf};

use ignis_core::RgbaFrame;

use super::{encode_png, parent_dir, Sink};
use crate::convert;
use crate::error::{MediaError, Result};
use crate::read::Pattern;

pub(crate) struct SequenceSink {
    exr: bool,
    pattern: Pattern,
    final_dir: PathBuf,
    /// A fresh temporary directory renamed to `final_dir` at the end, when `final_dir` did
    /// not exist; otherwise files are staged under hidden names inside `final_dir`.
    temp_dir: Option<tempfile::TempDir>,
    /// (staged path, final path) of each frame written.
    written: Vec<(PathBuf, PathBuf)>,
    finished: bool,
    /// Number of the first frame's file.
    first: u64,
}

impl SequenceSink {
    pub(crate) fn new(path: &Path, exr: bool, first: u64) -> Result<SequenceSink> {
        let ext = if exr { "exr" } else { "png" };
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        let (final_dir, pattern) = if name.contains('%') {
            let p = Pattern::parse(&name).ok_or_else(|| {
                MediaError::bad("path", format!("`{name}` is not a pattern like %04d.{ext}"))
            })?;
            (parent_dir(path), p)
        } else {
            (
                path.to_path_buf(),
                Pattern {
                    prefix: String::new(),
                    width: 4,
                    suffix: format!(".{ext}"),
                },
            )
        };
        let temp_dir = if final_dir.is_dir() {
            None
        } else {
            let parent = parent_dir(&final_dir);
            std::fs::create_dir_all(&parent).map_err(|e| MediaError::io(&parent, e))?;
            let dir_name = final_dir
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
                .unwrap_or_default();
            let mut b = tempfile::Builder::new();
            let prefix = format!(".{dir_name}.");
            b.prefix(&prefix).suffix(".partial");
            // an ordinary directory (0755), not tempfile's private 0700
            #[cfg(unix)]
            b.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o755));
            Some(
                b.tempdir_in(&parent)
                    .map_err(|e| MediaError::io(&parent, e))?,
            )
        };
        Ok(SequenceSink {
            exr,
            pattern,
            final_dir,
            temp_dir,
            written: Vec::new(),
            finished: false,
            first,
        })
    }

    fn write_frame(&self, frame: &RgbaFrame, staged: &Path) -> Result<()> {
        let file = std::fs::File::create(staged).map_err(|e| MediaError::io(staged, e))?;
        let mut w = std::io::BufWriter::new(file);
        if self.exr {
            let mut pre = frame.clone();
            convert::premultiply(&mut pre);
            let flat: Vec<f32> = pre.data().iter().flatten().copied().collect();
            let img = image::Rgba32FImage::from_raw(frame.width(), frame.height(), flat)
                .expect("frame size");
            img.write_to(&mut w, image::ImageFormat::OpenExr)
                .map_err(|e| MediaError::encode(staged, e.to_string()))?;
        } else {
            let rgba = convert::to_srgba8(frame);
            encode_png(&mut w, frame.size(), &rgba)
                .map_err(|e| MediaError::encode(staged, e.to_string()))?;
        }
        w.flush().map_err(|e| MediaError::io(staged, e))
    }
}

impl Sink for SequenceSink {
    fn push(&mut self, frame: &RgbaFrame) -> Result<()> {
        let name = self.pattern.format(self.first + self.written.len() as u64);
        let final_path = self.final_dir.join(&name);
        let staged = match &self.temp_dir {
            Some(t) => t.path().join(&name),
            None => self.final_dir.join(format!(".{name}.partial")),
        };
        // Record first so that a half-written file is cleaned up on drop.
        self.written.push((staged.clone(), final_path));
        self.write_frame(frame, &staged)
    }

    fn finish(mut self: Box<Self>) -> Result<Vec<PathBuf>> {
        let finals: Vec<PathBuf> = self.written.iter().map(|(_, f)| f.clone()).collect();
        match self.temp_dir.take() {
            Some(t) => {
                let staged_dir = t.keep();
                if let Err(e) = std::fs::rename(&staged_dir, &self.final_dir) {
                    let _ = std::fs::remove_dir_all(&staged_dir);
                    return Err(MediaError::io(&self.final_dir, e));
                }
            }
            None => {
                for (staged, fin) in &self.written {
                    std::fs::rename(staged, fin).map_err(|e| MediaError::io(fin, e))?;
                }
            }
        }
        self.finished = true;
        Ok(finals)
    }
}

impl Drop for SequenceSink {
    fn drop(&mut self) {
        if !self.finished && self.temp_dir.is_none() {
            for (staged, _) in &self.written {
                let _ = std::fs::remove_file(staged);
            }
        }
        // A `TempDir` still held removes itself.
    }
}
