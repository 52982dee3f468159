//! Internal single-channel images: the area resize used for the working size and the
//! pyramid, central-difference gradients and bilinear sampling.

use rayon::prelude::*;

/// A row-major `f32` image (no size limits beyond what its creator checked).
#[derive(Clone, Debug)]
pub(crate) struct Img {
    pub w: usize,
    pub h: usize,
    pub data: Vec<f32>,
}

impl Img {
    pub fn new(w: usize, h: usize, data: Vec<f32>) -> Img {
        debug_assert_eq!(data.len(), w * h);
        Img { w, h, data }
    }

    #[inline]
    pub fn row(&self, y: usize) -> &[f32] {
        &self.data[y * self.w..(y + 1) * self.w]
    }

    /// Area-average resize to `w × h` (each output pixel is the mean of the source area it
    /// covers, fractional coverage weighted). Used only for shrinking; growing degrades to
    /// nearest-neighbour, which no caller asks for.
    pub fn area_resize(&self, w: usize, h: usize) -> Img {
        if w == self.w && h == self.h {
            return self.clone();
        }
        area_resize(&self.data, self.w, self.h, w, h)
    }

    /// Central-difference gradients (one-sided at the edges, halved like the interior).
    pub fn gradients(&self) -> (Img, Img) {
        let (w, h) = (self.w, self.h);
        let mut gx = vec![0.0f32; w * h];
        let mut gy = vec![0.0f32; w * h];
        gx.par_chunks_mut(w)
            .zip(gy.par_chunks_mut(w))
            .enumerate()
            .for_each(|(y, (rx, ry))| {
                let r = self.row(y);
                let up = self.row(y.saturating_sub(1));
                let dn = self.row((y + 1).min(h - 1));
                for x in 0..w {
                    let l = r[x.saturating_sub(1)];
                    let rr = r[(x + 1).min(w - 1)];
                    rx[x] = 0.5 * (rr - l);
                    ry[x] = 0.5 * (dn[x] - up[x]);
                }
            });
        (Img::new(w, h, gx), Img::new(w, h, gy))
    }

    /// Bilinear sample at `(x, y)`, edge-clamped (the reference the fast paths are
    /// tested against).
    #[cfg(test)]
    pub fn sample(&self, x: f32, y: f32) -> f32 {
        let (x0, x1, wx) = crate::field::tap(x, self.w as u32);
        let (y0, y1, wy) = crate::field::tap(y, self.h as u32);
        let r0 = self.row(y0 as usize);
        let r1 = self.row(y1 as usize);
        let top = r0[x0 as usize] + (r0[x1 as usize] - r0[x0 as usize]) * wx;
        let bot = r1[x0 as usize] + (r1[x1 as usize] - r1[x0 as usize]) * wx;
        top + (bot - top) * wy
    }
}

/// [`Img::area_resize`] of a row-major `sw × sh` slice (no copy of the source).
pub(crate) fn area_resize(src: &[f32], sw: usize, sh: usize, w: usize, h: usize) -> Img {
    if w == sw && h == sh {
        return Img::new(w, h, src.to_vec());
    }
    resize_with(sw, sh, w, h, |y, wt, out| {
        for (o, &v) in out.iter_mut().zip(&src[y * sw..(y + 1) * sw]) {
            *o += v * wt;
        }
    })
}

/// [`area_resize`] of the luminance of a colour frame ([`crate::luma`]) without building
/// the full-size grey frame: the same values, bit for bit, as resizing `luma(frame)`.
pub(crate) fn area_resize_luma(src: &[[f32; 4]], sw: usize, sh: usize, w: usize, h: usize) -> Img {
    resize_with(sw, sh, w, h, |y, wt, out| {
        for (o, p) in out.iter_mut().zip(&src[y * sw..(y + 1) * sw]) {
            *o += crate::warp::luma_of(p) * wt;
        }
    })
}

/// The area resize of an `sw × sh` source to `w × h`, where `add_row(y, wt, out)` adds
/// `wt ×` source row `y` to `out`.
pub(crate) fn resize_with(
    sw: usize,
    sh: usize,
    w: usize,
    h: usize,
    add_row: impl Fn(usize, f32, &mut [f32]) + Sync,
) -> Img {
    let xw = area_weights(sw, w);
    let yw = area_weights(sh, h);
    // Vertical pass first: h rows of sw, each a weighted sum of whole source rows
    // (contiguous, vectorisable), so the gather-heavy horizontal pass runs on h rows
    // instead of sh.
    let mut tmp = vec![0.0f32; sw * h];
    tmp.par_chunks_mut(sw).enumerate().for_each(|(y, out)| {
        let (start, ws) = &yw[y];
        for (k, &wt) in ws.iter().enumerate() {
            add_row(start + k, wt, out);
        }
    });
    // Horizontal pass.
    let mut data = vec![0.0f32; w * h];
    data.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
        let src = &tmp[y * sw..(y + 1) * sw];
        for (o, (start, ws)) in out.iter_mut().zip(&xw) {
            let mut s = 0.0;
            for (k, &wt) in ws.iter().enumerate() {
                s += src[start + k] * wt;
            }
            *o = s;
        }
    });
    Img::new(w, h, data)
}

/// For each of `m` outputs over `n` inputs: the first input index and the weights of the
/// inputs it covers (summing to 1).
fn area_weights(n: usize, m: usize) -> Vec<(usize, Vec<f32>)> {
    let r = n as f64 / m as f64;
    (0..m)
        .map(|i| {
            let a = i as f64 * r;
            let b = ((i + 1) as f64 * r).min(n as f64);
            let first = (a.floor() as usize).min(n - 1);
            let last = ((b.ceil() as usize).max(first + 1)).min(n);
            let mut ws: Vec<f32> = (first..last)
                .map(|j| {
                    let lo = a.max(j as f64);
                    let hi = b.min(j as f64 + 1.0);
                    (hi - lo).max(0.0) as f32
                })
                .collect();
            let s: f32 = ws.iter().sum();
            if s > 0.0 {
                ws.iter_mut().for_each(|v| *v /= s);
            } else {
                ws = vec![1.0];
            }
            (first, ws)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn area_resize_averages_blocks_and_keeps_the_mean() {
        let img = Img::new(4, 2, vec![1.0, 3.0, 5.0, 7.0, 1.0, 3.0, 5.0, 7.0]);
        let r = img.area_resize(2, 1);
        assert_eq!(r.data, vec![2.0, 6.0]);
        let img = Img::new(5, 3, (0..15).map(|v| v as f32).collect());
        let r = img.area_resize(3, 2);
        let m0: f32 = img.data.iter().sum::<f32>() / 15.0;
        let m1: f32 = r.data.iter().sum::<f32>() / 6.0;
        assert!((m0 - m1).abs() < 1e-4, "{m0} vs {m1}");
    }

    #[test]
    fn gradients_of_a_ramp() {
        let img = Img::new(4, 3, (0..12).map(|i| (i % 4) as f32 * 2.0).collect());
        let (gx, gy) = img.gradients();
        assert_eq!(gx.data[5], 2.0);
        assert_eq!(gy.data[5], 0.0);
    }
}
