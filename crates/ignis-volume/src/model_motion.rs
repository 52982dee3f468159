//! The volumetric fire's own motion on screen, from the model: per output pixel, how far
//! what it shows moves from one frame ([`Pose`]) to another, in pixels. For motion-vector
//! flipbooks (issue 17), where the alternative is optical flow between the rendered frames.
//!
//! Source: fuller-procedural-volumetric-fire.txt §3–4. A sample at world point `x` has
//! texture coordinates `tex = L_a⁻¹(x)` in frame `a`'s lattice; its look comes from the
//! noise at `noise_position(tex, …)` (eq. 11), which scrolls up along the fire while its
//! time axis advances. A feature of frame `a` is taken to be at `tex'` in frame `b`, where
//!
//! - along the fire, `tex'_z · length_b = tex_z · length_a + rise`: it rises by `rise`
//!   world units, by [`Follow`]: not at all (the lattice carries it), with the scroll (a
//!   fixed spatial noise coordinate, what the paper's scroll moves), along the track
//!   through the 4-D noise that changes least, or as the profile the sample shows moves
//!   ([`Follow::Flow`], the model's own optical flow); over the shortest way round a loop;
//! - across it, `tex'_xy · r_b(tex'_z) = tex_xy · r_a(tex_z)` (eq. 10 scales the noise by
//!   the local radius);
//!
//! and in the world at `x' = L_b(tex')` (the lattice's map, extrapolated past its ends).
//! The sample's motion is `project(x') − project(x)` with the scene's camera; a pixel's is
//! the mean of its samples' motions weighted by their emission (luminance × alpha of the
//! shaded sample: what each adds to the additive blend), 0 where it has none.
//!
//! What no displacement describes: the noise's own change in time (only [`Follow::Flow`]
//! sees it, as far as it shifts the profile) and the profile, which does not scroll; so
//! model motion is one candidate among others (none / forward /
//! backward), chosen per pixel by the rendered in-between frames where they exist
//! (`ignis_media::write::motion::chosen_velocities`). Samples come from the renderer's
//! reference path (`render/reference.rs`: every slice, exact inverse): slow, but exact
//! and the same samples the image is made of.

use crate::error::{Result, VolumeError};
use crate::lattice::{Lattice, V3};
use crate::mapping::{kernel, turbulence_at, turbulence_at_periodic, LoopMix, PeriodicLoop};
use crate::render::{reference_sums, FireInstance, RenderParams};
use crate::scene::{FireScene, Pose};

/// Which motion of the noise a feature follows (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Follow {
    /// The model's own optical flow: each sample shows the profile at
    /// `v = z + D(tex)`, `D = f(z) · T(tex)` (eq. 12–13), so its brightness `E(v)` is kept
    /// by a shift `Δz = −ΔD / (1 + ∂D/∂z)` along the fire, `ΔD` the change of `D` at the
    /// sample between the frames. Per pixel, the least-squares shift over its samples,
    /// each weighted by `(∂E/∂v)²` (a sample on a flat part of the profile says nothing of
    /// motion; one at a fold, `1 + ∂D/∂z ≈ 0`, little), on screen along the lattice's
    /// axis there, plus the lattice's own motion.
    Flow,
    /// The lattice only: a feature keeps its texture coordinates (no scroll).
    Lattice,
    /// The lattice and the scroll of eq. (11): a feature keeps its spatial noise
    /// coordinate, as if the noise did not change in time.
    Scroll,
    /// The lattice and the track through the 4-D noise that changes least: the noise
    /// scrolls up along the fire at `s` (world units per second) while its time axis `w`
    /// (sheared with height by [`crate::mapping::TIME_SHEAR`] `= c`) advances at `τ`;
    /// a feature rising at `v` meets a change of `(v − s, τ + c·v)` in noise space per
    /// second (both scaled by the frequency), least for `v = (s − c·τ) / (1 + c²)`. For
    /// isotropic noise the blend's expected error grows with that distance, so this is the
    /// velocity the model predicts best.
    Noise,
}

/// Per pixel of `scene`'s frame in pose `from`, its motion to each `(pose, follow)` of
/// `to`, in pixels (`[dx, dy]`, y down; row-major). See the module docs. Fails if the
/// poses do not hold one lattice per fire of `scene`, or as [`crate::render()`] fails.
pub fn model_motion(
    scene: &FireScene,
    from: &Pose,
    to: &[(&Pose, Follow)],
) -> Result<Vec<Vec<[f32; 2]>>> {
    check_poses(scene, std::iter::once(from).chain(to.iter().map(|t| t.0)))?;
    let size = scene.size;
    let inst = from.instances(scene);
    let params = from.render_params(scene);
    let rates: Vec<[f32; 2]> = inst
        .iter()
        .map(|f| noise_rates(f, &params, from.time))
        .collect();
    let noise_a: Vec<NoiseAt> = inst
        .iter()
        .map(|f| NoiseAt::new(f, &params, from.time))
        .collect();
    // per target: its fires, per fire the rise (world units along the fire) and noise
    let targets: Vec<Target> = to
        .iter()
        .map(|&(p, follow)| {
            let dt = loop_delta(p.time - from.time, from.loop_period);
            let rise = rates.iter().map(|&r| rise(r, follow) * dt).collect();
            let inst = p.instances(scene);
            let params = p.render_params(scene);
            let noise = inst
                .iter()
                .map(|f| NoiseAt::new(f, &params, p.time))
                .collect();
            Target {
                inst,
                rise,
                noise,
                follow,
            }
        })
        .collect();
    let camera = scene.camera;
    // per sample and target of `chunk` (at most MAX_TARGETS), SLOT sums: [W, S1, S2, Jx,
    // Jy, Lx, Ly]: weight; least-squares shift along the fire, −S1/S2 (Follow::Flow);
    // screen px per unit of tex_z (weighted); the lattice's (or follow's) motion (weighted)
    let f = |fi: usize, tex: V3, col: [f32; 4], chunk: &[usize]| -> [f32; SLOT * MAX_TARGETS] {
        let mut out = [0.0; SLOT * MAX_TARGETS];
        let a = &inst[fi];
        let Some(p0) = camera.project(a.lattice.forward(tex), size) else {
            return out;
        };
        let lum = |c: [f32; 4]| c[3] * (0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]);
        let e = lum(col);
        let flow = chunk.iter().any(|&t| targets[t].follow == Follow::Flow);
        let local = flow.then(|| flow_terms(tex, a, noise_a[fi], camera, size, &lum));
        for (j, &t) in chunk.iter().enumerate() {
            let tg = &targets[t];
            let b = &tg.inst[fi];
            let o = &mut out[SLOT * j..SLOT * (j + 1)];
            let (w, tex_b) = match (tg.follow, local) {
                (Follow::Flow, Some(l)) => {
                    let Some(l) = l else { continue };
                    let dd = tg.noise[fi].displacement(b, tex) - l.d;
                    o[1] = l.w * l.slope * dd;
                    o[2] = l.w * l.slope * l.slope;
                    o[3] = l.w * l.axis[0];
                    o[4] = l.w * l.axis[1];
                    (l.w, tex)
                }
                _ => (e, follow(tex, a.lattice, b.lattice, tg.rise[fi])),
            };
            if w <= 0.0 {
                continue;
            }
            if let Some(p1) = camera.project(forward_extrapolated(b.lattice, tex_b), size) {
                o[0] = w;
                o[5] = w * (p1[0] - p0[0]);
                o[6] = w * (p1[1] - p0[1]);
            }
        }
        out
    };
    let mut fields = Vec::with_capacity(to.len());
    let all: Vec<usize> = (0..to.len()).collect();
    for chunk in all.chunks(MAX_TARGETS) {
        let sums = reference_sums(&inst, &camera, &params, from.time, &|fi, tex, col| {
            f(fi, tex, col, chunk)
        })?;
        fields.extend((0..chunk.len()).map(|j| field(&sums, j)));
    }
    Ok(fields)
}

/// Refuses poses that do not hold one lattice and scroll length per fire of `scene`.
fn check_poses<'a>(scene: &FireScene, poses: impl Iterator<Item = &'a Pose>) -> Result<()> {
    for p in poses {
        if p.lattices.len() != scene.fires.len() || p.scroll_lengths.len() != scene.fires.len() {
            return Err(VolumeError::bad(
                "pose",
                format!(
                    "{} lattices for {} fires; take poses from this scene's animator",
                    p.lattices.len(),
                    scene.fires.len()
                ),
            ));
        }
    }
    Ok(())
}

/// Target `j`'s motion per pixel from the per-pixel sums of [`model_motion`]: the
/// weighted lattice (or follow) motion plus, for [`Follow::Flow`], the least-squares shift
/// along the fire times the weighted screen axis; 0 where nothing was weighed.
fn field(sums: &[[f32; SLOT * MAX_TARGETS]], j: usize) -> Vec<[f32; 2]> {
    sums.iter()
        .map(|s| {
            let s = &s[SLOT * j..SLOT * (j + 1)];
            if !(s[0] > 0.0) {
                return [0.0; 2];
            }
            let dz = if s[2] > 0.0 { -s[1] / s[2] } else { 0.0 };
            [(s[5] + s[3] * dz) / s[0], (s[6] + s[4] * dz) / s[0]]
        })
        .collect()
}

/// Sums per target and pixel (see [`model_motion`]).
const SLOT: usize = 7;

/// One target pose of [`model_motion`].
struct Target<'a> {
    inst: Vec<FireInstance<'a>>,
    rise: Vec<f32>,
    noise: Vec<NoiseAt>,
    follow: Follow,
}

/// How a fire's noise is evaluated at one instant, as the renderer's reference path
/// evaluates it (`render/reference.rs`).
#[derive(Clone, Copy, Debug)]
enum NoiseAt {
    Periodic(PeriodicLoop),
    Mix(LoopMix),
}

impl NoiseAt {
    fn new(f: &FireInstance, params: &RenderParams, time: f32) -> NoiseAt {
        if let Some(pl) = params.periodic(f, time) {
            return NoiseAt::Periodic(pl);
        }
        NoiseAt::Mix(params.mix(f, time).unwrap_or(LoopMix {
            time: time * f.noise.time_scale,
            period: 0.0,
            a: 1.0,
            b: 0.0,
        }))
    }

    /// The profile displacement `D = f(z) · T(tex)` of fire `f` at `tex` (eq. 12–13).
    fn displacement(self, f: &FireInstance, tex: V3) -> f32 {
        let n = &f.noise;
        if n.octaves == 0 || n.stability == 0.0 {
            return 0.0;
        }
        let radius = f.lattice.radius_at(tex[2]);
        let length = f.lattice.length();
        let t = match self {
            NoiseAt::Periodic(pl) => turbulence_at_periodic(tex, radius, length, pl, n, f.offset),
            NoiseAt::Mix(m) => {
                turbulence_at(tex, radius, [length, f.scroll_length()], m, n, f.offset)
            }
        };
        kernel(tex[2], n.stability) * t
    }
}

/// [`Follow::Flow`]'s terms of one sample of frame `a`: weight `(∂E/∂v)²`, `D`,
/// `1 + ∂D/∂z`, and the screen motion per unit of `tex_z`; `None` for a sample
/// off screen.
#[derive(Clone, Copy, Debug)]
struct FlowTerms {
    w: f32,
    d: f32,
    slope: f32,
    axis: [f32; 2],
}

fn flow_terms(
    tex: V3,
    a: &FireInstance,
    na: NoiseAt,
    camera: crate::render::Camera,
    size: ignis_core::Size,
    lum: &dyn Fn([f32; 4]) -> f32,
) -> Option<FlowTerms> {
    const H: f32 = 1e-3;
    const HV: f32 = 0.01;
    let at = |dz: f32| [tex[0], tex[1], tex[2] + dz];
    let d = na.displacement(a, tex);
    let slope = 1.0 + (na.displacement(a, at(H)) - na.displacement(a, at(-H))) / (2.0 * H);
    let u = (tex[0] * tex[0] + tex[1] * tex[1]).sqrt();
    let v = tex[2] + d;
    let de = (lum(a.profile.sample(u, v + HV)) - lum(a.profile.sample(u, v - HV))) / (2.0 * HV);
    let up = camera.project(a.lattice.forward(at(H)), size)?;
    let down = camera.project(a.lattice.forward(at(-H)), size)?;
    Some(FlowTerms {
        w: de * de,
        d,
        slope,
        axis: [(up[0] - down[0]) / (2.0 * H), (up[1] - down[1]) / (2.0 * H)],
    })
}

/// Most targets one march serves (more are done in further marches).
const MAX_TARGETS: usize = 8;

/// Fire `f`'s noise at scene time `time`: `[s, τ]`, how fast its scroll moves along the
/// fire (world units per second) and its time axis `w` advances (noise time per second).
fn noise_rates(f: &FireInstance, params: &RenderParams, time: f32) -> [f32; 2] {
    let ts = f.noise.time_scale;
    if let Some(pl) = params.periodic(f, time) {
        // scroll: `scroll_time · scroll_length` with `scroll_time` the loop's noise time;
        // `w`: `Pw / (period · frequency)` noise-time units per loop noise-time unit
        let period = params.loop_period.unwrap_or(1.0) * ts;
        let w = pl.period[1] as f32 / (period * f.noise.frequency);
        return [ts * pl.scroll_length, ts * w];
    }
    [ts * f.scroll_length(), ts]
}

/// `dt` seconds as the shortest way round a loop of `period` seconds (if any).
fn loop_delta(dt: f32, period: Option<f32>) -> f32 {
    match period.filter(|p| *p > 0.0) {
        Some(p) => dt - p * (dt / p).round(),
        None => dt,
    }
}

/// How fast (world units per second, along the fire) a feature following `follow` rises
/// in noise moving at `[s, τ]` ([`noise_rates`]).
fn rise([s, tau]: [f32; 2], follow: Follow) -> f32 {
    let c = crate::mapping::TIME_SHEAR;
    match follow {
        Follow::Lattice | Follow::Flow => 0.0,
        Follow::Scroll => s,
        Follow::Noise => (s - c * tau) / (1.0 + c * c),
    }
}

/// Texture coordinates in lattice `b` of the feature at `tex` in lattice `a` that rose by
/// `rise` world units along the fire: see the module docs.
fn follow(tex: V3, a: &Lattice, b: &Lattice, rise: f32) -> V3 {
    let z = (tex[2] * a.length() + rise) / b.length().max(1e-12);
    let k = a.radius_at(tex[2]) / b.radius_at(z).max(1e-12);
    [tex[0] * k, tex[1] * k, z]
}

/// [`Lattice::forward`] without clamping the height: past either end the end cell's map
/// is extrapolated, so a feature that scrolls out of the top still moves on.
fn forward_extrapolated(l: &Lattice, tex: V3) -> V3 {
    let cells = l.cells();
    let x = tex[2] * cells.len() as f32;
    let j = (x.floor().max(0.0) as usize).min(cells.len() - 1);
    cells[j].forward([(tex[0] + 1.0) * 0.5, (tex[1] + 1.0) * 0.5, x - j as f32])
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{FireSpec, Motion};
    use crate::spline::BSpline;
    use ignis_core::Size;

    /// A straight vertical fire of radius 0.5 from z = 0 to 3, `dx` to the right, seen
    /// from the default camera (7 units away) at 64².
    fn column(dx: f32) -> Vec<[f32; 4]> {
        (0..4).map(|i| [dx, 0.0, i as f32, 0.5]).collect()
    }

    fn scene() -> FireScene {
        let mut s = FireScene::empty().with_size(Size::new(64, 64).unwrap());
        s.fires.push(FireSpec::new(Motion::Static(column(0.0))));
        s
    }

    fn lattice(s: &FireScene, points: Vec<[f32; 4]>) -> Lattice {
        Lattice::build(&BSpline::new(points, 3).unwrap(), s.lattice).unwrap()
    }

    /// Pixels per world unit at depth `z` (64² image, the default 40° camera).
    fn px_per_unit(z: f32) -> f32 {
        32.0 / (z * 20f32.to_radians().tan())
    }

    /// The rendered frame's bright pixels (alpha > 0.2) and their count.
    fn bright(s: &FireScene) -> (Vec<bool>, Pose) {
        let (frame, pose) = s.animator().unwrap().next_frame_with_pose().unwrap();
        let b: Vec<bool> = frame.hdr.data().iter().map(|p| p[3] > 0.2).collect();
        assert!(
            b.iter().filter(|&&x| x).count() > 200,
            "the fire is on screen"
        );
        (b, pose)
    }

    /// A fire moved 0.1 world units to the right between two poses (same noise time):
    /// every bright pixel moves right by 0.1 units at the fire's depth (6.5 to 7.5 units),
    /// not up or down, whatever it follows; pixels with no samples do not move.
    #[test]
    fn a_translated_fire_moves_by_its_translation() {
        let s = scene();
        let (bright, a) = bright(&s);
        let mut b = a.clone();
        b.lattices[0] = lattice(&s, column(0.1));
        let to = [Follow::Lattice, Follow::Scroll, Follow::Noise, Follow::Flow].map(|f| (&b, f));
        let (lo, hi) = (0.1 * px_per_unit(7.5), 0.1 * px_per_unit(6.5));
        for m in model_motion(&s, &a, &to).unwrap() {
            for (i, v) in m.iter().enumerate() {
                if bright[i] {
                    assert!(v[0] > lo - 1e-3 && v[0] < hi + 1e-3, "pixel {i}: {v:?}");
                    assert!(v[1].abs() < 0.02, "pixel {i}: {v:?}");
                }
            }
            assert_eq!(m[0], [0.0, 0.0], "a corner pixel shows no fire");
        }
    }

    /// A fire standing still while its noise scrolls: half a second later every bright
    /// pixel shows what was `rise` world units lower, so it moves straight up by that much
    /// on screen: `0.5 · scroll_length` following the scroll, `0.5 · (scroll_length − ½ ·
    /// 1) / (1 + ¼)` along the least-changing track (time scale 1), nothing with the lattice.
    #[test]
    fn a_pure_scroll_moves_straight_up() {
        let s = scene();
        let (bright, a) = bright(&s);
        let mut b = a.clone();
        b.time += 0.5;
        let sl = a.scroll_lengths[0];
        let cases = [
            (Follow::Scroll, 0.5 * sl),
            (Follow::Noise, 0.5 * (sl - 0.5) / 1.25),
            (Follow::Lattice, 0.0),
        ];
        let to = cases.map(|(f, _)| (&b, f));
        let fields = model_motion(&s, &a, &to).unwrap();
        for ((_, rise), m) in cases.iter().zip(&fields) {
            let (lo, hi) = (rise * px_per_unit(7.5), rise * px_per_unit(6.5));
            let mut n = 0;
            for (i, v) in m.iter().enumerate() {
                if bright[i] {
                    assert!(-v[1] >= lo * 0.99 - 1e-4, "pixel {i}: {v:?} {rise}");
                    assert!(-v[1] <= hi * 1.01 + 1e-4, "pixel {i}: {v:?} {rise}");
                    assert!(v[0].abs() < 0.02, "pixel {i}: {v:?}");
                    n += 1;
                }
            }
            assert!(n > 200);
        }
        // backwards in time it moves down
        let back = model_motion(&s, &b, &[(&a, Follow::Noise)])
            .unwrap()
            .remove(0);
        let i = bright.iter().position(|&b| b).unwrap();
        assert!(back[i][1] > 0.0, "{:?}", back[i]);
    }

    /// The model's optical flow sees only what changes the picture: without noise, time
    /// passing changes nothing, so nothing moves (the scroll still says "up"); with noise,
    /// it explains the change: the picture moved by it is closer to the next one.
    #[test]
    fn the_models_flow_moves_only_what_changes() {
        let mut s = scene();
        s.fires[0].noise.octaves = 0;
        let (dark, a) = bright(&s);
        let mut b = a.clone();
        b.time += 0.05;
        let m = model_motion(&s, &a, &[(&b, Follow::Flow), (&b, Follow::Scroll)]).unwrap();
        let i = dark.iter().position(|&b| b).unwrap();
        assert!(m[0].iter().all(|v| *v == [0.0, 0.0]), "no noise: no motion");
        assert!(m[1][i][1] < -0.1, "{:?}", m[1][i]);
        // with noise: frame a's picture moved by the field predicts frame b better than
        // frame a unmoved does (over the lit pixels)
        let s = scene();
        let (lit, a) = bright(&s);
        let mut b = a.clone();
        b.time += 0.05;
        let m = model_motion(&s, &a, &[(&b, Follow::Flow)])
            .unwrap()
            .remove(0);
        assert!(m.iter().all(|v| v[0].is_finite() && v[1].is_finite()));
        let img = |p: &Pose| {
            let inst = p.instances(&s);
            crate::render(&inst, &s.camera, &p.render_params(&s), p.time)
                .unwrap()
                .0
        };
        let (fa, fb) = (img(&a), img(&b));
        let w = s.size.width as usize;
        let lum = |f: &ignis_core::RgbaFrame, x: f32, y: f32| {
            // bilinear, edges clamped
            let (x, y) = ((x - 0.5).max(0.0), (y - 0.5).max(0.0));
            let (x0, y0) = ((x as usize).min(w - 2), (y as usize).min(w - 2));
            let (fx, fy) = ((x - x0 as f32).min(1.0), (y - y0 as f32).min(1.0));
            let l = |i: usize, j: usize| f.data()[j * w + i][1];
            let top = l(x0, y0) * (1.0 - fx) + l(x0 + 1, y0) * fx;
            let bot = l(x0, y0 + 1) * (1.0 - fx) + l(x0 + 1, y0 + 1) * fx;
            top * (1.0 - fy) + bot * fy
        };
        let (mut moved, mut still) = (0.0, 0.0);
        for (i, v) in m.iter().enumerate() {
            if !lit[i] {
                continue;
            }
            let (x, y) = ((i % w) as f32 + 0.5, (i / w) as f32 + 0.5);
            let want = lum(&fb, x, y);
            moved += (lum(&fa, x - v[0], y - v[1]) - want).abs();
            still += (lum(&fa, x, y) - want).abs();
        }
        assert!(moved < 0.9 * still, "moved {moved}, still {still}");
    }

    /// In a loop, a step across the seam is the short way round: the frame just before the
    /// end moves to frame 0 as it moves to the frame one step later.
    #[test]
    fn a_loop_seam_is_one_step() {
        let s = scene();
        let (bright, a) = bright(&s);
        let period = 2.0;
        let at = |t: f32| Pose {
            time: t,
            loop_period: Some(period),
            ..a.clone()
        };
        let (end, start, next) = (at(period - 0.1), at(0.0), at(period + 0.0));
        let m = model_motion(
            &s,
            &end,
            &[(&start, Follow::Scroll), (&next, Follow::Scroll)],
        )
        .unwrap();
        let i = bright.iter().position(|&b| b).unwrap();
        assert!(m[0][i][1] < 0.0, "{:?}", m[0][i]);
        assert_eq!(m[0], m[1]);
    }

    /// More targets than one march serves give the same fields as one target each; a pose
    /// that does not belong to the scene is refused.
    #[test]
    fn targets_together_or_apart_and_bad_poses() {
        let s = scene();
        let (_, a) = bright(&s);
        let mut b = a.clone();
        b.lattices[0] = lattice(&s, column(0.05));
        b.time += 0.1;
        let mut c = a.clone();
        c.time -= 0.2;
        let mut to = vec![(&b, Follow::Noise), (&c, Follow::Scroll)];
        to.extend(std::iter::repeat_n((&b, Follow::Noise), MAX_TARGETS));
        let all = model_motion(&s, &a, &to).unwrap();
        assert_eq!(all.len(), MAX_TARGETS + 2);
        assert_eq!(all[0], model_motion(&s, &a, &to[..1]).unwrap()[0]);
        assert_eq!(all[1], model_motion(&s, &a, &to[1..2]).unwrap()[0]);
        assert!(all[2..].iter().all(|m| *m == all[0]));
        assert_ne!(all[0], all[1]);
        let mut bad = a.clone();
        bad.lattices.clear();
        let e = model_motion(&s, &a, &[(&bad, Follow::Noise)])
            .unwrap_err()
            .to_string();
        assert!(e.contains("pose"), "{e}");
    }

    /// The same fields on one thread as on several (a scripted candle, a bent lattice).
    #[test]
    fn the_same_at_any_thread_count() {
        let s =
            crate::FireScene::preset(crate::Preset::Candle).with_size(Size::new(40, 56).unwrap());
        let mut anim = s.animator().unwrap();
        let a = anim.next_frame_with_pose().unwrap().1;
        anim.skip(3);
        let b = anim.next_frame_with_pose().unwrap().1;
        let to = [(&b, Follow::Scroll), (&b, Follow::Noise)];
        let many = model_motion(&s, &a, &to).unwrap();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let one = pool.install(|| model_motion(&s, &a, &to)).unwrap();
        assert_eq!(many, one);
        assert!(
            many[0].iter().any(|v| v[1] < -0.1),
            "the candle's noise rises"
        );
    }

    /// The frame [`crate::Animator::next_frame_with_pose`] renders is the frame
    /// `next_frame` renders.
    #[test]
    fn frames_with_poses_are_the_same_frames() {
        let s =
            crate::FireScene::preset(crate::Preset::Candle).with_size(Size::new(48, 48).unwrap());
        let (mut a, mut b) = (s.animator().unwrap(), s.animator().unwrap());
        for _ in 0..3 {
            let f = a.next_frame().unwrap();
            let (g, pose) = b.next_frame_with_pose().unwrap();
            assert_eq!(f.image.data(), g.image.data());
            assert_eq!(f.control_points, g.control_points);
            assert_eq!(pose.lattices.len(), 1);
        }
    }
}
