//! `ignis eigen`: Eigenfires I (eigenfires thesis ch. 3–4) — train a database from fire
//! footage, inspect it, plot it, reconstruct frames, and show what pre-processing does.
//! A thin layer over `ignis_eigen` (the library) and `ignis_media` (decoding, PNG output).

pub mod animate;
pub mod loop_cmd;
pub mod loop_demo;

use crate::global::{Global, StageBars};
use anyhow::{bail, Context, Result};
use ignis_core::Size;
use ignis_eigen::analysis::{self, ESelect};
use ignis_eigen::train::{ClipInput, ClipSpec, TrainConfig, TrainParams};
use ignis_eigen::{plot, EigenfireDb, PreprocessParams};
use ignis_eigen::{MediaFootage, Progress, SyntheticFootage};
use std::path::{Path, PathBuf};

/// `ignis eigen ...`
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// Train an Eigenfire database from videos (default settings) or from a clips.toml.
    #[command(
        after_help = "Examples:\n  ignis eigen train candle.mp4 campfire.mp4 -o fire.db\n  ignis eigen train clips.toml -o fire.db\n  ignis eigen train candle.mp4 --stride 2 --train-size 82x134 --keep 99% -o fire.db\n\nclips.toml:\n  [[clip]]\n  name = \"candle\"\n  path = \"candle.mp4\"\n  start = 0\n  end = 400\n  stride = 2\n  [preprocess]\n  train_size = \"102x168\"\n  [train]\n  pack_size = 100\n  e_detect = \"95%\""
    )]
    Train(TrainArgs),
    /// Describe a database: clips, frames, resolution, E, spectrum, thresholds, size.
    #[command(after_help = "Example:\n  ignis eigen info fire.db --json")]
    Info(InfoArgs),
    /// Draw the analysis figures (3-D scatter with paths, weight charts, spectrum,
    /// Eigenfire contact sheet, compression report) into a directory.
    #[command(after_help = "Example:\n  ignis eigen plot fire.db -o plots/")]
    Plot(PlotArgs),
    /// Reconstruct one training frame with E Eigenfires (eq. 22).
    #[command(
        after_help = "Example:\n  ignis eigen reconstruct fire.db --clip candle --frame 120 --eigenfires 50 -o f.png"
    )]
    Reconstruct(ReconstructArgs),
    /// Run pre-processing on a clip and write every stage's image, so you can see what
    /// each step does.
    #[command(
        after_help = "Example:\n  ignis eigen preprocess candle.mp4 --config pre.toml -o stages/\n  ignis eigen preprocess candle.mp4 --print-config > pre.toml"
    )]
    Preprocess(PreprocessArgs),
    /// Make a seamless loop of a clip range (§5.1): the range, then a transition from its
    /// end back to its start (End Growing, Direct Bridging or low-pass morphs).
    #[command(
        after_help = "Examples:\n  ignis eigen loop fire.db --clip candle --range 100..220 -o loop.mp4\n  ignis eigen loop fire.db --clip candle --length 4s -o loop.png\n  ignis eigen loop fire.db --clip candle --length 120 --range 0..400 -o loop.mp4\n  ignis eigen loop fire.db --clip candle --range 100..220 --size 640x360 -o loop.gif\n  ignis eigen loop fire.db --clip candle --range 100..220 --method low-pass --eigenfires 50 --palette candle -o loop.png\n  ignis eigen loop fire.db --clip candle --range 100..220 --relink candle=/new/place/candle.mp4 -o loop.mp4\n\nThe range is in source frame numbers (as `reconstruct --frame`); -o loop.png writes a flipbook.\nWith --length the clip (or the --range window) is searched for the best loop of about that length.\nFrames are at the source clip's size, in the footage's own colours with an alpha matte from the\npre-processing mask, database frames read from the source video (§7.1.2); --palette colours\nthe grey frames with a ramp instead; --from-database reconstructs every frame."
    )]
    Loop(LoopArgs),
    /// Create a new flame by setting Eigenfire weights by hand (§5.2), starting from the
    /// mean flame or from a database frame.
    #[command(
        after_help = "Examples:\n  ignis eigen synth fire.db --weights 2=12000,3=-5000 -o flame.png\n  ignis eigen synth fire.db --weights 0=1.5 --from candle:120 --eigenfires 50 -o flame.png\n\nIndices are 0-based Eigenfire numbers; the command prints each edited weight's spread in the database for scale."
    )]
    Synth(SynthArgs),
    /// Render a scenario (§5.1): named motions (clip ranges) in order, joined by
    /// transitions, coloured (original Algorithm 2, synthetic, palette or grey) with bloom,
    /// smoke and custom masks; prints a table per join (method, steps, seam ratio).
    #[command(
        after_help = "Examples:\n  ignis eigen scenario fire.db > scene.toml\n  ignis eigen animate scene.toml -o fire.mp4\n  ignis eigen animate scene.toml -o fire.png --columns 8\n  ignis eigen animate scene.toml --dry-run -o x.gif\n\nThe seam ratio is the largest step of the joined sequence over the footage's median step:\n1.0 is as smooth as the footage; a plain cut between different flames is typically 3 or more."
    )]
    Animate(crate::eigen::animate::AnimateArgs),
    /// Print a commented example scenario for a database (every clip as two motions).
    #[command(after_help = "Example:\n  ignis eigen scenario fire.db > scene.toml")]
    Scenario(crate::eigen::animate::ScenarioArgs),
}

fn parse_from(s: &str) -> std::result::Result<(String, usize), String> {
    let (c, f) = s
        .rsplit_once(':')
        .ok_or_else(|| format!("`{s}` is not CLIP:FRAME (e.g. candle:120)"))?;
    let f = f
        .parse::<usize>()
        .map_err(|_| format!("`{f}` in `{s}` is not a frame number"))?;
    if c.is_empty() {
        return Err(format!("`{s}` has no clip name (CLIP:FRAME)"));
    }
    Ok((c.to_string(), f))
}

#[derive(clap::Args, Debug)]
pub struct LoopArgs {
    /// Database directory.
    pub db: PathBuf,
    /// Clip name (see `ignis eigen info`).
    #[arg(long)]
    pub clip: String,
    /// Source frames START..END of the clip: alone, exactly this range is looped (closed
    /// with --method); with --length, the window the loop is searched in.
    #[arg(long, value_parser = crate::args::frame_span)]
    pub range: Option<std::ops::Range<usize>>,
    /// Search the clip (or the --range window) for the best loop of about this length:
    /// seconds (`4s`, at the clip's fps) or frames (`120`), ±20%; rendered from the source
    /// video at its own resolution and colours (needs the clip trained with --stride 1 and
    /// its source file where training found it).
    #[arg(long)]
    pub length: Option<String>,
    /// Transition back to the start. With --range alone: auto (best of the three),
    /// end-growing, direct (Direct Bridging) or low-pass. With --length: auto (best by
    /// measured seam and ghost), cut, crossfade or morph.
    #[arg(long, default_value = "auto", value_parser = ["auto", "end-growing", "direct", "low-pass", "cut", "crossfade", "morph"])]
    pub method: String,
    /// With --length: candidates to print.
    #[arg(long, default_value_t = 5)]
    pub top: usize,
    /// E for rendering reconstructed frames (default: the database's E for rendering).
    #[arg(long)]
    pub eigenfires: Option<usize>,
    /// Let the loop's first and last frames move inwards by up to N training frames each,
    /// to start and end where the footage is calm (0 = exactly the range).
    #[arg(long, default_value_t = 8)]
    pub search: usize,
    /// Colour the grey frames with a ramp (a preset or a gradient PNG, left = cold,
    /// right = hot) instead of the footage's own colours.
    #[arg(long)]
    pub palette: Option<crate::output::PaletteArg>,
    /// Alpha: `matte` (from the pre-processing mask: the flame keyed out of its
    /// surroundings) or `opaque`.
    #[arg(long, default_value = "matte", value_parser = crate::eigen::loop_cmd::ALPHA_CHOICES)]
    pub alpha: String,
    #[command(flatten)]
    pub footage: crate::eigen::animate::FootageArgs,
    #[command(flatten)]
    pub out: crate::output::OutputArgs,
}

#[derive(clap::Args, Debug)]
pub struct SynthArgs {
    /// Database directory.
    pub db: PathBuf,
    /// Weight edits INDEX=VALUE,... (0-based Eigenfire index), e.g. 2=12000,3=-5000.
    #[arg(long, allow_hyphen_values = true)]
    pub weights: String,
    /// Start from this database frame (CLIP:FRAME) instead of the mean flame.
    #[arg(long, value_parser = parse_from)]
    pub from: Option<(String, usize)>,
    /// E, the number of Eigenfires (default: the database's E for rendering; raised to
    /// cover every edited index).
    #[arg(long)]
    pub eigenfires: Option<usize>,
    /// Colour ramp: a preset or a gradient PNG; `grey` for the raw grey image.
    #[arg(long, default_value = "candle")]
    pub palette: crate::output::PaletteArg,
    /// Output PNG.
    #[arg(short, long)]
    pub output: PathBuf,
}

#[derive(clap::Args, Debug)]
pub struct TrainArgs {
    /// Videos / image sequences (each becomes a clip named after the file), or one .toml
    /// training configuration.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    #[command(flatten)]
    pub sequence: crate::args::SequenceFps,
    /// Output database directory (replaced atomically).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Pre-processing settings (TOML) for video inputs; see `ignis eigen preprocess --print-config`.
    #[arg(long)]
    pub config: Option<PathBuf>,
    #[command(flatten)]
    pub frames_from: FrameSelect,
    /// Eigenfires to keep: a count (200) or retained variance (99%); default all (M-1).
    #[arg(long)]
    pub keep: Option<ESelect>,
    /// E for recognition: a count or retained variance.
    #[arg(long)]
    pub e_detect: Option<ESelect>,
    /// E for rendering: a count or retained variance.
    #[arg(long)]
    pub e_render: Option<ESelect>,
    /// Eigenfires per pack file.
    #[arg(long)]
    pub pack_size: Option<usize>,
    /// Store the full-resolution pre-processed frames in the database (§7.1.2).
    #[arg(long)]
    pub store_frames: bool,
    /// Keep the data matrix on disk and use the streaming (randomized) PCA.
    #[arg(long)]
    pub streaming: bool,
    /// Memory budget in MB for the data matrix and PCA (default: available memory).
    #[arg(long)]
    pub memory_limit_mb: Option<u64>,
}

#[derive(clap::Args, Debug)]
pub struct InfoArgs {
    /// Database directory.
    pub db: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

#[derive(clap::Args, Debug)]
pub struct PlotArgs {
    /// Database directory.
    pub db: PathBuf,
    /// Output directory.
    #[arg(short, long)]
    pub output: PathBuf,
    /// Eigenfires on the contact sheet.
    #[arg(long, default_value_t = 16)]
    pub eigenfires: usize,
    /// Skip the compression report (slow on large databases).
    #[arg(long)]
    pub no_compression: bool,
}

#[derive(clap::Args, Debug)]
pub struct ReconstructArgs {
    /// Database directory.
    pub db: PathBuf,
    /// Clip name (see `ignis eigen info`).
    #[arg(long)]
    pub clip: String,
    /// Source frame number (must be one of the training frames).
    #[arg(long)]
    pub frame: usize,
    /// E, the number of Eigenfires (default: the database's E for rendering).
    #[arg(long)]
    pub eigenfires: Option<usize>,
    /// Apply Hermite background removal after reconstruction (§4.8).
    #[arg(long)]
    pub hermite: bool,
    /// Output PNG.
    #[arg(short, long)]
    pub output: PathBuf,
}

/// Which source frames a video input trains on, and the frame sizes (train and preprocess).
#[derive(clap::Args, Debug)]
pub struct FrameSelect {
    /// First source frame of every video input.
    #[arg(long, default_value_t = 0)]
    pub start: usize,
    /// One past the last source frame of every video input (default: to the end).
    #[arg(long)]
    pub end: Option<usize>,
    /// Use every N-th frame.
    #[arg(long, default_value_t = 1)]
    pub stride: usize,
    /// Size of the training frames, e.g. 102x168 (overrides the config).
    #[arg(long)]
    pub train_size: Option<Size>,
    /// Common pre-processed frame size, e.g. 410x670 (overrides the config).
    #[arg(long)]
    pub frame_size: Option<Size>,
    /// Only this rectangle X,Y,WIDTH,HEIGHT of every video input's frames (source pixels,
    /// top-left origin): one fire of several, a flame away from a lit wall. Recorded in
    /// the database, so renders from the footage cut it again. A config's clips take
    /// `crop = [x, y, width, height]`. Also as WIDTHxHEIGHT+X+Y, or ffmpeg cropdetect's
    /// crop=W:H:X:Y. Example: --crop 240,60,480,420
    #[arg(long, value_parser = crate::args::crop)]
    pub crop: Option<ignis_media::Rect>,
}

impl FrameSelect {
    /// A clip of `path` named `name` over the selected frames.
    fn clip(&self, name: &str, path: &Path) -> ClipSpec {
        let mut s = ClipSpec::new(name);
        s.path = Some(path.to_path_buf());
        s.start = self.start;
        s.end = self.end;
        s.stride = self.stride;
        s.crop = self.crop.map(|r| [r.x, r.y, r.width, r.height]);
        s
    }

    /// The sizes given on the command line, over those of the config.
    fn apply_sizes(&self, pre: &mut PreprocessParams) {
        if let Some(s) = self.train_size {
            pre.train_size = Some(s);
        }
        if let Some(s) = self.frame_size {
            pre.pose.frame_size = Some(s);
        }
    }
}

#[derive(clap::Args, Debug)]
pub struct PreprocessArgs {
    /// Video or image sequence.
    #[arg(required_unless_present = "print_config")]
    pub input: Option<PathBuf>,
    /// Pre-processing settings (TOML).
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Output directory for the stage images.
    #[arg(short, long, required_unless_present = "print_config")]
    pub output: Option<PathBuf>,
    /// Training-frame indices to show (default: first, middle, last).
    #[arg(long, value_delimiter = ',')]
    pub frames: Vec<usize>,
    #[command(flatten)]
    pub frames_from: FrameSelect,
    /// Print the settings (defaults, or --config with overrides) as TOML and exit.
    #[arg(long)]
    pub print_config: bool,
}

/// Runs `ignis eigen <cmd>`.
pub fn run(cmd: Command, g: &Global) -> Result<()> {
    match cmd {
        Command::Train(a) => train(a, g),
        Command::Info(a) => info(a, g),
        Command::Plot(a) => plot_cmd(a, g),
        Command::Reconstruct(a) => reconstruct(a, g),
        Command::Preprocess(a) => preprocess(a, g),
        Command::Loop(a) if a.length.is_some() => crate::eigen::loop_cmd::eigen_length_loop(&a, g),
        Command::Loop(a) => loop_cmd(&a, g).map(|_| ()),
        Command::Synth(a) => synth_cmd(&a, g).map(|_| ()),
        Command::Animate(a) => crate::eigen::animate::animate_cmd(&a, g).map(|_| ()),
        Command::Scenario(a) => crate::eigen::animate::scenario_cmd(&a),
    }
}

fn clip_name(path: &Path, taken: &[String]) -> String {
    let stem: String = path
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "clip".into())
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    let mut name = if stem.is_empty() {
        "clip".to_string()
    } else {
        stem
    };
    let base = name.clone();
    let mut i = 2;
    while taken.contains(&name) {
        name = format!("{base}-{i}");
        i += 1;
    }
    name
}

/// A clip's crop (`[x, y, width, height]`, as databases and configs record it) as a
/// rectangle.
pub fn rect([x, y, width, height]: [u32; 4]) -> ignis_media::Rect {
    ignis_media::Rect {
        x,
        y,
        width,
        height,
    }
}

/// `path`'s footage, cut to `crop` when given; a rectangle past the frame is refused,
/// naming the frame's size.
pub fn media_footage(path: &Path, crop: Option<[u32; 4]>) -> Result<MediaFootage> {
    let f = MediaFootage::open(path)?;
    match crop.map(rect) {
        None => Ok(f),
        Some(r) => {
            crate::args::crop_inside(&r, ignis_eigen::Footage::info(&f).size, path)?;
            Ok(f.cropped(r)?)
        }
    }
}

fn read_preprocess(config: Option<&Path>) -> Result<PreprocessParams> {
    match config {
        None => Ok(PreprocessParams::default()),
        Some(p) => {
            let text = crate::args::read_user_text(
                p,
                "pre-processing settings",
                "write them with `ignis eigen preprocess CLIP --print-config > pre.toml`",
            )?;
            PreprocessParams::from_toml(&text).with_context(|| format!("reading {}", p.display()))
        }
    }
}

pub fn train(a: TrainArgs, g: &Global) -> Result<()> {
    let is_toml = a.inputs.len() == 1 && a.inputs[0].extension().is_some_and(|e| e == "toml");
    let videos: Vec<&Path> = a.inputs.iter().map(PathBuf::as_path).collect();
    a.sequence.apply(if is_toml { &[] } else { &videos })?;
    let (specs, mut pre, mut tp) = if is_toml {
        let p = &a.inputs[0];
        let text = crate::args::read_user_text(
            p,
            "clips file",
            "give the videos themselves (`ignis eigen train --help` shows a clips file)",
        )?;
        let base = p.parent().unwrap_or(Path::new("."));
        let c = TrainConfig::from_toml(&text, base)
            .with_context(|| format!("reading {}", p.display()))?;
        (c.clips, c.preprocess, c.train)
    } else {
        let mut specs: Vec<ClipSpec> = Vec::new();
        for p in &a.inputs {
            let taken: Vec<String> = specs.iter().map(|s| s.name.clone()).collect();
            specs.push(a.frames_from.clip(&clip_name(p, &taken), p));
        }
        (
            specs,
            read_preprocess(a.config.as_deref())?,
            TrainParams::default(),
        )
    };
    a.frames_from.apply_sizes(&mut pre);
    // a variable frame rate: every frame is taken once, as if evenly spaced
    for s in &specs {
        let Some(path) = &s.path else { continue };
        // a sequence's file numbers given as its frames (`--start 1001` of shot.1001.exr …);
        // the whole clip (the usual case) needs no look
        let bounded = s.start > 0 || s.end.is_some();
        let count = bounded
            .then(|| ignis_media::probe(path).ok().and_then(|i| i.frame_count))
            .flatten();
        if let Some(n) = count.map(|n| n as usize) {
            if s.start >= n || s.end.is_some_and(|e| e > n) {
                let end = s.end.map(|e| e as u64);
                if let Some(h) = ignis_media::file_numbers_hint(path, s.start as u64, end) {
                    bail!(
                        "clip `{}`: the frames {}..{} go past the end of {} ({n} frames); {h}",
                        s.name,
                        s.start,
                        s.end.map_or(String::new(), |e| e.to_string()),
                        path.display()
                    );
                }
            }
        }
        let window = s.start..s.end.unwrap_or(usize::MAX);
        if let Some(t) = loop_cmd::WindowTiming::of(path, window) {
            g.say(format!(
                "warning: clip `{}`: {}",
                s.name,
                t.warning(
                    s.start,
                    &format!(
                        "its frames are taken as if evenly spaced and played at {} {:.3} fps \
                         (eigen loop, eigen animate)",
                        if t.numbered { "its" } else { "the average" },
                        t.played_fps()
                    ),
                    |r| match is_toml {
                        true => format!("start = {}, end = {}", r.start, r.end),
                        false => format!("--start {} --end {}", r.start, r.end),
                    },
                )
            ));
        }
    }
    if a.keep.is_some() {
        tp.keep = a.keep;
    }
    if let Some(e) = a.e_detect {
        tp.e_detect = e;
    }
    if let Some(e) = a.e_render {
        tp.e_render = e;
    }
    if let Some(p) = a.pack_size {
        tp.pack_size = p;
    }
    tp.store_frames |= a.store_frames;
    tp.streaming |= a.streaming;
    if let Some(mb) = a.memory_limit_mb {
        tp.memory_limit = Some(mb.saturating_mul(1 << 20));
    }
    let mut clips = Vec::new();
    for s in specs {
        let footage: Box<dyn ignis_eigen::Footage> = match (&s.path, s.synthetic) {
            (Some(p), _) => {
                Box::new(media_footage(p, s.crop).with_context(|| format!("clip `{}`", s.name))?)
            }
            (None, Some(style)) => Box::new(SyntheticFootage::new(
                ignis_eigen::synthetic::SyntheticParams {
                    style,
                    frames: s.end.unwrap_or(120),
                    ..Default::default()
                },
                30.0,
            )),
            (None, None) => bail!("clip `{}` has neither a path nor `synthetic`", s.name),
        };
        clips.push(ClipInput { spec: s, footage });
    }
    let mut bars = StageBars::new(g);
    let r = ignis_eigen::train(&clips, &pre, &tp, &a.output, &mut bars)
        .with_context(|| format!("training {}", a.output.display()))?;
    bars.finish_stage();
    let m = &r.manifest;
    g.say(format!(
        "wrote {}: {} clips, {} frames at {}, {} Eigenfires in {} packs, E detect {} / render {}",
        r.path.display(),
        m.clips.len(),
        m.frames,
        m.train_size,
        m.components,
        m.packs.len(),
        m.e_detect,
        m.e_render
    ));
    Ok(())
}

pub(crate) fn open_db(p: &Path) -> Result<EigenfireDb> {
    EigenfireDb::open(p).with_context(|| format!("opening {}", p.display()))
}

fn info(a: InfoArgs, g: &Global) -> Result<()> {
    let db = open_db(&a.db)?;
    let m = db.manifest();
    let problems = db.verify();
    let ev = db.eigenvalues();
    let total = m.total_variance.max(f64::MIN_POSITIVE);
    let for_var = |f: f64| ESelect::Variance(f).resolve(ev, total);
    let retained = ev.iter().sum::<f64>() / total;
    if a.json {
        let v = serde_json::json!({
            "path": a.db,
            "format_version": m.version,
            "frames": m.frames,
            "train_size": m.train_size.to_string(),
            "frame_size": m.frame_size.to_string(),
            "framing": m.framing,
            "components": m.components,
            "usable_components": db.usable_components(),
            "e_detect": m.e_detect,
            "e_render": m.e_render,
            "pack_size": m.pack_size,
            "packs": m.packs.len(),
            "eigenvalues_top": ev.iter().take(10).collect::<Vec<_>>(),
            "components_for_variance": {"90%": for_var(0.9), "95%": for_var(0.95), "99%": for_var(0.99)},
            "retained_variance": retained,
            "bytes_on_disk": db.bytes_on_disk(),
            "clips": m.clips,
            "problems": problems.iter().map(|(f, r)| serde_json::json!({"file": f, "reason": r})).collect::<Vec<_>>(),
        });
        outln!("{}", serde_json::to_string_pretty(&v)?)?;
        return Ok(());
    }
    let _ = g;
    outln!("{}", a.db.display())?;
    outln!(
        "  frames       {} (training size {}, pre-processed size {})",
        m.frames,
        m.train_size,
        m.frame_size
    )?;
    if !m.framing.is_empty() {
        outln!("  framing      {}", m.framing)?;
    }
    outln!(
        "  Eigenfires   {} stored in {} packs of {}, {} usable",
        m.components,
        m.packs.len(),
        m.pack_size,
        db.usable_components()
    )?;
    outln!(
        "  E            detection {}, rendering {}",
        m.e_detect,
        m.e_render
    )?;
    outln!(
        "  spectrum     λ1..3 = {}; 90% variance at E={}, 95% at {}, 99% at {}; stored Eigenfires retain {:.2}%",
        ev.iter().take(3).map(|v| format!("{v:.4}")).collect::<Vec<_>>().join(", "),
        for_var(0.9),
        for_var(0.95),
        for_var(0.99),
        retained * 100.0
    )?;
    outln!("  size on disk {:.2} MB", db.bytes_on_disk() as f64 / 1e6)?;
    for c in &m.clips {
        outln!(
            "  clip {:<12} {} frames {}..{} step {} @ {:.2} fps, {}{} → scale {:.3}{}; θ_min {:.4}, θ_average {:.4} (E={}, {} peaks)",
            c.name,
            c.frames,
            c.start,
            c.end,
            c.stride,
            c.fps,
            c.source_size,
            c.crop.map_or(String::new(), |[x, y, _, _]| format!(" cut at {x},{y}")),
            c.pose.scale,
            match (c.pose.isolate, c.static_lit) {
                (true, Some(f)) => format!(", flame isolated ({:.0}% of the lit pixels static: lit surroundings)", f * 100.0),
                (false, Some(f)) => format!(", whole lit area kept ({:.0}% static)", f * 100.0),
                (true, None) => ", flame isolated".to_string(),
                (false, None) => String::new(),
            },
            c.thresholds.theta_min,
            c.thresholds.theta_average,
            c.thresholds.e,
            c.thresholds.peaks.len()
        )?;
        if let Some(fc) = c.flame_colour {
            outln!(
                "    flame colour (linear RGB, the bloom's tint in original colouring) {:.3}, {:.3}, {:.3}",
                fc[0], fc[1], fc[2]
            )?;
        }
        let still = c.pose.still_lights.boxes();
        if !still.is_empty() {
            let list: Vec<String> = still
                .iter()
                .map(|b| format!("{}x{}+{}+{}", b[2] - b[0], b[3] - b[1], b[0], b[1]))
                .collect();
            outln!(
                "    {} still light(s) left out of the mask (bright and steady, away from the fire; WxH+X+Y): {}",
                still.len(),
                list.join(", ")
            )?;
        }
    }
    for (f, r) in &problems {
        outln!("  PROBLEM {f}: {r}")?;
    }
    Ok(())
}

fn write_gray(path: &Path, f: &ignis_core::GrayFrame) -> Result<()> {
    ignis_media::write_png(path, &f.to_rgba())
        .with_context(|| format!("writing {}", path.display()))
}

/// Writes every analysis figure of `db` into `dir`; returns `(file name, caption)`.
pub fn write_plots(
    db: &EigenfireDb,
    dir: &Path,
    sheet: usize,
    compression: bool,
) -> Result<Vec<(String, String)>> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut out = Vec::new();
    let p = dir.join("scatter3d.png");
    plot::scatter_3d(db, &p, (900, 700))?;
    out.push(("scatter3d.png".to_string(), "Training frames on Eigenfires 1-3, coloured by clip, consecutive frames joined (Figure 24)".to_string()));
    for c in db.clips() {
        let f = format!("weights-{}.png", c.name);
        plot::weight_clusters(db, &c.name, 0, 31, 10, &dir.join(&f), (900, 450))?;
        out.push((
            f,
            format!(
                "Clip {}: weights of Eigenfires 1-10 over 31 consecutive frames (Figure 27)",
                c.name
            ),
        ));
        let f = format!("frame-weights-{}.png", c.name);
        plot::frame_weights(db, c.first_row, 100, &dir.join(&f), (900, 400))?;
        out.push((
            f,
            format!(
                "Clip {}: the first 100 weights of one frame (Figure 28)",
                c.name
            ),
        ));
    }
    plot::spectrum(db, &dir.join("spectrum.png"), (800, 450))?;
    out.push((
        "spectrum.png".into(),
        "Eigenvalue spectrum and retained variance".into(),
    ));
    let s = analysis::eigenfire_sheet(db, sheet, 8)?;
    write_gray(&dir.join("eigenfires.png"), &s)?;
    out.push((
        "eigenfires.png".into(),
        format!("The first {sheet} Eigenfires scaled by eq. 19-20"),
    ));
    if compression {
        let k = db.usable_components();
        let mut es: Vec<usize> = [1, 2, 5, 10, 20, 50, 100, 200, 500, 1000]
            .iter()
            .copied()
            .filter(|&e| e < k)
            .collect();
        es.push(k);
        let rep = analysis::compression_report(db, &es, 8, &db.manifest().preprocess.hermite)?;
        plot::compression_chart(&rep, &dir.join("compression.png"), (800, 450))?;
        let json = serde_json::to_string_pretty(&rep)?;
        std::fs::write(dir.join("compression.json"), json)
            .with_context(|| format!("writing {}", dir.join("compression.json").display()))?;
        out.push((
            "compression.png".into(),
            "PSNR against E, with and without Hermite clean-up (data in compression.json)".into(),
        ));
    }
    Ok(out)
}

fn plot_cmd(a: PlotArgs, g: &Global) -> Result<()> {
    let db = open_db(&a.db)?;
    let sp = g.spinner("plotting");
    // All figures or none: staged beside the output directory, moved in at the end.
    let staged = crate::output::StagedDir::new(&a.output)?;
    let files = write_plots(&db, staged.path(), a.eigenfires, !a.no_compression)?;
    staged.commit()?;
    sp.finish_and_clear();
    for (f, c) in files {
        g.say(format!("wrote {} — {c}", a.output.join(f).display()));
    }
    Ok(())
}

fn reconstruct(a: ReconstructArgs, g: &Global) -> Result<()> {
    let db = open_db(&a.db)?;
    let row = db.frame_index(&a.clip, a.frame)?;
    let e = a.eigenfires.unwrap_or(db.manifest().e_render);
    let herm = db.manifest().preprocess.hermite.clone();
    let f = analysis::reconstruct_row(&db, row, e, a.hermite.then_some(&herm))?;
    write_gray(&a.output, &f)?;
    g.say(format!(
        "wrote {} ({} frame {} with E = {})",
        a.output.display(),
        a.clip,
        a.frame,
        e.min(db.usable_components())
    ));
    Ok(())
}

/// `ignis eigen loop`; returns the join (for the demo's caption).
fn loop_cmd(a: &LoopArgs, g: &Global) -> Result<ignis_eigen::transition::Join> {
    use ignis_eigen::scenario::ColourMode;
    use ignis_eigen::{animate, render};
    let db = open_db(&a.db)?;
    let method = animate::parse_method(&a.method)?;
    let e = a.eigenfires.unwrap_or(db.manifest().e_render);
    if e == 0 {
        bail!("--eigenfires must be at least 1");
    }
    // Bad --size and the like fail before the search.
    a.footage.options()?;
    let mut look = crate::eigen::animate::default_look();
    if let Some(p) = &a.palette {
        look.mode = ColourMode::Palette(p.load()?);
        look.bloom = None;
    }
    a.footage.adjust_look(&mut look, g);
    look.matte = a.alpha == "matte";
    let range = a.range.clone().context(
        "give --range START..END (loop exactly that range) or --length (search for a loop)",
    )?;
    if look.matte {
        let c = db.clip(&a.clip)?;
        let rows = animate::clip_rows(&db, &a.clip, range.clone())?;
        let (first, stride) = (c.start + (rows.start - c.first_row) * c.stride, c.stride);
        crate::eigen::loop_cmd::refuse_keyed_out_range(&db, rows, &|i| first + i * stride)?;
    }
    let sp = g.spinner("finding the transition");
    let (plan, report) = render::loop_plan(&db, &a.clip, range.clone(), method, e, a.search)
        .with_context(|| {
            format!(
                "looping clip `{}` frames {}..{} with {}",
                a.clip, range.start, range.end, a.method
            )
        })?;
    sp.finish_and_clear();
    let size = crate::eigen::animate::write_plan(&db, &plan, &look, &a.footage, &a.out, g)
        .with_context(|| format!("rendering the loop of clip `{}`", a.clip))?;
    g.say(format!(
        "{}; {size}, colour {}",
        report.summary(),
        look.mode.name()
    ));
    if let Some(moved) = report.moved() {
        g.say(moved);
    }
    g.say(format!("why: {}", report.join.why));
    Ok(report.join)
}

/// `ignis eigen synth`.
fn synth_cmd(a: &SynthArgs, g: &Global) -> Result<()> {
    use ignis_eigen::animate;
    let db = open_db(&a.db)?;
    let edits = animate::parse_weight_edits(&a.weights).context("reading --weights")?;
    let e = a.eigenfires.unwrap_or(db.manifest().e_render);
    let palette = a.palette.load()?;
    let from = a.from.as_ref().map(|(c, f)| (c.as_str(), *f));
    let f = animate::synth(&db, from, &edits, e).with_context(|| {
        format!(
            "synthesising from {}",
            match &a.from {
                Some((c, fr)) => format!("clip `{c}` frame {fr}"),
                None => "the mean flame".into(),
            }
        )
    })?;
    ignis_media::write_png(&a.output, &palette.apply(&f))
        .with_context(|| format!("writing {}", a.output.display()))?;
    let w = db.weights();
    let spread = |j: usize| {
        let m = w.nrows().max(1) as f64;
        let mean = (0..w.nrows()).map(|i| w[(i, j)] as f64).sum::<f64>() / m;
        ((0..w.nrows())
            .map(|i| (w[(i, j)] as f64 - mean).powi(2))
            .sum::<f64>()
            / m)
            .sqrt()
    };
    let notes: Vec<String> = edits
        .iter()
        .map(|&(i, v)| format!("ω{i} = {v} (database spread ±{:.3})", spread(i)))
        .collect();
    g.say(format!(
        "wrote {} ({} at {}): {}",
        a.output.display(),
        match &a.from {
            Some((c, fr)) => format!("clip {c} frame {fr}"),
            None => "mean flame".into(),
        },
        f.size(),
        notes.join(", ")
    ));
    Ok(())
}

fn preprocess(a: PreprocessArgs, g: &Global) -> Result<()> {
    let mut pre = read_preprocess(a.config.as_deref())?;
    a.frames_from.apply_sizes(&mut pre);
    if a.print_config {
        out!("{}", pre.to_toml())?;
        return Ok(());
    }
    let (Some(input), Some(out)) = (a.input, a.output) else {
        bail!("give an input and -o DIR")
    };
    let spec = a.frames_from.clip(&clip_name(&input, &[]), &input);
    let footage = media_footage(&input, spec.crop)?;
    let clip = ClipInput::new(spec, footage);
    let mut bars = StageBars::new(g);
    let stages = ignis_eigen::train::preprocess_clip(&clip, &pre, &a.frames, &mut bars)
        .with_context(|| format!("pre-processing {}", input.display()))?;
    bars.finish_stage();
    let staged = crate::output::StagedDir::new(&out)?;
    for (frame, st) in &stages {
        for (name, img) in &st.images {
            let p = staged.path().join(format!("frame{frame:05}-{name}.png"));
            ignis_media::write_png(&p, img).with_context(|| format!("writing {}", p.display()))?;
        }
    }
    staged.commit()?;
    g.say(format!(
        "wrote {} stage images for {} frames to {}",
        stages.iter().map(|s| s.1.images.len()).sum::<usize>(),
        stages.len(),
        out.display()
    ));
    Ok(())
}

/// The Eigenfire section of `ignis demo`: trains a database on two synthetic clips (so
/// nothing external is needed) and adds its figures to the gallery.
pub fn demo(ctx: &mut crate::demo::Demo) -> Result<()> {
    ctx.section(
        "Eigenfires I (eigenfires thesis ch. 3-4)",
        "Two synthetic flame clips rendered by Ignis are pre-processed (HSV mask, contours, Hermite background removal, pose normalisation), a PCA gives the Eigenfires, and every frame becomes a vector of weights.",
    );
    let (size, frames, train) = if ctx.quick {
        (
            Size {
                width: 48,
                height: 64,
            },
            10,
            Size {
                width: 24,
                height: 32,
            },
        )
    } else {
        (
            Size {
                width: 96,
                height: 128,
            },
            60,
            Size {
                width: 60,
                height: 96,
            },
        )
    };
    let clips = ignis_eigen::train::synthetic_clips(size, frames, ctx.seed);
    let mut pre = PreprocessParams::with_sizes(
        Size {
            width: train.width * 2,
            height: train.height * 2,
        },
        Some(train),
    );
    pre.pose_samples = 8;
    let tp = TrainParams {
        pack_size: 16,
        store_frames: true,
        ..Default::default()
    };
    let dbp = ctx.path("eigen/fire.db")?;
    let mut bars = StageBars::new(&ctx.global);
    let r = ignis_eigen::train(&clips, &pre, &tp, &dbp, &mut bars)
        .context("training the demo Eigenfire database")?;
    drop(bars);
    let db = open_db(&dbp)?;
    let settings = format!("2 synthetic clips × {frames} frames at {size}, seed {}, training size {train}, {} Eigenfires", ctx.seed, r.manifest.components);
    let plots = ctx.path("eigen/plots")?;
    let files = write_plots(&db, &plots, 16, true)?;
    for (f, caption) in files {
        ctx.item(&format!("eigen/plots/{f}"), &caption, &settings);
    }
    // Reconstructions with increasing E, side by side with the pre-processed frame.
    let row = db.clip("campfire")?.first_row + frames / 2;
    let k = db.usable_components();
    let mut strip = Vec::new();
    for e in [1, 3, 10, k] {
        strip.push(analysis::reconstruct_row(&db, row, e.min(k), None)?);
    }
    let sheet = analysis::contact_sheet(&strip, 4, 2)?;
    let p = ctx.path("eigen/reconstruct.png")?;
    write_gray(&p, &sheet)?;
    ctx.item(
        "eigen/reconstruct.png",
        &format!("A campfire frame reconstructed with E = 1, 3, 10 and {k} (eq. 22)"),
        &settings,
    );
    // A loop (§5.1) over most of the candle clip, and a synthesised flame (§5.2).
    let g = crate::global::Global { quiet: true };
    let c = db.clip("candle")?;
    let (lo, hi) = (c.start + c.stride, c.start + c.stride * c.frames);
    let range = format!("{lo}..{hi}");
    let dbs = dbp.to_string_lossy().to_string();
    let gif = ctx.path("eigen/loop.gif")?;
    let gifs = gif.to_string_lossy().to_string();
    let argv = [
        "loop",
        &dbs,
        "--clip",
        "candle",
        "--range",
        &range,
        "--palette",
        "candle",
        "-o",
        &gifs,
    ];
    let join = loop_cmd(&crate::parse_sub::<LoopArgs>(&argv)?, &g).context("demo loop")?;
    ctx.item(
        "eigen/loop.gif",
        &format!(
            "Candle frames {range} looped (§5.1): {} with {} transition frame(s), seam ratio {:.2}",
            join.method,
            join.frames.len(),
            join.seam_ratio
        ),
        &format!(
            "ignis eigen loop fire.db --clip candle --range {range} --palette candle -o loop.gif"
        ),
    );
    let png = ctx.path("eigen/synth.png")?;
    let pngs = png.to_string_lossy().to_string();
    let j = (0..db.n_frames())
        .map(|i| db.frame_weights(i)[0].abs())
        .fold(0.0f32, f32::max);
    let wts = format!("0={:.3}", 1.5 * j);
    let argv = [
        "synth",
        &dbs,
        "--weights",
        &wts,
        "--palette",
        "candle",
        "-o",
        &pngs,
    ];
    synth_cmd(&crate::parse_sub::<SynthArgs>(&argv)?, &g).context("demo synth")?;
    ctx.item(
        "eigen/synth.png",
        "A new flame (§5.2): the mean flame with Eigenfire 0's weight set to 1.5 × its largest value in the database",
        &format!("ignis eigen synth fire.db --weights {wts} --palette candle -o synth.png"),
    );
    crate::eigen::animate::demo(ctx, &dbp)
}
