//! Options every subcommand shares, and progress reporting.

use ignis_core::progress::Progress;
use indicatif::{ProgressBar, ProgressStyle};

/// Writes the command's output to stdout (what `outln!` / `out!` expand to). A reader
/// that has closed the pipe (`ignis info clip.mp4 | head -1`) stopped wanting the output:
/// the rest is dropped and the command ends normally, as `grep` or `rg` do, where
/// `println!` would panic. Any other failure (a full disk behind `> file`) is an error
/// that names standard output.
pub fn write_out(args: std::fmt::Arguments) -> anyhow::Result<()> {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    match out.write_fmt(args).and_then(|()| out.flush()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => {
            Err(anyhow::Error::new(e).context("cannot write to standard output"))
        }
        _ => Ok(()),
    }
}

/// Global options (`--quiet`).
#[derive(Clone, Debug, Default)]
pub struct Global {
    /// No progress bars and no chatter; errors still go to stderr.
    pub quiet: bool,
}

impl Global {
    /// A progress bar of `len` steps labelled `msg`; hidden when quiet or when stderr is
    /// not a terminal-like sink that indicatif can draw on.
    pub fn progress(&self, len: u64, msg: &str) -> ProgressBar {
        if self.quiet {
            return ProgressBar::hidden();
        }
        let pb = ProgressBar::new(len);
        pb.set_style(
            ProgressStyle::with_template("{msg:>12} [{bar:40}] {pos}/{len} ({per_sec}, eta {eta})")
                .expect("valid template")
                .progress_chars("=> "),
        );
        pb.set_message(msg.to_string());
        pb
    }

    /// A spinner for work of unknown length.
    pub fn spinner(&self, msg: &str) -> ProgressBar {
        if self.quiet {
            return ProgressBar::hidden();
        }
        let pb = ProgressBar::new_spinner();
        pb.set_message(msg.to_string());
        pb.enable_steady_tick(std::time::Duration::from_millis(120));
        pb
    }

    /// Prints a line to stdout unless quiet. Chatter: a stdout that cannot be written
    /// (a closed pipe, a full disk) does not stop the work.
    pub fn say(&self, msg: impl AsRef<str>) {
        if !self.quiet {
            let _ = write_out(format_args!("{}\n", msg.as_ref()));
        }
    }
}

/// Draws a library's [`Progress`] as one bar per stage (a spinner when the length is
/// unknown); messages are printed as lines above the bar. Quiet runs draw and print nothing.
pub struct StageBars<'a> {
    g: &'a Global,
    bar: Option<ProgressBar>,
    /// Stage lengths the caller knows better than the library (e.g. a clip's frame count).
    known: Vec<(String, u64)>,
}

impl<'a> StageBars<'a> {
    pub fn new(g: &'a Global) -> StageBars<'a> {
        StageBars {
            g,
            bar: None,
            known: Vec::new(),
        }
    }

    /// Draws stage `name` with `len` steps whatever length the library announces.
    pub fn with_length(mut self, name: &str, len: u64) -> StageBars<'a> {
        self.known.push((name.to_string(), len));
        self
    }
}

impl Progress for StageBars<'_> {
    fn stage(&mut self, name: &str, len: u64) {
        self.finish_stage();
        let len = self
            .known
            .iter()
            .find(|(n, _)| n == name)
            .map_or(len, |&(_, l)| l);
        self.bar = Some(if len > 0 {
            self.g.progress(len, name)
        } else {
            self.g.spinner(name)
        });
    }
    fn inc(&mut self, n: u64) {
        if let Some(b) = &self.bar {
            b.inc(n);
        }
    }
    fn message(&mut self, text: &str) {
        match &self.bar {
            Some(b) => b.suspend(|| self.g.say(text)),
            None => self.g.say(text),
        }
    }
    fn finish_stage(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
    }
}

impl Drop for StageBars<'_> {
    fn drop(&mut self) {
        self.finish_stage();
    }
}
