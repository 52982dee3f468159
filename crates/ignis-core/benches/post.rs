//! Criterion benches of the colour and post stage at the thesis frame size (410×670,
//! §4.2): bloom (§6.2) on a grey and an RGBA frame with default [`BloomParams`], and
//! synthetic HLS colouring (§6.1.2). The budget for colour + bloom is ≈ 4 ms per
//! frame on 2 cores.
//!
//! `cargo bench -p ignis-core --bench post`

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use ignis_core::colour::{synthetic_colour, Tint};
use ignis_core::post::{bloom, bloom_rgba, gaussian_blur, BloomParams};
use ignis_core::{GrayFrame, RgbaFrame, Rng, Size};

/// A flame-like grey frame: a bright teardrop near the bottom centre with seeded noise.
fn flame(size: Size, seed: u64) -> GrayFrame {
    let mut rng = Rng::new(seed);
    let (w, h) = (size.width as f32, size.height as f32);
    GrayFrame::from_fn(size, |x, y| {
        let u = (x as f32 + 0.5) / w - 0.5;
        let v = 1.0 - (y as f32 + 0.5) / h; // 0 at the bottom
        let half_width = 0.25 * (1.0 - v).max(0.0) * (v * 6.0).min(1.0);
        let body = (1.0 - (u.abs() / half_width.max(1e-3))).clamp(0.0, 1.0);
        (body * (0.8 + 0.4 * rng.f32())).min(1.2)
    })
}

fn post(c: &mut Criterion) {
    let size = Size::new(410, 670).unwrap();
    let gray = flame(size, 7);
    let rgba = RgbaFrame::from_vec(
        size,
        gray.data()
            .iter()
            .map(|&v| [v, 0.6 * v, 0.2 * v, 1.0])
            .collect(),
    )
    .unwrap();
    let p = BloomParams::default();
    let name = |what: &str| format!("{what} {}x{}", size.width, size.height);

    let mut g = c.benchmark_group("post");
    g.sample_size(20);
    g.throughput(Throughput::Elements(size.pixels() as u64));
    g.bench_function(name("bloom gray default"), |b| {
        b.iter(|| bloom(&gray, &p).unwrap())
    });
    g.bench_function(name("bloom_rgba default"), |b| {
        b.iter(|| bloom_rgba(&rgba, &p).unwrap())
    });
    g.bench_function(name("gaussian_blur sigma6"), |b| {
        b.iter(|| gaussian_blur(&gray, 6.0))
    });
    let tint = Tint::Solid([1.0, 0.35, 0.05]);
    g.bench_function(name("synthetic_colour solid"), |b| {
        b.iter(|| synthetic_colour(&gray, &tint).unwrap())
    });
    g.finish();
}

criterion_group!(benches, post);
criterion_main!(benches);
