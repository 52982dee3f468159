//! Criterion benches of learned flames: `cargo bench -p ignis-learned`.
//! Inputs are built outside the timed closures; everything is seeded.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use ignis_core::{GrayFrame, Size};
use ignis_learned::{synthetic, train, Controls, EmParams, Synthesiser, TrainParams};
use std::hint::black_box;

fn benches(c: &mut Criterion) {
    let size = Size::new(256, 256).unwrap();
    let clip = synthetic::flame_clip(size, 100, 1);
    let p = TrainParams {
        em: EmParams {
            seed: 1,
            ..EmParams::default()
        },
        ..TrainParams::default()
    };
    let model = train(clip.clone(), &p, &mut ignis_core::progress::NoProgress)
        .unwrap()
        .model;

    let mut g = c.benchmark_group("learned");
    g.sample_size(10);
    g.bench_function("learned train 100x256x256 26p nc200", |b| {
        b.iter(|| {
            black_box(
                train(clip.clone(), &p, &mut ignis_core::progress::NoProgress)
                    .unwrap()
                    .model
                    .n_state(),
            )
        })
    });
    g.throughput(Throughput::Elements(size.pixels() as u64));
    g.sample_size(50);
    g.bench_function("learned synth+render 256x256", |b| {
        let mut s = Synthesiser::new(&model, Controls::default(), 1).unwrap();
        let mut out = GrayFrame::new(size);
        b.iter(|| {
            s.next_frame_into(&mut out);
            black_box(out.data()[0])
        })
    });
    g.bench_function("learned normalise 256x256", |b| {
        let sp = ignis_learned::ShapeParams::default();
        b.iter(|| black_box(ignis_learned::shape::normalise(&clip[0], &sp).is_ok()))
    });
    g.finish();
}

criterion_group!(learned, benches);
criterion_main!(learned);
