//! The readers under test, each with seeds written by Ignis itself.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use ignis_core::{RgbaFrame, Size};

use crate::{put, Outcome, Target};

fn out<T, E: std::fmt::Display>(r: Result<T, E>) -> Outcome {
    match r {
        Ok(_) => Outcome::Ok,
        Err(e) => Outcome::Err(e.to_string()),
    }
}

/// Shared fixtures: a small Eigenfire database, a flipbook and a `.flame` model, written
/// once into a temporary directory.
pub struct Fixtures {
    _dir: tempfile::TempDir,
    pub db: PathBuf,
    pub flipbook_png: PathBuf,
    pub flipbook_json: Vec<u8>,
    pub flame: Vec<u8>,
}

impl Fixtures {
    pub fn new() -> Result<Fixtures, Box<dyn std::error::Error>> {
        let dir = tempfile::tempdir()?;
        // Database: two synthetic clips of 16 frames, training size 20x32, packs of 5,
        // stored frames (so every file kind is present).
        let clips = ignis_eigen::train::synthetic_clips(Size::new(40, 64)?, 16, 3);
        let mut pre = ignis_eigen::preprocess::PreprocessParams::with_sizes(
            Size::new(40, 64)?,
            Some(Size::new(20, 32)?),
        );
        pre.pose_samples = 4;
        let p = ignis_eigen::train::TrainParams {
            pack_size: 5,
            store_frames: true,
            ..Default::default()
        };
        let db = dir.path().join("db");
        ignis_eigen::train::train(&clips, &pre, &p, &db, &mut ignis_eigen::train::NoProgress)?;
        // Flipbook of 3 frames of 8x6.
        let fb = dir.path().join("fb.png");
        let size = Size::new(8, 6)?;
        let mut w = ignis_media::create(&fb, size, &ignis_media::WriteOptions::default())?;
        for t in 0..3 {
            let mut f = RgbaFrame::new(size);
            for (i, px) in f.data_mut().iter_mut().enumerate() {
                let v = ((i + t * 7) % 11) as f32 / 10.0;
                *px = [v, v * 0.5, 0.1, 1.0];
            }
            w.push(&f)?;
        }
        w.finish()?;
        let flipbook_json = std::fs::read(dir.path().join("fb.json"))?;
        // A learned-flame model from 40 synthetic frames.
        let clip = ignis_learned::synthetic::flame_clip(Size::new(64, 64)?, 40, 5);
        let tp = ignis_learned::TrainParams {
            em: ignis_learned::EmParams {
                particles: 60,
                seed: 5,
                ..Default::default()
            },
            ..Default::default()
        };
        let t = ignis_learned::train(clip, &tp, &mut ignis_core::progress::NoProgress)?;
        let fp = dir.path().join("m.flame");
        t.model.save(&fp)?;
        let flame = std::fs::read(&fp)?;
        Ok(Fixtures {
            _dir: dir,
            db,
            flipbook_png: fb,
            flipbook_json,
            flame,
        })
    }
}

fn copy_dir(from: &Path, to: &Path) -> std::io::Result<()> {
    std::fs::create_dir_all(to)?;
    for e in std::fs::read_dir(from)? {
        let e = e?;
        let t = to.join(e.file_name());
        if e.file_type()?.is_dir() {
            copy_dir(&e.path(), &t)?;
        } else {
            std::fs::copy(e.path(), &t)?;
        }
    }
    Ok(())
}

/// The database manifest. `resum`: the checksum sidecar is rewritten for the mutated
/// manifest, so validation (not the checksum) must catch every bad field; otherwise every
/// change must be refused.
pub struct Manifest {
    db: PathBuf,
    seeds: Vec<Vec<u8>>,
    resum: bool,
}

impl Manifest {
    pub fn new(fx: &Fixtures, resum: bool) -> Manifest {
        let m = std::fs::read(fx.db.join("manifest.json")).expect("fixture manifest");
        Manifest {
            db: fx.db.clone(),
            seeds: vec![m],
            resum,
        }
    }
}

impl Target for Manifest {
    fn name(&self) -> &'static str {
        if self.resum {
            "manifest (checksum rewritten)"
        } else {
            "manifest"
        }
    }
    fn seeds(&self) -> &[Vec<u8>] {
        &self.seeds
    }
    fn checksummed(&self) -> bool {
        !self.resum
    }
    fn run(&self, input: &[u8], scratch: &Path) -> Outcome {
        let db = scratch.join("db");
        if let Err(e) = copy_dir(&self.db, &db) {
            return Outcome::Err(format!("fixture copy: {e}"));
        }
        put(&db, "manifest.json", input);
        if self.resum {
            put(
                &db,
                ignis_eigen::db::MANIFEST_SUM,
                ignis_eigen::db::manifest_sum_text(input).as_bytes(),
            );
        }
        let d = match ignis_eigen::EigenfireDb::open(&db) {
            Ok(d) => d,
            Err(e) => return Outcome::Err(e.to_string()),
        };
        // Use what was accepted, as the commands do.
        let _ = d.verify();
        let k = d.usable_components();
        let m = d.manifest().clone();
        for c in &m.clips {
            if let Ok(row) = d.frame_index(&c.name, c.start) {
                let w = d.frame_weights(row);
                let _ = d.reconstruct(&w, m.e_render);
                let _ = d.reconstruct_batch(&[&w], k);
                let _ = d.distance(row, d.n_frames() - 1, m.e_detect);
                let _ = d.angle(row);
                let _ = d.row_origin(row);
            }
            let _ = d.preprocessed_frame(&c.name, c.start);
        }
        let _ = ignis_eigen::analysis::eigenfire_sheet(&d, 4, 2);
        Outcome::Ok
    }
}

/// `.npy` arrays (the database's data files and the streaming PCA's input).
pub struct Npy {
    seeds: Vec<Vec<u8>>,
}

impl Npy {
    pub fn new(fx: &Fixtures) -> Npy {
        let seeds = [
            "mean.npy",
            "eigenvalues.npy",
            "weights.npy",
            "packs/pack_001.npy",
        ]
        .iter()
        .map(|f| std::fs::read(fx.db.join(f)).expect("fixture npy"))
        .collect();
        Npy { seeds }
    }
}

impl Target for Npy {
    fn name(&self) -> &'static str {
        "npy"
    }
    fn seeds(&self) -> &[Vec<u8>] {
        &self.seeds
    }
    fn run(&self, input: &[u8], scratch: &Path) -> Outcome {
        let p = put(scratch, "a.npy", input);
        if let Ok(h) = ignis_pca::npy::parse_header(&p, input) {
            if h.file_len() == input.len() {
                let _ = ignis_pca::npy::f32_data(input, &h);
                let _ = ignis_pca::npy::f64_data(input, &h);
            }
        }
        if let Ok(mut s) = ignis_pca::NpySource::open(&p) {
            let _ = ignis_pca::fit_streaming(&mut s, 2, &Default::default());
        }
        out(ignis_pca::npy::read_f32(&p))
    }
}

/// `.flame` learned-flame models (checksummed: every change must be refused).
pub struct Flame {
    seeds: Vec<Vec<u8>>,
}

impl Flame {
    pub fn new(fx: &Fixtures) -> Flame {
        Flame {
            seeds: vec![fx.flame.clone()],
        }
    }
}

impl Target for Flame {
    fn name(&self) -> &'static str {
        ".flame"
    }
    fn seeds(&self) -> &[Vec<u8>] {
        &self.seeds
    }
    fn checksummed(&self) -> bool {
        true
    }
    fn run(&self, input: &[u8], scratch: &Path) -> Outcome {
        let p = put(scratch, "m.flame", input);
        match ignis_learned::FlameModel::load(&p) {
            Ok(m) => {
                let s = ignis_learned::Synthesiser::new(&m, Default::default(), 1)
                    .and_then(|mut s| s.frames(Size::new(24, 24).expect("size"), 2));
                let _ = s;
                Outcome::Ok
            }
            Err(e) => Outcome::Err(e.to_string()),
        }
    }
}

/// Flipbook JSON sidecars (read back by `read_flipbook`, and beside their sheet as footage).
pub struct Flipbook {
    png: PathBuf,
    seeds: Vec<Vec<u8>>,
}

impl Flipbook {
    pub fn new(fx: &Fixtures) -> Flipbook {
        Flipbook {
            png: fx.flipbook_png.clone(),
            seeds: vec![fx.flipbook_json.clone()],
        }
    }
}

impl Target for Flipbook {
    fn name(&self) -> &'static str {
        "flipbook JSON"
    }
    fn seeds(&self) -> &[Vec<u8>] {
        &self.seeds
    }
    fn run(&self, input: &[u8], scratch: &Path) -> Outcome {
        if std::fs::copy(&self.png, scratch.join("fb.png")).is_err() {
            return Outcome::Err("fixture copy".into());
        }
        let j = put(scratch, "fb.json", input);
        let book = out(ignis_media::read_flipbook(&j));
        // the same sidecar beside its sheet makes the sheet footage (`ignis info`, `convert`)
        let sheet = scratch.join("fb.png");
        let footage = ignis_media::open(&sheet, &ignis_media::ReadOptions::default())
            .and_then(|r| r.take(256).collect::<Result<Vec<_>, _>>());
        match (book, out(footage)) {
            (Outcome::Ok, f) => f,
            (b, _) => b,
        }
    }
}

/// A reader of TOML text, given the text and a scratch directory.
type TomlRun = Box<dyn Fn(&str, &Path) -> Outcome + Send + Sync>;

/// A TOML reader given as a function of (text, scratch directory).
pub struct Toml {
    name: &'static str,
    seeds: Vec<Vec<u8>>,
    run: TomlRun,
}

impl Target for Toml {
    fn name(&self) -> &'static str {
        self.name
    }
    fn seeds(&self) -> &[Vec<u8>] {
        &self.seeds
    }
    fn run(&self, input: &[u8], scratch: &Path) -> Outcome {
        match std::str::from_utf8(input) {
            Ok(t) => (self.run)(t, scratch),
            Err(e) => Outcome::Err(e.to_string()),
        }
    }
}

const SCENARIO: &str = r#"database = "db"
sequence = ["calm", "wind", "calm"]
loop = true
e_detect = 4
e_render = 6

[motions.calm]
clip = "candle"
start = 0
end = 8

[motions.wind]
clip = "campfire"
start = 2
end = 14
weights = "1=0.8"

[transition]
method = "auto"

[[join]]
method = "direct"
steps = 3

[[join]]
method = "low-pass"
kernel = [0.2, 0.2, 0.6]
"#;

const FIRE: &str = r#"seed = 7
fps = 30.0
[camera]
position = [0.0, -7.0, 1.5]
target = [0.0, 0.0, 1.5]
fov = 40.0
[render]
size = "16x16"
slice_spacing = 0.2
lattice = 12
blend = { tint = [0.3, 0.5, 1.0] }
intensity = 2.5
[bloom]
passes = 1
radius = 2.0
[[fire]]
degree = 3
noise = { kind = "perlin4", octaves = 2, frequency = 1.0, stability = 0.35 }
curve = { points = [[0,0,0,1], [0,0,1,0.9], [0,0,2,0.7], [0,0,3,0.4]] }
[[fire]]
degree = 2
[fire.simulation]
wind = [0.5, 0, 0]
control_points = 5
lifetime = 1.2
radius = 1.0
tip_radius = 0.5
[[obstacle]]
type = "sphere"
centre = [0.0, 0.0, 2.5]
radius = 0.5
"#;

const CLIPS: &str = r#"[[clip]]
name = "candle"
synthetic = "candle"
start = 0
end = 40
stride = 2

[[clip]]
name = "real"
path = "../shared/data/candle.mp4"
start = 10
end = 200
stride = 4

[preprocess]
train_size = "20x32"
pose_samples = 4

[train]
pack_size = 5
"#;

/// A frame for the pre-processing pipeline: a warm blob on black.
fn flame_frame(size: Size) -> RgbaFrame {
    let mut f = RgbaFrame::new(size);
    let (w, h) = (size.width as f32, size.height as f32);
    for y in 0..size.height {
        for x in 0..size.width {
            let dx = (x as f32 - w / 2.0) / (w / 4.0);
            let dy = (y as f32 - h * 0.6) / (h / 3.0);
            let v = (1.0 - dx * dx - dy * dy).max(0.0);
            f.set(x, y, [v, v * 0.5, v * 0.1, 1.0]);
        }
    }
    f
}

/// Every TOML reader: scenario, fire file, clips (training config), pre-processing.
pub fn toml_targets(fx: &Fixtures) -> Vec<Arc<dyn Target>> {
    let db = fx.db.clone();
    let scenario = Toml {
        name: "scenario TOML",
        seeds: vec![SCENARIO.as_bytes().to_vec()],
        run: Box::new(move |t, scratch| {
            let file = db.parent().expect("fixture dir").join("s.toml");
            let _ = scratch;
            match ignis_eigen::scenario::Scenario::parse(t, &file) {
                Ok(s) => {
                    // Plan against the fixture database (the scenario names it).
                    if let Ok(d) = ignis_eigen::EigenfireDb::open(&db) {
                        let _ = s.plan(&d, &mut ignis_core::progress::NoProgress);
                    }
                    Outcome::Ok
                }
                Err(e) => Outcome::Err(e.to_string()),
            }
        }),
    };
    let fire = Toml {
        name: "fire TOML",
        // a hand-written file, and every preset as `ignis volume scene` prints it (the
        // files users start from: scripts, simulations, every field spelt out)
        seeds: std::iter::once(FIRE.to_string())
            .chain(ignis_volume::Preset::ALL.into_iter().map(|p| {
                ignis_volume::FireScene::preset(p)
                    .to_toml(p.name())
                    .expect("a preset prints")
            }))
            .map(String::into_bytes)
            .collect(),
        run: Box::new(|t, scratch| {
            let s = ignis_volume::scene::FireScene::from_toml(t, scratch, &mut |_| {
                Err("no images while fuzzing".into())
            });
            match s {
                Ok(s) => {
                    let s = s.with_size(Size::new(16, 16).expect("size"));
                    if let Ok(mut a) = s.animator() {
                        for _ in 0..2 {
                            if a.next_frame().is_err() {
                                break;
                            }
                        }
                    }
                    Outcome::Ok
                }
                Err(e) => Outcome::Err(e.to_string()),
            }
        }),
    };
    let clips = Toml {
        name: "clips TOML",
        seeds: vec![CLIPS.as_bytes().to_vec()],
        run: Box::new(|t, scratch| out(ignis_eigen::train::TrainConfig::from_toml(t, scratch))),
    };
    let pre_seed = {
        let mut p = ignis_eigen::preprocess::PreprocessParams::with_sizes(
            Size::new(40, 64).expect("size"),
            Some(Size::new(20, 32).expect("size")),
        );
        p.pose_samples = 4;
        p.to_toml().into_bytes()
    };
    let pre = Toml {
        name: "pre-processing TOML",
        seeds: vec![pre_seed],
        run: Box::new(
            |t, _| match ignis_eigen::preprocess::PreprocessParams::from_toml(t) {
                Ok(p) => {
                    let frame = flame_frame(Size::new(40, 64).expect("size"));
                    let pose = ignis_eigen::pose::ClipPose {
                        fuel_x: 20.0,
                        base_y: 60.0,
                        scale: 1.0,
                        isolate: true,
                        still_lights: Default::default(),
                    };
                    let _ = ignis_eigen::preprocess::preprocess_stages(&frame, &pose, &p);
                    Outcome::Ok
                }
                Err(e) => Outcome::Err(e.to_string()),
            },
        ),
    };
    vec![
        Arc::new(scenario),
        Arc::new(fire),
        Arc::new(clips),
        Arc::new(pre),
    ]
}

/// Every target.
pub fn all(fx: &Fixtures) -> Vec<Arc<dyn Target>> {
    let mut v: Vec<Arc<dyn Target>> = vec![
        Arc::new(Manifest::new(fx, false)),
        Arc::new(Manifest::new(fx, true)),
        Arc::new(Npy::new(fx)),
        Arc::new(Flame::new(fx)),
        Arc::new(Flipbook::new(fx)),
    ];
    v.extend(toml_targets(fx));
    v
}
