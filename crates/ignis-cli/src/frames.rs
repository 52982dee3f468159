//! Options every procedural generator shares about *which* frames it writes: a seamless
//! loop (`--loop` / `--no-loop`) and a render-farm chunk (`--chunk A..B`).

use crate::output::OutputArgs;
use anyhow::Result;
use ignis_media::Format;
use std::ops::Range;

/// `--chunk A..B`: frames `A` (inclusive) to `B` (exclusive) of the full render.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Chunk {
    pub start: u32,
    pub end: u32,
}

impl std::str::FromStr for Chunk {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Chunk, String> {
        let (start, end) = crate::args::closed_range::<u32>(s, "a frame number")?;
        Ok(Chunk { start, end })
    }
}

/// Loop and chunk flags, flattened into each generator's arguments.
#[derive(clap::Args, Debug, Clone)]
pub struct FrameArgs {
    /// Make the animation a seamless loop: frame N would equal frame 0, so playing the N
    /// frames over and over shows no jump. The default for GIFs and flipbooks; `--loop`
    /// also loops MP4s and sequences, `--no-loop` renders the plain, unlooped animation.
    #[arg(long = "loop", conflicts_with = "no_loop")]
    pub loop_: bool,
    /// Write only frames A..B (A included, B excluded) of the `--frames N` render, exactly
    /// as the full render would write them (sequence files keep their frame numbers), for
    /// splitting a render across machines. A loop keeps its period of N frames.
    #[arg(long, value_name = "A..B")]
    pub chunk: Option<Chunk>,
}

/// What a generator must do: loop or not, and which frames to write.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Plan {
    /// The animation is a seamless loop of all `frames` frames.
    pub looping: bool,
    /// The frames to write (all of `0..frames` unless a chunk was asked for).
    pub range: Range<u32>,
    /// The writer may mark the output as looping (a whole loop was written).
    pub mark_loop: bool,
}

impl FrameArgs {
    /// Checks the flags against `--frames` and the output; nothing is written on error.
    pub fn plan(&self, frames: u32, out: &OutputArgs) -> Result<Plan> {
        anyhow::ensure!(
            frames > 0,
            "--frames 0: nothing to write; ask for at least 1 frame"
        );
        let loops_by_default = matches!(out.output_format(), Some(Format::Gif | Format::Flipbook));
        let looping = if out.no_loop {
            false
        } else if self.loop_ {
            anyhow::ensure!(
                frames >= 2,
                "--loop with --frames {frames}: a loop needs at least 2 frames; ask for more frames or drop --loop"
            );
            true
        } else {
            // one frame cannot loop; it is written as a still
            loops_by_default && frames >= 2
        };
        let range = match self.chunk {
            None => 0..frames,
            Some(c) => {
                anyhow::ensure!(
                    c.start < c.end && c.end <= frames,
                    "--chunk {}..{} is not a range of frames inside 0..{frames} (--frames {frames}); give A..B with A < B ≤ {frames}",
                    c.start,
                    c.end
                );
                c.start..c.end
            }
        };
        let whole = range == (0..frames);
        Ok(Plan {
            looping,
            mark_loop: looping && whole,
            range,
        })
    }
}
