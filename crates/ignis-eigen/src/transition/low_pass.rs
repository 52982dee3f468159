//! Motion transition with a low-pass filter on the weights.
//!
//! Source: eigenfires-thesis.txt §5.1.1 (Figures 34–35): the weight vectors of T1 and T2
//! are put in one sequence, filtered along time with a kernel K (default [1/3, 1/3, 1/3];
//! unbalanced kernels such as [1/5, 1/5, 3/5] are used as given for T1's side and flipped
//! for T2's side), and the outputs around the seam are projected onto the first 50
//! Eigenfires only (low frequencies: smooth deformation instead of layered flames, §4.9).
//! Fine detail may be restored by copying higher-order weights from the target images.
//!
//! How we read the thesis: the filter is an ordinary centred filter along time on T1 ++ T2.
//! Its outputs at the positions whose window straddles the seam (`K.len() - 1` of them:
//! for the 3-tap kernel, the last frame of T1 and the first of T2) are the morphs, and
//! they *replace* those frames — "we have to remove the last frame of T1 and the first
//! frame of T2". Of the "four" outputs the thesis mentions (last two of T1, first two of
//! T2) the other two see only one side, are near-copies of footage frames, and are
//! "ignored". [`Join::trim_t1`] / [`Join::trim_t2`] say how many frames were replaced.
//! A morph that still equals its predecessor (distance < 1e-6) is dropped as a duplicate.
//!
//! Where we depart from the thesis, and why:
//! - *Flip.* Positions in T1 use K, positions in T2 use K reversed; K[m] multiplies the
//!   m-th frame of the window in time order, the window starting `(K.len() - 1) / 2`
//!   frames before the position.
//! - *Normalisation.* K is divided by its sum so the morphs keep the weights' scale (the
//!   thesis's kernels already sum to 1); a kernel summing to 0 is an error.
//! - *Detail injection* is deterministic: weights `inject_from..E` are copied from the
//!   target image of the morph's side (α for T1 positions, β for T2 ones); the thesis
//!   copies "a few" such weights at random. Weights `e_render..inject_from` are 0.
//! - Windows reaching past the start of T1 or the end of T2 repeat the edge frame, and
//!   the number of frames replaced is capped by the length of T1 and T2.

use std::ops::Range;

use super::{bad, join_seam, FrameRef, Join, RecognitionParams, Result, WeightSpace};

/// Settings of the low-pass transition (§5.1.1).
#[derive(Clone, Debug, PartialEq)]
pub struct LowPassParams {
    /// Temporal kernel, at least 2 taps, any sum but 0 (normalised to sum 1).
    /// Default [1/3, 1/3, 1/3]. Its length − 1 is the number of morph frames.
    pub kernel: Vec<f32>,
    /// Number of leading Eigenfires kept in the morphs (weights beyond are zeroed).
    /// Default 50 (thesis); clamped to E. Must be ≥ 1.
    pub e_render: usize,
    /// If `Some(k)`, weights `k..E` of each morph are copied from its target frame (α or β)
    /// to restore detail. Must be ≥ `e_render`. Default `None`.
    pub inject_from: Option<usize>,
}

impl Default for LowPassParams {
    fn default() -> Self {
        LowPassParams {
            kernel: vec![1.0 / 3.0; 3],
            e_render: 50,
            inject_from: None,
        }
    }
}

impl LowPassParams {
    /// Checks the settings: a kernel of at least 2 finite taps not summing to 0,
    /// `e_render` ≥ 1 and `inject_from` ≥ `e_render`.
    pub fn validate(&self) -> Result<()> {
        let l = self.kernel.len();
        if l < 2 {
            return Err(bad(
                "kernel",
                format!("needs at least 2 taps to make a morph, got {l}"),
            ));
        }
        if self.kernel.iter().any(|k| !k.is_finite()) {
            return Err(bad("kernel", "contains NaN or infinity"));
        }
        let sum: f64 = self.kernel.iter().map(|&k| k as f64).sum();
        if sum.abs() < 1e-6 {
            return Err(bad(
                "kernel",
                format!("sums to {sum}; it must not sum to 0 (it is normalised by its sum)"),
            ));
        }
        if self.e_render == 0 {
            return Err(bad("e_render", "must be at least 1"));
        }
        if let Some(k) = self.inject_from {
            if k < self.e_render {
                return Err(bad(
                    "inject_from",
                    format!("must be ≥ e_render = {}, got {k}", self.e_render),
                ));
            }
        }
        Ok(())
    }
}

/// Low-pass transition from T1 to T2: `kernel.len() - 1` synthetic weight vectors.
pub fn low_pass(
    space: &WeightSpace,
    t1: Range<usize>,
    t2: Range<usize>,
    p: &LowPassParams,
    rec: &RecognitionParams,
) -> Result<Join> {
    space.check_range("T1", &t1)?;
    space.check_range("T2", &t2)?;
    p.validate()?;
    let l = p.kernel.len();
    let e = space.e();
    let e_render = p.e_render.min(e);
    let sum: f64 = p.kernel.iter().map(|&k| k as f64).sum();
    let k: Vec<f64> = p.kernel.iter().map(|&x| x as f64 / sum).collect();
    let (alpha, beta) = (t1.end - 1, t2.start);
    let n1 = t1.len() as isize;
    // Frame at position `pos` of the virtual sequence T1 ++ T2 (edges repeated).
    let at = |pos: isize| -> usize {
        if pos < n1 {
            t1.start + pos.max(0) as usize
        } else {
            (t2.start + (pos - n1) as usize).min(t2.end - 1)
        }
    };
    let c = (l as isize - 1) / 2; // window of position p: p - c .. p - c + l
                                  // Straddling positions: p - c ≤ n1 - 1 and p - c + l - 1 ≥ n1.
    let first = (n1 - l as isize + 1 + c).max(0);
    let last = (n1 - 1 + c).min(n1 + t2.len() as isize - 1);
    let trim_t1 = (n1 - first) as usize;
    let trim_t2 = (last - n1 + 1) as usize;
    let mut frames: Vec<FrameRef> = Vec::with_capacity(l - 1);
    let mut prev: Vec<f32> = space.frame(at(first - 1)).to_vec();
    for pos in first..=last {
        let t1_side = pos < n1;
        let mut out = vec![0.0f64; e];
        for m in 0..l {
            let km = if t1_side { k[m] } else { k[l - 1 - m] };
            let f = space.frame(at(pos - c + m as isize));
            for (o, &x) in out[..e_render].iter_mut().zip(f) {
                *o += km * x as f64;
            }
        }
        let mut out: Vec<f32> = out.into_iter().map(|x| x as f32).collect();
        if let Some(from) = p.inject_from {
            let target = space.frame(if t1_side { alpha } else { beta });
            out[from.min(e)..].copy_from_slice(&target[from.min(e)..]);
        }
        if super::dist(&out, &prev, usize::MAX) < 1e-6 {
            continue; // the thesis's duplicate frame
        }
        prev.clone_from(&out);
        frames.push(FrameRef::Weights(out));
    }
    let e_detect = rec.e_detect(space);
    let seam_ratio = join_seam(space, &t1, &t2, &frames, (trim_t1, trim_t2), e_detect);
    Ok(Join {
        why: format!(
            "{} morph frame(s) replacing T1's last {trim_t1} and T2's first {trim_t2} frame(s), from a {l}-tap kernel, rendered with {e_render} of {e} weights{}",
            frames.len(),
            match p.inject_from {
                Some(f) if f < e => format!(", weights {f}..{e} copied from α/β"),
                _ => String::new(),
            }
        ),
        frames,
        trim_t1,
        trim_t2,
        method: "low-pass",
        seam_ratio,
    })
}

#[cfg(test)]
mod tests {
    use super::super::{testdata, transition, Transition, TransitionError};
    use super::*;

    fn weights(f: &FrameRef) -> &[f32] {
        match f {
            FrameRef::Weights(w) => w,
            FrameRef::Db(_) => panic!("low-pass makes synthetic frames"),
        }
    }

    /// Frame i = i² × [1, 10, 100, 1000], i = 0..6.
    fn squares() -> Vec<f32> {
        (0..6)
            .flat_map(|i| [1.0, 10.0, 100.0, 1000.0].map(|s| s * (i * i) as f32))
            .collect()
    }

    #[test]
    fn box_kernel_arithmetic() {
        let w = squares();
        let s = WeightSpace::new(&w, 4, vec![]).unwrap();
        let p = LowPassParams {
            kernel: vec![1.0, 1.0, 1.0], // normalised to 1/3 each
            e_render: 4,
            inject_from: None,
        };
        let j = low_pass(&s, 0..3, 3..6, &p, &RecognitionParams::default()).unwrap();
        // The morphs replace α (frame 2) and β (frame 3): windows (1,2,3) and (2,3,4)
        // of the values 1, 4, 9, 16 give 14/3 and 29/3.
        assert_eq!((j.trim_t1, j.trim_t2), (1, 1));
        assert_eq!(j.frames.len(), 2);
        for (f, want) in j.frames.iter().zip([14.0f32 / 3.0, 29.0 / 3.0]) {
            let got = weights(f);
            for (g, sc) in got.iter().zip([1.0, 10.0, 100.0, 1000.0]) {
                assert!(
                    (g - want * sc).abs() < 1e-6 * sc * 10.0,
                    "{got:?} vs {want}"
                );
            }
        }
    }

    #[test]
    fn asymmetric_kernel_is_flipped_and_detail_injected() {
        let w = squares();
        let s = WeightSpace::new(&w, 4, vec![]).unwrap();
        let p = LowPassParams {
            kernel: vec![1.0, 2.0, 3.0], // → [1/6, 2/6, 3/6]
            e_render: 2,
            inject_from: Some(3),
        };
        let j = low_pass(&s, 0..3, 3..6, &p, &RecognitionParams::default()).unwrap();
        assert_eq!(j.frames.len(), 2);
        // α's window (1, 4, 9) with K: (1 + 8 + 27)/6 = 6; β's window (4, 9, 16) with K
        // flipped [3, 2, 1]/6: (12 + 18 + 16)/6 = 46/6. Weight 2 is zeroed (e_render = 2);
        // weight 3 is copied from α = frame 2 (4 × 1000) and β = frame 3 (9 × 1000).
        let want = [
            [6.0, 60.0, 0.0, 4000.0],
            [46.0 / 6.0, 460.0 / 6.0, 0.0, 9000.0],
        ];
        for (f, want) in j.frames.iter().zip(want) {
            let got = weights(f);
            for (g, w) in got.iter().zip(want) {
                assert!((g - w).abs() < 1e-4, "{got:?} vs {want:?}");
            }
        }
    }

    #[test]
    fn five_tap_kernel_replaces_two_frames_per_side() {
        let w = squares();
        let s = WeightSpace::new(&w, 4, vec![]).unwrap();
        let p = LowPassParams {
            kernel: vec![1.0; 5],
            e_render: 4,
            inject_from: None,
        };
        let j = low_pass(&s, 0..3, 3..6, &p, &RecognitionParams::default()).unwrap();
        assert_eq!((j.trim_t1, j.trim_t2, j.frames.len()), (2, 2, 4));
        // Position 1: window (0, 0, 1, 4, 9) — the edge frame repeated — mean 14/5.
        assert!((weights(&j.frames[0])[0] - 14.0 / 5.0).abs() < 1e-5);
        // Position 4: window (4, 9, 16, 25, 25), mean 79/5.
        assert!((weights(&j.frames[3])[0] - 79.0 / 5.0).abs() < 1e-5);
    }

    #[test]
    fn duplicate_morphs_are_dropped() {
        // T1 and T2 all the same frame: every morph equals α and is dropped.
        let w = vec![1.0f32; 12];
        let s = WeightSpace::new(&w, 2, vec![]).unwrap();
        let j = low_pass(
            &s,
            0..3,
            3..6,
            &LowPassParams::default(),
            &Default::default(),
        )
        .unwrap();
        assert!(j.frames.is_empty());
    }

    #[test]
    fn bad_kernels() {
        let w = squares();
        let s = WeightSpace::new(&w, 4, vec![]).unwrap();
        let rec = RecognitionParams::default();
        for kernel in [vec![1.0, -1.0], vec![0.5], vec![], vec![f32::NAN, 1.0]] {
            let p = LowPassParams {
                kernel: kernel.clone(),
                ..Default::default()
            };
            let e = low_pass(&s, 0..3, 3..6, &p, &rec).unwrap_err();
            assert!(
                matches!(&e, TransitionError::BadParameter { name, .. } if name == "kernel"),
                "{kernel:?}: {e}"
            );
        }
        let p = LowPassParams {
            e_render: 10,
            inject_from: Some(5),
            ..Default::default()
        };
        assert!(low_pass(&s, 0..3, 3..6, &p, &rec).is_err());
    }

    #[test]
    fn smooths_a_cut_on_the_parametric_flame() {
        let (w, clips) = testdata::flame(2, 40, 0.05, 0.9, 0.003, 11);
        let s = WeightSpace::new(&w, testdata::E, clips).unwrap();
        let rec = RecognitionParams::default();
        let med = s.source_median(testdata::E);
        let t1 = 0..20;
        // The T2 start in clip 1 whose plain cut is closest to 3.5 × the median step.
        let beta = (40..60)
            .filter(|&b| s.distance(19, b, testdata::E) / med >= 3.0)
            .min_by(|&a, &b| {
                let r = |x| (s.distance(19, x, testdata::E) / med - 3.5).abs();
                r(a).total_cmp(&r(b))
            })
            .unwrap();
        let t2 = beta..beta + 15;
        let cut = super::super::join_seam(&s, &t1, &t2, &[], (0, 0), testdata::E);
        assert!(cut >= 3.0, "plain cut {cut}");
        let p = LowPassParams {
            kernel: vec![1.0; 7],
            ..Default::default()
        };
        let j = transition(&s, t1, t2, &Transition::LowPass(p), &rec).unwrap();
        assert_eq!(j.frames.len(), 6);
        assert!(
            j.seam_ratio <= 1.5,
            "low-pass seam {} (cut {cut})",
            j.seam_ratio
        );
    }
}
