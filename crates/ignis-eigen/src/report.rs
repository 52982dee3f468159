//! What an animation step did and why, returned with its result so callers print it and
//! compute nothing: [`LoopReport`] for a loop of one clip ([`crate::animate::render_loop`],
//! [`crate::render::loop_plan`]), [`JoinReport`] for one join of a scenario.

use std::ops::Range;

use crate::scenario::Plan;
use crate::transition::Join;

/// A loop of one clip: the rows used, the join back to the start, its quality against a
/// plain cut, and the E actually used.
#[derive(Clone, Debug, PartialEq)]
pub struct LoopReport {
    pub clip: String,
    /// Source frames asked for.
    pub requested: Range<usize>,
    /// Source frames used: `requested`, or moved inwards by the loop-point search.
    pub used: Range<usize>,
    /// Loop-point search allowed (training frames each end; 0 = none).
    pub search: usize,
    /// Training rows of `used`.
    pub rows: Range<usize>,
    /// Range frames kept (those the transition does not replace).
    pub body_frames: usize,
    /// The transition back to the start: method, frames, seam ratio, trims, why.
    pub join: Join,
    /// Seam ratio of a plain cut from the end of `requested` back to its start.
    pub plain_cut: f64,
    /// E used for rendering synthetic frames (clamped to the usable Eigenfires).
    pub e_render: usize,
    /// E asked for.
    pub e_render_requested: usize,
}

impl LoopReport {
    /// Frames of the loop: the kept range frames plus the transition frames.
    pub fn frames(&self) -> usize {
        self.body_frames + self.join.frames.len()
    }

    /// One line: method, frame counts, E, trims, seam ratio against the plain cut.
    pub fn summary(&self) -> String {
        format!(
            "method {}: {} range frame(s) + {} transition frame(s) = {} frames, E = {}{} (the transition replaces the range's last {} and first {} frame(s)); seam ratio {:.2} (plain cut {:.2})",
            self.join.method,
            self.body_frames,
            self.join.frames.len(),
            self.frames(),
            self.e_render,
            if self.e_render != self.e_render_requested {
                format!(" (asked {}, clamped to the usable Eigenfires)", self.e_render_requested)
            } else {
                String::new()
            },
            self.join.trim_t1,
            self.join.trim_t2,
            self.join.seam_ratio,
            self.plain_cut,
        )
    }

    /// Where the loop points moved, when the search moved them.
    pub fn moved(&self) -> Option<String> {
        (self.used != self.requested).then(|| {
            format!(
                "loop points moved to {}..{} (--search {}; --search 0 keeps {}..{})",
                self.used.start,
                self.used.end,
                self.search,
                self.requested.start,
                self.requested.end
            )
        })
    }
}

/// How one join of a scenario was made: which motions it joins, the join itself (method
/// chosen, frames, seam ratio, why) and a plain cut's seam ratio at the same place.
/// [`JoinReport::of_plan`] reads them from a [`Plan`]; the scenario planner may fill them
/// directly.
#[derive(Clone, Debug, PartialEq)]
pub struct JoinReport {
    /// 1-based join number in the sequence.
    pub index: usize,
    /// Motion names, `from` → `to`.
    pub from: String,
    pub to: String,
    /// The transition: method (`auto` names the one it chose), frames, seam ratio, why.
    pub join: Join,
    /// Seam ratio of a plain cut between the same motions.
    pub plain_cut: f64,
}

impl JoinReport {
    /// The joins of `plan`, numbered from 1.
    pub fn of_plan(plan: &Plan) -> Vec<JoinReport> {
        plan.joins
            .iter()
            .enumerate()
            .map(|(i, j)| JoinReport {
                index: i + 1,
                from: j.from.clone(),
                to: j.to.clone(),
                join: j.join.clone(),
                plain_cut: j.plain_cut,
            })
            .collect()
    }

    /// Whether the join is rougher than a plain cut would be.
    pub fn worse_than_cut(&self) -> bool {
        self.join.seam_ratio > self.plain_cut + 1e-9
    }

    /// The table header matching [`JoinReport::row`].
    pub fn header() -> String {
        format!(
            "{:<4} {:<28} {:<16} {:>5} {:>10} {:>9}",
            "join", "motions", "method", "steps", "seam ratio", "plain cut"
        )
    }

    /// One table row: number, motions, method, steps, seam ratio, plain cut.
    pub fn row(&self) -> String {
        format!(
            "{:<4} {:<28} {:<16} {:>5} {:>10.2} {:>9.2}",
            self.index,
            format!("{} → {}", self.from, self.to),
            self.join.method,
            self.join.frames.len(),
            self.join.seam_ratio,
            self.plain_cut
        )
    }

    /// Why this method and these frames.
    pub fn why(&self) -> String {
        format!("join {}: {}", self.index, self.join.why)
    }

    /// A warning when [`JoinReport::worse_than_cut`].
    pub fn warning(&self) -> Option<String> {
        self.worse_than_cut().then(|| {
            format!(
                "warning: join {} ({} → {}): {} is rougher than a plain cut ({:.2} > {:.2}); try method = \"auto\" or another method for this join",
                self.index,
                self.from,
                self.to,
                self.join.method,
                self.join.seam_ratio,
                self.plain_cut
            )
        })
    }
}
