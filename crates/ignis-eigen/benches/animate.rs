//! Criterion benches of Eigenfires II on the small benchmark database (300 frames of
//! 164×268, trained from the synthetic clips, see `ignis_eigen::bench`): each transition
//! method on a fresh `WeightSpace` (cold step cache, as a user's first transition), and
//! reconstruction (eq. 22) single and batched. The thesis-size figures (2,197 × 410×670)
//! and the goals come from `ignis bench eigen-animate` (or
//! `cargo run --release -p ignis-eigen --example animate_bench`).
//!
//! `cargo bench -p ignis-eigen --bench animate`

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use ignis_eigen::transition::{
    transition, LowPassParams, RecognitionParams, Transition, WeightSpace,
};

fn animate(c: &mut Criterion) {
    let tmp = tempfile::tempdir().expect("temp dir");
    let (db, _) = ignis_eigen::bench::database(true, &tmp.path().join("db")).expect("database");
    let (m, k) = (db.n_frames(), db.n_components());
    let spans = ignis_eigen::animate::clip_spans(&db);
    // Clip 0 (middle) → clip 1 (middle).
    let (c0, c1) = (&spans[0], &spans[1]);
    let t1 = c0.start + c0.len / 2 - 16..c0.start + c0.len / 2;
    let t2 = c1.start + c1.len / 2..c1.start + c1.len / 2 + 16;
    let size = db.train_size();
    let mut g = c.benchmark_group(format!(
        "eigen transition {m}x{}x{}",
        size.width, size.height
    ));
    for e_detect in [db.manifest().e_detect, k] {
        let rec = RecognitionParams {
            e_detect,
            ..Default::default()
        };
        for (name, method) in [
            ("low-pass", Transition::LowPass(LowPassParams::default())),
            (
                "direct-bridging",
                Transition::DirectBridging { steps: None },
            ),
            ("end-growing", Transition::EndGrowing { max_steps: 40 }),
            ("auto", Transition::Auto),
        ] {
            g.bench_function(format!("{name} e_detect={e_detect}"), |b| {
                b.iter_batched(
                    || WeightSpace::from_db(&db).expect("space"),
                    |space| transition(&space, t1.clone(), t2.clone(), &method, &rec),
                    BatchSize::SmallInput,
                )
            });
        }
    }
    g.finish();

    let mut g = c.benchmark_group(format!("eigen reconstruct {}x{}", size.width, size.height));
    g.throughput(Throughput::Elements(size.pixels() as u64));
    let fw = db.frame_weights(m / 3);
    g.bench_function("single e50", |b| {
        b.iter(|| db.reconstruct(&fw, 50).expect("reconstruct"))
    });
    let rows: Vec<Vec<f32>> = (0..16).map(|i| db.frame_weights(i * m / 16)).collect();
    let refs: Vec<&[f32]> = rows.iter().map(|v| v.as_slice()).collect();
    g.throughput(Throughput::Elements((16 * size.pixels()) as u64));
    g.bench_function(format!("batch 16 frames e{k}"), |b| {
        b.iter(|| db.reconstruct_batch(&refs, k).expect("reconstruct"))
    });
    g.finish();
}

criterion_group!(benches, animate);
criterion_main!(benches);
