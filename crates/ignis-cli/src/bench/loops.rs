//! `ignis bench loops [CLIPS…]` (issue 15): Ignis's loop against the two peers of
//! `shared/tools/loop_metrics.py`, on the same metric frames, measured with
//! `ignis_core::loopq`.
//!
//! - **xfade** (Unity VFX Toolbox "Loop Sequence", Houdini "Make Loop", ffmpeg xfade
//!   scripts): a range of the requested length L plus K = 10 frames taken from the middle
//!   of the clip (`a = (n - L - K) / 2`), its last K frames crossfaded into its first K:
//!   L frames, exactly `xfade` of loop_metrics.py.
//! - **vt** (Video Textures, Schödl 2000): the loop `i..j` anywhere in the clip with
//!   `int(0.8 L) ≤ j - i < int(1.2 L)` of least filtered L2 cost on the grey 128-px frames
//!   (weights 1, 3, 3, 1 over offsets −2..=1), then the same crossfade: `video_texture` of
//!   loop_metrics.py.
//! - **ignis**: `ignis loop CLIP --length L` (cached database, search, closing chosen by
//!   seam and ghost, rendered at the source resolution and written as a flipbook to a
//!   temporary directory), measured by the writer on the frames written.
//!
//! The peers use the cache's metric frames of every clip frame (what the writer measures:
//! sRGB luma area-averaged to 128 px wide; loop_metrics.py uses ffmpeg's scale filter).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use ignis_core::loopq::{self, LoopQuality};
use ignis_core::{GrayFrame, Rng};
use ignis_eigen::loops::{self, SearchParams};
use serde_json::{json, Value};

use crate::eigen::loop_cmd::{self, Method};
use crate::global::Global;

/// Crossfade frames of the peers.
pub const K: usize = 10;

/// loop_metrics.py `xfade(src, a, b, k)`: `src[a..b]` with its last k frames crossfaded into
/// its first k (`b - a - k` frames; `b` clamped to the clip like a numpy slice).
pub fn xfade(src: &[GrayFrame], a: usize, b: usize, k: usize) -> Vec<GrayFrame> {
    let r = &src[a..b.min(src.len())];
    let n = r.len().saturating_sub(k);
    let mut out: Vec<GrayFrame> = r[..n].to_vec();
    for t in 0..k.min(n) {
        let w = (t + 1) as f32 / (k + 1) as f32;
        out[t] = loops::blend(&r[n + t], &r[t], w);
    }
    out
}

/// loop_metrics.py `video_texture(src, length, k)`: the frames and the loop `(i, j)`.
pub fn video_texture(
    src: &[GrayFrame],
    length: usize,
    k: usize,
) -> Option<(Vec<GrayFrame>, usize, usize)> {
    let n = src.len();
    let lo = (length as f64 * 0.8) as usize;
    let hi = (length as f64 * 1.2) as usize;
    // Distances along the diagonals the cost needs: d(a, a + δ) for δ in lo..hi.
    let diag: Vec<Vec<f64>> = (lo..hi.max(lo))
        .map(|delta| {
            (0..n.saturating_sub(delta))
                .map(|a| loopq::rms_diff(&src[a], &src[a + delta]))
                .collect()
        })
        .collect();
    let mut best: Option<(f64, usize, usize)> = None;
    for i in 2..n.saturating_sub(2) {
        for j in i + lo..(i + hi).min(n - 2) {
            let row = &diag[j - i - lo];
            // d[j + o, i + o] = d(i + o, i + o + δ) for o in -2..=1.
            let c = (0..4)
                .map(|t| loops::FILTER[t] * row[i + t - 2])
                .sum::<f64>()
                / 8.0;
            if best.is_none_or(|b| c < b.0) {
                best = Some((c, i, j));
            }
        }
    }
    let (_, i, j) = best?;
    Some((xfade(src, i, j + k, k), i, j))
}

fn q_json(q: &LoopQuality) -> Value {
    json!({"seam": q.seam, "seam_at": q.seam_at, "ghost": q.ghost, "ghost_at": q.ghost_at})
}

/// Loop search time over `n` frames of k = 40 pseudo-random weights (seeded).
fn search_timing(n: usize) -> Result<Value> {
    let k = 40;
    let mut rng = Rng::new(15);
    let x: Vec<f32> = (0..n * k).map(|_| rng.normal() as f32).collect();
    let t = Instant::now();
    let c = loops::search(
        &x,
        n,
        k,
        &SearchParams::new(120, k),
        Some(loops::BodyStats {
            steps: &vec![1.0; n - 1],
            softness: &vec![1.0; n],
        }),
    )?;
    let s = t.elapsed().as_secs_f64();
    Ok(
        json!({"frames": n, "eigenfires": k, "length": 120, "candidates": c.len(), "seconds": s, "goal_seconds": 1.0}),
    )
}

/// `ignis loop`'s default output, the flame keyed out by its matte, beside the peers
/// computed on the window's metric frames matted as the loop search sees them
/// ([`loop_cmd::FootageMatte::matted_metric`]); not the goal (the peers of
/// `shared/tools/loop_metrics.py` see the opaque footage), a check that the matte does not
/// cost the loop its quality.
fn matte_row(
    clip: &Path,
    first: usize,
    c: &loop_cmd::Cached,
    ask: &loop_cmd::LoopAsk,
    out: &crate::output::OutputArgs,
    a: usize,
    length: usize,
) -> Result<Value> {
    let src = loop_cmd::LoopFootage::cached(clip, first, c);
    let mm = src
        .matte
        .as_ref()
        .context("a cached clip has its matte")?
        .matted_metric(&c.metric, None)?;
    let xf = loopq::loop_quality(&xfade(&mm, a, a + length + K, K))?;
    let vt = video_texture(&mm, length, K)
        .map(|(f, _, _)| loopq::loop_quality(&f))
        .transpose()?;
    let quiet = Global { quiet: true };
    let d = match loop_cmd::make_loop(&src, ask, out, &quiet) {
        Ok(d) => d,
        Err(e) => return Ok(json!({"error": format!("{e:#}")})),
    };
    // A peer whose frames are all keyed out (a fireball clip's dark stretch) has no
    // steps to compare: reported, left out of the comparison.
    let live = |q: &LoopQuality| q.median_step > 0.0;
    let empty = json!("every frame keyed out (no steps): not compared");
    let show = |q: &LoopQuality| if live(q) { q_json(q) } else { empty.clone() };
    let best_peer_ghost = [Some(xf), vt]
        .into_iter()
        .flatten()
        .filter(live)
        .map(|q| q.ghost)
        .reduce(f64::max);
    Ok(json!({
        "closing": d.chosen.best.closing,
        "quality": q_json(&d.measured),
        "xfade": show(&xf),
        "vt": vt.map(|q| show(&q)),
        "seam_le_xfade": live(&xf).then_some(d.measured.seam <= xf.seam),
        "ghost_ge_best_peer": best_peer_ghost.map(|g| d.measured.ghost >= g),
        "render_and_write_s": d.render_s,
    }))
}

/// The default clips.
pub fn default_clips() -> Vec<PathBuf> {
    ["candle", "campfire", "fireball"]
        .iter()
        .map(|c| PathBuf::from(format!("../shared/data/{c}.mp4")))
        .collect()
}

/// Runs the benchmark; one JSON object. `skip_unreadable`: a clip that is not there, or
/// that needs the ffmpeg this machine lacks, is reported as skipped (the default clips of
/// `../shared/data`); otherwise it is an error (clips the user named).
pub fn bench(
    clips: &[PathBuf],
    skip_unreadable: bool,
    cache: Option<&Path>,
    g: &Global,
) -> Result<Value> {
    let cache_dir = match cache {
        Some(d) => d.to_path_buf(),
        None => loop_cmd::default_cache_dir()?,
    };
    // the loops written (removed on return, an error's too)
    let tmp_dir = tempfile::Builder::new()
        .prefix("ignis-bench-loops-")
        .tempdir()
        .context("creating a temporary directory for the loops")?;
    let tmp = tmp_dir.path();
    let mut results = Vec::new();
    for clip in clips {
        // A clip named on the command line (a file, a directory of frames or a pattern like
        // frames/%04d.png, which is no file itself) must be readable; a default one is
        // skipped when it is not there or needs the ffmpeg this machine lacks.
        if skip_unreadable && !clip.exists() {
            results.push(
                json!({"clip": clip, "skipped": format!("skipped: {} not found", clip.display())}),
            );
            continue;
        }
        let info = match ignis_media::probe(clip) {
            Ok(info) => info,
            Err(_) if skip_unreadable && !ignis_media::ffmpeg_available() => {
                results.push(json!({"clip": clip, "skipped": "skipped: ffmpeg not found"}));
                continue;
            }
            Err(e) => {
                return Err(e).with_context(|| format!("bench loops: reading {}", clip.display()))
            }
        };
        let (window, _) = loop_cmd::resolve_window(clip, None)?;
        let t = Instant::now();
        let c = loop_cmd::cached(
            loop_cmd::Clip::whole(clip),
            window.clone(),
            "32x48".parse()?,
            40,
            &cache_dir,
            g,
        )?;
        let cache_s = t.elapsed().as_secs_f64();
        for secs in [2.0f64, 4.0] {
            let length = (secs * c.fps).round() as usize;
            let n = c.metric.len();
            let mut entry = json!({
                "clip": clip, "source_size": info.size.to_string(), "fps": c.fps,
                "length_s": secs, "length": length, "clip_frames": n,
                "cache": if c.built { "built" } else { "reused" }, "cache_s": cache_s,
            });
            if n < length + K + 3 {
                entry["skipped"] = json!(format!(
                    "skipped: {n} frames is too short for a {secs}-s loop"
                ));
                results.push(entry);
                continue;
            }
            let a = (n - length - K) / 2;
            let xf = loopq::loop_quality(&xfade(&c.metric, a, a + length + K, K))?;
            entry["xfade"] = json!({"range": format!("{}..{}", a, a + length + K), "k": K, "quality": q_json(&xf)});
            let t = Instant::now();
            let vt = video_texture(&c.metric, length, K);
            let vt_s = t.elapsed().as_secs_f64();
            let vtq = match &vt {
                Some((f, i, j)) => {
                    let q = loopq::loop_quality(f)?;
                    entry["vt"] = json!({"loop": format!("{i}..{j}"), "k": K, "quality": q_json(&q), "seconds": vt_s});
                    Some(q)
                }
                None => None,
            };
            // A flipbook when the sheet fits the writer's limit, else a PNG sequence.
            let stem = clip
                .file_stem()
                .unwrap_or_default()
                .to_string_lossy()
                .to_string();
            let cells = (length as f64 * 1.2).ceil() as u64 * info.size.pixels() as u64;
            let flipbook = cells <= 1 << 26;
            let out_for = |tag: &str| crate::output::OutputArgs {
                fps: Some(c.fps),
                ..crate::output::OutputArgs::for_path(if flipbook {
                    tmp.join(format!("{stem}-{secs}s{tag}.png"))
                } else {
                    tmp.join(format!("{stem}-{secs}s{tag}/%04d.png"))
                })
            };
            let out = out_for("");
            let quiet = Global { quiet: true };
            let t = Instant::now();
            let ask = loop_cmd::LoopAsk {
                length,
                method: Method::Auto,
                top: 3,
                every: 1,
            };
            // Opaque, as the peers see the footage (the default matte keys the flame out,
            // which the peers' frames do not).
            let src = loop_cmd::LoopFootage::cached(clip, window.start, &c).opaque();
            let d = match loop_cmd::make_loop(&src, &ask, &out, &quiet) {
                Ok(d) => d,
                Err(e) => {
                    entry["ignis"] = json!({"error": format!("{e:#}")});
                    results.push(entry);
                    continue;
                }
            };
            let total_s = t.elapsed().as_secs_f64();
            let b = &d.chosen.best;
            let best_peer_ghost = vtq.map_or(xf.ghost, |q| q.ghost.max(xf.ghost));
            entry["ignis"] = json!({
                "loop": format!("{}..{}", window.start + b.candidate.start, window.start + b.candidate.end),
                "closing": b.closing,
                "predicted": q_json(&d.chosen.predicted_of(b).quality),
                "expected": q_json(&b.quality),
                "closings_rendered": d.chosen.rendered,
                "quality": q_json(&d.measured),
                "frames": d.frames, "size": d.size.to_string(),
                "written_as": if flipbook { "flipbook" } else { "png sequence (a flipbook would exceed the writer's 2^26-pixel sheet)" },
                "why": d.chosen.why,
                "seconds": {"search": d.chosen.search_s, "closings": d.chosen.evaluate_s,
                            "closings_rendered": d.chosen.verify_s,
                            "render_and_write": d.render_s, "total": total_s},
            });
            entry["goal"] = json!({
                "seam_le_xfade": d.measured.seam <= xf.seam,
                "ghost_ge_best_peer": d.measured.ghost >= best_peer_ghost,
            });
            entry["ignis_matte"] =
                matte_row(clip, window.start, &c, &ask, &out_for("-matte"), a, length)?;
            results.push(entry);
        }
    }
    Ok(json!({
        "target": "loops",
        "peers": "xfade (middle range, K=10) and vt (Video Textures + K=10 crossfade) as shared/tools/loop_metrics.py",
        "search_2000": search_timing(2000)?,
        "clips": results,
    }))
}
