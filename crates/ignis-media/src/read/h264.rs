//! The pure-cargo MP4/H.264 path: the `mp4` demuxer and OpenH264 (compiled from Cisco's
//! source by `openh264-sys2`, no runtime download).
//!
//! OpenH264 decodes the Constrained Baseline profile (what WebRTC, many phones and our own
//! MP4 writer produce); Main/High streams use CABAC and B-frames, which it does not
//! support, so [`probe_mp4`] sends them to `ffmpeg` by reading `profile_idc` from the
//! `avcC` sample description.
//!
//! Decoding runs one step ahead on a worker thread (demux + decode + YUV→RGBA8 there; the
//! 8-bit → linear `f32` conversion on the caller's thread), so the two cores overlap.

use std::fs::File;
use std::io::BufReader;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, Receiver};

use ignis_core::{RgbaFrame, Size};
use openh264::decoder::{DecodeOptions, Decoder as H264Decoder, DecoderConfig, Flush};
use openh264::formats::YUVSource;
use openh264::OpenH264API;

use super::{ffmpeg, Decoder, FrameSource, Probed, SourceInfo};
use crate::convert;
use crate::error::{MediaError, Result};

/// Human name of an H.264 profile from `profile_idc` and the constraint flags byte.
pub fn avc_profile_name(profile_idc: u8, constraints: u8) -> &'static str {
    match profile_idc {
        66 if constraints & 0x40 != 0 => "Constrained Baseline",
        66 => "Baseline",
        77 => "Main",
        88 => "Extended",
        100 => "High",
        110 => "High 10",
        122 => "High 4:2:2",
        244 => "High 4:4:4 Predictive",
        44 => "CAVLC 4:4:4 Intra",
        _ => "unknown profile",
    }
}

/// What the opener needs from the MP4 header.
pub(crate) struct Mp4Probe {
    track_id: u32,
    len: u64,
    /// How the stream's Y'CbCr become R'G'B' (its SPS's VUI).
    signal: Signal,
}

type Mp4File = mp4::Mp4Reader<BufReader<File>>;

fn read_header(path: &Path, len: u64) -> Result<Mp4File> {
    let file = File::open(path).map_err(|e| MediaError::io(path, e))?;
    // The `mp4` crate can panic on some malformed boxes; a damaged file must give an error.
    match catch_unwind(AssertUnwindSafe(|| {
        mp4::Mp4Reader::read_header(BufReader::new(file), len)
    })) {
        Ok(Ok(r)) => Ok(r),
        Ok(Err(e)) => Err(MediaError::decode(
            path,
            None,
            format!("not a readable MP4 ({e}); {}", super::DAMAGED),
        )),
        Err(_) => Err(MediaError::decode(
            path,
            None,
            format!("malformed MP4 header; {}", super::DAMAGED),
        )),
    }
}

/// Probes an ISO-BMFF file: H.264 Baseline → OpenH264; anything else → ffmpeg when
/// available, else an `Unsupported` error naming the profile/codec and the fix.
pub(crate) fn probe_mp4(path: &Path, len: u64, have_ffmpeg: bool) -> Result<Probed> {
    let reader = match read_header(path, len) {
        Ok(r) => r,
        // Fragmented or exotic layouts the `mp4` crate cannot parse may still be fine for
        // ffmpeg; if ffprobe cannot read it either, report the demuxer's error.
        Err(e) => {
            if have_ffmpeg {
                if let Ok(p) = ffmpeg::probed(path) {
                    return Ok(p);
                }
            }
            return Err(e);
        }
    };
    let video = reader
        .tracks()
        .values()
        .filter(|t| matches!(t.track_type(), Ok(mp4::TrackType::Video)))
        .min_by_key(|t| t.track_id());
    let Some(track) = video else {
        return Err(MediaError::decode(path, None, "the MP4 has no video track"));
    };
    let stsd = &track.trak.mdia.minf.stbl.stsd;
    let (codec, baseline) = match &stsd.avc1 {
        Some(avc1) => {
            let p = avc1.avcc.avc_profile_indication;
            let name = avc_profile_name(p, avc1.avcc.profile_compatibility);
            (format!("h264 ({name})"), p == 66)
        }
        None if stsd.hev1.is_some() => ("hevc".to_string(), false),
        None if stsd.vp09.is_some() => ("vp9".to_string(), false),
        None => ("an unknown video codec".to_string(), false),
    };
    // A display rotation (a phone's portrait clip is stored landscape with a turned
    // display matrix): the built-in decoder gives the stored picture, sideways; ffmpeg
    // turns it upright.
    let m = &track.trak.tkhd.matrix;
    let turned = m.b != 0 || m.c != 0 || m.a < 0 || m.d < 0;
    if turned {
        if have_ffmpeg {
            return ffmpeg::probed(path);
        }
        return Err(MediaError::unsupported(
            path,
            "video with a display rotation (e.g. a phone's portrait clip)",
            "the built-in decoder would give it sideways; install ffmpeg (e.g. `apt install \
             ffmpeg`), which turns it upright, or re-encode it upright elsewhere: ffmpeg -i \
             INPUT -c:v libx264 upright.mp4",
        ));
    }
    // A clip trimmed without re-encoding (`ffmpeg -ss … -c copy`, lossless cutters) keeps
    // the frames from the keyframe before the cut, with an edit list that starts the clip
    // after them: ffmpeg shows what a player shows, the built-in decoder would give every
    // sample (without ffmpeg the clip is read so, its first frames the ones before the cut).
    let skips = track
        .trak
        .edts
        .as_ref()
        .and_then(|e| e.elst.as_ref())
        .is_some_and(|l| {
            let times: Vec<u64> = l.entries.iter().map(|e| e.media_time).collect();
            edit_list_skips_samples(l.version, &times)
        });
    if have_ffmpeg && skips {
        return ffmpeg::probed(path);
    }
    if !baseline || track.trak.mdia.minf.stbl.stsd.avc1.is_none() {
        if have_ffmpeg {
            return ffmpeg::probed(path);
        }
        return Err(MediaError::unsupported(
            path,
            format!("{codec} video"),
            "the built-in decoder handles only H.264 (Constrained) Baseline; install ffmpeg \
             (e.g. `apt install ffmpeg`), or convert to a PNG sequence with ffmpeg elsewhere: \
             ffmpeg -i INPUT frames/%04d.png",
        ));
    }
    let count = track.sample_count() as u64;
    let mdhd = &track.trak.mdia.mdhd;
    let fps = if mdhd.duration > 0 && mdhd.timescale > 0 {
        count as f64 * mdhd.timescale as f64 / mdhd.duration as f64
    } else {
        0.0
    };
    let fps = if fps.is_finite() && fps > 0.0 {
        fps
    } else {
        30.0
    };
    let size = Size::new(track.width() as u32, track.height() as u32).map_err(|e| {
        MediaError::decode(path, None, format!("bad frame size in the MP4 header: {e}"))
    })?;
    // Non-square pixels, matrix and range, as the stream's sequence parameter set says (what
    // ffmpeg and players honour); read at square-pixel size like the ffmpeg path.
    let vui = stsd
        .avc1
        .as_ref()
        .and_then(|a| a.avcc.sequence_parameter_sets.first())
        .and_then(|sps| sps_vui(&sps.bytes));
    let aspect = vui.and_then(|v| v.pixel_aspect);
    let (anamorphic, size) = match aspect.and_then(|(n, d)| super::anamorphic(size, n, d)) {
        Some((a, shown)) => (Some(a), shown),
        None => (None, size),
    };
    let info = SourceInfo {
        size,
        fps,
        frame_count: Some(count),
        codec,
        decoder: Decoder::Openh264,
        path: path.to_path_buf(),
        anamorphic,
        rate_stated: true,
    };
    Ok(Probed::Mp4(
        info,
        Mp4Probe {
            track_id: track.track_id(),
            len,
            signal: vui.map_or(Signal::default(), |v| v.signal),
        },
    ))
}

/// Whether a track's edit list (its `elst` box's `version` and its entries' media times)
/// shows less than all of its samples from the first: an entry that starts later in the
/// media than its start, or more than one piece. Empty edits (a delay before the clip,
/// media time −1) show no sample and skip none.
fn edit_list_skips_samples(version: u8, media_times: &[u64]) -> bool {
    let empty = if version == 1 {
        u64::MAX
    } else {
        u32::MAX as u64
    };
    let shown: Vec<u64> = media_times
        .iter()
        .copied()
        .filter(|&t| t != empty)
        .collect();
    shown.len() > 1 || shown.iter().any(|&t| t > 0)
}

/// The presentation times (seconds, in sample order) of the probed track's samples, from
/// its sample table: decoding times (`stts`) plus composition offsets (`ctts`, B-frames),
/// over the media's time scale. `None` when the table does not give one time per frame
/// (`frames`, the probe's count) or its time scale is 0.
pub(crate) fn sample_times(
    path: &Path,
    probe: &Mp4Probe,
    frames: Option<u64>,
) -> Result<Option<Vec<f64>>> {
    let reader = read_header(path, probe.len)?;
    let Some(track) = reader.tracks().get(&probe.track_id) else {
        return Ok(None);
    };
    let n = track.sample_count() as usize;
    let scale = track.trak.mdia.mdhd.timescale;
    if scale == 0 || frames != Some(n as u64) || n > super::timing::MAX_TIMED_FRAMES {
        return Ok(None);
    }
    let stbl = &track.trak.mdia.minf.stbl;
    let mut decode = Vec::with_capacity(n);
    let mut t = 0u64;
    'table: for e in &stbl.stts.entries {
        for _ in 0..e.sample_count {
            if decode.len() == n {
                break 'table;
            }
            decode.push(i64::try_from(t).unwrap_or(i64::MAX));
            t = t.saturating_add(u64::from(e.sample_delta));
        }
    }
    if decode.len() != n {
        return Ok(None);
    }
    if let Some(ctts) = &stbl.ctts {
        let mut i = 0;
        'offsets: for e in &ctts.entries {
            for _ in 0..e.sample_count {
                if i == n {
                    break 'offsets;
                }
                decode[i] = decode[i].saturating_add(i64::from(e.sample_offset));
                i += 1;
            }
        }
    }
    Ok(Some(
        decode
            .into_iter()
            .map(|t| t as f64 / f64::from(scale))
            .collect(),
    ))
}

/// Length-prefixed (AVCC) NAL units → Annex B (start codes), appended to `out`.
fn avcc_to_annexb(
    sample: &[u8],
    length_size: usize,
    out: &mut Vec<u8>,
) -> std::result::Result<(), String> {
    let mut i = 0;
    while i < sample.len() {
        if i + length_size > sample.len() {
            return Err("truncated NAL length".into());
        }
        let mut n = 0usize;
        for &b in &sample[i..i + length_size] {
            n = (n << 8) | b as usize;
        }
        i += length_size;
        if n > sample.len() - i {
            return Err(format!(
                "NAL unit of {n} bytes runs past the end of its sample"
            ));
        }
        out.extend_from_slice(&[0, 0, 0, 1]);
        out.extend_from_slice(&sample[i..i + n]);
        i += n;
    }
    Ok(())
}

/// Pictures the worker may decode ahead of the caller (8-bit RGBA, ~0.9 MB each at
/// 480x480): enough slack that a busy scheduler does not stall the pipeline.
const QUEUE: usize = 8;

/// A decoded picture, tagged with its index in the stream: 8-bit sRGB RGBA, or already
/// converted to linear light on the decoding thread (so the conversion overlaps the
/// reader's work instead of following it).
type Msg = Result<(u64, Picture)>;

enum Picture {
    Srgba8(Vec<u8>, Size),
    Linear(RgbaFrame),
}

/// Streams frames from a Baseline MP4, starting at any frame (decoding from the preceding
/// sync sample).
pub(crate) struct Openh264Source {
    rx: Receiver<Msg>,
    expected: Size,
}

impl Openh264Source {
    /// `linear`: convert each picture to linear light on the decoding thread (else
    /// pictures stay 8-bit until [`FrameSource::next_frame`] or are handed over as they
    /// are by [`FrameSource::next_decoded`]).
    pub(crate) fn start(
        info: &SourceInfo,
        probe: Mp4Probe,
        start: u64,
        linear: bool,
    ) -> Result<Openh264Source> {
        Self::start_as(info, probe, start, linear)
    }

    /// [`Openh264Source::start`]; `linear`: convert each picture to linear light on the
    /// decoding thread (else pictures stay 8-bit: the raw throughput helper).
    fn start_as(
        info: &SourceInfo,
        probe: Mp4Probe,
        start: u64,
        linear: bool,
    ) -> Result<Openh264Source> {
        let path = info.path.clone();
        let reader = read_header(&path, probe.len)?;
        let track = reader.tracks().get(&probe.track_id).expect("probed track");
        let avcc = &track
            .trak
            .mdia
            .minf
            .stbl
            .stsd
            .avc1
            .as_ref()
            .expect("probed avc1")
            .avcc;
        let length_size = (avcc.length_size_minus_one & 3) as usize + 1;
        let mut header = Vec::new();
        for nal in avcc
            .sequence_parameter_sets
            .iter()
            .chain(&avcc.picture_parameter_sets)
        {
            header.extend_from_slice(&[0, 0, 0, 1]);
            header.extend_from_slice(&nal.bytes);
        }
        // Sample numbers are 1-based; decode from the last sync sample at or before `start`.
        let target = start + 1;
        let first = match &track.trak.mdia.minf.stbl.stss {
            Some(stss) => stss
                .entries
                .iter()
                .copied()
                .map(u64::from)
                .filter(|&s| s <= target)
                .max()
                .unwrap_or(1),
            None => target,
        };
        let count = track.sample_count() as u64;
        let api = OpenH264API::from_source();
        let config = DecoderConfig::new().flush_after_decode(Flush::NoFlush);
        let decoder = H264Decoder::with_api_config(api, config)
            .map_err(|e| MediaError::decode(&path, None, format!("cannot start OpenH264: {e}")))?;
        let (tx, rx) = sync_channel::<Msg>(QUEUE);
        let job = Job {
            path,
            reader,
            track_id: probe.track_id,
            length_size,
            header,
            first,
            target,
            count,
            decoder,
            linear,
            signal: probe.signal,
        };
        std::thread::Builder::new()
            .name("ignis-h264".into())
            .spawn(move || job.run(|m| tx.send(m).is_ok()))
            .map_err(|e| MediaError::io(&info.path, e))?;
        Ok(Openh264Source {
            rx,
            expected: info.anamorphic.map_or(info.size, |a| a.stored),
        })
    }
}

struct Job {
    path: PathBuf,
    reader: Mp4File,
    track_id: u32,
    length_size: usize,
    header: Vec<u8>,
    /// First sample decoded (1-based).
    first: u64,
    /// First sample sent (1-based).
    target: u64,
    count: u64,
    decoder: H264Decoder,
    /// Send linear-light frames ([`Picture::Linear`]).
    linear: bool,
    /// The stream's Y'CbCr → R'G'B' conversion.
    signal: Signal,
}

impl Job {
    /// Decodes samples `first..=count`, sending pictures from `target` on; stops when
    /// `send` returns false (the reader was dropped) or after the first error.
    fn run(mut self, mut send: impl FnMut(Msg) -> bool) {
        let mut annexb = Vec::new();
        let mut picture = self.first; // 1-based number of the next picture out of the decoder
        let mut header = std::mem::take(&mut self.header);
        for sample_id in self.first..=self.count {
            let frame = Some(sample_id - 1);
            let sample = catch_unwind(AssertUnwindSafe(|| {
                self.reader.read_sample(self.track_id, sample_id as u32)
            }));
            let sample = match sample {
                Ok(Ok(Some(s))) => s,
                Ok(Ok(None)) => break,
                Ok(Err(e)) => {
                    send(Err(MediaError::decode(
                        &self.path,
                        frame,
                        format!("cannot read sample: {e} (truncated file?)"),
                    )));
                    return;
                }
                Err(_) => {
                    send(Err(MediaError::decode(
                        &self.path,
                        frame,
                        "malformed sample table",
                    )));
                    return;
                }
            };
            annexb.clear();
            annexb.append(&mut header);
            if let Err(msg) = avcc_to_annexb(&sample.bytes, self.length_size, &mut annexb) {
                send(Err(MediaError::decode(&self.path, frame, msg)));
                return;
            }
            let want = picture >= self.target;
            match self.decoder.decode_with_options(
                &annexb,
                DecodeOptions::new().flush_after_decode(Flush::NoFlush),
            ) {
                Ok(Some(yuv)) => {
                    if want
                        && !send(Ok((
                            picture - 1,
                            picture_of(&yuv, self.linear, self.signal),
                        )))
                    {
                        return;
                    }
                    picture += 1;
                }
                Ok(None) => {}
                Err(e) => {
                    send(Err(MediaError::decode(
                        &self.path,
                        frame,
                        format!("H.264 decode failed: {e}"),
                    )));
                    return;
                }
            }
        }
        match self.decoder.flush_remaining() {
            Ok(rest) => {
                for yuv in rest {
                    if picture >= self.target
                        && !send(Ok((
                            picture - 1,
                            picture_of(&yuv, self.linear, self.signal),
                        )))
                    {
                        return;
                    }
                    picture += 1;
                }
            }
            Err(e) => {
                send(Err(MediaError::decode(
                    &self.path,
                    None,
                    format!("H.264 flush failed: {e}"),
                )));
            }
        }
    }
}

/// What is sent for a decoded picture (see [`Job::linear`]).
fn picture_of(yuv: &openh264::decoder::DecodedYUV<'_>, linear: bool, signal: Signal) -> Picture {
    let (rgba, size) = match signal == Signal::default() {
        true => rgba8_of(yuv),
        false => rgba8_with(yuv, signal),
    };
    if linear && size.width > 0 && size.height > 0 {
        Picture::Linear(convert::from_srgba8(size, &rgba))
    } else {
        Picture::Srgba8(rgba, size)
    }
}

impl FrameSource for Openh264Source {
    fn next_frame(&mut self) -> Option<Result<RgbaFrame>> {
        self.next_decoded()
            .map(|r| r.map(crate::read::DecodedFrame::into_linear))
    }

    fn next_decoded(&mut self) -> Option<Result<crate::read::DecodedFrame>> {
        use crate::read::DecodedFrame;
        let (_, pic) = match self.rx.recv().ok()? {
            Ok(m) => m,
            Err(e) => return Some(Err(e)),
        };
        let size = match &pic {
            Picture::Srgba8(_, s) => *s,
            Picture::Linear(f) => f.size(),
        };
        if size != self.expected {
            // Let the reader report the mismatch with its path and index.
            return Some(Ok(DecodedFrame::Linear(RgbaFrame::new(
                Size::new(size.width.max(1), size.height.max(1)).ok()?,
            ))));
        }
        Some(Ok(match pic {
            Picture::Linear(f) => DecodedFrame::Linear(f),
            Picture::Srgba8(bytes, size) => DecodedFrame::Srgba8 { size, bytes },
        }))
    }
}

/// Raw decode throughput helper for the benchmark: decodes every picture of a Baseline MP4
/// to 8-bit RGBA without the linear-light conversion, returning the number of pictures.
#[doc(hidden)]
pub fn decode_rgba8_count(path: &Path) -> Result<u64> {
    let len = std::fs::metadata(path)
        .map_err(|e| MediaError::io(path, e))?
        .len();
    let Probed::Mp4(info, probe) = probe_mp4(path, len, false)? else {
        return Err(MediaError::bad("path", "not a Baseline MP4"));
    };
    let source = Openh264Source::start_as(&info, probe, 0, false)?;
    let mut n = 0;
    for m in source.rx.iter() {
        m?;
        n += 1;
    }
    Ok(n)
}

/// A decoded picture as 8-bit RGBA and its size.
fn rgba8_of(yuv: &openh264::decoder::DecodedYUV<'_>) -> (Vec<u8>, Size) {
    let (w, h) = yuv.dimensions();
    let mut rgba = vec![0u8; w * h * 4];
    yuv.write_rgba8(&mut rgba);
    let size = Size {
        width: w as u32,
        height: h as u32,
    };
    (rgba, size)
}

/// How a stream's Y'CbCr code values become R'G'B': the matrix (H.264 Table E-5
/// `matrix_coefficients`) and whether the values use the full 0–255 range. The default,
/// BT.601 limited range, is what OpenH264's converter does and what ffmpeg assumes for a
/// stream that does not say.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Signal {
    pub matrix: Matrix,
    pub full_range: bool,
}

/// The luma weights of a Y'CbCr matrix.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) enum Matrix {
    /// BT.601 (also FCC and SMPTE 240M's near neighbours; and unspecified).
    #[default]
    Bt601,
    /// BT.709: HD cameras and encoders.
    Bt709,
    /// BT.2020 (non-constant luminance).
    Bt2020,
}

impl Matrix {
    /// `matrix_coefficients` → the matrix; codes that are not one of the three read as
    /// BT.601, as ffmpeg's converter does.
    fn of_code(code: u32) -> Matrix {
        match code {
            1 => Matrix::Bt709,
            9 | 10 => Matrix::Bt2020,
            _ => Matrix::Bt601,
        }
    }
    /// (Kr, Kb).
    fn weights(self) -> (f32, f32) {
        match self {
            Matrix::Bt601 => (0.299, 0.114),
            Matrix::Bt709 => (0.2126, 0.0722),
            Matrix::Bt2020 => (0.2627, 0.0593),
        }
    }
}

/// [`rgba8_of`] for a [`Signal`] other than the default: 4:2:0 chroma taken from the
/// sample of each 2×2 block (as OpenH264's converter does), the matrix and range applied in
/// 16.16 fixed point from per-code tables, rounded to the nearest level. Written here
/// because OpenH264's converter knows only BT.601 limited range: an HD clip tagged BT.709
/// read as BT.601 was 11 levels off in red on an orange (255, 128, 32), a full-range one 9
/// in blue.
fn rgba8_with(yuv: &impl YUVSource, signal: Signal) -> (Vec<u8>, Size) {
    let (w, h) = yuv.dimensions();
    let (ys, us, vs) = yuv.strides();
    let (kr, kb) = signal.matrix.weights();
    let kg = 1.0 - kr - kb;
    let (y_off, y_mul, c_mul) = match signal.full_range {
        true => (0.0, 1.0, 1.0),
        false => (16.0, 255.0 / 219.0, 255.0 / 224.0),
    };
    // Each code's contribution, in 1/65536 levels; luma carries the rounding half.
    let table = |f: &dyn Fn(f32) -> f32| -> [i32; 256] {
        std::array::from_fn(|c| (f(c as f32) * 65536.0).round() as i32)
    };
    let ty = table(&|y| (y - y_off) * y_mul + 0.5);
    let trv = table(&|v| c_mul * 2.0 * (1.0 - kr) * (v - 128.0));
    let tbu = table(&|u| c_mul * 2.0 * (1.0 - kb) * (u - 128.0));
    let tgu = table(&|u| -c_mul * 2.0 * (1.0 - kb) * kb / kg * (u - 128.0));
    let tgv = table(&|v| -c_mul * 2.0 * (1.0 - kr) * kr / kg * (v - 128.0));
    let q = |v: i32| (v >> 16).clamp(0, 255) as u8;
    let (yp, up, vp) = (yuv.y(), yuv.u(), yuv.v());
    let mut rgba = vec![0u8; w * h * 4];
    for (y, row) in rgba.chunks_exact_mut(w * 4).enumerate() {
        let yr = &yp[y * ys..][..w];
        let (ur, vr) = (&up[(y / 2) * us..], &vp[(y / 2) * vs..]);
        // Two pixels share each chroma sample; an odd last column has one.
        for ((px, ly), (&u, &v)) in row.chunks_mut(8).zip(yr.chunks(2)).zip(ur.iter().zip(vr)) {
            let (cr, cg, cb) = (
                trv[v as usize],
                tgu[u as usize] + tgv[v as usize],
                tbu[u as usize],
            );
            for (p, &l) in px.chunks_exact_mut(4).zip(ly) {
                let l = ty[l as usize];
                p.copy_from_slice(&[q(l + cr), q(l + cg), q(l + cb), 255]);
            }
        }
    }
    (
        rgba,
        Size {
            width: w as u32,
            height: h as u32,
        },
    )
}

/// What an H.264 SPS's VUI says ([`sps_vui`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Vui {
    /// Width : height of one pixel, when stated and specified.
    pub pixel_aspect: Option<(u32, u32)>,
    /// Matrix and range ([`Signal::default`] when not stated).
    pub signal: Signal,
}

/// What an H.264 sequence parameter set (`sps`: the NAL unit, header byte first, as stored
/// in `avcC`) says in its VUI (ITU-T H.264 §7.3.2.1.1, E.1.1): the sample aspect ratio
/// (Table E-1; `None` when unstated or "unspecified"), the matrix and the range. `None`
/// when the unit has no VUI or is cut short or malformed before the end of what is read.
/// Written here because the `mp4` and `openh264` crates parse the SPS but do not expose its
/// VUI; the fields before it are read and skipped, every read is bounds-checked and every
/// loop consumes bits, so a damaged unit ends with `None`.
pub(crate) fn sps_vui(sps: &[u8]) -> Option<Vui> {
    // Emulation prevention: 00 00 03 → 00 00.
    let mut rbsp = Vec::with_capacity(sps.len());
    let mut zeros = 0;
    for &b in sps.get(1..)? {
        if zeros >= 2 && b == 3 {
            zeros = 0;
            continue;
        }
        zeros = if b == 0 { zeros + 1 } else { 0 };
        rbsp.push(b);
    }
    let mut r = Bits {
        data: &rbsp,
        pos: 0,
    };
    let profile = r.u(8)?;
    r.u(16)?; // constraint flags, level
    r.ue()?; // seq_parameter_set_id
    if matches!(
        profile,
        100 | 110 | 122 | 244 | 44 | 83 | 86 | 118 | 128 | 138 | 139 | 134 | 135
    ) {
        let chroma = r.ue()?;
        if chroma == 3 {
            r.u(1)?;
        }
        r.ue()?;
        r.ue()?; // bit depths
        r.u(1)?;
        if r.u(1)? == 1 {
            for i in 0..if chroma == 3 { 12 } else { 8 } {
                if r.u(1)? == 1 {
                    let n = if i < 6 { 16 } else { 64 };
                    let (mut last, mut next) = (8i64, 8i64);
                    for _ in 0..n {
                        if next != 0 {
                            next = (last + r.se()? + 256).rem_euclid(256);
                        }
                        if next != 0 {
                            last = next;
                        }
                    }
                }
            }
        }
    }
    r.ue()?; // log2_max_frame_num_minus4
    match r.ue()? {
        0 => {
            r.ue()?;
        }
        1 => {
            r.u(1)?;
            r.se()?;
            r.se()?;
            for _ in 0..r.ue()?.min(255) {
                r.se()?;
            }
        }
        _ => {}
    }
    r.ue()?; // max_num_ref_frames
    r.u(1)?;
    r.ue()?;
    r.ue()?; // size in macroblocks
    if r.u(1)? == 0 {
        r.u(1)?; // mb_adaptive_frame_field
    }
    r.u(1)?; // direct_8x8_inference
    if r.u(1)? == 1 {
        for _ in 0..4 {
            r.ue()?; // cropping
        }
    }
    if r.u(1)? == 0 {
        return None; // no VUI
    }
    let pixel_aspect = match r.u(1)? {
        1 => aspect_ratio(&mut r)?,
        _ => None,
    };
    if r.u(1)? == 1 {
        r.u(1)?; // overscan_appropriate
    }
    let mut signal = Signal::default();
    if r.u(1)? == 1 {
        r.u(3)?; // video_format
        signal.full_range = r.u(1)? == 1;
        if r.u(1)? == 1 {
            r.u(16)?; // colour_primaries, transfer_characteristics
            signal.matrix = Matrix::of_code(r.u(8)?);
        }
    }
    Some(Vui {
        pixel_aspect,
        signal,
    })
}

/// `aspect_ratio_idc` and, for 255, the explicit ratio: `Some(None)` when unspecified.
fn aspect_ratio(r: &mut Bits<'_>) -> Option<Option<(u32, u32)>> {
    const TABLE: [(u32, u32); 17] = [
        (0, 0),
        (1, 1),
        (12, 11),
        (10, 11),
        (16, 11),
        (40, 33),
        (24, 11),
        (20, 11),
        (32, 11),
        (80, 33),
        (18, 11),
        (15, 11),
        (64, 33),
        (160, 99),
        (4, 3),
        (3, 2),
        (2, 1),
    ];
    Some(match r.u(8)? {
        255 => {
            let (w, h) = (r.u(16)?, r.u(16)?);
            (w > 0 && h > 0).then_some((w, h))
        }
        i => TABLE.get(i as usize).copied().filter(|&(w, _)| w > 0),
    })
}

/// An MSB-first bit reader over an RBSP.
struct Bits<'a> {
    data: &'a [u8],
    pos: usize,
}

impl Bits<'_> {
    fn bit(&mut self) -> Option<u32> {
        let b = self.data.get(self.pos / 8)?;
        let v = (b >> (7 - self.pos % 8)) & 1;
        self.pos += 1;
        Some(v as u32)
    }
    /// `n` ≤ 32 bits as an unsigned number.
    fn u(&mut self, n: u32) -> Option<u32> {
        (0..n).try_fold(0u32, |acc, _| Some((acc << 1) | self.bit()?))
    }
    /// Exp-Golomb unsigned (`ue(v)`); `None` past 31 leading zeros.
    fn ue(&mut self) -> Option<u32> {
        let mut zeros = 0;
        while self.bit()? == 0 {
            zeros += 1;
            if zeros > 31 {
                return None;
            }
        }
        Some(((1u64 << zeros) - 1 + self.u(zeros)? as u64).min(u32::MAX as u64) as u32)
    }
    /// Exp-Golomb signed (`se(v)`).
    fn se(&mut self) -> Option<i64> {
        let k = self.ue()? as i64;
        Some(if k % 2 == 1 { (k + 1) / 2 } else { -(k / 2) })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edit_lists_that_skip_samples_are_told_from_those_that_do_not() {
        // none, one from the start (what encoders write), a delay then the start
        for (v, t) in [
            (0, vec![]),
            (0, vec![0]),
            (1, vec![0]),
            (0, vec![u32::MAX as u64, 0]),
        ] {
            assert!(!edit_list_skips_samples(v, &t), "{v} {t:?}");
        }
        assert!(!edit_list_skips_samples(1, &[u64::MAX, 0]));
        // a trim (starts 15000 units in), a delay then a trim, two pieces
        for (v, t) in [(0, vec![15000]), (1, vec![u64::MAX, 7680]), (0, vec![0, 0])] {
            assert!(edit_list_skips_samples(v, &t), "{v} {t:?}");
        }
        // version 0's −1 is not an empty edit in version 1 (a real, if huge, media time)
        assert!(edit_list_skips_samples(1, &[u32::MAX as u64]));
    }

    #[test]
    fn avcc_conversion() {
        let mut out = Vec::new();
        avcc_to_annexb(&[0, 0, 0, 2, 0x65, 0xAA, 0, 0, 0, 1, 0x41], 4, &mut out).unwrap();
        assert_eq!(out, [0, 0, 0, 1, 0x65, 0xAA, 0, 0, 0, 1, 0x41]);
        assert!(avcc_to_annexb(&[0, 0, 0, 9, 0x65], 4, &mut Vec::new()).is_err());
        assert!(avcc_to_annexb(&[0, 0], 4, &mut Vec::new()).is_err());
    }

    fn hex(s: &str) -> Vec<u8> {
        (0..s.len())
            .step_by(2)
            .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
            .collect()
    }

    /// SPS units from x264 (their `avcC`): Baseline and High, square, 4:3 and 3:4 pixels
    /// (the extended `255` form), and `candle.mp4`'s, whose VUI gives no aspect.
    #[test]
    fn sps_pixel_aspects() {
        let cases = [
            // Baseline 360×480 with 4:3 pixels.
            (
                "6742c01ed90170f797c384000003000400000300f03c58b920",
                Some((4, 3)),
            ),
            // High 720×540 with 4:3 pixels.
            (
                "6764001eacd940b4117ef0e6a0c0a0a80000030008000003019078b16cb0",
                Some((4, 3)),
            ),
            // High 960×720 with 3:4 pixels.
            (
                "6764001facd940f016effc000c0011a830282a000003000200000300641e30632c",
                Some((3, 4)),
            ),
            // candle.mp4: Baseline, VUI without an aspect ratio.
            ("6742c01ed901e0f684000003000400000300f03c58b920", None),
            // campfire.mp4: High, square pixels stated (Table E-1 index 1).
            (
                "6764001facd940f0117ef016a0c0a0a80000030008000003019078c18cb0",
                Some((1, 1)),
            ),
        ];
        let aspect = |u: &[u8]| sps_vui(u).and_then(|v| v.pixel_aspect);
        for (sps, want) in cases {
            assert_eq!(aspect(&hex(sps)), want, "{sps}");
        }
        // Cut short anywhere, or empty: no panic; before the end of the VUI's colour fields
        // no answer, after them the right one.
        let full = hex(cases[1].0);
        let answers: Vec<_> = (0..full.len()).map(|n| aspect(&full[..n])).collect();
        let first = answers.iter().position(Option::is_some).unwrap();
        assert!(first > 8, "answered from {first} bytes");
        assert!(answers[..first].iter().all(Option::is_none));
        assert!(answers[first..].iter().all(|a| *a == Some((4, 3))));
        // Any single bit flipped in any of the units, and noise: an answer or none, never a
        // panic or a hang (the scaling-list and cycle loops are bounded by the data).
        for (sps, _) in cases {
            let unit = hex(sps);
            for bit in 0..unit.len() * 8 {
                let mut u = unit.clone();
                u[bit / 8] ^= 0x80 >> (bit % 8);
                let _ = sps_vui(&u);
            }
        }
        let mut x = 0x9E37_79B9_7F4A_7C15u64;
        for n in 0..4000 {
            let noise: Vec<u8> = (0..n % 64)
                .map(|_| {
                    x ^= x << 13;
                    x ^= x >> 7;
                    x ^= x << 17;
                    x as u8
                })
                .collect();
            let _ = sps_vui(&noise);
        }
    }

    /// The matrix and range in the VUI's video signal type (x264 Baseline units tagged
    /// BT.709 limited, BT.601 full and BT.601 limited), and the conversion each gives.
    #[test]
    fn vui_signals_and_their_conversion() {
        let signal = |h: &str| sps_vui(&hex(h)).unwrap().signal;
        let bt709 = signal("6742c00ad90426c05a808080a0000003002000000641e244c9");
        let full = signal("6742c00ad90426c05b81010320000003002000000641e244c9");
        let bt601 = signal("6742c00ad90426c05a81010320000003002000000641e244c9");
        assert_eq!((bt709.matrix, bt709.full_range), (Matrix::Bt709, false));
        assert_eq!((full.matrix, full.full_range), (Matrix::Bt601, true));
        assert_eq!(bt601, Signal::default());
        // candle.mp4 states no signal type: the default, OpenH264's own converter.
        assert_eq!(
            signal("6742c01ed901e0f684000003000400000300f03c58b920"),
            Signal::default()
        );
        // An orange (255, 128, 32) as ffmpeg's converter writes it (BT.709 limited: Y 143,
        // Cb 73, Cr 188; BT.601 full: Y 155, Cb 59, Cr 199), back within two levels.
        let orange = |y: u8, cb: u8, cr: u8, s: Signal| {
            let (yp, up, vp) = ([y; 16], [cb; 4], [cr; 4]);
            let src = openh264::formats::YUVSlices::new((&yp, &up, &vp), (4, 4), (4, 2, 2));
            rgba8_with(&src, s).0[..4].to_vec()
        };
        for (got, name) in [
            (orange(143, 73, 188, bt709), "BT.709 limited"),
            (orange(155, 59, 199, full), "BT.601 full"),
        ] {
            let want = [255i32, 128, 32, 255];
            let off = got
                .iter()
                .zip(want)
                .map(|(a, b)| (*a as i32 - b).abs())
                .max();
            assert!(off <= Some(2), "{name}: {got:?}");
        }
        // Read as BT.601 limited, the BT.709 orange is visibly off.
        let wrong = orange(143, 73, 188, Signal::default());
        assert!((wrong[0] as i32 - 255).abs() > 8 || (wrong[1] as i32 - 128).abs() > 8);
    }

    #[test]
    fn profile_names() {
        assert_eq!(avc_profile_name(66, 0xC0), "Constrained Baseline");
        assert_eq!(avc_profile_name(100, 0), "High");
    }
}
