//! Output options shared by every generating command, and the palette argument.

use anyhow::{Context, Result};
use ignis_core::{Palette, Size};
use ignis_media::{AlphaMode, FlipbookOptions, Format, FrameWriter, WriteOptions};
use std::path::PathBuf;

/// Where and how to write frames. The format follows the output path unless `--format`
/// says otherwise.
#[derive(clap::Args, Debug, Clone)]
pub struct OutputArgs {
    /// Output: `x.mp4`, `x.gif`, `x.png` (flipbook + `x.json`), a directory `dir/` or a
    /// pattern `dir/%04d.png` / `dir/%04d.exr` (sequence).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Force the format: mp4, gif, flipbook, png-seq, exr-seq.
    #[arg(long, value_parser = ["mp4", "gif", "flipbook", "png-seq", "exr-seq"])]
    pub format: Option<String>,
    /// Frames per second stored in the output.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Flipbook: columns (default near-square).
    #[arg(long)]
    pub columns: Option<u32>,
    /// Flipbook: rows (default from columns).
    #[arg(long)]
    pub rows: Option<u32>,
    /// Flipbook: edge-bleed padding around each cell, in pixels.
    #[arg(long, default_value_t = 0)]
    pub padding: u32,
    /// Flipbook: write premultiplied instead of straight alpha.
    #[arg(long)]
    pub premultiplied: bool,
    /// Do not mark GIFs and flipbooks as looping.
    #[arg(long)]
    pub no_loop: bool,
}

impl OutputArgs {
    pub fn write_options(&self) -> WriteOptions {
        WriteOptions {
            format: self.format.as_deref().map(|f| match f {
                "mp4" => Format::Mp4,
                "gif" => Format::Gif,
                "flipbook" => Format::Flipbook,
                "png-seq" => Format::PngSequence,
                _ => Format::ExrSequence,
            }),
            fps: self.fps,
            loop_: !self.no_loop,
            flipbook: FlipbookOptions {
                columns: self.columns,
                rows: self.rows,
                padding: self.padding,
                alpha: if self.premultiplied {
                    AlphaMode::Premultiplied
                } else {
                    AlphaMode::Straight
                },
            },
            background: [0.0; 3],
            first_frame: 0,
        }
    }

    /// Opens the writer (atomic: nothing appears under the final name until `finish`).
    pub fn create(&self, size: Size) -> Result<FrameWriter> {
        ignis_media::create(&self.output, size, &self.write_options())
            .with_context(|| format!("creating {}", self.output.display()))
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
        for f in &files {
            g.say(format!("wrote {}", f.display()));
        }
        Ok(files)
    }
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
