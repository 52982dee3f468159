//! Deterministic synthetic flame footage, so that demos and tests need nothing external.
//!
//! Two visually distinct "clips": [`FlameStyle::Candle`] (one narrow, tall, gently swaying
//! tongue with a blue root) and [`FlameStyle::Campfire`] (a wide bed of several flickering
//! tongues). Both sit on a black background with a faint reddish glow around the flame
//! (the "illuminated background and smoke" of thesis §3.1 that Hermite removal takes away).
//! Frames are linear-light RGBA, opaque (alpha 1). All randomness comes from
//! [`ignis_core::Rng`] seeded by `seed`.

use ignis_core::palette::srgb_to_linear;
use ignis_core::{Result as CoreResult, RgbaFrame, Rng, Size};

/// Which kind of flame to draw.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FlameStyle {
    /// One narrow tongue, 60–75 % of the frame height.
    Candle,
    /// Four to six tongues over a wide base, with more red.
    Campfire,
}

impl FlameStyle {
    const ALL: [(FlameStyle, &'static str); 2] = [
        (FlameStyle::Candle, "candle"),
        (FlameStyle::Campfire, "campfire"),
    ];

    pub fn name(self) -> &'static str {
        Self::ALL
            .iter()
            .find(|(s, _)| *s == self)
            .expect("listed")
            .1
    }
}

/// The source description a database records for a synthetic clip:
/// `synthetic:<style>:seed=<n>`. [`parse_source_name`] reads it back.
pub fn source_name(p: &SyntheticParams) -> String {
    format!("synthetic:{}:seed={}", p.style.name(), p.seed)
}

/// Style and seed of a [`source_name`]; `None` for any other source.
pub fn parse_source_name(s: &str) -> Option<(FlameStyle, u64)> {
    let (style, seed) = s.strip_prefix("synthetic:")?.split_once(":seed=")?;
    let style = FlameStyle::ALL.iter().find(|(_, n)| *n == style)?.0;
    Some((style, seed.parse().ok()?))
}

/// Settings of [`synthetic_clip`].
#[derive(Clone, Debug)]
pub struct SyntheticParams {
    /// Frame size in pixels. Default 96x128.
    pub size: Size,
    /// Number of frames. Default 48.
    pub frames: usize,
    /// Flame kind. Default candle.
    pub style: FlameStyle,
    /// Seed of every random choice. Default 1.
    pub seed: u64,
}

impl Default for SyntheticParams {
    fn default() -> Self {
        SyntheticParams {
            size: Size {
                width: 96,
                height: 128,
            },
            frames: 48,
            style: FlameStyle::Candle,
            seed: 1,
        }
    }
}

struct Tongue {
    x: f32,      // base position, fraction of width
    height: f32, // fraction of frame height
    width: f32,  // half width at the widest, fraction of frame width
    phase: [f32; 3],
    speed: [f32; 3],
}

/// Draws a clip of `p.frames` frames.
pub fn synthetic_clip(p: &SyntheticParams) -> CoreResult<Vec<RgbaFrame>> {
    (0..p.frames).map(|t| synthetic_frame(p, t)).collect()
}

/// Draws frame `t` of the clip described by `p` (each frame is independent of the others,
/// so any frame can be made on its own).
pub fn synthetic_frame(p: &SyntheticParams, t: usize) -> CoreResult<RgbaFrame> {
    let size = Size::new(p.size.width, p.size.height)?;
    let mut rng = Rng::derive(p.seed, p.style as u64 + 1);
    let tongues: Vec<Tongue> = match p.style {
        FlameStyle::Candle => vec![Tongue {
            x: 0.5,
            height: 0.68,
            width: 0.11,
            phase: [
                rng.f32() * std::f32::consts::TAU,
                rng.f32() * std::f32::consts::TAU,
                rng.f32() * std::f32::consts::TAU,
            ],
            speed: [0.21, 0.37, 0.11],
        }],
        FlameStyle::Campfire => {
            let n = 4 + rng.below(3) as usize;
            (0..n)
                .map(|i| Tongue {
                    x: 0.22 + 0.56 * (i as f32 + 0.5) / n as f32 + rng.uniform(-0.03, 0.03) as f32,
                    height: rng.uniform(0.3, 0.55) as f32,
                    width: rng.uniform(0.07, 0.11) as f32,
                    phase: [
                        rng.f32() * std::f32::consts::TAU,
                        rng.f32() * std::f32::consts::TAU,
                        rng.f32() * std::f32::consts::TAU,
                    ],
                    speed: [
                        rng.uniform(0.25, 0.5) as f32,
                        rng.uniform(0.4, 0.8) as f32,
                        rng.uniform(0.1, 0.3) as f32,
                    ],
                })
                .collect()
        }
    };
    // Per-frame noise (flicker), deterministic in (seed, style, t).
    let mut frng = Rng::derive(p.seed ^ 0x5EED, (p.style as u64 + 1) * 1_000_003 + t as u64);
    let tf = t as f32;
    let (w, h) = (size.width as f32, size.height as f32);
    let base_y = 0.92 * h;
    let mut heat = vec![0.0f32; size.pixels()];
    for tg in &tongues {
        let sway = 0.5 * (tg.phase[0] + tf * tg.speed[0]).sin()
            + 0.3 * (tg.phase[1] + tf * tg.speed[1]).sin();
        let stretch =
            1.0 + 0.15 * (tg.phase[2] + tf * tg.speed[2]).sin() + 0.05 * frng.normal() as f32;
        let th = (tg.height * stretch * h).max(4.0);
        let tw = tg.width * w * (1.0 + 0.1 * frng.normal() as f32);
        let bx = tg.x * w;
        for y in 0..size.height {
            let v = (base_y - y as f32) / th; // 0 at base, 1 at tip
            if !(-0.15..=1.0).contains(&v) {
                continue;
            }
            let vc = v.max(0.0);
            let profile = (std::f32::consts::PI * vc.powf(0.6)).sin().max(0.0)
                * (1.0 - vc).powf(0.25)
                + 0.35 * (1.0 - v.abs() / 0.15).max(0.0) * (v < 0.0) as i32 as f32;
            let halfw = (tw * profile).max(0.5);
            let cx = bx + sway * tw * 1.6 * vc * vc;
            let row =
                &mut heat[y as usize * size.width as usize..(y as usize + 1) * size.width as usize];
            for (x, hv) in row.iter_mut().enumerate() {
                let u = (x as f32 + 0.5 - cx) / halfw;
                if u.abs() > 1.6 {
                    continue;
                }
                let core = (1.0 - u * u).max(0.0).powf(0.7);
                let vert = if v < 0.0 {
                    1.0 + v / 0.15
                } else {
                    1.0 - 0.55 * vc
                };
                *hv = hv.max(core * vert);
            }
        }
    }
    let blue_root = p.style == FlameStyle::Candle;
    let mut data = Vec::with_capacity(size.pixels());
    for y in 0..size.height {
        for x in 0..size.width {
            let hv = heat[y as usize * size.width as usize + x as usize];
            // Faint reddish glow around the base (background lit by the flame).
            let dx = (x as f32 + 0.5 - 0.5 * w) / (0.45 * w);
            let dy = (y as f32 + 0.5 - 0.7 * h) / (0.45 * h);
            let glow = 0.05 * (-(dx * dx + dy * dy) * 2.0).exp();
            let c = flame_colour(hv, blue_root && (base_y - y as f32) < 0.08 * h, p.style);
            data.push([
                srgb_to_linear((c[0] + glow).min(1.0)),
                srgb_to_linear((c[1] + glow * 0.35).min(1.0)),
                srgb_to_linear((c[2] + glow * 0.1).min(1.0)),
                1.0,
            ]);
        }
    }
    RgbaFrame::from_vec(size, data)
}

/// sRGB-encoded colour of heat `h` in `0..=1`.
fn flame_colour(h: f32, blue: bool, style: FlameStyle) -> [f32; 3] {
    if h <= 0.0 {
        return [0.0; 3];
    }
    if blue && h < 0.8 {
        return [0.15 * h, 0.3 * h, 0.9 * h.sqrt()];
    }
    let (r, g, b) = match style {
        FlameStyle::Candle => (
            (1.6 * h).min(1.0),
            (1.3 * h - 0.05).clamp(0.0, 1.0),
            (1.5 * h - 0.8).clamp(0.0, 0.9),
        ),
        FlameStyle::Campfire => (
            (1.5 * h).min(1.0),
            (1.1 * h - 0.2).clamp(0.0, 1.0),
            (1.2 * h - 0.9).clamp(0.0, 0.6),
        ),
    };
    [r, g, b]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deterministic_and_distinct() {
        let p = SyntheticParams {
            frames: 3,
            ..Default::default()
        };
        let a = synthetic_clip(&p).unwrap();
        let b = synthetic_clip(&p).unwrap();
        assert_eq!(a, b);
        let c = synthetic_clip(&SyntheticParams {
            style: FlameStyle::Campfire,
            ..p.clone()
        })
        .unwrap();
        assert_ne!(a[0], c[0]);
        assert_ne!(a[0], a[1]);
        assert!(a[0].luminance().max() > 0.5);
    }
}
