//! `ignis info`: what a source is and which decoder will read it.

use anyhow::{Context, Result};

use crate::eigen::loop_cmd::WindowTiming;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  ignis info candle.mp4\n  ignis info campfire.mp4 --json\n  ignis info 'frames/%04d.png'    (a keyed element says how much of its first frame is see-through)\n  ignis info loop.png    (a flipbook: its frames, rate and measured loop quality)"
)]
pub struct Args {
    /// A video, an image, a flipbook (its sheet or JSON), a directory of frames or a printf
    /// pattern.
    pub input: PathBuf,
    /// Print one JSON object (for scripts).
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub sequence: crate::args::SequenceFps,
}

pub fn run(args: &Args) -> Result<()> {
    args.sequence.apply(&[&args.input])?;
    let info = ignis_media::probe(&args.input)
        .with_context(|| format!("reading {}", args.input.display()))?;
    let variable = WindowTiming::of(&args.input, 0..usize::MAX);
    // a header that reads but a first frame that does not (a cut-off download) is said,
    // after what the header says
    let see_through = first_frame_see_through(&args.input);
    // a file cut short after its index (an incomplete download) lists frames it lacks
    let short = ignis_media::frames_in_data(&args.input)
        .ok()
        .flatten()
        .zip(info.frame_count)
        .filter(|&(present, listed)| present < listed);
    let book = flipbook_meta(&info);
    // a sequence's first and last files: frames count from 0 in the order read, and a
    // compositor's numbers (shot.1001.exr) are not those
    let ends = (info.decoder == ignis_media::Decoder::ImageSequence)
        .then(|| ignis_media::source_files(&args.input).ok())
        .flatten()
        .and_then(|f| {
            let name = |p: &std::path::PathBuf| {
                p.file_name()
                    .map_or(String::new(), |n| n.to_string_lossy().into_owned())
            };
            Some((name(f.first()?), name(f.last()?)))
        });
    if args.json {
        let v = serde_json::json!({
            "path": info.path,
            "frames": info.frame_count,
            "fps": info.fps,
            "duration_s": duration(&info, variable.as_ref()),
            "width": info.size.width,
            "height": info.size.height,
            "codec": info.codec,
            "decoder": info.decoder.to_string(),
            "stored_width": info.anamorphic.map(|a| a.stored.width),
            "stored_height": info.anamorphic.map(|a| a.stored.height),
            "pixel_aspect": info.anamorphic.map(|a| format!("{}:{}", a.pixel_aspect.0, a.pixel_aspect.1)),
            "see_through_first_frame": see_through.as_ref().ok(),
            "first_file": ends.as_ref().map(|e| &e.0),
            "last_file": ends.as_ref().map(|e| &e.1),
            "flipbook": book.as_ref().map(|m| serde_json::json!({
                "columns": m.columns,
                "rows": m.rows,
                "variants": m.variants,
                "loop": m.loop_,
                "loop_quality": m.loop_quality,
                "variant_loop_quality": m.variant_loop_quality,
                "engine": m.engine,
                "alpha": m.alpha,
            })),
            "first_frame_error": see_through.as_ref().err().map(|e| format!("{e:#}")),
            "frames_in_data": short.map(|s| s.0),
            "variable_frame_rate": variable.as_ref().map(|v| serde_json::json!({
                "nominal_fps": v.nominal_fps,
                "average_fps": v.average_fps,
                "uneven_steps": v.uneven.len(),
                "steps": v.frames - 1,
                "shortest_step_s": v.steps.0,
                "longest_step_s": v.steps.1,
                "from_frame_numbers": v.numbered,
            })),
        });
        outln!("{}", serde_json::to_string_pretty(&v)?)?;
    } else {
        outln!("file:    {}", info.path.display())?;
        outln!(
            "frames:  {}",
            match (info.frame_count, duration(&info, variable.as_ref())) {
                (Some(n), Some(d)) => format!("{n} ({d:.2} s)"),
                (Some(n), None) => n.to_string(),
                (None, _) => "unknown (container does not say)".into(),
            }
        )?;
        if let (Some((first, last)), Some(n)) = (&ends, info.frame_count) {
            outln!("files:   {first} to {last} (frames 0..{n} in --range, in the order read)")?;
        }
        // a sequence's files mostly hold no rate: say where this one came from
        let given = match (info.decoder, args.sequence.sequence_fps) {
            (ignis_media::Decoder::ImageSequence, Some(_)) => " (--sequence-fps)",
            (ignis_media::Decoder::ImageSequence, None) if info.rate_stated => {
                " (its EXR headers' framesPerSecond; --sequence-fps sets another)"
            }
            (ignis_media::Decoder::ImageSequence, None) => {
                " (its files state none: --sequence-fps sets it)"
            }
            _ => "",
        };
        match &variable {
            Some(v) if v.numbered => outln!(
                "fps:     {}{given}; {}; `ignis convert` holds the frame before each gap",
                crate::args::fps_text(info.fps),
                v.steps_off()
            )?,
            Some(v) => outln!(
                "fps:     {} on average; variable: {:.3} nominal, {}; `ignis loop` loops evenly timed stretches at that rate",
                crate::args::fps_text(info.fps),
                v.nominal_fps,
                v.steps_off()
            )?,
            None => outln!("fps:     {}{given}", crate::args::fps_text(info.fps))?,
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
        if let Some((present, listed)) = short {
            outln!(
                "warning: its data holds at most {present} of the {listed} frames its header lists: \
                 the file may be truncated (an incomplete download or copy); copy it again, or \
                 use only its first frames"
            )?;
        }
        if let Some(m) = &book {
            match (&m.loop_quality, m.loop_) {
                (Some(q), true) => outln!(
                    "loop:    yes; seam {:.2}, ghost {:.2} (measured on the sheet's frames: \
                     largest step over the median, softest frame's sharpness)",
                    q.seam,
                    q.ghost
                )?,
                (None, true) => match &m.variant_loop_quality {
                    Some(v) => {
                        let seams: Vec<String> =
                            v.iter().map(|q| format!("{:.2}", q.seam)).collect();
                        let ghosts: Vec<String> =
                            v.iter().map(|q| format!("{:.2}", q.ghost)).collect();
                        outln!(
                            "loop:    yes, {} loops as rows; seams {}, ghosts {} (measured on the \
                             sheet's frames)",
                            v.len(),
                            seams.join(" / "),
                            ghosts.join(" / ")
                        )?
                    }
                    None => outln!("loop:    yes")?,
                },
                _ => outln!("loop:    no (a sequence that is not played as a loop)")?,
            }
        }
        match &see_through {
            Ok(s) if *s > 0.0 => outln!(
                "alpha:   its own (a keyed element: {:.0} % of the first frame see-through); `ignis loop` keeps it",
                s * 100.0
            )?,
            Ok(_) => {}
            Err(e) => outln!("warning: {e:#}")?,
        }
    }
    Ok(())
}

/// How long the source plays, as a player shows it: its frames at its (average) rate, or
/// for a sequence with frames missing (`timing`), from its first frame's number to one
/// step past its last. `None` when the frame count is unknown or the rate is not a
/// positive number.
fn duration(info: &ignis_media::SourceInfo, timing: Option<&WindowTiming>) -> Option<f64> {
    let n = info.frame_count?;
    if let Some(t) = timing.filter(|t| t.numbered && t.frames as u64 == n) {
        return Some((n - 1) as f64 / t.average_fps + 1.0 / t.nominal_fps);
    }
    (info.fps.is_finite() && info.fps > 0.0).then(|| n as f64 / info.fps)
}

/// A flipbook's sidecar (the source given as its sheet or as the sidecar itself).
fn flipbook_meta(info: &ignis_media::SourceInfo) -> Option<ignis_media::FlipbookMeta> {
    if info.decoder != ignis_media::Decoder::Flipbook {
        return None;
    }
    let files = ignis_media::source_files(&info.path).ok()?;
    ignis_media::read_flipbook_meta(files.last()?).ok()
}

/// The share of the first frame's pixels that are see-through (alpha below 1): 0 for
/// opaque footage, more for a keyed element with its own alpha.
fn first_frame_see_through(path: &std::path::Path) -> Result<f64> {
    let opts = ignis_media::ReadOptions {
        range: Some(ignis_media::FrameRange::frames(0, Some(1))),
        ..Default::default()
    };
    let mut r = ignis_media::open_keeping_8bit(path, &opts)
        .with_context(|| format!("reading {}", path.display()))?;
    let f = r
        .next_decoded()
        .with_context(|| format!("{} has no frame to read", path.display()))?
        .with_context(|| format!("the first frame of {} cannot be decoded", path.display()))?;
    Ok(f.see_through() as f64 / f.size().pixels() as f64)
}
