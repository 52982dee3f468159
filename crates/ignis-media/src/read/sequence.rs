//! Stills, image sequences (a directory or a printf pattern) and GIFs, via the `image` crate.
//!
//! A directory holds frames sorted by name (digit runs compared as numbers, so `f2.png`
//! comes before `f10.png`; zero-padded names sort the same either way). Hidden files
//! (starting with `.`, e.g. a writer's partial output) and non-image files are ignored.
//! A pattern `frames/%04d.png` (`%d`, `%Nd`, `%0Nd`) matches the files in `frames/` whose
//! name is the prefix, a number and the suffix, in numeric order from the smallest.
//! All frames must have one size; the opener checks every header (not the pixels) and
//! names the first file that differs.

use std::cmp::Ordering;
use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering as AtomicOrdering};

use ignis_core::{RgbaFrame, Size};
use image::ImageFormat;

use super::{Decoder, FrameSource, Probed, SourceInfo};
use crate::convert;
use crate::error::{MediaError, Result};

/// Frame rate assumed for image sequences and stills, which do not store one, unless the
/// process sets another ([`set_sequence_fps`]).
pub const DEFAULT_SEQUENCE_FPS: f64 = 30.0;

/// The bits of the rate [`set_sequence_fps`] set; 0 while it is unset.
static SEQUENCE_FPS_BITS: AtomicU64 = AtomicU64::new(0);

/// The rate image sequences and stills are read at in this process ([`SourceInfo::fps`],
/// their frames' times): [`DEFAULT_SEQUENCE_FPS`] unless [`set_sequence_fps`] set another.
/// (An EXR sequence whose headers state a rate is read at that rate unless one was set:
/// [`SourceInfo::rate_stated`].)
pub fn sequence_fps() -> f64 {
    given_sequence_fps().unwrap_or(DEFAULT_SEQUENCE_FPS)
}

/// The rate [`set_sequence_fps`] set, if it did.
fn given_sequence_fps() -> Option<f64> {
    match SEQUENCE_FPS_BITS.load(AtomicOrdering::Relaxed) {
        0 => None,
        bits => Some(f64::from_bits(bits)),
    }
}

/// The rate an EXR file's header states in the standard `framesPerSecond` attribute (as
/// Ignis's own EXR sequences, OpenImageIO and RV write it), when it is one
/// [`set_sequence_fps`] would accept; `None` for other files.
pub(crate) fn exr_frames_per_second(path: &Path) -> Option<f64> {
    if still_extension(&path.to_string_lossy()) != "exr" {
        return None;
    }
    let meta = exr::meta::MetaData::read_from_file(path, false).ok()?;
    let (n, d) = meta.headers.first()?.own_attributes.frames_per_second?;
    let fps = f64::from(n) / f64::from(d);
    (d > 0 && fps.is_finite() && SEQUENCE_FPS_RANGE.contains(&fps)).then_some(fps)
}

/// Sets the rate image sequences and stills are read at for the rest of this process, as
/// an editor's "interpret footage" or ffmpeg's `-framerate` does: a sequence's files hold
/// pictures, not times, and a 24-fps plate read at 30 plays fast. Process-wide, for a
/// command-line tool's one setting (`ignis --sequence-fps`); videos, GIFs and flipbooks keep
/// their own rates. Refused unless finite and in [`SEQUENCE_FPS_RANGE`].
pub fn set_sequence_fps(fps: f64) -> Result<()> {
    if !(fps.is_finite() && SEQUENCE_FPS_RANGE.contains(&fps)) {
        return Err(MediaError::BadParameter {
            name: "sequence fps",
            reason: format!(
                "{fps} is outside {}..={} frames per second",
                SEQUENCE_FPS_RANGE.start(),
                SEQUENCE_FPS_RANGE.end()
            ),
        });
    }
    SEQUENCE_FPS_BITS.store(fps.to_bits(), AtomicOrdering::Relaxed);
    Ok(())
}

/// The rates [`set_sequence_fps`] accepts: from one frame a second to high-speed footage.
pub const SEQUENCE_FPS_RANGE: std::ops::RangeInclusive<f64> = 1.0..=1000.0;

const STILL_EXTENSIONS: &[&str] = &["png", "jpg", "jpeg", "exr", "tif", "tiff"];

pub(crate) fn is_still_magic(m: &[u8]) -> bool {
    m.starts_with(b"\x89PNG")
        || m.starts_with(&[0xFF, 0xD8, 0xFF])
        || m.starts_with(b"II*\0")
        || m.starts_with(b"MM\0*")
        || m.starts_with(&[0x76, 0x2F, 0x31, 0x01])
}

fn open_reader(path: &Path) -> Result<image::ImageReader<BufReader<File>>> {
    let meta = std::fs::metadata(path).map_err(|e| MediaError::io(path, e))?;
    if !meta.is_file() {
        return Err(MediaError::decode(
            path,
            None,
            "not a regular file (a FIFO, a device or a directory); an image is a file",
        ));
    }
    if meta.len() == 0 {
        return Err(MediaError::decode(
            path,
            None,
            "the file is empty (0 bytes)",
        ));
    }
    image::ImageReader::open(path)
        .map_err(|e| MediaError::io(path, e))?
        .with_guessed_format()
        .map_err(|e| MediaError::io(path, e))
}

pub(crate) fn dimensions(path: &Path) -> Result<Size> {
    let (w, h) = open_reader(path)?
        .into_dimensions()
        .map_err(|e| MediaError::decode(path, None, format!("not a readable image: {e}")))?;
    Size::new(w, h).map_err(|e| MediaError::decode(path, None, e.to_string()))
}

/// Decodes one still to a linear, straight-alpha frame (EXR is un-premultiplied).
pub(crate) fn decode_still(path: &Path) -> Result<RgbaFrame> {
    let reader = open_reader(path)?;
    let exr = reader.format() == Some(ImageFormat::OpenExr);
    let img = reader
        .decode()
        .map_err(|e| MediaError::decode(path, None, format!("not a readable image: {e}")))?;
    let mut frame = convert::from_dynamic(img)?;
    if exr {
        convert::unpremultiply(&mut frame);
    }
    Ok(frame)
}

fn codec_of(path: &Path) -> String {
    match image::ImageReader::open(path)
        .ok()
        .and_then(|r| r.with_guessed_format().ok())
        .and_then(|r| r.format())
    {
        Some(f) => f
            .extensions_str()
            .first()
            .copied()
            .unwrap_or("image")
            .to_string(),
        None => "image".into(),
    }
}

pub(crate) fn probe_image(path: &Path) -> Result<Probed> {
    let size = dimensions(path)?;
    Ok(Probed::Image(SourceInfo {
        size,
        fps: sequence_fps(),
        frame_count: Some(1),
        codec: codec_of(path),
        decoder: Decoder::Image,
        path: path.to_path_buf(),
        anamorphic: None,
        rate_stated: false,
    }))
}

/// Natural order: digit runs compare as numbers.
fn natural_cmp(a: &str, b: &str) -> Ordering {
    let (mut a, mut b) = (a.as_bytes(), b.as_bytes());
    loop {
        match (a.first(), b.first()) {
            (None, None) => return Ordering::Equal,
            (None, _) => return Ordering::Less,
            (_, None) => return Ordering::Greater,
            (Some(x), Some(y)) if x.is_ascii_digit() && y.is_ascii_digit() => {
                let la = a.iter().take_while(|c| c.is_ascii_digit()).count();
                let lb = b.iter().take_while(|c| c.is_ascii_digit()).count();
                let (da, db) = (&a[..la], &b[..lb]);
                let ta = trim_zeros(da);
                let tb = trim_zeros(db);
                let o = ta.len().cmp(&tb.len()).then(ta.cmp(tb)).then(la.cmp(&lb));
                if o != Ordering::Equal {
                    return o;
                }
                a = &a[la..];
                b = &b[lb..];
            }
            (Some(x), Some(y)) => {
                if x != y {
                    return x.cmp(y);
                }
                a = &a[1..];
                b = &b[1..];
            }
        }
    }
}

fn trim_zeros(d: &[u8]) -> &[u8] {
    let n = d.iter().take_while(|&&c| c == b'0').count();
    &d[n.min(d.len().saturating_sub(1))..]
}

/// A parsed printf frame pattern: `prefix`, `%0{width}d`, `suffix`.
#[derive(Debug, PartialEq)]
pub(crate) struct Pattern {
    pub prefix: String,
    pub width: usize,
    pub suffix: String,
}

/// Where a name holds its frame number as compositors and renderers write it, one `#` per
/// digit (`shot.####.exr`: Nuke, Blender, RV, Deadline; `%04d` in ffmpeg's form), as the
/// run's start and length: a single run of at most 20, directly before a `.`, not after a
/// digit, in a name without `%`. Anything else (`take#2.mp4`) is no pattern.
fn hash_run(name: &str) -> Option<(usize, usize)> {
    let i = name.find('#')?;
    let n = name[i..].bytes().take_while(|&b| b == b'#').count();
    let rest = &name[i + n..];
    let after_digit = name[..i].bytes().last().is_some_and(|b| b.is_ascii_digit());
    (n <= 20 && rest.starts_with('.') && !after_digit && !rest.contains('#') && !name.contains('%'))
        .then_some((i, n))
}

/// Whether `name` is a frame pattern written with `#`s ([`hash_run`]) rather than `%Nd`.
pub(crate) fn is_hash_pattern(name: &str) -> bool {
    hash_run(name).is_some()
}

impl Pattern {
    /// `prefix%0Nd.suffix` (also `%d`, `%Nd`) or `prefix.####.suffix` ([`hash_run`]).
    pub(crate) fn parse(name: &str) -> Option<Pattern> {
        if let Some((i, n)) = hash_run(name) {
            return Some(Pattern {
                prefix: name[..i].to_string(),
                width: n,
                suffix: name[i + n..].to_string(),
            });
        }
        let i = name.find('%')?;
        let rest = &name[i + 1..];
        let digits = rest.chars().take_while(|c| c.is_ascii_digit()).count();
        if !rest[digits..].starts_with('d') {
            return None;
        }
        // At most 20 digits (u64::MAX); a wider field is not a frame number.
        let width: usize = match rest[..digits].parse() {
            Ok(w) if w <= 20 => w,
            Ok(_) => return None,
            Err(_) if digits == 0 => 0,
            Err(_) => return None,
        };
        let suffix = &rest[digits + 1..];
        if suffix.contains('%') {
            return None;
        }
        Some(Pattern {
            prefix: name[..i].to_string(),
            width,
            suffix: suffix.to_string(),
        })
    }
    pub(crate) fn format(&self, n: u64) -> String {
        format!("{}{:0w$}{}", self.prefix, n, self.suffix, w = self.width)
    }
    pub(crate) fn matches(&self, name: &str) -> Option<u64> {
        let mid = name
            .strip_prefix(&self.prefix)?
            .strip_suffix(&self.suffix)?;
        if mid.is_empty() || !mid.bytes().all(|c| c.is_ascii_digit()) || mid.len() < self.width {
            return None;
        }
        mid.parse().ok()
    }
}

fn list_dir(dir: &Path) -> Result<Vec<(String, PathBuf)>> {
    let rd = std::fs::read_dir(dir).map_err(|e| MediaError::io(dir, e))?;
    let mut out = Vec::new();
    for e in rd {
        let e = e.map_err(|e| MediaError::io(dir, e))?;
        let Ok(name) = e.file_name().into_string() else {
            continue;
        };
        if name.starts_with('.') || !e.path().is_file() {
            continue;
        }
        out.push((name, e.path()));
    }
    Ok(out)
}

pub(crate) fn probe_pattern(path: &Path) -> Result<Probed> {
    let name = path
        .file_name()
        .and_then(|n| n.to_str())
        .unwrap_or_default();
    let pat = Pattern::parse(name).ok_or_else(|| {
        MediaError::bad(
            "path",
            format!(
                "`{name}` is not a frame pattern; write e.g. frames/%04d.png or frames/####.png"
            ),
        )
    })?;
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    let mut files: Vec<(u64, PathBuf)> = list_dir(&dir)?
        .into_iter()
        .filter_map(|(n, p)| pat.matches(&n).map(|k| (k, p)))
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(MediaError::io(
            path,
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                format!("no files in {} match `{name}`", dir.display()),
            ),
        ));
    }
    let numbers: Vec<u64> = files.iter().map(|(k, _)| *k).collect();
    // frames no decoder here reads (DPX, TGA, …): how to convert them, with the numbers
    if let Err(e) = dimensions(&files[0].1) {
        let ext = still_extension(&pat.suffix);
        if !STILL_EXTENSIONS.contains(&ext.as_str()) {
            let convert = ffmpeg_to_png(&dir, &pat.prefix, pat.width, &pat.suffix, numbers[0]);
            // ffmpeg reads a numbered sequence up to its first gap
            let gap = missing_frames(&numbers).1.first().map(|&gap| {
                let next = numbers.iter().find(|&&n| n > gap).copied().unwrap_or(gap);
                format!(
                    "; it stops before the missing frame {gap}: run it again with \
                     -start_number {next} (both) for the frames from {next}"
                )
            });
            return Err(unread_frames(path, &ext, &convert, gap.as_deref()));
        }
        return Err(e);
    }
    finish_sequence(
        path,
        files.into_iter().map(|(_, p)| p).collect(),
        Some(&numbers),
    )
}

/// The ffmpeg command converting the numbered frames `dir/{prefix}{number}{suffix}`, their
/// numbers `width` digits wide (at most 1: not padded) from `first`, to PNGs of the same
/// names and numbers.
fn ffmpeg_to_png(dir: &Path, prefix: &str, width: usize, suffix: &str, first: u64) -> String {
    let field = match width {
        0 | 1 => "%d".to_string(),
        w => format!("%0{w}d"),
    };
    let png = match suffix.rsplit_once('.') {
        Some((stem, _)) => format!("{stem}.png"),
        None => format!("{suffix}.png"),
    };
    let start = start_number(first);
    format!(
        "ffmpeg {start}-i {} {start}{}",
        shell_word(&dir.join(format!("{prefix}{field}{suffix}"))),
        shell_word(&dir.join(format!("{prefix}{field}{png}")))
    )
}

/// `path` as one shell word: as it is when it holds only characters no shell treats
/// specially, else in single quotes.
fn shell_word(path: &Path) -> String {
    let s = path.display().to_string();
    if s.bytes()
        .all(|b| b.is_ascii_alphanumeric() || b"_./%-+,:@".contains(&b))
    {
        s
    } else {
        format!("'{}'", s.replace('\'', "'\\''"))
    }
}

/// ffmpeg's `-start_number` option (and a space) for a sequence numbered from `n`, given
/// to its input and its output alike so that the converted files keep their numbers
/// (ffmpeg numbers what it writes from 1); empty for 1.
fn start_number(n: u64) -> String {
    match n {
        1 => String::new(),
        n => format!("-start_number {n} "),
    }
}

/// The lower-case extension of a file name or suffix (`""` without one).
fn still_extension(name: &str) -> String {
    name.rsplit_once('.')
        .map(|(_, e)| e.to_ascii_lowercase())
        .unwrap_or_default()
}

/// A sequence of `.ext` frames (`ext` lower-case, [`still_extension`]), a format this crate
/// does not decode (DPX, Cineon, TGA, …), with the ffmpeg command `convert` that turns them
/// into frames it reads; `gap`: what to add about a missing frame, where ffmpeg stops.
fn unread_frames(path: &Path, ext: &str, convert: &str, gap: Option<&str>) -> MediaError {
    const LEVELS_NOTE: &str = " (a 16-bit PNG keeps a 10- or 12-bit scan's levels, and the \
                               colours stay as they are, log or not)";
    MediaError::Unsupported {
        path: path.to_path_buf(),
        what: format!(".{ext} frames"),
        fix: format!(
            "Ignis reads PNG, JPEG, TIFF and EXR frames; convert these with ffmpeg first: \
             `{convert}`{}{}",
            gap.unwrap_or_default(),
            match ext {
                "dpx" | "cin" => LEVELS_NOTE,
                _ => "",
            }
        ),
    }
}

/// Still formats ffmpeg reads and this crate does not, for which a directory of frames gets
/// a conversion command ([`other_frames`]).
const FFMPEG_FRAME_EXTENSIONS: &[&str] = &[
    "dpx", "cin", "tga", "bmp", "webp", "sgi", "jp2", "j2k", "jxl", "hdr", "ppm", "pnm", "qoi",
];

/// For a directory without frames this crate reads: the error naming its numbered frames in
/// a format ffmpeg reads (DPX, …) and the command converting them, from the first of them
/// in natural order (`s.1001.dpx`: `ffmpeg -start_number 1001 -i dir/s.%04d.dpx
/// dir/s.%04d.png`). `None` when it holds none.
fn other_frames(dir: &Path) -> Result<Option<MediaError>> {
    let mut names: Vec<String> = list_dir(dir)?
        .into_iter()
        .map(|(n, _)| n)
        .filter(|n| FFMPEG_FRAME_EXTENSIONS.contains(&still_extension(n).as_str()))
        .collect();
    names.sort_by(|a, b| natural_cmp(a, b));
    let Some(first) = names.first() else {
        return Ok(None);
    };
    let ext = still_extension(first);
    let stem = &first[..first.len() - ext.len() - 1];
    let digits = stem.bytes().rev().take_while(u8::is_ascii_digit).count();
    let convert = match stem[stem.len() - digits..].parse::<u64>() {
        Ok(n) => ffmpeg_to_png(
            dir,
            &stem[..stem.len() - digits],
            digits,
            &format!(".{ext}"),
            n,
        ),
        Err(_) => format!(
            "ffmpeg -i {} {}",
            shell_word(&dir.join(first)),
            shell_word(&dir.join(format!("{stem}.png")))
        ),
    };
    Ok(Some(unread_frames(dir, &ext, &convert, None)))
}

pub(crate) fn probe_dir(dir: &Path) -> Result<Probed> {
    let mut files: Vec<(String, PathBuf)> = list_dir(dir)?
        .into_iter()
        .filter(|(n, _)| STILL_EXTENSIONS.contains(&still_extension(n).as_str()))
        .collect();
    files.sort_by(|a, b| natural_cmp(&a.0, &b.0));
    if files.is_empty() {
        // the directory `ignis eigen train` writes, given where footage goes
        if dir.join("manifest.json").is_file() && dir.join("packs").is_dir() {
            return Err(MediaError::decode(
                dir,
                None,
                format!(
                    "this is an Eigenfire database (what `ignis eigen train` writes), not \
                     footage; describe it with `ignis eigen info {0}`, or loop one of its clips \
                     with `ignis eigen loop {0} --clip NAME`",
                    dir.display()
                ),
            ));
        }
        if let Some(e) = other_frames(dir)? {
            return Err(e);
        }
        return Err(MediaError::io(
            dir,
            std::io::Error::new(
                std::io::ErrorKind::NotFound,
                "the directory holds no PNG, JPEG, EXR or TIFF frames",
            ),
        ));
    }
    let numbers = frame_numbers(files.iter().map(|(n, _)| n.as_str()));
    finish_sequence(
        dir,
        files.into_iter().map(|(_, p)| p).collect(),
        numbers.as_deref(),
    )
}

/// The frame number of each name, in order, when every name is one prefix, a number and
/// one suffix (`f0001.png`, `f0002.png`, …; the number is the last run of digits): what
/// [`missing_frames`] reads a directory's gaps from. `None` for names of another form.
fn frame_numbers<'a>(names: impl Iterator<Item = &'a str>) -> Option<Vec<u64>> {
    let mut form: Option<(&str, &str)> = None;
    let mut out = Vec::new();
    for name in names {
        let end = name.rfind(|c: char| c.is_ascii_digit())? + 1;
        let start = name[..end]
            .char_indices()
            .rev()
            .find(|(_, c)| !c.is_ascii_digit())
            .map_or(0, |(i, c)| i + c.len_utf8());
        let (prefix, suffix) = (&name[..start], &name[end..]);
        match form {
            None => form = Some((prefix, suffix)),
            Some(f) if f != (prefix, suffix) => return None,
            Some(_) => {}
        }
        out.push(name[start..end].parse().ok()?);
    }
    Some(out)
}

/// A sequence's own step between frame numbers: the commonest difference between
/// neighbours in `numbers` (ascending), the smaller on a tie (1, or 2 for a render on
/// twos); `None` without two different numbers.
fn own_step(numbers: &[u64]) -> Option<u64> {
    let mut counts = std::collections::BTreeMap::new();
    for w in numbers.windows(2) {
        let d = w[1].saturating_sub(w[0]);
        if d > 0 {
            *counts.entry(d).or_insert(0usize) += 1;
        }
    }
    counts
        .into_iter()
        .max_by(|a, b| a.1.cmp(&b.1).then(b.0.cmp(&a.0)))
        .map(|(step, _)| step)
}

/// When a sequence's frames are shown, from their numbers, where frames are missing from
/// it: one frame per number at the sequence's own step, at `fps` ([`sequence_fps`]), so
/// that a lost frame is a step twice as long, as a dropped frame is in a video's
/// timestamps ([`super::frame_timing`]: `ignis convert` then holds the frame before each
/// gap, `--seconds` counts by the numbers, and training names the stretches without one).
/// `None` when nothing is missing, the numbers do not rise from file to file, or more
/// numbers are missing than there are files: names that count something else (a
/// timestamp), not a few lost frames.
pub(crate) fn gap_times(numbers: &[u64], fps: f64) -> Option<Vec<f64>> {
    if !rising(numbers) {
        return None;
    }
    let (missing, _) = missing_frames(numbers);
    if missing == 0 || !lost_frames(missing, numbers.len()) {
        return None;
    }
    let step = own_step(numbers)? as f64;
    let first = numbers[0];
    Some(
        numbers
            .iter()
            .map(|&n| (n - first) as f64 / step / fps)
            .collect(),
    )
}

/// [`super::file_numbers_hint`] for a sequence of `files` numbered `numbers` (ascending),
/// frames `start..end` asked for.
pub(crate) fn numbers_hint(
    numbers: &[u64],
    files: &[PathBuf],
    start: u64,
    end: Option<u64>,
) -> Option<String> {
    let first = *numbers.first()?;
    if first == 0 || !rising(numbers) {
        return None;
    }
    let i = numbers.partition_point(|&n| n < start);
    let j = end.map_or(numbers.len(), |e| numbers.partition_point(|&n| n < e));
    if i >= j {
        return None;
    }
    let name = files.first()?.file_name()?.to_string_lossy();
    let (asked, frames) = match end {
        Some(e) => (format!("{start}..{e}"), format!("{i}..{j}")),
        None => (format!("{start}.."), format!("{i}..")),
    };
    Some(format!(
        "frames count from 0 in the order read, not by file number ({name} is frame 0): file \
         numbers {asked} are frames {frames}"
    ))
}

/// Whether every file's number is above the one before (not so for `f1`, `f01`).
fn rising(numbers: &[u64]) -> bool {
    numbers.windows(2).all(|w| w[0] < w[1])
}

/// Whether `missing` numbers skipped by a sequence of `files` files are frames lost from
/// it (a render farm's failed frames, a few dropped ones) rather than names that count
/// something else (times of day, take numbers): no more of them than there are files.
fn lost_frames(missing: u64, files: usize) -> bool {
    missing <= files as u64
}

/// How many frame numbers a sequence skips, and the first few of them: of `numbers`
/// (ascending), those between the first and the last at the sequence's own step (the
/// commonest difference between neighbours, the smaller on a tie: 1, or 2 for a render on
/// twos) that have no file. A render farm's lost frame shows as a jump in the motion.
pub(crate) fn missing_frames(numbers: &[u64]) -> (u64, Vec<u64>) {
    let Some(step) = own_step(numbers) else {
        return (0, Vec::new());
    };
    let (mut count, mut first) = (0u64, Vec::new());
    for w in numbers.windows(2) {
        let d = w[1].saturating_sub(w[0]);
        if d > step {
            let skipped = (d - 1) / step;
            count = count.saturating_add(skipped);
            let mut k = w[0] + step;
            while k < w[1] && first.len() < 5 {
                first.push(k);
                k = k.saturating_add(step);
            }
        }
    }
    (count, first)
}

fn finish_sequence(path: &Path, files: Vec<PathBuf>, numbers: Option<&[u64]>) -> Result<Probed> {
    let size = dimensions(&files[0])?;
    for f in &files[1..] {
        let s = dimensions(f)?;
        if s != size {
            return Err(MediaError::decode(
                f,
                None,
                format!(
                    "frame size {s} differs from {size} of the first frame {}",
                    files[0].display()
                ),
            ));
        }
    }
    let mut codec = format!("{} sequence", codec_of(&files[0]));
    if let Some((n, first)) = numbers.map(missing_frames).filter(|m| m.0 > 0) {
        codec = if lost_frames(n, files.len()) {
            let listed: Vec<String> = first.iter().map(u64::to_string).collect();
            let more = if n > first.len() as u64 { ", …" } else { "" };
            format!(
                "{codec}, {n} frame{} missing ({}{more}): read without {}, a jump at each gap",
                if n == 1 { "" } else { "s" },
                listed.join(", "),
                if n == 1 { "it" } else { "them" },
            )
        } else {
            format!(
                "{codec}, its numbers skip {n}, more than it has files (times or takes, not \
                 lost frames): read one frame per file"
            )
        };
    }
    // a rate set for this run, else the one its EXR headers state, else the default
    let stated = match given_sequence_fps() {
        Some(_) => None,
        None => exr_frames_per_second(&files[0]),
    };
    if let Some(fps) = stated {
        let fps = format!("{fps:.3}");
        codec = format!(
            "{codec}, {} fps in its headers",
            fps.trim_end_matches('0').trim_end_matches('.')
        );
    }
    let info = SourceInfo {
        size,
        fps: stated.unwrap_or_else(sequence_fps),
        frame_count: Some(files.len() as u64),
        codec,
        decoder: Decoder::ImageSequence,
        path: path.to_path_buf(),
        anamorphic: None,
        rate_stated: stated.is_some(),
    };
    Ok(Probed::Sequence(info, files, numbers.map(<[u64]>::to_vec)))
}

/// Decodes the files of a sequence in order, from frame `start`.
pub(crate) struct SequenceSource {
    files: std::vec::IntoIter<PathBuf>,
}

impl SequenceSource {
    pub(crate) fn new(files: Vec<PathBuf>, start: u64) -> SequenceSource {
        let mut files = files.into_iter();
        if start > 0 {
            files.nth(start as usize - 1);
        }
        SequenceSource { files }
    }
}

impl FrameSource for SequenceSource {
    fn next_frame(&mut self) -> Option<Result<RgbaFrame>> {
        let f = self.files.next()?;
        Some(decode_still(&f))
    }
}

/// Whether a file name holds a frame-number field, `%d` or `%0Nd`: a sequence pattern.
/// A `%` otherwise (`100% fire.mp4`) is part of an ordinary name.
pub(crate) fn has_frame_number(name: &str) -> bool {
    is_hash_pattern(name)
        || name.match_indices('%').any(|(i, _)| {
            let rest = name[i + 1..].trim_start_matches(|c: char| c.is_ascii_digit());
            rest.starts_with('d')
        })
}

type GifDecoder = gif::Decoder<BufReader<File>>;

fn gif_decoder(path: &Path) -> Result<GifDecoder> {
    let f = File::open(path).map_err(|e| MediaError::io(path, e))?;
    let mut opts = gif::DecodeOptions::new();
    opts.set_color_output(gif::ColorOutput::RGBA);
    opts.read_info(BufReader::new(f))
        .map_err(|e| MediaError::decode(path, None, format!("not a readable GIF: {e}")))
}

pub(crate) fn probe_gif(path: &Path) -> Result<Probed> {
    let f = File::open(path).map_err(|e| MediaError::io(path, e))?;
    let mut opts = gif::DecodeOptions::new();
    // Frame headers only: the frames' compressed data is skipped, not decoded.
    opts.skip_frame_decoding(true);
    let mut dec = opts
        .read_info(BufReader::new(f))
        .map_err(|e| MediaError::decode(path, None, format!("not a readable GIF: {e}")))?;
    let size = Size::new(dec.width() as u32, dec.height() as u32)
        .map_err(|e| MediaError::decode(path, None, e.to_string()))?;
    let (frames, centiseconds, complete) =
        gif_delays(&mut dec).map_err(|e| MediaError::decode(path, Some(0), e.to_string()))?;
    if frames == 0 {
        return Err(MediaError::decode(path, None, "the GIF has no frames"));
    }
    Ok(Probed::Gif(SourceInfo {
        size,
        fps: gif_rate(frames, centiseconds),
        frame_count: complete.then_some(frames),
        codec: "gif".into(),
        decoder: Decoder::Gif,
        path: path.to_path_buf(),
        anamorphic: None,
        rate_stated: true,
    }))
}

/// Frames and summed delays (centiseconds) of a GIF, read frame header by frame header,
/// and whether the file was read to its end. An error on the first frame is returned; a
/// later one (a truncated file) ends the count there, as the frames before it still play.
fn gif_delays<R: std::io::Read>(
    dec: &mut gif::Decoder<R>,
) -> std::result::Result<(u64, u64, bool), gif::DecodingError> {
    let (mut frames, mut centiseconds) = (0u64, 0u64);
    loop {
        match dec.read_next_frame() {
            Ok(Some(f)) => {
                frames += 1;
                centiseconds += u64::from(f.delay);
            }
            Ok(None) => return Ok((frames, centiseconds, true)),
            Err(e) if frames == 0 => return Err(e),
            Err(_) => return Ok((frames, centiseconds, false)),
        }
    }
}

/// A GIF's frame rate: frames over their summed delays. Writers that keep a rate such as
/// 30 fps in whole centiseconds alternate delays (3, 3, 4 cs), so the first delay alone
/// would read 33.3 fps. Without any delay the rate is 10 fps, as browsers play it.
fn gif_rate(frames: u64, centiseconds: u64) -> f64 {
    if centiseconds == 0 {
        10.0
    } else {
        100.0 * frames as f64 / centiseconds as f64
    }
}

/// Streams the frames of a GIF composited onto its canvas (disposal methods honoured;
/// the background is transparent).
pub(crate) struct GifSource {
    dec: GifDecoder,
    canvas: Vec<u8>,
    saved: Vec<u8>,
    /// Disposal of the previous frame: method and rectangle (left, top, width, height).
    pending: Option<(gif::DisposalMethod, [usize; 4])>,
    size: Size,
    path: PathBuf,
    index: u64,
}

impl GifSource {
    pub(crate) fn start(path: &Path, start: u64) -> Result<GifSource> {
        let dec = gif_decoder(path)?;
        let size = Size::new(dec.width() as u32, dec.height() as u32)
            .map_err(|e| MediaError::decode(path, None, e.to_string()))?;
        let mut s = GifSource {
            dec,
            canvas: vec![0; size.pixels() * 4],
            saved: Vec::new(),
            pending: None,
            size,
            path: path.to_path_buf(),
            index: 0,
        };
        for _ in 0..start {
            match s.advance() {
                Ok(true) => {}
                Ok(false) => break,
                Err(e) => return Err(e),
            }
        }
        Ok(s)
    }

    /// Composites the next frame onto the canvas; false at the end.
    fn advance(&mut self) -> Result<bool> {
        let w = self.size.width as usize;
        let h = self.size.height as usize;
        if let Some((method, [l, t, fw, fh])) = self.pending.take() {
            match method {
                gif::DisposalMethod::Background => {
                    for y in t..(t + fh).min(h) {
                        let a = (y * w + l.min(w)) * 4;
                        let b = (y * w + (l + fw).min(w)) * 4;
                        self.canvas[a..b].fill(0);
                    }
                }
                gif::DisposalMethod::Previous if self.saved.len() == self.canvas.len() => {
                    self.canvas.copy_from_slice(&self.saved);
                }
                _ => {}
            }
        }
        let frame = match self.dec.read_next_frame() {
            Ok(Some(f)) => f,
            Ok(None) => return Ok(false),
            Err(e) => {
                return Err(MediaError::decode(
                    &self.path,
                    Some(self.index),
                    e.to_string(),
                ))
            }
        };
        let (l, t) = (frame.left as usize, frame.top as usize);
        let (fw, fh) = (frame.width as usize, frame.height as usize);
        if frame.dispose == gif::DisposalMethod::Previous {
            self.saved.clone_from(&self.canvas);
        }
        for y in 0..fh {
            let cy = t + y;
            if cy >= h {
                break;
            }
            for x in 0..fw {
                let cx = l + x;
                if cx >= w {
                    break;
                }
                let src = &frame.buffer[(y * fw + x) * 4..(y * fw + x) * 4 + 4];
                if src[3] != 0 {
                    self.canvas[(cy * w + cx) * 4..(cy * w + cx) * 4 + 4].copy_from_slice(src);
                }
            }
        }
        self.pending = Some((frame.dispose, [l, t, fw, fh]));
        self.index += 1;
        Ok(true)
    }
}

impl FrameSource for GifSource {
    fn next_frame(&mut self) -> Option<Result<RgbaFrame>> {
        match self.advance() {
            Ok(true) => Some(Ok(convert::from_srgba8(self.size, &self.canvas))),
            Ok(false) => None,
            Err(e) => Some(Err(e)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_order() {
        let mut v = vec!["f10.png", "f2.png", "f1.png", "f02.png"];
        v.sort_by(|a, b| natural_cmp(a, b));
        assert_eq!(v, ["f1.png", "f2.png", "f02.png", "f10.png"]);
    }

    #[test]
    fn missing_frames_at_the_sequences_own_step() {
        assert_eq!(missing_frames(&[1, 2, 3, 4]), (0, vec![]));
        assert_eq!(missing_frames(&[1, 2, 4, 5, 9]), (4, vec![3, 6, 7, 8]));
        // rendered on twos: every other number is not missing
        assert_eq!(missing_frames(&[0, 2, 4, 8, 10]), (1, vec![6]));
        // a huge gap is counted, a few listed
        let (n, first) = missing_frames(&[1, 2, 3, 1_000_000]);
        assert_eq!((n, first), (999_996, vec![4, 5, 6, 7, 8]));
        assert_eq!(missing_frames(&[]), (0, vec![]));
        // numbers up to u64::MAX (a 20-digit field) do not overflow
        assert_eq!(
            missing_frames(&[0, u64::MAX - 1, u64::MAX]),
            (u64::MAX - 2, vec![1, 2, 3, 4, 5])
        );
        assert_eq!(missing_frames(&[7]), (0, vec![]));
    }

    #[test]
    fn gaps_are_timed_by_the_frame_numbers() {
        let fps = DEFAULT_SEQUENCE_FPS;
        // nothing missing: no times (one rate for all)
        assert_eq!(gap_times(&[1, 2, 3, 4], fps), None);
        assert_eq!(gap_times(&[0, 2, 4, 6], fps), None);
        // frame 3 lost: a step twice as long; on twos, counted in steps of two (at the
        // rate given)
        assert_eq!(
            gap_times(&[1, 2, 4, 5], fps),
            Some(vec![0.0, 1.0 / fps, 3.0 / fps, 4.0 / fps])
        );
        assert_eq!(
            gap_times(&[10, 12, 16, 18], 24.0),
            Some(vec![0.0, 1.0 / 24.0, 3.0 / 24.0, 4.0 / 24.0])
        );
        // more missing than there are files (a timestamp, not lost frames); numbers that
        // do not rise from file to file (`f1`, `f01`)
        assert_eq!(gap_times(&[1, 2, 3, 1_000_000], fps), None);
        assert_eq!(gap_times(&[1, 1, 2, 4], fps), None);
        assert_eq!(gap_times(&[], fps), None);
        assert_eq!(gap_times(&[7], fps), None);
    }

    #[test]
    fn a_sequence_rate_that_is_not_one_is_refused() {
        for bad in [0.0, -24.0, 0.5, 1000.5, f64::NAN, f64::INFINITY] {
            let e = set_sequence_fps(bad).unwrap_err().to_string();
            assert!(e.contains("outside 1..=1000 frames per second"), "{e}");
        }
        // a refused rate changes nothing (no test in this crate sets one: it is process-wide)
        assert_eq!(sequence_fps(), DEFAULT_SEQUENCE_FPS);
    }

    #[test]
    fn file_numbers_are_said_as_frames() {
        let files: Vec<PathBuf> = (1001..1011)
            .map(|n| PathBuf::from(format!("s/shot.{n}.exr")))
            .collect();
        let numbers: Vec<u64> = (1001..1011).collect();
        assert_eq!(
            numbers_hint(&numbers, &files, 1001, Some(1005)).as_deref(),
            Some(
                "frames count from 0 in the order read, not by file number (shot.1001.exr is \
                 frame 0): file numbers 1001..1005 are frames 0..4"
            )
        );
        assert!(numbers_hint(&numbers, &files, 1004, None)
            .unwrap()
            .ends_with("file numbers 1004.. are frames 3.."));
        // with file 1003 missing, file numbers 1002..1006 are the three frames 1..4
        let (mut numbers, mut files) = (numbers, files);
        numbers.remove(2);
        files.remove(2);
        assert!(numbers_hint(&numbers, &files, 1002, Some(1006))
            .unwrap()
            .ends_with("file numbers 1002..1006 are frames 1..4"));
        // numbers no file has, or a sequence numbered from 0: nothing to say
        assert_eq!(numbers_hint(&numbers, &files, 5000, Some(6000)), None);
        assert_eq!(numbers_hint(&numbers, &files, 10, Some(20)), None);
        assert_eq!(numbers_hint(&[0, 1, 2], &files[..3], 5, None), None);
    }

    proptest::proptest! {
        /// Any names, any numbers: no panic; a name's number is its last digit run; every
        /// frame listed as missing lies inside the sequence and has no file.
        #[test]
        fn gaps_of_any_names(names in proptest::collection::vec(".{0,12}", 0..8),
                             mut numbers in proptest::collection::vec(proptest::prelude::any::<u64>(), 0..8)) {
            if let Some(n) = frame_numbers(names.iter().map(String::as_str)) {
                proptest::prop_assert_eq!(n.len(), names.len());
            }
            numbers.sort_unstable();
            let (count, listed) = missing_frames(&numbers);
            proptest::prop_assert!(listed.len() <= 5 && listed.len() as u64 <= count);
            for k in listed {
                proptest::prop_assert!(!numbers.contains(&k));
                proptest::prop_assert!(numbers[0] < k && k < numbers[numbers.len() - 1]);
            }
        }
    }

    #[test]
    fn frame_numbers_of_one_form_only() {
        let names = ["f0001.png", "f0002.png", "f0010.png"];
        assert_eq!(frame_numbers(names.into_iter()), Some(vec![1, 2, 10]));
        assert_eq!(
            frame_numbers(["shot2_001.exr", "shot2_002.exr"].into_iter()),
            Some(vec![1, 2])
        );
        assert_eq!(frame_numbers(["a1.png", "b2.png"].into_iter()), None);
        // a name of more than ASCII: the number after a two-byte letter
        assert_eq!(
            frame_numbers(["é001.png", "é003.png"].into_iter()),
            Some(vec![1, 3])
        );
        assert_eq!(
            frame_numbers(["001é.png", "002é.png"].into_iter()),
            Some(vec![1, 2])
        );
        assert_eq!(frame_numbers(["plate.png"].into_iter()), None);
    }

    #[test]
    fn patterns() {
        let p = Pattern::parse("%04d.png").unwrap();
        assert_eq!(
            p,
            Pattern {
                prefix: "".into(),
                width: 4,
                suffix: ".png".into()
            }
        );
        assert_eq!(p.format(7), "0007.png");
        assert_eq!(p.matches("0012.png"), Some(12));
        assert_eq!(p.matches("12.png"), None);
        assert_eq!(p.matches("0012.exr"), None);
        assert_eq!(
            Pattern::parse("f_%d.exr").unwrap().matches("f_123.exr"),
            Some(123)
        );
        assert!(Pattern::parse("f_%s.png").is_none());
    }

    #[test]
    fn hash_patterns_as_compositors_write_them() {
        let p = Pattern::parse("shot.####.exr").unwrap();
        assert_eq!(
            p,
            Pattern {
                prefix: "shot.".into(),
                width: 4,
                suffix: ".exr".into()
            }
        );
        assert_eq!(p.format(1001), "shot.1001.exr");
        assert_eq!(p.format(7), "shot.0007.exr");
        assert_eq!(p.matches("shot.1001.exr"), Some(1001));
        assert_eq!(p.matches("shot.12345.exr"), Some(12345));
        assert_eq!(p.matches("shot.101.exr"), None);
        assert_eq!(
            Pattern::parse("f_#.png").unwrap().matches("f_123.png"),
            Some(123)
        );
        assert_eq!(Pattern::parse("####.png").unwrap().format(3), "0003.png");
        for name in [
            "take#2.mp4",
            "a#b.png",
            "v2##.png",
            "s.##.##.png",
            "s.##x.png",
            "plain.png",
        ] {
            assert!(
                Pattern::parse(name).is_none() && !has_frame_number(name),
                "{name}"
            );
        }
        assert!(has_frame_number("shot.####.exr") && is_hash_pattern("shot_##.png"));
        assert!(Pattern::parse(&format!("s.{}.png", "#".repeat(21))).is_none());
    }
}
