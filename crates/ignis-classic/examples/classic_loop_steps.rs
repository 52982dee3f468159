//! Loop smoothness of the classic fire as `ignis classic --loop` writes it: the largest
//! step and the wrap step of the grey 128-px metric frames (`ignis_core::loopq`) over the
//! median step, with and without even re-timing, and the CPU time the re-timing took.
//! `cargo run --release -p ignis-classic --example classic_loop_steps -- SEED N [CELL PUFF FPS WxH]`
use ignis_classic::{ClassicFire, ClassicParams};
use ignis_core::{loopq, Palette};

fn main() {
    let a: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, d: &str| a.get(i).cloned().unwrap_or_else(|| d.to_string());
    let seed: u64 = arg(0, "1").parse().expect("seed");
    let n: u32 = arg(1, "120").parse().expect("frames");
    let p = ClassicParams {
        size: arg(5, "320x200").parse().expect("size"),
        seed,
        cell: arg(2, "6").parse().expect("cell"),
        puff: arg(3, "0.5").parse().expect("puff"),
        fps: arg(4, "30").parse().expect("fps"),
        ..ClassicParams::preset()
    };
    let palette = Palette::preset("classic").expect("palette");
    let mut fire = ClassicFire::new_looping(p, n).expect("fire");
    let settled = fire.settle_loop(60, 4000);
    let measure = |fire: &mut ClassicFire| {
        let frames: Vec<_> = (0..n)
            .map(|_| {
                fire.step_par();
                loopq::metric_frame_rgba(&fire.rgba(&palette), [0.0; 3])
            })
            .collect();
        let s = loopq::steps(&frames, true).expect("steps");
        let med = loopq::median(&mut s.clone());
        let max = s.iter().copied().fold(0.0, f64::max);
        let ghost = loopq::loop_quality(&frames).expect("quality").ghost;
        (max / med, s[s.len() - 1] / med, ghost)
    };
    let before = measure(&mut fire);
    // the first call also starts rayon's threads: time the second
    fire.even_loop_steps(&palette, [0.0; 3]);
    if let Ok(r) = std::env::var("PROFILE_EVEN") {
        for _ in 0..r.parse::<u32>().expect("repeats") {
            fire.even_loop_steps(&palette, [0.0; 3]);
        }
    }
    let c = cpu_ns();
    let evened = fire.even_loop_steps(&palette, [0.0; 3]);
    let ms = (cpu_ns() - c) as f64 / 1e6;
    let after = measure(&mut fire);
    if std::env::var("FLICKER").is_ok() {
        // the puffing measured on the re-timed loop as `ignis bench realism` measures a
        // render: the upper flame's brightness spectrum over one pass of the loop
        use ignis_core::realism::{display_luma, flicker, reduce};
        let lit: Vec<_> = (0..n)
            .map(|_| {
                fire.step_par();
                reduce(display_luma(&fire.rgba(&palette), [0.0; 3]), 128)
            })
            .collect();
        let f = flicker(&lit, f64::from(fire.params().fps)).expect("flicker");
        println!(
            "re-timed loop flicker {:.2} Hz (peak {:.0})",
            f.hz, f.peak_ratio
        );
    }
    println!(
        "seed {seed} N {n}: settled {settled:?}; steps max/median {:.3} wrap {:.3} ghost {:.3} \
         -> evened {evened} ({ms:.2} ms CPU): {:.3} wrap {:.3} ghost {:.3}",
        before.0, before.1, before.2, after.0, after.1, after.2
    );
}

/// CPU time of every thread of this process so far, ns (Linux).
fn cpu_ns() -> u64 {
    std::fs::read_dir("/proc/self/task")
        .expect("/proc")
        .map(|t| {
            let s = std::fs::read_to_string(t.expect("task").path().join("schedstat"));
            s.expect("schedstat")
                .split_whitespace()
                .next()
                .expect("field")
                .parse::<u64>()
                .expect("ns")
        })
        .sum()
}
