//! Synthetic HLS colouring.
//!
//! Source: eigenfires-thesis.txt §6.1.2. The result takes its **lightness** from the grey
//! source frame and its **hue and saturation** from a blend colour chosen by the artist:
//! a solid colour, a gradient, or a texture of the same size. The conversion is done in
//! linear light (the thesis works on 8-bit sRGB values; Ignis keeps linear light end to end
//! so that bloom and compositing stay physically additive).

use crate::error::{CoreError, Result};
use crate::frame::{GrayFrame, RgbaFrame};

/// Hue in `[0, 1)`, lightness and saturation in `[0, 1]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hls {
    pub h: f32,
    pub l: f32,
    pub s: f32,
}

/// RGB (`0..=1` each) → HLS, the standard double-hexcone model.
pub fn rgb_to_hls(rgb: [f32; 3]) -> Hls {
    let [r, g, b] = rgb.map(|c| c.clamp(0.0, 1.0));
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    let l = (max + min) / 2.0;
    if max - min < 1e-7 {
        return Hls { h: 0.0, l, s: 0.0 };
    }
    let d = max - min;
    let s = if l <= 0.5 {
        d / (max + min)
    } else {
        d / (2.0 - max - min)
    };
    let h = if max == r {
        ((g - b) / d).rem_euclid(6.0)
    } else if max == g {
        (b - r) / d + 2.0
    } else {
        (r - g) / d + 4.0
    } / 6.0;
    Hls {
        h: h.rem_euclid(1.0),
        l,
        s,
    }
}

/// HLS → RGB (`0..=1` each).
pub fn hls_to_rgb(c: Hls) -> [f32; 3] {
    let Hls { h, l, s } = c;
    if s <= 0.0 {
        return [l, l, l];
    }
    let m2 = if l <= 0.5 {
        l * (1.0 + s)
    } else {
        l + s - l * s
    };
    let m1 = 2.0 * l - m2;
    let v = |hue: f32| {
        let hue = hue.rem_euclid(1.0);
        if hue < 1.0 / 6.0 {
            m1 + (m2 - m1) * hue * 6.0
        } else if hue < 0.5 {
            m2
        } else if hue < 2.0 / 3.0 {
            m1 + (m2 - m1) * (2.0 / 3.0 - hue) * 6.0
        } else {
            m1
        }
    };
    [v(h + 1.0 / 3.0), v(h), v(h - 1.0 / 3.0)]
}

/// Where the hue and saturation come from.
#[derive(Clone, Debug, PartialEq)]
pub enum Tint {
    /// One colour (linear RGB `0..=1`), e.g. orange `[1.0, 0.35, 0.05]`.
    Solid([f32; 3]),
    /// A vertical gradient: `stops[0]` at the bottom of the frame, the last at the top;
    /// fire is usually hotter (yellower) at the base and redder at the tips.
    VerticalGradient(Vec<[f32; 3]>),
    /// A texture of the same size as the source frame.
    Texture(RgbaFrame),
}

/// HLS → RGB for a fixed hue and saturation, as a function of lightness only.
///
/// With h and s fixed, each channel of [`hls_to_rgb`] is linear in l on `[0, ½]` (through
/// 0 at l = 0) and on `[½, 1]` (through 1 at l = 1): m1 and m2 are linear in l on each
/// half, and the hue picks a fixed mix of them. So the channel is exactly the
/// interpolation between its values at l = 0, ½ and 1, which is what this evaluates —
/// a multiply-add per channel instead of the branchy general conversion.
#[derive(Clone, Copy, Debug)]
struct LightnessRamp {
    half: [f32; 3],
}

impl LightnessRamp {
    fn new(tint: [f32; 3]) -> Self {
        let t = rgb_to_hls(tint);
        LightnessRamp {
            half: hls_to_rgb(Hls {
                h: t.h,
                l: 0.5,
                s: t.s,
            }),
        }
    }

    #[inline]
    fn at(&self, l: f32) -> [f32; 4] {
        let l = l.clamp(0.0, 1.0);
        let c = |h: f32| {
            if l <= 0.5 {
                2.0 * l * h
            } else {
                h + (2.0 * l - 1.0) * (1.0 - h)
            }
        };
        [c(self.half[0]), c(self.half[1]), c(self.half[2]), 1.0]
    }
}

/// The colour [`synthetic_colour`] gives one grey value under a solid tint, for callers
/// that colour pixel by pixel inside their own pass (the same values bit for bit).
#[derive(Clone, Copy, Debug)]
pub struct SolidTintRamp(LightnessRamp);

impl SolidTintRamp {
    pub fn new(tint: [f32; 3]) -> Self {
        SolidTintRamp(LightnessRamp::new(tint))
    }
    /// `synthetic_colour`'s pixel for grey value `l` under `Tint::Solid(tint)`.
    #[inline]
    pub fn at(&self, l: f32) -> [f32; 4] {
        self.0.at(l)
    }
}

/// Colours `gray` by HLS transfer (§6.1.2 steps 1–4). Alpha is 1 everywhere; use
/// [`crate::post::alpha_matte`] for a matte. Rows are coloured in parallel.
pub fn synthetic_colour(gray: &GrayFrame, tint: &Tint) -> Result<RgbaFrame> {
    use rayon::prelude::*;
    let (w, h) = (gray.width() as usize, gray.height() as usize);
    // One ramp per row (solid: the same; gradient: by height).
    let row_ramps: Vec<LightnessRamp> = match tint {
        Tint::Solid(c) => vec![LightnessRamp::new(*c); h],
        Tint::VerticalGradient(stops) => {
            if stops.is_empty() {
                return Err(CoreError::bad(
                    "tint",
                    "a gradient needs at least one colour",
                ));
            }
            let n = stops.len();
            (0..h)
                .map(|y| {
                    // bottom row = stop 0
                    let pos = if h > 1 {
                        (h - 1 - y) as f32 / (h - 1) as f32
                    } else {
                        0.0
                    };
                    let x = pos * (n - 1) as f32;
                    let i = (x.floor() as usize).min(n.saturating_sub(2));
                    let f = if n > 1 { x - i as f32 } else { 0.0 };
                    let (a, b) = (stops[i], stops[(i + 1).min(n - 1)]);
                    LightnessRamp::new([0, 1, 2].map(|k| a[k] + (b[k] - a[k]) * f))
                })
                .collect()
        }
        Tint::Texture(tex) => {
            if tex.size() != gray.size() {
                return Err(CoreError::SizeMismatch(format!(
                    "tint texture is {} but the frame is {}; resize the texture",
                    tex.size(),
                    gray.size()
                )));
            }
            Vec::new()
        }
    };
    let mut out = vec![[0.0f32; 4]; w * h];
    out.par_chunks_mut(w.max(1))
        .enumerate()
        .for_each(|(y, row)| {
            let g = &gray.data()[y * w..(y + 1) * w];
            match tint {
                Tint::Texture(tex) => {
                    let t = &tex.data()[y * w..(y + 1) * w];
                    for ((o, &v), p) in row.iter_mut().zip(g).zip(t) {
                        *o = LightnessRamp::new([p[0], p[1], p[2]]).at(v);
                    }
                }
                _ => {
                    let ramp = row_ramps[y];
                    for (o, &v) in row.iter_mut().zip(g) {
                        *o = ramp.at(v);
                    }
                }
            }
        });
    RgbaFrame::from_vec(gray.size(), out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Size;

    #[test]
    fn hls_roundtrip() {
        for &c in &[
            [1.0, 0.35, 0.05],
            [0.2, 0.4, 0.9],
            [0.5, 0.5, 0.5],
            [0.0, 1.0, 0.0],
            [0.9, 0.1, 0.7],
        ] {
            let back = hls_to_rgb(rgb_to_hls(c));
            for k in 0..3 {
                assert!((back[k] - c[k]).abs() < 1e-5, "{c:?} -> {back:?}");
            }
        }
    }

    #[test]
    fn ramp_equals_the_general_conversion() {
        for &c in &[
            [1.0, 0.35, 0.05],
            [0.2, 0.4, 0.9],
            [0.5, 0.5, 0.5],
            [0.0, 1.0, 0.0],
            [0.9, 0.1, 0.7],
            [1.0, 0.42, 0.08],
        ] {
            let t = rgb_to_hls(c);
            let ramp = LightnessRamp::new(c);
            for i in 0..=200 {
                let l = i as f32 / 200.0;
                let want = hls_to_rgb(Hls { h: t.h, l, s: t.s });
                let got = ramp.at(l);
                for k in 0..3 {
                    assert!(
                        (got[k] - want[k]).abs() < 2e-6,
                        "{c:?} at l = {l}: {got:?} vs {want:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn lightness_comes_from_gray_hue_from_tint() {
        let s = Size::new(3, 1).unwrap();
        let g = GrayFrame::from_vec(s, vec![0.0, 0.5, 1.0]).unwrap();
        let out = synthetic_colour(&g, &Tint::Solid([1.0, 0.5, 0.0])).unwrap();
        assert_eq!(&out.data()[0][..3], &[0.0, 0.0, 0.0]);
        assert_eq!(&out.data()[2][..3], &[1.0, 1.0, 1.0]);
        let mid = hls_to_rgb(rgb_to_hls([1.0, 0.5, 0.0]));
        for (got, want) in out.data()[1].iter().zip(mid) {
            assert!((got - want).abs() < 1e-5);
        }
        let bad = RgbaFrame::new(Size::new(2, 2).unwrap());
        assert!(synthetic_colour(&g, &Tint::Texture(bad)).is_err());
    }
}
