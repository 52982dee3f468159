//! Reading a scenario: the TOML text deserialised once (serde, with a span on every value
//! that can be wrong) and checked into the typed [`Scenario`] with the settings types'
//! own `validate()`; a failing setting is reported at its key in the file.

use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use toml::Spanned;

use super::{look, At, JoinSpec, Loc, MorphSpec, MotionSpec, Scenario, MORPH_MAX_FRAMES};
use crate::animate::{self, parse_weight_edits};
use crate::error::{EigenError, Result};
use crate::transition::{RecognitionParams, Transition, TransitionError};

/// The file as written; every field that can be wrong keeps its byte span.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawScenario {
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
    pub(super) colour: look::RawColour,
    pub(super) bloom: Option<Spanned<look::RawBloom>>,
    pub(super) smoke: Option<Spanned<look::RawSmoke>>,
    #[serde(default)]
    pub(super) originals: BTreeMap<String, Spanned<String>>,
    #[serde(default)]
    pub(super) masks: BTreeMap<String, Spanned<String>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMotion {
    clip: Spanned<String>,
    start: Option<Spanned<usize>>,
    end: Option<Spanned<usize>>,
    weights: Option<Spanned<String>>,
}

/// A `[[join]]` table or the `[transition]` defaults.
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

impl RawJoin {
    /// Join settings: `self`'s, else those of `defaults`.
    fn over(&self, defaults: &RawJoin) -> RawJoin {
        macro_rules! pick {
            ($($f:ident),*) => {
                RawJoin { $($f: self.$f.clone().or_else(|| defaults.$f.clone())),* }
            };
        }
        pick!(
            method,
            steps,
            theta_min,
            theta_quantile,
            join_gap,
            reject_near,
            kernel,
            eigenfires,
            inject_from,
            frames
        )
    }
}

/// The text being read, for positions and errors.
pub(super) struct Source<'a> {
    pub(super) file: &'a Path,
    pub(super) text: &'a str,
}

impl Source<'_> {
    pub(super) fn loc(&self, span: Range<usize>) -> Loc {
        let (line, column) = line_col(self.text, span.start);
        Loc { line, column }
    }

    pub(super) fn at<T: Clone>(&self, s: &Spanned<T>) -> At<T> {
        At {
            value: s.get_ref().clone(),
            loc: self.loc(s.span()),
        }
    }

    pub(super) fn err(&self, span: Range<usize>, message: impl Into<String>) -> EigenError {
        self.loc(span).err(self.file, message)
    }

    /// The error for a settings type's `validate()` failure `bad`: at the scenario key the
    /// failing setting comes from (`keys`: setting name → key and its span when given),
    /// else at `fallback`. Settings named otherwise in the file (`e_render = 50` in a
    /// reason) are given their key's name.
    pub(super) fn invalid(
        &self,
        bad: Invalid,
        keys: &[(&str, &str, Option<Range<usize>>)],
        fallback: Range<usize>,
        prefix: &str,
    ) -> EigenError {
        let mut reason = bad.reason;
        for (name, key, _) in keys.iter().filter(|(name, key, _)| name != key) {
            reason = reason.replace(&format!("{name} ="), &format!("{key} ="));
        }
        match keys.iter().find(|(name, _, _)| *name == bad.name) {
            Some((_, key, Some(span))) => {
                self.err(span.clone(), format!("{prefix}`{key}` {reason}"))
            }
            Some((_, key, None)) => self.err(fallback, format!("{prefix}`{key}` {reason}")),
            None if bad.name.is_empty() => self.err(fallback, format!("{prefix}{reason}")),
            None => self.err(
                fallback,
                format!("{prefix}invalid setting `{}`: {reason}", bad.name),
            ),
        }
    }
}

/// A failed `validate()` of a settings type: the setting's name and why.
pub(super) struct Invalid {
    name: String,
    reason: String,
}

impl From<TransitionError> for Invalid {
    fn from(e: TransitionError) -> Self {
        match e {
            TransitionError::BadParameter { name, reason } => Invalid { name, reason },
            other => Invalid {
                name: String::new(),
                reason: other.to_string(),
            },
        }
    }
}

impl From<EigenError> for Invalid {
    fn from(e: EigenError) -> Self {
        match e {
            EigenError::BadParameter { name, reason } => Invalid { name, reason },
            other => Invalid {
                name: String::new(),
                reason: other.to_string(),
            },
        }
    }
}

impl From<ignis_core::CoreError> for Invalid {
    fn from(e: ignis_core::CoreError) -> Self {
        match e {
            ignis_core::CoreError::BadParameter { name, reason } => Invalid {
                name: name.to_string(),
                reason,
            },
            other => Invalid {
                name: String::new(),
                reason: other.to_string(),
            },
        }
    }
}

/// The value of an optional spanned setting.
pub(super) fn value<T: Copy>(v: &Option<Spanned<T>>) -> Option<T> {
    v.as_ref().map(|v| *v.get_ref())
}

/// The span of an optional spanned setting.
pub(super) fn span<T>(v: &Option<Spanned<T>>) -> Option<Range<usize>> {
    v.as_ref().map(Spanned::span)
}

/// Line and column (1-based) of byte `offset` in `text`.
pub(super) fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let col = before
        .rfind('\n')
        .map_or(before.len(), |i| before.len() - i - 1)
        + 1;
    (line, col)
}

/// Parses and checks `text` as the scenario file `file`: everything that needs no database.
pub(super) fn parse(text: &str, file: &Path) -> Result<Scenario> {
    let src = Source { file, text };
    let raw: RawScenario = toml::from_str(text).map_err(|e| {
        src.err(
            e.span().map_or(0..0, |s| s.start..s.start),
            e.message().trim(),
        )
    })?;
    let look = look::parse(&src, &raw)?;
    let sequence = sequence(&src, &raw)?;
    let joins = joins(&src, &raw)?;
    let motions = motions(&src, &raw)?;
    let e_detect = at_least_one(&src, "e_detect", &raw.e_detect)?;
    let e_render = at_least_one(&src, "e_render", &raw.e_render)?;
    Ok(Scenario {
        file: file.to_path_buf(),
        database: resolve_path(file, raw.database.get_ref()),
        look,
        sequence,
        loops: raw.loop_,
        e_detect,
        e_render,
        motions,
        joins,
    })
}

/// `p` resolved against the folder of the scenario file `file`.
pub(super) fn resolve_path(file: &Path, p: &str) -> PathBuf {
    let p = Path::new(p);
    if p.is_absolute() {
        return p.to_path_buf();
    }
    match file.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir.join(p),
        _ => p.to_path_buf(),
    }
}

/// The sequence: not empty, every name a `[motions.NAME]` table.
fn sequence(src: &Source, raw: &RawScenario) -> Result<At<Vec<At<String>>>> {
    let seq = &raw.sequence;
    if seq.get_ref().is_empty() {
        return Err(src.err(
            seq.span(),
            "`sequence` is empty; list at least one motion, e.g. sequence = [\"calm\"]",
        ));
    }
    for item in seq.get_ref() {
        if !raw.motions.contains_key(item.get_ref()) {
            let known: Vec<&str> = raw.motions.keys().map(String::as_str).collect();
            return Err(src.err(
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
    Ok(At {
        value: seq.get_ref().iter().map(|s| src.at(s)).collect(),
        loc: src.loc(seq.span()),
    })
}

/// Every join's settings (`[[join]]` i over `[transition]`), checked.
fn joins(src: &Source, raw: &RawScenario) -> Result<Vec<JoinSpec>> {
    let n = raw.sequence.get_ref().len() - 1 + usize::from(raw.loop_);
    if raw.join.len() > n {
        return Err(src.err(
            raw.join[n].span(),
            format!(
                "{} [[join]] tables for {n} join(s) ({} motions{})",
                raw.join.len(),
                raw.sequence.get_ref().len(),
                if raw.loop_ { " with loop = true" } else { "" }
            ),
        ));
    }
    let none = RawJoin::default();
    let defaults = raw.transition.as_ref().map_or(&none, |t| t.get_ref());
    (0..n)
        .map(|i| {
            // Where join i is configured, for errors found only against the database.
            let table = match (raw.join.get(i), &raw.transition) {
                (Some(j), _) => j.span(),
                (None, Some(t)) => t.span(),
                (None, None) => raw.sequence.span(),
            };
            let settings = raw
                .join
                .get(i)
                .map_or(defaults.clone(), |j| j.get_ref().over(defaults));
            join(src, &settings, table)
        })
        .collect()
}

/// One join's settings: the method's parameters and the recognition settings, each
/// checked by its own `validate()`.
fn join(src: &Source, j: &RawJoin, table: Range<usize>) -> Result<JoinSpec> {
    if let Some(f) = &j.frames {
        if !(1..=MORPH_MAX_FRAMES).contains(f.get_ref()) {
            return Err(src.err(
                f.span(),
                format!("`frames` must be in 1..={MORPH_MAX_FRAMES}"),
            ));
        }
    }
    let name = j.method.as_ref().map_or("auto", |m| m.get_ref().as_str());
    let frames = value(&j.frames);
    let morph = match name {
        "morph" | "auto" => Some(MorphSpec {
            frames,
            forced: name == "morph",
        }),
        _ => None,
    };
    let transition = method(src, j, name, &table)?;
    let d = RecognitionParams::default();
    let rec = RecognitionParams {
        theta_min: value(&j.theta_min),
        theta_quantile: value(&j.theta_quantile).unwrap_or(d.theta_quantile),
        join_gap: value(&j.join_gap),
        reject_near: j.reject_near.unwrap_or(d.reject_near),
        ..d
    };
    rec.validate().map_err(|e| {
        let keys = [
            ("theta_min", "theta_min", span(&j.theta_min)),
            ("theta_quantile", "theta_quantile", span(&j.theta_quantile)),
            ("join_gap", "join_gap", span(&j.join_gap)),
        ];
        src.invalid(e.into(), &keys, table.clone(), "")
    })?;
    Ok(JoinSpec {
        transition,
        rec,
        morph,
        loc: src.loc(table),
    })
}

/// The transition method `name` with its settings from `j`, checked by
/// [`Transition::validate`].
fn method(src: &Source, j: &RawJoin, name: &str, table: &Range<usize>) -> Result<Transition> {
    let mut t = if name == "morph" {
        Transition::Auto
    } else {
        animate::parse_method(name).map_err(|_| {
            src.err(
                j.method.as_ref().map_or(0..0, |m| m.span()),
                format!(
                    "unknown method `{name}`; choose auto, end-growing, direct, low-pass or morph"
                ),
            )
        })?
    };
    let steps = value(&j.steps);
    if let Some(s) = &j.steps {
        if *s.get_ref() == 0 {
            return Err(src.err(s.span(), "`steps` must be at least 1"));
        }
    }
    match &mut t {
        Transition::EndGrowing { max_steps } => *max_steps = steps.unwrap_or(*max_steps),
        Transition::DirectBridging { steps: st } => *st = steps,
        Transition::LowPass(p) => {
            if let Some(k) = &j.kernel {
                p.kernel = k.get_ref().clone();
            }
            p.e_render = value(&j.eigenfires).unwrap_or(p.e_render);
            p.inject_from = value(&j.inject_from);
        }
        Transition::Auto => {}
    }
    t.validate().map_err(|e| {
        let keys = [
            ("steps", "steps", span(&j.steps)),
            ("max_steps", "steps", span(&j.steps)),
            ("kernel", "kernel", span(&j.kernel)),
            ("e_render", "eigenfires", span(&j.eigenfires)),
            ("inject_from", "inject_from", span(&j.inject_from)),
        ];
        src.invalid(e.into(), &keys, table.clone(), "")
    })?;
    Ok(t)
}

/// Every motion: its clip and range as written (resolved against the database by
/// [`Scenario::plan`]) and its weight edits, parsed.
fn motions(src: &Source, raw: &RawScenario) -> Result<BTreeMap<String, MotionSpec>> {
    raw.motions
        .iter()
        .map(|(name, m)| {
            let m = m.get_ref();
            let edits = match &m.weights {
                Some(w) => Some(At {
                    value: parse_weight_edits(w.get_ref())
                        .map_err(|e| src.err(w.span(), format!("motion `{name}`: {e}")))?,
                    loc: src.loc(w.span()),
                }),
                None => None,
            };
            let spec = MotionSpec {
                clip: src.at(&m.clip),
                start: m.start.as_ref().map(|s| src.at(s)),
                end: m.end.as_ref().map(|s| src.at(s)),
                edits,
            };
            Ok((name.clone(), spec))
        })
        .collect()
}

/// An optional count that must be at least 1.
fn at_least_one(src: &Source, key: &str, v: &Option<Spanned<usize>>) -> Result<Option<usize>> {
    match v {
        Some(v) if *v.get_ref() == 0 => {
            Err(src.err(v.span(), format!("`{key}` must be at least 1")))
        }
        v => Ok(value(v)),
    }
}
