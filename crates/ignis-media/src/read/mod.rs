//! Reading: probe a source, then stream its frames.
//!
//! Every reader yields **linear-light, straight-alpha** [`RgbaFrame`]s, one at a time;
//! nothing decodes a whole clip up front, and the frame count comes from the container
//! (MP4 sample table, `ffprobe`'s `nb_frames`, the number of files) or is `None`.
//!
//! Which decoder handles a file is decided by **probing its content**, never its extension:
//! - an ISO-BMFF file (`ftyp`) holding H.264 whose `avcC` says `profile_idc` 66 (Baseline /
//!   Constrained Baseline) → the pure-cargo path, [`Decoder::Openh264`] (`mp4` demuxer +
//!   Cisco's OpenH264 compiled from source);
//! - every other codec or container (H.264 Main/High, HEVC, ProRes, MOV, WebM, AVI, …) →
//!   the system `ffmpeg` ([`Decoder::Ffmpeg`]), with `ffprobe` for size, fps and count;
//!   without `ffmpeg` on `PATH` that is a [`MediaError::Unsupported`] naming the profile or
//!   codec and the fix (set `IGNIS_NO_FFMPEG=1` to see this behaviour on a machine that
//!   has ffmpeg);
//! - PNG / JPEG / TIFF / EXR stills → [`Decoder::Image`]; GIF → [`Decoder::Gif`];
//! - an Ignis flipbook — a sheet whose JSON sidecar (same name, `.json`) names it, or the
//!   sidecar itself → [`Decoder::Flipbook`]: its frames in order, at its fps;
//! - a directory or a printf pattern (`frames/%04d.png`) → [`Decoder::ImageSequence`].
//!
//! Pixel conventions of the inputs: 8- and 16-bit images and video are taken as
//! sRGB-encoded (converted to linear here); float images (EXR, float TIFF) as linear light.
//! EXR files are read as premultiplied (the OpenEXR convention) and un-premultiplied.
//! Video is decoded with the stream's own matrix and range (its SPS's VUI on the pure path,
//! ffmpeg's reading of it otherwise), BT.601 limited range when it says nothing (what
//! OpenH264 and our MP4 writer use); non-square pixels are resampled to square ones here
//! ([`SourceInfo::anamorphic`]).

mod ffmpeg;
mod flipbook_src;
mod h264;
pub(crate) mod sequence;
mod timing;

use std::fmt;
use std::io::Read;
use std::path::{Path, PathBuf};

use ignis_core::atomic::record_input;
use ignis_core::{RgbaFrame, Size};

use crate::convert;
use crate::error::{MediaError, Result};

pub(crate) use ffmpeg::{ffmpeg_available, file_url};
pub use h264::avc_profile_name;
#[doc(hidden)]
pub use h264::decode_rgba8_count;
pub(crate) use sequence::Pattern;

pub use sequence::{sequence_fps, set_sequence_fps, DEFAULT_SEQUENCE_FPS, SEQUENCE_FPS_RANGE};
pub use timing::{frame_timing, frames_in_data, FrameTiming};

/// What a reader says of a file whose data ends early or does not parse, and what to do.
pub(crate) const DAMAGED: &str = "the file may be truncated or damaged (an incomplete \
     download or copy): copy it again, or export it again from its source";

/// Unit of a [`FrameRange`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum RangeUnit {
    /// Frame indices (0 = first frame). Values must be whole numbers.
    #[default]
    Frames,
    /// Seconds from the start; converted with the source's fps and rounded to the nearest frame.
    Seconds,
}

/// A half-open range `[start, end)` of a source, in frames or seconds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameRange {
    /// First frame (or second) read, ≥ 0.
    pub start: f64,
    /// One past the last frame (or second) read; `None` = to the end of the source.
    pub end: Option<f64>,
    /// What `start` and `end` count.
    pub unit: RangeUnit,
}

impl FrameRange {
    /// Frames `start..end` (`end` exclusive, `None` = to the end).
    pub fn frames(start: u64, end: Option<u64>) -> FrameRange {
        FrameRange {
            start: start as f64,
            end: end.map(|e| e as f64),
            unit: RangeUnit::Frames,
        }
    }
    /// Seconds `start..end` (`end` exclusive, `None` = to the end).
    pub fn seconds(start: f64, end: Option<f64>) -> FrameRange {
        FrameRange {
            start,
            end,
            unit: RangeUnit::Seconds,
        }
    }

    /// Resolves to frame indices `[start, end)` for a source with `fps` and (if known)
    /// `count` frames. Errors: negative/non-integral values, an empty range, a range past
    /// the end.
    pub fn resolve(&self, fps: f64, count: Option<u64>) -> Result<(u64, Option<u64>)> {
        let to_frame = |v: f64, what: &str| -> Result<u64> {
            if !v.is_finite() || v < 0.0 {
                return Err(MediaError::bad(
                    "range",
                    format!("{what} {v} must be a finite value ≥ 0"),
                ));
            }
            match self.unit {
                RangeUnit::Frames if v.fract() != 0.0 => Err(MediaError::bad(
                    "range",
                    format!("{what} {v} is not a whole frame number"),
                )),
                RangeUnit::Frames => Ok(v as u64),
                RangeUnit::Seconds => Ok((v * fps).round() as u64),
            }
        };
        let start = to_frame(self.start, "start")?;
        let end = self.end.map(|e| to_frame(e, "end")).transpose()?;
        if let Some(e) = end {
            if e <= start {
                return Err(MediaError::bad(
                    "range",
                    format!("empty range: frames {start}..{e} (end is exclusive and must be after start)"),
                ));
            }
        }
        if let Some(n) = count {
            if start >= n {
                return Err(MediaError::bad(
                    "range",
                    format!("starts at frame {start}, past the end of the source (it has {n} frames: 0..{n})"),
                ));
            }
            if let Some(e) = end.filter(|&e| e > n) {
                return Err(MediaError::bad(
                    "range",
                    format!(
                        "ends at frame {e}, past the end of the source (it has {n} frames: 0..{n})"
                    ),
                ));
            }
        }
        Ok((start, end))
    }
}

/// A rectangle in source pixels: top-left corner `(x, y)`, row 0 at the top.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Rect {
    pub x: u32,
    pub y: u32,
    pub width: u32,
    pub height: u32,
}

/// What to read from a source. `Default` reads every frame at full size.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ReadOptions {
    /// Only these frames (default: all).
    pub range: Option<FrameRange>,
    /// Cut this rectangle out of each frame first (default: whole frame).
    pub crop: Option<Rect>,
    /// Then resize to this size (default: keep). Triangle filter on premultiplied colour.
    pub scale: Option<Size>,
}

/// Which decoder handles a source.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Decoder {
    /// MP4 + H.264 Baseline through the `mp4` demuxer and OpenH264 (pure cargo).
    Openh264,
    /// The system `ffmpeg` (every other codec and container).
    Ffmpeg,
    /// A directory or printf pattern of stills.
    ImageSequence,
    /// A single still image (one frame).
    Image,
    /// An animated (or single-frame) GIF, decoded with the `image` crate.
    Gif,
    /// An Ignis flipbook: the frames cut from its sheet, as its JSON sidecar lays them out.
    Flipbook,
}

impl fmt::Display for Decoder {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Decoder::Openh264 => "openh264",
            Decoder::Ffmpeg => "ffmpeg",
            Decoder::ImageSequence => "image sequence",
            Decoder::Image => "image",
            Decoder::Gif => "gif",
            Decoder::Flipbook => "flipbook",
        })
    }
}

/// What [`probe`] learns about a source without decoding it.
#[derive(Clone, Debug, PartialEq)]
pub struct SourceInfo {
    /// Frame size in pixels, as read: upright and with square pixels ([`Self::anamorphic`]).
    pub size: Size,
    /// Frames per second (image sequences and stills: [`sequence_fps`], by default
    /// [`DEFAULT_SEQUENCE_FPS`], unless an EXR sequence's headers state one).
    pub fps: f64,
    /// Whether the source states `fps` itself: a video's stream, a GIF's delays, a
    /// flipbook's sidecar, an EXR sequence's `framesPerSecond`. `false` for a sequence or
    /// still read at [`sequence_fps`].
    pub rate_stated: bool,
    /// Number of frames, when the container says so (`None` for e.g. GIF or WebM without
    /// a frame count).
    pub frame_count: Option<u64>,
    /// Codec description, e.g. `"h264 (Constrained Baseline)"`, `"png sequence"`.
    pub codec: String,
    /// Which decoder [`open`] will use.
    pub decoder: Decoder,
    /// The path as given.
    pub path: PathBuf,
    /// Non-square pixels (anamorphic DV or HDV, some phone and broadcast footage): the
    /// pictures are stored at [`Anamorphic::stored`] and read at `size`, resampled to
    /// square pixels as a player shows them. `None` for square pixels.
    pub anamorphic: Option<Anamorphic>,
}

/// A source whose pixels are not square ([`SourceInfo::anamorphic`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Anamorphic {
    /// The size the pictures are stored (and decoded) at.
    pub stored: Size,
    /// Width : height of one stored pixel (the sample aspect ratio), in lowest terms.
    pub pixel_aspect: (u32, u32),
}

/// The pixel aspects beyond which a sample aspect ratio is taken to be damaged metadata
/// and ignored: real anamorphic formats stay within 1:2 … 2:1 (DV 8:9 to 2:1 for
/// anamorphic 2× lenses), so 1:4 … 4:1 leaves room without letting a bad header blow a
/// frame up sixteenfold.
const MAX_PIXEL_ASPECT: f64 = 4.0;

/// Pixel aspects within this of 1 are read as square. ffmpeg's `scale` after a crop
/// writes such ratios (a 405-px crop of 4:2:0 footage, rounded to 404, scaled to 540×960,
/// is tagged 404:405): resampling every frame for a shape change nobody can see (0.25 %)
/// only softens it. The nearest real anamorphic formats are 6 % off (DV's 16:15, 10:11).
const SQUARE_ENOUGH: f64 = 0.01;

/// What a source with stored pictures of `stored` and a sample aspect ratio `num:den`
/// is read as: the stored size widened (pixels wider than tall) or heightened (taller
/// than wide) to square pixels, so that no stored detail is lost. `None` when the
/// pixels are square or within [`SQUARE_ENOUGH`] of it, the ratio is unknown (`0:1`,
/// `0:0`), or it is outside 1:[`MAX_PIXEL_ASPECT`] … [`MAX_PIXEL_ASPECT`]:1.
pub(crate) fn anamorphic(stored: Size, num: u32, den: u32) -> Option<(Anamorphic, Size)> {
    if num == 0 || den == 0 || num == den {
        return None;
    }
    let g = gcd(num, den);
    let (num, den) = (num / g, den / g);
    let r = num as f64 / den as f64;
    if !(1.0 / MAX_PIXEL_ASPECT..=MAX_PIXEL_ASPECT).contains(&r) || (r - 1.0).abs() < SQUARE_ENOUGH
    {
        return None;
    }
    let (w, h) = (stored.width as f64, stored.height as f64);
    let (w, h) = if r > 1.0 {
        ((w * r).round(), h)
    } else {
        (w, (h / r).round())
    };
    let shown = Size::new(w as u32, h as u32).ok()?;
    (shown != stored).then_some((
        Anamorphic {
            stored,
            pixel_aspect: (num, den),
        },
        shown,
    ))
}

fn gcd(mut a: u32, mut b: u32) -> u32 {
    while b != 0 {
        (a, b) = (b, a % b);
    }
    a
}

/// A decoder positioned at some frame, yielding native-size frames in order.
pub(crate) trait FrameSource: Send {
    fn next_frame(&mut self) -> Option<Result<RgbaFrame>>;
    /// [`FrameSource::next_frame`], as the decoder made it: 8-bit decoders opened with
    /// [`open_keeping_8bit`] keep their sRGB bytes.
    fn next_decoded(&mut self) -> Option<Result<DecodedFrame>> {
        self.next_frame().map(|r| r.map(DecodedFrame::Linear))
    }
}

/// A decoded frame: linear light, or the 8-bit sRGB RGBA bytes (straight, linear alpha)
/// an 8-bit decoder made, not yet converted (see [`open_keeping_8bit`]).
#[derive(Clone, Debug, PartialEq)]
pub enum DecodedFrame {
    Linear(RgbaFrame),
    /// `size.pixels() * 4` bytes, rows top to bottom.
    Srgba8 {
        size: Size,
        bytes: Vec<u8>,
    },
}

impl DecodedFrame {
    pub fn size(&self) -> Size {
        match self {
            DecodedFrame::Linear(f) => f.size(),
            DecodedFrame::Srgba8 { size, .. } => *size,
        }
    }
    /// How many of its pixels are see-through (alpha below 1, or 255): 0 for an opaque
    /// frame, more for a keyed element with its own alpha.
    pub fn see_through(&self) -> usize {
        match self {
            DecodedFrame::Srgba8 { bytes, .. } => bytes
                .iter()
                .skip(3)
                .step_by(4)
                .filter(|&&a| a != 255)
                .count(),
            DecodedFrame::Linear(f) => f.data().iter().filter(|p| p[3] < 1.0).count(),
        }
    }

    /// The frame as it shows over black: a keyed element's colour times its own alpha
    /// (linear light; the alpha kept), so analysis sees it as footage shot on black and
    /// never the plate its key hides. An opaque frame (every alpha 1, or 255) is returned
    /// as it is, bit for bit (8-bit bytes stay bytes).
    pub fn over_black(self) -> DecodedFrame {
        if self.see_through() == 0 {
            return self;
        }
        let mut f = self.into_linear();
        convert::premultiply(&mut f);
        DecodedFrame::Linear(f)
    }

    /// The linear-light frame (the same values [`FrameReader`]'s iterator yields).
    pub fn into_linear(self) -> RgbaFrame {
        match self {
            DecodedFrame::Linear(f) => f,
            DecodedFrame::Srgba8 { size, bytes } => convert::from_srgba8(size, &bytes),
        }
    }
}

/// The result of probing: the info plus what the opener needs.
pub(crate) enum Probed {
    Mp4(SourceInfo, h264::Mp4Probe),
    Ffmpeg(SourceInfo, ffmpeg::Plan),
    /// The frames' files in playing order, and their frame numbers when every name has
    /// one (of one form).
    Sequence(SourceInfo, Vec<PathBuf>, Option<Vec<u64>>),
    Image(SourceInfo),
    Gif(SourceInfo),
    /// The flipbook and its sidecar.
    Flipbook(SourceInfo, PathBuf),
}

impl Probed {
    fn info(&self) -> &SourceInfo {
        match self {
            Probed::Mp4(i, _)
            | Probed::Ffmpeg(i, _)
            | Probed::Sequence(i, ..)
            | Probed::Image(i)
            | Probed::Gif(i)
            | Probed::Flipbook(i, _) => i,
        }
    }
}

/// Probes `path`: size, fps, frame count (when the container says), codec and decoder.
/// Reads headers only.
pub fn probe(path: &Path) -> Result<SourceInfo> {
    Ok(probe_inner(path, ffmpeg_available())?.info().clone())
}

/// When `path` is an image sequence whose files are numbered from above 0
/// (`shot.1001.exr` …) and frames `start..end` were asked for by file number: the clause
/// that says frames count from 0 in the order read, and which frames those file numbers
/// are (`frames count from 0 in the order read, not by file number (shot.1001.exr is frame
/// 0): file numbers 1001..1005 are frames 0..4`). `None` for anything else, or when no
/// file has a number in the range.
pub fn file_numbers_hint(path: &Path, start: u64, end: Option<u64>) -> Option<String> {
    match sequence_of(path).ok()?? {
        (files, Some(numbers)) => sequence::numbers_hint(&numbers, &files, start, end),
        _ => None,
    }
}

/// An image sequence's files in playing order and their frame numbers, when every name
/// has one ([`Probed::Sequence`]).
type SequenceFiles = (Vec<PathBuf>, Option<Vec<u64>>);

/// When `path` is an image sequence (a directory or a pattern): its [`SequenceFiles`].
fn sequence_of(path: &Path) -> Result<Option<SequenceFiles>> {
    if !(is_pattern(path) || path.is_dir()) {
        return Ok(None);
    }
    Ok(match probe_inner(path, false)? {
        Probed::Sequence(_, files, numbers) => Some((files, numbers)),
        _ => None,
    })
}

/// The files `path` reads: a sequence's frames in playing order (a directory or a printf
/// pattern, as [`open`] finds them), a flipbook's sheet and sidecar, else the path itself —
/// for fingerprinting a source.
pub fn source_files(path: &Path) -> Result<Vec<PathBuf>> {
    if let Some((files, _)) = sequence_of(path)? {
        return Ok(files);
    }
    if let Some(files) = flipbook_src::files(path) {
        return Ok(files);
    }
    Ok(vec![path.to_path_buf()])
}

/// Whether `path` names a sequence by a pattern (`%04d`, or `####` unless a file of that
/// very name exists: `#` is allowed in file names).
fn is_pattern(path: &Path) -> bool {
    path.file_name().and_then(|n| n.to_str()).is_some_and(|n| {
        sequence::has_frame_number(n) && !(sequence::is_hash_pattern(n) && path.exists())
    })
}

/// Probes `path` ([`probe_kind`]) and records the files it reads as the running command's
/// inputs, which no output of that command may then replace
/// ([`ignis_core::atomic::guard_inputs`]).
pub(crate) fn probe_inner(path: &Path, have_ffmpeg: bool) -> Result<Probed> {
    let probed = probe_kind(path, have_ffmpeg)?;
    match &probed {
        Probed::Sequence(_, files, _) => files.iter().for_each(|f| record_input(f)),
        Probed::Flipbook(..) => flipbook_src::files(path)
            .unwrap_or_else(|| vec![path.to_path_buf()])
            .iter()
            .for_each(|f| record_input(f)),
        _ => record_input(path),
    }
    Ok(probed)
}

fn probe_kind(path: &Path, have_ffmpeg: bool) -> Result<Probed> {
    if is_pattern(path) {
        return sequence::probe_pattern(path);
    }
    let meta = std::fs::metadata(path).map_err(|e| {
        let why = "there is no such file or directory; check the path (footage is a video \
                   file, a directory of frames, or a pattern such as frames/%04d.png or frames/####.png)";
        MediaError::io(path, ignis_core::textfile::explain_missing(e, why))
    })?;
    if meta.is_dir() {
        return sequence::probe_dir(path);
    }
    if !meta.is_file() {
        return Err(MediaError::decode(
            path,
            None,
            "not a regular file (a FIFO or a device); footage is a video file, a directory \
             of frames, or a pattern such as frames/%04d.png",
        ));
    }
    if meta.len() == 0 {
        return Err(MediaError::decode(
            path,
            None,
            "the file is empty (0 bytes)",
        ));
    }
    let mut magic = [0u8; 16];
    let n = {
        let mut f = std::fs::File::open(path).map_err(|e| MediaError::io(path, e))?;
        read_up_to(&mut f, &mut magic).map_err(|e| MediaError::io(path, e))?
    };
    let magic = &magic[..n];
    if magic.len() >= 8 && &magic[4..8] == b"ftyp" {
        let quicktime = magic.len() >= 12 && &magic[8..12] == b"qt  ";
        if !quicktime {
            return h264::probe_mp4(path, meta.len(), have_ffmpeg);
        }
    }
    if magic.starts_with(b"IGNIS-LEARNED-FL") {
        return Err(MediaError::decode(
            path,
            None,
            format!(
                "this is a learned-flame model (what `ignis learned train` writes), not footage; \
                 synthesise a flame from it with `ignis learned synth {0} -o flame.mp4`, or \
                 describe it with `ignis learned inspect {0}`",
                path.display()
            ),
        ));
    }
    if magic.starts_with(b"GIF8") {
        return sequence::probe_gif(path);
    }
    if sequence::is_still_magic(magic) {
        if let Some((json, meta)) = flipbook_src::sidecar_of_sheet(path) {
            return flipbook_src::probe(path, path, &json, meta);
        }
        return sequence::probe_image(path);
    }
    if flipbook_src::looks_like_json(magic) {
        return flipbook_src::probe_sidecar(path);
    }
    if let Some(e) = text_given_as_footage(path, magic) {
        return Err(e);
    }
    if have_ffmpeg {
        return ffmpeg::probed(path);
    }
    Err(MediaError::unsupported(
        path,
        "container or codec (not MP4/H.264 Baseline, not an image)",
        "install ffmpeg (it handles H.264 Main/High, HEVC, ProRes, MOV, WebM, AVI, …), \
         or convert to a PNG sequence elsewhere: ffmpeg -i INPUT frames/%04d.png",
    ))
}

/// A text file given as footage (a fire file, a scenario, a clips file, ...), told apart
/// from a video by its first bytes and then its whole content (bounded, UTF-8, no control
/// characters but tabs and line ends): an error saying what it is and which command reads
/// it. `None` for anything else.
fn text_given_as_footage(path: &Path, magic: &[u8]) -> Option<MediaError> {
    let texty = |b: &u8| matches!(b, b'\t' | b'\n' | b'\r' | 0x20..=0x7e | 0x80..);
    if magic.is_empty() || !magic.iter().all(texty) {
        return None;
    }
    let text = ignis_core::textfile::read_text(path).ok()?;
    if text
        .chars()
        .any(|c| c.is_control() && !matches!(c, '\t' | '\n' | '\r'))
    {
        return None;
    }
    // the text formats ffmpeg reads as video (a concat list, a playlist) go to ffmpeg
    if ["ffconcat", "#EXTM3U"]
        .iter()
        .any(|h| text.trim_start().starts_with(h))
    {
        return None;
    }
    let p = path.display();
    let (what, then) = if text.contains("[[fire]]") {
        (
            "a fire file",
            format!("; render it with `ignis volume render {p} -o fire.mp4`"),
        )
    } else if text.contains("[motions.") || text.contains("sequence =") {
        (
            "an Eigenfire scenario",
            format!("; render it with `ignis eigen animate {p} -o fire.mp4`"),
        )
    } else if text.contains("[[clip]]") {
        (
            "a clips file",
            format!("; train a database from it with `ignis eigen train {p} -o fire.db`"),
        )
    } else {
        ("a text file", String::new())
    };
    Some(MediaError::decode(
        path,
        None,
        format!(
            "this is {what}, not footage{then} (footage is a video, an image, a flipbook, a \
             directory of frames or a pattern such as frames/%04d.png)"
        ),
    ))
}

fn read_up_to(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..])? {
            0 => break,
            k => n += k,
        }
    }
    Ok(n)
}

/// Opens `path` for streaming with `opts` (range, crop, scale).
pub fn open(path: &Path, opts: &ReadOptions) -> Result<FrameReader> {
    open_inner(path, opts, ffmpeg_available(), false)
}

/// [`open`], for a reader read with [`FrameReader::next_decoded`]: an 8-bit decoder (the
/// OpenH264 path, and ffmpeg, which pipes 8-bit RGBA) hands over its sRGB bytes, cropped
/// if asked, instead of converting them to linear light on its thread (a renderer working
/// from 8-bit values saves the conversion and a frame 4× the size); a scale or non-square
/// pixels still give linear frames. The iterator always yields linear frames.
pub fn open_keeping_8bit(path: &Path, opts: &ReadOptions) -> Result<FrameReader> {
    open_inner(path, opts, ffmpeg_available(), true)
}

pub(crate) fn open_inner(
    path: &Path,
    opts: &ReadOptions,
    have_ffmpeg: bool,
    keep_8bit: bool,
) -> Result<FrameReader> {
    let probed = probe_inner(path, have_ffmpeg)?;
    let source_info = probed.info().clone();
    let (start, end) = match &opts.range {
        Some(r) => r
            .resolve(source_info.fps, source_info.frame_count)
            .map_err(|e| match (&probed, r.unit, e) {
                // a range of file numbers (`1001..1050` of `shot.1001.exr` …): said so
                (
                    Probed::Sequence(_, files, Some(numbers)),
                    RangeUnit::Frames,
                    MediaError::BadParameter { name, reason },
                ) => {
                    let hint = sequence::numbers_hint(
                        numbers,
                        files,
                        r.start as u64,
                        r.end.map(|e| e as u64),
                    );
                    MediaError::BadParameter {
                        name,
                        reason: match hint {
                            Some(h) => format!("{reason}; {h}"),
                            None => reason,
                        },
                    }
                }
                (_, _, e) => e,
            })?,
        None => (0, source_info.frame_count),
    };
    let mut out_size = source_info.size;
    if let Some(rect) = &opts.crop {
        out_size = convert::check_crop(rect, source_info.size)?;
    }
    if let Some(s) = opts.scale {
        out_size = Size::new(s.width, s.height)?;
    }
    let source: Box<dyn FrameSource> = match probed {
        Probed::Mp4(info, p) => Box::new(h264::Openh264Source::start(&info, p, start, !keep_8bit)?),
        Probed::Ffmpeg(info, plan) => Box::new(ffmpeg::FfmpegSource::start(
            &info, &plan, start, end, keep_8bit,
        )?),
        Probed::Sequence(_, files, _) => Box::new(sequence::SequenceSource::new(files, start)),
        Probed::Image(info) => Box::new(sequence::SequenceSource::new(
            vec![info.path.clone()],
            start,
        )),
        Probed::Gif(info) => Box::new(sequence::GifSource::start(&info.path, start)?),
        Probed::Flipbook(_, json) => Box::new(flipbook_src::FlipbookSource::start(&json, start)?),
    };
    let info = SourceInfo {
        size: out_size,
        frame_count: end.map(|e| e - start),
        ..source_info.clone()
    };
    Ok(FrameReader {
        source,
        info,
        source_info,
        index: start,
        end,
        crop: opts.crop,
        scale: opts.scale,
        done: false,
    })
}

/// A stream of linear-light, straight-alpha frames from one source.
///
/// Implements `Iterator<Item = Result<RgbaFrame, MediaError>>`; after the first error the
/// iterator ends.
pub struct FrameReader {
    source: Box<dyn FrameSource>,
    info: SourceInfo,
    source_info: SourceInfo,
    index: u64,
    end: Option<u64>,
    crop: Option<Rect>,
    scale: Option<Size>,
    done: bool,
}

impl FrameReader {
    /// What this reader yields: the source's fps, codec and decoder, with `size` after crop
    /// and scale and `frame_count` = frames in the requested range (when known).
    pub fn info(&self) -> &SourceInfo {
        &self.info
    }
    /// The source as probed (full size, all frames).
    pub fn source_info(&self) -> &SourceInfo {
        &self.source_info
    }
    /// Index (in the source) of the next frame this reader yields.
    pub fn position(&self) -> u64 {
        self.index
    }
}

impl FrameReader {
    /// The next frame as the decoder made it ([`DecodedFrame::Srgba8`] from an 8-bit
    /// decoder opened with [`open_keeping_8bit`] when no scale is asked and the pixels are
    /// square, cropped if asked; linear otherwise). The same checks and errors as the iterator.
    pub fn next_decoded(&mut self) -> Option<Result<DecodedFrame>> {
        if self.done || self.end.is_some_and(|e| self.index >= e) {
            return None;
        }
        let frame = match self.source.next_decoded() {
            Some(Ok(f)) => f,
            Some(Err(e)) => {
                self.done = true;
                return Some(Err(e));
            }
            None => {
                self.done = true;
                let path = &self.source_info.path;
                return match self.end {
                    Some(end) => Some(Err(MediaError::decode(
                        path,
                        Some(self.index),
                        format!(
                            "the stream ended at frame {i} before the end of the range ({end}); \
                             {DAMAGED}, or use only its first {i} frames",
                            i = self.index
                        ),
                    ))),
                    None => None,
                };
            }
        };
        let stored = self
            .source_info
            .anamorphic
            .map_or(self.source_info.size, |a| a.stored);
        if frame.size() != stored {
            self.done = true;
            return Some(Err(MediaError::decode(
                &self.source_info.path,
                Some(self.index),
                format!("decoded a {} frame, expected {stored}", frame.size()),
            )));
        }
        self.index += 1;
        let square = self.source_info.anamorphic.is_none();
        let frame = match (square && self.scale.is_none(), self.crop, frame) {
            (true, None, f) => return Some(Ok(f)),
            // an 8-bit frame's crop is cut from its bytes (no conversion to linear first)
            (true, Some(r), DecodedFrame::Srgba8 { bytes, .. }) => {
                return Some(Ok(DecodedFrame::Srgba8 {
                    size: Size {
                        width: r.width,
                        height: r.height,
                    },
                    bytes: convert::crop_srgba8(&bytes, stored.width, &r),
                }));
            }
            (_, _, f) => f.into_linear(),
        };
        Some(Ok(self.finish_linear(frame, square)))
    }

    /// A linear frame as read: square pixels, cropped, scaled.
    fn finish_linear(&self, frame: RgbaFrame, square: bool) -> DecodedFrame {
        // Non-square pixels first, so that crop rectangles are in the size `probe` reports.
        let frame = match square {
            true => frame,
            false => convert::resize(&frame, self.source_info.size),
        };
        let frame = match &self.crop {
            Some(r) => convert::crop(&frame, r),
            None => frame,
        };
        let frame = match self.scale {
            Some(s) => convert::resize(&frame, s),
            None => frame,
        };
        DecodedFrame::Linear(frame)
    }
}

impl Iterator for FrameReader {
    type Item = Result<RgbaFrame>;

    fn next(&mut self) -> Option<Self::Item> {
        self.next_decoded()
            .map(|r| r.map(DecodedFrame::into_linear))
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        match self.end {
            Some(e) if !self.done => {
                let n = e.saturating_sub(self.index) as usize;
                (0, Some(n))
            }
            _ => (0, None),
        }
    }
}

/// Reads a single still (PNG, JPEG, TIFF, EXR, or the first frame of a GIF) as a linear,
/// straight-alpha frame.
pub fn read_image(path: &Path) -> Result<RgbaFrame> {
    let meta = std::fs::metadata(path).map_err(|e| MediaError::io(path, e))?;
    ignis_core::atomic::record_input_with(path, &meta);
    if meta.len() == 0 {
        return Err(MediaError::decode(
            path,
            None,
            "the file is empty (0 bytes)",
        ));
    }
    sequence::decode_still(path)
}

#[cfg(test)]
mod tests {
    /// Over black: an opaque frame (no pixel see-through) is itself, bit for bit (8-bit
    /// bytes stay bytes); a translucent one is its colour times its alpha, the alpha kept.
    #[test]
    fn a_keyed_frame_is_seen_over_black() {
        let size = Size::new(2, 1).unwrap();
        let bytes = vec![10, 200, 30, 255, 250, 128, 0, 255];
        let f = DecodedFrame::Srgba8 {
            size,
            bytes: bytes.clone(),
        };
        assert_eq!(f.see_through(), 0);
        assert_eq!(DecodedFrame::over_black(f.clone()), f);
        let lin =
            RgbaFrame::from_vec(size, vec![[0.5, 0.25, 1.0, 1.0], [0.2, 0.4, 0.8, 1.0]]).unwrap();
        assert_eq!(
            DecodedFrame::over_black(DecodedFrame::Linear(lin.clone())),
            DecodedFrame::Linear(lin)
        );
        let keyed =
            RgbaFrame::from_vec(size, vec![[0.5, 0.25, 1.0, 0.5], [0.8, 0.8, 0.8, 0.0]]).unwrap();
        assert_eq!(DecodedFrame::Linear(keyed.clone()).see_through(), 2);
        let seen = DecodedFrame::over_black(DecodedFrame::Linear(keyed)).into_linear();
        assert_eq!(
            seen.data(),
            &[[0.25, 0.125, 0.5, 0.5], [0.0, 0.0, 0.0, 0.0]]
        );
        let mut half = bytes;
        half[7] = 0;
        assert_eq!(
            DecodedFrame::Srgba8 {
                size,
                bytes: half.clone()
            }
            .see_through(),
            1
        );
        let seen =
            DecodedFrame::over_black(DecodedFrame::Srgba8 { size, bytes: half }).into_linear();
        assert_eq!(seen.data()[1], [0.0; 4]);
    }

    use super::*;

    #[test]
    fn anamorphic_sizes_widen_or_heighten_to_square_pixels() {
        let s = |w, h| Size::new(w, h).unwrap();
        // HDV 1440×1080 with 4:3 pixels is shown 1920×1080; DV NTSC 720×480 at 8:9 (pixels
        // taller than wide) is heightened, not narrowed: no stored column is lost.
        assert_eq!(anamorphic(s(1440, 1080), 4, 3).unwrap().1, s(1920, 1080));
        assert_eq!(anamorphic(s(720, 480), 8, 9).unwrap().1, s(720, 540));
        assert_eq!(anamorphic(s(720, 576), 64, 45).unwrap().1, s(1024, 576));
        // Lowest terms.
        assert_eq!(
            anamorphic(s(720, 540), 8, 6).unwrap().0,
            Anamorphic {
                stored: s(720, 540),
                pixel_aspect: (4, 3)
            }
        );
        // Square, unknown and absurd ratios: read as stored.
        for (n, d) in [
            (1, 1),
            (7, 7),
            (0, 1),
            (1, 0),
            (0, 0),
            (5, 1),
            (1, 5),
            (1000, 1),
        ] {
            assert_eq!(anamorphic(s(720, 540), n, d), None, "{n}:{d}");
        }
        // Within 1 % of square (what ffmpeg's scale after an odd crop tags): as stored.
        assert_eq!(anamorphic(s(540, 960), 404, 405), None);
        assert_eq!(anamorphic(s(1920, 1080), 201, 200), None);
        // DV PAL widescreen's 16:15 (6.7 % off) is not.
        assert_eq!(anamorphic(s(720, 576), 16, 15).unwrap().1, s(768, 576));
    }

    #[test]
    fn range_resolution() {
        let r = FrameRange::frames(2, Some(5));
        assert_eq!(r.resolve(30.0, Some(10)).unwrap(), (2, Some(5)));
        assert_eq!(
            FrameRange::seconds(1.0, Some(2.0))
                .resolve(30.0, None)
                .unwrap(),
            (30, Some(60))
        );
        assert!(FrameRange::frames(5, Some(5)).resolve(30.0, None).is_err());
        assert!(FrameRange::frames(3, Some(12))
            .resolve(30.0, Some(10))
            .is_err());
        assert!(FrameRange::frames(10, None)
            .resolve(30.0, Some(10))
            .is_err());
        assert!(FrameRange {
            start: 1.5,
            end: None,
            unit: RangeUnit::Frames
        }
        .resolve(30.0, None)
        .is_err());
        assert!(FrameRange::seconds(-1.0, None).resolve(30.0, None).is_err());
    }

    /// Without ffmpeg, a High-profile MP4 is refused with the profile and the fix named,
    /// while Baseline still decodes.
    #[test]
    fn high_profile_without_ffmpeg_is_a_clear_error() {
        let data = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data"));
        if !data.exists() {
            println!("skipped: ../shared/data not present");
            return;
        }
        let e = open_inner(
            &data.join("campfire.mp4"),
            &ReadOptions::default(),
            false,
            false,
        )
        .err()
        .unwrap();
        let msg = e.to_string();
        assert!(matches!(e, MediaError::Unsupported { .. }), "{msg}");
        assert!(
            msg.contains("h264 (High)")
                && msg.contains("install ffmpeg")
                && msg.contains("PNG sequence"),
            "{msg}"
        );
        let info = probe_inner(&data.join("candle.mp4"), false).unwrap();
        assert_eq!(info.info().decoder, Decoder::Openh264);
    }
}
