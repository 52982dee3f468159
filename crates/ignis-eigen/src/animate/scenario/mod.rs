//! Scenarios: the artist's motion list (§5.1, Figures 32–33) as a TOML file.
//!
//! Source: eigenfires-thesis.txt §5.1 (an ordered list of named motions — ranges of
//! training clips — joined by transitions, optionally "producing loop"), §5.1.2 (E for
//! detection vs. E for rendering, θ_min, adaptive per clip), §5.2 (editing weights) and
//! chapter 6 (colouring, bloom, smoke, custom masks; see [`crate::animate`] for rendering).
//!
//! ```toml
//! database = "fire.db"          # relative to this file
//! sequence = ["calm", "wind", "calm"]
//! loop = true                   # join the last motion back to the first
//! e_detect = 40                 # optional: E for detection (default: the database's)
//! e_render = 50                 # optional: E for rendering (default: the database's)
//!
//! [motions.calm]                # a range of source frames of a training clip
//! clip = "candle"
//! start = 100                   # optional, default the clip's first training frame
//! end = 220                     # optional (excluded), default the clip's end
//!
//! [motions.wind]
//! clip = "candle"
//! start = 400
//! end = 520
//! weights = "1=0.8"             # optional §5.2 edits: set Eigenfire 1's weight on every frame
//!
//! [transition]                  # defaults for every join
//! method = "auto"               # auto | end-growing | direct | low-pass | morph
//!
//! [[join]]                      # join 1: calm → wind (positional; fewer than joins is fine)
//! method = "direct"
//! steps = 3
//!
//! [[join]]                      # join 2: wind → calm
//! method = "low-pass"
//! kernel = [0.2, 0.2, 0.6]
//! ```
//! Join settings: `method`, `steps` (direct: N frames; end-growing: N, the most frames;
//! default automatic / 40), `theta_min` (fixed θ_min in weight units; default adaptive,
//! per clip), `theta_quantile`, `join_gap`, `reject_near`, and for low-pass `kernel`,
//! `eigenfires` (E of the morphs, default 50) and `inject_from` (detail injection), and
//! for `morph` `frames` (the in-betweens; default automatic, see [`MorphRun`]).
//!
//! `method = "morph"` joins the last frame of one motion to the first of the next with
//! motion-compensated in-betweens (`ignis_flow`: DIS flow both ways at a reduced size,
//! warp and blend) of the two rendered frames. `auto` keeps a real-frame path (End
//! Growing, Direct Bridging) when its weight-space seam ratio is within
//! [`AUTO_MORPH_ABOVE`], and otherwise plans the morph — provisionally: before rendering,
//! [`Scenario::measure_joins`] renders every candidate (the real-frame paths and the morph,
//! its in-betweens chosen as the render will) with the real frames around it, measures
//! each one's worst step and ghost on the metric frames (grey, 128 px, `ignis_core::loopq`)
//! and keeps the lowest worst step + [`crate::loops::GHOST_WEIGHT`] × ghost shortfall
//! (ties: the real-frame path), saying why with every candidate's figures.
//! The look (`[colour]`, `[bloom]`, `[smoke]`, `[originals]`, `[masks]`) is described in
//! [`Look`].
//!
//! Two stages. [`Scenario::parse`] reads the file once (`spec`: serde into spanned raw
//! tables) and checks every setting that needs no database with the settings types' own
//! `validate()` ([`Transition::validate`], [`RecognitionParams::validate`],
//! [`BloomParams::validate`], [`SmokeParams::validate`], ...), keeping the typed result and
//! each value's place in the file. [`Scenario::plan`] (`plan`) only resolves names against
//! the database (clips, ranges, Eigenfire indices) and computes the joins. Every error
//! names the file, line and column of the offending value ([`EigenError::Scenario`]),
//! including those only found against the database (an unknown clip, a range past the
//! clip's end, an Eigenfire index beyond E, a join for which End Growing finds no path).
//!
//! Weight edits across joins: a motion's edits apply to all its frames; the frames of a
//! join ramp linearly from the edits of the motion before to those of the motion after
//! (strength `(i + 1) / (n + 1)` for the i-th of n join frames), so editing a motion does
//! not create a jump at its joins. Recognition (and the seam ratio) ignores edits: it
//! runs on the database's own weights.

use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

use ignis_core::colour::Tint;
use ignis_core::post::BloomParams;
use ignis_core::Palette;

use crate::colour::{MaskMode, SmokeParams};
use crate::error::{EigenError, Result};
use crate::transition::{self, FrameRef, Join, RecognitionParams, Transition, WeightSpace};

mod look;
mod measure;
mod plan;
mod spec;

/// A scenario read and checked (every setting that needs no database), not yet resolved
/// against its database ([`Scenario::plan`]).
#[derive(Debug)]
pub struct Scenario {
    file: PathBuf,
    /// The database directory, resolved against the scenario's folder.
    pub database: PathBuf,
    /// The look (colour and post), with paths resolved against the scenario's folder.
    pub look: Look,
    /// Motion names in playing order (each a key of `motions`).
    sequence: At<Vec<At<String>>>,
    loops: bool,
    e_detect: Option<usize>,
    e_render: Option<usize>,
    motions: BTreeMap<String, MotionSpec>,
    /// One per join: between consecutive motions, plus the loop join.
    joins: Vec<JoinSpec>,
}

/// A place in the scenario file (1-based), for errors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Loc {
    line: usize,
    column: usize,
}

impl Loc {
    fn err(self, file: &Path, message: impl Into<String>) -> EigenError {
        EigenError::Scenario {
            file: file.to_path_buf(),
            line: self.line,
            column: self.column,
            message: message.into(),
        }
    }
}

/// A value and where in the file it was written.
#[derive(Clone, Debug)]
struct At<T> {
    value: T,
    loc: Loc,
}

/// A motion as written: checked, its names not yet resolved against the database.
#[derive(Debug)]
struct MotionSpec {
    clip: At<String>,
    /// Source frames `start..end`; the clip's training range where not given.
    start: Option<At<usize>>,
    end: Option<At<usize>>,
    /// §5.2 edits `(Eigenfire index, weight)`, indices not yet checked against E.
    edits: Option<At<Vec<(usize, f32)>>>,
}

/// A join's checked settings (`[[join]]` over `[transition]`).
#[derive(Debug)]
struct JoinSpec {
    /// The real-frame or low-pass method (`Auto` for `method = "morph"`).
    transition: Transition,
    /// Recognition settings; `e_detect` is set when planning.
    rec: RecognitionParams,
    /// The morph for `auto` and `morph`.
    morph: Option<MorphSpec>,
    /// The join's table (`[[join]]`, else `[transition]`, else `sequence`).
    loc: Loc,
}

/// How frames are coloured and post-processed (chapter 6).
///
/// ```toml
/// [colour]
/// mode = "original"     # original (Algorithm 2) | synthetic (HLS, §6.1.2) | palette | grey
/// tint = [1.0, 0.42, 0.08]   # synthetic colour, and the bloom's tint in original mode
/// palette = "candle"    # palette mode: a preset name
/// threshold = 0.013     # original colouring: grey level above which the original is copied (thesis: 30/255)
/// alpha = "matte"       # matte (§6.2: bloom + source) | opaque
/// fast_path = true      # §7.1.2: database frames from the stored pre-processed frames
///
/// [bloom]               # §6.2; `enabled = false` turns it off
/// passes = 3
/// radius = 24.0
///
/// [smoke]               # §6.3, original mode only
/// enabled = true
/// threshold = 0.03
///
/// [originals]           # colour footage per clip (default: the clip's training source)
/// candle = "../footage/candle.mp4"
///
/// [masks]               # §6.4 custom masks per clip (frame-numbered like the clip)
/// candle = "masks/candle_%04d.png"
/// mask_mode = "add"     # (in [colour]) add | replace
/// ```
#[derive(Clone, Debug)]
pub struct Look {
    pub mode: ColourMode,
    /// Tint of synthetic colouring, and of the bloom in original colouring (unless
    /// `tint_from_footage`).
    pub tint: Tint,
    /// Original colouring tints each frame's bloom with its clip's own flame colour
    /// (`ClipEntry::flame_colour`, measured at training) instead of `tint`; clips without
    /// one keep `tint`. On by default; a scenario's `[colour] tint` turns it off.
    pub tint_from_footage: bool,
    /// Original colouring's threshold (grey units).
    pub threshold: f32,
    pub bloom: Option<BloomParams>,
    pub smoke: Option<SmokeParams>,
    /// Alpha: the matte of §6.2 (true) or opaque.
    pub matte: bool,
    /// §7.1.2: take database frames from the stored pre-processed frames.
    pub fast_path: bool,
    /// Colour footage per clip name, overriding the clip's recorded source.
    pub originals: BTreeMap<String, PathBuf>,
    /// Custom masks per clip name (§6.4).
    pub masks: BTreeMap<String, PathBuf>,
    pub mask_mode: MaskMode,
}

/// Colouring of the grey frames.
#[derive(Clone, Debug)]
pub enum ColourMode {
    /// Algorithm 2: colours from the original footage.
    Original,
    /// §6.1.2: HLS transfer of [`Look::tint`].
    Synthetic,
    /// A palette ramp (Ignis's own, as for classic fire).
    Palette(Palette),
    /// The grey frame itself.
    Grey,
}

impl ColourMode {
    pub fn name(&self) -> &'static str {
        match self {
            ColourMode::Original => "original",
            ColourMode::Synthetic => "synthetic",
            ColourMode::Palette(_) => "palette",
            ColourMode::Grey => "grey",
        }
    }
}

impl Default for Look {
    /// Original colouring with the thesis's threshold, default bloom, no smoke, a matte,
    /// the fast path, no originals or masks.
    fn default() -> Self {
        Look {
            mode: ColourMode::Original,
            tint: Tint::Solid([1.0, 0.42, 0.08]),
            tint_from_footage: true,
            threshold: crate::colour::THESIS_THRESHOLD,
            bloom: Some(BloomParams::default()),
            smoke: None,
            matte: true,
            fast_path: true,
            originals: BTreeMap::new(),
            masks: BTreeMap::new(),
            mask_mode: MaskMode::Add,
        }
    }
}

impl Scenario {
    /// Reads and parses a scenario file.
    pub fn from_file(path: &Path) -> Result<Scenario> {
        ignis_core::atomic::record_input(path);
        let text = ignis_core::textfile::read_text(path).map_err(|e| {
            let why = "there is no such scenario; check the path \
                       (`ignis eigen scenario DB > scene.toml` writes one for a database)";
            EigenError::io(path, ignis_core::textfile::explain_missing(e, why))
        })?;
        Scenario::parse(&text, path)
    }

    /// Parses `text` as the scenario file `file` (used for error messages and to resolve
    /// relative paths) and checks everything that needs no database.
    pub fn parse(text: &str, file: &Path) -> Result<Scenario> {
        spec::parse(text, file)
    }

    /// The scenario file's path.
    pub fn file(&self) -> &Path {
        &self.file
    }

    /// Whether the sequence loops back to its start.
    pub fn is_loop(&self) -> bool {
        self.loops
    }

    /// Number of joins: between consecutive motions, plus the loop join.
    pub fn join_count(&self) -> usize {
        self.joins.len()
    }

    /// The scenario error at `loc`.
    fn err(&self, loc: Loc, message: impl Into<String>) -> EigenError {
        loc.err(&self.file, message)
    }
}

/// Seam ratio above which `auto` replaces a real-frame (or low-pass) join by the morph
/// when the morph's own seam ratio is lower.
pub const AUTO_MORPH_ABOVE: f64 = 1.5;
/// The largest step an automatic morph aims for, in footage median steps.
pub const MORPH_STEP: f64 = 1.2;
/// Most in-between frames of one morph join.
pub const MORPH_MAX_FRAMES: usize = 120;

/// A join's morph settings: `frames` given or automatic; `forced` for `method = "morph"`
/// (else `auto` may use it).
#[derive(Clone, Debug)]
struct MorphSpec {
    frames: Option<usize>,
    forced: bool,
}

/// The morph join from the last row of `ra` to the first of `rb`: `frames` in-betweens,
/// or automatically as many as keep each step of the weight-space straight line within
/// [`MORPH_STEP`] × the footage's median step. The plan's frames for it carry the
/// linearly interpolated weights (what the planner measures and what a renderer that does
/// not know morphs shows); [`crate::render::render_plan_with`] renders them as the
/// motion-compensated morph of the two rendered endpoint frames ([`Plan::morphs`]), and —
/// unless `frames` was given — chooses the count again there from the rendered frames
/// ([`crate::animate::morph`]), so the written join may have another count than this
/// estimate.
fn morph_join(
    space: &WeightSpace,
    ra: &Range<usize>,
    rb: &Range<usize>,
    frames: Option<usize>,
    e: usize,
    reason: &str,
) -> Join {
    let (a, b) = (ra.end - 1, rb.start);
    let (wa, wb) = (space.frame(a), space.frame(b));
    let median = space.source_median(e);
    let d = space.distance(a, b, e);
    let n = frames.unwrap_or_else(|| {
        if median > 0.0 && d.is_finite() {
            ((d / (MORPH_STEP * median)).ceil() as usize)
                .saturating_sub(1)
                .clamp(1, MORPH_MAX_FRAMES)
        } else {
            1
        }
    });
    let refs: Vec<FrameRef> = (0..n)
        .map(|k| {
            let t = (k + 1) as f32 / (n + 1) as f32;
            FrameRef::Weights(wa.iter().zip(wb).map(|(x, y)| x + (y - x) * t).collect())
        })
        .collect();
    let seam = transition::join_seam(space, ra, rb, &refs, (0, 0), e);
    let how = if frames.is_some() {
        format!("{n} frames as asked")
    } else {
        format!(
            "{n} frames: distance {:.2} median steps, each step ≤ {MORPH_STEP}",
            if median > 0.0 { d / median } else { 0.0 }
        )
    };
    Join {
        frames: refs,
        trim_t1: 0,
        trim_t2: 0,
        method: "morph",
        seam_ratio: seam,
        why: format!(
            "{}motion-compensated morph from source row {a} to row {b}, {how}; weight-space seam ratio {seam:.2}",
            if reason.is_empty() {
                String::new()
            } else {
                format!("{reason}: ")
            }
        ),
    }
}

/// A run of morph frames in [`Plan::frames`]: frames `start..start + len` are the
/// motion-compensated in-betweens (t = (k + 1) / (len + 1)) of the rendered frame before
/// the run (`start − 1`, or the plan's last frame when `start` is 0) and the one after it
/// (`start + len`, wrapping to frame 0).
#[derive(Clone, Debug, PartialEq)]
pub struct MorphRun {
    pub start: usize,
    pub len: usize,
    /// The scenario fixed the count (`frames = N`); else `len` is the planner's estimate
    /// and the renderer chooses the count from the rendered frames
    /// ([`crate::animate::morph`]).
    pub fixed: bool,
    /// The in-betweens' times, already chosen from the rendered frames (`len` of them): a
    /// plan made by [`crate::animate::morph::resolve`], whose frame count is the one the
    /// render writes (what `--chunk` needs). `None`: chosen while rendering.
    pub times: Option<Vec<f32>>,
}

impl MorphRun {
    /// Indices of the run's endpoint frames in a plan of `n` frames.
    pub fn endpoints(&self, n: usize) -> (usize, usize) {
        let from = if self.start == 0 {
            n - 1
        } else {
            self.start - 1
        };
        (from, (self.start + self.len) % n)
    }
}

/// One join of a plan as the planner chose it (the printable report is
/// [`crate::report::JoinReport`], made from these).
#[derive(Clone, Debug)]
pub struct PlannedJoin {
    /// Motion names.
    pub from: String,
    pub to: String,
    pub join: Join,
    /// Seam ratio of a plain cut at the same place.
    pub plain_cut: f64,
    /// For `auto`: the other joins it could take (End Growing, Direct Bridging, the
    /// morph), until [`Scenario::measure_joins`] renders each, measures its worst step and
    /// ghost on the metric frames and keeps the best. Empty once decided (or when there is
    /// no choice).
    pub alternatives: Vec<Join>,
}

/// One output frame of a plan.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanFrame {
    /// A database frame or synthetic weights (low-pass morphs).
    pub source: FrameRef,
    /// Weight edits `(index, value, strength)`: w ← w + strength·(value − w).
    pub edits: Vec<(usize, f32, f32)>,
}

/// The frames to render, and how smooth they are.
#[derive(Clone, Debug)]
pub struct Plan {
    pub frames: Vec<PlanFrame>,
    /// The runs of `frames` that are motion-compensated morphs (method `morph`).
    pub morphs: Vec<MorphRun>,
    pub joins: Vec<PlannedJoin>,
    /// Seam ratio of the wrap from the last frame to the first (what a looping GIF or
    /// flipbook shows); with `loop = true` this is a footage step.
    pub wrap_seam: f64,
    /// Largest step between consecutive output frames, as a seam ratio.
    pub worst_step: f64,
    /// E for rendering (clamped to the usable Eigenfires) and as asked.
    pub e_render: usize,
    pub e_render_requested: usize,
    /// E for detection actually used.
    pub e_detect: usize,
    pub loops: bool,
}

#[cfg(test)]
mod tests {
    use super::spec::line_col;
    use super::*;

    #[test]
    fn line_col_counts() {
        let t = "a = 1\nbb = 2\n";
        assert_eq!(line_col(t, 0), (1, 1));
        assert_eq!(line_col(t, 6), (2, 1));
        assert_eq!(line_col(t, 9), (2, 4));
    }

    fn err(text: &str) -> String {
        Scenario::parse(text, Path::new("dir/scene.toml"))
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn static_errors_name_file_and_line() {
        let base = "database = \"fire.db\"\n";
        // An empty sequence.
        let e = err(&format!("{base}sequence = []\n"));
        assert!(e.starts_with("dir/scene.toml:2:"), "{e}");
        assert!(e.contains("empty"), "{e}");
        // An unknown motion in the sequence.
        let e = err(&format!(
            "{base}sequence = [\"calm\", \"storm\"]\n[motions.calm]\nclip = \"candle\"\n"
        ));
        assert!(e.starts_with("dir/scene.toml:2:"), "{e}");
        assert!(
            e.contains("unknown motion `storm`") && e.contains("calm"),
            "{e}"
        );
        // A non-numeric weight.
        let e = err(&format!(
            "{base}sequence = [\"calm\"]\n\n[motions.calm]\nclip = \"candle\"\nweights = \"2=abc\"\n"
        ));
        assert!(e.starts_with("dir/scene.toml:6:"), "{e}");
        assert!(e.contains("not a number"), "{e}");
        // A syntax error and an unknown key keep the toml parser's position.
        let e = err(&format!("{base}sequence = [\"calm\"\n"));
        assert!(e.starts_with("dir/scene.toml:"), "{e}");
        let e = err(&format!("{base}sequence = [\"a\"]\ncolor = 1\n"));
        assert!(e.starts_with("dir/scene.toml:3:"), "{e}");
        // A bad method in [[join]] and too many joins.
        let m = "[motions.a]\nclip = \"candle\"\n";
        let e = err(&format!(
            "{base}sequence = [\"a\", \"a\"]\n{m}[[join]]\nmethod = \"teleport\"\n"
        ));
        assert!(e.starts_with("dir/scene.toml:6:"), "{e}");
        assert!(e.contains("teleport"), "{e}");
        let e = err(&format!(
            "{base}sequence = [\"a\"]\n{m}[[join]]\nmethod = \"direct\"\n"
        ));
        assert!(e.contains("1 [[join]] tables for 0 join(s)"), "{e}");
        // An out-of-range bloom setting names its table's line.
        let e = err(&format!(
            "{base}sequence = [\"a\"]\n{m}[bloom]\nstrength = 9.0\n"
        ));
        assert!(
            e.starts_with("dir/scene.toml:5:") || e.starts_with("dir/scene.toml:6:"),
            "{e}"
        );
        assert!(e.contains("[bloom]") && e.contains("strength"), "{e}");
        // A kernel that cannot be normalised.
        let e = err(&format!(
            "{base}sequence = [\"a\", \"a\"]\n{m}[transition]\nmethod = \"low-pass\"\nkernel = [1.0, -1.0]\n"
        ));
        assert!(e.starts_with("dir/scene.toml:7:"), "{e}");
        // Morph joins: `frames` within range, named by line.
        let e = err(&format!(
            "{base}sequence = [\"a\", \"a\"]\n{m}[transition]\nmethod = \"morph\"\nframes = 0\n"
        ));
        assert!(e.starts_with("dir/scene.toml:7:"), "{e}");
        assert!(e.contains("`frames`"), "{e}");
        Scenario::parse(
            &format!("{base}sequence = [\"a\", \"a\"]\n{m}[transition]\nmethod = \"morph\"\nframes = 4\n"),
            Path::new("dir/scene.toml"),
        )
        .unwrap();
    }

    /// The bloom takes each clip's own flame colour unless `[colour] tint` is set.
    #[test]
    fn a_set_tint_replaces_the_footages_flame_colour() {
        let base = "database = \"fire.db\"\nsequence = [\"a\"]\n[motions.a]\nclip = \"c\"\n";
        let parse = |t: &str| Scenario::parse(t, Path::new("dir/scene.toml")).unwrap();
        let plain = parse(base);
        assert!(plain.look.tint_from_footage);
        let set = parse(&format!("{base}[colour]\ntint = [0.2, 0.4, 1.0]\n"));
        assert!(!set.look.tint_from_footage);
        assert_eq!(set.look.tint, Tint::Solid([0.2, 0.4, 1.0]));
    }

    /// A bad value in each section: the error names the key (`key` in backticks, or
    /// `what`) and starts at the line holding `line_of`.
    /// Long on purpose: one table of 29 cases, one per section and key.
    #[test]
    fn a_bad_field_in_each_section_names_the_field_and_its_line() {
        let head = "database = \"fire.db\"\nsequence = [\"a\", \"a\"]\n";
        let motion = "[motions.a]\nclip = \"candle\"\n";
        // (text after the motion table, text of the bad line, what the message says)
        let cases: &[(&str, &str, &str)] = &[
            (
                "[transition]\nmethod = \"low-pass\"\nkernel = [1.0, -1.0]\n",
                "kernel",
                "`kernel`",
            ),
            (
                "[transition]\nmethod = \"low-pass\"\neigenfires = 0\n",
                "eigenfires",
                "`eigenfires` must be at least 1",
            ),
            (
                "[transition]\nmethod = \"low-pass\"\neigenfires = 20\ninject_from = 10\n",
                "inject_from",
                "`inject_from` must be ≥ eigenfires = 20, got 10",
            ),
            (
                "[transition]\ntheta_min = -1.0\n",
                "theta_min",
                "`theta_min`",
            ),
            (
                "[[join]]\ntheta_quantile = 2.0\n",
                "theta_quantile",
                "`theta_quantile`",
            ),
            ("[[join]]\njoin_gap = 0.0\n", "join_gap", "`join_gap`"),
            (
                "[[join]]\nmethod = \"direct\"\nsteps = 0\n",
                "steps",
                "`steps` must be at least 1",
            ),
            (
                "[[join]]\nmethod = \"end-growing\"\nsteps = 1\n",
                "steps",
                "`steps` must be at least 2",
            ),
            (
                "[[join]]\nmethod = \"morph\"\nframes = 500\n",
                "frames",
                "`frames`",
            ),
            (
                "[[join]]\nmethod = \"teleport\"\n",
                "teleport",
                "unknown method `teleport`",
            ),
            (
                "[colour]\nmode = \"sepia\"\n",
                "sepia",
                "unknown colour mode `sepia`",
            ),
            ("[colour]\ntint = [2.0, 0.0, 0.0]\n", "tint", "`tint`"),
            ("[colour]\nthreshold = 1.5\n", "threshold", "`threshold`"),
            (
                "[colour]\nalpha = \"glass\"\n",
                "glass",
                "unknown alpha `glass`",
            ),
            (
                "[colour]\nmask_mode = \"xor\"\n",
                "xor",
                "unknown mask_mode `xor`",
            ),
            (
                "[colour]\nmode = \"palette\"\npalette = \"plaid\"\n",
                "plaid",
                "unknown palette `plaid`",
            ),
            ("[bloom]\npasses = 99\n", "passes", "[bloom]: `passes`"),
            ("[bloom]\nradius = -1.0\n", "radius", "[bloom]: `radius`"),
            (
                "[bloom]\nradius_falloff = 2.0\n",
                "radius_falloff",
                "[bloom]: `radius_falloff`",
            ),
            (
                "[bloom]\nstrength = 9.0\n",
                "strength",
                "[bloom]: `strength`",
            ),
            ("[bloom]\nglow = 1.0\n", "glow", "glow"),
            (
                "[smoke]\nthreshold = 2.0\n",
                "threshold",
                "[smoke]: `threshold`",
            ),
            ("[smoke]\nblur = 100.0\n", "blur", "[smoke]: `blur`"),
            (
                "[smoke]\ncolour = [9.0, 0.0, 0.0]\n",
                "colour",
                "[smoke]: `colour`",
            ),
            (
                "[motions.b]\nclip = \"candle\"\nweights = \"1=x\"\n",
                "weights",
                "motion `b`",
            ),
            ("[motions.c]\nclip = \"candle\"\nstart = -3\n", "start", ""),
        ];
        let top: &[(&str, &str, &str)] = &[
            (
                "e_detect = 0\n",
                "e_detect",
                "`e_detect` must be at least 1",
            ),
            (
                "e_render = 0\n",
                "e_render",
                "`e_render` must be at least 1",
            ),
            ("loop = \"yes\"\n", "loop", ""),
        ];
        let texts = cases
            .iter()
            .map(|(t, l, w)| (format!("{head}{motion}{t}"), *l, *w))
            .chain(
                top.iter()
                    .map(|(t, l, w)| (format!("{head}{t}{motion}"), *l, *w)),
            );
        for (text, line_of, what) in texts {
            let line = 1 + text
                .lines()
                .position(|l| l.contains(line_of))
                .unwrap_or_else(|| panic!("{line_of} not in {text}"));
            let e = err(&text);
            let want = format!("dir/scene.toml:{line}:");
            assert!(
                e.starts_with(&want),
                "`{e}` should start with `{want}`:\n{text}"
            );
            assert!(e.contains(what), "`{e}` should say `{what}`");
        }
    }

    /// `[[join]]` settings override `[transition]` ones; only the joins there are are
    /// checked, each in the table it comes from.
    #[test]
    fn join_settings_merge_over_the_defaults() {
        let head = "database = \"fire.db\"\nsequence = [\"a\", \"a\"]\nloop = true\n[motions.a]\nclip = \"candle\"\n";
        let s = Scenario::parse(
            &format!("{head}[transition]\nmethod = \"low-pass\"\nkernel = [0.5, 0.5]\n[[join]]\nmethod = \"direct\"\nsteps = 3\n"),
            Path::new("dir/scene.toml"),
        )
        .unwrap();
        assert_eq!(s.join_count(), 2);
        assert_eq!(
            s.joins[0].transition,
            Transition::DirectBridging { steps: Some(3) }
        );
        let Transition::LowPass(p) = &s.joins[1].transition else {
            panic!("{:?}", s.joins[1].transition)
        };
        assert_eq!(p.kernel, vec![0.5, 0.5]);
        assert_eq!(s.joins[0].loc.line, 9);
        assert_eq!(s.joins[1].loc.line, 6);
        // A default that only the second join takes is reported where it is written.
        let e = err(&format!(
            "{head}[transition]\ntheta_min = 0.0\n[[join]]\ntheta_min = 0.5\n"
        ));
        assert!(
            e.starts_with("dir/scene.toml:7:") && e.contains("`theta_min`"),
            "{e}"
        );
        // Morph and auto joins carry their morph settings.
        let s = Scenario::parse(
            &format!("{head}[transition]\nframes = 5\n[[join]]\nmethod = \"morph\"\n"),
            Path::new("dir/scene.toml"),
        )
        .unwrap();
        let m: Vec<_> = s
            .joins
            .iter()
            .map(|j| j.morph.clone().map(|m| (m.frames, m.forced)))
            .collect();
        assert_eq!(m, vec![Some((Some(5), true)), Some((Some(5), false))]);
    }

    #[test]
    fn paths_resolve_against_the_file() {
        let s = Scenario::parse(
            "database = \"fire.db\"\nsequence = [\"a\"]\n[motions.a]\nclip = \"c\"\n[originals]\nc = \"/abs/c.mp4\"\n[masks]\nc = \"m/%04d.png\"\n",
            Path::new("scenes/x.toml"),
        )
        .unwrap();
        assert_eq!(s.database, Path::new("scenes/fire.db"));
        assert_eq!(s.look.originals["c"], Path::new("/abs/c.mp4"));
        assert_eq!(s.look.masks["c"], Path::new("scenes/m/%04d.png"));
        assert_eq!(s.join_count(), 0);
        assert!(matches!(s.look.mode, ColourMode::Original));
    }
}
