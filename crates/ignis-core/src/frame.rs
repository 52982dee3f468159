//! Frames: the unit of data that flows from sources through generators and post effects
//! to writers.
//!
//! Pixel conventions: row-major, row 0 at the **top**, `x` to the right. Values are
//! **linear light** `f32`; `0.0` is black and `1.0` is nominal white, but HDR values above
//! 1 are allowed (bloom and additive volume rendering produce them). [`RgbaFrame`] uses
//! **straight** (not premultiplied) alpha in `0..=1`.

use crate::error::{CoreError, Result};

/// The largest side a frame may have, in pixels.
pub const MAX_SIDE: u32 = 16_384;
/// The largest number of pixels a frame may have (≈ 8K × 8K); larger requests are refused
/// before anything is allocated.
pub const MAX_PIXELS: u64 = 64 * 1024 * 1024;

/// A frame size in pixels, checked against [`MAX_SIDE`] and [`MAX_PIXELS`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
pub struct Size {
    pub width: u32,
    pub height: u32,
}

impl Size {
    /// A checked size: both sides ≥ 1, each ≤ [`MAX_SIDE`], area ≤ [`MAX_PIXELS`].
    pub fn new(width: u32, height: u32) -> Result<Size> {
        if width == 0 || height == 0 {
            return Err(CoreError::bad(
                "size",
                format!("{width}x{height} has a zero side; use at least 1x1, e.g. 320x200"),
            ));
        }
        if width > MAX_SIDE || height > MAX_SIDE {
            return Err(CoreError::LimitExceeded(format!(
                "size {width}x{height}: each side must be at most {MAX_SIDE} pixels"
            )));
        }
        let px = width as u64 * height as u64;
        if px > MAX_PIXELS {
            return Err(CoreError::LimitExceeded(format!(
                "size {width}x{height} is {px} pixels; at most {MAX_PIXELS} are allowed"
            )));
        }
        Ok(Size { width, height })
    }

    /// Number of pixels.
    pub fn pixels(self) -> usize {
        self.width as usize * self.height as usize
    }

    /// The largest size with this size's aspect that fits inside `frame` (each side
    /// rounded, at least 1): what a picture of this size is scaled to when it is fitted
    /// into `frame` without stretching. `frame` itself when the aspects differ by less than
    /// a pixel.
    pub fn fitted_inside(self, frame: Size) -> Size {
        let (w, h) = (f64::from(self.width), f64::from(self.height));
        let (fw, fh) = (f64::from(frame.width), f64::from(frame.height));
        let (iw, ih) = if fw * h <= fh * w {
            (fw, fw * h / w)
        } else {
            (fh * w / h, fh)
        };
        let side = |v: f64, max: u32| (v.round() as u32).clamp(1, max);
        let inner = Size {
            width: side(iw, frame.width),
            height: side(ih, frame.height),
        };
        if frame.width - inner.width <= 1 && frame.height - inner.height <= 1 {
            frame
        } else {
            inner
        }
    }
}

impl std::fmt::Display for Size {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}x{}", self.width, self.height)
    }
}

impl std::str::FromStr for Size {
    type Err = CoreError;
    /// Parses `WIDTHxHEIGHT`, e.g. `320x200` (also accepts `X` or `×`).
    fn from_str(s: &str) -> Result<Size> {
        let t = s.trim();
        let mut parts = t.splitn(2, ['x', 'X', '×']);
        let (w, h) = (parts.next().unwrap_or(""), parts.next().unwrap_or(""));
        let parse = |v: &str| v.trim().parse::<u32>().ok();
        match (parse(w), parse(h)) {
            (Some(w), Some(h)) => Size::new(w, h),
            _ => Err(CoreError::bad(
                "size",
                format!("`{s}` is not WIDTHxHEIGHT; write e.g. 320x200"),
            )),
        }
    }
}

/// A single-channel frame of linear luminance.
#[derive(Clone, Debug, PartialEq)]
pub struct GrayFrame {
    width: u32,
    height: u32,
    data: Vec<f32>,
}

impl GrayFrame {
    /// A black frame.
    pub fn new(size: Size) -> GrayFrame {
        GrayFrame {
            width: size.width,
            height: size.height,
            data: vec![0.0; size.pixels()],
        }
    }

    /// Wraps row-major data; fails if `data.len() != width * height`.
    pub fn from_vec(size: Size, data: Vec<f32>) -> Result<GrayFrame> {
        if data.len() != size.pixels() {
            return Err(CoreError::SizeMismatch(format!(
                "{} values for a {size} frame (needs {})",
                data.len(),
                size.pixels()
            )));
        }
        Ok(GrayFrame {
            width: size.width,
            height: size.height,
            data,
        })
    }

    /// Builds a frame by evaluating `f(x, y)` at every pixel.
    pub fn from_fn(size: Size, mut f: impl FnMut(u32, u32) -> f32) -> GrayFrame {
        let mut data = Vec::with_capacity(size.pixels());
        for y in 0..size.height {
            for x in 0..size.width {
                data.push(f(x, y));
            }
        }
        GrayFrame {
            width: size.width,
            height: size.height,
            data,
        }
    }

    pub fn width(&self) -> u32 {
        self.width
    }
    pub fn height(&self) -> u32 {
        self.height
    }
    pub fn size(&self) -> Size {
        Size {
            width: self.width,
            height: self.height,
        }
    }
    pub fn data(&self) -> &[f32] {
        &self.data
    }
    pub fn data_mut(&mut self) -> &mut [f32] {
        &mut self.data
    }
    pub fn into_vec(self) -> Vec<f32> {
        self.data
    }
    /// Value at `(x, y)`; panics when out of bounds (programmer error).
    pub fn get(&self, x: u32, y: u32) -> f32 {
        self.data[y as usize * self.width as usize + x as usize]
    }
    pub fn set(&mut self, x: u32, y: u32, v: f32) {
        let w = self.width as usize;
        self.data[y as usize * w + x as usize] = v;
    }
    /// Row `y`.
    pub fn row(&self, y: u32) -> &[f32] {
        let w = self.width as usize;
        &self.data[y as usize * w..(y as usize + 1) * w]
    }
    /// Iterator over rows, top to bottom.
    pub fn rows(&self) -> std::slice::ChunksExact<'_, f32> {
        self.data.chunks_exact(self.width as usize)
    }
    /// Mutable iterator over rows, top to bottom.
    pub fn rows_mut(&mut self) -> std::slice::ChunksExactMut<'_, f32> {
        self.data.chunks_exact_mut(self.width as usize)
    }
    /// Applies `f` to every value.
    pub fn map(&self, f: impl Fn(f32) -> f32) -> GrayFrame {
        GrayFrame {
            width: self.width,
            height: self.height,
            data: self.data.iter().map(|&v| f(v)).collect(),
        }
    }
    /// Largest value (0 for an all-black or empty frame).
    pub fn max(&self) -> f32 {
        self.data.iter().copied().fold(0.0, f32::max)
    }
    /// Mean value.
    pub fn mean(&self) -> f32 {
        (self.data.iter().map(|&v| v as f64).sum::<f64>() / self.data.len().max(1) as f64) as f32
    }
    /// An opaque grey RGBA frame with the same values in R, G and B.
    pub fn to_rgba(&self) -> RgbaFrame {
        RgbaFrame {
            width: self.width,
            height: self.height,
            data: self.data.iter().map(|&v| [v, v, v, 1.0]).collect(),
        }
    }
}

/// Rec. 709 / sRGB luminance weights of linear R, G, B.
pub const LUMA: [f32; 3] = [0.2126, 0.7152, 0.0722];

/// A frame of linear-light RGBA with **straight** alpha.
#[derive(Clone, Debug, PartialEq)]
pub struct RgbaFrame {
    width: u32,
    height: u32,
    data: Vec<[f32; 4]>,
}

impl RgbaFrame {
    /// A transparent black frame.
    pub fn new(size: Size) -> RgbaFrame {
        RgbaFrame {
            width: size.width,
            height: size.height,
            data: vec![[0.0; 4]; size.pixels()],
        }
    }
    /// A frame filled with one colour.
    pub fn filled(size: Size, c: [f32; 4]) -> RgbaFrame {
        RgbaFrame {
            width: size.width,
            height: size.height,
            data: vec![c; size.pixels()],
        }
    }
    /// This frame centred in a transparent frame of `size` (which must be at least as
    /// large on both sides; otherwise, or at the same size, the frame is returned as it
    /// is): the borders of a picture fitted inside a frame of another aspect
    /// ([`Size::fitted_inside`]).
    pub fn centred_in(&self, size: Size) -> RgbaFrame {
        let (w, h) = (self.width as usize, self.height as usize);
        let (fw, fh) = (size.width as usize, size.height as usize);
        if fw < w || fh < h || (fw, fh) == (w, h) {
            return self.clone();
        }
        let (x0, y0) = ((fw - w) / 2, (fh - h) / 2);
        let mut out = RgbaFrame::new(size);
        for (y, row) in self.data.chunks_exact(w).enumerate() {
            let at = (y0 + y) * fw + x0;
            out.data[at..at + w].copy_from_slice(row);
        }
        out
    }
    /// Wraps row-major data; fails if `data.len() != width * height`.
    pub fn from_vec(size: Size, data: Vec<[f32; 4]>) -> Result<RgbaFrame> {
        if data.len() != size.pixels() {
            return Err(CoreError::SizeMismatch(format!(
                "{} pixels for a {size} frame (needs {})",
                data.len(),
                size.pixels()
            )));
        }
        Ok(RgbaFrame {
            width: size.width,
            height: size.height,
            data,
        })
    }
    pub fn width(&self) -> u32 {
        self.width
    }
    pub fn height(&self) -> u32 {
        self.height
    }
    pub fn size(&self) -> Size {
        Size {
            width: self.width,
            height: self.height,
        }
    }
    pub fn data(&self) -> &[[f32; 4]] {
        &self.data
    }
    pub fn data_mut(&mut self) -> &mut [[f32; 4]] {
        &mut self.data
    }
    pub fn into_vec(self) -> Vec<[f32; 4]> {
        self.data
    }
    pub fn get(&self, x: u32, y: u32) -> [f32; 4] {
        self.data[y as usize * self.width as usize + x as usize]
    }
    pub fn set(&mut self, x: u32, y: u32, v: [f32; 4]) {
        let w = self.width as usize;
        self.data[y as usize * w + x as usize] = v;
    }
    /// Row `y`.
    pub fn row(&self, y: u32) -> &[[f32; 4]] {
        let w = self.width as usize;
        &self.data[y as usize * w..(y as usize + 1) * w]
    }
    /// Linear luminance (Rec. 709 weights) of each pixel, ignoring alpha.
    pub fn luminance(&self) -> GrayFrame {
        GrayFrame {
            width: self.width,
            height: self.height,
            data: self
                .data
                .iter()
                .map(|p| LUMA[0] * p[0] + LUMA[1] * p[1] + LUMA[2] * p[2])
                .collect(),
        }
    }
    /// Replaces the alpha channel by `alpha` (values clamped to `0..=1`).
    pub fn with_alpha(mut self, alpha: &GrayFrame) -> Result<RgbaFrame> {
        if alpha.size() != self.size() {
            return Err(CoreError::SizeMismatch(format!(
                "alpha {} for a {} frame",
                alpha.size(),
                self.size()
            )));
        }
        for (p, &a) in self.data.iter_mut().zip(alpha.data()) {
            p[3] = a.clamp(0.0, 1.0);
        }
        Ok(self)
    }
    /// Composites over an opaque background colour (straight alpha "over"), giving an
    /// opaque frame. Used by writers of formats without alpha (MP4, GIF).
    pub fn over(&self, bg: [f32; 3]) -> RgbaFrame {
        RgbaFrame {
            width: self.width,
            height: self.height,
            data: self
                .data
                .iter()
                .map(|p| {
                    let a = p[3].clamp(0.0, 1.0);
                    [
                        p[0] * a + bg[0] * (1.0 - a),
                        p[1] * a + bg[1] * (1.0 - a),
                        p[2] * a + bg[2] * (1.0 - a),
                        1.0,
                    ]
                })
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 16:9 picture fitted into a square keeps its aspect (a band across the middle),
    /// a tall one into a wide frame a column; a frame of the same aspect, or within a
    /// pixel of it, is taken whole. Centred with transparent borders, the picture's pixels
    /// are unchanged.
    #[test]
    fn a_picture_fitted_inside_another_aspect_keeps_its_own() {
        let s = |w, h| Size::new(w, h).unwrap();
        assert_eq!(s(640, 360).fitted_inside(s(256, 256)), s(256, 144));
        assert_eq!(s(304, 540).fitted_inside(s(512, 256)), s(144, 256));
        assert_eq!(s(640, 360).fitted_inside(s(320, 180)), s(320, 180));
        assert_eq!(s(640, 360).fitted_inside(s(320, 181)), s(320, 181));
        assert_eq!(s(1000, 1).fitted_inside(s(10, 10)), s(10, 1));
        let mut small = RgbaFrame::new(s(3, 2));
        small.data[4] = [0.5, 0.25, 0.125, 1.0];
        let big = small.centred_in(s(7, 4));
        assert_eq!(big.size(), s(7, 4));
        // the picture's (1, 1) lands at (2 + 1, 1 + 1)
        assert_eq!(big.get(3, 2), [0.5, 0.25, 0.125, 1.0]);
        let lit = big.data().iter().filter(|p| p[3] > 0.0).count();
        assert_eq!(lit, 1);
        assert_eq!(small.centred_in(s(3, 2)), small);
    }

    #[test]
    fn size_parses_and_checks() {
        assert_eq!(
            "320x200".parse::<Size>().unwrap(),
            Size {
                width: 320,
                height: 200
            }
        );
        assert!("0x0".parse::<Size>().is_err());
        assert!(matches!(
            "100000x100000".parse::<Size>(),
            Err(CoreError::LimitExceeded(_))
        ));
        assert!(matches!(
            "16000x16000".parse::<Size>(),
            Err(CoreError::LimitExceeded(_))
        ));
        assert!("abc".parse::<Size>().is_err());
        assert!("12x".parse::<Size>().is_err());
    }

    #[test]
    fn gray_rgba_roundtrip() {
        let s = Size::new(3, 2).unwrap();
        let g = GrayFrame::from_fn(s, |x, y| (x + 3 * y) as f32 / 6.0);
        let back = g.to_rgba().luminance();
        for (a, b) in g.data().iter().zip(back.data()) {
            assert!((a - b).abs() < 1e-6);
        }
        assert!(GrayFrame::from_vec(s, vec![0.0; 5]).is_err());
    }
}
