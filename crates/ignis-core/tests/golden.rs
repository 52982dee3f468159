//! Golden images of the bloom ([`ignis_core::post::bloom_rgba`]): a tiny synthetic HDR
//! frame bloomed with passes on both the exact blur (σ < 6 px) and the reduced-resolution
//! one (σ ≥ 6 px), compared with `tests/golden/*.f32` (format in [`ignis_core::golden`]).
//!
//! Tolerance: a max abs error of [`TOLERANCE`] per channel (input peaks of 4). The bloom is
//! deterministic whatever the thread count, so on one platform the difference is exactly
//! 0; the margin only absorbs another platform's `exp` rounding in the Gaussian kernel.
//! A change to the blur, the pyramid or the pass weights moves values by far more.
//! `UPDATE_GOLDEN=1` rewrites the goldens.

use ignis_core::golden::check_rgba;
use ignis_core::post::{bloom_rgba, BloomParams};
use ignis_core::{RgbaFrame, Size};
use std::path::PathBuf;

/// Max abs error per channel (see the module docs).
const TOLERANCE: f32 = 1e-5;

/// A 48×40 HDR frame: three coloured blobs of peak 4, a one-pixel spark and a faint
/// gradient, alpha from the luminance.
fn source() -> RgbaFrame {
    let size = Size::new(48, 40).unwrap();
    let blobs = [
        (12.0f32, 10.0f32, 2.5f32, [4.0f32, 1.5, 0.3]),
        (30.0, 24.0, 4.0, [1.0, 2.0, 4.0]),
        (44.0, 36.0, 1.5, [3.0, 3.0, 3.0]),
    ];
    let mut data = Vec::with_capacity(size.pixels());
    for y in 0..40 {
        for x in 0..48 {
            let mut c = [0.02 * x as f32 / 48.0, 0.01 * y as f32 / 40.0, 0.0];
            for (bx, by, r, col) in blobs {
                let d2 = (x as f32 - bx).powi(2) + (y as f32 - by).powi(2);
                let w = (-d2 / (2.0 * r * r)).exp();
                for k in 0..3 {
                    c[k] += col[k] * w;
                }
            }
            if (x, y) == (5, 33) {
                c = [4.0, 4.0, 2.0];
            }
            let a = (0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]).min(1.0);
            data.push([c[0], c[1], c[2], a]);
        }
    }
    RgbaFrame::from_vec(size, data).unwrap()
}

fn check(name: &str, frame: &RgbaFrame) {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("tests/golden")
        .join(name);
    match check_rgba(&path, frame, TOLERANCE) {
        Ok(worst) => println!("{name}: max abs difference {worst:e}"),
        Err(e) => panic!("{e}"),
    }
}

/// Three passes, σ = 12, 6, 3 px: the first two on reduced levels, the last exact.
#[test]
fn bloom_three_passes() {
    let p = BloomParams {
        passes: 3,
        radius: 12.0,
        radius_falloff: 0.5,
        strength: 0.4,
    };
    let out = bloom_rgba(&source(), &p).unwrap();
    check("bloom-48x40-p3-r12.f32", &out);
}

/// One exact pass (σ = 2 px) at full strength.
#[test]
fn bloom_one_exact_pass() {
    let p = BloomParams {
        passes: 1,
        radius: 2.0,
        radius_falloff: 0.5,
        strength: 1.0,
    };
    let out = bloom_rgba(&source(), &p).unwrap();
    check("bloom-48x40-p1-r2.f32", &out);
}
