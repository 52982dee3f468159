//! CPU cost of a seamless loop against the plain render, as `ignis bench classic`'s loop
//! case renders them (320×200, 120 frames drawn through the palette; plain: 60 warm-up
//! frames; looping: settled, re-timed, replayed), in CPU time of every thread, summed over
//! many alternating runs (steadier than the wall clock on a shared machine).
//! `cargo run --release -p ignis-classic --example loop_cost -- [RUNS]`
use ignis_classic::{ClassicFire, ClassicParams};
use ignis_core::{Palette, Size};

fn main() {
    let runs: usize = std::env::args()
        .nth(1)
        .map_or(40, |a| a.parse().expect("runs"));
    let palette = Palette::preset("classic").expect("palette");
    let base = ClassicParams {
        size: Size::new(320, 200).expect("size"),
        seed: 1,
        ..ClassicParams::preset()
    };
    let article = ClassicParams {
        cell: 1,
        puff: 0.0,
        ..base.clone()
    };
    for (name, p) in [("preset", base), ("article", article)] {
        let n = 120;
        let mut cpu = [0u64; 2];
        for i in 0..2 * runs {
            let looping = i % 2 == 1;
            let c = cpu_ns();
            let mut fire = if looping {
                ClassicFire::new_looping(p.clone(), n).expect("fire")
            } else {
                ClassicFire::new(p.clone()).expect("fire")
            };
            fire.settle_loop(60, 4000);
            if looping {
                fire.even_loop_steps(&palette, [0.0; 3]);
            }
            for _ in 0..n {
                fire.step_par();
                std::hint::black_box(fire.rgba(&palette));
            }
            cpu[i % 2] += cpu_ns() - c;
        }
        let ms = |c: u64| c as f64 / runs as f64 / 1e6;
        println!(
            "{name}: plain {:.2} ms CPU, looping {:.2} ms CPU, overhead {:+.1} %",
            ms(cpu[0]),
            ms(cpu[1]),
            (cpu[1] as f64 / cpu[0] as f64 - 1.0) * 100.0
        );
    }
}

/// CPU time of every thread of this process so far, ns (Linux).
fn cpu_ns() -> u64 {
    std::fs::read_dir("/proc/self/task")
        .expect("/proc")
        .map(|t| {
            let s = std::fs::read_to_string(t.expect("task").path().join("schedstat"));
            let s = s.expect("schedstat");
            s.split_whitespace()
                .next()
                .expect("field")
                .parse::<u64>()
                .expect("ns")
        })
        .sum()
}
