//! The generic flame model: deformation parameters from slice moments, normalisation of
//! the flame image, and the inverse (rendering) warp.
//!
//! Source: stich-magnor-learning-flames.txt §3.1 (deformation parameters), §3.2
//! (eigenflames are fitted on the images this module normalises).
//!
//! Per frame:
//! 0. Bright regions other than the main flame (reflections, a lit rim, sparks) are
//!    blacked out ([`drop_other_regions`]), so one flame is modelled.
//! 1. The global moments give the [`Pose`]: centroid, main-axis tilt and the height
//!    measure `σ_v` (deviation along the main axis). Coordinates become `(u, v)`: `v` up the
//!    main axis, `u` across it, both in units of `σ_v` and centred on the centroid.
//! 2. The canonical range `v ∈ [−below, above]` is cut into `n_path` (and `n_width`)
//!    equal height slices; each slice's own moments give its centroid across the axis (the
//!    *path*) and its deviation (the *width*).
//! 3. Natural cubic splines through the slice values give path and width at every row.
//! 4. The normalised image (`size × size`) samples the frame at
//!    `u = path(v) + u' · width(v)`, i.e. every slice is centred and scaled to unit width,
//!    and is scaled to the clip's average intensity.
//!
//! Rendering inverts steps 1–4 for every output pixel (one smooth warp).
//!
//! *Departures:* the sign of the main axis is fixed by "flames burn upwards"; the
//! normalised intensity gain is not part of the state (as in the paper's 26 parameters),
//! so per-frame brightness flicker lives only in the eigenflame weights.

mod avx2;

use crate::error::{LearnedError, Result};
use crate::moments::{Moments, Pose};
use crate::spline::{natural_cubic, SplinePlan};
use ignis_core::{GrayFrame, Size};
use serde::{Deserialize, Serialize};

/// Settings of the flame model.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShapeParams {
    /// `N_p`, path parameters (slices), 2..=64. Default 10 (§5).
    pub n_path: usize,
    /// `N_w`, width parameters (slices), 2..=64. Default 10 (§5).
    pub n_width: usize,
    /// `N_e`, eigenflames kept, 1..=64. Default 5 (§5).
    pub n_eigen: usize,
    /// Side of the normalised images in pixels, 16..=256. Default 64.
    pub norm_size: u32,
    /// Canonical extent below the centroid along the main axis, in `σ_v`. Default 2.2.
    pub below: f64,
    /// Canonical extent above the centroid, in `σ_v`. Default 3.2.
    pub above: f64,
    /// Canonical half-width across the axis, in slice widths. Default 3.5.
    pub half_width: f64,
    /// Skip frames whose thresholded flame has more than one sizeable component (§5).
    /// Default true. Kept frames (all of them when false) are modelled by their main
    /// flame only: other bright regions are blacked out first ([`drop_other_regions`]).
    pub skip_multiple: bool,
    /// Threshold for the component test, as a fraction of the frame's maximum. Default 0.2.
    pub component_threshold: f32,
    /// A component counts if it holds at least this fraction of the thresholded area.
    /// Default 0.03.
    pub min_component: f32,
    /// Linear intensity subtracted from every pixel (clamped at 0) before anything else,
    /// to drop a lit background such as a candle's glowing wax, ≥ 0. Default 0.
    #[serde(default)]
    pub black_level: f32,
}

impl Default for ShapeParams {
    fn default() -> Self {
        ShapeParams {
            n_path: 10,
            n_width: 10,
            n_eigen: 5,
            norm_size: 64,
            below: 2.2,
            above: 3.2,
            half_width: 3.5,
            skip_multiple: true,
            component_threshold: 0.2,
            min_component: 0.03,
            black_level: 0.0,
        }
    }
}

impl ShapeParams {
    pub fn validate(&self) -> Result<()> {
        for (name, v, lo, hi) in [
            ("n_path", self.n_path, 2, 64),
            ("n_width", self.n_width, 2, 64),
            ("n_eigen", self.n_eigen, 1, 64),
            ("norm_size", self.norm_size as usize, 16, 256),
        ] {
            if !(lo..=hi).contains(&v) {
                return Err(LearnedError::bad(
                    name,
                    format!("{v} is outside {lo}..={hi}"),
                ));
            }
        }
        for (name, v) in [
            ("below", self.below),
            ("above", self.above),
            ("half_width", self.half_width),
        ] {
            if !(v > 0.0 && v <= 20.0) {
                return Err(LearnedError::bad(name, format!("{v} must be in (0, 20]")));
            }
        }
        if !(self.black_level >= 0.0 && self.black_level.is_finite()) {
            return Err(LearnedError::bad(
                "black_level",
                format!("{} must be ≥ 0", self.black_level),
            ));
        }
        Ok(())
    }

    /// Number of shape parameters `N_p + N_w + 1`.
    pub fn n_shape(&self) -> usize {
        self.n_path + self.n_width + 1
    }

    /// Length of the full state `N_p + N_w + 1 + N_e`.
    pub fn n_state(&self) -> usize {
        self.n_shape() + self.n_eigen
    }

    /// `v` of normalised row `r` (top row = `above`).
    pub(crate) fn row_v(&self, r: f64) -> f64 {
        self.above - (r + 0.5) / self.norm_size as f64 * (self.above + self.below)
    }

    /// Centres of `n` equal slices of `[−below, above]`, bottom to top.
    fn slice_centres(&self, n: usize) -> Vec<f64> {
        let h = (self.above + self.below) / n as f64;
        (0..n).map(|i| -self.below + (i as f64 + 0.5) * h).collect()
    }
}

/// The shape of one frame: path and width per slice (bottom to top, `σ_v` units), and the
/// height `σ_v` as a fraction of the frame height.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Shape {
    pub path: Vec<f64>,
    pub width: Vec<f64>,
    pub height: f64,
}

impl Shape {
    /// `[path…, width…, height]`.
    pub fn to_vec(&self) -> Vec<f64> {
        let mut v = self.path.clone();
        v.extend_from_slice(&self.width);
        v.push(self.height);
        v
    }
}

/// Why a frame was not used.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Skip {
    /// No intensity at all.
    Dark,
    /// More than one disjoint flame (§5).
    Multiple,
}

/// Bilinear sample with zero outside; `(x, y)` in pixel-centre coordinates of `data`.
#[inline]
fn bilinear(data: &[f32], w: usize, h: usize, x: f64, y: f64) -> f32 {
    let (fx, fy) = (x - 0.5, y - 0.5);
    let (x0, y0) = (fx.floor(), fy.floor());
    let (tx, ty) = ((fx - x0) as f32, (fy - y0) as f32);
    let (x0, y0) = (x0 as isize, y0 as isize);
    let at = |xi: isize, yi: isize| -> f32 {
        if xi < 0 || yi < 0 || xi >= w as isize || yi >= h as isize {
            0.0
        } else {
            data[yi as usize * w + xi as usize]
        }
    };
    let top = at(x0, y0) * (1.0 - tx) + at(x0 + 1, y0) * tx;
    let bot = at(x0, y0 + 1) * (1.0 - tx) + at(x0 + 1, y0 + 1) * tx;
    top * (1.0 - ty) + bot * ty
}

/// Box-filters `frame` down by an integer factor (anti-aliasing before resampling).
fn box_down(frame: &GrayFrame, f: usize) -> (Vec<f32>, usize, usize) {
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    if f <= 1 {
        return (frame.data().to_vec(), w, h);
    }
    let (dw, dh) = (w.div_ceil(f), h.div_ceil(f));
    let mut out = vec![0.0f32; dw * dh];
    let mut cnt = vec![0u32; dw * dh];
    for (y, row) in frame.rows().enumerate() {
        let o = (y / f) * dw;
        for (x, &v) in row.iter().enumerate() {
            out[o + x / f] += v;
            cnt[o + x / f] += 1;
        }
    }
    out.iter_mut().zip(&cnt).for_each(|(v, &c)| *v /= c as f32);
    (out, dw, dh)
}

/// Counts sizeable 4-connected components above `thr · max` (on a ≤ 128-pixel
/// downsampled copy, so a 480² frame costs little).
pub fn count_flames(frame: &GrayFrame, thr: f32, min_frac: f32) -> usize {
    let f = (frame.width().max(frame.height()) as usize).div_ceil(128);
    let (d, w, h) = box_down(frame, f);
    let max = d.iter().copied().fold(0.0f32, f32::max);
    if max <= 0.0 {
        return 0;
    }
    let mask: Vec<bool> = d.iter().map(|&v| v > thr * max).collect();
    let total = mask.iter().filter(|&&m| m).count();
    let mut label = vec![false; w * h];
    let mut stack = Vec::new();
    let mut count = 0;
    for start in 0..w * h {
        if !mask[start] || label[start] {
            continue;
        }
        let mut area = 0usize;
        label[start] = true;
        stack.push(start);
        while let Some(i) = stack.pop() {
            area += 1;
            let (x, y) = (i % w, i / w);
            let mut visit = |j: usize| {
                if mask[j] && !label[j] {
                    label[j] = true;
                    stack.push(j);
                }
            };
            if x > 0 {
                visit(i - 1);
            }
            if x + 1 < w {
                visit(i + 1);
            }
            if y > 0 {
                visit(i - w);
            }
            if y + 1 < h {
                visit(i + w);
            }
        }
        if area as f32 >= min_frac * total as f32 {
            count += 1;
        }
    }
    count
}

/// Labels the 4-connected components of `mask` (`w × h`): 0 outside, 1.. inside.
fn label_components(mask: &[bool], w: usize, h: usize) -> (Vec<u32>, u32) {
    let mut label = vec![0u32; w * h];
    let mut stack = Vec::new();
    let mut n = 0;
    for start in 0..w * h {
        if !mask[start] || label[start] != 0 {
            continue;
        }
        n += 1;
        label[start] = n;
        stack.push(start);
        while let Some(i) = stack.pop() {
            let (x, y) = (i % w, i / w);
            let near = [
                (x > 0).then(|| i - 1),
                (x + 1 < w).then(|| i + 1),
                (y > 0).then(|| i - w),
                (y + 1 < h).then(|| i + w),
            ];
            for j in near.into_iter().flatten() {
                if mask[j] && label[j] == 0 {
                    label[j] = n;
                    stack.push(j);
                }
            }
        }
    }
    (label, n)
}

/// The frame with every bright region but the main flame blacked out, or `None` when
/// there is nothing to drop.
///
/// Footage of one flame holds other lit regions: its reflection in a glass, a lit rim,
/// sparks. Left in, they pull the slice moments sideways (a bent tip) and the eigenflames
/// learn them as a second shape. Regions are the 4-connected components above a quarter of
/// the component threshold (`thr · max / 4`, low, so a flame's dim edge stays attached to
/// it) on the same ≤ 128-pixel copy as [`count_flames`]; the main flame is the one holding
/// the most light. The others, grown by one cell, are set to zero; the main flame's glow
/// between regions is kept.
pub fn drop_other_regions(frame: &GrayFrame, thr: f32) -> Option<GrayFrame> {
    let f = (frame.width().max(frame.height()) as usize).div_ceil(128);
    let (d, w, h) = box_down(frame, f);
    let max = d.iter().copied().fold(0.0f32, f32::max);
    if !(max > 0.0) {
        return None;
    }
    let lo = 0.25 * thr * max;
    let mask: Vec<bool> = d.iter().map(|&v| v > lo).collect();
    let (label, n) = label_components(&mask, w, h);
    if n <= 1 {
        return None;
    }
    let mut mass = vec![0.0f64; n as usize + 1];
    label
        .iter()
        .zip(&d)
        .for_each(|(&l, &v)| mass[l as usize] += v as f64);
    let main = (1..=n)
        .max_by(|&a, &b| mass[a as usize].total_cmp(&mass[b as usize]))
        .expect("n ≥ 2");
    // Cells to black out: other regions and their 8-neighbours outside the main flame.
    let mut drop = vec![false; w * h];
    for y in 0..h {
        for x in 0..w {
            let l = label[y * w + x];
            if l == 0 || l == main {
                continue;
            }
            for yy in y.saturating_sub(1)..(y + 2).min(h) {
                for xx in x.saturating_sub(1)..(x + 2).min(w) {
                    if label[yy * w + xx] != main {
                        drop[yy * w + xx] = true;
                    }
                }
            }
        }
    }
    let mut out = frame.clone();
    for (y, row) in out.rows_mut().enumerate() {
        let o = (y / f) * w;
        for (x, v) in row.iter_mut().enumerate() {
            if drop[o + x / f] {
                *v = 0.0;
            }
        }
    }
    Some(out)
}

/// The result of normalising one frame.
#[derive(Clone, Debug)]
pub struct Normalised {
    pub pose: Pose,
    pub shape: Shape,
    /// `norm_size²` values, row-major, not yet scaled to the clip's average intensity.
    pub image: Vec<f32>,
}

/// Normalises one frame (§3.1): pose, slice moments, path/width splines and the
/// normalised image.
pub fn normalise(frame: &GrayFrame, p: &ShapeParams) -> std::result::Result<Normalised, Skip> {
    let levelled;
    let frame = if p.black_level > 0.0 {
        levelled = frame.map(|v| (v - p.black_level).max(0.0));
        &levelled
    } else {
        frame
    };
    if frame.max() > 0.0
        && p.skip_multiple
        && count_flames(frame, p.component_threshold, p.min_component) > 1
    {
        return Err(Skip::Multiple);
    }
    let isolated = drop_other_regions(frame, p.component_threshold);
    let frame = isolated.as_ref().unwrap_or(frame);
    let moments = Moments::of(frame);
    let pose = match moments.pose() {
        Some(pose) if pose.sigma_v > 0.25 && frame.max() > 0.0 => pose,
        _ => return Err(Skip::Dark),
    };
    let ns = p.norm_size as usize;
    let sv = pose.sigma_v;
    // Anti-alias: the canonical grid spacing along v in source pixels.
    let step = (p.above + p.below) * sv / ns as f64;
    let f = (step / 1.5).floor().max(1.0) as usize;
    let (src, sw, sh) = box_down(frame, f);
    let inv_f = 1.0 / f as f64;
    let (upx, upy) = pose.up();
    let (rx, ry) = pose.right();
    let sample = |u: f64, v: f64| -> f32 {
        let x = pose.cx + (u * rx + v * upx) * sv;
        let y = pose.cy + (u * ry + v * upy) * sv;
        bilinear(&src, sw, sh, x * inv_f, y * inv_f)
    };

    // Upright image U: ns rows over [−below, above], square cells, for slice moments.
    let cell = (p.above + p.below) / ns as f64;
    let nu = ns;
    let u_of = |c: usize| (c as f64 + 0.5 - nu as f64 / 2.0) * cell;
    let mut rows_m = vec![[0.0f64; 3]; ns]; // per row: Σ I, Σ u I, Σ u² I
    for (r, acc) in rows_m.iter_mut().enumerate() {
        let v = p.row_v(r as f64);
        for c in 0..nu {
            let u = u_of(c);
            let i = sample(u, v) as f64;
            acc[0] += i;
            acc[1] += i * u;
            acc[2] += i * u * u;
        }
    }
    let total: f64 = rows_m.iter().map(|a| a[0]).sum();
    if !(total > 0.0) {
        return Err(Skip::Dark);
    }
    // Slice moments: n slices over the ns rows (row 0 = top), bottom to top.
    let slices = |n: usize| -> (Vec<f64>, Vec<f64>) {
        let mut path = vec![f64::NAN; n];
        let mut width = vec![f64::NAN; n];
        for (s, (pp, ww)) in path.iter_mut().zip(width.iter_mut()).enumerate() {
            // Slice s (from the bottom) covers v in [−below + s h, −below + (s+1) h].
            let lo = -p.below + s as f64 * (p.above + p.below) / n as f64;
            let hi = lo + (p.above + p.below) / n as f64;
            let mut a = [0.0f64; 3];
            for (r, m) in rows_m.iter().enumerate() {
                let v = p.row_v(r as f64);
                if v >= lo && v < hi {
                    a.iter_mut().zip(m).for_each(|(x, y)| *x += y);
                }
            }
            if a[0] > 1e-3 * total / n as f64 {
                let mu = a[1] / a[0];
                *pp = mu;
                *ww = (a[2] / a[0] - mu * mu).max(0.0).sqrt().max(0.02);
            }
        }
        fill_gaps(&mut path);
        fill_gaps(&mut width);
        (path, width)
    };
    let (path, _) = slices(p.n_path);
    let (_, width) = slices(p.n_width);
    let height = sv / frame.height() as f64;
    let shape = Shape {
        path,
        width,
        height,
    };

    // Normalised image: every row centred on path(v) and scaled by width(v).
    let (path_r, width_r) = row_profiles(&shape, p);
    let mut image = vec![0.0f32; ns * ns];
    for r in 0..ns {
        let v = p.row_v(r as f64);
        for c in 0..ns {
            let up = canonical_u(c as f64, p);
            // 2 × 2 supersampling across, where the slice width stretches the grid.
            let du = 0.25 * 2.0 * p.half_width / ns as f64;
            let dv = 0.25 * cell;
            let mut acc = 0.0;
            for (a, b) in [(-du, -dv), (du, -dv), (-du, dv), (du, dv)] {
                acc += sample(path_r[r] + (up + a) * width_r[r], v + b);
            }
            image[r * ns + c] = 0.25 * acc;
        }
    }
    Ok(Normalised { pose, shape, image })
}

/// Canonical `u'` (in slice widths) of normalised column `c`.
#[inline]
fn canonical_u(c: f64, p: &ShapeParams) -> f64 {
    -p.half_width + (c + 0.5) / p.norm_size as f64 * 2.0 * p.half_width
}

/// Replaces NaN entries by the nearest valid neighbour (0.5 if none is valid).
fn fill_gaps(v: &mut [f64]) {
    let valid: Vec<usize> = (0..v.len()).filter(|&i| v[i].is_finite()).collect();
    if valid.is_empty() {
        v.iter_mut().for_each(|x| *x = 0.5);
        return;
    }
    for i in 0..v.len() {
        if !v[i].is_finite() {
            let j = *valid
                .iter()
                .min_by_key(|&&j| j.abs_diff(i))
                .expect("non-empty");
            v[i] = v[j];
        }
    }
}

/// Path and width at the centre of every normalised row (cubic spline through the slices).
pub fn row_profiles(shape: &Shape, p: &ShapeParams) -> (Vec<f64>, Vec<f64>) {
    let ns = p.norm_size as usize;
    let at: Vec<f64> = (0..ns).map(|r| p.row_v(r as f64)).rev().collect(); // increasing v
    let mut path = vec![0.0; ns];
    let mut width = vec![0.0; ns];
    natural_cubic(
        &p.slice_centres(shape.path.len()),
        &shape.path,
        &at,
        &mut path,
    );
    natural_cubic(
        &p.slice_centres(shape.width.len()),
        &shape.width,
        &at,
        &mut width,
    );
    path.reverse();
    width.reverse();
    width.iter_mut().for_each(|w| *w = w.max(0.02));
    (path, width)
}

/// Where and how large to draw a flame: centroid in output pixels, tilt in radians.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Placement {
    pub cx: f64,
    pub cy: f64,
    pub tilt: f64,
}

/// Scratch buffers and tables for rendering (reused between frames: no allocation per frame).
#[derive(Clone, Debug, Default)]
pub struct RenderScratch {
    path: Vec<f32>,
    width_inv: Vec<f32>,
    /// [`row_profiles`] by planned splines ([`RenderScratch::row_profiles`]): the plans'
    /// key (norm size, `above`, `below` bits, slices of path and width), the plans, and the
    /// last profiles.
    plans: Option<(PlanKey, [SplinePlan; 2])>,
    path_rows: Vec<f64>,
    width_rows: Vec<f64>,
}

/// What a [`RenderScratch`]'s spline plans are for: norm size, `above` and `below` (bits),
/// path and width slices.
type PlanKey = (u32, u64, u64, usize, usize);

impl RenderScratch {
    /// [`row_profiles`]`(shape, p)` (the same values), kept in the scratch: splines planned
    /// once for `p` and the slice counts ([`SplinePlan`]). Returns `(path, width)`.
    pub(crate) fn row_profiles(&mut self, shape: &Shape, p: &ShapeParams) -> (&[f64], &[f64]) {
        let ns = p.norm_size as usize;
        let (np, nw) = (shape.path.len(), shape.width.len());
        let key = (p.norm_size, p.above.to_bits(), p.below.to_bits(), np, nw);
        if self.plans.as_ref().map(|(k, _)| *k) != Some(key) {
            let at: Vec<f64> = (0..ns).map(|r| p.row_v(r as f64)).rev().collect();
            let plans = [np, nw].map(|n| SplinePlan::new(&p.slice_centres(n), &at));
            self.plans = Some((key, plans));
        }
        let [pp, wp] = &mut self.plans.as_mut().expect("just set").1;
        self.path_rows.resize(ns, 0.0);
        self.width_rows.resize(ns, 0.0);
        pp.eval(&shape.path, &mut self.path_rows);
        wp.eval(&shape.width, &mut self.width_rows);
        self.path_rows.reverse();
        self.width_rows.reverse();
        self.width_rows.iter_mut().for_each(|w| *w = w.max(0.02));
        (&self.path_rows, &self.width_rows)
    }
}

/// Renders a normalised image back into `out` (§3.1 reversed): the flame of `shape`,
/// centred at `place`, with `σ_v = shape.height · out.height()`. `out` is overwritten.
pub fn render_into(
    normalised: &[f32],
    shape: &Shape,
    place: &Placement,
    p: &ShapeParams,
    scratch: &mut RenderScratch,
    out: &mut GrayFrame,
) {
    let h = out.height() as f64;
    render_scaled_into(normalised, shape, place, p, scratch, h, out);
}

/// As [`render_into`], into a window of a larger frame: `place` is in the window's pixels
/// and `frame_height` is the whole frame's height, which sets the flame's scale
/// (`σ_v = shape.height · frame_height`).
pub(crate) fn render_scaled_into(
    normalised: &[f32],
    shape: &Shape,
    place: &Placement,
    p: &ShapeParams,
    scratch: &mut RenderScratch,
    frame_height: f64,
    out: &mut GrayFrame,
) {
    let ns = p.norm_size as usize;
    debug_assert_eq!(normalised.len(), ns * ns);
    let (path_r, width_r) = row_profiles(shape, p);
    scratch.path.clear();
    scratch.path.extend(path_r.iter().map(|&v| v as f32));
    scratch.width_inv.clear();
    scratch
        .width_inv
        .extend(width_r.iter().map(|&w| (1.0 / w) as f32));
    let sv = (shape.height * frame_height).max(1e-3);
    let (upx, upy) = (place.tilt.sin(), -place.tilt.cos());
    let (rx, ry) = (place.tilt.cos(), place.tilt.sin());
    // Row coordinate rr = (above − v) · ns / (above + below) − 0.5; column
    // cc = (u' + half_width) · ns / (2 half_width) − 0.5.
    let kr = ns as f64 / (p.above + p.below);
    let kc = (ns as f64 / (2.0 * p.half_width)) as f32;
    let c_off = (p.half_width * ns as f64 / (2.0 * p.half_width)) as f32 - 0.5;
    let nsf = ns as f32;
    let w = out.width() as usize;
    for (y, row) in out.rows_mut().enumerate() {
        let dy = (y as f64 + 0.5 - place.cy) / sv;
        // u and v are affine in x along the row.
        let dx0 = (0.5 - place.cx) / sv;
        let u0 = (dx0 * rx + dy * ry) as f32;
        let v0 = (dx0 * upx + dy * upy) as f32;
        let du = (rx / sv) as f32;
        let dv = (upx / sv) as f32;
        let rr0 = ((p.above - v0 as f64) * kr - 0.5) as f32;
        let drr = -(dv as f64 * kr) as f32;
        for (x, o) in row.iter_mut().enumerate().take(w) {
            let xf = x as f32;
            let rr = rr0 + drr * xf;
            if !(rr > -1.0 && rr < nsf) {
                *o = 0.0;
                continue;
            }
            let u = u0 + du * xf;
            // Path and width at this row: linear between row centres.
            let rc = rr.clamp(0.0, nsf - 1.0);
            let r0 = rc as usize;
            let r1 = (r0 + 1).min(ns - 1);
            let t = rc - r0 as f32;
            let path = scratch.path[r0] + (scratch.path[r1] - scratch.path[r0]) * t;
            let winv = scratch.width_inv[r0] + (scratch.width_inv[r1] - scratch.width_inv[r0]) * t;
            let cc = (u - path) * winv * kc + c_off;
            if !(cc > -1.0 && cc < nsf) {
                *o = 0.0;
                continue;
            }
            // Bilinear in the normalised image, zero outside.
            let (fr, fc) = (rr.floor(), cc.floor());
            let (ty, tx) = (rr - fr, cc - fc);
            let (ir, ic) = (fr as isize, fc as isize);
            let at = |r: isize, c: isize| -> f32 {
                if r < 0 || c < 0 || r >= ns as isize || c >= ns as isize {
                    0.0
                } else {
                    normalised[r as usize * ns + c as usize]
                }
            };
            let top = at(ir, ic) * (1.0 - tx) + at(ir, ic + 1) * tx;
            let bot = at(ir + 1, ic) * (1.0 - tx) + at(ir + 1, ic + 1) * tx;
            *o = (top * (1.0 - ty) + bot * ty).max(0.0);
        }
    }
}

/// How [`render_encoded_into`] turns a rendered value into what a writer shows: scaled by
/// `exposure`, clamped to `0..=1` and sRGB-encoded through `lut` (`lut.len() − 1` equal
/// intervals, linear between them; at least one).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Encoding<'a> {
    pub exposure: f32,
    pub lut: &'a [f32],
}

impl Encoding<'_> {
    /// One value, encoded.
    #[inline]
    pub(crate) fn apply(&self, v: f32) -> f32 {
        let v = if self.exposure != 1.0 {
            v * self.exposure
        } else {
            v
        };
        if v <= 0.0 {
            return 0.0;
        }
        let steps = self.lut.len() - 1;
        let x = v.min(1.0) * steps as f32;
        let i = (x as usize).min(steps - 1);
        self.lut[i] + (self.lut[i + 1] - self.lut[i]) * (x - i as f32)
    }
}

/// One output row's sampling of the normalised image for [`render_encoded_into`]: pixel
/// `x` sits at normalised row `rr0 + drr·x` and across-axis position `u0 + du·x`.
#[derive(Clone, Copy, Debug)]
struct RowSampling {
    rr0: f32,
    drr: f32,
    u0: f32,
    du: f32,
    kc: f32,
    c_off: f32,
    ns: usize,
}

/// As [`render_scaled_into`] into `out` (`w × h` values, row-major), then exposed and
/// encoded by `enc` ([`Encoding::apply`]): the same values as those two steps, in less
/// time per lit pixel (the loop timing's many small grey renders cover mostly lit pixels,
/// where the general renderer spends ≈ 10 ns a pixel): rows go eight pixels at a time with
/// AVX2 where the CPU has it ([`avx2`], equal lane by lane), and `floor` is inlined.
#[allow(clippy::too_many_arguments)]
pub(crate) fn render_encoded_into(
    normalised: &[f32],
    shape: &Shape,
    place: &Placement,
    p: &ShapeParams,
    scratch: &mut RenderScratch,
    frame_height: f64,
    size: (usize, usize),
    enc: Encoding,
    out: &mut [f32],
) {
    let simd = avx2::available();
    render_encoded_with(
        normalised,
        shape,
        place,
        p,
        scratch,
        frame_height,
        size,
        enc,
        out,
        simd,
    );
}

/// [`render_encoded_into`], its rows with AVX2 (`simd`, which the CPU must have) or not.
#[allow(clippy::too_many_arguments)]
fn render_encoded_with(
    normalised: &[f32],
    shape: &Shape,
    place: &Placement,
    p: &ShapeParams,
    scratch: &mut RenderScratch,
    frame_height: f64,
    (w, h): (usize, usize),
    enc: Encoding,
    out: &mut [f32],
    simd: bool,
) {
    let ns = p.norm_size as usize;
    debug_assert_eq!(normalised.len(), ns * ns);
    debug_assert_eq!(out.len(), w * h);
    assert!(enc.lut.len() >= 2, "an sRGB table of at least one interval");
    scratch.row_profiles(shape, p);
    scratch.path.clear();
    scratch
        .path
        .extend(scratch.path_rows.iter().map(|&v| v as f32));
    scratch.width_inv.clear();
    scratch
        .width_inv
        .extend(scratch.width_rows.iter().map(|&w| (1.0 / w) as f32));
    let sv = (shape.height * frame_height).max(1e-3);
    let (upx, upy) = (place.tilt.sin(), -place.tilt.cos());
    let (rx, ry) = (place.tilt.cos(), place.tilt.sin());
    let kr = ns as f64 / (p.above + p.below);
    let kc = (ns as f64 / (2.0 * p.half_width)) as f32;
    let c_off = (p.half_width * ns as f64 / (2.0 * p.half_width)) as f32 - 0.5;
    assert!(!simd || avx2::available(), "AVX2 on a CPU without it");
    for (y, row) in out.chunks_exact_mut(w.max(1)).enumerate().take(h) {
        let dy = (y as f64 + 0.5 - place.cy) / sv;
        let dx0 = (0.5 - place.cx) / sv;
        let v0 = (dx0 * upx + dy * upy) as f32;
        let dv = (upx / sv) as f32;
        let rs = RowSampling {
            rr0: ((p.above - v0 as f64) * kr - 0.5) as f32,
            drr: -(dv as f64 * kr) as f32,
            u0: (dx0 * rx + dy * ry) as f32,
            du: (rx / sv) as f32,
            kc,
            c_off,
            ns,
        };
        let done = if simd {
            // SAFETY: `avx2::available` checked that the CPU has AVX2 (asserted above).
            unsafe { avx2::row(&rs, scratch, normalised, enc, row) }
        } else {
            0
        };
        for (x, o) in row.iter_mut().enumerate().skip(done) {
            *o = enc.apply(sample(&rs, scratch, normalised, x));
        }
    }
}

/// The renderer's value of pixel `x` of the row `rs` (as [`render_scaled_into`] computes
/// it, before exposure) in the normalised image `img`, from the tables
/// [`render_encoded_into`] filled in `scratch`.
#[inline]
fn sample(rs: &RowSampling, scratch: &RenderScratch, img: &[f32], x: usize) -> f32 {
    let (ns, nsf) = (rs.ns, rs.ns as f32);
    let xf = x as f32;
    let rr = rs.rr0 + rs.drr * xf;
    if !(rr > -1.0 && rr < nsf) {
        return 0.0;
    }
    let u = rs.u0 + rs.du * xf;
    let rc = rr.clamp(0.0, nsf - 1.0);
    let r0 = rc as usize;
    let r1 = (r0 + 1).min(ns - 1);
    let t = rc - r0 as f32;
    let (path, winv) = (&scratch.path, &scratch.width_inv);
    let pth = path[r0] + (path[r1] - path[r0]) * t;
    let wi = winv[r0] + (winv[r1] - winv[r0]) * t;
    let cc = (u - pth) * wi * rs.kc + rs.c_off;
    if !(cc > -1.0 && cc < nsf) {
        return 0.0;
    }
    let (fr, fc) = (floor_in_range(rr), floor_in_range(cc));
    let (ty, tx) = (rr - fr, cc - fc);
    let (ir, ic) = (fr as isize, fc as isize);
    let at = |r: isize, c: isize| -> f32 {
        if r < 0 || c < 0 || r >= ns as isize || c >= ns as isize {
            0.0
        } else {
            img[r as usize * ns + c as usize]
        }
    };
    let top = at(ir, ic) * (1.0 - tx) + at(ir, ic + 1) * tx;
    let bot = at(ir + 1, ic) * (1.0 - tx) + at(ir + 1, ic + 1) * tx;
    (top * (1.0 - ty) + bot * ty).max(0.0)
}

/// `x.floor()` for `x` in `−2³¹..2³¹` (the renderer's coordinates lie in `−1..norm_size`),
/// without the library call: the same value except that `−0.0` gives `0.0`.
#[inline]
fn floor_in_range(x: f32) -> f32 {
    let t = x as i32 as f32;
    if t > x {
        t - 1.0
    } else {
        t
    }
}

/// A box in the flame's canonical coordinates, `[u_lo, u_hi, v_lo, v_hi]` (`σ_v` units,
/// `u` across the main axis, `v` up it), outside which [`render_into`] lights no pixel of
/// `shape` when only the normalised image's rows `lit[0]..=lit[1]` and columns
/// `lit[2]..=lit[3]` hold light: `v` over those rows (a row beyond each, where the
/// bilinear lookup still reaches them), `u` over every row's path ± the columns' reach at
/// the widest row's width (the renderer interpolates between rows, within their extremes).
#[cfg(test)]
pub(crate) fn canonical_box(shape: &Shape, p: &ShapeParams, lit: [usize; 4]) -> [f64; 4] {
    let (path, width) = row_profiles(shape, p);
    canonical_box_of(&path, &width, p, lit)
}

/// [`canonical_box`] of a flame whose [`row_profiles`] are `path` and `width`.
pub(crate) fn canonical_box_of(
    path: &[f64],
    width: &[f64],
    p: &ShapeParams,
    lit: [usize; 4],
) -> [f64; 4] {
    let ns = p.norm_size as f64;
    let kr = ns / (p.above + p.below);
    let kc = ns / (2.0 * p.half_width);
    let c_off = p.half_width * kc - 0.5;
    let [r0, r1, c0, c1] = lit.map(|v| v as f64);
    let (a, b) = ((c0 - 1.0 - c_off) / kc, (c1 + 1.0 - c_off) / kc);
    let wmax = width.iter().copied().fold(0.0, f64::max);
    let pmin = path.iter().copied().fold(f64::INFINITY, f64::min);
    let pmax = path.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    [
        pmin + a * wmax,
        pmax + b * wmax,
        p.above - (r1 + 1.5) / kr,
        p.above - (r0 - 0.5) / kr,
    ]
}

/// The pixel box `[x_lo, x_hi, y_lo, y_hi]` (pixel indices, inclusive, unclamped) covering
/// a [`canonical_box`] drawn at `place` with `σ_v = sv` pixels.
pub(crate) fn pixel_box(b: [f64; 4], place: &Placement, sv: f64) -> [f64; 4] {
    let (upx, upy) = (place.tilt.sin(), -place.tilt.cos());
    let (rx, ry) = (place.tilt.cos(), place.tilt.sin());
    let mut out = [
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    ];
    for u in [b[0], b[1]] {
        for v in [b[2], b[3]] {
            let x = place.cx + sv * (u * rx + v * upx) - 0.5;
            let y = place.cy + sv * (u * ry + v * upy) - 0.5;
            out = [out[0].min(x), out[1].max(x), out[2].min(y), out[3].max(y)];
        }
    }
    out
}

/// Output size check shared by the renderers.
pub(crate) fn check_size(size: Size) -> Result<()> {
    Size::new(size.width, size.height)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normalise_then_render_reproduces_a_flame() {
        let clip = crate::synthetic::flame_clip(Size::new(96, 96).unwrap(), 1, 5);
        let p = ShapeParams::default();
        let n = normalise(&clip[0], &p).unwrap();
        let mut out = GrayFrame::new(clip[0].size());
        let place = Placement {
            cx: n.pose.cx,
            cy: n.pose.cy,
            tilt: n.pose.tilt,
        };
        render_into(
            &n.image,
            &n.shape,
            &place,
            &p,
            &mut RenderScratch::default(),
            &mut out,
        );
        let psnr = crate::psnr(&clip[0], &out);
        assert!(psnr > 30.0, "PSNR {psnr}");
    }

    /// The timing's encoded renders equal the renderer's frame, exposed and encoded, bit
    /// for bit, with AVX2 and without: upright and tilted flames, windows of widths that
    /// are and are not multiples of eight, partly outside the normalised image.
    #[test]
    fn encoded_renders_equal_the_renderer_then_the_encoding() {
        let clip = crate::synthetic::flame_clip(Size::new(96, 80).unwrap(), 4, 3);
        let p = ShapeParams::default();
        let lut: Vec<f32> = (0..=64)
            .map(|i| ignis_core::palette::linear_to_srgb(i as f32 / 64.0))
            .collect();
        let mut checked = 0;
        for (k, frame) in clip.iter().enumerate() {
            let n = normalise(frame, &p).unwrap();
            // tilted (the rows' table lookups differ across a chunk of eight) and upright,
            // windows of widths that are and are not multiples of eight, partly outside
            // the image, exposures at, under and over 1
            for (tilt, (w, h), exposure) in [
                (0.0, (40, 30), 1.0),
                (0.4 * k as f64 - 0.6, (37, 29), 1.7),
                (0.1, (13, 50), 0.6),
                (-1.2, (96, 80), 3.0),
            ] {
                let place = Placement {
                    cx: n.pose.cx - 20.0 + 3.0 * k as f64,
                    cy: n.pose.cy - 12.0,
                    tilt: n.pose.tilt + tilt,
                };
                let enc = Encoding {
                    exposure,
                    lut: &lut,
                };
                let scratch = &mut RenderScratch::default();
                let mut want = GrayFrame::new(Size::new(w as u32, h as u32).unwrap());
                render_scaled_into(&n.image, &n.shape, &place, &p, scratch, 80.0, &mut want);
                let want: Vec<f32> = want.data().iter().map(|&v| enc.apply(v)).collect();
                for simd in [false, avx2::available()] {
                    let mut got = vec![f32::NAN; w * h];
                    let args = (&n.image, &n.shape, &place, &p);
                    render_encoded_with(
                        args.0,
                        args.1,
                        args.2,
                        args.3,
                        scratch,
                        80.0,
                        (w, h),
                        enc,
                        &mut got,
                        simd,
                    );
                    for (i, (g, v)) in got.iter().zip(&want).enumerate() {
                        assert_eq!(g.to_bits(), v.to_bits(), "{k} simd {simd}: pixel {i}");
                    }
                }
                checked += want.iter().filter(|&&v| v > 0.0).count();
            }
        }
        assert!(checked > 1000, "{checked} lit pixels");
    }

    /// The timing of loops renders windows only (`synth/looptime.rs`): every pixel a flame
    /// lights lies in its [`pixel_box`], and a window rendered with the whole frame's scale
    /// holds the whole frame's pixels.
    #[test]
    fn flames_stay_in_their_box_and_windows_match_the_frame() {
        let clip = crate::synthetic::flame_clip(Size::new(96, 80).unwrap(), 3, 7);
        let p = ShapeParams::default();
        let ns = p.norm_size as usize;
        for (k, frame) in clip.iter().enumerate() {
            let mut n = normalise(frame, &p).unwrap();
            // light only in rows 10..=40 and columns 20..=50 of the normalised image
            let lit = [10, 40, 20, 50];
            for (i, v) in n.image.iter_mut().enumerate() {
                let (r, c) = (i / ns, i % ns);
                if !(lit[0]..=lit[1]).contains(&r) || !(lit[2]..=lit[3]).contains(&c) {
                    *v = 0.0;
                }
            }
            let place = Placement {
                cx: n.pose.cx,
                cy: n.pose.cy,
                tilt: n.pose.tilt + 0.3 * k as f64,
            };
            let mut full = GrayFrame::new(frame.size());
            let scratch = &mut RenderScratch::default();
            render_into(&n.image, &n.shape, &place, &p, scratch, &mut full);
            let sv = n.shape.height * full.height() as f64;
            let b = pixel_box(canonical_box(&n.shape, &p, lit), &place, sv);
            let mut lit_pixels = 0;
            for (y, row) in full.rows().enumerate() {
                for (x, &v) in row.iter().enumerate() {
                    if v > 0.0 {
                        lit_pixels += 1;
                        let (x, y) = (x as f64, y as f64);
                        assert!(
                            x >= b[0] && x <= b[1] && y >= b[2] && y <= b[3],
                            "{k}: ({x}, {y}) outside {b:?}"
                        );
                    }
                }
            }
            assert!(lit_pixels > 20, "{k}: {lit_pixels}");
            let (x0, y0) = (b[0].floor().max(0.0) as u32, b[2].floor().max(0.0) as u32);
            let mut window = GrayFrame::new(Size::new(30, 25).unwrap());
            let shifted = Placement {
                cx: place.cx - x0 as f64,
                cy: place.cy - y0 as f64,
                ..place
            };
            let h = full.height() as f64;
            render_scaled_into(&n.image, &n.shape, &shifted, &p, scratch, h, &mut window);
            for (y, row) in window.rows().enumerate() {
                for (x, &v) in row.iter().enumerate() {
                    let (fx, fy) = (x as u32 + x0, y as u32 + y0);
                    let want = if fx < full.width() && fy < full.height() {
                        full.get(fx, fy)
                    } else {
                        0.0
                    };
                    assert!((v - want).abs() < 1e-4, "{k}: ({fx}, {fy}) {v} vs {want}");
                }
            }
        }
    }

    #[test]
    fn two_flames_are_detected() {
        let s = Size::new(64, 64).unwrap();
        let f = GrayFrame::from_fn(s, |x, y| {
            let g = |cx: f32| (-((x as f32 - cx).powi(2) + (y as f32 - 32.0).powi(2)) / 20.0).exp();
            g(16.0) + g(48.0)
        });
        assert_eq!(count_flames(&f, 0.2, 0.03), 2);
        assert!(matches!(
            normalise(&f, &ShapeParams::default()),
            Err(Skip::Multiple)
        ));
        assert!(matches!(
            normalise(&GrayFrame::new(s), &ShapeParams::default()),
            Err(Skip::Dark)
        ));
    }
}
