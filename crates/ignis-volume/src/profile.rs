//! The fire profile texture and the unit fire volume it defines.
//!
//! Source: fuller-procedural-volumetric-fire.txt §2, eq. (1)–(2), Figure 5. The profile is
//! any RGBA image (linear light, straight alpha, as `ignis-core` frames are). Convention:
//! `u = 0` is the **left** column (the fire's axis) and `u = 1` the right column (the
//! volume's rim); `v = 0` is the **bottom** row and `v = 1` the top. Look-ups are bilinear;
//! outside `u ∈ [0, 1]`, `v ∈ [0, 1]` the profile is empty (the swept volume is a cylinder
//! of radius 1 and height 1, so nothing exists outside it).

use crate::error::{Result, VolumeError};
use ignis_core::{Palette, RgbaFrame, Size};

/// A fire profile texture, ready for look-ups.
#[derive(Clone, Debug, PartialEq)]
pub struct FireProfile {
    w: usize,
    h: usize,
    /// Rows bottom-to-top (row 0 = v 0), straight-alpha RGBA.
    texels: Vec<[f32; 4]>,
    /// Largest alpha in each column, to skip the noise where the profile is empty.
    col_alpha: Vec<f32>,
    /// Per column pair `i, i + 1` (the bilinear footprint of a look-up): the closed range
    /// of `v` outside which [`FireProfile::sample`] has zero alpha; `[1, 0]` when empty.
    v_support: Vec<[f32; 2]>,
}

impl FireProfile {
    /// A profile from an image (row 0 = top, as every Ignis frame). Needs at least 2×2.
    pub fn from_frame(frame: &RgbaFrame) -> Result<FireProfile> {
        let (w, h) = (frame.width() as usize, frame.height() as usize);
        if w < 2 || h < 2 {
            return Err(VolumeError::bad(
                "profile",
                format!("{w}x{h} image; need at least 2x2"),
            ));
        }
        let mut texels = Vec::with_capacity(w * h);
        for y in (0..h).rev() {
            for p in frame.row(y as u32) {
                let a = if p[3].is_finite() {
                    p[3].clamp(0.0, 1.0)
                } else {
                    0.0
                };
                let c = |v: f32| if v.is_finite() { v.max(0.0) } else { 0.0 };
                texels.push([c(p[0]), c(p[1]), c(p[2]), a]);
            }
        }
        let col_alpha = (0..w)
            .map(|x| (0..h).map(|y| texels[y * w + x][3]).fold(0.0, f32::max))
            .collect();
        let v_support = (0..w - 1)
            .map(|i| {
                let lit = |y: usize| texels[y * w + i][3] > 0.0 || texels[y * w + i + 1][3] > 0.0;
                match ((0..h).find(|&y| lit(y)), (0..h).rev().find(|&y| lit(y))) {
                    // A look-up at `v` reads rows `j = ⌊v (h−1)⌋` (at most h−2) and `j + 1`,
                    // so it can see a lit row only if `rmin − 1 ≤ j ≤ rmax`, i.e.
                    // `(rmin − 1)/(h−1) ≤ v < (rmax + 1)/(h−1)`.
                    (Some(rmin), Some(rmax)) => [
                        ((rmin as f32 - 1.0) / (h - 1) as f32).max(0.0),
                        ((rmax as f32 + 1.0) / (h - 1) as f32).min(1.0),
                    ],
                    _ => [1.0, 0.0],
                }
            })
            .collect();
        Ok(FireProfile {
            w,
            h,
            texels,
            col_alpha,
            v_support,
        })
    }

    /// The built-in profile: a tear-drop flame, white-yellow at the hot core near the base,
    /// through orange to red at the rim and tip (colours from the `classic` palette).
    pub fn default_profile() -> FireProfile {
        let size = Size::new(64, 128).expect("valid");
        let pal = Palette::preset("classic").expect("preset exists");
        let mut frame = RgbaFrame::new(size);
        for y in 0..size.height {
            let v = 1.0 - (y as f32 + 0.5) / size.height as f32;
            // half-width of the flame at height v: round base, pointed tip
            let base = (v / 0.12).min(1.0).sqrt();
            let tip = (1.0 - v).max(0.0).powf(0.75);
            let width = 0.95 * base * tip;
            for x in 0..size.width {
                let u = (x as f32 + 0.5) / size.width as f32;
                if width <= 0.0 || u >= width {
                    continue;
                }
                let d = u / width; // 0 at the axis, 1 at the flame's edge
                let heat = (1.0 - d * d) * (1.0 - 0.75 * v);
                let mut c = pal.sample(0.25 + 0.75 * heat);
                let edge = ((1.0 - d) / 0.08).min(1.0);
                c[3] = (edge * (0.35 + 0.65 * heat)).clamp(0.0, 1.0);
                frame.set(x, y, c);
            }
        }
        FireProfile::from_frame(&frame).expect("64x128")
    }

    pub fn width(&self) -> usize {
        self.w
    }
    pub fn height(&self) -> usize {
        self.h
    }

    /// The profile as an image (row 0 = top).
    pub fn to_frame(&self) -> RgbaFrame {
        let size = Size::new(self.w as u32, self.h as u32).expect("built from a valid size");
        let mut data = Vec::with_capacity(self.w * self.h);
        for y in (0..self.h).rev() {
            data.extend_from_slice(&self.texels[y * self.w..(y + 1) * self.w]);
        }
        RgbaFrame::from_vec(size, data).expect("same size")
    }

    /// Whether the column at `u` (and its bilinear neighbour) is empty for every `v`: then no
    /// noise offset of `v` can make the sample visible.
    #[inline(always)]
    pub fn column_empty(&self, u: f32) -> bool {
        if !(0.0..=1.0).contains(&u) {
            return true;
        }
        let x = u * (self.w - 1) as f32;
        let i = column(x, self.w);
        self.col_alpha[i] <= 0.0 && self.col_alpha[i + 1] <= 0.0
    }

    /// The closed range `[v_lo, v_hi]` outside which the look-up at `(u, v)` has zero alpha
    /// (conservative: the alpha may also be zero inside); `None` when it is zero for every
    /// `v` (as [`FireProfile::column_empty`]). The renderer uses it to skip noise octaves
    /// that cannot make a sample visible.
    #[inline(always)]
    pub fn v_support(&self, u: f32) -> Option<[f32; 2]> {
        if !(0.0..=1.0).contains(&u) {
            return None;
        }
        // the same column index as `sample`
        let x = u * (self.w - 1) as f32;
        let i = column(x, self.w);
        let r = self.v_support[i];
        (r[0] <= r[1]).then_some(r)
    }

    /// Bilinear look-up at `(u, v)` (eq. 2 / 14); transparent black outside the unit square.
    #[inline(always)]
    pub fn sample(&self, u: f32, v: f32) -> [f32; 4] {
        if !(0.0..=1.0).contains(&u) || !(0.0..=1.0).contains(&v) {
            return [0.0; 4];
        }
        let x = u * (self.w - 1) as f32;
        let y = v * (self.h - 1) as f32;
        let i = column(x, self.w);
        let j = column(y, self.h);
        let (fx, fy) = (x - i as f32, y - j as f32);
        let t = &self.texels;
        let r0 = j * self.w + i;
        let r1 = r0 + self.w;
        let (a, b, c, d) = (t[r0], t[r0 + 1], t[r1], t[r1 + 1]);
        let mut out = [0.0; 4];
        for k in 0..4 {
            let top = a[k] + fx * (b[k] - a[k]);
            let bot = c[k] + fx * (d[k] - c[k]);
            out[k] = top + fy * (bot - top);
        }
        out
    }
}

/// `⌊x⌋` as a texel index below `n − 1`, for `x ∈ [0, n − 1]` (the callers check that
/// the coordinate lies in `[0, 1]`): the same value as `(x as usize).min(n − 2)` through
/// the cheaper conversion to `i32` (profiles are far narrower than `i32::MAX`).
#[inline(always)]
fn column(x: f32, n: usize) -> usize {
    (x as i32 as usize).min(n - 2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_profile_is_a_flame() {
        let p = FireProfile::default_profile();
        assert!(p.sample(0.0, 0.2)[3] > 0.5);
        assert_eq!(p.sample(0.99, 0.5)[3], 0.0);
        assert_eq!(p.sample(0.5, 1.5), [0.0; 4]);
        assert!(p.column_empty(1.0));
        assert!(!p.column_empty(0.1));
        // round trip through an image keeps the orientation
        let q = FireProfile::from_frame(&p.to_frame()).unwrap();
        assert_eq!(p, q);
    }

    /// Outside `v_support` every look-up is transparent, on a fine grid.
    #[test]
    fn v_support_bounds_the_alpha() {
        let p = FireProfile::default_profile();
        let n = 1000;
        let mut inside = 0;
        for a in 0..=n {
            let u = a as f32 / n as f32;
            let s = p.v_support(u);
            assert_eq!(s.is_none(), p.column_empty(u), "u {u}");
            for b in 0..=n {
                let v = b as f32 / n as f32;
                let alpha = p.sample(u, v)[3];
                match s {
                    Some([lo, hi]) if v >= lo && v <= hi => inside += (alpha > 0.0) as u32,
                    _ => assert_eq!(alpha, 0.0, "u {u} v {v} support {s:?}"),
                }
            }
        }
        assert!(inside > 1000);
    }
}
