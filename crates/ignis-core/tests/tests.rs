//! Integration tests of `ignis-core`.

mod loopq_reference {
    //! The Rust seam and ghost against `../shared/tools/loop_metrics.py` (the reference the
    //! team benchmarks with) on the very same grey frames.

    use std::path::PathBuf;
    use std::process::Command;

    use ignis_core::loopq::{loop_quality, LoopQuality};
    use ignis_core::{GrayFrame, Rng, Size};

    /// The tools folder and a Python interpreter that has numpy (the first `python3` on
    /// PATH may be a version manager's without it; Debian's is `/usr/bin/python3`).
    fn tools() -> Option<(PathBuf, &'static str)> {
        let p = PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../../shared/tools"
        ));
        if !p.join("loop_metrics.py").is_file() {
            println!("skipped: ../shared/tools/loop_metrics.py not present");
            return None;
        }
        let python = ["python3", "/usr/bin/python3"].into_iter().find(|py| {
            Command::new(py)
                .args(["-c", "import numpy"])
                .output()
                .map(|o| o.status.success())
                .unwrap_or(false)
        });
        let Some(python) = python else {
            println!("skipped: no python3 with numpy (Debian: apt-get install python3-numpy)");
            return None;
        };
        Some((p, python))
    }

    /// Soft blobs drifting upward with flicker, a jump back to the start (a cut) and, from
    /// `blend_at`, a crossfade of unrelated frames: every measure has something to find.
    fn frames(n: usize, size: Size, seed: u64) -> Vec<GrayFrame> {
        let mut rng = Rng::new(seed);
        let blobs: Vec<[f32; 4]> = (0..6)
            .map(|_| {
                [
                    rng.f32() * size.width as f32,
                    rng.f32() * size.height as f32,
                    2.0 + 6.0 * rng.f32(),
                    0.5 + rng.f32(),
                ]
            })
            .collect();
        let draw = |t: f32| {
            GrayFrame::from_fn(size, |x, y| {
                let mut v = 0.0;
                for (i, b) in blobs.iter().enumerate() {
                    let cy = (b[1] - t * b[3] * 1.5).rem_euclid(size.height as f32);
                    let cx = b[0] + 3.0 * (t * 0.3 + i as f32).sin();
                    let d2 = (x as f32 - cx).powi(2) + (y as f32 - cy).powi(2);
                    v += (-d2 / (2.0 * b[2] * b[2])).exp()
                        * (1.0 + 0.2 * (t * 0.9 + i as f32).sin());
                }
                (v * 0.6).min(1.0)
            })
        };
        let blend_at = n * 2 / 3;
        (0..n)
            .map(|t| {
                let f = draw(t as f32);
                if (blend_at..blend_at + 4).contains(&t) {
                    let g = draw(t as f32 + 37.0);
                    let d = f
                        .data()
                        .iter()
                        .zip(g.data())
                        .map(|(a, b)| 0.5 * (a + b))
                        .collect();
                    GrayFrame::from_vec(size, d).unwrap()
                } else {
                    f
                }
            })
            .collect()
    }

    fn reference(tools: &std::path::Path, python: &str, frames: &[GrayFrame]) -> serde_json::Value {
        let dir = tempfile::tempdir().unwrap();
        let raw = dir.path().join("frames.f32");
        let bytes: Vec<u8> = frames
            .iter()
            .flat_map(|f| f.data().iter().flat_map(|v| v.to_le_bytes()))
            .collect();
        std::fs::write(&raw, bytes).unwrap();
        let s = frames[0].size();
        let script = format!(
            "import sys, json, numpy as np\nsys.path.insert(0, {tools:?})\nimport loop_metrics as lm\n\
             f = np.fromfile({raw:?}, dtype='<f4').reshape({n}, {h}, {w})\n\
             print(json.dumps(lm.judge('x', f)))",
            tools = tools.display().to_string(),
            raw = raw.display().to_string(),
            n = frames.len(),
            h = s.height,
            w = s.width
        );
        let out = Command::new(python).args(["-c", &script]).output().unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        serde_json::from_slice(&out.stdout).unwrap()
    }

    fn agree(q: &LoopQuality, r: &serde_json::Value) {
        let rel = |a: f64, b: f64| (a - b).abs() / b.abs().max(1e-12);
        let (seam, ghost) = (r["seam"].as_f64().unwrap(), r["ghost"].as_f64().unwrap());
        assert!(
            rel(q.seam, seam) < 0.01,
            "seam {} vs reference {seam}",
            q.seam
        );
        assert!(
            rel(q.ghost, ghost) < 0.01,
            "ghost {} vs reference {ghost}",
            q.ghost
        );
        assert_eq!(q.seam_at as u64, r["seam_at"].as_u64().unwrap());
        assert_eq!(q.ghost_at as u64, r["ghost_at"].as_u64().unwrap());
    }

    #[test]
    fn seam_and_ghost_agree_with_loop_metrics_py() {
        let Some((tools, python)) = tools() else {
            return;
        };
        for (n, w, h, seed) in [(90, 128, 72, 1), (40, 128, 128, 2), (20, 96, 54, 3)] {
            let f = frames(n, Size::new(w, h).unwrap(), seed);
            let q = loop_quality(&f).unwrap();
            let r = reference(&tools, python, &f);
            agree(&q, &r);
            // The case must exercise both measures.
            assert!(q.ghost < 0.95, "{q:?}");
        }
    }
}
