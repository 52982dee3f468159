//! Even steps for a found loop: constant-speed re-timing of the kept loop frames.
//!
//! Why: the preset's fire puffs (its source heat rises and falls) and its random source's
//! total heat drifts slowly, so the picture changes more per frame while the flames are
//! long and bright than while they are short. The loop is exact, but its steps vary by
//! ±30 % around their median, which reads as the loop speeding up and slowing down, and
//! the wrap step is as uneven as any other.
//!
//! How: a looping fire's frames after settling are `N` states `S_0 … S_{N−1}` of a closed
//! path. Showing a blend of two consecutive states, `S_i·(1 − f) + S_{i+1}·f`, makes the
//! loop's time continuous (the preset already interpolates its cells, and its content
//! moves a third of a cell per step, so a blend of neighbours is the state between them
//! rather than a double image). Each output frame `k` is then shown at the time where the
//! path has covered `k / N` of its length ([`ignis_core::loopq::arc_times`]), measured on a
//! cheap proxy of the metric frames: the buffer's shown cells interpolated to
//! [`PROXY_WIDTH`] pixels wide and looked up in the palette's metric luma. A blend across
//! a state is a chord, a little shorter than the path through it, so the times are refined
//! for a few rounds on the chords of the frames actually shown, keeping the most even.
//!
//! The times depend only on the kept states and the palette, so any frame range of the
//! loop gives the same bytes (`--chunk`), at any thread count.

use crate::Kept;
use ignis_core::loopq::{arc_times, median};

/// Width of the proxy frames, pixels (the metric frame's is 128; narrower frames keep
/// their width): a third of the metric's pixels, plenty for whole-frame RMS steps.
const PROXY_WIDTH: usize = 48;

/// Refinement rounds on the shown frames' chords after the first re-timing.
const ROUNDS: usize = 10;

/// Blend weights are in 256ths.
const ONE: u32 = 256;

/// Where output frame `k` of an `N`-frame loop sits between kept states: state `at`
/// blended with state `at + 1` (cyclically) with weight `f / 256` on the second.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Slot {
    pub at: usize,
    pub f: u32,
}

/// Proxy frames of a kept loop: each state's sampled cells through the luma table, and
/// the squared distances between states at most [`NEAR`] apart (cyclically). A shown
/// frame is an affine blend of states and the distance between two such blends follows
/// from the states' pairwise distances (`|Σ cᵢxᵢ|² = −½ ΣΣ cᵢcⱼ|xᵢ − xⱼ|²` for `Σ cᵢ = 0`),
/// so each round of re-timing costs `O(N)` once the near distances are known. (The proxy
/// blends luma where the frames blend palette values: close for a smooth palette.)
struct Proxy {
    states: Vec<Vec<f32>>,
    near: Vec<[f64; NEAR + 1]>,
}

/// States this far apart (cyclically) have their distance computed up front.
const NEAR: usize = 3;

impl Proxy {
    fn new(states: Vec<Vec<f32>>) -> Proxy {
        let n = states.len();
        // One thread: the proxies are a few thousand values each, so waking the thread pool
        // (whose idle workers then spin) costs more CPU time than the work.
        let near = (0..n)
            .map(|i| {
                std::array::from_fn(|d| match d {
                    0 => 0.0,
                    _ => dist2(&states[i], &states[(i + d) % n]),
                })
            })
            .collect();
        Proxy { states, near }
    }

    /// Squared distance between states `i` and `j` (any integers, taken modulo `N`).
    fn d2(&self, i: usize, j: usize) -> f64 {
        let n = self.states.len();
        let (i, j) = (i % n, j % n);
        let fwd = (j + n - i) % n;
        if fwd <= NEAR {
            self.near[i][fwd]
        } else if n - fwd <= NEAR {
            self.near[j][n - fwd]
        } else {
            dist2(&self.states[i], &self.states[j])
        }
    }

    /// The cyclic chords between the frames shown at `slots` (the last back to the first).
    fn chords(&self, slots: &[Slot]) -> Vec<f64> {
        let n = slots.len();
        (0..n)
            .map(|k| {
                let (a, b) = (slots[k], slots[(k + 1) % n]);
                let w = |f: u32| f64::from(f) / f64::from(ONE);
                // coefficients: +a's blend, −b's blend
                let c = [
                    (a.at, 1.0 - w(a.f)),
                    (a.at + 1, w(a.f)),
                    (b.at, -(1.0 - w(b.f))),
                    (b.at + 1, -w(b.f)),
                ];
                let mut s = 0.0;
                for (x, &(i, ci)) in c.iter().enumerate() {
                    for &(j, cj) in &c[x + 1..] {
                        if ci != 0.0 && cj != 0.0 {
                            s -= ci * cj * self.d2(i, j);
                        }
                    }
                }
                s.max(0.0).sqrt()
            })
            .collect()
    }
}

/// Mean squared difference of two proxy frames.
fn dist2(a: &[f32], b: &[f32]) -> f64 {
    ignis_core::loopq::sum_sq_diff(a, b) / a.len().max(1) as f64
}

/// Bilinear taps from the shown cells to the proxy frame, as the frame's own
/// interpolation ([`crate::taps`]).
struct Taps {
    w: usize,
    x: Vec<(usize, usize, u32)>,
    y: Vec<(usize, usize, u32)>,
}

/// The kept state's shown cells bilinearly interpolated to the proxy frame (as the frame
/// interpolates them to its size, in 256ths and rounded the same way) and looked up in
/// the luma table.
fn sample((top, rows): &Kept, taps: &Taps, luma: &[f32; 256]) -> Vec<f32> {
    let (w, pw) = (taps.w, taps.x.len());
    // each shown cell row interpolated across, in 256ths (rows above the kept top are 0)
    let shown = taps.y.iter().map(|&(_, b, _)| b + 1).max().unwrap_or(0);
    let mut wide = vec![0u32; shown * pw];
    for y in (*top).min(shown)..shown {
        let r = &rows[(y - top) * w..(y - top + 1) * w];
        for (o, &(a, b, t)) in wide[y * pw..(y + 1) * pw].iter_mut().zip(&taps.x) {
            *o = r[a] as u32 * (256 - t) + r[b] as u32 * t;
        }
    }
    let mut out = Vec::with_capacity(pw * taps.y.len());
    for &(a, b, t) in &taps.y {
        let (ra, rb) = (&wide[a * pw..(a + 1) * pw], &wide[b * pw..(b + 1) * pw]);
        out.extend(
            ra.iter()
                .zip(rb)
                .map(|(&p, &q)| luma[((p * (256 - t) + q * t + 32768) >> 16) as usize]),
        );
    }
    out
}

/// Largest chord over the median (how uneven a loop's steps are).
fn unevenness(chords: &[f64]) -> f64 {
    let med = median(&mut chords.to_vec());
    let max = chords.iter().copied().fold(0.0, f64::max);
    if med > 0.0 {
        max / med
    } else {
        1.0
    }
}

/// Slots at continuous times `t` (in `0..n`), weights rounded to 256ths.
fn slots_at(t: &[f64], n: usize) -> Vec<Slot> {
    t.iter()
        .map(|&t| {
            let i = t.floor();
            let f = ((t - i) * ONE as f64).round() as u32;
            let at = i as usize + (f / ONE) as usize;
            Slot {
                at: at % n,
                f: f % ONE,
            }
        })
        .collect()
}

/// The even re-timing of the loop `ring` (state `j` is the loop's frame `j`; `w` cells
/// wide, the top `shown` rows shown as a frame of `frame` = (width, height) pixels), for
/// a palette whose metric luma of value `v` is `luma[v]`: one [`Slot`] per output frame,
/// frame 0 on state 0. `None` when the loop is too short to re-time (under 3 frames) or
/// no re-timing is more even than the states as they are.
pub(crate) fn even_slots(
    ring: &[Kept],
    (w, shown): (usize, usize),
    frame: (usize, usize),
    luma: &[f32; 256],
) -> Option<Vec<Slot>> {
    let n = ring.len();
    if n < 3 {
        return None;
    }
    let pw = frame.0.clamp(1, PROXY_WIDTH);
    let ph = ((pw * frame.1) as f64 / frame.0.max(1) as f64)
        .round()
        .max(2.0) as usize;
    let taps = Taps {
        w,
        x: crate::taps(pw, w),
        y: crate::taps(ph, shown),
    };
    // One thread, as `Proxy::new`: each state is sampled at the proxy's few thousand cells.
    let states = ring.iter().map(|k| sample(k, &taps, luma));
    let proxy = Proxy::new(states.collect());
    let mut slots: Vec<Slot> = (0..n).map(|at| Slot { at, f: 0 }).collect();
    let mut best: Option<(f64, Vec<Slot>)> = None;
    for round in 0..=ROUNDS {
        let chords = proxy.chords(&slots);
        let score = unevenness(&chords);
        if best.as_ref().is_none_or(|(b, _)| score < *b) {
            best = Some((score, slots.clone()));
        }
        if round == ROUNDS {
            break;
        }
        // the path through the shown frames, frame 0 again at its end (time n)
        let times: Vec<f64> = slots
            .iter()
            .map(|s| s.at as f64 + f64::from(s.f) / ONE as f64)
            .chain([n as f64])
            .collect();
        let mut arc = Vec::with_capacity(n + 1);
        arc.push(0.0);
        for c in &chords {
            arc.push(arc[arc.len() - 1] + c);
        }
        let t: Vec<f64> = arc_times(&arc, (0..n).map(|k| k as f64 / n as f64))
            .into_iter()
            .map(|p| {
                let x = p * n as f64;
                let i = (x.floor() as usize).min(n - 1);
                times[i] + (x - i as f64) * (times[i + 1] - times[i])
            })
            .collect();
        slots = slots_at(&t, n);
    }
    let (_, slots) = best?;
    let identity = slots.iter().enumerate().all(|(k, s)| s.at == k && s.f == 0);
    (!identity).then_some(slots)
}

/// The loop's shown buffer at `slot`: the two kept states blended (`w`×`h` cells).
pub(crate) fn blend(ring: &[Kept], slot: Slot, w: usize, h: usize) -> Vec<u8> {
    let n = ring.len();
    let full = |(top, rows): &Kept| {
        let mut b = vec![0u8; w * h];
        b[top * w..].copy_from_slice(rows);
        b
    };
    let a = full(&ring[slot.at]);
    if slot.f == 0 {
        return a;
    }
    let b = full(&ring[(slot.at + 1) % n]);
    let (wa, wb) = (ONE - slot.f, slot.f);
    a.iter()
        .zip(&b)
        .map(|(&x, &y)| ((x as u32 * wa + y as u32 * wb + ONE / 2) / ONE) as u8)
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// States along a path there and back whose steps alternate 4 and 12 grey levels:
    /// re-timed, the largest shown step is within 15 % of the median (rounding to whole
    /// levels is the rest), where the states' own steps differ threefold.
    #[test]
    fn uneven_straight_path_is_evened() {
        let (w, h) = (4usize, 2usize);
        let mut pos = 0u32;
        let mut values = Vec::new();
        for k in 0..12 {
            values.push(pos);
            pos += if k % 2 == 0 { 4 } else { 12 };
        }
        // there and back, so the loop closes: 0 .. 92 .. 0 over 24 states
        let mut there: Vec<u32> = values.clone();
        there.extend(values.iter().rev().map(|&v| v + 2));
        let ring: Vec<Kept> = there
            .iter()
            .map(|&v| (0, vec![(40 + v) as u8; w * h]))
            .collect();
        let luma: [f32; 256] = std::array::from_fn(|i| i as f32 / 255.0);
        let slots = even_slots(&ring, (w, h), (w, h), &luma).expect("re-timed");
        assert_eq!(slots[0], Slot { at: 0, f: 0 });
        let shown: Vec<f32> = slots
            .iter()
            .map(|&s| f32::from(blend(&ring, s, w, h)[0]))
            .collect();
        let n = shown.len();
        let steps: Vec<f32> = (0..n)
            .map(|k| (shown[(k + 1) % n] - shown[k]).abs())
            .collect();
        let taps = Taps {
            w,
            x: crate::taps(w, w),
            y: crate::taps(h, h),
        };
        let proxy = Proxy::new(ring.iter().map(|k| sample(k, &taps, &luma)).collect());
        let before =
            unevenness(&proxy.chords(&(0..n).map(|at| Slot { at, f: 0 }).collect::<Vec<_>>()));
        let med = median(&mut steps.iter().map(|&s| f64::from(s)).collect::<Vec<_>>());
        let max = steps.iter().copied().fold(0.0, f32::max);
        assert!(before > 2.0, "the states are uneven: {before}");
        assert!(f64::from(max) / med <= 1.15, "steps {steps:?}");
    }

    #[test]
    fn short_or_still_loops_are_left_alone() {
        let luma: [f32; 256] = std::array::from_fn(|i| i as f32);
        let two: Vec<Kept> = vec![(0, vec![1; 4]), (0, vec![9; 4])];
        assert!(even_slots(&two, (2, 2), (2, 2), &luma).is_none());
        let still: Vec<Kept> = vec![(0, vec![5; 4]); 6];
        assert!(even_slots(&still, (2, 2), (2, 2), &luma).is_none());
    }

    #[test]
    fn slots_round_and_wrap() {
        let s = slots_at(&[0.0, 1.999, 2.5, 5.9999], 6);
        assert_eq!(s[0], Slot { at: 0, f: 0 });
        assert_eq!(s[1], Slot { at: 2, f: 0 });
        assert_eq!(s[2], Slot { at: 2, f: 128 });
        assert_eq!(s[3], Slot { at: 0, f: 0 });
    }
}
