//! The per-sample mapping: texture coordinates → noise → profile look-up.
//!
//! Source: fuller-procedural-volumetric-fire.txt §4.2, eq. (9)–(14). These are small pure
//! functions on purpose: a GPU renderer must reproduce them line for line (they are the
//! pixel shader), and [`shade`] is what the CPU renderer calls for every sample.

use crate::noise::{periodic_octaves_fit, turbulence, turbulence_periodic, NoiseKind};
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

/// How far the noise's time axis `w` is sheared with height: `w` gains
/// `TIME_SHEAR · tex_z · length · frequency` (half a cell per cell of height).
///
/// Departure from the paper (whose `w` is `time · frequency` at every sample): Improved
/// Perlin noise changes with `w` at a rate that depends on where `w` lies in its lattice
/// cell (slowly at whole numbers, where the fade's slope is zero, fastest mid-cell), so
/// with one `w` for a whole fire the fire's image changed faster and slower by turns —
/// frame-to-frame steps spread by ±30 % on a loop. Sheared, every height is at another
/// place in the cell and the fire changes by about the same amount every frame. The
/// noise is still a 3-D slice of the 4-D noise, tilted (its vertical frequency is
/// `√(1 + 0.5²)` ≈ 1.12 times the paper's).
pub const TIME_SHEAR: f32 = 0.5;

/// Eq. (11) plus the instance offset of eq. (13):
/// `(tex_x, tex_y, tex_z − scroll, time) · noise_scale + offset`, where the paper has
/// `scroll = time` ([`scroll_time`]), and `w` sheared with height ([`TIME_SHEAR`]).
#[inline(always)]
pub fn noise_position(
    tex: [f32; 3],
    time: f32,
    scroll: f32,
    scale: [f32; 4],
    offset: [f32; 4],
) -> [f32; 4] {
    [
        tex[0] * scale[0] + offset[0],
        tex[1] * scale[1] + offset[1],
        (tex[2] - scroll) * scale[2] + offset[2],
        time * scale[3] + offset[3] + tex[2] * (scale[2] * TIME_SHEAR),
    ]
}

/// The upward scroll of eq. (11) in texture units at noise time `time`, for a fire whose
/// centre curve is `length` long now and whose scroll moves `scroll_length` world units
/// per unit of noise time: `time · scroll_length / length` (exactly `time` when the two
/// lengths are equal, as in the paper).
///
/// Departure from the paper: eq. (11) scrolls by `time` texture units, i.e. by
/// `time · length` world units, so when the length changes from frame to frame (a
/// simulated fire, a script, puffing) the whole noise field jumps by `time · Δlength` —
/// a jitter that grows with time (over a loop: the noise speeds up and slows down more and
/// more towards the loop's end). A fixed `scroll_length` per fire keeps the scroll at one
/// speed in world units whatever the length does.
#[inline(always)]
pub fn scroll_time(time: f32, length: f32, scroll_length: f32) -> f32 {
    if scroll_length == length || length <= 0.0 {
        time
    } else {
        time * (scroll_length / length)
    }
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
/// The fallback of [`PeriodicLoop`] (M-noise, 3-D Perlin noise, a lacunarity that is not a
/// whole number, or a loop so long that an octave's period would exceed 256 cells): it
/// costs a second noise evaluation while the second copy's weight is not zero (the
/// renderer skips it when `b = 0`), and the turning weights add to the image's change over
/// the loop's last quarter.
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

/// A seamless loop of `period` noise-time units made by a noise field that is itself
/// periodic in time, at no extra cost (the preferred way; [`LoopMix`] is the fallback).
///
/// Over one loop the noise position of eq. (11) moves along `z` (the upward scroll) and
/// along `w` (the 4-D noise's time). Both moves are made whole numbers of lattice cells,
/// `Pz = round(period · scroll_length · frequency)` and `Pw = round(period · frequency)`
/// (each at least 1: a loop shorter than half a cell falls back), by scaling the scroll
/// and the noise time by at most half a cell per loop (a relative change of at most
/// `1 / (2 P)`: 5 % once a loop spans ten cells, up to −33 % / +100 % for a loop of
/// 1.5 / 0.5 cells), and the Improved Perlin lattice is
/// wrapped modulo `Pz` and `Pw` cells (`Pz · 2^i`, `Pw · 2^i` at octave `i`, so every
/// octave's period divides the loop): frame `N` equals frame 0, and frame `N − 1` to
/// frame `N` is the same kind of step as every other — the noise never changes speed over
/// the loop. Needs 4-D Perlin noise, a whole-number lacunarity and every octave's period
/// within the permutation table's 256 cells; otherwise ([`periodic_loop`] gives `None`)
/// the loop falls back to [`LoopMix`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PeriodicLoop {
    /// Noise time along `w` (eq. 11's `time`), `time' · Pw / (period · frequency)` with
    /// `time' = time mod period`.
    pub time: f32,
    /// `time'`, the scroll's noise time ([`scroll_time`] with [`PeriodicLoop::scroll_length`]).
    pub scroll_time: f32,
    /// The scroll length that moves the noise `Pz` cells per loop: `Pz / (period · frequency)`.
    pub scroll_length: f32,
    /// `[Pz, Pw]`, the lattice's periods in cells at the first octave.
    pub period: [u32; 2],
}

/// The [`PeriodicLoop`] of a fire with `noise`, scrolling `scroll_length` world units per
/// noise-time unit, at noise time `time` of a loop `period` noise-time units long; `None`
/// where the lattice cannot be periodic (see [`PeriodicLoop`]).
pub fn periodic_loop(
    time: f32,
    period: f32,
    noise: &NoiseParams,
    scroll_length: f32,
) -> Option<PeriodicLoop> {
    let f = noise.frequency;
    if noise.kind != NoiseKind::Perlin4 || !(period > 0.0 && f > 0.0 && scroll_length > 0.0) {
        return None;
    }
    // under half a cell per loop the rounding would speed the noise up (by up to ×∞):
    // the fallback mixes two copies instead
    let cells = |x: f32| {
        let c = x.round();
        (1.0..=256.0).contains(&c).then_some(c as u32)
    };
    let pz = cells(period * scroll_length * f)?;
    let pw = cells(period * f)?;
    if !periodic_octaves_fit([pz, pw], noise.octaves, noise.lacunarity) {
        return None;
    }
    let t = time.rem_euclid(period);
    let t = if t >= period { 0.0 } else { t };
    Some(PeriodicLoop {
        time: t * (pw as f32 / (period * f)),
        scroll_time: t,
        scroll_length: pz as f32 / (period * f),
        period: [pz, pw],
    })
}

/// [`shade`] for a looping animation whose noise is periodic ([`PeriodicLoop`]), for a
/// fire whose centre curve is `length` long.
#[inline]
pub fn shade_periodic(
    tex: [f32; 3],
    radius: f32,
    length: f32,
    pl: PeriodicLoop,
    noise: &NoiseParams,
    offset: [f32; 4],
    profile: &FireProfile,
) -> [f32; 4] {
    shade_with(tex, noise, profile, || {
        turbulence_at_periodic(tex, radius, length, pl, noise, offset)
    })
}

/// The turbulence [`shade_periodic`] displaces the profile by (eq. 9–11, periodic noise).
#[inline]
pub fn turbulence_at_periodic(
    tex: [f32; 3],
    radius: f32,
    length: f32,
    pl: PeriodicLoop,
    noise: &NoiseParams,
    offset: [f32; 4],
) -> f32 {
    let scale = noise_scale(radius, length, noise.frequency);
    let scroll = scroll_time(pl.scroll_time, length, pl.scroll_length);
    let p = noise_position(tex, pl.time, scroll, scale, offset);
    turbulence_periodic(p, noise.octaves, noise.gain, noise.lacunarity, pl.period)
}

/// The profile colour at `tex` displaced by the turbulence `turb()` (eq. 13–14), which is
/// only evaluated where the profile's column is lit and the noise is on.
#[inline]
fn shade_with(
    tex: [f32; 3],
    noise: &NoiseParams,
    profile: &FireProfile,
    turb: impl FnOnce() -> f32,
) -> [f32; 4] {
    let u = radial_u(tex);
    if profile.column_empty(u) {
        return [0.0; 4];
    }
    let turb = if noise.octaves == 0 || noise.stability == 0.0 {
        0.0
    } else {
        turb()
    };
    let [u, v] = profile_uv(tex, turb, noise.stability);
    profile.sample(u, v)
}

/// [`shade`] for a looping animation: the same mapping with the turbulence mixed from two
/// copies of the noise field ([`LoopMix`], which carries the noise time).
#[inline]
pub fn shade_looped(
    tex: [f32; 3],
    radius: f32,
    length: [f32; 2],
    m: LoopMix,
    noise: &NoiseParams,
    offset: [f32; 4],
    profile: &FireProfile,
) -> [f32; 4] {
    shade_with(tex, noise, profile, || {
        turbulence_at(tex, radius, length, m, noise, offset)
    })
}

/// The turbulence [`shade_looped`] (and so [`shade`]) displaces the profile by
/// (eq. 9–11, the loop's two copies mixed).
#[inline]
pub fn turbulence_at(
    tex: [f32; 3],
    radius: f32,
    length: [f32; 2],
    m: LoopMix,
    noise: &NoiseParams,
    offset: [f32; 4],
) -> f32 {
    let scale = noise_scale(radius, length[0], noise.frequency);
    let t = |time: f32| {
        let scroll = scroll_time(time, length[0], length[1]);
        let p = noise_position(tex, time, scroll, scale, offset);
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
}

/// The whole mapping of eq. (9)–(14) for one sample: the profile colour (straight alpha)
/// at texture coordinates `tex` of a fire whose local radius is `radius`, whose centre
/// curve is `length[0]` long and whose noise scrolls `length[1]` world units per unit of
/// noise time ([`scroll_time`]; the paper's `length[1] = length[0]`), at noise time `time`.
/// ([`shade_looped`] with one noise copy.)
#[inline]
pub fn shade(
    tex: [f32; 3],
    radius: f32,
    length: [f32; 2],
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The scroll moves the noise at one speed in world units whatever the fire's length:
    /// `scroll_time · length` is `time · scroll_length`.
    #[test]
    fn scroll_keeps_its_speed_when_the_length_changes() {
        assert_eq!(scroll_time(3.25, 1.5, 1.5), 3.25);
        for length in [0.5f32, 1.0, 1.7, 4.0] {
            let world = scroll_time(2.0, length, 1.2) * length;
            assert!((world - 2.4).abs() < 1e-5, "{length}: {world}");
        }
    }

    /// A periodic loop moves the noise whole numbers of cells per loop, repeats exactly with
    /// the loop, and is refused (so the renderer mixes two copies) where it cannot be built.
    #[test]
    fn periodic_loop_whole_cells_or_none() {
        let noise = NoiseParams {
            frequency: 4.0,
            octaves: 4,
            ..Default::default()
        };
        let period = 0.8;
        let pl = periodic_loop(0.3, period, &noise, 1.1).expect("periodic");
        // 0.8 · 1.1 · 4 = 3.52 → 4 cells of scroll; 0.8 · 4 = 3.2 → 3 cells of time
        assert_eq!(pl.period, [4, 3]);
        let moved_z = period * pl.scroll_length * noise.frequency;
        let moved_w = periodic_loop(period - 1e-6, period, &noise, 1.1)
            .unwrap()
            .time
            * noise.frequency;
        assert!((moved_z - 4.0).abs() < 1e-5, "{moved_z}");
        assert!((moved_w - 3.0).abs() < 1e-4, "{moved_w}");
        assert_eq!(periodic_loop(0.3 + period, period, &noise, 1.1), Some(pl));
        let no = |n: NoiseParams| periodic_loop(0.3, period, &n, 1.1).is_none();
        assert!(no(NoiseParams {
            kind: NoiseKind::Mnoise,
            ..noise
        }));
        assert!(no(NoiseParams {
            lacunarity: 2.2,
            ..noise
        }));
        // under half a cell of noise time per loop: not rounded up to a whole one
        assert!(no(NoiseParams {
            frequency: 0.5,
            ..noise
        }));
        // 8 octaves: 4 cells · 2⁷ = 512 exceed the 256-cell table
        assert!(periodic_loop(
            0.3,
            period,
            &NoiseParams {
                octaves: 8,
                ..noise
            },
            1.1
        )
        .is_none());
    }
}
