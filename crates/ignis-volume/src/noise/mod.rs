//! Gradient noise for the fire's micro detail.
//!
//! Source: fuller-procedural-volumetric-fire.txt §4.2, eq. (9); Perlin, "Improving Noise"
//! (SIGGRAPH 2002) for [`perlin3_f64`] / [`perlin3`] / [`perlin4`]; Olano, "Modified Noise
//! for Evaluation on Graphics Hardware" (2005) for [`mnoise`].
//!
//! - [`perlin3_f64`] is a line-by-line port of Perlin's reference `ImprovedNoise.noise`
//!   (reference permutation, 12+4 gradient set, quintic fade) in `f64`; tests compare it with
//!   values from an independent port. [`perlin3`] is the same algorithm in `f32`, which the
//!   renderer uses (it differs from the `f64` one only by rounding).
//! - [`perlin4`] extends it to 4-D as GPU Gems 2 ch. 26 does: hash `p[p[p[p[X]+Y]+Z]+W]`,
//!   32 gradients (every vector with one zero and three ±1 components), quintic fade.
//! - [`mnoise`] follows Olano's idea of replacing the permutation-table look-ups by an
//!   arithmetic hash (a permutation polynomial modulo a prime, here `(34x² + x) mod 289`
//!   as popularised by Gustavson & McEwan), 3-D only. It is *not* a bit-exact port of
//!   Olano's shader; it is "the cheaper option" in the same spirit. Time enters it only
//!   through the upward scroll of eq. (11).
//!
//! All functions have a base frequency of one lattice cell per unit (the paper's
//! "corrected" frequency), and are zero at integer lattice points.
//!
//! Which is the reference: [`perlin3_f64`] for the algorithm (checked against an
//! independent port's values); the scalar `f32` functions [`perlin3`], [`perlin4`],
//! [`mnoise`] (through [`NoiseKind::eval`] and [`turbulence`]) for the renderer — the
//! public API, what [`crate::mapping::shade`] and the renderer's reference path use. The
//! renderer's fast path evaluates 8 points at a time: `eval_lanes_cached` (the corner
//! hashes memoised) and its AVX2 build (`avx2.rs`); the tests check both, and the uncached
//! `eval_lanes` / `turbulence_lanes`, against the scalar functions value for value. Those
//! lanes variants are crate-private.

use serde::{Deserialize, Serialize};

#[cfg(target_arch = "x86_64")]
pub(crate) mod avx2;

/// Perlin's reference permutation of 0..=255.
pub const PERMUTATION: [u8; 256] = [
    151, 160, 137, 91, 90, 15, 131, 13, 201, 95, 96, 53, 194, 233, 7, 225, 140, 36, 103, 30, 69,
    142, 8, 99, 37, 240, 21, 10, 23, 190, 6, 148, 247, 120, 234, 75, 0, 26, 197, 62, 94, 252, 219,
    203, 117, 35, 11, 32, 57, 177, 33, 88, 237, 149, 56, 87, 174, 20, 125, 136, 171, 168, 68, 175,
    74, 165, 71, 134, 139, 48, 27, 166, 77, 146, 158, 231, 83, 111, 229, 122, 60, 211, 133, 230,
    220, 105, 92, 41, 55, 46, 245, 40, 244, 102, 143, 54, 65, 25, 63, 161, 1, 216, 80, 73, 209, 76,
    132, 187, 208, 89, 18, 169, 200, 196, 135, 130, 116, 188, 159, 86, 164, 100, 109, 198, 173,
    186, 3, 64, 52, 217, 226, 250, 124, 123, 5, 202, 38, 147, 118, 126, 255, 82, 85, 212, 207, 206,
    59, 227, 47, 16, 58, 17, 182, 189, 28, 42, 223, 183, 170, 213, 119, 248, 152, 2, 44, 154, 163,
    70, 221, 153, 101, 155, 167, 43, 172, 9, 129, 22, 39, 253, 19, 98, 108, 110, 79, 113, 224, 232,
    178, 185, 112, 104, 218, 246, 97, 228, 251, 34, 242, 193, 238, 210, 144, 12, 191, 179, 162,
    241, 81, 51, 145, 235, 249, 14, 239, 107, 49, 192, 214, 31, 181, 199, 106, 157, 184, 84, 204,
    176, 115, 121, 50, 45, 127, 4, 150, 254, 138, 236, 205, 93, 222, 114, 67, 29, 24, 72, 243, 141,
    128, 195, 78, 66, 215, 61, 156, 180,
];

/// The permutation repeated twice (`p[i] = p[i + 256]`), as in the reference code.
static P: [u8; 512] = {
    let mut p = [0u8; 512];
    let mut i = 0;
    while i < 512 {
        p[i] = PERMUTATION[i & 255];
        i += 1;
    }
    p
};

#[inline(always)]
fn perm(i: usize) -> usize {
    // SAFETY-free: every index below is < 512 by construction (masked inputs + table values).
    P[i & 511] as usize
}

#[inline(always)]
fn fade64(t: f64) -> f64 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

#[inline(always)]
fn lerp64(t: f64, a: f64, b: f64) -> f64 {
    a + t * (b - a)
}

#[inline(always)]
fn grad3_64(hash: usize, x: f64, y: f64, z: f64) -> f64 {
    let h = hash & 15;
    let u = if h < 8 { x } else { y };
    let v = if h < 4 {
        y
    } else if h == 12 || h == 14 {
        x
    } else {
        z
    };
    (if h & 1 == 0 { u } else { -u }) + (if h & 2 == 0 { v } else { -v })
}

/// Perlin's Improved Noise in 3-D, double precision: the reference implementation.
pub fn perlin3_f64(x: f64, y: f64, z: f64) -> f64 {
    let (fx, fy, fz) = (x.floor(), y.floor(), z.floor());
    let (xi, yi, zi) = (
        (fx as i64 & 255) as usize,
        (fy as i64 & 255) as usize,
        (fz as i64 & 255) as usize,
    );
    let (x, y, z) = (x - fx, y - fy, z - fz);
    let (u, v, w) = (fade64(x), fade64(y), fade64(z));
    let a = perm(xi) + yi;
    let aa = perm(a) + zi;
    let ab = perm(a + 1) + zi;
    let b = perm(xi + 1) + yi;
    let ba = perm(b) + zi;
    let bb = perm(b + 1) + zi;
    lerp64(
        w,
        lerp64(
            v,
            lerp64(
                u,
                grad3_64(perm(aa), x, y, z),
                grad3_64(perm(ba), x - 1.0, y, z),
            ),
            lerp64(
                u,
                grad3_64(perm(ab), x, y - 1.0, z),
                grad3_64(perm(bb), x - 1.0, y - 1.0, z),
            ),
        ),
        lerp64(
            v,
            lerp64(
                u,
                grad3_64(perm(aa + 1), x, y, z - 1.0),
                grad3_64(perm(ba + 1), x - 1.0, y, z - 1.0),
            ),
            lerp64(
                u,
                grad3_64(perm(ab + 1), x, y - 1.0, z - 1.0),
                grad3_64(perm(bb + 1), x - 1.0, y - 1.0, z - 1.0),
            ),
        ),
    )
}

#[inline(always)]
fn fade(t: f32) -> f32 {
    t * t * t * (t * (t * 6.0 - 15.0) + 10.0)
}

#[inline(always)]
fn lerp(t: f32, a: f32, b: f32) -> f32 {
    a + t * (b - a)
}

/// Perlin's 16 gradients (12 cube-edge directions + 4 repeats) as a table, so the
/// renderer's noise has no data-dependent branches. `g · (x, y, z)` equals the reference
/// `grad` bit for bit: the zero component adds an exact zero and the ±1 factors are exact.
static GRAD3: [[f32; 3]; 16] = {
    let mut g = [[0.0f32; 3]; 16];
    let mut h = 0;
    while h < 16 {
        // u and v as in the reference `grad`: u = x (h < 8) else y; v = y (h < 4),
        // x (h = 12, 14) else z; signs from bits 0 and 1.
        let su = if h & 1 == 0 { 1.0 } else { -1.0 };
        let sv = if h & 2 == 0 { 1.0 } else { -1.0 };
        let ui = if h < 8 { 0 } else { 1 };
        let vi = if h < 4 {
            1
        } else if h == 12 || h == 14 {
            0
        } else {
            2
        };
        g[h][ui] = su;
        g[h][vi] = sv;
        h += 1;
    }
    g
};

#[inline(always)]
fn grad3(hash: usize, x: f32, y: f32, z: f32) -> f32 {
    let g = &GRAD3[hash & 15];
    g[0] * x + g[1] * y + g[2] * z
}

/// `floor` without a libm call (x86-64 baseline has no `roundss`); exact for |x| < 2³¹.
#[inline(always)]
pub(crate) fn ffloor(x: f32) -> f32 {
    let i = x as i32 as f32;
    if x < i {
        i - 1.0
    } else {
        i
    }
}

/// Integer cell and fraction of a coordinate.
#[inline(always)]
fn split(x: f32) -> (usize, f32) {
    let f = ffloor(x);
    ((f as i32 & 255) as usize, x - f)
}

/// Improved Noise in 3-D, single precision (the renderer's version of [`perlin3_f64`]).
#[inline]
pub fn perlin3(x: f32, y: f32, z: f32) -> f32 {
    let (xi, x) = split(x);
    let (yi, y) = split(y);
    let (zi, z) = split(z);
    let (u, v, w) = (fade(x), fade(y), fade(z));
    let a = perm(xi) + yi;
    let aa = perm(a) + zi;
    let ab = perm(a + 1) + zi;
    let b = perm(xi + 1) + yi;
    let ba = perm(b) + zi;
    let bb = perm(b + 1) + zi;
    lerp(
        w,
        lerp(
            v,
            lerp(u, grad3(perm(aa), x, y, z), grad3(perm(ba), x - 1.0, y, z)),
            lerp(
                u,
                grad3(perm(ab), x, y - 1.0, z),
                grad3(perm(bb), x - 1.0, y - 1.0, z),
            ),
        ),
        lerp(
            v,
            lerp(
                u,
                grad3(perm(aa + 1), x, y, z - 1.0),
                grad3(perm(ba + 1), x - 1.0, y, z - 1.0),
            ),
            lerp(
                u,
                grad3(perm(ab + 1), x, y - 1.0, z - 1.0),
                grad3(perm(bb + 1), x - 1.0, y - 1.0, z - 1.0),
            ),
        ),
    )
}

/// The 32 4-D gradients (one zero component, three ±1), indexed like the branchy form:
/// bits 3–4 pick the zero component (x, y, z, w → 0..3 reversed: 0 ⇒ x is zero, …) and bits
/// 0–2 the signs of the remaining three in order.
static GRAD4: [[f32; 4]; 32] = {
    let mut g = [[0.0f32; 4]; 32];
    let mut h = 0;
    while h < 32 {
        let zero = h >> 3;
        let mut bit = 0;
        let mut c = 0;
        while c < 4 {
            if c != zero {
                g[h][c] = if h & (1 << bit) == 0 { 1.0 } else { -1.0 };
                bit += 1;
            }
            c += 1;
        }
        h += 1;
    }
    g
};

/// One of the 32 4-D gradients dotted with `(x, y, z, w)` (table look-up, no branches; the
/// zero component contributes an exact zero, so the sum equals the three-term form).
#[inline(always)]
fn grad4(hash: usize, x: f32, y: f32, z: f32, w: f32) -> f32 {
    let g = &GRAD4[hash & 31];
    g[0] * x + g[1] * y + g[2] * z + g[3] * w
}

/// Improved Noise in 4-D (GPU Gems 2 ch. 26 extension of Perlin 2002). Zero at integer
/// points; range within ±[`PERLIN4_BOUND`].
#[inline]
pub fn perlin4(x: f32, y: f32, z: f32, w: f32) -> f32 {
    let (xi, x) = split(x);
    let (yi, y) = split(y);
    let (zi, z) = split(z);
    let (wi, w) = split(w);
    let (fu, fv, fs, ft) = (fade(x), fade(y), fade(z), fade(w));
    // Hashes of the 16 corners: h[ix][iy][iz][iw].
    let a = perm(xi) + yi;
    let b = perm(xi + 1) + yi;
    let aa = perm(a) + zi;
    let ab = perm(a + 1) + zi;
    let ba = perm(b) + zi;
    let bb = perm(b + 1) + zi;
    let (aaa, aab) = (perm(aa) + wi, perm(aa + 1) + wi);
    let (aba, abb) = (perm(ab) + wi, perm(ab + 1) + wi);
    let (baa, bab) = (perm(ba) + wi, perm(ba + 1) + wi);
    let (bba, bbb) = (perm(bb) + wi, perm(bb + 1) + wi);
    let (x1, y1, z1, w1) = (x - 1.0, y - 1.0, z - 1.0, w - 1.0);
    let cube = |dw: usize, w: f32| {
        lerp(
            fs,
            lerp(
                fv,
                lerp(
                    fu,
                    grad4(perm(aaa + dw), x, y, z, w),
                    grad4(perm(baa + dw), x1, y, z, w),
                ),
                lerp(
                    fu,
                    grad4(perm(aba + dw), x, y1, z, w),
                    grad4(perm(bba + dw), x1, y1, z, w),
                ),
            ),
            lerp(
                fv,
                lerp(
                    fu,
                    grad4(perm(aab + dw), x, y, z1, w),
                    grad4(perm(bab + dw), x1, y, z1, w),
                ),
                lerp(
                    fu,
                    grad4(perm(abb + dw), x, y1, z1, w),
                    grad4(perm(bbb + dw), x1, y1, z1, w),
                ),
            ),
        )
    };
    lerp(ft, cube(0, w), cube(1, w1))
}

/// A proven bound on |[`perlin4`]|: `√3` (in practice values stay near ±1).
///
/// Proof. With fractions `x_k ∈ [0, 1]` (k = 1..4) and fades `f_k = fade(x_k)`, the noise
/// is `n = Σ_c w_c (g_c · d_c)` over the 16 corners `c`, with weights
/// `w_c = Π_k (1 − f_k or f_k)` (non-negative, summing to 1), offsets `d_ck = x_k` or
/// `x_k − 1`, and gradients `g_c` with one zero component and three ±1, so `|g_c|₂ = √3`.
/// 1. Cauchy–Schwarz per corner: `|g_c · d_c| ≤ √3 |d_c|₂`.
/// 2. Jensen (the square root is concave, `Σ w_c = 1`):
///    `|n| ≤ √3 Σ_c w_c |d_c|₂ ≤ √3 (Σ_c w_c |d_c|₂²)^½`.
/// 3. The weights factorise over the axes, so `Σ_c w_c |d_c|₂² = Σ_k q(x_k)` with
///    `q(x) = (1 − f) x² + f (1 − x)² = x² + f (1 − 2x)`.
/// 4. `q ≤ ¼` on `[0, 1]`: `q` is symmetric about ½ (`f(1 − x) = 1 − f(x)`); for `x < ½`,
///    `q(x) ≤ ¼ ⟺ f(x)(1 − 2x) ≤ (½ − x)(½ + x) ⟺ f(x) ≤ ¼ + x/2`. The fade is convex
///    on `[0, ½]` (`f'' = 60x(1 − x)(1 − 2x) ≥ 0`) with `f(0) = 0`, `f(½) = ½`, so
///    `f(x) ≤ x ≤ ¼ + x/2` there.
///
/// Hence `|n| ≤ √3 · (4 · ¼)^½ = √3 ≈ 1.732` (the looser axis-by-axis bound is 2). The
/// constant is rounded up; `f32` evaluation adds a few ulps, covered by the renderer's
/// margins. Tested on random points (`noise_within_proven_bounds`) and on `q ≤ ¼`.
pub const PERLIN4_BOUND: f32 = 1.732_051;

/// A proven bound on |[`perlin3`]| and |[`mnoise`]|: `√(3/2)`. The argument of
/// [`PERLIN4_BOUND`] with three axes and gradients with two ±1 components and one zero
/// (Perlin's 12 edge directions; M-noise uses `hash % 12` of the same set), so `|g|₂ = √2`
/// and `|n| ≤ √2 · (3 · ¼)^½ = √(3/2) ≈ 1.2247` (the axis-by-axis bound is 1.5).
pub const PERLIN3_BOUND: f32 = 1.224_745;

/// Olano-style permutation polynomial `(34x² + x) mod 289` on integers 0..289.
#[inline(always)]
fn mperm(x: f32) -> f32 {
    let v = (34.0 * x + 1.0) * x;
    v - ffloor(v * (1.0 / 289.0)) * 289.0
}

#[inline(always)]
fn mwrap(i: f32) -> f32 {
    i - ffloor(i * (1.0 / 289.0)) * 289.0
}

/// M-noise: 3-D gradient noise with an arithmetic (table-free) hash, after Olano (2005).
/// Zero at integer points; range about ±1.
#[inline]
pub fn mnoise(x: f32, y: f32, z: f32) -> f32 {
    let (fx, fy, fz) = (ffloor(x), ffloor(y), ffloor(z));
    let (x, y, z) = (x - fx, y - fy, z - fz);
    let (ix, iy, iz) = (mwrap(fx), mwrap(fy), mwrap(fz));
    let (u, v, w) = (fade(x), fade(y), fade(z));
    let hx0 = mperm(ix);
    let hx1 = mperm(mwrap(ix + 1.0));
    let h = |hx: f32, dy: f32, dz: f32| -> usize {
        let hy = mperm(mwrap(hx + iy + dy));
        mperm(mwrap(hy + iz + dz)) as usize
    };
    let g = |hash: usize, x: f32, y: f32, z: f32| grad3(hash % 12, x, y, z);
    lerp(
        w,
        lerp(
            v,
            lerp(
                u,
                g(h(hx0, 0.0, 0.0), x, y, z),
                g(h(hx1, 0.0, 0.0), x - 1.0, y, z),
            ),
            lerp(
                u,
                g(h(hx0, 1.0, 0.0), x, y - 1.0, z),
                g(h(hx1, 1.0, 0.0), x - 1.0, y - 1.0, z),
            ),
        ),
        lerp(
            v,
            lerp(
                u,
                g(h(hx0, 0.0, 1.0), x, y, z - 1.0),
                g(h(hx1, 0.0, 1.0), x - 1.0, y, z - 1.0),
            ),
            lerp(
                u,
                g(h(hx0, 1.0, 1.0), x, y - 1.0, z - 1.0),
                g(h(hx1, 1.0, 1.0), x - 1.0, y - 1.0, z - 1.0),
            ),
        ),
    )
}

// ---------------------------------------------------------------------------------------
// Batched ("lanes") noise: the renderer's fast path.
//
// The functions below evaluate [`LANES`] points at once in structure-of-arrays form. Every
// lane performs exactly the same `f32` operations in the same order as the scalar
// function it mirrors, so the results are equal value for value (tested); the only change
// is the layout: the floating-point work (floor, fade, gradient dot products, lerps) is
// written as loops over fixed-size arrays, which LLVM turns into SSE2 vector code on the
// x86-64 baseline, while the permutation-table look-ups (which cannot be vectorised
// without gathers) stay a short scalar loop. Gradients are built from the hash bits
// instead of being loaded from [`GRAD3`] / [`GRAD4`], which keeps them in vector
// registers; the bit formulas produce the very same `±1.0` / `0.0` values as the tables.
// ---------------------------------------------------------------------------------------

/// Number of points the batched noise evaluates together.
pub(crate) const LANES: usize = 8;

/// One `f32` per lane.
pub(crate) type Lanes = [f32; LANES];

const ONE_BITS: u32 = 0x3f80_0000; // 1.0f32

/// The gradient [`GRAD3`]`[h & 15]` computed from the bits of `h` (no table look-up).
#[inline(always)]
fn grad3_bits(h: u32) -> [f32; 3] {
    let h = h & 15;
    let su = ONE_BITS | ((h & 1) << 31);
    let sv = ONE_BITS | ((h & 2) << 30);
    let lt8 = h < 8;
    let lt4 = h < 4;
    let v_is_x = (h & 13) == 12; // h = 12 or 14
    let gx = if lt8 {
        su
    } else if v_is_x {
        sv
    } else {
        0
    };
    let gy = if !lt8 {
        su
    } else if lt4 {
        sv
    } else {
        0
    };
    let gz = if !lt4 && !v_is_x { sv } else { 0 };
    [f32::from_bits(gx), f32::from_bits(gy), f32::from_bits(gz)]
}

/// The gradient [`GRAD4`]`[h & 31]` computed from the bits of `h` (no table look-up):
/// bits 3–4 name the zero component, bits 0–2 the signs of the other three in order.
#[inline(always)]
fn grad4_bits(h: u32) -> [f32; 4] {
    let zero = (h >> 3) & 3;
    let s0 = ONE_BITS | ((h & 1) << 31);
    let s1 = ONE_BITS | ((h & 2) << 30);
    let s2 = ONE_BITS | ((h & 4) << 29);
    let gx = if zero == 0 { 0 } else { s0 };
    let gy = if zero == 1 {
        0
    } else if zero == 0 {
        s0
    } else {
        s1
    };
    let gz = if zero == 2 {
        0
    } else if zero < 2 {
        s1
    } else {
        s2
    };
    let gw = if zero == 3 { 0 } else { s2 };
    [
        f32::from_bits(gx),
        f32::from_bits(gy),
        f32::from_bits(gz),
        f32::from_bits(gw),
    ]
}

/// `x` truncated towards zero, as `x as i32` for `|x| < 2³¹`, in a form that vectorises.
///
/// Rust's `as i32` saturates (and maps NaN to 0), which LLVM lowers lane by lane; clamping
/// first and then converting without the checks is one SSE2 `cvttps2dq`. The clamp makes
/// the conversion always defined (`f32::max` also turns NaN into the lower bound), so the
/// only difference from `as i32` is for |x| ≥ 2³¹ and NaN, where noise has no meaning.
#[inline(always)]
fn trunc_i32(x: f32) -> i32 {
    // 2147483520 is the largest f32 below 2³¹. Not `clamp`: that keeps NaN.
    #[allow(clippy::manual_clamp)]
    let c = x.max(-2_147_483_648.0).min(2_147_483_520.0);
    // SAFETY: `c` is finite and within i32's range, which is all `to_int_unchecked` needs.
    unsafe { c.to_int_unchecked::<i32>() }
}

/// [`ffloor`] via [`trunc_i32`]: the same value for |x| < 2³¹.
#[inline(always)]
fn ffloor_lane(x: f32) -> f32 {
    let i = trunc_i32(x) as f32;
    if x < i {
        i - 1.0
    } else {
        i
    }
}

/// [`split`] on every lane: integer cell (0..=255) and fraction.
#[inline(always)]
fn split_lanes(x: &Lanes) -> ([u32; LANES], Lanes) {
    let mut i = [0u32; LANES];
    let mut f = [0.0f32; LANES];
    for l in 0..LANES {
        let fl = ffloor_lane(x[l]);
        i[l] = (trunc_i32(fl) & 255) as u32;
        f[l] = x[l] - fl;
    }
    (i, f)
}

/// [`mperm`] with [`ffloor_lane`].
#[inline(always)]
fn mperm_lane(x: f32) -> f32 {
    let v = (34.0 * x + 1.0) * x;
    v - ffloor_lane(v * (1.0 / 289.0)) * 289.0
}

/// [`mwrap`] with [`ffloor_lane`].
#[inline(always)]
fn mwrap_lane(i: f32) -> f32 {
    i - ffloor_lane(i * (1.0 / 289.0)) * 289.0
}

#[inline(always)]
fn fade_lanes(x: &Lanes) -> Lanes {
    let mut o = [0.0f32; LANES];
    for l in 0..LANES {
        o[l] = fade(x[l]);
    }
    o
}

/// `lerp(t, a, b)` on every lane.
#[inline(always)]
fn lerp_lanes(t: &Lanes, a: &Lanes, b: &Lanes) -> Lanes {
    let mut o = [0.0f32; LANES];
    for l in 0..LANES {
        o[l] = lerp(t[l], a[l], b[l]);
    }
    o
}

/// Trilinear-with-fade blend of 8 corner values indexed `ix + 2 iy + 4 iz`, in the
/// reference order (x innermost, then y, then z).
#[inline(always)]
fn blend8(c: &[Lanes], fu: &Lanes, fv: &Lanes, fw: &Lanes) -> Lanes {
    let x00 = lerp_lanes(fu, &c[0], &c[1]);
    let x10 = lerp_lanes(fu, &c[2], &c[3]);
    let x01 = lerp_lanes(fu, &c[4], &c[5]);
    let x11 = lerp_lanes(fu, &c[6], &c[7]);
    let y0 = lerp_lanes(fv, &x00, &x10);
    let y1 = lerp_lanes(fv, &x01, &x11);
    lerp_lanes(fw, &y0, &y1)
}

/// The 8 corner hashes of [`perlin3`]'s cell `(xi, yi, zi)` (each 0..=255), indexed
/// `ix + 2 iy + 4 iz`: the values `perm(…)` that pick the corners' gradients.
#[inline(always)]
fn corners3(xi: usize, yi: usize, zi: usize) -> [u8; 8] {
    let a = perm(xi) + yi;
    let aa = perm(a) + zi;
    let ab = perm(a + 1) + zi;
    let b = perm(xi + 1) + yi;
    let ba = perm(b) + zi;
    let bb = perm(b + 1) + zi;
    let mut h = [0u8; 8];
    for (c, base) in [aa, ba, ab, bb].into_iter().enumerate() {
        h[c] = perm(base) as u8;
        h[c + 4] = perm(base + 1) as u8;
    }
    h
}

/// The 16 corner hashes of [`perlin4`]'s cell `(xi, yi, zi, wi)` (each 0..=255), indexed
/// `ix + 2 iy + 4 iz + 8 iw`.
#[inline(always)]
fn corners4(xi: usize, yi: usize, zi: usize, wi: usize) -> [u8; 16] {
    corners4_with(xi, yi, [zi, zi + 1], [wi, wi + 1])
}

/// [`corners4`] with the cell's lower and upper lattice indices along `z` and `w` given
/// (`[zi, zi + 1]` there; a periodic lattice wraps the upper one to 0 at its last cell).
/// The hash of a corner depends only on its indices, so neighbouring cells agree.
#[inline(always)]
fn corners4_with(xi: usize, yi: usize, [z0, z1]: [usize; 2], [w0, w1]: [usize; 2]) -> [u8; 16] {
    let a = perm(xi) + yi;
    let b = perm(xi + 1) + yi;
    let (pa, pb) = (perm(a), perm(b));
    let (pa1, pb1) = (perm(a + 1), perm(b + 1));
    // (x, y, z) corners in the order ix + 2 iy + 4 iz
    let xyz = [
        perm(pa + z0),
        perm(pb + z0),
        perm(pa1 + z0),
        perm(pb1 + z0),
        perm(pa + z1),
        perm(pb + z1),
        perm(pa1 + z1),
        perm(pb1 + z1),
    ];
    let mut h = [0u8; 16];
    for (c, base) in xyz.into_iter().enumerate() {
        h[c] = perm(base + w0) as u8;
        h[c + 8] = perm(base + w1) as u8;
    }
    h
}

/// A 4-D noise lattice periodic along `z` and `w` (the axes a fire's noise moves along in
/// time, eq. 11): `period = [Pz, Pw]` cells (1..=256 each) at the octave being
/// evaluated. The coordinates are first wrapped into `[0, P)` ([`wrap_coordinate`]) and
/// the last cell's upper corner is the first cell's lower one, so the noise is
/// continuous and `noise(z + Pz) = noise(z)`, `noise(w + Pw) = noise(w)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Wrap {
    pub(crate) period: [u32; 2],
}

impl Wrap {
    /// The corner hashes of cell `(x, y, z, w)` (`z < Pz`, `w < Pw`) of this lattice.
    #[inline(always)]
    fn corners(&self, [x, y, z, w]: [u32; 4]) -> [u8; 16] {
        let up = |i: u32, p: u32| if i + 1 >= p { 0 } else { i + 1 } as usize;
        let [pz, pw] = self.period;
        corners4_with(
            x as usize,
            y as usize,
            [z as usize, up(z, pz)],
            [w as usize, up(w, pw)],
        )
    }

    /// Whether cell `(z, w)` is a last one, whose corners differ from [`corners4`]'s.
    #[inline(always)]
    fn at_seam(&self, z: u32, w: u32) -> bool {
        z + 1 >= self.period[0] || w + 1 >= self.period[1]
    }
}

/// `x` wrapped into `[0, period)` (`period` > 0): `x − period · ⌊x / period⌋`, with the
/// rounding case `period` itself mapped to 0.
#[inline(always)]
pub(crate) fn wrap_coordinate(x: f32, period: f32) -> f32 {
    let r = x - period * ffloor(x / period);
    if r >= period || r < 0.0 {
        0.0
    } else {
        r
    }
}

/// [`wrap_coordinate`] on every lane, with [`ffloor_lane`] so that it vectorises (the
/// scalar `ffloor`'s saturating cast is lowered lane by lane, and this wrap runs twice per
/// octave for every sample of a looping render): the same values for `|x / period| < 2³¹`.
#[inline(always)]
pub(crate) fn wrap_lanes(x: &mut Lanes, period: f32) {
    for v in x.iter_mut() {
        let r = *v - period * ffloor_lane(*v / period);
        *v = if r >= period || r < 0.0 { 0.0 } else { r };
    }
}

/// [`perlin4`] on the periodic lattice `wrap` (the point's `z`, `w` already wrapped by
/// [`wrap_coordinate`]); equal to [`perlin4`] away from the last cells.
#[inline]
pub(crate) fn perlin4_wrapped(p: [f32; 4], wrap: Wrap) -> f32 {
    let lanes = p.map(|v| [v; LANES]);
    perlin4_lanes_with(&lanes, |x, y, z, w| wrap.corners([x, y, z, w]))[0]
}

/// A direct-mapped memo of lattice-cell corner hashes (`N` = 8 for [`perlin3`], 16 for
/// [`perlin4`]), keyed by the cell's integer coordinates packed into a `u32` (8 bits
/// each). A renderer's samples fall into few distinct noise cells (the 4th coordinate,
/// time, is the same for a whole frame), so almost every look-up hits and replaces 14
/// (3-D) or 30 (4-D) dependent permutation-table reads by one compare and one copy.
/// Entries always hold the exact hashes of their key, so results are unchanged.
pub(crate) struct HashCache<const N: usize> {
    keys: Box<[u32]>,
    vals: Box<[[u8; N]]>,
}

const CACHE_BITS: u32 = 11;

impl<const N: usize> HashCache<N> {
    #[inline(always)]
    fn slot(key: u32) -> usize {
        (key.wrapping_mul(0x9E37_79B1) >> (32 - CACHE_BITS)) as usize
    }

    fn with(init: [u8; N]) -> Self {
        // every entry starts as the (valid) entry of key u32::MAX = cell (255, 255, 255, 255)
        HashCache {
            keys: vec![u32::MAX; 1 << CACHE_BITS].into_boxed_slice(),
            vals: vec![init; 1 << CACHE_BITS].into_boxed_slice(),
        }
    }

    #[inline(always)]
    fn get(&mut self, key: u32, compute: impl FnOnce() -> [u8; N]) -> [u8; N] {
        let i = Self::slot(key);
        if self.keys[i] != key {
            self.keys[i] = key;
            self.vals[i] = compute();
        }
        self.vals[i]
    }
}

impl Default for HashCache<8> {
    fn default() -> Self {
        Self::with(corners3(255, 255, 255))
    }
}

impl Default for HashCache<16> {
    fn default() -> Self {
        Self::with(corners4(255, 255, 255, 255))
    }
}

/// Memos for [`NoiseKind::eval_lanes_cached`], and the periodic lattice ([`Wrap`]) the
/// 4-D noise is evaluated on, if any (set per octave by the renderer).
#[derive(Default)]
pub(crate) struct NoiseCache {
    c3: HashCache<8>,
    c4: HashCache<16>,
    pub(crate) wrap: Option<Wrap>,
}

impl NoiseCache {
    /// The corner hashes of 4-D cell `key` (packed as [`perlin4_lanes_cached`] packs it)
    /// on the current lattice: memoised, except a periodic lattice's last cells (the only
    /// ones whose hashes differ from the plain lattice's, so the memo stays valid for both).
    #[inline(always)]
    pub(crate) fn corners4(&mut self, key: u32) -> [u8; 16] {
        let c = [key & 255, (key >> 8) & 255, (key >> 16) & 255, key >> 24];
        match self.wrap {
            Some(w) if w.at_seam(c[2], c[3]) => w.corners(c),
            _ => self.c4.get(key, || {
                corners4(c[0] as usize, c[1] as usize, c[2] as usize, c[3] as usize)
            }),
        }
    }
}

/// [`perlin3`] on [`LANES`] points (`p[axis][lane]`); equal to it lane by lane.
#[cfg(test)]
#[inline]
pub(crate) fn perlin3_lanes(p: &[Lanes; 3]) -> Lanes {
    perlin3_lanes_with(p, |xi, yi, zi| {
        corners3(xi as usize, yi as usize, zi as usize)
    })
}

/// [`perlin3_lanes`] with the corner hashes from `cache`.
#[inline(always)]
pub(crate) fn perlin3_lanes_cached(p: &[Lanes; 3], cache: &mut HashCache<8>) -> Lanes {
    perlin3_lanes_with(p, |xi, yi, zi| {
        cache.get(xi | yi << 8 | zi << 16, || {
            corners3(xi as usize, yi as usize, zi as usize)
        })
    })
}

#[inline(always)]
fn perlin3_lanes_with(p: &[Lanes; 3], mut hash: impl FnMut(u32, u32, u32) -> [u8; 8]) -> Lanes {
    let (xi, x) = split_lanes(&p[0]);
    let (yi, y) = split_lanes(&p[1]);
    let (zi, z) = split_lanes(&p[2]);
    let (u, v, w) = (fade_lanes(&x), fade_lanes(&y), fade_lanes(&z));
    // corner hashes, scalar: h[ix + 2 iy + 4 iz][lane]
    // gathered per lane as a little-endian u64, then spread out corner by corner (see
    // `perlin4_lanes_with`)
    let mut all = [0u64; LANES];
    for l in 0..LANES {
        all[l] = u64::from_le_bytes(hash(xi[l], yi[l], zi[l]));
    }
    let mut h = [[0u32; LANES]; 8];
    for (c, hc) in h.iter_mut().enumerate() {
        for l in 0..LANES {
            hc[l] = ((all[l] >> (8 * c)) & 255) as u32;
        }
    }
    // gradient · offset per corner, vectorised over lanes
    let mut d = [[0.0f32; LANES]; 8];
    for (c, dc) in d.iter_mut().enumerate() {
        let (ox, oy, oz) = ((c & 1) as f32, ((c >> 1) & 1) as f32, (c >> 2) as f32);
        for l in 0..LANES {
            let g = grad3_bits(h[c][l]);
            // `x - 0.0` is `x` exactly, so this is the scalar's `x` or `x - 1.0`
            dc[l] = g[0] * (x[l] - ox) + g[1] * (y[l] - oy) + g[2] * (z[l] - oz);
        }
    }
    blend8(&d, &u, &v, &w)
}

/// [`perlin4`] on [`LANES`] points (`p[axis][lane]`); equal to it lane by lane.
#[cfg(test)]
#[inline]
pub(crate) fn perlin4_lanes(p: &[Lanes; 4]) -> Lanes {
    perlin4_lanes_with(p, |xi, yi, zi, wi| {
        corners4(xi as usize, yi as usize, zi as usize, wi as usize)
    })
}

/// [`perlin4_lanes`] with the corner hashes from `cache` (on its lattice, [`Wrap`]).
#[inline(always)]
pub(crate) fn perlin4_lanes_cached(p: &[Lanes; 4], cache: &mut NoiseCache) -> Lanes {
    perlin4_lanes_with(p, |xi, yi, zi, wi| {
        cache.corners4(xi | yi << 8 | zi << 16 | wi << 24)
    })
}

#[inline(always)]
fn perlin4_lanes_with(
    p: &[Lanes; 4],
    mut hash: impl FnMut(u32, u32, u32, u32) -> [u8; 16],
) -> Lanes {
    let (xi, x) = split_lanes(&p[0]);
    let (yi, y) = split_lanes(&p[1]);
    let (zi, z) = split_lanes(&p[2]);
    let (wi, w) = split_lanes(&p[3]);
    let (fu, fv, fs, ft) = (
        fade_lanes(&x),
        fade_lanes(&y),
        fade_lanes(&z),
        fade_lanes(&w),
    );
    // corner hashes, scalar: h[ix + 2 iy + 4 iz + 8 iw][lane]
    // gathered per lane as two little-endian u64 halves, then spread out corner by
    // corner with shifts across the lanes (vector code, unlike byte-wise transposition)
    let mut half = [[0u64; LANES]; 2];
    for l in 0..LANES {
        let hl = hash(xi[l], yi[l], zi[l], wi[l]);
        let (lo, hi) = hl.split_at(8);
        half[0][l] = u64::from_le_bytes(lo.try_into().expect("8 bytes"));
        half[1][l] = u64::from_le_bytes(hi.try_into().expect("8 bytes"));
    }
    let mut h = [[0u32; LANES]; 16];
    for (c, hc) in h.iter_mut().enumerate() {
        let src = &half[c / 8];
        for l in 0..LANES {
            hc[l] = ((src[l] >> (8 * (c % 8))) & 255) as u32;
        }
    }
    let mut d = [[0.0f32; LANES]; 16];
    for (c, dc) in d.iter_mut().enumerate() {
        let (ox, oy) = ((c & 1) as f32, ((c >> 1) & 1) as f32);
        let (oz, ow) = (((c >> 2) & 1) as f32, (c >> 3) as f32);
        for l in 0..LANES {
            let g = grad4_bits(h[c][l]);
            dc[l] =
                g[0] * (x[l] - ox) + g[1] * (y[l] - oy) + g[2] * (z[l] - oz) + g[3] * (w[l] - ow);
        }
    }
    let c0 = blend8(&d[..8], &fu, &fv, &fs);
    let c1 = blend8(&d[8..], &fu, &fv, &fs);
    lerp_lanes(&ft, &c0, &c1)
}

/// [`mnoise`] on [`LANES`] points (`p[axis][lane]`); equal to it lane by lane. The
/// arithmetic hash is all floating point, so here everything vectorises.
#[inline(always)]
pub(crate) fn mnoise_lanes(p: &[Lanes; 3]) -> Lanes {
    let mut f = [[0.0f32; LANES]; 3];
    let mut i = [[0.0f32; LANES]; 3];
    for a in 0..3 {
        for l in 0..LANES {
            let fl = ffloor_lane(p[a][l]);
            f[a][l] = p[a][l] - fl;
            i[a][l] = mwrap_lane(fl);
        }
    }
    let (u, v, w) = (fade_lanes(&f[0]), fade_lanes(&f[1]), fade_lanes(&f[2]));
    let mut hx = [[0.0f32; LANES]; 2];
    for l in 0..LANES {
        hx[0][l] = mperm_lane(i[0][l]);
        hx[1][l] = mperm_lane(mwrap_lane(i[0][l] + 1.0));
    }
    let mut d = [[0.0f32; LANES]; 8];
    for (c, dc) in d.iter_mut().enumerate() {
        let (cx, cy, cz) = (c & 1, (c >> 1) & 1, c >> 2);
        let (oy, oz) = (cy as f32, cz as f32);
        for l in 0..LANES {
            let hy = mperm_lane(mwrap_lane(hx[cx][l] + i[1][l] + oy));
            let hash = mperm_lane(mwrap_lane(hy + i[2][l] + oz));
            // `hash % 12` in floating point: `hash` is an integer below 289 and `/ 12.0` is
            // correctly rounded, so the floor is exact.
            let m = hash - ffloor_lane(hash / 12.0) * 12.0;
            let g = grad3_bits(trunc_i32(m) as u32);
            dc[l] = g[0] * (f[0][l] - cx as f32) + g[1] * (f[1][l] - oy) + g[2] * (f[2][l] - oz);
        }
    }
    blend8(&d, &u, &v, &w)
}

/// Which noise function drives the micro detail (Table 1's three rows).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum NoiseKind {
    /// 3-D Improved Perlin noise; time enters only through the upward scroll of eq. (11).
    Perlin3,
    /// 4-D Improved Perlin noise; the fourth coordinate is time (eq. 11). The default.
    #[default]
    Perlin4,
    /// M-noise (3-D, arithmetic hash), the cheaper option.
    Mnoise,
}

impl NoiseKind {
    /// One octave at noise-space position `p` (`p[3]` is time).
    #[inline(always)]
    pub fn eval(self, p: [f32; 4]) -> f32 {
        match self {
            NoiseKind::Perlin3 => perlin3(p[0], p[1], p[2]),
            NoiseKind::Perlin4 => perlin4(p[0], p[1], p[2], p[3]),
            NoiseKind::Mnoise => mnoise(p[0], p[1], p[2]),
        }
    }

    /// [`NoiseKind::eval`] on [`LANES`] points at once (`p[axis][lane]`); equal to it lane
    /// by lane.
    #[cfg(test)]
    #[inline(always)]
    pub(crate) fn eval_lanes(self, p: &[Lanes; 4]) -> Lanes {
        match self {
            NoiseKind::Perlin3 => perlin3_lanes(&[p[0], p[1], p[2]]),
            NoiseKind::Perlin4 => perlin4_lanes(p),
            NoiseKind::Mnoise => mnoise_lanes(&[p[0], p[1], p[2]]),
        }
    }

    /// [`NoiseKind::eval_lanes`] with the permutation hashes memoised in `cache`; the same
    /// values.
    #[inline(always)]
    pub(crate) fn eval_lanes_cached(self, p: &[Lanes; 4], cache: &mut NoiseCache) -> Lanes {
        match self {
            NoiseKind::Perlin3 => perlin3_lanes_cached(&[p[0], p[1], p[2]], &mut cache.c3),
            NoiseKind::Perlin4 => perlin4_lanes_cached(p, cache),
            NoiseKind::Mnoise => mnoise_lanes(&[p[0], p[1], p[2]]),
        }
    }

    /// A proven bound on |noise| for this kind (see [`PERLIN4_BOUND`]): `√(3/2)` for the
    /// 3-D noises (Perlin 3-D and M-noise share the gradient set and the fade), `√3` for
    /// 4-D.
    pub fn bound(self) -> f32 {
        match self {
            NoiseKind::Perlin3 | NoiseKind::Mnoise => PERLIN3_BOUND,
            NoiseKind::Perlin4 => PERLIN4_BOUND,
        }
    }

    /// Name used in fire files and benchmark output.
    pub fn name(self) -> &'static str {
        match self {
            NoiseKind::Perlin3 => "perlin3",
            NoiseKind::Perlin4 => "perlin4",
            NoiseKind::Mnoise => "mnoise",
        }
    }
}

/// Turbulence, eq. (9): `Σ_{i<octaves} gain^i · noise(p · lacunarity^i)`.
///
/// The paper's sum runs `i = 0..=#octaves`; here `octaves` is the number of terms, so
/// "3 octaves" in Table 1 means three noise evaluations.
#[inline]
pub fn turbulence(kind: NoiseKind, p: [f32; 4], octaves: u32, gain: f32, lacunarity: f32) -> f32 {
    let mut sum = 0.0;
    let mut amp = 1.0;
    let mut f = 1.0;
    for _ in 0..octaves {
        sum += amp * kind.eval([p[0] * f, p[1] * f, p[2] * f, p[3] * f]);
        amp *= gain;
        f *= lacunarity;
    }
    sum
}

/// [`turbulence`] of 4-D Perlin noise on a lattice periodic along `z` and `w` with
/// `period = [Pz, Pw]` cells at the first octave (`Pz · lacunarity^i` at octave `i`;
/// the lacunarity a whole number, every octave's period ≤ 256 — [`periodic_octaves_fit`]):
/// `turbulence(p + (0, 0, Pz, 0)) = turbulence(p + (0, 0, 0, Pw)) = turbulence(p)`.
#[inline]
pub fn turbulence_periodic(
    p: [f32; 4],
    octaves: u32,
    gain: f32,
    lacunarity: f32,
    period: [u32; 2],
) -> f32 {
    let mut sum = 0.0;
    let mut amp = 1.0;
    let mut f = 1.0;
    for _ in 0..octaves {
        let wrap = octave_wrap(period, f);
        let q = [
            p[0] * f,
            p[1] * f,
            wrap_coordinate(p[2] * f, wrap.period[0] as f32),
            wrap_coordinate(p[3] * f, wrap.period[1] as f32),
        ];
        sum += amp * perlin4_wrapped(q, wrap);
        amp *= gain;
        f *= lacunarity;
    }
    sum
}

/// The lattice of the octave whose frequency factor is `f` (a whole number) for a
/// first-octave `period`.
#[inline(always)]
pub(crate) fn octave_wrap(period: [u32; 2], f: f32) -> Wrap {
    Wrap {
        period: period.map(|p| (p as f32 * f) as u32),
    }
}

/// Whether [`turbulence_periodic`] can run with these settings: a whole-number lacunarity
/// ≥ 1 and every octave's periods within 1..=256 (the permutation table's).
pub fn periodic_octaves_fit(period: [u32; 2], octaves: u32, lacunarity: f32) -> bool {
    if !(lacunarity >= 1.0 && lacunarity.fract() == 0.0 && lacunarity <= 256.0) {
        return false;
    }
    let top = (lacunarity as f64).powi(octaves.saturating_sub(1) as i32);
    period.iter().all(|&p| p >= 1 && p as f64 * top <= 256.0)
}

/// [`turbulence`] on [`LANES`] points at once; equal to it lane by lane (same operations
/// in the same order).
#[cfg(test)]
#[inline]
pub(crate) fn turbulence_lanes(
    kind: NoiseKind,
    p: &[Lanes; 4],
    octaves: u32,
    gain: f32,
    lacunarity: f32,
) -> Lanes {
    let mut sum = [0.0f32; LANES];
    let mut amp = 1.0;
    let mut f = 1.0;
    for _ in 0..octaves {
        let q = p.map(|a| a.map(|v| v * f));
        let n = kind.eval_lanes(&q);
        for l in 0..LANES {
            sum[l] += amp * n[l];
        }
        amp *= gain;
        f *= lacunarity;
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn permutation_is_a_permutation() {
        let mut seen = [false; 256];
        for &v in PERMUTATION.iter() {
            assert!(!seen[v as usize]);
            seen[v as usize] = true;
        }
    }

    #[test]
    fn gradient_tables_match_the_branchy_reference() {
        let ref3 = |h: usize, x: f32, y: f32, z: f32| {
            let h = h & 15;
            let u = if h < 8 { x } else { y };
            let v = if h < 4 {
                y
            } else if h == 12 || h == 14 {
                x
            } else {
                z
            };
            (if h & 1 == 0 { u } else { -u }) + (if h & 2 == 0 { v } else { -v })
        };
        let ref4 = |h: usize, x: f32, y: f32, z: f32, w: f32| {
            let h = h & 31;
            let (a, b, c) = match h >> 3 {
                0 => (y, z, w),
                1 => (x, z, w),
                2 => (x, y, w),
                _ => (x, y, z),
            };
            (if h & 1 == 0 { a } else { -a })
                + (if h & 2 == 0 { b } else { -b })
                + (if h & 4 == 0 { c } else { -c })
        };
        let (x, y, z, w) = (0.3125f32, -0.71, 0.123, 0.9);
        for h in 0..64 {
            assert_eq!(grad3(h, x, y, z), ref3(h, x, y, z), "grad3 {h}");
            assert_eq!(grad4(h, x, y, z, w), ref4(h, x, y, z, w), "grad4 {h}");
        }
    }

    #[test]
    fn f32_matches_f64() {
        for i in 0..500 {
            let t = i as f32 * 0.137;
            let (x, y, z) = (t * 1.3 - 20.0, t * 0.7 + 3.3, 9.1 - t * 0.4);
            let a = perlin3(x, y, z);
            let b = perlin3_f64(x as f64, y as f64, z as f64) as f32;
            assert!((a - b).abs() < 2e-5, "{a} {b}");
        }
    }

    #[test]
    fn mnoise_zero_at_integers_and_bounded() {
        for i in -5..5 {
            assert_eq!(mnoise(i as f32, (2 * i) as f32, 7.0), 0.0);
        }
        let mut mx = 0.0f32;
        for i in 0..20000 {
            let t = i as f32 * 0.0173;
            let v = mnoise(t, t * 0.61 + 0.3, -t * 0.37 + 5.0);
            mx = mx.max(v.abs());
        }
        assert!(mx < 1.2 && mx > 0.3, "{mx}");
    }

    #[test]
    fn gradient_bits_match_the_tables() {
        for h in 0..64u32 {
            assert_eq!(
                grad3_bits(h).map(f32::to_bits),
                GRAD3[h as usize & 15].map(f32::to_bits),
                "grad3 {h}"
            );
            assert_eq!(
                grad4_bits(h).map(f32::to_bits),
                GRAD4[h as usize & 31].map(f32::to_bits),
                "grad4 {h}"
            );
        }
    }

    /// The batched noise and turbulence equal the scalar reference lane by lane (the
    /// same operations in the same order, so the values are identical, not just close).
    #[test]
    fn lanes_equal_scalar() {
        let mut rng = ignis_core::Rng::new(5);
        let mut cache = NoiseCache::default();
        for round in 0..4000 {
            let range = if round % 2 == 0 { 4.0 } else { 300.0 };
            let mut p = [[0.0f32; LANES]; 4];
            for a in p.iter_mut() {
                for v in a.iter_mut() {
                    *v = rng.uniform(-range, range) as f32;
                }
            }
            // integer points and cell borders too
            if round % 7 == 0 {
                p[0][0] = 3.0;
                p[1][1] = -2.0;
                p[2][2] = 255.999_99;
                p[3][3] = -0.0;
            }
            for kind in [NoiseKind::Perlin3, NoiseKind::Perlin4, NoiseKind::Mnoise] {
                let n = kind.eval_lanes(&p);
                // twice: the first fills the memo, the second reads it
                for _ in 0..2 {
                    assert!(
                        kind.eval_lanes_cached(&p, &mut cache) == n,
                        "{kind:?} cached"
                    );
                }
                let t = turbulence_lanes(kind, &p, 3, 0.5, 2.0);
                for l in 0..LANES {
                    let q = [p[0][l], p[1][l], p[2][l], p[3][l]];
                    let s = kind.eval(q);
                    assert!(n[l] == s, "{kind:?} at {q:?}: {} vs {s}", n[l]);
                    let ts = turbulence(kind, q, 3, 0.5, 2.0);
                    assert!((t[l] - ts).abs() <= 1e-6, "{kind:?} turbulence at {q:?}");
                    assert!(t[l] == ts);
                }
            }
        }
    }

    /// The periodic lattice: [`turbulence_periodic`] repeats after `Pz` along `z` and `Pw`
    /// along `w` (every octave's period dividing them), is continuous across the seam,
    /// equals [`turbulence`] where no octave is in a last cell, and the lanes noise on a
    /// wrapped lattice (plain and AVX2, through the memo) equals the scalar one.
    #[test]
    fn periodic_lattice_repeats_and_matches() {
        let mut rng = ignis_core::Rng::new(9);
        let mut cache = NoiseCache::default();
        for round in 0..3000 {
            let period = [1 + round % 7, 1 + (round / 7) % 5].map(|v| v as u32);
            assert!(periodic_octaves_fit(period, 4, 2.0));
            let p: [f32; 4] = [0; 4].map(|_| rng.uniform(0.0, 60.0) as f32);
            let t = turbulence_periodic(p, 4, 0.6, 2.0, period);
            for (a, pa) in [(2, period[0]), (3, period[1])] {
                let mut q = p;
                q[a] += pa as f32;
                let tq = turbulence_periodic(q, 4, 0.6, 2.0, period);
                // the shifted coordinate rounds differently in its fraction
                assert!(
                    (t - tq).abs() < 2e-4,
                    "axis {a} period {period:?}: {t} vs {tq}"
                );
                // continuous: a tiny move across the seam changes it only a little
                let mut seam = p;
                seam[a] = pa as f32 - 1e-3;
                let mut over = seam;
                over[a] = pa as f32 + 1e-3;
                let (u, v) = (
                    turbulence_periodic(seam, 4, 0.6, 2.0, period),
                    turbulence_periodic(over, 4, 0.6, 2.0, period),
                );
                assert!((u - v).abs() < 0.05, "seam on axis {a}: {u} vs {v}");
            }
            // inside the first cell of every octave's lattice no corner wraps
            let inner = [p[0], p[1], 0.05, 0.05];
            let plain = turbulence(NoiseKind::Perlin4, inner, 4, 0.6, 2.0);
            let wrapped = turbulence_periodic(inner, 4, 0.6, 2.0, [7, 5]);
            assert!((plain - wrapped).abs() < 1e-5, "{plain} vs {wrapped}");
            // lanes on one octave's wrapped lattice, through the memo
            let wrap = Wrap { period };
            let mut q = [[0.0f32; LANES]; 4];
            for (a, axis) in q.iter_mut().enumerate() {
                for v in axis.iter_mut() {
                    let x = rng.uniform(0.0, 40.0) as f32;
                    *v = if a >= 2 {
                        wrap_coordinate(x, period[a - 2] as f32)
                    } else {
                        x
                    };
                }
            }
            cache.wrap = Some(wrap);
            let n = NoiseKind::Perlin4.eval_lanes_cached(&q, &mut cache);
            #[cfg(target_arch = "x86_64")]
            let n_avx2 = std::arch::is_x86_feature_detected!("avx2")
                // SAFETY: AVX2 was detected.
                .then(|| unsafe { avx2::eval_lanes_cached(NoiseKind::Perlin4, &q, &mut cache) });
            cache.wrap = None;
            for l in 0..LANES {
                let s = perlin4_wrapped([q[0][l], q[1][l], q[2][l], q[3][l]], wrap);
                assert!(n[l] == s, "lanes {} vs scalar {s}", n[l]);
                #[cfg(target_arch = "x86_64")]
                if let Some(v) = n_avx2 {
                    assert!(v[l] == s, "avx2 {} vs scalar {s}", v[l]);
                }
            }
        }
        // the plain memo is not spoiled by the wrapped look-ups
        let p = [[1.5f32; LANES], [2.5; LANES], [0.5; LANES], [0.5; LANES]];
        assert_eq!(
            NoiseKind::Perlin4.eval_lanes_cached(&p, &mut cache),
            NoiseKind::Perlin4.eval_lanes(&p)
        );
        assert!(!periodic_octaves_fit([100, 3], 3, 2.0));
        assert!(!periodic_octaves_fit([4, 3], 3, 2.5));
        assert!(!periodic_octaves_fit([0, 3], 3, 2.0));
        assert!(periodic_octaves_fit([64, 32], 3, 2.0));
    }

    /// The bounds are the rounded-up square roots of the proof, and the lemma `q ≤ ¼` of
    /// [`PERLIN4_BOUND`] holds on a fine grid.
    /// The vectorised wrap gives the scalar one's values bit for bit: on both sides of
    /// every period boundary (one ulp either way), for negative and large coordinates.
    #[test]
    fn wrap_lanes_equals_wrap_coordinate() {
        let mut rng = ignis_core::rng::Rng::new(7);
        for period in [1.0f32, 2.0, 3.0, 7.0, 12.0, 255.0, 256.0] {
            let mut xs: Vec<f32> = (0..4000)
                .map(|i| {
                    let range = [2.0, 300.0, 1e5, 1e8][i % 4];
                    rng.uniform(-range, range) as f32
                })
                .collect();
            for k in -40i32..40 {
                let b = k as f32 * period;
                xs.extend([b, b.next_up(), b.next_down(), -0.0]);
            }
            for chunk in xs.chunks_exact(LANES) {
                let mut lanes: Lanes = chunk.try_into().unwrap();
                wrap_lanes(&mut lanes, period);
                for (got, &x) in lanes.iter().zip(chunk) {
                    let want = wrap_coordinate(x, period);
                    assert_eq!(got.to_bits(), want.to_bits(), "x {x}, period {period}");
                    assert!((0.0..period).contains(got), "x {x}, period {period}: {got}");
                }
            }
        }
    }

    #[test]
    fn proven_bound_constants() {
        assert!(PERLIN4_BOUND as f64 >= 3f64.sqrt() && (PERLIN4_BOUND as f64) < 3f64.sqrt() + 1e-6);
        assert!(
            PERLIN3_BOUND as f64 >= 1.5f64.sqrt() && (PERLIN3_BOUND as f64) < 1.5f64.sqrt() + 1e-6
        );
        for i in 0..=100_000 {
            let x = i as f64 / 100_000.0;
            let f = fade64(x);
            let q = (1.0 - f) * x * x + f * (1.0 - x) * (1.0 - x);
            assert!(q <= 0.25 + 1e-15, "q({x}) = {q}");
        }
    }

    /// Dense sampling never exceeds the proven bounds.
    #[test]
    fn noise_within_proven_bounds() {
        let mut rng = ignis_core::Rng::new(9);
        for _ in 0..50_000 {
            let q = [0; 4].map(|_| rng.uniform(-50.0, 50.0) as f32);
            for kind in [NoiseKind::Perlin3, NoiseKind::Perlin4, NoiseKind::Mnoise] {
                assert!(kind.eval(q).abs() <= kind.bound(), "{kind:?} {q:?}");
            }
        }
    }
}
