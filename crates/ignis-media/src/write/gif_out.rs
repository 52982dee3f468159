//! Animated GIF: composited over the background, 8-bit sRGB, a NeuQuant palette of up to
//! 256 colours per frame (via the `gif` crate), looping forever unless `loop_` is false.

use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use ignis_core::{RgbaFrame, Size};

use super::{persist, temp_file_for, Sink, WriteOptions};
use crate::convert;
use crate::error::{MediaError, Result};

/// NeuQuant sampling factor (1 = best, 30 = fastest); 10 is the usual compromise.
const QUANTISER_SPEED: i32 = 3;

pub(crate) struct GifSink {
    path: PathBuf,
    tmp: ignis_core::atomic::AtomicFile,
    encoder: gif::Encoder<BufWriter<std::fs::File>>,
    size: Size,
    fps: f64,
    background: [f32; 3],
    index: u64,
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
        })
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
        let mut rgba: Vec<u8> = rgb
            .chunks_exact(3)
            .flat_map(|p| [p[0], p[1], p[2], 255])
            .collect();
        let mut f = gif::Frame::from_rgba_speed(
            self.size.width as u16,
            self.size.height as u16,
            &mut rgba,
            QUANTISER_SPEED,
        );
        f.delay = self.delay(self.index);
        self.encoder
            .write_frame(&f)
            .map_err(|e| gif_err(&self.path, e))?;
        self.index += 1;
        Ok(())
    }

    fn finish(self: Box<Self>) -> Result<Vec<PathBuf>> {
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
