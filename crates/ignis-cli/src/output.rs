//! Output options shared by every generating command, and the palette argument.

use anyhow::{Context, Result};
use ignis_core::{Palette, Size};
use ignis_media::{
    AlphaMode, Engine, FlipbookOptions, Format, FrameWriter, MotionSource, WriteOptions,
};
use std::path::PathBuf;

/// The frame rate of generated fire when `--fps` is not given.
pub const DEFAULT_FPS: f64 = 30.0;

/// Where and how to write frames. The format follows the output path unless `--format`
/// says otherwise.
///
/// Flipbook examples (any generating command):
///   --engine unity --motion-vectors -o fire.png      Unity VFX Graph motion blend
///   --engine unreal --max-size 4096 --pot -o fire.png
///   --engine godot --emission --hdr -o fire.png          + fire.heat.png, fire.exr
///   --fit-frames --columns 8 -o fire.png             retime to fill every cell
#[derive(clap::Args, Debug, Clone)]
pub struct OutputArgs {
    /// Output: `x.mp4`, `x.gif`, `x.png` (flipbook + `x.json`), `x.mov` (ProRes 4444 with
    /// alpha) or `x.webm` (VP8 with alpha) through the system ffmpeg, a directory `dir/` or
    /// a pattern `dir/%04d.png` / `dir/%04d.exr` (sequence; also `dir/shot.####.exr`).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Force the format: mp4, gif, flipbook, png-seq, exr-seq, mov, webm.
    #[arg(long, value_parser = ["mp4", "gif", "flipbook", "png-seq", "exr-seq", "mov", "webm"])]
    pub format: Option<String>,
    /// Frames per second stored in the output (default 30; `ignis convert`, `eigen
    /// animate` and `eigen loop`: the rate of the footage the frames come from).
    #[arg(long)]
    pub fps: Option<f64>,
    /// Flipbook: columns (default near-square).
    #[arg(long)]
    pub columns: Option<u32>,
    /// Flipbook: rows (default from columns).
    #[arg(long)]
    pub rows: Option<u32>,
    /// Flipbook: edge-bleed padding around each cell, in pixels.
    #[arg(long, default_value_t = 0)]
    pub padding: u32,
    /// Flipbook: write premultiplied instead of straight alpha (the godot preset always
    /// writes premultiplied).
    #[arg(long)]
    pub premultiplied: bool,
    /// Flipbook: engine preset (UV origin, motion-vector green direction, alpha, ≥ 2 px
    /// extruded padding, and the engine's own settings in the JSON's `engine_settings`),
    /// e.g. `--engine unity`. See README "Engine-ready flipbooks".
    #[arg(long, default_value = "generic", value_parser = ["unity", "unreal", "godot", "sidefx", "generic"])]
    pub engine: String,
    /// Flipbook: also write `x.mv.png`, a 16-bit motion-vector sheet (RG, 0.5 = still) from
    /// dense optical flow between consecutive frames, for engines' motion-vector frame
    /// blending; the JSON's `motion_vectors.scale` is the material's strength. `volume
    /// render` and `learned synth` also render each in-between frame and keep, per pixel,
    /// the vector whose blend comes closest to it (about twice the render time), as `loop
    /// --every 2` does with the footage frames it leaves out.
    #[arg(long)]
    pub motion_vectors: bool,
    /// Flipbook: also write `x.heat.png`, an emission/temperature sheet (16-bit linear
    /// grey: the luminance of the premultiplied colour) for colour ramps in the engine.
    #[arg(long)]
    pub emission: bool,
    /// Flipbook: also write `x.exr`, the colour sheet in linear f32 (HDR, premultiplied).
    #[arg(long)]
    pub hdr: bool,
    /// Flipbook: largest sheet side in pixels (default 16384, the largest texture desktop
    /// GPUs and the engines' importers take; a sheet also holds at most 64 Mi pixels), e.g.
    /// 8192, or 4096 for mobile GPUs. The grid is chosen to fit; `ignis loop` scales its cells down
    /// (aspect kept, JSON `scaled_from`) when full-size cells do not fit and no --size is
    /// given; otherwise the command fails before writing anything.
    #[arg(long, value_name = "PIXELS")]
    pub max_size: Option<u32>,
    /// Flipbook: power-of-two sheet sides (power-of-two grids; extra pixels become padding).
    #[arg(long)]
    pub pot: bool,
    /// Flipbook: resample the animation in time so it fills every cell of the grid (fps
    /// raised to keep the duration; reported in the JSON's `retimed`).
    #[arg(long)]
    pub fit_frames: bool,
    /// Flipbook: crop every cell to the box the animation ever shows (every pixel any frame
    /// shows, and one transparent pixel around them), so no texture is spent on empty space
    /// around the fire; the JSON's `trimmed` says where that box lies in the rendered frame
    /// (offset the sprite's quad by it to keep its pivot). Example: `ignis volume render
    /// --preset campfire --size 512x512 --frames 64 --trim -o camp.png`
    #[arg(long)]
    pub trim: bool,
    /// Flipbook: N statistically different loops of the effect as the N rows of one sheet
    /// (Unity's Single Row mode, a row picked at random per particle): `ignis volume render`,
    /// `ignis classic` and `ignis learned synth` render `--frames` frames per row, each a
    /// seamless loop with seed `--seed + row`;
    /// motion vectors wrap within each row. Commands that render one animation refuse N > 1.
    /// Example: `ignis volume render --preset torch --frames 32 --variants 4 -o torch.png`.
    #[arg(long, default_value_t = 1, value_name = "N")]
    pub variants: u32,
    /// Do not mark GIFs and flipbooks as looping.
    #[arg(long)]
    pub no_loop: bool,
}

impl OutputArgs {
    /// The options a user gets who only gives `-o path` (every other flag at its default),
    /// for commands that write outputs of their own (benches, tests).
    pub fn for_path(output: PathBuf) -> OutputArgs {
        let mut argv = vec![std::ffi::OsString::from("ignis"), "-o".into()];
        argv.push(output.into_os_string());
        <OutputArgs as clap::FromArgMatches>::from_arg_matches(
            &<OutputArgs as clap::Args>::augment_args(clap::Command::new("ignis"))
                .get_matches_from(argv),
        )
        .expect("the defaults of OutputArgs parse")
    }

    /// `--fps`, or the default rate of generated fire, 30.
    pub fn fps(&self) -> f64 {
        self.fps.unwrap_or(DEFAULT_FPS)
    }

    /// The format `--format` forces, if given.
    fn forced_format(&self) -> Option<Format> {
        self.format.as_deref().map(|f| match f {
            "mp4" => Format::Mp4,
            "gif" => Format::Gif,
            "flipbook" => Format::Flipbook,
            "png-seq" => Format::PngSequence,
            "mov" => Format::Mov,
            "webm" => Format::Webm,
            _ => Format::ExrSequence,
        })
    }

    /// The format written: `--format`'s, or the one `-o`'s path implies (`None` when it
    /// implies none; writing then fails with the reason).
    pub fn output_format(&self) -> Option<Format> {
        self.forced_format()
            .or_else(|| Format::from_path(&self.output).ok())
    }

    pub fn write_options(&self) -> WriteOptions {
        WriteOptions {
            format: self.forced_format(),
            fps: self.fps(),
            loop_: !self.no_loop,
            flipbook: FlipbookOptions {
                columns: self.columns,
                rows: self.rows,
                padding: self.padding,
                alpha: if self.premultiplied {
                    AlphaMode::Premultiplied
                } else {
                    self.engine().conventions().alpha
                },
                engine: self.engine(),
                max_size: self.max_size,
                pot: self.pot,
                fit_frames: self.fit_frames,
                // A command that renders N loops sets this ([`OutputArgs::variants`]);
                // `create_with` refuses --variants for the others.
                variants: if self.variants == 0 { 0 } else { 1 },
                motion: self.motion_vectors.then(flow_source),
                heat: self.emission,
                hdr: self.hdr,
                scaled_from: None,
                trim: self.trim,
            },
            background: [0.0; 3],
            first_frame: 0,
        }
    }

    /// `--variants`: the number of loops a command that renders variants must make (set
    /// it as the write options' `flipbook.variants`).
    pub fn variants(&self) -> u32 {
        self.variants
    }

    /// The engine preset named by `--engine`.
    pub fn engine(&self) -> Engine {
        Engine::from_name(&self.engine).unwrap_or_default()
    }

    /// Opens the writer (atomic: nothing appears under the final name until `finish`).
    pub fn create(&self, size: Size) -> Result<FrameWriter> {
        self.create_with(size, &self.write_options())
    }

    /// The writer of a generator's render with `--variants N` (N whole loops with seeds
    /// seed, seed + 1, …, laid as the rows of one flipbook; N = 1 is one animation): sets
    /// `opts.flipbook.variants` and refuses variants of anything but one whole loop
    /// (`--no-loop`, `--chunk`) or of formats that are not flipbooks, before anything is
    /// written. Returns the writer and N.
    pub fn create_variants(
        &self,
        size: Size,
        frames: usize,
        opts: &mut WriteOptions,
        whole_loop: bool,
    ) -> Result<(FrameWriter, u32)> {
        let variants = self.variants();
        opts.flipbook.variants = variants;
        // Refuses --variants for other formats; nothing is written until `finish`.
        let writer = self.create_with(size, opts)?;
        anyhow::ensure!(
            variants <= 1 || whole_loop,
            "--variants {variants} lays {variants} whole loops as the rows of a flipbook; \
             drop --no-loop and --chunk"
        );
        // A flipbook's grid is laid out when it is finished: a frame count or a grid that
        // cannot be laid out is refused now, before the frames are rendered.
        if opts
            .format
            .map_or_else(|| Format::from_path(&self.output).ok(), Some)
            == Some(Format::Flipbook)
        {
            let n = frames.saturating_mul(variants.max(1) as usize);
            let n32 = u32::try_from(n).unwrap_or(u32::MAX);
            ignis_media::write::plan_layout(n32, size, &opts.flipbook).map_err(|e| {
                anyhow::anyhow!(
                    "{n} frames of {size} in the flipbook {}: {e}",
                    self.output.display()
                )
            })?;
        }
        Ok((writer, variants))
    }

    /// [`OutputArgs::create`] with options the command adjusted (loop marking, a chunk's
    /// first frame number, the footage's fps); flipbook-only flags are still refused for
    /// other formats.
    pub fn create_with(&self, size: Size, opts: &WriteOptions) -> Result<FrameWriter> {
        self.check_with(opts)?;
        ignis_media::create(&self.output, size, opts)
            .with_context(|| format!("creating {}", self.output.display()))
    }

    /// Everything [`OutputArgs::create_with`] would refuse, checked without writing: the
    /// flags against the format, and the path ([`ignis_media::check_output`]: format, frame
    /// rate, a directory that cannot be made or written). Commands that train or search
    /// before they render call it first, so a bad `-o` fails in a moment, not after minutes.
    pub fn check_with(&self, opts: &WriteOptions) -> Result<()> {
        let flipbook_only = self.motion_vectors
            || self.emission
            || self.hdr
            || self.max_size.is_some()
            || self.pot
            || self.fit_frames
            || self.variants != 1
            || self.trim
            || self.engine() != Engine::Generic;
        let format = match opts.format {
            Some(f) => f,
            None => Format::from_path(&self.output)?,
        };
        if self.variants > 1 && opts.flipbook.variants != self.variants {
            anyhow::bail!(
                "--variants {}: this command renders one animation, and splitting it into rows \
                 would not give {} different loops; use `ignis volume render`, `ignis classic` \
                 or `ignis learned synth` with --variants {}, or drop --variants",
                self.variants,
                self.variants,
                self.variants
            );
        }
        if flipbook_only && format != Format::Flipbook {
            anyhow::bail!(
                "--engine, --motion-vectors, --emission, --hdr, --max-size, --pot, --fit-frames, \
                 --trim and --variants apply to flipbooks; write to a .png file (e.g. -o fire.png)"
            );
        }
        ignis_media::check_output(&self.output, opts)
            .with_context(|| format!("creating {}", self.output.display()))?;
        Ok(())
    }
}

/// A flipbook's frame size, chosen before rendering by [`OutputArgs::fit_flipbook`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Fitted {
    /// The size to render the frames at.
    pub size: Size,
    /// Set when `size` is the source size scaled down to fit the sheet limit.
    pub scaled_from: Option<ignis_media::ScaledFrom>,
}

impl Fitted {
    /// The line a command prints when the cells were scaled (`None` otherwise).
    pub fn note(&self) -> Option<String> {
        let s = self.scaled_from?;
        Some(format!(
            "cells {}, scaled from {}x{} to fit the {}x{} sheet limit (at most {} Mi pixels); \
             choose the cell size with --size or the limit with --max-size, or write a frame \
             sequence (-o dir/%04d.png) for full resolution",
            self.size,
            s.width,
            s.height,
            s.max_size,
            s.max_size,
            s.max_pixels >> 20
        ))
    }
}

impl OutputArgs {
    /// For a command that renders `n` frames at a size of its choosing (`size`, the
    /// source's own unless `explicit`, the user's `--size`): the size to render at.
    ///
    /// A flipbook whose full-size cells do not fit the sheet limit (`--max-size`, default
    /// 16384 per side, and 64 Mi pixels) gets the largest cells with the same aspect that
    /// fit ([`ignis_media::fit_frame`]), recorded in `opts` so the JSON's `scaled_from`
    /// says so; an explicit size that does not fit is refused before anything is rendered,
    /// as is a limit too small for any useful cell. Other formats: `size` unchanged.
    pub fn fit_flipbook(
        &self,
        n: usize,
        size: Size,
        explicit: bool,
        opts: &mut WriteOptions,
    ) -> Result<Fitted> {
        let format = match opts.format {
            Some(f) => f,
            None => Format::from_path(&self.output)?,
        };
        if format != Format::Flipbook {
            return Ok(Fitted {
                size,
                scaled_from: None,
            });
        }
        let n = u32::try_from(n).unwrap_or(u32::MAX);
        let fb = &opts.flipbook;
        if explicit {
            ignis_media::write::plan_layout(n, size, fb).map_err(|e| {
                anyhow::anyhow!(
                    "--size {size}: {e}; a smaller --size, or no --size (the cells are then \
                     scaled to fit), or a frame sequence (-o dir/%04d.png)"
                )
            })?;
            return Ok(Fitted {
                size,
                scaled_from: None,
            });
        }
        let (fit, scaled_from) = ignis_media::fit_frame(n, size, fb)
            .with_context(|| format!("sizing the flipbook {}", self.output.display()))?;
        opts.flipbook.scaled_from = scaled_from;
        Ok(Fitted {
            size: fit,
            scaled_from,
        })
    }
}

impl OutputArgs {
    /// Pushes one frame, naming the output on failure.
    pub fn push(&self, writer: &mut FrameWriter, frame: &ignis_core::RgbaFrame) -> Result<()> {
        writer
            .push(frame)
            .with_context(|| format!("writing {}", self.output.display()))
    }

    /// Completes the output (renaming it into place) and lists what was written.
    pub fn finish(&self, writer: FrameWriter, g: &crate::global::Global) -> Result<Vec<PathBuf>> {
        let files = writer
            .finish()
            .with_context(|| format!("finishing {}", self.output.display()))?;
        for line in wrote_lines(&files) {
            g.say(line);
        }
        for f in &files {
            if f.extension().is_some_and(|e| e == "json") {
                if let Ok(m) = ignis_media::read_flipbook_meta(f) {
                    if let Some(r) = &m.retimed {
                        g.say(format!(
                            "retimed {} frames at {} fps to {} frames at {} fps to fill the {}×{} grid",
                            r.from_frames,
                            crate::args::fps_text(r.from_fps),
                            m.frame_count,
                            crate::args::fps_text(m.fps),
                            m.columns,
                            m.rows
                        ));
                    }
                }
            }
        }
        Ok(files)
    }
}

/// The `wrote …` lines for the files of one output: one per file, except a frame sequence
/// (more than three files of one kind in one directory), which gets one line with its count,
/// first and last file rather than a line per frame.
fn wrote_lines(files: &[PathBuf]) -> Vec<String> {
    let same =
        |f: &PathBuf| f.parent() == files[0].parent() && f.extension() == files[0].extension();
    if files.len() > 3 && files.iter().all(same) {
        return vec![format!(
            "wrote {} frames: {} … {}",
            files.len(),
            files[0].display(),
            files[files.len() - 1].display()
        )];
    }
    files
        .iter()
        .map(|f| format!("wrote {}", f.display()))
        .collect()
}

/// Motion vectors from the workspace's dense optical flow (DIS on the frames' luma), kept
/// where they are reliable ([`ignis_flow::motion_vector_pair`]: forward and backward flows
/// agree, and moving the pixels explains the change between the frames), so flicker,
/// occlusions and textureless areas get no motion and the engine's blend falls back to a
/// cross-fade there instead of dragging pixels along a wrong vector.
pub fn flow_source() -> MotionSource {
    MotionSource::pair(|a, b| {
        let (f, g) = ignis_flow::motion_vector_pair(a, b, &ignis_flow::VectorParams::default())
            .map_err(|e| e.to_string())?;
        Ok((f.into_vec(), g.into_vec()))
    })
}

/// `--palette`: a preset name or a gradient PNG.
#[derive(Clone, Debug)]
pub struct PaletteArg(pub String);

impl std::str::FromStr for PaletteArg {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s.to_lowercase().ends_with(".png") || ignis_core::palette::PRESETS.contains(&s) {
            Ok(PaletteArg(s.to_string()))
        } else {
            Err(format!(
                "unknown palette `{s}`; choose one of {} or give a gradient PNG (left = cold, right = hot)",
                ignis_core::palette::PRESETS.join(", ")
            ))
        }
    }
}

impl PaletteArg {
    /// The palette: a preset, or the middle row of a gradient PNG.
    pub fn load(&self) -> Result<Palette> {
        if self.0.to_lowercase().ends_with(".png") {
            let path = PathBuf::from(&self.0);
            let img = ignis_media::read_image(&path)
                .with_context(|| format!("reading palette {}", path.display()))?;
            let row = img.row(img.height() / 2).to_vec();
            Ok(Palette::from_strip(&self.0, &row)
                .with_context(|| format!("palette {}", path.display()))?)
        } else {
            Ok(Palette::preset(&self.0)?)
        }
    }
}

/// A directory of several outputs (plots, stage images) written as one unit: files go into
/// a fresh hidden staging directory beside the target ([`ignis_core::atomic::StagingDir`]),
/// which [`StagedDir::commit`] renames into place (or, when the target exists, whose files
/// it moves in). A failed command drops it, leaving nothing new; a killed one leaves a
/// PID-tagged directory the next run removes.
pub struct StagedDir {
    target: PathBuf,
    tmp: ignis_core::atomic::StagingDir,
}

impl StagedDir {
    pub fn new(target: &std::path::Path) -> Result<StagedDir> {
        if std::fs::metadata(target).is_ok_and(|m| !m.is_dir()) {
            anyhow::bail!(
                "{} exists and is not a directory; choose another output directory",
                target.display()
            );
        }
        let tmp = ignis_core::atomic::StagingDir::create(target)
            .with_context(|| format!("creating a directory beside {}", target.display()))?;
        Ok(StagedDir {
            target: target.to_path_buf(),
            tmp,
        })
    }

    /// Where to write the files now.
    pub fn path(&self) -> &std::path::Path {
        self.tmp.path()
    }

    /// Moves the staged files into the target directory (what is left of the staging
    /// directory is removed when `self` drops).
    pub fn commit(mut self) -> Result<()> {
        self.tmp.into_place();
        let tmp = self.tmp.path();
        if std::fs::symlink_metadata(&self.target).is_err() {
            std::fs::rename(tmp, &self.target)
                .with_context(|| format!("writing {}", self.target.display()))?;
            return Ok(());
        }
        move_into(tmp, &self.target)
    }
}

/// Moves every entry of `from` into `to`, merging directories that exist in both.
fn move_into(from: &std::path::Path, to: &std::path::Path) -> Result<()> {
    for e in std::fs::read_dir(from).with_context(|| format!("reading {}", from.display()))? {
        let e = e?;
        let dst = to.join(e.file_name());
        let both_dirs =
            e.file_type()?.is_dir() && std::fs::symlink_metadata(&dst).is_ok_and(|m| m.is_dir());
        if both_dirs {
            move_into(&e.path(), &dst)?;
        } else {
            ignis_core::atomic::check_not_an_input(&dst)?;
            std::fs::rename(e.path(), &dst)
                .with_context(|| format!("writing {}", dst.display()))?;
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sequence_is_one_wrote_line_other_outputs_one_per_file() {
        let seq: Vec<PathBuf> = (0..38)
            .map(|i| PathBuf::from(format!("o/{i:04}.png")))
            .collect();
        assert_eq!(
            wrote_lines(&seq),
            vec!["wrote 38 frames: o/0000.png … o/0037.png".to_string()]
        );
        let book = vec![PathBuf::from("o/fire.png"), PathBuf::from("o/fire.json")];
        assert_eq!(
            wrote_lines(&book),
            vec!["wrote o/fire.png", "wrote o/fire.json"]
        );
        let short: Vec<PathBuf> = (0..3).map(|i| PathBuf::from(format!("{i}.exr"))).collect();
        assert_eq!(wrote_lines(&short).len(), 3);
    }
}
