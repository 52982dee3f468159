//! Palettes (transfer functions): intensity in `0..=1` → linear RGBA colour.
//!
//! Source: mcnally-fire-special-fx.txt ("a ramping palette proceeding from black at 0 to
//! some desired hot colour at 255"); the same ramps colour learned flames (stich-magnor §5)
//! and any grey output. A palette is a table of [`Palette::LEN`] entries sampled with linear
//! interpolation. Colours are **linear light**, alpha is **straight**: the built-in ramps
//! fade alpha in from 0 at black so that a flipbook composites cleanly over any background.

use crate::error::{CoreError, Result};
use crate::frame::{GrayFrame, RgbaFrame};

/// An intensity → colour ramp.
#[derive(Clone, Debug, PartialEq)]
pub struct Palette {
    name: String,
    table: Vec<[f32; 4]>,
}

/// sRGB-encoded 8-bit component → linear light.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// [`srgb_to_linear`] of every 8-bit code (`k / 255`): the one decoding table for 8-bit
/// sRGB footage, built once.
pub fn srgb8_to_linear_table() -> &'static [f32; 256] {
    static T: std::sync::OnceLock<[f32; 256]> = std::sync::OnceLock::new();
    T.get_or_init(|| std::array::from_fn(|k| srgb_to_linear(k as f32 / 255.0)))
}

/// One 8-bit sRGB pixel (straight alpha, `[r, g, b, a]` bytes) as the readers make it
/// linear: colour through [`srgb8_to_linear_table`], alpha `a / 255`.
#[inline]
pub fn srgba8_to_linear(table: &[f32; 256], p: &[u8]) -> [f32; 4] {
    [
        table[p[0] as usize],
        table[p[1] as usize],
        table[p[2] as usize],
        p[3] as f32 / 255.0,
    ]
}

/// Linear light → sRGB-encoded value in `0..=1` (clamped).
pub fn linear_to_srgb(c: f32) -> f32 {
    let c = c.clamp(0.0, 1.0);
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }
}

/// The names of the built-in presets.
pub const PRESETS: &[&str] = &["classic", "candle", "blue-gas", "green", "grey"];

impl Palette {
    /// Number of table entries.
    pub const LEN: usize = 256;

    /// A palette through `stops` (position in `0..=1`, sRGB colour as `0..=255` bytes),
    /// interpolated in linear light, alpha ramping in over the first `alpha_ramp` of the range.
    pub fn from_stops(name: &str, stops: &[(f32, [u8; 3])], alpha_ramp: f32) -> Result<Palette> {
        if stops.len() < 2 {
            return Err(CoreError::bad("palette", "needs at least two colour stops"));
        }
        if stops.windows(2).any(|w| w[1].0 < w[0].0) {
            return Err(CoreError::bad("palette", "stop positions must increase"));
        }
        let lin = |c: [u8; 3]| c.map(|v| srgb_to_linear(v as f32 / 255.0));
        let mut table = Vec::with_capacity(Self::LEN);
        for i in 0..Self::LEN {
            let t = i as f32 / (Self::LEN - 1) as f32;
            let k = stops
                .iter()
                .position(|s| s.0 >= t)
                .unwrap_or(stops.len() - 1)
                .max(1);
            let (p0, c0) = stops[k - 1];
            let (p1, c1) = stops[k];
            let f = if p1 > p0 {
                ((t - p0) / (p1 - p0)).clamp(0.0, 1.0)
            } else {
                1.0
            };
            let (a, b) = (lin(c0), lin(c1));
            let a_alpha = if alpha_ramp > 0.0 {
                (t / alpha_ramp).min(1.0)
            } else {
                1.0
            };
            table.push([
                a[0] + (b[0] - a[0]) * f,
                a[1] + (b[1] - a[1]) * f,
                a[2] + (b[2] - a[2]) * f,
                a_alpha,
            ]);
        }
        Ok(Palette {
            name: name.to_string(),
            table,
        })
    }

    /// A palette from a strip of linear RGBA pixels (e.g. one row of a gradient PNG,
    /// left = cold, right = hot), resampled to [`Palette::LEN`] entries.
    pub fn from_strip(name: &str, strip: &[[f32; 4]]) -> Result<Palette> {
        if strip.len() < 2 {
            return Err(CoreError::bad(
                "palette",
                format!(
                    "a gradient strip needs at least 2 pixels, got {}",
                    strip.len()
                ),
            ));
        }
        let n = strip.len() - 1;
        let table = (0..Self::LEN)
            .map(|i| {
                let x = i as f32 / (Self::LEN - 1) as f32 * n as f32;
                let j = (x.floor() as usize).min(n - 1);
                let f = x - j as f32;
                let (a, b) = (strip[j], strip[j + 1]);
                [0, 1, 2, 3].map(|c| a[c] + (b[c] - a[c]) * f)
            })
            .collect();
        Ok(Palette {
            name: name.to_string(),
            table,
        })
    }

    /// A built-in preset by name: `classic`, `candle`, `blue-gas`, `green`, `grey`.
    pub fn preset(name: &str) -> Result<Palette> {
        let stops: &[(f32, [u8; 3])] = match name {
            "classic" => &[
                (0.0, [0, 0, 0]),
                (0.25, [120, 10, 0]),
                (0.5, [230, 70, 0]),
                (0.75, [255, 190, 30]),
                (1.0, [255, 255, 230]),
            ],
            "candle" => &[
                (0.0, [0, 0, 0]),
                (0.2, [90, 20, 0]),
                (0.45, [220, 110, 20]),
                (0.75, [255, 210, 120]),
                (1.0, [255, 250, 235]),
            ],
            "blue-gas" => &[
                (0.0, [0, 0, 0]),
                (0.3, [10, 20, 120]),
                (0.6, [40, 110, 255]),
                (0.85, [150, 210, 255]),
                (1.0, [240, 250, 255]),
            ],
            "green" => &[
                (0.0, [0, 0, 0]),
                (0.3, [0, 80, 10]),
                (0.6, [40, 200, 30]),
                (0.85, [170, 255, 120]),
                (1.0, [240, 255, 230]),
            ],
            "grey" => &[(0.0, [0, 0, 0]), (1.0, [255, 255, 255])],
            other => {
                return Err(CoreError::bad(
                    "palette",
                    format!(
                        "unknown palette `{other}`; choose one of {} or give a gradient PNG",
                        PRESETS.join(", ")
                    ),
                ))
            }
        };
        let ramp = if name == "grey" { 0.0 } else { 0.35 };
        Palette::from_stops(name, stops, ramp)
    }

    pub fn name(&self) -> &str {
        &self.name
    }

    /// The table of [`Palette::LEN`] linear RGBA entries.
    pub fn table(&self) -> &[[f32; 4]] {
        &self.table
    }

    /// Colour of intensity `v` (clamped to `0..=1`), linearly interpolated.
    #[inline]
    pub fn sample(&self, v: f32) -> [f32; 4] {
        let x = v.clamp(0.0, 1.0) * (Self::LEN - 1) as f32;
        let i = (x as usize).min(Self::LEN - 2);
        let f = x - i as f32;
        let (a, b) = (self.table[i], self.table[i + 1]);
        [
            a[0] + (b[0] - a[0]) * f,
            a[1] + (b[1] - a[1]) * f,
            a[2] + (b[2] - a[2]) * f,
            a[3] + (b[3] - a[3]) * f,
        ]
    }

    /// Colours a whole grey frame.
    pub fn apply(&self, gray: &GrayFrame) -> RgbaFrame {
        let data = gray.data().iter().map(|&v| self.sample(v)).collect();
        RgbaFrame::from_vec(gray.size(), data).expect("same size")
    }

    /// Colours an 8-bit index buffer (the classic fire's native format) directly by table
    /// entry, no interpolation.
    pub fn apply_indexed(&self, size: crate::Size, idx: &[u8]) -> Result<RgbaFrame> {
        let data = idx.iter().map(|&i| self.table[i as usize]).collect();
        RgbaFrame::from_vec(size, data)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn presets_ramp_from_black_to_hot() {
        for name in PRESETS {
            let p = Palette::preset(name).unwrap();
            assert_eq!(p.table().len(), Palette::LEN);
            let first = p.sample(0.0);
            assert!(first[0] + first[1] + first[2] < 1e-6, "{name} starts black");
            let last = p.sample(1.0);
            assert!(last[0] + last[1] + last[2] > 2.0, "{name} ends hot");
            // luminance never decreases along the ramp
            let lum = |c: [f32; 4]| 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
            for w in p.table().windows(2) {
                assert!(lum(w[1]) >= lum(w[0]) - 1e-6, "{name} monotone");
            }
        }
        assert!(Palette::preset("plaid").is_err());
    }

    #[test]
    fn strip_resamples_endpoints() {
        let p = Palette::from_strip("s", &[[0.0, 0.0, 0.0, 1.0], [1.0, 0.5, 0.0, 1.0]]).unwrap();
        assert_eq!(p.sample(1.0), [1.0, 0.5, 0.0, 1.0]);
        let mid = p.sample(0.5);
        assert!((mid[0] - 0.5).abs() < 1e-3);
        assert!(Palette::from_strip("s", &[[0.0; 4]]).is_err());
    }

    #[test]
    fn srgb_roundtrip() {
        for i in 0..=255 {
            let c = i as f32 / 255.0;
            assert!((linear_to_srgb(srgb_to_linear(c)) - c).abs() < 1e-5);
        }
    }
}
