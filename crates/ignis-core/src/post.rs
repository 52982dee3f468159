//! Post effects: Gaussian blur, bloom and the alpha matte.
//!
//! Source: eigenfires-thesis.txt §6.2. Bloom: copy the source to the destination, add
//! `strength ×` a large-radius Gaussian blur of the source, repeat with smaller radii
//! ("bloom passes"), then lighten-blend with the source (per-pixel max). The matte is the
//! sum of that bloom image and the source, clamped to `0..=1`.
//!
//! The separable Gaussian is written here rather than taken from `imageproc` because it
//! works in place on Ignis's linear `f32` frames (no conversion copies), clamps at the
//! edges, and parallelises over rows with `rayon`; it is about fifty lines.

use crate::error::{CoreError, Result};
use crate::frame::{GrayFrame, RgbaFrame};
use rayon::prelude::*;

/// Normalised 1-D Gaussian kernel for standard deviation `sigma` (radius 3σ).
pub fn gaussian_kernel(sigma: f32) -> Vec<f32> {
    if sigma <= 0.0 {
        return vec![1.0];
    }
    let r = (3.0 * sigma).ceil() as i32;
    let mut k: Vec<f32> = (-r..=r)
        .map(|i| (-(i * i) as f32 / (2.0 * sigma * sigma)).exp())
        .collect();
    let s: f32 = k.iter().sum();
    k.iter_mut().for_each(|v| *v /= s);
    k
}

/// Gaussian blur of a grey frame with standard deviation `sigma` pixels (edges clamped).
pub fn gaussian_blur(src: &GrayFrame, sigma: f32) -> GrayFrame {
    let k = gaussian_kernel(sigma);
    if k.len() == 1 {
        return src.clone();
    }
    let r = (k.len() / 2) as isize;
    let (w, h) = (src.width() as usize, src.height() as usize);
    let mut tmp = vec![0.0f32; w * h];
    // horizontal
    tmp.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        let s = &src.data()[y * w..(y + 1) * w];
        for (x, o) in row.iter_mut().enumerate() {
            let mut acc = 0.0;
            for (j, &kv) in k.iter().enumerate() {
                let xx = (x as isize + j as isize - r).clamp(0, w as isize - 1) as usize;
                acc += kv * s[xx];
            }
            *o = acc;
        }
    });
    // vertical, row by row so the inner loop runs along contiguous memory
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (j, &kv) in k.iter().enumerate() {
            let yy = (y as isize + j as isize - r).clamp(0, h as isize - 1) as usize;
            let s = &tmp[yy * w..(yy + 1) * w];
            for (o, &v) in row.iter_mut().zip(s) {
                *o += kv * v;
            }
        }
    });
    GrayFrame::from_vec(src.size(), out).expect("same size")
}

/// Bloom settings (§6.2).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(default)]
pub struct BloomParams {
    /// Number of blur passes ("bloom passes"). Default 3; 0 disables bloom.
    pub passes: u32,
    /// Gaussian σ of the first (largest) pass, in pixels. Default 24.
    pub radius: f32,
    /// Each further pass uses the previous σ times this factor (0 < f < 1). Default 0.5.
    pub radius_falloff: f32,
    /// Scale of each blurred image before it is added (the thesis's 0.4). Default 0.4.
    pub strength: f32,
}

impl Default for BloomParams {
    fn default() -> Self {
        BloomParams {
            passes: 3,
            radius: 24.0,
            radius_falloff: 0.5,
            strength: 0.4,
        }
    }
}

impl BloomParams {
    /// Checks the ranges of every field.
    pub fn validate(&self) -> Result<()> {
        if self.passes > 16 {
            return Err(CoreError::bad(
                "bloom.passes",
                format!("{} passes; use 0 to 16", self.passes),
            ));
        }
        if !(self.radius >= 0.0 && self.radius <= 512.0) {
            return Err(CoreError::bad(
                "bloom.radius",
                format!("{} px; use 0 to 512", self.radius),
            ));
        }
        if !(self.radius_falloff > 0.0 && self.radius_falloff <= 1.0) {
            return Err(CoreError::bad("bloom.radius_falloff", "must be in (0, 1]"));
        }
        if !(self.strength >= 0.0 && self.strength <= 4.0) {
            return Err(CoreError::bad("bloom.strength", "must be in 0..=4"));
        }
        Ok(())
    }
}

/// The bloom of a grey frame: steps 1–5 of §6.2 (colourise it afterwards with
/// [`crate::colour::synthetic_colour`] or a palette — step 6).
pub fn bloom(src: &GrayFrame, p: &BloomParams) -> Result<GrayFrame> {
    p.validate()?;
    let mut dest = src.clone();
    let mut sigma = p.radius;
    for _ in 0..p.passes {
        let blurred = gaussian_blur(src, sigma);
        for (d, &b) in dest.data_mut().iter_mut().zip(blurred.data()) {
            *d += p.strength * b;
        }
        sigma *= p.radius_falloff;
    }
    // lighten blending with the source
    for (d, &s) in dest.data_mut().iter_mut().zip(src.data()) {
        *d = d.max(s);
    }
    Ok(dest)
}

/// Bloom on each channel of an RGBA frame (alpha kept), for colour sources such as the
/// volume renderer's HDR output.
pub fn bloom_rgba(src: &RgbaFrame, p: &BloomParams) -> Result<RgbaFrame> {
    p.validate()?;
    let size = src.size();
    let mut out = src.clone();
    for c in 0..3 {
        let ch = GrayFrame::from_vec(size, src.data().iter().map(|px| px[c]).collect())?;
        let b = bloom(&ch, p)?;
        for (o, &v) in out.data_mut().iter_mut().zip(b.data()) {
            o[c] = v;
        }
    }
    Ok(out)
}

/// The alpha matte of §6.2: `clamp(bloom + source, 0, 1)`.
pub fn alpha_matte(src: &GrayFrame, bloomed: &GrayFrame) -> Result<GrayFrame> {
    if src.size() != bloomed.size() {
        return Err(CoreError::SizeMismatch(format!(
            "source {} vs bloom {}",
            src.size(),
            bloomed.size()
        )));
    }
    let data = src
        .data()
        .iter()
        .zip(bloomed.data())
        .map(|(&a, &b)| (a + b).clamp(0.0, 1.0))
        .collect();
    GrayFrame::from_vec(src.size(), data)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Size;

    fn spot() -> GrayFrame {
        GrayFrame::from_fn(Size::new(41, 31).unwrap(), |x, y| {
            if x == 20 && y == 15 {
                1.0
            } else {
                0.0
            }
        })
    }

    #[test]
    fn blur_preserves_mass_and_is_symmetric() {
        let b = gaussian_blur(&spot(), 2.0);
        let sum: f32 = b.data().iter().sum();
        assert!((sum - 1.0).abs() < 1e-4, "{sum}");
        assert!((b.get(18, 15) - b.get(22, 15)).abs() < 1e-7);
        assert!((b.get(20, 13) - b.get(20, 17)).abs() < 1e-7);
        assert!(b.get(20, 15) > b.get(21, 15));
    }

    #[test]
    fn bloom_lightens_and_spreads() {
        let s = spot();
        let b = bloom(
            &s,
            &BloomParams {
                radius: 3.0,
                ..Default::default()
            },
        )
        .unwrap();
        for (o, i) in b.data().iter().zip(s.data()) {
            assert!(o >= i);
        }
        assert!(b.get(23, 15) > 0.0);
        let none = bloom(
            &s,
            &BloomParams {
                passes: 0,
                ..Default::default()
            },
        )
        .unwrap();
        assert_eq!(none, s);
        assert!(bloom(
            &s,
            &BloomParams {
                radius_falloff: 0.0,
                ..Default::default()
            }
        )
        .is_err());
        let m = alpha_matte(&s, &b).unwrap();
        assert!(m.data().iter().all(|&v| (0.0..=1.0).contains(&v)));
        assert_eq!(m.get(20, 15), 1.0);
    }
}
