//! Options every subcommand shares, and progress reporting.

use indicatif::{ProgressBar, ProgressStyle};

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

    /// Prints a line to stdout unless quiet.
    pub fn say(&self, msg: impl AsRef<str>) {
        if !self.quiet {
            println!("{}", msg.as_ref());
        }
    }
}
