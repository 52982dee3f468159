//! Blends of two fire frames that stay on the fire's own colours (the closings of `ignis
//! loop`: crossfades and the blend of a morph's two warped frames).
//!
//! A flame's colour is close to a function of its brightness: dim parts are deep red, bright
//! ones orange, the brightest yellow-white (the ramps McNally's palettes and the Eigenfires
//! colouring draw, and what a black body does as it cools). A plain blend in linear light
//! leaves that ramp: bright yellow blended with the dark around a flame is a *dim yellow*,
//! which no flame shows and which reads as olive or green — the tint of every crossfade of
//! fire where a tongue of one frame meets the background of the other. A fading flame looks
//! like fire when it cools instead: its colour moves down the ramp as it dims.
//!
//! So each pixel's light `p` (premultiplied linear RGB) is split into its luminance
//! `Y = 0.2126 R + 0.7152 G + 0.0722 B` and its chromaticity's offset from the ramp,
//! `d = p / Y − ramp(Y)`; a blend `w` of the way from `a` to `b` keeps the plain blend's
//! luminance `Yo = (1 − w)·Ya + w·Yb` and alpha, blends the offsets by each side's share of
//! that light, and takes its colour from the ramp at the blended brightness:
//! `o = Yo·(ramp(Yo) + sa·da + sb·db)`, `sa = (1 − w)·Ya / Yo`, `sb = w·Yb / Yo`. A pixel
//! whose two sides are on the ramp stays on it; the offsets (a candle's blue base, grey
//! smoke, a lit wall) are carried across as they are; at `w = 0` and `1` the pixel is `a`
//! and `b`; the luminance is the plain blend's exactly (`Y(ramp) = 1`, `Y(d) = 0`), until a
//! channel that would go negative is clamped at 0.
//!
//! The ramp is measured on the two frames being blended: over [`RAMP_BINS`] bins of log
//! luminance from [`Y_FLOOR`] to the brightest pixel, each bin with enough light gives a
//! node at its pixels' light-weighted mean log luminance with their light-weighted mean
//! chromaticity `Σp / ΣY` (so `Y(ramp) = 1` everywhere), and the ramp is linear in log
//! luminance between nodes. Pixels darker than [`Y_FLOOR`] have no measurable colour:
//! offset 0.

use crate::frame::{RgbaFrame, LUMA};

/// Bins of log luminance the ramp is measured in.
pub const RAMP_BINS: usize = 32;

/// Luminance below which a pixel's colour is not measured (black, or noise in it).
pub const Y_FLOOR: f32 = 1e-4;

/// Pixels of a frame the ramp is measured on, at most (about: every `n / SAMPLES`-th).
const SAMPLES: usize = 1 << 16;

/// A bin needs this much light (`ΣY`, in pixels of luminance 1) to be measured.
const BIN_LIGHT: f64 = 0.05;

fn luma(p: [f32; 3]) -> f32 {
    LUMA[0] * p[0] + LUMA[1] * p[1] + LUMA[2] * p[2]
}

/// The colour ramp of some frames: chromaticity (linear RGB over luminance) as a function
/// of log luminance, one node per measured bin.
#[derive(Clone, Debug, PartialEq)]
pub struct Ramp {
    /// The ramp looked up by a luminance's top 16 bits (sign, exponent and 7 bits of
    /// mantissa: steps of at most 0.8 % in luminance), from [`Y_FLOOR`]'s up to the
    /// brightest pixel's; each entry the ramp at the middle of its step. No logarithm per
    /// pixel.
    table: Vec<[f32; 3]>,
}

/// The ramp through `nodes` (log luminance rising, chromaticity) at luminance `y`: linear
/// in `ln y` between the nodes around it, the end node's beyond the ends.
fn between_nodes(n: &[(f32, [f32; 3])], y: f32) -> [f32; 3] {
    let ly = y.max(Y_FLOOR).ln();
    let k = n.partition_point(|&(x, _)| x < ly);
    if k == 0 {
        return n[0].1;
    }
    if k == n.len() {
        return n[k - 1].1;
    }
    let ((x0, a), (x1, b)) = (n[k - 1], n[k]);
    let f = if x1 > x0 { (ly - x0) / (x1 - x0) } else { 0.0 };
    std::array::from_fn(|c| a[c] + f * (b[c] - a[c]))
}

/// A luminance's key into [`Ramp::table`] (before the floor's is subtracted).
fn key(y: f32) -> u32 {
    y.to_bits() >> 16
}

impl Ramp {
    /// The ramp of the premultiplied light of `frames` (straight-alpha frames: colour ×
    /// alpha). `None` when no bin holds enough light or a value is not finite (then there
    /// is no colour to keep, or nothing to trust: blend plainly).
    pub fn of(frames: &[&RgbaFrame]) -> Option<Ramp> {
        let light = |q: &[f32; 4]| [q[0] * q[3], q[1] * q[3], q[2] * q[3]];
        let mut top = 0.0f32;
        for f in frames {
            for q in f.data() {
                let y = luma(light(q));
                if !y.is_finite() {
                    return None;
                }
                top = top.max(y);
            }
        }
        if top <= Y_FLOOR {
            return None;
        }
        // A 32-bin curve needs no more than about 65,536 pixels a frame: every `stride`-th.
        let stride = |f: &RgbaFrame| f.data().len().div_ceil(SAMPLES).max(1);
        let lo = Y_FLOOR.ln();
        let step = ((top.ln() - lo) / RAMP_BINS as f32).max(1e-6);
        // per bin: Σ light per channel, ΣY, ΣY·ln Y
        let mut sum = vec![[0.0f64; 5]; RAMP_BINS];
        for f in frames {
            for q in f.data().iter().step_by(stride(f)) {
                let p = light(q);
                let y = luma(p);
                if y <= Y_FLOOR {
                    continue;
                }
                let ly = y.ln();
                let k = (((ly - lo) / step) as usize).min(RAMP_BINS - 1);
                for c in 0..3 {
                    sum[k][c] += f64::from(p[c]);
                }
                sum[k][3] += f64::from(y);
                sum[k][4] += f64::from(y) * f64::from(ly);
            }
        }
        let nodes: Vec<(f32, [f32; 3])> = sum
            .iter()
            .filter(|s| s[3] >= BIN_LIGHT)
            .map(|s| {
                (
                    (s[4] / s[3]) as f32,
                    std::array::from_fn(|c| (s[c] / s[3]) as f32),
                )
            })
            .collect();
        if nodes.is_empty() {
            return None;
        }
        let table = (key(Y_FLOOR)..=key(top))
            .map(|k| between_nodes(&nodes, f32::from_bits((k << 16) | 0x8000)))
            .collect();
        Some(Ramp { table })
    }

    /// The ramp's chromaticity at luminance `y` (> 0), from [`Ramp::table`].
    pub fn at(&self, y: f32) -> [f32; 3] {
        let k = key(y.max(Y_FLOOR)) - key(Y_FLOOR);
        self.table[(k as usize).min(self.table.len() - 1)]
    }

    /// The blend `w` of the way from the premultiplied pixel `a` to `b` (RGB light and
    /// alpha) on the ramp (see the module doc); premultiplied.
    pub fn blend_pm(&self, a: [f32; 4], b: [f32; 4], w: f32) -> [f32; 4] {
        let s = 1.0 - w;
        let alpha = s * a[3] + w * b[3];
        let (pa, pb) = ([a[0], a[1], a[2]], [b[0], b[1], b[2]]);
        let (ya, yb) = (luma(pa), luma(pb));
        let yo = s * ya + w * yb;
        if yo <= Y_FLOOR {
            return std::array::from_fn(|c| s * a[c] + w * b[c]);
        }
        let offset = |p: [f32; 3], y: f32| -> [f32; 3] {
            if y > Y_FLOOR {
                let r = self.at(y);
                std::array::from_fn(|c| p[c] / y - r[c])
            } else {
                [0.0; 3]
            }
        };
        let (da, db) = (offset(pa, ya), offset(pb, yb));
        let (sa, sb) = (s * ya.max(0.0) / yo, w * yb.max(0.0) / yo);
        let r = self.at(yo);
        let mut o = [0.0f32; 4];
        for c in 0..3 {
            o[c] = (yo * (r[c] + sa * da[c] + sb * db[c])).max(0.0);
        }
        o[3] = alpha;
        o
    }
}

/// The blend `w` of the way from the premultiplied pixel `p` to `q`, on `ramp` (plainly
/// without one), as a straight-alpha pixel (`[0; 4]` where its alpha is at most 1e-8): the
/// per-pixel step of [`blend_with`], for callers that make `p` and `q` themselves (a
/// morph's two warped rows).
pub fn blend_pm_to_straight(ramp: Option<&Ramp>, p: [f32; 4], q: [f32; 4], w: f32) -> [f32; 4] {
    let m = match ramp {
        Some(r) => r.blend_pm(p, q, w),
        None => std::array::from_fn(|c| p[c] + (q[c] - p[c]) * w),
    };
    if m[3] <= 1e-8 {
        return [0.0; 4];
    }
    [m[0] / m[3], m[1] / m[3], m[2] / m[3], m[3]]
}

/// Straight → premultiplied.
fn pm(q: [f32; 4]) -> [f32; 4] {
    [q[0] * q[3], q[1] * q[3], q[2] * q[3], q[3]]
}

/// [`Ramp::blend_pm`] of two straight-alpha frames of one size, pixel by pixel, the ramp
/// measured on the two (`None` when the sizes differ). Where the blended alpha is at most
/// 1e-8 the pixel is the plain blend of the straight colours with alpha 0 (what a keyed-out
/// pixel's colour is, for a straight-alpha sheet's filtering to bleed in). Without a ramp
/// (all dark, or a value not finite) every pixel is the plain premultiplied blend.
pub fn blend_on_ramp(a: &RgbaFrame, b: &RgbaFrame, w: f32) -> Option<RgbaFrame> {
    blend_with(Ramp::of(&[a, b]).as_ref(), a, b, w)
}

/// [`blend_on_ramp`] with a ramp measured once (for the blends of one pair at several
/// weights, or of the pair's warped frames: a warp moves the light, it does not recolour
/// it); `None` blends plainly.
pub fn blend_with(ramp: Option<&Ramp>, a: &RgbaFrame, b: &RgbaFrame, w: f32) -> Option<RgbaFrame> {
    use rayon::prelude::*;
    if a.size() != b.size() {
        return None;
    }
    let data: Vec<[f32; 4]> = a
        .data()
        .par_iter()
        .zip(b.data().par_iter())
        .map(|(&p, &q)| {
            let alpha = p[3] + (q[3] - p[3]) * w;
            if alpha <= 1e-8 {
                let mut o: [f32; 4] = std::array::from_fn(|c| p[c] + (q[c] - p[c]) * w);
                o[3] = 0.0;
                return o;
            }
            blend_pm_to_straight(ramp, pm(p), pm(q), w)
        })
        .collect();
    Some(RgbaFrame::from_vec(a.size(), data).expect("sized from a"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Size;

    /// A fire ramp: deep red when dim, orange, yellow when bright (linear chromaticity,
    /// luminance 1 by construction).
    fn fire(y: f32) -> [f32; 4] {
        let t = (y / 0.8).clamp(0.0, 1.0);
        let raw = [1.0, 0.15 + 0.75 * t, 0.02 + 0.2 * t * t];
        let l = luma(raw);
        [raw[0] * y / l, raw[1] * y / l, raw[2] * y / l, 1.0]
    }

    fn frame(px: &[[f32; 4]]) -> RgbaFrame {
        RgbaFrame::from_vec(Size::new(px.len() as u32, 1).unwrap(), px.to_vec()).unwrap()
    }

    fn chroma(p: [f32; 4]) -> [f32; 3] {
        let y = luma([p[0], p[1], p[2]]);
        [p[0] / y, p[1] / y, p[2] / y]
    }

    fn dist(a: [f32; 3], b: [f32; 3]) -> f32 {
        (0..3).map(|c| (a[c] - b[c]).powi(2)).sum::<f32>().sqrt()
    }

    /// Frames whose pixels all lie on one fire ramp, over a black background.
    fn ramp_frames() -> (RgbaFrame, RgbaFrame) {
        let levels: Vec<f32> = (0..64).map(|i| 0.002 * 1.1f32.powi(i)).collect();
        let mut a: Vec<[f32; 4]> = levels.iter().map(|&y| fire(y.min(0.9))).collect();
        let mut b: Vec<[f32; 4]> = levels.iter().rev().map(|&y| fire(y.min(0.9))).collect();
        // the test pixel: bright yellow in a, black (opaque background) in b
        a.push(fire(0.8));
        b.push([0.0, 0.0, 0.0, 1.0]);
        (frame(&a), frame(&b))
    }

    #[test]
    fn a_bright_flame_fading_into_the_dark_cools_instead_of_turning_olive() {
        let (a, b) = ramp_frames();
        let ramp = Ramp::of(&[&a, &b]).unwrap();
        let i = a.data().len() - 1;
        for w in [0.25f32, 0.5, 0.75] {
            let out = blend_on_ramp(&a, &b, w).unwrap().data()[i];
            let plain: [f32; 4] =
                std::array::from_fn(|c| a.data()[i][c] * (1.0 - w) + b.data()[i][c] * w);
            let (yo, yp) = (
                luma([out[0], out[1], out[2]]),
                luma([plain[0], plain[1], plain[2]]),
            );
            assert!(
                (yo - yp).abs() < 1e-5 * yp.max(1e-3),
                "luminance kept: {yo} {yp}"
            );
            // on the ramp at the dimmer brightness: the fire's own colour there
            let want = fire(yp);
            assert!(
                dist(chroma(out), chroma(want)) < 0.07,
                "w {w}: {out:?} vs {want:?}"
            );
            // the plain blend keeps the bright yellow's chromaticity: off the ramp
            assert!(dist(chroma(plain), chroma(want)) > 0.2, "w {w}: {plain:?}");
            assert!(
                out[1] / out[0] < plain[1] / plain[0],
                "redder than the plain blend"
            );
        }
        // the ramp it measured is the fire ramp
        for y in [0.01f32, 0.1, 0.5, 0.7] {
            assert!(
                dist(ramp.at(y), chroma(fire(y))) < 0.03,
                "{y}: {:?}",
                ramp.at(y)
            );
        }
    }

    #[test]
    fn ends_are_the_frames_and_offsets_from_the_ramp_are_carried() {
        let (mut a, b) = ramp_frames();
        // a blue-ish pixel (a candle's base): off the ramp
        a.data_mut()[10] = [0.05, 0.06, 0.3, 1.0];
        let ramp = Ramp::of(&[&a, &b]).unwrap();
        for (p, q) in a.data().iter().zip(b.data()) {
            let (p, q) = (pm(*p), pm(*q));
            for (w, want) in [(0.0f32, p), (1.0, q)] {
                let o = ramp.blend_pm(p, q, w);
                for c in 0..4 {
                    assert!(
                        (o[c] - want[c]).abs() < 1e-4 * want[c].abs().max(1e-2),
                        "{o:?} {want:?}"
                    );
                }
            }
        }
        // blended with itself, a pixel stays itself at any weight, off the ramp or on it
        let blue = pm(a.data()[10]);
        let o = ramp.blend_pm(blue, blue, 0.5);
        assert!((0..4).all(|c| (o[c] - blue[c]).abs() < 1e-5), "{o:?}");
    }

    #[test]
    fn dark_keyed_and_bad_frames_blend_plainly() {
        let z = frame(&[[0.0, 0.0, 0.0, 1.0]; 4]);
        assert!(Ramp::of(&[&z, &z]).is_none());
        let out = blend_on_ramp(&z, &z, 0.5).unwrap();
        assert_eq!(out.data()[0], [0.0, 0.0, 0.0, 1.0]);
        // keyed out in both: the straight colours blended, alpha 0
        let k = frame(&[[0.2, 0.1, 0.0, 0.0]]);
        let l = frame(&[[0.4, 0.3, 0.0, 0.0]]);
        let o = blend_on_ramp(&k, &l, 0.5).unwrap().data()[0];
        assert!(
            (o[0] - 0.3).abs() < 1e-6 && (o[1] - 0.2).abs() < 1e-6 && o[3] == 0.0,
            "{o:?}"
        );
        // a value that is not finite: no ramp (plain blend), no panic
        let nan = frame(&[[f32::NAN, 0.0, 0.0, 1.0], [1.0, 0.5, 0.1, 1.0]]);
        assert!(Ramp::of(&[&nan]).is_none());
        let _ = blend_on_ramp(&nan, &nan, 0.5).unwrap();
        // sizes differ
        assert!(blend_on_ramp(&z, &k, 0.5).is_none());
    }
}
