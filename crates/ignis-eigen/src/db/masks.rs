//! The pre-processing masks of a clip's training frames (`masks/<clip>.rle`), stored at
//! training so rendering from the footage (§7.1.2) need not run the mask pipeline — HSV
//! layers, flame isolation, morphology, contours — again on every frame at the source
//! resolution: it reads the frame's mask back, exactly as training made it.
//!
//! Format (little-endian): the magic `IGNMSK01`, width, height and frame count (`u32`
//! each), `frames + 1` byte offsets (`u64`, from the start of the data), then per frame
//! and per row the number of runs and each run's `[start, end)` columns (`u16`). A mask
//! is binary (0 or 255, what [`crate::preprocess::frame_mask`] makes). About 4 bytes per
//! row for a single blob: ~4 kB per 1080p frame. The file's SHA-256 is in the manifest
//! like every other file.

use image::GrayImage;

const MAGIC: &[u8; 8] = b"IGNMSK01";
/// Magic plus width, height and frame count.
const HEADER: usize = 8 + 12;

/// Appends `m`'s row runs (non-zero pixels) to `out`. Widths above 65535 are refused by
/// [`MaskWriter::push`] before this runs.
fn encode(m: &GrayImage, out: &mut Vec<u8>) {
    let w = m.width() as usize;
    let mut runs: Vec<u16> = Vec::new();
    for row in m.as_raw().chunks_exact(w.max(1)) {
        runs.clear();
        let mut x = 0;
        while x < w {
            if row[x] == 0 {
                x += 1;
                continue;
            }
            let s = x;
            while x < w && row[x] != 0 {
                x += 1;
            }
            runs.extend([s as u16, x as u16]);
        }
        out.extend_from_slice(&((runs.len() / 2) as u16).to_le_bytes());
        for v in &runs {
            out.extend_from_slice(&v.to_le_bytes());
        }
    }
}

/// Builds a mask file in memory, one frame at a time.
pub struct MaskWriter {
    width: u32,
    height: u32,
    offsets: Vec<u64>,
    data: Vec<u8>,
}

impl MaskWriter {
    pub fn new(width: u32, height: u32) -> MaskWriter {
        MaskWriter {
            width,
            height,
            offsets: vec![0],
            data: Vec::new(),
        }
    }

    /// Adds the next frame's mask; fails on a mask of another size, or wider than 65535.
    pub fn push(&mut self, m: &GrayImage) -> std::result::Result<(), String> {
        if (m.width(), m.height()) != (self.width, self.height) || self.width > u16::MAX as u32 {
            return Err(format!(
                "a {}x{} mask in a {}x{} mask file (widths up to 65535)",
                m.width(),
                m.height(),
                self.width,
                self.height
            ));
        }
        encode(m, &mut self.data);
        self.offsets.push(self.data.len() as u64);
        Ok(())
    }

    /// The file's bytes.
    pub fn into_bytes(self) -> Vec<u8> {
        let frames = (self.offsets.len() - 1) as u32;
        let mut b = Vec::with_capacity(HEADER + 8 * self.offsets.len() + self.data.len());
        b.extend_from_slice(MAGIC);
        for v in [self.width, self.height, frames] {
            b.extend_from_slice(&v.to_le_bytes());
        }
        for o in &self.offsets {
            b.extend_from_slice(&o.to_le_bytes());
        }
        b.extend_from_slice(&self.data);
        b
    }
}

/// A mask file read back (its checksum checked by the caller).
#[derive(Debug)]
pub struct MaskFile {
    width: u32,
    height: u32,
    frames: usize,
    bytes: Vec<u8>,
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"))
}

impl MaskFile {
    /// Parses `bytes`, expecting `frames` masks of `width`×`height`; the reason when the
    /// header or the offset table does not fit.
    pub fn parse(
        bytes: Vec<u8>,
        width: u32,
        height: u32,
        frames: usize,
    ) -> std::result::Result<MaskFile, String> {
        if bytes.len() < HEADER || &bytes[..8] != MAGIC {
            return Err("not a mask file (bad magic)".into());
        }
        let (w, h, n) = (
            u32_at(&bytes, 8),
            u32_at(&bytes, 12),
            u32_at(&bytes, 16) as usize,
        );
        if (w, h, n) != (width, height, frames) {
            return Err(format!(
                "holds {n} masks of {w}x{h}, the manifest says {frames} of {width}x{height}"
            ));
        }
        let table = HEADER + 8 * (n + 1);
        if bytes.len() < table {
            return Err("truncated offset table".into());
        }
        let f = MaskFile {
            width,
            height,
            frames,
            bytes,
        };
        let data_len = (f.bytes.len() - table) as u64;
        let mut prev = 0;
        for j in 0..=n {
            let o = f.offset(j);
            if o < prev || o > data_len || (j == 0 && o != 0) || (j == n && o != data_len) {
                return Err(format!("offset {j} ({o}) out of order or past the data"));
            }
            prev = o;
        }
        Ok(f)
    }

    fn offset(&self, j: usize) -> u64 {
        let at = HEADER + 8 * j;
        u64::from_le_bytes(self.bytes[at..at + 8].try_into().expect("8 bytes"))
    }

    /// Mask `j` (0-based frame of the clip), 0/255; the reason when it is corrupt.
    pub fn mask(&self, j: usize) -> std::result::Result<GrayImage, String> {
        if j >= self.frames {
            return Err(format!("mask {j} of {}", self.frames));
        }
        let base = HEADER + 8 * (self.frames + 1);
        let d = &self.bytes[base + self.offset(j) as usize..base + self.offset(j + 1) as usize];
        let bad = || format!("mask {j} is corrupt");
        let mut img = GrayImage::new(self.width, self.height);
        let w = self.width as usize;
        let mut at = 0;
        let mut next = || -> std::result::Result<usize, String> {
            let v = d.get(at..at + 2).ok_or_else(bad)?;
            at += 2;
            Ok(u16::from_le_bytes([v[0], v[1]]) as usize)
        };
        for row in img.chunks_exact_mut(w.max(1)) {
            let runs = next()?;
            let mut last = 0;
            for _ in 0..runs {
                let (s, e) = (next()?, next()?);
                if s < last || s >= e || e > w {
                    return Err(bad());
                }
                row[s..e].fill(255);
                last = e;
            }
        }
        if at != d.len() {
            return Err(bad());
        }
        Ok(img)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(w: u32, h: u32, seed: u32) -> GrayImage {
        GrayImage::from_fn(w, h, |x, y| {
            let v = (x * 7 + y * 13 + seed * 5) % 11;
            image::Luma([if v < 4 || (x == w - 1 && y % 2 == 0) {
                255
            } else {
                0
            }])
        })
    }

    #[test]
    fn masks_round_trip_and_corruption_is_an_error() {
        let (w, h) = (37, 9);
        let masks: Vec<GrayImage> = (0..4).map(|s| sample(w, h, s)).collect();
        let mut mw = MaskWriter::new(w, h);
        for m in &masks {
            mw.push(m).unwrap();
        }
        mw.push(&GrayImage::new(w + 1, h)).unwrap_err();
        mw.push(&GrayImage::new(w, h)).unwrap();
        let bytes = mw.into_bytes();
        let f = MaskFile::parse(bytes.clone(), w, h, 5).unwrap();
        for (j, m) in masks.iter().enumerate() {
            assert_eq!(&f.mask(j).unwrap(), m, "mask {j}");
        }
        assert_eq!(f.mask(4).unwrap(), GrayImage::new(w, h));
        f.mask(5).unwrap_err();
        MaskFile::parse(bytes.clone(), w, h, 4).unwrap_err();
        MaskFile::parse(bytes[..bytes.len() - 1].to_vec(), w, h, 5).unwrap_err();
        // A run past the row's end.
        let mut b = bytes.clone();
        let at = HEADER + 8 * 6 + 2;
        b[at..at + 2].copy_from_slice(&60u16.to_le_bytes());
        let f = MaskFile::parse(b, w, h, 5).unwrap();
        f.mask(0).unwrap_err();
    }
}
