//! `ignis`: controllable fire animations from the command line.
//!
//! A thin layer over the library crates: argument parsing, progress bars and error
//! reporting live here; every capability is a library call.

mod animate;
mod bench_export;
mod bench_loops;
mod bench_realism;
mod classic;
mod convert;
mod demo;
mod eigen;
mod frames;
mod global;
mod info;
mod learned;
mod loop_cmd;
mod output;
mod volume;

use anyhow::{Context, Result};
use clap::{FromArgMatches, Parser, Subcommand};
use global::Global;
use std::path::PathBuf;
use std::process::ExitCode;

#[derive(Parser, Debug)]
#[command(
    name = "ignis",
    version,
    about = "Controllable fire animations for games, motion graphics and VFX",
    after_help = "Examples:\n  ignis demo -o ignis-demo                 # every method on built-in defaults, with a gallery\n  \
ignis classic --size 320x200 --frames 300 -o fire.mp4\n  ignis info candle.mp4 --json\n  ignis bench classic"
)]
struct Cli {
    /// No progress bars or chatter (errors are still printed).
    #[arg(short, long, global = true)]
    quiet: bool,
    #[command(subcommand)]
    cmd: Cmd,
}

#[derive(Subcommand, Debug)]
enum Cmd {
    /// The classic pixel-buffer fire (McNally 1999).
    Classic(classic::Args),
    /// Frames, fps, size, codec and decoder of a video, image or frame sequence.
    Info(info::Args),
    /// Any source to any output (footage to a flipbook, MP4 to EXR frames, ...).
    Convert(convert::Args),
    /// The main job: every method on built-in defaults, written with a gallery page.
    Demo(DemoArgs),
    /// Eigenfires: train a PCA database on real fire footage, analyse and reconstruct.
    #[command(subcommand)]
    Eigen(eigen::Command),
    /// Learned flames (Stich & Magnor): a flame model + auto-regressive process.
    #[command(subcommand)]
    Learned(learned::Command),
    /// Procedural volumetric fire (Fuller et al.): profile + B-spline + lattice + noise.
    #[command(subcommand)]
    Volume(volume::Command),
    /// A seamless loop of a fire clip, found, closed and written at the clip's own size.
    Loop(loop_cmd::Args),
    /// Headline performance figures of a method as one JSON object.
    Bench(BenchArgs),
}

#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  ignis demo                 # writes ./ignis-demo/index.html\n  ignis demo -o /tmp/fire --quick"
)]
struct DemoArgs {
    /// Directory to write into (created if missing).
    #[arg(short, long, default_value = "ignis-demo")]
    output: PathBuf,
    /// Seed for every generator.
    #[arg(long, default_value_t = 7)]
    seed: u64,
    /// Tiny sizes and few frames (a smoke test in seconds).
    #[arg(long)]
    quick: bool,
}

#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  ignis bench classic\n  ignis bench classic --quick\n  ignis bench eigen-train\n  ignis bench eigen-animate --keep-db /tmp/bench.db\n  ignis bench eigen-footage   (only eigen-animate's footage case: a 1080p loop read from the source video)\n  ignis bench learned\n  ignis bench volume\n  ignis bench flow --quick\n  ignis bench export         # motion-vector blend vs cross-fade, flow timings\n  ignis bench loops\n  ignis bench loops fire1.mp4 fire2.mov --cache /tmp/ignis-cache\n  ignis bench realism        # flicker vs 1.5/√D and spectral slope vs the footage, every generator"
)]
struct BenchArgs {
    /// What to measure (`flow`: dense optical flow and the motion-compensated morph,
    /// against the issues' speed goals, plus mid-frame prediction on ../shared/data;
    /// `export`: flipbook motion-vector blending vs a cross-fade, and flipbook timing;
    /// `loops`: Ignis's loops against the crossfade and Video Textures peers;
    /// `realism`: flicker frequency and spectral slope of every generator against the
    /// puffing law and ../shared/data footage).
    #[arg(value_parser = ["classic", "eigen-train", "eigen-animate", "eigen-footage", "learned", "volume", "flow", "export", "loops", "realism"])]
    target: String,
    /// loops: the clips (default ../shared/data/{candle,campfire,fireball}.mp4; missing
    /// ones are reported as skipped).
    clips: Vec<PathBuf>,
    /// loops: the cache of clip databases (default as `ignis loop`).
    #[arg(long, value_name = "DIR")]
    cache: Option<PathBuf>,
    /// Fewer repetitions (a smoke test; figures are noisier).
    #[arg(long)]
    quick: bool,
    /// eigen-animate: keep the trained benchmark database in this directory and reuse it
    /// on later runs (training 2,197 frames takes about half a minute).
    #[arg(long, value_name = "DIR")]
    keep_db: Option<std::path::PathBuf>,
}

/// `ignis bench flow`: the speed goals of `ignis-flow` on synthetic pairs, and how well
/// the motion-compensated mid frame predicts the real middle frame of the shared footage
/// (when `../shared/data` is present) against the plain 50/50 blend.
fn flow_bench(quick: bool) -> Result<serde_json::Value> {
    use serde_json::json;
    let p = ignis_flow::FlowParams::default();
    let mut out = serde_json::Map::new();
    out.insert("threads".into(), rayon::current_num_threads().into());
    // Wall-clock figures scale with how busy the machine is; say how busy it was.
    if let Ok(l) = std::fs::read_to_string("/proc/loadavg") {
        if let Some(one) = l
            .split_whitespace()
            .next()
            .and_then(|v| v.parse::<f64>().ok())
        {
            out.insert("load_average_1min".into(), one.into());
        }
    }
    out.insert(
        "params".into(),
        json!({"max_side": p.max_side, "patch": p.patch, "stride": p.stride,
               "finest_scale": p.finest_scale, "iterations": p.iterations,
               "refine_iterations": p.refine_iterations}),
    );
    for t in ignis_flow::bench::figures(quick, &process_cpu_ms)? {
        out.insert(
            t.name.into(),
            json!({"size": t.size.to_string(), "median_ms": t.median_ms, "min_ms": t.min_ms,
                   "cpu_ms": t.cpu_ms, "goal_ms": t.goal_ms, "goal_met": t.goal_met(),
                   "mean_error_px": t.mean_error_px}),
        );
    }
    let starts: &[u64] = if quick {
        &[100]
    } else {
        &[30, 100, 200, 300, 400]
    };
    let mut rows = Vec::new();
    for clip in ["candle.mp4", "campfire.mp4", "fireball.mp4"] {
        let Some(path) = demo::shared_data(clip) else {
            continue;
        };
        for &s in starts {
            let opts = ignis_media::ReadOptions {
                range: Some(ignis_media::FrameRange::frames(s, Some(s + 3))),
                ..Default::default()
            };
            let fr: Vec<ignis_core::RgbaFrame> = ignis_media::open(&path, &opts)?
                .collect::<std::result::Result<_, _>>()
                .with_context(|| format!("decoding {}", path.display()))?;
            if fr.len() < 3 {
                continue;
            }
            let e = ignis_flow::bench::mid_frame_error(&fr[0], &fr[1], &fr[2], &p)?;
            rows.push(json!({"clip": clip, "frames": format!("{s}..{}", s + 3),
                             "morph_mae": e.morph_mae, "blend_mae": e.blend_mae,
                             "ratio": e.ratio()}));
        }
    }
    if rows.is_empty() {
        out.insert(
            "morph_vs_blend".into(),
            "skipped: ../shared/data not found".into(),
        );
    } else {
        out.insert("morph_vs_blend".into(), rows.into());
    }
    Ok(out.into())
}

/// CPU time of this process (all threads), in ms.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn process_cpu_ms() -> Option<f64> {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: `ts` is a valid, writable timespec for the duration of the call.
    let r = unsafe { libc::clock_gettime(libc::CLOCK_PROCESS_CPUTIME_ID, &mut ts) };
    (r == 0).then(|| ts.tv_sec as f64 * 1e3 + ts.tv_nsec as f64 / 1e6)
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn process_cpu_ms() -> Option<f64> {
    None
}

/// Parses a subcommand's arguments from an argv (first element = program name); used
/// by the demo to run commands exactly as a user would type them.
pub(crate) fn parse_sub<T: clap::Args + FromArgMatches>(argv: &[&str]) -> Result<T> {
    let cmd = T::augment_args(clap::Command::new("ignis").no_binary_name(false));
    let m = cmd.try_get_matches_from(argv)?;
    Ok(T::from_arg_matches(&m)?)
}

fn run(cli: Cli) -> Result<()> {
    let g = Global { quiet: cli.quiet };
    match cli.cmd {
        Cmd::Classic(a) => classic::run(&a, &g).map(|_| ()),
        Cmd::Info(a) => info::run(&a),
        Cmd::Convert(a) => convert::run(&a, &g).map(|_| ()),
        Cmd::Eigen(c) => eigen::run(c, &g),
        Cmd::Volume(c) => volume::run(c, &g),
        Cmd::Learned(c) => learned::run(c, &g),
        Cmd::Loop(a) => loop_cmd::run(&a, &g),
        Cmd::Demo(a) => {
            let t = std::time::Instant::now();
            let mut d = demo::Demo::new(&a.output, g.clone(), a.seed, a.quick)?;
            classic::demo(&mut d)?;
            eigen::demo(&mut d)?;
            learned::demo(&mut d)?;
            volume::demo(&mut d)?;
            let index = d.finish()?;
            g.say(format!(
                "done in {:.1} s; open {}",
                t.elapsed().as_secs_f64(),
                index.display()
            ));
            Ok(())
        }
        Cmd::Bench(a) => {
            let v = match a.target.as_str() {
                "classic" => classic::bench(a.quick)?,
                "eigen-train" => ignis_pca::bench_figures(a.quick),
                "eigen-animate" => {
                    let sp = g.spinner("training the benchmark database, then timing");
                    let mut v = ignis_eigen::bench::animate_figures(a.quick, a.keep_db.as_deref())?;
                    sp.finish_and_clear();
                    let sp = g.spinner("footage case: writing, training and rendering a clip");
                    let f = animate::bench_footage(a.quick)?;
                    sp.finish_and_clear();
                    v["footage"] = f;
                    v
                }
                "eigen-footage" => {
                    let sp = g.spinner("writing, training and rendering a clip");
                    let f = animate::bench_footage(a.quick)?;
                    sp.finish_and_clear();
                    serde_json::json!({"bench": "eigen-footage", "quick": a.quick, "footage": f})
                }
                "volume" => volume::bench(&g, a.quick)?,
                "learned" => learned::bench(&g, a.quick)?,
                "export" => bench_export::figures(&g, a.quick)?,
                "realism" => bench_realism::bench(&g, a.quick)?,
                "flow" => {
                    let sp = g.spinner("timing flow and morphs");
                    let v = flow_bench(a.quick)?;
                    sp.finish_and_clear();
                    v
                }
                "loops" => {
                    let clips = if a.clips.is_empty() {
                        bench_loops::default_clips()
                    } else {
                        a.clips.clone()
                    };
                    bench_loops::bench(&clips, a.cache.as_deref(), &g)?
                }
                other => anyhow::bail!("unknown bench target `{other}`"),
            };
            println!("{}", serde_json::to_string_pretty(&v)?);
            Ok(())
        }
    }
}

/// Keeps glibc from handing large freed buffers back to the kernel. A frame at 400×400 in
/// linear RGBA is 2.5 MB; by default glibc maps each such buffer afresh and unmaps it when
/// freed (or trims it off the heap), so every frame of a render or a benchmark pays ~1,200
/// page faults for its new buffers (measured: `perf stat -e page-faults ignis bench volume
/// --quick`, ~25,000 → ~4,500; up to ~15% of a Table 1 frame). Serving them from the heap
/// and keeping up to 256 MB of freed memory for reuse costs nothing else.
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn keep_freed_memory() {
    // SAFETY: `mallopt` only sets allocator parameters; called before any other thread
    // exists. A refused value (return 0) just leaves glibc's default.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 256 << 20);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn keep_freed_memory() {}

fn main() -> ExitCode {
    keep_freed_memory();
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            for cause in e.chain().skip(1) {
                eprintln!("  caused by: {cause}");
            }
            ExitCode::FAILURE
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn cli_is_well_formed() {
        <super::Cli as clap::CommandFactory>::command().debug_assert();
    }
}
