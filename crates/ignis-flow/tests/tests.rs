//! Integration tests of `ignis-flow`: known translations, the morph, reduced-size flow of
//! full-HD frames, real footage and determinism.
//!
//! Tests needing `../shared/data` or `ffmpeg` print why they skipped and return.

use std::path::PathBuf;

use ignis_core::{GrayFrame, RgbaFrame, Size};
use ignis_flow::*;

/// A smooth random texture: a seeded sum of sinusoids (wavelengths 6–40 px) evaluated at
/// `(x − dx, y − dy)`, so shifting by a sub-pixel amount is exact. Values in about 0.1..1.
fn texture(size: Size, seed: u64, d: [f32; 2]) -> GrayFrame {
    ignis_flow::bench::texture(size, seed, d, 1.0)
}

/// Per-pixel errors of `f` against the constant truth `d` on the interior (a `margin` px
/// border excluded): (mean vector error length, 95th percentile of per-pixel error).
fn errors(f: &FlowField, d: [f32; 2], margin: u32) -> ([f64; 2], f64) {
    let s = f.size();
    let mut sum = [0.0f64; 2];
    let mut per = Vec::new();
    for y in margin..s.height - margin {
        for x in margin..s.width - margin {
            let v = f.data()[(y * s.width + x) as usize];
            let (ex, ey) = ((v[0] - d[0]) as f64, (v[1] - d[1]) as f64);
            sum[0] += v[0] as f64;
            sum[1] += v[1] as f64;
            per.push((ex * ex + ey * ey).sqrt());
        }
    }
    let n = per.len() as f64;
    per.sort_by(|a, b| a.total_cmp(b));
    let p95 = per[((per.len() as f64 * 0.95) as usize).min(per.len() - 1)];
    ([sum[0] / n - d[0] as f64, sum[1] / n - d[1] as f64], p95)
}

fn mae_interior(a: &GrayFrame, b: &GrayFrame, margin: u32) -> f64 {
    let (w, h) = (a.width(), a.height());
    let mut s = 0.0f64;
    let mut n = 0usize;
    for y in margin..h - margin {
        for x in margin..w - margin {
            s += (a.get(x, y) - b.get(x, y)).abs() as f64;
            n += 1;
        }
    }
    s / n as f64
}

/// Bound on the per-pixel 95th-percentile error of a recovered translation, in pixels
/// (measured: 0.02–0.13 with the default parameters).
const P95_BOUND: f64 = 0.25;

mod translation {
    use super::*;

    fn check(d: [f32; 2], seed: u64) {
        check_with(d, seed, &FlowParams::default());
    }

    fn check_with(d: [f32; 2], seed: u64, p: &FlowParams) {
        let s = Size::new(256, 192).unwrap();
        let a = texture(s, seed, [0.0, 0.0]);
        let b = texture(s, seed, d);
        let f = flow(&a, &b, p).unwrap();
        assert_eq!(f.size(), s);
        let (mean, p95) = errors(&f, d, 16);
        println!("shift {d:?}: mean error {mean:?}, p95 {p95:.3}");
        assert!(
            mean[0].abs() < 0.5 && mean[1].abs() < 0.5,
            "{d:?}: mean error {mean:?}"
        );
        assert!(p95 < P95_BOUND, "{d:?}: p95 {p95}");
    }

    #[test]
    fn integer_shift_is_recovered() {
        check([3.0, -2.0], 11);
    }

    #[test]
    fn subpixel_shift_is_recovered() {
        check([1.5, 0.75], 12);
    }

    #[test]
    fn larger_shift_is_recovered_through_the_pyramid() {
        check([-9.0, 6.5], 13);
    }

    /// The optional variational refinement keeps a known shift (finest scale 0, where it
    /// refines at the working size).
    #[test]
    fn refinement_keeps_a_known_shift() {
        let p = FlowParams {
            refine_iterations: 5,
            finest_scale: 0,
            ..Default::default()
        };
        check_with([1.5, 0.75], 12, &p);
    }

    #[test]
    fn identical_frames_give_near_zero_flow() {
        let a = texture(Size::new(160, 120).unwrap(), 5, [0.0, 0.0]);
        let f = flow(&a, &a, &FlowParams::default()).unwrap();
        let worst = f
            .data()
            .iter()
            .map(|v| v[0].abs().max(v[1].abs()))
            .fold(0.0f32, f32::max);
        assert!(worst < 0.05, "largest vector {worst}");
    }

    #[test]
    fn both_directions_are_opposite() {
        let s = Size::new(128, 128).unwrap();
        let d = [2.25, -1.5];
        let (a, b) = (texture(s, 7, [0.0, 0.0]), texture(s, 7, d));
        let (f, g) = flow_pair(&a, &b, &FlowParams::default()).unwrap();
        let (mf, _) = errors(&f, d, 16);
        let (mg, _) = errors(&g, [-d[0], -d[1]], 16);
        assert!(mf.iter().chain(&mg).all(|e| e.abs() < 0.5), "{mf:?} {mg:?}");
    }

    /// A known shift of a 1920×1080 pair computed at the 512-px working size and
    /// upsampled: still within 0.5 px in full-resolution pixels.
    #[test]
    fn full_hd_shift_via_reduced_size() {
        let s = Size::new(1920, 1080).unwrap();
        let d = [7.5, -4.0];
        // A coarser texture so it survives the 3.75× reduction (wavelengths × 4).
        let big = |d: [f32; 2]| ignis_flow::bench::texture(s, 21, d, 4.0);
        let (a, b) = (big([0.0, 0.0]), big(d));
        let p = FlowParams::default();
        let f = flow(&a, &b, &p).unwrap();
        assert_eq!(f.size(), s);
        let (mean, p95) = errors(&f, d, 64);
        println!("1080p shift {d:?}: mean error {mean:?}, p95 {p95:.3}");
        assert!(
            mean[0].abs() < 0.5 && mean[1].abs() < 0.5,
            "mean error {mean:?}"
        );
        // Full-resolution pixels: the working-size bound scaled by about 2.
        assert!(p95 < 2.0 * P95_BOUND, "p95 {p95}");
    }
}

mod morph {
    use super::*;

    /// Mean absolute error of the mid frame on the interior, in intensity units of a
    /// texture spanning about 0.1..1 (measured: 0.0017; the 50/50 blend: 0.018).
    const MID_MAE_BOUND: f64 = 0.005;

    #[test]
    fn mid_frame_is_the_half_shifted_frame() {
        let s = Size::new(192, 160).unwrap();
        let d = [3.0, -2.0];
        let a = texture(s, 31, [0.0, 0.0]);
        let b = texture(s, 31, d);
        let truth = texture(s, 31, [d[0] / 2.0, d[1] / 2.0]);
        let (f, g) = flow_pair(&a, &b, &FlowParams::default()).unwrap();
        let mid = morph_gray(&a, &b, &f, &g, 0.5).unwrap();
        let blend = GrayFrame::from_vec(
            s,
            a.data()
                .iter()
                .zip(b.data())
                .map(|(x, y)| 0.5 * (x + y))
                .collect(),
        )
        .unwrap();
        let e_morph = mae_interior(&mid, &truth, 16);
        let e_blend = mae_interior(&blend, &truth, 16);
        println!("mid-frame MAE: morph {e_morph:.5}, 50/50 blend {e_blend:.5}");
        assert!(e_morph < MID_MAE_BOUND, "morph MAE {e_morph}");
        assert!(
            e_morph < 0.25 * e_blend,
            "morph {e_morph} vs blend {e_blend}"
        );
    }

    #[test]
    fn rgba_morph_matches_gray_morph_on_grey_opaque_frames() {
        let s = Size::new(96, 64).unwrap();
        let a = texture(s, 41, [0.0, 0.0]);
        let b = texture(s, 41, [1.5, 1.0]);
        let (f, g) = flow_pair(&a, &b, &FlowParams::default()).unwrap();
        let mg = morph_gray(&a, &b, &f, &g, 0.3).unwrap();
        let mc = morph_rgba(&a.to_rgba(), &b.to_rgba(), &f, &g, 0.3).unwrap();
        for (p, q) in mc.data().iter().zip(mg.data()) {
            assert!((p[0] - q).abs() < 1e-5 && (p[3] - 1.0).abs() < 1e-6);
        }
        // Reduced fields give the same kind of result as full-size ones.
        let (fr, gr) = (
            f.resized(Size::new(48, 32).unwrap()),
            g.resized(Size::new(48, 32).unwrap()),
        );
        let m2 = morph_gray(&a, &b, &fr, &gr, 0.3).unwrap();
        assert!(mae_interior(&m2, &mg, 8) < 0.01);
    }

    #[test]
    fn luma_is_alpha_weighted() {
        let s = Size::new(2, 1).unwrap();
        let f = RgbaFrame::from_vec(s, vec![[1.0, 1.0, 1.0, 0.5], [1.0, 0.0, 0.0, 1.0]]).unwrap();
        let l = luma(&f);
        assert!((l.get(0, 0) - 0.5).abs() < 1e-6);
        assert!((l.get(1, 0) - 0.2126).abs() < 1e-6);
    }
}

mod footage {
    use super::*;

    fn data(name: &str) -> Option<PathBuf> {
        let p =
            PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data")).join(name);
        if p.exists() {
            Some(p)
        } else {
            println!("skipped: ../shared/data not present");
            None
        }
    }

    /// Warping frame t+1 back along the flow brings it closer to frame t than no warp.
    #[test]
    fn candle_warp_reduces_the_error() {
        let Some(path) = data("candle.mp4") else {
            return;
        };
        let opts = ignis_media::ReadOptions {
            range: Some(ignis_media::FrameRange::frames(100, Some(102))),
            ..Default::default()
        };
        let frames: Vec<RgbaFrame> = match ignis_media::open(&path, &opts) {
            Ok(r) => r.collect::<Result<_, _>>().expect("decode candle.mp4"),
            Err(e) => {
                println!("skipped: cannot open candle.mp4 ({e})");
                return;
            }
        };
        assert_eq!(frames.len(), 2);
        let (a, b) = (luma(&frames[0]), luma(&frames[1]));
        let f = flow(&a, &b, &FlowParams::default()).unwrap();
        let back = warp_gray(&b, &f, 1.0);
        let e_warp = mae_interior(&back, &a, 8);
        let e_none = mae_interior(&b, &a, 8);
        println!("candle frames 100→101: MAE no warp {e_none:.5}, warped {e_warp:.5}");
        assert!(e_warp < 0.8 * e_none, "warped {e_warp} vs none {e_none}");
    }
}

mod determinism {
    use super::*;

    #[test]
    fn same_bytes_with_one_and_two_threads() {
        let s = Size::new(120, 90).unwrap();
        let a = texture(s, 51, [0.0, 0.0]);
        let b = texture(s, 51, [2.3, -1.1]);
        let p = FlowParams {
            refine_iterations: 3,
            ..Default::default()
        };
        let occ = MorphParams {
            occlusion_px: Some(1.0),
        };
        let run = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let (f, g) = flow_pair(&a, &b, &p).unwrap();
                let m = morph_rgba_with(&a.to_rgba(), &b.to_rgba(), &f, &g, 0.5, &occ).unwrap();
                (f, g, m)
            })
        };
        let (one, two) = (run(1), run(2));
        assert_eq!(one.0, two.0);
        assert_eq!(one.1, two.1);
        assert_eq!(one.2, two.2);
    }
}
