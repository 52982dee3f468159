//! Direct Bridging: database frames nearest to points on the segment α → β.
//!
//! Source: eigenfires-thesis.txt §5.1.2.1 (Figures 36–37), with the rejection rules of the
//! end of §5.1.2.2. The segment from α (last frame of T1) to β (first frame of T2) is
//! divided into N + 1 equal parts; each of the N inner points is replaced by its nearest
//! database frame (Euclidean distance on the first `e_detect` weights) that is not a frame
//! of T1 or T2, not already chosen, not one of the `reject_near` frames before α or after
//! β in their clips, and at least `theta_min` away from the previously chosen frame.
//!
//! Where we depart from the thesis, and why: the thesis only says the choice "should meet
//! the requirement of the permitted minimum threshold"; we read that as "at least θ_min
//! from the previous frame of the path" (starting with α), θ_min taken from the clip of
//! that previous frame, which is what keeps the path from stalling (slow motion). With
//! `steps: None` we pick N = round(|αβ| / median step) − 1 (≥ 1), the number of frames
//! that fill the gap at the footage's own speed; the thesis lets the artist choose N.

use std::ops::Range;

use super::{
    bad, join_seam, FrameRef, Join, RecognitionParams, Result, Transition, TransitionError,
    WeightSpace,
};

/// Direct Bridging from T1 to T2 with `steps` (N) frames; `None` = automatic N.
pub fn direct_bridging(
    space: &WeightSpace,
    t1: Range<usize>,
    t2: Range<usize>,
    steps: Option<usize>,
    rec: &RecognitionParams,
) -> Result<Join> {
    space.check_range("T1", &t1)?;
    space.check_range("T2", &t2)?;
    rec.validate()?;
    let e = rec.e_detect(space);
    let (alpha, beta) = (t1.end - 1, t2.start);
    let gap = space.distance(alpha, beta, e);
    Transition::DirectBridging { steps }.validate()?;
    let n = match steps {
        Some(n) => n,
        None => {
            let med = space.source_median(e);
            if med > 0.0 {
                ((gap / med).round() as usize).saturating_sub(1).max(1)
            } else {
                1
            }
        }
    };
    if n > space.len() {
        return Err(bad(
            "steps",
            format!(
                "{n} is more than the {} frames of the database",
                space.len()
            ),
        ));
    }
    let excluded = excluded_frames(space, &t1, &t2, rec.reject_near, true);
    let a = &space.frame(alpha)[..e];
    let b = &space.frame(beta)[..e];
    let mut chosen: Vec<usize> = Vec::with_capacity(n);
    let mut prev = alpha;
    for t in 1..=n {
        let f = t as f64 / (n + 1) as f64;
        let point: Vec<f32> = a
            .iter()
            .zip(b)
            .map(|(&x, &y)| (x as f64 + f * (y as f64 - x as f64)) as f32)
            .collect();
        let theta = rec.theta(space, prev);
        let best = nearest_allowed(space, prev, theta, &point, e, |i| {
            !excluded[i] && !chosen.contains(&i)
        });
        match best {
            Some((_, i)) => {
                chosen.push(i);
                prev = i;
            }
            None => {
                return Err(TransitionError::NoPath {
                    method: "direct-bridging",
                    reason: format!(
                        "no frame at least θ_min = {theta:.4} from frame {prev} for bridge point {t} of {n}"
                    ),
                })
            }
        }
    }
    let frames: Vec<FrameRef> = chosen.iter().map(|&i| FrameRef::Db(i)).collect();
    let seam_ratio = join_seam(space, &t1, &t2, &frames, (0, 0), e);
    Ok(Join {
        why: format!(
            "{n} bridge point(s) on α={alpha} → β={beta} (|αβ| = {gap:.4}), each replaced by its nearest frame"
        ),
        frames,
        trim_t1: 0,
        trim_t2: 0,
        method: "direct-bridging",
        seam_ratio,
    })
}

/// The frame nearest to `point` (first index among equal distances) among the frames
/// `allowed` and at least `theta` from `prev`, with its distance.
///
/// Frames are scanned in index order; each distance is abandoned as soon as its leading
/// weights put it past the best so far (see [`super::dist_upto`], which keeps the result
/// identical to computing every distance in full). Blocks of frames run on rayon's pool
/// and are merged in index order, so the answer does not depend on the thread count.
fn nearest_allowed(
    space: &WeightSpace,
    prev: usize,
    theta: f64,
    point: &[f32],
    e: usize,
    allowed: impl Fn(usize) -> bool + Sync,
) -> Option<(f64, usize)> {
    use rayon::prelude::*;
    const BLOCK: usize = 512;
    let p = space.frame(prev);
    let scan = |range: Range<usize>| -> Option<(f64, usize)> {
        let mut best: Option<(f64, usize)> = None;
        for i in range {
            if !allowed(i) {
                continue;
            }
            let f = space.frame(i);
            // `None` = farther than θ_min: allowed.
            if super::dist_upto(p, f, e, theta).is_some_and(|d| d < theta) {
                continue;
            }
            let limit = best.map_or(f64::INFINITY, |b| b.0);
            if let Some(d) = super::dist_upto(f, point, e, limit) {
                if best.is_none_or(|b| d < b.0) {
                    best = Some((d, i));
                }
            }
        }
        best
    };
    let blocks: Vec<Option<(f64, usize)>> = (0..space.len().div_ceil(BLOCK))
        .into_par_iter()
        .map(|b| scan(b * BLOCK..((b + 1) * BLOCK).min(space.len())))
        .collect();
    // Blocks in index order, strict `<`: the first of equal minima wins, as in one scan.
    blocks
        .into_iter()
        .flatten()
        .fold(None, |best, c| match best {
            Some(b) if b.0 <= c.0 => Some(b),
            _ => Some(c),
        })
}

/// Frames a recognition path may not use: the `reject_near` frames of α's clip up to α
/// and of β's clip from β (§5.1.2.2, last paragraph), and, if `whole_ranges`, all of T1
/// and T2 (§5.1.2.1).
pub(crate) fn excluded_frames(
    space: &WeightSpace,
    t1: &Range<usize>,
    t2: &Range<usize>,
    reject_near: usize,
    whole_ranges: bool,
) -> Vec<bool> {
    let mut ex = vec![false; space.len()];
    let (alpha, beta) = (t1.end - 1, t2.start);
    let ca = &space.clips()[space.clip_index(alpha)];
    let cb = &space.clips()[space.clip_index(beta)];
    ex[alpha.saturating_sub(reject_near).max(ca.start)..=alpha].fill(true);
    ex[beta..=(beta + reject_near).min(cb.start + cb.len - 1)].fill(true);
    if whole_ranges {
        for i in t1.clone().chain(t2.clone()) {
            ex[i] = true;
        }
    }
    ex
}

#[cfg(test)]
mod tests {
    use super::super::{join_seam, testdata, transition, Transition};
    use super::*;

    #[test]
    fn bridges_two_distant_ranges_on_the_parametric_flame() {
        let (w, clips) = testdata::flame(8, 40, 0.05, 0.25, 0.003, 5);
        let s = WeightSpace::new(&w, testdata::E, clips).unwrap();
        let rec = RecognitionParams::default();
        // T1 = clip 0 up to angle ≈ 0.95; T2 = clip 4 from angle ≈ 1.0 + 0.5 = 1.5.
        let (t1, t2) = (0..20, 170..200);
        let cut = join_seam(&s, &t1, &t2, &[], (0, 0), testdata::E);
        assert!(cut >= 3.0, "plain cut {cut}");
        let j = transition(
            &s,
            t1.clone(),
            t2.clone(),
            &Transition::DirectBridging { steps: None },
            &rec,
        )
        .unwrap();
        assert!(
            j.seam_ratio <= 1.5,
            "bridge seam {} (cut {cut}): {}",
            j.seam_ratio,
            j.why
        );
        for f in &j.frames {
            let FrameRef::Db(i) = f else { panic!() };
            assert!(
                !t1.contains(i) && !t2.contains(i),
                "used a frame of T1/T2: {i}"
            );
        }
    }

    #[test]
    fn nearest_allowed_equals_a_full_scan() {
        let w = super::super::tests::pca_like(1200, 70, 8);
        let s = WeightSpace::new(&w, 70, vec![]).unwrap();
        for (prev, target, e, theta) in [(3, 900, 70, 0.5), (600, 20, 9, 2.0), (10, 11, 70, 1e-9)] {
            let point: Vec<f32> = s.frame(target)[..e].iter().map(|x| x + 0.01).collect();
            let allowed = |i: usize| i % 7 != 3 && i != target;
            let want = (0..s.len())
                .filter(|&i| allowed(i))
                .filter(|&i| s.distance(prev, i, e) >= theta)
                .map(|i| (super::super::dist(s.frame(i), &point, e), i))
                .min_by(|x, y| x.0.total_cmp(&y.0));
            assert_eq!(nearest_allowed(&s, prev, theta, &point, e, allowed), want);
        }
        // Equal distances: the first frame wins, as with `min_by`.
        let w = [0.0f32, 5.0, 1.0, -1.0, 1.0, 3.0];
        let s = WeightSpace::new(&w, 1, vec![]).unwrap();
        assert_eq!(
            nearest_allowed(&s, 1, 0.5, &[0.0], 1, |i| i != 0),
            Some((1.0, 2))
        );
    }

    #[test]
    fn respects_theta_min_and_explicit_steps() {
        let (w, clips) = testdata::flame(8, 40, 0.05, 0.25, 0.003, 5);
        let s = WeightSpace::new(&w, testdata::E, clips).unwrap();
        let rec = RecognitionParams {
            theta_min: Some(0.4),
            ..Default::default()
        };
        let j = direct_bridging(&s, 0..20, 170..200, Some(3), &rec).unwrap();
        assert_eq!(j.frames.len(), 3);
        let mut prev = 19;
        for f in &j.frames {
            let FrameRef::Db(i) = f else { panic!() };
            assert!(s.distance(prev, *i, testdata::E) >= 0.4);
            prev = *i;
        }
        assert!(direct_bridging(&s, 0..20, 170..200, Some(0), &rec).is_err());
    }
}
