//! `ignis demo`'s first section: `ignis loop` on the real footage in `../shared/data`,
//! beside the two peers `ignis bench loops` measures it against (a 10-frame crossfade of
//! the clip's middle, as Unity's Loop Sequence or Houdini's Make Loop do, and Video
//! Textures' best loop with the same crossfade), each written as a GIF at one size and
//! measured on its written frames by the same writer, plus a picture of the frames around
//! each loop's wrap side by side and the engine flipbook a user gets by default (the flame
//! keyed out by its matte).
//!
//! The clips' databases go to `ignis loop`'s own cache, so a later `ignis loop` on the same
//! clip starts at once. Without the footage (or a decoder for it) the section says so.

use std::ops::Range;
use std::path::Path;

use anyhow::{Context, Result};
use ignis_core::loopq::{self, LoopQuality};
use ignis_core::{RgbaFrame, Size};
use ignis_eigen::loops::{self, Candidate, Closing, Evaluated, Skips};

use super::loop_cmd::{self, LoopAsk, LoopFootage, Method};
use crate::bench::loops::{video_texture, xfade, K};
use crate::demo::{shared_data, Demo};
use crate::global::Global;
use crate::output::OutputArgs;

/// Frames shown on each side of the wrap in the seam picture.
const AROUND: usize = 3;

/// The section: every clip of `../shared/data` that is there and can be read.
pub fn demo(ctx: &mut Demo) -> Result<()> {
    // (clip, the source frames looked in). fireball.mp4's burst fills frames ≈ 20–150 and
    // the rest is sparks on black, which is where an opaque loop of the whole clip (and the
    // crossfade of its middle) would be: its range is the burst, as a user would give it.
    // The quick demo (a smoke test) loops one second of the candle's first three.
    let clips: &[(&str, Option<Range<usize>>)] = if ctx.quick {
        &[("candle", Some(0..90))]
    } else {
        &[
            ("candle", None),
            ("campfire", None),
            ("fireball", Some(0..150)),
        ]
    };
    let found: Vec<_> = clips
        .iter()
        .filter_map(|(name, range)| {
            let p = shared_data(&format!("{name}.mp4"))?;
            // H.264 Baseline decodes without ffmpeg; anything else needs it.
            (ignis_media::ffmpeg_available() || ignis_media::probe(&p).is_ok()).then_some((
                *name,
                p,
                range.clone(),
            ))
        })
        .collect();
    let intro = "Ignis's core job: a seamless loop of real fire footage, found by the Eigenfire \
         search, closed by the best of a cut, a crossfade and a motion-compensated morph, and \
         written at the footage's own quality. Beside each, the loops artists make today from \
         the same clip and length: a 10-frame crossfade of the clip's middle (Unity's Loop \
         Sequence, Houdini's Make Loop) and Video Textures' best loop (Schödl et al. 2000) with \
         the same crossfade. Seam = the loop's largest step over its median step (1 is as \
         smooth as the footage; the wrap included); ghost = its softest frame's sharpness over \
         its neighbours' (1 = no double exposure). All are written at one size and measured \
         by the same writer; `ignis bench loops` gives the figures at full size.";
    if found.is_empty() {
        ctx.section(
            "Seamless loops from real footage",
            &format!(
                "{intro} Skipped here: no readable clip in ../shared/data (candle.mp4, \
                 campfire.mp4, fireball.mp4{}). On your own footage: ignis loop fire.mp4 \
                 --length 2s -o loop.gif",
                if ignis_media::ffmpeg_available() {
                    ""
                } else {
                    "; their codecs need the system ffmpeg"
                }
            ),
        );
        return Ok(());
    }
    ctx.section("Seamless loops from real footage", intro);
    // `ignis loop`'s cache, or (no HOME nor XDG_CACHE_HOME) one in the temporary directory
    let cache =
        loop_cmd::default_cache_dir().unwrap_or_else(|_| std::env::temp_dir().join("ignis-cache"));
    for (name, path, range) in found {
        clip(ctx, name, &path, range, &cache)
            .with_context(|| format!("demo loop of {name}.mp4"))?;
    }
    Ok(())
}

/// The size `size` is shown at: its longer side `side` px (at most its own), aspect kept.
fn shown_size(size: Size, side: u32) -> Result<Size> {
    let long = size.width.max(size.height);
    if long <= side {
        return Ok(size);
    }
    let scale = |v: u32| ((v as f64 * side as f64 / long as f64).round() as u32).max(1);
    Ok(Size::new(scale(size.width), scale(size.height))?)
}

/// One clip's loop, its peers, the seam picture and the default flipbook.
fn clip(
    ctx: &mut Demo,
    name: &str,
    path: &Path,
    range: Option<Range<usize>>,
    cache: &Path,
) -> Result<()> {
    let (window, fps) = loop_cmd::resolve_window(path, range.clone())?;
    let secs = if ctx.quick { 1.0 } else { 2.0 };
    let length = loops::parse_length(&format!("{secs}s"), fps)?;
    ctx.global.say(format!(
        "  {name}.mp4: the clip's database (cached for `ignis loop`)"
    ));
    let c = loop_cmd::cached(
        loop_cmd::Clip::whole(path),
        window.clone(),
        "32x48".parse()?,
        40,
        cache,
        &ctx.global,
    )?;
    let info = ignis_media::probe(path)?;
    let size = shown_size(info.size, if ctx.quick { 96 } else { 320 })?;
    let quiet = Global { quiet: true };
    let shown = format!("../shared/data/{name}.mp4");
    let range_arg = range
        .as_ref()
        .map(|r| format!(" --range {}..{}", r.start, r.end))
        .unwrap_or_default();
    let user = |extra: &str, out: &str| {
        format!("ignis loop {shown} --length {secs}s{range_arg} --size {size}{extra} -o {out}")
    };
    let src = LoopFootage::cached(path, window.start, &c);
    let ask = LoopAsk {
        length,
        method: Method::Auto,
        top: 3,
        every: 1,
    };

    // Ignis, opaque as the peers see the footage.
    let rel = format!("loops/{name}.gif");
    let out = OutputArgs {
        fps: Some(c.fps),
        ..OutputArgs::for_path(ctx.path(&rel)?)
    };
    let d = loop_cmd::make_loop_sized(&src.opaque(), &ask, Some(size), &out, &quiet)?;
    let b = d.chosen.best;
    ctx.item(
        &rel,
        &format!(
            "{name}.mp4, Ignis: frames {}..{} closed by a {}; seam {:.2}, ghost {:.2}",
            window.start + b.candidate.start,
            window.start + b.candidate.end,
            b.closing,
            d.measured.seam,
            d.measured.ghost
        ),
        &user(" --alpha opaque", &format!("{name}.gif")),
    );
    let mut rows = vec![frames_of(path, window.start, &b, size)?];

    // The peers, as `ignis bench loops` and shared/tools/loop_metrics.py make them.
    let n = c.metric.len();
    if n >= length + K + 3 {
        let a = (n - length - K) / 2;
        let xq = loopq::loop_quality(&xfade(&c.metric, a, a + length + K, K))?;
        let rel = format!("loops/{name}-crossfade.gif");
        let (q, f) = write_peer(ctx, &rel, path, window.start, a..a + length, xq, size, fps)?;
        ctx.item(
            &rel,
            &format!(
                "{name}.mp4, 10-frame crossfade of the middle{}: frames {}..{} with the next \
                 {K} crossfaded into its first {K}; seam {:.2}, ghost {:.2}",
                if range_arg.is_empty() { "" } else { " of the range" },
                window.start + a,
                window.start + a + length,
                q.seam,
                q.ghost
            ),
            "the peer of `ignis bench loops` (xfade of shared/tools/loop_metrics.py), rendered at the same size",
        );
        rows.push(f);
    }
    if let Some((vf, i, j)) = video_texture(&c.metric, length, K) {
        let vq = loopq::loop_quality(&vf)?;
        let rel = format!("loops/{name}-video-textures.gif");
        // `video_texture` crossfades the frames after `j` (as far as the window goes, like
        // a numpy slice): the body ends K frames before that.
        let end = (j + K).min(n) - K;
        let (q, f) = write_peer(ctx, &rel, path, window.start, i..end, vq, size, fps)?;
        ctx.item(
            &rel,
            &format!(
                "{name}.mp4, Video Textures: its best loop {}..{} with a {K}-frame crossfade; \
                 seam {:.2}, ghost {:.2}",
                window.start + i,
                window.start + end,
                q.seam,
                q.ghost
            ),
            "the peer of `ignis bench loops` (video_texture of shared/tools/loop_metrics.py), rendered at the same size",
        );
        rows.push(f);
    }
    let rel = format!("loops/{name}-wrap.png");
    ignis_media::write_png(&ctx.path(&rel)?, &seam_picture(&rows)?)
        .with_context(|| format!("writing {rel}"))?;
    ctx.item(
        &rel,
        &format!(
            "{name}.mp4 around each loop's wrap (the orange bar): its last {AROUND} and first \
             {AROUND} frames; rows: Ignis, the crossfade, Video Textures. A jump shows as a \
             change across the bar, a crossfade's ghost as a doubled flame"
        ),
        "the frames of the three GIFs above",
    );

    // What `ignis loop` writes by default: an engine flipbook, the flame keyed out.
    let rel = format!("loops/{name}-flipbook.png");
    let out = OutputArgs {
        fps: Some(c.fps),
        ..OutputArgs::for_path(ctx.path(&rel)?)
    };
    let d = loop_cmd::make_loop_sized(&src, &ask, Some(size), &out, &quiet)?;
    ctx.item(
        &rel,
        &format!(
            "{name}.mp4, the default output: a flipbook (+ JSON) with the flame keyed out by its \
             pre-processing matte (straight alpha); seam {:.2}, ghost {:.2}",
            d.measured.seam, d.measured.ghost
        ),
        &user("", &format!("{name}-flipbook.png")),
    );

    // The same keyed loop as a video with alpha, played over a checkerboard (browsers
    // show WebM's alpha): what compositing with the matte looks like. Made from the
    // flipbook's frames rather than a second search: the same loop, as `-o x.webm` writes.
    if ignis_media::ffmpeg_available() {
        let book = ignis_media::read_flipbook(&ctx.path(&rel)?.with_extension("json"))?;
        let rel = format!("loops/{name}-keyed.webm");
        let out = OutputArgs {
            fps: Some(c.fps),
            ..OutputArgs::for_path(ctx.path(&rel)?)
        };
        let mut w = out.create(size)?;
        for f in &book.frames {
            out.push(&mut w, f)?;
        }
        let q = w
            .loop_quality()
            .context("the loop has fewer than two frames")?;
        out.finish(w, &quiet)?;
        ctx.item(
            &rel,
            &format!(
                "{name}.mp4, the keyed loop as VP8 WebM with alpha, over a checkerboard: the \
                 flame as it composites; seam {:.2}, ghost {:.2} (-o loop.mov writes ProRes 4444 \
                 with the same alpha for compositing tools)",
                q.seam, q.ghost
            ),
            &user("", &format!("{name}.webm")),
        );
    }
    Ok(())
}

/// Writes a peer's loop `body` (window indices) closed by a `K`-frame crossfade of the
/// frames after it, opaque, at `size`, to the GIF `rel`; its quality as written and its
/// frames. `metric_quality` is the peer's figure on the footage's metric frames (what
/// `ignis bench loops` reports; kept in the plan, not shown).
#[allow(clippy::too_many_arguments)]
fn write_peer(
    ctx: &Demo,
    rel: &str,
    path: &Path,
    first: usize,
    body: Range<usize>,
    metric_quality: LoopQuality,
    size: Size,
    fps: f64,
) -> Result<(LoopQuality, Vec<RgbaFrame>)> {
    let e = Evaluated {
        candidate: Candidate {
            start: body.start,
            end: body.end,
            cost: 0.0,
        },
        closing: Closing::Crossfade(K),
        skips: Skips::default(),
        quality: metric_quality,
        transition_step: 0.0,
        score: loops::score(&metric_quality),
    };
    let out = OutputArgs {
        fps: Some(fps),
        ..OutputArgs::for_path(ctx.path(rel)?)
    };
    let mut opts = out.write_options();
    opts.fps = fps;
    opts.loop_ = true;
    let mut w = out.create_with(size, &opts)?;
    let mut frames = Vec::new();
    loop_cmd::render_peer(
        loop_cmd::Clip::whole(path),
        first,
        &e,
        Some(size),
        &mut |f| {
            frames.push(f.clone());
            out.push(&mut w, f)
        },
    )?;
    let q = w
        .loop_quality()
        .context("the peer's loop has fewer than two frames")?;
    out.finish(w, &Global { quiet: true })?;
    Ok((q, frames))
}

/// The frames of a chosen loop, opaque, at `size`.
fn frames_of(path: &Path, first: usize, e: &Evaluated, size: Size) -> Result<Vec<RgbaFrame>> {
    let mut frames = Vec::new();
    loop_cmd::render(
        loop_cmd::Clip::whole(path),
        first,
        e,
        Some(size),
        None,
        None,
        &mut |f| {
            frames.push(f.clone());
            Ok(())
        },
    )?;
    Ok(frames)
}

/// One row per loop: its last [`AROUND`] frames, an orange bar (the wrap), its first
/// [`AROUND`]; frames 4 px apart on dark grey.
fn seam_picture(rows: &[Vec<RgbaFrame>]) -> Result<RgbaFrame> {
    const GAP: u32 = 4;
    let cell = rows
        .first()
        .and_then(|r| r.first())
        .context("no loop to show")?
        .size();
    let cols = 2 * AROUND as u32;
    let width = cols * cell.width + (cols + 1) * GAP + GAP;
    let height = rows.len() as u32 * (cell.height + GAP) + GAP;
    let mut out = RgbaFrame::filled(Size::new(width, height)?, [0.02, 0.02, 0.02, 1.0]);
    for (r, frames) in rows.iter().enumerate() {
        let n = frames.len();
        let y0 = GAP + r as u32 * (cell.height + GAP);
        for (col, i) in (n.saturating_sub(AROUND)..n)
            .chain(0..AROUND.min(n))
            .enumerate()
        {
            let f = &frames[i];
            let col = col as u32;
            // the bar sits between the last frame and the first
            let x0 = GAP + col * (cell.width + GAP) + if col >= AROUND as u32 { GAP } else { 0 };
            for y in 0..cell.height.min(f.height()) {
                for x in 0..cell.width.min(f.width()) {
                    out.data_mut()[((y0 + y) * width + x0 + x) as usize] = f.get(x, y);
                }
            }
        }
        // the wrap: an orange bar centred in the double gap between the two halves
        let bx = GAP + AROUND as u32 * (cell.width + GAP);
        for y in y0.saturating_sub(GAP / 2)..(y0 + cell.height + GAP / 2).min(height) {
            for x in bx - GAP / 2..bx + GAP / 2 {
                out.data_mut()[(y * width + x) as usize] = [1.0, 0.35, 0.02, 1.0];
            }
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shown_sizes_keep_the_aspect_and_never_enlarge() {
        let s = |w, h| Size::new(w, h).unwrap();
        assert_eq!(shown_size(s(960, 540), 320).unwrap(), s(320, 180));
        assert_eq!(shown_size(s(540, 960), 320).unwrap(), s(180, 320));
        assert_eq!(shown_size(s(480, 480), 320).unwrap(), s(320, 320));
        assert_eq!(shown_size(s(200, 100), 320).unwrap(), s(200, 100));
        assert_eq!(shown_size(s(10_000, 3), 320).unwrap(), s(320, 1));
    }

    #[test]
    fn the_seam_picture_puts_the_wrap_between_the_last_and_first_frames() {
        let size = Size::new(2, 1).unwrap();
        // frame i is grey level i / 10
        let frames: Vec<RgbaFrame> = (0..8)
            .map(|i| {
                let v = i as f32 / 10.0;
                RgbaFrame::filled(size, [v, v, v, 1.0])
            })
            .collect();
        let p = seam_picture(&[frames.clone(), frames]).unwrap();
        // 6 cells of 2 px, 7 gaps + the bar's extra gap of 4 px
        assert_eq!(p.width(), 6 * 2 + 8 * 4);
        assert_eq!(p.height(), 2 * (1 + 4) + 4);
        let at = |col: u32, row: u32| {
            let x = 4 + col * 6 + if col >= 3 { 4 } else { 0 };
            p.get(x, 4 + row * 5)[0]
        };
        for row in 0..2 {
            let shown: Vec<f32> = (0..6).map(|c| at(c, row)).collect();
            assert_eq!(shown, [0.5, 0.6, 0.7, 0.0, 0.1, 0.2]);
        }
        // the bar is orange, between cells 2 and 3
        let bar_x = 4 + 3 * 6 + 1;
        assert_eq!(p.get(bar_x, 4), [1.0, 0.35, 0.02, 1.0]);
    }
}
