//! CPU cost of a seamless loop against the plain render, as `ignis bench classic`'s loop
//! case renders them (320×200, 120 frames drawn through the palette; plain: 60 warm-up
//! frames; looping: settled, re-timed, replayed), in CPU time of every thread, summed over
//! many alternating runs: the least and the median run of each (steadier than the wall
//! clock on a shared machine).
//! `cargo run --release -p ignis-classic --example classic_loop_cost -- [RUNS]`
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
    let case = std::env::var("CASE").ok();
    for (name, p) in [("preset", base), ("article", article)] {
        if case.as_deref().is_some_and(|c| c != name) {
            continue;
        }
        let n = 120;
        let mut cpu: [Vec<u64>; 2] = [Vec::new(), Vec::new()];
        // ONLY=plain or ONLY=loop runs just that case, CASE=preset or CASE=article just
        // that fire (for instruction counts under valgrind, which other processes do not
        // disturb)
        let only = std::env::var("ONLY").ok();
        for i in 0..2 * runs {
            let looping = i % 2 == 1;
            if only.as_deref().is_some_and(|o| (o == "loop") != looping) {
                continue;
            }
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
            cpu[i % 2].push(cpu_ns() - c);
        }
        // other processes only ever add time: the least and the median of the runs
        for c in cpu.iter_mut() {
            c.sort_unstable();
        }
        if only.is_some() {
            continue;
        }
        let (min, med) = (
            |k: usize| cpu[k][0] as f64,
            |k: usize| cpu[k][runs / 2] as f64,
        );
        println!(
            "{name}: plain {:.2} / {:.2} ms CPU (least / median), looping {:.2} / {:.2}, \
             overhead {:+.1} % / {:+.1} %",
            min(0) / 1e6,
            med(0) / 1e6,
            min(1) / 1e6,
            med(1) / 1e6,
            (min(1) / min(0) - 1.0) * 100.0,
            (med(1) / med(0) - 1.0) * 100.0
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
