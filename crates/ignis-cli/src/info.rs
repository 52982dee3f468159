//! `ignis info`: what a source is and which decoder will read it.

use anyhow::{Context, Result};

use crate::eigen::loop_cmd::WindowTiming;
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
    let variable = WindowTiming::of(&args.input, 0..usize::MAX);
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
                "uneven_steps": v.uneven.len(),
                "steps": v.frames - 1,
                "shortest_step_s": v.steps.0,
                "longest_step_s": v.steps.1,
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
                "fps:     {} on average; variable: {:.3} nominal, {}; `ignis loop` loops evenly timed stretches at that rate",
                info.fps,
                v.nominal_fps,
                v.steps_off()
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
