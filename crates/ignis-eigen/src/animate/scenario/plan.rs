//! Planning a scenario against its database: names resolved (clips, ranges, Eigenfire
//! indices), every join computed, the frame list assembled and measured. The settings
//! were checked when the file was read; what can fail here is what only the database
//! knows, reported at the key in the file it comes from.

use std::collections::BTreeMap;
use std::ops::Range;

use ignis_core::progress::Progress;

use super::{
    morph_join, JoinSpec, MorphRun, MotionSpec, Plan, PlanFrame, PlannedJoin, Scenario,
    AUTO_MORPH_ABOVE, MORPH_STEP,
};
use crate::animate;
use crate::db::{ClipEntry, EigenfireDb};
use crate::error::Result;
use crate::transition::{
    self, FrameRef, Join, RecognitionParams, Transition, TransitionError, WeightSpace,
};

/// A motion resolved against the database.
pub(super) struct MotionPlan {
    /// Its database rows.
    rows: Range<usize>,
    /// Its §5.2 edits `(Eigenfire index, weight)`, indices within the usable Eigenfires.
    edits: Vec<(usize, f32)>,
}

impl Scenario {
    /// Checks the scenario against `db` and computes every join: the frame list to render.
    /// Reports one progress stage, "finding transitions", of one step per join.
    pub fn plan(&self, db: &EigenfireDb, progress: &mut dyn Progress) -> Result<Plan> {
        let e_detect = self.e_detect.unwrap_or(db.manifest().e_detect);
        let (motions, space) = self.resolved(db)?;
        let n_joins = self.joins.len();
        progress.stage("finding transitions", n_joins as u64);
        let mut joins = Vec::with_capacity(n_joins);
        for i in 0..n_joins {
            joins.push(self.plan_join(&space, &motions, i, e_detect)?);
            progress.inc(1);
        }
        progress.finish_stage();
        Ok(self.assemble(db, &space, &motions, joins)?.0)
    }

    /// The plan of `joins` (the frame list, measured in weight space) and where each join's
    /// frames sit in it.
    pub(super) fn assemble(
        &self,
        db: &EigenfireDb,
        space: &WeightSpace,
        motions: &BTreeMap<&str, MotionPlan>,
        joins: Vec<PlannedJoin>,
    ) -> Result<(Plan, Vec<Range<usize>>)> {
        let usable = db.usable_components().max(1);
        let e_detect = self.e_detect.unwrap_or(db.manifest().e_detect);
        let e_render_req = self.e_render.unwrap_or(db.manifest().e_render);
        let (frames, morphs, spans) = self.frame_list(motions, &joins)?;
        let e = RecognitionParams {
            e_detect,
            ..Default::default()
        }
        .e_detect(space);
        let (wrap_seam, worst_step) = smoothness(space, &frames, e);
        let plan = Plan {
            frames,
            morphs,
            joins,
            wrap_seam,
            worst_step,
            e_render: e_render_req.clamp(1, usable),
            e_render_requested: e_render_req,
            e_detect: e,
            loops: self.loops,
        };
        Ok((plan, spans))
    }

    /// Every motion resolved against `db`, and its weight space.
    #[allow(clippy::type_complexity)]
    pub(super) fn resolved<'d>(
        &self,
        db: &'d EigenfireDb,
    ) -> Result<(BTreeMap<&str, MotionPlan>, WeightSpace<'d>)> {
        let usable = db.usable_components().max(1);
        Ok((self.resolve_motions(db, usable)?, WeightSpace::from_db(db)?))
    }

    /// Every motion's database rows and weight edits.
    fn resolve_motions(
        &self,
        db: &EigenfireDb,
        usable: usize,
    ) -> Result<BTreeMap<&str, MotionPlan>> {
        self.motions
            .iter()
            .map(|(name, m)| Ok((name.as_str(), self.resolve_motion(db, name, m, usable)?)))
            .collect()
    }

    /// Motion `name`: its clip, its range of source frames as database rows, and its edits
    /// checked against the `usable` Eigenfires.
    fn resolve_motion(
        &self,
        db: &EigenfireDb,
        name: &str,
        m: &MotionSpec,
        usable: usize,
    ) -> Result<MotionPlan> {
        let clip = self.clip(db, name, m)?;
        let start = m.start.as_ref().map_or(clip.start, |s| s.value);
        let end = m.end.as_ref().map_or(clip.end, |s| s.value);
        let last = clip.start + clip.frames.saturating_sub(1) * clip.stride;
        if let Some(e) = &m.end {
            if end > clip.end {
                return Err(self.err(
                    e.loc,
                    format!(
                        "motion `{name}`: end = {end} is past the end of clip `{}` (trained on frames {}..{})",
                        clip.name, clip.start, clip.end
                    ),
                ));
            }
        }
        if start >= end {
            let loc = m
                .start
                .as_ref()
                .map(|s| s.loc)
                .or(m.end.as_ref().map(|s| s.loc))
                .unwrap_or(m.clip.loc);
            return Err(self.err(
                loc,
                format!("motion `{name}`: the range {start}..{end} is empty"),
            ));
        }
        let rows = animate::clip_rows(db, &clip.name, start..end).map_err(|e| {
            self.err(
                m.start.as_ref().map_or(m.clip.loc, |s| s.loc),
                format!(
                    "motion `{name}`: {e} (clip `{}` has training frames {}..={last} every {})",
                    clip.name, clip.start, clip.stride
                ),
            )
        })?;
        let edits = match &m.edits {
            Some(w) => {
                if let Some((i, _)) = w.value.iter().find(|(i, _)| *i >= usable) {
                    return Err(self.err(
                        w.loc,
                        format!(
                            "motion `{name}`: Eigenfire index {i} is out of range: the database has {usable} usable Eigenfires (0..{usable})"
                        ),
                    ));
                }
                w.value.clone()
            }
            None => Vec::new(),
        };
        Ok(MotionPlan { rows, edits })
    }

    /// The clip motion `name` is cut from.
    fn clip<'d>(&self, db: &'d EigenfireDb, name: &str, m: &MotionSpec) -> Result<&'d ClipEntry> {
        db.clips()
            .iter()
            .find(|c| c.name == m.clip.value)
            .ok_or_else(|| {
                let names: Vec<&str> = db.clips().iter().map(|c| c.name.as_str()).collect();
                self.err(
                    m.clip.loc,
                    format!(
                        "motion `{name}`: unknown clip `{}`; database {} has {}",
                        m.clip.value,
                        db.path().display(),
                        names.join(", ")
                    ),
                )
            })
    }

    /// Join `i`, from the `i`-th motion of the sequence to the next (wrapping).
    fn plan_join(
        &self,
        space: &WeightSpace,
        motions: &BTreeMap<&str, MotionPlan>,
        i: usize,
        e_detect: usize,
    ) -> Result<PlannedJoin> {
        let seq = &self.sequence.value;
        let (a, b) = (&seq[i].value, &seq[(i + 1) % seq.len()].value);
        let spec = &self.joins[i];
        let rec = RecognitionParams {
            e_detect,
            ..spec.rec.clone()
        };
        let (ra, rb) = (
            motions[a.as_str()].rows.clone(),
            motions[b.as_str()].rows.clone(),
        );
        let e = rec.e_detect(space);
        let (join, alternatives) = choose_join(space, &ra, &rb, spec, &rec, e).map_err(|e| {
            let why = match &e {
                TransitionError::NoPath { .. } => {
                    format!("{e}; try a larger `steps`, another method, or method = \"auto\"")
                }
                _ => e.to_string(),
            };
            self.err(spec.loc, format!("join {} ({a} → {b}): {why}", i + 1))
        })?;
        let plain = transition::join_seam(space, &ra, &rb, &[], (0, 0), e);
        Ok(PlannedJoin {
            from: a.clone(),
            to: b.clone(),
            join,
            plain_cut: plain,
            alternatives,
        })
    }

    /// The frame list: each motion's body (less the frames its joins replace), then the
    /// join to the next motion, its frames' edits ramping from one motion's to the next's;
    /// with the morph runs and each join's frames (a range of the list).
    #[allow(clippy::type_complexity)]
    fn frame_list(
        &self,
        motions: &BTreeMap<&str, MotionPlan>,
        joins: &[PlannedJoin],
    ) -> Result<(Vec<PlanFrame>, Vec<MorphRun>, Vec<Range<usize>>)> {
        let seq = &self.sequence.value;
        let mut frames = Vec::new();
        let mut morphs = Vec::new();
        let mut spans = Vec::with_capacity(joins.len());
        for (i, name) in seq.iter().enumerate() {
            let m = &motions[name.value.as_str()];
            let trim_head = if i > 0 {
                joins[i - 1].join.trim_t2
            } else if self.loops {
                joins[joins.len() - 1].join.trim_t2
            } else {
                0
            };
            let trim_tail = joins.get(i).map_or(0, |j| j.join.trim_t1);
            let start = m.rows.start + trim_head.min(m.rows.len());
            let end = m.rows.end.saturating_sub(trim_tail).max(start);
            let full: Vec<(usize, f32, f32)> = m.edits.iter().map(|&(k, v)| (k, v, 1.0)).collect();
            for r in start..end {
                frames.push(PlanFrame {
                    source: FrameRef::Db(r),
                    edits: full.clone(),
                });
            }
            if let Some(j) = joins.get(i) {
                let next = &motions[seq[(i + 1) % seq.len()].value.as_str()];
                let n = j.join.frames.len();
                spans.push(frames.len()..frames.len() + n);
                if j.join.method == "morph" && n > 0 {
                    morphs.push(MorphRun {
                        start: frames.len(),
                        len: n,
                        fixed: self.joins[i]
                            .morph
                            .as_ref()
                            .is_some_and(|m| m.frames.is_some()),
                        times: None,
                    });
                }
                for (t, f) in j.join.frames.iter().enumerate() {
                    let s = (t + 1) as f32 / (n + 1) as f32;
                    let mut edits: Vec<(usize, f32, f32)> =
                        m.edits.iter().map(|&(k, v)| (k, v, 1.0 - s)).collect();
                    edits.extend(next.edits.iter().map(|&(k, v)| (k, v, s)));
                    frames.push(PlanFrame {
                        source: f.clone(),
                        edits,
                    });
                }
            }
        }
        if frames.is_empty() {
            return Err(self.err(
                self.sequence.loc,
                "the transitions replaced every frame of the motions; use longer ranges",
            ));
        }
        if morphs.iter().any(|m| m.len >= frames.len()) {
            return Err(self.err(
                self.sequence.loc,
                "a morph join has no real frame to start or end from; use longer ranges",
            ));
        }
        Ok((frames, morphs, spans))
    }
}

/// The join from the end of `ra` to the start of `rb` by `spec`'s method, and for `auto`
/// the other candidates [`Scenario::measure_joins`] measures. `auto` plans a real-frame
/// path when its weight-space seam ratio is within [`AUTO_MORPH_ABOVE`] (or the morph is
/// no better), else the morph, saying why; `method = "morph"` always morphs.
fn choose_join(
    space: &WeightSpace,
    ra: &Range<usize>,
    rb: &Range<usize>,
    spec: &JoinSpec,
    rec: &RecognitionParams,
    e: usize,
) -> Result<(Join, Vec<Join>), TransitionError> {
    let morph = |reason: &str| {
        morph_join(
            space,
            ra,
            rb,
            spec.morph.as_ref().and_then(|m| m.frames),
            e,
            reason,
        )
    };
    let run = |t: &Transition| transition::transition(space, ra.clone(), rb.clone(), t, rec);
    match &spec.morph {
        Some(m) if m.forced => return Ok((morph("method = \"morph\""), Vec::new())),
        None => return Ok((run(&spec.transition)?, Vec::new())),
        Some(_) => {}
    }
    let chosen = match run(&spec.transition) {
        Ok(j) if j.seam_ratio > AUTO_MORPH_ABOVE => {
            let mj = morph("");
            // An automatic morph's count is chosen again on the rendered frames, so that
            // every step is within MORPH_STEP × the footage's median step there (up to
            // `morph::max_frames`); the weight-space estimate overstates how far apart two
            // clips look (weights of different clips are far apart in E dimensions).
            let automatic = spec.morph.as_ref().is_some_and(|m| m.frames.is_none());
            let morph_seam = if automatic {
                mj.seam_ratio.min(MORPH_STEP)
            } else {
                mj.seam_ratio
            };
            if morph_seam < j.seam_ratio {
                let held = if automatic {
                    format!(" (its steps are held within {MORPH_STEP}× the footage's median step on the rendered frames)")
                } else {
                    String::new()
                };
                let why = format!(
                    "auto: {} gave seam ratio {:.2} (> {AUTO_MORPH_ABOVE}), the morph {:.2}{held}; {}",
                    j.method, j.seam_ratio, morph_seam, mj.why
                );
                Join { why, ..mj }
            } else {
                j
            }
        }
        Err(TransitionError::NoPath { .. }) => {
            let mj = morph("");
            let why = format!("auto: no real-frame path; {}", mj.why);
            Join { why, ..mj }
        }
        r => r?,
    };
    // The real-frame paths (§5.1.2) and the morph, measured on the rendered frames later.
    let mut alternatives: Vec<Join> = [
        Transition::EndGrowing { max_steps: 40 },
        Transition::DirectBridging { steps: None },
    ]
    .iter()
    .filter_map(|t| run(t).ok())
    .collect();
    alternatives.push(morph(""));
    alternatives.retain(|a| a.method != chosen.method);
    Ok((chosen, alternatives))
}

/// Seam ratios of the wrap (last frame → first) and of the largest step between
/// consecutive frames, on the first `e` weights.
fn smoothness(space: &WeightSpace, frames: &[PlanFrame], e: usize) -> (f64, f64) {
    let vec_of = |f: &PlanFrame| -> Vec<f32> {
        let v = match &f.source {
            FrameRef::Db(r) => space.frame(*r),
            FrameRef::Weights(w) => w.as_slice(),
        };
        v[..e.min(v.len())].to_vec()
    };
    let median = space.source_median(e);
    let wrap = transition::seam_ratio(
        &[vec_of(&frames[frames.len() - 1]), vec_of(&frames[0])],
        median,
    );
    let worst = frames
        .windows(2)
        .map(|p| transition::seam_ratio(&[vec_of(&p[0]), vec_of(&p[1])], median))
        .fold(0.0, f64::max);
    (wrap, worst)
}
