//! Analysis of a database: consecutive-frame distances and suggested thresholds,
//! Eigenfire display images and contact sheet, reconstruction quality and the compression
//! report, and the choice of E.
//!
//! Source: eigenfires-thesis.txt §4.4 (eq. 19–20), §4.5 (eq. 21, θ_min), §4.6
//! (θ_average, peaks), §4.8 (eq. 22, Hermite clean-up after reconstruction, packs),
//! §5.1.2 (separate E for detection and rendering).
//!
//! Departure: the thesis leaves θ_min and θ_average to the animator ("a hint for
//! initialisations"); here θ_min is suggested as the 10th percentile of a clip's
//! consecutive-frame distances and θ_average as their mean.

use crate::db::{EigenfireDb, Thresholds};
use crate::error::{EigenError, Result};
use crate::hermite::{hermite_darken, HermiteParams};
use ignis_core::palette::linear_to_srgb;
use ignis_core::{GrayFrame, Size};
use serde::{Deserialize, Serialize};

/// How many Eigenfires to use: a count, or the fewest whose eigenvalues retain a fraction
/// of the variance. Written `"50"` or `"95%"` in TOML and on the command line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ESelect {
    Count(usize),
    Variance(f64),
}

impl std::str::FromStr for ESelect {
    type Err = EigenError;
    fn from_str(s: &str) -> Result<ESelect> {
        let t = s.trim();
        if let Some(p) = t.strip_suffix('%') {
            let v: f64 = p
                .trim()
                .parse()
                .map_err(|_| EigenError::bad("E", format!("`{s}` is not a percentage like 95%")))?;
            if !(v > 0.0 && v <= 100.0) {
                return Err(EigenError::bad("E", format!("{v}% must be in (0, 100]")));
            }
            return Ok(ESelect::Variance(v / 100.0));
        }
        match t.parse::<usize>() {
            Ok(n) if n > 0 => Ok(ESelect::Count(n)),
            _ => Err(EigenError::bad(
                "E",
                format!("`{s}` is neither a count (e.g. 50) nor a retained variance (e.g. 95%)"),
            )),
        }
    }
}

impl std::fmt::Display for ESelect {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ESelect::Count(n) => write!(f, "{n}"),
            ESelect::Variance(v) => write!(f, "{}%", v * 100.0),
        }
    }
}

impl Serialize for ESelect {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(&self.to_string())
    }
}

impl<'de> Deserialize<'de> for ESelect {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<ESelect, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            N(usize),
            S(String),
        }
        match Raw::deserialize(d)? {
            Raw::N(n) => format!("{n}").parse().map_err(serde::de::Error::custom),
            Raw::S(s) => s.parse().map_err(serde::de::Error::custom),
        }
    }
}

impl ESelect {
    /// Resolves to a count in `1..=k` given the eigenvalues and the total variance.
    pub fn resolve(&self, eigenvalues: &[f64], total_variance: f64) -> usize {
        let k = eigenvalues.len().max(1);
        match *self {
            ESelect::Count(n) => n.clamp(1, k),
            ESelect::Variance(f) => {
                let total = if total_variance > 0.0 {
                    total_variance
                } else {
                    eigenvalues.iter().sum::<f64>().max(f64::MIN_POSITIVE)
                };
                let mut acc = 0.0;
                for (i, v) in eigenvalues.iter().enumerate() {
                    acc += v;
                    if acc / total >= f - 1e-12 {
                        return i + 1;
                    }
                }
                k
            }
        }
    }
}

/// Distances between consecutive rows `rows` of `weights` (M×k) over `e` components, and
/// the thresholds suggested from them.
pub fn thresholds(
    weights: faer::MatRef<'_, f32>,
    rows: std::ops::Range<usize>,
    e: usize,
) -> Thresholds {
    let e = e.min(weights.ncols());
    let d: Vec<f64> = rows
        .clone()
        .zip(rows.clone().skip(1))
        .map(|(a, b)| {
            (0..e)
                .map(|c| ((weights[(a, c)] - weights[(b, c)]) as f64).powi(2))
                .sum::<f64>()
                .sqrt()
        })
        .collect();
    if d.is_empty() {
        return Thresholds {
            e,
            ..Default::default()
        };
    }
    let mean = d.iter().sum::<f64>() / d.len() as f64;
    let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / d.len() as f64).sqrt();
    let mut sorted = d.clone();
    sorted.sort_by(|a, b| a.total_cmp(b));
    let p10 = sorted[((sorted.len() - 1) as f64 * 0.1).round() as usize];
    let peaks = (0..d.len())
        .filter(|&i| {
            d[i] > mean + sd
                && (i == 0 || d[i] >= d[i - 1])
                && (i + 1 == d.len() || d[i] >= d[i + 1])
        })
        .collect();
    Thresholds {
        e,
        mean,
        min: sorted[0],
        max: sorted[sorted.len() - 1],
        peaks,
        theta_min: p10,
        theta_average: mean,
    }
}

/// An Eigenfire scaled for display, eq. (19)–(20): its smallest value becomes 0 and its
/// largest 1 (the thesis's 0 and 255). The result is a display value, stored as a
/// linear-light frame whose sRGB encoding is that value, so writing it as 8-bit sRGB shows
/// exactly eq. (19)–(20).
pub fn eigenfire_image(u: &GrayFrame) -> GrayFrame {
    let (mut lo, mut hi) = (f32::MAX, f32::MIN);
    for &v in u.data() {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    let scale = if hi > lo { 1.0 / (hi - lo) } else { 0.0 };
    u.map(|v| ignis_core::palette::srgb_to_linear((v - lo) * scale))
}

/// Tiles frames (all the same size) into a grid `cols` wide with a `pad`-pixel black gap.
pub fn contact_sheet(frames: &[GrayFrame], cols: usize, pad: u32) -> Result<GrayFrame> {
    let first = frames
        .first()
        .ok_or_else(|| EigenError::bad("contact sheet", "no frames"))?;
    let s = first.size();
    let cols = cols.clamp(1, frames.len());
    let rows = frames.len().div_ceil(cols);
    let size = Size::new(
        cols as u32 * (s.width + pad) + pad,
        rows as u32 * (s.height + pad) + pad,
    )?;
    let mut out = GrayFrame::new(size);
    for (i, f) in frames.iter().enumerate() {
        if f.size() != s {
            return Err(EigenError::bad("contact sheet", "frames differ in size"));
        }
        let (ox, oy) = (
            pad + (i % cols) as u32 * (s.width + pad),
            pad + (i / cols) as u32 * (s.height + pad),
        );
        for y in 0..s.height {
            for x in 0..s.width {
                out.set(ox + x, oy + y, f.get(x, y));
            }
        }
    }
    Ok(out)
}

/// The first `n` Eigenfires scaled per eq. (19)–(20) on a contact sheet.
pub fn eigenfire_sheet(db: &EigenfireDb, n: usize, cols: usize) -> Result<GrayFrame> {
    let n = n.min(db.usable_components()).max(1).min(db.n_components());
    let frames = (0..n)
        .map(|i| db.eigenfire(i).map(|u| eigenfire_image(&u)))
        .collect::<Result<Vec<_>>>()?;
    contact_sheet(&frames, cols, 2)
}

/// Peak signal-to-noise ratio in dB of `b` against `a`, on sRGB-encoded values in `0..=1`
/// (infinite when identical).
pub fn psnr(a: &GrayFrame, b: &GrayFrame) -> f64 {
    let mse = a
        .data()
        .iter()
        .zip(b.data())
        .map(|(&x, &y)| ((linear_to_srgb(x) - linear_to_srgb(y)) as f64).powi(2))
        .sum::<f64>()
        / a.data().len().max(1) as f64;
    if mse <= 0.0 {
        f64::INFINITY
    } else {
        10.0 * (1.0 / mse).log10()
    }
}

/// Structural similarity (Wang et al. 2004) of `b` against `a` on sRGB-encoded values,
/// averaged over 7×7 windows with stride 2 (C₁ = 0.01², C₂ = 0.03²).
pub fn ssim(a: &GrayFrame, b: &GrayFrame) -> f64 {
    let (w, h) = (a.width() as usize, a.height() as usize);
    let ea: Vec<f64> = a.data().iter().map(|&v| linear_to_srgb(v) as f64).collect();
    let eb: Vec<f64> = b.data().iter().map(|&v| linear_to_srgb(v) as f64).collect();
    let (c1, c2) = (0.01f64.powi(2), 0.03f64.powi(2));
    let win = 7.min(w).min(h);
    let (mut sum, mut count) = (0.0, 0usize);
    let mut y = 0;
    while y + win <= h {
        let mut x = 0;
        while x + win <= w {
            let (mut sa, mut sb, mut saa, mut sbb, mut sab) = (0.0, 0.0, 0.0, 0.0, 0.0);
            for yy in y..y + win {
                for xx in x..x + win {
                    let (p, q) = (ea[yy * w + xx], eb[yy * w + xx]);
                    sa += p;
                    sb += q;
                    saa += p * p;
                    sbb += q * q;
                    sab += p * q;
                }
            }
            let n = (win * win) as f64;
            let (ma, mb) = (sa / n, sb / n);
            let (va, vb, cov) = (saa / n - ma * ma, sbb / n - mb * mb, sab / n - ma * mb);
            sum += ((2.0 * ma * mb + c1) * (2.0 * cov + c2))
                / ((ma * ma + mb * mb + c1) * (va + vb + c2));
            count += 1;
            x += 2;
        }
        y += 2;
    }
    if count == 0 {
        1.0
    } else {
        sum / count as f64
    }
}

/// Reconstructs training row `row` with `e` Eigenfires (eq. 22), optionally cleaned up by
/// Hermite background removal (§4.8; no contour protection, since a reconstruction has no
/// mask).
pub fn reconstruct_row(
    db: &EigenfireDb,
    row: usize,
    e: usize,
    hermite: Option<&HermiteParams>,
) -> Result<GrayFrame> {
    let w = db.frame_weights(row);
    let mut f = db.reconstruct(&w, e)?;
    for v in f.data_mut() {
        *v = v.max(0.0);
    }
    Ok(match hermite {
        Some(h) => hermite_darken(&f, None, h),
        None => f,
    })
}

/// One line of the compression report.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CompressionPoint {
    /// Eigenfires used.
    pub e: usize,
    /// Retained variance fraction of those Eigenfires.
    pub variance: f64,
    /// Mean PSNR (dB) and SSIM over the sampled training frames, against those frames
    /// reconstructed with every stored Eigenfire — which are exactly the pre-processed
    /// training frames when all M − 1 Eigenfires were kept (the default).
    pub psnr: f64,
    pub ssim: f64,
    /// Same with Hermite clean-up after reconstruction.
    pub psnr_hermite: f64,
    pub ssim_hermite: f64,
    /// Bytes needed for the mean, E Eigenfires and M×E weights as f32.
    pub bytes: u64,
}

/// Quality and size as functions of E (§4.8). `es` are the E values to try (clamped to
/// the usable Eigenfires); `samples` training rows are spread evenly over the database.
/// The reference for each frame is its reconstruction with every stored Eigenfire.
pub fn compression_report(
    db: &EigenfireDb,
    es: &[usize],
    samples: usize,
    hermite: &HermiteParams,
) -> Result<Vec<CompressionPoint>> {
    let k = db.usable_components();
    if k == 0 {
        return Err(EigenError::Database {
            db: db.path().into(),
            file: "packs".into(),
            reason: "no usable Eigenfire pack".into(),
        });
    }
    let m = db.n_frames();
    let rows: Vec<usize> = (0..samples.clamp(1, m))
        .map(|i| i * m / samples.clamp(1, m))
        .collect();
    let refs = rows
        .iter()
        .map(|&r| reconstruct_row(db, r, k, None))
        .collect::<Result<Vec<_>>>()?;
    let total: f64 = db.manifest().total_variance.max(f64::MIN_POSITIVE);
    let n = db.train_size().pixels() as u64;
    let mut out = Vec::new();
    for &e in es {
        let e = e.clamp(1, k);
        let (mut p, mut s, mut ph, mut sh) = (0.0, 0.0, 0.0, 0.0);
        for (&r, reference) in rows.iter().zip(&refs) {
            let f = reconstruct_row(db, r, e, None)?;
            let fh = hermite_darken(&f, None, hermite);
            p += psnr(reference, &f).min(99.0);
            s += ssim(reference, &f);
            ph += psnr(reference, &fh).min(99.0);
            sh += ssim(reference, &fh);
        }
        let c = rows.len() as f64;
        out.push(CompressionPoint {
            e,
            variance: db.eigenvalues()[..e].iter().sum::<f64>() / total,
            psnr: p / c,
            ssim: s / c,
            psnr_hermite: ph / c,
            ssim_hermite: sh / c,
            bytes: 4 * (n + e as u64 * n + m as u64 * e as u64),
        });
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eselect_parses_and_resolves() {
        assert_eq!("50".parse::<ESelect>().unwrap(), ESelect::Count(50));
        assert_eq!("95%".parse::<ESelect>().unwrap(), ESelect::Variance(0.95));
        assert!(
            "0".parse::<ESelect>().is_err()
                && "120%".parse::<ESelect>().is_err()
                && "x".parse::<ESelect>().is_err()
        );
        let ev = [5.0, 3.0, 1.0, 1.0];
        assert_eq!(ESelect::Variance(0.8).resolve(&ev, 10.0), 2);
        assert_eq!(ESelect::Count(9).resolve(&ev, 10.0), 4);
    }

    #[test]
    fn scaling_and_quality() {
        let s = Size::new(16, 16).unwrap();
        let u = GrayFrame::from_fn(s, |x, y| x as f32 * 0.01 - y as f32 * 0.02);
        let img = eigenfire_image(&u);
        assert!((linear_to_srgb(img.max()) - 1.0).abs() < 1e-5);
        assert!(img.data().contains(&0.0));
        let a = GrayFrame::from_fn(s, |x, y| ((x + y) % 5) as f32 / 5.0);
        assert!(psnr(&a, &a).is_infinite());
        assert!((ssim(&a, &a) - 1.0).abs() < 1e-9);
        let b = a.map(|v| v * 0.5);
        assert!(psnr(&a, &b) < 40.0 && ssim(&a, &b) < 1.0);
        let sheet = contact_sheet(&[a.clone(), b, a], 2, 1).unwrap();
        assert_eq!(sheet.size(), Size::new(35, 35).unwrap());
    }
}
