//! MP4/H.264 without ffmpeg: OpenH264 (Constrained Baseline, compiled from source) and the
//! `mp4` muxer. Composited over the background, sRGB-encoded, BT.601 limited-range 4:2:0
//! (tagged in the stream's VUI so players convert back the same way), one IDR every two
//! seconds. Odd sides are padded to even (and sides under 16 to 16, OpenH264's minimum)
//! by repeating the last column/row.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use ignis_core::{RgbaFrame, Size};
use openh264::encoder::{
    BitRate, Encoder, EncoderConfig, FrameRate, FrameType, IntraFramePeriod, Profile, QpRange,
    RateControlMode, VuiConfig,
};
use openh264::formats::{RgbSliceU8, YUVBuffer};
use openh264::OpenH264API;

use super::{persist, temp_file_for, Sink, WriteOptions};
use crate::convert;
use crate::error::{MediaError, Result};

/// Quantiser range for OpenH264's buffer-based rate control (its bitrate and quality modes
/// need frame skipping, which would drop frames). 16..=24 is visually clean for fire.
const QP_MIN: u8 = 16;
const QP_MAX: u8 = 24;
/// Nominal bitrate passed to the encoder (buffer and level sizing).
const BITS_PER_PIXEL: f64 = 0.3;

pub(crate) struct Mp4Sink {
    path: PathBuf,
    tmp: ignis_core::atomic::AtomicFile,
    encoder: Encoder,
    muxer: Option<mp4::Mp4Writer<BufWriter<std::fs::File>>>,
    size: Size,
    padded: Size,
    timescale: u32,
    background: [f32; 3],
    index: u64,
}

impl Mp4Sink {
    pub(crate) fn new(path: &Path, size: Size, opts: &WriteOptions) -> Result<Mp4Sink> {
        // Even sides for 4:2:0, and at least one macroblock (OpenH264 refuses smaller frames).
        let even = |v: u32| (v + v % 2).max(16);
        let padded = Size::new(even(size.width), even(size.height))?;
        let (long, short) = (
            padded.width.max(padded.height),
            padded.width.min(padded.height),
        );
        if long > 3840 || short > 2160 {
            return Err(MediaError::LimitExceeded(format!(
                "OpenH264 encodes at most 3840x2160 (or 2160x3840), not {size}; scale down or write a PNG sequence"
            )));
        }
        let bps = (padded.pixels() as f64 * opts.fps * BITS_PER_PIXEL)
            .clamp(200_000.0, 100_000_000.0) as u32;
        let gop = ((opts.fps * 2.0).round() as u32).max(1);
        let config = EncoderConfig::new()
            .bitrate(BitRate::from_bps(bps))
            .max_frame_rate(FrameRate::from_hz(opts.fps as f32))
            .skip_frames(false)
            .rate_control_mode(RateControlMode::Bufferbased)
            .qp(QpRange::new(QP_MIN, QP_MAX))
            .profile(Profile::Baseline)
            .intra_frame_period(IntraFramePeriod::from_num_frames(gop))
            .vui(VuiConfig::bt601());
        let encoder = Encoder::with_api_config(OpenH264API::from_source(), config)
            .map_err(|e| MediaError::encode(path, format!("cannot start OpenH264: {e}")))?;
        let tmp = temp_file_for(path)?;
        let timescale = ((opts.fps * 1000.0).round() as u32).max(1);
        Ok(Mp4Sink {
            path: path.to_path_buf(),
            tmp,
            encoder,
            muxer: None,
            size,
            padded,
            timescale,
            background: opts.background,
            index: 0,
        })
    }

    pub(crate) fn output_size(&self) -> Size {
        self.padded
    }

    fn rgb_padded(&self, frame: &RgbaFrame) -> Vec<u8> {
        let rgb = convert::to_srgb8_over(frame, self.background);
        if self.padded == self.size {
            return rgb;
        }
        let (w, h) = (self.size.width as usize, self.size.height as usize);
        let pw = self.padded.width as usize;
        let mut out = Vec::with_capacity(self.padded.pixels() * 3);
        for y in 0..self.padded.height as usize {
            let row = &rgb[y.min(h - 1) * w * 3..(y.min(h - 1) + 1) * w * 3];
            out.extend_from_slice(row);
            for _ in w..pw {
                out.extend_from_slice(&row[(w - 1) * 3..]);
            }
        }
        out
    }

    fn start_muxer(
        &self,
        sps: &[u8],
        pps: &[u8],
    ) -> Result<mp4::Mp4Writer<BufWriter<std::fs::File>>> {
        let err = |e: mp4::Error| MediaError::encode(&self.path, format!("MP4 muxer: {e}"));
        let file = self
            .tmp
            .try_clone_file()
            .map_err(|e| MediaError::io(self.tmp.temp_path(), e))?;
        let brand = |s: &str| s.parse::<mp4::FourCC>().expect("four characters");
        let config = mp4::Mp4Config {
            major_brand: brand("isom"),
            minor_version: 512,
            compatible_brands: vec![brand("isom"), brand("iso2"), brand("avc1"), brand("mp41")],
            timescale: 1000,
        };
        let mut muxer = mp4::Mp4Writer::write_start(BufWriter::new(file), &config).map_err(err)?;
        muxer
            .add_track(&mp4::TrackConfig {
                track_type: mp4::TrackType::Video,
                timescale: self.timescale,
                language: "und".into(),
                media_conf: mp4::MediaConfig::AvcConfig(mp4::AvcConfig {
                    width: self.padded.width as u16,
                    height: self.padded.height as u16,
                    seq_param_set: sps.to_vec(),
                    pic_param_set: pps.to_vec(),
                }),
            })
            .map_err(err)?;
        Ok(muxer)
    }
}

/// Strips an Annex B start code (`00 00 01` or `00 00 00 01`).
fn strip_start_code(nal: &[u8]) -> &[u8] {
    if nal.starts_with(&[0, 0, 0, 1]) {
        &nal[4..]
    } else if nal.starts_with(&[0, 0, 1]) {
        &nal[3..]
    } else {
        nal
    }
}

impl Sink for Mp4Sink {
    fn push(&mut self, frame: &RgbaFrame) -> Result<()> {
        let rgb = self.rgb_padded(frame);
        let dims = (self.padded.width as usize, self.padded.height as usize);
        let yuv = YUVBuffer::from_rgb8_source(RgbSliceU8::new(&rgb, dims));
        let path = self.path.clone();
        let bits = self.encoder.encode(&yuv).map_err(|e| {
            MediaError::encode(&path, format!("H.264 encode of frame {}: {e}", self.index))
        })?;
        let mut sample = Vec::new();
        let (mut sps, mut pps) = (None, None);
        let mut sync = bits.frame_type() == FrameType::IDR;
        for l in 0..bits.num_layers() {
            let layer = bits.layer(l).expect("layer index");
            for n in 0..layer.nal_count() {
                let nal = strip_start_code(layer.nal_unit(n).expect("nal index"));
                match nal.first().map(|b| b & 0x1f) {
                    Some(7) => sps = Some(nal.to_vec()),
                    Some(8) => pps = Some(nal.to_vec()),
                    Some(t) => {
                        sync |= t == 5;
                        sample.extend_from_slice(&(nal.len() as u32).to_be_bytes());
                        sample.extend_from_slice(nal);
                    }
                    None => {}
                }
            }
        }
        if self.muxer.is_none() {
            let (Some(sps), Some(pps)) = (sps, pps) else {
                return Err(MediaError::encode(
                    &path,
                    "OpenH264 produced no SPS/PPS for the first frame",
                ));
            };
            self.muxer = Some(self.start_muxer(&sps, &pps)?);
        }
        if sample.is_empty() {
            return Err(MediaError::encode(
                &path,
                format!("OpenH264 produced no picture for frame {}", self.index),
            ));
        }
        let duration = 1000u32;
        let s = mp4::Mp4Sample {
            start_time: self.index * duration as u64,
            duration,
            rendering_offset: 0,
            is_sync: sync,
            bytes: mp4::Bytes::from(sample),
        };
        self.muxer
            .as_mut()
            .expect("started above")
            .write_sample(1, &s)
            .map_err(|e| MediaError::encode(&path, format!("MP4 muxer: {e}")))?;
        self.index += 1;
        Ok(())
    }

    fn finish(self: Box<Self>) -> Result<Vec<PathBuf>> {
        let Mp4Sink {
            path, tmp, muxer, ..
        } = *self;
        let mut muxer = muxer.ok_or_else(|| MediaError::encode(&path, "no frames"))?;
        muxer
            .write_end()
            .map_err(|e| MediaError::encode(&path, format!("MP4 muxer: {e}")))?;
        let mut w = muxer.into_writer();
        w.flush().map_err(|e| MediaError::io(tmp.temp_path(), e))?;
        drop(w);
        persist(tmp, &path)?;
        Ok(vec![path])
    }
}
