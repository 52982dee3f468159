//! Warps along a flow field and the motion-compensated morph between two frames.
//!
//! Fields of any size are accepted: they are read through a bilinear map onto the frame's
//! pixel centres with the vectors scaled per axis (exactly what [`FlowField::resized`]
//! would give, without building the full-size field), so a field computed at a reduced
//! size can be passed straight in. Colour is interpolated on **premultiplied** values so
//! transparent pixels never bleed their colour; outputs use straight alpha like every
//! [`RgbaFrame`]. Samples outside the frame are clamped to its edge.

use crate::error::{FlowError, Result};
use crate::field::{tap, FieldMap, FlowField};
use ignis_core::{GrayFrame, RgbaFrame, Size};
use rayon::prelude::*;

/// Rec. 709 luminance weights (linear light).
const LUMA: [f32; 3] = [0.2126, 0.7152, 0.0722];

/// The input for [`crate::flow`] from a colour frame: linear Rec. 709 luminance times alpha
/// (what is visible over black), so transparent pixels carry no texture.
pub fn luma(frame: &RgbaFrame) -> GrayFrame {
    let data = frame.data().par_iter().map(luma_of).collect();
    GrayFrame::from_vec(frame.size(), data).expect("same size as a valid frame")
}

/// [`luma`] of one pixel.
#[inline(always)]
pub(crate) fn luma_of(p: &[f32; 4]) -> f32 {
    (LUMA[0] * p[0] + LUMA[1] * p[1] + LUMA[2] * p[2]) * p[3]
}

/// `out(x) = src(x + t·F(x))`, bilinear, edge-clamped; `F` is resampled to `src`'s size if
/// it has another (vectors scaled). A non-finite `t` reads every pixel from `src(0, 0)`.
pub fn warp_gray(src: &GrayFrame, f: &FlowField, t: f32) -> GrayFrame {
    let size = src.size();
    if size.pixels() == 0 || f.data().is_empty() {
        return src.clone();
    }
    let map = FieldMap::new(f, size);
    let d = src.data();
    let out = per_row(size, 0.0f32, |y, s, row| {
        s.warp_taps(&map, y, t, size);
        for (i, o) in row.iter_mut().enumerate() {
            *o = s.ka.gray(d, i);
        }
    });
    GrayFrame::from_vec(size, out).expect("sized from src")
}

/// `out(x) = src(x + t·F(x))` for colour, interpolated on premultiplied values (see the
/// module doc); otherwise as [`warp_gray`].
pub fn warp_rgba(src: &RgbaFrame, f: &FlowField, t: f32) -> RgbaFrame {
    let size = src.size();
    if size.pixels() == 0 || f.data().is_empty() {
        return src.clone();
    }
    let map = FieldMap::new(f, size);
    let d = src.data();
    let out = per_row(size, [0.0f32; 4], |y, s, row| {
        s.warp_taps(&map, y, t, size);
        for (i, o) in row.iter_mut().enumerate() {
            let mut acc = [0.0f32; 4];
            s.ka.add_pm(d, i, 1.0, &mut acc);
            *o = unpremultiply(acc);
        }
    });
    RgbaFrame::from_vec(size, out).expect("sized from src")
}

/// Rows of [`warp_rgba`]'s output kept **premultiplied** (not unpremultiplied), for a caller
/// that fuses the warp into its own row pass (the joins' detail-preserving in-between blends
/// premultiplied values, so it needs neither the straight-alpha frame nor a full-frame
/// intermediate per warp). Same sampling as [`warp_rgba`]: bilinear, edge-clamped, the
/// field resampled to the frame's size.
pub struct WarpRows<'a> {
    src: &'a [[f32; 4]],
    size: Size,
    map: Option<FieldMap<'a>>,
    t: f32,
}

impl<'a> WarpRows<'a> {
    /// The warp `out(x) = src(x + t·F(x))`; an empty field is the identity.
    pub fn new(src: &'a RgbaFrame, f: &'a FlowField, t: f32) -> WarpRows<'a> {
        let size = src.size();
        let map = (size.pixels() > 0 && !f.data().is_empty()).then(|| FieldMap::new(f, size));
        WarpRows {
            src: src.data(),
            size,
            map,
            t,
        }
    }

    /// Scratch for [`WarpRows::rows_with`] (one per thread, reused across calls).
    pub fn scratch(&self) -> WarpScratch {
        WarpScratch(RowScratch::new(self.size.width as usize))
    }

    /// Writes rows `y0..` of the warped frame, premultiplied, into `out` (as many rows as
    /// `out` holds whole rows of the frame's width; a partial last row is left as it is).
    /// Panics when the rows run past the frame's height.
    pub fn rows(&self, y0: usize, out: &mut [[f32; 4]]) {
        self.rows_with(&mut self.scratch(), y0, out)
    }

    /// [`WarpRows::rows`] with scratch from [`WarpRows::scratch`] of a frame as wide.
    pub fn rows_with(&self, scratch: &mut WarpScratch, y0: usize, out: &mut [[f32; 4]]) {
        let w = self.size.width as usize;
        if w == 0 {
            return;
        }
        let Some(map) = &self.map else {
            let src = &self.src[y0 * w..];
            for (o, p) in out.iter_mut().zip(src) {
                *o = [p[0] * p[3], p[1] * p[3], p[2] * p[3], p[3]];
            }
            return;
        };
        let s = &mut scratch.0;
        for (j, row) in out.chunks_exact_mut(w).enumerate() {
            s.warp_taps(map, y0 + j, self.t, self.size);
            for (i, o) in row.iter_mut().enumerate() {
                let mut acc = [0.0f32; 4];
                s.ka.add_pm(self.src, i, 1.0, &mut acc);
                *o = acc;
            }
        }
    }
}

/// Per-thread scratch of [`WarpRows::rows_with`].
pub struct WarpScratch(RowScratch);

/// A frame's pixels with its size, so inner loops index a slice directly.
#[derive(Clone, Copy)]
struct View<'a, T> {
    d: &'a [T],
    w: u32,
    h: u32,
}

impl<'a, T> View<'a, T> {
    fn new(d: &'a [T], size: Size) -> Self {
        View {
            d,
            w: size.width,
            h: size.height,
        }
    }

    /// The four bilinear taps at `(x, y)` (edge-clamped) and their weights.
    #[inline(always)]
    fn taps(&self, x: f32, y: f32) -> ([usize; 4], [f32; 4]) {
        let (x0, x1, wx) = tap(x, self.w);
        let (y0, y1, wy) = tap(y, self.h);
        let w = self.w as usize;
        let (r0, r1) = (y0 as usize * w, y1 as usize * w);
        let (x0, x1) = (x0 as usize, x1 as usize);
        (
            [r0 + x0, r0 + x1, r1 + x0, r1 + x1],
            [
                (1.0 - wx) * (1.0 - wy),
                wx * (1.0 - wy),
                (1.0 - wx) * wy,
                wx * wy,
            ],
        )
    }
}

/// Bilinear taps of one row of sample positions, computed in a separate (vectorisable)
/// pass before the gathers: base index, the x and y steps to the other taps (0 at the
/// clamped edge) and the weights of the second taps.
struct RowTaps {
    base: Vec<u32>,
    sx: Vec<u32>,
    sy: Vec<u32>,
    wx: Vec<f32>,
    wy: Vec<f32>,
}

impl RowTaps {
    fn new(n: usize) -> RowTaps {
        RowTaps {
            base: vec![0; n],
            sx: vec![0; n],
            sy: vec![0; n],
            wx: vec![0.0; n],
            wy: vec![0.0; n],
        }
    }

    /// Taps for positions `(xs[i], ys[i])` in a `w × h` frame, edge-clamped (positions
    /// are finite: fields and `t` are checked finite by their constructors).
    #[inline(always)]
    fn fill(&mut self, xs: &[f32], ys: &[f32], w: u32, h: u32) {
        // Bounded by 2²⁴ as well (far above `MAX_SIDE`) so the unchecked conversions
        // below stay in `i32` range even for a `Size` built without its checks.
        let bound = |n: u32| (n - 1).min(1 << 24) as f32;
        let (wm, hm) = (bound(w), bound(h));
        let n = xs.len();
        let (base, sx, sy) = (&mut self.base[..n], &mut self.sx[..n], &mut self.sy[..n]);
        let (wx, wy) = (&mut self.wx[..n], &mut self.wy[..n]);
        for i in 0..n {
            let x = xs[i].max(0.0).min(wm);
            let y = ys[i].max(0.0).min(hm);
            // SAFETY: `max` maps NaN to 0, so `x, y` are finite and in `0..=2²⁴` (within
            // `0..=w−1`, `0..=h−1`): the conversions are exact truncations, i.e. floor.
            // (Unchecked, they vectorise; `as` adds saturation and NaN handling.)
            let (x0, y0) = unsafe { (x.to_int_unchecked::<i32>(), y.to_int_unchecked::<i32>()) };
            wx[i] = x - x0 as f32;
            wy[i] = y - y0 as f32;
            let (x0, y0) = (x0 as u32, y0 as u32);
            sx[i] = (x0 < w - 1) as u32;
            sy[i] = if y0 < h - 1 { w } else { 0 };
            base[i] = y0 * w + x0;
        }
    }

    /// Grey bilinear sample `i`.
    #[inline(always)]
    fn gray(&self, d: &[f32], i: usize) -> f32 {
        let b = self.base[i] as usize;
        let (sx, sy) = (self.sx[i] as usize, self.sy[i] as usize);
        let (wx, wy) = (self.wx[i], self.wy[i]);
        let top = d[b] + (d[b + sx] - d[b]) * wx;
        let bot = d[b + sy] + (d[b + sy + sx] - d[b + sy]) * wx;
        top + (bot - top) * wy
    }

    /// Adds `scale ×` the premultiplied colour bilinear sample `i` to `acc`.
    #[inline(always)]
    fn add_pm(&self, d: &[[f32; 4]], i: usize, scale: f32, acc: &mut [f32; 4]) {
        let b = self.base[i] as usize;
        let (sx, sy) = (self.sx[i] as usize, self.sy[i] as usize);
        let (wx, wy) = (self.wx[i], self.wy[i]);
        let (ux, uy) = (1.0 - wx, 1.0 - wy);
        // One bounds check for the four taps: `fill` clamps the position into the frame, so
        // `b + sy + sx` (the largest) is within it when `d` is the frame the taps were made
        // for; the check keeps a mismatched `d` a panic, not undefined behaviour.
        assert!(b + sy + sx < d.len(), "taps outside the frame");
        // SAFETY: `b ≤ b + sx`, `b + sy ≤ b + sy + sx < d.len()` (checked above).
        let taps = unsafe {
            [
                (*d.get_unchecked(b), ux * uy),
                (*d.get_unchecked(b + sx), wx * uy),
                (*d.get_unchecked(b + sy), ux * wy),
                (*d.get_unchecked(b + sy + sx), wx * wy),
            ]
        };
        for (p, k) in taps {
            // `[r, g, b, 1] · a` in one 4-lane product (the compiler vectorises it).
            let a = p[3] * k * scale;
            let q = [p[0], p[1], p[2], 1.0];
            for c in 0..4 {
                acc[c] += q[c] * a;
            }
        }
    }
}

/// Per-thread scratch of a warp or morph row.
struct RowScratch {
    /// One field row (see [`FieldMap::row`]), grown to the field's width on first use.
    v: Vec<[f32; 2]>,
    fa: Vec<[f32; 2]>,
    fb: Vec<[f32; 2]>,
    xs: Vec<f32>,
    ys: Vec<f32>,
    ka: RowTaps,
    kb: RowTaps,
    wa: Vec<f32>,
}

impl RowScratch {
    fn new(n: usize) -> RowScratch {
        RowScratch {
            v: Vec::new(),
            fa: vec![[0.0; 2]; n],
            fb: vec![[0.0; 2]; n],
            xs: vec![0.0; n],
            ys: vec![0.0; n],
            ka: RowTaps::new(n),
            kb: RowTaps::new(n),
            wa: vec![0.0; n],
        }
    }

    /// Taps into `ka` for `x + t·F(x)` along row `y`, `F` read through `map`.
    #[inline(always)]
    fn warp_taps(&mut self, map: &FieldMap<'_>, y: usize, t: f32, size: Size) {
        self.v.resize(map.field_width(), [0.0; 2]);
        map.row(y, &mut self.fa, &mut self.v);
        RowScratch::along(&mut self.xs, &mut self.ys, &self.fa, y, t);
        self.ka.fill(&self.xs, &self.ys, size.width, size.height);
    }

    /// Taps into `ka` for `x + t·v(x)` along row `y` of the vectors `v`.
    #[inline(always)]
    fn along(xs: &mut [f32], ys: &mut [f32], v: &[[f32; 2]], y: usize, t: f32) {
        let yf = y as f32;
        for (x, ((px, py), v)) in xs.iter_mut().zip(ys.iter_mut()).zip(v).enumerate() {
            *px = x as f32 + t * v[0];
            *py = yf + t * v[1];
        }
    }
}

/// The one parallel row loop of every warp and morph: `row(y, scratch, out_row)` for each
/// row of a `size` output, with per-thread scratch (rows are independent, so the result
/// does not depend on the thread count).
fn per_row<T: Clone + Send + Sync>(
    size: Size,
    zero: T,
    row: impl Fn(usize, &mut RowScratch, &mut [T]) + Send + Sync,
) -> Vec<T> {
    let w = size.width as usize;
    let mut out = vec![zero; size.pixels()];
    out.par_chunks_mut(w)
        .enumerate()
        .for_each_init(|| RowScratch::new(w), |s, (y, r)| row(y, s, r));
    out
}

/// Calls `f(i, c)` with the consistency map `occ` (of `occ_size`) sampled at each frame
/// position `(xs[i], ys[i])` of a `w × h` frame.
#[inline(always)]
fn occlusion_at(
    occ: &[f32],
    occ_size: Size,
    (w, h): (u32, u32),
    xs: &[f32],
    ys: &[f32],
    mut f: impl FnMut(usize, f32),
) {
    let (rx, ry) = (
        occ_size.width as f32 / w as f32,
        occ_size.height as f32 / h as f32,
    );
    let v = View::new(occ, occ_size);
    for (i, (&x, &y)) in xs.iter().zip(ys).enumerate() {
        f(
            i,
            sample_gray(v, (x + 0.5) * rx - 0.5, (y + 0.5) * ry - 0.5),
        );
    }
}

#[inline(always)]
fn sample_gray(src: View<f32>, x: f32, y: f32) -> f32 {
    let (i, k) = src.taps(x, y);
    src.d[i[0]] * k[0] + src.d[i[1]] * k[1] + src.d[i[2]] * k[2] + src.d[i[3]] * k[3]
}

#[inline(always)]
fn unpremultiply(p: [f32; 4]) -> [f32; 4] {
    if p[3] > 1e-8 {
        let inv = 1.0 / p[3];
        [p[0] * inv, p[1] * inv, p[2] * inv, p[3]]
    } else {
        [0.0; 4]
    }
}

/// Options of [`morph_gray_with`] / [`morph_rgba_with`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MorphParams {
    /// Occlusion-aware weights: the forward–backward error, in frame pixels, at which a
    /// side's weight halves (see [`morph_gray`]). `None` (the default) gives the plain
    /// `(1−t, t)` weights, which measured better on real fire footage (`ignis bench flow`,
    /// `morph_vs_blend`); occlusion weights favour one side where the flows disagree, so
    /// they keep more detail on hard cuts. Range: finite, > 0.
    pub occlusion_px: Option<f32>,
}

impl MorphParams {
    /// Checks `occlusion_px`.
    pub fn validate(&self) -> Result<()> {
        match self.occlusion_px {
            Some(s) if !(s.is_finite() && s > 0.0) => Err(FlowError::bad(
                "occlusion_px",
                format!("{s} must be a finite number of pixels > 0, e.g. 1.0, or None"),
            )),
            _ => Ok(()),
        }
    }
}

/// Forward–backward consistency weight of every pixel of the field `f` (from frame A to
/// frame B) against `g` (B to A), on `f`'s grid: `1 / (1 + (e/σ)²)` with
/// `e = |f(x) + g(x + f(x))|` measured in pixels of `frame` size.
fn consistency(f: &FlowField, g: &FlowField, frame: Size, sigma: f32) -> Vec<f32> {
    let fs = f.size();
    let gs = g.size();
    // f's vectors in g's pixels, and errors back in frame pixels.
    let (fgx, fgy) = (
        gs.width as f32 / fs.width as f32,
        gs.height as f32 / fs.height as f32,
    );
    let (ex, ey) = (
        frame.width as f32 / gs.width as f32,
        frame.height as f32 / gs.height as f32,
    );
    let w = fs.width as usize;
    let mut out = vec![0.0f32; fs.pixels()];
    out.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, o) in row.iter_mut().enumerate() {
            let v = f.data()[y * w + x];
            // Position of this pixel centre in g's grid, then moved along f.
            let gx = (x as f32 + 0.5) * fgx - 0.5 + v[0] * fgx;
            let gy = (y as f32 + 0.5) * fgy - 0.5 + v[1] * fgy;
            let back = g.at(gx, gy);
            let dx = (v[0] * fgx + back[0]) * ex;
            let dy = (v[1] * fgy + back[1]) * ey;
            let e2 = (dx * dx + dy * dy) / (sigma * sigma);
            *o = 1.0 / (1.0 + e2);
        }
    });
    out
}

/// Checks `t`, the options and the frames' sizes for the morphs.
fn check_morph(a: Size, b: Size, t: f32, p: &MorphParams) -> Result<()> {
    if a != b {
        return Err(FlowError::SizeMismatch(format!(
            "morph between a {a} and a {b} frame; resize one so both have the same size"
        )));
    }
    if !(0.0..=1.0).contains(&t) {
        return Err(FlowError::bad(
            "t",
            format!("{t} is outside 0..=1; 0 gives the first frame, 1 the second"),
        ));
    }
    p.validate()
}

/// A zero field of one pixel standing in for a field with no pixels (only reachable
/// through a `Size` built without [`Size::new`]).
fn nonempty(f: &FlowField) -> std::borrow::Cow<'_, FlowField> {
    if f.data().is_empty() {
        std::borrow::Cow::Owned(FlowField::zero(Size {
            width: 1,
            height: 1,
        }))
    } else {
        std::borrow::Cow::Borrowed(f)
    }
}

/// Consistency maps of both sides, on their fields' grids.
struct Occlusion {
    ca: Vec<f32>,
    cb: Vec<f32>,
    ca_size: Size,
    cb_size: Size,
}

/// Per-pixel sampling plan of a morph: where to read A and B and with what weights.
struct MorphPlan<'a> {
    fwd: FieldMap<'a>,
    bwd: FieldMap<'a>,
    occ: Option<Occlusion>,
    t: f32,
    size: Size,
}

impl<'a> MorphPlan<'a> {
    fn new(
        size: Size,
        fwd: &'a FlowField,
        bwd: &'a FlowField,
        t: f32,
        p: &MorphParams,
    ) -> MorphPlan<'a> {
        let occ = p.occlusion_px.map(|sigma| {
            let (ca, cb) = rayon::join(
                || consistency(fwd, bwd, size, sigma),
                || consistency(bwd, fwd, size, sigma),
            );
            Occlusion {
                ca,
                cb,
                ca_size: fwd.size(),
                cb_size: bwd.size(),
            }
        });
        MorphPlan {
            fwd: FieldMap::new(fwd, size),
            bwd: FieldMap::new(bwd, size),
            occ,
            t,
            size,
        }
    }

    /// For row `y`: the taps into A (`s.ka`) and B (`s.kb`) and the weight of A
    /// (`s.wa`) per pixel.
    #[inline(always)]
    fn row(&self, y: usize, s: &mut RowScratch) {
        s.v.resize(self.fwd.field_width().max(self.bwd.field_width()), [0.0; 2]);
        self.fwd.row(y, &mut s.fa, &mut s.v);
        self.bwd.row(y, &mut s.fb, &mut s.v);
        let t = self.t;
        let (w, h) = (self.size.width, self.size.height);
        RowScratch::along(&mut s.xs, &mut s.ys, &s.fa, y, -t);
        s.ka.fill(&s.xs, &s.ys, w, h);
        let occ = self.occ.as_ref();
        let wa = &mut s.wa;
        if let Some(occ) = occ {
            occlusion_at(&occ.ca, occ.ca_size, (w, h), &s.xs, &s.ys, |i, c| wa[i] = c);
        }
        RowScratch::along(&mut s.xs, &mut s.ys, &s.fb, y, -(1.0 - t));
        s.kb.fill(&s.xs, &s.ys, w, h);
        match occ {
            None => wa.fill(1.0 - t),
            Some(occ) => occlusion_at(&occ.cb, occ.cb_size, (w, h), &s.xs, &s.ys, |i, cb| {
                let a = (1.0 - t) * wa[i].max(1e-3);
                let b = t * cb.max(1e-3);
                wa[i] = a / (a + b);
            }),
        }
    }
}

/// The in-between frame at time `t ∈ [0, 1]` from `a` (t = 0) to `b` (t = 1):
/// `(1−t)·a(x − t·F_ab(x)) + t·b(x − (1−t)·F_ba(x))`, with `fwd = F_ab`, `bwd = F_ba`
/// (e.g. from [`crate::flow_pair`]). Plain weights; see [`morph_gray_with`] for the
/// occlusion-aware variant.
///
/// `a` and `b` must have the same size (else [`FlowError::SizeMismatch`]); the fields may
/// have any size and are resampled to the frames' (vectors scaled). `t` outside `0..=1`
/// is a [`FlowError::BadParameter`].
pub fn morph_gray(
    a: &GrayFrame,
    b: &GrayFrame,
    fwd: &FlowField,
    bwd: &FlowField,
    t: f32,
) -> Result<GrayFrame> {
    morph_gray_with(a, b, fwd, bwd, t, &MorphParams::default())
}

/// [`morph_gray`] with options. With `occlusion_px = Some(σ)` the weights are
/// `wA ∝ (1−t)·cA` and `wB ∝ t·cB`, normalised to sum 1, where `cA = 1/(1 + (e/σ)²)` is
/// the forward–backward consistency of `F_ab` at the point read from `a`
/// (`e = |F_ab(p) + F_ba(p + F_ab(p))|` in frame pixels; likewise `cB` for `F_ba` at the
/// point read from `b`): where both flows agree this is the plain blend; where one side's
/// motion is not confirmed by the other flow (an occlusion or a mismatch) the other side
/// dominates.
pub fn morph_gray_with(
    a: &GrayFrame,
    b: &GrayFrame,
    fwd: &FlowField,
    bwd: &FlowField,
    t: f32,
    p: &MorphParams,
) -> Result<GrayFrame> {
    let size = a.size();
    check_morph(size, b.size(), t, p)?;
    if size.pixels() == 0 {
        return Ok(a.clone());
    }
    let (fwd, bwd) = (nonempty(fwd), nonempty(bwd));
    let plan = MorphPlan::new(size, &fwd, &bwd, t, p);
    let (da, db) = (a.data(), b.data());
    let out = per_row(size, 0.0f32, |y, s, row| {
        plan.row(y, s);
        for (i, o) in row.iter_mut().enumerate() {
            let k = s.wa[i];
            *o = k * s.ka.gray(da, i) + (1.0 - k) * s.kb.gray(db, i);
        }
    });
    Ok(GrayFrame::from_vec(size, out).expect("sized from a"))
}

/// [`morph_gray`] for colour frames, blended on premultiplied values.
pub fn morph_rgba(
    a: &RgbaFrame,
    b: &RgbaFrame,
    fwd: &FlowField,
    bwd: &FlowField,
    t: f32,
) -> Result<RgbaFrame> {
    morph_rgba_with(a, b, fwd, bwd, t, &MorphParams::default())
}

/// [`morph_gray_with`] for colour frames, blended on premultiplied values.
pub fn morph_rgba_with(
    a: &RgbaFrame,
    b: &RgbaFrame,
    fwd: &FlowField,
    bwd: &FlowField,
    t: f32,
    p: &MorphParams,
) -> Result<RgbaFrame> {
    let size = a.size();
    check_morph(size, b.size(), t, p)?;
    if size.pixels() == 0 {
        return Ok(a.clone());
    }
    let (fwd, bwd) = (nonempty(fwd), nonempty(bwd));
    let plan = MorphPlan::new(size, &fwd, &bwd, t, p);
    let (da, db) = (a.data(), b.data());
    let out = per_row(size, [0.0f32; 4], |y, s, row| {
        plan.row(y, s);
        for (i, o) in row.iter_mut().enumerate() {
            let k = s.wa[i];
            let mut acc = [0.0f32; 4];
            s.ka.add_pm(da, i, k, &mut acc);
            s.kb.add_pm(db, i, 1.0 - k, &mut acc);
            *o = unpremultiply(acc);
        }
    });
    Ok(RgbaFrame::from_vec(size, out).expect("sized from a"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(w: u32, h: u32) -> GrayFrame {
        GrayFrame::from_fn(Size::new(w, h).unwrap(), |x, y| x as f32 + 10.0 * y as f32)
    }

    #[test]
    fn warp_by_a_constant_shift_reads_the_shifted_pixel() {
        let g = ramp(8, 6);
        let f = FlowField::from_vec(g.size(), vec![[1.0, 2.0]; 48]).unwrap();
        let o = warp_gray(&g, &f, 1.0);
        assert_eq!(o.get(2, 1), g.get(3, 3));
        let o = warp_gray(&g, &f, 0.5);
        assert!((o.get(2, 1) - (2.5 + 20.0)).abs() < 1e-5);
        // A half-size field scales its vectors.
        let half = FlowField::from_vec(Size::new(4, 3).unwrap(), vec![[0.5, 1.0]; 12]).unwrap();
        assert_eq!(warp_gray(&g, &half, 1.0).get(2, 1), g.get(3, 3));
    }

    #[test]
    fn warp_rows_are_the_premultiplied_warp() {
        let s = Size::new(9, 7).unwrap();
        let src = RgbaFrame::from_vec(
            s,
            (0..63)
                .map(|i| {
                    let v = i as f32;
                    [
                        v * 0.1,
                        (v * 0.37).sin().abs(),
                        1.0 / (1.0 + v),
                        (i % 5) as f32 / 4.0,
                    ]
                })
                .collect(),
        )
        .unwrap();
        // A half-size field with varied vectors, and the empty field (identity).
        let fs = Size::new(5, 4).unwrap();
        let f = FlowField::from_vec(
            fs,
            (0..20)
                .map(|i| [(i % 3) as f32 - 1.2, (i % 4) as f32 * 0.7 - 1.0])
                .collect(),
        )
        .unwrap();
        let empty = FlowField::zero(Size {
            width: 0,
            height: 0,
        });
        for (field, t) in [(&f, 0.6f32), (&f, -0.3), (&empty, 0.5)] {
            let want = warp_rgba(&src, field, t);
            let rows = WarpRows::new(&src, field, t);
            let mut got = vec![[0.0f32; 4]; 63];
            // In two bands, as a caller's band loop would.
            let (top, bottom) = got.split_at_mut(3 * 9);
            rows.rows(0, top);
            rows.rows(3, bottom);
            for (g, p) in got.iter().zip(want.data()) {
                let pm = [p[0] * p[3], p[1] * p[3], p[2] * p[3], p[3]];
                for c in 0..4 {
                    assert!((g[c] - pm[c]).abs() < 1e-5, "{g:?} vs {pm:?}");
                }
            }
        }
    }

    #[test]
    fn transparent_pixels_do_not_bleed() {
        let s = Size::new(2, 1).unwrap();
        let src = RgbaFrame::from_vec(s, vec![[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 0.0]]).unwrap();
        let f = FlowField::from_vec(s, vec![[0.5, 0.0]; 2]).unwrap();
        let o = warp_rgba(&src, &f, 1.0);
        let p = o.get(0, 0);
        assert!(
            (p[0] - 1.0).abs() < 1e-6 && p[1] == 0.0 && (p[3] - 0.5).abs() < 1e-6,
            "{p:?}"
        );
    }

    #[test]
    fn morph_endpoints_and_errors() {
        let a = ramp(6, 5);
        let b = a.map(|v| v + 1.0);
        let z = FlowField::zero(a.size());
        let m0 = morph_gray(&a, &b, &z, &z, 0.0).unwrap();
        let m1 = morph_gray(&a, &b, &z, &z, 1.0).unwrap();
        assert_eq!(m0, a);
        assert_eq!(m1, b);
        let mid = morph_gray(&a, &b, &z, &z, 0.5).unwrap();
        assert!((mid.get(3, 2) - (a.get(3, 2) + 0.5)).abs() < 1e-5);
        assert!(morph_gray(&a, &b, &z, &z, 1.5).is_err());
        assert!(morph_gray(&a, &b, &z, &z, f32::NAN).is_err());
        assert!(morph_gray(&a, &ramp(5, 5), &z, &z, 0.5).is_err());
        for bad in [0.0, -1.0, f32::NAN, f32::INFINITY] {
            let p = MorphParams {
                occlusion_px: Some(bad),
            };
            assert!(morph_gray_with(&a, &b, &z, &z, 0.5, &p).is_err());
        }
    }

    #[test]
    fn consistency_weights() {
        let s = Size::new(8, 4).unwrap();
        let fwd = FlowField::from_vec(s, vec![[3.0, 0.0]; 32]).unwrap();
        let bwd = FlowField::from_vec(s, vec![[-3.0, 0.0]; 32]).unwrap();
        // Opposite flows agree: full weight everywhere.
        assert!(consistency(&fwd, &bwd, s, 1.0)
            .iter()
            .all(|&v| (v - 1.0).abs() < 1e-6));
        // A 3-px disagreement: 1 / (1 + 9).
        let z = FlowField::zero(s);
        assert!(consistency(&fwd, &z, s, 1.0)
            .iter()
            .all(|&v| (v - 0.1).abs() < 1e-6));
        // Measured in frame pixels: the same fields at half size for a frame twice as big.
        let big = Size::new(16, 8).unwrap();
        let c = consistency(&fwd, &z, big, 1.0);
        assert!(
            c.iter().all(|&v| (v - 1.0 / 37.0).abs() < 1e-6),
            "{:?}",
            c[0]
        );
        // Consistent flows: the occlusion-aware morph is the plain formula.
        let a = GrayFrame::from_fn(s, |x, _| x as f32);
        let b = GrayFrame::from_fn(s, |x, _| x as f32 - 3.0);
        let occ = MorphParams {
            occlusion_px: Some(1.0),
        };
        let m = morph_gray_with(&a, &b, &fwd, &bwd, 0.5, &occ).unwrap();
        let ws = warp_gray(&a, &fwd, -0.5);
        let wb = warp_gray(&b, &bwd, -0.5);
        for i in 0..32 {
            let want = 0.5 * ws.data()[i] + 0.5 * wb.data()[i];
            assert!((m.data()[i] - want).abs() < 1e-5);
        }
    }
}

#[cfg(test)]
mod occlusion_tests {
    use super::*;

    /// Where only B's motion is confirmed by the other flow, the occlusion-aware mid frame
    /// leans on B; the plain one stays 50/50.
    #[test]
    fn unconfirmed_side_is_down_weighted() {
        let s = Size::new(16, 4).unwrap();
        let a = GrayFrame::from_fn(s, |_, _| 0.0);
        let b = GrayFrame::from_fn(s, |_, _| 1.0);
        // Backward −2 px everywhere; forward +2 px on the left half, 0 on the right.
        // cA(p) = 1/(1 + |fwd(p) − 2|²): 1 on the left, 0.2 on the right.
        // cB(q) = 1/(1 + |fwd(q − 2) − 2|²): 1 for q < 10, 0.2 from q = 10.
        let fwd = FlowField::from_vec(
            s,
            (0..64)
                .map(|i| if i % 16 < 8 { [2.0, 0.0] } else { [0.0, 0.0] })
                .collect(),
        )
        .unwrap();
        let bwd = FlowField::from_vec(s, vec![[-2.0, 0.0]; 64]).unwrap();
        let plain = morph_gray(&a, &b, &fwd, &bwd, 0.5).unwrap();
        assert!(plain.data().iter().all(|&v| (v - 0.5).abs() < 1e-6));
        let p = MorphParams {
            occlusion_px: Some(1.0),
        };
        let occ = morph_gray_with(&a, &b, &fwd, &bwd, 0.5, &p).unwrap();
        // x = 8: A is read at 8 (cA = 0.2), B at 9 (cB = 1): weight of A = 0.1 / 0.6.
        assert!(
            (occ.get(8, 1) - 5.0 / 6.0).abs() < 1e-5,
            "{}",
            occ.get(8, 1)
        );
        // Both confirmed (x = 3) or both unconfirmed (x = 12): the plain blend.
        assert!((occ.get(3, 1) - 0.5).abs() < 1e-5);
        assert!((occ.get(12, 1) - 0.5).abs() < 1e-5);
    }
}
