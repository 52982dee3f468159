//! Decodes a file end to end and prints frames per second (wall clock).
//! Example: `cargo run --release -p ignis-media --example decode_speed -- ../shared/data/candle.mp4 [raw]`
//! With `raw`, stops at 8-bit RGBA (Baseline MP4 only), skipping the linear-light conversion.
fn main() {
    let mut args = std::env::args().skip(1);
    let path = std::path::PathBuf::from(args.next().expect("usage: decode_speed FILE [raw]"));
    let raw = args.next().as_deref() == Some("raw");
    let t = std::time::Instant::now();
    let n = if raw {
        ignis_media::bench_support::decode_rgba8_count(&path).unwrap()
    } else {
        let mut n = 0u64;
        for f in ignis_media::open(&path, &ignis_media::ReadOptions::default()).unwrap() {
            std::hint::black_box(f.unwrap());
            n += 1;
        }
        n
    };
    let s = t.elapsed().as_secs_f64();
    println!(
        "{n} frames in {s:.3} s = {:.0} frames/s ({})",
        n as f64 / s,
        if raw { "rgba8" } else { "linear RgbaFrame" }
    );
    // CPU seconds of the whole process and of this (the caller's) thread; the rest is the
    // decode worker. On an otherwise idle machine the two overlap, so the rate is bounded
    // by the busier thread.
    if let (Some(all), Some(main)) = (
        cpu_seconds("/proc/self/stat"),
        cpu_seconds("/proc/thread-self/stat"),
    ) {
        let worker = all - main;
        println!(
            "cpu: {all:.2} s total, caller thread {main:.2} s, worker {worker:.2} s -> ~{:.0} frames/s when both have a core",
            n as f64 / main.max(worker)
        );
    }
}

/// utime + stime of a /proc stat file, in seconds (Linux only; 100 ticks per second).
fn cpu_seconds(path: &str) -> Option<f64> {
    let text = std::fs::read_to_string(path).ok()?;
    let after = &text[text.rfind(')')? + 2..];
    let f: Vec<&str> = after.split_whitespace().collect();
    let ticks: f64 = f.get(11)?.parse::<f64>().ok()? + f.get(12)?.parse::<f64>().ok()?;
    Some(ticks / 100.0)
}
