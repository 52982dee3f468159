//! Golden images of the volume renderer: tiny frames of the built-in presets compared with
//! stored ones (`tests/golden/*.f32`, format in [`ignis_core::golden`]).
//!
//! Tolerance: a max abs error of [`TOLERANCE`] per channel of the linear HDR values (peaks
//! ≈ 1–3). The renderer is deterministic (same bytes on every thread count and with or
//! without AVX2, tested in `render`), so on one platform the difference is exactly 0; the
//! margin only absorbs another platform's `libm` rounding (`exp`, `powf` in the profile and
//! noise mapping). It is below the fast path's own error against the reference (1e-4), so
//! any change to the marching, inverse, noise or shading shows. `UPDATE_GOLDEN=1`
//! rewrites the goldens (look at them before committing: e.g. with numpy, see the format).

use ignis_core::golden::check_rgba;
use ignis_core::{RgbaFrame, Size};
use ignis_volume::{render, BSpline, FireInstance, FireScene, Lattice, Preset};
use std::path::PathBuf;

/// Max abs error per channel (see the module docs).
const TOLERANCE: f32 = 2e-5;

fn check(name: &str, frame: &RgbaFrame) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/golden")
        .join(name);
    // a golden of an empty frame would test nothing
    let peak = frame
        .data()
        .iter()
        .map(|p| p[0].max(p[1]).max(p[2]))
        .fold(0.0f32, f32::max);
    assert!(
        peak > 0.2,
        "{name}: the frame is nearly black (peak {peak})"
    );
    match check_rgba(&path, frame, TOLERANCE) {
        Ok(worst) => println!("{name}: max abs difference {worst:e}"),
        Err(e) => panic!("{e}"),
    }
}

fn small(p: Preset) -> FireScene {
    FireScene::preset(p).with_size(Size::new(48, 48).unwrap())
}

/// Frame 5 of the torch (a scripted fire, not looping): the renderer's premultiplied HDR
/// output and the finished frame (bloom, straight alpha).
#[test]
fn torch_frame() {
    let scene = small(Preset::Torch);
    let mut anim = scene.animator().unwrap();
    anim.skip(5);
    let f = anim.next_frame().unwrap();
    check("volume-torch-48-f5-hdr.f32", &f.hdr);
    check("volume-torch-48-f5-finished.f32", &f.image);
}

/// Frame 7 of an 18-frame campfire loop (several fires, the noise periodic in time, the
/// frames re-timed at constant speed: the golden was remade when that came in).
#[test]
fn campfire_loop_frame() {
    let scene = small(Preset::Campfire);
    let mut anim = scene.looping_animator(18).unwrap();
    anim.skip(7);
    let f = anim.next_frame().unwrap();
    check("volume-campfire-48-loop18-f7-hdr.f32", &f.hdr);
}

/// The reference path (`exact_inverse`) on the torch's frame 5.
#[test]
fn torch_frame_reference_path() {
    let scene = small(Preset::Torch);
    let mut anim = scene.animator().unwrap();
    anim.skip(5);
    let time = anim.frame_index() as f32 / scene.fps;
    let (pts, _) = anim.step();
    let lattices: Vec<Lattice> = pts
        .iter()
        .zip(&scene.fires)
        .map(|(p, f)| {
            Lattice::build(&BSpline::new(p.clone(), f.degree).unwrap(), scene.lattice).unwrap()
        })
        .collect();
    let inst: Vec<FireInstance> = lattices
        .iter()
        .zip(&scene.fires)
        .enumerate()
        .map(|(i, (lattice, f))| FireInstance {
            lattice,
            profile: &f.profile,
            noise: f.noise,
            offset: scene.offset(i),
            scroll_length: None,
        })
        .collect();
    let params = ignis_volume::RenderParams {
        exact_inverse: true,
        ..scene.render_params()
    };
    let (hdr, _) = render(&inst, &scene.camera, &params, time).unwrap();
    check("volume-torch-48-f5-reference-hdr.f32", &hdr);
}
