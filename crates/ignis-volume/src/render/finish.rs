//! The post pipeline of a rendered frame: bloom, then straight alpha; and the same
//! pipeline fused with the loop metric's conversion for the loop's preview frames.

use crate::error::Result;
use ignis_core::loopq::{area_resize, metric_frame_rgba, metric_luma, metric_size};
use ignis_core::post::{bloom_rgba, gaussian_kernel, BloomParams};
use ignis_core::{GrayFrame, RgbaFrame};
use rayon::prelude::*;

/// The post pipeline: bloom on the premultiplied HDR frame (skipped when
/// `bloom.passes == 0`), then conversion to straight alpha with
/// `a' = clamp(max(a, max(r, g, b)), 0, 1)` and `rgb' = rgb / a'` — so compositing the
/// result "over" a background adds the fire's light to it where it is faint.
pub fn finish(premultiplied: &RgbaFrame, bloom: &BloomParams) -> Result<RgbaFrame> {
    let straight = |p: &[f32; 4]| {
        let a = p[3].max(p[0]).max(p[1]).max(p[2]).clamp(0.0, 1.0);
        if a > 0.0 {
            [p[0] / a, p[1] / a, p[2] / a, a]
        } else {
            [0.0; 4]
        }
    };
    const CHUNK: usize = 4096;
    if bloom.passes > 0 {
        let mut f = bloom_rgba(premultiplied, bloom)?;
        f.data_mut()
            .par_chunks_mut(CHUNK)
            .for_each(|c| c.iter_mut().for_each(|p| *p = straight(p)));
        Ok(f)
    } else {
        let data = premultiplied
            .data()
            .par_iter()
            .with_min_len(CHUNK)
            .map(straight)
            .collect();
        Ok(RgbaFrame::from_vec(premultiplied.size(), data)?)
    }
}

/// Largest bloom σ, in pixels, that [`bloom_rgba`] blurs exactly at full resolution on
/// any frame (its reduced levels start at σ ≥ 6); the fused preview path below is exact
/// only there and hands larger σ back to [`finish`].
const EXACT_SIGMA: f32 = 6.0;

/// The metric frame ([`ignis_core::loopq::metric_frame_rgba`] over black) of what
/// [`finish`] makes of `premultiplied`, bit for bit, for the loop's preview.
///
/// Why: the preview renders hundreds of 64-px frames, and at that size the post pipeline
/// is a fixed cost per frame comparable to the sampling. Where every bloom pass is blurred
/// exactly (σ < 6 px, always so at the preview's 64 px wide unless the frame is tall) this
/// blooms the three colour planes in one sequential pass per frame (the preview already
/// renders its frames side by side, so nested row tasks only cost wake-ups), with the same
/// sums in the same order as `ignis_core::post` (compiled for AVX where the CPU has it:
/// the same IEEE operations on wider vectors, no fused multiply-add), then converts each
/// pixel to straight alpha and to its metric grey without writing the bloomed RGBA frame.
/// Otherwise it falls back to `finish` then `metric_frame_rgba`.
pub fn preview_metric(premultiplied: &RgbaFrame, bloom: &BloomParams) -> Result<GrayFrame> {
    bloom.validate()?;
    let sigmas: Vec<f32> = (0..bloom.passes)
        .scan(bloom.radius, |s, _| {
            let v = *s;
            *s *= bloom.radius_falloff;
            Some(v)
        })
        .collect();
    if sigmas.iter().any(|&s| s >= EXACT_SIGMA) {
        let f = finish(premultiplied, bloom)?;
        return Ok(metric_frame_rgba(&f, [0.0; 3]));
    }
    let size = premultiplied.size();
    let (w, h) = (size.width as usize, size.height as usize);
    let data = premultiplied.data();
    let kernels: Vec<Vec<f32>> = sigmas.iter().map(|&s| gaussian_kernel(s)).collect();
    let mut planes: [Vec<f32>; 3] = std::array::from_fn(|c| data.iter().map(|p| p[c]).collect());
    if !kernels.is_empty() {
        let mut scratch = Scratch::default();
        for plane in &mut planes {
            bloom_plane(plane, w, h, &kernels, bloom.strength, &mut scratch);
        }
    }
    let luma = metric_grey(&planes, data);
    let g = GrayFrame::from_vec(size, luma)?;
    Ok(area_resize(&g, metric_size(size)))
}

/// Buffers of [`bloom_plane`], reused over the three planes.
#[derive(Default)]
struct Scratch {
    src: Vec<f32>,
    tmp: Vec<f32>,
    pad: Vec<f32>,
    row: Vec<f32>,
    offs: Vec<usize>,
}

/// `plane = max(plane + strength·Σ blur_kᵢ(plane), plane)`, the exact passes of
/// `ignis_core::post::bloom`: dispatched to an AVX build of [`bloom_plane_generic`] when
/// the CPU has it (same results: only the vector width differs).
fn bloom_plane(
    plane: &mut [f32],
    w: usize,
    h: usize,
    kernels: &[Vec<f32>],
    strength: f32,
    s: &mut Scratch,
) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU supports AVX (checked just above).
        unsafe { bloom_plane_avx(plane, w, h, kernels, strength, s) };
        return;
    }
    bloom_plane_generic(plane, w, h, kernels, strength, s);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn bloom_plane_avx(
    plane: &mut [f32],
    w: usize,
    h: usize,
    kernels: &[Vec<f32>],
    strength: f32,
    s: &mut Scratch,
) {
    bloom_plane_generic(plane, w, h, kernels, strength, s);
}

/// [`bloom_plane`]'s body; inlined into each build so it vectorises for that target.
#[inline(always)]
fn bloom_plane_generic(
    plane: &mut [f32],
    w: usize,
    h: usize,
    kernels: &[Vec<f32>],
    strength: f32,
    s: &mut Scratch,
) {
    s.src.clear();
    s.src.extend_from_slice(plane);
    for k in kernels {
        if k.len() == 1 {
            for (a, &v) in plane.iter_mut().zip(&s.src) {
                *a += strength * v;
            }
            continue;
        }
        let r = k.len() / 2;
        // horizontal, as `post::blur_plane`: the row padded with its edge values, then
        // tap by tap over the row
        s.tmp.resize(w * h, 0.0);
        s.pad.resize(w + 2 * r, 0.0);
        s.offs.clear();
        s.offs.extend(0..k.len());
        for (o, src) in s.tmp.chunks_exact_mut(w).zip(s.src.chunks_exact(w)) {
            s.pad[..r].fill(src[0]);
            s.pad[r..r + w].copy_from_slice(src);
            s.pad[r + w..].fill(src[w - 1]);
            convolve(o, k, &s.pad, &s.offs);
        }
        // vertical, row by row, then added to the plane at `strength`
        s.row.resize(w, 0.0);
        for (y, acc) in plane.chunks_exact_mut(w).enumerate() {
            s.offs.clear();
            s.offs
                .extend((0..k.len()).map(|j| (y + j).saturating_sub(r).min(h - 1) * w));
            convolve(&mut s.row, k, &s.tmp, &s.offs);
            for (a, &v) in acc.iter_mut().zip(&s.row) {
                *a += strength * v;
            }
        }
    }
    for (a, &v) in plane.iter_mut().zip(&s.src) {
        *a = a.max(v);
    }
}

/// `out[x] = Σⱼ k[j]·src[offs[j] + x]`, summed from 0 in tap order (`post::blur_plane`'s
/// sums, bit for bit), eight outputs at a time held in registers across all the taps
/// instead of read and written back once per tap.
#[inline(always)]
fn convolve(out: &mut [f32], k: &[f32], src: &[f32], offs: &[usize]) {
    const L: usize = 8;
    let n = out.len() / L * L;
    for (x, o) in (0..n).step_by(L).zip(out.chunks_exact_mut(L)) {
        let mut acc = [0.0f32; L];
        for (&kv, &off) in k.iter().zip(offs) {
            let t: &[f32; L] = src[off + x..off + x + L].try_into().expect("eight values");
            for l in 0..L {
                acc[l] += kv * t[l];
            }
        }
        o.copy_from_slice(&acc);
    }
    for x in n..out.len() {
        let mut acc = 0.0f32;
        for (&kv, &off) in k.iter().zip(offs) {
            acc += kv * src[off + x];
        }
        out[x] = acc;
    }
}

/// The metric grey of every pixel of the bloomed planes (`alpha` from `data`): straight
/// alpha as [`finish`] makes it, then [`metric_luma`] over black — eight pixels at a time
/// with AVX2 where the CPU has it and the eight values are finite (the same IEEE
/// operations in the same order, the table's gathers for its look-ups), else one by one.
fn metric_grey(planes: &[Vec<f32>; 3], data: &[[f32; 4]]) -> Vec<f32> {
    // where the bloomed frame is empty (most of a flame's frame) the grey is a constant
    let empty = metric_luma(&[0.0; 4], [0.0; 3]);
    let one = |i: usize| {
        let px = [planes[0][i], planes[1][i], planes[2][i], data[i][3]];
        let a = px[3].max(px[0]).max(px[1]).max(px[2]).clamp(0.0, 1.0);
        if a > 0.0 {
            metric_luma(&[px[0] / a, px[1] / a, px[2] / a, a], [0.0; 3])
        } else {
            empty
        }
    };
    let mut out = vec![0.0f32; data.len()];
    let mut done = 0;
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        let table = ignis_core::loopq::srgb_encode_table();
        for (c, o) in out.chunks_exact_mut(8).enumerate() {
            let i = c * 8;
            let px = std::array::from_fn(|k| &planes[k][i..i + 8]);
            let alpha: [f32; 8] = std::array::from_fn(|l| data[i + l][3]);
            // SAFETY: the CPU supports AVX2 (checked above); `grey8` reads eight values
            // of each slice and indexes `table` only below its 4,097 entries.
            if !unsafe { grey8(px, &alpha, table, empty, o) } {
                o.iter_mut().enumerate().for_each(|(l, v)| *v = one(i + l));
            }
        }
        done = out.len() / 8 * 8;
    }
    for (i, o) in out.iter_mut().enumerate().skip(done) {
        *o = one(i);
    }
    out
}

/// Eight pixels of [`metric_grey`] into `out`; `false` (nothing written) when a value is
/// not finite, where the scalar clamps and maxima are the reference.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn grey8(
    px: [&[f32]; 3],
    alpha: &[f32; 8],
    table: &[f32],
    empty: f32,
    out: &mut [f32],
) -> bool {
    use std::arch::x86_64::*;
    assert!(px.iter().all(|p| p.len() >= 8) && out.len() >= 8 && table.len() == 4097);
    let v: [__m256; 3] = std::array::from_fn(|c| _mm256_loadu_ps(px[c].as_ptr()));
    let al = _mm256_loadu_ps(alpha.as_ptr());
    if !ignis_core::loopq::all_finite8(&[v[0], v[1], v[2], al]) {
        return false;
    }
    let (zero, one) = (_mm256_setzero_ps(), _mm256_set1_ps(1.0));
    // a = clamp(max(α, r, g, b), 0, 1), as `finish`
    let a = _mm256_max_ps(_mm256_max_ps(_mm256_max_ps(al, v[0]), v[1]), v[2]);
    let a = _mm256_min_ps(_mm256_max_ps(a, zero), one);
    let lit = _mm256_cmp_ps::<_CMP_GT_OQ>(a, zero);
    // over black: straight · a + 0 · (1 − a)
    let bg = _mm256_mul_ps(zero, _mm256_sub_ps(one, a));
    let lin = std::array::from_fn(|c| _mm256_add_ps(_mm256_mul_ps(_mm256_div_ps(v[c], a), a), bg));
    let sum = ignis_core::loopq::luma8_avx2(lin, table);
    let grey = _mm256_blendv_ps(_mm256_set1_ps(empty), sum, lit);
    _mm256_storeu_ps(out.as_mut_ptr(), grey);
    true
}

#[cfg(test)]
mod tests {
    use super::*;
    use ignis_core::Size;

    /// The fused preview pipeline on synthetic HDR frames (zeros, faint, saturated and
    /// over-range values, a NaN and an infinity, widths not a multiple of eight) gives the
    /// metric frame of `finish`'s image bit for bit, bloomed or not.
    #[test]
    fn preview_metric_equals_finish_then_metric_on_any_values() {
        let mut state = 0x2545_f491_u32;
        let mut rnd = move || {
            state ^= state << 13;
            state ^= state >> 17;
            state ^= state << 5;
            state as f32 / u32::MAX as f32
        };
        for (w, h) in [(64, 64), (61, 37), (9, 70)] {
            let size = Size::new(w, h).unwrap();
            let data: Vec<[f32; 4]> = (0..w * h)
                .map(|i| match i % 7 {
                    0 => [0.0; 4],
                    1 => [rnd() * 1e-4, rnd() * 1e-4, 0.0, rnd() * 1e-3],
                    2 => [3.0 * rnd(), 2.0 * rnd(), rnd(), rnd()],
                    _ => [rnd(), 0.7 * rnd(), 0.3 * rnd(), 0.9 * rnd()],
                })
                .enumerate()
                .map(|(i, p)| match i {
                    100 => [f32::NAN, 0.5, 0.5, 0.5],
                    200 => [0.5, f32::INFINITY, 0.0, 1.0],
                    _ => p,
                })
                .collect();
            let hdr = RgbaFrame::from_vec(size, data).unwrap();
            for passes in [0, 3] {
                let bloom = BloomParams {
                    passes,
                    radius: 3.8,
                    ..BloomParams::default()
                };
                let full = metric_frame_rgba(&finish(&hdr, &bloom).unwrap(), [0.0; 3]);
                let fused = preview_metric(&hdr, &bloom).unwrap();
                assert_eq!(full.size(), fused.size());
                for (i, (x, y)) in full.data().iter().zip(fused.data()).enumerate() {
                    assert_eq!(
                        x.to_bits(),
                        y.to_bits(),
                        "{w}x{h}, {passes} passes, pixel {i}"
                    );
                }
            }
        }
    }
}
