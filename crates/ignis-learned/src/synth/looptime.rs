//! Constant-speed timing of a loop's frames.
//!
//! A loop's states are a bridge sample of the learned process ([`crate::Arp::simulate_loop`])
//! and every output frame shows the state at a continuous process time, interpolated
//! between the two steps around it. Sampled at evenly spaced times, the frames inherit
//! the process's own uneven speed: measured on a model of `candle.mp4`, steps between
//! consecutive frames spread up to 2.2× the median step, and the step across the seam is
//! as likely as any other to be one of the large ones. Played as a loop, the fast parts
//! read as jumps.
//!
//! So the loop is re-timed. A cheap preview renders states around the cycle, small, grey
//! and sRGB-encoded as the loop measure sees written frames ([`ignis_core::loopq`]). Joined
//! by straight segments (pixel blends, standing in for the state blends rendered between
//! them) they form a closed path. How densely depends on the model: one preview per output
//! frame, each interval halved (up to three times) where the preview at its middle is far
//! from the pixel blend of its ends ([`Synthesiser::preview_grid`]), so a flame whose
//! states change smoothly between frames gets few and one that changes abruptly up to 8.
//! A walk from frame 0 places each next frame where the RMS distance from the previous
//! one first reaches a step length `L`; the smallest `L` that fits the loop's frames is
//! found by regula falsi on the walk's step count, so every step is `L` and the wrap what
//! is left, at most `L`, which a few equalising sweeps share among the frames around the
//! seam. Where the walk cannot
//! apply (a still loop) the frames are spaced evenly along the path
//! ([`ignis_core::loopq::arc_times`]).
//! Last, the frames are rendered at the measure's own size
//! ([`ignis_core::loopq::metric_size`]) and any step still over `EVEN_OUT` × the median
//! is evened out with its neighbour on those renders — the small preview misses detail
//! the measure sees. The frames show only states of the process, in the same order; only
//! their spacing in time changes.
//!
//! Every preview covers only the window of its frame that some state of the loop can light
//! ([`Synthesiser::loop_canvases`]): the rest is dark in every frame and adds nothing to
//! any step. A metric-size render covers only its own state's box within the frame
//! ([`Synthesiser::patch_at`]), often a small part of that window. Both are drawn by the
//! renderer's path for small encoded grey renders ([`crate::shape::render_encoded_into`]:
//! the free render's values, eight pixels at a time), since they cover mostly lit pixels.
//!
//! The timing depends on the output size (the preview has its aspect), the model, the
//! controls and the seed, never on which frames are rendered, so a chunk of a loop equals
//! the full render's frames.

use super::Synthesiser;
use ignis_core::loopq::{arc_times, metric_size};
use ignis_core::palette::linear_to_srgb;
use ignis_core::Size;

/// The most preview states per output frame ([`Synthesiser::preview_grid`]): the walk
/// places frames between them on pixel blends of neighbouring previews, which stand in for
/// the state blends rendered there only when the previews are close (figures in
/// `benches/README.md`).
const PREVIEW_MAX: usize = 1 << SPLIT_DEPTH;
/// Halvings of a frame's interval in [`Synthesiser::preview_grid`].
const SPLIT_DEPTH: usize = 3;
/// An interval of the preview path is halved where the preview at its middle lies farther
/// than this fraction of the loop's mean step from the pixel blend of its ends.
const SPLIT_TOLERANCE: f64 = 0.05;

/// Two previews and their process times: an interval of the preview path.
struct Ends<'a> {
    t: [f64; 2],
    img: [&'a Vec<f32>; 2],
}

/// The process time at preview-path position `pos` (in previews from preview 0, between
/// them linear), for previews at `times` around a loop of `steps` process steps.
fn time_at(times: &[f64], steps: f64, pos: f64) -> f64 {
    let m = times.len();
    let i = (pos.floor().max(0.0) as usize).min(m - 1);
    let f = pos - i as f64;
    let next = times.get(i + 1).copied().unwrap_or(times[0] + steps);
    times[i] + f * (next - times[i])
}
/// The shorter side of the walk's previews in pixels (at most the output's; the other to
/// its aspect, [`preview_size`]).
const PREVIEW_SIDE: u32 = 32;

impl Synthesiser<'_> {
    /// Sets `raw` to a loop's state for the next output frame, re-timing the loop for
    /// `size` first when it has not been timed for that size.
    pub(super) fn loop_frame_state(&mut self, size: Size) {
        if self.loop_times.as_ref().map(|(s, _)| *s) != Some(size) {
            let times = self.loop_times_for(size);
            self.loop_times = Some((size, times));
        }
        let times = &self.loop_times.as_ref().expect("just set").1;
        let tau = times[(self.frame % u64::from(self.loop_frames)) as usize];
        self.set_loop_state(tau);
    }

    /// Sets `raw` to the loop's state at process time `tau` (cyclic), linear between steps.
    pub(super) fn set_loop_state(&mut self, tau: f64) {
        let states = self.looped.as_ref().expect("a looping synthesiser");
        let len = states.len();
        let i = tau.floor();
        let frac = tau - i;
        let i = (i as usize) % len;
        let (a, b) = (&states[i], &states[(i + 1) % len]);
        for ((r, &a), &b) in self.raw.iter_mut().zip(a).zip(b) {
            *r = a + frac * (b - a);
        }
    }

    /// The process time of each of the loop's frames at constant measured speed.
    fn loop_times_for(&mut self, size: Size) -> Vec<f64> {
        let n = self.loop_frames as usize;
        let steps = self.looped.as_ref().map_or(0, |s| s.len()) as f64;
        let (small, metric) = (preview_size(size), metric_size(size));
        let per_frame = PREVIEW_MAX * small.pixels() + metric.pixels();
        if n.saturating_mul(per_frame) > MAX_PREVIEW_VALUES {
            // too long a loop to preview within the memory bound: even times
            return (0..n).map(|k| k as f64 * steps / n as f64).collect();
        }
        let [small, metric] = self.loop_canvases([small, metric]);
        let (grid, times) = self.preview_grid(&small);
        let m = grid.len();
        let mut arc = vec![0.0];
        for j in 0..m {
            arc.push(arc[j] + dist(&grid[j], &grid[(j + 1) % m]));
        }
        let pos = equal_steps(&grid, &arc, n).unwrap_or_else(|| {
            // a still loop, or one the walk cannot split: constant speed along the path
            arc_times(&arc, (0..n).map(|k| k as f64 / n as f64))
                .into_iter()
                .map(|u| u * m as f64)
                .collect()
        });
        let mut tau: Vec<f64> = pos.iter().map(|&p| time_at(&times, steps, p)).collect();
        self.even_out(&mut tau, metric);
        tau
    }

    /// The walk's preview frames around the loop and their process times: one per output
    /// frame at evenly spaced times, each interval then halved where the preview rendered
    /// at its middle lies farther than [`SPLIT_TOLERANCE`] × the mean step from the pixel
    /// blend of its ends (the walk's stand-in for the states between them), down to
    /// [`PREVIEW_MAX`] per frame. Every tested middle is kept, so at least 2 per frame.
    fn preview_grid(&mut self, canvas: &Canvas) -> (Vec<Vec<f32>>, Vec<f64>) {
        let n = self.loop_frames as usize;
        let steps = self.looped.as_ref().map_or(0, |s| s.len()) as f64;
        let base: Vec<(f64, Vec<f32>)> = (0..n)
            .map(|k| {
                let t = k as f64 * steps / n as f64;
                (t, self.preview_at(t, canvas))
            })
            .collect();
        let total: f64 = (0..n).map(|k| dist(&base[k].1, &base[(k + 1) % n].1)).sum();
        let tol = SPLIT_TOLERANCE * total / n as f64;
        let (mut grid, mut times) = (Vec::new(), Vec::new());
        for k in 0..n {
            // the last interval ends at the loop's end, where frame 0's state returns
            let (t1, b) = (base.get(k + 1).map_or(steps, |x| x.0), &base[(k + 1) % n].1);
            let (t0, a) = (base[k].0, &base[k].1);
            times.push(t0);
            grid.push(a.clone());
            let ends = Ends {
                t: [t0, t1],
                img: [a, b],
            };
            self.refine(ends, SPLIT_DEPTH, tol, canvas, &mut grid, &mut times);
        }
        (grid, times)
    }

    /// Renders the middle of the interval `ends` and appends the previews inside it, in
    /// order: the middle, and the halves refined further (`depth` more levels) where the
    /// middle is farther than `tol` from the pixel blend of the ends.
    #[allow(clippy::too_many_arguments)]
    fn refine(
        &mut self,
        ends: Ends,
        depth: usize,
        tol: f64,
        canvas: &Canvas,
        grid: &mut Vec<Vec<f32>>,
        times: &mut Vec<f64>,
    ) {
        if depth == 0 {
            return;
        }
        let tm = 0.5 * (ends.t[0] + ends.t[1]);
        let c = self.preview_at(tm, canvas);
        let [a, b] = ends.img;
        let off = blend_offset(a, b, &c);
        let split = (off / c.len().max(1) as f64).sqrt() > tol;
        if split {
            let left = Ends {
                t: [ends.t[0], tm],
                img: [a, &c],
            };
            self.refine(left, depth - 1, tol, canvas, grid, times);
        }
        times.push(tm);
        grid.push(c.clone());
        if split {
            let right = Ends {
                t: [tm, ends.t[1]],
                img: [&c, b],
            };
            self.refine(right, depth - 1, tol, canvas, grid, times);
        }
    }

    /// The preview frame of the loop's state at process time `tau` (cyclic; rendered, not
    /// a pixel blend), the controls taken at the output frame shown near it.
    fn preview_at(&mut self, tau: f64, canvas: &Canvas) -> Vec<f32> {
        let steps = self.looped.as_ref().map_or(0, |s| s.len()) as f64;
        self.set_loop_state(tau);
        let at = tau * f64::from(self.loop_frames) / steps;
        let mut out = Vec::new();
        self.render_encoded(at, canvas, &mut out);
        out
    }

    /// Renders `raw` (the controls at output frame `at`) within `canvas`'s window of its
    /// frame into `out`, exposed, clamped to `0..=1` and encoded as the loop measure sees a
    /// written frame (sRGB, [`srgb_lut`], or the table given to
    /// [`Synthesiser::measure_loop_through`]): the same values as [`Self::render_window`]
    /// then that encoding, by the renderer's faster path for small grey renders
    /// ([`crate::shape::render_encoded_into`]).
    fn render_encoded(&mut self, at: f64, canvas: &Canvas, out: &mut Vec<f32>) {
        self.apply_controls(at);
        let mut place = self.place(canvas.size);
        place.cx -= f64::from(canvas.origin.0);
        place.cy -= f64::from(canvas.origin.1);
        let (shape, w) = self.model.split(&self.shown);
        self.normalised.resize(self.model.pca.n_pixels(), 0.0);
        self.model
            .pca
            .reconstruct_into(&w, w.len(), &mut self.normalised);
        let (cw, ch) = (canvas.w as usize, canvas.h as usize);
        out.clear();
        out.resize(cw * ch, 0.0);
        let enc = crate::shape::Encoding {
            exposure: self.exposure,
            lut: match &self.loop_measure {
                Some(table) => table,
                None => srgb_lut(),
            },
        };
        crate::shape::render_encoded_into(
            &self.normalised,
            &shape,
            &place,
            &self.model.shape,
            &mut self.scratch,
            f64::from(canvas.size.height),
            (cw, ch),
            enc,
            out,
        );
    }

    /// The loop's state at process time `tau` rendered at `canvas`'s frame size within
    /// the state's own box (see [`Self::raw_boxes`]; `lit` from [`Self::loop_lit`]),
    /// encoded as [`Self::render_encoded`] does: outside the box it lights no pixel.
    fn patch_at(&mut self, tau: f64, lit: [usize; 4], canvas: &Canvas) -> Patch {
        let mut patch = Patch::empty(*canvas);
        self.patch_into(tau, lit, canvas, &mut patch);
        patch
    }

    /// [`Self::patch_at`] into `patch`, reusing its buffer.
    fn patch_into(&mut self, tau: f64, lit: [usize; 4], canvas: &Canvas, patch: &mut Patch) {
        let steps = self.looped.as_ref().map_or(0, |s| s.len()) as f64;
        self.set_loop_state(tau);
        let at = tau * f64::from(self.loop_frames) / steps;
        let [b] = self.raw_boxes(at, lit, [canvas.size]);
        patch.window = Canvas::covering(canvas.size, b);
        self.render_encoded(at, &patch.window, &mut patch.data);
        patch.energy = sum_sq(&patch.data);
    }

    /// The rows and columns of the normalised image (`[r0, r1, c0, c1]`, inclusive) that
    /// hold visible light in some state of the loop: where the mean eigenflame plus every
    /// eigenflame at the largest weight the loop gives it, `Σ |w_i|max |E_i|`, exposed,
    /// reaches [`VISIBLE`]. The whole image when none does.
    fn loop_lit(&self) -> [usize; 4] {
        let pca = &self.model.pca;
        let ns = self.model.shape.norm_size as usize;
        let e = pca.components.ncols();
        let first = self.model.shape.n_shape();
        let mut wmax = vec![0.0f32; e];
        for s in self.looped.iter().flatten() {
            for (m, &w) in wmax.iter_mut().zip(&s[first..]) {
                *m = m.max(w.abs() as f32);
            }
        }
        let mut lit = [usize::MAX, 0, usize::MAX, 0];
        for (i, &mean) in pca.mean.iter().enumerate() {
            let reach: f32 = (0..e).map(|k| wmax[k] * pca.components[(i, k)].abs()).sum();
            if (mean + reach) * self.exposure >= VISIBLE {
                let (r, c) = (i / ns, i % ns);
                lit = [lit[0].min(r), lit[1].max(r), lit[2].min(c), lit[3].max(c)];
            }
        }
        if lit[0] > lit[1] {
            return [0, ns - 1, 0, ns - 1];
        }
        lit
    }

    /// The windows of frames of each of `sizes` outside which no state of the loop lights a
    /// pixel (with a pixel's margin): every state's [`Self::raw_boxes`] at the output frame
    /// it is shown near, united. Frames in between show blends of neighbouring states,
    /// whose boxes lie within the two states' up to a second-order term the margin covers.
    /// The loop measure's steps are RMS differences over whole frames; pixels that are dark
    /// in every frame add nothing to them, so the timing renders, encodes and compares the
    /// windows only (a flame often lights a small part of its frame). RMS over a window is
    /// the whole frame's times a constant, and the timing compares steps only with each
    /// other.
    fn loop_canvases<const N: usize>(&mut self, sizes: [Size; N]) -> [Canvas; N] {
        let len = self.looped.as_ref().map_or(0, |s| s.len());
        let per_step = f64::from(self.loop_frames) / len.max(1) as f64;
        let lit = self.loop_lit();
        let mut union = [[
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ]; N];
        for i in 0..len {
            self.set_loop_state(i as f64);
            for (u, b) in union
                .iter_mut()
                .zip(self.raw_boxes(i as f64 * per_step, lit, sizes))
            {
                *u = [
                    u[0].min(b[0]),
                    u[1].max(b[1]),
                    u[2].min(b[2]),
                    u[3].max(b[3]),
                ];
            }
        }
        std::array::from_fn(|k| Canvas::covering(sizes[k], union[k]))
    }

    /// Checks the walk's frames on renders at the measure's size: each step longer than
    /// `EVEN_OUT` × the median moves its frame other than frame 0 towards where its two
    /// steps are equal ([`Synthesiser::balance`]), a few passes over the loop. Each frame
    /// is rendered only within its own state's box ([`Synthesiser::patch_at`]), a fraction
    /// of the loop's canvas when the flame moves about its frame. The steps are measured
    /// on renders streamed through two reused buffers (no memory per frame, each render
    /// compared while in cache); the few frames around long steps are rendered again
    /// when a pass needs them (the same values: a render depends on its time only).
    fn even_out(&mut self, pos: &mut [f64], canvas: Canvas) {
        let n = pos.len();
        if n < 2 {
            return;
        }
        let end = self.looped.as_ref().map_or(0, |s| s.len()) as f64;
        let lit = self.loop_lit();
        let canvas = &canvas;
        let (mut steps, first, last) = self.streamed_steps(pos, lit, canvas);
        let mut img: Vec<Option<Patch>> = (0..n).map(|_| None).collect();
        (img[0], img[n - 1]) = (Some(first), Some(last));
        let step = |img: &[Option<Patch>], k: usize| {
            let (a, b) = (&img[k], &img[(k + 1) % n]);
            a.as_ref()
                .expect("rendered")
                .dist(b.as_ref().expect("rendered"), canvas)
        };
        let med = ignis_core::loopq::median(&mut steps.clone());
        for _ in 0..EVEN_OUT_PASSES {
            for k in 0..n {
                if steps[k] <= EVEN_OUT * med {
                    continue;
                }
                // move the end of step k that is not frame 0, towards its shorter step
                let j = if (k + 1) % n != 0 && steps[(k + 1) % n] < steps[(k + n - 1) % n] {
                    (k + 1) % n
                } else if k != 0 {
                    k
                } else {
                    1
                };
                for i in [j - 1, j, (j + 1) % n] {
                    if img[i].is_none() {
                        img[i] = Some(self.patch_at(pos[i], lit, canvas));
                    }
                }
                let ends = [pos[j - 1], pos.get(j + 1).copied().unwrap_or(end)];
                let now = (pos[j], steps[j - 1] - steps[j], steps[j - 1].max(steps[j]));
                let (ia, ib) = (&img[j - 1], &img[(j + 1) % n]);
                let ends_img = [ia, ib].map(|p| p.as_ref().expect("rendered"));
                let (best, at) = self.balance(ends_img, ends, now, lit, canvas);
                let Some(best) = best else { continue };
                let before = (steps[j - 1].max(steps[j]), pos[j], img[j].replace(best));
                pos[j] = at;
                let (s0, s1) = (step(&img, j - 1), step(&img, j));
                if s0.max(s1) < before.0 {
                    (steps[j - 1], steps[j]) = (s0, s1);
                } else {
                    // no better: keep the frame where it was
                    pos[j] = before.1;
                    img[j] = before.2;
                }
            }
        }
    }

    /// The steps between consecutive frames at `pos` (the last one the wrap) on their
    /// metric-size renders ([`Self::patch_at`]), each render compared with the previous
    /// one as it is made, in two reused buffers; and the renders of the first and last
    /// frames. `pos` holds at least two frames.
    fn streamed_steps(
        &mut self,
        pos: &[f64],
        lit: [usize; 4],
        canvas: &Canvas,
    ) -> (Vec<f64>, Patch, Patch) {
        let first = self.patch_at(pos[0], lit, canvas);
        let mut prev = self.patch_at(pos[1], lit, canvas);
        let mut steps = vec![first.dist(&prev, canvas)];
        let mut cur = Patch::empty(*canvas);
        for &p in &pos[2..] {
            self.patch_into(p, lit, canvas, &mut cur);
            steps.push(prev.dist(&cur, canvas));
            std::mem::swap(&mut prev, &mut cur);
        }
        steps.push(prev.dist(&first, canvas));
        (steps, first, prev)
    }

    /// A frame between grid positions `ends` whose longer step, from `ends_img[0]` or to
    /// `ends_img[1]`, is shorter than the current frame's, and its position: the try with
    /// the shortest longer step of at most [`EVEN_OUT_RENDERS`] rendered tries at the root
    /// of `g(x) = d(a, x) − d(x, b)` (which runs from `−d(a, b)` at one end to `d(a, b)` at
    /// the other), sought from the frame's current position `now` (`(x, g(x), max step)`,
    /// known without a render) by regula falsi (Illinois), a bisection after a try that
    /// did not halve the bracket (the path's distances need not grow evenly), until the
    /// steps agree to [`EVEN_OUT_TOLERANCE`]. `None` when no try beats the current frame.
    fn balance(
        &mut self,
        ends_img: [&Patch; 2],
        ends: [f64; 2],
        now: (f64, f64, f64),
        lit: [usize; 4],
        canvas: &Canvas,
    ) -> (Option<Patch>, f64) {
        let span = ends_img[0].dist(ends_img[1], canvas);
        let (mut lo, mut hi) = ((ends[0], -span), (ends[1], span));
        if now.1 < 0.0 {
            lo = (now.0, now.1);
        } else {
            hi = (now.0, now.1);
        }
        let (mut best, mut at, mut best_max) = (None, now.0, now.2);
        let mut kept = 0i32; // which end the last tries kept: −1 lo, +1 hi
        let mut halved = true; // whether the last try halved the bracket
        for _ in 0..EVEN_OUT_RENDERS {
            let w = hi.0 - lo.0;
            let f = if halved && hi.1 > lo.1 {
                (-lo.1 / (hi.1 - lo.1)).clamp(0.1, 0.9)
            } else {
                0.5
            };
            let x = lo.0 + w * f;
            let ix = self.patch_at(x, lit, canvas);
            let (s0, s1) = (ends_img[0].dist(&ix, canvas), ix.dist(ends_img[1], canvas));
            let g = s0 - s1;
            if s0.max(s1) < best_max {
                (best_max, at) = (s0.max(s1), x);
                best = Some(ix);
            }
            if g.abs() <= EVEN_OUT_TOLERANCE * span {
                break;
            }
            halved = if g < 0.0 { f >= 0.5 } else { f <= 0.5 };
            if g < 0.0 {
                lo = (x, g);
                if kept == -1 {
                    hi.1 *= 0.5;
                }
                kept = -1;
            } else {
                hi = (x, g);
                if kept == 1 {
                    lo.1 *= 0.5;
                }
                kept = 1;
            }
        }
        (best, at)
    }
}

/// The least linear value the timing counts as light: below half a step of 8-bit sRGB
/// (`0.5 / 255` encoded), so a written frame shows it as black.
const VISIBLE: f32 = 1.5e-4;

/// A window of a frame of `size`: `w × h` pixels from `origin` (top left).
#[derive(Clone, Copy, Debug)]
struct Canvas {
    size: Size,
    origin: (u32, u32),
    w: u32,
    h: u32,
}

impl Canvas {
    /// The window of a frame of `size` covering the pixel box `b` (see
    /// [`crate::shape::pixel_box`]) with a pixel's margin, within the frame (the whole
    /// frame for a box that is not finite, at least one pixel).
    fn covering(size: Size, b: [f64; 4]) -> Canvas {
        if !b.iter().all(|v| v.is_finite()) {
            return Canvas {
                size,
                origin: (0, 0),
                w: size.width,
                h: size.height,
            };
        }
        let span = |lo: f64, hi: f64, n: u32| {
            let a = (lo.floor() - 1.0).clamp(0.0, f64::from(n - 1)) as u32;
            let b = (hi.floor() + 2.0).clamp(f64::from(a + 1), f64::from(n)) as u32;
            (a, b - a)
        };
        let (x0, w) = span(b[0], b[1], size.width);
        let (y0, h) = span(b[2], b[3], size.height);
        Canvas {
            size,
            origin: (x0, y0),
            w,
            h,
        }
    }
}

/// An encoded render within a window of its frame; the frame is dark outside it.
struct Patch {
    window: Canvas,
    data: Vec<f32>,
    /// Sum of the squared values.
    energy: f64,
}

impl Patch {
    /// A patch of no pixels in a window of `canvas`'s frame (a buffer to render into).
    fn empty(canvas: Canvas) -> Patch {
        Patch {
            window: canvas,
            data: Vec::new(),
            energy: 0.0,
        }
    }

    /// RMS difference of the two frames over `canvas` (a window of the same frame size
    /// holding both patches' light): the sum of squared differences where the windows
    /// overlap, plus each patch's own light outside the overlap.
    fn dist(&self, other: &Patch, canvas: &Canvas) -> f64 {
        let (a, b) = (&self.window, &other.window);
        let (x0, x1) = (
            a.origin.0.max(b.origin.0),
            (a.origin.0 + a.w).min(b.origin.0 + b.w),
        );
        let (y0, y1) = (
            a.origin.1.max(b.origin.1),
            (a.origin.1 + a.h).min(b.origin.1 + b.h),
        );
        let (mut diff, mut ea, mut eb) = (0.0, 0.0, 0.0);
        if x0 < x1 && y0 < y1 {
            fn row(p: &Patch, y: u32, x0: u32, x1: u32) -> &[f32] {
                let w = &p.window;
                let at = ((y - w.origin.1) * w.w + (x0 - w.origin.0)) as usize;
                &p.data[at..at + (x1 - x0) as usize]
            }
            for y in y0..y1 {
                let (ra, rb) = (row(self, y, x0, x1), row(other, y, x0, x1));
                diff += ignis_core::loopq::sum_sq_diff(ra, rb);
                ea += sum_sq(ra);
                eb += sum_sq(rb);
            }
        }
        let sq = diff + (self.energy - ea).max(0.0) + (other.energy - eb).max(0.0);
        (sq / (canvas.w * canvas.h).max(1) as f64).sqrt()
    }
}

/// The walk's preview size for output frames of `size`: the shorter side [`PREVIEW_SIDE`]
/// (or the output's when shorter), the other to the output's aspect, at least 2. A flame's
/// scale follows the frame's height, so a wide frame's preview keeps its height (its flame
/// as many preview pixels as in a square frame's) and a tall one its width.
fn preview_size(size: Size) -> Size {
    let short = size.width.min(size.height);
    let scale = f64::from(PREVIEW_SIDE.min(short).max(1)) / f64::from(short.max(1));
    let side = |v: u32| ((f64::from(v) * scale).round() as u32).clamp(2, v.max(2));
    Size {
        width: side(size.width),
        height: side(size.height),
    }
}

/// The most preview values a loop's timing holds at once (the walk's previews and the
/// even-out's metric-size renders): 128 M (512 MB), a 3,000-frame loop at 256² takes 74 M.
/// Longer loops keep even times.
const MAX_PREVIEW_VALUES: usize = 128 << 20;

/// Steps longer than this many times the median are evened out with their neighbour.
const EVEN_OUT: f64 = 1.15;
/// Passes of [`Synthesiser::even_out`] over the loop: each shares a long step with one
/// neighbour, so a run of long steps reaches the shorter ones around it a frame per pass
/// (3 passes left 1.23–1.25 × the median in 160×90 and 256×144 loops of the bench model).
const EVEN_OUT_PASSES: usize = 8;
/// Renders per evened-out frame ([`Synthesiser::balance`]).
const EVEN_OUT_RENDERS: usize = 6;
/// [`Synthesiser::balance`] stops when the two steps differ by less than this fraction of
/// their sum.
const EVEN_OUT_TOLERANCE: f64 = 0.02;

/// `n` positions on the closed preview path (in grid steps from grid point 0, the first
/// 0) whose consecutive preview frames are equally far apart: the smallest step length
/// whose [`walk`] fits `n` frames or fewer, found within [`LENGTH_TOLERANCE`] by regula
/// falsi on the walk's step count ([`Walk::steps`], continuous where the count changes
/// from `n` to `n + 1`), the few frames short of `n` [`fill`]ed in and the seam
/// [`relax`]ed. `None` for a path of zero length or when the walk falls more than
/// [`MAX_FILL`] frames short.
fn equal_steps(grid: &[Vec<f32>], arc: &[f64], n: usize) -> Option<Vec<f64>> {
    let total = arc[arc.len() - 1];
    if !(total > 1e-9) || n < 2 {
        return None;
    }
    // A step of length L spans at least L of the path, so L = total / (n − 1) fits n
    // frames or fewer; shrink it until more than n fit.
    let mut hi = total / (n - 1) as f64;
    let tol = LENGTH_TOLERANCE * hi;
    let first = walk(grid, arc, hi, n);
    let mut h_hi = first.steps - n as f64;
    let mut best = first.fits.then_some(first.pos)?;
    // the count goes about as 1 / L: first try just under where that puts n steps
    let mut lo = (hi * first.steps / n as f64 * GUESS_MARGIN).clamp(SHRINK * hi, hi * GUESS_MARGIN);
    let mut h_lo = f64::NAN;
    for _ in 0..40 {
        let w = walk(grid, arc, lo, n);
        if !w.fits {
            h_lo = w.steps - n as f64;
            break;
        }
        (best, hi, h_hi) = (w.pos, lo, w.steps - n as f64);
        lo *= SHRINK;
    }
    // Illinois: a secant between the bracket's ends, halving the weight of an end kept
    // twice in a row; within the bracket's middle 98 %, else its midpoint.
    let mut kept = 0i32; // −1: lo kept by the last try, +1: hi
    for _ in 0..MAX_LENGTH_TRIES {
        if !(hi - lo > tol) || !h_lo.is_finite() {
            break;
        }
        let secant = hi - h_hi * (hi - lo) / (h_hi - h_lo);
        let margin = 0.01 * (hi - lo);
        let x = if secant > lo + margin && secant < hi - margin {
            secant
        } else {
            0.5 * (lo + hi)
        };
        let w = walk(grid, arc, x, n);
        let h = w.steps - n as f64;
        if w.fits {
            (best, hi, h_hi) = (w.pos, x, h);
            if kept == 1 {
                h_lo *= 0.5;
            }
            kept = 1;
        } else {
            (lo, h_lo) = (x, h);
            if kept == -1 {
                h_hi *= 0.5;
            }
            kept = -1;
        }
    }
    if best.len() + MAX_FILL < n {
        return None;
    }
    fill(grid, &mut best, n);
    relax(grid, &mut best);
    Some(best)
}

/// The preview image at grid position `pos` (a pixel blend of the grid points around it).
fn image_at(grid: &[Vec<f32>], pos: f64) -> Vec<f32> {
    let m = grid.len();
    let i = pos.floor();
    let f = (pos - i) as f32;
    let (a, b) = (&grid[(i as usize) % m], &grid[(i as usize + 1) % m]);
    a.iter().zip(b).map(|(&x, &y)| x + f * (y - x)).collect()
}

/// Spreads the slack of the wrap step (the walk's remainder, shorter than its other steps)
/// over the frames around the seam: each of them in turn moves to where its two steps are
/// equal (Gauss–Seidel sweeps), so the seam is not a held frame. Frame 0 stays.
fn relax(grid: &[Vec<f32>], pos: &mut [f64]) {
    let n = pos.len();
    let m = grid.len() as f64;
    let w = (n / 4).min(SEAM_WINDOW);
    let window: Vec<usize> = ((n - w)..n).chain(1..=w.min(n - 1)).collect();
    for _ in 0..SEAM_SWEEPS {
        for &k in &window {
            let a = pos[k - 1];
            let b = if k + 1 < n { pos[k + 1] } else { m };
            let (ia, ib) = (image_at(grid, a), image_at(grid, b));
            let (mut lo, mut hi) = (a, b);
            for _ in 0..16 {
                let x = 0.5 * (lo + hi);
                let ix = image_at(grid, x);
                if dist(&ia, &ix) < dist(&ix, &ib) {
                    lo = x;
                } else {
                    hi = x;
                }
            }
            pos[k] = 0.5 * (lo + hi);
        }
    }
}

/// How close [`equal_steps`] brings the walk's step length to the least that fits, as a
/// fraction of the first length tried (the seam's relaxation spreads what is left over).
const LENGTH_TOLERANCE: f64 = 1.0 / 65536.0;
/// The most walks [`equal_steps`] tries after bracketing the step length (bisection alone
/// needs 14 to reach [`LENGTH_TOLERANCE`]).
const MAX_LENGTH_TRIES: usize = 24;
/// Factor by which the walk's step length is lowered until more than `n` frames fit.
const SHRINK: f64 = 0.75;
/// The first step length [`equal_steps`] lowers to: this factor under the length at which
/// the first walk's count, taken as inversely proportional to the length, would be `n`.
const GUESS_MARGIN: f64 = 0.995;
/// Frames on each side of the seam that share the wrap step's slack.
const SEAM_WINDOW: usize = 8;
/// Equalising sweeps over them.
const SEAM_SWEEPS: usize = 16;

/// Adds frames to a walk that placed fewer than `n` (its chord length fits `n + 1` but not
/// `n`): each goes halfway along the largest remaining step, so no step grows.
fn fill(grid: &[Vec<f32>], pos: &mut Vec<f64>, n: usize) {
    let m = grid.len() as f64;
    let step = |pos: &[f64], k: usize| {
        let end = pos.get(k + 1).copied().unwrap_or(m);
        dist(&image_at(grid, pos[k]), &image_at(grid, end))
    };
    let mut steps: Vec<f64> = (0..pos.len()).map(|k| step(pos, k)).collect();
    while pos.len() < n {
        let k = (0..steps.len())
            .max_by(|&a, &b| steps[a].total_cmp(&steps[b]))
            .unwrap_or(0);
        let end = pos.get(k + 1).copied().unwrap_or(m);
        pos.insert(k + 1, 0.5 * (pos[k] + end));
        steps[k] = step(pos, k);
        steps.insert(k + 1, step(pos, k + 1));
    }
}

/// The most frames [`fill`] adds to a walk (the search ends with the walk at most a
/// frame or two short of `n`).
const MAX_FILL: usize = 8;

/// The sRGB table of the timing's renders ([`crate::shape::Encoding`]): [`SRGB_STEPS`] + 1
/// points, linear between them. A preview frame is clamped to `0..=1` and encoded as the
/// loop measure sees a written one.
fn srgb_lut() -> &'static [f32] {
    static LUT: std::sync::OnceLock<Vec<f32>> = std::sync::OnceLock::new();
    LUT.get_or_init(|| {
        (0..=SRGB_STEPS)
            .map(|i| linear_to_srgb(i as f32 / SRGB_STEPS as f32))
            .collect()
    })
}

/// Intervals of the sRGB table.
const SRGB_STEPS: usize = 1024;

/// RMS difference of two preview frames.
fn dist(a: &[f32], b: &[f32]) -> f64 {
    (ignis_core::loopq::sum_sq_diff(a, b) / a.len().max(1) as f64).sqrt()
}

/// `[|g − p0|², (p0 − q)·(g − p0), |p0 − q|²]` for equally long `p0`, `g`, `q`: eight
/// running `f32` sums of each (so the loop vectorises), added in `f64` in a fixed order.
fn segment_sums(p0: &[f32], g: &[f32], q: &[f32]) -> [f64; 3] {
    let mut acc = [[0f32; 8]; 3];
    let (c0, c1, c2) = (p0.chunks_exact(8), g.chunks_exact(8), q.chunks_exact(8));
    let tail = (c0.remainder(), c1.remainder(), c2.remainder());
    for ((x0, x1), q) in c0.zip(c1).zip(c2) {
        for l in 0..8 {
            let (d0, e) = (x0[l] - q[l], x1[l] - x0[l]);
            acc[0][l] += e * e;
            acc[1][l] += d0 * e;
            acc[2][l] += d0 * d0;
        }
    }
    let mut out = acc.map(|lanes| lanes.iter().map(|&v| f64::from(v)).sum::<f64>());
    for ((&x0, &x1), &q) in tail.0.iter().zip(tail.1).zip(tail.2) {
        let (d0, e) = (f64::from(x0 - q), f64::from(x1 - x0));
        out[0] += e * e;
        out[1] += d0 * e;
        out[2] += d0 * d0;
    }
    out
}

/// Σ a² of a patch's samples: eight running `f32` sums (so the loop vectorises), added in
/// `f64` in a fixed order, as [`ignis_core::loopq::sum_sq_diff`] sums differences.
fn sum_sq(a: &[f32]) -> f64 {
    let mut lanes = [0f32; 8];
    let chunks = a.chunks_exact(8);
    let tail = chunks.remainder();
    for c in chunks {
        for (l, &v) in lanes.iter_mut().zip(c) {
            *l += v * v;
        }
    }
    let head: f64 = lanes.iter().map(|&v| f64::from(v)).sum();
    head + tail
        .iter()
        .map(|&v| f64::from(v) * f64::from(v))
        .sum::<f64>()
}

/// `Σ ((a + b) / 2 − c)²` for equally long slices: eight running `f32` sums (so the loop
/// vectorises), added in `f64` in a fixed order.
fn blend_offset(a: &[f32], b: &[f32], c: &[f32]) -> f64 {
    let mut lanes = [0f32; 8];
    let (ca, cb, cc) = (a.chunks_exact(8), b.chunks_exact(8), c.chunks_exact(8));
    let tail = (ca.remainder(), cb.remainder(), cc.remainder());
    for ((a, b), c) in ca.zip(cb).zip(cc) {
        for l in 0..8 {
            let d = 0.5 * (a[l] + b[l]) - c[l];
            lanes[l] += d * d;
        }
    }
    let head: f64 = lanes.iter().map(|&v| f64::from(v)).sum();
    let rest: f64 = (tail.0.iter().zip(tail.1).zip(tail.2))
        .map(|((&a, &b), &c)| f64::from(0.5 * (a + b) - c).powi(2))
        .sum();
    head + rest
}

/// A [`walk`]'s frames and its step count.
struct Walk {
    /// The frames' positions (all of them when the walk fits).
    pos: Vec<f64>,
    /// Steps of the walk's length around the loop: when it fits, its frames less one plus
    /// the wrap's fraction of a step (so it runs on continuously where the frame count
    /// changes); when it does not, `n` over the fraction of the path's length (`arc`) the
    /// first `n` steps covered, an estimate.
    steps: f64,
    /// Whether `n` frames or fewer fit.
    fits: bool,
}

/// Walks the closed polyline through `grid` (preview frames at evenly spaced times, the
/// last joined back to the first) from grid point 0, placing each next frame where the
/// straight-line (RMS) distance from the previous one first reaches `chord`; positions
/// are in grid steps, between grid points on the segment (a pixel blend, the preview's
/// model of the state blend rendered there). Stops once more than `n` frames fit.
fn walk(grid: &[Vec<f32>], arc: &[f64], chord: f64, n: usize) -> Walk {
    let m = grid.len();
    let l2 = chord * chord * grid[0].len() as f64;
    let mut cur: Vec<f32> = grid[0].clone();
    // the next frame's blend is made here, then swapped with `cur` (no allocation a step)
    let mut spare: Vec<f32> = Vec::with_capacity(cur.len());
    let mut pos = 0.0f64;
    let mut out = vec![0.0];
    let mut j = 1;
    let sq = ignis_core::loopq::sum_sq_diff;
    let len = grid[0].len() as f64;
    loop {
        // grid points less than `chord` along the path from cur are nearer than it
        let i = (pos.floor() as usize).min(m - 1);
        let at = arc[i] + (pos - i as f64) * (arc[i + 1] - arc[i]);
        j = j.max(arc.partition_point(|&v| v - at < chord));
        while j <= m {
            let d2 = sq(&grid[j % m], &cur);
            if d2 >= l2 {
                break;
            }
            // points within chord − d of grid point j along the path are nearer than chord
            let slack = chord - (d2 / len).sqrt();
            let from = arc[j];
            j = (j + 1).max(arc.partition_point(|&v| v - from < slack));
        }
        if j > m {
            // the wrap: what is left of the path from the last frame, under a step
            let left = (sq(&grid[0], &cur) / len).sqrt() / chord;
            let steps = (out.len() - 1) as f64 + left;
            return Walk {
                pos: out,
                steps,
                fits: true,
            };
        }
        // the segment into grid point j starts at cur when cur lies on it
        let from_cur = pos > (j - 1) as f64;
        let p0: &[f32] = if from_cur { &cur } else { &grid[j - 1] };
        let p0_pos = if from_cur { pos } else { (j - 1) as f64 };
        let g = &grid[j % m];
        // |p0 + s (g − p0) − cur|² = l2
        let [a, b, c] = segment_sums(p0, g, &cur);
        let c = c - l2;
        let s = if a > 0.0 {
            ((-b + (b * b - a * c).max(0.0).sqrt()) / a).clamp(0.0, 1.0)
        } else {
            1.0
        };
        spare.clear();
        spare.extend(
            p0.iter()
                .zip(g.iter())
                .map(|(&x0, &x1)| x0 + s as f32 * (x1 - x0)),
        );
        pos = p0_pos + s * (j as f64 - p0_pos);
        std::mem::swap(&mut cur, &mut spare);
        if out.len() == n {
            // n steps reached at this point of the path: as many again for the rest
            let i = (pos.floor() as usize).min(m - 1);
            let at = arc[i] + (pos - i as f64) * (arc[i + 1] - arc[i]);
            let total = arc[m];
            let steps = if at > 0.0 {
                n as f64 * total / at
            } else {
                f64::INFINITY
            };
            return Walk {
                pos: out,
                steps: steps.max(n as f64),
                fits: false,
            };
        }
        out.push(pos);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The even-out's steps measured on renders streamed through two reused buffers
    /// equal those between renders made each on its own (a reused buffer keeps nothing of
    /// the render before it), and its first and last renders are those frames'.
    #[test]
    fn streamed_steps_equal_steps_of_separate_renders() {
        let size = Size::new(96, 96).unwrap();
        let clip = crate::synthetic::flame_clip(size, 40, 2);
        let p = crate::TrainParams {
            em: crate::EmParams {
                particles: 60,
                seed: 2,
                ..crate::EmParams::default()
            },
            ..crate::TrainParams::default()
        };
        let t = crate::train(clip, &p, &mut ignis_core::progress::NoProgress).unwrap();
        let n = 12u32;
        let mut s = Synthesiser::looping(&t.model, crate::Controls::default(), 3, n).unwrap();
        let [canvas] = s.loop_canvases([metric_size(Size::new(80, 60).unwrap())]);
        let lit = s.loop_lit();
        let steps = s.looped.as_ref().unwrap().len() as f64;
        // uneven times, so neighbouring boxes differ in size
        let pos: Vec<f64> = (0..n)
            .map(|k| (k as f64 + 0.4 * (k % 3) as f64) * steps / (n as f64 + 1.0))
            .collect();
        let (streamed, first, last) = s.streamed_steps(&pos, lit, &canvas);
        let each: Vec<Patch> = pos.iter().map(|&p| s.patch_at(p, lit, &canvas)).collect();
        let want: Vec<f64> = (0..n as usize)
            .map(|k| each[k].dist(&each[(k + 1) % n as usize], &canvas))
            .collect();
        assert_eq!(streamed, want);
        for (a, b) in [(&first, &each[0]), (&last, &each[n as usize - 1])] {
            assert_eq!(a.data, b.data);
            assert_eq!(a.energy, b.energy);
        }
        assert!(want.iter().any(|&d| d > 0.0), "a still loop tests nothing");
        let sizes: Vec<usize> = each.iter().map(|p| p.data.len()).collect();
        assert!(
            sizes.iter().any(|&l| l != sizes[0]),
            "boxes all alike: {sizes:?}"
        );
    }

    /// A patch's distance is the RMS difference of the two frames over the canvas, each
    /// dark outside its window: overlapping, nested and disjoint windows.
    #[test]
    fn patch_distance_equals_the_whole_canvas_difference() {
        let size = Size {
            width: 20,
            height: 16,
        };
        let canvas = Canvas {
            size,
            origin: (2, 1),
            w: 15,
            h: 12,
        };
        let patch = |x0: u32, y0: u32, w: u32, h: u32, seed: u32| {
            let data: Vec<f32> = (0..w * h)
                .map(|i| ((i * 7 + seed * 13) % 11) as f32 / 10.0)
                .collect();
            let energy = data.iter().map(|&v| f64::from(v).powi(2)).sum();
            let window = Canvas {
                size,
                origin: (x0, y0),
                w,
                h,
            };
            Patch {
                window,
                data,
                energy,
            }
        };
        let embed = |p: &Patch| {
            let mut full = vec![0.0f32; (canvas.w * canvas.h) as usize];
            for y in 0..p.window.h {
                for x in 0..p.window.w {
                    let (cx, cy) = (p.window.origin.0 + x - 2, p.window.origin.1 + y - 1);
                    full[(cy * canvas.w + cx) as usize] = p.data[(y * p.window.w + x) as usize];
                }
            }
            full
        };
        let cases = [
            (patch(3, 2, 6, 5, 1), patch(5, 4, 8, 7, 2)),
            (patch(2, 1, 15, 12, 3), patch(6, 5, 3, 2, 4)),
            (patch(2, 1, 4, 4, 5), patch(12, 8, 5, 5, 6)),
        ];
        for (a, b) in &cases {
            let want = dist(&embed(a), &embed(b));
            let got = a.dist(b, &canvas);
            assert!((got - want).abs() < 1e-6 * want.max(1.0), "{got} vs {want}");
            assert!((b.dist(a, &canvas) - got).abs() < 1e-12);
        }
    }
}
