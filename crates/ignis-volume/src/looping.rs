//! Seamless loops ([`crate::FireScene::looping_animator`]): the motion of a loop as a
//! continuous periodic function of loop time, and the constant-speed re-timing of its
//! frames.
//!
//! A loop of `N` frames is a periodic animation of *loop time* `τ ∈ [0, N)` (in frames):
//! the noise is periodic in time ([`crate::mapping::PeriodicLoop`]), scripts repeat a whole
//! number of times per loop ([`LoopScript`]), a simulation is replayed from its states at
//! whole frames, its tail blended into its head ([`SimTrack`]), and the puffing makes a
//! whole number of cycles. Rendered at `τ = k`, the frames are periodic but their steps
//! are not even: the noise changes faster at some times than at others (±10–60 % over a
//! loop, by chance of the seed), so one step — the seam among them — can be 1.6× the
//! median.
//!
//! Since `τ` is continuous, the long steps are fixed by moving frames in loop time
//! ([`Retimer`]), measured on the output frames themselves, with no preview: the frames
//! are rendered at uniform loop times and their metric frames taken (`ignis_core::loopq`,
//! the measure of written frames); a step over [`LoopTiming::step_bound`] times the
//! median of the steps around it (the wrap over [`LoopTiming::wrap_bound`]) has the frame
//! at one of its ends — the one whose other step is shorter — rendered again where the two
//! steps are predicted equal (both ends when one frame cannot do it). If a step of the
//! frames moved is still over its bound, they are placed once more from the steps measured
//! on that render (a regula falsi step), and the best of the tries is kept. Most steps are
//! within the bounds as rendered (their spread is 10–13 % of the median), so only a few
//! frames are rendered twice. Frame 0 stays at `τ = 0`, the period stays `N`.
//!
//! Every decision reads a bounded stretch of the loop (the median over a window of steps
//! that does not cross the wrap, a long step's neighbours, a run of moved frames between
//! two unmoved ones), so a `--chunk` of a render, which renders its frames and that margin,
//! times its frames exactly as the full render does.

use crate::motion::{Collision, Keyframe, Script};
use crate::error::Result;
use ignis_core::GrayFrame;
use std::collections::{BTreeMap, HashMap};

/// How a looping animator times its frames (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopTiming {
    /// A step longer than this many times the median step around it is fixed by moving
    /// the frames at its ends in loop time; `f64::INFINITY` renders every frame at its
    /// uniform loop time.
    pub step_bound: f64,
    /// The same for the wrap step (the last frame → frame 0).
    pub wrap_bound: f64,
    /// Half-width, in steps, of the window the median step is taken over (the whole loop
    /// when it has at most `2 · window + 1` frames).
    pub window: u32,
}

impl LoopTiming {
    /// The default: steps over 1.15× (the wrap over 1.05×) the median of the 25 steps
    /// around them are fixed — a margin under issue 16's goal (1.2× and 1.1× the loop's
    /// median), which the window's median may miss by a few per cent. Steps and cost are in
    /// `benches/README.md`.
    pub const DEFAULT: LoopTiming = LoopTiming {
        step_bound: 1.15,
        wrap_bound: 1.05,
        window: 12,
    };
    /// Frames at uniform loop times `0, 1, …, N − 1`, nothing fixed.
    pub const UNIFORM: LoopTiming = LoopTiming {
        step_bound: f64::INFINITY,
        wrap_bound: f64::INFINITY,
        window: 12,
    };

    /// Whether this timing moves any frame.
    pub fn retimes(&self) -> bool {
        self.step_bound.is_finite() || self.wrap_bound.is_finite()
    }
}

impl Default for LoopTiming {
    fn default() -> Self {
        LoopTiming::DEFAULT
    }
}

/// How many frames at the start of an `frames`-frame loop blend a simulation's state one
/// loop later into its own (a third of the loop, at least 1).
pub fn loop_blend_frames(frames: u32) -> u32 {
    (frames / 3).max(1)
}

/// Largest move of a frame from its uniform loop time, in frames: steps stay 0.2–1.8
/// frames long, so a flicker is never skipped or repeated (a candle puffs every 3 frames at
/// 30 fps).
const MAX_SHIFT: f64 = 0.4;
/// One frame is moved to fix a long step when the two steps it balances are predicted to
/// average at most this share of their bounds; otherwise both frames of the step move.
const SINGLE_MARGIN: f64 = 0.97;

/// Most frames moved together to even out one burst of speed.
const MAX_RUN: usize = 8;

/// Loop starts considered: frame 0 is the uniform frame, among the first `SHIFTS`, whose
/// step from the one before it (the wrap) is shortest.
const SHIFTS: usize = 6;

/// Renders the frame at loop time `tau` (frames) and its metric frame.
pub(crate) type RenderAt<'r, F> = dyn FnMut(f64) -> Result<(F, GrayFrame)> + 'r;

/// The re-timing of a loop's frames from the frames themselves ([`crate::looping`]):
/// frames rendered at uniform loop times, the long steps among them found and fixed by
/// rendering the frames at their ends again at new times. Every decision reads a bounded
/// stretch of the loop, so a frame's time is the same whichever frame a render starts at.
/// Generic over the rendered frame `F` (a [`crate::Frame`] in the animator).
pub(crate) struct Retimer<F> {
    n: usize,
    timing: LoopTiming,
    /// Metric frames at the uniform loop times `u` (in `0..n`), each with its rendered
    /// frame while it may still be handed out.
    uniform: BTreeMap<usize, (GrayFrame, Option<F>)>,
    /// The loop's start: frame `k` is at uniform loop time `(k + shift) mod n`
    /// ([`Retimer::shift`]).
    shift: Option<usize>,
    /// Step `j`: metric distance from uniform frame `j` to uniform frame `j + 1` (mod n).
    steps: HashMap<usize, f64>,
    /// Median step of the window starting at step `lo`.
    medians: HashMap<usize, f64>,
    /// Whether each frame is a seed ([`Retimer::seed`]).
    seeds: HashMap<usize, bool>,
    /// Runs of seeds, by first frame: the frames they move ([`Retimer::grown`]).
    grown_runs: HashMap<usize, (usize, usize)>,
    /// Decided runs of moved frames, by first frame.
    runs: BTreeMap<usize, Run<F>>,
    /// The next frame to hand out: frames before it are not kept.
    cursor: usize,
    /// Frames rendered a second or third time at a new loop time.
    pub rerenders: usize,
    /// Frames rendered at their uniform loop times.
    pub uniform_renders: usize,
}

/// Consecutive frames moved together: their loop times and, while not yet handed out,
/// their frames (`None`: the uniform frame, or rendered again when asked).
struct Run<F> {
    times: Vec<f64>,
    frames: Vec<Option<F>>,
}

impl<F> Retimer<F> {
    pub fn new(frames: u32, timing: LoopTiming) -> Retimer<F> {
        Retimer {
            n: frames as usize,
            timing,
            uniform: BTreeMap::new(),
            shift: None,
            steps: HashMap::new(),
            medians: HashMap::new(),
            seeds: HashMap::new(),
            grown_runs: HashMap::new(),
            runs: BTreeMap::new(),
            cursor: 0,
            rerenders: 0,
            uniform_renders: 0,
        }
    }

    /// Frame `k` (in `0..n`) of the loop and its loop time, rendering what its time
    /// depends on. Frames are handed out in order; asking for an earlier frame starts a
    /// new pass (it is rendered again).
    pub fn take(&mut self, k: usize, r: &mut RenderAt<'_, F>) -> Result<(f64, F)> {
        let c = self.shift(r)?;
        self.cursor = k;
        self.prune(k);
        if self.is_mover(k, r)? {
            let p = self.run_of(k, r)?;
            let own = self.runs[&p].times[k - p];
            let t = self.loop_time(own);
            let run = self.runs.get_mut(&p).expect("decided");
            if let Some(f) = run.frames[k - p].take() {
                return Ok((t, f));
            }
            if own != k as f64 {
                self.rerenders += 1;
                return Ok((t, r(t)?.0));
            }
        }
        let u = (k + c) % self.n;
        self.metric(k, r)?;
        match self.uniform.get_mut(&u).and_then(|e| e.1.take()) {
            Some(f) => Ok((u as f64, f)),
            None => {
                self.uniform_renders += 1;
                Ok((u as f64, r(u as f64)?.0))
            }
        }
    }

    /// The loop time of frame `k` if it is already known without rendering.
    pub fn known_time(&self, k: usize) -> Option<f64> {
        let c = self.shift?;
        let t = match self.runs.range(..=k).next_back() {
            Some((p, run)) if k < p + run.times.len() => run.times[k - p],
            _ => k as f64,
        };
        Some(((t + c as f64) % self.n as f64).max(0.0))
    }

    /// The loop time (in `0..n`) of a time `t` counted from frame 0.
    fn loop_time(&self, t: f64) -> f64 {
        (t + self.shift.unwrap_or(0) as f64).rem_euclid(self.n as f64)
    }

    /// The loop's start, chosen once: of the uniform frames `0..SHIFTS`, the one whose
    /// step from the uniform frame before it is shortest (ties: the first), so the wrap —
    /// held to a tighter bound than the other steps — is a short step to begin with.
    fn shift(&mut self, r: &mut RenderAt<'_, F>) -> Result<usize> {
        if let Some(c) = self.shift {
            return Ok(c);
        }
        let n = self.n;
        let mut best = (f64::INFINITY, 0);
        for c in 0..SHIFTS.min(n) {
            let a = self.uniform_metric((c + n - 1) % n, r)?.clone();
            let d = ignis_core::loopq::rms_diff(&a, self.uniform_metric(c, r)?);
            if d < best.0 {
                best = (d, c);
            }
        }
        self.shift = Some(best.1);
        Ok(best.1)
    }

    /// Drops what frames far behind `k` kept (frame 0's metric closes the loop: kept).
    fn prune(&mut self, k: usize) {
        let (n, c) = (self.n, self.shift.unwrap_or(0));
        let reach = 2 * self.timing.window as usize + 8;
        self.uniform.retain(|&u, e| {
            let j = (u + n - c) % n;
            if j < k {
                e.1 = None;
            }
            j == 0 || j + reach >= k
        });
    }

    /// The metric frame of uniform loop time `u`, rendering it if needed (its frame is
    /// kept while it may still be handed out).
    fn uniform_metric(&mut self, u: usize, r: &mut RenderAt<'_, F>) -> Result<&GrayFrame> {
        if !self.uniform.contains_key(&u) {
            let (f, m) = r(u as f64)?;
            self.uniform_renders += 1;
            let keep = match self.shift {
                Some(c) => (u + self.n - c) % self.n >= self.cursor,
                None => true,
            };
            self.uniform.insert(u, (m, keep.then_some(f)));
        }
        Ok(&self.uniform[&u].0)
    }

    /// The metric frame of frame `j` (mod n) at its uniform time.
    fn metric(&mut self, j: usize, r: &mut RenderAt<'_, F>) -> Result<&GrayFrame> {
        let u = (j + self.shift.unwrap_or(0)) % self.n;
        self.uniform_metric(u, r)
    }

    /// Step `j` (in `0..n`) between uniform frames.
    fn step(&mut self, j: usize, r: &mut RenderAt<'_, F>) -> Result<f64> {
        if let Some(&s) = self.steps.get(&j) {
            return Ok(s);
        }
        let a = self.metric(j, r)?.clone();
        let s = ignis_core::loopq::rms_diff(&a, self.metric(j + 1, r)?);
        self.steps.insert(j, s);
        Ok(s)
    }

    /// The longest step `j` may be: its bound times the median step of the window of
    /// `2 · window + 1` steps around it (moved inside the loop at its ends, not across the
    /// wrap, so frame 0 needs no frames from the loop's end).
    fn bound(&mut self, j: usize, r: &mut RenderAt<'_, F>) -> Result<f64> {
        let (n, w) = (self.n, self.timing.window as usize);
        let (lo, len) = if n <= 2 * w + 1 {
            (0, n)
        } else {
            (j.saturating_sub(w).min(n - 1 - 2 * w), 2 * w + 1)
        };
        let med = match self.medians.get(&lo) {
            Some(&m) => m,
            None => {
                let mut v = (lo..lo + len)
                    .map(|i| self.step(i, r))
                    .collect::<Result<Vec<_>>>()?;
                let m = ignis_core::loopq::median(&mut v);
                self.medians.insert(lo, m);
                m
            }
        };
        let factor = if j == n - 1 {
            self.timing.wrap_bound
        } else {
            self.timing.step_bound
        };
        Ok(factor * med)
    }

    /// Whether step `j` is over its bound.
    fn long(&mut self, j: usize, r: &mut RenderAt<'_, F>) -> Result<bool> {
        Ok(self.step(j, r)? > self.bound(j, r)?)
    }

    /// Which of the frames at the ends of long step `j` move: `[frame j, frame j + 1]`.
    /// The one whose other step is shorter, if balancing the two steps is predicted to
    /// bring them under their bounds; else both. Frame 0 (and so frame `n`) never moves.
    fn movers_of(&mut self, j: usize, r: &mut RenderAt<'_, F>) -> Result<[bool; 2]> {
        let n = self.n;
        let s = self.step(j, r)?;
        let b = self.bound(j, r)?;
        let mut best: Option<(f64, usize)> = None;
        if j + 1 < n {
            let pred = 0.5 * (s + self.step(j + 1, r)?) / b.min(self.bound(j + 1, r)?);
            best = Some((pred, 1));
        }
        if j > 0 {
            let pred = 0.5 * (s + self.step(j - 1, r)?) / b.min(self.bound(j - 1, r)?);
            if best.is_none_or(|(q, _)| pred < q) {
                best = Some((pred, 0));
            }
        }
        Ok(match best {
            Some((pred, which)) if pred <= SINGLE_MARGIN => {
                let mut m = [false; 2];
                m[which] = true;
                m
            }
            _ => [j > 0, j + 1 < n],
        })
    }

    /// Whether frame `k` is at an end of a long step and chosen to move by
    /// [`Retimer::movers_of`].
    fn seed(&mut self, k: usize, r: &mut RenderAt<'_, F>) -> Result<bool> {
        if k == 0 || k >= self.n {
            return Ok(false);
        }
        if let Some(&m) = self.seeds.get(&k) {
            return Ok(m);
        }
        let m = (self.long(k - 1, r)? && self.movers_of(k - 1, r)?[1])
            || (self.long(k, r)? && self.movers_of(k, r)?[0]);
        self.seeds.insert(k, m);
        Ok(m)
    }

    /// The frames moved for the run of seeds `p..=q`: grown, one frame at a time on the
    /// side whose step beyond is shorter, while the steps between its unmoved ends are
    /// predicted to average over [`SINGLE_MARGIN`] of their bounds (a burst of speed
    /// longer than a step is evened out over the slower steps around it), up to
    /// [`MAX_RUN`] frames.
    fn grown(&mut self, p: usize, q: usize, r: &mut RenderAt<'_, F>) -> Result<(usize, usize)> {
        let (mut p, mut q) = (p, q);
        while q + 1 - p < MAX_RUN {
            let mut sum = 0.0;
            let mut lim = f64::INFINITY;
            for j in p - 1..=q {
                sum += self.step(j, r)?;
                lim = lim.min(self.bound(j, r)?);
            }
            if sum / (q + 2 - p) as f64 <= SINGLE_MARGIN * lim {
                break;
            }
            let left = if p > 1 { Some(self.step(p - 2, r)?) } else { None };
            let right = if q + 1 < self.n { Some(self.step(q + 1, r)?) } else { None };
            match (left, right) {
                (Some(a), Some(b)) if a < b => p -= 1,
                (Some(_), None) => p -= 1,
                (_, Some(_)) => q += 1,
                (None, None) => break,
            }
        }
        Ok((p, q))
    }

    /// Whether frame `k` moves: it is a seed, or a run of seeds near it grows over it.
    fn is_mover(&mut self, k: usize, r: &mut RenderAt<'_, F>) -> Result<bool> {
        if k == 0 || k >= self.n {
            return Ok(false);
        }
        if self.seed(k, r)? {
            return Ok(true);
        }
        let (lo, hi) = (k.saturating_sub(MAX_RUN).max(1), (k + MAX_RUN).min(self.n - 1));
        let mut j = lo;
        while j <= hi {
            if !self.seed(j, r)? {
                j += 1;
                continue;
            }
            let (mut p, mut q) = (j, j);
            while p > 1 && self.seed(p - 1, r)? {
                p -= 1;
            }
            while q + 1 < self.n && self.seed(q + 1, r)? {
                q += 1;
            }
            let (gp, gq) = match self.grown_runs.get(&p) {
                Some(&g) => g,
                None => {
                    let g = self.grown(p, q, r)?;
                    self.grown_runs.insert(p, g);
                    g
                }
            };
            if (gp..=gq).contains(&k) {
                return Ok(true);
            }
            j = q + 1;
        }
        Ok(false)
    }

    /// The first frame of the run of moved frames that holds mover `k`, deciding it.
    fn run_of(&mut self, k: usize, r: &mut RenderAt<'_, F>) -> Result<usize> {
        if let Some((&p, run)) = self.runs.range(..=k).next_back() {
            if k < p + run.times.len() {
                return Ok(p);
            }
        }
        let (mut p, mut q) = (k, k);
        while p > 1 && self.is_mover(p - 1, r)? {
            p -= 1;
        }
        while q + 1 < self.n && self.is_mover(q + 1, r)? {
            q += 1;
        }
        let run = self.decide(p, q, r)?;
        self.runs.insert(p, run);
        Ok(p)
    }
}

impl<F> Retimer<F> {
    /// Times for the moved frames `p..=q` between the unmoved frames `p − 1` and `q + 1`:
    /// placed where the steps between them are predicted equal, first from the uniform
    /// steps (distance growing linearly inside each step), then, if a step is still over
    /// its bound, once more from the steps measured on those renders (regula falsi, one
    /// frame at a time in effect). The best of the uniform times and the tries is kept.
    fn decide(&mut self, p: usize, q: usize, r: &mut RenderAt<'_, F>) -> Result<Run<F>> {
        let (a, b) = (p - 1, q + 1);
        let ends = [self.metric(a, r)?.clone(), self.metric(b, r)?.clone()];
        let steps = (a..=q).map(|j| self.step(j, r)).collect::<Result<Vec<_>>>()?;
        let bounds = (a..=q).map(|j| self.bound(j, r)).collect::<Result<Vec<_>>>()?;
        let score = |d: &[f64]| {
            d.iter()
                .zip(&bounds)
                .map(|(d, b)| d / b)
                .fold(0.0, f64::max)
        };
        let uniform: Vec<f64> = (p..=q).map(|k| k as f64).collect();
        let mut best = (score(&steps), uniform.clone(), None);
        let mut knots: Vec<f64> = (a..=b).map(|k| k as f64).collect();
        let mut dist = steps;
        for _ in 0..2 {
            let times = place(&knots, &dist, p);
            let mut frames = Vec::with_capacity(times.len());
            let mut metrics = vec![ends[0].clone()];
            for (i, &t) in times.iter().enumerate() {
                let (f, m) = r(self.loop_time(t))?;
                self.rerenders += 1;
                frames.push((p + i >= self.cursor).then_some(f));
                metrics.push(m);
            }
            metrics.push(ends[1].clone());
            dist = metrics
                .windows(2)
                .map(|w| ignis_core::loopq::rms_diff(&w[0], &w[1]))
                .collect();
            let sc = score(&dist);
            if sc < best.0 {
                best = (sc, times.clone(), Some(frames));
            }
            if sc <= 1.0 {
                break;
            }
            knots = [a as f64]
                .into_iter()
                .chain(times)
                .chain([b as f64])
                .collect();
        }
        let (_, times, frames) = best;
        let frames = frames.unwrap_or_else(|| times.iter().map(|_| None).collect());
        Ok(Run { times, frames })
    }
}

/// Loop times of the frames between the first and last of `knots` (in order, `knots[i]`
/// the time of frame `first − 1 + i` so far, the ends fixed) at which the distance covered,
/// growing linearly inside each interval by `dist[i]` over `knots[i]..knots[i + 1]`, is
/// split equally; each within [`MAX_SHIFT`] of its uniform time.
fn place(knots: &[f64], dist: &[f64], first: usize) -> Vec<f64> {
    let count = knots.len() - 2;
    let total: f64 = dist.iter().sum();
    (0..count)
        .map(|i| {
            let uniform = (first + i) as f64;
            if !(total > 0.0) {
                return uniform;
            }
            let mut target = total * (i + 1) as f64 / (count + 1) as f64;
            let mut t = knots[knots.len() - 1];
            for (s, d) in dist.iter().enumerate() {
                if target <= *d {
                    t = knots[s] + (knots[s + 1] - knots[s]) * (target / d).min(1.0);
                    break;
                }
                target -= d;
            }
            t.clamp(uniform - MAX_SHIFT, uniform + MAX_SHIFT)
        })
        .collect()
}
/// A looping animator's motion ([`crate::FireScene::looping_animator`]).
#[derive(Clone, Debug)]
pub(crate) struct Looping {
    /// The loop's period in frames.
    pub frames: u64,
    /// Per fire: its script made periodic (scripted fires only).
    pub scripts: Vec<Option<LoopScript>>,
    /// Per fire: its simulation over one loop (simulated fires only).
    pub sims: Vec<Option<SimTrack>>,
}

/// A simulated fire over one loop: its control points at whole frames `0..frames` (the
/// first [`loop_blend_frames`] moved from the simulation's state one loop later to its
/// own, so frame `frames − 1` is followed by the state of frame 0), and the contacts of
/// the step into each frame.
#[derive(Clone, Debug)]
pub(crate) struct SimTrack {
    points: Vec<Vec<[f32; 4]>>,
    hits: Vec<Vec<Collision>>,
}

impl SimTrack {
    /// From the simulation's states and contacts at frames `0..frames + blend` (`states`
    /// and `hits` of that length, state `k` after `k` steps).
    pub fn new(
        states: Vec<Vec<[f32; 4]>>,
        mut hits: Vec<Vec<Collision>>,
        frames: usize,
        blend: usize,
    ) -> SimTrack {
        let mut points = states[..frames].to_vec();
        for (k, cp) in points.iter_mut().enumerate().take(blend) {
            // smoothstep from the state one loop later to this one
            let head = &states[frames + k];
            let x = k as f32 / blend as f32;
            let w = x * x * (3.0 - 2.0 * x);
            for (c, h) in cp.iter_mut().zip(head) {
                *c = [0, 1, 2, 3].map(|a| h[a] + w * (c[a] - h[a]));
            }
        }
        hits.truncate(frames);
        SimTrack { points, hits }
    }

    /// Control points at loop time `tau` (frames, in `0..frames`): linear between the
    /// states of the whole frames around it, the last frame's followed by frame 0's.
    pub fn at(&self, tau: f64) -> Vec<[f32; 4]> {
        let n = self.points.len();
        let i = (tau.floor().max(0.0) as usize).min(n - 1);
        let f = (tau - i as f64).clamp(0.0, 1.0) as f32;
        let (a, b) = (&self.points[i], &self.points[(i + 1) % n]);
        if f == 0.0 {
            return a.clone();
        }
        a.iter()
            .zip(b)
            .map(|(p, q)| [0, 1, 2, 3].map(|c| p[c] + f * (q[c] - p[c])))
            .collect()
    }

    /// The contacts of the simulation's step into frame `k` of the loop (the animator's
    /// track has none into frame 0: its state follows the last frame's by the blend). A
    /// frame moved in loop time reports its own frame's step, so each is reported once per
    /// cycle.
    pub fn hits_into(&self, k: usize) -> &[Collision] {
        self.hits.get(k).map_or(&[], |h| h.as_slice())
    }
}

/// A script made periodic with a loop: its keys closed (back to the first pose), played a
/// whole number of times per loop, and interpolated with a periodic cubic Hermite spline
/// (Catmull–Rom tangents) so the motion never stops at a key — smoothstep, which a
/// one-shot script uses, halts at every key and makes the loop's frame-to-frame steps
/// uneven.
#[derive(Clone, Debug)]
pub(crate) struct LoopScript {
    /// Key times and poses; the last pose is the first, one period later.
    keys: Vec<Keyframe>,
    /// Script seconds per loop second.
    rate: f32,
}

impl LoopScript {
    pub fn new(sc: &Script, loop_len: f32) -> LoopScript {
        let mut keys = sc.keyframes.clone();
        let (t0, t1) = (keys[0].time, keys[keys.len() - 1].time);
        if keys.len() > 1 && keys[0].points != keys[keys.len() - 1].points {
            // close the keys: back to the first pose after the mean gap
            let gap = (t1 - t0) / (keys.len() - 1) as f32;
            let back = Keyframe {
                time: t1 + gap,
                points: keys[0].points.clone(),
            };
            keys.push(back);
        }
        let period = keys[keys.len() - 1].time - t0;
        let rate = if keys.len() > 1 && period > 0.0 {
            let repeats = (loop_len / period).round().max(1.0);
            repeats * period / loop_len
        } else {
            0.0
        };
        LoopScript { keys, rate }
    }

    /// Control points at loop time `t` seconds.
    pub fn at(&self, t: f32) -> Vec<[f32; 4]> {
        let k = &self.keys;
        let m = k.len() - 1;
        if m == 0 || self.rate == 0.0 {
            return k[0].points.clone();
        }
        let (t0, period) = (k[0].time, k[m].time - k[0].time);
        let ts = t0 + (t * self.rate).rem_euclid(period);
        let i = k.partition_point(|f| f.time <= ts).clamp(1, m) - 1;
        // key `j` of the periodic sequence (any integer), with its time
        let key = |j: isize| -> (f32, &Vec<[f32; 4]>) {
            let w = j.rem_euclid(m as isize) as usize;
            let laps = j.div_euclid(m as isize) as f32;
            (k[w].time + laps * period, &k[w].points)
        };
        let i = i as isize;
        let (ta, pa) = key(i);
        let (tb, pb) = key(i + 1);
        let (tp, pp) = key(i - 1);
        let (tn, pn) = key(i + 2);
        let h = tb - ta;
        let s = ((ts - ta) / h).clamp(0.0, 1.0);
        let (s2, s3) = (s * s, s * s * s);
        let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
        let h10 = s3 - 2.0 * s2 + s;
        let h01 = -2.0 * s3 + 3.0 * s2;
        let h11 = s3 - s2;
        (0..pa.len())
            .map(|c| {
                [0, 1, 2, 3].map(|a| {
                    let ma = (pb[c][a] - pp[c][a]) / (tb - tp);
                    let mb = (pn[c][a] - pa[c][a]) / (tn - ta);
                    h00 * pa[c][a] + h10 * h * ma + h01 * pb[c][a] + h11 * h * mb
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1-D pattern scrolling three turns per loop of `n` frames, at a speed with
    /// periodic bumps (`bumps`: centre and width in frames, extra speed), as a metric frame
    /// at loop time `tau`.
    fn scrolling(n: f64, bumps: &[(f64, f64, f64)], tau: f64) -> GrayFrame {
        let tau_turn = std::f64::consts::TAU / n;
        let speed = |t: f64| {
            1.0 + bumps
                .iter()
                .map(|&(c, w, a)| {
                    let kappa = (1.0 / (tau_turn * w)).powi(2);
                    a * (kappa * ((tau_turn * (t - c)).cos() - 1.0)).exp()
                })
                .sum::<f64>()
        };
        // the phase: the speed integrated (midpoint rule, 1/64 frame), over its loop total
        let integral = |t: f64| {
            let m = (t * 64.0).round().max(1.0);
            (0..m as usize)
                .map(|i| speed((i as f64 + 0.5) * t / m) * t / m)
                .sum::<f64>()
        };
        let phase = integral(tau) / integral(n);
        let size = ignis_core::Size::new(64, 1).unwrap();
        let v = (0..64)
            .map(|x| {
                let a = std::f64::consts::TAU * (x as f64 / 64.0 + 3.0 * phase);
                (0.5 + 0.4 * a.sin()) as f32
            })
            .collect();
        GrayFrame::from_vec(size, v).unwrap()
    }

    /// Renders frames of [`scrolling`] (the "frame" is its loop time).
    fn renderer(n: usize, bumps: &[(f64, f64, f64)]) -> impl FnMut(f64) -> Result<(f64, GrayFrame)> + '_ {
        move |tau| Ok((tau, scrolling(n as f64, bumps, tau)))
    }

    /// Steps of a loop's frames ÷ their median: (wrap, largest).
    fn figures(frames: &[GrayFrame]) -> (f64, f64) {
        let steps = ignis_core::loopq::steps(frames, true).unwrap();
        let med = ignis_core::loopq::median(&mut steps.clone());
        (steps[steps.len() - 1] / med, steps.iter().cloned().fold(0.0, f64::max) / med)
    }

    /// Long steps (a burst of speed mid-loop, another at the wrap) are fixed by moving a
    /// few frames, rendering them again; the others stay at their uniform times.
    #[test]
    fn long_steps_are_fixed_by_moving_a_few_frames() {
        let n = 24;
        let bumps = [(9.5, 0.8, 0.3), (23.6, 0.6, 0.3)];
        let uniform: Vec<_> = (0..n).map(|k| scrolling(n as f64, &bumps, k as f64)).collect();
        let (wrap, max) = figures(&uniform);
        assert!(wrap > 1.1 && max > 1.2, "uniform: wrap {wrap}, max {max}");
        let mut rt = Retimer::new(n as u32, LoopTiming::DEFAULT);
        let mut render = renderer(n, &bumps);
        let taken: Vec<(f64, f64)> = (0..n).map(|k| rt.take(k, &mut render).unwrap()).collect();
        let frames: Vec<_> = taken.iter().map(|&(t, _)| scrolling(n as f64, &bumps, t)).collect();
        let (wrap, max) = figures(&frames);
        let st = ignis_core::loopq::steps(&uniform, true).unwrap();
        let st2 = ignis_core::loopq::steps(&frames, true).unwrap();
        let med = ignis_core::loopq::median(&mut st.clone());
        eprintln!("u {:?}\nf {:?}\nt {:?}", st.iter().map(|s| format!("{:.2}", s / med)).collect::<Vec<_>>(), st2.iter().map(|s| format!("{:.2}", s / med)).collect::<Vec<_>>(), taken.iter().map(|t| format!("{:.2}", t.0)).collect::<Vec<_>>());
        assert!(wrap <= 1.1 && max <= 1.2, "fixed: wrap {wrap}, max {max}");
        let moved = taken.iter().enumerate().filter(|(k, (t, _))| *t != *k as f64).count();
        assert!((1..=5).contains(&moved), "{moved} moved: {taken:?}");
        assert!(rt.rerenders <= 2 * moved, "{} renders again", rt.rerenders);
        assert_eq!(taken[0].0, 0.0);
        for (k, (t, f)) in taken.iter().enumerate() {
            assert_eq!(t, f, "frame {k}: the frame rendered at its time");
            assert!((t - k as f64).abs() <= MAX_SHIFT, "frame {k} at {t}");
        }
        // asked again (a second cycle), a frame is the same
        assert_eq!(rt.take(0, &mut render).unwrap(), taken[0]);
    }

    /// A pattern at constant speed: nothing moves, nothing is rendered twice.
    #[test]
    fn even_steps_stay_at_uniform_times() {
        let n = 30;
        let mut rt = Retimer::new(n as u32, LoopTiming::DEFAULT);
        let mut render = renderer(n, &[]);
        for k in 0..n {
            assert_eq!(rt.take(k, &mut render).unwrap().0, k as f64);
        }
        assert_eq!(rt.rerenders, 0);
    }

    /// Any range of frames, taken by a fresh re-timer that starts there (a render-farm
    /// chunk), has the times and frames of the full pass — for loops shorter and longer
    /// than the median's window.
    #[test]
    fn a_chunk_times_its_frames_as_the_full_pass() {
        for n in [20usize, 40] {
            let bumps = [(9.5, 0.8, 0.3), (n as f64 - 0.4, 0.6, 0.3), (31.0, 2.0, 0.2)];
            let mut rt = Retimer::new(n as u32, LoopTiming::DEFAULT);
            let mut render = renderer(n, &bumps);
            let full: Vec<_> = (0..n).map(|k| rt.take(k, &mut render).unwrap()).collect();
            assert!(full.iter().enumerate().any(|(k, f)| f.0 != k as f64));
            for (a, b) in [(0, 7), (7, 13), (8, 11), (10, n), (n - 1, n)] {
                let mut rt = Retimer::new(n as u32, LoopTiming::DEFAULT);
                for k in a..b {
                    assert_eq!(rt.take(k, &mut render).unwrap(), full[k], "n {n}, {a}..{b}, frame {k}");
                }
            }
        }
    }

    /// A simulation track interpolates between whole frames (the last towards frame 0)
    /// and reports each step's contacts once per cycle.
    #[test]
    fn sim_track_is_periodic_and_reports_each_step_once() {
        let states: Vec<Vec<[f32; 4]>> = (0..5).map(|k| vec![[k as f32, 0.0, 0.0, 1.0]]).collect();
        let hit = |k: usize| Collision {
            fire: 0,
            obstacle: k,
            point: [0.0; 3],
            normal: [0.0, 0.0, 1.0],
            strength: 1.0,
        };
        let hits: Vec<Vec<Collision>> = (0..5).map(|k| vec![hit(k)]).collect();
        let tr = SimTrack::new(states, hits, 4, 1);
        // frame 0 is the state one loop later (blend weight 0)
        assert_eq!(tr.at(0.0)[0][0], 4.0);
        assert_eq!(tr.at(2.5)[0][0], 2.5);
        // between the last frame and frame 0 (= state 4, the successor of state 3)
        assert_eq!(tr.at(3.5)[0][0], 3.5);
        let seen: Vec<_> = (0..4)
            .flat_map(|k| tr.hits_into(k).iter().map(|h| h.obstacle))
            .collect();
        assert_eq!(seen, vec![0, 1, 2, 3]);
    }
}
