//! Fuller et al. Table 1 on the CPU: one unit-radius fire, slice spacing 0.2, ≈ 90,000
//! covered pixels; noise type × octaves × lattice resolution.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use ignis_volume::{render, FireInstance, FireScene, Lattice, NoiseKind};

fn table1(c: &mut Criterion) {
    let mut g = c.benchmark_group("volume table1");
    g.sample_size(20);
    for (kind, octaves) in [
        (NoiseKind::Mnoise, 1),
        (NoiseKind::Perlin3, 3),
        (NoiseKind::Perlin4, 3),
    ] {
        for lattice in [35usize, 135] {
            let scene = FireScene::table1(kind, octaves, lattice);
            let mut anim = scene.animator().expect("valid scene");
            let (pts, _) = anim.step();
            let curve = ignis_volume::BSpline::new(pts[0].clone(), scene.fires[0].degree).unwrap();
            let lat = Lattice::build(&curve, lattice).unwrap();
            let inst = [FireInstance {
                lattice: &lat,
                profile: &scene.fires[0].profile,
                noise: scene.fires[0].noise,
                offset: scene.offset(0),
                scroll_length: None,
            }];
            let params = scene.render_params();
            let counting = ignis_volume::RenderParams {
                count_coverage: true,
                ..params
            };
            let (_, stats) = render(&inst, &scene.camera, &counting, 0.5).unwrap();
            g.throughput(Throughput::Elements(stats.covered_pixels));
            let name = format!(
                "{} x{octaves} lattice {lattice} {}",
                kind.name(),
                scene.size
            );
            g.bench_function(name, |b| {
                b.iter(|| render(&inst, &scene.camera, &params, 0.5).unwrap())
            });
        }
    }
    g.finish();
}

criterion_group!(benches, table1);
criterion_main!(benches);
