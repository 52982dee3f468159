//! `ignis bench TARGET`: the headline performance figures of a method as one JSON object.
//!
//! Each target is implemented here, one file per target, over the libraries' public API:
//! `classic`, `eigen_train` (PCA), `learned`, `volume`, `flow`, `export`, `loops`, `realism`;
//! `eigen-animate` uses `ignis_eigen::bench` (shared with that crate's criterion bench) and
//! `crate::eigen::animate::bench_footage`. Measured figures are recorded in each crate's
//! `benches/README.md`, not in the code.

mod classic;
mod eigen_train;
pub mod export;
mod flow;
mod learned;
pub mod loops;
mod realism;
mod timing;
mod volume;

use crate::global::Global;
use anyhow::Result;
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
#[command(
    after_help = "Examples:\n  ignis bench classic\n  ignis bench classic --quick\n  ignis bench eigen-train\n  ignis bench eigen-animate --keep-db /tmp/bench.db\n  ignis bench eigen-footage   (only eigen-animate's footage case: a 1080p loop read from the source video)\n  ignis bench learned\n  ignis bench volume\n  ignis bench flow --quick\n  ignis bench export         # motion-vector blend vs cross-fade, flow timings\n  ignis bench loops\n  ignis bench loops fire1.mp4 fire2.mov --cache /tmp/ignis-cache\n  ignis bench realism        # flicker vs 1.5/√D and spectral slope vs the footage, every generator"
)]
pub struct BenchArgs {
    /// What to measure (`flow`: dense optical flow and the motion-compensated morph,
    /// against the issues' speed goals, plus mid-frame prediction on ../shared/data;
    /// `export`: flipbook motion-vector blending vs a cross-fade, and flipbook timing;
    /// `loops`: Ignis's loops against the crossfade and Video Textures peers;
    /// `realism`: flicker frequency and spectral slope of every generator against the
    /// puffing law and ../shared/data footage).
    #[arg(value_parser = ["classic", "eigen-train", "eigen-animate", "eigen-footage", "learned", "volume", "flow", "export", "loops", "realism"])]
    pub target: String,
    /// loops: the clips: videos, directories of frames or patterns like frames/%04d.png
    /// (default ../shared/data/{candle,campfire,fireball}.mp4, reported as skipped when
    /// missing; a clip named here must be readable).
    pub clips: Vec<PathBuf>,
    /// loops: the cache of clip databases (default as `ignis loop`).
    #[arg(long, value_name = "DIR")]
    pub cache: Option<PathBuf>,
    /// Fewer repetitions (a smoke test; figures are noisier).
    #[arg(long)]
    pub quick: bool,
    /// eigen-animate / eigen-footage: keep the trained benchmark database (and for
    /// eigen-footage its clip) in this directory and reuse it on later runs (training
    /// 2,197 frames takes about half a minute).
    #[arg(long, value_name = "DIR")]
    pub keep_db: Option<PathBuf>,
    // loops: the rate of clips that are image sequences
    #[command(flatten)]
    pub sequence: crate::args::SequenceFps,
}

/// Runs one benchmark target and prints its JSON object.
pub fn run(a: &BenchArgs, g: &Global) -> Result<()> {
    if a.sequence.sequence_fps.is_some() && a.target != "loops" {
        anyhow::bail!(
            "--sequence-fps sets the rate of `ignis bench loops`' image-sequence clips; `bench {}` reads none",
            a.target
        );
    }
    let v = match a.target.as_str() {
        "classic" => classic::figures(a.quick)?,
        "eigen-train" => eigen_train::figures(a.quick),
        "eigen-animate" => {
            let sp = g.spinner("training the benchmark database, then timing");
            let mut v = ignis_eigen::bench::animate_figures(a.quick, a.keep_db.as_deref())?;
            sp.finish_and_clear();
            let sp = g.spinner("footage case: writing, training and rendering a clip");
            let f = crate::eigen::animate::bench_footage(a.quick, None)?;
            sp.finish_and_clear();
            v["footage"] = f;
            v
        }
        "eigen-footage" => {
            let sp = g.spinner("writing, training and rendering a clip");
            let f = crate::eigen::animate::bench_footage(a.quick, a.keep_db.as_deref())?;
            sp.finish_and_clear();
            serde_json::json!({"bench": "eigen-footage", "quick": a.quick, "footage": f})
        }
        "volume" => volume::figures(g, a.quick)?,
        "learned" => learned::figures(a.quick)?,
        "export" => crate::bench::export::figures(g, a.quick)?,
        "realism" => realism::bench(g, a.quick)?,
        "flow" => {
            let sp = g.spinner("timing flow and morphs");
            let v = flow::figures(a.quick)?;
            sp.finish_and_clear();
            v
        }
        "loops" => {
            let (clips, defaults) = if a.clips.is_empty() {
                (crate::bench::loops::default_clips(), true)
            } else {
                (a.clips.clone(), false)
            };
            a.sequence
                .apply(&clips.iter().map(PathBuf::as_path).collect::<Vec<_>>())?;
            crate::bench::loops::bench(&clips, defaults, a.cache.as_deref(), g)?
        }
        other => anyhow::bail!("unknown bench target `{other}`"),
    };
    outln!("{}", serde_json::to_string_pretty(&v)?)?;
    Ok(())
}
