//! The volumetric fire's own motion on screen, from the model: per output pixel, how far
//! what it shows moves from one frame ([`Pose`]) to another, in pixels. For motion-vector
//! flipbooks (issue 17), where the alternative is optical flow between the rendered frames.
//!
//! Source: fuller-procedural-volumetric-fire.txt §3–4. A sample at world point `x` has
//! texture coordinates `tex = L_a⁻¹(x)` in frame `a`'s lattice; its look comes from the
//! noise at `noise_position(tex, …)` (eq. 11), which scrolls up along the fire. The same
//! noise feature (the same spatial noise coordinate) is at `tex'` in frame `b`, where
//!
//! - along the fire, `tex'_z · length_b − W_b = tex_z · length_a − W_a`, `W` the scroll
//!   in world units at each frame's noise time ([`crate::mapping::scroll_time`] × length;
//!   a loop's scroll is taken modulo its period, so the seam is not a jump);
//! - across it, `tex'_xy · r_b(tex'_z) = tex_xy · r_a(tex_z)` (eq. 10 scales the noise by
//!   the local radius);
//!
//! and in the world at `x' = L_b(tex')` (the lattice's map, extrapolated past its ends).
//! The sample's motion is `project(x') − project(x)` with the scene's camera; a pixel's is
//! the mean of its samples' motions weighted by their emission (luminance × alpha of the
//! shaded sample: what each adds to the additive blend), 0 where it has none.
//!
//! What this leaves out: the noise's own change in time (its 4-th coordinate `w`, which no
//! displacement describes) and the profile, which does not scroll; so it is one candidate
//! among others (none / forward / backward), chosen per pixel by the rendered in-between
//! frames where they exist (`ignis_media::write::motion::chosen_velocities`). Samples come
//! from the renderer's reference path (`render/reference.rs`: every slice, exact inverse):
//! slow, but exact and the same samples the image is made of.

use crate::error::{Result, VolumeError};
use crate::lattice::{Lattice, V3};
use crate::render::{reference_sums, FireInstance, RenderParams};
use crate::scene::{FireScene, Pose};

/// Per pixel of `scene`'s frame in pose `from`, its motion to each pose of `to`, in pixels
/// (`[dx, dy]`, y down; row-major). See the module docs. Fails if the poses do not hold one
/// lattice per fire of `scene`, or as [`crate::render()`] fails.
pub fn model_motion(scene: &FireScene, from: &Pose, to: &[&Pose]) -> Result<Vec<Vec<[f32; 2]>>> {
    for p in std::iter::once(from).chain(to.iter().copied()) {
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
    let size = scene.size;
    let inst = from.instances(scene);
    let params = from.render_params(scene);
    let scroll_a: Vec<(f32, Option<f32>)> = inst
        .iter()
        .map(|f| world_scroll(f, &params, from.time))
        .collect();
    let targets: Vec<(Vec<FireInstance>, Vec<(f32, Option<f32>)>)> = to
        .iter()
        .map(|p| {
            let inst = p.instances(scene);
            let params = p.render_params(scene);
            let sc = inst
                .iter()
                .map(|f| world_scroll(f, &params, p.time))
                .collect();
            (inst, sc)
        })
        .collect();
    let camera = scene.camera;
    // per sample and target of `chunk` (at most MAX_TARGETS): [w, w·dx, w·dy]
    let f = |fi: usize, tex: V3, col: [f32; 4], chunk: &[usize]| -> [f32; 3 * MAX_TARGETS] {
        let mut out = [0.0; 3 * MAX_TARGETS];
        let w = col[3] * (0.2126 * col[0] + 0.7152 * col[1] + 0.0722 * col[2]);
        if w <= 0.0 {
            return out;
        }
        let a = &inst[fi];
        let Some(p0) = camera.project(a.lattice.forward(tex), size) else {
            return out;
        };
        for (j, &t) in chunk.iter().enumerate() {
            let (tinst, tsc) = &targets[t];
            let b = &tinst[fi];
            let tex_b = follow(tex, a.lattice, scroll_a[fi], b.lattice, tsc[fi]);
            if let Some(p1) = camera.project(forward_extrapolated(b.lattice, tex_b), size) {
                out[3 * j] = w;
                out[3 * j + 1] = w * (p1[0] - p0[0]);
                out[3 * j + 2] = w * (p1[1] - p0[1]);
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
        for j in 0..chunk.len() {
            fields.push(
                sums.iter()
                    .map(|s| {
                        let w = s[3 * j];
                        if w > 0.0 {
                            [s[3 * j + 1] / w, s[3 * j + 2] / w]
                        } else {
                            [0.0; 2]
                        }
                    })
                    .collect(),
            );
        }
    }
    Ok(fields)
}

/// Most target poses one march serves (more are done in further marches).
const MAX_TARGETS: usize = 2;

/// Fire `f`'s scroll at scene time `time` in world units along the fire, `W` in the
/// module docs, and its period where a loop makes it periodic.
fn world_scroll(f: &FireInstance, params: &RenderParams, time: f32) -> (f32, Option<f32>) {
    if let Some(pl) = params.periodic(f, time) {
        let period = pl.period[0] as f32 / f.noise.frequency;
        return (pl.scroll_time * pl.scroll_length, Some(period));
    }
    if let Some(m) = params.mix(f, time) {
        return (
            m.time * f.scroll_length(),
            Some(m.period * f.scroll_length()),
        );
    }
    (time * f.noise.time_scale * f.scroll_length(), None)
}

/// Texture coordinates in lattice `b` (scroll `sb`) of the noise feature at `tex` in
/// lattice `a` (scroll `sa`): see the module docs.
fn follow(tex: V3, a: &Lattice, sa: (f32, Option<f32>), b: &Lattice, sb: (f32, Option<f32>)) -> V3 {
    let mut dw = sb.0 - sa.0;
    if let Some(p) = sa.1.or(sb.1).filter(|p| *p > 0.0) {
        dw -= p * (dw / p).round();
    }
    let z = (tex[2] * a.length() + dw) / b.length().max(1e-12);
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
    /// not up or down; pixels with no samples do not move.
    #[test]
    fn a_translated_fire_moves_by_its_translation() {
        let s = scene();
        let (bright, a) = bright(&s);
        let mut b = a.clone();
        b.lattices[0] = lattice(&s, column(0.1));
        let m = model_motion(&s, &a, &[&b]).unwrap().remove(0);
        let (lo, hi) = (0.1 * px_per_unit(7.5), 0.1 * px_per_unit(6.5));
        for (i, v) in m.iter().enumerate() {
            if bright[i] {
                assert!(v[0] > lo - 1e-3 && v[0] < hi + 1e-3, "pixel {i}: {v:?}");
                assert!(v[1].abs() < 0.02, "pixel {i}: {v:?}");
            }
        }
        assert_eq!(m[0], [0.0, 0.0], "a corner pixel shows no fire");
    }

    /// A fire standing still while its noise scrolls: half a second later every bright
    /// pixel shows what was `0.5 · scroll_length` world units lower (its noise rises),
    /// so it moves straight up by that much on screen.
    #[test]
    fn a_pure_scroll_moves_straight_up() {
        let s = scene();
        let (bright, a) = bright(&s);
        let mut b = a.clone();
        b.time += 0.5;
        let rise = 0.5 * a.scroll_lengths[0];
        let m = model_motion(&s, &a, &[&b]).unwrap().remove(0);
        let (lo, hi) = (rise * px_per_unit(7.5), rise * px_per_unit(6.5));
        let mut n = 0;
        for (i, v) in m.iter().enumerate() {
            if bright[i] {
                assert!(-v[1] > lo * 0.99 && -v[1] < hi * 1.01, "pixel {i}: {v:?}");
                assert!(v[0].abs() < 0.02, "pixel {i}: {v:?}");
                n += 1;
            }
        }
        assert!(n > 200);
        // backwards in time it moves down by as much
        let back = model_motion(&s, &b, &[&a]).unwrap().remove(0);
        let i = m.iter().zip(&bright).position(|(_, &b)| b).unwrap();
        assert!(back[i][1] > 0.0, "{:?}", back[i]);
    }

    /// Two targets in one march give the same fields as one target each; a pose that does
    /// not belong to the scene is refused.
    #[test]
    fn targets_together_or_apart_and_bad_poses() {
        let s = scene();
        let (_, a) = bright(&s);
        let mut b = a.clone();
        b.lattices[0] = lattice(&s, column(0.05));
        b.time += 0.1;
        let mut c = a.clone();
        c.time -= 0.2;
        let both = model_motion(&s, &a, &[&b, &c, &b]).unwrap();
        assert_eq!(both.len(), 3);
        assert_eq!(both[0], model_motion(&s, &a, &[&b]).unwrap()[0]);
        assert_eq!(both[1], model_motion(&s, &a, &[&c]).unwrap()[0]);
        assert_eq!(both[2], both[0]);
        let mut bad = a.clone();
        bad.lattices.clear();
        let e = model_motion(&s, &a, &[&bad]).unwrap_err().to_string();
        assert!(e.contains("pose"), "{e}");
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
