//! AVX2 builds of the renderer's lanes noise ([`super::perlin4_lanes_cached`],
//! [`super::perlin3_lanes_cached`]), written with intrinsics because LLVM keeps much of
//! the portable `[f32; 8]` code in 128-bit registers and on the stack.
//!
//! The values are identical to the portable lanes code and hence to the scalar reference
//! (tested): the same `f32` operations in the same order, never a fused multiply-add.
//! What differs is the common case of the renderer, where the 8 points of a batch lie in
//! one or two noise cells (samples are ordered by slice, then pixel): the cells' corner
//! gradients are then looked up once and broadcast (and, for two cells, chosen per lane
//! by a blend), instead of being gathered and decoded lane by lane. A batch that spans
//! three or more cells gets each cell's noise computed on all lanes the same way, and
//! every lane keeps its own cell's.

use super::{corners3, mnoise_lanes, Lanes, NoiseCache, NoiseKind, GRAD3, GRAD4};
use std::arch::x86_64::*;

/// [`super::ffloor_lane`] on 8 lanes: truncation of the clamped value, corrected down.
#[inline(always)]
unsafe fn ffloor(x: __m256) -> __m256 {
    let i = _mm256_cvtepi32_ps(trunc(x));
    let lt = _mm256_cmp_ps::<_CMP_LT_OQ>(x, i);
    _mm256_blendv_ps(i, _mm256_sub_ps(i, _mm256_set1_ps(1.0)), lt)
}

/// [`super::trunc_i32`] on 8 lanes (`max` returns its second operand for NaN, as
/// `f32::max` returns the non-NaN one).
#[inline(always)]
unsafe fn trunc(x: __m256) -> __m256i {
    let c = _mm256_min_ps(
        _mm256_max_ps(x, _mm256_set1_ps(-2_147_483_648.0)),
        _mm256_set1_ps(2_147_483_520.0),
    );
    _mm256_cvttps_epi32(c)
}

/// [`super::split_lanes`]: the cell (0..=255) and the fraction.
#[inline(always)]
unsafe fn split(x: __m256) -> (__m256i, __m256) {
    let fl = ffloor(x);
    let i = _mm256_and_si256(trunc(fl), _mm256_set1_epi32(255));
    (i, _mm256_sub_ps(x, fl))
}

/// `t³ (t (6t − 15) + 10)`, as [`super::fade`] groups it.
#[inline(always)]
unsafe fn fade(t: __m256) -> __m256 {
    let t3 = _mm256_mul_ps(_mm256_mul_ps(t, t), t);
    let inner = _mm256_add_ps(
        _mm256_mul_ps(
            t,
            _mm256_sub_ps(_mm256_mul_ps(t, _mm256_set1_ps(6.0)), _mm256_set1_ps(15.0)),
        ),
        _mm256_set1_ps(10.0),
    );
    _mm256_mul_ps(t3, inner)
}

/// `a + t (b − a)`, as [`super::lerp`].
#[inline(always)]
unsafe fn lerp(t: __m256, a: __m256, b: __m256) -> __m256 {
    _mm256_add_ps(a, _mm256_mul_ps(t, _mm256_sub_ps(b, a)))
}

/// The cells of a batch when it spans at most two: lane 0's key `a`, another key `b`
/// (`= a` when all lanes share one) and the mask of the lanes in `a` (all bits set per
/// lane); `None` for three or more.
#[inline(always)]
unsafe fn two_cells(key: __m256i) -> Option<(u32, u32, __m256)> {
    let first = _mm256_permutevar8x32_epi32(key, _mm256_setzero_si256());
    let in_a = _mm256_cmpeq_epi32(key, first);
    let bits = _mm256_movemask_ps(_mm256_castsi256_ps(in_a)) as u32;
    let mut keys = [0u32; 8];
    _mm256_storeu_si256(keys.as_mut_ptr() as *mut __m256i, key);
    let a = keys[0];
    if bits == 0xff {
        return Some((a, a, _mm256_castsi256_ps(in_a)));
    }
    let b = keys[(!bits & 0xff).trailing_zeros() as usize];
    let in_b = _mm256_cmpeq_epi32(key, _mm256_set1_epi32(b as i32));
    let both = _mm256_movemask_ps(_mm256_castsi256_ps(_mm256_or_si256(in_a, in_b)));
    (both == 0xff).then_some((a, b, _mm256_castsi256_ps(in_a)))
}

#[inline(always)]
unsafe fn load(p: &Lanes) -> __m256 {
    _mm256_loadu_ps(p.as_ptr())
}

#[inline(always)]
unsafe fn store(v: __m256) -> Lanes {
    let mut o = [0.0f32; 8];
    _mm256_storeu_ps(o.as_mut_ptr(), v);
    o
}

/// A gradient table with every component repeated over the 8 lanes, so a product with a
/// lane vector takes its factor straight from memory.
#[repr(C, align(32))]
struct Wide<const C: usize, const N: usize>([[[f32; 8]; C]; N]);

impl<const C: usize, const N: usize> Wide<C, N> {
    const fn of(table: &[[f32; C]; N]) -> Self {
        let mut w = [[[0.0f32; 8]; C]; N];
        let mut h = 0;
        while h < N {
            let mut c = 0;
            while c < C {
                w[h][c] = [table[h][c]; 8];
                c += 1;
            }
            h += 1;
        }
        Wide(w)
    }
}

/// [`GRAD4`], wide.
static GRAD4_WIDE: Wide<4, 32> = Wide::of(&GRAD4);
/// [`GRAD3`], wide.
static GRAD3_WIDE: Wide<3, 16> = Wide::of(&GRAD3);

/// `g · (dx, dy, dz, dw)` summed left to right, as [`super::grad4`], with a wide gradient.
#[inline(always)]
unsafe fn dot4w(g: &[[f32; 8]; 4], d: [__m256; 4]) -> __m256 {
    let s = _mm256_add_ps(
        _mm256_mul_ps(_mm256_load_ps(g[0].as_ptr()), d[0]),
        _mm256_mul_ps(_mm256_load_ps(g[1].as_ptr()), d[1]),
    );
    let s = _mm256_add_ps(s, _mm256_mul_ps(_mm256_load_ps(g[2].as_ptr()), d[2]));
    _mm256_add_ps(s, _mm256_mul_ps(_mm256_load_ps(g[3].as_ptr()), d[3]))
}

/// `g · (dx, dy, dz)` summed left to right, as [`super::grad3`], with a wide gradient.
#[inline(always)]
unsafe fn dot3w(g: &[[f32; 8]; 3], d: [__m256; 3]) -> __m256 {
    let s = _mm256_add_ps(
        _mm256_mul_ps(_mm256_load_ps(g[0].as_ptr()), d[0]),
        _mm256_mul_ps(_mm256_load_ps(g[1].as_ptr()), d[1]),
    );
    _mm256_add_ps(s, _mm256_mul_ps(_mm256_load_ps(g[2].as_ptr()), d[2]))
}

/// [`super::perlin4_lanes_cached`], equal to it lane by lane.
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) unsafe fn perlin4_cached(p: &[Lanes; 4], cache: &mut NoiseCache) -> Lanes {
    let (xi, x) = split(load(&p[0]));
    let (yi, y) = split(load(&p[1]));
    let (zi, z) = split(load(&p[2]));
    let (wi, w) = split(load(&p[3]));
    let key = _mm256_or_si256(
        _mm256_or_si256(xi, _mm256_slli_epi32::<8>(yi)),
        _mm256_or_si256(_mm256_slli_epi32::<16>(zi), _mm256_slli_epi32::<24>(wi)),
    );
    let one = _mm256_set1_ps(1.0);
    let off = [
        [x, _mm256_sub_ps(x, one)],
        [y, _mm256_sub_ps(y, one)],
        [z, _mm256_sub_ps(z, one)],
        [w, _mm256_sub_ps(w, one)],
    ];
    // corner `ci`'s offsets (bit 0: x + 1, bit 1: y + 1, bit 2: z + 1, bit 3: w + 1)
    let o = |ci: usize| {
        [
            off[0][ci & 1],
            off[1][(ci >> 1) & 1],
            off[2][(ci >> 2) & 1],
            off[3][ci >> 3],
        ]
    };
    let f = [fade(x), fade(y), fade(z), fade(w)];
    let Some((ka, kb, in_a)) = two_cells(key) else {
        // three or more cells: each cell's noise on all lanes, kept where it applies
        return store(per_cell(key, |k| {
            let h = cache.corners4(k);
            tree16(|ci| dot4w(&GRAD4_WIDE.0[h[ci] as usize & 31], o(ci)), f)
        }));
    };
    let ha = cache.corners4(ka);
    let v = if kb == ka {
        tree16(|ci| dot4w(&GRAD4_WIDE.0[ha[ci] as usize & 31], o(ci)), f)
    } else {
        let hb = cache.corners4(kb);
        tree16(
            |ci| {
                let (a, b) = (
                    dot4w(&GRAD4_WIDE.0[ha[ci] as usize & 31], o(ci)),
                    dot4w(&GRAD4_WIDE.0[hb[ci] as usize & 31], o(ci)),
                );
                _mm256_blendv_ps(b, a, in_a)
            },
            f,
        )
    };
    store(v)
}

/// A batch whose lanes lie in several noise cells (`key` per lane): `value(k)` computes
/// the noise of every lane with cell `k`'s corner gradients, which is the right value for
/// the lanes in cell `k` (the same operations as for a batch in that cell alone); each
/// lane keeps its own cell's.
#[inline(always)]
unsafe fn per_cell(key: __m256i, mut value: impl FnMut(u32) -> __m256) -> __m256 {
    let mut keys = [0u32; 8];
    _mm256_storeu_si256(keys.as_mut_ptr() as *mut __m256i, key);
    let mut left = 0xffu32;
    let mut out = _mm256_setzero_ps();
    while left != 0 {
        let k = keys[left.trailing_zeros() as usize];
        let mask = _mm256_castsi256_ps(_mm256_cmpeq_epi32(key, _mm256_set1_epi32(k as i32)));
        out = _mm256_blendv_ps(out, value(k), mask);
        left &= !(_mm256_movemask_ps(mask) as u32);
    }
    out
}

/// Corners `c(b..b + 8)` blended as [`super::perlin3`] (and each half of
/// [`super::perlin4`]) does: along `x` by `fu`, then `y` by `fv`, then `z` by `fs`. `c` is
/// called with constants, so after inlining every corner stays in registers.
#[inline(always)]
unsafe fn tree8(c: impl Fn(usize) -> __m256, b: usize, [fu, fv, fs]: [__m256; 3]) -> __m256 {
    let x00 = lerp(fu, c(b), c(b + 1));
    let x10 = lerp(fu, c(b + 2), c(b + 3));
    let x01 = lerp(fu, c(b + 4), c(b + 5));
    let x11 = lerp(fu, c(b + 6), c(b + 7));
    lerp(fs, lerp(fv, x00, x10), lerp(fv, x01, x11))
}

/// The 16 corners `c(0..16)` blended as [`super::perlin4`] does: [`tree8`] over the
/// corners at `w` and at `w + 1`, then along `w` by `ft`.
#[inline(always)]
unsafe fn tree16(c: impl Fn(usize) -> __m256, [fu, fv, fs, ft]: [__m256; 4]) -> __m256 {
    let c0 = tree8(&c, 0, [fu, fv, fs]);
    lerp(ft, c0, tree8(&c, 8, [fu, fv, fs]))
}

/// [`super::perlin3_lanes_cached`], equal to it lane by lane.
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) unsafe fn perlin3_cached(p: &[Lanes; 3], cache: &mut NoiseCache) -> Lanes {
    let (xi, x) = split(load(&p[0]));
    let (yi, y) = split(load(&p[1]));
    let (zi, z) = split(load(&p[2]));
    let key = _mm256_or_si256(
        _mm256_or_si256(xi, _mm256_slli_epi32::<8>(yi)),
        _mm256_slli_epi32::<16>(zi),
    );
    let hash = |k: u32| {
        corners3(
            (k & 255) as usize,
            ((k >> 8) & 255) as usize,
            (k >> 16) as usize,
        )
    };
    let one = _mm256_set1_ps(1.0);
    let off = [
        [x, _mm256_sub_ps(x, one)],
        [y, _mm256_sub_ps(y, one)],
        [z, _mm256_sub_ps(z, one)],
    ];
    let o = |ci: usize| [off[0][ci & 1], off[1][(ci >> 1) & 1], off[2][ci >> 2]];
    let f = [fade(x), fade(y), fade(z)];
    let Some((ka, kb, in_a)) = two_cells(key) else {
        // three or more cells: each cell's noise on all lanes, kept where it applies
        return store(per_cell(key, |k| {
            let h = cache.c3.get(k, || hash(k));
            tree8(|ci| dot3w(&GRAD3_WIDE.0[h[ci] as usize & 15], o(ci)), 0, f)
        }));
    };
    let ha = cache.c3.get(ka, || hash(ka));
    let v = if kb == ka {
        tree8(|ci| dot3w(&GRAD3_WIDE.0[ha[ci] as usize & 15], o(ci)), 0, f)
    } else {
        let hb = cache.c3.get(kb, || hash(kb));
        tree8(
            |ci| {
                let (a, b) = (
                    dot3w(&GRAD3_WIDE.0[ha[ci] as usize & 15], o(ci)),
                    dot3w(&GRAD3_WIDE.0[hb[ci] as usize & 15], o(ci)),
                );
                _mm256_blendv_ps(b, a, in_a)
            },
            0,
            f,
        )
    };
    store(v)
}

/// [`NoiseKind::eval_lanes_cached`] with the AVX2 builds above; the same values.
///
/// # Safety
/// The CPU must support AVX2.
#[target_feature(enable = "avx2")]
#[inline]
pub(crate) unsafe fn eval_lanes_cached(
    kind: NoiseKind,
    p: &[Lanes; 4],
    cache: &mut NoiseCache,
) -> Lanes {
    match kind {
        NoiseKind::Perlin3 => perlin3_cached(&[p[0], p[1], p[2]], cache),
        NoiseKind::Perlin4 => perlin4_cached(p, cache),
        NoiseKind::Mnoise => mnoise_lanes(&[p[0], p[1], p[2]]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The AVX2 noise equals the scalar reference lane by lane, for batches in one, two
    /// and up to five noise cells (the broadcast, blended and per-cell paths), near cell
    /// borders and at integer points.
    #[test]
    fn avx2_noise_equals_scalar() {
        if !std::arch::is_x86_feature_detected!("avx2") {
            println!("skipped: this CPU has no AVX2");
            return;
        }
        let mut rng = ignis_core::Rng::new(11);
        let mut cache = NoiseCache::default();
        let mut paths = [0usize; 5];
        for round in 0..6000 {
            let cells = 1 + round % 5;
            let base: [f32; 4] = [0; 4].map(|_| rng.uniform(-40.0, 40.0).floor() as f32);
            let mut p = [[0.0f32; 8]; 4];
            for l in 0..8 {
                // lanes spread over `cells` neighbouring cells along x
                let cell = (l % cells) as f32;
                for (a, axis) in p.iter_mut().enumerate() {
                    let f = match round % 5 {
                        0 => 0.0,
                        1 => 1.0 - f32::EPSILON,
                        _ => rng.uniform(0.0, 1.0) as f32,
                    };
                    axis[l] = base[a] + f + if a == 0 { cell } else { 0.0 };
                }
            }
            paths[cells - 1] += 1;
            let q3 = [p[0], p[1], p[2]];
            // SAFETY: AVX2 was detected above.
            let (n4, n3) = unsafe {
                (
                    perlin4_cached(&p, &mut cache),
                    perlin3_cached(&q3, &mut cache),
                )
            };
            for l in 0..8 {
                let s4 = super::super::perlin4(p[0][l], p[1][l], p[2][l], p[3][l]);
                let s3 = super::super::perlin3(p[0][l], p[1][l], p[2][l]);
                assert!(
                    n4[l] == s4,
                    "perlin4 {cells} cells lane {l}: {} vs {s4}",
                    n4[l]
                );
                assert!(
                    n3[l] == s3,
                    "perlin3 {cells} cells lane {l}: {} vs {s3}",
                    n3[l]
                );
            }
        }
        assert!(paths.iter().all(|&n| n > 1000));
    }
}
