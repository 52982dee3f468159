//! End Growing Connection: two paths grow from α and β until they meet.
//!
//! Source: eigenfires-thesis.txt §5.1.2.2, Algorithm 1 (Figures 38–39), and the rejection
//! rules in the last paragraph of §5.1.2.2.
//!
//! Each step (at most N/2) both sides build the list of database frames sorted by
//! distance to the current end (α or β), without the frames the side already used, the
//! `reject_near` frames before the original α / after the original β, and frames closer
//! than θ_min. Walking the two lists with indices j and k, the four distances
//! D = |α−β|, D12 = |α_j−β_k|, D1 = |α−β_k|, D2 = |β−α_j| decide, exactly as printed:
//! if D − D12 ≥ θ_min the pair is accepted (α ← α_j, β ← β_k, next step); otherwise
//! shortToα = D1 − D ≤ θ_min, shortToβ = D2 − D ≤ θ_min; both → j+1, k+1; else k+1 if not
//! shortToα and j+1 if not shortToβ. After each step the whole α-path is compared with the
//! whole β-path: a shared image α_a = β_b (possibly at different step counts, Figure 39)
//! or, failing that, a pair closer than θ_min joins them; elements past the join are
//! removed. Finally `Optimize_Path()` runs. No join within N steps is an error (the
//! thesis's case 3: "choose a larger step … or employ previous techniques").
//!
//! Where we depart from the thesis, and why:
//! - The printed `While … and foundStep` is read as `and not foundStep` (a typo: as
//!   printed the loop would never run).
//! - The lists hold only frames closer to the current end than the current gap D (the
//!   text: "short distances less than the difference between α and β"); Algorithm 1's
//!   lists hold all 2197 frames. This stops a side from leaping across the space.
//! - "Frames already used" are rejected per side: a side never revisits its own frames,
//!   but may pick the other side's, which is how shared images at different step counts
//!   (α3 = β6, Figure 39) can arise at all.
//! - Case 2 ("the distance between α_j and β_j is small and less than θ_min") is checked
//!   over all pairs of the two paths, like the shared-image test, earliest pair first,
//!   and against `join_gap` (default: the clips' median step), not θ_min. With θ_min a
//!   *minimum* step, the printed rules cannot close a gap between θ_min and ≈ 1.5 θ_min
//!   (each side must move ≥ θ_min and the gap must shrink by ≥ θ_min), so with the
//!   thesis's rule the paths stall just short of each other; a gap of one ordinary
//!   footage step is by definition smooth. Set `join_gap = theta_min` for the thesis.
//! - θ_min is per side (the clip of the current α or β) for the lists, and their mean in
//!   the four-distance test (the thesis's adaptive extension).
//! - `Optimize_Path()` is not specified in the thesis beyond "removing some images … if we
//!   encounter dramatic changes of distances". Ours first removes detours: a frame is
//!   dropped when its neighbours are at least θ_min apart yet no farther apart than the
//!   larger of its two steps (so the worst jump does not grow), until nothing changes.
//!   Then — an addition, not a removal — while the largest step is longer than
//!   `join_gap` and the path has fewer than N frames, the unused database frame that most
//!   lowers that step (both new steps ≥ θ_min) is inserted into it. The printed rules
//!   accept any pair that closes the gap by θ_min, so single steps of ~2 footage steps
//!   do occur (measured on the test flame: worst step 1.8 → below 1.5 after this).

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::ops::Range;

use super::bridging::excluded_frames;
use super::{
    join_seam, FrameRef, Join, RecognitionParams, Result, Transition, TransitionError, WeightSpace,
};

/// End Growing Connection from T1 to T2 with at most `max_steps` (N) new frames.
pub fn end_growing(
    space: &WeightSpace,
    t1: Range<usize>,
    t2: Range<usize>,
    max_steps: usize,
    rec: &RecognitionParams,
) -> Result<Join> {
    space.check_range("T1", &t1)?;
    space.check_range("T2", &t2)?;
    rec.validate()?;
    Transition::EndGrowing { max_steps }.validate()?;
    let e = rec.e_detect(space);
    let (alpha, beta) = (t1.end - 1, t2.start);
    let excluded = excluded_frames(space, &t1, &t2, rec.reject_near, false);
    let grown = grow(space, alpha, beta, max_steps / 2, &excluded, e, rec)?;
    let before = grown.path.len();
    let path = optimize_path(space, alpha, beta, grown.path, &excluded, max_steps, e, rec);
    let frames: Vec<FrameRef> = path.iter().map(|&i| FrameRef::Db(i)).collect();
    let seam_ratio = join_seam(space, &t1, &t2, &frames, (0, 0), e);
    Ok(Join {
        why: format!(
            "paths from α={alpha} and β={beta} {} with {before} frame(s), {} after Optimize_Path",
            match grown.join {
                JoinAt::Already => "needed no frames (gap under join_gap)".to_string(),
                JoinAt::Shared { a, b } => format!("met at a shared image α{a} = β{b}"),
                JoinAt::Gap { a, b } => format!("joined by a small gap α{a} → β{b}"),
            },
            frames.len()
        ),
        frames,
        trim_t1: 0,
        trim_t2: 0,
        method: "end-growing",
        seam_ratio,
    })
}

/// Where Algorithm 1 joined the two paths (indices into the paths, 0 = α or β itself).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum JoinAt {
    /// α and β were already closer than `join_gap`.
    Already,
    /// Case 1: α_a = β_b.
    Shared { a: usize, b: usize },
    /// Case 2: |α_a − β_b| < `join_gap`.
    Gap { a: usize, b: usize },
}

/// The result of Algorithm 1: the joined path without α and β, and where it joined.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Grown {
    pub path: Vec<usize>,
    pub join: JoinAt,
}

/// Algorithm 1 proper.
pub(crate) fn grow(
    space: &WeightSpace,
    alpha: usize,
    beta: usize,
    half_steps: usize,
    excluded: &[bool],
    e: usize,
    rec: &RecognitionParams,
) -> Result<Grown> {
    let d = |i: usize, j: usize| space.distance(i, j, e);
    // Paths including their origins: a_path[0] = α, b_path[0] = β.
    let mut a_path = vec![alpha];
    let mut b_path = vec![beta];
    if alpha == beta || d(alpha, beta) < rec.join_gap(space, alpha, beta) {
        return Ok(Grown {
            path: Vec::new(),
            join: JoinAt::Already,
        });
    }
    for step in 1..=half_steps {
        let (ca, cb) = (*a_path.last().unwrap(), *b_path.last().unwrap());
        let big_d = d(ca, cb);
        let mut list_a = NearList::new(space, ca, rec.theta(space, ca), big_d, e, |i| {
            !excluded[i] && !a_path.contains(&i)
        });
        let mut list_b = NearList::new(space, cb, rec.theta(space, cb), big_d, e, |i| {
            !excluded[i] && !b_path.contains(&i)
        });
        let theta = pair_theta(space, rec, ca, cb);
        // A pair is accepted only when D12 ≤ D − θ_min; a D12 known to be larger (by a
        // margin far beyond rounding) is rejected without finishing its sum.
        let d12_limit = (big_d - theta).max(0.0) + 1e-9 * (big_d + theta);
        // D1 depends on k only and D2 on j only: computed once per list entry.
        let (mut d1_of, mut d2_of) = (Vec::new(), Vec::new());
        let (mut j, mut k) = (0, 0);
        let mut found = false;
        while let (Some(aj), Some(bk)) = (list_a.get(j), list_b.get(k)) {
            // `None`: D12 > D − θ_min + margin, so D − D12 < θ_min (the branch that
            // computing D12 in full would take).
            let d12 = super::dist_upto(space.frame(aj), space.frame(bk), e, d12_limit);
            if d1_of.len() <= k {
                d1_of.push(d(ca, bk));
            }
            if d2_of.len() <= j {
                d2_of.push(d(cb, aj));
            }
            let (d1, d2) = (d1_of[k], d2_of[j]);
            if d12.is_none_or(|d12| big_d - d12 < theta) {
                let short_to_a = d1 - big_d <= theta;
                let short_to_b = d2 - big_d <= theta;
                if short_to_a && short_to_b {
                    j += 1;
                    k += 1;
                } else {
                    if !short_to_a {
                        k += 1;
                    }
                    if !short_to_b {
                        j += 1;
                    }
                }
            } else {
                a_path.push(aj);
                b_path.push(bk);
                found = true;
                break;
            }
        }
        if !found {
            return Err(TransitionError::NoPath {
                method: "end-growing",
                reason: format!(
                    "step {step} of {half_steps}: no pair of candidates brings the sides θ_min = {theta:.4} closer"
                ),
            });
        }
        if let Some(p) = try_join(space, &a_path, &b_path, e, rec) {
            return Ok(p);
        }
    }
    Err(TransitionError::NoPath {
        method: "end-growing",
        reason: format!(
            "no shared image and no gap under θ_min within N = {} steps; try a larger N, Direct Bridging or low-pass",
            2 * half_steps
        ),
    })
}

/// Algorithm 1's candidate list: the frames `allowed` with θ ≤ d < gap, d = the distance
/// from `from`, sorted by (d, index) — produced on demand, since the walk over the two
/// lists usually accepts a pair within the first few entries.
///
/// Every frame starts with a cheap lower bound of its distance (the first few weights,
/// see [`super::dist_lower_bound`]) in a min-heap; a popped bound is replaced by a tighter
/// one, then by the exact distance, and a popped exact distance is the next entry
/// (nothing left in the heap can be smaller, ties go to the lower index). The entries and
/// their order are exactly those of computing, filtering and sorting every distance.
struct NearList<'s, 'a> {
    space: &'s WeightSpace<'a>,
    from: usize,
    theta: f64,
    gap: f64,
    e: usize,
    /// (distance or lower bound, frame, stage), smallest first; stage `s` is a bound over
    /// the first [`NearList::STAGES`]`[s]` weights, the last stage the exact distance.
    heap: BinaryHeap<Reverse<(TotalF64, usize, usize)>>,
    list: Vec<usize>,
}

/// An f64 ordered by [`f64::total_cmp`].
#[derive(Clone, Copy, Debug, PartialEq)]
struct TotalF64(f64);
impl Eq for TotalF64 {}
impl PartialOrd for TotalF64 {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for TotalF64 {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        self.0.total_cmp(&o.0)
    }
}

impl<'s, 'a> NearList<'s, 'a> {
    /// Weights in the successive lower bounds; the last stage is the whole distance.
    const STAGES: [usize; 3] = [32, 192, usize::MAX];

    fn new(
        space: &'s WeightSpace<'a>,
        from: usize,
        theta: f64,
        gap: f64,
        e: usize,
        allowed: impl Fn(usize) -> bool,
    ) -> Self {
        let f = space.frame(from);
        let bounds: Vec<Reverse<(TotalF64, usize, usize)>> = (0..space.len())
            .filter(|&i| allowed(i))
            .filter_map(|i| {
                let lb = super::dist_lower_bound(f, space.frame(i), e, Self::STAGES[0]);
                // d ≥ lb ≥ gap: not a candidate.
                (lb < gap).then_some(Reverse((TotalF64(lb), i, 0)))
            })
            .collect();
        NearList {
            space,
            from,
            theta,
            gap,
            e,
            heap: BinaryHeap::from(bounds),
            list: Vec::new(),
        }
    }

    /// Entry `j` (0 = nearest), or `None` past the end.
    fn get(&mut self, j: usize) -> Option<usize> {
        let last = Self::STAGES.len() - 1;
        while self.list.len() <= j {
            let Reverse((_, i, stage)) = self.heap.pop()?;
            if stage == last {
                self.list.push(i);
                continue;
            }
            let (f, g) = (self.space.frame(self.from), self.space.frame(i));
            if stage + 1 < last {
                let lb = super::dist_lower_bound(f, g, self.e, Self::STAGES[stage + 1]);
                if lb < self.gap {
                    self.heap.push(Reverse((TotalF64(lb), i, stage + 1)));
                }
            } else if let Some(d) = super::dist_upto(f, g, self.e, self.gap) {
                if d >= self.theta && d < self.gap {
                    self.heap.push(Reverse((TotalF64(d), i, last)));
                }
            }
        }
        Some(self.list[j])
    }
}

fn pair_theta(space: &WeightSpace, rec: &RecognitionParams, a: usize, b: usize) -> f64 {
    0.5 * (rec.theta(space, a) + rec.theta(space, b))
}

/// The join test of Algorithm 1 (line 7) plus case 2, over all pairs of the two paths
/// (origins included, the origin pair excluded). Returns α_1..α_a then β_b..β_1 with the
/// elements past the join removed; a shared image appears once.
fn try_join(
    space: &WeightSpace,
    a_path: &[usize],
    b_path: &[usize],
    e: usize,
    rec: &RecognitionParams,
) -> Option<Grown> {
    let pairs = || {
        let mut v: Vec<(usize, usize)> = (0..a_path.len())
            .flat_map(|a| (0..b_path.len()).map(move |b| (a, b)))
            .filter(|&(a, b)| a + b > 0)
            .collect();
        v.sort_by_key(|&(a, b)| (a + b, a.max(b)));
        v
    };
    let build = |a: usize, b_incl: usize| -> Vec<usize> {
        let mut p: Vec<usize> = a_path[1..=a].to_vec();
        p.extend(b_path[1..b_incl].iter().rev());
        p
    };
    if let Some((a, b)) = pairs().into_iter().find(|&(a, b)| a_path[a] == b_path[b]) {
        // Shared image α_a = β_b: keep it once (from the α side).
        let path = if a == 0 {
            // β-path reached α itself: β_b..β_1 without β_b (= α).
            b_path[1..b].iter().rev().copied().collect()
        } else {
            build(a, b)
        };
        return Some(Grown {
            path,
            join: JoinAt::Shared { a, b },
        });
    }
    pairs()
        .into_iter()
        .find(|&(a, b)| {
            let (x, y) = (a_path[a], b_path[b]);
            let gap = rec.join_gap(space, x, y);
            super::dist_upto(space.frame(x), space.frame(y), e, gap).is_some_and(|d| d < gap)
        })
        .map(|(a, b)| Grown {
            path: build(a, b + 1),
            join: JoinAt::Gap { a, b },
        })
}

/// Optimize_Path(): drop detours, then split dramatic jumps (see the module docs).
pub(crate) fn optimize_path(
    space: &WeightSpace,
    alpha: usize,
    beta: usize,
    path: Vec<usize>,
    excluded: &[bool],
    max_len: usize,
    e: usize,
    rec: &RecognitionParams,
) -> Vec<usize> {
    // Distances between path frames are asked for again and again (the detour pass
    // restarts after every removal): remember them.
    let memo = std::cell::RefCell::new(std::collections::HashMap::new());
    let d = |i: usize, j: usize| {
        *memo
            .borrow_mut()
            .entry((i.min(j), i.max(j)))
            .or_insert_with(|| space.distance(i, j, e))
    };
    let mut full = Vec::with_capacity(path.len() + 2);
    full.push(alpha);
    full.extend(path);
    full.push(beta);
    // 1. Detours: drop c when its neighbours are ≥ θ_min apart and no farther apart than
    //    c's larger step.
    let mut changed = true;
    while changed {
        changed = false;
        for i in 1..full.len().saturating_sub(1) {
            let (p, c, n) = (full[i - 1], full[i], full[i + 1]);
            let skip = d(p, n);
            if skip >= rec.theta(space, p) && skip <= d(p, c).max(d(c, n)) {
                full.remove(i);
                changed = true;
                break;
            }
        }
    }
    // 2. Dramatic jumps: while the largest step is longer than join_gap (a footage step)
    //    and the path is shorter than N, insert the unused frame that most lowers it,
    //    keeping both new steps ≥ θ_min.
    while full.len() - 2 < max_len {
        let Some((i, worst)) = full
            .windows(2)
            .enumerate()
            .map(|(i, w)| (i, d(w[0], w[1])))
            .max_by(|x, y| x.1.total_cmp(&y.1))
        else {
            break;
        };
        let (p, n) = (full[i], full[i + 1]);
        if worst <= rec.join_gap(space, p, n) {
            break;
        }
        let theta = rec.theta(space, p);
        match best_split(space, p, n, theta, worst, e, |m| {
            !excluded[m] && !full.contains(&m)
        }) {
            Some(m) => full.insert(i + 1, m),
            None => break,
        }
    }
    full[1..full.len() - 1].to_vec()
}

/// The `allowed` frame m with both steps p→m and m→n at least `theta` that minimises the
/// larger of the two, if that is below `worst` (first index among equal minima).
///
/// The same as taking the minimum over every frame and then comparing it with `worst`:
/// scanning in index order with a strict `<` keeps the first minimum, and starting from
/// `worst` only drops frames that could not be inserted anyway. Distances past the best so
/// far are abandoned early (exactly, see [`super::dist_upto`]).
fn best_split(
    space: &WeightSpace,
    p: usize,
    n: usize,
    theta: f64,
    worst: f64,
    e: usize,
    allowed: impl Fn(usize) -> bool + Sync,
) -> Option<usize> {
    use rayon::prelude::*;
    const BLOCK: usize = 512;
    let (fp, fn_) = (space.frame(p), space.frame(n));
    let scan = |range: Range<usize>| -> (f64, Option<usize>) {
        let mut best = (worst, None);
        for m in range {
            if !allowed(m) {
                continue;
            }
            let fm = space.frame(m);
            let Some(x) = super::dist_upto(fp, fm, e, best.0) else {
                continue;
            };
            if x < theta {
                continue;
            }
            let Some(y) = super::dist_upto(fm, fn_, e, best.0) else {
                continue;
            };
            if y < theta {
                continue;
            }
            let w = x.max(y);
            if w < best.0 {
                best = (w, Some(m));
            }
        }
        best
    };
    let blocks: Vec<(f64, Option<usize>)> = (0..space.len().div_ceil(BLOCK))
        .into_par_iter()
        .map(|b| scan(b * BLOCK..((b + 1) * BLOCK).min(space.len())))
        .collect();
    blocks
        .into_iter()
        .fold((worst, None), |best, c| if c.0 < best.0 { c } else { best })
        .1
}

#[cfg(test)]
mod tests {
    use super::super::{join_seam, testdata, transition, Transition};
    use super::*;

    #[test]
    fn joins_two_distant_ranges_on_the_parametric_flame() {
        let (w, clips) = testdata::flame(8, 40, 0.05, 0.25, 0.003, 7);
        let s = WeightSpace::new(&w, testdata::E, clips).unwrap();
        let rec = RecognitionParams::default();
        let (t1, t2) = (0..20, 170..200);
        let cut = join_seam(&s, &t1, &t2, &[], (0, 0), testdata::E);
        assert!(cut >= 3.0, "plain cut {cut}");
        let j = transition(&s, t1, t2, &Transition::EndGrowing { max_steps: 40 }, &rec).unwrap();
        assert!(!j.frames.is_empty());
        assert!(
            j.seam_ratio <= 1.5,
            "end-growing seam {} (cut {cut}): {}",
            j.seam_ratio,
            j.why
        );
    }

    #[test]
    fn loop_on_the_parametric_flame() {
        let (w, clips) = testdata::flame(8, 40, 0.05, 0.25, 0.003, 9);
        let s = WeightSpace::new(&w, testdata::E, clips).unwrap();
        let rec = RecognitionParams::default();
        let range = 80..100; // clip 2, 20 frames ≈ 1 rad
        let cut = join_seam(&s, &range, &range, &[], (0, 0), testdata::E);
        assert!(cut >= 3.0, "plain loop cut {cut}");
        let j = super::super::make_loop(&s, range, &Transition::EndGrowing { max_steps: 60 }, &rec)
            .unwrap();
        assert!(j.seam_ratio <= 1.5, "loop seam {}: {}", j.seam_ratio, j.why);
    }

    /// Hand-made 2-D set (θ_min = 1, only shared images join): the β side reaches α's
    /// first frame on its third step, so the join is α1 = β3 and α2, α3 must go.
    ///
    /// frames: 0 α (0,0), 1 β (10,0), 2 (2,2), 3 (1,2), 4 (8,-1), 5 (7,-3), 6 (4,-2), 7 (1,0)
    ///
    /// Step 1 (D = 10): α list 7, 3, 2, 6, 5, 4; β list 4, 5, 6, 2, 7, 3.
    ///   (7, 4): D12 = 7.07, D − D12 = 2.93 ≥ 1 → α1 = 7, β1 = 4.
    /// Step 2 (D = 7.07; frames at ≥ D are not candidates): α list 3, 2, 6, 5; β list 5, 6, 2.
    ///   (3, 5): D − D12 < 1, D1 − D = −0.37 and D2 − D = 0.55, both short → j+1, k+1.
    ///   (2, 6): D − D12 = 2.6 → α2 = 2, β2 = 6.
    /// Step 3 (D = 4.47): α list 3; β list 5, 7.
    ///   (3, 5): D − D12 < 1, D1 − D = 2.6 > 1 → not shortToα → k+1.
    ///   (3, 7): D − D12 = 2.47 → α3 = 3, β3 = 7 = α1: shared image.
    fn hand_made() -> Vec<f32> {
        vec![
            0., 0., 10., 0., 2., 2., 1., 2., 8., -1., 7., -3., 4., -2., 1., 0.,
        ]
    }

    fn strict() -> RecognitionParams {
        RecognitionParams {
            theta_min: Some(1.0),
            join_gap: Some(0.01),
            reject_near: 0,
            ..Default::default()
        }
    }

    #[test]
    fn algorithm1_shared_image_at_different_steps() {
        let xs = hand_made();
        let s = WeightSpace::new(&xs, 2, vec![]).unwrap();
        let g = grow(&s, 0, 1, 6, &[false; 8], 2, &strict()).unwrap();
        assert_eq!(g.join, JoinAt::Shared { a: 1, b: 3 });
        // α1 (= β3, once), then β2, β1; α2 = 2 and α3 = 3 are past the shared image.
        assert_eq!(g.path, vec![7, 6, 4]);
        // The same through the public entry point, and the why says so.
        let j = end_growing(&s, 0..1, 1..2, 12, &strict()).unwrap();
        assert!(j.why.contains("α1 = β3"), "{}", j.why);
    }

    #[test]
    fn algorithm1_joins_on_a_small_gap() {
        // Same set, but a join gap of 3.7 lets step 2 stop: |α1 − β2| = |(1,0) − (4,-2)| = 3.6.
        let xs = hand_made();
        let s = WeightSpace::new(&xs, 2, vec![]).unwrap();
        let rec = RecognitionParams {
            join_gap: Some(3.7),
            ..strict()
        };
        let g = grow(&s, 0, 1, 6, &[false; 8], 2, &rec).unwrap();
        // Pairs are tried earliest first: (α1, β1) is 7.07 apart, (α0, β2) 4.47, (α1, β2) 3.6.
        assert_eq!(g.join, JoinAt::Gap { a: 1, b: 2 });
        assert_eq!(g.path, vec![7, 6, 4]);
        // α and β already closer than the join gap: nothing to insert.
        let rec = RecognitionParams {
            join_gap: Some(11.0),
            ..strict()
        };
        let g = grow(&s, 0, 1, 6, &[false; 8], 2, &rec).unwrap();
        assert_eq!((g.join, g.path.len()), (JoinAt::Already, 0));
    }

    #[test]
    fn fails_clearly_within_n_steps() {
        // 1-D: each side can step 10 towards the other, but N = 4 (2 per side) ends
        // with a gap of 60.
        let xs = [0.0f32, 100.0, 10.0, 20.0, 80.0, 90.0];
        let s = WeightSpace::new(&xs, 1, vec![]).unwrap();
        let e = end_growing(&s, 0..1, 1..2, 4, &strict()).unwrap_err();
        assert!(
            matches!(
                e,
                TransitionError::NoPath {
                    method: "end-growing",
                    ..
                }
            ),
            "{e}"
        );
        assert!(e.to_string().contains("N = 4"), "{e}");
        // Nothing to step to at all.
        let xs = [0.0f32, 100.0, -1.0, 101.0];
        let s = WeightSpace::new(&xs, 1, vec![]).unwrap();
        let e = end_growing(&s, 0..1, 1..2, 10, &strict()).unwrap_err();
        assert!(e.to_string().contains("step 1"), "{e}");
        assert!(end_growing(&s, 0..1, 1..2, 1, &strict()).is_err());
    }

    #[test]
    fn scans_equal_full_scans() {
        let w = super::super::tests::pca_like(1100, 70, 9);
        let s = WeightSpace::new(&w, 70, vec![]).unwrap();
        let d = |i: usize, j: usize, e: usize| s.distance(i, j, e);
        let allowed = |i: usize| i % 5 != 1;
        for (from, to, e) in [(5, 700, 70), (400, 420, 20), (1000, 30, 70)] {
            let gap = d(from, to, e);
            let theta = 0.1 * gap;
            let want: Vec<(f64, usize)> = (0..s.len())
                .filter(|&i| allowed(i))
                .map(|i| (d(from, i, e), i))
                .filter(|&(x, _)| x >= theta && x < gap)
                .collect();
            let mut want: Vec<usize> = want.into_iter().map(|(_, i)| i).collect();
            want.sort_by(|&x, &y| d(from, x, e).total_cmp(&d(from, y, e)).then(x.cmp(&y)));
            let mut list = NearList::new(&s, from, theta, gap, e, allowed);
            let got: Vec<usize> = (0..).map_while(|j| list.get(j)).collect();
            assert_eq!(got, want);
            assert!(list.get(got.len() + 3).is_none());
            for worst in [gap, 0.6 * gap, 0.3 * gap] {
                let want = (0..s.len())
                    .filter(|&m| allowed(m))
                    .map(|m| (d(from, m, e), d(m, to, e), m))
                    .filter(|&(x, y, _)| x >= theta && y >= theta)
                    .map(|(x, y, m)| (x.max(y), m))
                    .min_by(|x, y| x.0.total_cmp(&y.0))
                    .filter(|&(w, _)| w < worst)
                    .map(|(_, m)| m);
                assert_eq!(best_split(&s, from, to, theta, worst, e, allowed), want);
            }
        }
    }

    #[test]
    fn near_list_breaks_ties_by_index() {
        let xs = [0.0f32, 1.0, -1.0, 2.0, -2.0, 1.0, 0.2, 3.0];
        let s = WeightSpace::new(&xs, 1, vec![]).unwrap();
        let mut list = NearList::new(&s, 0, 0.5, 3.0, 1, |i| i != 5);
        let got: Vec<usize> = (0..).map_while(|j| list.get(j)).collect();
        assert_eq!(got, vec![1, 2, 3, 4]);
    }

    #[test]
    fn optimize_path_drops_detours() {
        // α=x0, path x1, x5 (overshoot), x2, β=x3.
        let xs = [0.0f32, 3.0, 1.0, 5.0, 2.0];
        let s = WeightSpace::new(&xs, 1, vec![]).unwrap();
        let rec = RecognitionParams {
            theta_min: Some(0.5),
            reject_near: 0,
            ..Default::default()
        };
        let p = optimize_path(&s, 0, 1, vec![2, 3, 4], &[false; 5], 0, 1, &rec);
        assert_eq!(p, vec![2, 4]);
    }
}
