//! The grey renderer's row, eight pixels at a time with AVX2 ([`super::render_encoded_into`]).
//!
//! Every lane does the scalar [`super::sample`] then [`super::Encoding::apply`] operation
//! for operation (no fused multiply-adds, the same order), so the values are the same
//! bit for bit; lanes outside the normalised image take the scalar path's `0`. Table
//! and image lookups are gathers with every index clamped into its table, so lanes whose
//! pixel (or bilinear tap) lies outside read valid memory and are then masked to `0`.

use super::{Encoding, RenderScratch, RowSampling};

/// Whether [`row`] may run on this CPU.
pub(super) fn available() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// Renders and encodes the pixels of `out` (row `rs`) and returns how many (all).
///
/// # Safety
/// The CPU must support AVX2 ([`available`]).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
pub(super) unsafe fn row(
    rs: &RowSampling,
    scratch: &RenderScratch,
    img: &[f32],
    enc: Encoding,
    out: &mut [f32],
) -> usize {
    use std::arch::x86_64::*;
    let ns = rs.ns as i32;
    let (path, winv, lut) = (
        scratch.path.as_ptr(),
        scratch.width_inv.as_ptr(),
        enc.lut.as_ptr(),
    );
    assert!(scratch.path.len() >= rs.ns && scratch.width_inv.len() >= rs.ns);
    assert!(img.len() >= rs.ns * rs.ns && rs.ns >= 1);
    let img = img.as_ptr();
    let steps = (enc.lut.len() - 1) as i32;
    let f = _mm256_set1_ps;
    let (zero, one, neg1, nsf) = (f(0.0), f(1.0), f(-1.0), f(ns as f32));
    let last_row = f((ns - 1) as f32);
    let iota = _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0);
    let (rr0, drr, u0, du) = (f(rs.rr0), f(rs.drr), f(rs.u0), f(rs.du));
    let (kc, c_off) = (f(rs.kc), f(rs.c_off));
    let (one_i, ns_i, last_i) = (
        _mm256_set1_epi32(1),
        _mm256_set1_epi32(ns),
        _mm256_set1_epi32(ns - 1),
    );
    let (neg1_i, zero_i) = (_mm256_set1_epi32(-1), _mm256_setzero_si256());
    let (exposure, expose) = (f(enc.exposure), enc.exposure != 1.0);
    let (steps_f, steps_m1) = (f(steps as f32), _mm256_set1_epi32(steps - 1));
    let mut tail = [0.0f32; 8];
    for k in 0..out.len().div_ceil(8) {
        let xf = _mm256_add_ps(f((k * 8) as f32), iota);
        let rr = _mm256_add_ps(rr0, _mm256_mul_ps(drr, xf));
        let in_r = _mm256_and_ps(
            _mm256_cmp_ps::<_CMP_GT_OQ>(rr, neg1),
            _mm256_cmp_ps::<_CMP_LT_OQ>(rr, nsf),
        );
        let u = _mm256_add_ps(u0, _mm256_mul_ps(du, xf));
        // clamp(rr, 0, ns − 1); a NaN lane becomes 0 (max returns its second operand)
        let rc = _mm256_min_ps(_mm256_max_ps(rr, zero), last_row);
        let r0 = _mm256_cvttps_epi32(rc);
        let r1 = _mm256_min_epi32(_mm256_add_epi32(r0, one_i), last_i);
        let t = _mm256_sub_ps(rc, _mm256_cvtepi32_ps(r0));
        let lerp = |a: __m256, b: __m256, t: __m256| {
            _mm256_add_ps(a, _mm256_mul_ps(_mm256_sub_ps(b, a), t))
        };
        // r0 is monotonic along the row (rr is affine in x, rounding keeps the order), so
        // equal end lanes mean one row of the tables for all eight: loads, not gathers
        let first = _mm256_cvtsi256_si32(r0);
        let (pth, wi) = if first == _mm256_extract_epi32::<7>(r0) {
            let (i0, i1) = (first as usize, first.saturating_add(1).min(ns - 1) as usize);
            (
                lerp(f(*path.add(i0)), f(*path.add(i1)), t),
                lerp(f(*winv.add(i0)), f(*winv.add(i1)), t),
            )
        } else {
            (
                lerp(
                    _mm256_i32gather_ps::<4>(path, r0),
                    _mm256_i32gather_ps::<4>(path, r1),
                    t,
                ),
                lerp(
                    _mm256_i32gather_ps::<4>(winv, r0),
                    _mm256_i32gather_ps::<4>(winv, r1),
                    t,
                ),
            )
        };
        let cc = _mm256_add_ps(
            _mm256_mul_ps(_mm256_mul_ps(_mm256_sub_ps(u, pth), wi), kc),
            c_off,
        );
        let inside = _mm256_and_ps(
            in_r,
            _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GT_OQ>(cc, neg1),
                _mm256_cmp_ps::<_CMP_LT_OQ>(cc, nsf),
            ),
        );
        let (fr, fc) = (_mm256_floor_ps(rr), _mm256_floor_ps(cc));
        let (ty, tx) = (_mm256_sub_ps(rr, fr), _mm256_sub_ps(cc, fc));
        // the four taps: rows ir, ir + 1 and columns ic, ic + 1, each 0 outside the image
        // (read at an index clamped into it, then masked)
        let (ir, ic) = (_mm256_cvttps_epi32(fr), _mm256_cvttps_epi32(fc));
        let (ir1, ic1) = (_mm256_add_epi32(ir, one_i), _mm256_add_epi32(ic, one_i));
        let within = |v: __m256i| {
            _mm256_andnot_si256(_mm256_cmpgt_epi32(v, last_i), _mm256_cmpgt_epi32(v, neg1_i))
        };
        let clamp = |v: __m256i| _mm256_min_epi32(_mm256_max_epi32(v, zero_i), last_i);
        let (vr0, vr1, vc0, vc1) = (within(ir), within(ir1), within(ic), within(ic1));
        let (row0, row1) = (
            _mm256_mullo_epi32(clamp(ir), ns_i),
            _mm256_mullo_epi32(clamp(ir1), ns_i),
        );
        let (col0, col1) = (clamp(ic), clamp(ic1));
        let tap = |row: __m256i, col: __m256i, vr: __m256i, vc: __m256i| {
            let v = _mm256_i32gather_ps::<4>(img, _mm256_add_epi32(row, col));
            _mm256_and_ps(v, _mm256_castsi256_ps(_mm256_and_si256(vr, vc)))
        };
        let one_tx = _mm256_sub_ps(one, tx);
        let top = _mm256_add_ps(
            _mm256_mul_ps(tap(row0, col0, vr0, vc0), one_tx),
            _mm256_mul_ps(tap(row0, col1, vr0, vc1), tx),
        );
        let bot = _mm256_add_ps(
            _mm256_mul_ps(tap(row1, col0, vr1, vc0), one_tx),
            _mm256_mul_ps(tap(row1, col1, vr1, vc1), tx),
        );
        let mut v = _mm256_add_ps(
            _mm256_mul_ps(top, _mm256_sub_ps(one, ty)),
            _mm256_mul_ps(bot, ty),
        );
        v = _mm256_max_ps(v, zero);
        if expose {
            v = _mm256_mul_ps(v, exposure);
        }
        // encode: lanes ≤ 0 (and dark ones) give 0
        let lit = _mm256_and_ps(inside, _mm256_cmp_ps::<_CMP_GT_OQ>(v, zero));
        let x = _mm256_mul_ps(_mm256_min_ps(v, one), steps_f);
        let i = _mm256_min_epi32(_mm256_max_epi32(_mm256_cvttps_epi32(x), zero_i), steps_m1);
        let l0 = _mm256_i32gather_ps::<4>(lut, i);
        let l1 = _mm256_i32gather_ps::<4>(lut, _mm256_add_epi32(i, one_i));
        let e = _mm256_add_ps(
            l0,
            _mm256_mul_ps(
                _mm256_sub_ps(l1, l0),
                _mm256_sub_ps(x, _mm256_cvtepi32_ps(i)),
            ),
        );
        let e = _mm256_and_ps(e, lit);
        match out.get_mut(k * 8..k * 8 + 8) {
            Some(chunk) => _mm256_storeu_ps(chunk.as_mut_ptr(), e),
            None => {
                // the row's last pixels: lanes past its end are computed and dropped
                _mm256_storeu_ps(tail.as_mut_ptr(), e);
                let rest = &mut out[k * 8..];
                let len = rest.len();
                rest.copy_from_slice(&tail[..len]);
            }
        }
    }
    out.len()
}

/// Not built off x86-64 ([`available`] is false there).
///
/// # Safety
/// Never called.
#[cfg(not(target_arch = "x86_64"))]
pub(super) unsafe fn row(
    _: &RowSampling,
    _: &RenderScratch,
    _: &[f32],
    _: Encoding,
    _: &mut [f32],
) -> usize {
    0
}
