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
//! Since `τ` is continuous, the frames are instead rendered where the animation has moved
//! equal distances: a small preview ([`LoopTiming`]: two frames per output frame, 64 px
//! wide) is rendered at uniform loop times as metric frames
//! (`ignis_core::loopq`), and the frames are placed so that the RMS differences between
//! consecutive ones, read off the preview, are all equal ([`even_step_times`]). Frame 0
//! stays at `τ = 0`, the period stays `N`, and every step, the wrap included, covers about
//! the same distance.
//! The times depend on the whole loop only, so every `--chunk` of a render computes the
//! same ones.

use crate::motion::{Collision, Keyframe, Script};
use ignis_core::GrayFrame;
use std::sync::Arc;

/// How a looping animator times its frames (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LoopTiming {
    /// Width in pixels of the preview the steps are measured on, at most the width of the
    /// metric frames (`ignis_core::loopq::metric_size`: 128 px, or the scene's own width
    /// when narrower); the height keeps the scene's aspect.
    pub preview_width: u32,
    /// Preview frames per output frame, at uniform loop times; 0 renders the frames at
    /// uniform loop times `0, 1, …, N − 1` without a preview.
    pub samples_per_frame: u32,
}

impl LoopTiming {
    /// The default: a 64-px preview, 2 samples per frame. A 32-px preview misses the
    /// detail the metric frames see and leaves steps up to 1.5× the median; one sample per
    /// frame is too coarse to place frames between samples (up to 1.36×). Steps and cost
    /// of each are in `benches/README.md`.
    pub const DEFAULT: LoopTiming = LoopTiming {
        preview_width: 64,
        samples_per_frame: 2,
    };
    /// Frames at uniform loop times, no preview.
    pub const UNIFORM: LoopTiming = LoopTiming {
        preview_width: 0,
        samples_per_frame: 0,
    };

    /// Whether this timing renders a preview.
    pub fn retimes(&self) -> bool {
        self.samples_per_frame > 0 && self.preview_width > 0
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

/// Loop times (in frames, in `0..frames`) at which the `frames` steps of a loop (the
/// wrap back to frame 0 included) are equally long, from a preview of the loop: `preview`
/// holds metric frames at the uniform loop times `j · frames / preview.len()` (a whole
/// number `K ≥ 1` of them per frame). Frame 0 is at time 0.
///
/// The distance between any two loop times is the RMS difference of the preview frames
/// around them, interpolated ([`PreviewDistances`]). Starting from uniform times, each
/// frame is moved, sweep after sweep, to where its steps to its two neighbours are equal
/// ([`relax`]); frame 0 and the loop's end stay put, so the wrap is evened out with the
/// rest. A step is measured whole, not summed from sub-steps: the RMS difference of a
/// flame grows more slowly than its time apart (the noise decorrelates), so a sum of
/// short steps would overrate the stretches that change fast at fine scales.
///
/// Errors when the preview's length is not a multiple of `frames` or its frames differ in
/// size.
pub fn even_step_times(preview: &[GrayFrame], frames: u32) -> Result<Vec<f64>, String> {
    let mut d = PreviewDistances::builder(preview.len(), frames)?;
    for f in preview {
        d.push(f.clone())?;
    }
    Ok(d.finish()?.even_step_times())
}

/// Sweeps over the interior times of `t` (in samples, `per_frame` to a frame; `t[0]` and
/// the last fixed), each moved towards where its two steps are equal (over-relaxed by
/// [`RELAX_OVERSHOOT`]) but no step shorter than [`MIN_STEP`] or longer than
/// [`MAX_STEP`] frames, until the longest step is within 0.5 % of the shortest, the
/// spread stops shrinking, or 2,000 sweeps (fewer for loops over 2,000 frames: ~4 million
/// moves in all, each ~60 cheap look-ups).
fn relax(d: &PreviewDistances, t: &mut [f64], per_frame: f64) {
    let n = t.len() - 1;
    let (short, long) = (MIN_STEP * per_frame, MAX_STEP * per_frame);
    let (mut best, mut stalled) = (f64::INFINITY, 0);
    // a long loop's sweeps are long: at most ~4 million moves in all (each ~60 look-ups)
    let sweeps = (4_000_000 / n.max(1)).clamp(20, 2000);
    for _ in 0..sweeps {
        let steps = t.windows(2).map(|w| d.between(w[0], w[1]));
        let (lo, hi) = steps.fold((f64::MAX, 0.0f64), |(a, b), s| (a.min(s), b.max(s)));
        // even (or a preview that never changes: nothing to even out)
        if hi <= lo * 1.005 || hi == 0.0 {
            break;
        }
        // where the step bounds or a dip in the distances hold it, the spread stops
        // shrinking within ~100 sweeps; 50 more without a 0.1 % gain end the search
        if hi / lo < best * 0.999 {
            (best, stalled) = (hi / lo, 0);
        } else {
            stalled += 1;
            if stalled == 50 {
                break;
            }
        }
        for i in 1..n {
            let (a, b) = (t[i - 1], t[i + 1]);
            let (from, to) = ((a + short).max(b - long), (b - short).min(a + long));
            if from >= to {
                continue;
            }
            let (mut lo, mut hi) = (from, to);
            for _ in 0..30 {
                let mid = 0.5 * (lo + hi);
                if d.between(a, mid) < d.between(mid, b) {
                    lo = mid;
                } else {
                    hi = mid;
                }
            }
            let x = t[i] + RELAX_OVERSHOOT * (0.5 * (lo + hi) - t[i]);
            t[i] = x.clamp(from, to);
        }
    }
}

/// Successive over-relaxation factor of [`relax`] (1 = plain Gauss–Seidel; the long,
/// smooth unevenness along a loop then takes `O(frames²)` sweeps to spread out).
const RELAX_OVERSHOOT: f64 = 1.6;
/// Shortest and longest step the re-timing may make, in frames: it evens out the steps
/// by warping time locally, never by skipping or repeating a flicker (a candle puffs
/// every 3 frames at 30 fps, so the distance between two frames is not monotonic in their
/// time apart beyond about a frame and a half).
const MIN_STEP: f64 = 0.6;
const MAX_STEP: f64 = 1.6;

/// RMS differences between the frames of a cyclic preview up to `span − 1` samples apart,
/// and the distance between any two loop times (in samples) interpolated from them.
pub(crate) struct PreviewDistances {
    /// `d[i][o]`: from sample `i` to sample `(i + o) mod m`, `o < span`.
    d: Vec<Vec<f64>>,
    span: usize,
    /// Output frames of the loop.
    frames: usize,
}

/// [`PreviewDistances`] built from preview frames pushed one at a time, holding only the
/// first and the latest `span` of them (a long loop's preview is not kept in memory).
pub(crate) struct DistanceBuilder {
    m: usize,
    frames: usize,
    span: usize,
    first: Vec<GrayFrame>,
    recent: std::collections::VecDeque<GrayFrame>,
    pushed: usize,
    d: Vec<Vec<f64>>,
}

impl DistanceBuilder {
    /// Adds the next preview frame (in loop order).
    pub fn push(&mut self, f: GrayFrame) -> Result<(), String> {
        let j = self.pushed;
        if j >= self.m {
            return Err(format!("more than {} preview frames", self.m));
        }
        if let Some(g) = self.first.first().filter(|g| g.size() != f.size()) {
            return Err(format!("preview frames of {} and {}", g.size(), f.size()));
        }
        // distances from the latest frames (up to span − 1 back) to this one
        let back = self.recent.len();
        for (o, g) in self.recent.iter().enumerate() {
            let i = j - (back - o);
            self.d[i][j - i] = ignis_core::loopq::rms_diff(g, &f);
        }
        if self.first.len() < self.span - 1 {
            self.first.push(f.clone());
        }
        self.recent.push_back(f);
        if self.recent.len() > self.span - 1 {
            self.recent.pop_front();
        }
        self.pushed += 1;
        Ok(())
    }

    /// The distances, once all `m` frames are in: the last frames' steps past the loop's
    /// end are to its first frames.
    pub fn finish(mut self) -> Result<PreviewDistances, String> {
        if self.pushed != self.m {
            return Err(format!("{} of {} preview frames", self.pushed, self.m));
        }
        let m = self.m;
        let back = self.recent.len();
        for (o, g) in self.recent.iter().enumerate() {
            let i = m - (back - o);
            for (q, h) in self.first.iter().enumerate() {
                let off = m - i + q;
                if off < self.span {
                    self.d[i][off] = ignis_core::loopq::rms_diff(g, h);
                }
            }
        }
        Ok(PreviewDistances {
            d: self.d,
            span: self.span,
            frames: self.frames,
        })
    }
}

impl PreviewDistances {
    /// A builder for the `m` preview frames (a whole number ≥ 1 per output frame) of an
    /// `frames`-frame loop.
    pub fn builder(m: usize, frames: u32) -> Result<DistanceBuilder, String> {
        let n = frames as usize;
        if n == 0 || m == 0 || !m.is_multiple_of(n) {
            return Err(format!("a preview of {m} frames for a loop of {frames}"));
        }
        let per_frame = m / n;
        let span = ((MAX_STEP * per_frame as f64).ceil() as usize + 2).min(m + 1);
        Ok(DistanceBuilder {
            m,
            frames: n,
            span,
            first: Vec::new(),
            recent: Default::default(),
            pushed: 0,
            d: vec![vec![0.0; span]; m],
        })
    }

    /// [`even_step_times`] from these distances.
    pub fn even_step_times(&self) -> Vec<f64> {
        let n = self.frames;
        let k = self.d.len() / n;
        let mut t: Vec<f64> = (0..=n).map(|i| (i * k) as f64).collect();
        relax(self, &mut t, k as f64);
        t[..n]
            .iter()
            .map(|&t| (t / k as f64).clamp(0.0, n as f64))
            .collect()
    }

    /// Distance from sample `i` (any integer) to `i + o`, `0 ≤ o < span`.
    fn at(&self, i: i64, o: i64) -> f64 {
        let m = self.d.len() as i64;
        self.d[i.rem_euclid(m) as usize][o.clamp(0, self.span as i64 - 1) as usize]
    }

    /// Distance between loop times `a ≤ b` (samples, `b − a < span − 1`): bilinear in
    /// the grid of sample pairs around `(a, b)`. (Two alternatives measured worse on the
    /// presets' loops: the distance between preview frames blended to `a` and `b`, which
    /// underrates it, blends being softer; and interpolating in the time apart from each
    /// sample around `a`.)
    fn between(&self, a: f64, b: f64) -> f64 {
        let (ia, ib) = (a.floor(), b.floor());
        let (fa, fb) = (a - ia, b - ib);
        let (ia, ib) = (ia as i64, ib as i64);
        let g = |x: i64, y: i64| if y <= x { 0.0 } else { self.at(x, y - x) };
        let lo = g(ia, ib) * (1.0 - fb) + g(ia, ib + 1) * fb;
        let hi = g(ia + 1, ib) * (1.0 - fb) + g(ia + 1, ib + 1) * fb;
        lo * (1.0 - fa) + hi * fa
    }
}

/// A looping animator's state ([`crate::FireScene::looping_animator`]).
#[derive(Clone, Debug)]
pub(crate) struct Looping {
    /// The loop's period in frames.
    pub frames: u64,
    /// Loop time (frames, in `0..frames`) of each frame of one cycle, non-decreasing
    /// from 0. A cycle has `frames` frames; a preview has more.
    pub times: Arc<[f64]>,
    /// Per fire: its script made periodic (scripted fires only).
    pub scripts: Arc<[Option<LoopScript>]>,
    /// Per fire: its simulation over one loop (simulated fires only).
    pub sims: Arc<[Option<SimTrack>]>,
}

impl Looping {
    /// Loop time of frame `frame` (any index: the times repeat every cycle).
    pub fn time(&self, frame: u64) -> f64 {
        self.times[(frame % self.times.len() as u64) as usize]
    }

    /// Loop time of the frame before `frame`, minus a period at the cycle's start (so it
    /// is below [`Looping::time`] of `frame`).
    pub fn previous_time(&self, frame: u64) -> f64 {
        let c = self.times.len() as u64;
        let k = frame % c;
        if k == 0 {
            self.times[c as usize - 1] - self.frames as f64
        } else {
            self.times[k as usize - 1]
        }
    }
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

    /// The contacts of the steps into the whole frames `j` with `lo < j ≤ hi` (`lo` may
    /// be negative: the cycle's first frame reports frame 0's).
    pub fn hits_between(&self, lo: f64, hi: f64) -> impl Iterator<Item = &Collision> {
        let n = self.hits.len();
        let first = (lo.floor() + 1.0).max(0.0) as usize;
        let last = (hi.floor().max(-1.0) + 1.0) as usize;
        self.hits[first.min(n)..last.clamp(first.min(n), n)]
            .iter()
            .flatten()
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

    /// Frames of a 1-D pattern scrolling at a speed that varies over the loop: the times
    /// found make every step (the wrap included) the same length, and a pattern scrolling
    /// at constant speed keeps the uniform times.
    #[test]
    fn times_make_the_steps_even() {
        let size = ignis_core::Size::new(64, 1).unwrap();
        // phase at loop time u in 0..1: one whole turn, fast in the first half
        let phase = |u: f64, uneven: f64| u + uneven * (std::f64::consts::TAU * u).sin() / 7.0;
        let frame = |u: f64, uneven: f64| {
            let p = phase(u, uneven);
            let v = (0..64)
                .map(|x| {
                    let a = std::f64::consts::TAU * (x as f64 / 64.0 + p);
                    (0.5 + 0.4 * a.sin()) as f32
                })
                .collect();
            GrayFrame::from_vec(size, v).unwrap()
        };
        let n = 12u32;
        for uneven in [0.0, 0.3] {
            let k = 4;
            let preview: Vec<_> = (0..n * k)
                .map(|j| frame(f64::from(j) / f64::from(n * k), uneven))
                .collect();
            let t = even_step_times(&preview, n).unwrap();
            assert_eq!(t[0], 0.0);
            let frames: Vec<_> = t.iter().map(|&t| frame(t / f64::from(n), uneven)).collect();
            let steps = ignis_core::loopq::steps(&frames, true).unwrap();
            let med = ignis_core::loopq::median(&mut steps.clone());
            let worst = steps
                .iter()
                .map(|s| (s / med - 1.0).abs())
                .fold(0.0, f64::max);
            assert!(worst < 0.02, "uneven {uneven}: {steps:?}");
            if uneven == 0.0 {
                for (i, t) in t.iter().enumerate() {
                    assert!((t - i as f64).abs() < 0.02, "{t:?}");
                }
            } else {
                // uniform times would not do: the fast half's steps are longer
                let uniform: Vec<_> = (0..n)
                    .map(|i| frame(f64::from(i) / f64::from(n), uneven))
                    .collect();
                let us = ignis_core::loopq::steps(&uniform, true).unwrap();
                let umed = ignis_core::loopq::median(&mut us.clone());
                assert!(
                    us.iter().cloned().fold(0.0, f64::max) / umed > 1.2,
                    "{us:?}"
                );
            }
        }
        assert!(even_step_times(&[], 3).is_err());
        assert!(even_step_times(&vec![frame(0.0, 0.0); 5], 3).is_err());
    }

    /// The distances built from frames pushed one at a time (holding only a few) are the
    /// RMS differences of the cyclic preview, past its end too, for short and long loops.
    #[test]
    fn streamed_distances_wrap_around_the_loop() {
        let size = ignis_core::Size::new(3, 1).unwrap();
        for (m, frames) in [(2usize, 1u32), (2, 2), (3, 3), (8, 4), (24, 12)] {
            let preview: Vec<_> = (0..m)
                .map(|j| {
                    let v = (0..3)
                        .map(|x| ((j * 7 + x * 3) % 11) as f32 / 10.0)
                        .collect();
                    GrayFrame::from_vec(size, v).unwrap()
                })
                .collect();
            let mut b = PreviewDistances::builder(m, frames).unwrap();
            for f in &preview {
                b.push(f.clone()).unwrap();
            }
            assert!(b.push(preview[0].clone()).is_err());
            let d = b.finish().unwrap();
            for i in 0..m {
                for o in 0..d.span {
                    let want = ignis_core::loopq::rms_diff(&preview[i], &preview[(i + o) % m]);
                    assert_eq!(d.d[i][o], want, "m {m}, i {i}, o {o}");
                }
            }
        }
        assert!(PreviewDistances::builder(5, 2).is_err());
        let b = PreviewDistances::builder(4, 2).unwrap();
        assert!(b.finish().is_err());
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
        let times = [0.0, 0.7, 1.9, 3.2];
        let mut seen = Vec::new();
        for k in 0..4 {
            let lo = if k == 0 { times[3] - 4.0 } else { times[k - 1] };
            seen.extend(tr.hits_between(lo, times[k]).map(|h| h.obstacle));
        }
        assert_eq!(seen, vec![0, 1, 2, 3]);
    }
}
