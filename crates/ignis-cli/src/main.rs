//! `ignis`: controllable fire animations from the command line.
//!
//! A thin layer over the library crates: argument parsing, progress bars and error
//! reporting live here; every capability is a library call.

/// `println!` for a command's output, through [`global::write_out`]: evaluates to an
/// `anyhow::Result<()>` (a closed pipe is not an error; a failed write is).
macro_rules! outln {
    ($($t:tt)*) => {
        $crate::global::write_out(format_args!("{}\n", format_args!($($t)*)))
    };
}

/// `print!` for a command's output, as [`outln!`] without the newline.
macro_rules! out {
    ($($t:tt)*) => {
        $crate::global::write_out(format_args!($($t)*))
    };
}

mod args;
mod bench;
mod classic;
mod convert;
mod demo;
mod eigen;
mod frames;
mod global;
mod inbetween;
mod info;
mod learned;
mod output;
mod volume;

use anyhow::Result;
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
    // The output keeps the footage's frame rate and refuses --fps: not listed in --help.
    #[command(mut_arg("fps", |a| a.hide(true)))]
    Loop(eigen::loop_cmd::Args),
    /// Headline performance figures of a method as one JSON object.
    Bench(bench::BenchArgs),
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
        Cmd::Loop(a) => eigen::loop_cmd::run(&a, &g),
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
        Cmd::Bench(a) => bench::run(&a, &g),
    }
}

/// Keeps glibc from handing large freed buffers back to the kernel. A frame at 400×400 in
/// linear RGBA is 2.5 MB; by default glibc maps each such buffer afresh and unmaps it when
/// freed (or trims it off the heap), so every frame of a render or a benchmark pays page
/// faults for its new buffers (figures: `crates/ignis-cli/benches/README.md`). Serving them
/// from the heap and keeping up to 256 MB of freed memory for reuse costs nothing else.
/// One arena: glibc gives each worker thread its own arena, whose heaps are unmapped
/// whenever they empty, so a 1080p frame (33 MB in linear RGBA) freed on a worker thread
/// was faulted in afresh by the next one (`ignis bench eigen-footage`: 4.1 → 1.9 s of
/// kernel time for 118 frames).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn keep_freed_memory() {
    // SAFETY: `mallopt` only sets allocator parameters; called before any other thread
    // exists. A refused value (return 0) just leaves glibc's default.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 256 << 20);
        libc::mallopt(libc::M_ARENA_MAX, 1);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn keep_freed_memory() {}

/// Flags a subcommand takes through the shared output options but cannot honour, refused
/// when given on the command line rather than silently ignored: `ignis loop` writes the
/// footage's own frames, so it plays them at the footage's own frame rate.
fn refused_flags(m: &clap::ArgMatches) -> Option<String> {
    let (name, sub) = m.subcommand()?;
    let given = |id: &str| sub.value_source(id) == Some(clap::parser::ValueSource::CommandLine);
    (name == "loop" && given("fps")).then(|| {
        "--fps: `ignis loop` writes the footage's own frames at the footage's own frame rate \
         (another rate would play the flame faster or slower); drop --fps, and to store \
         another playback rate convert the result: `ignis convert loop.mp4 --fps 30 -o \
         loop30.mp4`"
            .to_string()
    })
}

/// Ctrl-C, a closed terminal or a render farm's stop (SIGINT, SIGHUP, SIGTERM): the
/// process removes the temporaries it is writing ([`ignis_core::tempfiles::remove_live`])
/// and exits with 128 + the signal, rather than leaving hidden partial files for the next
/// run in that directory to clean (which still happens after SIGKILL, which no process
/// can catch). The signals are blocked in every thread and taken by one waiting thread, so
/// the clean-up runs as ordinary code, not in a signal handler.
#[cfg(unix)]
fn remove_partial_output_on_interrupt() {
    // SAFETY: `sigemptyset`/`sigaddset` fill a local set; `pthread_sigmask` changes the
    // calling (main) thread's mask before any other thread exists, so every thread
    // started later inherits it (child processes do not: `std::process::Command` gives
    // them an empty mask).
    let set = unsafe {
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut set);
        for s in [libc::SIGINT, libc::SIGTERM, libc::SIGHUP] {
            libc::sigaddset(&mut set, s);
        }
        if libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut()) != 0 {
            return;
        }
        set
    };
    let waiter = std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || loop {
            let mut sig = 0;
            // SAFETY: `set` is a valid signal set; `sig` receives the signal number.
            if unsafe { libc::sigwait(&set, &mut sig) } == 0 {
                let removed = ignis_core::tempfiles::remove_live();
                let name = match sig {
                    libc::SIGINT => "interrupted",
                    libc::SIGTERM => "terminated",
                    _ => "hung up",
                };
                match removed.len() {
                    0 => eprintln!("\n{name}: stopped (no output was being written)"),
                    n => eprintln!(
                        "\n{name}: stopped; removed {n} unfinished output{} (nothing \
                         half-written is left)",
                        if n == 1 { "" } else { "s" }
                    ),
                }
                std::process::exit(128 + sig);
            }
        });
    if waiter.is_err() {
        // SAFETY: as above; the signals' default actions again.
        unsafe { libc::pthread_sigmask(libc::SIG_UNBLOCK, &set, std::ptr::null_mut()) };
    }
}

#[cfg(not(unix))]
fn remove_partial_output_on_interrupt() {}

fn main() -> ExitCode {
    keep_freed_memory();
    remove_partial_output_on_interrupt();
    let matches = <Cli as clap::CommandFactory>::command().get_matches();
    let cli = Cli::from_arg_matches(&matches).unwrap_or_else(|e| e.exit());
    if let Some(why) = refused_flags(&matches) {
        eprintln!("error: {why}");
        return ExitCode::FAILURE;
    }
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
