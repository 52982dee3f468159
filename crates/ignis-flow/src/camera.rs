//! Camera shake: where a hand-held shot's view sits in each frame against a reference
//! frame, and the warp that holds the view still (`ignis loop --stabilise`).
//!
//! A loop of hand-held footage repeats its shake, and at the wrap the view jumps from
//! where the camera was at the loop's end to where it was at its start. What moves the
//! whole view is the camera; the fire moves on its own. So each frame's translation
//! against the reference is estimated where the picture is rigid:
//!
//! 1. **Phase correlation** (Kuglin & Hines 1975) of the frame and the reference, on grey
//!    frames area-averaged to powers of two near [`TRACK_SIDE`] and Hann-windowed: the
//!    normalised cross-power spectrum's inverse is a peak at the shift the rigid
//!    parts share, whatever the fire does (its content changes from frame to frame and
//!    adds no coherent peak; a flame's light moving over a still candle jar does, but
//!    weakly, where an intensity fit is pulled by it). Sub-pixel from the peak's larger
//!    neighbour on each axis (Foroosh, Zerubia & Berthod 2002: the peak of a sub-pixel
//!    shift is a sampled sinc). The peak's height over the height unrelated pictures reach
//!    (`4/√pixels`) is the track's confidence ([`Track::peak`]).
//! 2. **Is it the camera?** The frame's robust cost against the reference unshifted over
//!    its cost at the shift ([`Track::explains`]; Tukey's biweight of the residuals, a gain
//!    and an offset fitted because fire light brightens the whole scene from frame to
//!    frame): a camera's shift explains the whole textured picture, a flame's does not.
//!
//! Measured (`cargo run --release -p ignis-flow --example camera_track -- CLIP 1` on
//! `campfire.mp4` and `candle.mp4` moved by known whole pixels, up to ±25 px): the
//! campfire 0.22 px median error, 0.45 px at the 95th percentile; the candle in its glass
//! jar 0.34 / 0.85 px (its flame's reflections). Tried: zero-padding to the next powers of
//! two (0.18 / 0.39 px on the campfire, 1.7 times the time); an intensity (Gauss–Newton)
//! refinement after a correlation at half the size, 0.14 px on the campfire but 1.2 px on
//! the candle, pulled by the reflections; the one-sided Foroosh estimate, 0.20 / 0.35 px.
//!
//! The reference is the window's first frame unless it has less than half the detail of
//! the best of the next [`REFERENCE_FRAMES`] ([`choose_reference`]): a clip that fades in
//! from black has nothing to match in its first frame, and no frame was tracked against it.
//!
//! Only translation is modelled: a hand-held camera over a few seconds mostly shifts the
//! view; roll and zoom are left in. A camera that pans away from the reference (the view
//! no longer shares enough with it) fails the confidence test, and the caller leaves the
//! footage as it is.
//!
//! Why hand-written: no well-kept crate does robust global registration on our frames
//! (`opencv`'s would need the system library the README keeps optional); the FFT is the
//! workspace's own ([`ignis_core::realism::fft_2d`]).

use ignis_core::realism::fft_2d;
use ignis_core::{GrayFrame, RgbaFrame, Size};
use rayon::prelude::*;

use crate::image::{resize_with, Img};

/// Longest side of the grey frames a camera is tracked on (each side is then taken to a
/// power of two). Measured with zero padding: 384 (padded to 512) gave the campfire 0.14
/// px against 0.20 at 256, for four times the time; the candle's error did not fall.
pub const TRACK_SIDE: usize = 256;

/// The least phase-correlation peak ([`Track::peak`], in units of the height unrelated
/// pictures reach, `4/√pixels`) a track is trusted at.
pub const PEAK_MIN: f32 = 5.0;

/// Share of a run's frames that must be tracked for it to be steadied.
pub const TRACKED_MIN: f32 = 0.9;

/// How much better, at the median over the frames whose view moved a pixel or more, the
/// shift must explain a frame than no shift ([`Track::explains`]) before `auto` calls it
/// the camera's. Measured: clips moved by known shifts give 1.48 (a candle in a jar) and
/// 1.63 (a campfire); the still candle's few frames that seem to move a pixel (its
/// flame's reflections in the jar) give 0.97.
pub const EXPLAINS_MIN: f32 = 1.25;

/// The most a steadied loop is zoomed to keep its frames inside the picture.
pub const ZOOM_MAX: f32 = 1.25;

/// The least wander (source pixels) `auto` steadies: a pixel, or a quarter of a percent
/// of the shorter side, whichever is more (below it a shake is invisible and the
/// resampling would only soften the frames).
pub fn wander_min(source: Size) -> f32 {
    (0.0025 * source.width.min(source.height) as f32).max(1.0)
}

/// Grey levels (of 1) per pixel below which the picture is flat: one 8-bit level.
const TEXTURE: f32 = 1.0 / 255.0;

/// The least scale of the residuals (of 1): 8-bit footage's quantisation and codec noise,
/// a couple of levels, so a clean match does not reject its own noise.
const NOISE: f32 = 2.0 / 255.0;

/// A frame's grey as it is tracked: sRGB-encoded luma, area-averaged to fit
/// [`TRACK_SIDE`], with the size of the frame it came from.
#[derive(Clone, Debug)]
pub struct TrackGray {
    img: Img,
    source: Size,
}

/// The tracking size of a `source`-sized frame: each side a power of two (the FFT's
/// lengths, no padding), the one nearest (on a log scale) to the side scaled to fit
/// [`TRACK_SIDE`], never more than the source's own (the area resize only shrinks). The
/// two sides may be scaled a little differently; offsets are scaled back per axis.
fn track_size(source: Size) -> (usize, usize) {
    let (w, h) = (source.width as usize, source.height as usize);
    let k = (TRACK_SIDE as f64 / w.max(h).max(1) as f64).min(1.0);
    let side = |v: usize| {
        let want = (v as f64 * k).max(1.0);
        let p = 1usize << (want.log2().round() as u32).min(30);
        if p > v.max(1) {
            (p / 2).max(1)
        } else {
            p
        }
    };
    (side(w), side(h))
}

impl TrackGray {
    /// From 8-bit sRGB RGBA bytes of a `size` frame (`None` when the length is wrong).
    pub fn from_srgba8(size: Size, bytes: &[u8]) -> Option<TrackGray> {
        if bytes.len() != size.pixels() * 4 || size.pixels() == 0 {
            return None;
        }
        let (sw, sh) = (size.width as usize, size.height as usize);
        let (w, h) = track_size(size);
        let img = resize_with(sw, sh, w, h, |y, wt, out| {
            let row = &bytes[y * sw * 4..(y + 1) * sw * 4];
            for (o, p) in out.iter_mut().zip(row.chunks_exact(4)) {
                let l = 0.299 * f32::from(p[0]) + 0.587 * f32::from(p[1]) + 0.114 * f32::from(p[2]);
                *o += l * (wt / 255.0);
            }
        });
        Some(TrackGray { img, source: size })
    }

    /// From a linear frame (each channel sRGB-encoded first, as 8-bit footage is, by the
    /// metric's table).
    pub fn from_rgba(frame: &RgbaFrame) -> TrackGray {
        let size = frame.size();
        let (sw, sh) = (size.width as usize, size.height as usize);
        let (w, h) = track_size(size);
        let enc = ignis_core::loopq::srgb_encode;
        let data = frame.data();
        let img = resize_with(sw, sh, w, h, |y, wt, out| {
            for (o, p) in out.iter_mut().zip(&data[y * sw..(y + 1) * sw]) {
                let l = 0.299 * enc(p[0]) + 0.587 * enc(p[1]) + 0.114 * enc(p[2]);
                *o += l * wt;
            }
        });
        TrackGray { img, source: size }
    }

    /// The size of the frame it came from.
    pub fn source(&self) -> Size {
        self.source
    }
}

/// One frame's track: its view's shift against the reference, in pixels of the source
/// frame (`frame(x) ≈ reference(x − offset)`: content moved by `offset`), the match's
/// confidence and whether the shift is the camera's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Track {
    pub offset: [f32; 2],
    pub peak: f32,
    /// The robust cost of the picture unshifted over its cost at `offset` (≥ 1 when the
    /// shift explains the frame better than none).
    pub explains: f32,
}

impl Track {
    /// The track of a frame that could not be read for tracking.
    pub const LOST: Track = Track {
        offset: [0.0; 2],
        peak: 0.0,
        explains: 1.0,
    };

    /// Whether the match is trusted ([`PEAK_MIN`]).
    pub fn tracked(&self) -> bool {
        self.peak >= PEAK_MIN && self.offset.iter().all(|v| v.is_finite())
    }
}

/// Tracks frames against one reference frame (see the module doc).
pub struct Tracker {
    reference: Img,
    /// The transforms' lengths (the tracking size, both powers of two).
    pw: usize,
    ph: usize,
    /// The windowed reference's spectrum.
    spec: (Vec<f64>, Vec<f64>),
    source: Size,
    /// The reference's pixels with detail (a gradient of at least [`TEXTURE`]), off the
    /// one-pixel border: where [`Tracker::explains`] compares (flat pixels, a dark sky,
    /// fit any shift and would make the residuals' scale zero).
    textured: Vec<u32>,
}

/// The pixels of `img` with detail (a gradient of at least [`TEXTURE`]), off the one-pixel
/// border, as indices.
fn textured_pixels(img: &Img) -> Vec<u32> {
    let (gx, gy) = img.gradients();
    let (w, h) = (img.w, img.h);
    (1..h.saturating_sub(1))
        .flat_map(|y| (1..w.saturating_sub(1)).map(move |x| y * w + x))
        .filter(|&i| gx.data[i].abs().max(gy.data[i].abs()) >= TEXTURE)
        .map(|i| i as u32)
        .collect()
}

/// Frames at the start of a window among which [`choose_reference`] looks: about two
/// seconds at 24 fps, the length of a fade in from black.
pub const REFERENCE_FRAMES: usize = 48;

/// Which of a window's first frames (`heads`, in order; [`REFERENCE_FRAMES`] of them) to
/// track the camera against: the first whose detail (pixels with a gradient of an 8-bit
/// level or more) is at least half the most any of them has. That is the first frame,
/// unless it is flat or soft next to those after it — a fade in from black (nothing to
/// match, so no frame would be tracked), a blurred or flashed first frame. `None` when
/// `heads` is empty.
pub fn choose_reference(heads: &[TrackGray]) -> Option<usize> {
    let detail: Vec<usize> = heads
        .iter()
        .map(|g| textured_pixels(&g.img).len())
        .collect();
    let most = *detail.iter().max()?;
    detail.iter().position(|&d| 2 * d >= most)
}

impl Tracker {
    pub fn new(reference: &TrackGray) -> Tracker {
        let img = reference.img.clone();
        let (pw, ph) = (img.w, img.h);
        let spec = spectrum(&img, pw, ph);
        let textured = textured_pixels(&img);
        Tracker {
            reference: img,
            pw,
            ph,
            spec,
            source: reference.source,
            textured,
        }
    }

    /// `frame`'s track against the reference. A frame of another size is refused with a
    /// zero-confidence track.
    pub fn track(&self, frame: &TrackGray) -> Track {
        let r = &self.reference;
        if frame.img.w != r.w || frame.img.h != r.h {
            return Track::LOST;
        }
        let (fr, fi) = spectrum(&frame.img, self.pw, self.ph);
        let (d, peak) = correlate(&self.spec, (&fr, &fi), self.pw, self.ph);
        let peak = peak * ((r.w * r.h) as f32).sqrt() / 4.0;
        let sx = self.source.width as f32 / r.w as f32;
        let sy = self.source.height as f32 / r.h as f32;
        let offset = [d[0] * sx, d[1] * sy];
        // only shifts of a pixel or more are asked whether they are the camera's
        let explains = if offset[0].hypot(offset[1]) >= 1.0 {
            self.explains(&frame.img, d)
        } else {
            1.0
        };
        Track {
            offset,
            peak,
            explains,
        }
    }

    /// How much better the frame matches the reference at `d` (tracking pixels) than at
    /// no shift: the ratio of Tukey's costs, with a gain and an offset fitted (fire light
    /// brightens the whole scene from frame to frame) and the residuals' scale estimated
    /// at `d` (iteratively reweighted least squares), over the reference's pixels with
    /// detail whose match lies inside. A flame's pixels, which no shift explains, cost the
    /// same both ways.
    fn explains(&self, f: &Img, d: [f32; 2]) -> f32 {
        let r = &self.reference;
        let (xmax, ymax) = ((r.w - 1) as f32, (r.h - 1) as f32);
        let rows: Vec<(usize, f32)> = self
            .textured
            .iter()
            .filter_map(|&i| {
                let i = i as usize;
                let (sx, sy) = ((i % r.w) as f32 + d[0], (i / r.w) as f32 + d[1]);
                ((0.0..=xmax).contains(&sx) && (0.0..=ymax).contains(&sy))
                    .then(|| (i, bilinear(f, sx, sy) - r.data[i]))
            })
            .collect();
        if rows.len() < 16 {
            return 1.0;
        }
        let mut gain = [0.0f64; 2];
        let mut c = 4.685 * NOISE;
        let mut resid: Vec<f32> = Vec::with_capacity(rows.len());
        for _ in 0..3 {
            resid.clear();
            resid.extend(
                rows.iter()
                    .map(|&(i, e)| (e - (gain[0] as f32 * r.data[i] + gain[1] as f32)).abs()),
            );
            let mid = resid.len() / 2;
            let med = *resid.select_nth_unstable_by(mid, f32::total_cmp).1;
            c = 4.685 * (1.4826 * med).max(NOISE);
            // weighted least squares of e = a·ref + b
            let (mut s00, mut s01, mut s11, mut b0, mut b1) = (0.0f64, 0.0, 0.0, 0.0, 0.0);
            for &(i, e) in &rows {
                let u = (e - (gain[0] as f32 * r.data[i] + gain[1] as f32)) / c;
                if u.abs() >= 1.0 {
                    continue;
                }
                let w = f64::from((1.0 - u * u) * (1.0 - u * u));
                let x = f64::from(r.data[i]);
                s00 += w * x * x;
                s01 += w * x;
                s11 += w;
                b0 += w * x * f64::from(e);
                b1 += w * f64::from(e);
            }
            let det = s00 * s11 - s01 * s01;
            if det.abs() <= 1e-12 * (s00 * s11).max(1e-300) {
                break;
            }
            gain = [(b0 * s11 - b1 * s01) / det, (s00 * b1 - s01 * b0) / det];
        }
        (self.cost(f, [0.0; 2], d, gain, c) / self.cost(f, d, d, gain, c).max(1e-9)) as f32
    }

    /// Tukey's cost (scale `c`) of matching the frame at `x + at` under the gain and
    /// offset, over the pixels with detail whose match at `x + inside` lies in the frame.
    fn cost(&self, f: &Img, at: [f32; 2], inside: [f32; 2], gain: [f64; 2], c: f32) -> f64 {
        let r = &self.reference;
        let (w, h) = (r.w, r.h);
        let (xmax, ymax) = ((w - 1) as f32, (h - 1) as f32);
        let mut sum = 0.0f64;
        for &i in &self.textured {
            let i = i as usize;
            let (x, y) = ((i % w) as f32, (i / w) as f32);
            let (ix, iy) = (x + inside[0], y + inside[1]);
            if !(0.0..=xmax).contains(&ix) || !(0.0..=ymax).contains(&iy) {
                continue;
            }
            let (sx, sy) = ((x + at[0]).clamp(0.0, xmax), (y + at[1]).clamp(0.0, ymax));
            let e = bilinear(f, sx, sy) - r.data[i];
            let u = (e - (gain[0] as f32 * r.data[i] + gain[1] as f32)) / c;
            let v = 1.0 - u * u;
            sum += if u.abs() >= 1.0 {
                1.0
            } else {
                f64::from(1.0 - v * v * v)
            };
        }
        sum
    }
}

/// Bilinear sample of `img` at `(x, y)` inside `[0, w−1] × [0, h−1]`.
fn bilinear(img: &Img, x: f32, y: f32) -> f32 {
    let x0 = (x.floor() as usize).min(img.w - 1);
    let y0 = (y.floor() as usize).min(img.h - 1);
    let x1 = (x0 + 1).min(img.w - 1);
    let y1 = (y0 + 1).min(img.h - 1);
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let r0 = img.row(y0);
    let r1 = img.row(y1);
    let top = r0[x0] + (r0[x1] - r0[x0]) * fx;
    let bot = r1[x0] + (r1[x1] - r1[x0]) * fx;
    top + (bot - top) * fy
}

/// The 2-D spectrum of `img` less its mean, Hann-windowed (so the transform's wrap-around
/// joins faded edges), in a `pw × ph` box (its own size: both powers of two).
fn spectrum(img: &Img, pw: usize, ph: usize) -> (Vec<f64>, Vec<f64>) {
    let mean = img.data.iter().map(|&v| f64::from(v)).sum::<f64>() / img.data.len() as f64;
    let hann = |i: usize, n: usize| {
        if n < 2 {
            1.0
        } else {
            0.5 - 0.5 * (std::f64::consts::TAU * i as f64 / (n - 1) as f64).cos()
        }
    };
    let wx: Vec<f64> = (0..img.w).map(|x| hann(x, img.w)).collect();
    let mut re = vec![0.0; pw * ph];
    for y in 0..img.h {
        let wy = hann(y, img.h);
        for (x, &v) in img.row(y).iter().enumerate() {
            re[y * pw + x] = (f64::from(v) - mean) * wx[x] * wy;
        }
    }
    let mut im = vec![0.0; pw * ph];
    fft_2d(&mut re, &mut im, pw, ph);
    (re, im)
}

/// Phase correlation of a frame's spectrum `f` against the reference's `r`: the shift of
/// the frame's content (pixels, sub-pixel from the peak's larger neighbour on each axis)
/// and the peak's height.
fn correlate(
    r: &(Vec<f64>, Vec<f64>),
    f: (&[f64], &[f64]),
    pw: usize,
    ph: usize,
) -> ([f32; 2], f32) {
    let n = pw * ph;
    // normalised cross-power F · conj(R) / |F · conj(R)|, conjugated for the inverse
    let mut re = vec![0.0; n];
    let mut im = vec![0.0; n];
    let mut top = 0.0f64;
    for k in 0..n {
        let (a, b) = (f.0[k], f.1[k]);
        let (c, d) = (r.0[k], r.1[k]);
        let (x, y) = (a * c + b * d, b * c - a * d);
        top = top.max(x.hypot(y));
    }
    let floor = top * 1e-9;
    for k in 0..n {
        let (a, b) = (f.0[k], f.1[k]);
        let (c, d) = (r.0[k], r.1[k]);
        let (x, y) = (a * c + b * d, b * c - a * d);
        let m = x.hypot(y);
        if m > floor {
            re[k] = x / m;
            im[k] = -y / m;
        }
    }
    // inverse by the forward transform of the conjugate (the real part is all we need)
    fft_2d(&mut re, &mut im, pw, ph);
    let at = |x: isize, y: isize| {
        let xi = x.rem_euclid(pw as isize) as usize;
        let yi = y.rem_euclid(ph as isize) as usize;
        re[yi * pw + xi] / n as f64
    };
    let (mut best, mut bx, mut by) = (f64::NEG_INFINITY, 0isize, 0isize);
    for y in 0..ph {
        for x in 0..pw {
            let v = re[y * pw + x];
            if v > best {
                (best, bx, by) = (v, x as isize, y as isize);
            }
        }
    }
    let peak = best / n as f64;
    // Foroosh, Zerubia & Berthod 2002: the correlation of a sub-pixel shift δ is a
    // sampled sinc, so a neighbour over itself plus the peak is |δ| on its side; both
    // sides are taken (the far one is ≤ 0 for a pure shift), so a peak spread evenly by
    // the window stays centred
    let sub = |m: f64, c: f64, p: f64| {
        if c <= 0.0 {
            return 0.0;
        }
        let side = |v: f64| if v > 0.0 { v / (v + c) } else { 0.0 };
        (side(p) - side(m)).clamp(-0.5, 0.5)
    };
    let dx = sub(at(bx - 1, by), peak, at(bx + 1, by));
    let dy = sub(at(bx, by - 1), peak, at(bx, by + 1));
    let signed = |i: isize, n: usize| {
        if i > n as isize / 2 {
            i - n as isize
        } else {
            i
        }
    };
    (
        [
            (signed(bx, pw) as f64 + dx) as f32,
            (signed(by, ph) as f64 + dy) as f32,
        ],
        peak as f32,
    )
}

// ---------------------------------------------------------------------------------------
// The path of a shot's camera, and holding it still
// ---------------------------------------------------------------------------------------

/// The tracks of a run of frames against one reference.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraPath {
    pub tracks: Vec<Track>,
    /// The size the offsets are in (the source frames').
    pub source: Size,
}

/// How a run of frames is held still: each frame `i` read at `x + shift(i)`, scaled by
/// `zoom` about the frame's centre so no frame shows past its edge.
#[derive(Clone, Debug, PartialEq)]
pub struct Steadying {
    /// Per frame of the path, in source pixels.
    pub shifts: Vec<[f32; 2]>,
    pub zoom: f32,
    pub source: Size,
}

impl CameraPath {
    /// Whether frame `i`'s track is used: trusted ([`Track::tracked`]) and not an outlier,
    /// i.e. within 2 % of the frame's diagonal of the median of its trusted neighbours two
    /// frames either side (a camera does not jump there and back in a frame; a blurred or
    /// flash frame's match does).
    pub fn usable(&self, i: usize) -> bool {
        let Some(t) = self.tracks.get(i).filter(|t| t.tracked()) else {
            return false;
        };
        let near: Vec<[f32; 2]> = (i.saturating_sub(2)..(i + 3).min(self.tracks.len()))
            .filter(|&j| j != i && self.tracks[j].tracked())
            .map(|j| self.tracks[j].offset)
            .collect();
        if near.len() < 2 {
            return true;
        }
        let m = median_point(&near);
        let diag = (self.source.width as f32).hypot(self.source.height as f32);
        (t.offset[0] - m[0]).hypot(t.offset[1] - m[1]) <= 0.02 * diag
    }

    /// [`CameraPath::usable`] of every frame.
    fn usable_all(&self) -> Vec<bool> {
        (0..self.tracks.len()).map(|i| self.usable(i)).collect()
    }

    /// The share of frames tracked with confidence ([`CameraPath::usable`]).
    pub fn tracked_share(&self) -> f32 {
        share(&self.usable_all())
    }

    /// Whether `auto` steadies the path's frames, and how (see
    /// [`CameraPath::steadying`]); `forced` (`--stabilise on`) skips the tests that the
    /// camera moves and that the shifts are the camera's. `Err` says why not, in words.
    pub fn decide(&self, forced: bool) -> Result<Steadying, String> {
        let usable = self.usable_all();
        let share = share(&usable);
        let Some(offsets) = self.offsets_of(&usable).filter(|_| share >= TRACKED_MIN) else {
            return Err(format!(
                "the camera could not be tracked: {:.0} % of the frames match the first (at least {:.0} % needed; a pan, a cut, or a shot with little still detail)",
                share * 100.0,
                TRACKED_MIN * 100.0
            ));
        };
        let wander = wander_of(&offsets);
        if !forced {
            let least = wander_min(self.source);
            if wander < least {
                return Err(format!(
                    "the camera is still: the view wanders {wander:.1} px at most (under {least:.1} px)"
                ));
            }
            let mut ex: Vec<f32> = self
                .tracks
                .iter()
                .zip(&usable)
                .filter(|(t, &u)| u && t.offset[0].hypot(t.offset[1]) >= 1.0)
                .map(|(t, _)| t.explains)
                .collect();
            ex.sort_by(f32::total_cmp);
            let med = ex.get(ex.len() / 2).copied().unwrap_or(1.0);
            if med < EXPLAINS_MIN {
                return Err(format!(
                    "the view's shifts (up to {wander:.1} px) hardly explain the frames (×{med:.2}, at least ×{EXPLAINS_MIN} for a camera): what moves is the fire's light, not the camera"
                ));
            }
        }
        let s = steadying_of(&offsets, self.source);
        if s.zoom > ZOOM_MAX {
            return Err(format!(
                "the camera moves too far to steady: the frames would be zoomed ×{:.2} (at most ×{ZOOM_MAX})",
                s.zoom
            ));
        }
        Ok(s)
    }

    /// Offsets of every frame, the untracked ones interpolated linearly between their
    /// tracked neighbours (held at the ends); `None` when no frame is tracked.
    pub fn offsets(&self) -> Option<Vec<[f32; 2]>> {
        self.offsets_of(&self.usable_all())
    }

    /// [`CameraPath::offsets`] given each frame's [`CameraPath::usable`].
    fn offsets_of(&self, usable: &[bool]) -> Option<Vec<[f32; 2]>> {
        let known: Vec<(usize, [f32; 2])> = self
            .tracks
            .iter()
            .enumerate()
            .filter(|&(i, _)| usable[i])
            .map(|(i, t)| (i, t.offset))
            .collect();
        if known.is_empty() {
            return None;
        }
        let mut k = 0;
        Some(
            (0..self.tracks.len())
                .map(|i| {
                    while k + 1 < known.len() && known[k + 1].0 <= i {
                        k += 1;
                    }
                    let (ia, a) = known[k];
                    match known.get(k + 1) {
                        Some(&(ib, b)) if i > ia => {
                            let t = (i - ia) as f32 / (ib - ia) as f32;
                            [a[0] + (b[0] - a[0]) * t, a[1] + (b[1] - a[1]) * t]
                        }
                        _ => a,
                    }
                })
                .collect(),
        )
    }

    /// How far the view wanders (source pixels): the largest distance of a frame's
    /// offset from their median position; 0 when no frame is tracked.
    pub fn wander(&self) -> f32 {
        self.offsets().map_or(0.0, |o| wander_of(&o))
    }

    /// The steadying of the path's frames: every frame shifted onto the middle of their
    /// views, and the zoom that keeps the shifted frames inside the picture. `None` when
    /// no frame is tracked.
    pub fn steadying(&self) -> Option<Steadying> {
        Some(steadying_of(&self.offsets()?, self.source))
    }
}

/// The share of `true`s (0 for none).
fn share(flags: &[bool]) -> f32 {
    if flags.is_empty() {
        return 0.0;
    }
    flags.iter().filter(|&&u| u).count() as f32 / flags.len() as f32
}

/// [`CameraPath::wander`] of offsets.
fn wander_of(o: &[[f32; 2]]) -> f32 {
    if o.is_empty() {
        return 0.0;
    }
    let c = median_point(o);
    o.iter()
        .map(|p| (p[0] - c[0]).hypot(p[1] - c[1]))
        .fold(0.0, f32::max)
}

/// [`CameraPath::steadying`] of (non-empty) offsets.
fn steadying_of(o: &[[f32; 2]], source: Size) -> Steadying {
    let c = middle_point(o);
    let shifts: Vec<[f32; 2]> = o.iter().map(|p| [p[0] - c[0], p[1] - c[1]]).collect();
    let zoom = zoom_for(&shifts, source);
    Steadying {
        shifts,
        zoom,
        source,
    }
}

/// The zoom about the centre that keeps frames shifted by `shifts` inside the picture.
fn zoom_for(shifts: &[[f32; 2]], source: Size) -> f32 {
    let (mx, my) = shifts.iter().fold((0.0f32, 0.0f32), |(a, b), s| {
        (a.max(s[0].abs()), b.max(s[1].abs()))
    });
    let (w, h) = (source.width as f32, source.height as f32);
    (w / (w - 2.0 * mx).max(1.0)).max(h / (h - 2.0 * my).max(1.0))
}

impl Steadying {
    /// The same steadying re-centred on the middle of frames `run`'s views (indices into
    /// its shifts), zoomed only as far as those frames need: what a loop made of them is
    /// written with (a slow pan over a long window would otherwise zoom every loop for the
    /// whole window's drift). Frames outside `run` keep their shifts, re-centred alike.
    pub fn for_run(&self, run: std::ops::Range<usize>) -> Steadying {
        let part = &self.shifts[run.start.min(self.shifts.len())..run.end.min(self.shifts.len())];
        if part.is_empty() {
            return self.clone();
        }
        let c = middle_point(part);
        let shifts: Vec<[f32; 2]> = self
            .shifts
            .iter()
            .map(|p| [p[0] - c[0], p[1] - c[1]])
            .collect();
        let zoom = zoom_for(
            &shifts[run.start.min(shifts.len())..run.end.min(shifts.len())],
            self.source,
        );
        Steadying {
            shifts,
            zoom,
            source: self.source,
        }
    }
}

/// The middle of points' extent on each axis: the view that needs the least zoom to hold
/// them all (the outliers are out already, [`CameraPath::usable`]).
fn middle_point(p: &[[f32; 2]]) -> [f32; 2] {
    let ext = |k: usize| {
        let (lo, hi) = p
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), q| {
                (a.min(q[k]), b.max(q[k]))
            });
        0.5 * (lo + hi)
    };
    [ext(0), ext(1)]
}

/// The per-axis median of points.
fn median_point(p: &[[f32; 2]]) -> [f32; 2] {
    let med = |k: usize| {
        let mut v: Vec<f32> = p.iter().map(|q| q[k]).collect();
        v.sort_by(f32::total_cmp);
        let n = v.len();
        if n % 2 == 1 {
            v[n / 2]
        } else {
            0.5 * (v[n / 2 - 1] + v[n / 2])
        }
    };
    [med(0), med(1)]
}

/// Catmull-Rom weights of the four taps around a sample at fraction `t`.
#[inline]
fn cubic(t: f32) -> [f32; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    [
        0.5 * (-t3 + 2.0 * t2 - t),
        0.5 * (3.0 * t3 - 5.0 * t2 + 2.0),
        0.5 * (-3.0 * t3 + 4.0 * t2 + t),
        0.5 * (t3 - t2),
    ]
}

/// Per output coordinate along one axis: the first of four source taps (clamped) and
/// their Catmull-Rom weights, for `out(u) = src(c + (u − c)/zoom + shift)`.
fn taps(n: usize, shift: f32, zoom: f32) -> Vec<([usize; 4], [f32; 4])> {
    let c = (n as f32 - 1.0) * 0.5;
    (0..n)
        .map(|u| {
            let s = c + (u as f32 - c) / zoom + shift;
            let f = s.floor();
            let t = s - f;
            let i = f as isize;
            let idx =
                std::array::from_fn(|k| (i - 1 + k as isize).clamp(0, n as isize - 1) as usize);
            (idx, cubic(t))
        })
        .collect()
}

/// `frame` held still: `out(x) = frame(c + (x − c)/zoom + shift)` (`shift` in this frame's
/// pixels, `c` its centre), Catmull-Rom, edge-clamped, colour kept ≥ 0 and alpha in
/// `0..=1`. An integer shift at zoom 1 copies pixels exactly.
pub fn steady_rgba(frame: &RgbaFrame, shift: [f32; 2], zoom: f32) -> RgbaFrame {
    let size = frame.size();
    let (w, h) = (size.width as usize, size.height as usize);
    if w == 0 || h == 0 {
        return frame.clone();
    }
    let tx = taps(w, shift[0], zoom);
    let ty = taps(h, shift[1], zoom);
    let src = frame.data();
    // horizontal pass over every source row, then vertical
    let mut mid = vec![[0.0f32; 4]; w * h];
    mid.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
        let row = &src[y * w..(y + 1) * w];
        for (o, (idx, wt)) in out.iter_mut().zip(&tx) {
            let mut s = [0.0f32; 4];
            for k in 0..4 {
                let p = row[idx[k]];
                for c in 0..4 {
                    s[c] += wt[k] * p[c];
                }
            }
            *o = s;
        }
    });
    let mut data = vec![[0.0f32; 4]; w * h];
    data.par_chunks_mut(w).enumerate().for_each(|(y, out)| {
        let (idx, wt) = ty[y];
        for (x, o) in out.iter_mut().enumerate() {
            let mut s = [0.0f32; 4];
            for k in 0..4 {
                let p = mid[idx[k] * w + x];
                for c in 0..4 {
                    s[c] += wt[k] * p[c];
                }
            }
            *o = [
                s[0].max(0.0),
                s[1].max(0.0),
                s[2].max(0.0),
                s[3].clamp(0.0, 1.0),
            ];
        }
    });
    RgbaFrame::from_vec(size, data).expect("same size")
}

/// [`steady_rgba`] of a grey frame (the metric frames a loop is chosen on, held still as
/// the render will be).
pub fn steady_gray(frame: &GrayFrame, shift: [f32; 2], zoom: f32) -> GrayFrame {
    let f = steady_rgba(&frame.to_rgba(), shift, zoom);
    GrayFrame::from_vec(frame.size(), f.data().iter().map(|p| p[0]).collect()).expect("same size")
}

/// The whole-pixel part of a track (`[0, 0]` for an untrusted one): what the cached
/// aligned metric frames were moved by ([`shift_whole`]).
pub fn whole_pixels(t: &Track) -> [i32; 2] {
    if t.tracked() {
        t.offset.map(|v| v.round().clamp(-1e6, 1e6) as i32)
    } else {
        [0, 0]
    }
}

/// `out(x, y) = src(x + dx, y + dy)`, edge-clamped, on a row-major `w × h` image of
/// pixels of `channels` values each (8-bit RGBA bytes: 4; grey `f32`s or `[f32; 4]`s: 1):
/// a whole-pixel move, no resampling.
pub fn shift_whole<T: Copy>(src: &[T], w: usize, h: usize, channels: usize, d: [i32; 2]) -> Vec<T> {
    if w == 0 || h == 0 || channels == 0 || src.len() != w * h * channels {
        return src.to_vec();
    }
    let mut out = Vec::with_capacity(src.len());
    let col = |x: usize| (x as i64 + i64::from(d[0])).clamp(0, w as i64 - 1) as usize;
    for y in 0..h {
        let sy = (y as i64 + i64::from(d[1])).clamp(0, h as i64 - 1) as usize;
        let row = &src[sy * w * channels..(sy + 1) * w * channels];
        for x in 0..w {
            let c = col(x) * channels;
            out.extend_from_slice(&row[c..c + channels]);
        }
    }
    out
}

/// The steadying of one source frame at another frame size: its shift in that size's
/// pixels.
pub fn shift_at(shift: [f32; 2], source: Size, size: Size) -> [f32; 2] {
    [
        shift[0] * size.width as f32 / source.width.max(1) as f32,
        shift[1] * size.height as f32 / source.height.max(1) as f32,
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A textured scene (sum of a few blobs and ridges), `w × h`, sampled at `(x − dx, y − dy)`.
    fn scene(w: u32, h: u32, dx: f32, dy: f32) -> RgbaFrame {
        let size = Size::new(w, h).unwrap();
        let data = (0..h)
            .flat_map(|y| {
                (0..w).map(move |x| {
                    let (u, v) = (x as f32 - dx, y as f32 - dy);
                    let g = 0.3
                        + 0.15 * (u * 0.11).sin() * (v * 0.07).cos()
                        + 0.1 * (u * 0.031 + v * 0.023).sin()
                        + 0.1
                            * ((u - 60.0).powi(2) + (v - 40.0).powi(2))
                                .sqrt()
                                .mul_add(0.2, 0.0)
                                .cos()
                        + 0.08 * (u * 0.19 + v * 0.05).sin();
                    let g = g.clamp(0.0, 1.0);
                    [g, g * 0.9, g * 0.8, 1.0]
                })
            })
            .collect();
        RgbaFrame::from_vec(size, data).unwrap()
    }

    /// `f` with a "flame" standing on the scene at `d` (it moves with the camera): a soft
    /// bright tongue whose inside changes with `phase`.
    fn with_flame(mut f: RgbaFrame, phase: f32, d: (f32, f32)) -> RgbaFrame {
        let (w, h) = (f.width(), f.height());
        for y in 0..h {
            for x in 0..w {
                let u = (x as f32 - d.0) / w as f32 - 0.5;
                let v = (y as f32 - d.1) / h as f32 - 0.6;
                let a = (-(u / 0.1).powi(2) - (v / 0.2).powi(2)).exp();
                let t = (0.5
                    + 0.5 * (x as f32 * 0.3 + phase * 2.1).sin() * (y as f32 * 0.17 - phase).cos())
                .powi(2);
                let p = f.get(x, y);
                let flame = [1.0, 0.6 * t + 0.2, 0.1 * t];
                f.set(
                    x,
                    y,
                    std::array::from_fn(|c| {
                        if c == 3 {
                            1.0
                        } else {
                            p[c] + (flame[c] - p[c]) * a
                        }
                    }),
                );
            }
        }
        f
    }

    #[test]
    fn sub_pixel_shifts_are_recovered_past_a_flame() {
        let reference = with_flame(scene(480, 270, 0.0, 0.0), 0.0, (0.0, 0.0));
        let tracker = Tracker::new(&TrackGray::from_rgba(&reference));
        for (i, &(dx, dy)) in [
            (0.0, 0.0),
            (3.0, -2.0),
            (-7.4, 5.3),
            (12.25, 0.5),
            (-0.3, -9.8),
        ]
        .iter()
        .enumerate()
        {
            let f = with_flame(scene(480, 270, dx, dy), 1.0 + i as f32, (dx, dy));
            let t = tracker.track(&TrackGray::from_rgba(&f));
            assert!(t.tracked(), "{dx},{dy}: peak {}", t.peak);
            let err = (t.offset[0] - dx).hypot(t.offset[1] - dy);
            // about a quarter of a tracking pixel (480×270 is tracked at 256×128: 1.9 px
            // across, 2.1 px down)
            assert!(err < 0.6, "{dx},{dy}: found {:?} (error {err})", t.offset);
        }
    }

    /// `f`'s colours times `k` (a fade from black).
    fn faded(mut f: RgbaFrame, k: f32) -> RgbaFrame {
        for p in f.data_mut() {
            for c in &mut p[..3] {
                *c *= k;
            }
        }
        f
    }

    #[test]
    fn the_reference_is_the_first_frame_unless_a_fade_hides_it() {
        let shot = |i: usize| {
            with_flame(
                scene(320, 180, i as f32, 0.5 * i as f32),
                i as f32,
                (0.0, 0.0),
            )
        };
        // as shot: the first frame
        let heads: Vec<TrackGray> = (0..8).map(|i| TrackGray::from_rgba(&shot(i))).collect();
        assert_eq!(choose_reference(&heads), Some(0));
        // a fade in from black over 8 frames: black frames have no detail to match
        let fade: Vec<TrackGray> = (0..12)
            .map(|i| TrackGray::from_rgba(&faded(shot(i), (i as f32 / 8.0).min(1.0))))
            .collect();
        let r = choose_reference(&fade).unwrap();
        assert!((1..8).contains(&r), "reference {r}");
        // tracked against it, the frames after the fade find the camera; against the
        // black first frame, none does
        for (i, g) in fade.iter().enumerate().skip(8) {
            let t = Tracker::new(&fade[r]).track(g);
            assert!(t.tracked(), "frame {i}: {t:?}");
            let want = [i as f32 - r as f32, 0.5 * (i as f32 - r as f32)];
            assert!(
                (t.offset[0] - want[0]).hypot(t.offset[1] - want[1]) < 0.6,
                "frame {i}: {t:?} against {want:?}"
            );
            assert!(!Tracker::new(&fade[0]).track(g).tracked());
        }
        assert_eq!(choose_reference(&[]), None);
    }

    #[test]
    fn unrelated_pictures_are_not_tracked() {
        let reference = scene(320, 240, 0.0, 0.0);
        let tracker = Tracker::new(&TrackGray::from_rgba(&reference));
        // noise: nothing in common with the reference
        let mut s = 12345u32;
        let size = Size::new(320, 240).unwrap();
        let noise = RgbaFrame::from_vec(
            size,
            (0..size.pixels())
                .map(|_| {
                    s = s.wrapping_mul(1664525).wrapping_add(1013904223);
                    let g = (s >> 8) as f32 / (1u32 << 24) as f32;
                    [g, g, g, 1.0]
                })
                .collect(),
        )
        .unwrap();
        let t = tracker.track(&TrackGray::from_rgba(&noise));
        assert!(!t.tracked(), "peak {}", t.peak);
        let same = tracker.track(&TrackGray::from_rgba(&reference));
        assert!(
            same.peak > 0.9 && same.offset.iter().all(|v| v.abs() < 1e-3),
            "{same:?}"
        );
    }

    #[test]
    fn srgba8_and_linear_greys_agree() {
        let f = scene(200, 120, 0.0, 0.0);
        let bytes: Vec<u8> = f
            .data()
            .iter()
            .flat_map(|p| {
                let e = |v: f32| (ignis_core::palette::linear_to_srgb(v) * 255.0).round() as u8;
                [e(p[0]), e(p[1]), e(p[2]), 255]
            })
            .collect();
        let a = TrackGray::from_srgba8(f.size(), &bytes).unwrap();
        let b = TrackGray::from_rgba(&f);
        let worst = a
            .img
            .data
            .iter()
            .zip(&b.img.data)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max);
        assert!(worst < 0.003, "{worst}");
        assert!(TrackGray::from_srgba8(f.size(), &bytes[4..]).is_none());
    }

    #[test]
    fn steadying_undoes_the_shifts_and_zooms_past_the_edges() {
        let shifts = [[0.0, 0.0], [4.0, -2.0], [-2.0, 6.0], [1.0, 1.0], [8.0, 0.0]];
        let size = Size::new(2000, 1000).unwrap();
        let path = CameraPath {
            tracks: shifts
                .iter()
                .map(|&offset| Track {
                    offset,
                    peak: 12.0,
                    explains: 2.0,
                })
                .collect(),
            source: size,
        };
        let s = path.steadying().unwrap();
        // middle view (3, 2); widest x shift 5, y 4
        assert_eq!(s.shifts[4], [5.0, -2.0]);
        let want = (2000.0f32 / 1990.0).max(1000.0 / 992.0);
        assert!((s.zoom - want).abs() < 1e-6, "{}", s.zoom);
        // a run of frames 0..2 is centred on its own middle view (2, -1) and zoomed for
        // its own widest shift (2 across, 1 down) only
        let run = s.for_run(0..2);
        assert_eq!(run.shifts[0], [-2.0, 1.0]);
        assert_eq!(run.shifts[4], [6.0, 1.0]);
        let want = (2000.0f32 / 1996.0).max(1000.0 / 998.0);
        assert!(
            (run.zoom - want).abs() < 1e-6 && run.zoom < s.zoom,
            "{}",
            run.zoom
        );
        assert!((path.wander() - 7.0).abs() < 1e-6);
        // an integer shift at zoom 1 copies pixels
        let f = scene(64, 48, 0.0, 0.0);
        let moved = steady_rgba(&f, [3.0, -2.0], 1.0);
        assert_eq!(moved.get(10, 10), f.get(13, 8));
        assert_eq!(moved.get(0, 47), f.get(3, 45));
        // a frame whose content moved by d, read at x + d, matches the reference inside
        let d = [2.5f32, -1.5];
        let shifted = scene(64, 48, d[0], d[1]);
        let back = steady_rgba(&shifted, d, 1.0);
        let worst = (8..40)
            .flat_map(|y| (8..56).map(move |x| (x, y)))
            .map(|(x, y)| (back.get(x, y)[0] - f.get(x, y)[0]).abs())
            .fold(0.0, f32::max);
        assert!(worst < 0.01, "{worst}");
        let g = steady_gray(&f.luminance(), [1.0, 0.0], 1.0);
        assert_eq!(g.get(5, 5), f.luminance().get(6, 5));
    }

    #[test]
    fn auto_steadies_only_a_camera_that_moves_the_picture() {
        let size = Size::new(400, 300).unwrap();
        let path = |f: &dyn Fn(usize) -> Track| CameraPath {
            tracks: (0..50).map(f).collect(),
            source: size,
        };
        let shake = |i: usize| [6.0 * (i as f32 * 0.7).sin(), 4.0 * (i as f32 * 0.4).cos()];
        let camera = path(&|i| Track {
            offset: shake(i),
            peak: 12.0,
            explains: 1.6,
        });
        let s = camera.decide(false).unwrap();
        assert!(
            s.zoom > 1.0 && s.zoom < 1.1 && s.shifts.len() == 50,
            "{s:?}"
        );
        let light = path(&|i| Track {
            offset: shake(i),
            peak: 12.0,
            explains: 1.05,
        });
        let why = light.decide(false).unwrap_err();
        assert!(why.contains("fire's light"), "{why}");
        assert!(light.decide(true).is_ok());
        let still = path(&|i| Track {
            offset: [0.1 * (i % 3) as f32, 0.0],
            peak: 12.0,
            explains: 1.0,
        });
        assert!(still.decide(false).unwrap_err().contains("still"));
        let lost = path(&|i| Track {
            offset: shake(i),
            peak: if i % 4 == 0 { 2.0 } else { 12.0 },
            explains: 1.6,
        });
        assert!(lost
            .decide(true)
            .unwrap_err()
            .contains("could not be tracked"));
        let far = path(&|i| Track {
            offset: [2.0 * i as f32 - 50.0, 0.0],
            peak: 12.0,
            explains: 1.6,
        });
        assert!(far.decide(false).unwrap_err().contains("too far"));
        // one wild match among steady ones is an outlier, not a shake
        let blip = path(&|i| Track {
            offset: if i == 20 { [80.0, 60.0] } else { [0.0, 0.0] },
            peak: 12.0,
            explains: 1.0,
        });
        assert!(!blip.usable(20) && blip.usable(19));
        assert!(blip.decide(false).unwrap_err().contains("still"));
    }

    #[test]
    fn whole_pixel_moves_clamp_at_the_edges() {
        let src: Vec<u8> = (0..12).collect();
        assert_eq!(
            shift_whole(&src, 4, 3, 1, [1, 0]),
            vec![1, 2, 3, 3, 5, 6, 7, 7, 9, 10, 11, 11]
        );
        assert_eq!(
            shift_whole(&src, 4, 3, 1, [0, -1]),
            vec![0, 1, 2, 3, 0, 1, 2, 3, 4, 5, 6, 7]
        );
        // pixels of two values move whole
        assert_eq!(
            shift_whole(&src, 2, 3, 2, [-1, 1]),
            vec![4, 5, 4, 5, 8, 9, 8, 9, 8, 9, 8, 9]
        );
        let t = Track {
            offset: [2.6, -0.4],
            peak: 12.0,
            explains: 1.0,
        };
        assert_eq!(whole_pixels(&t), [3, 0]);
        assert_eq!(whole_pixels(&Track::LOST), [0, 0]);
    }

    #[test]
    fn untracked_frames_are_filled_from_their_neighbours() {
        let t = |x: f32, peak: f32| Track {
            offset: [x, 0.0],
            peak,
            explains: 1.0,
        };
        let path = CameraPath {
            tracks: vec![
                t(9.0, 0.0),
                t(2.0, 10.0),
                t(5.0, 1.0),
                t(6.0, 10.0),
                t(1.0, 0.0),
            ],
            source: Size::new(10, 10).unwrap(),
        };
        let o: Vec<f32> = path.offsets().unwrap().iter().map(|p| p[0]).collect();
        assert_eq!(o, vec![2.0, 2.0, 4.0, 6.0, 6.0]);
        assert!((path.tracked_share() - 0.4).abs() < 1e-6);
        let none = CameraPath {
            tracks: vec![t(1.0, 0.0)],
            source: Size::new(10, 10).unwrap(),
        };
        assert!(none.offsets().is_none() && none.steadying().is_none());
    }
}
