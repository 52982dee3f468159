//! Measures Fuller et al.'s Table 1 grid on this machine and optionally dumps preview
//! images: `cargo run --release -p ignis-volume --example table1 [-- DIR]`
//! (`TABLE1_ONLY=perlin4-35` or `TABLE1_ONLY=perlin4` restricts the grid; `TABLE1_FRAMES=3`
//! times 3 frames instead of 40, e.g. for counting instructions under callgrind).

use ignis_volume::{render, BSpline, FireInstance, FireScene, Lattice, NoiseKind, Preset};
use std::io::Write;
use std::time::Instant;

fn write_ppm(path: &std::path::Path, f: &ignis_core::RgbaFrame) {
    let mut out = format!("P6\n{} {}\n255\n", f.width(), f.height()).into_bytes();
    for p in f.over([0.0; 3]).data() {
        for c in &p[..3] {
            out.push((ignis_core::palette::linear_to_srgb(c.clamp(0.0, 1.0)) * 255.0 + 0.5) as u8);
        }
    }
    std::fs::File::create(path)
        .unwrap()
        .write_all(&out)
        .unwrap();
}

/// User + system CPU seconds of this process (Linux), to report figures independent of
/// other load on a shared machine.
fn cpu_seconds() -> f64 {
    let s = std::fs::read_to_string("/proc/self/stat").unwrap_or_default();
    let rest = s.rsplit_once(')').map(|x| x.1).unwrap_or("");
    let f: Vec<&str> = rest.split_whitespace().collect();
    let tick = |i: usize| f.get(i).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (tick(11) + tick(12)) / 100.0
}

fn main() {
    let dir = std::env::args().nth(1).map(std::path::PathBuf::from);
    for (kind, octaves) in [
        (NoiseKind::Mnoise, 1),
        (NoiseKind::Perlin3, 3),
        (NoiseKind::Perlin4, 3),
    ] {
        for lattice in [35usize, 135] {
            // `TABLE1_ONLY=perlin4-35` (or `perlin4`) runs a subset, e.g. for profiling.
            if let Ok(only) = std::env::var("TABLE1_ONLY") {
                let name = format!("{}-{lattice}", kind.name());
                if !(name == only || kind.name() == only) {
                    continue;
                }
            }
            let scene = FireScene::table1(kind, octaves, lattice);
            let mut anim = scene.animator().unwrap();
            let (pts, _) = anim.step();
            let lat = Lattice::build(&BSpline::new(pts[0].clone(), 3).unwrap(), lattice).unwrap();
            let inst = [FireInstance {
                lattice: &lat,
                profile: &scene.fires[0].profile,
                noise: scene.fires[0].noise,
                offset: scene.offset(0),
                scroll_length: None,
            }];
            let params = scene.render_params();
            // the covered pixels from one frame that counts them (extra work), then the
            // timed frames as a user renders them
            let counting = ignis_volume::RenderParams {
                count_coverage: true,
                ..params
            };
            let (img, stats) = render(&inst, &scene.camera, &counting, 0.0).unwrap();
            // `TABLE1_FRAMES=3` renders fewer frames (e.g. under callgrind)
            let n = std::env::var("TABLE1_FRAMES")
                .ok()
                .and_then(|v| v.parse().ok())
                .unwrap_or(40);
            let (t, c) = (Instant::now(), cpu_seconds());
            for i in 0..n {
                std::hint::black_box(
                    render(&inst, &scene.camera, &params, i as f32 / 30.0).unwrap(),
                );
            }
            let fps = n as f64 / t.elapsed().as_secs_f64();
            let cpu_ms = (cpu_seconds() - c) * 1e3 / n as f64;
            println!(
                "{:8} x{octaves} lattice {lattice:3}: {fps:7.1} fps wall, {cpu_ms:6.1} CPU-ms/frame ({:5.1} fps if all {} threads were free)  covered {} px  samples {} shaded {}",
                kind.name(),
                1e3 * rayon::current_num_threads() as f64 / cpu_ms,
                rayon::current_num_threads(),
                stats.covered_pixels,
                stats.samples,
                stats.shaded
            );
            if let Some(d) = &dir {
                write_ppm(
                    &d.join(format!("table1-{}-{lattice}.ppm", kind.name())),
                    &ignis_volume::finish(&img, &scene.bloom).unwrap(),
                );
            }
        }
    }
    if let Some(d) = &dir {
        for p in Preset::ALL {
            let s = FireScene::preset(p).with_size(ignis_core::Size::new(192, 192).unwrap());
            let mut a = s.animator().unwrap();
            for i in 0..12 {
                let f = a.next_frame().unwrap();
                if i % 6 == 0 {
                    write_ppm(&d.join(format!("{}-{i}.ppm", p.name())), &f.image);
                }
            }
        }
    }
}
