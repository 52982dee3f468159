//! The periodic orbit of a looping fire, solved row by row from the source up.
//!
//! Why: a looping fire is driven by a source line and sparklies that repeat every `N`
//! frames, and its loop is the buffer's periodic orbit under that drive. Simulating the
//! whole buffer from a cold start until it repeats is slow: averaging keeps a uniform
//! difference, which only the black sky, the dead edges, the source row and rounding
//! remove, so a 320×200 per-pixel fire needs 240–480 frames, its rows settling from the
//! source up at about one row per 8 frames. But no row reads the row above it: row `y`'s
//! next values are its own and row `y + 1`'s old values, averaged and faded. Once row
//! `y + 1`'s orbit is known, row `y` alone is a one-row recurrence under a periodic drive,
//! and it forgets its start within a few dozen steps (a row's own pixels carry three
//! quarters of the average, so a difference shrinks by about a third a step; the last
//! differences of 1 are removed by rounding). Solving the rows one at a time from the
//! source up, each for one period plus its short transient, gives a periodic orbit of the
//! whole fire for about one period plus a few dozen frames of burning.
//!
//! What comes out is a true orbit of the simulation (burning from its state at any phase
//! gives the next), the same bytes for the same inputs. It need not be the orbit a cold
//! fire would reach: the integer recurrence has neighbouring fixed points (a difference of
//! 1 can persist), and each row starts from the values of the row below it instead of
//! from a cold start; both look the same.
//!
//! Speed: the article's row is a serial chain (each pixel reads its new left neighbour),
//! so a row runs two steps at a time, one pixel apart, their chains overlapping in the
//! CPU; a row's phases sit side by side in one store, beside the row below's.

use crate::{sparkled, Kernel, Rng, Sparkle, SPARK_STREAM};

/// The rows of a loop's states: for each row solved so far, from the bottom row up (the
/// solve adds a row above at a time), its value at each phase `k` (the state after a frame
/// number `≡ k` modulo the period), a row's phases side by side; or only the last two
/// rows (the row being solved and the one below it, which drives it) when the whole loop
/// is too large to keep.
pub(crate) struct Orbit {
    period: usize,
    w: usize,
    h: usize,
    keep_all: bool,
    data: Vec<u8>,
}

impl Orbit {
    /// An orbit of `period` phases of `w`×`h` buffers, keeping every row or two, with the
    /// rows from `y` down to the bottom present and zero.
    pub fn new(period: usize, w: usize, h: usize, keep_all: bool, y: usize) -> Orbit {
        let rows = if keep_all { h - y } else { 2 };
        Orbit {
            period,
            w,
            h,
            keep_all,
            data: vec![0; rows * period * w],
        }
    }

    /// Makes room for row `y` (zero), the row above the topmost so far.
    pub fn add_row(&mut self, y: usize) {
        if self.keep_all {
            self.data.resize((self.h - y) * self.period * self.w, 0);
        }
    }

    fn offset(&self, k: usize, y: usize) -> usize {
        let r = if self.keep_all { self.h - 1 - y } else { y % 2 };
        (r * self.period + k) * self.w
    }

    pub fn row(&self, k: usize, y: usize) -> &[u8] {
        let o = self.offset(k, y);
        &self.data[o..o + self.w]
    }

    pub fn row_mut(&mut self, k: usize, y: usize) -> &mut [u8] {
        let o = self.offset(k, y);
        &mut self.data[o..o + self.w]
    }

    /// Whether row `y` is non-zero, at each phase.
    pub fn lit(&self, y: usize) -> Vec<bool> {
        (0..self.period)
            .map(|k| self.row(k, y).iter().fold(0, |a, &v| a | v) != 0)
            .collect()
    }

    /// The kept loop (every row kept): each phase's buffer as its topmost non-zero row
    /// `tops[k]` and the rows from there down.
    pub fn into_kept(self, tops: &[usize]) -> Vec<crate::Kept> {
        debug_assert!(self.keep_all);
        (0..self.period)
            .map(|k| {
                let top = tops[k];
                let mut rows = Vec::with_capacity((self.h - top) * self.w);
                for y in top..self.h {
                    rows.extend_from_slice(self.row(k, y));
                }
                (top, rows)
            })
            .collect()
    }
}

/// What drives a row besides the row below: the kernel and its constants and where each
/// phase's sparkle falls in each row.
pub(crate) struct Drive {
    w: usize,
    h: usize,
    e: usize,
    fade: u8,
    kernel: Kernel,
    heat: u8,
    sparkle: Option<Sparkle>,
    /// The sparkle's column in row `y` during the frame of phase `k`: `[k·h + y]`, drawn
    /// from the same stream as [`crate::ClassicFire`]'s looping steps.
    spark_x: Vec<u32>,
}

impl Drive {
    pub fn new(p: &crate::ClassicParams, w: usize, h: usize, period: usize) -> Drive {
        let e = p.edge as usize;
        let mut spark_x = Vec::new();
        if p.sparkle.is_some() {
            spark_x = vec![0; period * h];
            for k in 0..period {
                let mut rng = Rng::derive(p.seed, SPARK_STREAM + k as u64);
                for y in e..h - e {
                    spark_x[k * h + y] = (e + rng.below((w - 2 * e) as u32) as usize) as u32;
                }
            }
        }
        Drive {
            w,
            h,
            e,
            fade: p.fade,
            kernel: p.kernel,
            heat: p.heat,
            sparkle: p.sparkle,
            spark_x,
        }
    }

    /// The sparkle's column in row `y` at phase `k` (`usize::MAX`: none).
    fn spark(&self, k: usize, y: usize) -> usize {
        match self.sparkle {
            Some(_) => self.spark_x[k * self.h + y] as usize,
            None => usize::MAX,
        }
    }
}

/// Solves row `y` given row `y + 1`'s orbit: starts from row `y + 1`'s phase-0 values and
/// steps the row until it equals itself a period before, writing each step into its phase.
/// `Ok(steps)` once periodic (every phase of the row then holds the orbit), `Err(steps)`
/// if not within about `cap` steps (the phases hold the last period's values).
pub(crate) fn solve_row(
    orbit: &mut Orbit,
    y: usize,
    d: &Drive,
    cap: usize,
    (mid, new): (&mut Vec<u8>, &mut Vec<u8>),
) -> Result<usize, usize> {
    let (n, w) = (orbit.period, d.w);
    for v in [&mut *mid, &mut *new] {
        v.clear();
        v.resize(w, 0);
    }
    let start = orbit.row(0, y + 1).to_vec();
    orbit.row_mut(0, y).copy_from_slice(&start);
    // two steps at a time (see `two_steps`)
    for t in (0..cap).step_by(2) {
        let (k0, k1) = (t % n, (t + 1) % n);
        let below = [orbit.row(k0, y + 1), orbit.row(k1, y + 1)];
        let spark = [d.spark(k0, y), d.spark(k1, y)];
        two_steps(orbit.row(k0, y), below, (mid, new), d, spark);
        for (tau, row) in [(t + 1, &mid[..]), (t + 2, &new[..])] {
            let slot = orbit.row_mut(tau % n, y);
            if tau >= n && slot == row {
                // equal to itself a period before: periodic from then on, and the
                // phases hold the last period
                return Ok(tau);
            }
            slot.copy_from_slice(row);
        }
    }
    Err(cap.next_multiple_of(2))
}

/// Two steps of one row: `old` the row's state, `below[i]` the old row below it at step
/// `i`, `spark[i]` the column of step `i`'s sparkle; `mid` and `new` (edges zero) receive
/// the row after each step. With the article's kernel a row is a serial chain (each pixel
/// reads its new left neighbour), but the second step at pixel `x` only needs the first up
/// to `x + 1`, so the two run together one pixel apart and their chains overlap in the CPU.
fn two_steps(
    old: &[u8],
    below: [&[u8]; 2],
    (mid, new): (&mut [u8], &mut [u8]),
    d: &Drive,
    spark: [usize; 2],
) {
    let (w, e) = (d.w, d.e);
    match (d.kernel, d.sparkle) {
        (Kernel::Article, sparkle) => {
            let n = w - 2 * e;
            let (me, right) = (&old[e..e + n], &old[e + 1..e + 1 + n]);
            let (u0, u1) = (&below[0][e..e + n], &below[1][e..e + n]);
            let m = &mut mid[e..e + n];
            let o = &mut new[e..e + n];
            let f4 = 4 * d.fade as i32;
            let sp = sparkle.unwrap_or(Sparkle {
                threshold: 0,
                boost: 0,
            });
            let s0 = spark[0].wrapping_sub(e);
            // `(left + self + right + below) / 4 − fade` clamped at 0, left to right, each
            // step's `left` its own new value (the edge's 0 first), before any sparkle
            let px = |left: i32, a: u8, b: u8, c: u8| {
                ((left + a as i32 + b as i32 + c as i32 - f4) >> 2).max(0)
            };
            let spk = |i: usize, v: i32| {
                if i == s0 {
                    sparkled(v as u8, sp, d.heat)
                } else {
                    v as u8
                }
            };
            // the first step's pixel `i` and the second's `i − 1`, which reads the first's
            // pixels `i − 1` and `i` (kept in registers as `mp` and `mi`)
            let mut l0 = px(0, me[0], right[0], u0[0]);
            let mut mp = spk(0, l0);
            m[0] = mp;
            let mut l1 = 0i32;
            let ones = me[1..].iter().zip(&right[1..]).zip(&u0[1..]);
            let twos = u1[..n - 1].iter().zip(o[..n - 1].iter_mut());
            let mids = m[1..n].iter_mut();
            for (i, (((a, b), c), (mo, (u, oo)))) in (1..).zip(ones.zip(mids.zip(twos))) {
                l0 = px(l0, *a, *b, *c);
                let mi = spk(i, l0);
                *mo = mi;
                l1 = px(l1, mp, mi, *u);
                *oo = l1 as u8;
                mp = mi;
            }
            // the second step's last pixel reads the first's right edge, 0
            o[n - 1] = px(l1, mp, 0, u1[n - 1]) as u8;
        }
        (Kernel::Buffered, sparkle) => {
            crate::burn_row_buffered(mid, old, below[0], e, d.fade);
            if let (Some(sp), Some(p)) = (sparkle, mid.get_mut(spark[0])) {
                *p = sparkled(*p, sp, d.heat);
            }
            crate::burn_row_buffered(new, mid, below[1], e, d.fade);
        }
    }
    // the second step's sparkle comes after its whole step, so no pixel's `left` saw it
    if let (Some(sp), Some(p)) = (d.sparkle, new.get_mut(spark[1])) {
        *p = sparkled(*p, sp, d.heat);
    }
}
