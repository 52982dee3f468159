//! Video with alpha through the system `ffmpeg`: Apple ProRes 4444 in QuickTime (`.mov`,
//! what compositing and editing tools take for keyed elements: After Effects, Nuke,
//! Resolve, Premiere) and VP8 with alpha in WebM (`.webm`, what browsers and Unity's
//! VideoPlayer play with transparency). No crate encodes either, so frames go to `ffmpeg`
//! on a pipe as 16-bit sRGB RGBA (straight alpha); the encoder is ffmpeg's own
//! (`prores_ks`, `libvpx`), which Debian's and most builds of ffmpeg carry.
//!
//! ffmpeg writes the atomic temporary by name (the container given with `-f`, as the
//! temporary's name ends in `.partial`), so a failed or dropped writer leaves nothing under
//! the final name, as every other writer. Without ffmpeg, [`super::check_output`] refuses
//! these formats before anything is rendered.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::thread::JoinHandle;

use ignis_core::atomic::AtomicFile;
use ignis_core::palette::linear_to_srgb;
use ignis_core::{RgbaFrame, Size};
use rayon::prelude::*;

use super::{persist, temp_file_for, Format, Sink, WriteOptions};
use crate::error::{MediaError, Result};

/// Largest side either encoder is given (ProRes and VP8 both stop at 16,383).
pub(crate) const MAX_SIDE: u32 = 16_383;

/// How much of ffmpeg's error output is kept for the error message.
const STDERR_TAIL: usize = 4096;

/// The error for a video-with-alpha format on a machine without ffmpeg.
pub(crate) fn needs_ffmpeg(path: &Path, format: Format) -> MediaError {
    let (what, name) = match format {
        Format::Webm => ("VP8 WebM with alpha", ".webm"),
        _ => ("ProRes 4444 QuickTime with alpha", ".mov"),
    };
    MediaError::unsupported(
        path,
        format!("output format ({what})"),
        format!(
            "writing {name} needs the system ffmpeg, which was not found; install it (e.g. \
             apt-get install ffmpeg) or write a PNG sequence, which keeps the alpha without it \
             (-o frames/%04d.png)"
        ),
    )
}

/// The frame rate as the rational ffmpeg is given: NTSC rates (`k × 1000/1001`) exactly,
/// anything else to a thousandth of a frame per second (as the MP4 writer's time scale).
pub(crate) fn fps_rational(fps: f64) -> String {
    let ntsc = fps * 1.001;
    if ntsc.round() >= 1.0 && (ntsc - ntsc.round()).abs() < 1e-6 * ntsc {
        format!("{}/1001", ntsc.round() as u64 * 1000)
    } else {
        format!("{}/1000", ((fps * 1000.0).round() as u64).max(1))
    }
}

/// VP8's bitrate ceiling, in bits per pixel per frame (as the MP4 writer's nominal rate).
/// Constant quality 10 needs a ceiling (without one libvpx falls back to a low default):
/// on `fireball.mp4`'s 720p loop, composited over grey against the ProRes frames, 0.3
/// gives 33.1 dB PSNR at 1.8 MB for 2 s, the same as 0.6 (the rest is 4:2:0 chroma);
/// without a ceiling 31.3 dB.
const VP8_BITS_PER_PIXEL: f64 = 0.3;

/// The encoder's arguments (after the raw input's) for `format`.
fn encoder_args(format: Format, size: Size, fps: f64) -> Vec<String> {
    let args = if format == Format::Mov {
        // 4444 profile, 10-bit 4:4:4 with a 16-bit alpha plane; tagged BT.709 primaries
        // and matrix with the sRGB transfer the pixels are encoded with.
        "-vf setparams=color_primaries=bt709:color_trc=iec61966-2-1:colorspace=bt709 \
         -c:v prores_ks -profile:v 4444 -pix_fmt yuva444p10le -vendor apl0 -f mov"
            .to_string()
    } else {
        // VP8 keeps alpha (a second stream inside WebM) only without alt-ref frames;
        // constant quality 10 (0–63) under the bitrate ceiling. The WebM muxer draws its
        // segment and track UIDs at random unless bit-exact: the same frames would give
        // different bytes on every run.
        let ceiling = (size.pixels() as f64 * fps * VP8_BITS_PER_PIXEL).clamp(2e5, 1e8);
        format!(
            "-c:v libvpx -pix_fmt yuva420p -auto-alt-ref 0 -crf 10 -b:v {} -deadline good \
             -cpu-used 2 -fflags +bitexact -f webm",
            ceiling as u64
        )
    };
    args.split_whitespace().map(str::to_string).collect()
}

pub(crate) struct FfmpegSink {
    path: PathBuf,
    tmp: Option<AtomicFile>,
    child: Option<Child>,
    stdin: Option<ChildStdin>,
    stderr: Option<JoinHandle<String>>,
    size: Size,
    buf: Vec<u8>,
}

impl FfmpegSink {
    pub(crate) fn new(
        path: &Path,
        size: Size,
        opts: &WriteOptions,
        format: Format,
    ) -> Result<FfmpegSink> {
        if size.width > MAX_SIDE || size.height > MAX_SIDE {
            return Err(MediaError::LimitExceeded(format!(
                "{size} is larger than {MAX_SIDE} pixels on a side, the most ProRes and VP8 \
                 encode; scale down or write a PNG sequence (-o frames/%04d.png)"
            )));
        }
        // Without ffmpeg, `create`'s `check_output` has refused the format already.
        let tmp = temp_file_for(path)?;
        // `file:` + the absolute path: a name like `a:b.mov` is a file, not a protocol.
        let target = crate::read::file_url(tmp.temp_path())?;
        let mut child = Command::new(ffmpeg_sidecar::paths::ffmpeg_path())
            .args(["-hide_banner", "-nostats", "-loglevel", "error"])
            .args(["-f", "rawvideo", "-pix_fmt", "rgba64le", "-s"])
            .arg(format!("{}x{}", size.width, size.height))
            .arg("-framerate")
            .arg(fps_rational(opts.fps))
            .args(["-i", "pipe:0", "-an"])
            .args(encoder_args(format, size, opts.fps))
            .arg("-y")
            .arg(target)
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| {
                MediaError::encode(path, format!("cannot start ffmpeg ({e}); is it installed?"))
            })?;
        let stdin = child.stdin.take();
        let stderr = child.stderr.take().map(|mut err| {
            std::thread::spawn(move || {
                // Drained to the end (so ffmpeg never blocks on it), the tail kept.
                let mut tail: Vec<u8> = Vec::new();
                let mut chunk = [0u8; 4096];
                while let Ok(n) = err.read(&mut chunk) {
                    if n == 0 {
                        break;
                    }
                    tail.extend_from_slice(&chunk[..n]);
                    if tail.len() > 2 * STDERR_TAIL {
                        tail.drain(..tail.len() - STDERR_TAIL);
                    }
                }
                let start = tail.len().saturating_sub(STDERR_TAIL);
                String::from_utf8_lossy(&tail[start..]).trim().to_string()
            })
        });
        Ok(FfmpegSink {
            path: path.to_path_buf(),
            tmp: Some(tmp),
            child: Some(child),
            stdin,
            stderr,
            size,
            buf: vec![0u8; size.pixels() * 8],
        })
    }

    /// Waits for ffmpeg and returns its exit error, if any, with what it printed.
    fn wait(&mut self) -> Option<String> {
        self.stdin.take();
        let status = self.child.take().map(|mut c| c.wait());
        let printed = self
            .stderr
            .take()
            .and_then(|t| t.join().ok())
            .unwrap_or_default();
        match status {
            Some(Ok(s)) if s.success() => None,
            Some(Ok(s)) => Some(format!("ffmpeg failed ({s}): {printed}")),
            Some(Err(e)) => Some(format!("ffmpeg did not finish ({e}): {printed}")),
            None => Some("ffmpeg is not running".into()),
        }
    }
}

/// 16-bit sRGB RGBA, straight alpha (little-endian, ffmpeg's `rgba64le`); NaN → 0.
fn to_srgba16_le(frame: &RgbaFrame, out: &mut [u8]) {
    let width = frame.width() as usize;
    let unit = |v: f32| if v.is_nan() { 0.0 } else { v.clamp(0.0, 1.0) };
    let q = |v: f32| ((v * 65535.0).round() as u16).to_le_bytes();
    out.par_chunks_mut(width * 8)
        .zip(frame.data().par_chunks(width))
        .for_each(|(row, px)| {
            for (o, p) in row.chunks_exact_mut(8).zip(px) {
                for c in 0..3 {
                    o[2 * c..2 * c + 2].copy_from_slice(&q(linear_to_srgb(unit(p[c]))));
                }
                o[6..8].copy_from_slice(&q(unit(p[3])));
            }
        });
}

impl Sink for FfmpegSink {
    fn push(&mut self, frame: &RgbaFrame) -> Result<()> {
        debug_assert_eq!(frame.size(), self.size);
        to_srgba16_le(frame, &mut self.buf);
        let written = match self.stdin.as_mut() {
            Some(stdin) => stdin.write_all(&self.buf),
            None => Err(std::io::Error::other("ffmpeg's input is closed")),
        };
        if let Err(e) = written {
            let why = self.wait().unwrap_or_else(|| e.to_string());
            return Err(MediaError::encode(&self.path, why));
        }
        Ok(())
    }

    fn finish(mut self: Box<Self>) -> Result<Vec<PathBuf>> {
        if let Some(why) = self.wait() {
            return Err(MediaError::encode(&self.path, why));
        }
        let tmp = self.tmp.take().expect("finished once");
        let written = std::fs::metadata(tmp.temp_path()).map_or(0, |m| m.len());
        if written == 0 {
            return Err(MediaError::encode(&self.path, "ffmpeg wrote nothing"));
        }
        persist(tmp, &self.path)?;
        Ok(vec![self.path.clone()])
    }
}

impl Drop for FfmpegSink {
    /// Unfinished: ffmpeg is stopped before the temporary is removed.
    fn drop(&mut self) {
        self.stdin.take();
        if let Some(mut c) = self.child.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
        if let Some(t) = self.stderr.take() {
            let _ = t.join();
        }
        self.tmp.take();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_rates_are_exact_rationals() {
        assert_eq!(fps_rational(30.0), "30000/1000");
        assert_eq!(fps_rational(25.0), "25000/1000");
        assert_eq!(fps_rational(30000.0 / 1001.0), "30000/1001");
        assert_eq!(fps_rational(24000.0 / 1001.0), "24000/1001");
        assert_eq!(fps_rational(60000.0 / 1001.0), "60000/1001");
        assert_eq!(fps_rational(12.5), "12500/1000");
        assert_eq!(fps_rational(29.97), "29970/1000");
        assert_eq!(fps_rational(0.001), "1/1000");
    }

    #[test]
    fn sixteen_bit_pixels_are_srgb_with_linear_alpha() {
        let size = Size::new(3, 1).unwrap();
        let frame = RgbaFrame::from_vec(
            size,
            vec![
                [0.0, 1.0, 0.214_041_14, 0.5],
                [2.0, -1.0, f32::NAN, 1.0],
                [1.0, 1.0, 1.0, f32::NAN],
            ],
        )
        .unwrap();
        let mut out = vec![0u8; 24];
        to_srgba16_le(&frame, &mut out);
        let v: Vec<u16> = out
            .chunks_exact(2)
            .map(|b| u16::from_le_bytes([b[0], b[1]]))
            .collect();
        // linear 0.214 is sRGB 0.5 (to a 16-bit step); alpha stays linear
        assert_eq!(&v[..2], &[0, 65535]);
        assert!(v[2].abs_diff(32768) <= 1, "{}", v[2]);
        assert_eq!(v[3], 32768);
        assert_eq!(&v[4..8], &[65535, 0, 0, 65535]);
        assert_eq!(&v[8..], &[65535, 65535, 65535, 0]);
    }
}
