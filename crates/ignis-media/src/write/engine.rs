//! Engine presets for flipbooks: the conventions each engine's importer and material
//! expect, and the metadata keys they need, written into the flipbook JSON under
//! `engine_settings` with the engine's own parameter names.
//!
//! Every preset writes the same sheet layout: row-major, the first frame in the top-left
//! cell (Unity's Texture Sheet Animation / Shader Graph Flipbook, Unreal's SubUV, Godot's
//! particle animation and SideFX Labs' texture sheets all read it so). What differs:
//!
//! | preset | UV origin | motion-vector green | alpha | padding |
//! |---|---|---|---|---|
//! | `generic` | top-left | +y down | straight | as given |
//! | `unity` | bottom-left (Shader Graph Flipbook needs Invert Y) | +v up | straight | ≥ 2 |
//! | `unreal` | top-left | +v down | straight | ≥ 2 |
//! | `godot` | top-left | +v down | premultiplied (`blend_mode = premul_alpha`) | ≥ 2 |
//! | `sidefx` | bottom-left (Houdini UVs) | +v up ("green flipped" vs. the image) | straight | ≥ 2 |
//!
//! Colour is 8-bit sRGB (import as sRGB); motion vectors and heat are linear data (import
//! with sRGB off, uncompressed).

use super::flipbook::AlphaMode;
use serde_json::{json, Value};

/// A target engine.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Engine {
    /// Top-left origin, +y down motion, settings from the options as given.
    #[default]
    Generic,
    /// Unity: Particle System Texture Sheet Animation, VFX Graph, Shader Graph Flipbook.
    Unity,
    /// Unreal: Cascade/Niagara SubUV, material Flipbook / SubUV with motion vectors.
    Unreal,
    /// Godot 4: CanvasItemMaterial / StandardMaterial3D particles animation.
    Godot,
    /// SideFX Labs game-development texture sheets and shaders.
    Sidefx,
}

/// The conventions a preset sets.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Conventions {
    /// Whether the engine's UV `v` grows upwards (origin bottom-left).
    pub v_up: bool,
    /// Alpha the engine's default particle material expects.
    pub alpha: AlphaMode,
    /// Smallest padding (extruded edge pixels per side) the preset writes.
    pub min_padding: u32,
}

impl Engine {
    /// All presets, in CLI order.
    pub const ALL: [Engine; 5] = [
        Engine::Unity,
        Engine::Unreal,
        Engine::Godot,
        Engine::Sidefx,
        Engine::Generic,
    ];

    /// The preset's CLI name.
    pub fn name(self) -> &'static str {
        match self {
            Engine::Generic => "generic",
            Engine::Unity => "unity",
            Engine::Unreal => "unreal",
            Engine::Godot => "godot",
            Engine::Sidefx => "sidefx",
        }
    }

    /// Parses a CLI name.
    pub fn from_name(s: &str) -> Option<Engine> {
        Engine::ALL.into_iter().find(|e| e.name() == s)
    }

    /// The preset's conventions.
    pub fn conventions(self) -> Conventions {
        let (v_up, alpha, min_padding) = match self {
            Engine::Generic => (false, AlphaMode::Straight, 0),
            Engine::Unity => (true, AlphaMode::Straight, 2),
            Engine::Unreal => (false, AlphaMode::Straight, 2),
            Engine::Godot => (false, AlphaMode::Premultiplied, 2),
            Engine::Sidefx => (true, AlphaMode::Straight, 2),
        };
        Conventions {
            v_up,
            alpha,
            min_padding,
        }
    }
}

/// What the engine settings are computed from.
pub(crate) struct SettingsInput {
    pub columns: u32,
    pub rows: u32,
    pub frames: u32,
    pub fps: f64,
    pub loop_: bool,
    pub variants: u32,
    pub alpha: AlphaMode,
    /// Motion-vector strength in tile-UV units, when a motion sheet is written.
    pub mv_scale: Option<f32>,
}

impl SettingsInput {
    /// The strength as the JSON shows it (the f32 value's shortest decimal).
    fn scale(&self) -> Option<f64> {
        self.mv_scale.and_then(|s| format!("{s}").parse().ok())
    }
}

/// The engine's own parameter names and the values this flipbook needs (JSON object).
pub(crate) fn settings(engine: Engine, s: &SettingsInput) -> Value {
    let premul = s.alpha == AlphaMode::Premultiplied;
    match engine {
        Engine::Generic => json!({
            "columns": s.columns,
            "rows": s.rows,
            "frames": s.frames,
            "fps": s.fps,
            "loop": s.loop_,
            "motion_vector_scale": s.scale(),
        }),
        Engine::Unity => json!({
            "Texture Sheet Animation": {
                "Mode": "Grid",
                "Tiles": { "X": s.columns, "Y": s.rows },
                "Animation": if s.variants > 1 { "Single Row" } else { "Whole Sheet" },
                "Row Mode": if s.variants > 1 { "Random" } else { "Custom" },
                "Time Mode": "FPS",
                "FPS": s.fps,
                "Cycles": 1,
            },
            "VFX Graph": {
                "Flipbook Size": { "x": s.columns, "y": s.rows },
                "UV Mode": if s.mv_scale.is_some() { "FlipbookMotionBlend" } else { "Flipbook" },
                "Motion Vector Scale": s.scale(),
            },
            "Shader Graph Flipbook": { "Width": s.columns, "Height": s.rows, "Invert Y": true },
            "Import": { "Color sRGB": true, "Alpha Is Transparency": !premul, "Motion vectors sRGB": false, "Compression": "None" },
        }),
        Engine::Unreal => json!({
            "SubImages_Horizontal": s.columns,
            "SubImages_Vertical": s.rows,
            "SubUV": { "SubImage Index": "frame + blend (0 .. frames)", "FrameRate": s.fps, "Frames": s.frames },
            "Motion Vector Strength": s.scale(),
            "Texture": { "Color sRGB": true, "Motion vectors sRGB": false, "Motion vectors Compression Settings": "VectorDisplacementmap (RGBA8) or HDR (RGBA16F), uncompressed" },
        }),
        Engine::Godot => json!({
            "particles_anim_h_frames": s.columns,
            "particles_anim_v_frames": s.rows,
            "particles_anim_loop": s.loop_,
            "blend_mode": if premul { "premul_alpha" } else { "mix" },
            "anim_speed_fps": s.fps,
            "motion_vector_scale": s.scale(),
        }),
        Engine::Sidefx => json!({
            "Rows": s.rows,
            "Columns": s.columns,
            "Total Frames": s.frames,
            "FPS": s.fps,
            "Motion Vector Strength": s.scale(),
            "Green Flipped": true,
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip() {
        for e in Engine::ALL {
            assert_eq!(Engine::from_name(e.name()), Some(e));
        }
        assert_eq!(Engine::from_name("frostbite"), None);
    }
}
