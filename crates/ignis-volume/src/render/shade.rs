//! Shading in batches: the turbulence [`LANES`] samples at a time through the
//! structure-of-arrays noise (the same values as the scalar noise), octave by octave,
//! dropping a sample as soon as the proven noise bound shows that no remaining octave can
//! make it visible. Samples are put in slice-then-pixel order first, so the eight of a
//! batch mostly share their noise cells.

use super::tile::{FrameRenderer, Scratch};
use super::visible::turbulence_bounds;
use super::FireInstance;
use crate::mapping::{
    kernel, noise_position, noise_scale, profile_uv, radial_u, scroll_time, TIME_SHEAR,
};
use crate::noise::{octave_wrap, wrap_lanes, NoiseCache, NoiseKind, LANES};

/// A sample whose noise is still being summed.
#[derive(Clone, Copy, Debug)]
pub(super) struct LiveSample {
    /// Index into the sample arrays.
    pub(super) idx: u32,
    /// Noise-space position (eq. 11 + 13) but for `w`, which is the fire's
    /// `time · frequency + offset` plus the sample's `sw`.
    pub(super) p: [f32; 3],
    /// Partial turbulence sum.
    pub(super) sum: f32,
    /// A looping render's second copy of the noise ([`LoopMix`]): its `z` (its `x`, `y`
    /// are `p`'s) and its partial sum. Unused otherwise.
    pub(super) pz2: f32,
    pub(super) sum2: f32,
    /// The sample's share of `w`, its height's shear ([`crate::mapping::TIME_SHEAR`]).
    pub(super) sw: f32,
    /// `u` (eq. 12), `tex_z` and the kernel `f(tex_z)` (eq. 13).
    pub(super) u: f32,
    pub(super) z: f32,
    pub(super) kern: f32,
    /// The turbulence values that can make the sample visible ([`TurbulenceWindow`]).
    pub(super) win: TurbulenceWindow,
}

/// The turbulence values `t` for which a sample's profile look-up `v = z + kern · t`
/// (eq. 12–13) can have non-zero alpha: `v` in the column's visible range `[lo, hi]`
/// ([`FireProfile::v_support`]), i.e. `kern · t ∈ [lo − z, hi − z]`, here widened by a
/// margin of `2e-4 · (1 + 2 kern B)` in `v` (`B` the bound on the whole turbulence,
/// which bounds `|sum| + rem` at every octave; far above the `f32` rounding of `v` and
/// of these few operations), so a sample whose turbulence range misses the window is
/// certain to get zero alpha. A negative kernel gets no window (no culling); a NaN one
/// culls the sample, whose `v` (NaN) gives zero alpha anyway.
#[derive(Clone, Copy, Debug)]
pub(super) struct TurbulenceWindow {
    pub(super) min: f32,
    pub(super) max: f32,
}

impl TurbulenceWindow {
    #[inline(always)]
    pub(super) fn new(z: f32, kern: f32, [lo, hi]: [f32; 2], bound: f32) -> TurbulenceWindow {
        if kern < 0.0 {
            return TurbulenceWindow {
                min: f32::NEG_INFINITY,
                max: f32::INFINITY,
            };
        }
        let eps = 2e-4 * (1.0 + 2.0 * kern * bound);
        TurbulenceWindow {
            min: lo - eps - z,
            max: hi + eps - z,
        }
    }

    /// Whether a turbulence within `rem` of `sum` can lie in the window of a sample with
    /// kernel `kern` (`false` is certain).
    #[inline(always)]
    pub(super) fn reachable(&self, kern: f32, sum: f32, rem: f32) -> bool {
        kern * (sum + rem) >= self.min && kern * (sum - rem) <= self.max
    }
}

impl FrameRenderer<'_, '_> {
    /// Shades every collected sample exactly as [`shade`] does, but with the turbulence
    /// evaluated [`LANES`] samples at a time and only while it can still matter.
    ///
    /// The turbulence only moves the profile look-up vertically: `v = tex_z + f(tex_z)·t`
    /// (eq. 12–13). With `|noise| ≤ B` ([`NoiseKind::bound`], proven), the octaves not yet
    /// added change `t` by at most `B · Σ |gain|^i` over them. So before the first octave
    /// and after each one, a sample whose possible `v` range misses the profile column's
    /// visible range ([`FireProfile::v_support`]) is certain to get zero alpha — and a
    /// zero-alpha sample adds exactly nothing to any blend — so its remaining octaves are
    /// skipped. Samples that stay in play get the same turbulence value as the scalar
    /// [`crate::noise::turbulence`] (same operations, same order), hence the same colour.
    ///
    /// `avx2`: the CPU has AVX2 (only passed as `true` from the AVX2 build of the tile
    /// renderer); the noise then runs [`crate::noise::avx2`], which gives the same values.
    ///
    /// Long on purpose (~100 lines): the octave loop over a batch of 8 samples is one hot
    /// body, so the window, culling and mix weights stay in registers.
    #[inline(always)]
    pub(super) fn shade_batched(&self, fire: &FireInstance, s: &mut Scratch, avx2: bool) {
        let noise = &fire.noise;
        let n = s.tex.len();
        s.col.clear();
        s.col.resize(n, [0.0; 4]);
        if noise.octaves == 0 || noise.stability == 0.0 {
            // no turbulence: nothing to batch
            shade_calm(fire, s);
            return;
        }
        let periodic = self.params.periodic(fire, self.time);
        let mix = self.params.mix(fire, self.time);
        // the first copy's noise time; a loop's second copy is a whole loop behind, and
        // the pair's turbulence `a·sum + b·sum2` is bounded by `(a + b)` times one's
        let (time, time2, wa, wb) = match (periodic, mix) {
            (Some(pl), _) => (pl.time, 0.0, 1.0, 0.0),
            (None, Some(m)) => (m.time, m.time - m.period, m.a, m.b),
            (None, None) => (self.time * noise.time_scale, 0.0, 1.0, 0.0),
        };
        // a loop's second copy costs nothing while its weight is zero (`a = 1` exactly)
        let looped = mix.is_some_and(|m| m.b != 0.0);
        let turb = |a: &LiveSample| {
            if looped {
                wa * a.sum + wb * a.sum2
            } else {
                a.sum
            }
        };
        let length = fire.lattice.length();
        let profile = fire.profile;
        let octaves = noise.octaves as usize;
        let mut rem = turbulence_bounds(noise);
        if looped {
            rem = rem.map(|r| r * (wa + wb));
        }
        let uniform = fire.lattice.uniform_radius();
        // the fire's part of every sample's `w` (each adds its height's shear, `sw`)
        let wscale = noise_scale(1.0, length, noise.frequency);
        let pw = noise_position([0.0; 3], time, 0.0, wscale, fire.offset)[3];
        let pw2 = noise_position([0.0; 3], time2, 0.0, wscale, fire.offset)[3];
        // eq. (11)'s upward scroll at one speed in world units ([`scroll_time`])
        let scroll_length = fire.scroll_length();
        let scroll = match periodic {
            Some(pl) => scroll_time(pl.scroll_time, length, pl.scroll_length),
            None => scroll_time(time, length, scroll_length),
        };
        let scroll2 = scroll_time(time2, length, scroll_length);
        slice_order(&s.slice, &mut s.buckets, &mut s.order);
        let act = &mut s.live;
        act.clear();
        for &i in &s.order {
            let tex = s.tex[i as usize];
            let u = radial_u(tex);
            let Some([lo, hi]) = profile.v_support(u) else {
                continue; // empty column: transparent whatever the noise
            };
            let z = tex[2];
            let kern = kernel(z, noise.stability);
            let win = TurbulenceWindow::new(z, kern, [lo, hi], rem[0]);
            if !win.reachable(kern, 0.0, rem[0]) {
                continue;
            }
            let radius = uniform.unwrap_or_else(|| fire.lattice.radius_at(z));
            let scale = noise_scale(radius, length, noise.frequency);
            let [px, py, pz, _] = noise_position(tex, time, scroll, scale, fire.offset);
            let pz2 = if looped {
                noise_position(tex, time2, scroll2, scale, fire.offset)[2]
            } else {
                0.0
            };
            act.push(LiveSample {
                idx: i,
                p: [px, py, pz],
                sum: 0.0,
                pz2,
                sum2: 0.0,
                sw: tex[2] * (scale[2] * TIME_SHEAR),
                u,
                z,
                kern,
                win,
            });
        }
        // turbulence (eq. 9), octave by octave, as `turbulence` computes it
        let mut amp = 1.0f32;
        let mut f = 1.0f32;
        for o in 0..octaves {
            // a periodic loop's lattice at this octave ([`PeriodicLoop`])
            s.noise_cache.wrap = periodic.map(|pl| octave_wrap(pl.period, f));
            for batch in act.chunks_mut(LANES) {
                let kind = noise.kind;
                add_octave(
                    kind,
                    batch,
                    [f, amp],
                    [pw, pw2],
                    looped,
                    &mut s.noise_cache,
                    avx2,
                );
            }
            amp *= noise.gain;
            f *= noise.lacunarity;
            if o + 1 < octaves {
                let r = rem[o + 1];
                act.retain(|a| a.win.reachable(a.kern, turb(a), r));
            }
        }
        s.noise_cache.wrap = None;
        for live in act.iter() {
            // `profile_uv` of the sample, from the values computed above
            let v = live.z + live.kern * turb(live);
            s.col[live.idx as usize] = profile.sample(live.u, v);
        }
    }
}

/// The colours of samples without turbulence (no octaves, or stability 0): the profile
/// look-up of [`profile_uv`] with zero turbulence.
#[inline(always)]
fn shade_calm(fire: &FireInstance, s: &mut Scratch) {
    let stability = fire.noise.stability;
    for (c, &tex) in s.col.iter_mut().zip(&s.tex) {
        let [u, v] = profile_uv(tex, 0.0, stability);
        *c = if fire.profile.column_empty(u) {
            [0.0; 4]
        } else {
            fire.profile.sample(u, v)
        };
    }
}

/// Adds one octave (`[frequency, amplitude]`) of the noise to the turbulence sums of up
/// to [`LANES`] live samples; with `looped`, also to the loop's second copy (noise time
/// `w` = `pw2` instead of `pw`, the samples' `pz2` for `z`). The same operations in the
/// same order as [`crate::noise::turbulence`].
#[inline(always)]
fn add_octave(
    kind: NoiseKind,
    batch: &mut [LiveSample],
    [f, amp]: [f32; 2],
    [pw, pw2]: [f32; 2],
    looped: bool,
    cache: &mut NoiseCache,
    avx2: bool,
) {
    let mut q = [[pw * f; LANES]; 4];
    for (l, live) in batch.iter().enumerate() {
        for (qa, pa) in q.iter_mut().zip(live.p) {
            qa[l] = pa * f;
        }
        q[3][l] = (pw + live.sw) * f;
    }
    if let Some(w) = cache.wrap {
        // a periodic lattice: `z`, `w` into its period, as `turbulence_periodic` does
        for (a, p) in [(2, w.period[0]), (3, w.period[1])] {
            wrap_lanes(&mut q[a], p as f32);
        }
    }
    let val = lanes_noise(kind, &q, cache, avx2);
    for (live, v) in batch.iter_mut().zip(val) {
        live.sum += amp * v;
    }
    if looped {
        q[3] = [pw2 * f; LANES];
        for (l, live) in batch.iter().enumerate() {
            q[2][l] = live.pz2 * f;
            q[3][l] = (pw2 + live.sw) * f;
        }
        let val = lanes_noise(kind, &q, cache, avx2);
        for (live, v) in batch.iter_mut().zip(val) {
            live.sum2 += amp * v;
        }
    }
}

/// One octave of noise on [`LANES`] points, with the AVX2 build when `avx2` (the caller
/// guarantees the CPU has it); the same values either way.
#[inline(always)]
pub(super) fn lanes_noise(
    kind: NoiseKind,
    q: &[[f32; LANES]; 4],
    cache: &mut NoiseCache,
    avx2: bool,
) -> [f32; LANES] {
    #[cfg(target_arch = "x86_64")]
    if avx2 {
        // SAFETY: `avx2` is true only on CPUs with AVX2 (see `FrameRenderer::tile`).
        return unsafe { crate::noise::avx2::eval_lanes_cached(kind, q, cache) };
    }
    let _ = avx2;
    kind.eval_lanes_cached(q, cache)
}

/// Orders sample indices by slice index `k` (stable, so by pixel within a slice): a
/// counting sort. Neighbouring pixels' samples on one slice are close in noise space, so
/// consecutive samples then mostly share their noise cell, which the lanes noise exploits.
/// Falls back to march order when the slices span an unusually wide range.
pub(super) fn slice_order(k: &[i64], buckets: &mut Vec<u32>, order: &mut Vec<u32>) {
    order.clear();
    if k.is_empty() {
        return;
    }
    let (lo, hi) = k
        .iter()
        .fold((i64::MAX, i64::MIN), |(lo, hi), &v| (lo.min(v), hi.max(v)));
    let span = (hi - lo) as usize + 1;
    if span > 1 << 16 {
        order.extend(0..k.len() as u32);
        return;
    }
    buckets.clear();
    buckets.resize(span + 1, 0);
    for &v in k {
        buckets[(v - lo) as usize + 1] += 1;
    }
    for b in 1..=span {
        buckets[b] += buckets[b - 1];
    }
    order.resize(k.len(), 0);
    for (i, &v) in k.iter().enumerate() {
        let slot = &mut buckets[(v - lo) as usize];
        order[*slot as usize] = i as u32;
        *slot += 1;
    }
}
