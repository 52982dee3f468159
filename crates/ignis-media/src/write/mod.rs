//! Writing: PNG and EXR sequences, GIF, MP4/H.264, video with alpha (ProRes 4444 `.mov`,
//! VP8 `.webm`, through the system ffmpeg) and flipbooks (sprite sheet + JSON).
//!
//! Frames pushed in are **linear light, straight alpha**. What each output stores:
//!
//! | format | pixels | alpha |
//! |---|---|---|
//! | PNG sequence | 8-bit sRGB RGBA | **straight** (unassociated), as PNG specifies |
//! | EXR sequence | linear `f32` RGBA | **premultiplied**, the OpenEXR convention compositors expect |
//! | GIF | 8-bit sRGB, ≤ 256 colours per frame (NeuQuant) | none: composited over `background` (default black) |
//! | MP4 (H.264 Constrained Baseline, BT.601 limited range, 4:2:0) | 8-bit | none: composited over `background` (default black) |
//! | MOV (ProRes 4444, system ffmpeg) | 10-bit sRGB 4:4:4 | **straight**, 16-bit |
//! | WebM (VP8, system ffmpeg) | 8-bit sRGB 4:2:0 | **straight** (WebM's alpha stream) |
//! | flipbook PNG | 8-bit sRGB RGBA | `straight` or `premultiplied` (linear light premultiplied, then sRGB-encoded), stated in the JSON |
//!
//! MP4 needs even dimensions (4:2:0): an odd width or height is padded by one pixel
//! (and a side under 16 pixels to 16, OpenH264's minimum), repeating the last column/row; [`FrameWriter::output_size`] says what was written.
//! GIF delays are whole centiseconds (accumulated so the average rate is right); browsers
//! treat delays under 2 cs as 10 cs, so rates above 50 fps play at 50.
//!
//! Every writer is atomic ([`ignis_core::atomic`]): output goes to a hidden temporary name
//! in the destination's directory (`.name.ignis-tmp-PID.N.partial`) and is renamed into
//! place by [`FrameWriter::finish`]. An error, or dropping the writer without `finish`, deletes the
//! temporary output and leaves nothing under the final name; temporaries of a killed run
//! carry its PID and are removed by the next run in that directory
//! ([`ignis_core::tempfiles`]). A flipbook's PNG and JSON are committed as one unit (a
//! journal completes an interrupted commit). Sequences go into a fresh temporary directory
//! renamed into place at the end; when the destination directory already exists, its other
//! files are linked into the new one and the two are swapped in one atomic exchange (a
//! directory with subdirectories, or the working directory, gets the frames renamed in one
//! by one instead). Outputs that exist and are not regular files (devices, FIFOs) are
//! refused; frame rates must be in [`MIN_FPS`]..=[`MAX_FPS`].

pub mod engine;
mod ffmpeg_out;
pub(crate) mod flipbook;
mod gif_out;
pub mod motion;
mod mp4_out;
mod sequence_out;

use std::io::Write;
use std::path::{Path, PathBuf};

use ignis_core::loopq::{self, LoopQuality};
use ignis_core::{GrayFrame, RgbaFrame, Size};

use crate::error::{MediaError, Result};
pub(crate) use ignis_core::atomic::parent_dir;
use ignis_core::atomic::{self, AtomicFile};

pub use engine::Engine;
pub use flipbook::{
    fit_frame, plan_layout, read_flipbook, read_flipbook_meta, retime, sheet_limit, visible_box,
    AlphaMode, Flipbook, FlipbookMeta, FlipbookOptions, HeatMeta, Layout, MotionMeta, Retime,
    ScaledFrom, Trimmed, MIN_FIT_SIDE,
};
pub use motion::MotionSource;

/// An output format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Format {
    /// H.264 in MP4 (OpenH264 encoder + `mp4` muxer; no ffmpeg needed).
    Mp4,
    /// Animated GIF.
    Gif,
    /// A directory of 8-bit sRGB PNGs, or a `%04d.png` pattern.
    PngSequence,
    /// A directory of linear `f32` EXRs, or a `%04d.exr` pattern.
    ExrSequence,
    /// One sprite-sheet PNG plus a JSON sidecar.
    Flipbook,
    /// Apple ProRes 4444 with alpha in QuickTime (system ffmpeg).
    Mov,
    /// VP8 with alpha in WebM (system ffmpeg).
    Webm,
}

impl Format {
    /// The format a path implies: `.mp4`, `.gif`, `.png` (flipbook), `.mov`, `.webm`, a directory (trailing
    /// `/` or an existing directory: PNG sequence) or a pattern `%04d.png` / `%04d.exr`.
    pub fn from_path(path: &Path) -> Result<Format> {
        let s = path.to_string_lossy();
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().to_lowercase())
            .unwrap_or_default();
        if crate::read::sequence::has_frame_number(&name) {
            return if name.ends_with(".png") {
                Ok(Format::PngSequence)
            } else if name.ends_with(".exr") {
                Ok(Format::ExrSequence)
            } else {
                Err(MediaError::bad(
                    "path",
                    format!("frame pattern `{s}` must end in .png or .exr"),
                ))
            };
        }
        if s.ends_with('/') || s.ends_with(std::path::MAIN_SEPARATOR) || path.is_dir() {
            return Ok(Format::PngSequence);
        }
        match name.rsplit_once('.').map(|(_, e)| e) {
            Some("mp4") => Ok(Format::Mp4),
            Some("gif") => Ok(Format::Gif),
            Some("png") => Ok(Format::Flipbook),
            Some("mov") => Ok(Format::Mov),
            Some("webm") => Ok(Format::Webm),
            _ => Err(MediaError::bad(
                "path",
                format!(
                    "cannot tell the output format of `{s}`: use .mp4, .gif, .png (flipbook), .mov \
                     (ProRes 4444 with alpha), .webm (VP8 with alpha), a directory ending in / (PNG \
                     sequence), a pattern like frames/%04d.png or frames/shot.####.exr, or set the format"
                ),
            )),
        }
    }
}

/// Smallest frame rate any writer accepts (MP4's time scale is 1000 × fps, at least 1).
pub const MIN_FPS: f64 = 0.001;
/// Largest frame rate any writer accepts.
pub const MAX_FPS: f64 = 1000.0;

/// How to write. `Default`: format from the path, 30 fps, looping, black background.
#[derive(Clone, Debug, PartialEq)]
pub struct WriteOptions {
    /// Output format; `None` = from the path ([`Format::from_path`]).
    pub format: Option<Format>,
    /// Frames per second, > 0 (default 30). Stored in MP4, GIF delays and flipbook JSON.
    pub fps: f64,
    /// Loop playback (GIF loop count, flipbook JSON `loop`). Default true.
    pub loop_: bool,
    /// Sprite-sheet layout for [`Format::Flipbook`].
    pub flipbook: FlipbookOptions,
    /// Linear-light colour that formats without alpha (MP4, GIF) composite over. Default black.
    pub background: [f32; 3],
    /// Sequences: the number in the first file's name (a render-farm chunk of a longer
    /// render keeps the full render's frame numbers). Default 0.
    pub first_frame: u64,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions {
            format: None,
            fps: 30.0,
            loop_: true,
            flipbook: FlipbookOptions::default(),
            background: [0.0; 3],
            first_frame: 0,
        }
    }
}

/// One output format's encoder.
pub(crate) trait Sink: Send {
    fn push(&mut self, frame: &RgbaFrame) -> Result<()>;
    /// The loop quality measured on every pushed frame, given just before `finish` when the
    /// output loops; formats with a sidecar record it (flipbook JSON `loop_quality`).
    fn set_loop_quality(&mut self, _quality: LoopQuality) {}
    /// Completes the output and renames it into place.
    fn finish(self: Box<Self>) -> Result<Vec<PathBuf>>;
}

/// A writer of frames of one size; see the module docs for formats and atomicity.
pub struct FrameWriter {
    sink: Option<Box<dyn Sink>>,
    size: Size,
    output_size: Size,
    frames: u64,
    path: PathBuf,
    format: Format,
    loop_: bool,
    background: [f32; 3],
    /// Seam and ghost measured as frames are pushed ([`ignis_core::loopq`] on their
    /// 128-px grey metric frames).
    measure: Measure,
}

/// [`loopq::loop_quality`] and [`loopq::sequence_quality`] of every pushed frame, measured
/// as they stream past: the first and the latest metric frame, each step between
/// consecutive frames and each frame's sharpness. Sixteen bytes a frame, where keeping the
/// metric frames took 36–64 KB (an hour of 30-fps video: 4–7 GB); the same values.
#[derive(Default)]
struct Measure {
    first: Option<GrayFrame>,
    last: Option<GrayFrame>,
    steps: Vec<f64>,
    sharp: Vec<f64>,
}

impl Measure {
    fn push(&mut self, m: GrayFrame) {
        if let Some(last) = &self.last {
            self.steps.push(loopq::rms_diff(last, &m));
        }
        self.sharp.push(loopq::sharpness(&m));
        if self.first.is_none() {
            self.first = Some(m.clone());
        }
        self.last = Some(m);
    }

    fn loop_quality(&self) -> Option<LoopQuality> {
        let (first, last) = (self.first.as_ref()?, self.last.as_ref()?);
        if self.sharp.len() < 2 {
            return None;
        }
        let mut d = self.steps.clone();
        d.push(loopq::rms_diff(last, first));
        Some(loopq::quality_of(&d, &self.sharp))
    }

    fn sequence_quality(&self) -> Option<LoopQuality> {
        (self.sharp.len() >= 3).then(|| loopq::quality_of(&self.steps, &self.sharp))
    }

    fn wrap_step(&self) -> Option<f64> {
        let (first, last) = (self.first.as_ref()?, self.last.as_ref()?);
        (self.sharp.len() >= 3).then(|| loopq::rms_diff(last, first))
    }
}

/// Creates a writer for frames of `size` at `path`.
pub fn create(path: &Path, size: Size, opts: &WriteOptions) -> Result<FrameWriter> {
    let size = Size::new(size.width, size.height)?;
    let format = check_output(path, opts)?;
    let mut output_size = size;
    let sink: Box<dyn Sink> = match format {
        Format::PngSequence | Format::ExrSequence => Box::new(sequence_out::SequenceSink::new(
            path,
            format == Format::ExrSequence,
            opts.first_frame,
            opts.fps,
        )?),
        Format::Gif => Box::new(gif_out::GifSink::new(path, size, opts)?),
        Format::Mp4 => {
            let s = mp4_out::Mp4Sink::new(path, size, opts)?;
            output_size = s.output_size();
            Box::new(s)
        }
        Format::Flipbook => Box::new(flipbook::FlipbookSink::new(path, size, opts)?),
        Format::Mov | Format::Webm => {
            Box::new(ffmpeg_out::FfmpegSink::new(path, size, opts, format)?)
        }
    };
    Ok(FrameWriter {
        sink: Some(sink),
        size,
        output_size,
        frames: 0,
        path: path.to_path_buf(),
        format,
        loop_: opts.loop_,
        background: opts.background,
        measure: Measure::default(),
    })
}

/// Checks, creating nothing, what [`create`] or [`FrameWriter::finish`] would refuse about
/// writing to `path` with `opts`: the frame rate, the format, a sequence pattern, a target
/// that exists and is not a regular file (a sequence's: not a directory), and a destination
/// directory that cannot be made or written in. Returns the format.
///
/// [`create`] runs it, so a flipbook (whose files are only made by `finish`) fails at once
/// rather than after the render; a command that works for minutes before creating its
/// writer (training, a search) should run it first too.
pub fn check_output(path: &Path, opts: &WriteOptions) -> Result<Format> {
    if !(opts.fps.is_finite() && opts.fps > 0.0) {
        return Err(MediaError::bad(
            "fps",
            format!("{} must be a finite number > 0, e.g. 30", opts.fps),
        ));
    }
    if opts.fps < MIN_FPS || opts.fps > MAX_FPS {
        return Err(MediaError::bad(
            "fps",
            format!(
                "{} is outside {MIN_FPS}..={MAX_FPS} frames per second (MP4 stores 1/1000-frame \
                 time steps); use e.g. 30",
                opts.fps
            ),
        ));
    }
    let format = match opts.format {
        Some(f) => f,
        None => Format::from_path(path)?,
    };
    let dir = match format {
        Format::Mp4 | Format::Gif => {
            check_regular_target(path)?;
            parent_dir(path)
        }
        Format::Mov | Format::Webm => {
            if !crate::read::ffmpeg_available() {
                return Err(ffmpeg_out::needs_ffmpeg(path, format));
            }
            check_regular_target(path)?;
            parent_dir(path)
        }
        Format::Flipbook => {
            check_regular_target(path)?;
            check_regular_target(&path.with_extension("json"))?;
            parent_dir(path)
        }
        Format::PngSequence | Format::ExrSequence => {
            let (final_dir, _) = sequence_out::destination(path, format == Format::ExrSequence)?;
            parent_dir(&final_dir)
        }
    };
    check_writable_dir(&dir)?;
    Ok(format)
}

/// Refuses a destination directory `dir` that cannot be made or written in: its nearest
/// existing ancestor must be a directory in which a file can be created (probed with a
/// temporary name of this process, removed at once; a killed run's probe is cleaned like
/// any other temporary, [`ignis_core::tempfiles`]).
fn check_writable_dir(dir: &Path) -> Result<()> {
    let mut at = dir;
    let existing = loop {
        match std::fs::metadata(at) {
            Ok(m) if m.is_dir() => break at,
            Ok(_) => {
                let what = if at == dir {
                    String::new()
                } else {
                    format!(", so {} cannot be made", dir.display())
                };
                return Err(MediaError::bad(
                    "output",
                    format!(
                        "{} is not a directory{what}; choose an output path inside a directory",
                        at.display()
                    ),
                ));
            }
            // Missing, or below a file (`ENOTDIR`): the ancestor decides.
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory
                ) =>
            {
                match at.parent() {
                    Some(p) if !p.as_os_str().is_empty() => at = p,
                    _ => break Path::new("."),
                }
            }
            Err(e) => return Err(MediaError::io(at, e)),
        }
    };
    let probe = existing.join(ignis_core::tempfiles::temp_name("output", "probe"));
    let _live = ignis_core::tempfiles::track(&probe, false);
    match std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(&probe)
    {
        Ok(_) => {
            let _ = std::fs::remove_file(&probe);
            Ok(())
        }
        // Another writer of this process probing the same directory: it is writable.
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => Ok(()),
        Err(e) => Err(MediaError::bad(
            "output",
            format!(
                "cannot write in {} ({e}); choose an output path in a directory you can write to",
                existing.display()
            ),
        )),
    }
}

impl FrameWriter {
    /// Encodes one frame (linear light, straight alpha, of the size given to [`create`]).
    /// After an error the writer is unusable and `finish` returns an error.
    pub fn push(&mut self, frame: &RgbaFrame) -> Result<()> {
        if frame.size() != self.size {
            return Err(MediaError::bad(
                "frame",
                format!(
                    "frame {} is {}, but this writer was created for {}",
                    self.frames,
                    frame.size(),
                    self.size
                ),
            ));
        }
        let sink = self
            .sink
            .as_mut()
            .ok_or_else(|| MediaError::encode(&self.path, "an earlier frame failed"))?;
        if let Err(e) = sink.push(frame) {
            self.sink = None; // drops the temporary output
            return Err(e);
        }
        self.measure
            .push(loopq::metric_frame_rgba(frame, self.background));
        self.frames += 1;
        Ok(())
    }

    /// Seam and ghost of the frames pushed so far played as a loop (wrap included), as
    /// [`ignis_core::loopq`] measures them on what this writer shows (composited over the
    /// background). `None` with fewer than two frames.
    pub fn loop_quality(&self) -> Option<LoopQuality> {
        self.measure.loop_quality()
    }

    /// Seam and ghost of the frames pushed so far played once (no wrap step). `None` with
    /// fewer than three frames.
    pub fn sequence_quality(&self) -> Option<LoopQuality> {
        self.measure.sequence_quality()
    }

    /// The step from the last frame pushed back to the first (RMS difference of their
    /// metric frames, as [`FrameWriter::loop_quality`]'s steps), to compare with the
    /// steps within: [`FrameWriter::sequence_quality`]'s `median_step`. `None` with fewer
    /// than three frames.
    pub fn wrap_step(&self) -> Option<f64> {
        self.measure.wrap_step()
    }

    /// Completes the output and moves it into place; returns every path written (for a
    /// flipbook: the PNG then the JSON; for a sequence: each frame in order).
    ///
    /// A looping output's sidecar (flipbook JSON) records [`FrameWriter::loop_quality`].
    pub fn finish(mut self) -> Result<Vec<PathBuf>> {
        let quality = if self.loop_ {
            self.loop_quality()
        } else {
            None
        };
        let mut sink = self
            .sink
            .take()
            .ok_or_else(|| MediaError::encode(&self.path, "an earlier frame failed"))?;
        if let Some(q) = quality {
            sink.set_loop_quality(q);
        }
        if self.frames == 0 {
            return Err(MediaError::bad(
                "frames",
                format!("no frames were written to {}", self.path.display()),
            ));
        }
        sink.finish()
    }

    /// Frames pushed so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }
    /// The format being written.
    pub fn format(&self) -> Format {
        self.format
    }
    /// The size of frames in the file: the input size, except MP4 pads odd sides to even.
    pub fn output_size(&self) -> Size {
        self.output_size
    }
}

/// The atomic temporary for `path` ([`ignis_core::atomic::AtomicFile`], deleted on drop
/// unless committed); creates `path`'s directory first.
pub(crate) fn temp_file_for(path: &Path) -> Result<AtomicFile> {
    let dir = parent_dir(path);
    std::fs::create_dir_all(&dir).map_err(|e| MediaError::io(&dir, e))?;
    AtomicFile::create(path).map_err(|e| target_error(path, e))
}

/// Refuses an output path that exists and is not a regular file
/// ([`ignis_core::atomic::check_regular_target`]) as a bad `output`.
pub(crate) fn check_regular_target(path: &Path) -> Result<()> {
    atomic::check_regular_target(path).map_err(|e| target_error(path, e))
}

/// A refused target is a bad `output` argument; any other failure an I/O error.
fn target_error(path: &Path, e: std::io::Error) -> MediaError {
    if e.kind() == std::io::ErrorKind::InvalidInput {
        MediaError::bad("output", e.to_string())
    } else {
        MediaError::io(path, e)
    }
}

/// Moves several finished temporaries (all in one directory) into place as one unit; see
/// [`ignis_core::atomic::commit_all`].
pub(crate) fn commit_temps(files: Vec<AtomicFile>) -> Result<()> {
    let dir = files
        .first()
        .map(|f| parent_dir(f.target()))
        .unwrap_or_default();
    atomic::commit_all(files).map_err(|e| MediaError::io(&dir, e))
}

/// Flushes, syncs and renames a temporary file into place.
pub(crate) fn persist(tmp: AtomicFile, path: &Path) -> Result<()> {
    tmp.commit().map_err(|e| MediaError::io(path, e))
}

/// Encodes 8-bit RGBA as PNG into `w`.
pub(crate) fn encode_png(w: impl Write, size: Size, rgba: &[u8]) -> image::ImageResult<()> {
    use image::codecs::png::{CompressionType, FilterType, PngEncoder};
    use image::ImageEncoder;
    PngEncoder::new_with_quality(w, CompressionType::Fast, FilterType::Adaptive).write_image(
        rgba,
        size.width,
        size.height,
        image::ExtendedColorType::Rgba8,
    )
}

/// Writes one still as an 8-bit sRGB PNG with straight alpha, atomically.
pub fn write_png(path: &Path, frame: &RgbaFrame) -> Result<()> {
    let mut tmp = temp_file_for(path)?;
    let rgba = crate::convert::to_srgba8(frame);
    encode_png(tmp.writer(), frame.size(), &rgba)
        .map_err(|e| MediaError::encode(path, e.to_string()))?;
    persist(tmp, path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn format_from_path() {
        for (path, want) in [
            ("a/fire.mp4", Some(Format::Mp4)),
            ("fire.GIF", Some(Format::Gif)),
            ("fire.png", Some(Format::Flipbook)),
            ("fire.MOV", Some(Format::Mov)),
            ("fire.webm", Some(Format::Webm)),
            ("out/", Some(Format::PngSequence)),
            ("f/%04d.png", Some(Format::PngSequence)),
            ("f/%04d.exr", Some(Format::ExrSequence)),
            // a `%` that is not a frame-number field is part of an ordinary name
            ("100% fire.gif", Some(Format::Gif)),
            ("f_%d.png", Some(Format::PngSequence)),
            ("fire.mkv", None),
            ("f/%04d.gif", None),
            ("f/%04d.jpg", None),
        ] {
            assert_eq!(Format::from_path(Path::new(path)).ok(), want, "{path}");
        }
    }
}
