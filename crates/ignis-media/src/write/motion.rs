//! Motion vectors for flipbooks: where they come from ([`MotionSource`]), how a sheet
//! stores them (RG, 16 bits, 32768 = no motion) and the engines' frame blend that uses them
//! ([`mv_blend`]), ported from the reference shaders in `engines/`.
//!
//! Convention (Unity VFX Graph's "Flipbook Motion Blend", which Unreal's and SideFX's
//! material functions share): the cell of frame `k` holds the motion of frame `k` per
//! frame, `F_k(x)` (content at `x` moves to about `x + F_k(x)` by the next frame; Ignis
//! writes the velocity, see [`MotionSource`]), in tile-UV units (a fraction of
//! one cell's width and height: the UV range an engine maps onto one sub-image). Between frames `k` and `k+1` at blend `t ∈ [0, 1)`:
//!
//! ```text
//! prev = frame_k    (uv - F_k(uv)     * t)
//! next = frame_k+1  (uv + F_k+1(uv)   * (1 - t))
//! out  = lerp(prev, next, t)
//! ```
//!
//! Stored: `rg = 0.5 + F / (2 * scale)`, so `F = (rg * 2 - 1) * scale`, with `scale` (the
//! material's "motion vector strength") written in the JSON. 16-bit channels put zero
//! motion at exactly 32768 (= 128 in 8 bits, what Unreal users require of empty cells);
//! `rg * 2 - 1` then reads 1.5e-5 × scale, far below a pixel.

use std::fmt;
use std::sync::Arc;

use ignis_core::RgbaFrame;

/// Forward flow between two frames of the same size: one `[dx, dy]` per pixel of `a`
/// (row-major, pixels, +y down) with `a(x) ≈ b(x + F(x))`.
pub type FlowFn = dyn Fn(&RgbaFrame, &RgbaFrame) -> Result<Vec<[f32; 2]>, String> + Send + Sync;

/// Both flows of a pair, `(a→b, b→a)`, each as a [`FlowFn`] gives it.
pub type FlowPairFn =
    dyn Fn(&RgbaFrame, &RgbaFrame) -> Result<(Vec<[f32; 2]>, Vec<[f32; 2]>), String> + Send + Sync;

/// Where a flipbook's motion vectors come from: a dense optical flow (the CLI passes
/// `ignis_flow`), or a generator that knows its own motion and gives each loop's
/// velocities itself ([`MotionSource::velocities`]). Compared by identity.
///
/// From a flow, the writer stores each frame's **velocity**: the mean of its forward motion
/// (to the next frame) and its reversed backward motion (from the previous frame), because
/// an engine reads a frame's one vector both when the frame is `prev` of a blend (sampled
/// at `−mv·t`) and when it is `next` (sampled at `+mv·(1−t)`).
#[derive(Clone)]
pub struct MotionSource(pub(crate) Source);

/// Gives the velocities of one loop of a sheet (one row with variants): called with the
/// row index and the row's frames as written, returns one velocity field per frame.
pub type VelocityFn =
    dyn Fn(usize, &[RgbaFrame]) -> Result<Vec<Vec<[f32; 2]>>, String> + Send + Sync;

#[derive(Clone)]
pub(crate) enum Source {
    /// Both flows of each pair of consecutive frames.
    Flow(Arc<FlowPairFn>),
    /// Each loop's velocities from the generator, and what they are (the JSON's
    /// `motion_vectors.source` and `direction`).
    Velocities {
        f: Arc<VelocityFn>,
        source: String,
        direction: String,
    },
}

impl MotionSource {
    /// Wraps a one-direction flow function (called twice per pair of frames).
    pub fn new(
        f: impl Fn(&RgbaFrame, &RgbaFrame) -> Result<Vec<[f32; 2]>, String> + Send + Sync + 'static,
    ) -> MotionSource {
        MotionSource(Source::Flow(Arc::new(move |a, b| Ok((f(a, b)?, f(b, a)?)))))
    }

    /// Wraps a function giving both directions of a pair at once (cheaper when the two
    /// share work, e.g. a forward–backward consistency check).
    pub fn pair(
        f: impl Fn(&RgbaFrame, &RgbaFrame) -> Result<(Vec<[f32; 2]>, Vec<[f32; 2]>), String>
            + Send
            + Sync
            + 'static,
    ) -> MotionSource {
        MotionSource(Source::Flow(Arc::new(f)))
    }

    /// Velocities the generator gives per loop ([`VelocityFn`], in pixels per frame, +y
    /// down), described in the JSON by `source` (where they come from) and `direction`
    /// (what each frame's vector is). The writer checks their count and size.
    pub fn velocities(
        f: impl Fn(usize, &[RgbaFrame]) -> Result<Vec<Vec<[f32; 2]>>, String> + Send + Sync + 'static,
        source: impl Into<String>,
        direction: impl Into<String>,
    ) -> MotionSource {
        MotionSource(Source::Velocities {
            f: Arc::new(f),
            source: source.into(),
            direction: direction.into(),
        })
    }

    /// `Some((source, direction))` for velocities from the generator, `None` for a flow.
    pub fn description(&self) -> Option<(&str, &str)> {
        match &self.0 {
            Source::Flow(_) => None,
            Source::Velocities {
                source, direction, ..
            } => Some((source, direction)),
        }
    }
}

impl fmt::Debug for MotionSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.description() {
            None => f.write_str("MotionSource(flow)"),
            Some((s, _)) => write!(f, "MotionSource({s})"),
        }
    }
}

impl PartialEq for MotionSource {
    fn eq(&self, other: &Self) -> bool {
        match (&self.0, &other.0) {
            (Source::Flow(a), Source::Flow(b)) => Arc::ptr_eq(a, b),
            (Source::Velocities { f: a, .. }, Source::Velocities { f: b, .. }) => Arc::ptr_eq(a, b),
            _ => false,
        }
    }
}

/// The 16-bit code of zero motion.
pub const MV_NEUTRAL: u16 = 32768;

/// A frame's velocity: the mean of its flow to the next frame (`ahead`) and its reversed
/// flow to the previous frame (`behind` is the pair (previous, frame)'s backward flow, frame
/// → previous), one side at the ends of a one-shot; `None` without either.
pub fn frame_velocity(
    ahead: Option<&[[f32; 2]]>,
    behind: Option<&[[f32; 2]]>,
) -> Option<Vec<[f32; 2]>> {
    match (ahead, behind) {
        (Some(f), Some(b)) => Some(
            f.iter()
                .zip(b)
                .map(|(f, b)| [0.5 * (f[0] - b[0]), 0.5 * (f[1] - b[1])])
                .collect(),
        ),
        (Some(f), None) => Some(f.to_vec()),
        (None, Some(b)) => Some(b.iter().map(|b| [-b[0], -b[1]]).collect()),
        (None, None) => None,
    }
}

/// Encodes one motion component `m` (tile-UV units) at strength `scale` as 16 bits:
/// `32768 + round(m / scale * 32767)`, clamped to `[1, 65535]` (symmetric around zero).
pub fn encode_mv16(m: f32, scale: f32) -> u16 {
    let q = (m / scale * 32767.0).round().clamp(-32767.0, 32767.0);
    (MV_NEUTRAL as f32 + q) as u16
}

/// Inverse of [`encode_mv16`] (exact for 32768 → 0).
pub fn decode_mv16(v: u16, scale: f32) -> f32 {
    (v as f32 - MV_NEUTRAL as f32) / 32767.0 * scale
}

/// The smallest "nice" strength (1, 2 or 5 × a power of ten, times 1.25 steps) at least
/// `max_abs`, so the largest vector uses most of the 16-bit range; 1e-3 at least.
pub fn mv_scale_for(max_abs: f32) -> f32 {
    let m = max_abs.max(1e-3) as f64;
    let e = m.log10().floor();
    let base = 10f64.powf(e);
    for step in [1.0, 1.25, 1.6, 2.0, 2.5, 3.2, 4.0, 5.0, 6.4, 8.0, 10.0] {
        if base * step >= m {
            return (base * step) as f32;
        }
    }
    (base * 10.0) as f32
}

/// Bilinear sample of a frame at pixel-centre coordinates `(x, y)` (pixel `i` covers
/// `[i, i+1)`, its centre at `i + 0.5`), clamping to the edge (what an extruded padding
/// gives a texture sampler near a cell's border).
#[inline]
pub fn sample_bilinear(frame: &RgbaFrame, x: f32, y: f32) -> [f32; 4] {
    let (w, h) = (frame.width() as i64, frame.height() as i64);
    let fx = x - 0.5;
    let fy = y - 0.5;
    // floor without a libm call (the same value for every finite coordinate)
    let floor = |v: f32| {
        let i = v as i64;
        if i as f32 > v {
            i - 1
        } else {
            i
        }
    };
    let (x0, y0) = (floor(fx), floor(fy));
    let (ax, ay) = (fx - x0 as f32, fy - y0 as f32);
    let cx = |v: i64| v.clamp(0, w - 1) as usize;
    let cy = |v: i64| v.clamp(0, h - 1) as usize;
    let d = frame.data();
    let wu = w as usize;
    let p00 = d[cy(y0) * wu + cx(x0)];
    let p10 = d[cy(y0) * wu + cx(x0 + 1)];
    let p01 = d[cy(y0 + 1) * wu + cx(x0)];
    let p11 = d[cy(y0 + 1) * wu + cx(x0 + 1)];
    let mut out = [0.0; 4];
    for c in 0..4 {
        let top = p00[c] + (p10[c] - p00[c]) * ax;
        let bot = p01[c] + (p11[c] - p01[c]) * ax;
        out[c] = top + (bot - top) * ay;
    }
    out
}

/// The engines' motion-vector frame blend (see the module docs), in pixels: `mv_prev` and
/// `mv_next` are the stored motion of `prev` and `next` (per frame, one `[dx, dy]` per
/// pixel, +y down; Ignis stores each frame's velocity), `t` the blend (0 = `prev`,
/// 1 = `next`). The same formula as `engines/*`.
pub fn mv_blend(
    prev: &RgbaFrame,
    next: &RgbaFrame,
    mv_prev: &[[f32; 2]],
    mv_next: &[[f32; 2]],
    t: f32,
) -> RgbaFrame {
    let size = prev.size();
    assert_eq!(next.size(), size, "mv_blend: frames of different sizes");
    assert_eq!(mv_prev.len(), size.pixels(), "mv_blend: mv_prev size");
    assert_eq!(mv_next.len(), size.pixels(), "mv_blend: mv_next size");
    let w = size.width as usize;
    let mut out = RgbaFrame::new(size);
    for (i, o) in out.data_mut().iter_mut().enumerate() {
        let (x, y) = ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
        let [pu, pv] = mv_prev[i];
        let [nu, nv] = mv_next[i];
        let a = sample_bilinear(prev, x - pu * t, y - pv * t);
        let b = sample_bilinear(next, x + nu * (1.0 - t), y + nv * (1.0 - t));
        for c in 0..4 {
            o[c] = a[c] + (b[c] - a[c]) * t;
        }
    }
    out
}

/// A plain cross-fade of two frames, the blend engines do without motion vectors.
pub fn linear_blend(prev: &RgbaFrame, next: &RgbaFrame, t: f32) -> RgbaFrame {
    let mut out = prev.clone();
    for (o, b) in out.data_mut().iter_mut().zip(next.data()) {
        for c in 0..4 {
            o[c] += (b[c] - o[c]) * t;
        }
    }
    out
}

/// One motion vector per pixel, `[dx, dy]` in pixels (+y down), row-major.
pub type Field = Vec<[f32; 2]>;

/// Per pixel of each key frame, one of its vectors from `pairs` (per key interval, the
/// forward motion from the earlier key frame's pixels and the backward motion from the
/// later one's): none, the forward motion, the reversed backward motion or their mean
/// (the central velocity), chosen so that the blends at 0.5 ([`mv_blend`]) of the whole
/// run of key frames err least against the true in-between frames `mids` (one per
/// interval), in 8-bit sRGB levels of the colour premultiplied by alpha. Exact, by dynamic
/// programming along the key frames, pixel by pixel: each blend's error at a pixel depends
/// only on its two key frames' vectors there. One vector per key frame, so a sheet can
/// store it: what a generator that can render its in-between frames gives a flipbook.
///
/// `pairs.len()` (= `mids.len()`) is `keys.len() − 1` for a one-shot, or `keys.len()` for
/// a loop (the last interval joins the last key frame to the first; the chain is then a
/// cycle, solved exactly for each choice at the first key frame). Never worse than no
/// motion on the blends it was chosen on. Panics if the counts or sizes disagree.
pub fn chosen_velocities(
    keys: &[RgbaFrame],
    mids: &[&RgbaFrame],
    pairs: &[(Field, Field)],
) -> Vec<Field> {
    use rayon::prelude::*;
    let n = keys.len();
    assert!(n >= 2, "chosen_velocities: at least two key frames");
    assert!(
        pairs.len() == mids.len() && (pairs.len() == n || pairs.len() + 1 == n),
        "chosen_velocities: {} key frames, {} pairs, {} in-between frames",
        n,
        pairs.len(),
        mids.len()
    );
    let size = keys[0].size();
    assert!(
        keys.iter().all(|k| k.size() == size) && mids.iter().all(|m| m.size() == size),
        "chosen_velocities: frames of different sizes"
    );
    let candidates = chain_candidates(pairs, n);
    let blank: Vec<Vec<bool>> = keys
        .par_iter()
        .zip(&candidates)
        .map(|(k, c)| blank_reach(k, c))
        .collect();
    let w = size.width as usize;
    let intervals = mids.len();
    // Pixels in runs of `RUN`, each run interval by interval (the frames' and vectors'
    // rows stay in cache), then each pixel's chain: the same costs and choices as pixel
    // by pixel.
    const RUN: usize = 256;
    // (each thread's cost buffer is reused from run to run: a fresh one per run costs
    // as much in page faults as the runs' bookkeeping)
    let picks: Vec<u8> = (0..size.pixels().div_ceil(RUN))
        .into_par_iter()
        .map_init(Vec::new, |costs, r| {
            let (lo, hi) = (r * RUN, ((r + 1) * RUN).min(size.pixels()));
            costs.clear();
            costs.resize((hi - lo) * intervals, [[0f32; 4]; 4]);
            for k in 0..intervals {
                for i in lo..hi {
                    let xy = ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
                    let j = (k + 1) % n;
                    // every sample either blend reads is blank and so is the truth: every
                    // pair errs 0 (what `interval_cost` gives there, without its samples)
                    costs[(i - lo) * intervals + k] =
                        if blank[k][i] && blank[j][i] && dark(&mids[k].data()[i]) {
                            [[0.0; 4]; 4]
                        } else {
                            interval_cost(keys, mids, &candidates, k, i, xy)
                        };
                }
            }
            let mut picks = Vec::with_capacity((hi - lo) * n);
            for c in costs.chunks(intervals) {
                picks.extend_from_slice(&best_chain(c, n));
            }
            picks
        })
        .flatten_iter()
        .collect();
    (0..n)
        .into_par_iter()
        .map(|k| {
            let c = &candidates[k];
            picks
                .chunks(n)
                .enumerate()
                .map(|(i, p)| c[p[k] as usize][i])
                .collect()
        })
        .collect()
}

/// Per pixel of `frame`: whether every pixel a bilinear sample at any of the `candidates`'
/// half-vectors from it reads (`|½v| + 1` around it, clamped to the frame) has no colour,
/// or every one has no alpha, so that every such sample is exactly dark (its colour or its
/// alpha interpolates zeros). All `false` when a vector is not finite.
fn blank_reach(frame: &RgbaFrame, candidates: &[Field; 4]) -> Vec<bool> {
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    let reach = candidates.iter().flatten().try_fold(0f32, |m, v| {
        (v[0].is_finite() && v[1].is_finite()).then(|| m.max(v[0].abs()).max(v[1].abs()))
    });
    let Some(reach) = reach else {
        return vec![false; w * h];
    };
    let r = (0.5 * reach).ceil() as usize + 1;
    // summed-area tables of the pixels with colour and with alpha
    let table = |lit: &dyn Fn(&[f32; 4]) -> bool| {
        let mut t = vec![0u32; (w + 1) * (h + 1)];
        for y in 0..h {
            let mut row = 0u32;
            for x in 0..w {
                row += u32::from(lit(&frame.data()[y * w + x]));
                t[(y + 1) * (w + 1) + x + 1] = t[y * (w + 1) + x + 1] + row;
            }
        }
        t
    };
    let colour = table(&|p| p[0] != 0.0 || p[1] != 0.0 || p[2] != 0.0);
    let alpha = table(&|p| p[3] != 0.0);
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let (x0, x1) = (x.saturating_sub(r), (x + r).min(w - 1) + 1);
            let (y0, y1) = (y.saturating_sub(r), (y + r).min(h - 1) + 1);
            let sum = |t: &[u32]| {
                t[y1 * (w + 1) + x1] + t[y0 * (w + 1) + x0]
                    - t[y0 * (w + 1) + x1]
                    - t[y1 * (w + 1) + x0]
            };
            sum(&colour) == 0 || sum(&alpha) == 0
        })
        .collect()
}

/// The vectors [`chosen_velocities`] chooses from for each of `n` key frames: none, the
/// forward motion, the reversed backward motion, the central velocity (one-sided motion
/// in place of a missing side at the ends of a one-shot).
fn chain_candidates(pairs: &[(Field, Field)], n: usize) -> Vec<[Field; 4]> {
    use rayon::prelude::*;
    let looped = pairs.len() == n;
    (0..n)
        .into_par_iter()
        .map(|k| {
            let ahead = (k < pairs.len()).then(|| pairs[k].0.clone());
            let behind = (k > 0 || looped).then(|| pairs[(k + n - 1) % n].1.clone());
            let central = frame_velocity(ahead.as_deref(), behind.as_deref())
                .expect("at least two key frames");
            let reversed = behind.map(|b| b.iter().map(|v| [-v[0], -v[1]]).collect());
            let zero = vec![[0.0; 2]; central.len()];
            // ties (a dark pixel) go to the first: no motion
            [
                zero,
                ahead.unwrap_or_else(|| central.clone()),
                reversed.unwrap_or_else(|| central.clone()),
                central,
            ]
        })
        .collect()
}

/// At pixel `i` (centre `(x, y)`), for key interval `k`, the error of its blend at 0.5
/// against `mids[k]` for each pair of candidates `[a][b]` (`a` of the earlier key frame,
/// `b` of the later). With AVX2 where the CPU has it ([`interval_cost_avx2`]), the same
/// operations in the same order otherwise ([`interval_cost_scalar`]): both give the same
/// bits (test `interval_costs_match_the_scalar_ones_bit_for_bit`).
fn interval_cost(
    keys: &[RgbaFrame],
    mids: &[&RgbaFrame],
    candidates: &[[Field; 4]],
    k: usize,
    i: usize,
    xy: (f32, f32),
) -> [[f32; 4]; 4] {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: AVX2 is present (checked above).
        return unsafe { interval_cost_avx2(keys, mids, candidates, k, i, xy) };
    }
    interval_cost_scalar(keys, mids, candidates, k, i, xy)
}

/// [`interval_cost`], one sample and one pair at a time.
fn interval_cost_scalar(
    keys: &[RgbaFrame],
    mids: &[&RgbaFrame],
    candidates: &[[Field; 4]],
    k: usize,
    i: usize,
    (x, y): (f32, f32),
) -> [[f32; 4]; 4] {
    let lut = srgb255_table();
    let enc = |p: [f32; 4]| levels_of(lut, p);
    let j = (k + 1) % keys.len();
    let want = enc(mids[k].data()[i]);
    let prev = candidates[k]
        .each_ref()
        .map(|c| sample_bilinear(&keys[k], x - 0.5 * c[i][0], y - 0.5 * c[i][1]));
    let next = candidates[j]
        .each_ref()
        .map(|c| sample_bilinear(&keys[j], x + 0.5 * c[i][0], y + 0.5 * c[i][1]));
    // dark everywhere the blend looks (most of a fire's frame): every pair errs 0
    if want == [0.0; 3] && prev.iter().chain(&next).all(dark) {
        return [[0.0; 4]; 4];
    }
    prev.map(|p| {
        next.map(|q| {
            let got = enc([0, 1, 2, 3].map(|c| 0.5 * (p[c] + q[c])));
            (0..3).map(|c| (got[c] - want[c]).abs()).sum::<f32>()
        })
    })
}

/// [`interval_cost`] with AVX2: the eight bilinear samples' coordinates, corners and
/// weights eight at a time ([`samples_avx2`]), then the 16 pairs eight at a time
/// ([`pair_costs_avx2`]).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn interval_cost_avx2(
    keys: &[RgbaFrame],
    mids: &[&RgbaFrame],
    candidates: &[[Field; 4]],
    k: usize,
    i: usize,
    (x, y): (f32, f32),
) -> [[f32; 4]; 4] {
    let lut = srgb255_table();
    let j = (k + 1) % keys.len();
    let want = levels_of(lut, mids[k].data()[i]);
    // the scalar coordinates: x − 0.5·v for the earlier frame, x + 0.5·v for the later
    let at: [[f32; 2]; 8] = std::array::from_fn(|s| {
        if s < 4 {
            let v = candidates[k][s][i];
            [x - 0.5 * v[0], y - 0.5 * v[1]]
        } else {
            let v = candidates[j][s - 4][i];
            [x + 0.5 * v[0], y + 0.5 * v[1]]
        }
    });
    // far outside the frame (or not finite), where lanes of 32-bit indices would not
    // clamp as the scalar does: the scalar
    if at.iter().flatten().any(|c| !(c.abs() < 1.0e6)) {
        return interval_cost_scalar(keys, mids, candidates, k, i, (x, y));
    }
    let got = samples_avx2(&keys[k], &keys[j], &at);
    let prev: [[f32; 4]; 4] = std::array::from_fn(|a| got[a]);
    let next: [[f32; 4]; 4] = std::array::from_fn(|b| got[4 + b]);
    if want == [0.0; 3] && got.iter().all(dark) {
        return [[0.0; 4]; 4];
    }
    pair_costs_avx2(&prev, &next, want, lut)
}

/// [`sample_bilinear`] at the eight points `at`, the first four of `a`, the others of
/// `b` (frames of one size): floor, weights and clamped corners in eight lanes, each
/// sample's four corners blended as one 4-channel vector, in the scalar's order.
///
/// # Safety
/// The CPU must support AVX2; coordinates must be finite and within ±10⁶ (so floors and
/// corners fit 32-bit lanes exactly).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn samples_avx2(a: &RgbaFrame, b: &RgbaFrame, at: &[[f32; 2]; 8]) -> [[f32; 4]; 8] {
    use std::arch::x86_64::*;
    let (w, h) = (a.width() as i32, a.height() as i32);
    let half = _mm256_set1_ps(0.5);
    let fx = _mm256_sub_ps(
        _mm256_setr_ps(
            at[0][0], at[1][0], at[2][0], at[3][0], at[4][0], at[5][0], at[6][0], at[7][0],
        ),
        half,
    );
    let fy = _mm256_sub_ps(
        _mm256_setr_ps(
            at[0][1], at[1][1], at[2][1], at[3][1], at[4][1], at[5][1], at[6][1], at[7][1],
        ),
        half,
    );
    let (x0f, y0f) = (_mm256_floor_ps(fx), _mm256_floor_ps(fy));
    let (ax, ay) = (_mm256_sub_ps(fx, x0f), _mm256_sub_ps(fy, y0f));
    let (x0, y0) = (_mm256_cvttps_epi32(x0f), _mm256_cvttps_epi32(y0f));
    let one = _mm256_set1_epi32(1);
    let clamp = |v: __m256i, hi: i32| {
        _mm256_max_epi32(
            _mm256_min_epi32(v, _mm256_set1_epi32(hi - 1)),
            _mm256_setzero_si256(),
        )
    };
    let (cx0, cx1) = (clamp(x0, w), clamp(_mm256_add_epi32(x0, one), w));
    let wv = _mm256_set1_epi32(w);
    let (ry0, ry1) = (
        _mm256_mullo_epi32(clamp(y0, h), wv),
        _mm256_mullo_epi32(clamp(_mm256_add_epi32(y0, one), h), wv),
    );
    let mut idx = [[0i32; 8]; 4];
    for (o, v) in idx.iter_mut().zip([
        _mm256_add_epi32(ry0, cx0),
        _mm256_add_epi32(ry0, cx1),
        _mm256_add_epi32(ry1, cx0),
        _mm256_add_epi32(ry1, cx1),
    ]) {
        _mm256_storeu_si256(o.as_mut_ptr().cast(), v);
    }
    let (mut wx, mut wy) = ([0f32; 8], [0f32; 8]);
    _mm256_storeu_ps(wx.as_mut_ptr(), ax);
    _mm256_storeu_ps(wy.as_mut_ptr(), ay);
    let mut out = [[0f32; 4]; 8];
    for s in 0..8 {
        let d = if s < 4 { a.data() } else { b.data() };
        // SAFETY: the corners are clamped to the frame, so every index is in `d`
        let load = |n: usize| _mm_loadu_ps(d.get_unchecked(idx[n][s] as usize).as_ptr());
        let (p00, p10, p01, p11) = (load(0), load(1), load(2), load(3));
        let (sx, sy) = (_mm_set1_ps(wx[s]), _mm_set1_ps(wy[s]));
        let top = _mm_add_ps(p00, _mm_mul_ps(_mm_sub_ps(p10, p00), sx));
        let bot = _mm_add_ps(p01, _mm_mul_ps(_mm_sub_ps(p11, p01), sx));
        _mm_storeu_ps(
            out[s].as_mut_ptr(),
            _mm_add_ps(top, _mm_mul_ps(_mm_sub_ps(bot, top), sy)),
        );
    }
    out
}

/// The error of each pair's blend at 0.5 (`prev[a]` with `next[b]`) against `want` (8-bit
/// sRGB levels of the premultiplied colour, summed over the channels), as
/// [`interval_cost_scalar`] computes it: pairs `(a, b)` in lanes `4a + b`, eight at a time,
/// each step the scalar one's (no fused multiply-add), the table read by gathers.
///
/// # Safety
/// The CPU must support AVX2; `lut` must have at least 2 entries and fewer than 2³¹.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn pair_costs_avx2(
    prev: &[[f32; 4]; 4],
    next: &[[f32; 4]; 4],
    want: [f32; 3],
    lut: &[f32],
) -> [[f32; 4]; 4] {
    use std::arch::x86_64::*;
    let steps = lut.len() - 1;
    let mut out = [[0f32; 4]; 4];
    let half = _mm256_set1_ps(0.5);
    let (zero, one) = (_mm256_setzero_ps(), _mm256_set1_ps(1.0));
    let steps_f = _mm256_set1_ps(steps as f32);
    let last = _mm256_set1_epi32(steps as i32 - 1);
    let levels = _mm256_set1_ps(255.0);
    let sign = _mm256_set1_ps(-0.0);
    for h in 0..2 {
        let (a0, a1) = (2 * h, 2 * h + 1);
        let p = |c: usize| {
            let (u, v) = (prev[a0][c], prev[a1][c]);
            _mm256_setr_ps(u, u, u, u, v, v, v, v)
        };
        let q = |c: usize| {
            let n = [next[0][c], next[1][c], next[2][c], next[3][c]];
            _mm256_setr_ps(n[0], n[1], n[2], n[3], n[0], n[1], n[2], n[3])
        };
        let alpha = _mm256_mul_ps(half, _mm256_add_ps(p(3), q(3)));
        let mut sum = zero;
        for (c, &w) in want.iter().enumerate() {
            let got = _mm256_mul_ps(half, _mm256_add_ps(p(c), q(c)));
            let pm = _mm256_mul_ps(got, alpha);
            // srgb255: clamp, scale, index, interpolate, levels
            let x = _mm256_mul_ps(_mm256_min_ps(_mm256_max_ps(pm, zero), one), steps_f);
            let i = _mm256_min_epi32(_mm256_cvttps_epi32(x), last);
            let f = _mm256_sub_ps(x, _mm256_cvtepi32_ps(i));
            // SAFETY: every index is in 0..steps, so i and i + 1 are inside `lut`
            let t0 = _mm256_i32gather_ps::<4>(lut.as_ptr(), i);
            let t1 = _mm256_i32gather_ps::<4>(lut.as_ptr().add(1), i);
            let e = _mm256_mul_ps(
                _mm256_add_ps(t0, _mm256_mul_ps(_mm256_sub_ps(t1, t0), f)),
                levels,
            );
            let d = _mm256_andnot_ps(sign, _mm256_sub_ps(e, _mm256_set1_ps(w)));
            // the scalar sum starts from zero: 0 + d0 is d0 (d0 ≥ 0), then + d1, + d2
            sum = if c == 0 { d } else { _mm256_add_ps(sum, d) };
        }
        let mut lanes = [0f32; 8];
        _mm256_storeu_ps(lanes.as_mut_ptr(), sum);
        out[a0].copy_from_slice(&lanes[..4]);
        out[a1].copy_from_slice(&lanes[4..]);
    }
    out
}

/// Whether a straight-alpha pixel's premultiplied colour is black (what the choice's
/// error measure encodes as 0 in every channel).
fn dark(p: &[f32; 4]) -> bool {
    (0..3).all(|c| p[c] * p[3] <= 0.0)
}

/// The sRGB encoding tabled for the blends' error measure ([`chosen_velocities`] evaluates
/// it 16 times per pixel and interval): `ignis_core::loopq`'s table, `linear_to_srgb` at
/// `i / (len − 1)`.
fn srgb255_table() -> &'static [f32] {
    ignis_core::loopq::srgb_encode_table()
}

/// The 8-bit sRGB levels (unrounded) of a straight-alpha pixel's premultiplied colour:
/// what the choice's errors compare.
fn levels_of(table: &[f32], p: [f32; 4]) -> [f32; 3] {
    [0, 1, 2].map(|c| srgb255(table, p[c] * p[3]))
}

/// 8-bit sRGB level (unrounded) of linear `c` (clamped to `[0, 1]`), linear between the
/// table's entries (within 0.01 levels of the exact curve).
fn srgb255(table: &[f32], c: f32) -> f32 {
    let steps = table.len() - 1;
    let x = c.clamp(0.0, 1.0) * steps as f32;
    let i = (x as usize).min(steps - 1);
    let f = x - i as f32;
    (table[i] + (table[i + 1] - table[i]) * f) * 255.0
}

/// The candidate index per key frame (of `n`) whose chain of interval `costs` is least:
/// along a path for a one-shot (`costs.len() = n − 1`), around the cycle for a loop
/// (`costs.len() = n`: the best chain for each fixed first choice, then the best of those).
fn best_chain(costs: &[[[f32; 4]; 4]], n: usize) -> Vec<u8> {
    if costs.len() + 1 == n {
        return path_chain(costs, n);
    }
    // a loop: the chains from each first choice `s` side by side, each as `path_chain`
    // from `cost[s] = 0` (the others infinite) and closing in `s`
    let mut cost = [[f32::INFINITY; 4]; 4];
    for (s, c) in cost.iter_mut().enumerate() {
        c[s] = 0.0;
    }
    let mut back: Vec<[[u8; 4]; 4]> = Vec::with_capacity(costs.len());
    for c in costs {
        let mut to = [[f32::INFINITY; 4]; 4];
        let mut from = [[0u8; 4]; 4];
        // for each (s, b) the candidates a in order, the first least kept (the sixteen
        // (s, b) side by side)
        for (a, row) in c.iter().enumerate() {
            for s in 0..4 {
                for b in 0..4 {
                    let e = cost[s][a] + row[b];
                    if e < to[s][b] {
                        (to[s][b], from[s][b]) = (e, a as u8);
                    }
                }
            }
        }
        cost = to;
        back.push(from);
    }
    // the least total, the first of equals
    let s = (0..4)
        .min_by(|&a, &b| cost[a][a].total_cmp(&cost[b][b]))
        .expect("four starts");
    let mut pick = vec![0u8; n];
    let mut at = s as u8;
    for k in (0..costs.len()).rev() {
        at = back[k][s][at as usize];
        pick[k] = at;
    }
    pick
}

/// Dynamic programming along a one-shot's `costs` (`n − 1` intervals): the choices with
/// the least total, ties to the first candidate.
fn path_chain(costs: &[[[f32; 4]; 4]], n: usize) -> Vec<u8> {
    let mut cost = [0f32; 4];
    // the step back from each candidate of each key frame after the first
    let mut back: Vec<[u8; 4]> = Vec::with_capacity(costs.len());
    for c in costs {
        let mut to = [f32::INFINITY; 4];
        let mut from = [0u8; 4];
        // for each b the candidates a in order, the first least kept (the four b side
        // by side)
        for (a, row) in c.iter().enumerate() {
            for b in 0..4 {
                let e = cost[a] + row[b];
                if e < to[b] {
                    (to[b], from[b]) = (e, a as u8);
                }
            }
        }
        cost = to;
        back.push(from);
    }
    let last = (0..4)
        .min_by(|&a, &b| cost[a].total_cmp(&cost[b]))
        .unwrap_or(0) as u8;
    // back[k] leads from key frame k + 1 to key frame k
    let mut pick = vec![0u8; n];
    let mut at = last;
    for k in (0..costs.len()).rev() {
        at = back[k][at as usize];
        pick[k] = at;
    }
    pick[n - 1] = last;
    pick
}

#[cfg(test)]
mod tests {
    use super::*;
    use ignis_core::Size;

    #[test]
    fn mv16_roundtrip_and_neutral() {
        assert_eq!(encode_mv16(0.0, 0.05), MV_NEUTRAL);
        assert_eq!(decode_mv16(MV_NEUTRAL, 0.05), 0.0);
        assert_eq!(MV_NEUTRAL >> 8, 128);
        for m in [-0.05f32, -0.0123, 0.0004, 0.049] {
            let back = decode_mv16(encode_mv16(m, 0.05), 0.05);
            assert!((back - m).abs() < 0.05 / 32767.0, "{m} → {back}");
        }
        assert_eq!(encode_mv16(1.0, 0.05), 65535);
        assert_eq!(encode_mv16(-1.0, 0.05), 1);
    }

    #[test]
    fn scale_is_nice_and_covers() {
        for m in [0.0001f32, 0.013, 0.05, 0.051, 0.3, 2.0] {
            let s = mv_scale_for(m);
            assert!(s >= m && s <= m.max(1e-3) * 1.3, "{m} → {s}");
        }
    }

    /// A blob translated by (3, -2) px per frame: the blend at t = 0.5 puts it half-way,
    /// where a cross-fade shows two half-bright copies.
    #[test]
    fn blend_moves_content_half_way() {
        let size = Size::new(32, 32).unwrap();
        let blob = |cx: f32, cy: f32| {
            let px = (0..size.pixels())
                .map(|i| {
                    let (x, y) = ((i % 32) as f32 + 0.5, (i / 32) as f32 + 0.5);
                    let v = (-((x - cx).powi(2) + (y - cy).powi(2)) / 8.0).exp();
                    [v, v, v, 1.0]
                })
                .collect();
            RgbaFrame::from_vec(size, px).unwrap()
        };
        let a = blob(12.0, 16.0);
        let b = blob(15.0, 14.0);
        let truth = blob(13.5, 15.0);
        let mv = vec![[3.0f32, -2.0]; size.pixels()];
        let m = mv_blend(&a, &b, &mv, &mv, 0.5);
        let l = linear_blend(&a, &b, 0.5);
        let err = |f: &RgbaFrame| {
            f.data()
                .iter()
                .zip(truth.data())
                .map(|(p, q)| (p[0] - q[0]).abs())
                .sum::<f32>()
        };
        assert!(err(&m) < 0.1 * err(&l), "{} vs {}", err(&m), err(&l));
        // t = 0 and t = 1 reproduce the key frames exactly.
        let maxdiff = |p: &RgbaFrame, q: &RgbaFrame| {
            p.data()
                .iter()
                .zip(q.data())
                .map(|(x, y)| (x[0] - y[0]).abs())
                .fold(0f32, f32::max)
        };
        assert!(maxdiff(&mv_blend(&a, &b, &mv, &mv, 0.0), &a) < 1e-6);
        assert!(maxdiff(&mv_blend(&a, &b, &mv, &mv, 1.0), &b) < 1e-6);
    }

    /// A smooth texture shifted `dx` px right.
    fn texture(size: Size, dx: f32) -> RgbaFrame {
        let w = size.width as usize;
        let px = (0..size.pixels())
            .map(|i| {
                let (x, y) = ((i % w) as f32 + 0.5 - dx, (i / w) as f32 + 0.5);
                let v = 0.5
                    + 0.25 * (x * 0.45).sin() * (y * 0.3).cos()
                    + 0.2 * (x * 0.13 + y * 0.21).sin();
                [v, 0.8 * v, 0.5 * v, 1.0]
            })
            .collect();
        RgbaFrame::from_vec(size, px).unwrap()
    }

    /// Total error of the blends at 0.5 of consecutive key frames (the last interval
    /// wrapping to the first when there are as many `mids` as keys), in the measure
    /// [`chosen_velocities`] minimises (8-bit sRGB levels of premultiplied colour).
    fn chain_error(keys: &[RgbaFrame], mids: &[&RgbaFrame], mv: &[Field]) -> f64 {
        let lut = srgb255_table();
        let enc = |p: &[f32; 4], c: usize| srgb255(lut, p[c] * p[3]) as f64;
        let n = keys.len();
        (0..mids.len())
            .map(|k| {
                let j = (k + 1) % n;
                let m = mv_blend(&keys[k], &keys[j], &mv[k], &mv[j], 0.5);
                m.data()
                    .iter()
                    .zip(mids[k].data())
                    .map(|(p, q)| (0..3).map(|c| (enc(p, c) - enc(q, c)).abs()).sum::<f64>())
                    .sum::<f64>()
            })
            .sum()
    }

    /// A texture sliding right then back (the middle key frame's motion reverses), as a
    /// one-shot and as a loop: the chosen vectors, one per key frame, err no more than no
    /// motion or any single candidate used on every key frame (the chain is exact), and
    /// on a steady slide they are close to the motion.
    #[test]
    fn chosen_vectors_are_the_best_chain() {
        let size = Size::new(40, 32).unwrap();
        let field = |v: f32| vec![[v, 0.0]; size.pixels()];
        // steady: +1.5 px per frame, key frames every other frame
        let frames: Vec<RgbaFrame> = (0..5).map(|i| texture(size, 1.5 * i as f32)).collect();
        let keys: Vec<RgbaFrame> = frames.iter().step_by(2).cloned().collect();
        let mids: Vec<&RgbaFrame> = frames.iter().skip(1).step_by(2).collect();
        let pairs = vec![(field(3.0), field(-3.0)); 2];
        let chosen = chosen_velocities(&keys, &mids, &pairs);
        let e = chain_error(&keys, &mids, &chosen);
        let still = chain_error(&keys, &mids, &vec![field(0.0); 3]);
        let exact = chain_error(&keys, &mids, &vec![field(3.0); 3]);
        assert!(e <= exact + 1e-6 && e < 0.2 * still, "{e} {exact} {still}");
        // there and back, as a one-shot and as a loop (its wrap interval blends the last
        // key frame into the first)
        let frames: Vec<RgbaFrame> = [0.0, 1.5, 3.0, 1.5].map(|d| texture(size, d)).into();
        for looped in [false, true] {
            let keys = vec![frames[0].clone(), frames[2].clone()];
            let mut mids = vec![&frames[1]];
            let mut pairs = vec![(field(3.0), field(-3.0))];
            if looped {
                mids.push(&frames[3]);
                pairs.push((field(-3.0), field(3.0)));
            }
            let chosen = chosen_velocities(&keys, &mids, &pairs);
            assert_eq!(chosen.len(), 2);
            assert!(chosen.iter().all(|f| f.len() == size.pixels()));
            let e = chain_error(&keys, &mids, &chosen);
            let candidates = chain_candidates(&pairs, 2);
            for j in 0..4 {
                let same: Vec<Field> = candidates.iter().map(|c| c[j].clone()).collect();
                let e_same = chain_error(&keys, &mids, &same);
                assert!(
                    e <= e_same + 1e-6,
                    "{e} > {e_same}, candidate {j} throughout"
                );
            }
            // one vector per key frame cannot follow the reversal in both blends of the loop
            let still = chain_error(&keys, &mids, &vec![field(0.0); 2]);
            let bound = if looped { still } else { 0.5 * still };
            assert!(e < bound, "looped {looped}: {e} vs {still}");
        }
    }

    /// The DP's guarantee on unrelated frames too: never worse than no motion on the
    /// blends it was chosen on, whatever the candidate vectors (here random ones).
    #[test]
    fn chosen_vectors_never_lose_to_none() {
        let size = Size::new(24, 20).unwrap();
        let mut rng = ignis_core::Rng::new(3);
        let mut random_field = || -> Field {
            (0..size.pixels())
                .map(|_| [4.0 * rng.normal() as f32, 4.0 * rng.normal() as f32])
                .collect()
        };
        let keys: Vec<RgbaFrame> = (0..4).map(|k| texture(size, 2.3 * k as f32)).collect();
        let truth: Vec<RgbaFrame> = (0..4)
            .map(|k| texture(size, 2.3 * k as f32 + 0.9))
            .collect();
        for looped in [false, true] {
            let intervals = if looped { 4 } else { 3 };
            let mids: Vec<&RgbaFrame> = truth[..intervals].iter().collect();
            let pairs: Vec<(Field, Field)> = (0..intervals)
                .map(|_| (random_field(), random_field()))
                .collect();
            let chosen = chosen_velocities(&keys, &mids, &pairs);
            let none = vec![vec![[0.0; 2]; size.pixels()]; 4];
            let (e, e0) = (
                chain_error(&keys, &mids, &chosen),
                chain_error(&keys, &mids, &none),
            );
            assert!(e <= e0 + 1e-6, "looped {looped}: {e} > {e0}");
            assert!(e < e0, "some random vector helps somewhere");
        }
    }

    /// Where `blank_reach` says a pixel is blank, every candidate's half-vector sample
    /// from it is exactly dark (so skipping it changes no choice); it finds such pixels
    /// in frames keyed out by alpha (colour left) and by colour (alpha left), and none
    /// when a vector is not finite.
    #[test]
    fn blank_reach_marks_only_exactly_dark_samples() {
        let size = Size::new(80, 40).unwrap();
        let mut rng = ignis_core::Rng::new(5);
        for keyed_by_alpha in [true, false] {
            // a lit disc, the rest keyed out one way or the other
            let px = (0..size.pixels())
                .map(|i| {
                    let (x, y) = ((i % 80) as f32 - 20.0, (i / 80) as f32 - 20.0);
                    let inside = x * x + y * y < 20.0;
                    match (inside, keyed_by_alpha) {
                        (true, _) => [0.8, 0.5, 0.2, 1.0],
                        (false, true) => [0.9, 0.9, 0.9, 0.0],
                        (false, false) => [0.0, 0.0, 0.0, 0.7],
                    }
                })
                .collect();
            let frame = RgbaFrame::from_vec(size, px).unwrap();
            let mut field = || -> Field {
                (0..size.pixels())
                    .map(|_| {
                        // 4.6 px in a random direction: samples reach 2.3 px away
                        let a = rng.uniform(0.0, std::f64::consts::TAU) as f32;
                        [4.6 * a.cos(), 4.6 * a.sin()]
                    })
                    .collect()
            };
            let c: [Field; 4] = [field(), field(), field(), field()];
            let blank = blank_reach(&frame, &c);
            assert!(blank.iter().filter(|&&b| b).count() > size.pixels() / 4);
            for (i, _) in blank.iter().enumerate().filter(|(_, &b)| b) {
                let (x, y) = ((i % 80) as f32 + 0.5, (i / 80) as f32 + 0.5);
                for f in &c {
                    for s in [-0.5f32, 0.5] {
                        let p = sample_bilinear(&frame, x + s * f[i][0], y + s * f[i][1]);
                        assert!((0..3).all(|k| p[k] * p[3] <= 0.0), "pixel {i}: {p:?}");
                    }
                }
            }
            let mut bad = c.clone();
            bad[2][7] = [f32::NAN, 0.0];
            assert!(blank_reach(&frame, &bad).iter().all(|&b| !b));
        }
    }

    /// The AVX2 costs are the scalar ones bit for bit (what keeps the choice the same on
    /// any CPU): frames with colour, dark pixels, zero alpha and alpha between, vectors
    /// that sample inside, across the border and far outside the frame, a frame's last
    /// column and row, and coordinates past the lanes' range (the scalar's fallback).
    #[test]
    fn interval_costs_match_the_scalar_ones_bit_for_bit() {
        #[cfg(target_arch = "x86_64")]
        if !std::arch::is_x86_feature_detected!("avx2") {
            eprintln!("skipped: this CPU has no AVX2 (the scalar path is the only one)");
            return;
        }
        let size = Size::new(23, 17).unwrap();
        let mut rng = ignis_core::Rng::new(11);
        let frame = |rng: &mut ignis_core::Rng| {
            let px = (0..size.pixels())
                .map(|_| match rng.below(4) {
                    0 => [0.0, 0.0, 0.0, rng.uniform(0.0, 1.0) as f32],
                    1 => [0.7, 0.4, 0.1, 0.0],
                    _ => [0, 1, 2, 3].map(|_| rng.uniform(0.0, 1.2) as f32),
                })
                .collect();
            RgbaFrame::from_vec(size, px).unwrap()
        };
        let keys: Vec<RgbaFrame> = (0..3).map(|_| frame(&mut rng)).collect();
        let truth: Vec<RgbaFrame> = (0..3).map(|_| frame(&mut rng)).collect();
        let mids: Vec<&RgbaFrame> = truth.iter().collect();
        let mut field = |scale: f64| -> Field {
            (0..size.pixels())
                .map(|_| [0, 1].map(|_| (scale * rng.normal()) as f32))
                .collect()
        };
        for scale in [0.7, 6.0, 60.0] {
            let pairs: Vec<(Field, Field)> = (0..3).map(|_| (field(scale), field(scale))).collect();
            let mut candidates = chain_candidates(&pairs, 3);
            candidates[1][2][5] = [3.0e6, -1.0];
            candidates[2][1][9] = [0.25, -2.5e7];
            for k in 0..3 {
                for i in 0..size.pixels() {
                    let xy = ((i % 23) as f32 + 0.5, (i / 23) as f32 + 0.5);
                    let fast = interval_cost(&keys, &mids, &candidates, k, i, xy);
                    let slow = interval_cost_scalar(&keys, &mids, &candidates, k, i, xy);
                    let bits = |c: [[f32; 4]; 4]| c.map(|r| r.map(f32::to_bits));
                    assert_eq!(bits(fast), bits(slow), "interval {k}, pixel {i}");
                }
            }
        }
    }

    /// A loop's chains from the four first choices side by side are the four chains
    /// run one by one (each from its first choice, closing in it; the least total, the
    /// first of equals), on costs with many ties.
    #[test]
    fn loop_chains_are_the_four_separate_chains() {
        fn separate(costs: &[[[f32; 4]; 4]], n: usize) -> Vec<u8> {
            let chain = |s: usize| {
                let mut cost = [f32::INFINITY; 4];
                cost[s] = 0.0;
                let mut back = Vec::new();
                for c in costs {
                    let mut to = [f32::INFINITY; 4];
                    let mut from = [0u8; 4];
                    for b in 0..4 {
                        for a in 0..4 {
                            if cost[a] + c[a][b] < to[b] {
                                (to[b], from[b]) = (cost[a] + c[a][b], a as u8);
                            }
                        }
                    }
                    cost = to;
                    back.push(from);
                }
                let mut pick = vec![0u8; n];
                let mut at = s as u8;
                for k in (0..costs.len()).rev() {
                    at = back[k][at as usize];
                    pick[k] = at;
                }
                (cost[s], pick)
            };
            (0..4)
                .map(chain)
                .min_by(|a, b| a.0.total_cmp(&b.0))
                .unwrap()
                .1
        }
        let mut rng = ignis_core::Rng::new(2);
        for n in [2, 3, 7, 16] {
            for _ in 0..200 {
                let costs: Vec<[[f32; 4]; 4]> = (0..n)
                    .map(|_| [0; 4].map(|_| [0; 4].map(|_| rng.below(3) as f32 * 0.5)))
                    .collect();
                assert_eq!(best_chain(&costs, n), separate(&costs, n), "{costs:?}");
            }
        }
    }

    /// The tabled sRGB curve of the choice is within 0.01 levels of the exact one.
    #[test]
    fn tabled_srgb_is_close() {
        let t = srgb255_table();
        for i in 0..=100_000 {
            let c = i as f32 / 100_000.0;
            let exact = ignis_core::palette::linear_to_srgb(c) * 255.0;
            assert!((srgb255(t, c) - exact).abs() < 0.01, "{c}");
        }
    }
}
