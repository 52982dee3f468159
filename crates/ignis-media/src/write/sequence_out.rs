//! PNG (8-bit sRGB, straight alpha) and EXR (linear f32, premultiplied) sequences. An EXR
//! frame states the sequence's rate in the standard `framesPerSecond` attribute (PNG has
//! no such field), which reading it back takes ([`crate::SourceInfo::rate_stated`]).
//!
//! A directory destination is filled with `0000.png`, `0001.png`, … (or `.exr`); a pattern
//! destination `frames/f_%04d.png` numbers from 0 the same way (or from
//! [`super::WriteOptions::first_frame`]).

use std::io::Write;
use std::path::{Path, PathBuf};

use ignis_core::atomic::StagingDir;
use ignis_core::RgbaFrame;

use super::{encode_png, parent_dir, Sink};
use crate::convert;
use crate::error::{MediaError, Result};
use crate::read::Pattern;

pub(crate) struct SequenceSink {
    exr: bool,
    pattern: Pattern,
    final_dir: PathBuf,
    /// The fresh temporary directory the frames are staged in (see `commit_sequence`);
    /// `None` once finished. Dropping it removes every staged frame.
    temp_dir: Option<StagingDir>,
    /// (staged path, final path) of each frame written.
    written: Vec<(PathBuf, PathBuf)>,
    /// Number of the first frame's file.
    first: u64,
    /// The rate stated in each EXR frame's `framesPerSecond` (`None`: one not stated).
    fps: Option<(i32, u32)>,
}

/// `fps` as the rational an EXR header stores it as: exactly where a small denominator
/// (or NTSC's 1001) gives it, as 24000/1001 or 2997/100; `None` otherwise.
pub(crate) fn exr_rational(fps: f64) -> Option<(i32, u32)> {
    [1u32, 1001, 2, 4, 5, 8, 10, 100, 1000]
        .into_iter()
        .find_map(|d| {
            let n = fps * f64::from(d);
            let r = n.round();
            ((n - r).abs() <= 1e-6 * r.max(1.0) && r >= 1.0 && r <= f64::from(i32::MAX))
                .then_some((r as i32, d))
        })
}

/// The directory a sequence at `path` (a directory, or a pattern `dir/%04d.png`) fills and
/// its file-name pattern; refuses a bad pattern or a destination that is not a directory.
/// Creates nothing.
pub(crate) fn destination(path: &Path, exr: bool) -> Result<(PathBuf, Pattern)> {
    let ext = if exr { "exr" } else { "png" };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let (final_dir, pattern) =
        if name.contains('%') || crate::read::sequence::is_hash_pattern(&name) {
            let p = Pattern::parse(&name).ok_or_else(|| {
                MediaError::bad(
                    "path",
                    format!(
                    "`{name}` is not a pattern like %04d.{ext} or ####.{ext} (one `%Nd` or run \
                     of `#`, at most 20 digits)"
                ),
                )
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
    if let Ok(m) = std::fs::metadata(&final_dir) {
        if !m.is_dir() {
            return Err(MediaError::bad(
                "output",
                format!(
                    "{} exists and is not a directory; a frame sequence needs a directory \
                         (choose another output path)",
                    final_dir.display()
                ),
            ));
        }
    }
    check_existing_frames(&final_dir, &pattern)?;
    Ok((final_dir, pattern))
}

/// Refuses a destination whose existing files named like its frames include one that
/// cannot be replaced ([`super::check_regular_target`]): a device, or a frame the running
/// command reads — a sequence converted or looped onto itself.
fn check_existing_frames(final_dir: &Path, pattern: &Pattern) -> Result<()> {
    let Ok(rd) = std::fs::read_dir(final_dir) else {
        return Ok(());
    };
    for e in rd.flatten() {
        let name = e.file_name();
        if name.to_str().is_some_and(|n| pattern.matches(n).is_some()) {
            if let Some(input) = ignis_core::atomic::input_at(&e.path()) {
                return Err(MediaError::bad(
                    "output",
                    format!(
                        "{} is named like this sequence's frames and is {} this command \
                         reads: the frames would be written over it. Write them to another \
                         directory or pattern",
                        e.path().display(),
                        if input == e.path() {
                            "a frame".to_string()
                        } else {
                            format!("the same file as {}, which", input.display())
                        }
                    ),
                ));
            }
            super::check_regular_target(&e.path())?;
        }
    }
    Ok(())
}

impl SequenceSink {
    pub(crate) fn new(path: &Path, exr: bool, first: u64, fps: f64) -> Result<SequenceSink> {
        let (final_dir, pattern) = destination(path, exr)?;
        // Frames always go into a fresh hidden directory beside the destination
        // (`.<dir>.ignis-tmp-<pid>.<n>.dir`, removed by a later run if this one is killed).
        let temp_dir = Some(
            StagingDir::create(&final_dir)
                .map_err(|e| MediaError::io(&parent_dir(&final_dir), e))?,
        );
        Ok(SequenceSink {
            exr,
            pattern,
            final_dir,
            temp_dir,
            written: Vec::new(),
            first,
            fps: exr_rational(fps),
        })
    }

    fn write_frame(&self, frame: &RgbaFrame, staged: &Path) -> Result<()> {
        let file = std::fs::File::create(staged).map_err(|e| MediaError::io(staged, e))?;
        let mut w = std::io::BufWriter::new(file);
        if self.exr {
            let mut pre = frame.clone();
            convert::premultiply(&mut pre);
            // Scan lines in increasing Y, written sequentially: the same bytes every run
            // (a parallel writer stores chunks in completion order).
            use exr::prelude::*;
            let (fw, fh) = (frame.width() as usize, frame.height() as usize);
            let px = pre.data();
            let enc = Encoding {
                compression: Compression::RLE,
                blocks: Blocks::ScanLines,
                line_order: LineOrder::Increasing,
            };
            let mut image = Image::from_encoded_channels(
                (fw, fh),
                enc,
                SpecificChannels::rgba(|p: Vec2<usize>| {
                    let [r, g, b, a] = px[p.y() * fw + p.x()];
                    (r, g, b, a)
                }),
            );
            image.layer_data.attributes.frames_per_second = self.fps;
            image
                .write()
                .non_parallel()
                .to_buffered(&mut w)
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
            None => {
                return Err(MediaError::encode(
                    &self.final_dir,
                    "the writer has finished",
                ))
            }
        };
        // Record first so that a half-written file is cleaned up on drop.
        self.written.push((staged.clone(), final_path));
        self.write_frame(frame, &staged)
    }

    fn finish(mut self: Box<Self>) -> Result<Vec<PathBuf>> {
        let finals: Vec<PathBuf> = self.written.iter().map(|(_, f)| f.clone()).collect();
        let Some(mut t) = self.temp_dir.take() else {
            return Err(MediaError::encode(
                &self.final_dir,
                "the writer has finished",
            ));
        };
        // Frames named since `destination` checked the directory, and inputs a
        // reader opened since then: nothing the commit would replace may be one.
        for (_, fin) in &self.written {
            super::check_regular_target(fin)?;
        }
        // Dropping `t` removes what commit_sequence left of the staged directory.
        t.into_place();
        commit_sequence(t.path(), &self.final_dir, &self.written)?;
        Ok(finals)
    }
}

/// Whether the existing directory `dir` can be replaced as a whole: it holds no
/// subdirectory and is not the working directory or one of its ancestors.
fn swappable(dir: &Path) -> bool {
    let (Ok(d), Ok(cwd)) = (
        std::fs::canonicalize(dir),
        std::env::current_dir().and_then(std::fs::canonicalize),
    ) else {
        return false;
    };
    if cwd.starts_with(&d) {
        return false;
    }
    let Ok(rd) = std::fs::read_dir(dir) else {
        return false;
    };
    rd.flatten()
        .all(|e| e.file_type().map(|t| !t.is_dir()).unwrap_or(false))
}

/// Moves the staged frames into `final_dir` in one step: a new directory is renamed into
/// place; an existing one is replaced by an atomic exchange after the files of the old
/// directory that this sequence does not overwrite are hard-linked (or copied) into the
/// staged one, so they stay. A directory that cannot be swapped (it has subdirectories, or
/// is the working directory) gets the frames renamed in one by one.
fn commit_sequence(
    staged_dir: &Path,
    final_dir: &Path,
    written: &[(PathBuf, PathBuf)],
) -> Result<()> {
    if std::fs::symlink_metadata(final_dir).is_err() {
        return std::fs::rename(staged_dir, final_dir).map_err(|e| MediaError::io(final_dir, e));
    }
    if !swappable(final_dir) {
        for (staged, fin) in written {
            std::fs::rename(staged, fin).map_err(|e| MediaError::io(fin, e))?;
        }
        return Ok(());
    }
    let rd = std::fs::read_dir(final_dir).map_err(|e| MediaError::io(final_dir, e))?;
    for e in rd {
        let e = e.map_err(|e| MediaError::io(final_dir, e))?;
        let name = e.file_name();
        let to = staged_dir.join(&name);
        if std::fs::symlink_metadata(&to).is_ok() {
            continue; // replaced by a new frame
        }
        let from = e.path();
        let is_link = e.file_type().map(|t| t.is_symlink()).unwrap_or(false);
        let r = if is_link {
            std::fs::read_link(&from).and_then(|l| {
                #[cfg(unix)]
                {
                    std::os::unix::fs::symlink(l, &to)
                }
                #[cfg(not(unix))]
                {
                    let _ = l;
                    std::fs::copy(&from, &to).map(|_| ())
                }
            })
        } else {
            std::fs::hard_link(&from, &to).or_else(|_| std::fs::copy(&from, &to).map(|_| ()))
        };
        r.map_err(|e| MediaError::io(&from, e))?;
    }
    if let Ok(m) = std::fs::metadata(final_dir) {
        let _ = std::fs::set_permissions(staged_dir, m.permissions());
    }
    ignis_core::tempfiles::replace_dir(staged_dir, final_dir)
        .map_err(|e| MediaError::io(final_dir, e))
}

#[cfg(test)]
mod tests {
    use super::exr_rational;

    #[test]
    fn rates_as_exr_rationals() {
        assert_eq!(exr_rational(24.0), Some((24, 1)));
        assert_eq!(exr_rational(24000.0 / 1001.0), Some((24000, 1001)));
        assert_eq!(exr_rational(30000.0 / 1001.0), Some((30000, 1001)));
        assert_eq!(exr_rational(29.97), Some((2997, 100)));
        assert_eq!(exr_rational(12.5), Some((25, 2)));
        assert_eq!(exr_rational(std::f64::consts::PI), None);
        assert_eq!(exr_rational(0.0), None);
        assert_eq!(exr_rational(f64::NAN), None);
    }
}
