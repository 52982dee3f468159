//! Per-stage CPU profile of the 1080p morph (luma, both flows, the morph) and of the
//! 1080p flow: `cargo run --release -p ignis-flow --example stages [reps]`. Stages are
//! timed single-threaded (a one-thread pool), so the figures are CPU time whatever the load.
use ignis_core::Size;
use ignis_flow::*;
use std::time::Instant;

fn main() {
    let reps: usize = std::env::args()
        .nth(1)
        .and_then(|v| v.parse().ok())
        .unwrap_or(5);
    let hd = Size::new(1920, 1080).unwrap();
    let d = [7.5, -4.0];
    let (a, b) = (
        bench::texture(hd, 2, [0.0; 2], 4.0),
        bench::texture(hd, 2, d, 4.0),
    );
    let (ca, cb) = (a.to_rgba(), b.to_rgba());
    let p = FlowParams::default();
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let only = std::env::args().nth(2);
    let t = |name: &str, f: &mut dyn FnMut()| {
        if only.as_deref().is_some_and(|o| !name.starts_with(o)) {
            return;
        }
        f();
        let (t0, c0) = (Instant::now(), thread_cpu_ms());
        for _ in 0..reps {
            f();
        }
        let n = reps as f64;
        println!(
            "{name:<28} {:8.2} ms wall {:8.2} ms CPU (1 thread)",
            t0.elapsed().as_secs_f64() * 1e3 / n,
            (thread_cpu_ms() - c0) / n
        );
    };
    pool.install(|| {
        let (la, lb) = (luma(&ca), luma(&cb));
        let (f, g) = flow_pair_reduced(&la, &lb, &p).unwrap();
        t("luma x2", &mut || {
            std::hint::black_box((luma(&ca), luma(&cb)));
        });
        t("flow_reduced x1", &mut || {
            std::hint::black_box(flow_reduced(&la, &lb, &p).unwrap());
        });
        t("flow_pair_reduced", &mut || {
            std::hint::black_box(flow_pair_reduced(&la, &lb, &p).unwrap());
        });
        t("flow (1080p, upsampled)", &mut || {
            std::hint::black_box(flow(&a, &b, &p).unwrap());
        });
        t("morph_rgba", &mut || {
            std::hint::black_box(morph_rgba(&ca, &cb, &f, &g, 0.5).unwrap());
        });
        t("clone of one RGBA frame", &mut || {
            std::hint::black_box(ca.clone());
        });
        t("warp_rgba", &mut || {
            std::hint::black_box(warp_rgba(&ca, &f, 0.5));
        });
        t("morph_gray", &mut || {
            std::hint::black_box(morph_gray(&la, &lb, &f, &g, 0.5).unwrap());
        });
        let s256 = Size::new(256, 256).unwrap();
        let (sa, sb) = (
            bench::texture(s256, 3, [0.0; 2], 1.5).to_rgba(),
            bench::texture(s256, 3, [1.5, -1.0], 1.5).to_rgba(),
        );
        let vp = VectorParams::default();
        t("motion_vector_pair 256", &mut || {
            std::hint::black_box(motion_vector_pair(&sa, &sb, &vp).unwrap());
        });
        let (ga, gb) = (luma(&sa), luma(&sb));
        t("flow_pair 256", &mut || {
            std::hint::black_box(flow_pair(&ga, &gb, &p).unwrap());
        });
        let s720 = Size::new(1280, 720).unwrap();
        let (ha, hb) = (
            bench::texture(s720, 3, [0.0; 2], 3.0).to_rgba(),
            bench::texture(s720, 3, [3.0, -2.0], 3.0).to_rgba(),
        );
        t("motion_vector_pair 720p", &mut || {
            std::hint::black_box(motion_vector_pair(&ha, &hb, &vp).unwrap());
        });
        let (h1, h2) = (luma(&ha), luma(&hb));
        t("flow_pair 720p", &mut || {
            std::hint::black_box(flow_pair(&h1, &h2, &p).unwrap());
        });
        t("whole morph_1080p case", &mut || {
            let (la, lb) = (luma(&ca), luma(&cb));
            let (f, g) = flow_pair_reduced(&la, &lb, &p).unwrap();
            std::hint::black_box(morph_rgba(&ca, &cb, &f, &g, 0.5).unwrap());
        });
    });
}

/// CPU time of the calling thread in ms (Linux `/proc/thread-self/schedstat`; 0 elsewhere).
fn thread_cpu_ms() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .map_or(0.0, |ns| ns / 1e6)
}
