//! Motion transition between two ranges of Eigenfire weights (T1 + T2), and loops.
//!
//! Source: eigenfires-thesis.txt §5.1 (Motion Transition), §5.1.1 (low-pass filter),
//! §5.1.2 (recognition: `theta_min`, separate E for detection and rendering),
//! §5.1.2.1 (Direct Bridging), §5.1.2.2 (End Growing Connection, Algorithm 1), and §4.5
//! (thresholds from the distances of consecutive frames).
//!
//! This module works on **weight vectors only**: a [`WeightSpace`] borrows the M×E weight
//! matrix of a database (row-major, frame `i` = `weights[i*E..(i+1)*E]`) and the clip
//! spans. It reads no files and renders no images; a [`Join`] names database frames
//! ([`FrameRef::Db`]) or carries synthetic weight vectors ([`FrameRef::Weights`], low-pass
//! morphs) that a renderer projects onto the Eigenfires.
//!
//! T1 and T2 are ranges of *global* frame indices (rows of the weight matrix). As in the
//! thesis, α is the last frame of T1 and β the first frame of T2. [`Join::frames`] holds
//! only the new frames to insert between T1 and T2; low-pass morphs also replace T1's last
//! [`Join::trim_t1`] and T2's first [`Join::trim_t2`] frames (0 for the other methods).
//! For a loop over a range shorter than the kernel, those two trims may overlap.
//!
//! Every join reports a [`seam_ratio`]: the largest distance between consecutive frames of
//! T1's tail + transition + T2's head, divided by the median distance between consecutive
//! frames of the source clips (1.0 = as smooth as the footage; a plain cut between
//! different flames is typically 3 or more). This figure is ours, not the thesis's.
//!
//! Departures from the thesis (each is repeated where it is implemented):
//! - All distances (recognition *and* seam ratio) use the first `e_detect` weights
//!   (§5.1.2 lets detection use fewer Eigenfires than rendering).
//! - `theta_min` defaults, per clip, to a quantile (default the 10th percentile) of the
//!   distances between consecutive frames of the clip the path is at — the same rule as
//!   `Thresholds::theta_min` of the database — and so adapts when a path crosses clips
//!   (the thesis's proposed "adaptive mode", end of §5.1.2.2), instead of one user
//!   number (§4.1 asks for a threshold "slightly bigger than zero"; the clip's median
//!   step rejects the natural next frame about half of the time — see
//!   `benches/README.md`).
//!
//! Speed: the consecutive-frame distances behind θ_min, the join gap and the seam ratio
//! are computed once per `e_detect` and cached in the [`WeightSpace`] (reuse one space for
//! several transitions). Scans abandon a distance as soon as its leading weights pass the
//! bound that matters, and End Growing's candidate lists are produced lazily from lower
//! bounds; both are exact. Distances are summed in f64 over 8 interleaved lanes.
//! `ignis bench eigen-animate` ([`crate::bench`]) measures it; figures in
//! `benches/README.md`.

mod bridging;
mod end_growing;
mod low_pass;

pub use bridging::direct_bridging;
pub use end_growing::end_growing;
pub use low_pass::{low_pass, LowPassParams};

use std::ops::Range;

/// Frames of T1's tail and T2's head that enter the seam ratio on each side.
pub const SEAM_CONTEXT: usize = 4;

/// Errors of the transition algorithms, split by who is at fault.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum TransitionError {
    /// A setting is out of range; the message names it and the valid range.
    #[error("invalid setting `{name}`: {reason}")]
    BadParameter { name: String, reason: String },
    /// A frame range (T1, T2 or a loop range) is empty or outside the database.
    #[error("range `{name}` {start}..{end}: {reason}")]
    BadRange {
        name: String,
        start: usize,
        end: usize,
        reason: String,
    },
    /// A recognition method found no path (e.g. End Growing did not join within N steps).
    #[error("{method}: no transition found: {reason}")]
    NoPath {
        method: &'static str,
        reason: String,
    },
}

fn bad(name: &str, reason: impl Into<String>) -> TransitionError {
    TransitionError::BadParameter {
        name: name.into(),
        reason: reason.into(),
    }
}

pub type Result<T, E = TransitionError> = std::result::Result<T, E>;

/// One clip of the database: global frames `start..start + len`.
#[derive(Clone, Debug, PartialEq)]
pub struct ClipSpan {
    pub name: String,
    pub start: usize,
    pub len: usize,
}

/// The weight vectors of a database, borrowed, with the clip each frame belongs to.
#[derive(Clone, Debug)]
pub struct WeightSpace<'a> {
    weights: &'a [f32],
    e: usize,
    clips: Vec<ClipSpan>,
    /// Index into `clips` for every frame.
    clip_of: Vec<usize>,
    /// Sorted consecutive distances per `e_detect`, computed on first use.
    steps: StepCache,
}

/// The distances between consecutive frames of every clip on the first `e_detect` weights,
/// sorted: what θ_min, the join gap and the seam ratio's denominator are quantiles of.
#[derive(Debug)]
struct Steps {
    /// Per clip, ascending.
    per_clip: Vec<Vec<f64>>,
    /// Median over all clips ([`WeightSpace::source_median`]).
    median: f64,
}

/// [`Steps`] per `e_detect`. A transition asks for the same few quantiles many times (every
/// step of a path, every pair End Growing compares); computing and sorting the M − 1
/// distances once per `e_detect` instead of per call is what keeps a step under a
/// millisecond on 2,197 frames × 2,196 weights.
#[derive(Debug, Default)]
struct StepCache(std::sync::Mutex<Vec<(usize, std::sync::Arc<Steps>)>>);

impl Clone for StepCache {
    fn clone(&self) -> Self {
        StepCache(std::sync::Mutex::new(self.lock().clone()))
    }
}

impl StepCache {
    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<(usize, std::sync::Arc<Steps>)>> {
        // The cache holds only finished entries, so a panic elsewhere cannot leave it torn.
        self.0.lock().unwrap_or_else(|p| p.into_inner())
    }
}

impl<'a> WeightSpace<'a> {
    /// `weights` is M×E row-major. `clips` must tile `0..M` without overlap (any order);
    /// an empty `clips` means one clip `"all"` covering every frame.
    pub fn new(weights: &'a [f32], e: usize, clips: Vec<ClipSpan>) -> Result<Self> {
        if e == 0 {
            return Err(bad(
                "e",
                "the number of weights per frame must be at least 1",
            ));
        }
        if weights.is_empty() || !weights.len().is_multiple_of(e) {
            return Err(bad(
                "weights",
                format!(
                    "length {} is not a positive multiple of E = {e}",
                    weights.len()
                ),
            ));
        }
        if weights.iter().any(|w| !w.is_finite()) {
            return Err(bad("weights", "contains NaN or infinity"));
        }
        let m = weights.len() / e;
        let clips = if clips.is_empty() {
            vec![ClipSpan {
                name: "all".into(),
                start: 0,
                len: m,
            }]
        } else {
            clips
        };
        let mut clip_of = vec![usize::MAX; m];
        for (c, span) in clips.iter().enumerate() {
            if span.len == 0 || span.start + span.len > m {
                return Err(bad(
                    "clips",
                    format!(
                        "clip `{}` {}..{} is empty or past the {m} frames",
                        span.name,
                        span.start,
                        span.start + span.len
                    ),
                ));
            }
            for slot in &mut clip_of[span.start..span.start + span.len] {
                if *slot != usize::MAX {
                    return Err(bad(
                        "clips",
                        format!("clip `{}` overlaps another", span.name),
                    ));
                }
                *slot = c;
            }
        }
        if let Some(i) = clip_of.iter().position(|&c| c == usize::MAX) {
            return Err(bad("clips", format!("frame {i} belongs to no clip")));
        }
        Ok(WeightSpace {
            weights,
            e,
            clips,
            clip_of,
            steps: StepCache::default(),
        })
    }

    /// Number of frames M.
    pub fn len(&self) -> usize {
        self.clip_of.len()
    }

    /// Always false (a space has at least one frame).
    pub fn is_empty(&self) -> bool {
        self.clip_of.is_empty()
    }

    /// Weights per frame E.
    pub fn e(&self) -> usize {
        self.e
    }

    pub fn clips(&self) -> &[ClipSpan] {
        &self.clips
    }

    /// The weight vector of frame `i` (all E weights).
    pub fn frame(&self, i: usize) -> &[f32] {
        &self.weights[i * self.e..(i + 1) * self.e]
    }

    /// Index (into [`WeightSpace::clips`]) of the clip frame `i` belongs to.
    pub fn clip_index(&self, i: usize) -> usize {
        self.clip_of[i]
    }

    /// Euclidean distance between frames `i` and `j` on the first `e_detect` weights (the
    /// thesis's recognition distance, §4.5 / §5.1.2).
    pub fn distance(&self, i: usize, j: usize, e_detect: usize) -> f64 {
        dist(self.frame(i), self.frame(j), e_detect)
    }

    /// Quantile `q` (0 = smallest, 0.5 = median, 1 = largest) of the distances between
    /// consecutive frames of clip `c`, on the first `e_detect` weights, picked like
    /// `analysis` does (nearest rank). 0 for a one-frame clip.
    pub fn clip_step_quantile(&self, c: usize, e_detect: usize, q: f64) -> f64 {
        let steps = self.steps(e_detect);
        let d = &steps.per_clip[c];
        if d.is_empty() {
            return 0.0;
        }
        d[((d.len() - 1) as f64 * q.clamp(0.0, 1.0)).round() as usize]
    }

    /// Median distance between consecutive frames over all clips (first `e_detect`
    /// weights): the denominator of [`seam_ratio`]. Returns 0 when no clip has 2 frames.
    pub fn source_median(&self, e_detect: usize) -> f64 {
        self.steps(e_detect).median
    }

    /// The sorted consecutive distances on the first `e_detect` weights (cached).
    fn steps(&self, e_detect: usize) -> std::sync::Arc<Steps> {
        if let Some((_, s)) = self.steps.lock().iter().find(|(e, _)| *e == e_detect) {
            return s.clone();
        }
        // Computed outside the lock; two threads racing compute the same values.
        let s = std::sync::Arc::new(self.compute_steps(e_detect));
        let mut cache = self.steps.lock();
        if !cache.iter().any(|(e, _)| *e == e_detect) {
            cache.push((e_detect, s.clone()));
        }
        s
    }

    fn compute_steps(&self, e_detect: usize) -> Steps {
        use rayon::prelude::*;
        // One task per block of frames (a fixed split, so the values do not depend on the
        // number of threads; each distance is computed whole by one task anyway).
        const BLOCK: usize = 256;
        let m = self.len();
        let mut d = vec![0.0f64; m];
        d.par_chunks_mut(BLOCK).enumerate().for_each(|(b, out)| {
            for (j, o) in out.iter_mut().enumerate() {
                let i = b * BLOCK + j;
                if i > 0 {
                    *o = self.distance(i - 1, i, e_detect);
                }
            }
        });
        let per_clip: Vec<Vec<f64>> = self
            .clips
            .iter()
            .map(|s| {
                let mut v = d[s.start + 1..s.start + s.len].to_vec();
                v.sort_by(f64::total_cmp);
                v
            })
            .collect();
        let mut all: Vec<f64> = per_clip.iter().flatten().copied().collect();
        let median = median(&mut all);
        Steps { per_clip, median }
    }

    /// Checks that `r` is a non-empty range of frames of this space.
    pub(crate) fn check_range(&self, name: &str, r: &Range<usize>) -> Result<()> {
        let reason = if r.start >= r.end {
            "is empty"
        } else if r.end > self.len() {
            "runs past the last frame of the database"
        } else {
            return Ok(());
        };
        Err(TransitionError::BadRange {
            name: name.into(),
            start: r.start,
            end: r.end,
            reason: format!("{reason} ({} frames)", self.len()),
        })
    }
}

/// Settings shared by the recognition methods (§5.1.2).
#[derive(Clone, Debug, PartialEq)]
pub struct RecognitionParams {
    /// Number of leading weights used for every distance ("E for detection", §5.1.2).
    /// 0 = all E. Values above E are clamped to E.
    pub e_detect: usize,
    /// Minimum distance between consecutive frames of a path, in weight units (on the
    /// first `e_detect` weights). Must be > 0. `None` = adaptive: `theta_quantile` of the
    /// consecutive distances of the clip of the frame being extended (§4.5–4.6; the
    /// thesis's adaptive mode at the end of §5.1.2.2). Default `None`.
    pub theta_min: Option<f64>,
    /// Quantile of a clip's consecutive distances used as the adaptive θ_min, in [0, 1].
    /// Default 0.1 (the database's `Thresholds::theta_min`); 0.5 = the median step.
    pub theta_quantile: f64,
    /// End Growing's case 2: the two paths are joined when their ends are closer than
    /// this, in weight units. `None` = the mean of the median consecutive distance of the
    /// two ends' clips (a footage-sized step). Must be > 0. See `end_growing` for why this
    /// is not θ_min as in the thesis.
    pub join_gap: Option<f64>,
    /// Frames of T1 before α and of T2 after β that may not be picked (thesis: "e.g. the
    /// last 7 images"), to avoid deadlocks and moving back along the same pattern.
    /// Default 7.
    pub reject_near: usize,
}

impl Default for RecognitionParams {
    fn default() -> Self {
        RecognitionParams {
            e_detect: 0,
            theta_min: None,
            theta_quantile: 0.1,
            join_gap: None,
            reject_near: 7,
        }
    }
}

impl RecognitionParams {
    pub(crate) fn e_detect(&self, space: &WeightSpace) -> usize {
        if self.e_detect == 0 {
            space.e()
        } else {
            self.e_detect.min(space.e())
        }
    }

    /// Checks the settings: `theta_min` and `join_gap` finite and > 0 when given,
    /// `theta_quantile` in [0, 1].
    pub fn validate(&self) -> Result<()> {
        if let Some(t) = self.theta_min {
            if !(t > 0.0 && t.is_finite()) {
                return Err(bad(
                    "theta_min",
                    format!("must be a finite number > 0, got {t}"),
                ));
            }
        }
        if let Some(t) = self.join_gap {
            if !(t > 0.0 && t.is_finite()) {
                return Err(bad(
                    "join_gap",
                    format!("must be a finite number > 0, got {t}"),
                ));
            }
        }
        if !(0.0..=1.0).contains(&self.theta_quantile) {
            return Err(bad(
                "theta_quantile",
                format!("must lie in [0, 1], got {}", self.theta_quantile),
            ));
        }
        Ok(())
    }

    /// θ_min around frame `i`: the fixed value, or the adaptive per-clip quantile.
    pub(crate) fn theta(&self, space: &WeightSpace, i: usize) -> f64 {
        self.fixed_or_quantile(space, i, self.theta_min, self.theta_quantile)
    }

    /// End Growing's join gap between frames `a` and `b`.
    pub(crate) fn join_gap(&self, space: &WeightSpace, a: usize, b: usize) -> f64 {
        0.5 * (self.fixed_or_quantile(space, a, self.join_gap, 0.5)
            + self.fixed_or_quantile(space, b, self.join_gap, 0.5))
    }

    fn fixed_or_quantile(&self, space: &WeightSpace, i: usize, fixed: Option<f64>, q: f64) -> f64 {
        match fixed {
            Some(t) => t,
            None => {
                let e = self.e_detect(space);
                let t = space.clip_step_quantile(space.clip_index(i), e, q);
                // A one-frame clip has no steps; fall back to the median of the database.
                if t > 0.0 {
                    t
                } else {
                    space
                        .source_median(self.e_detect(space))
                        .max(f64::MIN_POSITIVE)
                }
            }
        }
    }
}

/// Which transition to build (§5.1; the thesis's three methods plus automatic choice).
#[derive(Clone, Debug, PartialEq)]
pub enum Transition {
    /// §5.1.1: morph weights with a low-pass kernel.
    LowPass(LowPassParams),
    /// §5.1.2.1: `steps` database frames near the straight segment α→β. `None` = as many
    /// as the gap holds at the footage's median step (`round(|αβ| / median) - 1`, ≥ 1).
    DirectBridging { steps: Option<usize> },
    /// §5.1.2.2: grow paths from α and β, at most `max_steps` frames (N) in total.
    EndGrowing { max_steps: usize },
    /// End Growing (N = 40), then Direct Bridging, then low-pass; the smallest worst jump wins.
    Auto,
}

impl Transition {
    /// Checks the method's own settings (the recognition settings are
    /// [`RecognitionParams::validate`]'s): Direct Bridging's `steps` ≥ 1, End Growing's
    /// N ≥ 2, and [`LowPassParams::validate`].
    pub fn validate(&self) -> Result<()> {
        match self {
            Transition::LowPass(p) => p.validate(),
            Transition::DirectBridging { steps: Some(0) } => {
                Err(bad("steps", "must be at least 1"))
            }
            Transition::EndGrowing { max_steps } if *max_steps < 2 => Err(bad(
                "max_steps",
                format!("must be at least 2 (one frame per side per step), got {max_steps}"),
            )),
            _ => Ok(()),
        }
    }
}

/// A frame of a transition.
#[derive(Clone, Debug, PartialEq)]
pub enum FrameRef {
    /// A frame of the database (global index, a row of the weight matrix).
    Db(usize),
    /// A synthetic weight vector (length E) to project onto the Eigenfires.
    Weights(Vec<f32>),
}

/// The frames to insert between T1 and T2, and how smooth the result is.
#[derive(Clone, Debug, PartialEq)]
pub struct Join {
    /// The inserted frames, in playing order (T1 and T2 themselves are not included).
    pub frames: Vec<FrameRef>,
    /// How many of T1's last frames the transition replaces (play T1 without them).
    /// Non-zero only for low-pass, whose morphs are filtered versions of those frames.
    pub trim_t1: usize,
    /// How many of T2's first frames the transition replaces (see `trim_t1`).
    pub trim_t2: usize,
    /// `"low-pass"`, `"direct-bridging"` or `"end-growing"`.
    pub method: &'static str,
    /// See [`seam_ratio`]; computed on T1's last [`SEAM_CONTEXT`] frames (after `trim_t1`)
    /// + `frames` + T2's first [`SEAM_CONTEXT`] frames (after `trim_t2`).
    pub seam_ratio: f64,
    /// A human-readable account of what was done (and, for [`Transition::Auto`], why
    /// this method won).
    pub why: String,
}

/// Largest distance between consecutive vectors of `sequence`, divided by
/// `source_median` (the median consecutive distance of the source clips).
/// Returns 0 for fewer than two vectors and infinity when `source_median` is 0 and the
/// sequence moves. Vectors are compared over their common length.
pub fn seam_ratio(sequence: &[Vec<f32>], source_median: f64) -> f64 {
    let worst = sequence
        .windows(2)
        .map(|w| dist(&w[0], &w[1], usize::MAX))
        .fold(0.0, f64::max);
    if worst == 0.0 {
        0.0
    } else {
        worst / source_median
    }
}

/// Builds the transition from T1 to T2 with `method`.
pub fn transition(
    space: &WeightSpace,
    t1: Range<usize>,
    t2: Range<usize>,
    method: &Transition,
    rec: &RecognitionParams,
) -> Result<Join> {
    match method {
        Transition::LowPass(p) => low_pass(space, t1, t2, p, rec),
        Transition::DirectBridging { steps } => direct_bridging(space, t1, t2, *steps, rec),
        Transition::EndGrowing { max_steps } => end_growing(space, t1, t2, *max_steps, rec),
        Transition::Auto => auto(space, t1, t2, rec),
    }
}

/// A loop (§5.1, "producing loop"): a transition from the end of `range` back to its start.
pub fn make_loop(
    space: &WeightSpace,
    range: Range<usize>,
    method: &Transition,
    rec: &RecognitionParams,
) -> Result<Join> {
    transition(space, range.clone(), range, method, rec)
}

/// Tries End Growing (N = 40), then Direct Bridging (automatic steps), then low-pass
/// (default kernel, rendering with min(50, E) weights); keeps the successful result with
/// the smallest seam ratio (the worst jump). The thesis orders the fallbacks the same way
/// (§5.1.2.2, case 3) but leaves the choice to the artist.
pub fn auto(
    space: &WeightSpace,
    t1: Range<usize>,
    t2: Range<usize>,
    rec: &RecognitionParams,
) -> Result<Join> {
    space.check_range("T1", &t1)?;
    space.check_range("T2", &t2)?;
    rec.validate()?;
    let tries = [
        Transition::EndGrowing { max_steps: 40 },
        Transition::DirectBridging { steps: None },
        Transition::LowPass(LowPassParams::default()),
    ];
    // The three tries are independent: run them side by side (after filling the shared
    // step cache once), then judge them in the order above.
    space.source_median(rec.e_detect(space));
    let results: Vec<Result<Join>> = {
        use rayon::prelude::*;
        tries
            .par_iter()
            .map(|t| transition(space, t1.clone(), t2.clone(), t, rec))
            .collect()
    };
    let mut best: Option<Join> = None;
    let mut notes = Vec::new();
    for r in results {
        match r {
            Ok(j) => {
                notes.push(format!("{}: seam ratio {:.2}", j.method, j.seam_ratio));
                if best.as_ref().is_none_or(|b| j.seam_ratio < b.seam_ratio) {
                    best = Some(j);
                }
            }
            Err(e) => notes.push(format!("failed ({e})")),
        }
    }
    let mut best = best.ok_or_else(|| TransitionError::NoPath {
        method: "auto",
        reason: notes.join("; "),
    })?;
    best.why = format!(
        "auto chose {} (smallest worst jump): {}. {}",
        best.method,
        notes.join("; "),
        best.why
    );
    Ok(best)
}

/// Seam ratio of T1's tail + `frames` + T2's head, on the first `e_detect` weights, with
/// `trim` = (frames cut from T1's end, frames cut from T2's start).
pub(crate) fn join_seam(
    space: &WeightSpace,
    t1: &Range<usize>,
    t2: &Range<usize>,
    frames: &[FrameRef],
    trim: (usize, usize),
    e_detect: usize,
) -> f64 {
    let cut = |v: &[f32]| v[..e_detect.min(v.len())].to_vec();
    let t1_end = t1.end.saturating_sub(trim.0).max(t1.start);
    let t2_start = (t2.start + trim.1).min(t2.end);
    let tail = t1_end.saturating_sub(SEAM_CONTEXT).max(t1.start)..t1_end;
    let head = t2_start..(t2_start + SEAM_CONTEXT).min(t2.end);
    let mut seq: Vec<Vec<f32>> = tail.map(|i| cut(space.frame(i))).collect();
    seq.extend(frames.iter().map(|f| match f {
        FrameRef::Db(i) => cut(space.frame(*i)),
        FrameRef::Weights(w) => cut(w),
    }));
    seq.extend(head.map(|i| cut(space.frame(i))));
    seam_ratio(&seq, space.source_median(e_detect))
}

/// Euclidean distance between `a` and `b` over their first `e` elements (and their common
/// length), accumulated in f64.
pub(crate) fn dist(a: &[f32], b: &[f32], e: usize) -> f64 {
    dist_upto(a, b, e, f64::INFINITY).unwrap_or(f64::INFINITY)
}

/// Elements summed between two checks against the limit in [`dist_upto`].
const CHECK_EVERY: usize = 32;
/// Independent f64 partial sums (vectorisable; a fixed order, so results are reproducible).
const LANES: usize = 8;

/// Adds the squared differences of `a` and `b` to the lanes: element t goes to lane
/// t mod [`LANES`] (for `a` starting at a multiple of [`LANES`]).
#[inline(always)]
fn add_squares(acc: &mut [f64; LANES], a: &[f32], b: &[f32]) {
    let (ca, cb) = (a.chunks_exact(LANES), b.chunks_exact(LANES));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (ca, cb) in ca.zip(cb) {
        for l in 0..LANES {
            let d = ca[l] as f64 - cb[l] as f64;
            acc[l] += d * d;
        }
    }
    for (l, (&x, &y)) in ra.iter().zip(rb).enumerate() {
        let d = x as f64 - y as f64;
        acc[l] += d * d;
    }
}

#[inline(always)]
fn reduce(acc: &[f64; LANES]) -> f64 {
    ((acc[0] + acc[1]) + (acc[2] + acc[3])) + ((acc[4] + acc[5]) + (acc[6] + acc[7]))
}

/// [`dist`] if it is at most `limit`, else `None` — decided early, from the leading
/// elements, as soon as their partial distance exceeds `limit` (Eigenfire weights fall off
/// quickly, so far frames are rejected after the first few dozen weights).
///
/// Exact: when `Some(d)` is returned, `d` is bit-for-bit what [`dist`] returns, and `None`
/// only when [`dist`] would exceed `limit`. The partial sums only grow (every term is
/// ≥ 0, rounding is monotone and the lanes are reduced in one fixed order), so a partial
/// distance is a lower bound of the whole one.
pub(crate) fn dist_upto(a: &[f32], b: &[f32], e: usize, limit: f64) -> Option<f64> {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        return unsafe { dist_upto_avx2(a, b, e, limit) };
    }
    dist_upto_body(a, b, e, limit)
}

/// [`dist_upto`] compiled for AVX2 (4 f64 lanes instead of SSE2's 2). The same operations
/// in the same order — no fused multiply-add — so the results are bit-for-bit the same.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn dist_upto_avx2(a: &[f32], b: &[f32], e: usize, limit: f64) -> Option<f64> {
    dist_upto_body(a, b, e, limit)
}

#[inline(always)]
fn dist_upto_body(a: &[f32], b: &[f32], e: usize, limit: f64) -> Option<f64> {
    let n = e.min(a.len()).min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f64; LANES];
    // Squared limit, enlarged far beyond rounding: a partial sum above it has a square
    // root above `limit` (cheaper than a square root per block; the final test is exact).
    let limit_sq = limit * limit * (1.0 + 1e-9);
    let (blocks_a, blocks_b) = (a.chunks_exact(CHECK_EVERY), b.chunks_exact(CHECK_EVERY));
    let (rest_a, rest_b) = (blocks_a.remainder(), blocks_b.remainder());
    for (ba, bb) in blocks_a.zip(blocks_b) {
        add_squares(&mut acc, ba, bb);
        if reduce(&acc) > limit_sq {
            return None;
        }
    }
    add_squares(&mut acc, rest_a, rest_b);
    let d = reduce(&acc).sqrt();
    (d <= limit).then_some(d)
}

/// A lower bound of [`dist`]: the same sums over the first `upto` elements only (a prefix
/// of every lane's sum, hence never more than the whole, see [`dist_upto`]).
pub(crate) fn dist_lower_bound(a: &[f32], b: &[f32], e: usize, upto: usize) -> f64 {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        return unsafe { dist_lower_bound_avx2(a, b, e, upto) };
    }
    dist_lower_bound_body(a, b, e, upto)
}

/// [`dist_lower_bound`] for AVX2 (see [`dist_upto_avx2`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn dist_lower_bound_avx2(a: &[f32], b: &[f32], e: usize, upto: usize) -> f64 {
    dist_lower_bound_body(a, b, e, upto)
}

#[inline(always)]
fn dist_lower_bound_body(a: &[f32], b: &[f32], e: usize, upto: usize) -> f64 {
    let n = e.min(upto).min(a.len()).min(b.len());
    let mut acc = [0.0f64; LANES];
    add_squares(&mut acc, &a[..n], &b[..n]);
    reduce(&acc).sqrt()
}

fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return 0.0;
    }
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

#[cfg(test)]
pub(crate) mod testdata {
    //! A smooth parametric "flame": points on a smooth closed curve in 6-D, clips being
    //! overlapping arcs of it sampled with different phases, plus small noise.
    use super::ClipSpan;
    use ignis_core::Rng;

    pub const E: usize = 6;

    /// Point of the closed curve at angle `t` (radians). Radius ~10 in the first plane.
    pub fn curve(t: f64) -> [f32; E] {
        [
            (10.0 * t.cos()) as f32,
            (10.0 * t.sin()) as f32,
            (2.0 * (2.0 * t).cos()) as f32,
            (2.0 * (2.0 * t).sin()) as f32,
            (0.5 * (3.0 * t).cos()) as f32,
            (0.5 * (3.0 * t).sin()) as f32,
        ]
    }

    /// `clips` clips of `len` frames each, steps of `dt` × U(0.6, 1.4) radians (a flame's
    /// speed varies), clip `c` starting at angle `c * spread` plus a fraction of a step;
    /// noise σ = `noise`.
    pub fn flame(
        clips: usize,
        len: usize,
        dt: f64,
        spread: f64,
        noise: f64,
        seed: u64,
    ) -> (Vec<f32>, Vec<ClipSpan>) {
        let mut rng = Rng::new(seed);
        let mut w = Vec::with_capacity(clips * len * E);
        let mut spans = Vec::new();
        for c in 0..clips {
            let phase = c as f64 * spread + dt * (c as f64 * 0.37).fract();
            let mut t = phase;
            for _ in 0..len {
                let p = curve(t);
                t += dt * rng.uniform(0.6, 1.4);
                w.extend(p.iter().map(|x| x + (noise * rng.normal()) as f32));
            }
            spans.push(ClipSpan {
                name: format!("clip{c}"),
                start: c * len,
                len,
            });
        }
        (w, spans)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seam_ratio_is_worst_step_over_median() {
        let seq = vec![
            vec![0.0, 0.0],
            vec![1.0, 0.0],
            vec![1.0, 3.0],
            vec![1.0, 4.0],
        ];
        assert!((seam_ratio(&seq, 1.5) - 2.0).abs() < 1e-12);
        assert_eq!(seam_ratio(&seq[..1], 1.0), 0.0);
    }

    #[test]
    fn space_rejects_bad_input() {
        let w = [0.0f32; 12];
        assert!(WeightSpace::new(&w, 0, vec![]).is_err());
        assert!(WeightSpace::new(&w[..5], 2, vec![]).is_err());
        let gap = vec![ClipSpan {
            name: "a".into(),
            start: 0,
            len: 5,
        }];
        assert!(matches!(
            WeightSpace::new(&w, 2, gap),
            Err(TransitionError::BadParameter { .. })
        ));
        let s = WeightSpace::new(&w, 2, vec![]).unwrap();
        assert_eq!(s.len(), 6);
        let rec = RecognitionParams::default();
        for m in [
            Transition::Auto,
            Transition::EndGrowing { max_steps: 10 },
            Transition::DirectBridging { steps: Some(2) },
            Transition::LowPass(LowPassParams::default()),
        ] {
            let e = transition(&s, 2..2, 3..5, &m, &rec).unwrap_err();
            assert!(matches!(e, TransitionError::BadRange { .. }), "{m:?}: {e}");
            let e = transition(&s, 0..2, 3..9, &m, &rec).unwrap_err();
            assert!(matches!(e, TransitionError::BadRange { .. }), "{m:?}: {e}");
        }
    }

    #[test]
    fn theta_min_must_be_positive() {
        let (w, clips) = testdata::flame(2, 30, 0.05, 1.0, 0.0, 1);
        let s = WeightSpace::new(&w, testdata::E, clips).unwrap();
        for t in [0.0, -1.0, f64::NAN] {
            let rec = RecognitionParams {
                theta_min: Some(t),
                ..Default::default()
            };
            let gap = RecognitionParams {
                join_gap: Some(t),
                ..Default::default()
            };
            let e = end_growing(&s, 0..10, 40..50, 10, &gap).unwrap_err();
            assert!(matches!(&e, TransitionError::BadParameter { name, .. } if name == "join_gap"));
            let q = RecognitionParams {
                theta_quantile: [1.5, -0.1, f64::NAN][(t.abs() as usize).min(2)],
                ..Default::default()
            };
            let e = end_growing(&s, 0..10, 40..50, 10, &q).unwrap_err();
            assert!(
                matches!(&e, TransitionError::BadParameter { name, .. } if name == "theta_quantile"),
                "{e}"
            );
            for m in [
                Transition::EndGrowing { max_steps: 10 },
                Transition::DirectBridging { steps: Some(2) },
                Transition::Auto,
            ] {
                let e = transition(&s, 0..10, 40..50, &m, &rec).unwrap_err();
                assert!(
                    matches!(&e, TransitionError::BadParameter { name, .. } if name == "theta_min"),
                    "{m:?}: {e}"
                );
            }
        }
    }

    /// Weights like a PCA's: component c has scale 10/(1 + c), plus a flat noise floor.
    pub(crate) fn pca_like(m: usize, e: usize, seed: u64) -> Vec<f32> {
        let mut rng = ignis_core::Rng::new(seed);
        let mut t = 0.0f64;
        let mut w = Vec::with_capacity(m * e);
        for _ in 0..m {
            t += 0.05 * rng.uniform(0.5, 1.5);
            for c in 0..e {
                let s = 10.0 / (1.0 + c as f64);
                w.push((s * (t * (1.0 + 0.3 * c as f64)).sin() + 0.05 * rng.normal()) as f32);
            }
        }
        w
    }

    #[test]
    fn dist_upto_is_exact_and_decides_like_dist() {
        let w = pca_like(40, 77, 5);
        let s = WeightSpace::new(&w, 77, vec![]).unwrap();
        for (i, j) in [(0, 1), (3, 30), (10, 39), (5, 5)] {
            for e in [1, 8, 31, 32, 33, 64, 77, 1000] {
                let d = dist(s.frame(i), s.frame(j), e);
                // The old definition, summed in order: equal to rounding.
                let seq: f64 = s
                    .frame(i)
                    .iter()
                    .zip(s.frame(j))
                    .take(e)
                    .map(|(x, y)| (*x as f64 - *y as f64).powi(2))
                    .sum::<f64>()
                    .sqrt();
                assert!((d - seq).abs() <= 1e-12 * seq.max(1e-300), "{d} vs {seq}");
                assert_eq!(dist(s.frame(j), s.frame(i), e), d);
                for upto in [0, 5, 8, 32, 40, e] {
                    assert!(dist_lower_bound(s.frame(i), s.frame(j), e, upto) <= d);
                }
                assert_eq!(dist_lower_bound(s.frame(i), s.frame(j), e, usize::MAX), d);
                for limit in [0.0, 0.5 * d, d, 2.0 * d, f64::INFINITY] {
                    let got = dist_upto(s.frame(i), s.frame(j), e, limit);
                    assert_eq!(
                        got,
                        (d <= limit).then_some(d),
                        "{i} {j} e={e} limit={limit}"
                    );
                }
            }
        }
    }

    #[test]
    fn simd_paths_agree_bit_for_bit() {
        let w = pca_like(20, 203, 4);
        let s = WeightSpace::new(&w, 203, vec![]).unwrap();
        for (i, j) in [(0, 19), (4, 5)] {
            for e in [7, 64, 100, 203] {
                let (a, b) = (s.frame(i), s.frame(j));
                let d = dist_upto_body(a, b, e, f64::INFINITY);
                assert_eq!(dist_upto(a, b, e, f64::INFINITY), d);
                assert_eq!(
                    dist_lower_bound(a, b, e, 40),
                    dist_lower_bound_body(a, b, e, 40)
                );
            }
        }
    }

    #[test]
    fn cached_quantiles_equal_sorting_every_time() {
        let w = pca_like(90, 12, 6);
        let clips = vec![
            ClipSpan {
                name: "a".into(),
                start: 0,
                len: 40,
            },
            ClipSpan {
                name: "b".into(),
                start: 40,
                len: 49,
            },
            ClipSpan {
                name: "c".into(),
                start: 89,
                len: 1,
            },
        ];
        let s = WeightSpace::new(&w, 12, clips).unwrap();
        for e in [3, 12] {
            let steps = |c: usize| -> Vec<f64> {
                let sp = &s.clips()[c];
                (sp.start + 1..sp.start + sp.len)
                    .map(|i| s.distance(i - 1, i, e))
                    .collect()
            };
            let mut all: Vec<f64> = (0..3).flat_map(steps).collect();
            assert_eq!(s.source_median(e), median(&mut all));
            for c in 0..3 {
                let mut d = steps(c);
                d.sort_by(f64::total_cmp);
                for q in [0.0, 0.1, 0.5, 1.0] {
                    let want = if d.is_empty() {
                        0.0
                    } else {
                        d[((d.len() - 1) as f64 * q).round() as usize]
                    };
                    assert_eq!(s.clip_step_quantile(c, e, q), want);
                }
            }
        }
        // A clone carries the cache and answers the same.
        assert_eq!(s.clone().source_median(3), s.source_median(3));
    }

    #[test]
    fn auto_reports_the_winner() {
        let (w, clips) = testdata::flame(6, 40, 0.05, 0.9, 0.005, 3);
        let s = WeightSpace::new(&w, testdata::E, clips).unwrap();
        let rec = RecognitionParams::default();
        // T1 ends around angle 0.05*19, T2 starts around angle 0.9*1 + 0.05*12.
        let j = auto(&s, 0..20, 52..80, &rec).unwrap();
        assert!(j.why.starts_with("auto chose"), "{}", j.why);
        assert!(j.seam_ratio <= 1.5, "{}: {}", j.seam_ratio, j.why);
    }
}
