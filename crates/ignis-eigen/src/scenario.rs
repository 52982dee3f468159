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
//! Growing, Direct Bridging) when its seam ratio is within [`AUTO_MORPH_ABOVE`], and
//! otherwise uses the morph, saying why.
//! The look (`[colour]`, `[bloom]`, `[smoke]`, `[originals]`, `[masks]`) is described in
//! [`Look`].
//!
//! Every error names the file, line and column of the offending value
//! ([`EigenError::Scenario`]), including those only found against the database (an
//! unknown clip, a range past the clip's end, an Eigenfire index beyond E, a join for which
//! End Growing finds no path).
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
use serde::Deserialize;
use toml::Spanned;

use crate::animate::{self, parse_weight_edits};
use crate::colour::{MaskMode, SmokeParams};
use crate::db::EigenfireDb;
use crate::error::{EigenError, Result};
use crate::transition::{
    self, FrameRef, Join, RecognitionParams, Transition, TransitionError, WeightSpace,
};

/// A parsed scenario, not yet checked against its database.
#[derive(Debug)]
pub struct Scenario {
    file: PathBuf,
    text: String,
    raw: RawScenario,
    /// The database directory, resolved against the scenario's folder.
    pub database: PathBuf,
    /// The look (colour and post), with paths resolved against the scenario's folder.
    pub look: Look,
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
    /// Tint of synthetic colouring, and of the bloom in original colouring.
    pub tint: Tint,
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

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScenario {
    database: Spanned<String>,
    sequence: Spanned<Vec<Spanned<String>>>,
    #[serde(rename = "loop", default)]
    loop_: bool,
    e_detect: Option<Spanned<usize>>,
    e_render: Option<Spanned<usize>>,
    #[serde(default)]
    motions: BTreeMap<String, Spanned<RawMotion>>,
    transition: Option<Spanned<RawJoin>>,
    #[serde(default)]
    join: Vec<Spanned<RawJoin>>,
    #[serde(default)]
    colour: RawColour,
    bloom: Option<Spanned<RawBloom>>,
    smoke: Option<Spanned<RawSmoke>>,
    #[serde(default)]
    originals: BTreeMap<String, Spanned<String>>,
    #[serde(default)]
    masks: BTreeMap<String, Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMotion {
    clip: Spanned<String>,
    start: Option<Spanned<usize>>,
    end: Option<Spanned<usize>>,
    weights: Option<Spanned<String>>,
}

#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawJoin {
    method: Option<Spanned<String>>,
    steps: Option<Spanned<usize>>,
    theta_min: Option<Spanned<f64>>,
    theta_quantile: Option<Spanned<f64>>,
    join_gap: Option<Spanned<f64>>,
    reject_near: Option<usize>,
    kernel: Option<Spanned<Vec<f32>>>,
    eigenfires: Option<Spanned<usize>>,
    inject_from: Option<Spanned<usize>>,
    frames: Option<Spanned<usize>>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawColour {
    mode: Option<Spanned<String>>,
    tint: Option<Spanned<[f32; 3]>>,
    palette: Option<Spanned<String>>,
    threshold: Option<Spanned<f32>>,
    alpha: Option<Spanned<String>>,
    fast_path: Option<bool>,
    mask_mode: Option<Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawBloom {
    #[serde(default = "yes")]
    enabled: bool,
    passes: Option<u32>,
    radius: Option<f32>,
    radius_falloff: Option<f32>,
    strength: Option<f32>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSmoke {
    #[serde(default = "yes")]
    enabled: bool,
    threshold: Option<f32>,
    blur: Option<f32>,
    colour: Option<[f32; 3]>,
    absolute: Option<bool>,
}

fn yes() -> bool {
    true
}

/// Line and column (1-based) of byte `offset` in `text`.
fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before
        .rfind('\n')
        .map_or(before.len(), |i| before.len() - i - 1)
        + 1;
    (line, col)
}

impl Scenario {
    /// Reads and parses a scenario file.
    pub fn from_file(path: &Path) -> Result<Scenario> {
        let text = std::fs::read_to_string(path).map_err(|e| EigenError::io(path, e))?;
        Scenario::parse(&text, path)
    }

    /// Parses `text` as the scenario file `file` (used for error messages and to resolve
    /// relative paths).
    pub fn parse(text: &str, file: &Path) -> Result<Scenario> {
        let raw: RawScenario = toml::from_str(text).map_err(|e| {
            let (line, column) = line_col(text, e.span().map_or(0, |s| s.start));
            EigenError::Scenario {
                file: file.to_path_buf(),
                line,
                column,
                message: e.message().trim().to_string(),
            }
        })?;
        let mut s = Scenario {
            file: file.to_path_buf(),
            text: text.to_string(),
            database: PathBuf::new(),
            look: Look {
                mode: ColourMode::Original,
                tint: Tint::Solid([1.0, 0.42, 0.08]),
                threshold: crate::colour::THESIS_THRESHOLD,
                bloom: Some(BloomParams::default()),
                smoke: None,
                matte: true,
                fast_path: true,
                originals: BTreeMap::new(),
                masks: BTreeMap::new(),
                mask_mode: MaskMode::Add,
            },
            raw,
        };
        s.database = s.resolve_path(s.raw.database.get_ref());
        s.look = s.parse_look()?;
        s.check_static()?;
        Ok(s)
    }

    /// The scenario file's path.
    pub fn file(&self) -> &Path {
        &self.file
    }

    /// Whether the sequence loops back to its start.
    pub fn is_loop(&self) -> bool {
        self.raw.loop_
    }

    fn resolve_path(&self, p: &str) -> PathBuf {
        let p = Path::new(p);
        if p.is_absolute() {
            return p.to_path_buf();
        }
        match self.file.parent() {
            Some(dir) if !dir.as_os_str().is_empty() => dir.join(p),
            _ => p.to_path_buf(),
        }
    }

    fn err_at(&self, span: Range<usize>, message: impl Into<String>) -> EigenError {
        let (line, column) = line_col(&self.text, span.start);
        EigenError::Scenario {
            file: self.file.clone(),
            line,
            column,
            message: message.into(),
        }
    }

    fn parse_look(&self) -> Result<Look> {
        let c = &self.raw.colour;
        let mut look = self.look.clone();
        if let Some(t) = &c.tint {
            let v = t.get_ref();
            if v.iter().any(|x| !(0.0..=1.0).contains(x)) {
                return Err(self.err_at(
                    t.span(),
                    format!("`tint` must be three linear RGB values in 0..=1, got {v:?}"),
                ));
            }
            look.tint = Tint::Solid(*v);
        }
        if let Some(m) = &c.mode {
            look.mode = match m.get_ref().as_str() {
                "original" => ColourMode::Original,
                "synthetic" => ColourMode::Synthetic,
                "grey" | "gray" => ColourMode::Grey,
                "palette" => {
                    let name = c.palette.as_ref().map_or("candle", |p| p.get_ref().as_str());
                    let p = Palette::preset(name).map_err(|_| {
                        self.err_at(
                            c.palette.as_ref().map_or(m.span(), |p| p.span()),
                            format!(
                                "unknown palette `{name}`; choose one of {}",
                                ignis_core::palette::PRESETS.join(", ")
                            ),
                        )
                    })?;
                    ColourMode::Palette(p)
                }
                other => {
                    return Err(self.err_at(
                        m.span(),
                        format!("unknown colour mode `{other}`; choose original, synthetic, palette or grey"),
                    ))
                }
            };
        }
        if let Some(t) = &c.threshold {
            let v = *t.get_ref();
            if !(v > 0.0 && v <= 1.0) {
                return Err(self.err_at(
                    t.span(),
                    format!("`threshold` must be in (0, 1] (grey units), got {v}"),
                ));
            }
            look.threshold = v;
        }
        if let Some(a) = &c.alpha {
            look.matte = match a.get_ref().as_str() {
                "matte" => true,
                "opaque" => false,
                other => {
                    return Err(self.err_at(
                        a.span(),
                        format!("unknown alpha `{other}`; choose matte or opaque"),
                    ))
                }
            };
        }
        if let Some(f) = c.fast_path {
            look.fast_path = f;
        }
        if let Some(m) = &c.mask_mode {
            look.mask_mode = match m.get_ref().as_str() {
                "add" => MaskMode::Add,
                "replace" => MaskMode::Replace,
                other => {
                    return Err(self.err_at(
                        m.span(),
                        format!("unknown mask_mode `{other}`; choose add or replace"),
                    ))
                }
            };
        }
        if let Some(bs) = &self.raw.bloom {
            let b = bs.get_ref();
            look.bloom = if b.enabled {
                let d = BloomParams::default();
                let p = BloomParams {
                    passes: b.passes.unwrap_or(d.passes),
                    radius: b.radius.unwrap_or(d.radius),
                    radius_falloff: b.radius_falloff.unwrap_or(d.radius_falloff),
                    strength: b.strength.unwrap_or(d.strength),
                };
                p.validate()
                    .map_err(|e| self.err_at(bs.span(), format!("[bloom]: {e}")))?;
                Some(p)
            } else {
                None
            };
        }
        if let Some(ss) = &self.raw.smoke {
            let s = ss.get_ref();
            look.smoke = if s.enabled {
                let d = SmokeParams::default();
                let p = SmokeParams {
                    threshold: s.threshold.unwrap_or(d.threshold),
                    blur_sigma: s.blur.unwrap_or(d.blur_sigma),
                    colour: s.colour.unwrap_or(d.colour),
                    absolute: s.absolute.unwrap_or(d.absolute),
                };
                let bad = !(0.0..=1.0).contains(&p.threshold)
                    || !(0.0..=64.0).contains(&p.blur_sigma)
                    || p.colour.iter().any(|c| !(0.0..=4.0).contains(c));
                if bad {
                    return Err(self.err_at(
                        ss.span(),
                        "[smoke]: threshold must be in 0..=1, blur in 0..=64 px, colour values in 0..=4",
                    ));
                }
                Some(p)
            } else {
                None
            };
        }
        look.originals = self
            .raw
            .originals
            .iter()
            .map(|(k, v)| (k.clone(), self.resolve_path(v.get_ref())))
            .collect();
        look.masks = self
            .raw
            .masks
            .iter()
            .map(|(k, v)| (k.clone(), self.resolve_path(v.get_ref())))
            .collect();
        Ok(look)
    }

    /// Checks that need no database: the sequence, motion names, join settings.
    fn check_static(&self) -> Result<()> {
        let seq = &self.raw.sequence;
        if seq.get_ref().is_empty() {
            return Err(self.err_at(
                seq.span(),
                "`sequence` is empty; list at least one motion, e.g. sequence = [\"calm\"]",
            ));
        }
        for item in seq.get_ref() {
            if !self.raw.motions.contains_key(item.get_ref()) {
                let known: Vec<&str> = self.raw.motions.keys().map(String::as_str).collect();
                return Err(self.err_at(
                    item.span(),
                    format!(
                        "unknown motion `{}`; the scenario defines {}",
                        item.get_ref(),
                        if known.is_empty() {
                            "none (add a [motions.NAME] table)".to_string()
                        } else {
                            known.join(", ")
                        }
                    ),
                ));
            }
        }
        let joins = self.join_count();
        if self.raw.join.len() > joins {
            return Err(self.err_at(
                self.raw.join[joins].span(),
                format!(
                    "{} [[join]] tables for {joins} join(s) ({} motions{})",
                    self.raw.join.len(),
                    seq.get_ref().len(),
                    if self.raw.loop_ {
                        " with loop = true"
                    } else {
                        ""
                    }
                ),
            ));
        }
        for i in 0..joins {
            self.join_method(i)?;
        }
        for (name, m) in &self.raw.motions {
            if let Some(w) = &m.get_ref().weights {
                parse_weight_edits(w.get_ref())
                    .map_err(|e| self.err_at(w.span(), format!("motion `{name}`: {e}")))?;
            }
        }
        for (k, v) in [
            ("e_detect", &self.raw.e_detect),
            ("e_render", &self.raw.e_render),
        ] {
            if let Some(v) = v {
                if *v.get_ref() == 0 {
                    return Err(self.err_at(v.span(), format!("`{k}` must be at least 1")));
                }
            }
        }
        Ok(())
    }

    /// Number of joins: between consecutive motions, plus the loop join.
    pub fn join_count(&self) -> usize {
        let n = self.raw.sequence.get_ref().len();
        n - 1 + usize::from(self.raw.loop_)
    }

    /// The transition of join `i` (0-based), from `[[join]]` i over `[transition]`.
    fn join_method(&self, i: usize) -> Result<(Transition, RecognitionParams, Option<MorphSpec>)> {
        let dflt = RawJoin::default();
        let d = self.raw.transition.as_ref().map_or(&dflt, |t| t.get_ref());
        let j = self.raw.join.get(i).map(|s| s.get_ref());
        macro_rules! pick {
            ($f:ident) => {
                j.and_then(|j| j.$f.clone()).or_else(|| d.$f.clone())
            };
        }
        let method = pick!(method);
        let steps = pick!(steps);
        let kernel = pick!(kernel);
        let eigenfires = pick!(eigenfires);
        let inject_from = pick!(inject_from);
        let n_frames = pick!(frames);
        let name = method.as_ref().map_or("auto", |m| m.get_ref().as_str());
        if let Some(f) = &n_frames {
            if *f.get_ref() == 0 || *f.get_ref() > MORPH_MAX_FRAMES {
                return Err(self.err_at(
                    f.span(),
                    format!("`frames` must be in 1..={MORPH_MAX_FRAMES}"),
                ));
            }
        }
        let morph = match name {
            "morph" => Some(MorphSpec {
                frames: n_frames.as_ref().map(|f| *f.get_ref()),
                forced: true,
            }),
            "auto" => Some(MorphSpec {
                frames: n_frames.as_ref().map(|f| *f.get_ref()),
                forced: false,
            }),
            _ => None,
        };
        let mut t = if name == "morph" {
            Transition::Auto
        } else {
            animate::parse_method(name).map_err(|_| {
                self.err_at(
                    method.as_ref().map_or(0..0, |m| m.span()),
                    format!("unknown method `{name}`; choose auto, end-growing, direct, low-pass or morph"),
                )
            })?
        };
        if let Some(s) = &steps {
            if *s.get_ref() == 0 {
                return Err(self.err_at(s.span(), "`steps` must be at least 1"));
            }
        }
        match &mut t {
            Transition::EndGrowing { max_steps } => {
                if let Some(s) = &steps {
                    *max_steps = *s.get_ref();
                }
            }
            Transition::DirectBridging { steps: st } => *st = steps.as_ref().map(|s| *s.get_ref()),
            Transition::LowPass(p) => {
                if let Some(k) = &kernel {
                    let v = k.get_ref();
                    let sum: f32 = v.iter().sum();
                    if v.len() < 2 || v.iter().any(|x| !x.is_finite()) || sum.abs() < 1e-6 {
                        return Err(self.err_at(
                            k.span(),
                            format!(
                                "`kernel` needs at least 2 finite taps not summing to 0, got {v:?}"
                            ),
                        ));
                    }
                    p.kernel = v.clone();
                }
                if let Some(e) = &eigenfires {
                    if *e.get_ref() == 0 {
                        return Err(self.err_at(e.span(), "`eigenfires` must be at least 1"));
                    }
                    p.e_render = *e.get_ref();
                }
                if let Some(f) = &inject_from {
                    if *f.get_ref() < p.e_render {
                        return Err(self.err_at(
                            f.span(),
                            format!(
                                "`inject_from` must be ≥ the morphs' eigenfires ({})",
                                p.e_render
                            ),
                        ));
                    }
                    p.inject_from = Some(*f.get_ref());
                }
            }
            Transition::Auto => {}
        }
        let mut rec = RecognitionParams::default();
        if let Some(v) = pick!(theta_min) {
            if !(*v.get_ref() > 0.0 && v.get_ref().is_finite()) {
                return Err(self.err_at(v.span(), "`theta_min` must be a number > 0"));
            }
            rec.theta_min = Some(*v.get_ref());
        }
        if let Some(v) = pick!(theta_quantile) {
            if !(0.0..=1.0).contains(v.get_ref()) {
                return Err(self.err_at(v.span(), "`theta_quantile` must be in 0..=1"));
            }
            rec.theta_quantile = *v.get_ref();
        }
        if let Some(v) = pick!(join_gap) {
            if !(*v.get_ref() > 0.0 && v.get_ref().is_finite()) {
                return Err(self.err_at(v.span(), "`join_gap` must be a number > 0"));
            }
            rec.join_gap = Some(*v.get_ref());
        }
        if let Some(v) = pick!(reject_near) {
            rec.reject_near = v;
        }
        Ok((t, rec, morph))
    }

    /// Where join `i` is configured (its `[[join]]` table, else `[transition]`, else the
    /// sequence), for errors.
    fn join_span(&self, i: usize) -> Range<usize> {
        if let Some(j) = self.raw.join.get(i) {
            return j.span();
        }
        match &self.raw.transition {
            Some(t) => t.span(),
            None => self.raw.sequence.span(),
        }
    }

    /// Checks the scenario against `db` and computes every join: the frame list to render.
    /// `progress(i, n)` is called before join `i` of `n`.
    pub fn plan(&self, db: &EigenfireDb, progress: &mut dyn FnMut(usize, usize)) -> Result<Plan> {
        let usable = db.usable_components().max(1);
        let e_detect = self
            .raw
            .e_detect
            .as_ref()
            .map_or(db.manifest().e_detect, |v| *v.get_ref());
        let e_render_req = self
            .raw
            .e_render
            .as_ref()
            .map_or(db.manifest().e_render, |v| *v.get_ref());
        // Motions.
        let mut motions: BTreeMap<&str, MotionPlan> = BTreeMap::new();
        for (name, m) in &self.raw.motions {
            let m = m.get_ref();
            let clip = db
                .clips()
                .iter()
                .find(|c| &c.name == m.clip.get_ref())
                .ok_or_else(|| {
                    let names: Vec<&str> = db.clips().iter().map(|c| c.name.as_str()).collect();
                    self.err_at(
                        m.clip.span(),
                        format!(
                            "motion `{name}`: unknown clip `{}`; database {} has {}",
                            m.clip.get_ref(),
                            db.path().display(),
                            names.join(", ")
                        ),
                    )
                })?;
            let start = m.start.as_ref().map_or(clip.start, |s| *s.get_ref());
            let end = m.end.as_ref().map_or(clip.end, |s| *s.get_ref());
            let last = clip.start + clip.frames.saturating_sub(1) * clip.stride;
            if let Some(e) = &m.end {
                if end > clip.end {
                    return Err(self.err_at(
                        e.span(),
                        format!(
                            "motion `{name}`: end = {end} is past the end of clip `{}` (trained on frames {}..{})",
                            clip.name, clip.start, clip.end
                        ),
                    ));
                }
            }
            if start >= end {
                return Err(self.err_at(
                    m.start
                        .as_ref()
                        .or(m.end.as_ref())
                        .map_or(m.clip.span(), |s| s.span()),
                    format!("motion `{name}`: the range {start}..{end} is empty"),
                ));
            }
            let rows = animate::clip_rows(db, &clip.name, start..end).map_err(|e| {
                self.err_at(
                    m.start.as_ref().map_or(m.clip.span(), |s| s.span()),
                    format!(
                        "motion `{name}`: {e} (clip `{}` has training frames {}..={last} every {})",
                        clip.name, clip.start, clip.stride
                    ),
                )
            })?;
            let mut edits = Vec::new();
            if let Some(w) = &m.weights {
                for (i, v) in parse_weight_edits(w.get_ref())
                    .map_err(|e| self.err_at(w.span(), format!("motion `{name}`: {e}")))?
                {
                    if i >= usable {
                        return Err(self.err_at(
                            w.span(),
                            format!(
                                "motion `{name}`: Eigenfire index {i} is out of range: the database has {usable} usable Eigenfires (0..{usable})"
                            ),
                        ));
                    }
                    edits.push((i, v));
                }
            }
            motions.insert(name, MotionPlan { rows, edits });
        }
        let space = WeightSpace::from_db(db)?;
        let seq: Vec<&str> = self
            .raw
            .sequence
            .get_ref()
            .iter()
            .map(|s| s.get_ref().as_str())
            .collect();
        let n_joins = self.join_count();
        let mut joins = Vec::with_capacity(n_joins);
        for i in 0..n_joins {
            progress(i, n_joins);
            let (a, b) = (seq[i], seq[(i + 1) % seq.len()]);
            let (t, mut rec, morph) = self.join_method(i)?;
            rec.e_detect = e_detect;
            let (ra, rb) = (motions[a].rows.clone(), motions[b].rows.clone());
            let e = rec.e_detect(&space);
            let forced = morph.as_ref().is_some_and(|m| m.forced);
            let tried = if forced {
                None
            } else {
                Some(transition::transition(
                    &space,
                    ra.clone(),
                    rb.clone(),
                    &t,
                    &rec,
                ))
            };
            let join = match (tried, &morph) {
                (None, Some(m)) => morph_join(&space, &ra, &rb, m.frames, e, "method = \"morph\""),
                (Some(Ok(j)), Some(m)) if j.seam_ratio > AUTO_MORPH_ABOVE => {
                    let mj = morph_join(&space, &ra, &rb, m.frames, e, "");
                    if mj.seam_ratio < j.seam_ratio {
                        let why = format!(
                            "auto: {} gave seam ratio {:.2} (> {AUTO_MORPH_ABOVE}), the morph {:.2}; {}",
                            j.method, j.seam_ratio, mj.seam_ratio, mj.why
                        );
                        Join { why, ..mj }
                    } else {
                        j
                    }
                }
                (Some(Err(TransitionError::NoPath { .. })), Some(m)) if !m.forced => {
                    let mj = morph_join(&space, &ra, &rb, m.frames, e, "");
                    let why = format!("auto: no real-frame path; {}", mj.why);
                    Join { why, ..mj }
                }
                (Some(r), _) => r.map_err(|e| {
                    let why = match &e {
                        TransitionError::NoPath { .. } => format!(
                            "{e}; try a larger `steps`, another method, or method = \"auto\""
                        ),
                        _ => e.to_string(),
                    };
                    self.err_at(
                        self.join_span(i),
                        format!("join {} ({a} → {b}): {why}", i + 1),
                    )
                })?,
                (None, m) => morph_join(
                    &space,
                    &ra,
                    &rb,
                    m.as_ref().and_then(|m| m.frames),
                    e,
                    "method = \"morph\"",
                ),
            };
            let plain = transition::join_seam(&space, &ra, &rb, &[], (0, 0), e);
            joins.push(JoinReport {
                from: a.to_string(),
                to: b.to_string(),
                join,
                plain_cut: plain,
            });
        }
        progress(n_joins, n_joins);
        // The frame list: each motion's body (less the frames its joins replace), then the
        // join to the next motion.
        let mut frames = Vec::new();
        let mut morphs = Vec::new();
        for (i, &name) in seq.iter().enumerate() {
            let m = &motions[name];
            let trim_head = if i > 0 {
                joins[i - 1].join.trim_t2
            } else if self.raw.loop_ {
                joins[n_joins - 1].join.trim_t2
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
                let next = &motions[seq[(i + 1) % seq.len()]];
                let n = j.join.frames.len();
                if j.join.method == "morph" && n > 0 {
                    morphs.push(MorphRun {
                        start: frames.len(),
                        len: n,
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
            return Err(self.err_at(
                self.raw.sequence.span(),
                "the transitions replaced every frame of the motions; use longer ranges",
            ));
        }
        // Smoothness of the sequence as written, and of its wrap (last → first).
        let e = RecognitionParams {
            e_detect,
            ..Default::default()
        }
        .e_detect(&space);
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
        if morphs.iter().any(|m| m.len >= frames.len()) {
            return Err(self.err_at(
                self.raw.sequence.span(),
                "a morph join has no real frame to start or end from; use longer ranges",
            ));
        }
        Ok(Plan {
            frames,
            morphs,
            joins,
            wrap_seam: wrap,
            worst_step: worst,
            e_render: e_render_req.clamp(1, usable),
            e_render_requested: e_render_req,
            e_detect: e,
            loops: self.raw.loop_,
        })
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
/// motion-compensated morph of the two rendered endpoint frames ([`Plan::morphs`]).
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
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MorphRun {
    pub start: usize,
    pub len: usize,
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

struct MotionPlan {
    rows: Range<usize>,
    edits: Vec<(usize, f32)>,
}

/// One join of a plan, for the table `ignis eigen animate` prints.
#[derive(Clone, Debug)]
pub struct JoinReport {
    /// Motion names.
    pub from: String,
    pub to: String,
    pub join: Join,
    /// Seam ratio of a plain cut at the same place.
    pub plain_cut: f64,
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
    pub joins: Vec<JoinReport>,
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
