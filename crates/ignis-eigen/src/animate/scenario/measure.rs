//! `auto` joins decided by measurement (issue 15 §2): the planner only knows weight-space
//! distances, which overstate how far apart two clips look and cannot see a soft frame. So
//! before rendering, every candidate of an `auto` join — the real-frame paths (End Growing,
//! Direct Bridging over the whole database) and the motion-compensated morph — is rendered
//! with up to [`SIDE`] real frames on each side (the ghost's ±15 neighbourhood) (a morph with its in-betweens chosen
//! as the full render chooses them, [`morph::render_metric`]) and measured on the metric
//! frames the written output is judged on (grey, 128 px, `ignis_core::loopq`): the worst
//! step from the last frame before the join to the first after it, over the median step of
//! those real frames, and the ghost (the softest of those frames over the median sharpness
//! of its ±15 neighbours in the rendered stretch). The lowest worst step +
//! [`GHOST_WEIGHT`] × ghost shortfall wins (the rule [`crate::loops::score`] ranks loops
//! by; ties: the real-frame path); the join says why with every candidate's figures.

use std::ops::Range;

use ignis_core::{loopq, GrayFrame};

use super::{Look, MorphRun, Plan, PlanFrame, Scenario};
use crate::animate::morph;
use crate::db::EigenfireDb;
use crate::error::Result;
use crate::footage::FootageOpener;
use crate::loops::GHOST_WEIGHT;
use crate::render::RenderOptions;
use crate::transition::Join;

/// Real frames rendered on each side of a join to measure it: the ghost's radius, so the
/// join's frames are judged against the neighbourhood the written output's ghost uses.
pub const SIDE: usize = loopq::GHOST_RADIUS;

/// A candidate join as measured on its rendered frames.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct JoinMeasure {
    /// Largest step of the join over the median step of the real frames around it.
    pub worst_step: f64,
    /// Softest frame of the join (its end frames included) over its neighbours' median.
    pub ghost: f64,
    /// Frames the join inserts (a morph: the in-betweens the render will write).
    pub frames: usize,
}

impl JoinMeasure {
    /// Worst step + [`GHOST_WEIGHT`] × the ghost's shortfall below 1.
    pub fn score(&self) -> f64 {
        self.worst_step + GHOST_WEIGHT * (1.0 - self.ghost).max(0.0)
    }
}

impl Scenario {
    /// `plan` (from [`Scenario::plan`]) with every `auto` join decided by measurement (see
    /// the module doc); a plan without undecided joins comes back as it is. Renders only
    /// the frames around those joins. Deterministic: the same inputs give the same plan.
    pub fn measure_joins(
        &self,
        db: &EigenfireDb,
        plan: Plan,
        look: &Look,
        opts: &RenderOptions,
        sources: &mut dyn FootageOpener,
    ) -> Result<Plan> {
        if plan.joins.iter().all(|j| j.alternatives.is_empty()) {
            return Ok(plan);
        }
        let (motions, space) = self.resolved(db)?;
        let mut joins = plan.joins;
        for i in 0..joins.len() {
            if joins[i].alternatives.is_empty() {
                continue;
            }
            let mut options = vec![joins[i].join.clone()];
            options.append(&mut joins[i].alternatives);
            let mut measured = Vec::with_capacity(options.len());
            for o in &options {
                let mut trial = joins.clone();
                trial[i].join = o.clone();
                let (cand, spans) = self.assemble(db, &space, &motions, trial)?;
                measured.push(measure_join(db, &cand, &spans, i, look, opts, sources)?);
            }
            joins[i].join = decide(options, &measured);
        }
        Ok(self.assemble(db, &space, &motions, joins)?.0)
    }
}

/// Join `i` of `cand` (its frames `spans[i]`) rendered with the real frames around it
/// and measured; `None` when fewer than two real steps around it can be rendered.
fn measure_join(
    db: &EigenfireDb,
    cand: &Plan,
    spans: &[Range<usize>],
    i: usize,
    look: &Look,
    opts: &RenderOptions,
    sources: &mut dyn FootageOpener,
) -> Result<Option<JoinMeasure>> {
    let n = cand.frames.len();
    let span = spans[i].clone();
    let other = |k: usize| {
        spans
            .iter()
            .enumerate()
            .any(|(j, s)| j != i && s.contains(&k))
    };
    let mut before: Vec<usize> = (1..=SIDE)
        .map_while(|o| span.start.checked_sub(o).filter(|&k| !other(k)))
        .collect();
    before.reverse();
    let mut after = Vec::new();
    for o in 0..SIDE {
        let mut k = span.end + o;
        if k >= n {
            if !cand.loops {
                break;
            }
            k -= n;
        }
        if span.contains(&k) || other(k) || before.contains(&k) {
            break;
        }
        after.push(k);
    }
    if before.is_empty() || after.is_empty() || before.len() + after.len() < 4 {
        return Ok(None);
    }
    let at = |k: &usize| cand.frames[*k].clone();
    let mut frames: Vec<PlanFrame> = before.iter().map(at).collect();
    frames.extend_from_slice(&cand.frames[span.clone()]);
    frames.extend(after.iter().map(at));
    let morphs: Vec<MorphRun> = cand
        .morphs
        .iter()
        .filter(|r| r.start == span.start && r.len == span.len() && r.len > 0)
        .map(|r| MorphRun {
            start: before.len(),
            ..r.clone()
        })
        .collect();
    let sub = Plan {
        frames,
        morphs,
        joins: Vec::new(),
        ..cand.clone()
    };
    let (metric, runs) = morph::render_metric(db, cand, &sub, look, opts, sources)?;
    let len = runs.first().map_or(span.len(), |r| r.len);
    Ok(
        join_quality(&metric, before.len(), len).map(|(worst_step, ghost)| JoinMeasure {
            worst_step,
            ghost,
            frames: len,
        }),
    )
}

/// Worst step and ghost of the join in `metric`: `before` real frames, `len` join frames,
/// then real frames (see the module doc); `None` without a measurable median step.
pub fn join_quality(metric: &[GrayFrame], before: usize, len: usize) -> Option<(f64, f64)> {
    let (a, b) = (before.checked_sub(1)?, before + len);
    if b >= metric.len() {
        return None;
    }
    let steps = loopq::steps(metric, false).ok()?;
    let mut real: Vec<f64> = steps[..a].to_vec();
    real.extend_from_slice(&steps[b..]);
    let median = loopq::median(&mut real);
    if real.len() < 2 || median <= 0.0 {
        return None;
    }
    let worst = steps[a..b].iter().copied().fold(0.0, f64::max) / median;
    let sharp: Vec<f64> = metric.iter().map(loopq::sharpness).collect();
    let r = loopq::GHOST_RADIUS;
    let ghost = (a..=b)
        .map(|t| {
            let w = &sharp[t.saturating_sub(r)..(t + r + 1).min(sharp.len())];
            sharp[t] / loopq::median(&mut w.to_vec()).max(1e-9)
        })
        .fold(f64::INFINITY, f64::min);
    Some((worst, ghost))
}

/// The winner among `options` (the planner's choice first) by [`JoinMeasure::score`]
/// (ties: a real-frame path, then the earlier), its `why` saying so; the planner's choice
/// when any candidate could not be measured.
fn decide(mut options: Vec<Join>, measured: &[Option<JoinMeasure>]) -> Join {
    let all: Option<Vec<JoinMeasure>> = measured.iter().copied().collect();
    let Some(m) = all else {
        let mut j = options.swap_remove(0);
        j.why = format!(
            "{} (not measured on rendered frames: too few real frames around the join)",
            j.why
        );
        return j;
    };
    let is_morph = |k: usize| options[k].method == "morph";
    let best = (0..options.len())
        .min_by(|&a, &b| {
            m[a].score()
                .total_cmp(&m[b].score())
                .then(is_morph(a).cmp(&is_morph(b)))
                .then(a.cmp(&b))
        })
        .unwrap_or(0);
    let label = |k: usize| {
        format!(
            "{} ({} frame{})",
            options[k].method,
            m[k].frames,
            if m[k].frames == 1 { "" } else { "s" }
        )
    };
    let list: Vec<String> = (0..options.len())
        .map(|k| {
            format!(
                "{} worst step {:.2}, ghost {:.2}",
                label(k),
                m[k].worst_step,
                m[k].ghost
            )
        })
        .collect();
    let why = format!(
        "auto, measured on the rendered frames: {}; {} scores lowest ({:.2} = worst step + {GHOST_WEIGHT} × ghost shortfall). {}",
        list.join("; "),
        label(best),
        m[best].score(),
        options[best].why
    );
    let mut j = options.swap_remove(best);
    j.why = why;
    j
}

#[cfg(test)]
mod tests {
    use super::*;
    use ignis_core::Size;

    /// A bar moving one pixel per frame; from frame `lift` on, the background is lifted
    /// (a jump); `blur` frames smeared (soft).
    fn bars(n: usize, lift: Option<usize>, blur: &[usize]) -> Vec<GrayFrame> {
        let size = Size::new(48, 8).unwrap();
        (0..n)
            .map(|i| {
                let x = 4 + i;
                let bg = if lift.is_some_and(|l| i >= l) {
                    0.5
                } else {
                    0.0
                };
                let mut f = GrayFrame::from_vec(size, vec![bg; 48 * 8]).unwrap();
                for y in 0..8 {
                    if blur.contains(&i) {
                        for d in 0..3 {
                            f.data_mut()[y * 48 + x - 1 + d] = 1.0 / 3.0;
                        }
                    } else {
                        f.data_mut()[y * 48 + x] = 1.0;
                    }
                }
                f
            })
            .collect()
    }

    #[test]
    fn join_quality_sees_jumps_and_soft_frames() {
        // Smooth: every step alike, nothing soft.
        let (w, g) = join_quality(&bars(20, None, &[]), 8, 2).unwrap();
        assert!((w - 1.0).abs() < 1e-9 && (g - 1.0).abs() < 1e-9, "{w} {g}");
        // A brightness jump inside the join: the worst step is the jump's.
        let (w, _) = join_quality(&bars(20, Some(9), &[]), 8, 2).unwrap();
        assert!(w > 2.0, "{w}");
        // A smeared join frame is the ghost.
        let (_, g) = join_quality(&bars(20, None, &[9]), 8, 2).unwrap();
        assert!(g < 0.5, "{g}");
        // Nothing to measure against.
        assert!(join_quality(&bars(4, None, &[]), 1, 2).is_none());
    }

    #[test]
    fn decide_takes_the_lowest_score_and_says_why() {
        let j = |method: &'static str| Join {
            frames: Vec::new(),
            trim_t1: 0,
            trim_t2: 0,
            method,
            seam_ratio: 1.0,
            why: format!("{method} path"),
        };
        let m = |worst_step, ghost| {
            Some(JoinMeasure {
                worst_step,
                ghost,
                frames: 3,
            })
        };
        let opts = vec![j("morph"), j("end-growing"), j("direct-bridging")];
        let got = decide(opts.clone(), &[m(1.2, 0.9), m(3.0, 1.0), m(1.1, 1.0)]);
        assert_eq!(got.method, "direct-bridging");
        assert!(
            got.why
                .contains("morph (3 frames) worst step 1.20, ghost 0.90"),
            "{}",
            got.why
        );
        assert!(got.why.ends_with("direct-bridging path"), "{}", got.why);
        // A tie goes to the real-frame path.
        let got = decide(opts.clone(), &[m(1.0, 1.0), m(1.0, 1.0), m(2.0, 1.0)]);
        assert_eq!(got.method, "end-growing");
        // Unmeasured: the planner's choice stays.
        let got = decide(opts, &[m(1.0, 1.0), None, m(2.0, 1.0)]);
        assert_eq!(got.method, "morph");
        assert!(got.why.contains("not measured"), "{}", got.why);
    }
}
