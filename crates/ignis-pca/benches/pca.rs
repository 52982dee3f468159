//! Criterion benches of ignis-pca at a reduced size (the thesis size, 2,197×410×670, takes
//! ~0.5 min and 2.5 GB per iteration: run it once with
//! `cargo run --release -p ignis-pca --example eigen_train_bench`).
//!
//! `cargo bench -p ignis-pca`

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use ignis_pca::{
    fit_streaming, synthetic_flames, Keep, MatSource, Method, Pca, PcaOptions, StreamingOptions,
};

fn pca(c: &mut Criterion) {
    // A quarter of the thesis frame (205×335) and 500 frames: 137 MB of data.
    let (w, h, m) = (205, 335, 500);
    let gen = synthetic_flames(w, h, 7);
    let data = gen.data_matrix(m);
    let pixels = (w * h * m) as u64;

    let mut g = c.benchmark_group("pca");
    g.sample_size(10);
    g.throughput(Throughput::Elements(pixels));
    g.bench_function(format!("snapshot fit_owned {m}x{w}x{h}"), |b| {
        b.iter_batched(
            || data.clone(),
            |a| Pca::fit_owned_with_weights(a, &PcaOptions::default()).unwrap(),
            BatchSize::LargeInput,
        )
    });
    for k in [20usize, 100] {
        let method = Method::Randomized {
            k,
            oversample: 10,
            power_iters: 2,
            seed: 1,
        };
        g.bench_function(format!("randomized k{k} {m}x{w}x{h}"), |b| {
            b.iter(|| {
                Pca::fit(
                    data.as_ref(),
                    &PcaOptions {
                        method,
                        ..Default::default()
                    },
                )
                .unwrap()
            })
        });
    }
    g.bench_function(format!("streaming k20 {m}x{w}x{h}"), |b| {
        b.iter(|| {
            fit_streaming(
                &mut MatSource {
                    data: data.as_ref(),
                },
                20,
                &StreamingOptions::default(),
            )
            .unwrap()
        })
    });
    g.finish();

    let model = Pca::fit(
        data.as_ref(),
        &PcaOptions {
            keep: Keep::Count(200),
            ..Default::default()
        },
    )
    .unwrap();
    let frame = data.col_as_slice(0).to_vec();
    let weights = model.project(&frame);
    let mut out = vec![0.0f32; w * h];
    let mut g = c.benchmark_group("pca per frame");
    g.throughput(Throughput::Elements((w * h) as u64));
    g.bench_function(format!("project k200 {w}x{h}"), |b| {
        b.iter(|| model.project(&frame))
    });
    g.bench_function(format!("reconstruct_into k200 {w}x{h}"), |b| {
        b.iter(|| model.reconstruct_into(&weights, 200, &mut out))
    });
    g.finish();
}

criterion_group!(benches, pca);
criterion_main!(benches);
