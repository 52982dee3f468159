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

use serde::{Deserialize, Serialize};

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
pub fn ffloor(x: f32) -> f32 {
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

/// A bound on |[`perlin4`]|: every corner term is at most 3 in magnitude on the unit cell
/// and the weights sum to one, so |n| ≤ 3 is certain; in practice values stay near ±1.
pub const PERLIN4_BOUND: f32 = 3.0;

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
}
