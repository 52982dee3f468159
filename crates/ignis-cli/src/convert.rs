//! `ignis convert`: any source Ignis reads to any output it writes (footage to a flipbook,
//! an MP4 to an EXR sequence, ...), with the readers' range, crop and scale options.

use crate::args;
use crate::global::Global;
use crate::output::OutputArgs;
use anyhow::{anyhow, Context, Result};
use ignis_core::Size;
use ignis_media::{FrameRange, RangeUnit, ReadOptions};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  ignis convert candle.mp4 --range 100..160 --scale 128x128 -o candle.png   # flipbook\n  \
ignis convert campfire.mp4 --seconds 2..4 -o frames/%04d.exr\n  ignis convert 'frames/%04d.png' --sequence-fps 24 -o clip.mp4    (a 24-fps sequence; it stores no rate)\n  \
ignis convert loop.png -o loop.mp4                                         # a flipbook played as video\n\n\
Footage is written at its own frame rate (--fps sets another). A variable-frame-rate clip (a phone's, \
slowing down in low light) is written at its nominal rate with each frame shown for as long as it was shot, \
and --seconds counts by the frames' own times. A GIF or flipbook is marked as looping (--no-loop: played once); \
when the frames do not loop (the step from the last back to the first is over twice their median step), convert \
says so and names the `ignis loop` command that makes a seamless loop."
)]
pub struct Args {
    /// A video, an image, a flipbook (its sheet or JSON), a directory of frames or a printf
    /// pattern.
    pub input: PathBuf,
    /// Frame range START..END (END exclusive; either may be omitted).
    #[arg(long, conflicts_with = "seconds")]
    pub range: Option<String>,
    /// Time range in seconds START..END.
    #[arg(long)]
    pub seconds: Option<String>,
    /// Crop X,Y,WIDTH,HEIGHT (before scaling; also as WIDTHxHEIGHT+X+Y, or ffmpeg
    /// cropdetect's crop=W:H:X:Y).
    #[arg(long)]
    pub crop: Option<String>,
    /// Resize to WIDTHxHEIGHT (after cropping).
    #[arg(long)]
    pub scale: Option<Size>,
    #[command(flatten)]
    pub sequence: crate::args::SequenceFps,
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

/// When `--scale` gives the (cropped) picture another aspect: a note that it is stretched,
/// with the size that keeps its aspect (as ffmpeg's `scale`, `--scale` resizes to exactly
/// the size given).
fn stretch_note(read: &ReadOptions, source: Size) -> Option<String> {
    let scale = read.scale?;
    let picture = read.crop.map_or(source, |r| Size {
        width: r.width,
        height: r.height,
    });
    let kept = picture.fitted_inside(scale);
    (kept != scale).then(|| {
        format!(
            "note: --scale {scale} stretches the {picture} picture to another aspect; --scale \
             {kept} keeps its aspect (or --crop a part of it with the new aspect first)"
        )
    })
}

pub fn run(args: &Args, g: &Global) -> Result<Vec<PathBuf>> {
    let input = &args.input;
    args.sequence.apply(&[input])?;
    let mut read = args.read_options()?;
    let info = ignis_media::probe(input).with_context(|| format!("reading {}", input.display()))?;
    if let Some(note) = args.sequence.default_rate_note(&info) {
        g.say(note);
    }
    if let Some(note) = stretch_note(&read, info.size) {
        g.say(note);
    }
    // timestamps that cannot be read: every frame once, at the probe's average rate
    let timing = ignis_media::frame_timing(input)
        .ok()
        .flatten()
        .filter(|t| t.is_variable());
    // A variable frame rate: --seconds by the frames' own times, and every frame written
    // for as long as it is shown, at the nominal rate (or --fps), as a player shows it.
    if let (Some(t), Some(r)) = (&timing, read.range) {
        if r.unit == RangeUnit::Seconds {
            read.range = Some(FrameRange::frames(
                t.frame_at(r.start),
                r.end.map(|e| t.frame_at(e)),
            ));
        }
    }
    let fps = args.out.fps.unwrap_or(match &timing {
        Some(t) => t.nominal_fps(),
        None => info.fps,
    });
    let out = OutputArgs {
        fps: Some(fps),
        ..args.out.clone()
    };
    out.check_with(&out.write_options())?;
    let holds = match &timing {
        Some(t) => {
            let (a, b) = read
                .range
                .unwrap_or(FrameRange::frames(0, None))
                .resolve(info.fps, info.frame_count)?;
            let (a, b) = (a as usize, b.map_or(t.len(), |b| b as usize));
            // a gap in the timestamps is held as a player holds it, up to a bound
            let most = 100 * (b - a) as u64 + 1000;
            let holds = t.holds(a..b, fps, most).map_err(|n| {
                let gap = t.longest_step(a..b).map_or(String::new(), |(i, s)| {
                    format!(" (the longest gap: {s:.3} s after frame {i})")
                });
                anyhow!(
                    "{}: its frames' timestamps span {:.1} s, {n} frames at {} fps for {} frames read{gap}; \
                     give --range to leave a gap out, or a lower --fps",
                    input.display(),
                    n / fps,
                    crate::args::fps_text(fps),
                    b - a
                )
            })?;
            let held = holds.iter().filter(|&&n| n > 1).count();
            let dropped = holds.iter().filter(|&&n| n == 0).count();
            g.say(if t.from_frame_numbers() {
                format!(
                    "timing: frames are missing from the sequence ({} of {} steps jump over them); \
                     written at {fps:.3} fps with the frame before each gap held over it ({held} held \
                     longer, {dropped} left out), so the rest keep their place in time; --fps sets \
                     another rate",
                    t.uneven_steps().len(),
                    t.len() - 1
                )
            } else {
                format!(
                    "timing: the frame rate varies ({:.3} fps nominal, {:.3} on average); written at {fps:.3} fps \
                     with each frame shown for as long as it was shot ({held} held longer, {dropped} left out); \
                     --fps sets another rate",
                    t.nominal_fps(),
                    t.average_fps()
                )
            });
            Some(holds)
        }
        None => None,
    };
    let times = |i: usize| holds.as_ref().map_or(1, |h| h.get(i).copied().unwrap_or(1));
    let reader =
        ignis_media::open(input, &read).with_context(|| format!("reading {}", input.display()))?;
    let pb = g.progress(info.frame_count.unwrap_or(0), "converting");
    let mut writer = None;
    for (i, frame) in reader.enumerate() {
        let frame = frame.with_context(|| format!("decoding {}", input.display()))?;
        let w = match &mut writer {
            Some(w) => w,
            None => writer.insert(out.create(frame.size())?),
        };
        for _ in 0..times(i) {
            out.push(w, &frame)?;
        }
        pb.inc(1);
    }
    pb.finish_and_clear();
    let writer =
        writer.with_context(|| format!("{}: no frames in the requested range", input.display()))?;
    let warning = not_a_loop(&writer, input, &out);
    let files = out.finish(writer, g)?;
    if let Some(w) = warning {
        g.say(w);
    }
    Ok(files)
}

/// How many median steps the step from the last frame back to the first may be before a
/// looping output is said not to loop: twice a typical step is a jump every cycle (the
/// reference loop metrics call a seam of 2 or more "a cut"), where a seamless loop's wrap
/// is one step among the others. Measured with `shared/tools/loop_metrics.py`'s steps:
/// `ignis loop CLIP --length 2s` of the three dev clips, 1.01–1.11; 200 random stretches of
/// 24–120 frames each, median 2.1 (candle.mp4), 6.1 (fireball.mp4), but 1.3 on
/// campfire.mp4, whose every step is already a large change (there a cut is not called out).
const JUMP: f64 = 2.0;

/// A GIF or flipbook is marked as looping unless `--no-loop`, but a stretch of footage
/// rarely is a loop: when the step from its last frame back to its first is over [`JUMP`]
/// median steps, the warning says so and names the command that makes a seamless loop.
fn not_a_loop(
    writer: &ignis_media::FrameWriter,
    input: &std::path::Path,
    out: &OutputArgs,
) -> Option<String> {
    use ignis_media::Format;
    if out.no_loop || !matches!(writer.format(), Format::Gif | Format::Flipbook) {
        return None;
    }
    let wrap = writer.wrap_step()?;
    let median = writer.sequence_quality()?.median_step;
    (median > 0.0 && wrap > JUMP * median).then(|| {
        format!(
            "warning: these frames do not loop: the step from the last back to the first is {:.1}× \
             their median step, a jump every cycle (the {} is still marked as looping). \
             `ignis loop {} --length {} -o {}` makes a seamless loop from the clip; \
             --no-loop marks this one as played once",
            wrap / median,
            if writer.format() == Format::Gif { "GIF" } else { "flipbook" },
            input.display(),
            writer.frames(),
            out.output.display()
        )
    })
}
