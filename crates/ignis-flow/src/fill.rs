//! Vectors where a frame shows nothing, filled from where it shows something.
//!
//! A matted frame (a flame keyed out of its surroundings) is black wherever its alpha is 0,
//! and DIS has nothing to match there: the vectors it leaves over the empty background are
//! whatever the patches that overlap the flame's edge and the coarser pyramid levels
//! carried in — piecewise constant over the patch grid, sometimes large. A morph reads its
//! frames along those vectors, so its in-betweens can drag the flame's edge over the
//! background in straight-edged blocks (seen over a light plate).
//! [`fill_unseen`] keeps each vector in proportion to its frame's alpha there and takes the
//! rest from a smooth fill of the seen vectors: a push–pull pyramid (Gortler et al., "The
//! Lumigraph", SIGGRAPH 1996, §3.3): weighted 2×2 sums down to one pixel, then, going back
//! up, each pixel's missing weight taken from the bilinear upsampling of the coarser level.
//! Fully opaque frames keep their field bit for bit.
//!
//! Hand-written because it is a few dozen lines on this crate's own field type; image
//! crates' inpainting works on 8-bit images, not on vector fields with weights.

use crate::field::FlowField;
use crate::image::resize_with;
use ignis_core::{RgbaFrame, Size};

/// One pyramid level: premultiplied vectors and their weights (each at most 1).
struct Level {
    w: usize,
    h: usize,
    weight: Vec<f32>,
    value: Vec<[f32; 2]>,
}

impl Level {
    /// The next coarser level: 2×2 sums, weights above 1 normalised to 1.
    fn pull(&self) -> Level {
        let (w, h) = (self.w.div_ceil(2), self.h.div_ceil(2));
        let mut weight = vec![0.0f32; w * h];
        let mut value = vec![[0.0f32; 2]; w * h];
        for y in 0..h {
            for x in 0..w {
                let (mut s, mut v) = (0.0f32, [0.0f32; 2]);
                for fy in 2 * y..(2 * y + 2).min(self.h) {
                    for fx in 2 * x..(2 * x + 2).min(self.w) {
                        let i = fy * self.w + fx;
                        s += self.weight[i];
                        v[0] += self.value[i][0];
                        v[1] += self.value[i][1];
                    }
                }
                if s > 1.0 {
                    v = [v[0] / s, v[1] / s];
                    s = 1.0;
                }
                weight[y * w + x] = s;
                value[y * w + x] = v;
            }
        }
        Level {
            w,
            h,
            weight,
            value,
        }
    }

    /// The vectors of a filled level (every weight 1) as a field.
    fn into_field(self) -> FlowField {
        FlowField::from_parts(
            Size {
                width: self.w as u32,
                height: self.h as u32,
            },
            self.value,
        )
    }

    /// Fills each pixel's missing weight from `coarse` (already filled), bilinearly
    /// upsampled (coarse pixel `i` is centred at fine `2i + 0.5`).
    fn push(&mut self, coarse: &FlowField) {
        for y in 0..self.h {
            let cy = (y as f32 - 0.5) * 0.5;
            for x in 0..self.w {
                let i = y * self.w + x;
                let missing = 1.0 - self.weight[i];
                if missing > 0.0 {
                    let up = coarse.at((x as f32 - 0.5) * 0.5, cy);
                    self.value[i][0] += missing * up[0];
                    self.value[i][1] += missing * up[1];
                }
                self.weight[i] = 1.0;
            }
        }
    }
}

/// `f` (a field from `frame` to another frame, at any size) with each vector kept in
/// proportion to `frame`'s alpha there (area-averaged to the field's size) and the rest
/// filled smoothly from the vectors where the frame is seen (module docs). A frame that is
/// opaque everywhere, or shows nothing anywhere, returns `f` unchanged; a non-finite alpha
/// counts as 0.
pub fn fill_unseen(f: &FlowField, frame: &RgbaFrame) -> FlowField {
    match alpha_weights(f.size(), frame) {
        Some(weight) => fill_weighted(f, weight),
        None => f.clone(),
    }
}

/// `frame`'s alpha area-averaged to `size`, in 0..=1 (non-finite as 0); `None` where the
/// sizes are empty.
fn alpha_weights(size: Size, frame: &RgbaFrame) -> Option<Vec<f32>> {
    let (w, h) = (size.width as usize, size.height as usize);
    let fs = frame.size();
    if w == 0 || h == 0 || fs.pixels() == 0 {
        return None;
    }
    let (sw, sh) = (fs.width as usize, fs.height as usize);
    let alpha = |p: &[f32; 4]| {
        if p[3].is_finite() {
            p[3].clamp(0.0, 1.0)
        } else {
            0.0
        }
    };
    // area-averaged row by row, as `area_resize_luma` does: no full-size alpha plane
    let small = resize_with(sw, sh, w, h, |y, wt, out| {
        for (o, p) in out.iter_mut().zip(&frame.data()[y * sw..(y + 1) * sw]) {
            *o += alpha(p) * wt;
        }
    });
    Some(small.data.into_iter().map(|a| a.clamp(0.0, 1.0)).collect())
}

/// `f` with each vector kept in proportion to its `weight` (0..=1, one a pixel) and the
/// rest filled by push–pull from the weighted vectors; all weights 1, or all 0, give `f`.
fn fill_weighted(f: &FlowField, weight: Vec<f32>) -> FlowField {
    let size = f.size();
    let (w, h) = (size.width as usize, size.height as usize);
    if weight.iter().all(|&a| a >= 1.0) || weight.iter().all(|&a| a <= 0.0) {
        return f.clone();
    }
    let value = f
        .data()
        .iter()
        .zip(&weight)
        .map(|(v, &a)| [v[0] * a, v[1] * a])
        .collect();
    let mut levels = vec![Level {
        w,
        h,
        weight,
        value,
    }];
    while levels.last().is_some_and(|l| l.w > 1 || l.h > 1) {
        let next = levels.last().expect("non-empty").pull();
        levels.push(next);
    }
    // The top (1×1) level: the weighted mean of every seen vector.
    let top = levels.last_mut().expect("non-empty");
    let s = top.weight[0];
    top.value[0] = if s > 0.0 {
        [top.value[0][0] / s, top.value[0][1] / s]
    } else {
        [0.0; 2]
    };
    top.weight[0] = 1.0;
    while levels.len() > 1 {
        let coarse = levels.pop().expect("more than one").into_field();
        levels.last_mut().expect("non-empty").push(&coarse);
    }
    levels.pop().expect("the finest level").into_field()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(size: Size, alpha: impl Fn(usize, usize) -> f32) -> RgbaFrame {
        let w = size.width as usize;
        let data = (0..size.pixels())
            .map(|i| [0.5, 0.4, 0.2, alpha(i % w, i / w)])
            .collect();
        RgbaFrame::from_vec(size, data).unwrap()
    }

    #[test]
    fn seen_vectors_stay_and_unseen_ones_come_from_the_seen() {
        let size = Size::new(40, 30).unwrap();
        // Seen: a disc in the middle moving right by 3 px; garbage elsewhere.
        let seen = |x: usize, y: usize| {
            let (dx, dy) = (x as f32 - 20.0, y as f32 - 15.0);
            dx * dx + dy * dy < 64.0
        };
        let data = (0..size.pixels())
            .map(|i| {
                let (x, y) = (i % 40, i / 40);
                if seen(x, y) {
                    [3.0, 0.0]
                } else {
                    [-((x * 7 % 11) as f32), (y * 5 % 13) as f32 - 6.0]
                }
            })
            .collect();
        let f = FlowField::from_vec(size, data).unwrap();
        let a = frame(size, |x, y| if seen(x, y) { 1.0 } else { 0.0 });
        let filled = fill_unseen(&f, &a);
        for (i, (v, u)) in filled.data().iter().zip(f.data()).enumerate() {
            if seen(i % 40, i / 40) {
                assert_eq!(v, u, "a seen vector is kept bit for bit");
            } else {
                // Only the disc's motion is there to fill from.
                assert!(
                    (v[0] - 3.0).abs() < 1e-4 && v[1].abs() < 1e-4,
                    "{v:?} at {i}"
                );
            }
        }
    }

    #[test]
    fn the_fill_is_smooth_between_two_motions() {
        let size = Size::new(64, 16).unwrap();
        // Seen: a strip at each end, moving up on the left and down on the right.
        let data = (0..size.pixels())
            .map(|i| if i % 64 < 32 { [0.0, -4.0] } else { [0.0, 4.0] })
            .collect();
        let f = FlowField::from_vec(size, data).unwrap();
        let a = frame(size, |x, _| if !(4..60).contains(&x) { 1.0 } else { 0.0 });
        let filled = fill_unseen(&f, &a);
        let row: Vec<f32> = filled.data()[8 * 64..9 * 64].iter().map(|v| v[1]).collect();
        // Monotone from one motion to the other, no jump of a patch's size.
        for x in 4..60 {
            assert!(row[x + 1] >= row[x] - 1e-4, "{row:?}");
            assert!(row[x + 1] - row[x] < 1.5, "a step at {x}: {row:?}");
        }
        assert!(row[10] < -2.0 && row[53] > 2.0, "{row:?}");
        // Half-seen pixels keep half of their vector.
        let half = frame(size, |_, _| 0.5);
        let g = fill_unseen(&f, &half);
        for (v, u) in g.data().iter().zip(f.data()) {
            assert!(v[1].abs() <= u[1].abs() + 1e-4);
        }
    }

    #[test]
    fn opaque_empty_and_bad_alpha_frames_keep_the_field() {
        let size = Size::new(9, 7).unwrap();
        let data = (0..size.pixels())
            .map(|i| [i as f32, -(i as f32)])
            .collect();
        let f = FlowField::from_vec(size, data).unwrap();
        assert_eq!(fill_unseen(&f, &frame(size, |_, _| 1.0)), f);
        assert_eq!(fill_unseen(&f, &frame(size, |_, _| 0.0)), f);
        assert_eq!(fill_unseen(&f, &frame(size, |_, _| f32::NAN)), f);
        // A field of another size than the frame: alpha is averaged to the field's size.
        let big = frame(
            Size::new(90, 70).unwrap(),
            |x, _| if x < 45 { 1.0 } else { 0.0 },
        );
        let g = fill_unseen(&f, &big);
        assert_eq!(g.size(), size);
        assert!(g
            .data()
            .iter()
            .all(|v| v[0].is_finite() && v[1].is_finite()));
        assert_eq!(g.data()[0], f.data()[0]);
    }
}
