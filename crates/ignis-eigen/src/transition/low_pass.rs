//! Motion transition with a low-pass filter on the weights.
//!
//! Source: eigenfires-thesis.txt §5.1.1 (Figures 34–35): the weight vectors of T1 and T2
//! are put in one sequence, filtered along time with a kernel K (default [1/3, 1/3, 1/3];
//! unbalanced kernels such as [1/5, 1/5, 3/5] are used as given for T1's side and flipped
//! for T2's side), and the outputs around the seam are projected onto the first 50
//! Eigenfires only (low frequencies: smooth deformation instead of layered flames, §4.9).
//! Fine detail may be restored by copying higher-order weights from the target images.
//!
//! Where we depart from the thesis, and why:
//! - *Which outputs.* We emit one morph per kernel window that straddles the seam, i.e.
//!   `K.len() - 1` frames, in time order, and keep T1's last and T2's first frames. For the
//!   3-tap kernel the thesis computes four outputs (last two of T1, first two of T2) of
//!   which two repeat the same windows, and says to "ignore two results out of four"; our
//!   rule is that choice made once and for any kernel length. Any morph that still equals
//!   its predecessor (distance < 1e-6) is dropped as the thesis's duplicate.
//! - *Flip.* A window with at least as many T1 frames as T2 frames uses K; the others use
//!   K reversed. K[m] multiplies the m-th frame of the window in time order.
//! - *Normalisation.* K is divided by its sum so the morphs keep the weights' scale (the
//!   thesis's kernels already sum to 1); a kernel summing to 0 is an error.
//! - *Detail injection* is deterministic: weights `inject_from..E` are copied from the
//!   target image of the morph's side (α for T1-side windows, β for T2-side ones); the
//!   thesis copies "a few" such weights at random. Weights `e_render..inject_from` are 0.
//! - Windows reaching past the start of T1 or the end of T2 repeat the edge frame.

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
    let l = p.kernel.len();
    if l < 2 {
        return Err(bad(
            "kernel",
            format!("needs at least 2 taps to make a morph, got {l}"),
        ));
    }
    if p.kernel.iter().any(|k| !k.is_finite()) {
        return Err(bad("kernel", "contains NaN or infinity"));
    }
    let sum: f64 = p.kernel.iter().map(|&k| k as f64).sum();
    if sum.abs() < 1e-6 {
        return Err(bad(
            "kernel",
            format!("sums to {sum}; it must not sum to 0 (it is normalised by its sum)"),
        ));
    }
    if p.e_render == 0 {
        return Err(bad("e_render", "must be at least 1"));
    }
    let e = space.e();
    let e_render = p.e_render.min(e);
    if let Some(k) = p.inject_from {
        if k < p.e_render {
            return Err(bad(
                "inject_from",
                format!("must be ≥ e_render = {}, got {k}", p.e_render),
            ));
        }
    }
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
    let mut frames: Vec<FrameRef> = Vec::with_capacity(l - 1);
    let mut prev: Vec<f32> = space.frame(alpha).to_vec();
    for w in 0..l - 1 {
        let s = n1 - (l as isize - 1) + w as isize; // first position of the window
        let t1_count = l - 1 - w;
        let t1_side = t1_count >= l - t1_count;
        let mut out = vec![0.0f64; e];
        for (m, _) in k.iter().enumerate() {
            let km = if t1_side { k[m] } else { k[l - 1 - m] };
            let f = space.frame(at(s + m as isize));
            for (o, &x) in out[..e_render].iter_mut().zip(f) {
                *o += km * x as f64;
            }
        }
        let mut out: Vec<f32> = out.into_iter().map(|x| x as f32).collect();
        if let Some(from) = p.inject_from {
            let target = space.frame(if t1_side { alpha } else { beta });
            for d in from.min(e)..e {
                out[d] = target[d];
            }
        }
        if super::dist(&out, &prev, usize::MAX) < 1e-6 {
            continue; // the thesis's duplicate frame
        }
        prev.clone_from(&out);
        frames.push(FrameRef::Weights(out));
    }
    let e_detect = rec.e_detect(space);
    let seam_ratio = join_seam(space, &t1, &t2, &frames, e_detect);
    Ok(Join {
        why: format!(
            "{} morph frame(s) from a {l}-tap kernel, rendered with {e_render} of {e} weights{}",
            frames.len(),
            match p.inject_from {
                Some(f) if f < e => format!(", weights {f}..{e} copied from α/β"),
                _ => String::new(),
            }
        ),
        frames,
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

    /// Frame i = [i, 10 i, 100 i, 1000 i].
    fn ramp() -> Vec<f32> {
        (0..6)
            .flat_map(|i| [1.0, 10.0, 100.0, 1000.0].map(|s| s * i as f32))
            .collect()
    }

    #[test]
    fn box_kernel_arithmetic() {
        let w = ramp();
        let s = WeightSpace::new(&w, 4, vec![]).unwrap();
        let p = LowPassParams {
            kernel: vec![1.0, 1.0, 1.0], // normalised to 1/3 each
            e_render: 4,
            inject_from: None,
        };
        let j = low_pass(&s, 0..3, 3..6, &p, &RecognitionParams::default()).unwrap();
        assert_eq!(j.frames.len(), 2);
        // Windows (1,2,3) and (2,3,4): means 2 and 3.
        for (f, want) in j.frames.iter().zip([2.0f32, 3.0]) {
            let got = weights(f);
            for (g, sc) in got.iter().zip([1.0, 10.0, 100.0, 1000.0]) {
                assert!((g - want * sc).abs() < 1e-3, "{got:?} vs {want}");
            }
        }
    }

    #[test]
    fn asymmetric_kernel_is_flipped_and_detail_injected() {
        let w = ramp();
        let s = WeightSpace::new(&w, 4, vec![]).unwrap();
        let p = LowPassParams {
            kernel: vec![1.0, 2.0, 3.0], // → [1/6, 2/6, 3/6]
            e_render: 2,
            inject_from: Some(3),
        };
        let j = low_pass(&s, 0..3, 3..6, &p, &RecognitionParams::default()).unwrap();
        assert_eq!(j.frames.len(), 2);
        // T1-side window (1,2,3) with K: (1+4+9)/6 = 14/6; T2-side window (2,3,4) with K
        // flipped [3,2,1]/6: (6+6+4)/6 = 16/6. Weight 2 is zeroed (e_render = 2), weight 3
        // is copied from α = frame 2 (2000) and β = frame 3 (3000).
        let want = [
            [14.0 / 6.0, 140.0 / 6.0, 0.0, 2000.0],
            [16.0 / 6.0, 160.0 / 6.0, 0.0, 3000.0],
        ];
        for (f, want) in j.frames.iter().zip(want) {
            let got = weights(f);
            for (g, w) in got.iter().zip(want) {
                assert!((g - w).abs() < 1e-4, "{got:?} vs {want:?}");
            }
        }
    }

    #[test]
    fn duplicate_morphs_are_dropped() {
        // T1 and T2 all the same frame: every morph equals α and is dropped.
        let w = vec![1.0f32; 12];
        let s = WeightSpace::new(&w, 2, vec![]).unwrap();
        let j = low_pass(&s, 0..3, 3..6, &LowPassParams::default(), &Default::default()).unwrap();
        assert!(j.frames.is_empty());
    }

    #[test]
    fn bad_kernels() {
        let w = ramp();
        let s = WeightSpace::new(&w, 4, vec![]).unwrap();
        let rec = RecognitionParams::default();
        for kernel in [vec![1.0, -1.0], vec![0.5], vec![], vec![f32::NAN, 1.0]] {
            let p = LowPassParams { kernel: kernel.clone(), ..Default::default() };
            let e = low_pass(&s, 0..3, 3..6, &p, &rec).unwrap_err();
            assert!(
                matches!(&e, TransitionError::BadParameter { name, .. } if name == "kernel"),
                "{kernel:?}: {e}"
            );
        }
        let p = LowPassParams { e_render: 10, inject_from: Some(5), ..Default::default() };
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
        let cut = super::super::join_seam(&s, &t1, &t2, &[], testdata::E);
        assert!(cut >= 3.0, "plain cut {cut}");
        let p = LowPassParams { kernel: vec![1.0; 7], ..Default::default() };
        let j = transition(&s, t1, t2, &Transition::LowPass(p), &rec).unwrap();
        assert_eq!(j.frames.len(), 6);
        assert!(j.seam_ratio <= 1.5, "low-pass seam {} (cut {cut})", j.seam_ratio);
    }
}
