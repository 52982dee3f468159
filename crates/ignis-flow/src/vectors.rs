//! Flow for motion-vector sheets: the vectors an engine's flipbook blend drags pixels
//! along, kept only where they are reliable.
//!
//! An engine's motion-vector blend (Unity VFX Graph's "Flipbook Motion Blend", Unreal's and
//! SideFX's material functions) moves both key frames along the stored vectors and then
//! cross-fades them; where a vector is wrong the blend shows a smeared or torn frame that
//! is worse than the plain cross-fade. Fire changes by flicker and growth as much as by
//! motion, so a raw flow is often wrong. [`motion_vector_pair`] scales each vector by two
//! confidences in `[0, 1]`:
//!
//! - **consistency**: `exp(-(|F(x) + B(x + F(x))| / σ)²)` — the backward flow must bring
//!   the pixel back (fails at occlusions, in textureless areas and in flicker);
//! - **explained change**: over a `(2r+1)²` window, the mean absolute difference between
//!   the frames (sRGB-encoded luminance over black) must drop by at least a fraction `g`
//!   when the second frame is sampled along the flow: weight
//!   `clamp((E₀ − E_F) / (g · E₀), 0, 1)`. Where moving the pixels does not explain the
//!   change (intensity change is not motion), the vector goes and the engine's blend falls
//!   back to the cross-fade.

use crate::error::{FlowError, Result};
use crate::{flow_pair, luma, FlowField, FlowParams};
use ignis_core::{GrayFrame, RgbaFrame};
use rayon::prelude::*;

/// Parameters of [`motion_vector_pair`]; the defaults were chosen on `ignis bench export`.
#[derive(Clone, Debug, PartialEq)]
pub struct VectorParams {
    /// The optical flow.
    pub flow: FlowParams,
    /// Forward–backward tolerance σ in pixels (at the frames' size). Range (0, 1e4];
    /// default 2.
    pub consistency_px: f32,
    /// Fraction `g` of the frame difference a vector must explain for full weight. Range
    /// (0, 1]; default 0.25.
    pub explained: f32,
    /// Window half side `r` for the explained change, in pixels. Range 0..=32; default 3.
    pub window: u32,
}

impl Default for VectorParams {
    fn default() -> Self {
        VectorParams {
            flow: FlowParams::default(),
            consistency_px: 2.0,
            explained: 0.25,
            window: 3,
        }
    }
}

impl VectorParams {
    /// Checks every field against its documented range.
    pub fn validate(&self) -> Result<()> {
        self.flow.validate()?;
        if !(self.consistency_px > 0.0 && self.consistency_px <= 1e4) {
            return Err(FlowError::bad(
                "consistency_px",
                format!("{} is outside (0, 1e4]; default 2", self.consistency_px),
            ));
        }
        if !(self.explained > 0.0 && self.explained <= 1.0) {
            return Err(FlowError::bad(
                "explained",
                format!("{} is outside (0, 1]; default 0.25", self.explained),
            ));
        }
        if self.window > 32 {
            return Err(FlowError::bad(
                "window",
                format!("{} is outside 0..=32; default 3", self.window),
            ));
        }
        Ok(())
    }
}

/// The flows `(a→b, b→a)` at the frames' size (pixels, `a(x) ≈ b(x + F(x))`), each vector
/// scaled by its consistency and explained-change confidences (see the module docs).
pub fn motion_vector_pair(
    a: &RgbaFrame,
    b: &RgbaFrame,
    p: &VectorParams,
) -> Result<(FlowField, FlowField)> {
    p.validate()?;
    let (la, lb) = (luma(a), luma(b));
    let (f, g) = flow_pair(&la, &lb, &p.flow)?;
    let (pa, pb) = rayon::join(|| perceptual(&la), || perceptual(&lb));
    let (wf, wg) = rayon::join(
        || reliable(&f, &g, &pa, &pb, p),
        || reliable(&g, &f, &pb, &pa, p),
    );
    Ok((wf, wg))
}

/// sRGB-encoded luminance (the space the explained change is judged in).
fn perceptual(l: &GrayFrame) -> GrayFrame {
    let d = l
        .data()
        .par_iter()
        .map(|&v| ignis_core::palette::linear_to_srgb(v))
        .collect();
    GrayFrame::from_vec(l.size(), d).expect("same size")
}

/// `f` (from `pa` to `pb`) weighted by both confidences; `g` is the reverse flow.
fn reliable(
    f: &FlowField,
    g: &FlowField,
    pa: &GrayFrame,
    pb: &GrayFrame,
    p: &VectorParams,
) -> FlowField {
    let size = f.size();
    let (w, h) = (size.width as usize, size.height as usize);
    let (a, b) = (pa.data(), pb.data());
    let inv_s2 = 1.0 / (p.consistency_px * p.consistency_px);
    // Per pixel: |a − b| and |a − b(x + F)|.
    let mut e0 = vec![0.0f32; w * h];
    let mut e1 = vec![0.0f32; w * h];
    e0.par_chunks_mut(w)
        .zip(e1.par_chunks_mut(w))
        .enumerate()
        .for_each(|(y, (r0, r1))| {
            let row = y * w;
            let fr = &f.data()[row..row + w];
            for (x, (([dx, dy], o0), o1)) in fr.iter().zip(r0).zip(r1).enumerate() {
                let i = row + x;
                *o0 = (a[i] - b[i]).abs();
                *o1 = (a[i] - sample(b, w, h, x as f32 + dx, y as f32 + dy)).abs();
            }
        });
    let r = p.window as usize;
    let (e0, e1) = rayon::join(|| box_sum(&e0, w, h, r), || box_sum(&e1, w, h, r));
    // The consistency weight (a read of the reverse flow and an `exp`) only where the
    // explained change leaves some weight: elsewhere the vector is 0 either way.
    let mut data = vec![[0.0f32; 2]; w * h];
    data.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
        let row = y * w;
        for (x, o) in out.iter_mut().enumerate() {
            let i = row + x;
            let [dx, dy] = f.data()[i];
            let explained = if e0[i] > 0.0 {
                ((e0[i] - e1[i]) / (p.explained * e0[i])).clamp(0.0, 1.0)
            } else {
                0.0 // identical neighbourhoods: nothing moved that shows
            };
            let k = if explained > 0.0 {
                let [bx, by] = g.at(x as f32 + dx, y as f32 + dy);
                let cons = (-((dx + bx).powi(2) + (dy + by).powi(2)) * inv_s2).exp();
                cons * explained
            } else {
                0.0
            };
            *o = [dx * k, dy * k];
        }
    });
    FlowField::from_parts(size, data)
}

/// Bilinear sample at `(x, y)` (pixel centres at integers), edge-clamped; non-finite
/// positions read the edge.
#[inline]
fn sample(img: &[f32], w: usize, h: usize, x: f32, y: f32) -> f32 {
    let x = if x.is_finite() {
        x.clamp(0.0, (w - 1) as f32)
    } else {
        0.0
    };
    let y = if y.is_finite() {
        y.clamp(0.0, (h - 1) as f32)
    } else {
        0.0
    };
    let (x0, y0) = (x.floor(), y.floor());
    let (ax, ay) = (x - x0, y - y0);
    let (x0, y0) = (x0 as usize, y0 as usize);
    let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
    let top = img[y0 * w + x0] + (img[y0 * w + x1] - img[y0 * w + x0]) * ax;
    let bot = img[y1 * w + x0] + (img[y1 * w + x1] - img[y1 * w + x0]) * ax;
    top + (bot - top) * ay
}

/// Sum over the `(2r+1)²` window around each pixel, clipped at the edges (prefix sums in
/// f64, so the result does not depend on the thread count).
fn box_sum(c: &[f32], w: usize, h: usize, r: usize) -> Vec<f32> {
    if r == 0 || c.is_empty() {
        return c.to_vec();
    }
    let mut rows = vec![0.0f64; w * h];
    rows.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
        let src = &c[y * w..(y + 1) * w];
        let mut pre = vec![0.0f64; w + 1];
        for x in 0..w {
            pre[x + 1] = pre[x] + src[x] as f64;
        }
        for (x, o) in out.iter_mut().enumerate() {
            *o = pre[(x + r + 1).min(w)] - pre[x.saturating_sub(r)];
        }
    });
    let mut out = vec![0.0f32; w * h];
    out.par_chunks_mut(w).enumerate().for_each(|(y, o)| {
        let mut acc = vec![0.0f64; w];
        for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
            for (a, v) in acc.iter_mut().zip(&rows[yy * w..(yy + 1) * w]) {
                *a += v;
            }
        }
        for (ov, a) in o.iter_mut().zip(&acc) {
            *ov = *a as f32;
        }
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use ignis_core::Size;

    fn rgba(g: &GrayFrame) -> RgbaFrame {
        g.to_rgba()
    }

    /// A translated texture keeps its vectors; a flickering one (same picture, brighter)
    /// loses them, since no motion explains a change of brightness.
    #[test]
    fn motion_kept_flicker_dropped() {
        let s = Size::new(96, 96).unwrap();
        let a = crate::bench::texture(s, 5, [0.0, 0.0], 1.0);
        let b = crate::bench::texture(s, 5, [2.0, -1.0], 1.0);
        let p = VectorParams::default();
        let (f, g) = motion_vector_pair(&rgba(&a), &rgba(&b), &p).unwrap();
        let [mx, my] = f.mean();
        assert!(
            (mx - 2.0).abs() < 0.3 && (my + 1.0).abs() < 0.3,
            "{mx} {my}"
        );
        let [gx, gy] = g.mean();
        assert!(
            (gx + 2.0).abs() < 0.3 && (gy - 1.0).abs() < 0.3,
            "{gx} {gy}"
        );
        let bright = GrayFrame::from_fn(s, |x, y| a.get(x, y) * 1.3);
        let (f, _) = motion_vector_pair(&rgba(&a), &rgba(&bright), &p).unwrap();
        let most = f
            .data()
            .iter()
            .map(|v| v[0].abs().max(v[1].abs()))
            .fold(0f32, f32::max);
        assert!(most < 0.05, "flicker kept a vector of {most} px");
    }

    #[test]
    fn box_sum_matches_brute_force() {
        let (w, h, r) = (7, 5, 2);
        let c: Vec<f32> = (0..w * h).map(|i| ((i * 13) % 7) as f32).collect();
        let s = box_sum(&c, w, h, r);
        for y in 0..h {
            for x in 0..w {
                let mut want = 0.0;
                for yy in y.saturating_sub(r)..(y + r + 1).min(h) {
                    for xx in x.saturating_sub(r)..(x + r + 1).min(w) {
                        want += c[yy * w + xx];
                    }
                }
                assert!((s[y * w + x] - want).abs() < 1e-4);
            }
        }
    }

    #[test]
    fn bad_params_are_refused() {
        for p in [
            VectorParams {
                consistency_px: 0.0,
                ..Default::default()
            },
            VectorParams {
                explained: f32::NAN,
                ..Default::default()
            },
            VectorParams {
                window: 99,
                ..Default::default()
            },
        ] {
            assert!(matches!(p.validate(), Err(FlowError::BadParameter { .. })));
        }
    }
}
