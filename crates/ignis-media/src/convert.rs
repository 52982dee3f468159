//! Pixel conversions between linear-light `f32` frames and 8-bit sRGB, plus crop and
//! resize. This is the only place in Ignis that encodes or decodes sRGB.

use std::sync::OnceLock;

use ignis_core::palette::srgb_to_linear;
use ignis_core::{RgbaFrame, Size};

use crate::error::{MediaError, Result};
use crate::read::Rect;

/// 8-bit sRGB code → linear light.
pub(crate) fn srgb8_lut() -> &'static [f32; 256] {
    ignis_core::palette::srgb8_to_linear_table()
}

/// Linear value at which the nearest 8-bit sRGB code changes from `k - 1` to `k`
/// (index 0 unused). Encoding by search over these is exact rounding and fast.
fn srgb8_thresholds() -> &'static [f32; 256] {
    static T: OnceLock<[f32; 256]> = OnceLock::new();
    T.get_or_init(|| {
        std::array::from_fn(|k| {
            if k == 0 {
                f32::NEG_INFINITY
            } else {
                srgb_to_linear((k as f32 - 0.5) / 255.0)
            }
        })
    })
}

/// Bins of the coarse table of [`encode_srgb8`].
const SRGB8_BINS: usize = 4096;

/// The sRGB code of `i / SRGB8_BINS` for every bin start (the number of thresholds at or
/// below it, minus one).
fn srgb8_coarse() -> &'static [u8; SRGB8_BINS] {
    static C: OnceLock<[u8; SRGB8_BINS]> = OnceLock::new();
    C.get_or_init(|| std::array::from_fn(|i| encode_srgb8_search(i as f32 / SRGB8_BINS as f32)))
}

/// Linear light → nearest 8-bit sRGB code (clamped), identical to
/// `round(linear_to_srgb(v) * 255)` up to float ties ([`Srgb8Encoder::encode`]; loops
/// fetch the tables once with [`Srgb8Encoder::new`]).
#[cfg(test)]
fn encode_srgb8(v: f32) -> u8 {
    Srgb8Encoder::new().encode(v)
}

/// The tables of [`encode_srgb8`], fetched once for a loop over many values.
#[derive(Clone, Copy)]
pub(crate) struct Srgb8Encoder {
    coarse: &'static [u8; SRGB8_BINS],
    thresholds: &'static [f32; 256],
}

impl Srgb8Encoder {
    pub(crate) fn new() -> Srgb8Encoder {
        Srgb8Encoder {
            coarse: srgb8_coarse(),
            thresholds: srgb8_thresholds(),
        }
    }

    /// The code at the start of `v`'s bin in a 4096-entry table, then the thresholds
    /// above it (at most one or two steps: the steepest part of the curve, near 0, rises
    /// 0.8 codes per bin).
    #[inline]
    pub(crate) fn encode(&self, v: f32) -> u8 {
        // NaN and v ≤ 0 → 0; v ≥ 1 → 255 (the last threshold is below 1).
        if !(v > 0.0) {
            return 0;
        }
        if v >= 1.0 {
            return 255;
        }
        let t = self.thresholds;
        let mut k = self.coarse[((v * SRGB8_BINS as f32) as usize).min(SRGB8_BINS - 1)] as usize;
        while k < 255 && t[k + 1] <= v {
            k += 1;
        }
        k as u8
    }
}

/// [`encode_srgb8`] by binary search over the 256 thresholds (builds the coarse table).
fn encode_srgb8_search(v: f32) -> u8 {
    let t = srgb8_thresholds();
    // Branch-light binary search over 256 thresholds: number of thresholds <= v, minus one.
    let mut lo = 0usize;
    let mut step = 128usize;
    while step > 0 {
        if t[lo + step] <= v {
            lo += step;
        }
        step /= 2;
    }
    if v.is_nan() {
        0
    } else {
        lo as u8
    }
}

/// Alpha `0..=1` → 8-bit (alpha is stored linearly, never sRGB-encoded).
#[inline]
pub(crate) fn encode_alpha8(a: f32) -> u8 {
    (a.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// A linear straight-alpha frame → 8-bit sRGB RGBA bytes (straight alpha).
pub(crate) fn to_srgba8(frame: &RgbaFrame) -> Vec<u8> {
    let mut out = vec![0u8; frame.data().len() * 4];
    let e = Srgb8Encoder::new();
    for (o, p) in out.chunks_exact_mut(4).zip(frame.data()) {
        o[0] = e.encode(p[0]);
        o[1] = e.encode(p[1]);
        o[2] = e.encode(p[2]);
        o[3] = encode_alpha8(p[3]);
    }
    out
}

/// A linear frame composited over an opaque `bg` → 8-bit sRGB RGB bytes.
pub(crate) fn to_srgb8_over(frame: &RgbaFrame, bg: [f32; 3]) -> Vec<u8> {
    let mut out = vec![0u8; frame.data().len() * 3];
    let e = Srgb8Encoder::new();
    for (o, p) in out.chunks_exact_mut(3).zip(frame.data()) {
        let a = p[3].clamp(0.0, 1.0);
        for c in 0..3 {
            o[c] = e.encode(p[c] * a + bg[c] * (1.0 - a));
        }
    }
    out
}

/// 8-bit sRGB RGBA bytes (straight alpha) → a linear frame.
pub(crate) fn from_srgba8(size: Size, bytes: &[u8]) -> RgbaFrame {
    let lut = srgb8_lut();
    let data = bytes
        .chunks_exact(4)
        .map(|p| ignis_core::palette::srgba8_to_linear(lut, p))
        .collect();
    RgbaFrame::from_vec(size, data).expect("length checked by caller")
}

/// Any decoded still → a linear frame. Integer formats are taken as sRGB-encoded colour with
/// linear alpha; float formats (EXR, float TIFF) as linear light already.
pub(crate) fn from_dynamic(img: image::DynamicImage) -> Result<RgbaFrame> {
    use image::DynamicImage as D;
    let size = Size::new(img.width(), img.height())?;
    Ok(match img {
        D::ImageRgb32F(_) | D::ImageRgba32F(_) => {
            let buf = img.into_rgba32f();
            let data = buf.pixels().map(|p| p.0).collect();
            RgbaFrame::from_vec(size, data)?
        }
        D::ImageLuma16(_) | D::ImageLumaA16(_) | D::ImageRgb16(_) | D::ImageRgba16(_) => {
            let buf = img.into_rgba16();
            let data = buf
                .pixels()
                .map(|p| {
                    let f = |v: u16| srgb_to_linear(v as f32 / 65535.0);
                    [f(p[0]), f(p[1]), f(p[2]), p[3] as f32 / 65535.0]
                })
                .collect();
            RgbaFrame::from_vec(size, data)?
        }
        other => from_srgba8(size, other.into_rgba8().as_raw()),
    })
}

/// Straight → premultiplied alpha, in place.
pub(crate) fn premultiply(frame: &mut RgbaFrame) {
    for p in frame.data_mut() {
        let a = p[3];
        p[0] *= a;
        p[1] *= a;
        p[2] *= a;
    }
}

/// Premultiplied → straight alpha, in place (colour of fully transparent pixels becomes 0).
pub(crate) fn unpremultiply(frame: &mut RgbaFrame) {
    for p in frame.data_mut() {
        let a = p[3];
        if a > 0.0 {
            p[0] /= a;
            p[1] /= a;
            p[2] /= a;
        } else {
            p[0] = 0.0;
            p[1] = 0.0;
            p[2] = 0.0;
        }
    }
}

/// Checks that `rect` lies inside a frame of `size` and is not empty; its size.
pub fn check_crop(rect: &Rect, size: Size) -> Result<Size> {
    let ok = rect.width > 0
        && rect.height > 0
        && rect
            .x
            .checked_add(rect.width)
            .is_some_and(|r| r <= size.width)
        && rect
            .y
            .checked_add(rect.height)
            .is_some_and(|b| b <= size.height);
    if !ok {
        return Err(MediaError::bad(
            "crop",
            format!(
                "{}x{}+{}+{} does not fit inside the {size} source (and must not be empty)",
                rect.width, rect.height, rect.x, rect.y
            ),
        ));
    }
    Ok(Size::new(rect.width, rect.height)?)
}

/// Cuts `rect` (already checked) out of `frame`.
pub(crate) fn crop(frame: &RgbaFrame, rect: &Rect) -> RgbaFrame {
    let size = Size {
        width: rect.width,
        height: rect.height,
    };
    RgbaFrame::from_vec(size, crop_values(frame.data(), frame.width(), rect)).expect("crop size")
}

/// Cuts `rect` (already checked) out of `data`, one value per pixel of a `width`-wide
/// frame (colour, motion vectors), row by row.
pub(crate) fn crop_values<T: Copy>(data: &[T], width: u32, rect: &Rect) -> Vec<T> {
    let mut out = Vec::with_capacity(rect.width as usize * rect.height as usize);
    for y in rect.y..rect.y + rect.height {
        let start = y as usize * width as usize + rect.x as usize;
        out.extend_from_slice(&data[start..start + rect.width as usize]);
    }
    out
}

/// Cuts `rect` (already checked) out of 8-bit RGBA `bytes` of a `width`-wide frame.
pub(crate) fn crop_srgba8(bytes: &[u8], width: u32, rect: &Rect) -> Vec<u8> {
    crop_values(bytes.as_chunks::<4>().0, width, rect).into_flattened()
}

/// One output sample's source taps: first source index and normalised weights.
struct Taps {
    first: usize,
    weights: Vec<f32>,
}

/// Triangle-filter taps from `n` source samples to `m` (the filter widened by the ratio
/// when shrinking; taps past the edges are dropped and the rest renormalised, as the
/// `image` crate's `Triangle` resize does).
fn triangle_taps(n: usize, m: usize) -> Vec<Taps> {
    let ratio = n as f64 / m as f64;
    let support = ratio.max(1.0);
    (0..m)
        .map(|i| {
            let c = (i as f64 + 0.5) * ratio - 0.5;
            let lo = ((c - support).floor() as i64 + 1).max(0) as usize;
            let hi = (((c + support).ceil() as i64).max(0) as usize).min(n - 1);
            let mut w: Vec<f32> = (lo..=hi)
                .map(|j| (1.0 - (j as f64 - c).abs() / support).max(0.0) as f32)
                .collect();
            // The tap nearest `c` is within the support, so the sum is > 0.
            let sum: f32 = w.iter().sum();
            w.iter_mut().for_each(|v| *v /= sum);
            Taps {
                first: lo,
                weights: w,
            }
        })
        .collect()
}

/// Resizes with a triangle (bilinear, widened when shrinking) filter. Colour is
/// premultiplied for the filter so that transparent pixels do not bleed their colour.
/// Separable: columns first (whole rows at a time, so it vectorises), then rows on the
/// fewer (when shrinking) output rows; rows in parallel, the same at any thread count.
pub(crate) fn resize(frame: &RgbaFrame, to: Size) -> RgbaFrame {
    use rayon::prelude::*;
    if frame.size() == to {
        return frame.clone();
    }
    let (sw, sh) = (frame.width() as usize, frame.height() as usize);
    let (tw, th) = (to.width as usize, to.height as usize);
    let (hx, vy) = (triangle_taps(sw, tw), triangle_taps(sh, th));
    let mut data = vec![[0f32; 4]; th * tw];
    data.par_chunks_mut(tw).zip(&vy).for_each_init(
        || vec![[0f32; 4]; sw],
        |mid, (out, t)| {
            // Vertical: this output row at the source width, premultiplied.
            mid.iter_mut().for_each(|m| *m = [0.0; 4]);
            for (k, &w) in t.weights.iter().enumerate() {
                for (m, p) in mid.iter_mut().zip(frame.row((t.first + k) as u32)) {
                    let a = p[3] * w;
                    m[0] += p[0] * a;
                    m[1] += p[1] * a;
                    m[2] += p[2] * a;
                    m[3] += a;
                }
            }
            // Horizontal, then back to straight alpha.
            for (o, t) in out.iter_mut().zip(&hx) {
                let mut acc = [0f32; 4];
                for (m, &w) in mid[t.first..].iter().zip(&t.weights) {
                    for c in 0..4 {
                        acc[c] += m[c] * w;
                    }
                }
                let a = acc[3];
                *o = if a > 0.0 {
                    [acc[0] / a, acc[1] / a, acc[2] / a, a]
                } else {
                    [0.0; 4]
                };
            }
        },
    );
    RgbaFrame::from_vec(to, data).expect("resize size")
}

/// Debug helper kept for tests: the slow reference encoder.
#[cfg(test)]
fn encode_srgb8_reference(v: f32) -> u8 {
    (ignis_core::palette::linear_to_srgb(v) * 255.0).round() as u8
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb8_roundtrip_is_exact() {
        let lut = srgb8_lut();
        for k in 0..=255u8 {
            assert_eq!(encode_srgb8(lut[k as usize]), k);
        }
    }

    /// The table-and-step encoder equals the binary search everywhere, thresholds and
    /// their neighbours included.
    #[test]
    fn encode_table_matches_search() {
        let t = srgb8_thresholds();
        let mut vals: Vec<f32> = (0..=200_000).map(|i| i as f32 / 190_000.0 - 0.01).collect();
        for &x in &t[1..] {
            vals.extend([
                x,
                f32::from_bits(x.to_bits() - 1),
                f32::from_bits(x.to_bits() + 1),
            ]);
        }
        vals.extend([f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1.0, 0.0, -0.0]);
        for v in vals {
            assert_eq!(encode_srgb8(v), encode_srgb8_search(v), "{v}");
        }
    }

    #[test]
    fn encode_matches_reference() {
        for i in 0..=10_000 {
            let v = i as f32 / 9_000.0 - 0.05;
            let (a, b) = (encode_srgb8(v), encode_srgb8_reference(v));
            assert!((a as i32 - b as i32).abs() <= 1, "{v}: {a} vs {b}");
        }
        assert_eq!(encode_srgb8(f32::NAN), 0);
        assert_eq!(encode_srgb8(7.0), 255);
    }

    #[test]
    fn crop_checks_bounds() {
        let s = Size::new(4, 3).unwrap();
        assert!(check_crop(
            &Rect {
                x: 1,
                y: 1,
                width: 3,
                height: 2
            },
            s
        )
        .is_ok());
        assert!(check_crop(
            &Rect {
                x: 2,
                y: 0,
                width: 3,
                height: 1
            },
            s
        )
        .is_err());
        assert!(check_crop(
            &Rect {
                x: 0,
                y: 0,
                width: 0,
                height: 1
            },
            s
        )
        .is_err());
        let f =
            RgbaFrame::from_vec(s, (0..12).map(|i| [i as f32, 0.0, 0.0, 1.0]).collect()).unwrap();
        let c = crop(
            &f,
            &Rect {
                x: 1,
                y: 1,
                width: 2,
                height: 2,
            },
        );
        assert_eq!(c.get(0, 0)[0], 5.0);
        assert_eq!(c.get(1, 1)[0], 10.0);
    }

    #[test]
    fn resize_keeps_flat_colour() {
        let f = RgbaFrame::filled(Size::new(8, 6).unwrap(), [0.25, 0.5, 0.75, 0.5]);
        let r = resize(&f, Size::new(3, 5).unwrap());
        assert_eq!(r.size(), Size::new(3, 5).unwrap());
        for p in r.data() {
            assert!((p[0] - 0.25).abs() < 1e-5 && (p[3] - 0.5).abs() < 1e-5);
        }
    }

    /// The separable resize equals the `image` crate's Triangle resize of the
    /// premultiplied frame (what it replaced) when shrinking and enlarging.
    #[test]
    fn resize_matches_image_triangle() {
        let size = Size::new(37, 23).unwrap();
        let data = (0..size.pixels())
            .map(|i| {
                let h = (i as u32).wrapping_mul(2_654_435_761);
                let v = |k: u32| ((h >> k) & 255) as f32 / 255.0;
                [v(0), v(8), v(16), v(24) * (i % 3) as f32 / 2.0]
            })
            .collect();
        let f = RgbaFrame::from_vec(size, data).unwrap();
        for to in [Size::new(11, 7).unwrap(), Size::new(50, 40).unwrap()] {
            let mut pre = f.clone();
            premultiply(&mut pre);
            let flat: Vec<f32> = pre.data().iter().flatten().copied().collect();
            let buf = image::Rgba32FImage::from_raw(37, 23, flat).unwrap();
            let want = image::imageops::resize(
                &buf,
                to.width,
                to.height,
                image::imageops::FilterType::Triangle,
            );
            let got = resize(&f, to);
            for (g, w) in got.data().iter().zip(want.pixels()) {
                let w = w.0;
                assert!(
                    (g[3] - w[3]).abs() < 1e-4,
                    "{to}: alpha {} vs {}",
                    g[3],
                    w[3]
                );
                for c in 0..3 {
                    assert!((g[c] * g[3] - w[c]).abs() < 1e-4, "{to}: {g:?} vs {w:?}");
                }
            }
        }
    }
}
