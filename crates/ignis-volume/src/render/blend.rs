//! How a pixel's samples combine (§4.1, Figure 11): additive, cartoon and tint.

use super::tile::Scratch;
use serde::{Deserialize, Serialize};

/// How samples are combined (§4.1, Figure 11).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Blend {
    /// Emissive: every sample adds `rgb · a`. The paper's default.
    #[default]
    Additive,
    /// Opaque, hand-drawn look: the nearest sample with `a ≥ 0.5` gives the pixel's colour.
    Cartoon,
    /// Additive with the profile's colour replaced by this linear RGB times its luminance.
    Tint([f32; 3]),
}

/// Adds one fire's shaded samples (`scratch.pix`, `.slice`, `.col`) into the tile's pixels
/// `acc`, each weighted by `gain` (intensity × slice spacing). `best_k`: per pixel, the
/// slice of its nearest opaque sample so far (the cartoon blend; `i64::MAX` for none).
#[inline(always)]
pub(super) fn blend_samples(
    blend: Blend,
    gain: f32,
    scratch: &Scratch,
    acc: &mut [[f32; 4]],
    best_k: &mut [i64],
) {
    for s in 0..scratch.pix.len() {
        let p = scratch.pix[s] as usize;
        let c = scratch.col[s];
        let a = &mut acc[p];
        match blend {
            Blend::Additive => {
                let e = gain * c[3];
                *a = [a[0] + c[0] * e, a[1] + c[1] * e, a[2] + c[2] * e, a[3] + e];
            }
            Blend::Tint(tc) => {
                let lum = 0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2];
                let e = gain * c[3] * lum;
                *a = [
                    a[0] + tc[0] * e,
                    a[1] + tc[1] * e,
                    a[2] + tc[2] * e,
                    a[3] + gain * c[3],
                ];
            }
            Blend::Cartoon => {
                // the nearest opaque sample along the ray, over this fire and the earlier
                // ones (a pixel has at most one sample per slice and fire; the march
                // already dropped samples behind an earlier fire's hit)
                if c[3] >= 0.5 && scratch.slice[s] < best_k[p] {
                    best_k[p] = scratch.slice[s];
                    *a = [c[0], c[1], c[2], 1.0];
                }
            }
        }
    }
}
