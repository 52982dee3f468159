//! [`FlowField`]: a dense 2-D motion field and its resampling.
//!
//! Convention: pixel centres sit at integer coordinates, row 0 at the top, `x` to the
//! right. For `flow(a, b)` the field holds, at each pixel `x` of `a`, the displacement
//! `F(x)` with `a(x) ≈ b(x + F(x))`, in pixels of the field's own size.

use crate::error::{FlowError, Result};
use ignis_core::Size;

/// A dense motion field: one `[dx, dy]` per pixel, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct FlowField {
    size: Size,
    data: Vec<[f32; 2]>,
}

impl FlowField {
    /// The field with no motion anywhere.
    pub fn zero(size: Size) -> FlowField {
        FlowField {
            size,
            data: vec![[0.0; 2]; size.pixels()],
        }
    }

    /// A field from row-major vectors; the length must be `size.pixels()` and every
    /// component finite.
    pub fn from_vec(size: Size, data: Vec<[f32; 2]>) -> Result<FlowField> {
        if data.len() != size.pixels() {
            return Err(FlowError::SizeMismatch(format!(
                "{} vectors for a {size} field; give exactly {} (width × height)",
                data.len(),
                size.pixels()
            )));
        }
        if let Some(i) = data
            .iter()
            .position(|v| !v[0].is_finite() || !v[1].is_finite())
        {
            let w = size.width as usize;
            return Err(FlowError::BadInput(format!(
                "flow vector at pixel ({}, {}) is not finite; replace NaN/infinite vectors \
                 (e.g. by 0) before building the field",
                i % w,
                i / w
            )));
        }
        Ok(FlowField { size, data })
    }

    pub(crate) fn from_parts(size: Size, data: Vec<[f32; 2]>) -> FlowField {
        debug_assert_eq!(data.len(), size.pixels());
        FlowField { size, data }
    }

    /// The field's size.
    pub fn size(&self) -> Size {
        self.size
    }

    /// The vectors, row-major.
    pub fn data(&self) -> &[[f32; 2]] {
        &self.data
    }

    /// Consumes the field, giving its vectors.
    pub fn into_vec(self) -> Vec<[f32; 2]> {
        self.data
    }

    /// The vector at `(x, y)` (field pixels), bilinearly interpolated; positions outside the
    /// field are clamped to its edge, non-finite positions read as the edge at 0.
    #[inline]
    pub fn at(&self, x: f32, y: f32) -> [f32; 2] {
        if self.data.is_empty() {
            return [0.0; 2];
        }
        let (x0, x1, wx) = tap(x, self.size.width);
        let (y0, y1, wy) = tap(y, self.size.height);
        let w = self.size.width as usize;
        let (r0, r1) = (y0 as usize * w, y1 as usize * w);
        let p00 = self.data[r0 + x0 as usize];
        let p01 = self.data[r0 + x1 as usize];
        let p10 = self.data[r1 + x0 as usize];
        let p11 = self.data[r1 + x1 as usize];
        let mut out = [0.0; 2];
        for c in 0..2 {
            let top = p00[c] + (p01[c] - p00[c]) * wx;
            let bot = p10[c] + (p11[c] - p10[c]) * wx;
            out[c] = top + (bot - top) * wy;
        }
        out
    }

    /// The field resampled to `size` (bilinear, pixel centres aligned), each vector scaled
    /// per axis by the size ratio so it stays in pixels of the new size.
    pub fn resized(&self, size: Size) -> FlowField {
        if size == self.size {
            return self.clone();
        }
        if self.data.is_empty() || size.pixels() == 0 {
            return FlowField::zero(size);
        }
        let map = FieldMap::new(self, size);
        let w = size.width as usize;
        let mut data = vec![[0.0f32; 2]; size.pixels()];
        use rayon::prelude::*;
        data.par_chunks_mut(w)
            .enumerate()
            .for_each_init(|| map.scratch(), |v, (y, row)| map.row(y, row, v));
        FlowField { size, data }
    }

    /// Mean vector over the whole field.
    pub fn mean(&self) -> [f64; 2] {
        let mut s = [0.0f64; 2];
        for v in &self.data {
            s[0] += v[0] as f64;
            s[1] += v[1] as f64;
        }
        let n = self.data.len().max(1) as f64;
        [s[0] / n, s[1] / n]
    }
}

/// Bilinear taps for coordinate `x` on an axis of `n` samples: `(i0, i1, weight of i1)`,
/// clamped to the axis; a non-finite coordinate reads sample 0.
#[inline(always)]
pub(crate) fn tap(x: f32, n: u32) -> (u32, u32, f32) {
    let max = (n - 1) as f32;
    let x = if x.is_finite() {
        x.clamp(0.0, max)
    } else {
        0.0
    };
    let i0 = crate::dis::ffloor(x);
    let w = x - i0;
    let i0 = i0 as u32;
    let i1 = (i0 + 1).min(n - 1);
    (i0, i1, w)
}

/// Precomputed taps that sample a field at the pixel centres of another size, scaling the
/// vectors to that size: `resized`, `warp_*` and `morph_*` read fields through it so a
/// reduced-size field never has to be materialised at full resolution.
pub(crate) struct FieldMap<'a> {
    field: &'a FlowField,
    xs: Vec<(u32, u32, f32)>,
    ys: Vec<(u32, u32, f32)>,
    scale: [f32; 2],
}

impl<'a> FieldMap<'a> {
    pub(crate) fn new(field: &'a FlowField, to: Size) -> FieldMap<'a> {
        let fs = field.size;
        let rx = fs.width as f32 / to.width as f32;
        let ry = fs.height as f32 / to.height as f32;
        let xs = (0..to.width)
            .map(|x| tap((x as f32 + 0.5) * rx - 0.5, fs.width))
            .collect();
        let ys = (0..to.height)
            .map(|y| tap((y as f32 + 0.5) * ry - 0.5, fs.height))
            .collect();
        FieldMap {
            field,
            xs,
            ys,
            scale: [1.0 / rx, 1.0 / ry],
        }
    }

    /// The field's width (the scratch length [`FieldMap::row`] needs).
    pub(crate) fn field_width(&self) -> usize {
        self.field.size.width as usize
    }

    /// Scratch for [`FieldMap::row`]: one field row.
    pub(crate) fn scratch(&self) -> Vec<[f32; 2]> {
        vec![[0.0; 2]; self.field.size.width as usize]
    }

    /// Fills `out` with the (scaled) vectors of target row `y`. The field's two rows are
    /// interpolated vertically (and scaled) once into `v` (from [`FieldMap::scratch`]), so
    /// each target pixel reads two vectors instead of four.
    #[inline(always)]
    pub(crate) fn row(&self, y: usize, out: &mut [[f32; 2]], v: &mut [[f32; 2]]) {
        let (y0, y1, wy) = self.ys[y];
        let w = self.field.size.width as usize;
        let r0 = &self.field.data[y0 as usize * w..(y0 as usize + 1) * w];
        let r1 = &self.field.data[y1 as usize * w..(y1 as usize + 1) * w];
        for ((o, a), b) in v[..w].iter_mut().zip(r0).zip(r1) {
            for c in 0..2 {
                o[c] = (a[c] + (b[c] - a[c]) * wy) * self.scale[c];
            }
        }
        for (o, &(x0, x1, wx)) in out.iter_mut().zip(&self.xs) {
            let (p, q) = (v[x0 as usize], v[x1 as usize]);
            *o = [p[0] + (q[0] - p[0]) * wx, p[1] + (q[1] - p[1]) * wx];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn from_vec_checks_length_and_finiteness() {
        let s = Size::new(3, 2).unwrap();
        assert!(FlowField::from_vec(s, vec![[0.0; 2]; 5]).is_err());
        let mut v = vec![[0.0; 2]; 6];
        v[4] = [f32::NAN, 0.0];
        let e = FlowField::from_vec(s, v).unwrap_err().to_string();
        assert!(e.contains("(1, 1)"), "{e}");
    }

    #[test]
    fn at_interpolates_and_clamps() {
        let s = Size::new(2, 2).unwrap();
        let f =
            FlowField::from_vec(s, vec![[0.0, 0.0], [2.0, 4.0], [0.0, 0.0], [2.0, 4.0]]).unwrap();
        assert_eq!(f.at(0.5, 0.5), [1.0, 2.0]);
        assert_eq!(f.at(-3.0, 9.0), [0.0, 0.0]);
        assert_eq!(f.at(7.0, 0.0), [2.0, 4.0]);
        assert_eq!(f.at(f32::NAN, 0.0), [0.0, 0.0]);
    }

    #[test]
    fn resized_scales_vectors_per_axis() {
        let f = FlowField::from_vec(Size::new(4, 2).unwrap(), vec![[1.0, -0.5]; 8]).unwrap();
        let g = f.resized(Size::new(12, 8).unwrap());
        assert_eq!(g.size(), Size::new(12, 8).unwrap());
        for v in g.data() {
            assert!(
                (v[0] - 3.0).abs() < 1e-6 && (v[1] + 2.0).abs() < 1e-6,
                "{v:?}"
            );
        }
        // A linear ramp stays a linear ramp (pixel centres aligned).
        let s = Size::new(8, 1).unwrap();
        let ramp = FlowField::from_vec(s, (0..8).map(|x| [x as f32, 0.0]).collect()).unwrap();
        let half = ramp.resized(Size::new(4, 1).unwrap());
        let want = [0.25, 1.25, 2.25, 3.25];
        for (v, w) in half.data().iter().zip(want) {
            assert!((v[0] - w).abs() < 1e-5, "{v:?} vs {w}");
        }
    }
}
