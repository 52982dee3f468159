//! Animated GIF: composited over the background, 8-bit sRGB, a NeuQuant palette of up to
//! 256 colours per frame (via the `gif` crate), looping forever unless `loop_` is false.
//!
//! Each frame's palette and LZW stream depend on that frame alone, so frames are
//! quantised and compressed a batch at a time on the thread pool and written in order:
//! the same bytes as one frame after another, whatever the number of threads, and at
//! 1080p the quantiser is most of a GIF loop's time (NeuQuant ≈ 0.4 s a frame on one
//! core).

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use ignis_core::{RgbaFrame, Size};

use rayon::prelude::*;

use super::{persist, temp_file_for, Sink, WriteOptions};
use crate::convert;
use crate::error::{MediaError, Result};

/// NeuQuant sampling factor (1 = best, 30 = fastest); 10 is the usual compromise.
const QUANTISER_SPEED: i32 = 3;

/// The most bytes of 8-bit frames a GIF holds before quantising them as a batch.
const BATCH_BYTES: usize = 128 << 20;

pub(crate) struct GifSink {
    path: PathBuf,
    tmp: ignis_core::atomic::AtomicFile,
    encoder: gif::Encoder<BufWriter<std::fs::File>>,
    size: Size,
    fps: f64,
    background: [f32; 3],
    index: u64,
    /// Frames composited to 8-bit RGBA, not yet quantised; at most `batch`.
    pending: Vec<Vec<u8>>,
    batch: usize,
}

fn gif_err(path: &Path, e: impl std::fmt::Display) -> MediaError {
    MediaError::encode(path, e.to_string())
}

impl GifSink {
    pub(crate) fn new(path: &Path, size: Size, opts: &WriteOptions) -> Result<GifSink> {
        if size.width > u16::MAX as u32 || size.height > u16::MAX as u32 {
            return Err(MediaError::LimitExceeded(format!(
                "GIF frames are at most 65535 pixels a side, not {size}"
            )));
        }
        let tmp = temp_file_for(path)?;
        let file = tmp
            .try_clone_file()
            .map_err(|e| MediaError::io(tmp.temp_path(), e))?;
        let mut encoder = gif::Encoder::new(
            BufWriter::new(file),
            size.width as u16,
            size.height as u16,
            &[],
        )
        .map_err(|e| gif_err(path, e))?;
        let repeat = if opts.loop_ {
            gif::Repeat::Infinite
        } else {
            gif::Repeat::Finite(0)
        };
        encoder.set_repeat(repeat).map_err(|e| gif_err(path, e))?;
        Ok(GifSink {
            path: path.to_path_buf(),
            tmp,
            encoder,
            size,
            fps: opts.fps,
            background: opts.background,
            index: 0,
            pending: Vec::new(),
            // a frame's 4 bytes of RGBA and 1 palette index per pixel
            batch: ignis_core::stream::batch_len(size.pixels() * 5, BATCH_BYTES),
        })
    }

    /// Quantises and compresses the pending frames on the thread pool, then writes them in
    /// order (the bytes `Encoder::write_frame` writes for each).
    fn flush(&mut self) -> Result<()> {
        let (w, h) = (self.size.width as u16, self.size.height as u16);
        let frames: Vec<gif::Frame<'static>> = self
            .pending
            .par_iter_mut()
            .map(|rgba| {
                let mut f = gif::Frame::from_rgba_speed(w, h, rgba, QUANTISER_SPEED);
                f.make_lzw_pre_encoded();
                f
            })
            .collect();
        self.pending.clear();
        for mut f in frames {
            f.delay = self.delay(self.index);
            self.encoder
                .write_lzw_pre_encoded_frame(&f)
                .map_err(|e| gif_err(&self.path, e))?;
            self.index += 1;
        }
        Ok(())
    }

    /// Delay of frame `i` in centiseconds, accumulated so the long-run rate matches `fps`.
    fn delay(&self, i: u64) -> u16 {
        let at = |k: u64| (k as f64 * 100.0 / self.fps).round() as i64;
        (at(i + 1) - at(i)).clamp(2, u16::MAX as i64) as u16
    }
}

impl Sink for GifSink {
    fn push(&mut self, frame: &RgbaFrame) -> Result<()> {
        let rgb = convert::to_srgb8_over(frame, self.background);
        let rgba: Vec<u8> = rgb
            .chunks_exact(3)
            .flat_map(|p| [p[0], p[1], p[2], 255])
            .collect();
        self.pending.push(rgba);
        if self.pending.len() >= self.batch {
            self.flush()?;
        }
        Ok(())
    }

    fn finish(mut self: Box<Self>) -> Result<Vec<PathBuf>> {
        self.flush()?;
        let GifSink {
            path, tmp, encoder, ..
        } = *self;
        let mut w = encoder.into_inner().map_err(|e| gif_err(&path, e))?;
        w.flush().map_err(|e| MediaError::io(tmp.temp_path(), e))?;
        drop(w);
        persist(tmp, &path)?;
        Ok(vec![path])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame of many colours (a fire-like gradient with per-pixel variation), or of a
    /// few (`few`), with alpha that varies.
    fn frame(size: Size, k: u32, few: bool) -> RgbaFrame {
        let mut f = RgbaFrame::new(size);
        let w = size.width as usize;
        for (i, px) in f.data_mut().iter_mut().enumerate() {
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            let mut s = (i as u32 ^ k.wrapping_mul(0x9e37_79b9)).wrapping_mul(0x85eb_ca6b);
            s ^= s >> 13;
            let n = (s % 1000) as f32 / 1000.0;
            *px = if few {
                [
                    ((x as u32 + k) % 4) as f32 / 3.0,
                    0.5,
                    (y as u32 % 3) as f32 / 2.0,
                    1.0,
                ]
            } else {
                let t = (y / size.height as f32 + 0.1 * n + 0.05 * k as f32).fract();
                [
                    t,
                    t * t * 0.8,
                    t.powi(4) * 0.5,
                    (x / size.width as f32 + 0.3).min(1.0),
                ]
            };
        }
        f
    }

    /// What the encoder wrote frame by frame, before the batches: each frame quantised and
    /// written by `Encoder::write_frame`.
    fn one_by_one(frames: &[RgbaFrame], size: Size, opts: &WriteOptions) -> Vec<u8> {
        let mut out = Vec::new();
        let mut enc =
            gif::Encoder::new(&mut out, size.width as u16, size.height as u16, &[]).unwrap();
        enc.set_repeat(gif::Repeat::Infinite).unwrap();
        let at = |k: u64| (k as f64 * 100.0 / opts.fps).round() as i64;
        for (i, fr) in frames.iter().enumerate() {
            let rgb = convert::to_srgb8_over(fr, opts.background);
            let mut rgba: Vec<u8> = rgb
                .chunks_exact(3)
                .flat_map(|p| [p[0], p[1], p[2], 255])
                .collect();
            let mut f = gif::Frame::from_rgba_speed(
                size.width as u16,
                size.height as u16,
                &mut rgba,
                QUANTISER_SPEED,
            );
            let i = i as u64;
            f.delay = (at(i + 1) - at(i)).clamp(2, u16::MAX as i64) as u16;
            enc.write_frame(&f).unwrap();
        }
        drop(enc);
        out
    }

    #[test]
    fn batches_write_the_bytes_of_frame_by_frame_at_any_thread_count() {
        let size = Size::new(37, 23).unwrap();
        let frames: Vec<RgbaFrame> = (0..11).map(|k| frame(size, k, k % 4 == 3)).collect();
        let opts = WriteOptions {
            fps: 24.0,
            background: [0.02, 0.01, 0.05],
            ..WriteOptions::default()
        };
        let want = one_by_one(&frames, size, &opts);
        let dir = tempfile::tempdir().unwrap();
        for (threads, batch) in [(1, 1), (1, 4), (3, 4), (2, 64)] {
            let path = dir.path().join(format!("t{threads}b{batch}.gif"));
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let mut sink = Box::new(GifSink::new(&path, size, &opts).unwrap());
                sink.batch = batch;
                for f in &frames {
                    sink.push(f).unwrap();
                }
                sink.finish().unwrap();
            });
            let got = std::fs::read(&path).unwrap();
            assert!(
                got == want,
                "{threads} threads, batches of {batch}: the GIF differs from one written frame by frame"
            );
        }
    }
}
