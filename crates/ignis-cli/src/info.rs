//! `ignis info`: what a source is and which decoder will read it.

use anyhow::{Context, Result};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  ignis info candle.mp4\n  ignis info campfire.mp4 --json\n  ignis info 'frames/%04d.png'"
)]
pub struct Args {
    /// A video, an image, a directory of frames or a printf pattern.
    pub input: PathBuf,
    /// Print one JSON object (for scripts).
    #[arg(long)]
    pub json: bool,
}

pub fn run(args: &Args) -> Result<()> {
    let info = ignis_media::probe(&args.input)
        .with_context(|| format!("reading {}", args.input.display()))?;
    // timestamps that cannot be read say nothing of the rate: the probe's average stands
    let timing = ignis_media::frame_timing(&args.input).ok().flatten();
    let variable = timing.as_ref().and_then(variable_rate);
    if args.json {
        let v = serde_json::json!({
            "path": info.path,
            "frames": info.frame_count,
            "fps": info.fps,
            "width": info.size.width,
            "height": info.size.height,
            "codec": info.codec,
            "decoder": info.decoder.to_string(),
            "stored_width": info.anamorphic.map(|a| a.stored.width),
            "stored_height": info.anamorphic.map(|a| a.stored.height),
            "pixel_aspect": info.anamorphic.map(|a| format!("{}:{}", a.pixel_aspect.0, a.pixel_aspect.1)),
            "variable_frame_rate": variable.as_ref().map(|v| serde_json::json!({
                "nominal_fps": v.nominal_fps,
                "average_fps": v.average_fps,
                "uneven_steps": v.uneven,
                "steps": v.steps,
                "shortest_step_s": v.shortest,
                "longest_step_s": v.longest,
            })),
        });
        outln!("{}", serde_json::to_string_pretty(&v)?)?;
    } else {
        outln!("file:    {}", info.path.display())?;
        outln!(
            "frames:  {}",
            info.frame_count
                .map(|n| n.to_string())
                .unwrap_or_else(|| "unknown (container does not say)".into())
        )?;
        match &variable {
            Some(v) => outln!(
                "fps:     {} on average; variable: {:.3} nominal, {} of {} frame steps off it ({:.1}–{:.1} ms apart; `ignis loop` loops evenly timed stretches at {:.3} fps)",
                info.fps,
                v.nominal_fps,
                v.uneven,
                v.steps,
                v.shortest * 1e3,
                v.longest * 1e3,
                v.nominal_fps
            )?,
            None => outln!("fps:     {}", info.fps)?,
        }
        match info.anamorphic {
            Some(a) => outln!(
                "size:    {} (stored {} with {}:{} pixels; read at square pixels)",
                info.size,
                a.stored,
                a.pixel_aspect.0,
                a.pixel_aspect.1
            )?,
            None => outln!("size:    {}", info.size)?,
        }
        outln!("codec:   {}", info.codec)?;
        outln!("decoder: {}", info.decoder)?;
    }
    Ok(())
}

/// What `info` says of a variable frame rate.
struct VariableRate {
    nominal_fps: f64,
    average_fps: f64,
    /// Steps between frames not at the nominal rate, of `steps`.
    uneven: usize,
    steps: usize,
    shortest: f64,
    longest: f64,
}

/// The variable rate of `t`, `None` when its rate holds.
fn variable_rate(t: &ignis_media::FrameTiming) -> Option<VariableRate> {
    let uneven = t.uneven_steps().len();
    (uneven > 0).then(|| {
        let (shortest, longest) = t.step_range();
        VariableRate {
            nominal_fps: t.nominal_fps(),
            average_fps: t.average_fps(),
            uneven,
            steps: t.len() - 1,
            shortest,
            longest,
        }
    })
}
