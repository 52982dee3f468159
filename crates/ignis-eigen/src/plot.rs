//! Figures of the analysis stage as PNG, drawn with `plotters`.
//!
//! Source: eigenfires-thesis.txt §4.4 Figure 24 (training frames on the first three
//! components, coloured by clip, consecutive frames joined into "paths"), §4.6 Figure 27
//! (weights of the first 10 Eigenfires for 31 consecutive frames, clustered columns) and
//! Figure 28 (the first 100 weights of one frame); plus the eigenvalue spectrum and the
//! compression report of §4.8.
//!
//! Text needs a system font (plotters' `ttf` feature, via fontconfig). If drawing text
//! fails, the figure is drawn again without any text rather than not at all.

use crate::analysis::CompressionPoint;
use crate::db::EigenfireDb;
use crate::error::{EigenError, Result};
use plotters::prelude::*;
use std::path::Path;

/// Colours for clips, cycled.
pub const CLIP_COLOURS: [RGBColor; 6] = [
    RGBColor(230, 70, 40),
    RGBColor(60, 170, 240),
    RGBColor(250, 200, 40),
    RGBColor(90, 200, 90),
    RGBColor(200, 90, 220),
    RGBColor(240, 240, 240),
];

type DrawResult = std::result::Result<(), Box<dyn std::error::Error>>;

/// Draws a `size` figure with `f` into an RGB buffer (with text; again without text when
/// that fails) and writes it to `path` as PNG through [`ignis_core::atomic`].
fn draw_with_fallback(
    path: &Path,
    size: (u32, u32),
    f: impl Fn(&mut [u8], bool) -> DrawResult,
) -> Result<()> {
    let err = |e: Box<dyn std::error::Error>| EigenError::Plot {
        file: path.display().to_string(),
        reason: e.to_string(),
    };
    if let Some(parent) = path.parent() {
        if !parent.as_os_str().is_empty() {
            std::fs::create_dir_all(parent).map_err(|e| EigenError::io(parent, e))?;
        }
    }
    let len = size.0 as usize * size.1 as usize * 3;
    let mut buf = vec![0u8; len];
    if f(&mut buf, true).is_err() {
        buf = vec![0u8; len];
        f(&mut buf, false).map_err(err)?;
    }
    ignis_core::atomic::write_file(path, |w| {
        use image::ImageEncoder;
        image::codecs::png::PngEncoder::new(w)
            .write_image(&buf, size.0, size.1, image::ExtendedColorType::Rgb8)
            .map_err(std::io::Error::other)
    })
    .map_err(|e| EigenError::io(path, e))
}

fn font(labels: bool, size: u32) -> TextStyle<'static> {
    ("sans-serif", if labels { size } else { 0 })
        .into_font()
        .color(&WHITE)
}

/// Figure 24: every training frame on the first three components, one colour per clip,
/// consecutive frames joined by lines.
pub fn scatter_3d(db: &EigenfireDb, path: &Path, size: (u32, u32)) -> Result<()> {
    let w = db.weights();
    let k = w.ncols();
    let get = |r: usize, c: usize| if c < k { w[(r, c)] as f64 } else { 0.0 };
    let mut lo = [f64::MAX; 3];
    let mut hi = [f64::MIN; 3];
    for r in 0..w.nrows() {
        for c in 0..3 {
            lo[c] = lo[c].min(get(r, c));
            hi[c] = hi[c].max(get(r, c));
        }
    }
    for c in 0..3 {
        if hi[c] <= lo[c] {
            hi[c] = lo[c] + 1.0;
        }
    }
    draw_with_fallback(path, size, |buf, labels| {
        let root = BitMapBackend::with_buffer(buf, size).into_drawing_area();
        root.fill(&RGBColor(17, 17, 17))?;
        let mut b = ChartBuilder::on(&root);
        b.margin(20);
        if labels {
            b.caption(
                "Training frames on Eigenfires 1-3 (paths join consecutive frames)",
                font(true, 18),
            );
        }
        let mut chart = b.build_cartesian_3d(lo[0]..hi[0], lo[1]..hi[1], lo[2]..hi[2])?;
        chart.with_projection(|mut pb| {
            pb.pitch = 0.35;
            pb.yaw = 0.7;
            pb.scale = 0.85;
            pb.into_matrix()
        });
        let mut axes = chart.configure_axes();
        axes.light_grid_style(RGBColor(50, 50, 50))
            .bold_grid_style(RGBColor(80, 80, 80))
            .axis_panel_style(RGBColor(25, 25, 25));
        if labels {
            axes.label_style(font(true, 11));
        } else {
            axes.x_labels(0).y_labels(0).z_labels(0);
        }
        axes.draw()?;
        for (ci, clip) in db.clips().iter().enumerate() {
            let col = CLIP_COLOURS[ci % CLIP_COLOURS.len()];
            let rows = clip.first_row..clip.first_row + clip.frames;
            let pts: Vec<(f64, f64, f64)> =
                rows.map(|r| (get(r, 0), get(r, 1), get(r, 2))).collect();
            chart.draw_series(LineSeries::new(pts.iter().copied(), col.mix(0.45)))?;
            let s = chart.draw_series(pts.iter().map(|&q| Circle::new(q, 2, col.filled())))?;
            if labels {
                s.label(clip.name.clone())
                    .legend(move |(x, y)| Circle::new((x, y), 4, col.filled()));
            }
        }
        if labels {
            chart
                .configure_series_labels()
                .label_font(font(true, 14))
                .background_style(RGBColor(30, 30, 30))
                .border_style(WHITE)
                .draw()?;
        }
        root.present()?;
        Ok(())
    })
}

/// Figure 27: weights of the first `components` Eigenfires for `frames` consecutive
/// training frames of `clip` from its training frame `from`, as clustered columns (dark =
/// first frame, bright = last).
pub fn weight_clusters(
    db: &EigenfireDb,
    clip: &str,
    from: usize,
    frames: usize,
    components: usize,
    path: &Path,
    size: (u32, u32),
) -> Result<()> {
    let c = db.clip(clip)?;
    let w = db.weights();
    let comps = components.min(w.ncols()).max(1);
    let frames = frames.min(c.frames.saturating_sub(from)).max(1);
    let rows: Vec<usize> = (0..frames)
        .map(|i| c.first_row + (from + i).min(c.frames - 1))
        .collect();
    let (mut lo, mut hi) = (0.0f64, 0.0f64);
    for &r in &rows {
        for k in 0..comps {
            lo = lo.min(w[(r, k)] as f64);
            hi = hi.max(w[(r, k)] as f64);
        }
    }
    if hi <= lo {
        hi = lo + 1.0;
    }
    let pad = 0.05 * (hi - lo);
    let name = c.name.clone();
    draw_with_fallback(path, size, |buf, labels| {
        let root = BitMapBackend::with_buffer(buf, size).into_drawing_area();
        root.fill(&RGBColor(17, 17, 17))?;
        let mut b = ChartBuilder::on(&root);
        b.margin(15)
            .x_label_area_size(if labels { 30 } else { 0 })
            .y_label_area_size(if labels { 60 } else { 0 });
        if labels {
            b.caption(
                format!("{name}: weights of Eigenfires 1-{comps}, {frames} consecutive frames"),
                font(true, 16),
            );
        }
        let mut chart = b.build_cartesian_2d(-0.5..comps as f64 - 0.5, (lo - pad)..(hi + pad))?;
        let mut mesh = chart.configure_mesh();
        mesh.disable_x_mesh()
            .light_line_style(RGBColor(40, 40, 40))
            .bold_line_style(RGBColor(60, 60, 60))
            .axis_style(WHITE);
        if labels {
            mesh.label_style(font(true, 11))
                .x_desc("Eigenfire")
                .y_desc("weight")
                .x_labels(comps + 1)
                .x_label_formatter(&|x| format!("{}", x.round() as i64 + 1));
        } else {
            mesh.x_labels(0).y_labels(0);
        }
        mesh.draw()?;
        let bw = 0.85 / frames as f64;
        for (fi, &r) in rows.iter().enumerate() {
            let t = if frames > 1 {
                fi as f64 / (frames - 1) as f64
            } else {
                1.0
            };
            let col = RGBColor(
                (60.0 + 190.0 * t) as u8,
                (25.0 + 150.0 * t) as u8,
                (10.0 + 40.0 * t) as u8,
            );
            chart.draw_series((0..comps).map(|k| {
                let x0 = k as f64 - 0.425 + fi as f64 * bw;
                let v = w[(r, k)] as f64;
                Rectangle::new([(x0, 0.0), (x0 + bw, v)], col.filled())
            }))?;
        }
        root.present()?;
        Ok(())
    })
}

/// Figure 28: the first `components` weights of one training frame (`row`).
pub fn frame_weights(
    db: &EigenfireDb,
    row: usize,
    components: usize,
    path: &Path,
    size: (u32, u32),
) -> Result<()> {
    let w = db.frame_weights(row);
    let comps = components.min(w.len()).max(1);
    let lo = w[..comps].iter().fold(0.0f64, |a, &v| a.min(v as f64));
    let mut hi = w[..comps].iter().fold(0.0f64, |a, &v| a.max(v as f64));
    if hi <= lo {
        hi = lo + 1.0;
    }
    let title = match db.row_origin(row) {
        Some((c, f)) => format!("{} frame {f}: first {comps} weights", c.name),
        None => format!("frame {row}"),
    };
    draw_with_fallback(path, size, |buf, labels| {
        let root = BitMapBackend::with_buffer(buf, size).into_drawing_area();
        root.fill(&RGBColor(17, 17, 17))?;
        let mut b = ChartBuilder::on(&root);
        b.margin(15)
            .x_label_area_size(if labels { 30 } else { 0 })
            .y_label_area_size(if labels { 60 } else { 0 });
        if labels {
            b.caption(&title, font(true, 16));
        }
        let mut chart = b.build_cartesian_2d(0.0..comps as f64, lo * 1.05..hi * 1.05)?;
        let mut mesh = chart.configure_mesh();
        mesh.disable_x_mesh()
            .light_line_style(RGBColor(40, 40, 40))
            .bold_line_style(RGBColor(60, 60, 60))
            .axis_style(WHITE);
        if labels {
            mesh.label_style(font(true, 11))
                .x_desc("Eigenfire")
                .y_desc("weight");
        } else {
            mesh.x_labels(0).y_labels(0);
        }
        mesh.draw()?;
        chart.draw_series((0..comps).map(|k| {
            Rectangle::new(
                [(k as f64 + 0.1, 0.0), (k as f64 + 0.9, w[k] as f64)],
                RGBColor(240, 140, 40).filled(),
            )
        }))?;
        root.present()?;
        Ok(())
    })
}

/// The eigenvalue spectrum (log scale) and the cumulative retained variance.
pub fn spectrum(db: &EigenfireDb, path: &Path, size: (u32, u32)) -> Result<()> {
    let ev = db.eigenvalues();
    let total = db.manifest().total_variance.max(f64::MIN_POSITIVE);
    let k = ev.len().max(1);
    let mut cum = Vec::with_capacity(k);
    let mut acc = 0.0;
    for v in ev {
        acc += v;
        cum.push(acc / total);
    }
    draw_with_fallback(path, size, |buf, labels| {
        let root = BitMapBackend::with_buffer(buf, size).into_drawing_area();
        root.fill(&RGBColor(17, 17, 17))?;
        let mut b = ChartBuilder::on(&root);
        b.margin(15)
            .x_label_area_size(if labels { 30 } else { 0 })
            .y_label_area_size(if labels { 50 } else { 0 });
        if labels {
            b.caption(
                "Retained variance (orange) and eigenvalue / largest (blue, log10 + 1)",
                font(true, 15),
            );
        }
        let mut chart = b.build_cartesian_2d(1.0..k as f64, 0.0..1.0)?;
        let mut mesh = chart.configure_mesh();
        mesh.light_line_style(RGBColor(40, 40, 40))
            .bold_line_style(RGBColor(60, 60, 60))
            .axis_style(WHITE);
        if labels {
            mesh.label_style(font(true, 11)).x_desc("E");
        } else {
            mesh.x_labels(0).y_labels(0);
        }
        mesh.draw()?;
        chart.draw_series(LineSeries::new(
            cum.iter().enumerate().map(|(i, &c)| (i as f64 + 1.0, c)),
            RGBColor(240, 140, 40).stroke_width(2),
        ))?;
        let top = ev.first().copied().unwrap_or(1.0).max(f64::MIN_POSITIVE);
        chart.draw_series(LineSeries::new(
            ev.iter().enumerate().map(|(i, &v)| {
                (
                    i as f64 + 1.0,
                    ((v / top).max(1e-10).log10() / 10.0 + 1.0).clamp(0.0, 1.0),
                )
            }),
            RGBColor(60, 170, 240).stroke_width(2),
        ))?;
        root.present()?;
        Ok(())
    })
}

/// PSNR (orange, with Hermite clean-up dashed-lighter) against E, from a compression
/// report.
pub fn compression_chart(points: &[CompressionPoint], path: &Path, size: (u32, u32)) -> Result<()> {
    if points.is_empty() {
        return Err(EigenError::bad("compression chart", "no points"));
    }
    let emax = points.iter().map(|q| q.e).max().unwrap_or(1) as f64;
    let pmax = points
        .iter()
        .map(|q| q.psnr.max(q.psnr_hermite))
        .fold(10.0f64, f64::max)
        .min(100.0);
    draw_with_fallback(path, size, |buf, labels| {
        let root = BitMapBackend::with_buffer(buf, size).into_drawing_area();
        root.fill(&RGBColor(17, 17, 17))?;
        let mut b = ChartBuilder::on(&root);
        b.margin(15)
            .x_label_area_size(if labels { 30 } else { 0 })
            .y_label_area_size(if labels { 50 } else { 0 });
        if labels {
            b.caption(
                "PSNR (dB) vs E: plain (orange), after Hermite clean-up (yellow)",
                font(true, 15),
            );
        }
        let mut chart = b.build_cartesian_2d(0.0..emax * 1.05, 0.0..pmax * 1.05)?;
        let mut mesh = chart.configure_mesh();
        mesh.light_line_style(RGBColor(40, 40, 40))
            .bold_line_style(RGBColor(60, 60, 60))
            .axis_style(WHITE);
        if labels {
            mesh.label_style(font(true, 11))
                .x_desc("E")
                .y_desc("PSNR dB");
        } else {
            mesh.x_labels(0).y_labels(0);
        }
        mesh.draw()?;
        chart.draw_series(LineSeries::new(
            points.iter().map(|q| (q.e as f64, q.psnr.min(100.0))),
            RGBColor(240, 140, 40).stroke_width(2),
        ))?;
        chart.draw_series(LineSeries::new(
            points
                .iter()
                .map(|q| (q.e as f64, q.psnr_hermite.min(100.0))),
            RGBColor(250, 220, 60).stroke_width(2),
        ))?;
        root.present()?;
        Ok(())
    })
}
