//! Hermite background and smoke removal.
//!
//! Source: eigenfires-thesis.txt §3.3.1, Figure 20. With `S = (I − I_min)/(I_max − I_min)`
//! clamped to `0..=1`, a pixel is multiplied by the Hermite basis function
//! `h(S) = 3S² − 2S³`: pixels above `I_max` are kept, pixels below `I_min` become black,
//! pixels in between are darkened smoothly. Pixels inside the flame's contour mask are
//! left untouched (Figure 20d).
//!
//! Departure: the thesis's equation is not legible in our copy; "the second Hermite basis
//! function" is read as h₀₁(S) = 3S² − 2S³, the one that rises from 0 at S=0 to 1 at S=1
//! with zero slope at both ends, which is what the text describes. The thresholds are on
//! the **sRGB-encoded** luminance in `0..=1` (the thesis's 110 and 220 are 0.43 and 0.86);
//! the frame itself stays linear light.

use crate::error::{EigenError, Result};
use ignis_core::frame::LUMA;
use ignis_core::palette::{linear_to_srgb, srgb_to_linear};
use ignis_core::{GrayFrame, RgbaFrame};
use image::GrayImage;
use serde::{Deserialize, Serialize};

/// Settings of [`hermite_darken`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HermiteParams {
    /// Below this (sRGB-encoded, `0..1`) a pixel outside the contour becomes black.
    /// Default 0.15.
    pub i_min: f32,
    /// Above this a pixel is kept. Must be > `i_min`. Default 0.55.
    pub i_max: f32,
    /// Leave pixels inside the contour mask untouched. Default true.
    pub protect_interior: bool,
}

impl Default for HermiteParams {
    fn default() -> Self {
        HermiteParams {
            i_min: 0.15,
            i_max: 0.55,
            protect_interior: true,
        }
    }
}

impl HermiteParams {
    pub fn validate(&self) -> Result<()> {
        if !((0.0..1.0).contains(&self.i_min) && self.i_max > self.i_min && self.i_max <= 1.0) {
            return Err(EigenError::bad(
                "hermite",
                format!(
                    "needs 0 <= i_min < i_max <= 1 (got i_min={}, i_max={})",
                    self.i_min, self.i_max
                ),
            ));
        }
        Ok(())
    }
}

/// The Hermite basis function h₀₁(s) = 3s² − 2s³ on `s` clamped to `0..=1`.
#[inline]
pub fn hermite_h01(s: f32) -> f32 {
    let s = s.clamp(0.0, 1.0);
    s * s * (3.0 - 2.0 * s)
}

/// Darkens `gray` (linear luminance) outside `mask` (255 = protected) per §3.3.1.
/// `mask` may be `None` (nothing protected).
pub fn hermite_darken(gray: &GrayFrame, mask: Option<&GrayImage>, p: &HermiteParams) -> GrayFrame {
    let mut out = gray.clone();
    let protect = if p.protect_interior {
        mask.map(|m| m.as_raw().as_slice())
    } else {
        None
    };
    let f = Darken::new(p);
    for (i, v) in out.data_mut().iter_mut().enumerate() {
        if protect.is_some_and(|m| m.get(i).is_some_and(|&b| b > 0)) {
            continue;
        }
        *v = f.apply(*v);
    }
    out
}

/// [`hermite_darken`] of `frame`'s luminance, each pixel then multiplied by `matte` (the
/// flame isolation of [`crate::preprocess::source_grey_with_mask`]) — the same values bit
/// for bit, in one pass: no luminance frame, and no sRGB encoding where the matte is 0 (the
/// product is then `v × 0`) or where the value is clearly below `i_min` or above `i_max`
/// (see [`Darken`]).
pub fn hermite_darken_rgba(
    frame: &RgbaFrame,
    mask: &GrayImage,
    matte: Option<&GrayFrame>,
    p: &HermiteParams,
) -> GrayFrame {
    let f = Darken::new(p);
    let n = frame.data().len();
    let m = mask.as_raw();
    let protected = |i: usize| p.protect_interior && m.get(i).is_some_and(|&b| b > 0);
    let t = matte.map(|t| t.data()).filter(|t| t.len() == n);
    let data = frame
        .data()
        .iter()
        .enumerate()
        .map(|(i, px)| match t {
            Some(t) => darken_matted(&f, px, t[i], protected(i)),
            None => {
                let v = luma(px);
                if protected(i) {
                    v
                } else {
                    f.apply(v)
                }
            }
        })
        .collect();
    GrayFrame::from_vec(frame.size(), data).expect("same size")
}

/// [`hermite_darken_rgba`] with `matte`, computed only inside `area` = `(x0, y0, x1, y1)`
/// (end-exclusive), the box outside which `matte` is 0; pixels outside are 0 without
/// being read (the rule's `v × 0` differs from +0 only for a negative or non-finite `v`,
/// which linear-light footage does not hold).
pub fn hermite_darken_rgba_in(
    frame: &RgbaFrame,
    mask: &GrayImage,
    matte: &GrayFrame,
    area: (u32, u32, u32, u32),
    p: &HermiteParams,
) -> GrayFrame {
    let size = frame.size();
    let mut out = GrayFrame::new(size);
    let w = size.width as usize;
    let (x0, y0) = (area.0 as usize, area.1 as usize);
    let (x1, y1) = (
        (area.2 as usize).min(w),
        (area.3 as usize).min(size.height as usize),
    );
    if matte.size() != size || x0 >= x1 || y0 >= y1 {
        return hermite_darken_rgba(frame, mask, Some(matte), p);
    }
    let f = Darken::new(p);
    let m = mask.as_raw();
    let protected = |i: usize| p.protect_interior && m.get(i).is_some_and(|&b| b > 0);
    for y in y0..y1 {
        let at = y * w;
        let row = &frame.data()[at + x0..at + x1];
        let t = &matte.data()[at + x0..at + x1];
        let o = &mut out.data_mut()[at + x0..at + x1];
        for (j, ((o, px), &t)) in o.iter_mut().zip(row).zip(t).enumerate() {
            *o = darken_matted(&f, px, t, protected(at + x0 + j));
        }
    }
    out
}

/// [`hermite_darken_rgba_in`] of an 8-bit sRGB RGBA frame (`bytes`, `size`), read
/// through [`crate::footage::srgb8_table`]: bit for bit the result on the frame converted
/// to linear light first, without that conversion (renders of 8-bit footage). Its loop
/// is [`hermite_darken_rgba_in`]'s with another pixel read; one generic body over both
/// cost 4 % more CPU in `ignis bench eigen-footage`, so the two stay apart.
pub fn hermite_darken_srgb8_in(
    size: ignis_core::Size,
    bytes: &[u8],
    mask: &GrayImage,
    matte: &GrayFrame,
    area: (u32, u32, u32, u32),
    p: &HermiteParams,
) -> GrayFrame {
    let w = size.width as usize;
    let (x0, y0) = (area.0 as usize, area.1 as usize);
    let (x1, y1) = (
        (area.2 as usize).min(w),
        (area.3 as usize).min(size.height as usize),
    );
    if matte.size() != size || x0 >= x1 || y0 >= y1 || bytes.len() != size.pixels() * 4 {
        let lin = crate::footage::SourceFrame::Srgb8 {
            size,
            bytes: bytes.to_vec(),
        };
        return hermite_darken_rgba(&lin.to_linear(), mask, Some(matte), p);
    }
    let f = Darken::new(p);
    let t8 = crate::footage::srgb8_table();
    let m = mask.as_raw();
    let protected = |i: usize| p.protect_interior && m.get(i).is_some_and(|&b| b > 0);
    // Written once, row by row (0 outside the area), never zero-filled first.
    let mut out = Vec::with_capacity(size.pixels());
    out.resize(y0 * w, 0.0);
    for y in y0..y1 {
        let at = y * w;
        out.resize(at + w, 0.0);
        let row = &bytes[(at + x0) * 4..(at + x1) * 4];
        let t = &matte.data()[at + x0..at + x1];
        let o = &mut out[at + x0..at + x1];
        for (j, ((o, px), &t)) in o.iter_mut().zip(row.chunks_exact(4)).zip(t).enumerate() {
            // Where the matte is 0 the rule's `v × 0` is +0 (8-bit pixels are finite and
            // ≥ 0), so the pixel is not read.
            *o = if t == 0.0 {
                0.0
            } else {
                let px = crate::footage::srgb8_pixel(t8, px);
                darken_matted(&f, &px, t, protected(at + x0 + j))
            };
        }
    }
    out.resize(size.pixels(), 0.0);
    GrayFrame::from_vec(size, out).expect("the frame's pixels")
}

/// Linear Rec. 709 luminance of a pixel (as `RgbaFrame::luminance`).
#[inline]
fn luma(px: &[f32; 4]) -> f32 {
    LUMA[0] * px[0] + LUMA[1] * px[1] + LUMA[2] * px[2]
}

/// One pixel of the fused pass: its luminance, darkened unless `protected`, times the
/// matte value `t`; where `t` is 0 no darkening is computed (`v × h × 0` has `v`'s sign,
/// as `h ≥ +0`, and is NaN where `v` is not finite, as `v × 0`).
#[inline]
fn darken_matted(f: &Darken, px: &[f32; 4], t: f32, protected: bool) -> f32 {
    let v = luma(px);
    if t == 0.0 {
        v * 0.0
    } else if protected {
        v * t
    } else {
        f.apply(v) * t
    }
}

/// The darkening of one unprotected pixel, `v × h₀₁((sRGB(v) − i_min)/(i_max − i_min))`,
/// without the sRGB encoding (a `powf`) where its result is known: `h` is exactly 0 where
/// `sRGB(v) ≤ i_min` and exactly 1 where `sRGB(v) ≥ i_max`, so below `lo` (0.1 % under
/// `i_min` in linear light, far more than the encoding's rounding) the result is `v × 0`
/// and above `hi` (0.1 % over `i_max`) it is `v`. Bit for bit the rule's value.
struct Darken {
    i_min: f32,
    span: f32,
    lo: f32,
    hi: f32,
}

impl Darken {
    fn new(p: &HermiteParams) -> Self {
        Darken {
            i_min: p.i_min,
            span: p.i_max - p.i_min,
            lo: srgb_to_linear(p.i_min) * 0.999,
            hi: if p.i_max < 1.0 {
                srgb_to_linear(p.i_max) * 1.001
            } else {
                f32::INFINITY
            },
        }
    }
    #[inline]
    fn apply(&self, v: f32) -> f32 {
        if v <= self.lo {
            v * 0.0
        } else if v >= self.hi {
            v
        } else {
            v * hermite_h01((linear_to_srgb(v) - self.i_min) / self.span)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ignis_core::palette::srgb_to_linear;
    use ignis_core::Size;

    #[test]
    fn hermite_keeps_darkens_and_protects() {
        let p = HermiteParams::default();
        let vals = [
            srgb_to_linear(0.9),
            srgb_to_linear(0.1),
            srgb_to_linear(0.35),
            srgb_to_linear(0.1),
        ];
        let g = GrayFrame::from_vec(Size::new(4, 1).unwrap(), vals.to_vec()).unwrap();
        let m = GrayImage::from_raw(4, 1, vec![0, 0, 0, 255]).unwrap();
        let o = hermite_darken(&g, Some(&m), &p);
        assert_eq!(o.data()[0], vals[0]);
        assert_eq!(o.data()[1], 0.0);
        assert!(o.data()[2] > 0.0 && o.data()[2] < vals[2]);
        assert_eq!(o.data()[3], vals[3]); // protected
        assert_eq!(hermite_h01(0.5), 0.5);
    }

    /// The 8-bit pass equals the linear one on the frame converted to linear light, bit
    /// for bit (pixels where the matte is 0 are not read): a matte with zeros, ones and
    /// values between, a protected region, the box inside the frame.
    #[test]
    fn srgb8_darkening_equals_the_linear_darkening() {
        let size = Size::new(23, 17).unwrap();
        let bytes: Vec<u8> = (0..size.pixels() * 4)
            .map(|i| (i * 53 % 256) as u8)
            .collect();
        let lin = crate::footage::SourceFrame::Srgb8 {
            size,
            bytes: bytes.clone(),
        }
        .to_linear()
        .into_owned();
        let matte = GrayFrame::from_fn(size, |x, y| match (x + 2 * y) % 5 {
            0 => 0.0,
            1 => 1.0,
            _ => ((x * y) % 7) as f32 / 7.0,
        });
        let mask = GrayImage::from_fn(23, 17, |x, y| {
            image::Luma([if x < 6 && y < 9 { 255 } else { 0 }])
        });
        let area = (2, 3, 20, 15);
        for p in [
            HermiteParams::default(),
            HermiteParams {
                protect_interior: false,
                ..Default::default()
            },
        ] {
            let want = hermite_darken_rgba_in(&lin, &mask, &matte, area, &p);
            let got = hermite_darken_srgb8_in(size, &bytes, &mask, &matte, area, &p);
            let bits = |g: &GrayFrame| g.data().iter().map(|v| v.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&got), bits(&want));
        }
    }

    /// The fused pass equals the luminance, `hermite_darken` and the matte product bit for
    /// bit, on values dense around the shortcuts' bounds and on odd ones.
    #[test]
    fn fused_darkening_equals_the_rule() {
        for p in [
            HermiteParams::default(),
            HermiteParams {
                i_min: 0.0,
                i_max: 1.0,
                protect_interior: true,
            },
            HermiteParams {
                i_min: 0.3,
                i_max: 0.31,
                protect_interior: false,
            },
        ] {
            let mut vals = vec![0.0f32, -0.0, -0.5, 1.0, 2.0, f32::INFINITY, f32::NAN];
            for edge in [p.i_min, p.i_max] {
                let l = srgb_to_linear(edge);
                for k in -400..=400 {
                    vals.push(l * (1.0 + k as f32 * 1e-5));
                    vals.push(l + k as f32 * f32::EPSILON * l);
                }
            }
            vals.extend((0..=1000).map(|i| i as f32 / 1000.0));
            let n = vals.len();
            let size = Size::new(n as u32, 1).unwrap();
            let rgba = RgbaFrame::from_vec(
                size,
                vals.iter()
                    .enumerate()
                    .map(|(i, &v)| [v, v * (1.0 - (i % 3) as f32 * 0.1), v, 1.0])
                    .collect(),
            )
            .unwrap();
            let mask = GrayImage::from_fn(n as u32, 1, |x, _| {
                image::Luma([if x % 7 == 0 { 255 } else { 0 }])
            });
            let matte =
                GrayFrame::from_vec(size, (0..n).map(|i| [0.0, 1.0, 0.5, 0.25][i % 4]).collect())
                    .unwrap();
            let mut want = hermite_darken(&rgba.luminance(), Some(&mask), &p);
            let same = |got: &GrayFrame, want: &GrayFrame| {
                for (i, (a, b)) in got.data().iter().zip(want.data()).enumerate() {
                    assert!(
                        a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                        "pixel {i}: {a} vs {b}"
                    );
                }
            };
            same(&hermite_darken_rgba(&rgba, &mask, None, &p), &want);
            for (g, &m) in want.data_mut().iter_mut().zip(matte.data()) {
                *g *= m;
            }
            same(&hermite_darken_rgba(&rgba, &mask, Some(&matte), &p), &want);
            // Inside a box with the matte 0 outside it: the same where the values are
            // finite and non-negative (everywhere outside the box here).
            let boxed = GrayFrame::from_vec(
                size,
                (0..n)
                    .map(|i| {
                        if (100..n - 50).contains(&i) {
                            matte.data()[i]
                        } else {
                            0.0
                        }
                    })
                    .collect(),
            )
            .unwrap();
            let inside = |i: usize| (100..n - 50).contains(&i);
            let rgba = RgbaFrame::from_vec(
                size,
                rgba.data()
                    .iter()
                    .enumerate()
                    .map(|(i, &px)| {
                        if inside(i) || (px[0].is_finite() && px[0].is_sign_positive()) {
                            px
                        } else {
                            [0.5; 4]
                        }
                    })
                    .collect(),
            )
            .unwrap();
            let mut want = hermite_darken(&rgba.luminance(), Some(&mask), &p);
            for (g, &m) in want.data_mut().iter_mut().zip(boxed.data()) {
                *g *= m;
            }
            let got = hermite_darken_rgba_in(&rgba, &mask, &boxed, (100, 0, n as u32 - 50, 1), &p);
            same(&got, &want);
        }
    }
}
