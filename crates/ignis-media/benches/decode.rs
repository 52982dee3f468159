//! Decode throughput of the pure-cargo MP4/H.264 path on the shared candle clip.
//!
//! Run: `cargo bench -p ignis-media --bench decode`. Criterion's "thrpt" line is in
//! frames per second (one element = one 480x480 frame).

use std::path::PathBuf;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use ignis_media::{open, ReadOptions};

const FRAMES: u64 = 796;

fn candle() -> Option<PathBuf> {
    let p = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../../shared/data/candle.mp4"
    ));
    p.exists().then_some(p)
}

fn decode(c: &mut Criterion) {
    let Some(path) = candle() else {
        eprintln!("skipped: ../shared/data not present");
        return;
    };
    let mut g = c.benchmark_group("decode");
    g.sample_size(10);
    g.measurement_time(std::time::Duration::from_secs(12));
    g.throughput(Throughput::Elements(FRAMES));
    g.bench_function("openh264 candle 480x480x796 to linear RgbaFrame", |b| {
        b.iter(|| {
            let mut n = 0u64;
            for f in open(&path, &ReadOptions::default()).unwrap() {
                std::hint::black_box(f.unwrap());
                n += 1;
            }
            assert_eq!(n, FRAMES);
        })
    });
    g.bench_function(
        "openh264 candle 480x480x796 to rgba8 (no linear conversion)",
        |b| {
            b.iter(|| {
                assert_eq!(
                    ignis_media::bench_support::decode_rgba8_count(&path).unwrap(),
                    FRAMES
                )
            })
        },
    );
    g.finish();

    let mut g = c.benchmark_group("convert");
    let size = ignis_media::Size::new(480, 480).unwrap();
    let bytes: Vec<u8> = (0..size.pixels() * 4)
        .map(|i| (i * 31 % 256) as u8)
        .collect();
    g.throughput(Throughput::Elements(1));
    g.bench_function("srgba8 to linear RgbaFrame 480x480", |b| {
        b.iter(|| ignis_media::bench_support::srgba8_to_linear(size, std::hint::black_box(&bytes)))
    });
    g.finish();
}

criterion_group!(benches, decode);
criterion_main!(benches);
