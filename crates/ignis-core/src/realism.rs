//! Does it look like fire? Two measurable properties of real flames, computed the same way
//! on renders and on footage (issue 16 §2):
//!
//! - **Flicker** ([`flicker`]): buoyant diffusion flames *puff* at `f ≈ 1.5 / √D` Hz for a
//!   fire `D` metres across (Cetegen & Ahmed 1993; [`puffing_frequency`]). Measured as the
//!   dominant frequency of the mean brightness of the upper flame region (the upper half of
//!   the box where the time-averaged frame is at least [`REGION_LEVEL`] of its bright
//!   level), by a Hann-windowed DFT of the mean-removed, detrended series, above
//!   [`MIN_FLICKER_HZ`].
//! - **Detail** ([`spectral_slope`]): the slope of the radially averaged spatial power
//!   spectrum `P(k) ∝ k^slope` of the flame region: a square crop around the flame (its box
//!   at [`REGION_LEVEL`] of the frame's bright level, enlarged by a quarter so the edges are
//!   inside), area-resampled to [`SPECTRUM_SIDE`]², mean removed, Hann-windowed, 2-D FFT,
//!   power averaged over rings of integer radius, fitted by least squares on `ln P` over
//!   `ln k` for `k` in [`SLOPE_OCTAVES`] (the middle octaves: the lowest ones are the
//!   flame's outline, the highest the resampling and the video codec), each octave weighted
//!   equally. A soft cone's spectrum falls steeply; real flames, with sharp edges and
//!   tongues, fall about as `k^-3`.
//!
//! Both work on *display luma* ([`display_luma`]): the frame composited over a background,
//! sRGB-encoded, Rec. 601 luma — what a viewer sees and what decoded footage holds — so
//! renders (linear light) and footage (decoded by `ignis-media` to linear light) are
//! compared on the same scale.

use crate::error::{CoreError, Result};
use crate::frame::{GrayFrame, RgbaFrame, Size};
use crate::palette::linear_to_srgb;

/// Fraction of the bright level (the 99.5th percentile of display luma) a pixel needs to
/// count as flame.
pub const REGION_LEVEL: f32 = 0.3;
/// Lowest frequency the flicker search considers, Hz (slower changes are drift).
pub const MIN_FLICKER_HZ: f64 = 0.5;
/// Side of the square the spatial spectrum is computed on.
pub const SPECTRUM_SIDE: usize = 64;
/// Ring radii (cycles per crop) the spectral slope is fitted over: the middle octaves
/// 4–16 of a [`SPECTRUM_SIDE`] crop.
pub const SLOPE_OCTAVES: std::ops::RangeInclusive<usize> = 4..=16;

/// The puffing frequency of a buoyant diffusion flame of diameter `diameter_m` metres,
/// `1.5 / √D` Hz (Cetegen & Ahmed 1993).
pub fn puffing_frequency(diameter_m: f64) -> f64 {
    1.5 / diameter_m.sqrt()
}

/// Display luma of a linear straight-alpha frame: composited over `background` (linear
/// RGB), sRGB-encoded, Rec. 601 luma, in `0..=1`, at the frame's own size.
pub fn display_luma(frame: &RgbaFrame, background: [f32; 3]) -> GrayFrame {
    let data = frame
        .data()
        .iter()
        .map(|p| {
            let a = p[3].clamp(0.0, 1.0);
            let c =
                |i: usize| linear_to_srgb((p[i] * a + background[i] * (1.0 - a)).clamp(0.0, 1.0));
            0.299 * c(0) + 0.587 * c(1) + 0.114 * c(2)
        })
        .collect();
    GrayFrame::from_vec(frame.size(), data).expect("one value per pixel")
}

/// An axis-aligned pixel box, `x0..x1` × `y0..y1` (ends excluded).
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct PixelBox {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

/// The box of the pixels at least [`REGION_LEVEL`] of the frame's bright level (its 99.5th
/// percentile); `None` for a frame with no light (bright level ≤ 1e-4).
pub fn flame_box(frame: &GrayFrame) -> Option<PixelBox> {
    let mut v: Vec<f32> = frame.data().to_vec();
    let k = ((v.len() as f64 * 0.995) as usize).min(v.len().saturating_sub(1));
    v.select_nth_unstable_by(k, f32::total_cmp);
    let bright = v[k];
    if !(bright > 1e-4) {
        return None;
    }
    let level = REGION_LEVEL * bright;
    let (w, h) = (frame.width(), frame.height());
    let mut b = PixelBox {
        x0: w,
        y0: h,
        x1: 0,
        y1: 0,
    };
    for (y, row) in frame.rows().enumerate() {
        for (x, &p) in row.iter().enumerate() {
            if p >= level {
                b.x0 = b.x0.min(x as u32);
                b.x1 = b.x1.max(x as u32 + 1);
                b.y0 = b.y0.min(y as u32);
                b.y1 = b.y1.max(y as u32 + 1);
            }
        }
    }
    (b.x1 > b.x0 && b.y1 > b.y0).then_some(b)
}

/// The measured flicker of a sequence.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Flicker {
    /// Dominant frequency of the upper flame region's brightness, Hz.
    pub hz: f64,
    /// Power at the peak over the mean power of the searched band (1 = no peak at all).
    pub peak_ratio: f64,
    /// The upper flame region the brightness was averaged over (pixels of the input).
    pub region: PixelBox,
    /// Frequency resolution of the DFT, `fps / frames`.
    pub resolution_hz: f64,
}

/// The flicker of a sequence of display-luma frames (of one size) played at `fps`: see the
/// module doc. Needs at least 16 frames with some light and `fps > 2 ·` [`MIN_FLICKER_HZ`].
pub fn flicker(frames: &[GrayFrame], fps: f64) -> Result<Flicker> {
    if frames.len() < 16 {
        return Err(CoreError::bad(
            "frames",
            format!(
                "{} frame(s); the flicker needs at least 16 (a 10-s render is best)",
                frames.len()
            ),
        ));
    }
    if !(fps > 2.0 * MIN_FLICKER_HZ && fps.is_finite()) {
        return Err(CoreError::bad(
            "fps",
            format!("{fps}: must be above {}", 2.0 * MIN_FLICKER_HZ),
        ));
    }
    let size = frames[0].size();
    if let Some(f) = frames.iter().find(|f| f.size() != size) {
        return Err(CoreError::SizeMismatch(format!(
            "frame of {} in a sequence of {size}",
            f.size()
        )));
    }
    let mut mean = GrayFrame::new(size);
    for f in frames {
        for (m, &p) in mean.data_mut().iter_mut().zip(f.data()) {
            *m += p;
        }
    }
    let inv = 1.0 / frames.len() as f32;
    mean.data_mut().iter_mut().for_each(|m| *m *= inv);
    let b = flame_box(&mean).ok_or_else(|| {
        CoreError::bad(
            "frames",
            "no flame: every frame is dark; render or decode a visible fire",
        )
    })?;
    let region = PixelBox {
        y1: b.y0 + (b.y1 - b.y0).div_ceil(2),
        ..b
    };
    let signal: Vec<f64> = frames
        .iter()
        .map(|f| {
            let mut s = 0.0f64;
            for y in region.y0..region.y1 {
                s += f.row(y)[region.x0 as usize..region.x1 as usize]
                    .iter()
                    .map(|&p| f64::from(p))
                    .sum::<f64>();
            }
            s
        })
        .collect();
    let (hz, peak_ratio) = dominant_frequency(&signal, fps, MIN_FLICKER_HZ);
    Ok(Flicker {
        hz,
        peak_ratio,
        region,
        resolution_hz: fps / frames.len() as f64,
    })
}

/// The dominant frequency of `signal` sampled at `rate` Hz, at or above `min_hz`: the
/// series is detrended (least-squares line removed) and Hann-windowed; its DFT power is
/// searched from `min_hz` to Nyquist and the peak refined by a parabola through the log
/// power of its neighbours. Returns (frequency, peak power over the band's mean power);
/// (0, 1) for a flat signal.
pub fn dominant_frequency(signal: &[f64], rate: f64, min_hz: f64) -> (f64, f64) {
    let n = signal.len();
    if n < 4 {
        return (0.0, 1.0);
    }
    // detrend
    let nf = n as f64;
    let tm = (nf - 1.0) / 2.0;
    let ym = signal.iter().sum::<f64>() / nf;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (i, &y) in signal.iter().enumerate() {
        let t = i as f64 - tm;
        sxy += t * (y - ym);
        sxx += t * t;
    }
    let slope = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    let x: Vec<f64> = signal
        .iter()
        .enumerate()
        .map(|(i, &y)| {
            let w = 0.5 - 0.5 * (std::f64::consts::TAU * i as f64 / (nf - 1.0)).cos();
            (y - ym - slope * (i as f64 - tm)) * w
        })
        .collect();
    let lo = ((min_hz * nf / rate).ceil() as usize).max(1);
    let hi = n / 2;
    if lo > hi {
        return (0.0, 1.0);
    }
    // a direct real DFT of the bins searched (n ≤ a few thousand: O(n²) is milliseconds)
    let power: Vec<f64> = (lo..=hi)
        .map(|k| {
            let (mut re, mut im) = (0.0, 0.0);
            let step = std::f64::consts::TAU * k as f64 / nf;
            for (i, &v) in x.iter().enumerate() {
                let (s, c) = (step * i as f64).sin_cos();
                re += v * c;
                im -= v * s;
            }
            re * re + im * im
        })
        .collect();
    let total: f64 = power.iter().sum();
    if !(total > 0.0) {
        return (0.0, 1.0);
    }
    let (j, &pk) = power
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))
        .expect("non-empty band");
    let mut k = (lo + j) as f64;
    if j > 0 && j + 1 < power.len() {
        let (a, b, c) = (
            power[j - 1].max(1e-300).ln(),
            pk.max(1e-300).ln(),
            power[j + 1].max(1e-300).ln(),
        );
        let d = a - 2.0 * b + c;
        if d < 0.0 {
            k += (0.5 * (a - c) / d).clamp(-0.5, 0.5);
        }
    }
    (k * rate / nf, pk / (total / power.len() as f64))
}

/// The spatial detail of one frame.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Spectrum {
    /// Fitted slope of `ln P` over `ln k` on [`SLOPE_OCTAVES`].
    pub slope: f64,
    /// The flame box the crop was centred on.
    pub region: PixelBox,
    /// Side of the square crop in input pixels (before resampling).
    pub crop_side: u32,
}

/// The spectral slope of one display-luma frame's flame region: see the module doc.
/// Errors for a dark frame.
pub fn spectral_slope(frame: &GrayFrame) -> Result<Spectrum> {
    let b = flame_box(frame).ok_or_else(|| {
        CoreError::bad(
            "frame",
            "no flame: the frame is dark; render or decode a visible fire",
        )
    })?;
    let n = SPECTRUM_SIDE;
    let side = (1.25 * f64::from((b.x1 - b.x0).max(b.y1 - b.y0))).max(n as f64 / 4.0);
    let cx = 0.5 * f64::from(b.x0 + b.x1);
    let cy = 0.5 * f64::from(b.y0 + b.y1);
    let crop = resample_crop(frame, cx - side / 2.0, cy - side / 2.0, side, n);
    let mean = crop.iter().sum::<f64>() / crop.len() as f64;
    let hann: Vec<f64> = (0..n)
        .map(|i| 0.5 - 0.5 * (std::f64::consts::TAU * (i as f64 + 0.5) / n as f64).cos())
        .collect();
    let mut re: Vec<f64> = crop
        .iter()
        .enumerate()
        .map(|(i, &v)| (v - mean) * hann[i % n] * hann[i / n])
        .collect();
    let mut im = vec![0.0; n * n];
    fft_2d(&mut re, &mut im, n, n);
    let half = n / 2;
    let mut ring = vec![(0.0f64, 0usize); half + 1];
    for y in 0..n {
        let ky = if y <= half {
            y as f64
        } else {
            y as f64 - n as f64
        };
        for x in 0..n {
            let kx = if x <= half {
                x as f64
            } else {
                x as f64 - n as f64
            };
            let r = (kx * kx + ky * ky).sqrt().round() as usize;
            if r <= half {
                let i = y * n + x;
                ring[r].0 += re[i] * re[i] + im[i] * im[i];
                ring[r].1 += 1;
            }
        }
    }
    // weighted least squares, weight 1/k so every octave counts the same
    let (mut sw, mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for k in SLOPE_OCTAVES {
        let (p, c) = ring[k];
        let p = (p / c.max(1) as f64).max(1e-30);
        let (lx, ly, w) = ((k as f64).ln(), p.ln(), 1.0 / k as f64);
        sw += w;
        sx += w * lx;
        sy += w * ly;
        sxx += w * lx * lx;
        sxy += w * lx * ly;
    }
    let slope = (sw * sxy - sx * sy) / (sw * sxx - sx * sx);
    Ok(Spectrum {
        slope,
        region: b,
        crop_side: side.round() as u32,
    })
}

/// The median spectral slope of several frames (dark frames skipped); errors when every
/// frame is dark.
pub fn median_slope(frames: &[GrayFrame]) -> Result<f64> {
    let mut s: Vec<f64> = frames
        .iter()
        .filter_map(|f| spectral_slope(f).ok().map(|s| s.slope))
        .collect();
    if s.is_empty() {
        return Err(CoreError::bad(
            "frames",
            "no flame in any frame; nothing to measure",
        ));
    }
    Ok(crate::loopq::median(&mut s))
}

/// The `side`-pixel square of `frame` at (`x0`, `y0`) area-averaged to `n`², row-major;
/// outside the frame the nearest edge pixel is used.
fn resample_crop(frame: &GrayFrame, x0: f64, y0: f64, side: f64, n: usize) -> Vec<f64> {
    let (w, h) = (frame.width() as i64, frame.height() as i64);
    let px =
        |x: i64, y: i64| f64::from(frame.get(x.clamp(0, w - 1) as u32, y.clamp(0, h - 1) as u32));
    let cell = side / n as f64;
    // sub-samples per output pixel and axis: at least one per input pixel
    let sub = (cell.ceil() as usize).clamp(1, 16);
    let mut out = vec![0.0; n * n];
    for oy in 0..n {
        for ox in 0..n {
            let mut s = 0.0;
            for j in 0..sub {
                let y = y0 + (oy as f64 + (j as f64 + 0.5) / sub as f64) * cell;
                for i in 0..sub {
                    let x = x0 + (ox as f64 + (i as f64 + 0.5) / sub as f64) * cell;
                    s += px(x.floor() as i64, y.floor() as i64);
                }
            }
            out[oy * n + ox] = s / (sub * sub) as f64;
        }
    }
    out
}

/// In-place 2-D DFT of a `w`×`h` complex image, row-major (both powers of two), rows then
/// columns.
pub fn fft_2d(re: &mut [f64], im: &mut [f64], w: usize, h: usize) {
    let (fx, fy) = (Fft::new(w), Fft::new(h));
    for (r, i) in re.chunks_exact_mut(w).zip(im.chunks_exact_mut(w)) {
        fx.run(r, i);
    }
    let (mut cr, mut ci) = (vec![0.0; h], vec![0.0; h]);
    for x in 0..w {
        for y in 0..h {
            cr[y] = re[y * w + x];
            ci[y] = im[y * w + x];
        }
        fy.run(&mut cr, &mut ci);
        for y in 0..h {
            re[y * w + x] = cr[y];
            im[y * w + x] = ci[y];
        }
    }
}

/// In-place iterative radix-2 FFT (forward, unnormalised); `re.len()` a power of two.
pub fn fft(re: &mut [f64], im: &mut [f64]) {
    let n = re.len();
    assert!(
        n.is_power_of_two() && im.len() == n,
        "fft needs a power-of-two length"
    );
    Fft::new(n).run(re, im);
}

/// [`fft`] of one power-of-two length with its twiddles tabled, for many transforms of
/// that length (a sine and cosine per butterfly would be most of the time).
pub struct Fft {
    n: usize,
    tw: Vec<(f64, f64)>,
}

impl Fft {
    /// A plan for length `n` (a power of two).
    pub fn new(n: usize) -> Fft {
        assert!(n.is_power_of_two(), "fft needs a power-of-two length");
        let tw = (0..n / 2)
            .map(|k| {
                let (s, c) = (-std::f64::consts::TAU * k as f64 / n as f64).sin_cos();
                (c, s)
            })
            .collect();
        Fft { n, tw }
    }

    /// Transforms `re`, `im` (each of the plan's length) in place.
    pub fn run(&self, re: &mut [f64], im: &mut [f64]) {
        let n = self.n;
        assert!(re.len() == n && im.len() == n, "fft of the wrong length");
        let mut j = 0;
        for i in 1..n {
            let mut bit = n >> 1;
            while j & bit != 0 {
                j ^= bit;
                bit >>= 1;
            }
            j |= bit;
            if i < j {
                re.swap(i, j);
                im.swap(i, j);
            }
        }
        let mut len = 2;
        while len <= n {
            let stride = n / len;
            for start in (0..n).step_by(len) {
                for k in 0..len / 2 {
                    let (c, s) = self.tw[k * stride];
                    let (a, b) = (start + k, start + k + len / 2);
                    let tr = re[b] * c - im[b] * s;
                    let ti = re[b] * s + im[b] * c;
                    re[b] = re[a] - tr;
                    im[b] = im[a] - ti;
                    re[a] += tr;
                    im[a] += ti;
                }
            }
            len <<= 1;
        }
    }
}

/// Area-reduces a frame so it is at most `max_width` wide (aspect kept); frames already
/// narrow enough are returned as they are. For the flicker series, whose region sums do
/// not need full resolution.
pub fn reduce(frame: GrayFrame, max_width: u32) -> GrayFrame {
    if frame.width() <= max_width {
        return frame;
    }
    let h = ((u64::from(frame.height()) * u64::from(max_width)) / u64::from(frame.width())).max(1)
        as u32;
    crate::loopq::area_resize(
        &frame,
        Size {
            width: max_width,
            height: h,
        },
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    #[test]
    fn fft_matches_a_direct_dft() {
        let mut r = Rng::new(3);
        let x: Vec<f64> = (0..16).map(|_| r.uniform(-1.0, 1.0)).collect();
        let (mut re, mut im) = (x.clone(), vec![0.0; 16]);
        fft(&mut re, &mut im);
        for k in 0..16 {
            let (mut a, mut b) = (0.0, 0.0);
            for (i, &v) in x.iter().enumerate() {
                let t = -std::f64::consts::TAU * (k * i) as f64 / 16.0;
                a += v * t.cos();
                b += v * t.sin();
            }
            assert!(
                (re[k] - a).abs() < 1e-9 && (im[k] - b).abs() < 1e-9,
                "bin {k}"
            );
        }
    }

    /// A random field with power spectrum `k^beta` (random phases), in a Gaussian blob so
    /// it has a flame box.
    fn power_law_field(n: usize, beta: f64, seed: u64) -> GrayFrame {
        let mut r = Rng::new(seed);
        let (mut re, mut im) = (vec![0.0; n * n], vec![0.0; n * n]);
        for y in 0..n {
            let ky = if y <= n / 2 {
                y as f64
            } else {
                y as f64 - n as f64
            };
            for x in 0..n {
                let kx = if x <= n / 2 {
                    x as f64
                } else {
                    x as f64 - n as f64
                };
                let k = (kx * kx + ky * ky).sqrt();
                if k > 0.0 {
                    let a = k.powf(beta / 2.0);
                    let ph = r.uniform(0.0, std::f64::consts::TAU);
                    re[y * n + x] = a * ph.cos();
                    im[y * n + x] = a * ph.sin();
                }
            }
        }
        // inverse via the forward transform of the conjugate
        im.iter_mut().for_each(|v| *v = -*v);
        fft_2d(&mut re, &mut im, n, n);
        let sd = (re.iter().map(|v| v * v).sum::<f64>() / (n * n) as f64).sqrt();
        GrayFrame::from_fn(Size::new(n as u32, n as u32).unwrap(), |x, y| {
            (0.5 + 0.15 * re[y as usize * n + x as usize] / sd) as f32
        })
    }

    #[test]
    fn slope_of_a_power_law_field_is_recovered() {
        for beta in [-2.0, -3.0, -4.0] {
            let f = power_law_field(256, beta, 9);
            let s = spectral_slope(&f).unwrap();
            assert!(
                (s.slope - beta).abs() < 0.25,
                "beta {beta}: measured {}",
                s.slope
            );
        }
    }

    #[test]
    fn a_blurred_field_is_steeper() {
        let f = power_law_field(128, -3.0, 5);
        let blurred = crate::post::gaussian_blur(&f, 3.0);
        let a = spectral_slope(&f).unwrap().slope;
        let b = spectral_slope(&blurred).unwrap().slope;
        assert!(b < a - 1.0, "sharp {a}, blurred {b}");
    }

    #[test]
    fn flicker_finds_the_puffing_frequency() {
        // a flame whose upper half brightens and dims at 7 Hz, with noise, at 60 fps
        let mut r = Rng::new(1);
        let size = Size::new(32, 48).unwrap();
        let frames: Vec<GrayFrame> = (0..600)
            .map(|i| {
                let t = i as f64 / 60.0;
                let puff = 0.3 * (std::f64::consts::TAU * 7.0 * t).sin();
                let noise: Vec<f64> = (0..4).map(|_| r.uniform(-0.3, 0.3)).collect();
                GrayFrame::from_fn(size, |x, y| {
                    let inside = (8..24).contains(&x) && (8..44).contains(&y);
                    if !inside {
                        return 0.0;
                    }
                    let top = if y < 26 {
                        puff + noise[(x / 8) as usize % 4]
                    } else {
                        0.0
                    };
                    (0.6 + top) as f32
                })
            })
            .collect();
        let f = flicker(&frames, 60.0).unwrap();
        assert!((f.hz - 7.0).abs() < 0.15, "{f:?}");
        assert!(f.peak_ratio > 10.0, "{f:?}");
        assert_eq!((f.region.y0, f.region.y1), (8, 26));
    }

    #[test]
    fn bad_input_is_refused() {
        let size = Size::new(8, 8).unwrap();
        let dark = vec![GrayFrame::new(size); 20];
        assert!(flicker(&dark, 60.0).is_err());
        assert!(flicker(&dark[..3], 60.0).is_err());
        assert!(spectral_slope(&dark[0]).is_err());
        let lit = vec![GrayFrame::from_fn(size, |x, _| x as f32); 20];
        assert!(flicker(&lit, 0.0).is_err());
        assert!(flicker(&lit, f64::NAN).is_err());
    }

    #[test]
    fn puffing_law() {
        assert!((puffing_frequency(0.25) - 3.0).abs() < 1e-12);
    }
}
