//! Footage: the one way frames come into `ignis-eigen`, for training (a clip read from a
//! start frame) and for rendering (original colouring, smoke and custom masks read at
//! chosen frames).
//!
//! [`Footage`] is a clip: its [`FootageInfo`], its frames from a start index, and its
//! frames at chosen indices. Implementations: [`SyntheticFootage`] (Ignis's own drawn
//! clips), [`FrameList`] (frames already in memory) and, with the `media` feature,
//! [`MediaFootage`] over `ignis-media` (videos, image sequences). Rendering asks a
//! [`FootageOpener`] for the footage of a database clip (or of another file, such as a
//! custom mask); [`SyntheticSources`] opens synthetic clips only. Rendering reads through
//! [`Footage::source_frames_at`]: 8-bit footage may stay 8-bit ([`SourceFrame::Srgb8`],
//! a quarter of the memory and no conversion pass; read through [`srgb8_table`], the
//! same values as the linear frame).

use std::borrow::Cow;
use std::path::Path;

use ignis_core::{RgbaFrame, Size};

use crate::db::ClipEntry;
use crate::error::{EigenError, Result};
use crate::synthetic::{parse_source_name, source_name, synthetic_frame, SyntheticParams};

/// What a clip is: where it comes from, its frame size, rate and length.
#[derive(Clone, Debug, PartialEq)]
pub struct FootageInfo {
    /// Description for the manifest (a path or `synthetic:candle:seed=1`).
    pub source: String,
    pub fps: f64,
    /// Frame size.
    pub size: Size,
    /// Number of frames when known (containers usually say).
    pub frame_count: Option<usize>,
}

/// A stream of decoded frames (linear RGBA).
pub type Frames<'a> = Box<dyn Iterator<Item = Result<RgbaFrame>> + 'a>;

/// A source frame for rendering: linear light, or the 8-bit sRGB RGBA bytes an 8-bit
/// decoder made (straight alpha, stored linearly), read through [`srgb8_table`] where
/// used — 4 bytes a pixel instead of 16, and no conversion pass. Both give the same
/// linear values (`ignis-media`'s 8-bit decoding rule).
#[derive(Clone, Debug, PartialEq)]
pub enum SourceFrame {
    Linear(RgbaFrame),
    /// `size.pixels() * 4` bytes, rows top to bottom.
    Srgb8 {
        size: Size,
        bytes: Vec<u8>,
    },
}

/// The linear value of each 8-bit sRGB code (`ignis_core::palette::srgb_to_linear` of
/// `code / 255`, as `ignis-media` decodes 8-bit footage).
pub fn srgb8_table() -> &'static [f32; 256] {
    ignis_core::palette::srgb8_to_linear_table()
}

/// Linear RGBA of 8-bit sRGB RGBA bytes `p` (alpha `p[3] / 255`, read from a table of
/// those quotients: no division per pixel).
#[inline]
pub fn srgb8_pixel(t: &[f32; 256], p: &[u8]) -> [f32; 4] {
    [
        t[p[0] as usize],
        t[p[1] as usize],
        t[p[2] as usize],
        ALPHA8[p[3] as usize],
    ]
}

/// `a as f32 / 255.0` for every byte `a` (the same quotients, computed at compile time).
static ALPHA8: [f32; 256] = {
    let mut t = [0.0f32; 256];
    let mut a = 0;
    while a < 256 {
        t[a] = a as f32 / 255.0;
        a += 1;
    }
    t
};

impl SourceFrame {
    /// Checks that 8-bit bytes hold `size` pixels.
    pub fn srgb8(size: Size, bytes: Vec<u8>) -> Result<SourceFrame> {
        if bytes.len() != size.pixels() * 4 {
            return Err(EigenError::bad(
                "frame",
                format!(
                    "{} bytes do not hold a {size} RGBA frame ({} bytes)",
                    bytes.len(),
                    size.pixels() * 4
                ),
            ));
        }
        Ok(SourceFrame::Srgb8 { size, bytes })
    }
    pub fn size(&self) -> Size {
        match self {
            SourceFrame::Linear(f) => f.size(),
            SourceFrame::Srgb8 { size, .. } => *size,
        }
    }
    /// The frame in linear light (borrowed when it is already).
    pub fn to_linear(&self) -> Cow<'_, RgbaFrame> {
        match self {
            SourceFrame::Linear(f) => Cow::Borrowed(f),
            SourceFrame::Srgb8 { size, bytes } => {
                let t = srgb8_table();
                let data = bytes.chunks_exact(4).map(|p| srgb8_pixel(t, p)).collect();
                Cow::Owned(RgbaFrame::from_vec(*size, data).expect("checked length"))
            }
        }
    }
}

/// A clip's frames. Errors are [`EigenError::Decode`] naming the source and frame.
pub trait Footage {
    /// Source, size, rate and length.
    fn info(&self) -> &FootageInfo;

    /// The frames from `start` (0-based) on: the first item is frame `start`, or nothing
    /// when the clip is shorter.
    fn frames(&self, start: usize) -> Result<Frames<'_>>;

    /// Frames `indices` (ascending, distinct), `None` for an index past the end. The
    /// default reads from the first index to the last and keeps the wanted ones.
    fn frames_at(&self, indices: &[usize]) -> Result<Vec<Option<RgbaFrame>>> {
        let (Some(&lo), Some(&hi)) = (indices.first(), indices.last()) else {
            return Ok(Vec::new());
        };
        let mut out = vec![None; indices.len()];
        let mut want = indices.iter().enumerate().peekable();
        for (i, f) in self.frames(lo)?.enumerate() {
            let n = lo + i;
            if n > hi {
                break;
            }
            let f = f?;
            while let Some((j, _)) = want.next_if(|(_, &w)| w == n) {
                out[j] = Some(f.clone());
            }
            if want.peek().is_none() {
                break;
            }
        }
        Ok(out)
    }

    /// [`Footage::frames_at`] for rendering: 8-bit footage may come as its sRGB bytes
    /// ([`SourceFrame::Srgb8`]); the default wraps the linear frames.
    fn source_frames_at(&self, indices: &[usize]) -> Result<Vec<Option<SourceFrame>>> {
        Ok(self
            .frames_at(indices)?
            .into_iter()
            .map(|f| f.map(SourceFrame::Linear))
            .collect())
    }
}

impl<T: Footage + ?Sized> Footage for &T {
    fn info(&self) -> &FootageInfo {
        (**self).info()
    }
    fn frames(&self, start: usize) -> Result<Frames<'_>> {
        (**self).frames(start)
    }
    fn frames_at(&self, indices: &[usize]) -> Result<Vec<Option<RgbaFrame>>> {
        (**self).frames_at(indices)
    }
    fn source_frames_at(&self, indices: &[usize]) -> Result<Vec<Option<SourceFrame>>> {
        (**self).source_frames_at(indices)
    }
}

impl<T: Footage + ?Sized> Footage for Box<T> {
    fn info(&self) -> &FootageInfo {
        (**self).info()
    }
    fn frames(&self, start: usize) -> Result<Frames<'_>> {
        (**self).frames(start)
    }
    fn frames_at(&self, indices: &[usize]) -> Result<Vec<Option<RgbaFrame>>> {
        (**self).frames_at(indices)
    }
    fn source_frames_at(&self, indices: &[usize]) -> Result<Vec<Option<SourceFrame>>> {
        (**self).source_frames_at(indices)
    }
}

/// A synthetic clip (see [`crate::synthetic`]): frames drawn on demand, identical every
/// time.
#[derive(Clone, Debug)]
pub struct SyntheticFootage {
    params: SyntheticParams,
    info: FootageInfo,
}

impl SyntheticFootage {
    pub fn new(params: SyntheticParams, fps: f64) -> SyntheticFootage {
        let info = FootageInfo {
            source: source_name(&params),
            fps,
            size: params.size,
            frame_count: Some(params.frames),
        };
        SyntheticFootage { params, info }
    }

    /// The footage of a database clip whose source is synthetic
    /// (`synthetic:<style>:seed=<n>`), `None` for any other source.
    pub fn of_clip(clip: &ClipEntry) -> Option<SyntheticFootage> {
        let (style, seed) = parse_source_name(&clip.source)?;
        let p = SyntheticParams {
            size: clip.source_size,
            frames: clip.end,
            style,
            seed,
        };
        Some(SyntheticFootage::new(p, clip.fps))
    }

    pub fn params(&self) -> &SyntheticParams {
        &self.params
    }
}

impl Footage for SyntheticFootage {
    fn info(&self) -> &FootageInfo {
        &self.info
    }
    fn frames(&self, start: usize) -> Result<Frames<'_>> {
        let p = &self.params;
        Ok(Box::new(
            (start..p.frames).map(move |t| Ok(synthetic_frame(p, t)?)),
        ))
    }
    fn frames_at(&self, indices: &[usize]) -> Result<Vec<Option<RgbaFrame>>> {
        let p = &self.params;
        indices
            .iter()
            .map(|&t| {
                if t < p.frames {
                    Ok(Some(synthetic_frame(p, t)?))
                } else {
                    Ok(None)
                }
            })
            .collect()
    }
}

/// Frames already in memory.
#[derive(Clone, Debug)]
pub struct FrameList<'a> {
    frames: &'a [RgbaFrame],
    info: FootageInfo,
}

impl<'a> FrameList<'a> {
    /// `frames` as a clip named `source` at `fps` (size of the first frame; 1x1 when empty).
    pub fn new(source: &str, frames: &'a [RgbaFrame], fps: f64) -> FrameList<'a> {
        let size = frames.first().map(|f| f.size()).unwrap_or(Size {
            width: 1,
            height: 1,
        });
        FrameList {
            frames,
            info: FootageInfo {
                source: source.into(),
                fps,
                size,
                frame_count: Some(frames.len()),
            },
        }
    }
}

impl Footage for FrameList<'_> {
    fn info(&self) -> &FootageInfo {
        &self.info
    }
    fn frames(&self, start: usize) -> Result<Frames<'_>> {
        Ok(Box::new(self.frames.iter().skip(start).cloned().map(Ok)))
    }
    fn frames_at(&self, indices: &[usize]) -> Result<Vec<Option<RgbaFrame>>> {
        Ok(indices
            .iter()
            .map(|&i| self.frames.get(i).cloned())
            .collect())
    }
}

/// Opens footage while rendering: a database clip's own footage (`path` = `None`) or
/// another file for it (`path`: footage given under `[originals]`, a custom mask).
pub trait FootageOpener {
    fn open(&mut self, clip: &ClipEntry, path: Option<&Path>) -> Result<Box<dyn Footage + '_>>;
}

/// [`FootageOpener`] for clips whose source is `synthetic:<style>:seed=<n>` (the clips of
/// [`crate::train::synthetic_clips`]): frames are drawn again, identical to training.
/// Any other source is an error naming the clip.
#[derive(Clone, Copy, Debug, Default)]
pub struct SyntheticSources;

impl FootageOpener for SyntheticSources {
    fn open(&mut self, clip: &ClipEntry, path: Option<&Path>) -> Result<Box<dyn Footage + '_>> {
        match (path, SyntheticFootage::of_clip(clip)) {
            (None, Some(f)) => Ok(Box::new(f)),
            _ => Err(EigenError::clip(
                &clip.name,
                format!(
                    "cannot read {} here (only Ignis's synthetic clips can be redrawn without a media reader)",
                    path.map_or(clip.source.clone(), |p| p.display().to_string())
                ),
            )),
        }
    }
}

#[cfg(feature = "media")]
pub use media::MediaFootage;

#[cfg(feature = "media")]
mod media {
    use super::*;
    use std::path::PathBuf;

    /// [`Footage`] over `ignis-media`: a video, image sequence or still.
    #[derive(Clone, Debug)]
    pub struct MediaFootage {
        path: PathBuf,
        crop: Option<ignis_media::Rect>,
        scale: Option<Size>,
        info: FootageInfo,
        /// How errors name the footage (default: its path).
        label: String,
        /// The reader [`Footage::frames_at`] left off at, continued by the next call that
        /// asks for later frames (a render reads its batches in order: one decode pass,
        /// no seek per batch).
        cursor: Cursor,
    }

    /// An open reader, the index of the frame it yields next and whether it keeps 8-bit
    /// frames ([`ignis_media::open_keeping_8bit`]). A clone starts without
    /// one (readers are not shared).
    #[derive(Default)]
    struct Cursor(std::sync::Mutex<Option<(usize, bool, ignis_media::FrameReader)>>);

    impl Clone for Cursor {
        fn clone(&self) -> Cursor {
            Cursor::default()
        }
    }

    impl std::fmt::Debug for Cursor {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str("Cursor")
        }
    }

    /// Farthest, in frames, [`Footage::frames_at`] decodes forward from its cursor instead
    /// of seeking (a seek decodes from the previous key frame anyway).
    const MAX_SKIP: usize = 256;

    impl MediaFootage {
        /// Probes `path`. The recorded source is the absolute path (a database is used
        /// later from any directory).
        pub fn open(path: &Path) -> Result<MediaFootage> {
            let probed = ignis_media::probe(path).map_err(|e| EigenError::Decode {
                what: path.display().to_string(),
                frame: None,
                source: Box::new(e),
            })?;
            let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
            Ok(MediaFootage {
                path: path.to_path_buf(),
                crop: None,
                scale: None,
                label: path.display().to_string(),
                cursor: Cursor::default(),
                info: FootageInfo {
                    source: abs.display().to_string(),
                    fps: probed.fps,
                    size: probed.size,
                    frame_count: probed.frame_count.map(|n| n as usize),
                },
            })
        }

        /// Only `rect` of every frame (a region of interest: `ignis loop --crop`), in
        /// source pixels; a [`MediaFootage::scaled`] after it scales the cut (one before it
        /// is dropped). A rectangle that does not fit inside the frame is refused, naming
        /// the frame's size.
        pub fn cropped(mut self, rect: ignis_media::Rect) -> Result<MediaFootage> {
            let cut =
                ignis_media::check_crop(&rect, self.info.size).map_err(|e| self.fail(None, e))?;
            self.crop = Some(rect);
            self.scale = None;
            self.cursor = Cursor::default();
            self.info.size = cut;
            Ok(self)
        }

        /// Every frame resized to `size` as it is decoded (tests and previews).
        pub fn scaled(mut self, size: Size) -> MediaFootage {
            self.scale = Some(size);
            self.cursor = Cursor::default();
            self.info.size = size;
            self
        }

        /// Names the footage `label` in errors (e.g. the path plus where it was given).
        pub fn labelled(mut self, label: impl Into<String>) -> MediaFootage {
            self.label = label.into();
            self
        }

        pub fn path(&self) -> &Path {
            &self.path
        }

        fn read(
            &self,
            start: usize,
            end: Option<usize>,
            keep_8bit: bool,
        ) -> Result<ignis_media::FrameReader> {
            let opts = ignis_media::ReadOptions {
                range: Some(ignis_media::FrameRange::frames(
                    start as u64,
                    end.map(|e| e as u64),
                )),
                crop: self.crop,
                scale: self.scale,
            };
            let open = if keep_8bit {
                ignis_media::open_keeping_8bit
            } else {
                ignis_media::open
            };
            open(&self.path, &opts).map_err(|e| self.fail(None, e))
        }

        fn fail(&self, frame: Option<usize>, e: ignis_media::MediaError) -> EigenError {
            EigenError::Decode {
                what: self.label.clone(),
                frame,
                source: Box::new(e),
            }
        }
    }

    impl Footage for MediaFootage {
        fn info(&self) -> &FootageInfo {
            &self.info
        }
        fn frames(&self, start: usize) -> Result<Frames<'_>> {
            let r = self.read(start, None, false)?;
            Ok(Box::new(r.enumerate().map(move |(i, f)| {
                f.map(|f| {
                    ignis_media::DecodedFrame::Linear(f)
                        .over_black()
                        .into_linear()
                })
                .map_err(|e| self.fail(Some(start + i), e))
            })))
        }
        /// Reads `indices[0]..=indices[last]` in one forward pass, continuing the reader
        /// the previous call left off when it is at or a little before `indices[0]`
        /// (else it opens one there); the reader is kept for the next call. Frames past
        /// the end of the source are `None`.
        fn frames_at(&self, indices: &[usize]) -> Result<Vec<Option<RgbaFrame>>> {
            self.read_at(indices, false, |f| f.into_linear())
        }
        /// [`MediaFootage::frames_at`] with 8-bit decoders' frames kept as their bytes.
        fn source_frames_at(&self, indices: &[usize]) -> Result<Vec<Option<SourceFrame>>> {
            self.read_at(indices, true, |f| match f {
                ignis_media::DecodedFrame::Linear(f) => SourceFrame::Linear(f),
                ignis_media::DecodedFrame::Srgba8 { size, bytes } => {
                    SourceFrame::Srgb8 { size, bytes }
                }
            })
        }
    }

    impl MediaFootage {
        /// The frames `indices` (see [`Footage::frames_at`]) read by a reader opened with
        /// `keep_8bit` ([`ignis_media::open_keeping_8bit`]), each made into a `T` by `take`.
        fn read_at<T: Clone>(
            &self,
            indices: &[usize],
            keep_8bit: bool,
            take: impl Fn(ignis_media::DecodedFrame) -> T,
        ) -> Result<Vec<Option<T>>> {
            let (Some(&lo), Some(&hi)) = (indices.first(), indices.last()) else {
                return Ok(Vec::new());
            };
            let end = self.info.frame_count.map_or(hi + 1, |n| n.min(hi + 1));
            if lo >= end {
                return Ok(vec![None; indices.len()]);
            }
            let mut guard = self.cursor.0.lock().unwrap_or_else(|e| e.into_inner());
            let (mut n, mut reader) = match guard.take() {
                Some((at, k, r)) if k == keep_8bit && at <= lo && lo - at <= MAX_SKIP => (at, r),
                _ => (lo, self.read(lo, None, keep_8bit)?),
            };
            let mut out = vec![None; indices.len()];
            let mut want = indices.iter().enumerate().peekable();
            while want.peek().is_some() {
                let Some(f) = reader.next_decoded() else {
                    break;
                };
                let f = take(f.map_err(|e| self.fail(Some(n), e))?.over_black());
                n += 1;
                let mut hits = Vec::new();
                while let Some((j, _)) = want.next_if(|(_, &w)| w == n - 1) {
                    hits.push(j);
                }
                // The last wanted copy takes the frame itself (no copy for distinct indices).
                if let Some((&last, rest)) = hits.split_last() {
                    for &j in rest {
                        out[j] = Some(f.clone());
                    }
                    out[last] = Some(f);
                }
            }
            *guard = Some((n, keep_8bit, reader));
            Ok(out)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::FlameStyle;

    /// The alpha table holds `a / 255` for every byte, bit for bit (the runtime division).
    #[test]
    fn alpha_table_is_the_division() {
        let t = srgb8_table();
        for a in 0..=255u8 {
            let want = std::hint::black_box(a) as f32 / std::hint::black_box(255.0f32);
            assert_eq!(srgb8_pixel(t, &[0, 0, 0, a])[3].to_bits(), want.to_bits());
        }
    }

    fn params(frames: usize) -> SyntheticParams {
        SyntheticParams {
            size: Size::new(16, 24).unwrap(),
            frames,
            style: FlameStyle::Candle,
            seed: 5,
        }
    }

    /// Footage with only `frames` (the trait's default `frames_at`).
    struct Streamed<'a>(FrameList<'a>);
    impl Footage for Streamed<'_> {
        fn info(&self) -> &FootageInfo {
            self.0.info()
        }
        fn frames(&self, start: usize) -> Result<Frames<'_>> {
            self.0.frames(start)
        }
    }

    #[test]
    fn frames_at_agrees_with_frames_everywhere() {
        let syn = SyntheticFootage::new(params(7), 30.0);
        assert_eq!(syn.info().frame_count, Some(7));
        assert_eq!(syn.info().source, "synthetic:candle:seed=5");
        let all: Vec<RgbaFrame> = syn.frames(0).unwrap().map(|f| f.unwrap()).collect();
        assert_eq!(all.len(), 7);
        assert_eq!(syn.frames(5).unwrap().count(), 2);
        assert_eq!(syn.frames(9).unwrap().count(), 0);
        let list = FrameList::new("mem", &all, 30.0);
        let streamed = Streamed(list.clone());
        let want = [1, 2, 5, 6, 8];
        for f in [&syn as &dyn Footage, &list, &streamed] {
            let got = f.frames_at(&want).unwrap();
            assert_eq!(got.len(), want.len());
            for (g, &i) in got.iter().zip(&want) {
                assert_eq!(g.as_ref(), all.get(i), "frame {i} of {}", f.info().source);
            }
            assert!(f.frames_at(&[]).unwrap().is_empty());
        }
    }

    #[cfg(feature = "media")]
    #[test]
    fn media_footage_reads_a_sequence_by_index_and_names_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let syn = SyntheticFootage::new(params(5), 30.0);
        for (i, f) in syn.frames(0).unwrap().enumerate() {
            ignis_media::write_png(&dir.path().join(format!("f{i:03}.png")), &f.unwrap()).unwrap();
        }
        let m = MediaFootage::open(&dir.path().join("f%03d.png")).unwrap();
        assert_eq!(m.info().size, Size::new(16, 24).unwrap());
        assert_eq!(m.info().frame_count, Some(5));
        let seq: Vec<RgbaFrame> = m.frames(0).unwrap().map(|f| f.unwrap()).collect();
        assert_eq!(seq.len(), 5);
        let got = m.frames_at(&[1, 4, 7]).unwrap();
        assert_eq!(got[0].as_ref(), Some(&seq[1]));
        assert_eq!(got[1].as_ref(), Some(&seq[4]));
        assert_eq!(got[2], None);
        // Successive calls continue one reader forward, or reopen for an earlier frame;
        // either way each index gets its own frame.
        for want in [
            &[0usize, 1][..],
            &[1, 2],
            &[3, 4],
            &[0, 2, 2, 3],
            &[4],
            &[2, 3],
        ] {
            let got = m.frames_at(want).unwrap();
            for (g, &i) in got.iter().zip(want) {
                assert_eq!(g.as_ref(), Some(&seq[i]), "frame {i} after earlier reads");
            }
        }
        // The sequence's frames come linear through `source_frames_at` too.
        let src = m.source_frames_at(&[0, 3]).unwrap();
        assert_eq!(src[1].as_ref().unwrap().to_linear().as_ref(), &seq[3]);
        let e = MediaFootage::open(&dir.path().join("missing.mp4")).unwrap_err();
        assert!(matches!(e, EigenError::Decode { frame: None, .. }), "{e}");
        assert!(e.to_string().contains("missing.mp4"), "{e}");
        let e = e.in_clip("fire");
        assert!(e.to_string().starts_with("clip `fire`"), "{e}");
    }

    /// An MP4 (OpenH264) read for rendering comes as its 8-bit bytes, and they read as
    /// exactly the linear frames `frames_at` gives, interleaving the two kinds of call.
    #[cfg(feature = "media")]
    #[test]
    fn media_footage_8bit_frames_are_the_linear_frames() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("clip.mp4");
        let size = Size::new(32, 48).unwrap();
        let syn = SyntheticFootage::new(SyntheticParams { size, ..params(6) }, 30.0);
        let mut w = ignis_media::create(&path, size, &Default::default()).unwrap();
        for f in syn.frames(0).unwrap() {
            w.push(&f.unwrap()).unwrap();
        }
        w.finish().unwrap();
        let m = MediaFootage::open(&path).unwrap();
        for want in [&[0usize, 2][..], &[3, 5], &[1, 1, 4]] {
            let lin = m.frames_at(want).unwrap();
            let src = m.source_frames_at(want).unwrap();
            for (l, s) in lin.iter().zip(&src) {
                let s = s.as_ref().unwrap();
                assert!(matches!(s, SourceFrame::Srgb8 { .. }), "converted");
                assert_eq!(s.to_linear().as_ref(), l.as_ref().unwrap());
            }
        }
        assert_eq!(m.source_frames_at(&[6]).unwrap(), vec![None]);
    }
}
