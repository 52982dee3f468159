//! `ignis-media`: getting frames in and out of Ignis.
//!
//! - [`open`] / [`probe`]: stream linear-light frames from MP4 (H.264 Baseline decoded in
//!   pure cargo with OpenH264; everything else through the system `ffmpeg`), image
//!   sequences (PNG, JPEG, TIFF, EXR), stills and GIFs, with a frame range, crop and
//!   scale ([`ReadOptions`]). See [`read`] for how the decoder is chosen.
//! - [`create`]: write PNG/EXR sequences, GIF, MP4 (OpenH264 + `mp4`, no ffmpeg) and
//!   flipbooks (sprite sheet + JSON, [`read_flipbook`] reads them back). See [`mod@write`] for
//!   the pixel and **alpha convention of each output** and for atomicity.
//! - [`write_png`] / [`read_image`]: single stills.
//!
//! Pixel convention at this crate's boundary: [`RgbaFrame`] is **linear light** with
//! **straight** alpha, row 0 at the top. Only this crate converts to and from 8-bit sRGB.
//!
//! **Invariant:** no network access, ever: OpenH264 is compiled from source by cargo and
//! `ffmpeg` is used only if already installed.

mod convert;
pub mod error;
mod fingerprint;
pub mod read;
pub mod write;

pub use convert::check_crop;
pub use error::{MediaError, Result};
pub use fingerprint::source_fingerprint;
pub use ignis_core::{RgbaFrame, Size};
pub use read::{
    file_numbers_hint, frame_timing, frames_in_data, open, open_keeping_8bit, probe, read_image,
    source_files, Anamorphic, DecodedFrame, Decoder, FrameRange, FrameReader, FrameTiming,
    RangeUnit, ReadOptions, Rect, SourceInfo, DEFAULT_SEQUENCE_FPS,
};
pub use read::{sequence_fps, set_sequence_fps, SEQUENCE_FPS_RANGE};
pub use write::{
    check_output, create, fit_frame, read_flipbook, read_flipbook_meta, write_png, AlphaMode,
    Engine, Flipbook, FlipbookMeta, FlipbookOptions, Format, FrameWriter, MotionSource, ScaledFrom,
    Trimmed, WriteOptions,
};

/// Whether the system `ffmpeg` and `ffprobe` are usable (and `IGNIS_NO_FFMPEG` is not set).
pub fn ffmpeg_available() -> bool {
    read::ffmpeg_available()
}

#[doc(hidden)]
pub mod bench_support {
    //! For `benches/decode.rs` only.
    pub use crate::read::decode_rgba8_count;

    /// 8-bit sRGB RGBA → linear frame, the per-frame conversion every 8-bit decoder does.
    pub fn srgba8_to_linear(size: ignis_core::Size, bytes: &[u8]) -> ignis_core::RgbaFrame {
        crate::convert::from_srgba8(size, bytes)
    }
}

#[cfg(test)]
mod tests {
    /// Readers and writers can move to worker threads.
    #[test]
    fn readers_and_writers_are_send() {
        fn send<T: Send>() {}
        send::<crate::FrameReader>();
        send::<crate::FrameWriter>();
        send::<crate::MediaError>();
    }
}
