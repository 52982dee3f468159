//! Golden test of Eigenfire reconstruction (eq. 22), imageproc `truth/` style: a tiny
//! database is trained from a synthetic clip (deterministic: fixed seed and sizes), a
//! frame is reconstructed with 6 Eigenfires and compared with the stored result
//! `tests/golden/reconstruct_e6.npy` (a 20×32 f32 array, readable with numpy).
//!
//! Tolerance: 1e-4 absolute per pixel (grey values lie in [0, 1]). Reconstruction does not
//! depend on the sign of an Eigenfire or on the thread count; the tolerance covers float
//! summation differences between CPUs, while a change of the pre-processing, the PCA or
//! eq. 22 moves pixels by far more.
//!
//! `UPDATE_GOLDEN=1 cargo test --release -p ignis-eigen --test golden` rewrites the file
//! (then look at it, and say why in the commit).

use ignis_core::Size;
use ignis_eigen::train::{synthetic_clips, train, NoProgress, TrainParams};
use ignis_eigen::{EigenfireDb, PreprocessParams};
use ignis_pca::npy;
use std::path::Path;

const TOLERANCE: f32 = 1e-4;

#[test]
fn reconstruction_matches_golden() {
    let dir = tempfile::tempdir().unwrap();
    let clips = synthetic_clips(Size::new(40, 64).unwrap(), 16, 11);
    let mut pre =
        PreprocessParams::with_sizes(Size::new(40, 64).unwrap(), Some(Size::new(20, 32).unwrap()));
    pre.pose_samples = 4;
    let out = dir.path().join("fire.db");
    let tp = TrainParams {
        pack_size: 4,
        ..Default::default()
    };
    train(&clips[..1], &pre, &tp, &out, &mut NoProgress).unwrap();
    let db = EigenfireDb::open(&out).unwrap();
    let row = db.frame_index("candle", 5).unwrap();
    let got = db.reconstruct(&db.frame_weights(row), 6).unwrap();
    let (w, h) = (got.width() as usize, got.height() as usize);
    let golden = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/golden/reconstruct_e6.npy");
    if std::env::var_os("UPDATE_GOLDEN").is_some() {
        std::fs::create_dir_all(golden.parent().unwrap()).unwrap();
        npy::write_f32(&golden, got.data(), &[h, w], false).unwrap();
        println!("rewrote {}", golden.display());
        return;
    }
    let (want, header) = npy::read_f32(&golden)
        .unwrap_or_else(|e| panic!("{e}; run with UPDATE_GOLDEN=1 to create the golden file"));
    assert_eq!(header.shape, vec![h, w], "golden shape");
    let worst = got
        .data()
        .iter()
        .zip(&want)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0f32, f32::max);
    assert!(
        worst <= TOLERANCE,
        "reconstruction differs from {} by up to {worst} (tolerance {TOLERANCE}); \
         if the change is intended, rerun with UPDATE_GOLDEN=1",
        golden.display()
    );
    // The golden frame is a flame, not a blank: reconstruction did something.
    let mean: f32 = want.iter().sum::<f32>() / want.len() as f32;
    let max = want.iter().cloned().fold(0.0f32, f32::max);
    assert!(
        max > 0.3 && mean < max / 2.0,
        "golden frame: max {max}, mean {mean}"
    );
}
