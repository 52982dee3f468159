//! `ignis convert`: any source Ignis reads to any output it writes (footage to a flipbook,
//! an MP4 to an EXR sequence, ...), with the readers' range, crop and scale options.

use crate::args;
use crate::global::Global;
use crate::output::OutputArgs;
use anyhow::{anyhow, Context, Result};
use ignis_core::Size;
use ignis_media::{FrameRange, ReadOptions};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  ignis convert candle.mp4 --range 100..160 --scale 128x128 -o candle.png   # flipbook\n  \
ignis convert campfire.mp4 --seconds 2..4 -o frames/%04d.exr\n  ignis convert 'frames/%04d.png' --fps 24 -o clip.mp4"
)]
pub struct Args {
    /// A video, an image, a directory of frames or a printf pattern.
    pub input: PathBuf,
    /// Frame range START..END (END exclusive; either may be omitted).
    #[arg(long, conflicts_with = "seconds")]
    pub range: Option<String>,
    /// Time range in seconds START..END.
    #[arg(long)]
    pub seconds: Option<String>,
    /// Crop X,Y,WIDTH,HEIGHT (before scaling).
    #[arg(long)]
    pub crop: Option<String>,
    /// Resize to WIDTHxHEIGHT (after cropping).
    #[arg(long)]
    pub scale: Option<Size>,
    #[command(flatten)]
    pub out: OutputArgs,
}

impl Args {
    pub fn read_options(&self) -> Result<ReadOptions> {
        let range = match (&self.range, &self.seconds) {
            (Some(r), _) => {
                let (a, b) = args::frame_range(r).map_err(|e| anyhow!("--range {e}"))?;
                Some(FrameRange::frames(a, b))
            }
            (None, Some(r)) => {
                let (a, b) = args::seconds_range(r).map_err(|e| anyhow!("--seconds {e}"))?;
                Some(FrameRange::seconds(a, b))
            }
            _ => None,
        };
        let crop = self
            .crop
            .as_deref()
            .map(|c| args::crop(c).map_err(|e| anyhow!("--{e}")))
            .transpose()?;
        Ok(ReadOptions {
            range,
            crop,
            scale: self.scale,
        })
    }
}

pub fn run(args: &Args, g: &Global) -> Result<Vec<PathBuf>> {
    let input = &args.input;
    let mut reader = ignis_media::open(input, &args.read_options()?)
        .with_context(|| format!("reading {}", input.display()))?;
    let info = reader.info().clone();
    let first = reader
        .next()
        .with_context(|| format!("{}: no frames in the requested range", input.display()))?;
    let first = first.with_context(|| format!("decoding {}", input.display()))?;
    let mut writer = args.out.create(first.size())?;
    let pb = g.progress(info.frame_count.unwrap_or(0), "converting");
    args.out.push(&mut writer, &first)?;
    for frame in reader {
        let frame = frame.with_context(|| format!("decoding {}", input.display()))?;
        args.out.push(&mut writer, &frame)?;
        pb.inc(1);
    }
    pb.finish_and_clear();
    args.out.finish(writer, g)
}
