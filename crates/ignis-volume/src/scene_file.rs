//! Writing a scene as a fire file ([`FireScene::to_toml`]): every setting spelt out with a
//! comment saying what it does, so a preset can be printed (`ignis volume scene --preset
//! torch > torch.toml`), edited and rendered. [`FireScene::from_toml`] reads the text back
//! to the same scene (tested for every preset), so the file renders the same bytes as the
//! preset.
//!
//! Written by hand rather than by `toml::to_string`: serde would write `0.45f32` as
//! `0.44999998807907104` (it widens to `f64`) and cannot write comments. Numbers here are
//! Rust's shortest round-trip form of each `f32`.

use crate::error::{Result, VolumeError};
use crate::motion::{Keyframe, Obstacle, SimParams};
use crate::noise::NoiseKind;
use crate::profile::FireProfile;
use crate::render::Blend;
use crate::scene::{FireScene, Motion};
use std::fmt::Write;

/// An `f32` as a TOML float that reads back to the same `f32` (always with a `.`, so it
/// reads as a float; `nan` / `inf` as TOML spells them).
fn num(x: f32) -> String {
    if x.is_nan() {
        return "nan".into();
    }
    if x.is_infinite() {
        return if x > 0.0 { "inf" } else { "-inf" }.into();
    }
    let s = format!("{x}");
    if s.contains(['.', 'e', 'E']) {
        s
    } else {
        s + ".0"
    }
}

/// An array of `f32` as a TOML array.
fn nums(xs: &[f32]) -> String {
    let v: Vec<String> = xs.iter().map(|&x| num(x)).collect();
    format!("[{}]", v.join(", "))
}

/// Control points `[x, y, z, radius]`, one per line.
fn points(ps: &[[f32; 4]]) -> String {
    let mut s = String::from("[\n");
    for p in ps {
        let _ = writeln!(s, "  {},", nums(p));
    }
    s.push(']');
    s
}

/// A `key = value` line with its comment aligned after it.
fn line(out: &mut String, key: &str, value: &str, comment: &str) {
    let kv = format!("{key} = {value}");
    if comment.is_empty() {
        let _ = writeln!(out, "{kv}");
    } else {
        let _ = writeln!(out, "{kv:<28} # {comment}");
    }
}

fn keyframes(out: &mut String, ks: &[Keyframe]) {
    for k in ks {
        out.push_str("[[fire.script.keyframes]]\n");
        line(out, "time", &num(k.time), "seconds");
        line(out, "points", &points(&k.points), "");
    }
}

fn simulation(out: &mut String, p: &SimParams) {
    out.push_str(
        "[fire.simulation]            # particles rising from the base carry the centre \
         curve (eq. 7-8)\n",
    );
    line(out, "source", &nums(&p.source), "where particles are born");
    line(
        out,
        "velocity",
        &nums(&p.velocity),
        "the fire's own velocity",
    );
    line(
        out,
        "rise_speed",
        &num(p.rise_speed),
        "a new particle's upward speed",
    );
    line(out, "temperature", &num(p.temperature), "at birth, K");
    line(out, "ambient", &num(p.ambient), "ambient temperature, K");
    line(out, "cooling", &num(p.cooling), "rate towards ambient, 1/s");
    line(out, "gravity", &num(p.gravity), "");
    line(
        out,
        "buoyancy",
        &num(p.buoyancy),
        "scale of the buoyancy term",
    );
    line(out, "wind", &nums(&p.wind), "constant wind velocity");
    line(out, "gust", &num(p.gust), "relative strength of gusts, 0-2");
    line(
        out,
        "dispersion",
        &num(p.dispersion),
        "a hot particle's sideways speed, units/s",
    );
    line(out, "lifetime", &num(p.lifetime), "age of the tip, seconds");
    line(
        out,
        "control_points",
        &p.control_points.to_string(),
        "of the centre curve (>= degree + 1)",
    );
    line(out, "radius", &num(p.radius), "at the base");
    line(out, "tip_radius", &num(p.tip_radius), "at the tip");
    line(
        out,
        "substeps",
        &p.substeps.to_string(),
        "integration steps per frame, 1-64",
    );
}

fn obstacle(out: &mut String, o: &Obstacle) {
    out.push_str("\n[[obstacle]]                 # a solid the fire cannot enter\n");
    match o {
        Obstacle::Sphere { centre, radius } => {
            line(out, "type", "\"sphere\"", "");
            line(out, "centre", &nums(centre), "");
            line(out, "radius", &num(*radius), "");
        }
        Obstacle::Plane { point, normal } => {
            line(out, "type", "\"plane\"", "");
            line(out, "point", &nums(point), "a point of the plane");
            line(out, "normal", &nums(normal), "the side the fire stays on");
        }
    }
}

impl FireScene {
    /// The scene as a commented fire file that [`FireScene::from_toml`] reads back to this
    /// same scene; `title` heads it (e.g. "the torch preset"). Every fire must have the
    /// built-in profile (a fire file names any other profile by its image's path, which a
    /// scene does not keep).
    pub fn to_toml(&self, title: &str) -> Result<String> {
        self.validate()?;
        let default_profile = FireProfile::default_profile();
        for (i, f) in self.fires.iter().enumerate() {
            if *f.profile != default_profile {
                return Err(VolumeError::bad(
                    format!("fire[{i}].profile"),
                    "an image profile cannot be written into a fire file (it names the image \
                     by its path); write the scene from its own fire file",
                ));
            }
        }
        let mut o = String::new();
        let _ = writeln!(o, "# Ignis fire file: {title}.");
        o.push_str(
            "# Render it with `ignis volume render THIS.toml -o fire.png` (options such as\n\
             # --size, --seed and --fps override the settings below). Every setting is\n\
             # optional except one [[fire]] with one motion: a `curve`, a `script` or a\n\
             # `simulation`. World units: z is up; each fire is a unit-radius flame swept\n\
             # along its centre curve (Fuller et al. 2007).\n\n",
        );
        line(
            &mut o,
            "seed",
            &self.seed.to_string(),
            "noise offsets and particle dispersion",
        );
        line(&mut o, "fps", &num(self.fps), "frames per second");
        line(
            &mut o,
            "diameter",
            &num(self.diameter),
            "metres: the fire puffs at 1.5/sqrt(D) Hz",
        );
        line(
            &mut o,
            "puff",
            &num(self.puff),
            "puffing amplitude at the tip, 0-0.5; 0 = none",
        );

        o.push_str("\n[camera]\n");
        line(&mut o, "position", &nums(&self.camera.position), "the eye");
        line(&mut o, "target", &nums(&self.camera.target), "looked at");
        line(
            &mut o,
            "fov",
            &num(self.camera.fov),
            "field of view across the frame's shorter side, degrees",
        );

        o.push_str("\n[render]\n");
        line(
            &mut o,
            "size",
            &format!("\"{}\"", self.size),
            "WIDTHxHEIGHT (--size scales the bloom with it)",
        );
        line(
            &mut o,
            "slice_spacing",
            &num(self.slice_spacing),
            "between view-aligned slices; smaller is finer",
        );
        line(
            &mut o,
            "lattice",
            &self.lattice.to_string(),
            "lattice levels along the curve",
        );
        let blend = match self.blend {
            Blend::Additive => "\"additive\"".to_string(),
            Blend::Cartoon => "\"cartoon\"".to_string(),
            Blend::Tint(t) => format!("{{ tint = {} }}", nums(&t)),
        };
        line(
            &mut o,
            "blend",
            &blend,
            "\"additive\", \"cartoon\" or { tint = [R, G, B] }",
        );
        line(
            &mut o,
            "intensity",
            &num(self.intensity),
            "emission per unit length (exposure)",
        );

        o.push_str("\n[bloom]                      # glow around the flame\n");
        line(
            &mut o,
            "passes",
            &self.bloom.passes.to_string(),
            "blur passes; 0 = no bloom",
        );
        line(
            &mut o,
            "radius",
            &num(self.bloom.radius),
            "pixels, the first pass's sigma",
        );
        line(
            &mut o,
            "radius_falloff",
            &num(self.bloom.radius_falloff),
            "each further pass's sigma, times this",
        );
        line(
            &mut o,
            "strength",
            &num(self.bloom.strength),
            "how much of each blur is added",
        );

        for f in &self.fires {
            o.push_str("\n[[fire]]\n");
            line(
                &mut o,
                "profile",
                "\"default\"",
                "or an RGBA image's path, relative to this file",
            );
            line(
                &mut o,
                "degree",
                &f.degree.to_string(),
                "of the centre curve's B-spline, 1-7",
            );
            let n = &f.noise;
            o.push_str("[fire.noise]                 # the turbulence (eq. 9-13)\n");
            let kind = match n.kind {
                NoiseKind::Perlin3 => "perlin3",
                NoiseKind::Perlin4 => "perlin4",
                NoiseKind::Mnoise => "mnoise",
            };
            line(
                &mut o,
                "kind",
                &format!("\"{kind}\""),
                "perlin3, perlin4 or mnoise",
            );
            line(
                &mut o,
                "octaves",
                &n.octaves.to_string(),
                "0-8; 0 = no noise",
            );
            line(&mut o, "gain", &num(n.gain), "amplitude factor per octave");
            line(
                &mut o,
                "lacunarity",
                &num(n.lacunarity),
                "frequency factor per octave",
            );
            line(
                &mut o,
                "frequency",
                &num(n.frequency),
                "spatial frequency of the detail",
            );
            line(
                &mut o,
                "stability",
                &num(n.stability),
                "more = more flicker at the top",
            );
            line(
                &mut o,
                "time_scale",
                &num(n.time_scale),
                "seconds to noise time: speed",
            );
            match n.offset {
                Some(off) => line(&mut o, "offset", &nums(&off), "in noise space"),
                None => o.push_str(
                    "# offset = [0.0, 0.0, 0.0, 0.0]  # in noise space; default: from the seed\n",
                ),
            }
            match &f.motion {
                Motion::Static(ps) => {
                    o.push_str(
                        "[fire.curve]                 # fixed control points [x, y, z, radius]\n",
                    );
                    line(&mut o, "points", &points(ps), "");
                }
                Motion::Script(s) => {
                    o.push_str(
                        "[fire.script]                # keyframed control points \
                         [x, y, z, radius]\n",
                    );
                    line(
                        &mut o,
                        "looped",
                        &s.looped.to_string(),
                        "repeat after the last keyframe",
                    );
                    keyframes(&mut o, &s.keyframes);
                }
                Motion::Simulation(p) => simulation(&mut o, p),
            }
        }
        for ob in &self.obstacles {
            obstacle(&mut o, ob);
        }
        Ok(o)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::{FireSpec, Preset};
    use std::path::Path;

    fn read(text: &str) -> FireScene {
        FireScene::from_toml(text, Path::new("."), &mut |p| {
            Err(format!("no image loader in this test ({})", p.display()))
        })
        .unwrap_or_else(|e| panic!("{e}\n{text}"))
    }

    #[test]
    fn every_preset_reads_back_as_itself() {
        for p in Preset::ALL {
            let s = FireScene::preset(p);
            let text = s.to_toml(&format!("the {} preset", p.name())).unwrap();
            assert_eq!(read(&text), s, "{}:\n{text}", p.name());
            assert!(text.contains("[[fire]]") && text.contains("# "), "{text}");
        }
    }

    #[test]
    fn every_kind_of_setting_reads_back() {
        let mut s =
            FireScene::preset(Preset::Wall).with_size(ignis_core::Size::new(100, 37).unwrap());
        s.seed = u64::MAX;
        s.blend = Blend::Tint([0.3, 0.5, 1.0]);
        s.obstacles = vec![
            Obstacle::Plane {
                point: [0.0, 0.0, 2.5],
                normal: [0.0, 0.0, -1.0],
            },
            Obstacle::Sphere {
                centre: [0.1, -0.2, 1.0 / 3.0],
                radius: 0.7,
            },
        ];
        s.fires[0].noise.offset = Some([0.1, 1e-7, -3.0, 123456.79]);
        s.fires[0].noise.kind = NoiseKind::Mnoise;
        s.fires[1] = FireSpec::new(Motion::Simulation(SimParams::default()));
        s.bloom.passes = 0;
        let text = s.to_toml("a test").unwrap();
        assert_eq!(read(&text), s, "{text}");
        // the same when the blend is cartoon and numbers are awkward
        s.blend = Blend::Cartoon;
        s.intensity = std::f32::consts::PI;
        s.slice_spacing = f32::MIN_POSITIVE * 1e6;
        let text = s.to_toml("a test").unwrap();
        assert_eq!(read(&text), s, "{text}");
    }

    #[test]
    fn numbers_read_back_exactly() {
        for x in [
            0.0f32,
            -0.0,
            1.0,
            0.45,
            1e-30,
            3.0e20,
            16777217.0,
            f32::MAX,
            0.1 + 0.2,
        ] {
            let t = format!("x = {}", num(x));
            let v: toml::Value = toml::from_str(&t).unwrap();
            let back = v["x"].as_float().unwrap() as f32;
            assert_eq!(back.to_bits(), x.to_bits(), "{t}");
        }
    }

    #[test]
    fn an_image_profile_is_refused_by_name() {
        let mut s = FireScene::preset(Preset::Torch);
        let mut p = FireProfile::default_profile().to_frame();
        let mid = p.data().len() / 2;
        p.data_mut()[mid] = [1.0, 0.0, 0.0, 1.0];
        s.fires[0].profile = std::sync::Arc::new(FireProfile::from_frame(&p).unwrap());
        let e = s.to_toml("x").unwrap_err().to_string();
        assert!(e.contains("fire[0].profile") && e.contains("image"), "{e}");
    }
}
