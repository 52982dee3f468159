//! The per-sample mapping: texture coordinates → noise → profile look-up.
//!
//! Source: fuller-procedural-volumetric-fire.txt §4.2, eq. (9)–(14). These are small pure
//! functions on purpose: a GPU renderer must reproduce them line for line (they are the
//! pixel shader), and [`shade`] is what the CPU renderer calls for every sample.

use crate::noise::{turbulence, NoiseKind};
use crate::profile::FireProfile;
use serde::{Deserialize, Serialize};

/// Noise settings of one fire (§4.2).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NoiseParams {
    /// Noise function. Default `perlin4`.
    pub kind: NoiseKind,
    /// Number of octaves in the turbulence sum (eq. 9), 0–8; 0 disables noise. Default 3.
    pub octaves: u32,
    /// Amplitude factor per octave (eq. 9). Default 0.5.
    pub gain: f32,
    /// Frequency factor per octave (eq. 9). Default 2.
    pub lacunarity: f32,
    /// World-space spatial frequency of the detail, 1/units (eq. 10). Default 1.
    pub frequency: f32,
    /// Stability factor of the kernel `f(tex_z) = stability · √tex_z` (eq. 13); larger
    /// means more flicker at the top. Default 0.35.
    pub stability: f32,
    /// Seconds → noise time (eq. 11's `time`). Default 1.
    pub time_scale: f32,
    /// Per-instance offset in noise space so no two fires match; `None` = derived from the
    /// scene seed and the fire's index.
    pub offset: Option<[f32; 4]>,
}

impl Default for NoiseParams {
    fn default() -> Self {
        NoiseParams {
            kind: NoiseKind::Perlin4,
            octaves: 3,
            gain: 0.5,
            lacunarity: 2.0,
            frequency: 1.0,
            stability: 0.35,
            time_scale: 1.0,
            offset: None,
        }
    }
}

/// Eq. (10): `noise_scale = (radius, radius, length, 1) · frequency`.
#[inline(always)]
pub fn noise_scale(radius: f32, length: f32, frequency: f32) -> [f32; 4] {
    [
        radius * frequency,
        radius * frequency,
        length * frequency,
        frequency,
    ]
}

/// Eq. (11) plus the instance offset of eq. (13):
/// `(tex_x, tex_y, tex_z − time, time) · noise_scale + offset`.
#[inline(always)]
pub fn noise_position(tex: [f32; 3], time: f32, scale: [f32; 4], offset: [f32; 4]) -> [f32; 4] {
    [
        tex[0] * scale[0] + offset[0],
        tex[1] * scale[1] + offset[1],
        (tex[2] - time) * scale[2] + offset[2],
        time * scale[3] + offset[3],
    ]
}

/// The kernel of eq. (13): `f(tex_z) = stability · √tex_z`.
#[inline(always)]
pub fn kernel(tex_z: f32, stability: f32) -> f32 {
    stability * tex_z.max(0.0).sqrt()
}

/// Eq. (12): `u = √(tex_x² + tex_y²)`.
#[inline(always)]
pub fn radial_u(tex: [f32; 3]) -> f32 {
    (tex[0] * tex[0] + tex[1] * tex[1]).sqrt()
}

/// Eq. (12)–(13): the profile coordinates given the turbulence value at this sample.
#[inline(always)]
pub fn profile_uv(tex: [f32; 3], turb: f32, stability: f32) -> [f32; 2] {
    [radial_u(tex), tex[2] + kernel(tex[2], stability) * turb]
}

/// How a seamless loop of `period` noise-time units mixes two copies of the noise field:
/// `a · T(time') + b · T(time' − period)` with `time' = time mod period`, `a = cos θ`,
/// `b = sin θ`, `θ = ½π · clamp((time'/period − (1 − F)) / F, 0, 1)` and `F` =
/// [`LOOP_MIX_FRACTION`]: the first copy alone for most of the loop, the two mixed over its
/// last `F`.
///
/// At `time' = 0` this is `T(0)`; as `time'` approaches `period` it approaches
/// `T(0)` again (the second copy, a whole loop behind), so frame `N` of an `N`-frame loop
/// equals frame 0. Both copies scroll upwards as eq. (11) says, so flames keep rising
/// through the seam. `a² + b² = 1` keeps the turbulence's variance constant (the copies
/// are a whole loop apart in noise space, so nearly independent), so the flicker does not
/// fade in mid-loop as a linear crossfade of the noise would.
///
/// Departure from the paper (which has no loops): the 4-D noise's time axis cannot walk a
/// circle without a fifth dimension, and a lattice periodic in time would need a period
/// built into every noise kernel (and, because the field also scrolls up by the fire's
/// changing length, a period along a direction that changes every frame); this costs a
/// second noise evaluation instead, only while the second copy's weight is not zero
/// (the renderer skips it when `b = 0`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopMix {
    /// Noise time of the first copy, `time mod period`.
    pub time: f32,
    /// The loop's length in noise time; the second copy is at `time − period`.
    pub period: f32,
    /// Weight of the first copy.
    pub a: f32,
    /// Weight of the second copy.
    pub b: f32,
}

/// The fraction of a loop over which [`LoopMix`] mixes its two copies of the noise.
/// Shorter is cheaper (one noise evaluation elsewhere) but turns the weights faster, which
/// adds to the image's change per frame while they turn; over a quarter of the loop the
/// steps stay within the spread of the fire's own (a fifth shows in the step series).
pub const LOOP_MIX_FRACTION: f32 = 0.25;

/// The [`LoopMix`] at noise time `time` of a loop `period` noise-time units long (> 0).
pub fn loop_mix(time: f32, period: f32) -> LoopMix {
    let t = time.rem_euclid(period);
    // rem_euclid can round up to `period` itself for a tiny negative time
    let t = if t >= period { 0.0 } else { t };
    let x = ((t / period - (1.0 - LOOP_MIX_FRACTION)) / LOOP_MIX_FRACTION).clamp(0.0, 1.0);
    let theta = std::f32::consts::FRAC_PI_2 * x;
    LoopMix {
        time: t,
        period,
        a: theta.cos(),
        b: theta.sin(),
    }
}

/// [`shade`] for a looping animation: the same mapping with the turbulence mixed from two
/// copies of the noise field ([`LoopMix`], which carries the noise time).
#[inline]
pub fn shade_looped(
    tex: [f32; 3],
    radius: f32,
    length: f32,
    m: LoopMix,
    noise: &NoiseParams,
    offset: [f32; 4],
    profile: &FireProfile,
) -> [f32; 4] {
    let u = radial_u(tex);
    if profile.column_empty(u) {
        return [0.0; 4];
    }
    let turb = if noise.octaves == 0 || noise.stability == 0.0 {
        0.0
    } else {
        let scale = noise_scale(radius, length, noise.frequency);
        let t = |time: f32| {
            let p = noise_position(tex, time, scale, offset);
            turbulence(noise.kind, p, noise.octaves, noise.gain, noise.lacunarity)
        };
        // the second copy is skipped while its weight is zero (exactly `a · T`, as the
        // renderer's batched shading does)
        let first = m.a * t(m.time);
        if m.b == 0.0 {
            first
        } else {
            first + m.b * t(m.time - m.period)
        }
    };
    let [u, v] = profile_uv(tex, turb, noise.stability);
    profile.sample(u, v)
}

/// The whole mapping of eq. (9)–(14) for one sample: the profile colour (straight alpha)
/// at texture coordinates `tex` of a fire whose local radius is `radius` and whose centre
/// curve is `length` long, at noise time `time`. ([`shade_looped`] with one noise copy.)
#[inline]
pub fn shade(
    tex: [f32; 3],
    radius: f32,
    length: f32,
    time: f32,
    noise: &NoiseParams,
    offset: [f32; 4],
    profile: &FireProfile,
) -> [f32; 4] {
    let one = LoopMix {
        time,
        period: 0.0,
        a: 1.0,
        b: 0.0,
    };
    shade_looped(tex, radius, length, one, noise, offset, profile)
}
