//! Everything the pure path cannot decode goes through the system `ffmpeg`, found on `PATH`
//! (or next to the executable) by the `ffmpeg-sidecar` crate, built without its
//! `download_ffmpeg` feature: nothing is ever downloaded, so offline machines behave the
//! same. `ffprobe` (run directly; sidecar only locates it) gives size, fps and frame count
//! from the container without decoding.
//!
//! Frames come out of `ffmpeg` as raw 8-bit RGBA on a pipe, each decoded frame once
//! (`-fps_mode passthrough`); crop, scale and square pixels are applied in Rust like every
//! other source so results do not depend on ffmpeg's scalers. ffmpeg's filters are used only
//! where a stream is not an ordinary SDR progressive picture ([`Plan`]: deinterlacing, HDR
//! and BT.2020 to SDR BT.709), and libvpx where a WebM carries alpha. A read from frame `k`
//! seeks by the frames' own timestamps (variable-frame-rate clips have no fixed frame
//! duration) and decodes from the keyframe before it.
//!
//! Set `IGNIS_NO_FFMPEG=1` to behave as if ffmpeg were absent (e.g. to check that a file
//! decodes on machines without it).

use std::collections::HashMap;
use std::path::Path;
use std::process::Command;
use std::sync::{Arc, Mutex, OnceLock};

use ffmpeg_sidecar::child::FfmpegChild;
use ffmpeg_sidecar::command::FfmpegCommand;
use ffmpeg_sidecar::event::{FfmpegEvent, LogLevel};
use ffmpeg_sidecar::iter::FfmpegIterator;
use ignis_core::{RgbaFrame, Size};

use super::{Decoder, FrameSource, SourceInfo};
use crate::convert;
use crate::error::{MediaError, Result};

/// Whether both `ffmpeg` and `ffprobe` run (checked once per process), unless
/// `IGNIS_NO_FFMPEG` is set.
pub(crate) fn ffmpeg_available() -> bool {
    static FOUND: OnceLock<bool> = OnceLock::new();
    if std::env::var_os("IGNIS_NO_FFMPEG").is_some_and(|v| !v.is_empty() && v != "0") {
        return false;
    }
    *FOUND.get_or_init(|| {
        ffmpeg_sidecar::command::ffmpeg_is_installed()
            && ffmpeg_sidecar::ffprobe::ffprobe_is_installed()
    })
}

/// The output option that hands every decoded frame over once, as decoded: `-fps_mode
/// passthrough` (ffmpeg 5.1 and later; `-vsync` was removed in 9), or `-vsync
/// passthrough` for an older ffmpeg. Without it, ffmpeg's default frame-rate mode for raw
/// output fills the time between an accurate seek and the first frame after it: a clip
/// with a sound track read from frame 20 gave frames 20, 20, 21, … — every ranged read
/// (loops, windows, transitions) one frame late after a doubled first frame.
fn passthrough_args() -> [&'static str; 2] {
    static NEW: OnceLock<bool> = OnceLock::new();
    let new = *NEW.get_or_init(|| {
        let out = Command::new(ffmpeg_sidecar::paths::ffmpeg_path())
            .args(["-hide_banner", "-version"])
            .output();
        match out {
            Ok(o) => fps_mode_known(&String::from_utf8_lossy(&o.stdout)),
            Err(_) => true,
        }
    });
    if new {
        ["-fps_mode", "passthrough"]
    } else {
        ["-vsync", "passthrough"]
    }
}

/// Whether the ffmpeg whose `-version` printed `text` knows `-fps_mode` (5.1 or later; a
/// build without a release number, e.g. from git, is taken to be recent).
fn fps_mode_known(text: &str) -> bool {
    let Some(v) = text
        .lines()
        .next()
        .and_then(|l| l.strip_prefix("ffmpeg version "))
    else {
        return true;
    };
    let v = v.trim_start_matches(|c: char| !c.is_ascii_digit() && c != 'N');
    let mut parts = v.split(|c: char| !c.is_ascii_digit());
    let (Some(Ok(major)), minor) = (
        parts.next().map(str::parse::<u32>),
        parts.next().and_then(|m| m.parse::<u32>().ok()),
    ) else {
        return true;
    };
    (major, minor.unwrap_or(0)) >= (5, 1)
}

#[derive(serde::Deserialize)]
struct ProbeOut {
    #[serde(default)]
    streams: Vec<ProbeStream>,
    format: Option<ProbeFormat>,
}

/// The container, as ffprobe names its demuxer (`mov,mp4,m4a,3gp,3g2,mj2`, `avi`, ...).
#[derive(serde::Deserialize)]
struct ProbeFormat {
    format_name: Option<String>,
}

#[derive(serde::Deserialize)]
struct ProbeStream {
    index: Option<u32>,
    codec_name: Option<String>,
    profile: Option<String>,
    width: Option<u32>,
    height: Option<u32>,
    avg_frame_rate: Option<String>,
    r_frame_rate: Option<String>,
    nb_frames: Option<String>,
    sample_aspect_ratio: Option<String>,
    color_transfer: Option<String>,
    color_primaries: Option<String>,
    color_space: Option<String>,
    color_range: Option<String>,
    field_order: Option<String>,
    #[serde(default)]
    side_data_list: Vec<SideData>,
    #[serde(default)]
    tags: StreamTags,
}

/// A stream's display-matrix side data (phones record portrait video this way).
#[derive(serde::Deserialize)]
struct SideData {
    rotation: Option<f64>,
}

/// Older muxers give the rotation as a `rotate` tag instead.
#[derive(serde::Deserialize, Default)]
struct StreamTags {
    rotate: Option<String>,
    /// `1` on a WebM VP8/VP9 stream that carries alpha.
    alpha_mode: Option<String>,
}

impl ProbeStream {
    /// Whether the picture is shown turned by a quarter turn (±90°, 270°): ffmpeg then
    /// decodes it upright (its default autorotation), so width and height swap.
    fn quarter_turn(&self) -> bool {
        let side = self.side_data_list.iter().filter_map(|d| d.rotation);
        let tag = self
            .tags
            .rotate
            .as_deref()
            .and_then(|r| r.trim().parse().ok());
        side.chain(tag)
            .any(|r: f64| r.is_finite() && (r.round() as i64).rem_euclid(180) == 90)
    }
}

fn parse_rate(r: Option<&str>) -> Option<f64> {
    let r = r?;
    let v = match r.split_once('/') {
        Some((n, d)) => n.parse::<f64>().ok()? / d.parse::<f64>().ok()?,
        None => r.parse().ok()?,
    };
    (v.is_finite() && v > 0.0).then_some(v)
}

/// The argument that names the local file `path` to ffmpeg/ffprobe: `file:` + the
/// absolute path, so that a name like `http://...`, `my:clip.mp4` or `-report.mp4` is
/// always a local file, never a URL, a protocol or an option. Use it together with
/// [`PROTOCOL_WHITELIST`].
pub(crate) fn file_url(path: &Path) -> Result<std::ffi::OsString> {
    let abs = std::path::absolute(path).map_err(|e| MediaError::io(path, e))?;
    let mut s = std::ffi::OsString::from("file:");
    s.push(abs.as_os_str());
    Ok(s)
}

/// `-protocol_whitelist file`: ffmpeg/ffprobe may open local files only (no network, and
/// no nested protocols from playlists or concat lists).
pub(crate) const PROTOCOL_WHITELIST: [&str; 2] = ["-protocol_whitelist", "file"];

/// [`probe`], as the reader's [`Probed`](super::Probed), remembered for the process: a
/// command reads a clip in many ranged reads (`ignis loop` on a 4-s loop of a 720p clip
/// opened it 13 times), and each used to start its own `ffprobe` (≈ 70 ms). Keyed by the
/// path, the file's length and modification time, so a file written since is probed
/// again; errors are not kept, and the memo is emptied past [`PROBE_MEMO`] files.
pub(crate) fn probed(path: &Path) -> Result<super::Probed> {
    type Key = (std::path::PathBuf, u64, std::time::SystemTime);
    static SEEN: OnceLock<Mutex<HashMap<Key, (SourceInfo, Plan)>>> = OnceLock::new();
    let key = std::fs::metadata(path)
        .ok()
        .and_then(|m| Some((path.to_path_buf(), m.len(), m.modified().ok()?)));
    let seen = SEEN.get_or_init(Default::default);
    let kept = key.as_ref().and_then(|k| seen.lock().ok()?.get(k).cloned());
    let (info, plan) = match kept {
        Some(v) => v,
        None => {
            let v = probe(path, None)?;
            if let (Some(k), Ok(mut m)) = (key, seen.lock()) {
                if m.len() >= PROBE_MEMO {
                    m.clear();
                }
                m.insert(k, v.clone());
            }
            v
        }
    };
    Ok(super::Probed::Ffmpeg(info, plan))
}

/// Most files [`probed`] remembers at once.
const PROBE_MEMO: usize = 256;

/// Probes `path` with `ffprobe` (container headers only): what the source is, and the
/// [`Plan`] that make its frames ordinary SDR progressive pictures.
pub(crate) fn probe(path: &Path, _hint: Option<&str>) -> Result<(SourceInfo, Plan)> {
    let url = file_url(path)?;
    let out = Command::new(ffmpeg_sidecar::ffprobe::ffprobe_path())
        .args(["-v", "error", "-select_streams", "V", "-show_entries"])
        .arg(
            "stream=index,codec_name,profile,width,height,avg_frame_rate,r_frame_rate,nb_frames,\
             sample_aspect_ratio,color_transfer,color_primaries,color_space,color_range,\
             field_order\
             :stream_side_data=rotation:stream_tags=rotate,alpha_mode:format=format_name",
        )
        .args(["-of", "json"])
        .args(PROTOCOL_WHITELIST)
        .arg("-i")
        .arg(url)
        .output()
        .map_err(|e| {
            MediaError::unsupported(
                path,
                "input for the built-in decoders",
                format!("install ffmpeg/ffprobe ({e})"),
            )
        })?;
    if !out.status.success() {
        let msg = String::from_utf8_lossy(&out.stderr);
        return Err(MediaError::decode(
            path,
            None,
            format!(
                "ffprobe cannot read it: {}{}",
                msg.trim(),
                damage_hint(&[msg.to_string()])
            ),
        ));
    }
    let parsed: ProbeOut = serde_json::from_slice(&out.stdout)
        .map_err(|e| MediaError::decode(path, None, format!("unexpected ffprobe output: {e}")))?;
    // The video ffmpeg itself would pick: of the streams that are not attached pictures
    // (cover art, thumbnails: `V`), the largest, the first of equals. A file whose first
    // video stream is a one-frame still before the clip reads as the clip.
    let Some(s) = parsed
        .streams
        .into_iter()
        .rev()
        .max_by_key(|s| s.width.unwrap_or(0) as u64 * s.height.unwrap_or(0) as u64)
    else {
        return Err(MediaError::decode(path, None, "no video stream"));
    };
    let stream = s.index.unwrap_or(0);
    let (Some(w), Some(h)) = (s.width, s.height) else {
        return Err(MediaError::decode(
            path,
            None,
            "ffprobe reports no frame size",
        ));
    };
    // A portrait phone clip is stored landscape with a rotation; its frames decode upright,
    // and so do their pixels: a quarter turn swaps the pixel aspect too.
    let turned = s.quarter_turn();
    let (w, h) = if turned { (h, w) } else { (w, h) };
    let stored =
        Size::new(w, h).map_err(|e| MediaError::decode(path, None, format!("frame size: {e}")))?;
    let (num, den) = parse_aspect(s.sample_aspect_ratio.as_deref()).unwrap_or((1, 1));
    let (num, den) = if turned { (den, num) } else { (num, den) };
    let (anamorphic, size) = match super::anamorphic(stored, num, den) {
        Some((a, shown)) => (Some(a), shown),
        None => (None, stored),
    };
    let fps = parse_rate(s.avg_frame_rate.as_deref())
        .or(parse_rate(s.r_frame_rate.as_deref()))
        .unwrap_or(30.0);
    let codec_name = s.codec_name.unwrap_or_else(|| "unknown".into());
    let (decoder, alpha_note) =
        alpha_decoder(&codec_name, s.tags.alpha_mode.as_deref(), has_decoder);
    let codec = match s.profile {
        Some(p) if !p.is_empty() && p != "unknown" => format!("{codec_name} ({p})"),
        _ => codec_name,
    };
    let colour = Colour {
        transfer: s.color_transfer.as_deref(),
        primaries: s.color_primaries.as_deref(),
        matrix: s.color_space.as_deref(),
        range: s.color_range.as_deref(),
    };
    let (filters, notes) = conversion(colour, s.field_order.as_deref(), has_filter);
    let codec = alpha_note
        .iter()
        .chain(&notes)
        .fold(codec, |c, n| format!("{c}, {n}"));
    let demuxers = parsed
        .format
        .as_ref()
        .and_then(|f| f.format_name.clone())
        .unwrap_or_default();
    let demuxer = |names: &[&str]| demuxers.split(',').any(|n| names.contains(&n));
    let plan = Plan {
        filters,
        decoder,
        stream,
        index_seek: demuxer(&["mov", "mp4", "matroska", "webm"]),
    };
    // The stated count only where the container indexes every frame (MP4 and MOV: one
    // sample-table entry per frame). Other headers' counts are estimates: an AVI written by
    // `ffmpeg -shortest` states one frame more than it holds, and reading to the stated
    // count then fails at its end. Elsewhere the packets are counted (demuxing only, once
    // per file: the frame times and seeks list them anyway).
    let indexed = demuxer(&["mov", "mp4"]);
    let stated = s
        .nb_frames
        .as_deref()
        .and_then(|n| n.parse::<u64>().ok())
        .filter(|&n| n > 0);
    // An edit list's pre-roll is in the index but not shown (its packets are marked
    // discarded): a clip trimmed without re-encoding states more frames than it plays.
    let listed = packets(path, stream)?;
    let frame_count = match (stated, &listed) {
        (Some(n), Some(p)) if indexed => Some(n.saturating_sub(p.discarded)).filter(|&n| n > 0),
        (Some(n), None) if indexed => Some(n),
        (_, Some(p)) => Some(p.count).filter(|&n| n > 0).or(stated),
        (_, None) => stated,
    };
    let info = SourceInfo {
        size,
        fps,
        frame_count,
        codec,
        decoder: Decoder::Ffmpeg,
        path: path.to_path_buf(),
        anamorphic,
        rate_stated: true,
    };
    Ok((info, plan))
}

/// The ffmpeg filters a source needs before its frames are the 8-bit SDR BT.709
/// progressive pictures the rest of Ignis reads (`-vf`; `None`: none), and the decoder it
/// needs when ffmpeg's default would lose something (`-c:v`; `None`: the default).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(crate) struct Plan {
    filters: Option<String>,
    decoder: Option<&'static str>,
    /// The index of the video stream read (`-map 0:N`).
    stream: u32,
    /// The container seeks through an index to the keyframe before a time (MP4, MOV,
    /// Matroska, WebM), so a read from frame `k` can start there ([`seek_seconds`]).
    /// Others are decoded from their start and their first `k` frames left out: an MPEG-TS
    /// (a camcorder's AVCHD `.mts`, a broadcast or screen recording) has no index, and
    /// ffmpeg's seek in it lands on a keyframe after the time or finds no frame at all; an
    /// AVI's packets carry no presentation times, and with B-frames its frames' times run
    /// the decoder's delay behind the rate's.
    index_seek: bool,
}

/// Whether this ffmpeg has the decoder `name` (`ffmpeg -decoders`, once per process).
fn has_decoder(name: &str) -> bool {
    static LIST: OnceLock<String> = OnceLock::new();
    listed(&LIST, "-decoders", name)
}

/// Whether `ffmpeg -hide_banner LIST_OPTION` (`-filters`, `-decoders`: one entry a line,
/// flags then name) names `name`; the list is read once into `cache`.
fn listed(cache: &OnceLock<String>, list_option: &str, name: &str) -> bool {
    let list = cache.get_or_init(|| {
        Command::new(ffmpeg_sidecar::paths::ffmpeg_path())
            .args(["-hide_banner", list_option])
            .output()
            .map(|o| String::from_utf8_lossy(&o.stdout).into_owned())
            .unwrap_or_default()
    });
    list.lines()
        .any(|l| l.split_whitespace().nth(1) == Some(name))
}

/// The decoder for a VP8/VP9 stream with alpha (WebM keeps it in a side channel that
/// ffmpeg's own VP8/VP9 decoders ignore: `ignis loop -o keyed.webm` read back opaque), and
/// a note for the codec description when this ffmpeg lacks it.
fn alpha_decoder(
    codec: &str,
    alpha_mode: Option<&str>,
    have: impl Fn(&str) -> bool,
) -> (Option<&'static str>, Option<String>) {
    if alpha_mode.map(str::trim) != Some("1") {
        return (None, None);
    }
    let name = match codec {
        "vp8" => "libvpx",
        "vp9" => "libvpx-vp9",
        _ => return (None, None),
    };
    if have(name) {
        (Some(name), Some("with alpha".to_string()))
    } else {
        let note = format!("alpha not read: this ffmpeg has no {name} decoder");
        (None, Some(note))
    }
}

/// Whether this ffmpeg has the filter `name` (`ffmpeg -filters`, once per process).
fn has_filter(name: &str) -> bool {
    static LIST: OnceLock<String> = OnceLock::new();
    listed(&LIST, "-filters", name)
}

/// A stream's colour properties as ffprobe names them (`None`: not stated).
#[derive(Clone, Copy, Debug, Default)]
struct Colour<'a> {
    transfer: Option<&'a str>,
    primaries: Option<&'a str>,
    matrix: Option<&'a str>,
    range: Option<&'a str>,
}

/// The filters for a stream with these ffprobe colour and field properties, and notes for
/// its codec description (what `ignis info` shows):
/// - HDR (PQ `smpte2084`, HLG `arib-std-b67`): to linear light with the HDR reference
///   white of ITU-R BT.2408 (203 cd/m², HLG's 75 % signal) as SDR white 1.0 (`zscale`
///   `npl=203`; measured: HLG 75 % → 1.001), BT.709 primaries, then BT.709's transfer,
///   highlights above white clipped as an SDR camera clips them: fire read from an HDR
///   clip looks as the SDR footage Ignis is measured on does (cores clipped to yellow and
///   white), and nothing under reference white changes. (A tone curve instead — `tonemap`
///   `mobius` or `hable` with HLG's 1,000 cd/m² peak — darkens white to 0.68–0.77 to make
///   room for highlights a flipbook cannot show.)
/// - SDR with BT.2020 primaries (10-bit SDR from some cameras): the primaries converted;
/// - interlaced (`tt`, `bb`, `tb`, `bt` field order): deinterlaced to one frame per frame
///   (`bwdif`, only frames flagged interlaced).
///
/// The input's properties are given to `zscale` explicitly (it refuses a frame whose
/// primaries or matrix are unstated: "no path between colorspaces"), unstated ones as
/// what such footage uses (BT.2020, its non-constant-luminance matrix, limited range).
/// Without the filter it needs (`zscale`, e.g. an ffmpeg built without libzimg), the clip
/// is read as it decodes and the note says so.
fn conversion(
    colour: Colour<'_>,
    field_order: Option<&str>,
    have: impl Fn(&str) -> bool,
) -> (Option<String>, Vec<String>) {
    let mut chain = Vec::new();
    let mut notes = Vec::new();
    if matches!(field_order, Some("tt" | "bb" | "tb" | "bt")) {
        if have("bwdif") {
            chain.push("bwdif=mode=send_frame:parity=auto:deint=interlaced".to_string());
            notes.push("interlaced (deinterlaced)".to_string());
        } else {
            notes.push("interlaced (read as is: this ffmpeg has no bwdif filter)".to_string());
        }
    }
    let hdr = match colour.transfer {
        Some("smpte2084") => Some("HDR PQ"),
        Some("arib-std-b67") => Some("HDR HLG"),
        _ => None,
    };
    let wide = colour.primaries == Some("bt2020");
    if hdr.is_some() || wide {
        let what = hdr.unwrap_or("BT.2020 colour");
        if have("zscale") {
            let tin = colour
                .transfer
                .filter(|t| {
                    matches!(
                        *t,
                        "smpte2084" | "arib-std-b67" | "bt709" | "bt2020-10" | "bt2020-12"
                    )
                })
                .unwrap_or("bt709");
            let pin = colour
                .primaries
                .filter(|p| matches!(*p, "bt709" | "bt2020"))
                .unwrap_or("bt2020");
            let min = match colour.matrix {
                Some(m @ ("bt709" | "bt2020nc" | "bt2020c")) => m,
                Some("smpte170m") => "170m",
                Some("bt470bg") => "470bg",
                _ => "bt2020nc",
            };
            let rin = match colour.range {
                Some("pc") => "full",
                _ => "limited",
            };
            chain.push(format!(
                "zscale=tin={tin}:pin={pin}:min={min}:rin={rin}:t=linear:p=bt709:npl=203,\
                 format=gbrpf32le,zscale=t=bt709,format=gbrp"
            ));
            notes.push(match hdr {
                Some(_) => format!("{what} (read as SDR BT.709, highlights clipped)"),
                None => format!("{what} (converted to BT.709)"),
            });
        } else {
            notes.push(format!(
                "{what} (read without conversion: this ffmpeg has no zscale filter; \
                 colours will look washed out)"
            ));
        }
    }
    let chain = (!chain.is_empty()).then(|| chain.join(","));
    (chain, notes)
}

/// A sample aspect ratio as ffprobe prints it (`4:3`; `N/A` or `0:1` when unknown).
fn parse_aspect(r: Option<&str>) -> Option<(u32, u32)> {
    let (n, d) = r?.trim().split_once(':')?;
    Some((n.parse().ok()?, d.parse().ok()?))
}

/// The video frames the data of the stream `plan` reads holds: its shown packets
/// ([`packets`]; the probe counts a container's frames by them too, except MP4/MOV's).
/// One packet is one frame for the video codecs ffmpeg muxes (H.264, HEVC, ProRes, VP8
/// with alt-ref frames, VP9 superframes, AV1 temporal units; checked against
/// `-count_frames` on each). `None` when ffprobe lists none.
pub(crate) fn counted_packets(path: &Path, plan: &Plan) -> Result<Option<u64>> {
    Ok(packets(path, plan.stream)?.map(|p| p.count))
}

/// Presentation times of the frames of video stream `stream` (the one read), in order, in seconds from the
/// file's start (what an input `-ss` counts from), from its packets' timestamps
/// ([`packets`]); `None` when a packet has no timestamp. A variable-frame-rate clip (a
/// phone's, slowing down in low light) has no fixed frame duration, so frame `k` is not at
/// `k / fps`: a seek by the average rate landed up to several frames off.
fn frame_times(path: &Path, stream: u32) -> Result<Option<Arc<Vec<f64>>>> {
    Ok(packets(path, stream)?.and_then(|p| p.times.clone()))
}

/// The presentation times of the frames ffmpeg reads from `path` ([`frame_times`]), when
/// there is one packet per frame read (`frames`, the probe's count); `None` otherwise.
pub(crate) fn timed_frames(
    path: &Path,
    plan: &Plan,
    frames: Option<u64>,
) -> Result<Option<Vec<f64>>> {
    Ok(frame_times(path, plan.stream)?
        .filter(|t| frames == Some(t.len() as u64))
        .map(|t| t.to_vec()))
}

/// What the read video stream's packets say: how many frames they show, how many they
/// do not, and the shown ones' presentation times ([`frame_times`]).
struct Packets {
    /// Packets shown: one per frame ffmpeg outputs.
    count: u64,
    /// Packets marked to be discarded (`D`): the pre-roll an MP4's edit list leaves out, as
    /// in a clip trimmed without re-encoding (`ffmpeg -ss … -c copy`, lossless cutters),
    /// which ffmpeg decodes from the keyframe before the cut but never outputs.
    discarded: u64,
    times: Option<Arc<Vec<f64>>>,
}

/// Video stream `stream`'s [`Packets`], listed by `ffprobe` demuxing only (no decoding:
/// a few ms for a short clip, about a disk read of the file for a long one); once per file,
/// length and modification time in a process (a command opens its input several times).
/// `None` when ffprobe lists no packet.
fn packets(path: &Path, stream: u32) -> Result<Option<Arc<Packets>>> {
    type Key = (std::path::PathBuf, u64, Option<std::time::SystemTime>, u32);
    static CACHE: OnceLock<Mutex<HashMap<Key, Option<Arc<Packets>>>>> = OnceLock::new();
    let meta = std::fs::metadata(path).map_err(|e| MediaError::io(path, e))?;
    let key = (path.to_path_buf(), meta.len(), meta.modified().ok(), stream);
    let cache = CACHE.get_or_init(Default::default);
    if let Some(v) = cache.lock().ok().and_then(|c| c.get(&key).cloned()) {
        return Ok(v);
    }
    let out = Command::new(ffmpeg_sidecar::ffprobe::ffprobe_path())
        .args(["-v", "error", "-select_streams", &stream.to_string()])
        .args([
            "-show_entries",
            "packet=pts_time,flags:format=start_time",
            "-of",
            "json",
        ])
        .args(PROTOCOL_WHITELIST)
        .arg("-i")
        .arg(file_url(path)?)
        .output()
        .map_err(|e| MediaError::io(path, e))?;
    let v = out
        .status
        .success()
        .then(|| parse_packets(&out.stdout))
        .flatten()
        .map(Arc::new);
    if let Ok(mut c) = cache.lock() {
        c.insert(key, v.clone());
    }
    Ok(v)
}

/// [`Packets`] from ffprobe's JSON: the number shown and discarded, and the shown
/// packets' `pts_time` sorted (packets come in decoding order) less the format's
/// `start_time`.
fn parse_packets(json: &[u8]) -> Option<Packets> {
    #[derive(serde::Deserialize)]
    struct Out {
        #[serde(default)]
        packets: Vec<Packet>,
        format: Option<Format>,
    }
    #[derive(serde::Deserialize)]
    struct Packet {
        pts_time: Option<String>,
        flags: Option<String>,
    }
    #[derive(serde::Deserialize)]
    struct Format {
        start_time: Option<String>,
    }
    let out: Out = serde_json::from_slice(json).ok()?;
    if out.packets.is_empty() {
        return None;
    }
    let shown = |p: &&Packet| !p.flags.as_deref().is_some_and(|f| f.contains('D'));
    let start = out
        .format
        .and_then(|f| f.start_time)
        .and_then(|t| t.parse::<f64>().ok())
        .filter(|t| t.is_finite())
        .unwrap_or(0.0);
    let times = out
        .packets
        .iter()
        .filter(shown)
        .map(|p| {
            p.pts_time
                .as_deref()?
                .parse::<f64>()
                .ok()
                .filter(|t| t.is_finite())
        })
        .collect::<Option<Vec<f64>>>()
        .map(|mut t| {
            t.sort_by(f64::total_cmp);
            Arc::new(t.into_iter().map(|x| x - start).collect())
        });
    let count = out.packets.iter().filter(shown).count() as u64;
    Some(Packets {
        count,
        discarded: out.packets.len() as u64 - count,
        times,
    })
}

/// Where an input `-ss` must seek to start decoding at frame `start` (> 0): half way
/// between the frame before it and it, by the frames' own timestamps when the file has
/// them, else by the average rate (`fps`) — half a frame early, so rounding of timestamps
/// cannot skip frame `start`.
fn seek_seconds(times: Option<&[f64]>, start: u64, fps: f64) -> f64 {
    let k = start as usize;
    match times {
        Some(t) if k < t.len() && k > 0 && t[k] > t[k - 1] => 0.5 * (t[k - 1] + t[k]),
        _ => (start as f64 - 0.5) / fps,
    }
}

/// A running `ffmpeg` decoding to raw RGBA on stdout.
pub(crate) struct FfmpegSource {
    child: FfmpegChild,
    events: FfmpegIterator,
    info: SourceInfo,
    errors: Vec<String>,
    finished: bool,
    /// Hand frames over as ffmpeg's sRGB bytes ([`super::open_keeping_8bit`]).
    keep_8bit: bool,
}

impl FfmpegSource {
    /// Starts `ffmpeg` at frame `start` (an accurate seek where the container has an index
    /// and the frames their own times: ffmpeg decodes from the previous keyframe and drops
    /// frames before the seek time; otherwise decoding from the start, the first `start`
    /// frames left out by count: [`Plan::index_seek`]), stopping after `end` if given.
    pub(crate) fn start(
        info: &SourceInfo,
        plan: &Plan,
        start: u64,
        end: Option<u64>,
        keep_8bit: bool,
    ) -> Result<FfmpegSource> {
        let mut cmd = FfmpegCommand::new();
        cmd.hide_banner();
        let times = if start > 0 && plan.index_seek {
            frame_times(&info.path, plan.stream)?
        } else {
            None
        };
        if let Some(t) = &times {
            let at = seek_seconds(Some(t), start, info.fps);
            cmd.seek(format!("{:.6}", at.max(0.0)));
        }
        // by count, after the conversions (a deinterlacer sees the frames before, as in
        // a read from the start)
        let skip = (start > 0 && times.is_none()).then(|| format!("select=gte(n\\,{start})"));
        cmd.args(PROTOCOL_WHITELIST);
        if let Some(decoder) = plan.decoder {
            cmd.args(["-c:v", decoder]);
        }
        cmd.input(file_url(&info.path)?);
        cmd.args(["-map", &format!("0:{}", plan.stream), "-an", "-sn", "-dn"]);
        let chain = match (&plan.filters, skip) {
            (Some(f), Some(s)) => Some(format!("{f},{s}")),
            (f, s) => f.clone().or(s),
        };
        if let Some(chain) = &chain {
            cmd.args(["-vf", chain]);
        }
        cmd.args(passthrough_args());
        if let Some(e) = end {
            cmd.arg("-frames:v").arg((e - start).to_string());
        }
        cmd.args(["-f", "rawvideo", "-pix_fmt", "rgba"]).output("-");
        let mut child = cmd.spawn().map_err(|e| {
            MediaError::unsupported(
                &info.path,
                "input for the built-in decoders",
                format!("install ffmpeg ({e})"),
            )
        })?;
        let events = child.iter().map_err(|e| {
            MediaError::decode(&info.path, None, format!("cannot talk to ffmpeg: {e}"))
        })?;
        Ok(FfmpegSource {
            child,
            events,
            info: info.clone(),
            errors: Vec::new(),
            finished: false,
            keep_8bit,
        })
    }
}

impl FrameSource for FfmpegSource {
    fn next_frame(&mut self) -> Option<Result<RgbaFrame>> {
        self.next_bytes()
            .map(|r| r.map(|(size, bytes)| convert::from_srgba8(size, &bytes)))
    }

    fn next_decoded(&mut self) -> Option<Result<super::DecodedFrame>> {
        if !self.keep_8bit {
            return self
                .next_frame()
                .map(|r| r.map(super::DecodedFrame::Linear));
        }
        self.next_bytes()
            .map(|r| r.map(|(size, bytes)| super::DecodedFrame::Srgba8 { size, bytes }))
    }
}

impl FfmpegSource {
    /// The next frame as ffmpeg wrote it: 8-bit sRGB RGBA bytes and their size.
    fn next_bytes(&mut self) -> Option<Result<(Size, Vec<u8>)>> {
        if self.finished {
            return None;
        }
        for event in self.events.by_ref() {
            match event {
                FfmpegEvent::OutputFrame(f) => {
                    let Ok(size) = Size::new(f.width, f.height) else {
                        continue;
                    };
                    if f.data.len() != size.pixels() * 4 {
                        self.finished = true;
                        return Some(Err(MediaError::decode(
                            &self.info.path,
                            None,
                            "short frame from ffmpeg",
                        )));
                    }
                    return Some(Ok((size, f.data)));
                }
                FfmpegEvent::Log(LogLevel::Error | LogLevel::Fatal, msg)
                | FfmpegEvent::Error(msg)
                    if self.errors.len() < 8 =>
                {
                    self.errors.push(msg);
                }
                _ => {}
            }
        }
        self.finished = true;
        match self.child.wait() {
            Ok(status) if status.success() => None,
            Ok(status) => Some(Err(MediaError::decode(
                &self.info.path,
                None,
                match damage_hint(&self.errors) {
                    hint if hint.is_empty() => {
                        format!("ffmpeg failed ({status}): {}", self.errors.join("; "))
                    }
                    hint => format!(
                        "ffmpeg failed ({status}){hint}. ffmpeg said: {}",
                        self.errors.join("; ")
                    ),
                },
            ))),
            Err(e) => Some(Err(MediaError::io(&self.info.path, e))),
        }
    }
}

/// What to do when ffmpeg's errors say the file's data is cut short or corrupt (the MP4
/// demuxer's "partial file" at the end of an incomplete download, or its "moov atom not
/// found" where the index, written last, never arrived; a bitstream whose NAL units
/// overrun it): empty when they do not.
fn damage_hint(errors: &[String]) -> String {
    const SIGNS: [&str; 5] = [
        "partial file",
        "moov atom not found",
        "truncat",
        "invalid nal unit size",
        "invalid data found",
    ];
    let damaged = errors.iter().any(|e| {
        let e = e.to_ascii_lowercase();
        SIGNS.iter().any(|s| e.contains(s))
    });
    if damaged {
        format!(" — {}", super::DAMAGED)
    } else {
        String::new()
    }
}

impl Drop for FfmpegSource {
    fn drop(&mut self) {
        if !self.finished {
            let _ = self.child.kill();
        }
        let _ = self.child.wait();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn damage_hints_follow_ffmpeg_truncation_messages() {
        let said = |m: &[&str]| damage_hint(&m.iter().map(|s| s.to_string()).collect::<Vec<_>>());
        for m in [
            "[mov,mp4,m4a,3gp,3g2,mj2 @ 0x1] stream 0, offset 0xaa9: partial file",
            "[h264 @ 0x1] Invalid NAL unit size (689 > 528).",
            "file.mkv: Invalid data found when processing input",
            "[mov,mp4,m4a,3gp,3g2,mj2 @ 0x1] moov atom not found",
        ] {
            assert!(
                said(&["something else", m]).contains("copy it again"),
                "{m}"
            );
        }
        assert_eq!(said(&[]), "");
        assert_eq!(said(&["Conversion failed!", "unknown encoder"]), "");
    }

    #[test]
    fn conversions_follow_the_stream_and_the_filters_at_hand() {
        let all = |_: &str| true;
        let none = |_: &str| false;
        // An ordinary SDR progressive clip, tagged or not: nothing.
        let col = |transfer, primaries| Colour {
            transfer,
            primaries,
            ..Colour::default()
        };
        for (t, p, f) in [
            (Some("bt709"), Some("bt709"), Some("progressive")),
            (None, None, None),
            (Some("bt470bg"), Some("smpte170m"), Some("unknown")),
        ] {
            assert_eq!(conversion(col(t, p), f, all), (None, vec![]));
        }
        let (Some(c), n) = conversion(col(Some("arib-std-b67"), Some("bt2020")), None, all) else {
            panic!("HLG needs a conversion")
        };
        assert!(c.contains("t=linear") && c.contains("npl=203") && c.ends_with("gbrp"));
        // Unstated properties are given as what HDR footage uses.
        assert!(
            c.contains("tin=arib-std-b67:pin=bt2020:min=bt2020nc:rin=limited"),
            "{c}"
        );
        let tagged = Colour {
            transfer: Some("smpte2084"),
            primaries: Some("bt2020"),
            matrix: Some("bt2020c"),
            range: Some("pc"),
        };
        let (Some(f), _) = conversion(tagged, None, all) else {
            panic!()
        };
        assert!(
            f.contains("tin=smpte2084:pin=bt2020:min=bt2020c:rin=full"),
            "{f}"
        );
        assert_eq!(n, ["HDR HLG (read as SDR BT.709, highlights clipped)"]);
        let (Some(c), n) = conversion(col(Some("smpte2084"), Some("bt2020")), None, all) else {
            panic!("PQ needs a conversion")
        };
        assert!(c.contains("tin=smpte2084"));
        assert!(n[0].starts_with("HDR PQ"));
        // BT.2020 SDR: primaries only, no tone mapping.
        let (Some(c), _) = conversion(col(Some("bt2020-10"), Some("bt2020")), None, all) else {
            panic!("BT.2020 needs a conversion")
        };
        assert!(c.contains("p=bt709") && c.contains("tin=bt2020-10"), "{c}");
        // Interlaced, both field orders; deinterlaced first.
        for f in ["tt", "bb", "tb", "bt"] {
            let (Some(c), n) = conversion(col(None, None), Some(f), all) else {
                panic!("{f}")
            };
            assert!(c.starts_with("bwdif="), "{c}");
            assert_eq!(n, ["interlaced (deinterlaced)"]);
        }
        let (Some(c), n) = conversion(col(Some("arib-std-b67"), Some("bt2020")), Some("tt"), all)
        else {
            panic!()
        };
        assert!(c.starts_with("bwdif=") && c.contains("zscale"), "{c}");
        assert_eq!(n.len(), 2);
        // Without the filters: read as decoded, and the note says so.
        let (f, n) = conversion(col(Some("arib-std-b67"), Some("bt2020")), Some("tt"), none);
        assert_eq!(f, None);
        assert!(
            n[0].contains("no bwdif") && n[1].contains("no zscale"),
            "{n:?}"
        );
    }

    #[test]
    fn vp8_and_vp9_with_alpha_get_libvpx() {
        let all = |_: &str| true;
        let none = |_: &str| false;
        assert_eq!(alpha_decoder("vp8", Some("1"), all).0, Some("libvpx"));
        assert_eq!(alpha_decoder("vp9", Some("1"), all).0, Some("libvpx-vp9"));
        for (codec, mode) in [("vp8", None), ("vp8", Some("0")), ("h264", Some("1"))] {
            assert_eq!(
                alpha_decoder(codec, mode, all),
                (None, None),
                "{codec} {mode:?}"
            );
        }
        let (d, note) = alpha_decoder("vp9", Some("1"), none);
        assert_eq!(d, None);
        assert!(note.unwrap().contains("no libvpx-vp9"));
    }

    #[test]
    fn seeks_go_half_way_to_the_frame_before() {
        let json = br#"{"packets": [{"pts_time": "0.100000"}, {"pts_time": "0.166667"},
            {"pts_time": "0.133333"}, {"pts_time": "0.300000"}],
            "format": {"start_time": "0.100000"}}"#;
        let p = parse_packets(json).unwrap();
        assert_eq!(p.count, 4);
        let t = p.times.unwrap();
        let want = [0.0, 0.033333, 0.066667, 0.2];
        assert!(
            t.iter().zip(want).all(|(a, b)| (a - b).abs() < 1e-9),
            "{t:?}"
        );
        // Frame 3 follows a long frame: half way between 0.066667 and 0.2, not 2.5 / fps.
        assert!((seek_seconds(Some(&t), 3, 30.0) - 0.1333335).abs() < 1e-9);
        assert!((seek_seconds(None, 3, 30.0) - 2.5 / 30.0).abs() < 1e-12);
        // Beyond the packets, or two equal times: the average rate.
        assert!((seek_seconds(Some(&t), 4, 30.0) - 3.5 / 30.0).abs() < 1e-12);
        assert!((seek_seconds(Some(&[0.0, 0.0]), 1, 30.0) - 0.5 / 30.0).abs() < 1e-12);
        // A packet without a timestamp: no times.
        let p = parse_packets(br#"{"packets": [{"pts_time": "0.1"}, {}]}"#).unwrap();
        assert_eq!((p.count, p.times.is_none()), (2, true));
        assert!(parse_packets(br#"{"packets": []}"#).is_none());
        // An edit list's pre-roll (flags `D`) is neither counted nor timed.
        let p = parse_packets(
            br#"{"packets": [{"pts_time": "-0.08", "flags": "KD"}, {"pts_time": "-0.04", "flags": "_D"},
                {"pts_time": "0.04", "flags": "__"}, {"pts_time": "0.0", "flags": "K_"}],
                "format": {"start_time": "0.000000"}}"#,
        )
        .unwrap();
        assert_eq!((p.count, p.discarded), (2, 2));
        assert_eq!(p.times.unwrap().as_slice(), &[0.0, 0.04]);
    }

    #[test]
    fn fps_mode_is_used_from_5_1() {
        assert!(fps_mode_known(
            "ffmpeg version 5.1.9-0+deb12u1 Copyright (c) 2000-2026"
        ));
        assert!(fps_mode_known("ffmpeg version 7.1 Copyright"));
        assert!(fps_mode_known("ffmpeg version n6.0 Copyright"));
        assert!(!fps_mode_known(
            "ffmpeg version 4.4.2-0ubuntu0.22.04.1 Copyright"
        ));
        assert!(!fps_mode_known("ffmpeg version 5.0.1 Copyright"));
        assert!(fps_mode_known("ffmpeg version N-113000-g1234 Copyright"));
        assert!(fps_mode_known("something else"));
    }

    #[test]
    fn rates() {
        assert_eq!(parse_rate(Some("25/1")), Some(25.0));
        assert!((parse_rate(Some("30000/1001")).unwrap() - 29.97).abs() < 0.01);
        assert_eq!(parse_rate(Some("0/0")), None);
        assert_eq!(parse_rate(None), None);
    }

    /// Writes `frames` transparent frames of `size` as a GIF at `path`.
    fn write_gif(path: &Path, size: Size, frames: usize) {
        let opts = crate::WriteOptions {
            format: Some(crate::Format::Gif),
            ..Default::default()
        };
        let mut w = crate::write::create(path, size, &opts).unwrap();
        for _ in 0..frames {
            w.push(&RgbaFrame::new(size)).unwrap();
        }
        w.finish().unwrap();
    }

    /// Issue 18 defect 3: names that look like URLs, protocols or options are local files.
    #[test]
    fn odd_file_names_are_local_files_never_urls_or_options() {
        if !ffmpeg_available() {
            println!("skipped: ffmpeg/ffprobe not on PATH");
            return;
        }
        let tmp = tempfile::tempdir().unwrap();
        let size = Size::new(8, 6).unwrap();
        let src = tmp.path().join("src.gif");
        write_gif(&src, size, 2);
        std::fs::create_dir_all(tmp.path().join("http:/127.0.0.1:9")).unwrap();
        for name in ["-report.gif", "my:clip.gif", "http:/127.0.0.1:9/x.gif"] {
            let p = tmp.path().join(name);
            std::fs::copy(&src, &p).unwrap();
            // Relative to the directory, exactly as a user would type it.
            let rel = Path::new(name);
            let (info, plan) = probe(&p, None).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(info.size, size, "{name}");
            let mut s = FfmpegSource::start(&info, &plan, 0, Some(1), false).unwrap();
            let f = s.next_frame().expect("one frame").unwrap();
            assert_eq!(f.size(), size);
            assert!(file_url(rel)
                .unwrap()
                .to_string_lossy()
                .starts_with("file:/"));
        }
        // `http://host/x` typed as a path is a local file that does not exist here: an
        // error, never a network request.
        let e = probe(Path::new("http://127.0.0.1:9/none.gif"), None).unwrap_err();
        assert!(e.to_string().contains("ffprobe"), "{e}");
        assert!(!tmp.path().join("-report.log").exists());
    }

    /// A file probed twice gives the same answer (the second from the memo), and a file
    /// written again since is probed again.
    #[test]
    fn a_rewritten_file_is_probed_again() {
        if !ffmpeg_available() {
            println!("skipped: ffmpeg/ffprobe not on PATH");
            return;
        }
        let tmp = tempfile::tempdir().unwrap();
        let p = tmp.path().join("clip.gif");
        let write = |size: Size, frames: usize| write_gif(&p, size, frames);
        let info = |p: &Path| match probed(p).unwrap() {
            super::super::Probed::Ffmpeg(info, _) => info,
            _ => unreachable!("ffmpeg's probe"),
        };
        write(Size::new(8, 6).unwrap(), 2);
        let first = info(&p);
        assert_eq!(first.size, Size::new(8, 6).unwrap());
        assert_eq!(info(&p), first);
        write(Size::new(10, 4).unwrap(), 3);
        assert_eq!(info(&p).size, Size::new(10, 4).unwrap());
    }
}
