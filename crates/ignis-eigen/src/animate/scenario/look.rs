//! Reading the look of a scenario (`[colour]`, `[bloom]`, `[smoke]`, `[originals]`,
//! `[masks]`) into [`Look`], checked by the settings types' own `validate()`.

use ignis_core::colour::Tint;
use ignis_core::post::BloomParams;
use ignis_core::Palette;
use serde::Deserialize;
use toml::Spanned;

use super::spec::{resolve_path, span, value, RawScenario, Source};
use super::{ColourMode, Look};
use crate::colour::{MaskMode, OriginalColour, SmokeParams};
use crate::error::Result;

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawColour {
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
pub(super) struct RawBloom {
    #[serde(default = "yes")]
    enabled: bool,
    passes: Option<Spanned<u32>>,
    radius: Option<Spanned<f32>>,
    radius_falloff: Option<Spanned<f32>>,
    strength: Option<Spanned<f32>>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSmoke {
    #[serde(default = "yes")]
    enabled: bool,
    threshold: Option<Spanned<f32>>,
    blur: Option<Spanned<f32>>,
    colour: Option<Spanned<[f32; 3]>>,
    absolute: Option<bool>,
}

fn yes() -> bool {
    true
}

/// The look of `raw`, with paths resolved against the scenario's folder.
pub(super) fn parse(src: &Source, raw: &RawScenario) -> Result<Look> {
    let c = &raw.colour;
    let mut look = Look::default();
    if let Some(t) = &c.tint {
        let v = t.get_ref();
        if v.iter().any(|x| !(0.0..=1.0).contains(x)) {
            return Err(src.err(
                t.span(),
                format!("`tint` must be three linear RGB values in 0..=1, got {v:?}"),
            ));
        }
        look.tint = Tint::Solid(*v);
        look.tint_from_footage = false;
    }
    if let Some(m) = &c.mode {
        look.mode = mode(src, c, m)?;
    }
    if let Some(t) = &c.threshold {
        let o = OriginalColour {
            threshold: *t.get_ref(),
            ..Default::default()
        };
        o.validate().map_err(|e| {
            src.invalid(
                e.into(),
                &[("colour.threshold", "threshold", Some(t.span()))],
                t.span(),
                "",
            )
        })?;
        look.threshold = o.threshold;
    }
    if let Some(a) = &c.alpha {
        look.matte = choose(src, "alpha", a, &[("matte", true), ("opaque", false)])?;
    }
    if let Some(f) = c.fast_path {
        look.fast_path = f;
    }
    if let Some(m) = &c.mask_mode {
        look.mask_mode = choose(
            src,
            "mask_mode",
            m,
            &[("add", MaskMode::Add), ("replace", MaskMode::Replace)],
        )?;
    }
    if let Some(b) = &raw.bloom {
        look.bloom = bloom(src, b)?;
    }
    if let Some(s) = &raw.smoke {
        look.smoke = smoke(src, s)?;
    }
    let paths = |m: &std::collections::BTreeMap<String, Spanned<String>>| {
        m.iter()
            .map(|(k, v)| (k.clone(), resolve_path(src.file, v.get_ref())))
            .collect()
    };
    look.originals = paths(&raw.originals);
    look.masks = paths(&raw.masks);
    Ok(look)
}

/// `[colour] mode` (and `palette` for the palette mode).
fn mode(src: &Source, c: &RawColour, m: &Spanned<String>) -> Result<ColourMode> {
    Ok(match m.get_ref().as_str() {
        "original" => ColourMode::Original,
        "synthetic" => ColourMode::Synthetic,
        "grey" | "gray" => ColourMode::Grey,
        "palette" => {
            let name = c
                .palette
                .as_ref()
                .map_or("candle", |p| p.get_ref().as_str());
            let p = Palette::preset(name).map_err(|_| {
                src.err(
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
            return Err(src.err(
                m.span(),
                format!(
                    "unknown colour mode `{other}`; choose original, synthetic, palette or grey"
                ),
            ))
        }
    })
}

/// One of the named `choices` for the setting `key`.
fn choose<T: Copy>(
    src: &Source,
    key: &str,
    v: &Spanned<String>,
    choices: &[(&str, T)],
) -> Result<T> {
    match choices.iter().find(|(name, _)| name == v.get_ref()) {
        Some((_, value)) => Ok(*value),
        None => {
            let names: Vec<&str> = choices.iter().map(|(n, _)| *n).collect();
            Err(src.err(
                v.span(),
                format!(
                    "unknown {key} `{}`; choose {}",
                    v.get_ref(),
                    names.join(" or ")
                ),
            ))
        }
    }
}

/// `[bloom]`: `None` when disabled; checked by [`BloomParams::validate`].
fn bloom(src: &Source, bs: &Spanned<RawBloom>) -> Result<Option<BloomParams>> {
    let b = bs.get_ref();
    if !b.enabled {
        return Ok(None);
    }
    let d = BloomParams::default();
    let p = BloomParams {
        passes: value(&b.passes).unwrap_or(d.passes),
        radius: value(&b.radius).unwrap_or(d.radius),
        radius_falloff: value(&b.radius_falloff).unwrap_or(d.radius_falloff),
        strength: value(&b.strength).unwrap_or(d.strength),
    };
    p.validate().map_err(|e| {
        src.invalid(
            e.into(),
            &[
                ("bloom.passes", "passes", span(&b.passes)),
                ("bloom.radius", "radius", span(&b.radius)),
                (
                    "bloom.radius_falloff",
                    "radius_falloff",
                    span(&b.radius_falloff),
                ),
                ("bloom.strength", "strength", span(&b.strength)),
            ],
            bs.span(),
            "[bloom]: ",
        )
    })?;
    Ok(Some(p))
}

/// `[smoke]`: `None` when disabled; checked by [`SmokeParams::validate`].
fn smoke(src: &Source, ss: &Spanned<RawSmoke>) -> Result<Option<SmokeParams>> {
    let s = ss.get_ref();
    if !s.enabled {
        return Ok(None);
    }
    let d = SmokeParams::default();
    let p = SmokeParams {
        threshold: value(&s.threshold).unwrap_or(d.threshold),
        blur_sigma: value(&s.blur).unwrap_or(d.blur_sigma),
        colour: value(&s.colour).unwrap_or(d.colour),
        absolute: s.absolute.unwrap_or(d.absolute),
    };
    p.validate().map_err(|e| {
        src.invalid(
            e.into(),
            &[
                ("smoke.threshold", "threshold", span(&s.threshold)),
                ("smoke.blur_sigma", "blur", span(&s.blur)),
                ("smoke.colour", "colour", span(&s.colour)),
            ],
            ss.span(),
            "[smoke]: ",
        )
    })?;
    Ok(Some(p))
}
