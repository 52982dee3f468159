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
mod cache_cmd;
mod classic;
mod convert;
mod demo;
mod eigen;
mod frames;
mod global;
mod inbetween;
mod info;
mod kept_times;
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
ignis classic --size 320x200 --frames 300 -o fire.mp4\n  ignis info candle.mp4 --json\n  ignis bench classic\n  \
ignis cache --max-size 5G                # keep `ignis loop`'s cache of clip databases under 5 GiB"
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
    /// Frames and duration, fps, size, codec and decoder of a video, image or frame sequence (and
    /// its alpha).
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
    /// What `ignis loop`'s cache holds (clip databases, kept loop times), and trimming it.
    Cache(cache_cmd::Args),
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
    // A command's outputs never replace what it reads (its footage, a database's source
    // video, a model, a settings file): `-o` naming the input by mistake is refused. The
    // demo and the benchmarks write only into directories of their own.
    let _inputs =
        (!matches!(cli.cmd, Cmd::Demo(_) | Cmd::Bench(_))).then(ignis_core::atomic::guard_inputs);
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
            eigen::loop_demo::demo(&mut d)?;
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
        Cmd::Cache(a) => cache_cmd::run(&a, &g),
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
/// can catch). The handler only writes the signal's number to a pipe; a waiting thread
/// reads it and does the clean-up as ordinary code. No signal mask changes, so child
/// processes (ffmpeg) get the terminal's Ctrl-C as usual, and `exec` resets the handler
/// in them.
#[cfg(unix)]
fn remove_partial_output_on_interrupt() {
    use std::sync::atomic::{AtomicI32, AtomicU32, Ordering};
    static WRITE_END: AtomicI32 = AtomicI32::new(-1);
    // The signals given the handler (bit `sig`), not those left ignored.
    static HANDLED: AtomicU32 = AtomicU32::new(0);
    const SIGNALS: [libc::c_int; 3] = [libc::SIGINT, libc::SIGTERM, libc::SIGHUP];
    extern "C" fn on_signal(sig: libc::c_int) {
        let b = sig as u8;
        // SAFETY: `write` is async-signal-safe; the descriptor is the pipe's non-blocking
        // write end (a full pipe drops the byte: a signal is already waiting there). It
        // may change `errno` under the interrupted thread; the process exits right after.
        unsafe { libc::write(WRITE_END.load(Ordering::Relaxed), (&raw const b).cast(), 1) };
    }
    let mut fds = [-1 as libc::c_int; 2];
    // SAFETY: `pipe` fills `fds`; `fcntl` on the two descriptors just made: neither is
    // passed to child processes, and the write end is non-blocking.
    unsafe {
        if libc::pipe(fds.as_mut_ptr()) != 0 {
            return;
        }
        for fd in fds {
            libc::fcntl(fd, libc::F_SETFD, libc::FD_CLOEXEC);
        }
        libc::fcntl(fds[1], libc::F_SETFL, libc::O_NONBLOCK);
    }
    WRITE_END.store(fds[1], Ordering::Relaxed);
    let read_end = fds[0];
    let waiter = std::thread::Builder::new()
        .name("signals".into())
        .spawn(move || loop {
            let mut b = 0u8;
            // SAFETY: reads one byte into `b` from the pipe's read end.
            let n = unsafe { libc::read(read_end, (&raw mut b).cast(), 1) };
            if n == 1 {
                let sig = libc::c_int::from(b);
                // a second Ctrl-C during the clean-up stops the process at once
                for s in SIGNALS {
                    if HANDLED.load(Ordering::Relaxed) & (1 << s) != 0 {
                        // SAFETY: restores the default action of a signal given the handler.
                        unsafe { libc::signal(s, libc::SIG_DFL) };
                    }
                }
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
            } else if n == 0 {
                return;
            }
        });
    if waiter.is_err() {
        return;
    }
    for sig in SIGNALS {
        // SAFETY: reads the signal's current action into a zeroed `sigaction`; then sets
        // one with an empty mask, `SA_RESTART` (system calls the signal interrupts in
        // other threads resume) and a handler that only writes to a pipe — unless the
        // signal is ignored (`nohup`, a shell's background job): that choice stands.
        unsafe {
            let mut old: libc::sigaction = std::mem::zeroed();
            if libc::sigaction(sig, std::ptr::null(), &mut old) != 0
                || old.sa_sigaction == libc::SIG_IGN
            {
                continue;
            }
            let mut act: libc::sigaction = std::mem::zeroed();
            act.sa_sigaction = on_signal as extern "C" fn(libc::c_int) as libc::sighandler_t;
            act.sa_flags = libc::SA_RESTART;
            libc::sigemptyset(&mut act.sa_mask);
            if libc::sigaction(sig, &act, std::ptr::null_mut()) == 0 {
                HANDLED.fetch_or(1 << sig, Ordering::Relaxed);
            }
        }
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
            for cause in causes_to_print(&e) {
                eprintln!("  caused by: {cause}");
            }
            if let Some(h) = disk_hint(&e) {
                eprintln!("  hint: {h}");
            }
            ExitCode::FAILURE
        }
    }
}

/// What to do when `e` comes from the disk rather than the command: full or over quota
/// (mid-write, after the output checks passed; a read-only disk is refused by those
/// checks, with its own message). Encoders and ffmpeg pass the system's words on as text,
/// so the text counts as well as an I/O error's kind.
fn disk_hint(e: &anyhow::Error) -> Option<&'static str> {
    use std::io::ErrorKind as K;
    let text = format!("{e:#}");
    let kind = |k: K, words: &str| {
        text.contains(words)
            || e.chain()
                .filter_map(|c| c.downcast_ref::<std::io::Error>())
                .any(|io| io.kind() == k)
    };
    if kind(K::StorageFull, "No space left on device") {
        Some(
            "the disk is full: free some space on it, or write to another disk, and run the \
             command again (nothing half-written was left)",
        )
    } else if kind(K::QuotaExceeded, "Disk quota exceeded") {
        Some(
            "your disk quota is used up: free some of your space, or write to another disk, \
             and run the command again (nothing half-written was left)",
        )
    } else {
        None
    }
}

/// The causes of `e` worth printing under its message: those whose text is not already in
/// a line above (an I/O error's message quotes its source, which the chain then gives
/// again).
fn causes_to_print(e: &anyhow::Error) -> Vec<String> {
    let mut shown = e.to_string();
    let mut out = Vec::new();
    for cause in e.chain().skip(1) {
        let c = cause.to_string();
        if !c.is_empty() && !shown.contains(&c) {
            shown.push('\n');
            shown.push_str(&c);
            out.push(c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_cause_already_quoted_above_is_not_printed_again() {
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "no such file");
        let e = anyhow::Error::new(io)
            .context("I/O error on a.mp4: no such file")
            .context("reading a.mp4");
        assert_eq!(
            super::causes_to_print(&e),
            vec!["I/O error on a.mp4: no such file".to_string()]
        );
        let e = anyhow::anyhow!("the size is wrong").context("--size");
        assert_eq!(
            super::causes_to_print(&e),
            vec!["the size is wrong".to_string()]
        );
    }

    /// A full or over-quota disk gets its own hint, whether the system's error
    /// arrives as an I/O error or as an encoder's or ffmpeg's text; other errors get none.
    #[test]
    fn disk_errors_get_a_hint() {
        use std::io::{Error, ErrorKind};
        let io = |k: ErrorKind| anyhow::Error::new(Error::from(k)).context("writing a.png");
        let text = |t: &str| anyhow::anyhow!("cannot encode a.mov: ffmpeg failed: {t}");
        let hint = |e: anyhow::Error| super::disk_hint(&e).unwrap_or("none");
        assert!(hint(io(ErrorKind::StorageFull)).starts_with("the disk is full"));
        assert!(hint(text(
            "av_interleaved_write_frame(): No space left on device"
        ))
        .starts_with("the disk is full"));
        assert!(hint(text("Disk quota exceeded")).starts_with("your disk quota"));
        assert_eq!(hint(io(ErrorKind::ReadOnlyFilesystem)), "none");
        assert_eq!(hint(io(ErrorKind::NotFound)), "none");
        assert_eq!(
            hint(text("Invalid data found when processing input")),
            "none"
        );
    }

    #[test]
    fn cli_is_well_formed() {
        <super::Cli as clap::CommandFactory>::command().debug_assert();
    }
}
