//! ns per pixel per frame of the classic fire at 1920×1080.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use ignis_classic::{ClassicFire, ClassicParams, Kernel};
use ignis_core::Size;

fn bench(c: &mut Criterion) {
    let size = Size::new(1920, 1080).unwrap();
    let mut g = c.benchmark_group("classic 1920x1080");
    g.throughput(Throughput::Elements(size.pixels() as u64));
    for kernel in [Kernel::Article, Kernel::Buffered] {
        let mut fire = ClassicFire::new(ClassicParams {
            size,
            fade: 1,
            kernel,
            seed: 1,
            ..Default::default()
        })
        .unwrap();
        for _ in 0..100 {
            fire.step();
        }
        let name = format!("{kernel:?}").to_lowercase();
        g.bench_function(format!("{name} 1 thread"), |b| b.iter(|| fire.step()));
        g.bench_function(format!("{name} rayon"), |b| b.iter(|| fire.step_par()));
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
