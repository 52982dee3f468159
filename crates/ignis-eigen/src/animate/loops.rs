//! Loop search and loop closing (issue 15): find the best loop of about a requested length in
//! a clip, and choose how to close it, by what the written frames will measure.
//!
//! Sources: eigenfires-thesis.txt §5.1 (loops from a database clip); Schödl et al., *Video
//! Textures* (SIGGRAPH 2000) §3.2–3.3 (the dynamics-preserving transition cost: frame
//! distances filtered over neighbouring pairs); `shared/tools/loop_metrics.py` (the seam
//! and ghost measures and the crossfade / Video Textures peers).
//!
//! Two stages:
//! 1. [`search`]: distances between frames in PCA weight space (first E Eigenfires),
//!    O(n²·E), and for every loop `start..end` of length within ±[`SearchParams::tolerance`]
//!    of the target the filtered cost of jumping from `end - 1` back to `start`:
//!    `Σ_{o=-2..=1} w_o · D[end + o][start + o] / 8` with `w = 1, 3, 3, 1` (the weights of
//!    loop_metrics.py): frame `end` (the one the footage would show next) must look like
//!    frame `start`, and so must their neighbours, so motion carries across the seam.
//!    Ranked, near-duplicates suppressed.
//! 2. [`evaluate`]: each candidate closed every way ([`Closing`]: a plain cut, a crossfade
//!    or a motion-compensated morph over m frames) is built on the *metric frames* of the
//!    footage (128-px grey, what `ignis_core::loopq` measures the written output on) and
//!    its seam and ghost are computed exactly as they will be measured; [`choose`] picks the
//!    lowest [`score`]. So the choice adapts to the footage (its own median step, its own
//!    bursts) instead of constants tuned to a few clips.
//!
//! Layout of a closed loop `start..end` with `m` transition frames (indices into the
//! window): the body `start + m .. end`, then transition frame `t` (0..m) made from frame
//! `end + t` going into frame `start + t` with weight `(t + 1) / (m + 1)` on the latter
//! (the crossfade of loop_metrics.py, rotated to start after the head it replaces). Played
//! repeatedly, the last transition frame is followed by `start + m`. It needs frames up to
//! `end + m - 1`. Soft frames of the body (alone or two in a row) may be left out
//! ([`Skips`]) when the measured score says the loop is better without them: the footage's
//! own blurred frames would otherwise be the loop's ghost.
//!
//! This crate knows no flow or codec: the morph comes in through [`PairMorph`] (the CLI
//! implements it with `ignis_flow`); [`Crossfade`] is the plain blend.

use ignis_core::loopq::{self, LoopQuality};
use ignis_core::GrayFrame;
use rayon::prelude::*;

use crate::error::{EigenError, Result};

/// Filter taps over neighbouring frame pairs (offsets −2..=1), as loop_metrics.py.
pub const FILTER: [f64; 4] = [1.0, 3.0, 3.0, 1.0];
/// Transition lengths tried by [`evaluate`] (0 = plain cut).
pub const TRANSITION_LENGTHS: [usize; 10] = [0, 2, 3, 4, 6, 8, 10, 12, 16, 20];
/// Weight of the ghost shortfall in [`score`].
pub const GHOST_WEIGHT: f64 = 3.0;
/// Most footage frames a closed loop may leave out ([`Skips`]): the capacity of the
/// fixed-size set. The real bounds are the footage's (see [`Skips`]).
pub const MAX_SKIPS: usize = 16;

/// Body frames a closed loop leaves out (window indices, ascending): soft footage frames —
/// motion blur, a duplicated blurred frame, a compression glitch — that would be the loop's
/// ghost, alone or two in a row. Playing `i - 1` then `i + 1` (or `i + 2`) is a Video
/// Textures transition to a later frame (Schödl 2000 §3). Allowed only where the step
/// across the left-out frames is no larger than the largest step the footage itself takes
/// inside the loop (so the loop never moves faster than its own footage does), with a kept
/// frame between two left-out runs, the loop never shorter than the search's shortest
/// loop; and kept only when the measured [`score`] is better with it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub struct Skips {
    n: u8,
    at: [u32; MAX_SKIPS],
}

impl Skips {
    /// The left-out frames, ascending.
    pub fn as_slice(&self) -> &[u32] {
        &self.at[..self.n as usize]
    }
    pub fn len(&self) -> usize {
        self.n as usize
    }
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }
    pub fn contains(&self, i: usize) -> bool {
        self.as_slice().iter().any(|&s| s as usize == i)
    }
    /// With `i` added (ignored when full).
    fn with(mut self, i: usize) -> Skips {
        if (self.n as usize) < MAX_SKIPS {
            self.at[self.n as usize] = i as u32;
            self.n += 1;
            self.at[..self.n as usize].sort_unstable();
        }
        self
    }
}

impl serde::Serialize for Skips {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        self.as_slice().serialize(s)
    }
}

/// What [`search`] looks for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SearchParams {
    /// Target loop length in frames.
    pub length: usize,
    /// Allowed relative deviation of the length (0.2 = ±20%).
    pub tolerance: f64,
    /// Eigenfires used for distances (clamped to the weights' width).
    pub e: usize,
    /// How many ranked candidates to return.
    pub candidates: usize,
}

impl SearchParams {
    /// ±20%, 160 candidates.
    pub fn new(length: usize, e: usize) -> SearchParams {
        SearchParams {
            length,
            tolerance: 0.2,
            e,
            candidates: 160,
        }
    }
    /// Shortest and longest loop allowed: whole frames inside the tolerance (48 ± 20 % is
    /// 39..=57, never 38, which is 20.8 % short).
    pub fn bounds(&self) -> (usize, usize) {
        let l = self.length as f64;
        let lo = ((l * (1.0 - self.tolerance) - 1e-9).ceil() as usize).max(2);
        let hi = ((l * (1.0 + self.tolerance) + 1e-9).floor() as usize).max(lo);
        (lo, hi)
    }
}

/// A loop `start..end` (window indices; `end` excluded) and its filtered transition cost.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Candidate {
    pub start: usize,
    pub end: usize,
    /// Filtered distance (weight-space units) of the jump from `end - 1` back to `start`.
    pub cost: f64,
}

impl Candidate {
    pub fn len(&self) -> usize {
        self.end - self.start
    }
    pub fn is_empty(&self) -> bool {
        self.end <= self.start
    }
}

/// Euclidean distances between all rows of the n×k row-major `x`, on the first `e` columns,
/// as an n×n row-major matrix. Rows are computed in parallel; each entry is a sum over the
/// same columns in the same order, so the result does not depend on the thread count.
pub fn distances(x: &[f32], n: usize, k: usize, e: usize) -> Vec<f32> {
    let e = e.clamp(1, k.max(1)).min(k);
    let mut d = vec![0f32; n * n];
    d.par_chunks_mut(n.max(1)).enumerate().for_each(|(i, row)| {
        let a = &x[i * k..i * k + e];
        for (j, out) in row.iter_mut().enumerate() {
            let b = &x[j * k..j * k + e];
            // Four partial sums: vectorises, and the order is fixed.
            let mut s = [0f32; 4];
            let mut ca = a.chunks_exact(4);
            let mut cb = b.chunks_exact(4);
            for (p, q) in (&mut ca).zip(&mut cb) {
                for l in 0..4 {
                    let t = p[l] - q[l];
                    s[l] += t * t;
                }
            }
            let mut tail = 0f32;
            for (p, q) in ca.remainder().iter().zip(cb.remainder()) {
                tail += (p - q) * (p - q);
            }
            *out = ((s[0] + s[1]) + (s[2] + s[3]) + tail).sqrt();
        }
    });
    d
}

/// Shortest window [`search`] accepts for `p`: the shortest loop plus the filter's two
/// frames before the start and one after the end.
pub fn min_window(p: &SearchParams) -> usize {
    p.bounds().0 + 3
}

/// Ranked loop candidates of the n×k row-major weights `x` (one row per frame of the
/// window, consecutive source frames). Errors when the window cannot hold a loop of the
/// requested length.
///
/// With `body_steps` (the footage's own RMS steps between consecutive frames of the window,
/// `n - 1` values, e.g. from [`MetricWindow::steps`]) the ranking also counts the loop's
/// body: a candidate's rank is the larger of its jump (filtered cost over the median
/// weight-space step, times the median pixel step) and the largest step inside the loop,
/// over the loop's own median step — an estimate of the seam a plain cut would measure —
/// plus [`GHOST_WEIGHT`] × the shortfall of the softest frame inside it (as [`score`]) — so the search prefers
/// calm stretches of bursty footage. Half of the returned candidates are then the best of
/// that ranking, half the best by transition cost alone.
pub fn search(
    x: &[f32],
    n: usize,
    k: usize,
    p: &SearchParams,
    body: Option<BodyStats>,
) -> Result<Vec<Candidate>> {
    check_search(x, n, k, p, body)?;
    let body_steps = body.map(|b| b.steps);
    let soft = body.map(|b| b.softness);
    let (lo, hi) = p.bounds();
    let d = distances(x, n, k, p.e);
    let at = |i: usize, j: usize| f64::from(d[i * n + j]);
    // start ≥ 2, end + 1 ≤ n - 1.
    let mut all: Vec<(Candidate, f64)> = Vec::new();
    let w_med = loopq::median(&mut (0..n - 1).map(|i| at(i, i + 1)).collect::<Vec<_>>()).max(1e-12);
    let b_med = body_steps.map(|b| loopq::median(&mut b.to_vec()).max(1e-12));
    for start in 2..n {
        // Running maximum of the body steps start..end-1 as the end grows, and the median
        // step of the shortest loop from `start` (the seam's denominator: a still stretch
        // has a tiny one, so a loop there would measure a huge seam).
        let mut body_max = 0.0f64;
        let mut body_soft = f64::INFINITY;
        let mut upto = start;
        let local_med = body_steps.map(|b| {
            let e = (start + lo - 1).min(b.len());
            loopq::median(&mut b[start.min(e)..e].to_vec()).max(1e-12)
        });
        for len in lo..=hi {
            let end = start + len;
            if end + 1 >= n {
                break;
            }
            let cost = (0..4)
                .map(|t| FILTER[t] * at(end + t - 2, start + t - 2))
                .sum::<f64>()
                / 8.0;
            let rank = match (body_steps, b_med) {
                (Some(b), Some(m)) => {
                    while upto + 1 < end {
                        body_max = body_max.max(b[upto]);
                        if let Some(sf) = soft {
                            body_soft = body_soft.min(sf[upto]);
                        }
                        upto += 1;
                    }
                    // The jump in pixel-step units (weight-space ratio × the median step),
                    // and the body's largest step, over the loop's own median step.
                    let local = local_med.unwrap_or(m);
                    let shortfall = if body_soft.is_finite() {
                        (1.0 - body_soft).max(0.0)
                    } else {
                        0.0
                    };
                    (cost / w_med * m).max(body_max) / local + GHOST_WEIGHT * shortfall
                }
                _ => cost,
            };
            all.push((Candidate { start, end, cost }, rank));
        }
    }
    let want = p.candidates.max(1);
    let mut out: Vec<Candidate> = Vec::new();
    if body_steps.is_some() {
        pick_distinct(&mut all, |a| a.1, want.div_ceil(2), &mut out);
        pick_distinct(&mut all, |a| a.0.cost, want / 2, &mut out);
    } else {
        pick_distinct(&mut all, |a| a.0.cost, want, &mut out);
    }
    Ok(out)
}

/// Refuses a search [`search`] cannot do: too short a loop, weights that are not `n × k`,
/// body statistics of the wrong length, a window too short for the loop.
fn check_search(
    x: &[f32],
    n: usize,
    k: usize,
    p: &SearchParams,
    body: Option<BodyStats>,
) -> Result<()> {
    if p.length < 2 {
        return Err(EigenError::bad(
            "length",
            format!(
                "{} frame(s) is too short for a loop; ask for at least 2",
                p.length
            ),
        ));
    }
    if k == 0 || x.len() != n * k {
        return Err(EigenError::bad(
            "weights",
            format!("{} values do not form {n} rows of {k}", x.len()),
        ));
    }
    if let Some(b) = body {
        if b.steps.len() + 1 != n || b.softness.len() != n {
            return Err(EigenError::bad(
                "steps",
                format!(
                    "{} body steps and {} softness values for {n} frames (expected {} and {n})",
                    b.steps.len(),
                    b.softness.len(),
                    n.saturating_sub(1)
                ),
            ));
        }
    }
    let lo = p.bounds().0;
    if n < min_window(p) {
        return Err(EigenError::bad(
            "length",
            format!(
                "a loop of about {} frames (at least {lo} with the ±{:.0}% tolerance) does not fit in {n} frames: \
                 the search needs {} (2 frames before the loop and 1 after it); ask for a shorter --length or a longer window",
                p.length,
                p.tolerance * 100.0,
                min_window(p)
            ),
        ));
    }
    Ok(())
}

/// Appends to `out` the `want` best of `all` by `key` (ties by start, then end), skipping
/// near-duplicates: within 3 frames (both ends) of one already in `out`.
fn pick_distinct(
    all: &mut [(Candidate, f64)],
    key: fn(&(Candidate, f64)) -> f64,
    want: usize,
    out: &mut Vec<Candidate>,
) {
    all.sort_by(|a, b| {
        key(a)
            .total_cmp(&key(b))
            .then(a.0.start.cmp(&b.0.start))
            .then(a.0.end.cmp(&b.0.end))
    });
    let mut added = 0;
    for (c, _) in all.iter() {
        if added >= want {
            break;
        }
        let near = out
            .iter()
            .any(|o| o.start.abs_diff(c.start) <= 3 && o.end.abs_diff(c.end) <= 3);
        if !near {
            out.push(*c);
            added += 1;
        }
    }
}

/// How a loop is closed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize)]
#[serde(tag = "method", content = "frames", rename_all = "kebab-case")]
pub enum Closing {
    /// The loop's last frame cuts straight to its first.
    Cut,
    /// The tail blends into the head over m frames (what the crossfade peers do).
    Crossfade(usize),
    /// The tail morphs into the head over m frames along the optical flow.
    Morph(usize),
}

impl Closing {
    /// Transition frames.
    pub fn frames(&self) -> usize {
        match *self {
            Closing::Cut => 0,
            Closing::Crossfade(m) | Closing::Morph(m) => m,
        }
    }
}

impl std::fmt::Display for Closing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Closing::Cut => f.write_str("plain cut"),
            Closing::Crossfade(m) => write!(f, "crossfade over {m} frames"),
            Closing::Morph(m) => write!(f, "motion-compensated morph over {m} frames"),
        }
    }
}

/// One output frame of a closed loop (window indices).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Planned {
    /// A footage frame as it is.
    Src(usize),
    /// Frame `from` going into frame `to`, `w` of the way (0 = `from`, 1 = `to`).
    Mix { from: usize, to: usize, w: f32 },
}

/// The output frames of `c` closed with `closing` (see the module doc for the layout).
pub fn plan(c: &Candidate, closing: Closing) -> Vec<Planned> {
    plan_with(c, closing, &Skips::default())
}

/// [`plan`] leaving out the body frames `skips` (an [`Evaluated::skips`]).
pub fn plan_with(c: &Candidate, closing: Closing, skips: &Skips) -> Vec<Planned> {
    let m = closing.frames().min(c.len());
    let mut out: Vec<Planned> = (c.start + m..c.end)
        .filter(|&i| !skips.contains(i))
        .map(Planned::Src)
        .collect();
    for t in 0..m {
        out.push(Planned::Mix {
            from: c.end + t,
            to: c.start + t,
            w: (t + 1) as f32 / (m + 1) as f32,
        });
    }
    out
}

/// The last window frame a plan reads (exclusive bound).
pub fn plan_end(c: &Candidate, closing: Closing) -> usize {
    c.end + closing.frames()
}

/// An in-between of two frames: `prepare` once per pair, then frames at any weight.
pub trait PairMorph: Sync {
    /// Whether this is a motion-compensated morph (else a blend).
    fn motion(&self) -> bool;
    /// Prepared state for the pair (`a`, `b`); the returned function gives the frame `w`
    /// of the way from `a` to `b`.
    fn prepare<'a>(
        &'a self,
        a: &'a GrayFrame,
        b: &'a GrayFrame,
    ) -> Box<dyn Fn(f32) -> GrayFrame + Send + Sync + 'a>;
}

/// The plain blend `(1 - w)·a + w·b`.
pub struct Crossfade;

impl PairMorph for Crossfade {
    fn motion(&self) -> bool {
        false
    }
    fn prepare<'a>(
        &'a self,
        a: &'a GrayFrame,
        b: &'a GrayFrame,
    ) -> Box<dyn Fn(f32) -> GrayFrame + Send + Sync + 'a> {
        Box::new(move |w| blend(a, b, w))
    }
}

/// `(1 - w)·a + w·b` (same sizes).
pub fn blend(a: &GrayFrame, b: &GrayFrame, w: f32) -> GrayFrame {
    let data = a
        .data()
        .iter()
        .zip(b.data())
        .map(|(&x, &y)| x + (y - x) * w)
        .collect();
    GrayFrame::from_vec(a.size(), data).expect("same size")
}

/// A candidate closed one way, with its seam and ghost on the metric frames.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct Evaluated {
    pub candidate: Candidate,
    pub closing: Closing,
    /// Soft footage frames of the body left out (see [`Skips`]).
    pub skips: Skips,
    pub quality: LoopQuality,
    /// Largest step of the transition (the steps into and out of it included; a cut's
    /// single jump) over the median step.
    pub transition_step: f64,
    pub score: f64,
}

/// The ranking [`choose`] uses: seam plus [`GHOST_WEIGHT`] × the ghost's shortfall below 1.
/// Both are ratios to the footage's own statistics (its median step, its neighbours'
/// sharpness), so one weighting serves any footage.
pub fn score(q: &LoopQuality) -> f64 {
    q.seam + GHOST_WEIGHT * (1.0 - q.ghost).max(0.0)
}

/// The footage's own statistics a [`search`] ranks loop bodies by.
#[derive(Clone, Copy, Debug)]
pub struct BodyStats<'a> {
    /// RMS steps between consecutive frames (`n - 1`).
    pub steps: &'a [f64],
    /// Each frame's sharpness over the median of its ±15 neighbours in the footage (`n`).
    pub softness: &'a [f64],
}

/// Precomputed per-frame statistics of the window's metric frames.
pub struct MetricWindow<'a> {
    frames: &'a [GrayFrame],
    /// `steps[i]` = RMS step from frame i to i + 1.
    steps: Vec<f64>,
    sharp: Vec<f64>,
    softness: Vec<f64>,
    /// The softest tenth's bound: frames with `softness` below it may be left out
    /// ([`Skips`]); at most 1.
    soft_cut: f64,
}

impl<'a> MetricWindow<'a> {
    /// Errors when the frames differ in size or there are fewer than two.
    pub fn new(frames: &'a [GrayFrame]) -> Result<MetricWindow<'a>> {
        if frames.len() < 2 {
            return Err(EigenError::bad(
                "frames",
                format!("{} metric frame(s); a loop needs at least 2", frames.len()),
            ));
        }
        let steps = loopq::steps(frames, false)?;
        let sharp: Vec<f64> = frames.par_iter().map(loopq::sharpness).collect();
        let n = sharp.len();
        let r = loopq::GHOST_RADIUS;
        let softness: Vec<f64> = (0..n)
            .map(|t| {
                let (a, b) = (t.saturating_sub(r), (t + r + 1).min(n));
                sharp[t] / loopq::median(&mut sharp[a..b].to_vec()).max(1e-9)
            })
            .collect();
        let mut sorted = softness.clone();
        sorted.sort_by(f64::total_cmp);
        let soft_cut = sorted[(n - 1) / 10].min(1.0);
        Ok(MetricWindow {
            frames,
            steps,
            sharp,
            softness,
            soft_cut,
        })
    }
    pub fn len(&self) -> usize {
        self.frames.len()
    }
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }
    /// RMS steps between consecutive frames (`len() - 1` values).
    pub fn steps(&self) -> &[f64] {
        &self.steps
    }
    /// The statistics [`search`] ranks bodies by.
    pub fn body_stats(&self) -> BodyStats<'_> {
        BodyStats {
            steps: &self.steps,
            softness: &self.softness,
        }
    }
    /// The footage's own median step over the window.
    pub fn median_step(&self) -> f64 {
        loopq::median(&mut self.steps.clone())
    }
}

/// Evaluates every candidate closed every way in [`TRANSITION_LENGTHS`] that fits in the
/// window: a cut and crossfades for all, and — when `morph` is motion-compensated, which
/// costs a flow per pair — morphs for the `morph_candidates` candidates whose best cut or
/// crossfade scores best. Sorted by [`score`] (ties: fewer transition frames, then the
/// search's order). Deterministic. Soft frames are left out ([`Skips`]) only as long as
/// the loop stays at least as long as the shortest candidate (the search's lower bound);
/// [`evaluate_with`] takes that bound explicitly.
pub fn evaluate(
    win: &MetricWindow,
    cands: &[Candidate],
    morph: &dyn PairMorph,
    morph_candidates: usize,
) -> Vec<Evaluated> {
    let min_len = cands.iter().map(Candidate::len).min().unwrap_or(0);
    evaluate_with(win, cands, morph, morph_candidates, min_len)
}

/// [`evaluate`], the written loops never shorter than `min_len` frames.
pub fn evaluate_with(
    win: &MetricWindow,
    cands: &[Candidate],
    morph: &dyn PairMorph,
    morph_candidates: usize,
    min_len: usize,
) -> Vec<Evaluated> {
    let mut out: Vec<(usize, Evaluated)> = cands
        .par_iter()
        .enumerate()
        .flat_map_iter(|(rank, c)| {
            evaluate_one(win, c, &Crossfade, min_len)
                .into_iter()
                .map(move |e| (rank, e))
        })
        .collect();
    sort_evaluated(&mut out);
    if morph.motion() {
        let mut picked: Vec<usize> = Vec::new();
        for (rank, _) in &out {
            if picked.len() >= morph_candidates {
                break;
            }
            if !picked.contains(rank) {
                picked.push(*rank);
            }
        }
        let morphs: Vec<(usize, Evaluated)> = picked
            .par_iter()
            .flat_map_iter(|&rank| {
                evaluate_one(win, &cands[rank], morph, min_len)
                    .into_iter()
                    .map(move |e| (rank, e))
            })
            .collect();
        out.extend(morphs);
        sort_evaluated(&mut out);
    }
    out.into_iter().map(|(_, e)| e).collect()
}

fn sort_evaluated(v: &mut [(usize, Evaluated)]) {
    v.sort_by(|(ra, a), (rb, b)| {
        a.score
            .total_cmp(&b.score)
            .then(a.closing.frames().cmp(&b.closing.frames()))
            .then(ra.cmp(rb))
            .then(
                matches!(a.closing, Closing::Morph(_)).cmp(&matches!(b.closing, Closing::Morph(_))),
            )
    });
}

/// `c` closed every way `morph` offers: with [`Crossfade`], a cut and crossfades; with a
/// motion-compensated morph, morphs only.
fn evaluate_one(
    win: &MetricWindow,
    c: &Candidate,
    morph: &dyn PairMorph,
    min_len: usize,
) -> Vec<Evaluated> {
    let n = win.len();
    let max_m = TRANSITION_LENGTHS
        .iter()
        .copied()
        .filter(|&m| c.end + m <= n && m < c.len())
        .max()
        .unwrap_or(0);
    let pairs: Vec<_> = (0..max_m)
        .map(|t| morph.prepare(&win.frames[c.end + t], &win.frames[c.start + t]))
        .collect();
    let mut out = Vec::new();
    for &m in TRANSITION_LENGTHS.iter().filter(|&&m| m <= max_m) {
        let closing = match (m, morph.motion()) {
            (0, true) => continue,
            (0, false) => Closing::Cut,
            (m, false) => Closing::Crossfade(m),
            (m, true) => Closing::Morph(m),
        };
        let mids: Vec<GrayFrame> = (0..m)
            .map(|t| pairs[t]((t + 1) as f32 / (m + 1) as f32))
            .collect();
        out.push(measure(win, c, closing, &mids, min_len));
    }
    out
}

/// `c` closed with `closing` whose transition frames are `mids` as they will be written
/// (rendered at the output's size, then reduced to metric frames like the window's),
/// measured and scored as [`evaluate`] measures its own in-betweens, the left-out soft
/// frames chosen again. `mids` must hold `closing.frames()` frames of the window's metric
/// size; `min_len` as in [`evaluate_with`].
pub fn evaluate_rendered(
    win: &MetricWindow,
    c: &Candidate,
    closing: Closing,
    mids: &[GrayFrame],
    min_len: usize,
) -> Result<Evaluated> {
    if mids.len() != closing.frames() {
        return Err(EigenError::bad(
            "mids",
            format!("{} transition frames for a {closing}", mids.len()),
        ));
    }
    if c.is_empty() || c.end + mids.len() > win.len() || mids.len() >= c.len() {
        return Err(EigenError::bad(
            "candidate",
            format!(
                "{}..{} closed over {} frames does not fit the window",
                c.start,
                c.end,
                mids.len()
            ),
        ));
    }
    let size = win.frames[0].size();
    if let Some(m) = mids.iter().find(|m| m.size() != size) {
        return Err(EigenError::bad(
            "mids",
            format!(
                "a transition frame of {} in a window of {size} metric frames",
                m.size()
            ),
        ));
    }
    Ok(measure(win, c, closing, mids, min_len))
}

/// Seam and ghost of `c` closed with `closing` whose transition frames are `mids`, and its
/// best version with soft body frames left out ([`Skips`]): the soft runs ([`soft_runs`])
/// are left out cumulatively, softest first, and every prefix is measured; the best
/// [`score`] wins. Measuring every prefix (not stopping at the first that does not help)
/// gets past ties: two equally soft frames only raise the ghost once both are gone. The
/// loop keeps at least `min_len` frames.
fn measure(
    win: &MetricWindow,
    c: &Candidate,
    closing: Closing,
    mids: &[GrayFrame],
    min_len: usize,
) -> Evaluated {
    let fixed = Fixed::new(win, c, mids);
    let mut across = std::collections::HashMap::new();
    let mut best = measure_fixed(win, c, closing, &fixed, Skips::default(), &mut across);
    let body = c.start + mids.len()..c.end;
    let room = MAX_SKIPS.min(c.len().saturating_sub(min_len));
    if room == 0 || body.len() < 4 {
        return best;
    }
    // The largest step the footage itself takes inside the loop.
    let natural = win.steps[body.start..body.end - 1]
        .iter()
        .copied()
        .fold(0.0, f64::max);
    let mut skips = Skips::default();
    for run in soft_runs(win, body) {
        // The left-out run this one would join: a pair may grow from a single left out
        // before it (a duplicated soft frame is its single first, and leaving out one copy
        // alone keeps the other), but two runs never touch and no run is longer than two.
        let (mut lo, mut hi) = (run.start, run.end);
        while skips.contains(lo - 1) {
            lo -= 1;
        }
        while skips.contains(hi) {
            hi += 1;
        }
        let added = run.clone().filter(|&i| !skips.contains(i)).count();
        if added == 0 || hi - lo > 2 || skips.len() + added > room {
            continue;
        }
        let step = *across
            .entry((lo - 1, hi))
            .or_insert_with(|| loopq::rms_diff(&win.frames[lo - 1], &win.frames[hi]));
        if step > natural {
            continue;
        }
        let before = skips;
        skips = run
            .filter(|&i| !before.contains(i))
            .fold(skips, |s, i| s.with(i));
        let tried = measure_fixed(win, c, closing, &fixed, skips, &mut across);
        if tried.score < best.score {
            best = tried;
        }
    }
    best
}

/// The runs of one or two soft frames inside `body`, with a body frame on each side,
/// softest first (a pair by its sharper frame; ties by position, then the single first).
/// Soft: among the softest tenth of the window's frames by sharpness over the median of
/// their ±15 footage neighbours ([`MetricWindow::soft_cut`]) — the footage's own outliers,
/// so a sharp loop is not thinned out for a metric's sake.
fn soft_runs(win: &MetricWindow, body: std::ops::Range<usize>) -> Vec<std::ops::Range<usize>> {
    let soft = |i: usize| win.softness[i] < win.soft_cut;
    let mut runs: Vec<(f64, std::ops::Range<usize>)> = Vec::new();
    for i in body.start + 1..body.end - 1 {
        if !soft(i) {
            continue;
        }
        runs.push((win.softness[i], i..i + 1));
        if i + 2 < body.end && soft(i + 1) {
            runs.push((win.softness[i].max(win.softness[i + 1]), i..i + 2));
        }
    }
    runs.sort_by(|a, b| {
        a.0.total_cmp(&b.0)
            .then(a.1.start.cmp(&b.1.start))
            .then(a.1.len().cmp(&b.1.len()))
    });
    runs.into_iter().map(|(_, r)| r).collect()
}

/// What [`measure_fixed`] needs that does not change with the left-out frames: the steps
/// into, through and out of the transition, and the transition frames' sharpness.
struct Fixed {
    m: usize,
    /// Last body frame → first mid, mids, last mid → first body frame (a cut: the jump).
    trans: Vec<f64>,
    mid_sharp: Vec<f64>,
}

impl Fixed {
    fn new(win: &MetricWindow, c: &Candidate, mids: &[GrayFrame]) -> Fixed {
        let m = mids.len();
        let (first, last) = (c.start + m, c.end - 1);
        let mut trans = Vec::with_capacity(m + 1);
        if m == 0 {
            trans.push(loopq::rms_diff(&win.frames[last], &win.frames[first]));
        } else {
            trans.push(loopq::rms_diff(&win.frames[last], &mids[0]));
            for t in 1..m {
                trans.push(loopq::rms_diff(&mids[t - 1], &mids[t]));
            }
            trans.push(loopq::rms_diff(&mids[m - 1], &win.frames[first]));
        }
        Fixed {
            m,
            trans,
            mid_sharp: mids.iter().map(loopq::sharpness).collect(),
        }
    }
}

/// Seam and ghost of `c` closed with `closing` (transition frames `mids`), body frames
/// `skips` left out.
#[cfg(test)]
fn measure_with(
    win: &MetricWindow,
    c: &Candidate,
    closing: Closing,
    mids: &[GrayFrame],
    skips: Skips,
) -> Evaluated {
    let fixed = Fixed::new(win, c, mids);
    measure_fixed(win, c, closing, &fixed, skips, &mut Default::default())
}

/// [`measure_with`] from the [`Fixed`] parts; `across` caches the steps across left-out
/// frames. The body's first and last frames are never left out.
fn measure_fixed(
    win: &MetricWindow,
    c: &Candidate,
    closing: Closing,
    fixed: &Fixed,
    skips: Skips,
    across: &mut std::collections::HashMap<(usize, usize), f64>,
) -> Evaluated {
    let body: Vec<usize> = (c.start + fixed.m..c.end)
        .filter(|&i| !skips.contains(i))
        .collect();
    let mut step = |a: usize, b: usize| {
        if b == a + 1 {
            win.steps[a]
        } else {
            *across
                .entry((a, b))
                .or_insert_with(|| loopq::rms_diff(&win.frames[a], &win.frames[b]))
        }
    };
    // Steps: body (natural, or across left-out frames), then the transition's.
    let mut steps: Vec<f64> = body.windows(2).map(|w| step(w[0], w[1])).collect();
    steps.extend_from_slice(&fixed.trans);
    let med = loopq::median(&mut steps.clone());
    let (seam_at, max) =
        steps.iter().enumerate().fold(
            (0, f64::NEG_INFINITY),
            |b, (i, &v)| if v > b.1 { (i, v) } else { b },
        );
    let mut sharp: Vec<f64> = body.iter().map(|&i| win.sharp[i]).collect();
    sharp.extend_from_slice(&fixed.mid_sharp);
    let (ghost, ghost_at) = loopq::ghost(&sharp);
    // As loopq: a still loop is perfectly smooth, a step out of stillness infinitely rough.
    let ratio = |v: f64| {
        if med > 0.0 {
            v / med
        } else if v > 0.0 {
            f64::INFINITY
        } else {
            1.0
        }
    };
    let quality = LoopQuality {
        seam: ratio(max),
        seam_at,
        ghost,
        ghost_at,
        median_step: med,
    };
    Evaluated {
        candidate: *c,
        closing,
        skips,
        quality,
        transition_step: ratio(fixed.trans.iter().copied().fold(0.0, f64::max)),
        score: score(&quality),
    }
}

/// The best evaluated closing with a sentence saying why it won (frame numbers offset by
/// `first`, the window's first source frame), or `None` for an empty list.
pub fn choose(evaluated: &[Evaluated], first: usize) -> Option<(Evaluated, String)> {
    let best = *evaluated.first()?;
    let best_of = |f: &dyn Fn(&Closing) -> bool| evaluated.iter().find(|e| f(&e.closing));
    let mut why = format!(
        "{} at {}..{} scores {:.3} (seam {:.2} + {GHOST_WEIGHT} × ghost shortfall {:.2})",
        best.closing,
        first + best.candidate.start,
        first + best.candidate.end,
        best.score,
        best.quality.seam,
        (1.0 - best.quality.ghost).max(0.0)
    );
    if !best.skips.is_empty() {
        let list: Vec<String> = best
            .skips
            .as_slice()
            .iter()
            .map(|&i| (first + i as usize).to_string())
            .collect();
        why.push_str(&format!(
            ", leaving out {} soft footage frame(s) ({})",
            best.skips.len(),
            list.join(", ")
        ));
    }
    let others: Vec<String> = [
        ("plain cut", best_of(&|c| matches!(c, Closing::Cut))),
        (
            "crossfade",
            best_of(&|c| matches!(c, Closing::Crossfade(_))),
        ),
        ("morph", best_of(&|c| matches!(c, Closing::Morph(_)))),
    ]
    .into_iter()
    .filter_map(|(name, e)| {
        let e = e?;
        (std::mem::discriminant(&e.closing) != std::mem::discriminant(&best.closing)).then(|| {
            format!(
                "best {name} {:.3} (seam {:.2}, ghost {:.2})",
                e.score, e.quality.seam, e.quality.ghost
            )
        })
    })
    .collect();
    if !others.is_empty() {
        why.push_str("; ");
        why.push_str(&others.join(", "));
    }
    Some((best, why))
}

/// Parses a loop length: `4s` / `2.5s` (seconds, at `fps`) or a whole number of frames.
pub fn parse_length(s: &str, fps: f64) -> Result<usize> {
    let bad = |why: String| EigenError::bad("length", format!("`{s}`: {why} (e.g. 4s or 120)"));
    let t = s.trim();
    let frames = if let Some(sec) = t.strip_suffix('s') {
        let v: f64 = sec
            .trim()
            .parse()
            .map_err(|_| bad("the seconds are not a number".into()))?;
        if !v.is_finite() || v <= 0.0 {
            return Err(bad("the seconds must be above 0".into()));
        }
        if !(fps.is_finite() && fps > 0.0) {
            return Err(bad(format!(
                "the clip's fps ({fps}) is unknown; give frames"
            )));
        }
        (v * fps).round()
    } else {
        t.parse::<usize>()
            .map_err(|_| bad("not a whole number of frames or seconds".into()))? as f64
    };
    if frames < 2.0 {
        return Err(bad(format!("{frames} frame(s) is too short for a loop")));
    }
    Ok(frames as usize)
}

#[cfg(test)]
mod tests {
    use super::*;
    use ignis_core::{Rng, Size};

    /// The bounds are whole frames inside ±tolerance: a 2-s loop at 24 fps (48 frames)
    /// may be 39..=57 frames, not 38 (20.8 % short); exact multiples stay in.
    #[test]
    fn length_bounds_stay_inside_the_tolerance() {
        assert_eq!(SearchParams::new(48, 8).bounds(), (39, 57));
        assert_eq!(SearchParams::new(60, 8).bounds(), (48, 72));
        assert_eq!(SearchParams::new(120, 8).bounds(), (96, 144));
        for len in 3..400 {
            let (lo, hi) = SearchParams::new(len, 8).bounds();
            let l = len as f64;
            assert!(lo as f64 >= 0.8 * l - 1e-9 || lo == 2, "{len}: {lo}");
            assert!(hi as f64 <= 1.2 * l + 1e-9 || hi == lo, "{len}: {hi}");
            assert!(lo <= len && len <= hi, "{len}: {lo}..={hi}");
        }
    }

    /// Weights of a noisy periodic motion with period `p`: the search must find loops of a
    /// whole number of periods.
    fn periodic(n: usize, k: usize, p: usize, seed: u64) -> Vec<f32> {
        let mut rng = Rng::new(seed);
        let mut x = vec![0f32; n * k];
        for i in 0..n {
            let ph = (i % p) as f32 / p as f32 * std::f32::consts::TAU;
            for j in 0..k {
                x[i * k + j] = (ph * (j as f32 + 1.0)).sin() * 10.0 / (j as f32 + 1.0)
                    + (rng.f32() - 0.5) * 0.2;
            }
        }
        x
    }

    #[test]
    fn finds_whole_periods() {
        let (n, k) = (300, 8);
        let x = periodic(n, k, 25, 3);
        let c = search(&x, n, k, &SearchParams::new(60, 8), None).unwrap();
        assert!(!c.is_empty());
        // 60 ± 20% = 48..=72: the only whole number of periods is 50.
        assert_eq!(c[0].len(), 50, "{:?}", &c[..3]);
        assert!(c[0].cost < 1.0, "{:?}", c[0]);
        let d = distances(&x, n, k, 8);
        assert_eq!(d[7 * n + 7], 0.0);
        assert!((d[3 * n + 40] - d[40 * n + 3]).abs() < 1e-6);
    }

    #[test]
    fn bad_lengths_are_errors() {
        let x = periodic(50, 4, 10, 1);
        let e = search(&x, 50, 4, &SearchParams::new(60, 4), None).unwrap_err();
        assert!(e.to_string().contains("does not fit in 50 frames"), "{e}");
        assert!(search(&x, 50, 4, &SearchParams::new(1, 4), None).is_err());
        assert_eq!(parse_length("2s", 30.0).unwrap(), 60);
        assert_eq!(parse_length("48", 30.0).unwrap(), 48);
        assert!(parse_length("-1s", 30.0).is_err());
        assert!(parse_length("abc", 30.0).is_err());
        assert!(parse_length("1", 30.0).is_err());
    }

    #[test]
    fn plan_layout_and_measure() {
        let c = Candidate {
            start: 5,
            end: 25,
            cost: 0.0,
        };
        let p = plan(&c, Closing::Crossfade(4));
        assert_eq!(p.len(), 20);
        assert_eq!(p[0], Planned::Src(9));
        assert_eq!(
            p[16],
            Planned::Mix {
                from: 25,
                to: 5,
                w: 0.2
            }
        );
        assert_eq!(plan(&c, Closing::Cut).len(), 20);
        // Metric frames: a bright bar moving one pixel per frame, period 20.
        let size = Size::new(32, 8).unwrap();
        let frames: Vec<GrayFrame> = (0..60)
            .map(|i| {
                let mut f = GrayFrame::new(size);
                for y in 0..8 {
                    f.data_mut()[y * 32 + 4 + i % 20] = 1.0;
                }
                f
            })
            .collect();
        let win = MetricWindow::new(&frames).unwrap();
        let ev = evaluate(&win, &[c], &Crossfade, 0);
        // A whole period: the plain cut is perfect, and wins over every crossfade.
        assert_eq!(ev[0].closing, Closing::Cut, "{:?}", ev[0]);
        assert!((ev[0].quality.seam - 1.0).abs() < 1e-9);
        // The same, measured by loopq on the planned frames.
        let built: Vec<GrayFrame> = plan(&c, Closing::Cut)
            .iter()
            .map(|p| match p {
                Planned::Src(i) => frames[*i].clone(),
                Planned::Mix { .. } => unreachable!(),
            })
            .collect();
        let q = loopq::loop_quality(&built).unwrap();
        assert!((q.seam - ev[0].quality.seam).abs() < 1e-9);
        assert!((q.ghost - ev[0].quality.ghost).abs() < 1e-9);
        // Every other closing was tried too.
        assert!(ev.iter().any(|e| e.closing == Closing::Crossfade(4)));
        assert!(choose(&ev, 0).unwrap().1.contains("plain cut"));
        assert!(ev[0].skips.is_empty());
    }

    /// 100 frames of a bar moving a pixel a frame (wrapping every 20), the frames `blurred`
    /// all showing the bar of the first of them smeared over three pixels (motion blur,
    /// repeated when several), and the candidate loop 10..70 in them.
    fn bar_clip_blurred_at(blurred: &[usize]) -> (Vec<GrayFrame>, Candidate) {
        let size = Size::new(32, 8).unwrap();
        let frames: Vec<GrayFrame> = (0..100)
            .map(|i| {
                let mut f = GrayFrame::new(size);
                for y in 0..8 {
                    if blurred.contains(&i) {
                        for d in 0..3 {
                            f.data_mut()[y * 32 + 3 + blurred[0] % 20 + d] = 1.0 / 3.0;
                        }
                    } else {
                        f.data_mut()[y * 32 + 4 + i % 20] = 1.0;
                    }
                }
                f
            })
            .collect();
        let c = Candidate {
            start: 10,
            end: 70,
            cost: 0.0,
        };
        (frames, c)
    }

    /// A blurred footage frame inside the loop is left out, and the plan and loopq agree
    /// with the prediction.
    #[test]
    fn soft_footage_frame_is_left_out() {
        let (frames, c) = bar_clip_blurred_at(&[30]);
        let win = MetricWindow::new(&frames).unwrap();
        // A lone candidate is the shortest: nothing may be left out.
        assert!(evaluate(&win, &[c], &Crossfade, 0)[0].skips.is_empty());
        let ev = evaluate_with(&win, &[c], &Crossfade, 0, 50);
        let best = ev[0];
        assert_eq!(best.closing, Closing::Cut, "{best:?}");
        assert_eq!(best.skips.as_slice(), &[30], "{best:?}");
        let p = plan_with(&c, best.closing, &best.skips);
        assert!(!p.contains(&Planned::Src(30)) && p.contains(&Planned::Src(31)));
        let built: Vec<GrayFrame> = p
            .iter()
            .map(|p| match *p {
                Planned::Src(i) => frames[i].clone(),
                Planned::Mix { from, to, w } => blend(&frames[from], &frames[to], w),
            })
            .collect();
        let q = loopq::loop_quality(&built).unwrap();
        assert!((q.seam - best.quality.seam).abs() < 1e-9);
        assert!((q.ghost - best.quality.ghost).abs() < 1e-9);
        // Without the skip the blurred frame is the ghost.
        let with_blur = measure_with(&win, &c, best.closing, &[], Skips::default());
        assert!(with_blur.quality.ghost < 0.5 && best.quality.ghost > 0.9);
        assert!(choose(&ev, 0)
            .unwrap()
            .1
            .contains("leaving out 1 soft footage frame(s) (30)"));
    }

    /// A soft frame shown twice (footage converted to a higher frame rate repeats frames)
    /// is left out as a pair: leaving out one copy alone keeps the other as the ghost.
    #[test]
    fn a_duplicated_soft_frame_is_left_out_as_a_pair() {
        let (frames, c) = bar_clip_blurred_at(&[30, 31]);
        let win = MetricWindow::new(&frames).unwrap();
        let best = evaluate_with(&win, &[c], &Crossfade, 0, 50)[0];
        assert_eq!(best.skips.as_slice(), &[30, 31], "{best:?}");
        assert!(best.quality.ghost > 0.9, "{best:?}");
        // One copy alone does not help.
        let one = measure_with(&win, &c, best.closing, &[], Skips::default().with(30));
        assert!(one.quality.ghost < 0.5, "{one:?}");
    }

    /// A closing measured on given in-betweens: the crossfade's own blends give exactly
    /// what `evaluate` predicted; other in-betweens (here the bar moved on, as a morph
    /// would) measure as the plan built with them; wrong counts and sizes are refused.
    #[test]
    fn a_closing_measures_as_its_rendered_frames() {
        let size = Size::new(32, 8).unwrap();
        // A bar moving one pixel per frame, its period 23 frames; the loop 5..25 is not a
        // whole period, so its closing has to bridge a jump.
        let bar = |x: f32| {
            let mut f = GrayFrame::new(size);
            for y in 0..8 {
                for px in 0..32 {
                    f.data_mut()[y * 32 + px] = (1.0 - (px as f32 - x).abs()).max(0.0);
                }
            }
            f
        };
        let frames: Vec<GrayFrame> = (0..60).map(|i| bar(4.0 + (i % 23) as f32)).collect();
        let win = MetricWindow::new(&frames).unwrap();
        let c = Candidate {
            start: 5,
            end: 25,
            cost: 0.0,
        };
        let closing = Closing::Crossfade(4);
        let predicted = *evaluate(&win, &[c], &Crossfade, 0)
            .iter()
            .find(|e| e.closing == closing)
            .unwrap();
        let blends: Vec<GrayFrame> = (0..4)
            .map(|t| blend(&frames[25 + t], &frames[5 + t], (t + 1) as f32 / 5.0))
            .collect();
        let same = evaluate_rendered(&win, &c, closing, &blends, c.len()).unwrap();
        assert_eq!(same.quality.seam, predicted.quality.seam);
        assert_eq!(same.quality.ghost, predicted.quality.ghost);
        assert_eq!(same.score, predicted.score);
        // In-betweens that move the bar from where the tail leaves it to where the head
        // starts: a smoother closing than the blends, measured as the built plan.
        // (the frames around them: 24 at x = 5, 9 at x = 13).
        let moved: Vec<GrayFrame> = (0..4)
            .map(|t| bar((5.0 + 8.0 * (t + 1) as f32 / 5.0).round()))
            .collect();
        let e = evaluate_rendered(&win, &c, closing, &moved, c.len()).unwrap();
        let built: Vec<GrayFrame> = plan(&c, closing)
            .iter()
            .map(|p| match *p {
                Planned::Src(i) => frames[i].clone(),
                Planned::Mix { from, .. } => moved[from - 25].clone(),
            })
            .collect();
        let q = loopq::loop_quality(&built).unwrap();
        assert!((q.seam - e.quality.seam).abs() < 1e-9, "{q:?} {e:?}");
        assert!((q.ghost - e.quality.ghost).abs() < 1e-9);
        assert!(
            (e.transition_step - predicted.transition_step).abs() > 0.01,
            "{e:?} {predicted:?}"
        );
        assert!(evaluate_rendered(&win, &c, closing, &moved[..3], c.len()).is_err());
        let small = vec![GrayFrame::new(Size::new(16, 8).unwrap()); 4];
        assert!(evaluate_rendered(&win, &c, closing, &small, c.len()).is_err());
        let late = Candidate {
            start: 40,
            end: 58,
            cost: 0.0,
        };
        assert!(evaluate_rendered(&win, &late, closing, &moved, 2).is_err());
    }
}
