//! Morph joins at render time (issue 15): the motion-compensated in-betweens of a plan's
//! morph runs ([`MorphRun`]), made from the two *rendered* endpoint frames.
//!
//! The planner only knows PCA weights; how far apart two frames really are shows only once
//! they are rendered (two clips of different size and brightness, a reconstruction against
//! the footage's own frame). So, per run: the endpoints and up to [`NEIGHBOURS`] real
//! frames on each side are rendered, the footage's own median step is measured on them
//! (grey 128-px metric frames of `ignis_core::loopq`, what the written output is judged
//! on), the flow between the endpoints is computed once, and in-betweens are added until
//! every step of the join is within [`MORPH_STEP`] × that median — at most [`max_frames`]
//! (2 s of the footage); a run that hits the bound keeps it (the join is then as smooth as
//! 2 s allow). A run whose count the scenario fixed (`frames = N`) keeps its count.
//!
//! The in-betweens are a detail-preserving blend of the two frames warped toward each other
//! along the flow (after Heitz & Neyret, *High-Performance By-Example Noise using a
//! Histogram-Preserving Blending Operator*, HPG 2018, §3: a blend of two uncorrelated
//! textures has the variance of each scaled by (1−t)² + t², half at t = ½, so the in-between
//! looks soft — the loop metric's *ghost*). Each frame is split into its local mean (a box
//! mean of [`detail_radius`]) and the detail around it; the mean is blended plainly (shape,
//! brightness, alpha stay the plain morph's) and the blended detail is scaled so its energy is
//! the interpolation of the two warped frames' — measured per frame, so well-aligned similar
//! frames (correlated detail) get a gain near 1, unrelated ones up to 1/√((1−t)² + t²).

use std::collections::HashMap;

use ignis_core::loopq;
use ignis_core::{GrayFrame, RgbaFrame, Size};

use crate::db::EigenfireDb;
use crate::error::{EigenError, Result};
use crate::render::{render_frames, Geometry, RenderOptions, MORPH_FLOW_SIDE};
use crate::scenario::{Look, MorphRun, Plan, MORPH_STEP};

pub use crate::footage::FootageOpener;

mod detail;
pub use detail::Stages;

/// Real frames rendered on each side of a morph run to measure the footage's median step.
pub const NEIGHBOURS: usize = 8;

/// Most in-betweens of an automatic morph run: 2 s at the database's highest frame rate.
pub fn max_frames(db: &EigenfireDb) -> usize {
    let fps = db
        .manifest()
        .clips
        .iter()
        .map(|c| c.fps / c.stride.max(1) as f64)
        .filter(|f| f.is_finite() && *f > 0.0)
        .fold(0.0, f64::max);
    ((2.0 * if fps > 0.0 { fps } else { 30.0 }).ceil() as usize).max(1)
}

/// Side of the box mean that separates a frame's detail from its local mean: a 64th of the
/// frame's longer side (2 px on a 128-px metric frame), at least 1.
pub fn detail_radius(size: Size) -> usize {
    (size.width.max(size.height) as usize / 64).max(1)
}

/// What a morph run became when rendered.
#[derive(Clone, Debug, PartialEq)]
pub struct MorphOutcome {
    /// In-betweens written.
    pub frames: usize,
    /// The footage's median step near the join (metric frames), 0 when not measurable.
    pub median_step: f64,
    /// Largest step of the join (into, within and out of the in-betweens) over that median,
    /// measured on the rendered frames' metric frames (NaN when not measurable).
    pub worst_step: f64,
    /// Whether [`max_frames`] stopped the count short of the goal.
    pub bound_hit: bool,
}

/// Box mean of radius `r` (edge-clamped window), separable, for `C` channels: rows in
/// parallel, then columns as running sums down bands of columns (contiguous, in parallel).
/// Every sum runs in a fixed order, so the result does not depend on the thread count.
fn box_mean<const C: usize>(d: &[[f32; C]], size: Size, r: usize) -> Vec<[f32; C]> {
    use rayon::prelude::*;
    let (w, h) = (size.width as usize, size.height as usize);
    if w == 0 || h == 0 {
        return d.to_vec();
    }
    let mut rows = vec![[0.0f32; C]; d.len()];
    rows.par_chunks_mut(w)
        .zip(d.par_chunks(w))
        .for_each(|(out, src)| box_line(src, out, r));
    // Columns: band `k` holds columns k·BAND..; its running sums move down the rows.
    const BAND: usize = 64;
    let bands: Vec<Vec<[f32; C]>> = (0..w.div_ceil(BAND))
        .into_par_iter()
        .map(|k| {
            let (x0, x1) = (k * BAND, ((k + 1) * BAND).min(w));
            let bw = x1 - x0;
            let row = |y: usize| &rows[y * w + x0..y * w + x1];
            let mut acc = vec![[0.0f64; C]; bw];
            let add = |acc: &mut [[f64; C]], src: &[[f32; C]], sign: f64| {
                for (a, p) in acc.iter_mut().zip(src) {
                    for c in 0..C {
                        a[c] += sign * f64::from(p[c]);
                    }
                }
            };
            for y in 0..=r.min(h - 1) {
                add(&mut acc, row(y), 1.0);
            }
            let mut out = vec![[0.0f32; C]; bw * h];
            for y in 0..h {
                let n = ((y + r).min(h - 1) - y.saturating_sub(r) + 1) as f64;
                for (o, a) in out[y * bw..(y + 1) * bw].iter_mut().zip(&acc) {
                    *o = std::array::from_fn(|c| (a[c] / n) as f32);
                }
                if y + r + 1 < h {
                    add(&mut acc, row(y + r + 1), 1.0);
                }
                if y >= r {
                    add(&mut acc, row(y - r), -1.0);
                }
            }
            out
        })
        .collect();
    let mut out = vec![[0.0f32; C]; d.len()];
    out.par_chunks_mut(w).enumerate().for_each(|(y, line)| {
        for (k, band) in bands.iter().enumerate() {
            let (x0, x1) = (k * BAND, ((k + 1) * BAND).min(w));
            let bw = x1 - x0;
            line[x0..x1].copy_from_slice(&band[y * bw..(y + 1) * bw]);
        }
    });
    out
}

/// The local mean the detail is measured around: [`box_mean`] of radius `r`; for large radii
/// (full-resolution frames) the box mean of the frame reduced by `k = r / 4` (block means),
/// radius `r / k`, upsampled bilinearly — the same smooth low-pass at a 16th of the cost or
/// less, as the split into mean and detail only needs a local mean.
fn local_mean<const C: usize>(d: &[[f32; C]], size: Size, r: usize) -> Vec<[f32; C]> {
    use rayon::prelude::*;
    let k = r / 4;
    let (w, h) = (size.width as usize, size.height as usize);
    if k < 2 || w < 2 * k || h < 2 * k {
        return box_mean(d, size, r);
    }
    let (sw, sh) = (w.div_ceil(k), h.div_ceil(k));
    let small: Vec<[f32; C]> = (0..sw * sh)
        .into_par_iter()
        .map(|i| {
            let (bx, by) = (i % sw, i / sw);
            let (x0, x1, y0, y1) = (bx * k, ((bx + 1) * k).min(w), by * k, ((by + 1) * k).min(h));
            let mut acc = [0.0f64; C];
            for y in y0..y1 {
                for p in &d[y * w + x0..y * w + x1] {
                    for c in 0..C {
                        acc[c] += f64::from(p[c]);
                    }
                }
            }
            let n = ((x1 - x0) * (y1 - y0)) as f64;
            std::array::from_fn(|c| (acc[c] / n) as f32)
        })
        .collect();
    let sm = box_mean(
        &small,
        Size::new(sw as u32, sh as u32).expect("smaller"),
        r / k,
    );
    // Bilinear, block centres at ((b + ½)·k − ½).
    let coord = |x: usize, n: usize| {
        let u = ((x as f32 + 0.5) / k as f32 - 0.5).clamp(0.0, (n - 1) as f32);
        let i = (u as usize).min(n - 1);
        (i, (i + 1).min(n - 1), u - i as f32)
    };
    let xs: Vec<(usize, usize, f32)> = (0..w).map(|x| coord(x, sw)).collect();
    let mut out = vec![[0.0f32; C]; d.len()];
    out.par_chunks_mut(w).enumerate().for_each(|(y, line)| {
        let (y0, y1, fy) = coord(y, sh);
        let (r0, r1) = (&sm[y0 * sw..(y0 + 1) * sw], &sm[y1 * sw..(y1 + 1) * sw]);
        for (o, &(x0, x1, fx)) in line.iter_mut().zip(&xs) {
            *o = std::array::from_fn(|c| {
                let top = r0[x0][c] + fx * (r0[x1][c] - r0[x0][c]);
                let bot = r1[x0][c] + fx * (r1[x1][c] - r1[x0][c]);
                top + fy * (bot - top)
            });
        }
    });
    out
}

/// One line's box mean of radius `r` (edge-clamped window).
fn box_line<const C: usize>(src: &[[f32; C]], out: &mut [[f32; C]], r: usize) {
    let len = src.len();
    let mut acc = [0.0f64; C];
    for p in &src[..=r.min(len - 1)] {
        for c in 0..C {
            acc[c] += f64::from(p[c]);
        }
    }
    for i in 0..len {
        let n = ((i + r).min(len - 1) - i.saturating_sub(r) + 1) as f64;
        out[i] = std::array::from_fn(|c| (acc[c] / n) as f32);
        if i + r + 1 < len {
            for c in 0..C {
                acc[c] += f64::from(src[i + r + 1][c]);
            }
        }
        if i >= r {
            for c in 0..C {
                acc[c] -= f64::from(src[i - r][c]);
            }
        }
    }
}

/// Which pixels the detail energies of a `size` frame are summed over, as `(band,
/// stride)`: pixel `(x, y)` counts when block `(x / band, y / band)` is sampled
/// ([`gain_block`]). The gain is one number per frame, a ratio of energies, so frames whose
/// local mean is taken from blocks of `band = r / 4 ≥ 2` px (the fused path, `detail.rs`)
/// estimate it from every `stride`-th block along diagonals — one block in `stride` in
/// every block row and column, so the sample covers the whole frame evenly — while the
/// fused pass skips the per-block sums of the others. At least 32 block rows per stride
/// are kept (a 1080p frame samples one block in 4); the estimate moves the gain by well
/// under 1 % (tested: `subsampled_gain_matches_the_whole_frame`). Smaller frames sum every
/// pixel.
pub(crate) fn gain_rows(size: Size) -> (usize, usize) {
    let band = detail_radius(size) / 4;
    if band < 2 {
        return (1, 1);
    }
    let bands = (size.height as usize).div_ceil(band);
    (band, (bands / 32).clamp(1, 4))
}

/// Whether block `(bx, by)` is among those the gain is estimated from ([`gain_rows`]).
#[inline(always)]
pub(crate) fn gain_block(bx: usize, by: usize, stride: usize) -> bool {
    (bx + by).is_multiple_of(stride)
}

/// Σ over rows of `f(row)` (three sums at once): rows in parallel, added in row order, so
/// the result does not depend on the thread count.
fn sum_rows(n: usize, w: usize, f: impl Fn(std::ops::Range<usize>) -> [f64; 3] + Sync) -> [f64; 3] {
    use rayon::prelude::*;
    let parts: Vec<[f64; 3]> = (0..n.div_ceil(w.max(1)))
        .into_par_iter()
        .map(|y| f(y * w..((y + 1) * w).min(n)))
        .collect();
    parts
        .iter()
        .fold([0.0; 3], |s, p| [s[0] + p[0], s[1] + p[1], s[2] + p[2]])
}

/// The one gain of a detail-preserving in-between at `t` from the detail energies
/// `[Σ(a − ma)², Σ(b − mb)², Σ(s(a − ma) + t(b − mb))²]` (`s = 1 − t`): the blended
/// detail scaled to the interpolated energy `s·ea + t·eb`, never below 1 nor above the
/// uncorrelated bound `1/√(s² + t²)`.
fn detail_gain([ea, eb, em]: [f64; 3], t: f32) -> f32 {
    let s = 1.0 - t;
    let want = f64::from(s) * ea + f64::from(t) * eb;
    let bound = 1.0 / f64::from(s * s + t * t).sqrt();
    if em > 0.0 {
        (want / em).sqrt().clamp(1.0, bound) as f32
    } else {
        1.0
    }
}

/// The detail-preserving blend of `a` and `b` (`t` of the way to `b`) on `C`-channel
/// pixels; see the module doc. Each blended pixel (not clamped) goes through `finish`.
fn detail_blend<const C: usize>(
    a: &[[f32; C]],
    b: &[[f32; C]],
    size: Size,
    t: f32,
    finish: impl Fn([f32; C]) -> [f32; C] + Sync,
) -> Vec<[f32; C]> {
    use rayon::prelude::*;
    let r = detail_radius(size);
    let w = size.width as usize;
    let (ma, mb) = rayon::join(|| local_mean(a, size, r), || local_mean(b, size, r));
    let s = 1.0 - t;
    let mixed = |i: usize, c: usize| s * (a[i][c] - ma[i][c]) + t * (b[i][c] - mb[i][c]);
    // Detail energies of a, b and of their plain blend.
    let (band, stride) = gain_rows(size);
    let [ea, eb, em] = sum_rows(a.len(), w, |rg| {
        let by = rg.start / w / band;
        let mut e = [0.0f64; 3];
        for i in rg {
            if stride > 1 && !gain_block(i % w / band, by, stride) {
                continue;
            }
            for c in 0..C {
                e[0] += f64::from(a[i][c] - ma[i][c]).powi(2);
                e[1] += f64::from(b[i][c] - mb[i][c]).powi(2);
                e[2] += f64::from(mixed(i, c)).powi(2);
            }
        }
        e
    });
    let gain = detail_gain([ea, eb, em], t);
    (0..a.len())
        .into_par_iter()
        .map(|i| {
            finish(std::array::from_fn(|c| {
                s * ma[i][c] + t * mb[i][c] + gain * mixed(i, c)
            }))
        })
        .collect()
}

/// The detail-preserving blend of two grey frames of one size.
pub fn detail_blend_gray(a: &GrayFrame, b: &GrayFrame, t: f32) -> GrayFrame {
    let wrap = |f: &GrayFrame| f.data().iter().map(|&v| [v]).collect::<Vec<[f32; 1]>>();
    let out = detail_blend(&wrap(a), &wrap(b), a.size(), t, |p| [p[0].max(0.0)]);
    GrayFrame::from_vec(a.size(), out.into_iter().map(|p| p[0]).collect()).expect("sized from a")
}

/// The detail-preserving blend of two colour frames of one size (straight alpha), on
/// premultiplied values; alpha clamped to `0..=1`, colour to at least 0.
pub fn detail_blend_rgba(a: &RgbaFrame, b: &RgbaFrame, t: f32) -> RgbaFrame {
    use rayon::prelude::*;
    let pm = |f: &RgbaFrame| -> Vec<[f32; 4]> {
        f.data()
            .par_iter()
            .map(|p| [p[0] * p[3], p[1] * p[3], p[2] * p[3], p[3]])
            .collect()
    };
    let out = detail_blend(&pm(a), &pm(b), a.size(), t, |p| {
        let al = p[3].clamp(0.0, 1.0);
        if al <= 1e-6 {
            [0.0; 4]
        } else {
            [
                p[0].max(0.0) / al,
                p[1].max(0.0) / al,
                p[2].max(0.0) / al,
                al,
            ]
        }
    });
    RgbaFrame::from_vec(a.size(), out).expect("sized from a")
}

/// The in-between `t` of the way from `a` to `b`: both warped toward it along the flow
/// (`fw` = a→b, `bw` = b→a), then [`detail_blend_rgba`] — for frames whose local mean is
/// taken from block means (longer side ≥ 512) in two fused row passes with no full-size
/// intermediate (`detail.rs`; within 1e-4 of the unfused computation).
pub fn inbetween_rgba(
    a: &RgbaFrame,
    b: &RgbaFrame,
    fw: &ignis_flow::FlowField,
    bw: &ignis_flow::FlowField,
    t: f32,
) -> RgbaFrame {
    inbetween_rgba_timed(a, b, fw, bw, t, None)
}

/// [`inbetween_rgba`] with the wall time of each pass of the fused path (names empty and
/// times zero when the frames take the unfused path), for benchmarks.
pub fn inbetween_rgba_stages(
    a: &RgbaFrame,
    b: &RgbaFrame,
    fw: &ignis_flow::FlowField,
    bw: &ignis_flow::FlowField,
    t: f32,
) -> (RgbaFrame, Stages) {
    let mut st = [("", std::time::Duration::ZERO); 3];
    let f = inbetween_rgba_timed(a, b, fw, bw, t, Some(&mut st));
    (f, st)
}

/// The fused path when the frames allow it (timing its passes into `stages`), else the
/// unfused one.
fn inbetween_rgba_timed(
    a: &RgbaFrame,
    b: &RgbaFrame,
    fw: &ignis_flow::FlowField,
    bw: &ignis_flow::FlowField,
    t: f32,
    stages: Option<&mut Stages>,
) -> RgbaFrame {
    detail::inbetween_rgba(a, b, fw, bw, t, stages)
        .unwrap_or_else(|| inbetween_rgba_unfused(a, b, fw, bw, t))
}

/// [`inbetween_rgba`] as two warps and [`detail_blend_rgba`]: the path of small frames, and
/// the reference the fused path is tested against.
fn inbetween_rgba_unfused(
    a: &RgbaFrame,
    b: &RgbaFrame,
    fw: &ignis_flow::FlowField,
    bw: &ignis_flow::FlowField,
    t: f32,
) -> RgbaFrame {
    let (wa, wb) = rayon::join(
        || ignis_flow::warp_rgba(a, fw, -t),
        || ignis_flow::warp_rgba(b, bw, -(1.0 - t)),
    );
    detail_blend_rgba(&wa, &wb, t)
}

/// [`inbetween_rgba`] for grey frames.
pub fn inbetween_gray(
    a: &GrayFrame,
    b: &GrayFrame,
    fw: &ignis_flow::FlowField,
    bw: &ignis_flow::FlowField,
    t: f32,
) -> GrayFrame {
    let wa = ignis_flow::warp_gray(a, fw, -t);
    let wb = ignis_flow::warp_gray(b, bw, -(1.0 - t));
    detail_blend_gray(&wa, &wb, t)
}

/// Samples of the morph path `ma` → `mb` used to space the in-betweens evenly.
const PATH_SAMPLES: usize = 48;

/// Times of `n` in-betweens spaced evenly along the path whose cumulative step length at
/// the uniform times `k / (len − 1)` is `arc` (a morph does not move at an even pace in
/// t: the warps and the detail gain bunch the change up).
fn even_times(arc: &[f64], n: usize) -> Vec<f32> {
    loopq::arc_times(arc, (1..=n).map(|k| k as f64 / (n + 1) as f64))
        .into_iter()
        .map(|t| t as f32)
        .collect()
}

/// The fewest in-betweens (from 1 up to `max`) of the metric frames `ma` → `mb`, spaced
/// evenly along the path, whose every step is within `limit`; returns their times, the
/// largest step and whether `max` was hit.
pub fn choose_times(
    ma: &GrayFrame,
    mb: &GrayFrame,
    fw: &ignis_flow::FlowField,
    bw: &ignis_flow::FlowField,
    limit: f64,
    max: usize,
) -> (Vec<f32>, f64, bool) {
    use rayon::prelude::*;
    let at = |t: f32| inbetween_gray(ma, mb, fw, bw, t);
    let path: Vec<GrayFrame> = (0..=PATH_SAMPLES)
        .into_par_iter()
        .map(|k| match k {
            0 => ma.clone(),
            k if k == PATH_SAMPLES => mb.clone(),
            k => at(k as f32 / PATH_SAMPLES as f32),
        })
        .collect();
    let mut arc = vec![0.0];
    for p in path.windows(2) {
        arc.push(arc[arc.len() - 1] + loopq::rms_diff(&p[0], &p[1]));
    }
    let worst_with = |times: &[f32]| -> f64 {
        let mids: Vec<GrayFrame> = times.par_iter().map(|&t| at(t)).collect();
        let mut chain: Vec<&GrayFrame> = vec![ma];
        chain.extend(mids.iter());
        chain.push(mb);
        steps_of(&chain).into_iter().fold(0.0, f64::max)
    };
    let mut last = (Vec::new(), f64::INFINITY);
    for n in 1..=max.max(1) {
        let times = even_times(&arc, n);
        let w = worst_with(&times);
        if w <= limit {
            return (times, w, false);
        }
        last = (times, w);
    }
    (last.0, last.1, true)
}

/// The metric frame of a rendered frame (as an opaque writer over black shows it).
fn metric(f: &RgbaFrame) -> GrayFrame {
    loopq::metric_frame_rgba(f, [0.0; 3])
}

/// Steps between consecutive metric frames.
fn steps_of(frames: &[&GrayFrame]) -> Vec<f64> {
    frames
        .windows(2)
        .map(|p| loopq::rms_diff(p[0], p[1]))
        .collect()
}

/// Where rendered frames go, counting them and keeping what the morph runs need: the
/// metric frames of the real frames near a run (`want`) and the full frame before each run.
struct Out<'s> {
    sink: &'s mut dyn FnMut(RgbaFrame) -> Result<()>,
    progress: &'s mut dyn FnMut(usize),
    done: usize,
    want: Vec<bool>,
    keep_full: Vec<bool>,
    metric: HashMap<usize, GrayFrame>,
    full: HashMap<usize, RgbaFrame>,
}

impl Out<'_> {
    fn emit(&mut self, f: RgbaFrame) -> Result<()> {
        (self.sink)(f)?;
        self.done += 1;
        (self.progress)(self.done);
        Ok(())
    }
    /// Plan frame `i` (a real frame).
    fn real(&mut self, i: usize, f: RgbaFrame) -> Result<()> {
        if self.want[i] {
            self.metric.insert(i, metric(&f));
        }
        if self.keep_full[i] {
            self.full.insert(i, f.clone());
        }
        self.emit(f)
    }
}

/// The plan's morph runs, sorted, each checked to sit between two real frames and not to
/// overlap the next.
fn checked_runs(plan: &Plan) -> Result<Vec<&MorphRun>> {
    let n = plan.frames.len();
    let mut runs: Vec<&MorphRun> = plan.morphs.iter().collect();
    runs.sort_by_key(|r| r.start);
    for r in &runs {
        let (a, b) = r.endpoints(n.max(1));
        let inside = |i: usize| i >= r.start && i < r.start + r.len;
        if n == 0
            || r.len == 0
            || r.start + r.len > n
            || inside(a)
            || inside(b)
            || r.times.as_ref().is_some_and(|t| t.len() != r.len)
        {
            return Err(EigenError::bad(
                "plan",
                format!(
                    "morph run {}..{} does not sit between two real frames of the {n}-frame plan",
                    r.start,
                    r.start + r.len
                ),
            ));
        }
    }
    if runs.windows(2).any(|p| p[1].start < p[0].start + p[0].len) {
        return Err(EigenError::bad("plan", "morph runs overlap"));
    }
    Ok(runs)
}

/// Everything [`render_with_morphs`] renders with.
pub(crate) struct Ctx<'c> {
    pub db: &'c EigenfireDb,
    pub plan: &'c Plan,
    pub look: &'c Look,
    pub opts: &'c RenderOptions,
    pub geo: Geometry,
}

impl Ctx<'_> {
    fn render(
        &self,
        range: std::ops::Range<usize>,
        sources: &mut dyn FootageOpener,
    ) -> Result<Vec<RgbaFrame>> {
        let mut got = Vec::with_capacity(range.len());
        self.render_each(range, sources, &mut |_, f| {
            got.push(f);
            Ok(())
        })?;
        Ok(got)
    }

    /// Renders `range` frame by frame into `each(plan index, frame)`: no more than a batch
    /// of full-size frames held at once, whatever the range's length.
    fn render_each(
        &self,
        range: std::ops::Range<usize>,
        sources: &mut dyn FootageOpener,
        each: &mut dyn FnMut(usize, RgbaFrame) -> Result<()>,
    ) -> Result<()> {
        let c = self;
        let mut i = range.start;
        render_frames(
            c.db,
            c.plan,
            &c.plan.frames[range],
            c.look,
            c.opts,
            c.geo,
            sources,
            &mut |f| {
                i += 1;
                each(i - 1, f)
            },
        )
    }
}

/// Renders the whole plan into `sink` in order — real frames in batches, each morph run as
/// its in-betweens (see the module doc) — and returns what each run became.
pub(crate) fn render_with_morphs(
    c: &Ctx,
    sources: &mut dyn FootageOpener,
    sink: &mut dyn FnMut(RgbaFrame) -> Result<()>,
    progress: &mut dyn FnMut(usize),
) -> Result<Vec<MorphOutcome>> {
    let n = c.plan.frames.len();
    let runs = checked_runs(c.plan)?;
    let mut want = vec![false; n];
    let mut keep_full = vec![false; n];
    let in_run = |i: usize| runs.iter().any(|r| i >= r.start && i < r.start + r.len);
    for r in &runs {
        let from = r.start.saturating_sub(NEIGHBOURS);
        for (i, w) in want.iter_mut().enumerate().take(r.start).skip(from) {
            *w = !in_run(i);
        }
        if r.start > 0 {
            keep_full[r.start - 1] = true;
        }
        if r.start + r.len == n {
            for (i, w) in want.iter_mut().enumerate().take(NEIGHBOURS.min(n)) {
                *w = !in_run(i);
            }
        }
    }
    let mut out = Out {
        sink,
        progress,
        done: 0,
        want,
        keep_full,
        metric: HashMap::new(),
        full: HashMap::new(),
    };
    let mut outcomes = Vec::with_capacity(runs.len());
    let mut at = 0;
    for (k, r) in runs.iter().enumerate() {
        c.render_each(at..r.start, sources, &mut |i, f| out.real(i, f))?;
        let next = runs.get(k + 1).map_or(n, |q| q.start);
        at = morph_run(c, r, next, sources, &mut out, &mut outcomes)?;
    }
    c.render_each(at..n, sources, &mut |i, f| out.real(i, f))?;
    Ok(outcomes)
}

/// The flows between a run's two end frames (forward, backward), at [`MORPH_FLOW_SIDE`].
/// Where an end frame is keyed out (the matte's alpha 0: nothing for the flow to match),
/// its field is filled from where it is seen (`ignis_flow::flow_pair_matted_rgba`), as
/// `ignis loop`'s morph closings do, so the in-betweens do not drag the flame's fringe over
/// the empty background along the patch grid's vectors; opaque frames keep their fields as
/// computed.
fn end_flows(
    fa: &RgbaFrame,
    fb: &RgbaFrame,
) -> Result<(ignis_flow::FlowField, ignis_flow::FlowField)> {
    let p = ignis_flow::FlowParams {
        max_side: MORPH_FLOW_SIDE,
        ..Default::default()
    };
    let flow_err = |e: ignis_flow::FlowError| EigenError::bad("morph", e.to_string());
    ignis_flow::flow_pair_matted_rgba(fa, fb, &p).map_err(flow_err)
}

/// How a run's in-betweens were chosen.
struct Choice {
    times: Vec<f32>,
    /// Largest step of the rendered join (NaN: not measured yet).
    worst: f64,
    bound_hit: bool,
    median: f64,
    measurable: bool,
}

/// The in-betweens' times of run `r` between the rendered end frames, given the steps of the
/// real frames around it (see the module doc): the resolved times of a resolved plan, the
/// scenario's fixed count evenly in t, else the fewest that keep every step within
/// [`MORPH_STEP`] × the median step.
fn choose_run(
    c: &Ctx,
    r: &MorphRun,
    (fa, fb): (&RgbaFrame, &RgbaFrame),
    (ma, mb): (&GrayFrame, &GrayFrame),
    (fw, bw): (&ignis_flow::FlowField, &ignis_flow::FlowField),
    steps: &[f64],
) -> Choice {
    let median = loopq::median(&mut steps.to_vec());
    let measurable = steps.len() >= 2 && median > 0.0;
    // The worst step of the rendered in-betweens at `times`, on their metric frames.
    let real_worst = |times: &[f32]| -> f64 {
        let mut chain = vec![ma.clone()];
        chain.extend(
            times
                .iter()
                .map(|&t| metric(&inbetween_rgba(fa, fb, fw, bw, t))),
        );
        chain.push(mb.clone());
        steps_of(&chain.iter().collect::<Vec<_>>())
            .into_iter()
            .fold(0.0, f64::max)
    };
    let (times, worst, bound_hit) = if let Some(t) = &r.times {
        (t.clone(), f64::NAN, false)
    } else if r.fixed || !measurable {
        let n = r.len;
        let even = (1..=n).map(|k| k as f32 / (n + 1) as f32).collect();
        (even, f64::NAN, false)
    } else {
        // Chosen on the metric-size morph, then checked on the rendered frames once: when
        // they step further than predicted, the goal is tightened by that ratio.
        let (goal, max) = (MORPH_STEP * median, max_frames(c.db));
        let (times, predicted, hit) = choose_times(ma, mb, fw, bw, goal, max);
        let real = real_worst(&times);
        if real <= goal || hit || predicted <= 0.0 {
            (times, real, hit)
        } else {
            let (times, _, hit) = choose_times(ma, mb, fw, bw, goal * predicted / real, max);
            (times, f64::NAN, hit)
        }
    };
    Choice {
        times,
        worst,
        bound_hit,
        median,
        measurable,
    }
}

/// `plan` with the in-betweens of every automatic morph run chosen now
/// ([`MorphRun::times`]), so its frame count is the count the render writes and any range of
/// it renders the same frames as the whole (`--chunk`). Renders each run's end frames and the
/// real frames around it that the full render measures (the same frames, so the same
/// choice); the rest of the plan is not rendered.
pub fn resolve(
    db: &EigenfireDb,
    plan: &Plan,
    look: &Look,
    opts: &RenderOptions,
    sources: &mut dyn FootageOpener,
) -> Result<Plan> {
    let geo = crate::render::geometry(db, plan, opts)?;
    let c = Ctx {
        db,
        plan,
        look,
        opts,
        geo,
    };
    resolve_ctx(&c, sources)
}

/// [`resolve`] of `c.plan`, rendered at `c.geo`.
fn resolve_ctx(c: &Ctx, sources: &mut dyn FootageOpener) -> Result<Plan> {
    let plan = c.plan;
    let n = plan.frames.len();
    let runs = checked_runs(plan)?;
    let in_run = |i: usize| runs.iter().any(|r| i >= r.start && i < r.start + r.len);
    let mut frames = Vec::with_capacity(n);
    let mut morphs = Vec::with_capacity(runs.len());
    let mut at = 0;
    for (k, r) in runs.iter().enumerate() {
        frames.extend_from_slice(&plan.frames[at..r.start]);
        let start = frames.len();
        let times = if r.fixed || r.times.is_some() {
            r.times.clone()
        } else {
            let next = runs.get(k + 1).map_or(n, |q| q.start);
            Some(resolve_run(c, r, next, &in_run, sources)?)
        };
        let len = times.as_ref().map_or(r.len, Vec::len);
        frames.extend(std::iter::repeat_n(plan.frames[r.start].clone(), len));
        morphs.push(MorphRun {
            start,
            len,
            fixed: r.fixed,
            times,
        });
        at = r.start + r.len;
    }
    frames.extend_from_slice(&plan.frames[at..]);
    Ok(Plan {
        frames,
        morphs,
        ..plan.clone()
    })
}

/// The metric frames `sub` renders to (as an opaque writer over black shows them; its
/// morph runs resolved as a full render resolves them, [`resolve`]) at the geometry of
/// `full`, the plan it is cut from; and `sub`'s morph runs as resolved. What
/// [`crate::scenario::Scenario::measure_joins`] measures a candidate join on.
pub fn render_metric(
    db: &EigenfireDb,
    full: &Plan,
    sub: &Plan,
    look: &Look,
    opts: &RenderOptions,
    sources: &mut dyn FootageOpener,
) -> Result<(Vec<GrayFrame>, Vec<MorphRun>)> {
    let geo = crate::render::geometry(db, full, opts)?;
    let c = Ctx {
        db,
        plan: sub,
        look,
        opts,
        geo,
    };
    let resolved = resolve_ctx(&c, sources)?;
    let c = Ctx {
        db,
        plan: &resolved,
        look,
        opts,
        geo,
    };
    let mut out = Vec::with_capacity(resolved.frames.len());
    render_with_morphs(
        &c,
        sources,
        &mut |f| {
            out.push(metric(&f));
            Ok(())
        },
        &mut |_| {},
    )?;
    Ok((out, resolved.morphs))
}

/// [`choose_run`] for one automatic run of [`resolve`], from the frames the full render
/// measures: the real frames consecutive up to the run's first end (none for a run at the
/// plan's start, whose end frame is rendered last) and from its second end up to
/// [`NEIGHBOURS`] (stopping at the next run; a run wrapping to the start: the plan's first
/// real frames).
fn resolve_run(
    c: &Ctx,
    r: &MorphRun,
    next: usize,
    in_run: &dyn Fn(usize) -> bool,
    sources: &mut dyn FootageOpener,
) -> Result<Vec<f32>> {
    let n = c.plan.frames.len();
    let (a, b) = r.endpoints(n);
    let before_n = if r.start == 0 {
        0
    } else {
        (0..NEIGHBOURS)
            .take_while(|&o| a.checked_sub(o).is_some_and(|i| !in_run(i)))
            .count()
    };
    let after_range = if b < r.start {
        0..(0..NEIGHBOURS.min(n)).take_while(|&i| !in_run(i)).count()
    } else {
        b..(b + NEIGHBOURS).min(next).max(b + 1)
    };
    let before = c.render(a + 1 - before_n.max(1)..a + 1, sources)?;
    let fa = before
        .last()
        .cloned()
        .ok_or_else(|| EigenError::bad("morph", "no end frame"))?;
    let before = &before[before.len() - before_n..];
    let after = c.render(after_range.clone(), sources)?;
    let fb = match after.first() {
        Some(f) if after_range.start == b => f.clone(),
        _ => c.render(b..b + 1, sources)?.remove(0),
    };
    let (ma, mb) = (metric(&fa), metric(&fb));
    let bm: Vec<GrayFrame> = before.iter().map(metric).collect();
    let am: Vec<GrayFrame> = after.iter().map(metric).collect();
    let mut steps = steps_of(&bm.iter().collect::<Vec<_>>());
    steps.extend(steps_of(&am.iter().collect::<Vec<_>>()));
    let (fw, bw) = end_flows(&fa, &fb)?;
    Ok(choose_run(c, r, (&fa, &fb), (&ma, &mb), (&fw, &bw), &steps).times)
}

/// One morph run: its endpoints and neighbours, the count, the in-betweens, then the real
/// frames rendered after it; returns the plan index rendering continues from.
fn morph_run(
    c: &Ctx,
    r: &MorphRun,
    next: usize,
    sources: &mut dyn FootageOpener,
    out: &mut Out,
    outcomes: &mut Vec<MorphOutcome>,
) -> Result<usize> {
    let n = c.plan.frames.len();
    let (a, b) = r.endpoints(n);
    let fa = match out.full.remove(&a) {
        Some(f) => f,
        None => c.render(a..a + 1, sources)?.remove(0),
    };
    // The real frames after the run: rendered now (and written after it) unless the run
    // wraps to the plan's start, whose frames are already written.
    let wraps = b < r.start;
    let after: Vec<RgbaFrame> = if wraps {
        Vec::new()
    } else {
        c.render(b..(b + NEIGHBOURS).min(next).max(b + 1), sources)?
    };
    let fb = match after.first() {
        Some(f) => f.clone(),
        None => c.render(b..b + 1, sources)?.remove(0),
    };
    let (ma, mb) = (metric(&fa), metric(&fb));
    // The footage's median step: real frames consecutive up to `a`, and from `b` on.
    let before: Vec<&GrayFrame> = (0..NEIGHBOURS)
        .map_while(|o| a.checked_sub(o).and_then(|i| out.metric.get(&i)))
        .collect::<Vec<_>>()
        .into_iter()
        .rev()
        .collect();
    let after_m: Vec<GrayFrame> = if wraps {
        (b..b + NEIGHBOURS)
            .map_while(|i| out.metric.get(&i).cloned())
            .collect()
    } else {
        after.iter().map(metric).collect()
    };
    let mut steps = steps_of(&before);
    steps.extend(steps_of(&after_m.iter().collect::<Vec<_>>()));
    let (fw, bw) = end_flows(&fa, &fb)?;
    let ch = choose_run(c, r, (&fa, &fb), (&ma, &mb), (&fw, &bw), &steps);
    let (times, mut worst, bound_hit, median, measurable) =
        (ch.times, ch.worst, ch.bound_hit, ch.median, ch.measurable);
    let count = times.len();
    let mut chain = vec![ma.clone()];
    for &t in &times {
        let f = inbetween_rgba(&fa, &fb, &fw, &bw, t);
        chain.push(metric(&f));
        out.emit(f)?;
    }
    chain.push(mb.clone());
    if worst.is_nan() && measurable {
        worst = steps_of(&chain.iter().collect::<Vec<_>>())
            .into_iter()
            .fold(0.0, f64::max);
    }
    outcomes.push(MorphOutcome {
        frames: count,
        median_step: if measurable { median } else { 0.0 },
        worst_step: if measurable { worst / median } else { f64::NAN },
        bound_hit,
    });
    let resume = r.start + r.len;
    if wraps {
        return Ok(resume);
    }
    let got = after.len();
    for (j, f) in after.into_iter().enumerate() {
        out.real(b + j, f)?;
    }
    Ok(b + got)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn noise(size: Size, seed: u64) -> GrayFrame {
        let mut rng = ignis_core::Rng::new(seed);
        let d = (0..size.pixels())
            .map(|_| rng.uniform(0.0, 1.0) as f32)
            .collect();
        GrayFrame::from_vec(size, d).unwrap()
    }

    #[test]
    fn detail_blend_keeps_detail_of_unrelated_frames() {
        let size = Size::new(96, 64).unwrap();
        let (a, b) = (noise(size, 1), noise(size, 2));
        let plain = crate::loops::blend(&a, &b, 0.5);
        let kept = detail_blend_gray(&a, &b, 0.5);
        let (sa, sb) = (loopq::sharpness(&a), loopq::sharpness(&b));
        let (sp, sk) = (loopq::sharpness(&plain), loopq::sharpness(&kept));
        // The plain blend of two uncorrelated textures loses about 1 − 1/√2 of the detail.
        assert!(sp < 0.8 * 0.5 * (sa + sb), "plain {sp} vs {sa} {sb}");
        assert!(sk > 0.9 * 0.5 * (sa + sb), "kept {sk} vs {sa} {sb}");
        // The local mean is the plain blend's.
        let r = detail_radius(size);
        let m = |f: &GrayFrame| {
            box_mean(
                &f.data().iter().map(|&v| [v]).collect::<Vec<_>>(),
                size,
                r * 3,
            )
        };
        let (mp, mk) = (m(&plain), m(&kept));
        let d = mp
            .iter()
            .zip(&mk)
            .map(|(x, y)| (x[0] - y[0]).abs())
            .fold(0.0f32, f32::max);
        assert!(d < 0.05, "local means differ by {d}");
    }

    #[test]
    fn detail_blend_of_identical_frames_is_the_frame() {
        let size = Size::new(40, 30).unwrap();
        let a = noise(size, 3);
        let m = detail_blend_gray(&a, &a, 0.3);
        let d = loopq::rms_diff(&a, &m);
        assert!(d < 1e-5, "{d}");
        let rgba = RgbaFrame::from_vec(
            size,
            a.data().iter().map(|&v| [v, v * 0.5, 0.1, 0.8]).collect(),
        )
        .unwrap();
        let m = detail_blend_rgba(&rgba, &rgba, 0.7);
        for (p, q) in rgba.data().iter().zip(m.data()) {
            for c in 0..4 {
                assert!((p[c] - q[c]).abs() < 1e-4);
            }
        }
    }

    /// A textured colour frame with varying (sometimes zero) alpha.
    fn noisy_rgba(size: Size, seed: u64) -> RgbaFrame {
        let n = noise(size, seed);
        let w = size.width as usize;
        let d = n
            .data()
            .iter()
            .enumerate()
            .map(|(i, &v)| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let al = ((x * 0.013).sin() + (y * 0.021).cos() + v).clamp(0.0, 1.0);
                [v + x / 900.0, 0.5 * v + 0.2, (y / 700.0) * v, al]
            })
            .collect();
        RgbaFrame::from_vec(size, d).unwrap()
    }

    /// The fused in-between equals the unfused one (two warps and `detail_blend_rgba`)
    /// within 1e-4 on every premultiplied channel (what shows over black), on noise with
    /// ragged sizes (rows and columns not a multiple of the block) and on a synthetic
    /// campfire pair with its computed flow; and gives the same bytes on 1 and 3 threads.
    #[test]
    fn fused_inbetween_equals_the_unfused_one() {
        use crate::synthetic::{synthetic_frame, FlameStyle, SyntheticParams};
        let mut cases = Vec::new();
        for (w, h) in [(640, 360), (1030, 581)] {
            let size = Size::new(w, h).unwrap();
            let fs = Size::new(37, 21).unwrap();
            let field = |k: f32| {
                let v = (0..fs.pixels())
                    .map(|i| {
                        [
                            ((i % 37) as f32 * 0.3 + k).sin() * 2.5,
                            ((i / 37) as f32 * 0.4 - k).cos() * 1.5,
                        ]
                    })
                    .collect();
                ignis_flow::FlowField::from_vec(fs, v).unwrap()
            };
            let a = noisy_rgba(size, 7);
            // A correlated partner (gain well inside its bounds) and an unrelated one.
            let near = a
                .data()
                .iter()
                .zip(noisy_rgba(size, 9).data())
                .map(|(p, q)| std::array::from_fn(|c| 0.85 * p[c] + 0.15 * q[c]))
                .collect();
            let near = RgbaFrame::from_vec(size, near).unwrap();
            cases.push((a.clone(), near, field(0.0), field(0.05)));
            cases.push((a, noisy_rgba(size, 8), field(0.0), field(1.0)));
        }
        let p = SyntheticParams {
            size: Size::new(768, 432).unwrap(),
            frames: 8,
            style: FlameStyle::Campfire,
            seed: 5,
        };
        let (a, b) = (
            synthetic_frame(&p, 2).unwrap(),
            synthetic_frame(&p, 5).unwrap(),
        );
        let (fw, bw) = end_flows(&a, &b).unwrap();
        cases.push((a, b, fw, bw));
        for (a, b, fw, bw) in &cases {
            for t in [0.2f32, 0.5, 0.9] {
                let (fast, st) = inbetween_rgba_stages(a, b, fw, bw, t);
                assert!(st.iter().all(|s| !s.0.is_empty()), "fused path taken");
                let slow = inbetween_rgba_unfused(a, b, fw, bw, t);
                let pm = |p: &[f32; 4]| [p[0] * p[3], p[1] * p[3], p[2] * p[3], p[3]];
                let worst = fast
                    .data()
                    .iter()
                    .zip(slow.data())
                    .flat_map(|(x, y)| {
                        let (x, y) = (pm(x), pm(y));
                        (0..4).map(move |c| (x[c] - y[c]).abs())
                    })
                    .fold(0.0f32, f32::max);
                assert!(
                    worst <= 1e-4,
                    "{} t={t}: fused differs by {worst}",
                    a.size()
                );
            }
        }
        let (a, b, fw, bw) = &cases[2];
        let on = |n: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(n)
                .build()
                .unwrap()
                .install(|| inbetween_rgba(a, b, fw, bw, 0.4))
        };
        assert!(on(1) == on(3), "thread count changed the in-between");
    }

    /// Frames too small for the block means take the unfused path, unchanged.
    #[test]
    fn small_frames_take_the_unfused_path() {
        let size = Size::new(200, 120).unwrap();
        let (a, b) = (noisy_rgba(size, 1), noisy_rgba(size, 2));
        let z = ignis_flow::FlowField::zero(size);
        let (f, st) = inbetween_rgba_stages(&a, &b, &z, &z, 0.5);
        assert!(st.iter().all(|s| s.0.is_empty()));
        assert_eq!(f, inbetween_rgba_unfused(&a, &b, &z, &z, 0.5));
    }

    #[test]
    fn even_times_follow_the_arc() {
        // A path that covers its first half in a tenth of the time.
        let arc: Vec<f64> = (0..=10)
            .map(|k| {
                if k == 0 {
                    0.0
                } else {
                    0.5 + 0.5 * (k - 1) as f64 / 9.0
                }
            })
            .collect();
        let t = even_times(&arc, 1);
        assert!((t[0] - 0.1).abs() < 1e-6, "{t:?}");
        let flat = even_times(&[0.0, 0.0], 3);
        assert_eq!(flat, vec![0.25, 0.5, 0.75]);
    }

    #[test]
    fn box_mean_is_the_window_mean() {
        let size = Size::new(5, 3).unwrap();
        let d: Vec<[f32; 1]> = (0..15).map(|i| [i as f32]).collect();
        let m = box_mean(&d, size, 1);
        // Centre pixel (2, 1): mean of rows 0..=2, columns 1..=3.
        let want = [1.0, 2.0, 3.0, 6.0, 7.0, 8.0, 11.0, 12.0, 13.0]
            .iter()
            .sum::<f32>()
            / 9.0;
        assert!((m[7][0] - want).abs() < 1e-5);
        // Corner (0, 0): rows 0..=1, columns 0..=1.
        assert!((m[0][0] - (0.0 + 1.0 + 5.0 + 6.0) / 4.0).abs() < 1e-5);
    }

    /// The reduced local mean of a large radius stays close to the exact box mean (a
    /// gradient plus noise), and small radii are the exact box mean.
    #[test]
    fn local_mean_follows_the_box_mean() {
        let size = Size::new(300, 200).unwrap();
        let n = noise(size, 3);
        let d: Vec<[f32; 1]> = n
            .data()
            .iter()
            .enumerate()
            .map(|(i, &v)| [(i % 300) as f32 / 300.0 + 0.2 * v])
            .collect();
        let (exact, reduced) = (box_mean(&d, size, 16), local_mean(&d, size, 16));
        let worst = exact
            .iter()
            .zip(&reduced)
            .map(|(a, b)| (a[0] - b[0]).abs())
            .fold(0.0f32, f32::max);
        assert!(worst < 0.03, "reduced local mean off by {worst}");
        assert_eq!(box_mean(&d, size, 3), local_mean(&d, size, 3));
    }

    #[test]
    fn count_grows_until_steps_fit() {
        let size = Size::new(64, 48).unwrap();
        let (a, b) = (noise(size, 4), noise(size, 5));
        let zero = ignis_flow::FlowField::zero(size);
        let d = loopq::rms_diff(&a, &b);
        let (t, worst, hit) = choose_times(&a, &b, &zero, &zero, d / 4.0, 60);
        assert!(
            !hit && worst <= d / 4.0 && t.len() >= 3,
            "{t:?} {worst} {d}"
        );
        assert!(t.windows(2).all(|p| p[0] < p[1]) && t[0] > 0.0 && t[t.len() - 1] < 1.0);
        let (t2, _, hit2) = choose_times(&a, &b, &zero, &zero, d / 100.0, 5);
        assert!(hit2 && t2.len() == 5);
    }

    /// A join's flow is the matted pair's (`ignis_flow::flow_pair_matted_rgba`, at
    /// [`MORPH_FLOW_SIDE`]): filled over the end frames' keyed-out background, not DIS's raw
    /// vectors there.
    #[test]
    fn a_joins_flow_is_filled_over_a_keyed_out_background() {
        let size = Size::new(96, 64).unwrap();
        let keyed = |f: RgbaFrame| {
            let mut d = f.data().to_vec();
            d.iter_mut().step_by(3).for_each(|p| p[3] = 0.0);
            RgbaFrame::from_vec(size, d).unwrap()
        };
        let (a, b) = (keyed(noisy_rgba(size, 7)), keyed(noisy_rgba(size, 9)));
        let p = ignis_flow::FlowParams {
            max_side: MORPH_FLOW_SIDE,
            ..Default::default()
        };
        let got = end_flows(&a, &b).unwrap();
        assert!(got == ignis_flow::flow_pair_matted_rgba(&a, &b, &p).unwrap());
        let raw = ignis_flow::flow_pair_reduced_rgba(&a, &b, &p).unwrap();
        assert!(got != raw, "the fill changed nothing");
    }
}
