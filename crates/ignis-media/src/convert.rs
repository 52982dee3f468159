//! Pixel conversions between linear-light `f32` frames and 8-bit sRGB, plus crop and
//! resize. This is the only place in Ignis that encodes or decodes sRGB.

use std::sync::OnceLock;

use ignis_core::palette::srgb_to_linear;
use ignis_core::{RgbaFrame, Size};

use crate::error::{MediaError, Result};
use crate::read::Rect;

/// 8-bit sRGB code → linear light.
pub(crate) fn srgb8_lut() -> &'static [f32; 256] {
    static LUT: OnceLock<[f32; 256]> = OnceLock::new();
    LUT.get_or_init(|| std::array::from_fn(|i| srgb_to_linear(i as f32 / 255.0)))
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

/// Linear light → nearest 8-bit sRGB code (clamped), identical to
/// `round(linear_to_srgb(v) * 255)` up to float ties.
#[inline]
pub(crate) fn encode_srgb8(v: f32) -> u8 {
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
    for (o, p) in out.chunks_exact_mut(4).zip(frame.data()) {
        o[0] = encode_srgb8(p[0]);
        o[1] = encode_srgb8(p[1]);
        o[2] = encode_srgb8(p[2]);
        o[3] = encode_alpha8(p[3]);
    }
    out
}

/// A linear frame composited over an opaque `bg` → 8-bit sRGB RGB bytes.
pub(crate) fn to_srgb8_over(frame: &RgbaFrame, bg: [f32; 3]) -> Vec<u8> {
    let mut out = vec![0u8; frame.data().len() * 3];
    for (o, p) in out.chunks_exact_mut(3).zip(frame.data()) {
        let a = p[3].clamp(0.0, 1.0);
        for c in 0..3 {
            o[c] = encode_srgb8(p[c] * a + bg[c] * (1.0 - a));
        }
    }
    out
}

/// 8-bit sRGB RGBA bytes (straight alpha) → a linear frame.
pub(crate) fn from_srgba8(size: Size, bytes: &[u8]) -> RgbaFrame {
    let lut = srgb8_lut();
    let data = bytes
        .chunks_exact(4)
        .map(|p| {
            [
                lut[p[0] as usize],
                lut[p[1] as usize],
                lut[p[2] as usize],
                p[3] as f32 / 255.0,
            ]
        })
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

/// Checks that `rect` lies inside a frame of `size`.
pub(crate) fn check_crop(rect: &Rect, size: Size) -> Result<Size> {
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
    let mut data = Vec::with_capacity(size.pixels());
    for y in rect.y..rect.y + rect.height {
        let row = frame.row(y);
        data.extend_from_slice(&row[rect.x as usize..(rect.x + rect.width) as usize]);
    }
    RgbaFrame::from_vec(size, data).expect("crop size")
}

/// Resizes with a triangle (bilinear, widened when shrinking) filter. Colour is
/// premultiplied for the filter so that transparent pixels do not bleed their colour.
pub(crate) fn resize(frame: &RgbaFrame, to: Size) -> RgbaFrame {
    if frame.size() == to {
        return frame.clone();
    }
    let mut pre = frame.clone();
    premultiply(&mut pre);
    let flat: Vec<f32> = pre.data().iter().flatten().copied().collect();
    let buf =
        image::Rgba32FImage::from_raw(frame.width(), frame.height(), flat).expect("buffer size");
    let out = image::imageops::resize(
        &buf,
        to.width,
        to.height,
        image::imageops::FilterType::Triangle,
    );
    let data = out.pixels().map(|p| p.0).collect();
    let mut f = RgbaFrame::from_vec(to, data).expect("resize size");
    unpremultiply(&mut f);
    f
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
}
