//! The fast paths against the reference path, and the invariants they rely on.

use super::bin::Candidate;
use super::march_cells::per_cell_ok;
use super::march_ray::{in_unit_cylinder, MAX_RANGES};
use super::tile::{FrameRenderer, Scratch};
use super::visible::visible_parts;
use super::*;
use crate::lattice::{dot, sub};
use crate::mapping::radial_u;

use crate::{BSpline, FireScene, NoiseKind, Preset};

/// The lattices of `scene`'s fires at its animation's first step.
fn first_lattices(scene: &FireScene) -> Vec<Lattice> {
    let mut anim = scene.animator().unwrap();
    let (pts, _) = anim.step();
    pts.iter()
        .zip(&scene.fires)
        .map(|(p, f)| {
            Lattice::build(&BSpline::new(p.clone(), f.degree).unwrap(), scene.lattice).unwrap()
        })
        .collect()
}

/// `scene`'s fires over `lats`, as the renderer takes them.
fn instances<'a>(scene: &'a FireScene, lats: &'a [Lattice]) -> Vec<FireInstance<'a>> {
    lats.iter()
        .zip(&scene.fires)
        .enumerate()
        .map(|(i, (lat, f))| FireInstance {
            lattice: lat,
            profile: &f.profile,
            noise: f.noise,
            offset: scene.offset(i),
            scroll_length: None,
        })
        .collect()
}

/// Renders the first frame of `scene` (all fires) with and without `exact_inverse`.
fn fast_and_exact(
    scene: &FireScene,
    time: f32,
    loop_period: Option<f32>,
) -> [(RgbaFrame, RenderStats); 2] {
    let lats = first_lattices(scene);
    let inst = instances(scene, &lats);
    let mut params = scene.render_params();
    params.loop_period = loop_period;
    assert!(!params.exact_inverse);
    params.count_coverage = true;
    let fast = render(&inst, &scene.camera, &params, time).unwrap();
    params.exact_inverse = true;
    let exact = render(&inst, &scene.camera, &params, time).unwrap();
    [fast, exact]
}

fn max_difference(a: &RgbaFrame, b: &RgbaFrame) -> (f32, f32) {
    let mut worst = 0.0f32;
    let mut peak = 0.0f32;
    for (a, b) in a.data().iter().zip(b.data()) {
        for k in 0..4 {
            worst = worst.max((a[k] - b[k]).abs());
            peak = peak.max(b[k].abs());
        }
    }
    (worst, peak)
}

/// The fast path (predicted Newton / chord inverse, batched noise, octave skipping)
/// against the reference path (`exact_inverse`: chord-then-Newton from the cell centre
/// to 1e-5, every sample shaded by the scalar `shade`). The shading is identical for
/// identical samples (see `batched_shading_equals_scalar_shading`), so what remains is
/// the inverse's accuracy (the certified inverse's texture coordinates are within
/// [`INVERSE_TEX_TOL`] of the exact ones), against peaks ≥ 1 (Table 1 scenes, lattice 35
/// and 135, all noises, cartoon blend, two bent presets). The limit, 1e-4 of the peak (at
/// least 1), is just above the measured difference (`benches/README.md`), so a regression shows.
#[test]
fn fast_path_matches_exact_within_tolerance() {
    let small = Size::new(96, 72).unwrap();
    let mut scenes = Vec::new();
    for lattice in [35usize, 135] {
        for (kind, octaves) in [(NoiseKind::Perlin3, 2), (NoiseKind::Perlin4, 3)] {
            scenes.push(FireScene::table1(kind, octaves, lattice).with_size(small));
        }
    }
    let mut mn = FireScene::table1(NoiseKind::Mnoise, 1, 35).with_size(small);
    mn.blend = Blend::Cartoon;
    scenes.push(mn);
    for p in [Preset::Campfire, Preset::Torch] {
        // the bent lattices with moderate noise: the presets' own detailed noise turns
        // the same texture-coordinate error into up to 3e-4 of the peak
        let mut s = FireScene::preset(p).with_size(Size::new(64, 64).unwrap());
        s.fires.iter_mut().for_each(|f| f.noise.stability = 0.45);
        scenes.push(s);
    }
    // the Table 1 lattices take the per-cell march
    for lattice in [35usize, 135] {
        let scene = FireScene::table1(NoiseKind::Perlin4, 3, lattice);
        let mut anim = scene.animator().unwrap();
        let (pts, _) = anim.step();
        let lat = Lattice::build(&BSpline::new(pts[0].clone(), 3).unwrap(), lattice).unwrap();
        assert!(per_cell_ok(&lat), "lattice {lattice}");
    }
    // and every scene looping (two noise copies mixed) at a time near the mix's middle
    let runs = scenes
        .iter()
        .map(|s| (s, None))
        .chain(scenes.iter().map(|s| (s, Some(1.3f32))));
    for (i, (scene, loop_period)) in runs.enumerate() {
        let [(fast, sf), (exact, se)] = fast_and_exact(scene, 0.5, loop_period);
        assert!(se.covered_pixels > 200, "scene {i}: {se:?}");
        let (worst, peak) = max_difference(&fast, &exact);
        println!("scene {i}: max difference {worst:.2e}, peak {peak:.3}");
        assert!(peak > 0.1, "scene {i}: peak {peak}");
        // relative to the peak: exposure scales the inverse's error with the image
        assert!(
            worst < 1e-4 * peak.max(1.0),
            "scene {i}: max difference {worst} (peak {peak})"
        );
        let dc = sf.covered_pixels.abs_diff(se.covered_pixels);
        assert!(dc * 100 <= se.covered_pixels, "scene {i}: {sf:?} vs {se:?}");
    }
}

/// The per-cell march gives every sample to exactly one cell, also where a pixel
/// row's samples lie on the faces between cells: a straight upright fire with levels
/// every 0.1 and a horizontal camera ray at a level's height (the middle row of an odd
/// image), against the ray-by-ray reference. A sample counted twice or dropped would
/// change its pixel by about `intensity · spacing · alpha` (≥ 1e-2 here).
#[test]
fn per_cell_march_claims_samples_on_faces_once() {
    use crate::{FireSpec, Motion};
    for (lattice, kind) in [(31usize, NoiseKind::Perlin4), (121, NoiseKind::Perlin3)] {
        let mut scene = FireScene::table1(kind, 2, lattice).with_size(Size::new(75, 61).unwrap());
        scene.fires[0] = FireSpec {
            noise: scene.fires[0].noise,
            ..FireSpec::new(Motion::Static(vec![
                [0.0, 0.0, 0.0, 1.0],
                [0.0, 0.0, 1.0, 1.0],
                [0.0, 0.0, 2.0, 1.0],
                [0.0, 0.0, 3.0, 1.0],
            ]))
        };
        scene.camera = Camera {
            position: [0.0, -7.0, 1.5],
            target: [0.0, 0.0, 1.5],
            fov: 40.0,
        };
        let mut anim = scene.animator().unwrap();
        let (pts, _) = anim.step();
        let lat = Lattice::build(&BSpline::new(pts[0].clone(), 3).unwrap(), lattice).unwrap();
        assert!(per_cell_ok(&lat));
        let [(fast, sf), (exact, se)] = fast_and_exact(&scene, 0.3, None);
        let (worst, peak) = max_difference(&fast, &exact);
        assert!(peak > 0.1 && se.shaded > 1000, "{se:?}");
        assert!(worst < 1e-4, "lattice {lattice}: max difference {worst}");
        // the middle row (on a face) has samples, and the same number as the reference
        let row = |f: &RgbaFrame| f.data()[30 * 75..31 * 75].iter().map(|p| p[3]).sum::<f32>();
        assert!(row(&exact) > 1.0);
        assert!((row(&fast) - row(&exact)).abs() < 1e-3);
        assert!(sf.covered_pixels.abs_diff(se.covered_pixels) * 100 <= se.covered_pixels);
    }
}

/// The square-root-free cylinder test (`in_unit_cylinder`) agrees with
/// `radial_u(tex) ≤ 1`.
#[test]
fn squared_radius_test_matches_radial_u() {
    let mut q = 0.999_f32;
    while q < 1.001 {
        let tex = [q.sqrt(), 0.0, 0.5];
        let exact = radial_u([tex[0], tex[1], 0.0]) > 1.0;
        let fast = !in_unit_cylinder(tex);
        assert_eq!(exact, fast, "{q}");
        q = f32::from_bits(q.to_bits() + 1);
    }
    for bits in (1.0f32 - 1e-3).to_bits()..(1.0f32 + 1e-3).to_bits() {
        let s = f32::from_bits(bits);
        assert_eq!(s.sqrt() > 1.0, s > 1.0 + f32::EPSILON, "{s}");
    }
}

/// The AVX2 build of the tile renderer and the baseline build give the same bytes
/// (both paths, additive and cartoon blends).
#[test]
fn simd_build_matches_baseline_build() {
    let mut scenes = vec![
        FireScene::table1(NoiseKind::Perlin4, 3, 35).with_size(Size::new(80, 60).unwrap()),
        FireScene::table1(NoiseKind::Perlin3, 3, 135).with_size(Size::new(80, 60).unwrap()),
        FireScene::preset(Preset::Campfire).with_size(Size::new(64, 64).unwrap()),
    ];
    let mut mn = FireScene::table1(NoiseKind::Mnoise, 1, 35).with_size(Size::new(64, 48).unwrap());
    mn.blend = Blend::Cartoon;
    scenes.push(mn);
    for scene in &scenes {
        let lats = first_lattices(scene);
        let inst = instances(scene, &lats);
        let mut params = scene.render_params();
        for exact in [false, true] {
            params.exact_inverse = exact;
            let a = render_with(&inst, &scene.camera, &params, 0.7, true).unwrap();
            let b = render_with(&inst, &scene.camera, &params, 0.7, false).unwrap();
            assert_eq!(a.1, b.1);
            assert!(a.1.shaded > 100);
            for (x, y) in a.0.data().iter().zip(b.0.data()) {
                assert_eq!(x.map(f32::to_bits), y.map(f32::to_bits));
            }
        }
    }
}

/// The batched shading (lanes noise, octaves skipped only where the alpha is provably
/// zero) gives the very same colour as `shade` for every sample, and every sample with
/// some alpha lies in the part of its cell the fast path marches (`visible_parts`).
// (Long: it marches each scene once and checks the culling, the row spans and the shading
// on the very same samples.)
#[test]
fn batched_shading_equals_scalar_shading_and_culls_only_invisible_samples() {
    let mut scenes = Vec::new();
    for kind in [NoiseKind::Perlin3, NoiseKind::Perlin4, NoiseKind::Mnoise] {
        scenes.push(FireScene::table1(kind, 3, 35).with_size(Size::new(64, 48).unwrap()));
    }
    for p in Preset::ALL {
        scenes.push(FireScene::preset(p).with_size(Size::new(48, 48).unwrap()));
    }
    let mut calm = FireScene::table1(NoiseKind::Perlin4, 0, 35);
    calm = calm.with_size(Size::new(64, 48).unwrap());
    scenes.push(calm);
    for scene in &scenes {
        let mut anim = scene.animator().unwrap();
        let (pts, _) = anim.step();
        let f = &scene.fires[0];
        let lat = Lattice::build(
            &BSpline::new(pts[0].clone(), f.degree).unwrap(),
            scene.lattice,
        )
        .unwrap();
        let inst = [FireInstance {
            lattice: &lat,
            profile: &f.profile,
            noise: f.noise,
            offset: scene.offset(0),
            scroll_length: None,
        }];
        let params = scene.render_params();
        let (forward, right, up) = scene.camera.basis();
        let size = params.size;
        let ctx = FrameRenderer {
            fires: &inst,
            camera: &scene.camera,
            params: &params,
            forward,
            right,
            up,
            tan: scene.camera.half_height(size),
            aspect: size.width as f32 / size.height as f32,
            time: 1.25,
            simd: true,
            per_cell: vec![false],
        };
        // every sample of the whole image in one batch
        let cands: Vec<Candidate> = lat
            .cells()
            .iter()
            .enumerate()
            .map(|(i, c)| Candidate {
                fire: 0,
                cell: i as u32,
                min: sub(c.min, scene.camera.position),
                max: sub(c.max, scene.camera.position),
                visible_min: sub(c.min, scene.camera.position),
                visible_max: sub(c.max, scene.camera.position),
                disc: None,
                pixel_rect: [i32::MIN, i32::MAX, i32::MIN, i32::MAX],
            })
            .collect();
        let mut s = Scratch::default();
        let mut ranges = [(0u32, 0.0f32, 0.0f32); MAX_RANGES];
        let mut stats = RenderStats::default();
        for y in 0..size.height {
            for x in 0..size.width {
                ctx.march(
                    &inst[0],
                    &cands,
                    x,
                    y,
                    i64::MAX,
                    0,
                    &mut ranges,
                    &mut stats,
                    &mut s,
                );
            }
        }
        assert!(s.tex.len() > 300, "{stats:?}");
        ctx.shade_reference(&inst[0], &mut s);
        let reference = s.col.clone();
        // every visible sample lies in its cell's visible box (what the fast path
        // marches)
        let visible = visible_parts(&inst[0], scene.camera.position, false, None);
        let n = lat.cells().len();
        let mut discs = 0;
        for (tex, c) in s.tex.iter().zip(&reference) {
            if c[3] <= 0.0 {
                continue;
            }
            let p = lat.forward(*tex);
            let j = ((tex[2] * n as f32) as usize).min(n - 1);
            let inside = |j: usize| {
                let v = &visible[j];
                let in_box = (0..3).all(|a| p[a] >= v.min[a] && p[a] <= v.max[a]);
                match &v.disc {
                    Some(d) => in_box && d.contains(p, scene.camera.position),
                    None => in_box,
                }
            };
            discs += visible[j].disc.is_some() as usize;
            assert!(
                inside(j) || (j > 0 && inside(j - 1)),
                "visible sample at {tex:?} outside the visible part of cell {j}"
            );
            // and its ray's screen position within the row span of its cell's disc
            // (`march_cells` widens that by a pixel, ≈ 4e-3 in `sx` here)
            let d = sub(p, scene.camera.position);
            let z = dot(d, ctx.forward);
            let (sx, sy) = ((dot(d, ctx.right) / z) as f64, dot(d, ctx.up) / z);
            let spans = |j: usize| match &visible[j].disc {
                Some(disc) => disc
                    .row_span(ctx.forward, ctx.right, ctx.up, sy)
                    .is_some_and(|(lo, hi)| lo - 1e-4 <= sx && sx <= hi + 1e-4),
                None => true,
            };
            assert!(
                spans(j) || (j > 0 && spans(j - 1)),
                "visible sample at {tex:?} outside the row span of cell {j}"
            );
        }
        // nearly every visible sample was checked against a disc too
        let lit = reference.iter().filter(|c| c[3] > 0.0).count();
        assert!(
            discs * 10 >= lit * 9,
            "{discs} of {lit} in cells with a disc"
        );
        let visible = reference.iter().filter(|c| c[3] > 0.0).count();
        assert!(visible > 100 && visible < reference.len());
        #[cfg(target_arch = "x86_64")]
        let builds = [false, std::arch::is_x86_feature_detected!("avx2")];
        #[cfg(not(target_arch = "x86_64"))]
        let builds = [false];
        for avx2 in builds {
            ctx.shade_batched(&inst[0], &mut s, avx2);
            for (i, (a, b)) in s.col.iter().zip(&reference).enumerate() {
                assert!(
                    a == b,
                    "sample {i} at {:?}: {a:?} vs {b:?} ({avx2})",
                    s.tex[i]
                );
            }
        }
    }
}
