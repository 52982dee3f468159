//! `ignis volume`: real-time procedural volumetric fire (Fuller et al.), CPU renderer.
//! A thin layer over `ignis-volume`: fire files and presets are parsed there; this module
//! only maps arguments, loads profile images and writes frames via `ignis-media`.

use crate::frames::FrameArgs;
use crate::global::Global;
use crate::output::OutputArgs;
use anyhow::{Context, Result};
use ignis_core::Size;
use ignis_volume::{Blend, FireScene, NoiseKind, Preset};
use std::path::{Path, PathBuf};

#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// Render a fire file or a preset to MP4, GIF, a flipbook (PNG + JSON) or a sequence.
    #[command(
        after_help = "Examples:\n  ignis volume render fire.toml --frames 240 -o fire.mp4\n  \
ignis volume render --preset torch --size 512x512 --frames 120 -o fire.png     # flipbook with alpha\n  \
ignis volume render --preset campfire --noise mnoise --octaves 2 -o camp.gif\n  \
ignis volume render fire.toml --collisions hits.jsonl -o fire.mp4            # report contacts\n  \
ignis volume render --preset torch --frames 64 --loop -o loop.mp4            # seamless loop as MP4\n  \
ignis volume render --preset torch --frames 1000 --chunk 300..400 -o out/%04d.exr   # one farm job"
    )]
    Render(Box<RenderArgs>),
    /// Print a preset as a commented fire file, to edit and render (`> fire.toml`).
    #[command(
        after_help = "Examples:\n  ignis volume scene --preset torch > torch.toml      # edit it, then:\n  \
ignis volume render torch.toml --frames 64 -o torch.png\n  \
ignis volume scene --preset campfire -o camp.toml\n\n\
Rendered unedited, the file gives the same frames as the preset, byte for byte."
    )]
    Scene(SceneArgs),
}

#[derive(clap::Args, Debug)]
pub struct SceneArgs {
    /// The built-in scene to print: torch, candle, campfire or wall.
    #[arg(long, default_value = "torch", value_parser = ["torch", "candle", "campfire", "wall"])]
    pub preset: String,
    /// Write the fire file here instead of printing it.
    #[arg(short, long)]
    pub output: Option<PathBuf>,
}

#[derive(clap::Args, Debug)]
pub struct RenderArgs {
    /// Fire file (TOML: profile, curve/script/simulation, noise, camera, obstacles).
    pub file: Option<PathBuf>,
    /// Built-in scene instead of a file: torch, candle, campfire or wall.
    #[arg(long, value_parser = ["torch", "candle", "campfire", "wall"], conflicts_with = "file")]
    pub preset: Option<String>,
    /// Output size WIDTHxHEIGHT (default: the file's `render.size`, else 256x256).
    #[arg(long)]
    pub size: Option<Size>,
    /// Number of frames.
    #[arg(long, default_value_t = 120)]
    pub frames: u32,
    /// Seed (per-fire noise offsets, particle dispersion); default: the file's.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Noise for every fire: perlin3, perlin4 or mnoise.
    #[arg(long, value_parser = ["perlin3", "perlin4", "mnoise"])]
    pub noise: Option<String>,
    /// Octaves of turbulence for every fire (0–8).
    #[arg(long)]
    pub octaves: Option<u32>,
    /// Lattice resolution (levels along the curve).
    #[arg(long)]
    pub lattice: Option<usize>,
    /// Slice spacing, world units (> 0).
    #[arg(long)]
    pub slice_spacing: Option<f32>,
    /// Blend mode: additive, cartoon, or tint:R,G,B (linear, e.g. tint:0.3,0.5,1).
    #[arg(long)]
    pub blend: Option<String>,
    /// Disable bloom.
    #[arg(long)]
    pub no_bloom: bool,
    /// Write every fire–obstacle contact as JSON lines (frame, fire, obstacle, point, normal, strength).
    #[arg(long)]
    pub collisions: Option<PathBuf>,
    /// Where a loop's frame times are kept (default: `ignis loop`'s cache,
    /// $XDG_CACHE_HOME/ignis or ~/.cache/ignis). A looping render times its frames on a
    /// preview of the whole loop; a later render of the same scene, size and --frames by
    /// the same `ignis` (another --chunk of a farm render, another output format) reads
    /// them instead and writes the same bytes. Point the farm's jobs at shared storage,
    /// e.g. --cache /farm/cache
    #[arg(long, value_name = "DIR")]
    pub cache: Option<PathBuf>,
    #[command(flatten)]
    pub frames_args: FrameArgs,
    #[command(flatten)]
    pub out: OutputArgs,
}

fn parse_blend(s: &str) -> Result<Blend> {
    match s {
        "additive" => Ok(Blend::Additive),
        "cartoon" => Ok(Blend::Cartoon),
        t if t.starts_with("tint:") => {
            let v: Vec<f32> = t[5..]
                .split(',')
                .map(|x| x.trim().parse::<f32>())
                .collect::<Result<_, _>>()
                .with_context(|| format!("--blend {t}: write tint:R,G,B, e.g. tint:0.3,0.5,1"))?;
            anyhow::ensure!(
                v.len() == 3,
                "--blend {t}: a tint needs three numbers R,G,B"
            );
            Ok(Blend::Tint([v[0], v[1], v[2]]))
        }
        other => anyhow::bail!("--blend {other}: choose additive, cartoon or tint:R,G,B"),
    }
}

fn parse_noise(s: &str) -> NoiseKind {
    match s {
        "perlin3" => NoiseKind::Perlin3,
        "mnoise" => NoiseKind::Mnoise,
        _ => NoiseKind::Perlin4,
    }
}

/// Reads a fire file, loading profile images with `ignis-media`.
pub fn load_fire_file(path: &Path) -> Result<FireScene> {
    let text = crate::args::read_user_text(
        path,
        "fire file",
        "render a built-in scene with --preset torch, candle, campfire or wall",
    )?;
    let base = path.parent().unwrap_or(Path::new("."));
    FireScene::from_toml(&text, base, &mut |p| {
        ignis_media::read_image(p).map_err(|e| e.to_string())
    })
    .with_context(|| format!("fire file {}", path.display()))
}

impl RenderArgs {
    /// The scene these arguments describe.
    pub fn scene(&self) -> Result<FireScene> {
        let mut s = match (&self.file, &self.preset) {
            (Some(f), _) => load_fire_file(f)?,
            (None, Some(p)) => FireScene::preset(p.parse::<Preset>()?),
            (None, None) => {
                anyhow::bail!("give a fire file or --preset torch|candle|campfire|wall")
            }
        };
        if let Some(size) = self.size {
            s = s.with_size(size);
        }
        if let Some(seed) = self.seed {
            s.seed = seed;
        }
        if let Some(v) = self.lattice {
            s.lattice = v;
        }
        if let Some(v) = self.slice_spacing {
            s.slice_spacing = v;
        }
        if let Some(b) = &self.blend {
            s.blend = parse_blend(b)?;
        }
        if self.no_bloom {
            s.bloom.passes = 0;
        }
        for f in &mut s.fires {
            if let Some(n) = &self.noise {
                f.noise.kind = parse_noise(n);
            }
            if let Some(o) = self.octaves {
                f.noise.octaves = o;
            }
        }
        // --fps sets the animation rate too; a preset plays at the default rate
        if self.out.fps.is_some() || self.file.is_none() {
            s.fps = self.out.fps() as f32;
        }
        s.validate().context("volume settings")?;
        Ok(s)
    }
}

pub fn run(cmd: Command, g: &Global) -> Result<()> {
    match cmd {
        Command::Render(a) => render(&a, g).map(|_| ()),
        Command::Scene(a) => scene(&a, g),
    }
}

/// Runs `ignis volume scene`: the preset as a commented fire file.
fn scene(a: &SceneArgs, g: &Global) -> Result<()> {
    let preset = a.preset.parse::<Preset>()?;
    let text = FireScene::preset(preset).to_toml(&format!(
        "the `{}` preset (`ignis volume scene --preset {}`)",
        preset.name(),
        preset.name()
    ))?;
    match &a.output {
        None => out!("{text}")?,
        Some(p) => {
            crate::args::text_output(p, &text)?
                .commit()
                .with_context(|| format!("writing {}", p.display()))?;
            g.say(format!("wrote {}", p.display()));
        }
    }
    Ok(())
}

/// Runs `ignis volume render`; returns the files written.
pub fn render(a: &RenderArgs, g: &Global) -> Result<Vec<PathBuf>> {
    let plan = a.frames_args.plan(a.frames, &a.out)?;
    let scene = a.scene()?;
    if let Some(p) = &a.collisions {
        crate::args::check_text_output(p)?;
    }
    let mut opts = a.out.write_options();
    opts.fps = scene.fps as f64;
    opts.loop_ = plan.mark_loop;
    opts.first_frame = plan.range.start as u64;
    // --variants N: N loops with seeds seed, seed + 1, …, one per row of the sheet.
    let whole_loop = plan.looping && plan.range == (0..a.frames);
    // motion vectors chosen by the rendered in-between frames, unless the sheet is retimed
    // (its frames are then cross-fades the renderer never drew): then the flow's
    let in_between = (opts.flipbook.motion.is_some() && !opts.flipbook.fit_frames)
        .then(|| crate::inbetween::InBetween::new(opts.loop_));
    if let Some(m) = &in_between {
        opts.flipbook.motion = Some(m.source());
    }
    let (mut writer, variants) =
        a.out
            .create_variants(scene.size, plan.range.len(), &mut opts, whole_loop)?;
    let mut hits = String::new();
    let scenes: Vec<_> = (0..variants)
        .map(|v| {
            let mut sc = scene.clone();
            sc.seed = scene.seed.wrapping_add(v as u64);
            sc
        })
        .collect();
    let mut anim = None;
    let pb = g.progress(plan.range.len() as u64 * variants as u64, "rendering");
    for (variant, i) in (0..variants).flat_map(|v| plan.range.clone().map(move |i| (v, i))) {
        if i == plan.range.start {
            let sc = &scenes[variant as usize];
            anim = Some(if plan.looping {
                looping_animator(sc, a.frames, a.cache.as_deref(), g)?
            } else {
                sc.animator()?
            });
            // a chunk replays only the motion (cheap) up to its first frame
            if let Some(an) = anim.as_mut() {
                an.skip(plan.range.start as u64);
            }
            if let Some(m) = &in_between {
                m.start_row();
            }
        }
        let an = anim.as_mut().expect("made at the range's start");
        let f = an.next_frame().context("rendering")?;
        if let Some(m) = &in_between {
            if m.wants(i + 1 < plan.range.end) {
                m.record(an.frame_between(0.5).context("rendering")?.image);
            }
        }
        if a.collisions.is_some() {
            for c in &f.collisions {
                let mut v = serde_json::to_value(c)?;
                v["frame"] = (variant * a.frames + i).into(); // the frame's place in the output
                hits.push_str(&v.to_string());
                hits.push('\n');
            }
        }
        writer
            .push(&f.image)
            .with_context(|| format!("writing {}", a.out.output.display()))?;
        pb.inc(1);
    }
    pb.finish_and_clear();
    // The collision log is written to its atomic temporary first: if that fails, the
    // writer is dropped and nothing is written; then the frames, then the log renamed.
    let staged = match &a.collisions {
        Some(p) => Some((crate::args::text_output(p, &hits)?, p.clone())),
        None => None,
    };
    // On an error the log's temporary is removed as `staged` drops.
    let mut files = writer
        .finish()
        .with_context(|| format!("finishing {}", a.out.output.display()))?;
    if let Some((f, p)) = staged {
        f.commit()
            .with_context(|| format!("writing {}", p.display()))?;
        files.push(p);
    }
    for f in &files {
        g.say(format!("wrote {}", f.display()));
    }
    Ok(files)
}

/// `sc`'s looping animator of `frames` frames, its frames' loop times read from the cache
/// (`dir`, else `ignis loop`'s; [`crate::kept_times`]) when a render of the same scene,
/// size and length by this same build of `ignis` kept them, else timed on a preview and
/// kept there.
fn looping_animator<'a>(
    sc: &'a FireScene,
    frames: u32,
    dir: Option<&Path>,
    g: &Global,
) -> Result<ignis_volume::Animator<'a>> {
    // everything the times depend on: the scene (every field, by its `Debug` form, which
    // prints floats exactly), the loop's length and the timing
    let key = format!(
        "frames={frames} timing={:?} scene={sc:?}",
        ignis_volume::LoopTiming::DEFAULT
    );
    let kept = crate::kept_times::KeptTimes::new(
        dir,
        "volume",
        &key,
        "ignis volume render: the loop time (in frames) of each frame of one cycle",
    );
    if let Some(times) = kept.read(frames as usize) {
        if let Ok(a) = sc.looping_animator_with_times(frames, &times) {
            return Ok(a);
        }
    }
    let a = sc.looping_animator(frames)?;
    if let Some(times) = a.loop_times() {
        kept.keep(times, g);
    }
    Ok(a)
}

/// The demo section: every preset as a looping GIF and a flipbook with alpha.
pub fn demo(ctx: &mut crate::demo::Demo) -> Result<()> {
    ctx.section(
        "Procedural volumetric fire",
        "Fuller et al. (2007): a fire profile image swept into a volume, bent along a B-spline lattice moved by a \
         script or a particle simulation, animated by 4-D Improved Perlin noise and rendered by view-aligned slicing \
         (CPU). Each preset as a seamlessly looping GIF and flipbook with alpha (a billboard); `ignis volume scene \
         --preset NAME > fire.toml` prints one as a commented fire file to edit and render.",
    );
    let (size, frames) = if ctx.quick {
        (Size::new(48, 48)?, 8u32)
    } else {
        (Size::new(128, 128)?, 48u32)
    };
    for p in Preset::ALL {
        let mut scene = FireScene::preset(p).with_size(size);
        scene.seed = ctx.seed;
        let gif_rel = format!("volume/{}.gif", p.name());
        let book_rel = format!("volume/{}-flipbook.png", p.name());
        let (gif, book) = (ctx.path(&gif_rel)?, ctx.path(&book_rel)?);
        let opts = ignis_media::WriteOptions {
            fps: scene.fps as f64,
            ..Default::default()
        };
        let mut wg = ignis_media::create(&gif, size, &opts)
            .with_context(|| format!("creating {}", gif.display()))?;
        let mut wb = ignis_media::create(&book, size, &opts)
            .with_context(|| format!("creating {}", book.display()))?;
        // a seamless loop, as `ignis volume render` makes for GIFs and flipbooks
        let mut anim = scene.looping_animator(frames)?;
        let pb = ctx.global.progress(frames as u64, "rendering");
        for _ in 0..frames {
            let f = anim.next_frame()?;
            wg.push(&f.image)
                .with_context(|| format!("writing {}", gif.display()))?;
            wb.push(&f.image)
                .with_context(|| format!("writing {}", book.display()))?;
            pb.inc(1);
        }
        pb.finish_and_clear();
        wg.finish()
            .with_context(|| format!("finishing {}", gif.display()))?;
        wb.finish()
            .with_context(|| format!("finishing {}", book.display()))?;
        let settings = format!(
            "ignis volume render --preset {} --size {size} --frames {frames} --seed {} -o",
            p.name(),
            ctx.seed
        );
        ctx.item(
            &gif_rel,
            &format!("{} (GIF)", p.name()),
            &format!("{settings} {}.gif", p.name()),
        );
        ctx.item(
            &book_rel,
            &format!("{} flipbook with alpha", p.name()),
            &format!("{settings} {}.png", p.name()),
        );
    }
    Ok(())
}
