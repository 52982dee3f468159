//! Scenes: fires, camera, obstacles and render settings, from a TOML fire file or a preset,
//! and the animator that steps them frame by frame.
//!
//! A fire file (all fields optional except at least one `[[fire]]` with one motion):
//!
//! ```toml
//! seed = 7
//! fps = 30.0
//! diameter = 0.3           # the fire's base diameter in metres: it puffs at 1.5/√D Hz
//! puff = 0.4               # amplitude of that puffing (radius ±40 % at the tip), 0 = none
//! [camera]
//! position = [0.0, -7.0, 1.5]
//! target = [0.0, 0.0, 1.5]
//! fov = 40.0
//! [render]
//! size = "256x256"
//! slice_spacing = 0.05     # world units, > 0
//! lattice = 35             # lattice resolution c
//! blend = "additive"       # or "cartoon", or { tint = [0.3, 0.5, 1.0] }
//! intensity = 2.5
//! [bloom]                  # ignis-core BloomParams; passes = 0 disables
//! passes = 2
//! radius = 8.0
//! [[fire]]
//! profile = "default"      # or an image path, relative to the fire file
//! degree = 3
//! noise = { kind = "perlin4", octaves = 3, frequency = 1.0, stability = 0.35 }
//! curve = { points = [[0,0,0,1], [0,0,1,0.9], [0,0,2,0.7], [0,0,3,0.4]] }  # [x, y, z, radius]
//! # or: [fire.script] looped = true, [[fire.script.keyframes]] time = 0.0, points = [...]
//! # or: [fire.simulation] wind = [0.5, 0, 0], control_points = 6, ...
//! [[obstacle]]
//! type = "plane"           # or "sphere" with centre and radius
//! point = [0.0, 0.0, 2.5]
//! normal = [0.0, 0.0, -1.0]
//! ```

use crate::error::{Result, VolumeError};
use crate::lattice::{Lattice, Puff};
pub use crate::looping::loop_blend_frames;
use crate::looping::{LoopScript, LoopTiming, Looping, PreviewDistances, SimTrack};
use crate::mapping::NoiseParams;
use crate::motion::{
    deflect_points, Collision, Keyframe, Obstacle, ParticleSim, Script, SimParams,
};
use crate::noise::NoiseKind;
use crate::profile::FireProfile;
use crate::render::{finish, render, Blend, Camera, FireInstance, RenderParams, RenderStats};
use crate::spline::BSpline;
use ignis_core::post::BloomParams;
use ignis_core::{RgbaFrame, Rng, Size};

/// The longest loop [`FireScene::looping_animator`] times, in frames (2²⁰: 9.7 hours at
/// 30 fps). The timing keeps a few hundred bytes a frame (the loop times, the preview's
/// distances, a simulation's control points) and renders two preview frames per frame,
/// so an unbounded `--frames` would be an unbounded allocation.
pub const MAX_LOOP_FRAMES: u32 = 1 << 20;

/// Preview frames rendered side by side before their distances are taken: a bound on the
/// preview's memory (at 64 px, 4 MB) that keeps both threads busy.
const PREVIEW_BATCH: usize = 256;
use serde::Deserialize;
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// How a fire's control points move.
#[derive(Clone, Debug, PartialEq)]
pub enum Motion {
    /// Fixed control points `[x, y, z, radius]`.
    Static(Vec<[f32; 4]>),
    /// Scripted keyframes.
    Script(Script),
    /// Particle simulation (eq. 7–8).
    Simulation(SimParams),
}

/// One fire of a scene.
#[derive(Clone, Debug, PartialEq)]
pub struct FireSpec {
    pub profile: Arc<FireProfile>,
    /// Degree of the centre curve (1–7). Default 3.
    pub degree: usize,
    pub noise: NoiseParams,
    pub motion: Motion,
}

impl FireSpec {
    /// A fire with the default profile and noise.
    pub fn new(motion: Motion) -> FireSpec {
        FireSpec {
            profile: Arc::new(FireProfile::default_profile()),
            degree: 3,
            noise: NoiseParams::default(),
            motion,
        }
    }
}

/// The built-in scenes (`ignis volume render --preset ...`, `ignis demo`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Preset {
    Torch,
    Candle,
    Campfire,
    Wall,
}

impl Preset {
    pub const ALL: [Preset; 4] = [
        Preset::Torch,
        Preset::Candle,
        Preset::Campfire,
        Preset::Wall,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Preset::Torch => "torch",
            Preset::Candle => "candle",
            Preset::Campfire => "campfire",
            Preset::Wall => "wall",
        }
    }
}

impl std::str::FromStr for Preset {
    type Err = VolumeError;
    fn from_str(s: &str) -> Result<Preset> {
        Preset::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| {
                VolumeError::bad(
                    "preset",
                    format!("`{s}`; choose torch, candle, campfire or wall"),
                )
            })
    }
}

/// Everything needed to render an animation.
#[derive(Clone, Debug, PartialEq)]
pub struct FireScene {
    /// Seed of every random choice (per-fire noise offsets, particle dispersion).
    pub seed: u64,
    /// Frames per second of the animation (> 0). Default 30.
    pub fps: f32,
    /// Physical size of the fire: its base diameter in metres (> 0), which sets how fast
    /// it puffs (`1.5/√D` Hz, Cetegen & Ahmed 1993; [`ignis_core::realism`]). Independent
    /// of the scene's world units. Default 0.3 (a small campfire).
    pub diameter: f32,
    /// Puffing (Cetegen & Ahmed 1993): relative amplitude, `0..=0.5`, of the neck-and-bulge
    /// wave that travels up the flame at the puffing frequency `1.5/√diameter` Hz
    /// ([`Puff`]: the radius swings by this fraction at the tip). 0 = none.
    /// Default 0.
    pub puff: f32,
    pub camera: Camera,
    /// Output size. Default 256×256.
    pub size: Size,
    /// Distance between view-aligned slices, world units (> 0). Default 0.05.
    pub slice_spacing: f32,
    /// Lattice resolution `c` (levels), 2–4096. Default 35.
    pub lattice: usize,
    pub blend: Blend,
    /// See [`RenderParams::intensity`]. Default 2.5.
    pub intensity: f32,
    /// Post bloom (ignis-core). Default: 2 passes, radius 6 % of the image height.
    pub bloom: BloomParams,
    pub fires: Vec<FireSpec>,
    pub obstacles: Vec<Obstacle>,
}

// ---- fire file -------------------------------------------------------------------------

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileScene {
    #[serde(default)]
    seed: u64,
    fps: Option<f32>,
    diameter: Option<f32>,
    puff: Option<f32>,
    #[serde(default)]
    camera: Camera,
    #[serde(default)]
    render: FileRender,
    bloom: Option<BloomParams>,
    #[serde(default)]
    fire: Vec<FileFire>,
    #[serde(default)]
    obstacle: Vec<Obstacle>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct FileRender {
    size: Option<String>,
    slice_spacing: Option<f32>,
    lattice: Option<usize>,
    blend: Option<Blend>,
    intensity: Option<f32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileFire {
    profile: Option<String>,
    degree: Option<usize>,
    #[serde(default)]
    noise: NoiseParams,
    curve: Option<FileCurve>,
    script: Option<Script>,
    simulation: Option<SimParams>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FileCurve {
    points: Vec<[f32; 4]>,
}

/// Prefixes the field of a [`VolumeError::BadParameter`].
fn within(prefix: &str, e: VolumeError) -> VolumeError {
    match e {
        VolumeError::BadParameter { field, reason } => VolumeError::BadParameter {
            field: format!("{prefix}.{field}"),
            reason,
        },
        other => other,
    }
}

/// The frame's shorter side, in pixels: the side the camera's field of view spans.
fn shorter_side(size: Size) -> f32 {
    size.width.min(size.height) as f32
}

/// The bloom's default: its radius 6 % of the frame's shorter side, so the glow keeps its
/// size relative to the fire.
fn default_bloom(size: Size) -> BloomParams {
    BloomParams {
        passes: 2,
        radius: (shorter_side(size) * 0.06).max(1.0),
        radius_falloff: 0.5,
        strength: 0.3,
    }
}

impl FireScene {
    /// A scene with no fires and default settings.
    pub fn empty() -> FireScene {
        let size = Size::new(256, 256).expect("valid");
        FireScene {
            seed: 0,
            fps: 30.0,
            diameter: 0.3,
            puff: 0.0,
            camera: Camera::default(),
            size,
            slice_spacing: 0.05,
            lattice: 35,
            blend: Blend::Additive,
            intensity: 2.5,
            bloom: default_bloom(size),
            fires: Vec::new(),
            obstacles: Vec::new(),
        }
    }

    /// Parses a fire file. Relative profile paths are resolved against `base_dir`; images
    /// are loaded by `load_image` (the library does not decode files: the CLI passes
    /// `ignis_media::read_image`). Every error names the offending field.
    pub fn from_toml(
        text: &str,
        base_dir: &Path,
        load_image: &mut dyn FnMut(&Path) -> std::result::Result<RgbaFrame, String>,
    ) -> Result<FireScene> {
        let file: FileScene =
            toml::from_str(text).map_err(|e| VolumeError::Parse(e.to_string()))?;
        let mut s = FireScene::empty();
        s.seed = file.seed;
        if let Some(f) = file.fps {
            s.fps = f;
        }
        if let Some(d) = file.diameter {
            s.diameter = d;
        }
        if let Some(p) = file.puff {
            s.puff = p;
        }
        s.camera = file.camera;
        if let Some(sz) = &file.render.size {
            s.size = sz
                .parse::<Size>()
                .map_err(|e| VolumeError::bad("render.size", e.to_string()))?;
        }
        if let Some(v) = file.render.slice_spacing {
            s.slice_spacing = v;
        }
        if let Some(v) = file.render.lattice {
            s.lattice = v;
        }
        if let Some(v) = file.render.blend {
            s.blend = v;
        }
        if let Some(v) = file.render.intensity {
            s.intensity = v;
        }
        s.bloom = file.bloom.unwrap_or_else(|| default_bloom(s.size));
        s.obstacles = file.obstacle;
        if file.fire.is_empty() {
            return Err(VolumeError::bad(
                "fire",
                "the file has no [[fire]]; add at least one",
            ));
        }
        let default_profile = Arc::new(FireProfile::default_profile());
        for (i, f) in file.fire.into_iter().enumerate() {
            let field = format!("fire[{i}]");
            let profile = match f.profile.as_deref() {
                None | Some("default") => default_profile.clone(),
                Some(p) => {
                    let path: PathBuf = if Path::new(p).is_absolute() {
                        PathBuf::from(p)
                    } else {
                        base_dir.join(p)
                    };
                    if !path.exists() {
                        return Err(VolumeError::Image {
                            field: format!("{field}.profile"),
                            path,
                            reason: "no such file".into(),
                        });
                    }
                    let img = load_image(&path).map_err(|reason| VolumeError::Image {
                        field: format!("{field}.profile"),
                        path: path.clone(),
                        reason,
                    })?;
                    Arc::new(FireProfile::from_frame(&img).map_err(|e| within(&field, e))?)
                }
            };
            let motion = match (f.curve, f.script, f.simulation) {
                (Some(c), None, None) => Motion::Static(c.points),
                (None, Some(s), None) => Motion::Script(s),
                (None, None, Some(p)) => Motion::Simulation(p),
                (None, None, None) => {
                    return Err(VolumeError::bad(
                        field,
                        "needs one of `curve`, `script` or `simulation`",
                    ))
                }
                _ => {
                    return Err(VolumeError::bad(
                        field,
                        "give only one of `curve`, `script` or `simulation`",
                    ))
                }
            };
            s.fires.push(FireSpec {
                profile,
                degree: f.degree.unwrap_or(3),
                noise: f.noise,
                motion,
            });
        }
        s.validate()?;
        Ok(s)
    }

    /// Checks every setting; errors name the field as it is spelt in a fire file.
    pub fn validate(&self) -> Result<()> {
        if !(self.fps > 0.0 && self.fps <= 1000.0) {
            return Err(VolumeError::bad(
                "fps",
                format!("{}; use (0, 1000]", self.fps),
            ));
        }
        if !(self.diameter > 0.0 && self.diameter <= 1000.0) {
            return Err(VolumeError::bad(
                "diameter",
                format!(
                    "{} m; give the fire's physical base diameter in metres, in (0, 1000] (a candle 0.02, a campfire 0.4)",
                    self.diameter
                ),
            ));
        }
        if !(0.0..=0.5).contains(&self.puff) {
            return Err(VolumeError::bad(
                "puff",
                format!("{}; use 0 (no puffing) to 0.5", self.puff),
            ));
        }
        self.camera.validate()?;
        self.render_params().validate()?;
        if !(2..=4096).contains(&self.lattice) {
            return Err(VolumeError::bad(
                "render.lattice",
                format!("{}; use 2 to 4096", self.lattice),
            ));
        }
        self.bloom
            .validate()
            .map_err(|e| VolumeError::bad("bloom", e.to_string()))?;
        if self.fires.len() > 256 {
            return Err(VolumeError::bad("fire", "at most 256 fires"));
        }
        for (i, o) in self.obstacles.iter().enumerate() {
            o.validate(&format!("obstacle[{i}]"))?;
        }
        for (i, f) in self.fires.iter().enumerate() {
            let field = format!("fire[{i}]");
            let n = &f.noise;
            if n.octaves > 8 {
                return Err(VolumeError::bad(
                    format!("{field}.noise.octaves"),
                    format!("{}; use 0 to 8", n.octaves),
                ));
            }
            for (name, v) in [
                ("gain", n.gain),
                ("lacunarity", n.lacunarity),
                ("frequency", n.frequency),
                ("stability", n.stability),
                ("time_scale", n.time_scale),
            ] {
                if !v.is_finite() || v < 0.0 {
                    return Err(VolumeError::bad(
                        format!("{field}.noise.{name}"),
                        format!("{v}; must be finite and ≥ 0"),
                    ));
                }
            }
            if n.offset.is_some_and(|o| o.iter().any(|v| !v.is_finite())) {
                return Err(VolumeError::bad(
                    format!("{field}.noise.offset"),
                    "must be finite",
                ));
            }
            match &f.motion {
                Motion::Static(pts) => {
                    BSpline::new(pts.clone(), f.degree)
                        .map_err(|e| within(&format!("{field}.curve"), e))?;
                }
                Motion::Script(s) => {
                    s.validate(&format!("{field}.script"))?;
                    for (k, kf) in s.keyframes.iter().enumerate() {
                        BSpline::new(kf.points.clone(), f.degree)
                            .map_err(|e| within(&format!("{field}.script.keyframes[{k}]"), e))?;
                    }
                }
                Motion::Simulation(p) => {
                    if !(1..=7).contains(&f.degree) {
                        return Err(VolumeError::bad(format!("{field}.degree"), "use 1 to 7"));
                    }
                    p.validate(&format!("{field}.simulation"), f.degree)?;
                    // A step longer than a particle's life emits `step / interval`
                    // particles that all die within it: nothing is left to draw, and the
                    // burst grows without bound as the step does (a frame rate of 1e-6
                    // asked for gigabytes). At most a lifetime a step, a step emits at most
                    // `3 (control points − 1) + 1` particles.
                    let step = 1.0 / (f64::from(self.fps) * p.substeps.max(1) as f64);
                    if step > f64::from(p.lifetime) {
                        let need = (1.0 / f64::from(p.lifetime) / f64::from(self.fps)).ceil();
                        let fix = if need <= 64.0 {
                            format!("use substeps ≥ {need} or a higher fps")
                        } else {
                            let fps = 1.0 / (64.0 * f64::from(p.lifetime));
                            format!("use fps ≥ {fps:.3} with substeps = 64, or a longer lifetime")
                        };
                        return Err(VolumeError::bad(
                            format!("{field}.simulation.substeps"),
                            format!(
                                "{}: at {} fps a simulation step is {step:.3} s, longer than the \
                                 particles' lifetime of {} s, so every particle would be born \
                                 and die within one step; {fix}",
                                p.substeps, self.fps, p.lifetime
                            ),
                        ));
                    }
                }
            }
        }
        Ok(())
    }

    /// The renderer settings of this scene.
    pub fn render_params(&self) -> RenderParams {
        RenderParams {
            size: self.size,
            slice_spacing: self.slice_spacing,
            blend: self.blend,
            intensity: self.intensity,
            exact_inverse: false,
            count_coverage: false,
            loop_period: None,
        }
    }

    /// Sets the output size (and rescales the bloom radius with its shorter side, which
    /// the camera's field of view spans).
    pub fn with_size(mut self, size: Size) -> FireScene {
        let r = self.bloom.radius / shorter_side(self.size);
        self.bloom.radius = (r * shorter_side(size)).max(1.0);
        self.size = size;
        self
    }

    /// The noise offset of fire `i` (its own, or derived from the seed).
    pub fn offset(&self, i: usize) -> [f32; 4] {
        self.fires[i].noise.offset.unwrap_or_else(|| {
            let mut r = Rng::derive(self.seed, 0x0ff5e7 + i as u64);
            [0; 4].map(|_| r.uniform(0.0, 200.0) as f32)
        })
    }

    /// Phase offset (radians) of fire `i`'s puffing: the fires of one scene puff nearly
    /// together (within a quarter cycle), as the parts of one fire do.
    pub fn puff_offset(&self, i: usize) -> f32 {
        let mut r = Rng::derive(self.seed, 0x9f0f + i as u64);
        r.uniform(0.0, std::f64::consts::FRAC_PI_2) as f32
    }

    /// A checked animator starting at frame 0.
    pub fn animator(&self) -> Result<Animator<'_>> {
        self.validate()?;
        let sims = self
            .fires
            .iter()
            .enumerate()
            .map(|(i, f)| match &f.motion {
                Motion::Simulation(p) => Some(ParticleSim::new(
                    p.clone(),
                    Rng::derive(self.seed, 0x5133 + i as u64).next_u64(),
                    &self.obstacles,
                )),
                _ => None,
            })
            .collect();
        let mut a = Animator {
            scene: self,
            sims,
            frame: 0,
            count_coverage: false,
            looping: None,
            scroll: Vec::new(),
        };
        a.scroll = a.scroll_lengths()?;
        Ok(a)
    }

    /// A checked animator for a seamless loop of `frames` frames (at most
    /// [`MAX_LOOP_FRAMES`]): frame `frames` (which
    /// is never rendered) would equal frame 0, so the frames play as a loop with no jump,
    /// and every step, the seam included, covers about the same distance
    /// ([`FireScene::looping_animator_with`] with [`LoopTiming::DEFAULT`]).
    ///
    /// Fails for fewer than 2 frames.
    pub fn looping_animator(&self, frames: u32) -> Result<Animator<'_>> {
        self.looping_animator_with(frames, LoopTiming::DEFAULT)
    }

    /// [`FireScene::looping_animator`] with the frames timed by `timing`
    /// ([`crate::looping`]): the animation is a periodic function of loop time, and
    /// its frames are rendered at the loop times where a preview says consecutive frames
    /// differ equally ([`crate::looping::even_step_times`]).
    ///
    /// - The noise is periodic with the loop ([`crate::mapping::PeriodicLoop`], else
    ///   [`crate::mapping::LoopMix`]).
    /// - A script repeats a whole number of times per loop: its period (keys that do not
    ///   end on the first pose are closed by returning to it) is stretched to the nearest
    ///   whole fraction of the loop, and its keys are joined by a periodic cubic spline.
    /// - A simulation's tail is blended into its head in control-point space: the loop's
    ///   first [`loop_blend_frames`] frames move from the simulation's state one loop later
    ///   to its own, so frame `frames − 1` is followed by the simulation's own successor;
    ///   between whole frames its control points are interpolated linearly.
    ///
    /// The preview is rendered here, from the whole loop, so every chunk of a render
    /// (an animator [`Animator::skip`]ping to its first frame) times its frames the same.
    /// Fails for fewer than 2 frames.
    pub fn looping_animator_with(&self, frames: u32, timing: LoopTiming) -> Result<Animator<'_>> {
        if frames < 2 {
            return Err(VolumeError::bad(
                "loop",
                format!(
                    "{frames} frame(s) cannot loop; ask for at least 2 frames or turn the loop off"
                ),
            ));
        }
        if frames > MAX_LOOP_FRAMES {
            return Err(VolumeError::bad(
                "loop",
                format!(
                    "a loop of {frames} frames is longer than the longest Ignis times \
                     ({MAX_LOOP_FRAMES} frames, {:.1} hours at {} fps); loop fewer frames and \
                     play the loop over, or turn the loop off",
                    f64::from(MAX_LOOP_FRAMES) / f64::from(self.fps) / 3600.0,
                    self.fps
                ),
            ));
        }
        let mut a = self.animator()?;
        let n = frames as usize;
        let blend = loop_blend_frames(frames) as usize;
        let dt = 1.0 / self.fps;
        let loop_len = frames as f32 * dt;
        let mut scripts = Vec::with_capacity(self.fires.len());
        let mut sims = Vec::with_capacity(self.fires.len());
        for (i, f) in self.fires.iter().enumerate() {
            let mut script = None;
            let mut track = None;
            match &f.motion {
                Motion::Static(_) => {}
                Motion::Script(sc) => script = Some(LoopScript::new(sc, loop_len)),
                Motion::Simulation(_) => {
                    // the simulation's states at frames 0 .. n + blend (one loop and its head)
                    let mut sim = a.sims[i].clone().expect("a simulation per simulated fire");
                    let mut states = vec![sim.control_points()];
                    let mut hits = vec![Vec::new()];
                    for _ in 1..n + blend {
                        hits.push(sim.advance(dt, &self.obstacles, i));
                        states.push(sim.control_points());
                    }
                    track = Some(SimTrack::new(states, hits, n, blend));
                }
            }
            scripts.push(script);
            sims.push(track);
        }
        let mut looping = Looping {
            frames: frames as u64,
            times: (0..n).map(|k| k as f64).collect(),
            scripts: scripts.into(),
            sims: sims.into(),
        };
        if timing.retimes() {
            looping.times = self.constant_speed_times(&a, &looping, timing)?.into();
        }
        a.looping = Some(looping);
        Ok(a)
    }

    /// [`FireScene::looping_animator`] with its frames' loop times given instead of
    /// measured on a preview: those an earlier looping animator of this same scene and
    /// loop length computed ([`Animator::loop_times`]), kept by the caller (a render
    /// farm's chunks, a second output of one render). The frames are then those of that
    /// animator, bit for bit, and no preview is rendered. Times of another scene still make
    /// a seamless loop, only with less even steps. Errors on times no loop has: not
    /// `frames` of them, not starting at 0, decreasing, or outside `0..frames`.
    pub fn looping_animator_with_times(&self, frames: u32, times: &[f64]) -> Result<Animator<'_>> {
        let bad = |why: String| {
            Err(VolumeError::bad(
                "loop",
                format!("loop times {why}; render without them to measure new ones"),
            ))
        };
        if times.len() != frames as usize {
            return bad(format!(
                "for {} frames given to a loop of {frames}",
                times.len()
            ));
        }
        if times.first().is_some_and(|&t| t != 0.0) {
            return bad("that do not start at 0".into());
        }
        if let Some(t) = times
            .iter()
            .find(|t| !(t.is_finite() && (0.0..f64::from(frames)).contains(*t)))
        {
            return bad(format!("with {t}, outside the loop's 0..{frames}"));
        }
        if times.windows(2).any(|w| w[1] < w[0]) {
            return bad("that go backwards".into());
        }
        let mut a = self.looping_animator_with(frames, LoopTiming::UNIFORM)?;
        if let Some(l) = a.looping.as_mut() {
            l.times = times.into();
        }
        Ok(a)
    }

    /// The loop times at which the frames of `looping` cover equal distances: measured on
    /// a preview `timing.preview_width` pixels wide (at most the metric frames' width) at
    /// `timing.samples_per_frame` uniform loop times per frame ([`crate::looping`]).
    fn constant_speed_times(
        &self,
        a: &Animator<'_>,
        looping: &Looping,
        timing: LoopTiming,
    ) -> Result<Vec<f64>> {
        let w = timing
            .preview_width
            .min(ignis_core::loopq::metric_size(self.size).width)
            .max(1);
        let h = (f64::from(w) * f64::from(self.size.height) / f64::from(self.size.width))
            .round()
            .max(1.0) as u32;
        let small = self
            .clone()
            .with_size(Size::new(w, h).map_err(|e| VolumeError::bad("size", e.to_string()))?);
        let k = timing.samples_per_frame as usize;
        let m = looping.frames as usize * k;
        let probe_looping = Looping {
            times: (0..m).map(|j| j as f64 / k as f64).collect(),
            ..looping.clone()
        };
        // A loop's frames are functions of their loop time alone, so the preview's small
        // frames render side by side, one per thread, rather than one at a time split into
        // tiles (a 64-px frame is too little work to share: the pool's threads spent more
        // time waking and spinning than sampling). The same frames, in order, a batch at a
        // time: the distances need only the latest few, so memory stays bounded however
        // long the loop.
        use rayon::prelude::*;
        let bad = |e: String| VolumeError::bad("loop", e);
        let mut d = PreviewDistances::builder(m, looping.frames as u32).map_err(bad)?;
        for batch in (0..m).step_by(PREVIEW_BATCH) {
            let metric: Vec<ignis_core::GrayFrame> = (batch..(batch + PREVIEW_BATCH).min(m))
                .into_par_iter()
                .map(|j| {
                    let mut probe = Animator {
                        scene: &small,
                        sims: Vec::new(),
                        frame: j as u64,
                        count_coverage: false,
                        looping: Some(probe_looping.clone()),
                        scroll: a.scroll.clone(),
                    };
                    // the metric frame of `next_frame`'s image, made without that image
                    let (hdr, ..) = probe.next_hdr()?;
                    crate::render::preview_metric(&hdr, &small.bloom)
                })
                .collect::<Result<_>>()?;
            for f in metric {
                d.push(f).map_err(bad)?;
            }
        }
        Ok(d.finish().map_err(bad)?.even_step_times())
    }

    // (Long: data, one match arm per preset.)
    /// The built-in scenes.
    pub fn preset(p: Preset) -> FireScene {
        let mut s = FireScene::empty();
        s.seed = 1;
        match p {
            Preset::Candle => {
                s.puff = 0.4;
                // a candle flame, about 2 cm across
                s.diameter = 0.02;
                let pose = |dx: f32| {
                    vec![
                        [0.0, 0.0, 0.0, 0.22],
                        [0.3 * dx, 0.0, 0.35, 0.2],
                        [dx, 0.0, 0.75, 0.14],
                        [1.8 * dx, 0.0, 1.1, 0.05],
                    ]
                };
                let mut f = FireSpec::new(Motion::Script(Script {
                    keyframes: vec![
                        Keyframe {
                            time: 0.0,
                            points: pose(0.0),
                        },
                        Keyframe {
                            time: 0.8,
                            points: pose(0.04),
                        },
                        Keyframe {
                            time: 1.6,
                            points: pose(-0.03),
                        },
                        Keyframe {
                            time: 2.4,
                            points: pose(0.0),
                        },
                    ],
                    looped: true,
                }));
                // detail tuned against candle.mp4's spectral slope (ignis bench realism)
                f.noise = NoiseParams {
                    frequency: 9.0,
                    stability: 1.05,
                    octaves: 4,
                    gain: 0.6,
                    ..Default::default()
                };
                s.fires.push(f);
                s.camera = Camera {
                    position: [0.0, -3.2, 0.55],
                    target: [0.0, 0.0, 0.55],
                    fov: 30.0,
                };
                s.slice_spacing = 0.02;
                // exposed like footage: the core saturates
                s.intensity = 18.0;
            }
            Preset::Torch => {
                s.puff = 0.4;
                // a torch head, about 10 cm
                s.diameter = 0.1;
                let mut f = FireSpec::new(Motion::Simulation(SimParams {
                    wind: [0.6, 0.0, 0.0],
                    gust: 0.6,
                    radius: 0.45,
                    tip_radius: 0.15,
                    lifetime: 1.0,
                    rise_speed: 1.2,
                    ..Default::default()
                }));
                f.noise = NoiseParams {
                    frequency: 4.0,
                    stability: 1.6,
                    octaves: 4,
                    gain: 0.6,
                    ..Default::default()
                };
                s.fires.push(f);
                s.camera = Camera {
                    position: [0.4, -5.5, 1.1],
                    target: [0.4, 0.0, 1.1],
                    fov: 36.0,
                };
                s.slice_spacing = 0.04;
                s.intensity = 10.5;
            }
            Preset::Campfire => {
                s.puff = 0.4;
                // a small campfire, 40 cm
                s.diameter = 0.4;
                for k in 0..5 {
                    let a = k as f32 / 5.0 * std::f32::consts::TAU + 0.3;
                    let (c, sn) = (a.cos(), a.sin());
                    let r0 = 0.55;
                    let h = 1.5 + 0.3 * ((k * 7 % 5) as f32 / 4.0);
                    let lean = |f: f32| [r0 * c * (1.0 - f), r0 * sn * (1.0 - f)];
                    let pts: Vec<[f32; 4]> = (0..5)
                        .map(|i| {
                            let f = i as f32 / 4.0;
                            let [x, y] = lean(f.min(0.8));
                            [x, y, h * f, 0.45 * (1.0 - 0.7 * f)]
                        })
                        .collect();
                    let mut sway = pts.clone();
                    for p in sway.iter_mut().skip(2) {
                        p[0] += 0.08 * (a * 3.0).sin();
                        p[1] += 0.08 * (a * 3.0).cos();
                    }
                    let mut f = FireSpec::new(Motion::Script(Script {
                        keyframes: vec![
                            Keyframe {
                                time: 0.0,
                                points: pts.clone(),
                            },
                            Keyframe {
                                time: 1.1 + 0.2 * k as f32,
                                points: sway,
                            },
                            Keyframe {
                                time: 2.2 + 0.4 * k as f32,
                                points: pts,
                            },
                        ],
                        looped: true,
                    }));
                    f.noise = NoiseParams {
                        frequency: 3.0,
                        stability: 1.2,
                        octaves: 5,
                        gain: 0.6,
                        ..Default::default()
                    };
                    s.fires.push(f);
                }
                s.camera = Camera {
                    position: [0.0, -6.0, 1.6],
                    target: [0.0, 0.0, 0.9],
                    fov: 36.0,
                };
                s.slice_spacing = 0.05;
                s.intensity = 3.2;
            }
            Preset::Wall => {
                s.puff = 0.4;
                // each burning element of the wall, 60 cm
                s.diameter = 0.6;
                for k in 0..9 {
                    let x = -3.2 + 0.8 * k as f32;
                    let h = 2.0 + 0.5 * ((k * 5 % 9) as f32 / 8.0);
                    let mut f = FireSpec::new(Motion::Static(vec![
                        [x, 0.0, 0.0, 0.55],
                        [x, 0.0, h * 0.33, 0.5],
                        [x + 0.05, 0.0, h * 0.66, 0.4],
                        [x + 0.1, 0.0, h, 0.25],
                    ]));
                    f.noise = NoiseParams {
                        frequency: 1.3,
                        stability: 0.5,
                        ..Default::default()
                    };
                    s.fires.push(f);
                }
                s.camera = Camera {
                    position: [0.0, -7.5, 1.3],
                    target: [0.0, 0.0, 1.2],
                    fov: 45.0,
                };
                s.slice_spacing = 0.06;
                s.intensity = 3.2;
            }
        }
        s
    }

    /// The scene of Fuller et al.'s Table 1: one unit-radius fire, slice spacing 0.2, seen
    /// from the side so that about 90,000 pixels are covered at 400×400.
    pub fn table1(kind: NoiseKind, octaves: u32, lattice: usize) -> FireScene {
        let mut s = FireScene::empty().with_size(Size::new(400, 400).expect("valid"));
        let mut f = FireSpec::new(Motion::Static(vec![
            [0.0, 0.0, 0.0, 1.0],
            [0.0, 0.0, 1.0, 1.0],
            [0.2, 0.0, 2.0, 1.0],
            [0.4, 0.0, 3.0, 1.0],
        ]));
        f.noise = NoiseParams {
            kind,
            octaves,
            ..Default::default()
        };
        s.fires.push(f);
        s.lattice = lattice;
        s.slice_spacing = 0.2;
        s.intensity = 1.0;
        s.bloom.passes = 0;
        s.camera = Camera {
            position: [0.2, -TABLE1_DISTANCE, 1.5],
            target: [0.2, 0.0, 1.5],
            fov: 40.0,
        };
        s
    }
}

/// Camera distance of [`FireScene::table1`] (chosen so ≈ 90,000 pixels are covered).
pub const TABLE1_DISTANCE: f32 = 5.4;

/// Fixed control points as a one-key script (whose contacts the script computes).
fn static_points(p: &[[f32; 4]]) -> Script {
    Script {
        keyframes: vec![Keyframe {
            time: 0.0,
            points: p.to_vec(),
        }],
        looped: false,
    }
}

/// What [`Animator::next_hdr`] returns: the HDR frame, its statistics, the collisions and
/// the control points.
type HdrFrame = (RgbaFrame, RenderStats, Vec<Collision>, Vec<Vec<[f32; 4]>>);

/// One rendered frame.
#[derive(Clone, Debug)]
pub struct Frame {
    /// Final frame: bloomed, straight alpha, linear HDR.
    pub image: RgbaFrame,
    /// The renderer's premultiplied HDR output before bloom.
    pub hdr: RgbaFrame,
    pub stats: RenderStats,
    /// Contacts between fires and obstacles during this frame.
    pub collisions: Vec<Collision>,
    /// Each fire's control points at this frame.
    pub control_points: Vec<Vec<[f32; 4]>>,
}

/// Steps a scene's fires (scripts, simulations, collisions) and renders frames.
pub struct Animator<'a> {
    scene: &'a FireScene,
    sims: Vec<Option<ParticleSim>>,
    frame: u64,
    count_coverage: bool,
    looping: Option<Looping>,
    /// Per fire: its scroll length ([`Animator::scroll_lengths`]).
    scroll: Vec<f32>,
}

impl Animator<'_> {
    /// Whether the next frames count [`RenderStats::covered_pixels`] (extra work that does
    /// not change the image; see [`RenderParams::count_coverage`]). Default off.
    pub fn set_count_coverage(&mut self, on: bool) {
        self.count_coverage = on;
    }

    /// Index of the next frame.
    pub fn frame_index(&self) -> u64 {
        self.frame
    }

    /// A looping animator's loop time of each frame of one cycle (in frames, from 0), to
    /// give [`FireScene::looping_animator_with_times`] later; `None` when not looping.
    pub fn loop_times(&self) -> Option<&[f64]> {
        self.looping.as_ref().map(|l| &l.times[..])
    }

    /// Skips `n` frames without rendering them: only the motion (scripts, simulations,
    /// collisions) is stepped, so the next frame is exactly the one a full run would
    /// render there. This is how a render-farm chunk starts in the middle. (A looping
    /// animator's motion is a function of loop time, computed when it was made: skipping
    /// costs nothing.)
    pub fn skip(&mut self, n: u64) {
        if self.looping.is_some() {
            self.frame += n;
            return;
        }
        for _ in 0..n {
            self.step();
        }
    }

    /// The scene time (seconds) the next frame is rendered at: its frame time, or for a
    /// loop its loop time ([`crate::looping`]).
    fn time(&self) -> f32 {
        match &self.looping {
            Some(l) => l.time(self.frame) as f32 / self.scene.fps,
            None => self.frame as f32 / self.scene.fps,
        }
    }

    /// Advances the motion one frame; returns control points and contacts.
    pub fn step(&mut self) -> (Vec<Vec<[f32; 4]>>, Vec<Collision>) {
        let out = match &self.looping {
            Some(l) => self.loop_pose(l),
            None => self.plain_step(),
        };
        self.frame += 1;
        out
    }

    /// A plain animation's motion at the next frame (simulations advanced one step).
    fn plain_step(&mut self) -> (Vec<Vec<[f32; 4]>>, Vec<Collision>) {
        let s = self.scene;
        let dt = 1.0 / s.fps;
        let t = self.frame as f32 * dt;
        let mut pts = Vec::with_capacity(s.fires.len());
        let mut hits = Vec::new();
        for (i, f) in s.fires.iter().enumerate() {
            let (p, h) = match &f.motion {
                Motion::Static(p) => static_points(p).at_with_collisions(t, dt, &s.obstacles, i),
                Motion::Script(sc) => sc.at_with_collisions(t, dt, &s.obstacles, i),
                Motion::Simulation(_) => {
                    let sim = self.sims[i]
                        .as_mut()
                        .expect("a simulation per simulated fire");
                    let h = if self.frame > 0 {
                        sim.advance(dt, &s.obstacles, i)
                    } else {
                        Vec::new()
                    };
                    (sim.control_points(), h)
                }
            };
            pts.push(p);
            hits.extend(h);
        }
        (pts, hits)
    }

    /// A loop's motion at the next frame's loop time; a simulation reports the contacts
    /// of its whole-frame steps since the previous frame's time.
    fn loop_pose(&self, l: &Looping) -> (Vec<Vec<[f32; 4]>>, Vec<Collision>) {
        let s = self.scene;
        let dt = 1.0 / s.fps;
        let tau = l.time(self.frame);
        let t = tau as f32 * dt;
        let mut pts = Vec::with_capacity(s.fires.len());
        let mut hits = Vec::new();
        for (i, f) in s.fires.iter().enumerate() {
            let p = match (&f.motion, &l.scripts[i], &l.sims[i]) {
                (Motion::Static(p), _, _) => {
                    let (p, h) = static_points(p).at_with_collisions(t, dt, &s.obstacles, i);
                    hits.extend(h);
                    p
                }
                (_, Some(ls), _) => {
                    let mut p = ls.at(t);
                    deflect_points(&mut p, dt, &s.obstacles, i, &mut hits);
                    p
                }
                (_, _, Some(track)) => {
                    let lo = l.previous_time(self.frame);
                    hits.extend(track.hits_between(lo, tau).cloned());
                    track.at(tau)
                }
                _ => unreachable!("a looping script or simulation per moving fire"),
            };
            pts.push(p);
        }
        (pts, hits)
    }

    /// Each fire's scroll length ([`FireInstance::scroll_length`]): the length of its
    /// centre curve at frame 0 (before any loop blending), fixed for the whole animation
    /// so that every frame range of it scrolls the same way.
    fn scroll_lengths(&self) -> Result<Vec<f32>> {
        let s = self.scene;
        let mut probe = Animator {
            scene: s,
            sims: self.sims.clone(),
            frame: 0,
            count_coverage: false,
            looping: None,
            scroll: Vec::new(),
        };
        let (pts, _) = probe.step();
        pts.into_iter()
            .zip(&s.fires)
            .enumerate()
            .map(|(i, (p, f))| {
                let c = BSpline::new(p, f.degree).map_err(|e| within(&format!("fire[{i}]"), e))?;
                Ok(Lattice::build(&c, s.lattice)?.length())
            })
            .collect()
    }

    /// Fire `i`'s puffing wave at the next frame, if the scene puffs.
    fn puff_wave(&self, i: usize) -> Option<Puff> {
        self.puff_wave_at(i, self.puff_phase())
    }

    /// Fire `i`'s puffing wave when the scene's puffing cycle is at `phase`.
    fn puff_wave_at(&self, i: usize, phase: f32) -> Option<Puff> {
        let s = self.scene;
        (s.puff > 0.0).then(|| Puff {
            amplitude: s.puff,
            phase: phase + s.puff_offset(i),
        })
    }

    /// Phase (radians) of the puffing cycle at the current frame: `2π f t` with `f` the
    /// puffing frequency, rounded for a loop to a whole number of cycles per loop (at least
    /// one) and computed from the frame's loop time, so it repeats exactly.
    fn puff_phase(&self) -> f32 {
        let s = self.scene;
        let f = ignis_core::realism::puffing_frequency(f64::from(s.diameter));
        let tau = std::f64::consts::TAU;
        match &self.looping {
            Some(l) => {
                let cycles = (f * l.frames as f64 / f64::from(s.fps)).round().max(1.0);
                (tau * cycles * l.time(self.frame) / l.frames as f64) as f32
            }
            None => self.plain_puff_phase(self.frame as f64),
        }
    }

    /// A plain animation's puffing phase at frame `frame` (fractional between frames).
    fn plain_puff_phase(&self, frame: f64) -> f32 {
        let s = self.scene;
        let f = ignis_core::realism::puffing_frequency(f64::from(s.diameter));
        (std::f64::consts::TAU * (f * frame / f64::from(s.fps)).fract()) as f32
    }

    /// Renders the next frame.
    pub fn next_frame(&mut self) -> Result<Frame> {
        let (hdr, stats, collisions, control_points) = self.next_hdr()?;
        let image = finish(&hdr, &self.scene.bloom)?;
        Ok(Frame {
            image,
            hdr,
            stats,
            collisions,
            control_points,
        })
    }

    /// [`Self::next_frame`], with the pose it was rendered in (for
    /// [`crate::model_motion`]: the frame's own motion, from the model).
    pub fn next_frame_with_pose(&mut self) -> Result<(Frame, Pose)> {
        let (pose, collisions, control_points) = self.next_pose()?;
        let (hdr, stats) = self.render_pose(&pose)?;
        let image = finish(&hdr, &self.scene.bloom)?;
        let frame = Frame {
            image,
            hdr,
            stats,
            collisions,
            control_points,
        };
        Ok((frame, pose))
    }

    /// The frame a fraction `s` (in `[0, 1]`) of the way in time from the frame rendered
    /// last to the next one, rendered as [`Self::next_frame`] renders frames, without
    /// stepping the animation: what a flipbook's motion vectors are chosen against (the
    /// engines blend a sheet's neighbouring frames at every fraction in between).
    ///
    /// A loop's frames are functions of loop time, so the in-between frame is exact (the
    /// cycle's last frame is followed by its first); a simulation's control points move
    /// linearly between the two frames' states, as in a loop. In a plain animation,
    /// scripts and static fires are evaluated at the in-between time, and a simulation's
    /// next state is stepped on a copy. Fails before the first frame.
    pub fn frame_between(&self, s: f64) -> Result<Frame> {
        let k = self.frame.checked_sub(1).ok_or_else(|| {
            VolumeError::bad("frame_between", "no frame rendered yet: render one first")
        })?;
        let s = s.clamp(0.0, 1.0);
        let sc = self.scene;
        let (pose, control_points) = match &self.looping {
            Some(l) => {
                let cycle = l.times.len() as u64;
                let lo = l.time(k);
                let hi = if (k + 1) % cycle == 0 {
                    l.frames as f64
                } else {
                    l.time(k + 1)
                };
                // a loop whose one time is the in-between one: its frame 0 is that frame
                let mut probe = Animator {
                    scene: sc,
                    sims: Vec::new(),
                    frame: 0,
                    count_coverage: self.count_coverage,
                    looping: Some(Looping {
                        times: [lo + s * (hi - lo)].into(),
                        ..l.clone()
                    }),
                    scroll: self.scroll.clone(),
                };
                let (pose, _, pts) = probe.next_pose()?;
                (pose, pts)
            }
            None => {
                let dt = 1.0 / sc.fps;
                let frame = k as f64 + s;
                let t = (frame / f64::from(sc.fps)) as f32;
                let mut pts = Vec::with_capacity(sc.fires.len());
                for (i, f) in sc.fires.iter().enumerate() {
                    pts.push(match &f.motion {
                        Motion::Static(p) => {
                            static_points(p)
                                .at_with_collisions(t, dt, &sc.obstacles, i)
                                .0
                        }
                        Motion::Script(script) => {
                            script.at_with_collisions(t, dt, &sc.obstacles, i).0
                        }
                        Motion::Simulation(_) => {
                            let sim = self.sims[i]
                                .as_ref()
                                .expect("a simulation per simulated fire");
                            let (a, mut next) = (sim.control_points(), sim.clone());
                            next.advance(dt, &sc.obstacles, i);
                            let b = next.control_points();
                            a.iter()
                                .zip(&b)
                                .map(|(p, q)| [0, 1, 2, 3].map(|c| p[c] + s as f32 * (q[c] - p[c])))
                                .collect()
                        }
                    });
                }
                let phase = self.plain_puff_phase(frame);
                let puffs: Vec<Option<Puff>> = (0..sc.fires.len())
                    .map(|i| self.puff_wave_at(i, phase))
                    .collect();
                (self.pose_of(t, &pts, &puffs)?, pts)
            }
        };
        let (hdr, stats) = self.render_pose(&pose)?;
        let image = finish(&hdr, &sc.bloom)?;
        Ok(Frame {
            image,
            hdr,
            stats,
            collisions: Vec::new(),
            control_points,
        })
    }

    /// [`Self::next_frame`] before the post pipeline: the renderer's premultiplied HDR
    /// frame, its statistics, the collisions and the control points (the loop's preview
    /// takes its metric frames from the HDR frame directly).
    fn next_hdr(&mut self) -> Result<HdrFrame> {
        let (pose, collisions, pts) = self.next_pose()?;
        let (hdr, stats) = self.render_pose(&pose)?;
        Ok((hdr, stats, collisions, pts))
    }

    /// Steps the motion to the next frame and builds its lattices: the next frame's
    /// [`Pose`], its collisions and control points.
    #[allow(clippy::type_complexity)]
    fn next_pose(&mut self) -> Result<(Pose, Vec<Collision>, Vec<Vec<[f32; 4]>>)> {
        let s = self.scene;
        let t = self.time();
        let puffs: Vec<Option<Puff>> = (0..s.fires.len()).map(|i| self.puff_wave(i)).collect();
        let (pts, collisions) = self.step();
        let pose = self.pose_of(t, &pts, &puffs)?;
        Ok((pose, collisions, pts))
    }

    /// The [`Pose`] at scene time `t` of fires with control points `pts` and puffing
    /// waves `puffs` (one each).
    fn pose_of(&self, t: f32, pts: &[Vec<[f32; 4]>], puffs: &[Option<Puff>]) -> Result<Pose> {
        let s = self.scene;
        let lattices = pts
            .iter()
            .zip(&s.fires)
            .enumerate()
            .map(|(i, (p, f))| {
                let c = BSpline::new(p.clone(), f.degree)
                    .map_err(|e| within(&format!("fire[{i}]"), e))?;
                Lattice::build_puffed(&c, s.lattice, puffs[i])
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(Pose {
            time: t,
            lattices,
            scroll_lengths: self.scroll.clone(),
            count_coverage: self.count_coverage,
            loop_period: self.looping.as_ref().map(|l| l.frames as f32 / s.fps),
        })
    }

    /// Renders `pose` (the scene's fires in it, seen by the scene's camera).
    fn render_pose(&self, pose: &Pose) -> Result<(RgbaFrame, RenderStats)> {
        let inst = pose.instances(self.scene);
        let params = pose.render_params(self.scene);
        render(&inst, &self.scene.camera, &params, pose.time)
    }
}

/// Everything a frame is rendered from besides the scene: its time, each fire's lattice
/// and scroll length, and the loop (if any). Made by [`Animator::next_frame_with_pose`].
#[derive(Clone, Debug)]
pub struct Pose {
    /// Scene time, seconds (for a loop, its loop time).
    pub time: f32,
    /// Per fire: its lattice at this frame (puffing included).
    pub lattices: Vec<Lattice>,
    /// Per fire: its scroll length ([`FireInstance::scroll_length`]).
    pub scroll_lengths: Vec<f32>,
    /// The render's [`RenderParams::count_coverage`].
    pub count_coverage: bool,
    /// The render's [`RenderParams::loop_period`].
    pub loop_period: Option<f32>,
}

impl Pose {
    /// The fires of `scene` in this pose, ready to render.
    pub fn instances<'a>(&'a self, scene: &'a FireScene) -> Vec<FireInstance<'a>> {
        self.lattices
            .iter()
            .zip(&scene.fires)
            .enumerate()
            .map(|(i, (l, f))| FireInstance {
                lattice: l,
                profile: &f.profile,
                noise: f.noise,
                offset: scene.offset(i),
                scroll_length: Some(self.scroll_lengths[i]),
            })
            .collect()
    }

    /// The settings `scene`'s frame in this pose is rendered with.
    pub fn render_params(&self, scene: &FireScene) -> RenderParams {
        RenderParams {
            count_coverage: self.count_coverage,
            loop_period: self.loop_period,
            ..scene.render_params()
        }
    }
}

#[cfg(test)]
mod hardening_tests {
    use super::*;

    fn scene(toml: &str) -> Result<FireScene> {
        FireScene::from_toml(toml, Path::new("."), &mut |_| Err("no images".into()))
    }

    /// Loop times kept from one animator give another the same frames, bit for bit (a
    /// simulated fire and a scripted one); times no loop has are refused.
    #[test]
    fn kept_loop_times_give_the_same_frames() {
        for p in [Preset::Campfire, Preset::Candle] {
            let s = FireScene::preset(p).with_size(Size::new(24, 24).unwrap());
            let mut a = s.looping_animator(8).unwrap();
            let times = a.loop_times().unwrap().to_vec();
            assert_eq!(times.len(), 8);
            assert!(
                times.iter().skip(1).any(|&t| t != t.round()),
                "re-timed: {times:?}"
            );
            let mut b = s.looping_animator_with_times(8, &times).unwrap();
            assert_eq!(b.loop_times().unwrap(), &times[..]);
            // a chunk starting at frame 5, as a farm job renders it
            let mut c = s.looping_animator_with_times(8, &times).unwrap();
            c.skip(5);
            for i in 0..8 {
                let (fa, fb) = (a.next_frame().unwrap(), b.next_frame().unwrap());
                assert_eq!(fa.image.data(), fb.image.data(), "{p:?} frame {i}");
                if i >= 5 {
                    assert_eq!(fa.image.data(), c.next_frame().unwrap().image.data());
                }
            }
            assert!(s.animator().unwrap().loop_times().is_none());
        }
        let s = FireScene::preset(Preset::Torch).with_size(Size::new(16, 16).unwrap());
        for bad in [
            vec![0.0, 1.0, 2.0],
            vec![0.5, 1.0, 2.0, 3.0],
            vec![0.0, 2.0, 1.0, 3.0],
            vec![0.0, 1.0, 2.0, 4.0],
            vec![0.0, 1.0, f64::NAN, 3.0],
            vec![0.0, -1.0, 2.0, 3.0],
        ] {
            let e = s
                .looping_animator_with_times(4, &bad)
                .err()
                .unwrap_or_else(|| panic!("{bad:?} refused"))
                .to_string();
            assert!(e.contains("loop times"), "{e}");
        }
    }

    /// Issue 18 defect 4: work past the documented limits is refused before rendering
    /// (quickly, without a large allocation), with the number and the fix.
    #[test]
    fn runaway_work_is_refused_before_rendering() {
        let mut s = FireScene::preset(Preset::Candle).with_size(Size::new(32, 32).unwrap());
        for spacing in [1e-7f32, 1e-9] {
            s.slice_spacing = spacing;
            let mut a = s.animator().unwrap();
            let e = a.next_frame().expect_err("refused");
            assert!(matches!(e, VolumeError::LimitExceeded(_)), "{e}");
            let e = e.to_string();
            assert!(e.contains("samples") && e.contains("slice_spacing"), "{e}");
        }
        let fire = |body: &str| format!("[render]\nsize = \"48x48\"\n[[fire]]\n{body}\n");
        let many: Vec<String> = (0..100_000).map(|i| format!("[0,0,{i},1]")).collect();
        let cases = [
            fire("[fire.simulation]\nradius = 1e5"),
            fire("[fire.simulation]\ntip_radius = 1e9"),
            fire("[fire.simulation]\nlifetime = 1e-9"),
            // a frame rate so low that one step emitted ~1e10 particles (found by ignis-fuzz)
            format!("fps = 1e-6\n{}", fire("[fire.simulation]\nlifetime = 0.5")),
            fire("curve = { points = [[0,0,0,1e9], [0,0,1,1], [0,0,2,1], [0,0,3,1]] }"),
            fire(&format!("curve = {{ points = [{}] }}", many.join(","))),
            format!(
                "{}[[obstacle]]\ntype = \"sphere\"\ncentre = [0, 0, 0]\nradius = 1e30\n",
                fire("curve = { points = [[0,0,0,1], [0,0,1,1], [0,0,2,1], [0,0,3,1]] }")
            ),
            "[render]\nblend = { tint = [nan, 0, 0] }\n[[fire]]\ncurve = { points = [[0,0,0,1], [0,0,1,1], [0,0,2,1], [0,0,3,1]] }\n".to_string(),
        ];
        for (i, c) in cases.iter().enumerate() {
            assert!(scene(c).is_err(), "case {i} accepted");
        }
    }

    /// A simulation step may not outlive the particles: the error names the field and the
    /// substeps that fix it, and those substeps are accepted.
    #[test]
    fn a_simulation_step_longer_than_a_lifetime_is_refused() {
        let file = |fps: &str, substeps: u32| {
            format!(
                "fps = {fps}\n[render]\nsize = \"16x16\"\n[[fire]]\n[fire.simulation]\n\
                 lifetime = 0.5\nsubsteps = {substeps}\n"
            )
        };
        let e = scene(&file("0.5", 1)).expect_err("refused").to_string();
        assert!(
            e.contains("fire[0].simulation.substeps") && e.contains("substeps ≥ 4"),
            "{e}"
        );
        let ok = scene(&file("0.5", 4)).expect("four steps a frame fit the lifetime");
        let mut a = ok.animator().unwrap();
        a.next_frame().unwrap();
        assert!(scene(&file("30", 1)).is_ok());
        let e = scene(&file("0.001", 64)).expect_err("refused").to_string();
        assert!(e.contains("use fps ≥ 0.031 with substeps = 64"), "{e}");
    }

    /// Issue 18 defect 10: a tint must be finite and non-negative.
    #[test]
    fn bad_tints_are_refused() {
        for t in [
            [f32::NAN, 0.0, 0.0],
            [f32::INFINITY, 0.0, 0.0],
            [-1.0, 0.0, 0.0],
        ] {
            let mut p = FireScene::preset(Preset::Candle).render_params();
            p.blend = Blend::Tint(t);
            assert!(p.validate().is_err(), "{t:?}");
        }
    }
}

#[cfg(test)]
mod preview_tests {
    use super::*;

    /// The loop preview's fused post pipeline gives the metric frames of the full one bit
    /// for bit: every preset, wide, tall and square, with and without bloom, and a bloom
    /// too wide for the exact path (the fallback). (The wall at 33×64 also guards the
    /// renderer: it panicked there before `march_cells` skipped candidates whose pixel
    /// rectangle misses a tile.)
    #[test]
    fn preview_metric_equals_the_metric_of_the_finished_frame() {
        let mut checked = 0;
        for p in Preset::ALL {
            for (w, h) in [(64, 64), (64, 37), (33, 64), (64, 150)] {
                let base = FireScene::preset(p).with_size(Size::new(w, h).unwrap());
                let mut no_bloom = base.clone();
                no_bloom.bloom.passes = 0;
                let mut wide_bloom = base.clone();
                wide_bloom.bloom.radius = 9.0;
                for s in [base, no_bloom, wide_bloom] {
                    let mut a = s.animator().unwrap();
                    for _ in 0..2 {
                        let f = a.next_frame().unwrap();
                        let full = ignis_core::loopq::metric_frame_rgba(&f.image, [0.0; 3]);
                        let fused = crate::render::preview_metric(&f.hdr, &s.bloom).unwrap();
                        assert_eq!(full.size(), fused.size());
                        let same = full
                            .data()
                            .iter()
                            .zip(fused.data())
                            .all(|(x, y)| x.to_bits() == y.to_bits());
                        assert!(same, "{p:?} {w}x{h} bloom {:?}", s.bloom);
                        assert!(full.data().iter().any(|&v| v > 0.05), "{p:?}: blank frame");
                        checked += 1;
                    }
                }
            }
        }
        assert!(checked >= 24);
    }
}
