//! `ignis learned`: Learning Flames (Stich & Magnor) — fit a 26-parameter flame model to a
//! flame video, learn its dynamics, and synthesise new, steerable flames of any length.
//! A thin layer over `ignis_learned` (the library) and `ignis_media` (decoding, writing).

use crate::args;
use crate::frames::FrameArgs;
use crate::global::{Global, StageBars};
use crate::output::{OutputArgs, PaletteArg};
use anyhow::{anyhow, bail, Context, Result};
use ignis_core::{GrayFrame, Palette, Size};
use ignis_learned::{Controls, EmParams, FlameModel, ShapeParams, Synthesiser, TrainParams, Wind};
use ignis_media::MotionSource;
use std::cell::RefCell;
use std::path::{Path, PathBuf};

/// `ignis learned ...`
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// Fit the flame model to a video and learn its dynamics (EM with condensation);
    /// prints the likelihood of every iteration and a fit summary.
    #[command(
        after_help = "Examples:\n  ignis learned train flame.mp4 --range 0..300 -o flame.flame       # one flame on a dark background\n  \
# candle.mp4 (../shared/data): the flame only, not the wax glowing around it in its jar\n  \
ignis learned train candle.mp4 --crop 190,200,100,130 --black-level 0.7 --keep-multiple -o c.flame\n  \
ignis learned train flame.mp4 --particles 300 --order 3 --seed 2 -o flame.flame"
    )]
    Train(TrainArgs),
    /// Synthesise a new flame of any length from a model, with wind, height, width and
    /// scale controls and a colour palette.
    #[command(
        after_help = "Examples:\n  ignis learned synth candle.flame --frames 3000 --wind 0.3 --height 1.2 --seed 1 -o flame.mp4\n  \
ignis learned synth candle.flame --wind 0:0,150:1.5,300:-1 --palette blue-gas -o gusty.gif\n  \
ignis learned synth candle.flame --frames 64 --size 128x128 -o sheet.png     # looping flipbook + sheet.json\n  \
ignis learned synth candle.flame --frames 32 --variants 4 -o rows.png       # 4 different loops, one per row\n  \
ignis learned synth candle.flame --frames 1000 --chunk 100..200 -o out/%04d.png  # one farm job\n\n\
Loops (the default for GIFs and flipbooks) are a sample of the learned process conditioned on returning to its\n\
start state (an exact Kalman bridge), so the step across the seam is one of the process's own.\n\
The process steps at the training footage's frame rate (recorded in the model); --fps 60 renders the same motion\n\
in twice the frames (a frame between two process steps shows the state interpolated between them)."
    )]
    Synth(SynthArgs),
    /// Describe a model: parameters, fit summary, likelihoods, spectral radius; optionally
    /// write the mean flame and the eigenflames as PNGs.
    #[command(
        after_help = "Examples:\n  ignis learned inspect candle.flame\n  ignis learned inspect candle.flame --images eigenflames/ --json"
    )]
    Inspect(InspectArgs),
}

#[derive(clap::Args, Debug)]
pub struct TrainArgs {
    /// Flame video or image sequence (a single flame on a dark background).
    pub input: PathBuf,
    #[command(flatten)]
    pub sequence: crate::args::SequenceFps,
    /// Frames to use, `START..END` (END exclusive) or `START..`; default all.
    #[arg(long)]
    pub range: Option<String>,
    /// Output model file (written atomically).
    #[arg(short, long)]
    pub output: PathBuf,
    /// N_p, path parameters.
    #[arg(long, default_value_t = 10)]
    pub path_params: usize,
    /// N_w, width parameters.
    #[arg(long, default_value_t = 10)]
    pub width_params: usize,
    /// N_e, eigenflames.
    #[arg(long, default_value_t = 5)]
    pub eigenflames: usize,
    /// Side of the normalised images the eigenflames are computed on.
    #[arg(long, default_value_t = 64)]
    pub norm_size: u32,
    /// ARP order K.
    #[arg(long, default_value_t = 2)]
    pub order: usize,
    /// Condensation particles N_c.
    #[arg(long, default_value_t = 200)]
    pub particles: usize,
    /// Upper bound on EM iterations (EM stops earlier when the likelihood has not
    /// increased for three iterations).
    #[arg(long, default_value_t = 60)]
    pub max_iterations: usize,
    /// Cut this rectangle `X,Y,W,H` (source pixels, top-left origin) out of every frame
    /// first, e.g. to leave out a lit candle holder (also as WIDTHxHEIGHT+X+Y, or ffmpeg
    /// cropdetect's crop=W:H:X:Y).
    #[arg(long)]
    pub crop: Option<String>,
    /// Linear intensity (0–1) subtracted from every pixel before fitting, to drop a lit
    /// background such as glowing wax.
    #[arg(long, default_value_t = 0.0)]
    pub black_level: f32,
    /// Keep frames with more than one disjoint flame (skipped by default, as in the paper);
    /// only the main flame of such a frame (the region with the most light) is modelled.
    #[arg(long)]
    pub keep_multiple: bool,
    /// Seed of the particle filter.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
}

#[derive(clap::Args, Debug)]
pub struct SynthArgs {
    /// Model file from `ignis learned train`.
    pub model: PathBuf,
    /// Number of frames.
    #[arg(long, default_value_t = 300)]
    pub frames: u32,
    /// Output size WIDTHxHEIGHT.
    #[arg(long, default_value = "256x256")]
    pub size: Size,
    /// Wind (bends the tip; units of the flame's main-axis deviation, + = right): a
    /// number, or `frame:value` keys such as `0:0,150:1,300:-0.5` (linear in between).
    #[arg(long, default_value = "0", allow_hyphen_values = true)]
    pub wind: String,
    /// Height multiplier (0.1–10).
    #[arg(long, default_value_t = 1.0)]
    pub height: f64,
    /// Width multiplier (0.1–10).
    #[arg(long, default_value_t = 1.0)]
    pub width: f64,
    /// Scale multiplier of the whole flame (0.1–10; 1 = the training footage's framing).
    /// Default: the largest up to 1 at which the model's flame stays inside the frame (its
    /// tip below the top, its sides within the edges) in 99 % of its states, so a model
    /// trained on a close crop does not draw its tall flames through the top edge nor its
    /// wide ones through the sides of a narrow frame; --height, --width and --wind act
    /// within that framing (a note gives the scale that fits them). Printed unless -q.
    #[arg(long)]
    pub scale: Option<f64>,
    /// Intensity multiplier before the palette.
    #[arg(long, default_value_t = 1.0)]
    pub gain: f32,
    /// Colour transfer function: a preset or a gradient PNG (left = cold, right = hot).
    #[arg(long, default_value = "candle")]
    pub palette: PaletteArg,
    /// Seed; the same model, settings and seed give the same bytes.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Where a loop's frame times are kept (default: `ignis loop`'s cache,
    /// $XDG_CACHE_HOME/ignis or ~/.cache/ignis). A looping synthesis times its frames on
    /// previews of the whole loop; a later one of the same model, settings, seed, size and
    /// --frames by the same `ignis` (another --chunk of a farm render) reads them instead
    /// and writes the same bytes. Point the farm's jobs at shared storage
    #[arg(long, value_name = "DIR")]
    pub cache: Option<PathBuf>,
    #[command(flatten)]
    pub frames_args: FrameArgs,
    #[command(flatten)]
    pub out: OutputArgs,
}

#[derive(clap::Args, Debug)]
pub struct InspectArgs {
    /// Model file.
    pub model: PathBuf,
    /// Write `mean.png` and `eigenflame-N.png` into this directory.
    #[arg(long)]
    pub images: Option<PathBuf>,
    /// Print JSON instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Runs one `ignis learned` subcommand.
pub fn run(cmd: Command, g: &Global) -> Result<()> {
    match cmd {
        Command::Train(a) => train(&a, g).map(|_| ()),
        Command::Synth(a) => synth(&a, g).map(|_| ()),
        Command::Inspect(a) => inspect(&a, g),
    }
}

fn parse_range(s: &str) -> Result<ignis_media::FrameRange> {
    let (a, b) = args::frame_range(s).map_err(|e| anyhow!("--range {e}"))?;
    Ok(ignis_media::FrameRange::frames(a, b))
}

/// Reads the video, trains, writes the model. Returns the model.
pub fn train(a: &TrainArgs, g: &Global) -> Result<FlameModel> {
    let path = &a.input;
    a.sequence.apply(&[path])?;
    let opts = ignis_media::ReadOptions {
        range: a.range.as_deref().map(parse_range).transpose()?,
        crop: a
            .crop
            .as_deref()
            .map(|c| args::crop(c).map_err(|e| anyhow!("--{e}")))
            .transpose()?,
        ..Default::default()
    };
    let reader =
        ignis_media::open(path, &opts).with_context(|| format!("reading {}", path.display()))?;
    // Before training, not after: an output that is the footage, or a device, is refused.
    ignis_core::atomic::check_regular_target(&a.output)
        .with_context(|| format!("writing {}", a.output.display()))?;
    let total = reader.info().frame_count;
    let mut footage_fps = reader.info().fps;
    // a variable frame rate: the process steps once per frame, as if they were evenly
    // spaced; most steps are at the nominal rate, which is what it learns
    let first = reader.position() as usize;
    let window = first..total.map_or(usize::MAX, |n| first + n as usize);
    if let Some(t) = crate::eigen::loop_cmd::WindowTiming::of(path, window) {
        let w = t.warning(
            first,
            &format!(
                "the model steps once per frame as if they were evenly spaced, at the nominal {:.3} fps",
                t.nominal_fps
            ),
            |r| format!("--range {}..{}", r.start, r.end),
        );
        g.say(format!("warning: {w}"));
        footage_fps = t.nominal_fps;
    }
    let p = TrainParams {
        shape: ShapeParams {
            n_path: a.path_params,
            n_width: a.width_params,
            n_eigen: a.eigenflames,
            norm_size: a.norm_size,
            skip_multiple: !a.keep_multiple,
            black_level: a.black_level,
            ..ShapeParams::default()
        },
        em: EmParams {
            order: a.order,
            particles: a.particles,
            max_iterations: a.max_iterations,
            seed: a.seed,
            ..EmParams::default()
        },
    };
    let read_error: RefCell<Option<ignis_media::MediaError>> = RefCell::new(None);
    // a keyed element as it shows over black: a flame on a dark background
    let seen = |f: ignis_core::RgbaFrame| {
        ignis_media::DecodedFrame::Linear(f)
            .over_black()
            .into_linear()
            .luminance()
    };
    let frames = reader.map_while(|f| match f {
        Ok(f) => Some(seen(f)),
        Err(e) => {
            *read_error.borrow_mut() = Some(e);
            None
        }
    });
    let mut bars =
        StageBars::new(g).with_length(ignis_learned::STAGE_NORMALISE, total.unwrap_or(0));
    let t = std::time::Instant::now();
    let result = ignis_learned::train(frames, &p, &mut bars);
    drop(bars);
    if let Some(e) = read_error.into_inner() {
        return Err(e).with_context(|| format!("reading {}", path.display()));
    }
    let mut training = result.with_context(|| format!("training on {}", path.display()))?;
    // the process steps once per footage frame: record the rate so synthesis at another
    // output rate keeps the footage's flicker frequencies
    training.model.summary.fps =
        Some(footage_fps).filter(|f| f.is_finite() && *f > 0.0 && *f <= 1000.0);
    let m = &training.model;
    m.save(&a.output)
        .with_context(|| format!("writing {}", a.output.display()))?;
    let psnrs: Vec<f64> = {
        // Reproduction quality on up to 20 evenly spaced training frames (needs the frames
        // again: re-read them; cheap compared with training).
        let n = training.states.len();
        let pick: Vec<usize> = (0..n.min(20)).map(|i| i * n / n.min(20)).collect();
        let reader = ignis_media::open(path, &opts)
            .with_context(|| format!("reading {}", path.display()))?;
        let wanted: std::collections::HashMap<usize, usize> =
            pick.iter().map(|&j| (training.frame_index[j], j)).collect();
        let mut out = Vec::new();
        for (i, f) in reader.enumerate() {
            if let Some(&j) = wanted.get(&i) {
                let f = seen(f.with_context(|| format!("reading {}", path.display()))?)
                    .map(|v| (v - a.black_level).max(0.0));
                out.push(ignis_learned::psnr(&f, &training.render_fitted(j)));
            }
            if out.len() == wanted.len() {
                break;
            }
        }
        out
    };
    let s = &m.summary;
    let r = &m.report;
    g.say(format!(
        "fit: {} frames read, {} dark and {} with several flames skipped; dynamics learned on frames {}..{} ({} frames)",
        s.frames,
        s.skipped_dark,
        s.skipped_multiple,
        s.run_start,
        s.run_start + s.run_len,
        s.run_len
    ));
    g.say(format!(
        "model: {} parameters (N_p {}, N_w {}, height, N_e {}); eigenflames explain {:.1}% of the normalised variance",
        m.n_state(),
        m.shape.n_path,
        m.shape.n_width,
        m.shape.n_eigen,
        100.0 * s.explained_variance
    ));
    g.say(format!(
        "ARP: order {}, {} EM iterations, best log-likelihood {:.3} (iteration {}), spectral radius {:.4}{}",
        m.arp.order(),
        r.log_likelihood.len(),
        r.log_likelihood[r.best_iteration],
        r.best_iteration,
        r.spectral_radius,
        match r.stabilised {
            Some(st) => format!(" (learned process was unstable, radius {:.4}; pulled back inside the unit circle)", st.before),
            None => String::new(),
        }
    ));
    let regressors = m.n_state() * m.arp.order() + 1;
    if s.run_len < 2 * regressors {
        // frames skipped for a second flame (a reflection in a glass, sparks) cut the runs
        // the dynamics are learned on; keeping them models each one's brightest flame
        let why = if s.skipped_multiple > 0 && !a.keep_multiple {
            format!(
                "; {} frames were skipped for showing several flames (a reflection, sparks, a \
                 second flame) and broke the runs: --keep-multiple models each one's brightest \
                 flame instead, or --crop leaves the others out",
                s.skipped_multiple
            )
        } else {
            String::new()
        };
        g.say(format!(
            "warning: the dynamics were learned on {} frames for {regressors} coefficients per parameter; \
             synthesis may drift — train on at least {} consecutive frames{why}",
            s.run_len,
            2 * regressors
        ));
    }
    if !psnrs.is_empty() {
        let mean = psnrs.iter().sum::<f64>() / psnrs.len() as f64;
        let min = psnrs.iter().copied().fold(f64::MAX, f64::min);
        g.say(format!(
            "reproduction of {} training frames: PSNR mean {mean:.2} dB, min {min:.2} dB",
            psnrs.len()
        ));
    }
    g.say(format!(
        "wrote {} in {:.1} s",
        a.output.display(),
        t.elapsed().as_secs_f64()
    ));
    Ok(training.model)
}

/// What the loop measure ([`ignis_core::loopq::metric_frame_rgba`], over the writer's
/// `background`) reads for a rendered intensity `i / 1024` (`i` in `0..=1024`) multiplied
/// by `gain` and coloured by `palette`: the table a looping synthesiser times its frames
/// through ([`Synthesiser::measure_loop_through`]), so the written frames' steps are the
/// ones evened out (a palette's luma is not the grey frame's).
fn loop_measure(palette: &Palette, gain: f32, background: [f32; 3]) -> Vec<f32> {
    (0..=1024)
        .map(|i| {
            let c = palette.sample(i as f32 / 1024.0 * gain);
            ignis_core::loopq::metric_luma(&c, background)
        })
        .collect()
}

/// Synthesises and writes frames. Returns what the writer wrote.
pub fn synth(a: &SynthArgs, g: &Global) -> Result<Vec<PathBuf>> {
    let model =
        FlameModel::load(&a.model).with_context(|| format!("reading {}", a.model.display()))?;
    let mut controls = Controls {
        wind: Wind::parse(&a.wind)?,
        height: a.height,
        width: a.width,
        scale: 1.0,
    };
    controls.scale = match a.scale {
        Some(s) => s,
        None => {
            // the model's own flame framed; --height, --width and --wind then act within it
            let s = ignis_learned::fit_scale(&model, &Controls::default(), a.size)?;
            if s <= ignis_learned::synth::MIN_SCALE {
                g.say(format!(
                    "scale {s:.3}, the smallest: even at that scale the model's flame leaves a \
                     frame of this shape in more than 1 % of its states; a frame closer to \
                     the footage's shape, or --width below 1, keeps it inside"
                ));
            } else if s < 1.0 {
                g.say(format!(
                    "scale {s:.3}: at that scale the model's flame stays inside the frame (tip \
                     and sides) in 99 % of its states; --scale 1 keeps the footage's framing"
                ));
            }
            if controls.height != 1.0 || controls.width != 1.0 || controls.wind != Wind::default() {
                let as_given = ignis_learned::fit_scale(&model, &controls, a.size)?;
                if as_given < 0.95 * s {
                    g.say(format!(
                        "with --height, --width and --wind as given the flame leaves the frame \
                         in more than 1 % of the states; --scale {as_given:.3} keeps it inside"
                    ));
                }
            }
            s
        }
    };
    if !(a.gain > 0.0 && a.gain.is_finite()) {
        bail!("--gain {} must be a positive number", a.gain);
    }
    let plan = a.frames_args.plan(a.frames, &a.out)?;
    let palette = a.palette.load()?;
    let fps = Some(a.out.fps());
    // a loop is timed on the frames as written: through the gain and the palette
    let measure = loop_measure(&palette, a.gain, a.out.write_options().background);
    let make = |seed: u64| -> Result<Synthesiser> {
        if plan.looping {
            let mut s = Synthesiser::looping_at(&model, controls.clone(), seed, a.frames, fps)?;
            s.measure_loop_through(measure.clone())?;
            Ok(s)
        } else {
            Ok(Synthesiser::new_at(&model, controls.clone(), seed, fps)?)
        }
    };
    // --variants N: N loops with seeds seed, seed + 1, …, one per row of the sheet; the
    // first is made before the writer so bad settings are reported first.
    let mut first = Some(make(a.seed)?);
    let mut opts = a.out.write_options();
    opts.loop_ = plan.mark_loop;
    opts.first_frame = plan.range.start as u64;
    let whole_loop = plan.looping && plan.range == (0..a.frames);
    // the model's own motion for the vectors, unless the sheet is retimed (its frames
    // are then cross-fades the model never drew)
    let model_motion = (opts.flipbook.motion.is_some() && !opts.flipbook.fit_frames)
        .then(|| ModelMotion::new(&model.shape, opts.loop_));
    if let Some(m) = &model_motion {
        opts.flipbook.motion = Some(m.source());
    }
    let (mut writer, variants) =
        a.out
            .create_variants(a.size, plan.range.len(), &mut opts, whole_loop)?;
    let mut frame = GrayFrame::new(a.size);
    let colour = |f: &mut GrayFrame| {
        if a.gain != 1.0 {
            f.data_mut().iter_mut().for_each(|v| *v *= a.gain);
        }
        palette.apply(f)
    };
    // a loop's frame times, kept for the farm's other chunks ([`crate::kept_times`]): they
    // depend on the model, the controls, the seed, the loop, the rate, the size and the
    // measure
    let model_sha = if plan.looping {
        crate::eigen::loop_cmd::source_sha256(&a.model)?
    } else {
        String::new()
    };
    let kept = |seed: u64| {
        plan.looping.then(|| {
            let key = format!(
                "model={model_sha} controls={controls:?} seed={seed} frames={} fps={fps:?} size={} measure={measure:?}",
                a.frames, a.size
            );
            crate::kept_times::KeptTimes::new(
                a.cache.as_deref(),
                "learned",
                &key,
                "ignis learned synth: the process time of each of the loop's frames",
            )
        })
    };
    let bar = g.progress(plan.range.len() as u64 * variants as u64, "synthesising");
    for v in 0..variants {
        let seed = a.seed.wrapping_add(v as u64);
        let mut synth = match first.take() {
            Some(s) => s,
            None => make(seed)?,
        };
        let kept = kept(seed);
        let mut timed = false;
        if let Some(times) = kept.as_ref().and_then(|k| k.read(a.frames as usize)) {
            timed = synth.set_loop_times(a.size, times).is_ok();
        }
        // a chunk steps only the (cheap) process to its first frame
        synth.skip(plan.range.start as u64);
        if let Some(m) = &model_motion {
            m.start_row();
        }
        for i in plan.range.clone() {
            synth.next_frame_into(&mut frame);
            if let (false, Some(k)) = (timed, &kept) {
                if let Some((_, times)) = synth.loop_times() {
                    k.keep(times, g);
                }
                timed = true;
            }
            if let Some(m) = &model_motion {
                m.record(&mut synth, a.size, i + 1 < plan.range.end, colour);
            }
            writer
                .push(&colour(&mut frame))
                .with_context(|| format!("writing {}", a.out.output.display()))?;
            bar.inc(1);
        }
    }
    bar.finish_and_clear();
    let files = writer
        .finish()
        .with_context(|| format!("writing {}", a.out.output.display()))?;
    g.say(format!(
        "wrote {} frames to {}",
        plan.range.len() * variants as usize,
        a.out.output.display()
    ));
    Ok(files)
}

/// What a learned flipbook's model motion vectors need of each loop (row) of the sheet:
/// every frame's warp, and the in-between frame of each pair of consecutive frames.
#[derive(Default)]
struct RowMotion {
    warps: Vec<ignis_learned::Warp>,
    mids: Vec<ignis_media::RgbaFrame>,
}

/// Motion vectors of a learned flipbook from the model: gathered while the frames are
/// synthesised ([`ModelMotion::record`]), given to the writer as a [`MotionSource`]
/// ([`ModelMotion::source`]). Each interval's forward and backward model motion
/// ([`ignis_learned::model_motion`], between the frames' warps) offer each frame four
/// vectors (none, forward, reversed backward, their mean); per pixel the one whose blends
/// best match the rendered in-between frames is stored
/// ([`ignis_media::write::motion::chosen_velocities`]). The flow gives 0.07 of the 0.30
/// error reduction on the learned flame, the chosen model vectors about 0.35 at held-out
/// blends (`crates/ignis-flow/benches/README.md`).
pub(crate) struct ModelMotion {
    shape: ShapeParams,
    looped: bool,
    rows: std::sync::Arc<std::sync::Mutex<Vec<RowMotion>>>,
}

/// The JSON's `motion_vectors.source` for a learned flipbook's model vectors.
pub(crate) const MODEL_SOURCE: &str =
    "model (learned flame's motion between the frames' warps, chosen per pixel by the in-between frames)";

impl ModelMotion {
    /// For a model of `shape` settings; `looped`: the sheet is a loop (its last frame
    /// blends into its first, so that interval gets an in-between frame too).
    pub(crate) fn new(shape: &ShapeParams, looped: bool) -> ModelMotion {
        ModelMotion {
            shape: shape.clone(),
            looped,
            rows: Default::default(),
        }
    }

    /// A new loop (row of the sheet) begins.
    pub(crate) fn start_row(&self) {
        self.rows
            .lock()
            .expect("not poisoned")
            .push(RowMotion::default());
    }

    /// After `synth` rendered a frame of `size`: records its warp and, when another frame
    /// of the row follows (`more`) or the row is a loop, renders the in-between frame,
    /// coloured by `colour` as the frames are.
    pub(crate) fn record(
        &self,
        synth: &mut Synthesiser,
        size: Size,
        more: bool,
        colour: impl Fn(&mut GrayFrame) -> ignis_media::RgbaFrame,
    ) {
        let mut rows = self.rows.lock().expect("not poisoned");
        let row = rows.last_mut().expect("start_row first");
        row.warps.push(synth.warp(size));
        let mut grey = GrayFrame::new(size);
        if more || self.looped {
            synth.between_into(&mut grey);
            row.mids.push(colour(&mut grey));
        }
    }

    /// The motion source for the writer.
    pub(crate) fn source(&self) -> MotionSource {
        let (rows, shape, looped) = (self.rows.clone(), self.shape.clone(), self.looped);
        let direction = if looped {
            "velocity at frame k's pixels: per pixel none, the model motion k to k+1, the reversed model motion k to k-1 or their mean (wrapping within each loop), whichever makes the blends at 0.5 closest to the rendered in-between frames"
        } else {
            "velocity at frame k's pixels: per pixel none, the model motion k to k+1, the reversed model motion k to k-1 or their mean (one side only at the first and last frame), whichever makes the blends at 0.5 closest to the rendered in-between frames"
        };
        MotionSource::velocities(
            move |r, frames| {
                let rows = rows.lock().map_err(|_| "a synthesis thread panicked")?;
                let row = rows
                    .get(r)
                    .ok_or("no model motion recorded for this loop")?;
                model_vectors(&shape, row, frames, looped)
            },
            MODEL_SOURCE,
            direction,
        )
    }
}

/// The chosen model velocities of one row's `frames` (see [`ModelMotion`]).
fn model_vectors(
    shape: &ShapeParams,
    row: &RowMotion,
    frames: &[ignis_media::RgbaFrame],
    looped: bool,
) -> std::result::Result<Vec<Vec<[f32; 2]>>, String> {
    let n = frames.len();
    let intervals = if looped { n } else { n.saturating_sub(1) };
    if row.warps.len() != n || row.mids.len() < intervals || n < 2 {
        return Err(format!(
            "{n} frames, but the model motion was recorded for {} frames with {} in-between frames",
            row.warps.len(),
            row.mids.len()
        ));
    }
    let size = frames[0].size();
    let w = &row.warps;
    let m = |i: usize, j: usize| ignis_learned::model_motion(shape, &w[i], &w[j], size);
    let pairs: Vec<_> = (0..intervals)
        .map(|k| (m(k, (k + 1) % n), m((k + 1) % n, k)))
        .collect();
    let mids: Vec<&ignis_media::RgbaFrame> = row.mids[..intervals].iter().collect();
    Ok(ignis_media::write::motion::chosen_velocities(
        frames, &mids, &pairs,
    ))
}

fn inspect(a: &InspectArgs, g: &Global) -> Result<()> {
    let m = FlameModel::load(&a.model).with_context(|| format!("reading {}", a.model.display()))?;
    let mut written = Vec::new();
    if let Some(dir) = &a.images {
        written = write_eigenflames(&m, dir)?;
    }
    let r = &m.report;
    if a.json {
        let v = serde_json::json!({
            "model": a.model.display().to_string(),
            "format_version": ignis_learned::MODEL_VERSION,
            "parameters": m.n_state(),
            "shape": m.shape,
            "summary": m.summary,
            "arp_order": m.arp.order(),
            "spectral_radius": r.spectral_radius,
            "stabilised": r.stabilised,
            "log_likelihood": r.log_likelihood,
            "best_iteration": r.best_iteration,
            "observation_noise": r.obs_noise,
            "state_mean": m.state_mean,
            "state_std": m.state_std,
            "eigenvalues": m.pca.eigenvalues,
            "images": written.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
        });
        outln!("{}", serde_json::to_string_pretty(&v)?)?;
        return Ok(());
    }
    let s = &m.summary;
    outln!(
        "model         {} (format version {})",
        a.model.display(),
        ignis_learned::MODEL_VERSION
    )?;
    outln!(
        "parameters    {} = N_p {} + N_w {} + height + N_e {}",
        m.n_state(),
        m.shape.n_path,
        m.shape.n_width,
        m.shape.n_eigen
    )?;
    outln!("normalised    {0}x{0} pixels", m.shape.norm_size)?;
    outln!(
        "training      {} frames of {} ({} dark, {} several flames skipped); dynamics on {}..{}",
        s.frames,
        s.source_size,
        s.skipped_dark,
        s.skipped_multiple,
        s.run_start,
        s.run_start + s.run_len
    )?;
    outln!(
        "eigenflames   explain {:.1}% of the normalised variance",
        100.0 * s.explained_variance
    )?;
    outln!(
        "ARP           order {}, spectral radius {:.4}{}",
        m.arp.order(),
        r.spectral_radius,
        match r.stabilised {
            Some(st) => format!(" (stabilised from {:.4})", st.before),
            None => " (stable as learned)".into(),
        }
    )?;
    outln!(
        "EM            {} iterations, best {} ",
        r.log_likelihood.len(),
        r.best_iteration
    )?;
    for (i, ll) in r.log_likelihood.iter().enumerate() {
        outln!("  iteration {i:>3}  log-likelihood {ll:.3}")?;
    }
    let (np, nw) = (m.shape.n_path, m.shape.n_width);
    let name = |i: usize| {
        if i < np {
            format!("path[{i}]")
        } else if i < np + nw {
            format!("width[{}]", i - np)
        } else if i == np + nw {
            "height".into()
        } else {
            format!("eigenflame[{}]", i - np - nw - 1)
        }
    };
    outln!(
        "{:<16} {:>12} {:>12} {:>12}",
        "parameter",
        "mean",
        "std",
        "obs. noise"
    )?;
    for i in 0..m.n_state() {
        outln!(
            "{:<16} {:>12.5} {:>12.5} {:>12.5}",
            name(i),
            m.state_mean[i],
            m.state_std[i],
            r.obs_noise[i]
        )?;
    }
    for p in &written {
        g.say(format!("wrote {}", p.display()));
    }
    Ok(())
}

/// Writes the mean normalised flame and every eigenflame as PNGs (scaled to 0..1).
fn write_eigenflames(m: &FlameModel, dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let mut out = Vec::new();
    for e in 0..=m.shape.n_eigen {
        let Some(img) = m.eigenflame_image(e) else {
            break;
        };
        let p = dir.join(if e == 0 {
            "mean.png".to_string()
        } else {
            format!("eigenflame-{e}.png")
        });
        ignis_media::write_png(&p, &img.to_rgba())
            .with_context(|| format!("writing {}", p.display()))?;
        out.push(p);
    }
    Ok(out)
}

/// The demo section: a model trained on a flame Ignis renders itself (and on candle.mp4
/// when `../shared/data` is present), then new flames with wind and height controls.
pub fn demo(ctx: &mut crate::demo::Demo) -> Result<()> {
    ctx.section(
        "Learned flames",
        "Stich & Magnor, Learning Flames: a 26-parameter flame model (slice path and width, height, 5 eigenflames) \
         is fitted to flame footage, an auto-regressive process of its parameters is learned by EM with a particle \
         filter, and new, never-repeating flames are sampled from it in real time — here steered with wind and height.",
    );
    let quick = ctx.quick;
    let g = Global { quiet: true };
    // 1. Training footage Ignis renders itself.
    let (side, frames, synth_frames, particles) = if quick {
        (64, 100, "12", "50")
    } else {
        (256, 150, "300", "200")
    };
    let clip_rel = "learned/synthetic-clip.mp4";
    let clip_path = ctx.path(clip_rel)?;
    let size = Size::new(side, side)?;
    {
        let clip = ignis_learned::synthetic::flame_clip(size, frames, ctx.seed);
        let opts = ignis_media::WriteOptions {
            fps: 30.0,
            ..Default::default()
        };
        let mut w = ignis_media::create(&clip_path, size, &opts)
            .with_context(|| format!("creating {}", clip_path.display()))?;
        for f in &clip {
            w.push(&f.to_rgba())
                .with_context(|| format!("writing {}", clip_path.display()))?;
        }
        w.finish()
            .with_context(|| format!("writing {}", clip_path.display()))?;
    }
    ctx.item(
        clip_rel,
        "training footage: a synthetic flickering flame (ignis_learned::synthetic)",
        "built in",
    );
    let mut sources = vec![(
        "synthetic",
        clip_rel.to_string(),
        clip_path.clone(),
        None::<&str>,
    )];
    if !quick {
        if let Some(c) = crate::demo::shared_data("candle.mp4") {
            sources.push((
                "candle",
                "../shared/data/candle.mp4".into(),
                c,
                Some("0..300"),
            ));
        }
    }
    for (name, shown_src, src, range) in sources {
        let model_rel = format!("learned/{name}.flame");
        let model_path = ctx.path(&model_rel)?;
        let seed = ctx.seed.to_string();
        let mut argv = vec![
            "train".to_string(),
            src.to_string_lossy().into_owned(),
            "-o".into(),
        ];
        argv.push(model_path.to_string_lossy().into_owned());
        argv.extend([
            "--particles".into(),
            particles.to_string(),
            "--seed".into(),
            seed.clone(),
        ]);
        if let Some(r) = range {
            argv.extend(["--range".into(), r.to_string()]);
        }
        if name == "candle" {
            // candle.mp4 (480²) shows the flame in a glass holder over glowing wax, with
            // its reflection in the glass above it (rows ~218–262) and the glass's lit rim
            // crossing below it as a wide bright bar (rows ~330–336). The crop keeps the
            // whole visible flame (rows ~270–330, its base is lost in the wax glow below)
            // and stops above the rim; an earlier crop ended at row 316 and cut the flame
            // in half, so the model learned a round stub sitting on the crop's edge. The
            // black level drops the wax glow; the reflection stays in the crop and is
            // blacked out as a second flame (--keep-multiple keeps those frames, or too
            // few consecutive frames remain).
            argv.extend(
                [
                    "--crop",
                    "190,200,100,130",
                    "--black-level",
                    "0.7",
                    "--keep-multiple",
                ]
                .map(String::from),
            );
        }
        let refs: Vec<&str> = argv.iter().map(|s| s.as_str()).collect();
        let a = crate::parse_sub::<TrainArgs>(&refs)?;
        let model = train(&a, &g)?;
        let shown = |argv: &[String]| {
            argv.iter()
                .map(|s| {
                    if *s == model_path.to_string_lossy() {
                        model_rel.clone()
                    } else if *s == src.to_string_lossy() {
                        shown_src.clone()
                    } else {
                        s.clone()
                    }
                })
                .collect::<Vec<_>>()
                .join(" ")
        };
        ctx.item(
            &model_rel,
            &format!(
                "model trained on {name}: spectral radius {:.3}, {} EM iterations",
                model.report.spectral_radius,
                model.report.log_likelihood.len()
            ),
            &format!("ignis learned {}", shown(&argv)),
        );
        let sheet_rel = format!("learned/{name}-eigenflames");
        let written = write_eigenflames(
            &model,
            &ctx.path(&format!("{sheet_rel}/x"))?.with_file_name(""),
        )?;
        for p in written.iter().take(3) {
            let rel = format!(
                "{sheet_rel}/{}",
                p.file_name().unwrap_or_default().to_string_lossy()
            );
            ctx.item(
                &rel,
                &format!(
                    "{name}: {}",
                    if rel.ends_with("mean.png") {
                        "mean normalised flame"
                    } else {
                        "eigenflame"
                    }
                ),
                &format!("ignis learned inspect {model_rel} --images {sheet_rel}"),
            );
        }
        let out_size = if quick { "64x64" } else { "256x256" };
        let variants: &[(&str, &str, &[&str])] = &[
            ("plain.mp4", "new flame, learned dynamics only", &[]),
            (
                "wind.mp4",
                "wind rising from 0 to 1.5 and back to −1",
                &["--wind", "0:0,100:1.5,200:-1"],
            ),
            (
                "tall.gif",
                "height ×1.3, blue-gas palette",
                &["--height", "1.3", "--palette", "blue-gas"],
            ),
        ];
        for (i, (file, caption, extra)) in variants.iter().enumerate() {
            let rel = format!("learned/{name}-{file}");
            let path = ctx.path(&rel)?;
            let seed = (ctx.seed + i as u64).to_string();
            let mut argv: Vec<String> = [
                "synth",
                &model_path.to_string_lossy(),
                "--frames",
                synth_frames,
                "--size",
                out_size,
                "--seed",
                &seed,
                "-o",
            ]
            .iter()
            .map(|s| s.to_string())
            .collect();
            argv.push(path.to_string_lossy().into_owned());
            argv.extend(extra.iter().map(|s| s.to_string()));
            let refs: Vec<&str> = argv.iter().map(|s| s.as_str()).collect();
            let a = crate::parse_sub::<SynthArgs>(&refs)?;
            synth(&a, &g)?;
            let settings = format!(
                "ignis learned {}",
                shown(&argv).replace(&path.to_string_lossy().into_owned(), &rel)
            );
            ctx.item(&rel, &format!("{name}: {caption}"), &settings);
        }
    }
    Ok(())
}
