//! `ignis classic`: the classic pixel-buffer fire (McNally 1999) to any output.

use crate::frames::FrameArgs;
use crate::global::Global;
use crate::output::{OutputArgs, PaletteArg};
use anyhow::{Context, Result};
use ignis_classic::{ClassicFire, ClassicParams, Kernel, SourceEdge, SourceMode, Sparkle};
use ignis_core::Size;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  ignis classic --size 320x200 --frames 300 --fps 30 --palette classic --seed 7 -o fire.mp4\n  \
ignis classic --source perlin --palette blue-gas -o sheet.png          # flipbook + sheet.json\n  \
ignis classic --frames 48 -o frames/%04d.exr                           # linear EXR sequence\n  \
ignis classic --frames 120 --loop -o loop.mp4                          # a seamless loop as MP4\n  \
ignis classic --frames 1000 --chunk 0..100 -o frames/%04d.png          # job 1 of 10 on a farm\n  \
ignis classic --size 128x128 --frames 32 --variants 4 -o rows.png      # 4 different loops, one per row\n  \
ignis classic --cell 1 --puff 0 -o article.mp4                         # the 1999 article's fire exactly\n  \
ignis classic --frames 64 --every 2 --motion-vectors --engine unity -o sheet.png\n                       # 32 cells at 15 fps; the engine's motion-vector blend fills in\n\n\
Realism: by default the fire is a 1 m fire bed simulated on 6-px cells (on a 320x200 frame; larger\n\
frames scale them, so the fire looks the same at any size) that puffs at 1.5/√D Hz\n\
(--diameter D); `ignis bench realism` measures it against that law and campfire footage.\n\n\
Loops (the default for GIFs and flipbooks): the source line and sparklies repeat every N frames and the\n\
fire is stepped until its buffer repeats exactly, so frame N equals frame 0 byte for byte. With cells\n\
over 1 px (the default), the loop is then re-timed at constant speed (frames blend neighbouring states),\n\
so every step, the wrap included, is within about 15% of the median step."
)]
pub struct Args {
    /// Frame size WIDTHxHEIGHT (the simulation buffer is this divided by --cell).
    #[arg(long, default_value = "320x200")]
    pub size: Size,
    /// Number of frames to render (all written, or every Nth with --every N).
    #[arg(long, default_value_t = 300)]
    pub frames: u32,
    /// BURNFADE: subtracted after the box filter (0–255); larger = shorter flames.
    #[arg(long, default_value_t = 1)]
    pub fade: u8,
    /// DONTBURN: cells at each edge that never burn (≥ 1).
    #[arg(long, default_value_t = 1)]
    pub edge: u32,
    /// Hottest value of the source line (1–255).
    #[arg(long, default_value_t = 255)]
    pub heat: u8,
    /// Source line: `random` (each pixel drifts) or `perlin` (smooth 1-D noise).
    #[arg(long, default_value = "random", value_parser = ["random", "perlin"])]
    pub source: String,
    /// Random source: largest step per frame (0–255).
    #[arg(long, default_value_t = 48)]
    pub drift: u8,
    /// Perlin source: feature size along the line, in pixels.
    #[arg(long, default_value_t = 24.0)]
    pub noise_scale: f32,
    /// Perlin source: how fast the pattern evolves (noise units per frame).
    #[arg(long, default_value_t = 0.08)]
    pub noise_speed: f32,
    /// Where the wall of flame sits: `bottom` (flames rise) or `top` (flames hang).
    #[arg(long, default_value = "bottom", value_parser = ["bottom", "top"])]
    pub source_edge: String,
    /// Sparklies: brighten one random pixel per line darker than this (0 disables).
    #[arg(long, default_value_t = 48)]
    pub sparkle: u8,
    /// Sparklies: how much brighter.
    #[arg(long, default_value_t = 24)]
    pub sparkle_boost: u8,
    /// `article` (the article's exact in-place loop) or `buffered` (double-buffered, SIMD).
    #[arg(long, default_value = "article", value_parser = ["article", "buffered"])]
    pub kernel: String,
    /// Simulation cell size in pixels: the buffer is SIZE / CELL, interpolated smoothly to
    /// SIZE. 6 (the default) gives real flames' large-scale structure; 1 is the article's
    /// per-pixel buffer (with --puff 0: the article's fire exactly).
    /// [default: 6 up to 216 px on the shorter side, then 6 per 200 px of it (1920x1080:
    /// 32), so a larger render shows the same fire, not shorter flames; fewer on frames
    /// under 96 px so the buffer keeps 16 cells a side]
    #[arg(long)]
    pub cell: Option<u32>,
    /// Puffing depth 0–1 (0 = off): the source heat rises and falls at 1.5/√DIAMETER Hz, the
    /// puffing frequency of a real flame of that width (a model addition beyond the article).
    #[arg(long, default_value_t = ignis_classic::PRESET_PUFF)]
    pub puff: f32,
    /// The physical width of the fire, metres: sets the puffing frequency (1 m: 1.5 Hz).
    #[arg(long, default_value_t = 1.0)]
    pub diameter: f32,
    /// Frames simulated before the first written frame, so the fire is burning from frame 0.
    #[arg(long, default_value_t = 60)]
    pub warmup: u32,
    /// Colour ramp: a preset or a gradient PNG (left = cold, right = hot).
    #[arg(long, default_value = "classic")]
    pub palette: PaletteArg,
    /// Seed of every random choice; the same seed gives the same bytes.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Write every Nth of the --frames frames, at 1/N of --fps: the same fire in fewer
    /// cells for an engine to blend between (--frames must be a multiple of N; --chunk
    /// counts written frames). With --motion-vectors and an even N, each vector is chosen
    /// by the frame half-way between two written ones, which is simulated anyway (as
    /// `volume render` and `loop --every` do). Example: --every 2
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=16))]
    pub every: u32,
    #[command(flatten)]
    pub frames_args: FrameArgs,
    #[command(flatten)]
    pub out: OutputArgs,
}

impl Args {
    pub fn params(&self) -> ClassicParams {
        ClassicParams {
            size: self.size,
            fade: self.fade,
            edge: self.edge,
            heat: self.heat,
            source: if self.source == "perlin" {
                SourceMode::Perlin {
                    scale: self.noise_scale,
                    speed: self.noise_speed,
                }
            } else {
                SourceMode::Random { drift: self.drift }
            },
            source_edge: if self.source_edge == "top" {
                SourceEdge::Top
            } else {
                SourceEdge::Bottom
            },
            sparkle: (self.sparkle > 0).then_some(Sparkle {
                threshold: self.sparkle,
                boost: self.sparkle_boost,
            }),
            kernel: if self.kernel == "buffered" {
                Kernel::Buffered
            } else {
                Kernel::Article
            },
            seed: self.seed,
            cell: self.cell.unwrap_or_else(|| default_cell(self.size)),
            puff: self.puff,
            diameter: self.diameter,
            fps: self.out.fps() as f32,
        }
    }
}

/// `--cell`'s default for frames of `size`: [`ignis_classic::PRESET_CELL`] on the default
/// 320×200 frame, scaled with the shorter side above it (`PRESET_CELL` per 200 px,
/// rounded), so the buffer keeps about the same cells and a larger render is the same
/// fire at more pixels — with 6-px cells a 1080p frame held 5× the cells and flames a
/// fifth of its height; fewer on frames under 96 px so the buffer keeps 16 cells a side.
pub(crate) fn default_cell(size: Size) -> u32 {
    let side = size.width.min(size.height);
    let scaled = (f64::from(ignis_classic::PRESET_CELL) * f64::from(side) / 200.0).round() as u32;
    ignis_classic::PRESET_CELL.max(scaled).min(side / 16).max(1)
}

/// Runs `ignis classic`; returns the files written.
pub fn run(args: &Args, g: &Global) -> Result<Vec<PathBuf>> {
    let every = args.every.max(1);
    let written = written_frames(args)?;
    let plan = args.frames_args.plan(written, &args.out)?;
    // --variants N: N loops with seeds seed, seed + 1, …, one per row of the sheet; the
    // first fire is made before the writer so bad settings are reported first.
    let mut first = Some(new_fire(args, args.seed, plan.looping)?);
    let palette = args.palette.load()?;
    let mut opts = args.out.write_options();
    opts.fps = args.out.fps() / f64::from(every);
    opts.loop_ = plan.mark_loop;
    opts.first_frame = plan.range.start as u64;
    let whole_loop = plan.looping && plan.range == (0..written);
    // --every with an even N: the frame half-way between two written ones is simulated
    // anyway, so the motion vectors are chosen by it (unless the sheet is retimed)
    let in_between =
        (every.is_multiple_of(2) && opts.flipbook.motion.is_some() && !opts.flipbook.fit_frames)
            .then(|| crate::inbetween::InBetween::new(opts.loop_));
    if let Some(m) = &in_between {
        opts.flipbook.motion = Some(m.source());
    }
    let (mut writer, variants) =
        args.out
            .create_variants(args.size, plan.range.len(), &mut opts, whole_loop)?;
    if every > 1 {
        g.say(format!(
            "writing every {} of the {} frames: {written} frames at {} fps",
            crate::args::nth(every),
            args.frames,
            crate::args::fps_text(opts.fps)
        ));
    }
    let pb = g.progress(plan.range.len() as u64 * variants as u64, "classic");
    for v in 0..variants {
        let seed = args.seed.wrapping_add(v as u64);
        let mut fire = match first.take() {
            Some(f) => f,
            None => new_fire(args, seed, plan.looping)?,
        };
        settle(&mut fire, args, seed, variants, g);
        // the found loop re-timed so every step (the wrap included) is as large as the
        // others, measured as the writer's loop metric sees the frames
        fire.even_loop_steps(&palette, opts.background);
        // a chunk steps (without drawing) to its first frame
        for _ in 0..plan.range.start * every {
            fire.step_par();
        }
        if let Some(m) = &in_between {
            m.start_row();
        }
        for j in plan.range.clone() {
            fire.step_par();
            args.out.push(&mut writer, &fire.rgba(&palette))?;
            pb.inc(1);
            // the frames left out up to the next written one (--every), the middle one
            // kept for the motion vectors
            let mid = in_between
                .as_ref()
                .filter(|m| m.wants(j + 1 < plan.range.end));
            if j + 1 == plan.range.end && mid.is_none() {
                break;
            }
            for s in 1..every {
                fire.step_par();
                if let Some(m) = mid.filter(|_| 2 * s == every) {
                    m.record(fire.rgba(&palette));
                }
            }
        }
    }
    pb.finish_and_clear();
    args.out.finish(writer, g)
}

/// The number of frames written: every `--every`th of `--frames`, checked so that a loop's
/// wrap is an ordinary step and at least two frames are written.
fn written_frames(args: &Args) -> Result<u32> {
    let every = args.every.max(1);
    if every == 1 {
        return Ok(args.frames);
    }
    anyhow::ensure!(
        args.frames.is_multiple_of(every) && args.frames / every >= 2,
        "--frames {} with --every {every}: the frames must be a multiple of {every} with at least \
         two of them written; ask for --frames {} (or a smaller --every)",
        args.frames,
        (args.frames.div_ceil(every)).max(2) * every
    );
    let written = args.frames / every;
    if let Some(c) = args.frames_args.chunk {
        anyhow::ensure!(
            c.start < c.end && c.end <= written,
            "--chunk {}..{} is not a range of written frames: --frames {} with --every {every} \
             writes frames 0..{written}; give A..B with A < B ≤ {written}",
            c.start,
            c.end,
            args.frames
        );
    }
    Ok(written)
}

/// The fire of these settings with `seed` (looping: repeating every `--frames` frames).
fn new_fire(args: &Args, seed: u64, looping: bool) -> Result<ClassicFire> {
    let params = ClassicParams {
        seed,
        ..args.params()
    };
    if looping {
        ClassicFire::new_looping(params, args.frames)
    } else {
        ClassicFire::new(params)
    }
    .context("classic fire settings")
}

/// Warms the fire up; a loop is put on its periodic orbit (solved row by row, each row
/// stepped at most `cap` times until it repeats), with a note when it does not settle.
fn settle(fire: &mut ClassicFire, args: &Args, seed: u64, variants: u32, g: &Global) {
    let cap = (16 * args.frames as u64)
        .max(40 * args.size.height as u64)
        .max(4000);
    if fire.settle_loop(args.warmup as u64, cap).is_none() {
        let which = if variants > 1 {
            format!(" (variant with seed {seed})")
        } else {
            String::new()
        };
        g.say(format!(
            "note: the fire{which} did not settle into an exact {}-frame loop within {cap} steps \
             a row; it loops with a seam (see the flipbook's loop_quality)",
            args.frames
        ));
    }
}

/// The demo section: the classic fire in every output format.
pub fn demo(ctx: &mut crate::demo::Demo) -> Result<()> {
    ctx.section(
        "Classic fire",
        "McNally's pixel-buffer fire (1999): each pixel becomes the average of itself, its left, right and lower \
         neighbours minus a fade, shown through a palette. Every output format Ignis writes.",
    );
    let (size, frames) = if ctx.quick {
        ("64x48", 8)
    } else {
        ("320x200", 120)
    };
    let variants: &[(&str, &str, &[&str])] = &[
        (
            "classic/fire.mp4",
            "MP4 (H.264, OpenH264)",
            &["--palette", "classic"],
        ),
        (
            "classic/fire.gif",
            "looping GIF preview, smooth Perlin source",
            &["--source", "perlin", "--palette", "candle"],
        ),
        (
            "classic/flipbook.png",
            "flipbook sprite sheet (+ flipbook.json), blue gas",
            &["--palette", "blue-gas", "--fade", "3"],
        ),
        (
            "classic/png/%04d.png",
            "PNG sequence, green, fire hanging from the top",
            &["--palette", "green", "--source-edge", "top"],
        ),
        (
            "classic/exr/%04d.exr",
            "EXR sequence (linear f32, for compositing)",
            &["--palette", "classic"],
        ),
        (
            "classic/engine.png",
            "Unity flipbook at half the frame rate (+ engine.json, engine.mv.png): every 2nd frame, \
             its motion vectors chosen by the frames left out, for the engine's motion-vector blend",
            &["--every", "2", "--motion-vectors", "--engine", "unity"],
        ),
    ];
    for (i, (rel, caption, extra)) in variants.iter().enumerate() {
        let path = ctx.path(rel)?;
        let frames_s = frames.to_string();
        let seed = (ctx.seed + i as u64).to_string();
        let mut argv = vec![
            "classic", "--size", size, "--frames", &frames_s, "--seed", &seed, "-o",
        ];
        let path_s = path.to_string_lossy().to_string();
        argv.push(&path_s);
        argv.extend_from_slice(extra);
        let args = crate::parse_sub::<Args>(&argv)?;
        run(&args, &Global { quiet: true })?;
        let shown = if rel.contains('%') {
            rel.replace("%04d", "0000")
        } else {
            rel.to_string()
        };
        let settings = format!(
            "ignis {}",
            argv.iter()
                .map(|a| if *a == path_s { *rel } else { *a })
                .collect::<Vec<&str>>()
                .join(" ")
        );
        ctx.item(&shown, caption, &settings);
        if rel.ends_with("engine.png") {
            ctx.item(
                "classic/engine.mv.png",
                "its motion-vector sheet (16-bit, linear; red and green = the motion, 0.5 = none)",
                &settings,
            );
        }
    }
    Ok(())
}
