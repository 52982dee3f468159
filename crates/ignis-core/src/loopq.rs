//! Loop and transition quality measured on the frames a command actually writes: *seam* and
//! *ghost*, the two measures of `../shared/tools/loop_metrics.py` (the reference
//! implementation the team benchmarks against).
//!
//! Frames are first turned into *metric frames*: composited over the writer's background,
//! sRGB-encoded, reduced to Rec. 601 luma (what `ffmpeg -vf format=gray` reads from a video)
//! and area-averaged down to [`METRIC_WIDTH`] pixels wide (height scaled to keep the aspect,
//! rounded to an even number like ffmpeg's `scale=128:-2`). Both measures are ratios, so the
//! value range of the grey does not matter, only its shape.
//!
//! - **seam**: the largest RMS step between consecutive frames, the wrap from the last frame
//!   back to the first included, over the median step (1.0 = the seam is as smooth as a
//!   typical step; a plain cut between different flames is usually ≥ 2).
//! - **ghost**: the softest frame relative to its neighbourhood: the minimum over t of the
//!   frame's mean gradient magnitude over the median of frames t−15..=t+15 (cyclic); 1.0 =
//!   no frame is softer than those around it; blends of unrelated flames fall to ~0.7.

use crate::error::{CoreError, Result};
use crate::frame::{GrayFrame, RgbaFrame, Size};
use crate::palette::linear_to_srgb;

/// Width of the frames both measures are computed on.
pub const METRIC_WIDTH: u32 = 128;
/// Half-width of the cyclic neighbourhood the ghost measure compares a frame with.
pub const GHOST_RADIUS: usize = 15;
/// Rec. 601 luma weights on sRGB-encoded components (ffmpeg's `format=gray`).
const LUMA_601: [f32; 3] = [0.299, 0.587, 0.114];

/// Seam and ghost of a sequence, with where each was found.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LoopQuality {
    /// Largest step (wrap included for loops) over the median step.
    pub seam: f64,
    /// Index of the largest step: step `i` goes from frame `i` to frame `i + 1` (the last,
    /// for a loop, from the last frame back to frame 0).
    pub seam_at: usize,
    /// Softest frame's sharpness over the median sharpness of its ±15 neighbours.
    pub ghost: f64,
    /// Index of the softest frame.
    pub ghost_at: usize,
    /// The median RMS step of the sequence (metric frames, values in `0..=1`).
    pub median_step: f64,
}

/// Size of the metric frame of a `size` frame: [`METRIC_WIDTH`] wide (or the frame's own
/// width when narrower), height to scale rounded to an even number, at least 2.
pub fn metric_size(size: Size) -> Size {
    let w = METRIC_WIDTH.min(size.width).max(1);
    let h = (f64::from(w) * f64::from(size.height) / (f64::from(size.width) * 2.0)).round() * 2.0;
    Size {
        width: w,
        height: (h as u32).max(2),
    }
}

/// The metric frame of a linear grey frame as a grey writer writes it (clamped to `0..=1`,
/// sRGB-encoded), area-averaged down to [`metric_size`].
pub fn metric_frame_gray(frame: &GrayFrame) -> GrayFrame {
    let encoded = frame.map(linear_to_srgb);
    area_resize(&encoded, metric_size(frame.size()))
}

/// The metric frame of a linear RGBA frame (straight alpha) as an opaque writer shows it:
/// composited over `background` (linear RGB), sRGB-encoded, Rec. 601 luma, area-averaged
/// down to [`metric_size`].
pub fn metric_frame_rgba(frame: &RgbaFrame, background: [f32; 3]) -> GrayFrame {
    let lut = srgb_lut();
    metric_of_rows(frame.size(), frame.data(), |out, px| {
        luma_row(lut, px, background, out)
    })
}

/// The per-pixel grey of a frame's `pixels` (one `T` or, for bytes, `pixels.len() /
/// size.pixels()` of them a pixel) made by `row` on runs of 16 rows, side by side for
/// large frames (each pixel on its own: the same values on any threads), then
/// area-averaged down to [`metric_size`].
fn metric_of_rows<T: Sync>(
    size: Size,
    pixels: &[T],
    row: impl Fn(&mut [f32], &[T]) + Sync,
) -> GrayFrame {
    use rayon::prelude::*;
    let per = pixels.len() / size.pixels().max(1);
    let mut luma = vec![0f32; size.pixels()];
    let chunk = (size.width as usize).max(1) * 16;
    let rows = |(out, px): (&mut [f32], &[T])| row(out, px);
    if luma.len() >= 1 << 16 {
        luma.par_chunks_mut(chunk)
            .zip(pixels.par_chunks(chunk * per))
            .for_each(rows);
    } else {
        luma.chunks_mut(chunk)
            .zip(pixels.chunks(chunk * per))
            .for_each(rows);
    }
    let g = GrayFrame::from_vec(size, luma).expect("one value per pixel");
    area_resize(&g, metric_size(size))
}

/// [`metric_frame_rgba`] of an 8-bit sRGB frame over black, straight from its bytes
/// (`size.pixels() * 4` bytes, RGBA, rows top to bottom, as decoders hand them over):
/// bit for bit the metric frame of the linear frame the readers make of those bytes
/// (colour through [`crate::palette::srgb8_to_linear_table`], alpha `a / 255`). An opaque
/// pixel's grey depends on its three codes alone, so it is three table look-ups and two
/// additions instead of a 16-byte linear pixel, its composite and three sRGB encodes; a
/// pixel with alpha below 255 takes the linear pixel's own path. `None` when `bytes` is not
/// `size.pixels() * 4` long.
pub fn metric_frame_srgba8(size: Size, bytes: &[u8]) -> Option<GrayFrame> {
    if bytes.len() != size.pixels() * 4 {
        return None;
    }
    let tables = opaque_luma8_tables();
    let lut = srgb_lut();
    let dec = crate::palette::srgb8_to_linear_table();
    Some(metric_of_rows(size, bytes, |out, px| {
        for (o, p) in out.iter_mut().zip(px.chunks_exact(4)) {
            *o = if p[3] == 255 {
                // `luma_with`'s sum of the three weighted encodes, in its order.
                tables[0][p[0] as usize] + tables[1][p[1] as usize] + tables[2][p[2] as usize]
            } else {
                luma_with(lut, &crate::palette::srgba8_to_linear(dec, p), [0.0; 3])
            };
        }
    }))
}

/// Per channel, the weighted sRGB encode of each 8-bit code's linear value at alpha 1 over
/// black: `LUMA_601[c] · encode_lut(decode(k))`, the term [`luma_with`] adds for it (at
/// alpha 1 the composite `p · 1 + 0 · 0` is `p` exactly).
fn opaque_luma8_tables() -> &'static [[f32; 256]; 3] {
    static T: std::sync::OnceLock<[[f32; 256]; 3]> = std::sync::OnceLock::new();
    T.get_or_init(|| {
        let (lut, dec) = (srgb_lut(), crate::palette::srgb8_to_linear_table());
        std::array::from_fn(|c| std::array::from_fn(|k| LUMA_601[c] * encode_lut(lut, dec[k])))
    })
}

/// The metric grey of one linear straight-alpha pixel over `background` (before the area
/// resize): what [`metric_frame_rgba`] computes per pixel, bit for bit, for callers that
/// make the pixels themselves (the volume loop's preview fuses it with its bloom).
#[inline]
pub fn metric_luma(p: &[f32; 4], background: [f32; 3]) -> f32 {
    luma_with(srgb_lut(), p, background)
}

/// [`metric_luma`] with the sRGB table already in hand (per frame, not per pixel).
#[inline]
fn luma_with(lut: &[f32; LUT_SIZE + 1], p: &[f32; 4], background: [f32; 3]) -> f32 {
    let a = p[3].clamp(0.0, 1.0);
    (0..3)
        .map(|c| LUMA_601[c] * encode_lut(lut, p[c] * a + background[c] * (1.0 - a)))
        .sum()
}

/// [`luma_with`] of every pixel of `px` into `out`: eight pixels at a time with AVX2 where
/// the CPU has it — the same IEEE operations in the same order (no fused multiply-add),
/// so the same values bit for bit — and by the scalar code for the rest and for any group
/// holding a value that is not finite (where the scalar clamps are the reference).
fn luma_row(lut: &[f32; LUT_SIZE + 1], px: &[[f32; 4]], background: [f32; 3], out: &mut [f32]) {
    let mut done = 0;
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && background.iter().all(|b| b.is_finite()) {
        for (o, p) in out.chunks_exact_mut(8).zip(px.chunks_exact(8)) {
            // SAFETY: the CPU has AVX2 (checked above); `luma8` reads eight pixels and
            // writes eight values, and indexes `lut` below its last entry.
            if !unsafe { luma8(lut, p, background, o) } {
                for (v, q) in o.iter_mut().zip(p) {
                    *v = luma_with(lut, q, background);
                }
            }
        }
        done = out.len().min(px.len()) / 8 * 8;
    }
    for (o, p) in out[done..].iter_mut().zip(&px[done..]) {
        *o = luma_with(lut, p, background);
    }
}

/// Eight pixels of [`luma_with`] over a finite `background`; `false` (nothing written)
/// when a pixel's value is not finite.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn luma8(
    lut: &[f32; LUT_SIZE + 1],
    px: &[[f32; 4]],
    background: [f32; 3],
    out: &mut [f32],
) -> bool {
    use std::arch::x86_64::*;
    assert!(px.len() >= 8 && out.len() >= 8);
    let lane = |c: usize| {
        _mm256_setr_ps(
            px[0][c], px[1][c], px[2][c], px[3][c], px[4][c], px[5][c], px[6][c], px[7][c],
        )
    };
    let v: [__m256; 4] = std::array::from_fn(lane);
    if !all_finite8(&v) {
        return false;
    }
    let (zero, one) = (_mm256_setzero_ps(), _mm256_set1_ps(1.0));
    // a = clamp(α, 0, 1)
    let a = _mm256_min_ps(_mm256_max_ps(v[3], zero), one);
    let rest = _mm256_sub_ps(one, a);
    // p · a + background · (1 − a)
    let lin = std::array::from_fn(|c| {
        _mm256_add_ps(
            _mm256_mul_ps(v[c], a),
            _mm256_mul_ps(_mm256_set1_ps(background[c]), rest),
        )
    });
    _mm256_storeu_ps(out.as_mut_ptr(), luma8_avx2(lin, lut));
    true
}

/// Whether every lane of `v` is finite (`x − x == 0`: NaN and ±∞ give NaN), for the
/// vectorised paths that leave non-finite values to their scalar reference.
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub unsafe fn all_finite8(v: &[std::arch::x86_64::__m256]) -> bool {
    use std::arch::x86_64::*;
    let fin = v
        .iter()
        .fold(_mm256_castsi256_ps(_mm256_set1_epi32(-1)), |m, &x| {
            _mm256_and_ps(
                m,
                _mm256_cmp_ps::<_CMP_EQ_OQ>(_mm256_sub_ps(x, x), _mm256_setzero_ps()),
            )
        });
    _mm256_movemask_ps(fin) == 0xff
}

/// The Rec. 601 luma of eight linear RGB values as [`metric_luma`] takes it: each channel
/// clamped to `0..=1` and sRGB-encoded through `table` ([`srgb_encode_table`], linear
/// between its entries), weighted and summed in the same order — the same IEEE operations
/// as the scalar code (no fused multiply-add), so the same bits. Shared by the vectorised
/// metric paths (here and the volume preview's).
///
/// # Safety
/// The CPU must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
pub unsafe fn luma8_avx2(
    lin: [std::arch::x86_64::__m256; 3],
    table: &[f32],
) -> std::arch::x86_64::__m256 {
    use std::arch::x86_64::*;
    assert_eq!(table.len(), LUT_SIZE + 1, "the sRGB encode table");
    let (zero, one) = (_mm256_setzero_ps(), _mm256_set1_ps(1.0));
    let mut sum = _mm256_set1_ps(-0.0);
    for (c, &w) in LUMA_601.iter().enumerate() {
        // `encode_lut`: x = clamp(v, 0, 1) · 4096, i = min(⌊x⌋, 4095), f = x − i
        let x = _mm256_mul_ps(
            _mm256_min_ps(_mm256_max_ps(lin[c], zero), one),
            _mm256_set1_ps(LUT_SIZE as f32),
        );
        let i = _mm256_min_epi32(
            _mm256_cvttps_epi32(x),
            _mm256_set1_epi32(LUT_SIZE as i32 - 1),
        );
        let f = _mm256_sub_ps(x, _mm256_cvtepi32_ps(i));
        // SAFETY: i ≤ 4095, so i and i + 1 index the table's 4,097 entries
        let lo = _mm256_i32gather_ps::<4>(table.as_ptr(), i);
        let hi = _mm256_i32gather_ps::<4>(table.as_ptr().add(1), i);
        let enc = _mm256_add_ps(lo, _mm256_mul_ps(_mm256_sub_ps(hi, lo), f));
        sum = _mm256_add_ps(sum, _mm256_mul_ps(_mm256_set1_ps(w), enc));
    }
    sum
}

const LUT_SIZE: usize = 4096;

/// [`linear_to_srgb`] sampled at `LUT_SIZE` points of `0..=1` (interpolated linearly between
/// them: within 2e-4 of the exact curve above 0.001, a ninth of an 8-bit step).
/// The table [`metric_frame_rgba`] encodes sRGB with (`LUT_SIZE + 1` = 4,097 values of
/// [`linear_to_srgb`] at `i / 4096`, interpolated linearly between them), for callers
/// that vectorise [`metric_luma`] and must give its values bit for bit.
pub fn srgb_encode_table() -> &'static [f32] {
    srgb_lut()
}

/// [`linear_to_srgb`] from the table [`srgb_encode_table`] (within 2e-4 of the exact
/// curve above 0.001): for per-pixel encoding on hot paths, a table lookup instead of a
/// power.
#[inline]
pub fn srgb_encode(v: f32) -> f32 {
    encode_lut(srgb_lut(), v)
}

#[inline]
fn srgb_lut() -> &'static [f32; LUT_SIZE + 1] {
    static LUT: std::sync::OnceLock<[f32; LUT_SIZE + 1]> = std::sync::OnceLock::new();
    LUT.get_or_init(|| std::array::from_fn(|i| linear_to_srgb(i as f32 / LUT_SIZE as f32)))
}

#[inline]
fn encode_lut(lut: &[f32; LUT_SIZE + 1], v: f32) -> f32 {
    let x = v.clamp(0.0, 1.0) * LUT_SIZE as f32;
    let i = (x as usize).min(LUT_SIZE - 1);
    let f = x - i as f32;
    lut[i] + (lut[i + 1] - lut[i]) * f
}

/// RMS difference of consecutive frames; with `wrap`, a last step from the last frame back
/// to the first (`frames.len()` steps), else `frames.len() - 1` steps.
///
/// Errors when the frames differ in size.
pub fn steps(frames: &[GrayFrame], wrap: bool) -> Result<Vec<f64>> {
    same_size(frames)?;
    let n = frames.len();
    let count = if wrap { n } else { n.saturating_sub(1) };
    Ok((0..count)
        .map(|i| rms_diff(&frames[i], &frames[(i + 1) % n]))
        .collect())
}

/// RMS difference of two frames of the same size.
pub fn rms_diff(a: &GrayFrame, b: &GrayFrame) -> f64 {
    let s: f64 = a
        .data()
        .iter()
        .zip(b.data())
        .map(|(&x, &y)| {
            let d = f64::from(x) - f64::from(y);
            d * d
        })
        .sum();
    (s / a.data().len().max(1) as f64).sqrt()
}

/// Σ (a − b)² of two equally long slices of samples, fast: eight f32 running sums (so the
/// loop vectorises) and the tail, added in f64 in a fixed order, so the same value
/// everywhere. For the many small previews the loop re-timings compare.
pub fn sum_sq_diff(a: &[f32], b: &[f32]) -> f64 {
    let mut lanes = [0f32; 8];
    let (ca, cb) = (a.chunks_exact(8), b.chunks_exact(8));
    let tail: f64 = ca
        .remainder()
        .iter()
        .zip(cb.remainder())
        .map(|(&x, &y)| f64::from((x - y) * (x - y)))
        .sum();
    for (x, y) in ca.zip(cb) {
        for l in 0..8 {
            let d = x[l] - y[l];
            lanes[l] += d * d;
        }
    }
    lanes.iter().map(|&v| f64::from(v)).sum::<f64>() + tail
}

/// Mean absolute horizontal plus mean absolute vertical difference of neighbouring pixels
/// (the measure `ghost` compares between frames).
pub fn sharpness(frame: &GrayFrame) -> f64 {
    let (w, h) = (frame.width() as usize, frame.height() as usize);
    let d = frame.data();
    let mut gx = 0.0f64;
    let mut gy = 0.0f64;
    for y in 0..h {
        let row = &d[y * w..(y + 1) * w];
        for x in 1..w {
            gx += f64::from((row[x] - row[x - 1]).abs());
        }
        if y > 0 {
            let up = &d[(y - 1) * w..y * w];
            for x in 0..w {
                gy += f64::from((row[x] - up[x]).abs());
            }
        }
    }
    let nx = (h * w.saturating_sub(1)).max(1) as f64;
    let ny = (h.saturating_sub(1) * w).max(1) as f64;
    gx / nx + gy / ny
}

/// The ghost measure of a sequence of sharpness values: for each frame its sharpness over
/// the median of the 31 frames `t-15..=t+15` taken cyclically (with repeats when the
/// sequence is shorter), minimum over frames. Returns (ghost, index).
pub fn ghost(sharp: &[f64]) -> (f64, usize) {
    let n = sharp.len();
    let mut best = (f64::INFINITY, 0);
    let mut window = Vec::with_capacity(2 * GHOST_RADIUS + 1);
    for t in 0..n {
        window.clear();
        for o in -(GHOST_RADIUS as isize)..=GHOST_RADIUS as isize {
            let i = (t as isize + o).rem_euclid(n as isize) as usize;
            window.push(sharp[i]);
        }
        let rel = sharp[t] / median(&mut window).max(1e-9);
        if rel < best.0 {
            best = (rel, t);
        }
    }
    best
}

/// Median as numpy computes it (mean of the two middle values for an even count); 0 for an
/// empty slice. Reorders `v`.
pub fn median(v: &mut [f64]) -> f64 {
    let n = v.len();
    if n == 0 {
        return 0.0;
    }
    v.sort_unstable_by(f64::total_cmp);
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Seam and ghost of metric frames played as a loop (the wrap step included). At least two
/// frames of one size.
pub fn loop_quality(frames: &[GrayFrame]) -> Result<LoopQuality> {
    quality(frames, true)
}

/// Seam and ghost of metric frames played once (no wrap step; the ghost neighbourhood is
/// still cyclic, as in the reference). At least three frames of one size.
pub fn sequence_quality(frames: &[GrayFrame]) -> Result<LoopQuality> {
    quality(frames, false)
}

fn quality(frames: &[GrayFrame], wrap: bool) -> Result<LoopQuality> {
    let need = if wrap { 2 } else { 3 };
    if frames.len() < need {
        return Err(CoreError::bad(
            "frames",
            format!(
                "{} frame(s): seam and ghost need at least {need}",
                frames.len()
            ),
        ));
    }
    let d = steps(frames, wrap)?;
    let sharp: Vec<f64> = frames.iter().map(sharpness).collect();
    Ok(quality_of(&d, &sharp))
}

/// Seam and ghost from a sequence's steps (RMS differences of consecutive metric frames,
/// the wrap step last for a loop) and each frame's [`sharpness`]: what [`loop_quality`]
/// and [`sequence_quality`] compute from the frames, for a caller that measured the frames
/// as they streamed past instead of keeping them.
pub fn quality_of(d: &[f64], sharp: &[f64]) -> LoopQuality {
    let med = median(&mut d.to_vec());
    let (seam_at, max) =
        d.iter().enumerate().fold(
            (0, f64::NEG_INFINITY),
            |b, (i, &v)| if v > b.1 { (i, v) } else { b },
        );
    let (ghost, ghost_at) = ghost(sharp);
    LoopQuality {
        // A still sequence has no steps to compare: call it perfectly smooth.
        seam: if med > 0.0 {
            max / med
        } else if max > 0.0 {
            f64::INFINITY
        } else {
            1.0
        },
        seam_at,
        ghost,
        ghost_at,
        median_step: med,
    }
}

fn same_size(frames: &[GrayFrame]) -> Result<()> {
    if let Some(f) = frames.first() {
        if let Some(g) = frames.iter().find(|g| g.size() != f.size()) {
            return Err(CoreError::SizeMismatch(format!(
                "metric frames of {} and {} in one sequence",
                f.size(),
                g.size()
            )));
        }
    }
    Ok(())
}

/// Parameter values (in `0..=1`) at which a path reaches the given fractions of its length:
/// `arc` is the path's cumulative step length sampled at the uniform parameters
/// `k / (arc.len() − 1)` (`arc[0] = 0`, non-decreasing), and each fraction `f` in `0..=1`
/// maps to the parameter where the arc reaches `f × total`, linearly between samples.
/// A path of zero length maps fractions to themselves.
///
/// This is constant-speed re-timing: a generator whose time is a continuous parameter
/// (a noise phase, a state interpolated between steps) renders frames at the returned
/// parameters so every step covers the same measured distance — the in-betweens of a
/// morph (fractions `k / (n + 1)`) or the frames of a loop (fractions `k / n`, the last
/// step back to the start as long as the others).
pub fn arc_times(arc: &[f64], fractions: impl IntoIterator<Item = f64>) -> Vec<f64> {
    let total = arc.last().copied().unwrap_or(0.0);
    let m = arc.len().saturating_sub(1).max(1);
    fractions
        .into_iter()
        .map(|f| {
            if total.is_nan() || total <= 0.0 {
                return f;
            }
            let want = total * f;
            let i = arc.partition_point(|&v| v < want).clamp(1, m);
            let (lo, hi) = (arc[i - 1], arc[i]);
            let frac = if hi > lo {
                ((want - lo) / (hi - lo)).clamp(0.0, 1.0)
            } else {
                0.0
            };
            ((i - 1) as f64 + frac) / m as f64
        })
        .collect()
}

/// Area-average resize (each output pixel the coverage-weighted mean of the input pixels
/// under it); exact copy when the size is unchanged. Separable: rows, then columns.
pub fn area_resize(src: &GrayFrame, size: Size) -> GrayFrame {
    if src.size() == size {
        return src.clone();
    }
    let (sw, sh) = (src.width() as usize, src.height() as usize);
    let (dw, dh) = (size.width as usize, size.height as usize);
    let wx = area_weights(sw, dw);
    let wy = area_weights(sh, dh);
    // Horizontal pass: sh × dw; rows side by side (each output's sum in the same order on
    // any threads), for large frames only.
    use rayon::prelude::*;
    let mut tmp = vec![0f32; sh * dw];
    let horizontal = |(y, out): (usize, &mut [f32])| {
        let row = &src.data()[y * sw..(y + 1) * sw];
        for (o, taps) in out.iter_mut().zip(&wx) {
            *o = taps.iter().map(|&(i, w)| row[i] * w).sum();
        }
    };
    if sw * sh >= 1 << 16 {
        tmp.par_chunks_mut(dw).enumerate().for_each(horizontal);
    } else {
        tmp.chunks_mut(dw).enumerate().for_each(horizontal);
    }
    let mut out = vec![0f32; dw * dh];
    for (y, taps) in wy.iter().enumerate() {
        for &(i, w) in taps {
            let src_row = &tmp[i * dw..(i + 1) * dw];
            for (o, &v) in out[y * dw..(y + 1) * dw].iter_mut().zip(src_row) {
                *o += v * w;
            }
        }
    }
    GrayFrame::from_vec(size, out).expect("one value per pixel")
}

/// For each of `dst` output cells, the input indices it covers and their weights (summing
/// to 1). Upscaling degenerates to nearest-neighbour-like box sampling.
fn area_weights(src: usize, dst: usize) -> Vec<Vec<(usize, f32)>> {
    let scale = src as f64 / dst as f64;
    (0..dst)
        .map(|o| {
            let (a, b) = (o as f64 * scale, (o + 1) as f64 * scale);
            let mut taps = Vec::new();
            let mut i = a.floor() as usize;
            while (i as f64) < b && i < src {
                let cover = (b.min(i as f64 + 1.0) - a.max(i as f64)).max(0.0);
                if cover > 0.0 {
                    taps.push((i, (cover / (b - a)) as f32));
                }
                i += 1;
            }
            taps
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lane sum equals the plain sum of squares (ragged lengths, so the tail counts).
    #[test]
    fn sum_sq_diff_is_the_sum_of_squares() {
        for n in [0usize, 1, 7, 8, 9, 61] {
            let a: Vec<f32> = (0..n).map(|i| (i as f32 * 0.37).sin()).collect();
            let b: Vec<f32> = (0..n).map(|i| (i as f32 * 0.11).cos()).collect();
            let want: f64 = a
                .iter()
                .zip(&b)
                .map(|(&x, &y)| (f64::from(x) - f64::from(y)).powi(2))
                .sum();
            let got = sum_sq_diff(&a, &b);
            assert!(
                (got - want).abs() <= 1e-5 * want.max(1e-12),
                "{n}: {got} vs {want}"
            );
        }
    }

    #[test]
    fn arc_times_follow_the_path_length() {
        // All of the length is in the second half: the midpoint of the length is at 0.75.
        let arc = [0.0, 0.0, 1.0];
        let t = arc_times(&arc, [0.0, 0.5, 1.0]);
        assert_eq!(t, vec![0.0, 0.75, 1.0]);
        // Even pace: parameters equal fractions.
        let even = arc_times(&[0.0, 1.0, 2.0, 3.0], (0..4).map(|k| k as f64 / 3.0));
        for (k, v) in even.iter().enumerate() {
            assert!((v - k as f64 / 3.0).abs() < 1e-12);
        }
        // A still path keeps the fractions.
        assert_eq!(arc_times(&[0.0, 0.0], [0.25]), vec![0.25]);
    }

    fn frame(size: Size, f: impl Fn(u32, u32) -> f32) -> GrayFrame {
        GrayFrame::from_fn(size, f)
    }

    #[test]
    fn metric_size_follows_ffmpeg_scale_128_minus_2() {
        let s = |w, h| metric_size(Size::new(w, h).unwrap());
        assert_eq!(s(480, 480), Size::new(128, 128).unwrap());
        assert_eq!(s(960, 540), Size::new(128, 72).unwrap());
        assert_eq!(s(1280, 720), Size::new(128, 72).unwrap());
        assert_eq!(s(640, 1136), Size::new(128, 228).unwrap());
        assert_eq!(s(64, 48), Size::new(64, 48).unwrap());
    }

    #[test]
    fn area_resize_keeps_the_mean_and_constant_frames() {
        let src = frame(Size::new(300, 170).unwrap(), |x, y| {
            ((x * 7 + y * 3) % 11) as f32
        });
        let dst = area_resize(&src, Size::new(128, 72).unwrap());
        assert!((src.mean() - dst.mean()).abs() < 1e-3 * src.mean());
        let flat = frame(Size::new(301, 99).unwrap(), |_, _| 0.25);
        assert!(area_resize(&flat, Size::new(128, 42).unwrap())
            .data()
            .iter()
            .all(|&v| (v - 0.25).abs() < 1e-6));
    }

    #[test]
    fn a_cut_has_a_large_seam_and_a_blend_a_low_ghost() {
        let size = Size::new(64, 48).unwrap();
        // Stripes of period 16 moving one pixel per frame, 40 frames: the wrap jumps back
        // 39 pixels (7 modulo the period).
        let frames: Vec<GrayFrame> = (0..40)
            .map(|t| {
                frame(
                    size,
                    move |x, _| if (x + 64 - t) % 16 < 8 { 1.0 } else { 0.0 },
                )
            })
            .collect();
        let q = loop_quality(&frames).unwrap();
        assert_eq!(q.seam_at, 39);
        assert!(q.seam > 2.0, "{q:?}");
        // 7 or 8 stripe edges in view, depending on the shift.
        assert!(q.ghost > 0.85, "{q:?}");
        // Replace frame 20 by the blend of two frames half a period apart: flat grey.
        let mut blended = frames.clone();
        let mix: Vec<f32> = frames[5]
            .data()
            .iter()
            .zip(frames[13].data())
            .map(|(a, b)| 0.5 * (a + b))
            .collect();
        blended[20] = GrayFrame::from_vec(size, mix).unwrap();
        let g = loop_quality(&blended).unwrap();
        assert_eq!(g.ghost_at, 20);
        assert!(g.ghost < 0.8, "{g:?}");
    }

    #[test]
    fn sequence_quality_has_no_wrap_step() {
        let size = Size::new(16, 16).unwrap();
        let frames: Vec<GrayFrame> = (0..10)
            .map(|t| frame(size, move |x, _| if x == t { 1.0 } else { 0.0 }))
            .collect();
        assert_eq!(steps(&frames, false).unwrap().len(), 9);
        assert_eq!(steps(&frames, true).unwrap().len(), 10);
        let q = sequence_quality(&frames).unwrap();
        assert!((q.seam - 1.0).abs() < 1e-12);
        assert!(loop_quality(&frames[..1]).is_err());
    }

    #[test]
    fn median_matches_numpy() {
        assert_eq!(median(&mut [3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&mut [4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(median(&mut []), 0.0);
    }

    #[test]
    fn sizes_must_agree() {
        let a = GrayFrame::new(Size::new(4, 4).unwrap());
        let b = GrayFrame::new(Size::new(4, 5).unwrap());
        assert!(loop_quality(&[a, b]).is_err());
    }

    #[test]
    fn luma_rows_equal_the_scalar_pixel_bit_for_bit() {
        let mut state = 0x9e37_79b9_u32;
        let mut rnd = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state
        };
        let special = [
            0.0,
            -0.0,
            1.0,
            1e-30,
            0.999_999_9,
            1.5,
            -0.25,
            f32::NAN,
            f32::INFINITY,
        ];
        let mut value = || match rnd() % 8 {
            0 => special[(rnd() % special.len() as u32) as usize],
            _ => rnd() as f32 / u32::MAX as f32 * 1.4 - 0.2,
        };
        let lut = srgb_lut();
        for background in [[0.0; 3], [0.2, 0.5, 1.0], [-0.0, 0.0, 0.7]] {
            for n in (0..40).chain([257, 1031]) {
                let px: Vec<[f32; 4]> = (0..n)
                    .map(|_| [value(), value(), value(), value()])
                    .collect();
                let mut out = vec![0.0; n];
                luma_row(lut, &px, background, &mut out);
                for (o, p) in out.iter().zip(&px) {
                    let want = luma_with(lut, p, background);
                    assert_eq!(o.to_bits(), want.to_bits(), "{p:?} over {background:?}");
                }
            }
        }
    }

    /// The linear frame the readers make of 8-bit RGBA bytes (`ignis_media`'s
    /// `from_srgba8`, pixel by pixel through the same `srgba8_to_linear`).
    fn linear_of_srgba8(size: Size, bytes: &[u8]) -> RgbaFrame {
        let dec = crate::palette::srgb8_to_linear_table();
        let px = bytes
            .chunks_exact(4)
            .map(|p| crate::palette::srgba8_to_linear(dec, p))
            .collect();
        RgbaFrame::from_vec(size, px).unwrap()
    }

    #[test]
    fn the_8bit_metric_equals_the_metric_of_the_linear_frame() {
        // Every (red, green) pair once, blue varied, some pixels part transparent; 128 wide
        // so the metric frame is the per-pixel grey itself (no resize), and 65,536 pixels
        // so the rows run side by side.
        let size = Size::new(128, 512).unwrap();
        let bytes: Vec<u8> = (0..size.pixels())
            .flat_map(|i| {
                let a = if i % 97 == 5 {
                    (i * 13 % 256) as u8
                } else {
                    255
                };
                [
                    (i % 256) as u8,
                    (i / 256 % 256) as u8,
                    (i * 31 % 256) as u8,
                    a,
                ]
            })
            .collect();
        let fast = metric_frame_srgba8(size, &bytes).unwrap();
        let slow = metric_frame_rgba(&linear_of_srgba8(size, &bytes), [0.0; 3]);
        assert_eq!(fast.size(), size);
        for (i, (a, b)) in fast.data().iter().zip(slow.data()).enumerate() {
            assert_eq!(a.to_bits(), b.to_bits(), "pixel {i}: {a} against {b}");
        }
        // Resized frames of odd sizes, small (one thread) and large, noisy bytes.
        for (w, h) in [(7, 3), (333, 187), (1280, 720)] {
            let size = Size::new(w, h).unwrap();
            let mut x = 0x9e37_79b9_u32;
            let bytes: Vec<u8> = (0..size.pixels() * 4)
                .map(|i| {
                    x ^= x << 13;
                    x ^= x >> 17;
                    x ^= x << 5;
                    if i % 4 == 3 && !x.is_multiple_of(5) {
                        255
                    } else {
                        (x >> 24) as u8
                    }
                })
                .collect();
            let fast = metric_frame_srgba8(size, &bytes).unwrap();
            let slow = metric_frame_rgba(&linear_of_srgba8(size, &bytes), [0.0; 3]);
            assert_eq!(fast.size(), slow.size());
            assert!(
                fast.data()
                    .iter()
                    .zip(slow.data())
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "{w}x{h}"
            );
        }
        assert!(metric_frame_srgba8(size, &bytes[..bytes.len() - 1]).is_none());
    }

    #[test]
    fn srgb_lut_is_close_to_the_curve() {
        let lut = srgb_lut();
        for i in 0..=10_000 {
            let v = i as f32 / 10_000.0;
            let tol = if v < 0.001 { 2e-3 } else { 2e-4 };
            assert!((encode_lut(lut, v) - linear_to_srgb(v)).abs() < tol, "{v}");
        }
    }

    #[test]
    fn rgba_metric_frame_composites_and_encodes() {
        let size = Size::new(256, 144).unwrap();
        let f = RgbaFrame::filled(size, [1.0, 1.0, 1.0, 0.5]);
        let m = metric_frame_rgba(&f, [0.0; 3]);
        assert_eq!(m.size(), Size::new(128, 72).unwrap());
        let want = linear_to_srgb(0.5);
        assert!(m.data().iter().all(|&v| (v - want).abs() < 1e-5));
    }
}
