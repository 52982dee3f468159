//! Criterion benches of `ignis-flow`: the issues' speed goals (512² flow ≤ 15 ms, 1080p
//! flow ≤ 60 ms, 1080p RGBA motion-compensated mid frame ≤ 50 ms, on 2 cores). Inputs are
//! seeded synthetic textures moved by a known shift, built outside the timed closures.
//! `ignis bench flow` prints the same figures as JSON.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use ignis_core::{RgbaFrame, Size};
use ignis_flow::{bench::texture, flow, flow_pair_reduced, luma, morph_rgba, FlowParams};

fn benches(c: &mut Criterion) {
    let p = FlowParams::default();
    let mut g = c.benchmark_group("flow");
    g.sample_size(20);

    let s = Size::new(512, 512).unwrap();
    let (a, b) = (
        texture(s, 1, [0.0; 2], 1.5),
        texture(s, 1, [2.5, -1.5], 1.5),
    );
    g.throughput(Throughput::Elements(s.pixels() as u64));
    g.bench_function("flow dis 512x512", |bn| {
        bn.iter(|| flow(&a, &b, &p).unwrap())
    });

    let hd = Size::new(1920, 1080).unwrap();
    let (a, b) = (
        texture(hd, 2, [0.0; 2], 4.0),
        texture(hd, 2, [7.5, -4.0], 4.0),
    );
    g.throughput(Throughput::Elements(hd.pixels() as u64));
    g.bench_function("flow dis 1920x1080 via 512", |bn| {
        bn.iter(|| flow(&a, &b, &p).unwrap())
    });

    let (ca, cb): (RgbaFrame, RgbaFrame) = (a.to_rgba(), b.to_rgba());
    g.bench_function("morph rgba 1920x1080 mid frame", |bn| {
        bn.iter(|| {
            let (f, gb) = flow_pair_reduced(&luma(&ca), &luma(&cb), &p).unwrap();
            morph_rgba(&ca, &cb, &f, &gb, 0.5).unwrap()
        })
    });
    g.finish();
}

criterion_group!(flow_benches, benches);
criterion_main!(flow_benches);
