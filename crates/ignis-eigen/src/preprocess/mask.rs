//! HSV masks and their clean-up: multi-range masks combined by union, intersection or
//! difference, then morphology and smoothing.
//!
//! Source: eigenfires-thesis.txt §3.2.1, eq. (3)–(4), Figure 17.
//!
//! Pixel conventions: input frames are linear light; the HSV thresholds are on the
//! **sRGB-encoded** colour (what an animator sees and what the thesis's 8-bit OpenCV
//! values mean), with H in degrees `0..360` and S, V in `0..=1`. A mask is an 8-bit
//! [`image::GrayImage`], 255 = inside, 0 = outside.

use crate::error::{EigenError, Result};
use crate::still::StillLights;
use ignis_core::palette::{linear_to_srgb, srgb_to_linear};
use ignis_core::RgbaFrame;
use image::GrayImage;
use serde::{Deserialize, Serialize};

/// A box in HSV space. `h[0] > h[1]` wraps around 360° (e.g. `[330, 30]` is the reds).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct HsvRange {
    /// Hue range in degrees, `0..=360`. Default `[0, 360]` (any hue).
    #[serde(default = "full_hue")]
    pub h: [f32; 2],
    /// Saturation range, `0..=1`. Default `[0, 1]`.
    #[serde(default = "unit")]
    pub s: [f32; 2],
    /// Value (brightness) range, `0..=1`. Default `[0, 1]`.
    #[serde(default = "unit")]
    pub v: [f32; 2],
}

fn full_hue() -> [f32; 2] {
    [0.0, 360.0]
}
fn unit() -> [f32; 2] {
    [0.0, 1.0]
}

/// How a layer's range combines with the mask built so far (thesis: "adding",
/// "subtracting", "difference").
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Combine {
    /// `mask ∪ range`.
    #[default]
    Union,
    /// `mask ∩ range`.
    Intersection,
    /// `mask \ range` (removes the range from the mask).
    Difference,
}

/// One repetition of eq. (4): a range and how it combines.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaskLayer {
    #[serde(flatten)]
    pub range: HsvRange,
    #[serde(default)]
    pub combine: Combine,
}

/// A morphological operation on the mask.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MorphOp {
    Dilate,
    Erode,
    Open,
    Close,
}

/// A morphology step: `op` with a disk (L2 norm) of `radius` pixels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Morph {
    pub op: MorphOp,
    /// Radius in pixels, `1..=50`.
    pub radius: u8,
}

/// Settings of [`flame_mask`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct MaskParams {
    /// Layers applied in order to an initially empty mask. Default: everything with
    /// V ≥ 0.3 (any hue), union the blue root of a flame (H 180–260°, S ≥ 0.3, V ≥ 0.12):
    /// works on flames filmed on a dark background.
    pub layers: Vec<MaskLayer>,
    /// Morphology steps applied in order. Default: close r=2, open r=1.
    pub morphology: Vec<Morph>,
    /// Gaussian smoothing of the mask (σ in pixels, 0 = off), re-thresholded at one half.
    /// Default 1.0.
    pub smooth_sigma: f32,
    /// Canny thresholds `[low, high]` (on 8-bit gradient magnitudes) for the `edges`
    /// stage image; the edges are for inspection and do not change the mask. Default
    /// `[50, 100]`.
    pub canny: [f32; 2],
    /// Flame isolation on cluttered footage (a lit jar, a lit wall): `auto` (default)
    /// turns it on for a clip whose mask is mostly static lit surroundings (see
    /// [`static_fraction`]), `on` always, `off` never. See [`isolate_flame`].
    pub isolate: Isolate,
    /// Darkest sRGB-encoded luminance an isolated flame reaches, `0..1`. Default 0.3.
    pub isolate_floor: f32,
    /// With isolation, mask pixels at least this saturated (sRGB HSV S) are kept as
    /// flame where they connect to the isolated flame: a flame's own light is saturated
    /// (orange, red, its blue root), the surfaces it lights are paler (the lit jar of
    /// candle.mp4: 3 % of its lit pixels reach 0.5; the fire of fireball.mp4: all); a
    /// saturated glint away from the flame (a jar's rim) is not flame. Default 0.5.
    pub isolate_saturation: f32,
    /// With isolation, how much weaker than the strongest edge (`0..1`, a fraction) the
    /// flame's outer edge may be and still be chosen over the edge of its white-hot core.
    /// Default 0.1.
    pub isolate_edge_tolerance: f32,
    /// With isolation, also drop lit islands ([`drop_lit_islands`]): parts of the
    /// isolated region away from the flame whose edge is soft — a surface the flame lights
    /// (candle.mp4's wax glowing through the jar), not a separate tongue. Default `false`:
    /// on some frames of candle.mp4 that wax glows as bright as the flame's core (linear
    /// grey ≥ 0.8), which issue 14's cover bound counts as flame, and sparing it only on
    /// those frames would make it blink in and out of the animation.
    pub isolate_lit_islands: bool,
    /// Find still lights over the clip (a lamp, a lit window: bright, steady, away from
    /// anything that flickers; [`crate::still`]) and keep them out of every frame's mask.
    /// Default `true`.
    pub still_lights: bool,
    /// Drop the parts of a frame's mask that hold no coloured pixel (white text or a
    /// burnt-in timecode, a white sign, a glint on glass) when the frame has coloured fire
    /// elsewhere ([`drop_colourless_parts`]). Default `true`.
    pub colourless_parts: bool,
}

/// When [`isolate_flame`] runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Isolate {
    #[default]
    Auto,
    On,
    Off,
}

impl Default for MaskParams {
    fn default() -> Self {
        MaskParams {
            layers: vec![
                MaskLayer {
                    range: HsvRange {
                        h: full_hue(),
                        s: unit(),
                        v: [0.3, 1.0],
                    },
                    combine: Combine::Union,
                },
                MaskLayer {
                    range: HsvRange {
                        h: [180.0, 260.0],
                        s: [0.3, 1.0],
                        v: [0.12, 1.0],
                    },
                    combine: Combine::Union,
                },
            ],
            morphology: vec![
                Morph {
                    op: MorphOp::Close,
                    radius: 2,
                },
                Morph {
                    op: MorphOp::Open,
                    radius: 1,
                },
            ],
            smooth_sigma: 1.0,
            canny: [50.0, 100.0],
            isolate: Isolate::Auto,
            isolate_floor: 0.3,
            isolate_saturation: 0.5,
            isolate_edge_tolerance: 0.1,
            isolate_lit_islands: false,
            still_lights: true,
            colourless_parts: true,
        }
    }
}

impl MaskParams {
    /// Checks every range and radius.
    pub fn validate(&self) -> Result<()> {
        if self.layers.is_empty() {
            return Err(EigenError::bad(
                "mask.layers",
                "needs at least one HSV range",
            ));
        }
        for (i, l) in self.layers.iter().enumerate() {
            let r = &l.range;
            let ok_h = r.h.iter().all(|v| (0.0..=360.0).contains(v));
            let ok_sv =
                r.s.iter()
                    .chain(r.v.iter())
                    .all(|v| (0.0..=1.0).contains(v));
            if !ok_h || !ok_sv || r.s[0] > r.s[1] || r.v[0] > r.v[1] {
                return Err(EigenError::bad(
                    "mask.layers",
                    format!("layer {i}: h must be within 0..=360, s and v within 0..=1 with min <= max (got h={:?} s={:?} v={:?})", r.h, r.s, r.v),
                ));
            }
        }
        for m in &self.morphology {
            if m.radius == 0 || m.radius > 50 {
                return Err(EigenError::bad(
                    "mask.morphology",
                    format!("radius {} must be within 1..=50", m.radius),
                ));
            }
        }
        if !(0.0..=50.0).contains(&self.smooth_sigma) {
            return Err(EigenError::bad(
                "mask.smooth_sigma",
                "must be within 0..=50 pixels",
            ));
        }
        if !(0.0..1.0).contains(&self.isolate_edge_tolerance) {
            return Err(EigenError::bad(
                "mask.isolate_edge_tolerance",
                "must be within 0..1",
            ));
        }
        if !(0.0..=1.0).contains(&self.isolate_saturation) {
            return Err(EigenError::bad(
                "mask.isolate_saturation",
                "must be within 0..=1",
            ));
        }
        if !(0.0..1.0).contains(&self.isolate_floor) {
            return Err(EigenError::bad("mask.isolate_floor", "must be within 0..1"));
        }
        // imageproc's hysteresis walks off the image when low = 0 (every zero-gradient
        // border pixel counts as an edge), so low must be positive.
        if !(self.canny[0] > 0.0 && self.canny[0] <= self.canny[1] && self.canny[1] <= 1e6) {
            return Err(EigenError::bad(
                "mask.canny",
                format!(
                    "{:?}: needs 0 < low <= high <= 1e6, e.g. [50, 100]",
                    self.canny
                ),
            ));
        }
        Ok(())
    }
}

/// The HSV (eq. (3)) of a linear pixel's sRGB-encoded colour, as the mask layers see it.
fn pixel_hsv(px: &[f32; 4]) -> (f32, f32, f32) {
    rgb_to_hsv(srgb_encode(px[0]), srgb_encode(px[1]), srgb_encode(px[2]))
}

/// sRGB-encoded RGB (`0..=1`) → (H degrees, S, V), eq. (3).
pub fn rgb_to_hsv(r: f32, g: f32, b: f32) -> (f32, f32, f32) {
    let max = r.max(g).max(b);
    let min = r.min(g).min(b);
    let d = max - min;
    let v = max;
    let s = if max > 0.0 { d / max } else { 0.0 };
    let h = if d <= 0.0 {
        0.0
    } else if max == r {
        60.0 * ((g - b) / d).rem_euclid(6.0)
    } else if max == g {
        60.0 * ((b - r) / d + 2.0)
    } else {
        60.0 * ((r - g) / d + 4.0)
    };
    (h, s, v)
}

impl HsvRange {
    /// Whether an (H, S, V) triple lies in the range (hue wraps when `h[0] > h[1]`).
    pub fn contains(&self, h: f32, s: f32, v: f32) -> bool {
        let in_h = if self.h[0] <= self.h[1] {
            h >= self.h[0] && h <= self.h[1]
        } else {
            h >= self.h[0] || h <= self.h[1]
        };
        in_h && s >= self.s[0] && s <= self.s[1] && v >= self.v[0] && v <= self.v[1]
    }
}

/// The raw HSV mask of eq. (4) repeated over `layers` (no morphology).
pub fn hsv_mask(frame: &RgbaFrame, layers: &[MaskLayer]) -> GrayImage {
    let (w, h) = (frame.width(), frame.height());
    let mut out = GrayImage::new(w, h);
    let mut last = LastColour::default();
    for (px, o) in frame.data().iter().zip(out.as_mut().iter_mut()) {
        *o = last.of(px, |px| {
            let (hh, s, v) = pixel_hsv(px);
            let mut m = false;
            for l in layers {
                let inside = l.range.contains(hh, s, v);
                m = match l.combine {
                    Combine::Union => m || inside,
                    Combine::Intersection => m && inside,
                    Combine::Difference => m && !inside,
                };
            }
            if m {
                255
            } else {
                0
            }
        });
    }
    out
}

/// The last pixel's colour and what was computed from it. Footage repeats colours pixel
/// after pixel (a frame of `campfire.mp4` is 78 % repeats of the previous pixel, `candle.mp4`
/// and `fireball.mp4` 64 %: dark backgrounds, clipped cores), so per-pixel colour work —
/// sRGB encodes, HSV — is done once per run: the same values, as they depend on the colour
/// alone.
#[derive(Default)]
struct LastColour<T> {
    last: Option<([u32; 3], T)>,
}

impl<T: Copy> LastColour<T> {
    /// `f(px)`, a function of `px`'s colour (not its alpha), computed again only when the
    /// colour's bits differ from the last pixel's.
    #[inline]
    fn of(&mut self, px: &[f32; 4], f: impl FnOnce(&[f32; 4]) -> T) -> T {
        let key = [px[0].to_bits(), px[1].to_bits(), px[2].to_bits()];
        match self.last {
            Some((k, v)) if k == key => v,
            _ => {
                let v = f(px);
                self.last = Some((key, v));
                v
            }
        }
    }
}

/// Applies one morphology step: imageproc's L2 dilate / erode / open / close, bit for bit,
/// by runs of set pixels ([`super::dilate_l2`], [`super::erode_l2`]) rather than a
/// floating-point distance transform of the whole frame (a fifth of a clip's training).
pub fn morph(mask: &GrayImage, m: Morph) -> GrayImage {
    use super::{dilate_l2, erode_l2};
    let r = m.radius;
    match m.op {
        MorphOp::Dilate => dilate_l2(mask, r),
        MorphOp::Erode => erode_l2(mask, r),
        MorphOp::Open => dilate_l2(&erode_l2(mask, r), r),
        MorphOp::Close => erode_l2(&dilate_l2(mask, r), r),
    }
}

/// Gaussian smoothing of a binary mask, re-thresholded at 128 (rounds corners, removes
/// single-pixel specks).
pub fn smooth_mask(mask: &GrayImage, sigma: f32) -> GrayImage {
    if sigma <= 0.0 {
        return mask.clone();
    }
    // imageproc's Gaussian bit for bit, summing only where the mask changes value nearby
    let mut b = super::gaussian_blur_u8(mask, sigma);
    for v in b.as_mut().iter_mut() {
        *v = if *v >= 128 { 255 } else { 0 };
    }
    b
}

/// The full mask of §3.2.1: HSV layers, then morphology, then smoothing. When `isolate`,
/// the HSV mask is first restricted to the [`isolate_flame`] region and the saturated —
/// emissive — pixels connected to it, and the isolated region (dilated by 2 px) is added
/// back after the clean-up: specular reflections of the flame are as bright as the flame
/// and flicker with it, but thin, and opening would erase them.
pub fn flame_mask(frame: &RgbaFrame, p: &MaskParams, isolate: bool) -> GrayImage {
    flame_mask_without(frame, p, isolate, &StillLights::default())
}

/// [`flame_mask`] of a frame whose clip has `still` lights ([`crate::still`]): they are
/// blanked in the HSV mask and in the luminance the isolation measures (so a lamp at full
/// white is not a seed), and in the result.
pub fn flame_mask_without(
    frame: &RgbaFrame,
    p: &MaskParams,
    isolate: bool,
    still: &StillLights,
) -> GrayImage {
    let w = frame.width() as usize;
    let mut m = hsv_mask(frame, &p.layers);
    still.clear(m.as_mut(), w, 0);
    let mut bright = None;
    if isolate {
        let mut luma = luma8(frame);
        still.clear(&mut luma, w, 0);
        let keep = isolate_flame(
            &luma,
            frame.width(),
            frame.height(),
            p.isolate_floor,
            p.isolate_edge_tolerance,
            p.isolate_lit_islands,
        );
        // Kept: the isolated flame, and saturated (emissive) pixels connected to it — a
        // flame's own light is saturated (orange, red, its blue root), what it lights is
        // paler; a saturated glint on a jar's rim away from the flame is not flame.
        let mut b = GrayImage::new(frame.width(), frame.height());
        let mut cand = vec![false; m.as_raw().len()];
        let mut stack = Vec::new();
        let mut saturated = LastColour::default();
        for (i, ((&a, &k), px)) in m
            .as_raw()
            .iter()
            .zip(keep.as_raw())
            .zip(frame.data())
            .enumerate()
        {
            if a == 0 {
                continue;
            }
            if k > 0 {
                b.as_mut()[i] = 255;
                stack.push(i);
            } else {
                cand[i] = saturated.of(px, |px| pixel_hsv(px).1 >= p.isolate_saturation);
            }
        }
        let out = grow_into(&mut cand, stack, frame.width() as usize);
        m = out;
        bright = Some(morph(
            &b,
            Morph {
                op: MorphOp::Dilate,
                radius: 2,
            },
        ));
    }
    for step in &p.morphology {
        m = morph(&m, *step);
    }
    let mut m = smooth_mask(&m, p.smooth_sigma);
    if let Some(b) = bright {
        for (o, &v) in m.as_mut().iter_mut().zip(b.as_raw()) {
            *o = (*o).max(v);
        }
    }
    if p.colourless_parts {
        drop_colourless_parts(&mut m, frame);
    }
    still.clear(m.as_mut(), w, 0);
    m
}

/// A mask part is coloured when some pixel of it is at least this saturated (sRGB HSV S,
/// among pixels with V ≥ [`COLOURED_MIN_V`]).
const COLOURED: f32 = 0.1;
/// The dimmest pixel whose saturation counts: the blue root's floor in the default mask
/// layers (darker pixels' hue is noise, and the mask's closing can take some in).
const COLOURED_MIN_V: f32 = 0.12;
/// ... and parts without one are dropped only when the frame's most saturated masked pixel
/// reaches this: there is coloured fire to keep.
const FIRE_COLOURED: f32 = 0.2;

/// Removes from `mask` (255 = kept; the size of `frame`, linear light) every 8-connected
/// part that holds no pixel at least [`COLOURED`] saturated, when some masked pixel of the
/// frame reaches [`FIRE_COLOURED`]. Otherwise leaves it alone.
///
/// Why: fire always has colour somewhere — the orange, yellow or red of its body and rim,
/// its blue root — even where its core is clipped to white; white text, a burnt-in
/// timecode, a white sign or a glint on glass has none, and a timecode changes every frame,
/// so the still-light rule ([`crate::still`]) cannot catch it. A frame whose every part is
/// colourless (a flame overexposed to white everywhere) is kept whole. Measured (sRGB S,
/// the most saturated pixel of each part of ≥ 30 px, every 7th frame): candle.mp4's parts
/// 0.24–0.62 (isolated), campfire.mp4 ≥ 0.40, fireball.mp4 ≥ 0.74; white burnt-in text
/// over campfire.mp4 0.00. Deterministic; O(masked pixels).
pub fn drop_colourless_parts(mask: &mut GrayImage, frame: &RgbaFrame) {
    let w = mask.width() as usize;
    if mask.width() != frame.width() || mask.height() != frame.height() {
        return;
    }
    let mut open = vec![false; mask.as_raw().len()];
    let mut seeds = Vec::new();
    let mut most = 0.0f32;
    let mut hsv = LastColour::default();
    for (i, (&m, px)) in mask.as_raw().iter().zip(frame.data()).enumerate() {
        if m == 0 {
            continue;
        }
        open[i] = true;
        let (_, s, v) = hsv.of(px, pixel_hsv);
        if v >= COLOURED_MIN_V && s >= COLOURED {
            seeds.push(i);
            most = most.max(s);
        }
    }
    if most < FIRE_COLOURED {
        return;
    }
    *mask = grow_into(&mut open, seeds, w);
}

/// The pixels reachable (8-connected) from `seeds` through `open` pixels, as a mask (the
/// seeds included). `open` is consumed as the visited set.
fn grow_into(open: &mut [bool], mut stack: Vec<usize>, w: usize) -> GrayImage {
    let n = open.len();
    let h = n / w.max(1);
    let mut out = GrayImage::new(w as u32, h as u32);
    for &i in &stack {
        open[i] = false;
    }
    while let Some(i) = stack.pop() {
        out.as_mut()[i] = 255;
        let (x, y) = ((i % w) as isize, (i / w) as isize);
        for dy in -1..=1isize {
            for dx in -1..=1isize {
                let (xx, yy) = (x + dx, y + dy);
                if xx < 0 || yy < 0 || xx >= w as isize || yy >= h as isize {
                    continue;
                }
                let j = yy as usize * w + xx as usize;
                if open[j] {
                    open[j] = false;
                    stack.push(j);
                }
            }
        }
    }
    out
}

/// Tables for [`srgb_encode`] and [`srgb_encode8`].
struct SrgbTables {
    /// The 256 linear values of 8-bit sRGB codes (as decoders make them), ascending.
    lin: [f32; 256],
    /// `linear_to_srgb` of each.
    enc: [f32; 256],
    /// `bound[k]` (k ≥ 1): the linear value half-way between codes `k − 1` and `k`.
    bound: [f32; 256],
    /// Where the searches of [`srgb_encode`] and [`srgb_encode8`] start for a value in
    /// `0..=1`, by its bucket (its bits over [`BUCKET_SHIFT`]): the first `lin` not below
    /// the bucket's smallest value, and how many `bound[1..]` lie below it. A search then
    /// walks a step or two instead of bisecting 256 entries (three times a pixel).
    lin_from: Vec<u16>,
    bound_from: Vec<u16>,
}

/// An `f32` in `0..=1` falls in bucket `bits >> BUCKET_SHIFT` (5 mantissa bits: a bucket
/// spans at most a 32nd of its value, a few 8-bit codes at most).
const BUCKET_SHIFT: u32 = 18;
/// The bits of `1.0f32`: non-negative values up to it (not −0.0, not NaN) are bucketed.
const ONE_BITS: u32 = 0x3f80_0000;

fn srgb_tables() -> &'static SrgbTables {
    static T: std::sync::OnceLock<SrgbTables> = std::sync::OnceLock::new();
    T.get_or_init(|| {
        let lin = *ignis_core::palette::srgb8_to_linear_table();
        let bound: [f32; 256] =
            std::array::from_fn(|k| srgb_to_linear((k as f32 - 0.5).max(0.0) / 255.0));
        let lowest = |b: u32| f32::from_bits(b << BUCKET_SHIFT);
        let buckets = 0..=ONE_BITS >> BUCKET_SHIFT;
        SrgbTables {
            lin,
            enc: lin.map(linear_to_srgb),
            bound,
            lin_from: buckets
                .clone()
                .map(|b| lin.partition_point(|&v| v < lowest(b)) as u16)
                .collect(),
            bound_from: buckets
                .map(|b| bound[1..].partition_point(|&x| x < lowest(b)) as u16)
                .collect(),
        }
    })
}

/// `linear_to_srgb(c)`, exactly, fast for the values footage decoded from 8-bit sRGB
/// holds (a table look-up instead of a `powf`; other values take the formula).
pub fn srgb_encode(c: f32) -> f32 {
    let t = srgb_tables();
    let bits = c.to_bits();
    // the first code whose linear value is not below `c` (a bisection outside 0..=1)
    let k = if bits <= ONE_BITS {
        let mut k = t.lin_from[(bits >> BUCKET_SHIFT) as usize] as usize;
        while k < 256 && t.lin[k] < c {
            k += 1;
        }
        k
    } else {
        t.lin.partition_point(|&v| v < c)
    };
    if k < 256 && t.lin[k].to_bits() == c.to_bits() {
        t.enc[k]
    } else {
        linear_to_srgb(c)
    }
}

/// `(linear_to_srgb(c) * 255).round() as u8` for `c` in `0..=1`, exactly: the code from
/// the table of half-way values, the formula for values within a hair of a half-way
/// value (where rounding of the table and the formula could disagree).
pub fn srgb_encode8(c: f32) -> u8 {
    let t = srgb_tables();
    let bits = c.to_bits();
    // how many half-way values `c` reaches (a bisection outside 0..=1)
    let k = if bits <= ONE_BITS {
        let mut k = t.bound_from[(bits >> BUCKET_SHIFT) as usize] as usize;
        while k < 255 && t.bound[k + 1] <= c {
            k += 1;
        }
        k
    } else {
        t.bound[1..].partition_point(|&b| b <= c)
    };
    let near = |b: f32| (c - b).abs() <= b * 1e-4 + 1e-9;
    if near(t.bound[k.max(1)]) || (k < 255 && near(t.bound[k + 1])) {
        return (linear_to_srgb(c) * 255.0).round() as u8;
    }
    k as u8
}

/// sRGB-encoded luminance of a linear frame, 8-bit.
pub fn luma8(frame: &RgbaFrame) -> Vec<u8> {
    let mut last = LastColour::default();
    frame
        .data()
        .iter()
        .map(|p| {
            last.of(p, |p| {
                let l = 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
                srgb_encode8(l.clamp(0.0, 1.0))
            })
        })
        .collect()
}

/// sRGB-encoded HSV value (max channel) of a linear frame, 8-bit.
pub fn value8(frame: &RgbaFrame) -> Vec<u8> {
    let mut last = LastColour::default();
    frame
        .data()
        .iter()
        .map(|p| {
            last.of(p, |p| {
                srgb_encode8(p[0].max(p[1]).max(p[2]).clamp(0.0, 1.0))
            })
        })
        .collect()
}

/// Below this white ([`clip_white`], sRGB value: 15 of 255) a clip shows nothing but dark
/// noise.
pub const BLACK: f32 = 15.0 / 255.0;

/// Pixels a frame's white is read at by [`clip_white`]: its 16th-brightest, so a hot pixel
/// or a lone glint does not count.
const WHITE_RANK: usize = 16;

/// A clip's white, sRGB-encoded `0..1`: over sampled frames' 8-bit HSV values
/// ([`value8`]), the brightest of each frame's 16th-brightest pixel (a clip dark but for a
/// few frames of fire is judged by those; a hot pixel or a lone glint is not). Normally
/// exposed fire clips its core to white: `candle.mp4`, `campfire.mp4` and `fireball.mp4`
/// reach 1.0, the same clips two stops darker 0.56–0.59 (and still train). 0 for no frames.
pub fn clip_white(values: &[Vec<u8>]) -> f32 {
    let white = values
        .iter()
        .map(|v| {
            let mut hist = [0usize; 256];
            for &x in v {
                hist[x as usize] += 1;
            }
            let rank = WHITE_RANK.min(v.len().max(1));
            let mut seen = 0;
            (0..=255u8)
                .rev()
                .find(|&l| {
                    seen += hist[l as usize];
                    seen >= rank
                })
                .unwrap_or(0)
        })
        .max()
        .unwrap_or(0);
    f32::from(white) / 255.0
}

/// Levels of luminance (8-bit) over which [`isolate_flame`] measures the region's growth.
const GROWTH_STEP: usize = 12;
/// Growth over [`GROWTH_STEP`] levels that marks the flame region merging into lit
/// surroundings.
const MERGE_GROWTH: f64 = 1.5;

/// Flame isolation: the part of the frame lit by the flame itself, not by its light.
///
/// A flame is the brightest thing in its frame and ends at a sharp edge; what it lights
/// (a jar, a wall, the ground) is dimmer and fades smoothly. From seeds at the frame's
/// brightest pixels (within 8 levels of the maximum of `luma`, sRGB-encoded luminance),
/// a priority flood visits pixels in decreasing luminance down to `floor`, which gives
/// each pixel the threshold `τ` at which it joins the seeds' region `R(τ)`. Walking `τ`
/// down, the level below which the area grows fastest over the next 12 levels (by at
/// least [`MERGE_GROWTH`]) is where the flame's region merges into the lit surroundings
/// (a flame ends at a steep edge, few pixels per level; lit surroundings are a plateau);
/// above it, the mean luminance step between neighbours across each region's boundary is
/// measured, and the lowest `τ` whose step is within `tolerance` of the strongest (the
/// flame's outer edge) is chosen — but never below halfway from the median lit pixel
/// (≥ `floor`) to the peak: a flame is brighter than most of what it lights. Returns
/// the mask of the pixels at least as bright as `τ` (255 inside), connected or not — a
/// reflection or a second tongue not connected to the seeds is kept — less, with
/// `lit_islands`, the parts that are only a lit surface with a soft edge
/// ([`drop_lit_islands`]).
/// Deterministic; O(pixels). The thresholds adapt to each frame: nothing is tuned to a
/// clip.
pub fn isolate_flame(
    luma: &[u8],
    w: u32,
    h: u32,
    floor: f32,
    tolerance: f32,
    lit_islands: bool,
) -> GrayImage {
    let mut out = GrayImage::new(w, h);
    if let Some(lv) = isolate_levels(luma, w, h, floor, tolerance) {
        for (o, &v) in out.as_mut().iter_mut().zip(luma) {
            if v as usize >= lv.chosen {
                *o = 255;
            }
        }
        if lit_islands {
            let floor = (floor * 255.0).round() as usize;
            drop_lit_islands(&mut out, luma, lv.vmax.saturating_sub(8).max(floor));
        }
    }
    out
}

/// Removes from `keep` every 8-connected part that holds no seed (no pixel at least
/// `seed` bright in `luma`) and whose edge is less than a third as sharp as the seeded
/// parts' edge: the mean luminance step from its pixels to their 4-neighbours outside
/// `keep`, against the same mean over the parts that hold a seed.
///
/// Why: a flame — every separate tongue of a campfire or a wall of fire — ends at a sharp
/// edge (the same cue [`isolate_levels`] picks the threshold by); a surface it lights
/// fades smoothly, so where such a surface is brighter than the threshold (the wax of a
/// candle glowing through its jar) it forms an island with a soft edge. Measured: the lit
/// wax of candle.mp4 steps 0.15–0.26 of the flame's edge, the separate tongues of
/// campfire.mp4 0.43–0.98 (one small dim island 0.31). Relative to each frame's own flame:
/// nothing is tuned to a clip. The decision does not look at brightness beyond the seeds,
/// so a lit surface is dropped on every frame alike (no blinking). Deterministic;
/// O(pixels).
pub fn drop_lit_islands(keep: &mut GrayImage, luma: &[u8], seed: usize) {
    let w = keep.width() as usize;
    let n = keep.as_raw().len();
    if luma.len() != n || w == 0 {
        return;
    }
    let h = n / w;
    // The parts (8-connected, imageproc's labelling), each with (peak, step sum, count).
    let labels = imageproc::region_labelling::connected_components(
        keep,
        imageproc::region_labelling::Connectivity::Eight,
        image::Luma([0u8]),
    );
    let label = labels.as_raw();
    let mut parts = vec![(0usize, 0f64, 0u64); label.iter().max().map_or(0, |&m| m as usize)];
    let inside = |j: usize| keep.as_raw()[j] > 0;
    for (i, &l) in label.iter().enumerate() {
        let Some(part) = (l as usize).checked_sub(1).map(|k| &mut parts[k]) else {
            continue;
        };
        part.0 = part.0.max(luma[i] as usize);
        let (x, y) = (i % w, i / w);
        for (ok, j) in [
            (x > 0, i.wrapping_sub(1)),
            (x + 1 < w, i + 1),
            (y > 0, i.wrapping_sub(w)),
            (y + 1 < h, i + w),
        ] {
            if ok && !inside(j) {
                part.1 += (luma[i] as f64 - luma[j] as f64).abs();
                part.2 += 1;
            }
        }
    }
    let (fs, fc) = parts
        .iter()
        .filter(|p| p.0 >= seed)
        .fold((0f64, 0u64), |a, p| (a.0 + p.1, a.1 + p.2));
    if fc == 0 {
        return;
    }
    let flame_edge = fs / fc as f64;
    let drop: Vec<bool> = parts
        .iter()
        .map(|&(peak, sum, count)| {
            peak < seed && count > 0 && sum / (count as f64) < flame_edge / LIT_EDGE_RATIO
        })
        .collect();
    for (o, &l) in keep.as_mut().iter_mut().zip(label) {
        if l > 0 && drop[l as usize - 1] {
            *o = 0;
        }
    }
}

/// How many times sharper a flame's edge is than the soft edge of a lit island that
/// [`drop_lit_islands`] removes.
const LIT_EDGE_RATIO: f64 = 3.0;

/// What [`isolate_flame`] measured on a frame, per luminance level `τ` (8-bit).
#[derive(Clone, Debug)]
pub struct IsolateLevels {
    /// Brightest luminance of the frame.
    pub vmax: usize,
    /// Area of the seeds' region `R(τ)` (pixels).
    pub area: Vec<u64>,
    /// Mean luminance step across the boundary of `R(τ)`.
    pub edge: Vec<f64>,
    /// The merge level (the lowest level searched).
    pub merge: usize,
    /// The chosen threshold: every pixel at least this bright is flame.
    pub chosen: usize,
}

/// The measurements behind [`isolate_flame`]; `None` when nothing reaches `floor` or
/// `luma` is not `w × h`.
pub fn isolate_levels(
    luma: &[u8],
    w: u32,
    h: u32,
    floor: f32,
    tolerance: f32,
) -> Option<IsolateLevels> {
    let (w, h) = (w as usize, h as usize);
    let floor = (floor * 255.0).round() as usize;
    let vmax = luma.iter().copied().max().unwrap_or(0) as usize;
    if vmax < floor || luma.len() != w * h {
        return None;
    }
    let entry = entry_levels(luma, w, h, floor, vmax);
    let (area, mean) = boundary_steps(&entry, luma, w, h);
    let (stop, top) = merge_level(&area, vmax, floor);
    // The flame's edge: the strongest boundary above the merge; of the boundaries within
    // `tolerance` of it, the lowest (the outer edge of the flame rather than the edge of
    // its white-hot core).
    let strongest = (stop..=top.max(stop))
        .filter(|&t| area[t] > 0)
        .map(|t| mean[t])
        .fold(0.0f64, f64::max);
    let best = (stop..=top.max(stop))
        .find(|&t| area[t] > 0 && mean[t] >= (1.0 - tolerance as f64) * strongest)
        .unwrap_or(top);
    // Never below halfway from the median lit pixel to the peak: a flame is brighter than
    // most of what it lights (where no merge shows, the strongest edges can be the
    // outline of a lit jar against the dark).
    let mut lit: Vec<u8> = luma
        .iter()
        .copied()
        .filter(|&v| v as usize >= floor)
        .collect();
    let mid = lit.len() / 2;
    let median_lit = *lit.select_nth_unstable(mid).1 as usize;
    // And never above where the merge search starts (24 levels below the peak): the edge
    // of the white-hot core is not the flame's edge.
    let best = best
        .min(vmax.saturating_sub(24))
        .max((median_lit + vmax).div_ceil(2))
        .min(top.max(floor));
    // Everything at least that bright, connected to the seeds or not (a flame's
    // reflection, a second tongue), less the lit islands `isolate_flame` drops.
    Some(IsolateLevels {
        vmax,
        area: area.to_vec(),
        edge: mean.to_vec(),
        merge: stop,
        chosen: best,
    })
}

/// The entry level of each pixel in a flood from the brightest pixels down to `floor`
/// (a priority flood by luminance): the level at which it joins the seeds' region `R(τ)`,
/// −1 if never.
fn entry_levels(luma: &[u8], w: usize, h: usize, floor: usize, vmax: usize) -> Vec<i16> {
    let mut entry = vec![-1i16; w * h];
    let mut queued = vec![false; w * h];
    let mut buckets: Vec<Vec<u32>> = vec![Vec::new(); 256];
    let seed = vmax.saturating_sub(8).max(floor);
    for (i, &v) in luma.iter().enumerate() {
        if v as usize >= seed {
            queued[i] = true;
            buckets[v as usize].push(i as u32);
        }
    }
    let mut cur = 255usize;
    loop {
        let Some(i) = buckets[cur].pop() else {
            if cur <= floor {
                break;
            }
            cur -= 1;
            continue;
        };
        let i = i as usize;
        entry[i] = cur as i16;
        let (x, y) = (i % w, i / w);
        let mut push = |j: usize| {
            if !queued[j] {
                queued[j] = true;
                let v = luma[j] as usize;
                if v >= floor {
                    buckets[v.min(cur)].push(j as u32);
                }
            }
        };
        if x > 0 {
            push(i - 1);
        }
        if x + 1 < w {
            push(i + 1);
        }
        if y > 0 {
            push(i - w);
        }
        if y + 1 < h {
            push(i + w);
        }
    }
    entry
}

/// Area of `R(τ)` and the mean luminance step across its boundary, for every level τ.
fn boundary_steps(entry: &[i16], luma: &[u8], w: usize, h: usize) -> ([u64; 257], [f64; 257]) {
    let mut joined = [0u64; 257];
    for &e in entry {
        if e >= 0 {
            joined[e as usize] += 1;
        }
    }
    let mut area = [0u64; 257];
    for t in (0..256).rev() {
        area[t] = area[t + 1] + joined[t];
    }
    // A neighbour pair with entry levels a < b (−1 = never) is on the boundary of R(τ)
    // for a < τ <= b: difference arrays over τ.
    let mut dsum = [0f64; 258];
    let mut dcount = [0i64; 258];
    let mut pair = |i: usize, j: usize| {
        let (a, b) = (entry[i], entry[j]);
        if a != b {
            let (lo, hi) = (a.min(b), a.max(b));
            let d = (luma[i] as f64 - luma[j] as f64).abs();
            let (from, to) = ((lo + 1) as usize, (hi + 1) as usize);
            dsum[from] += d;
            dsum[to] -= d;
            dcount[from] += 1;
            dcount[to] -= 1;
        }
    };
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if x + 1 < w {
                pair(i, i + 1);
            }
            if y + 1 < h {
                pair(i, i + w);
            }
        }
    }
    let mut mean = [0f64; 257];
    let (mut s, mut c) = (0f64, 0i64);
    for t in 0..257 {
        s += dsum[t];
        c += dcount[t];
        mean[t] = if c > 0 { s / c as f64 } else { 0.0 };
    }
    (area, mean)
}

/// The merge level and the top of the search (`(stop, top)`); see [`isolate_levels`].
fn merge_level(area: &[u64; 257], vmax: usize, floor: usize) -> (usize, usize) {
    // The merge level: of the levels below the seeds, the one where the region grows
    // fastest over the next GROWTH_STEP levels down — a flame ends at a steep edge (few
    // pixels per level), lit surroundings are a plateau (many) — if it grows by at least
    // MERGE_GROWTH there; else nothing merges and the whole range down to `floor` is open.
    let top = vmax.saturating_sub(8).max(floor);
    let mut stop = floor;
    let mut fastest = MERGE_GROWTH;
    let mut t = vmax.saturating_sub(24);
    while t >= floor + GROWTH_STEP && t > 0 {
        let growth = area[t - GROWTH_STEP] as f64 / area[t].max(1) as f64;
        if growth > fastest {
            fastest = growth;
            stop = t;
        }
        t -= 1;
    }
    (stop, top)
}

/// Fraction of the lit pixels (V ≥ `floor`) of `samples` (8-bit sRGB values, one `Vec`
/// per sampled frame, same size) that stay within 0.08 of their temporal median: lit
/// surroundings are static, a flame is not. [`Isolate::Auto`] isolates the flame when
/// this exceeds [`STATIC_LIT`].
pub fn static_fraction(samples: &[Vec<u8>], floor: f32) -> f64 {
    let Some(n) = samples.first().map(Vec::len) else {
        return 0.0;
    };
    let floor = (floor * 255.0).round() as u8;
    let (mut lit, mut still) = (0u64, 0u64);
    let mut col = Vec::with_capacity(samples.len());
    for i in 0..n {
        col.clear();
        col.extend(samples.iter().filter_map(|s| s.get(i).copied()));
        if col.iter().all(|&v| v < floor) {
            continue;
        }
        let mut sorted = col.clone();
        sorted.sort_unstable();
        let med = sorted[sorted.len() / 2] as i32;
        for &v in &col {
            if v >= floor {
                lit += 1;
                if (v as i32 - med).abs() < 20 {
                    still += 1;
                }
            }
        }
    }
    if lit == 0 {
        0.0
    } else {
        still as f64 / lit as f64
    }
}

/// [`static_fraction`] above which [`Isolate::Auto`] isolates the flame. A flame on
/// black scores near 0 (fireball.mp4: 0.00); footage with lit surroundings 0.4–0.6
/// (candle.mp4 0.43, campfire.mp4 0.59).
pub const STATIC_LIT: f64 = 0.2;

/// Canny edges of the mask (for the `edges` stage image).
pub fn mask_edges(mask: &GrayImage, p: &MaskParams) -> GrayImage {
    imageproc::edges::canny(mask, p.canny[0], p.canny[1])
}

/// Number of pixels inside a mask, counted 255 bytes at a time in 8-bit sums, which the
/// compiler vectorises.
pub fn mask_area(mask: &GrayImage) -> usize {
    mask.as_raw()
        .chunks(255)
        .map(|c| c.iter().fold(0u8, |a, &v| a + (v > 0) as u8) as usize)
        .sum()
}

/// A mask steadied over time: per pixel 255 where at least two of the three binary masks
/// `a`, `b`, `c` (a frame's own `b` and its neighbours in the footage) are set, 0
/// elsewhere — a mask that collapses or flares on one frame alone takes its neighbours'
/// shape. Masks of different sizes do not vote: `b` is returned as it is.
pub fn majority3(a: &GrayImage, b: &GrayImage, c: &GrayImage) -> GrayImage {
    if a.dimensions() != b.dimensions() || c.dimensions() != b.dimensions() {
        return b.clone();
    }
    // Branch-free per byte (vectorised): majority of three bits = (x∧y) ∨ (x∧z) ∨ (y∧z).
    let data = a
        .as_raw()
        .iter()
        .zip(b.as_raw())
        .zip(c.as_raw())
        .map(|((&x, &y), &z)| {
            let (x, y, z) = (u8::from(x > 127), u8::from(y > 127), u8::from(z > 127));
            ((x & y) | (x & z) | (y & z)) * 255
        })
        .collect();
    GrayImage::from_raw(b.width(), b.height(), data).expect("the masks' size")
}

#[cfg(test)]
mod tests {

    /// Two of three votes keep a pixel: a mask that collapses or flares on one frame takes
    /// its neighbours' shape; masks of another size do not vote.
    #[test]
    fn majority3_keeps_what_two_of_three_masks_agree_on() {
        let full = GrayImage::from_fn(8, 6, |x, _| image::Luma([if x < 6 { 255 } else { 0 }]));
        let collapsed = GrayImage::from_fn(8, 6, |x, y| {
            image::Luma([if x < 2 && y < 2 { 255 } else { 0 }])
        });
        let flared = GrayImage::from_pixel(8, 6, image::Luma([255]));
        assert_eq!(majority3(&full, &collapsed, &full), full);
        assert_eq!(majority3(&full, &flared, &full), full);
        assert_eq!(majority3(&collapsed, &full, &collapsed), collapsed);
        let other = GrayImage::from_pixel(4, 4, image::Luma([0]));
        assert_eq!(majority3(&other, &collapsed, &other), collapsed);
    }

    /// Issue 18 defect 5: a zero low threshold is refused; the smallest accepted one runs.
    #[test]
    fn canny_thresholds_are_checked() {
        let mut p = MaskParams {
            canny: [0.0, 100.0],
            ..Default::default()
        };
        assert!(p.validate().is_err());
        p.canny = [f32::NAN, 100.0];
        assert!(p.validate().is_err());
        p.canny = [1e-6, 1e-6];
        p.validate().unwrap();
        let mut m = GrayImage::new(9, 7);
        for (i, v) in m.iter_mut().enumerate() {
            *v = ((i * 37) % 256) as u8;
        }
        let e = mask_edges(&m, &p);
        assert_eq!(e.dimensions(), (9, 7));
    }

    use super::*;
    use ignis_core::palette::srgb_to_linear;
    use ignis_core::Size;

    fn px(r: f32, g: f32, b: f32) -> [f32; 4] {
        [srgb_to_linear(r), srgb_to_linear(g), srgb_to_linear(b), 1.0]
    }

    /// The per-pixel colour work done once per run of one colour ([`LastColour`]) gives
    /// what each pixel gives alone: a frame of runs, repeats after a change and lone
    /// colours (and a NaN, −0.0 beside +0.0), against the same pixels as 1×1 frames.
    #[test]
    fn colour_runs_give_what_each_pixel_gives_alone() {
        let mut data = Vec::new();
        let colours = [
            px(0.0, 0.0, 0.0),
            px(1.0, 0.55, 0.1),
            px(0.9, 0.9, 0.85),
            [-0.0, 0.0, 0.0, 1.0],
            [0.0, f32::NAN, 0.2, 1.0],
            px(0.3, 0.1, 0.6),
            px(1.0, 1.0, 1.0),
            // colours that differ in one channel only
            px(1.0, 0.3, 0.1),
            px(1.0, 0.9, 0.1),
            px(1.0, 0.9, 0.6),
        ];
        let mut rng = ignis_core::Rng::new(5);
        for i in 0..600 {
            let c = colours[(i / 7 + i % 3) % colours.len()];
            let run = 1 + rng.below(5) as usize;
            // alpha varies inside a run: the work reads the colour only
            data.extend((0..run).map(|k| [c[0], c[1], c[2], 1.0 - 0.1 * k as f32]));
        }
        let n = data.len() as u32;
        let frame = RgbaFrame::from_vec(Size::new(n, 1).unwrap(), data.clone()).unwrap();
        let one = |p: [f32; 4]| RgbaFrame::from_vec(Size::new(1, 1).unwrap(), vec![p]).unwrap();
        let layers = MaskParams::default().layers;
        let mask = hsv_mask(&frame, &layers);
        let (luma, value) = (luma8(&frame), value8(&frame));
        let mut counted = 0;
        for (i, &p) in data.iter().enumerate() {
            let f = one(p);
            assert_eq!(
                mask.as_raw()[i],
                hsv_mask(&f, &layers).as_raw()[0],
                "pixel {i}"
            );
            assert_eq!(luma[i], luma8(&f)[0], "pixel {i}");
            assert_eq!(value[i], value8(&f)[0], "pixel {i}");
            counted += (mask.as_raw()[i] > 0) as usize;
        }
        assert!(
            counted > 0 && counted < data.len(),
            "{counted} of {}",
            data.len()
        );
        // and the work is done once per run
        let mut last = LastColour::default();
        let mut calls = 0;
        for p in &data {
            last.of(p, |_| calls += 1);
        }
        let runs = 1 + data
            .windows(2)
            .filter(|w| (0..3).any(|c| w[0][c].to_bits() != w[1][c].to_bits()))
            .count();
        assert_eq!(calls, runs);
    }

    /// White text beside an orange flame is dropped from the mask; a white core inside
    /// the flame's coloured rim stays; a frame whose only lit part is white (a flame
    /// overexposed everywhere) keeps it; through `flame_mask`, a burnt-in white label is
    /// left out and `colourless_parts = false` keeps it.
    #[test]
    fn colourless_parts_are_dropped_beside_coloured_fire() {
        let size = Size::new(40, 20).unwrap();
        let white = px(1.0, 1.0, 1.0);
        let orange = px(1.0, 0.55, 0.1);
        let mut f = RgbaFrame::new(size);
        let mut m = GrayImage::new(40, 20);
        for y in 4..16u32 {
            for x in 4..16u32 {
                // A flame: an orange rim around a white core.
                let core = (7..13).contains(&x) && (7..13).contains(&y);
                f.data_mut()[(y * 40 + x) as usize] = if core { white } else { orange };
                m.put_pixel(x, y, image::Luma([255]));
            }
            for x in 24..36u32 {
                // A white label, apart from it.
                f.data_mut()[(y * 40 + x) as usize] = white;
                m.put_pixel(x, y, image::Luma([255]));
            }
        }
        let mut kept = m.clone();
        drop_colourless_parts(&mut kept, &f);
        for y in 0..20 {
            for x in 0..40 {
                let want = if x < 20 { m.get_pixel(x, y)[0] } else { 0 };
                assert_eq!(kept.get_pixel(x, y)[0], want, "({x}, {y})");
            }
        }
        // Only the white label: nothing coloured to keep instead, so it stays.
        let mut alone = m.clone();
        for y in 0..20 {
            for x in 0..20 {
                alone.put_pixel(x, y, image::Luma([0]));
            }
        }
        let before = alone.clone();
        drop_colourless_parts(&mut alone, &f);
        assert_eq!(alone, before);
        // Through the whole mask.
        let p = MaskParams::default();
        let full = flame_mask(&f, &p, false);
        assert!(full.get_pixel(10, 10)[0] > 0 && full.get_pixel(30, 10)[0] == 0);
        let off = MaskParams {
            colourless_parts: false,
            ..Default::default()
        };
        assert!(flame_mask(&f, &off, false).get_pixel(30, 10)[0] > 0);
    }

    #[test]
    fn hsv_and_combine() {
        let (h, s, v) = rgb_to_hsv(1.0, 0.0, 0.0);
        assert_eq!((h, s, v), (0.0, 1.0, 1.0));
        assert!((rgb_to_hsv(0.0, 0.0, 1.0).0 - 240.0).abs() < 1e-4);
        let wrap = HsvRange {
            h: [330.0, 30.0],
            s: unit(),
            v: unit(),
        };
        assert!(
            wrap.contains(350.0, 0.5, 0.5)
                && wrap.contains(10.0, 0.5, 0.5)
                && !wrap.contains(90.0, 0.5, 0.5)
        );
        let f = RgbaFrame::from_vec(
            Size::new(3, 1).unwrap(),
            vec![px(1.0, 0.0, 0.0), px(0.0, 0.0, 1.0), px(0.0, 0.0, 0.0)],
        )
        .unwrap();
        let red = MaskLayer {
            range: HsvRange {
                h: [330.0, 30.0],
                s: [0.5, 1.0],
                v: [0.5, 1.0],
            },
            combine: Combine::Union,
        };
        let blue = MaskLayer {
            range: HsvRange {
                h: [200.0, 260.0],
                s: [0.5, 1.0],
                v: [0.5, 1.0],
            },
            combine: Combine::Union,
        };
        let bright = MaskLayer {
            range: HsvRange {
                h: full_hue(),
                s: unit(),
                v: [0.5, 1.0],
            },
            combine: Combine::Union,
        };
        assert_eq!(
            hsv_mask(&f, &[red.clone(), blue.clone()]).as_raw(),
            &vec![255, 255, 0]
        );
        let inter = MaskLayer {
            combine: Combine::Intersection,
            ..red.clone()
        };
        assert_eq!(
            hsv_mask(&f, &[bright.clone(), inter]).as_raw(),
            &vec![255, 0, 0]
        );
        let diff = MaskLayer {
            combine: Combine::Difference,
            ..red
        };
        assert_eq!(hsv_mask(&f, &[bright, diff]).as_raw(), &vec![0, 255, 0]);
    }

    /// Issue 14: on a lit plate (a jar), isolation keeps the flame, its saturated rim
    /// and a thin specular reflection of it, and drops the plate and a saturated glint
    /// away from the flame.
    #[test]
    fn isolation_keeps_flame_rim_and_reflection_not_plate_or_glint() {
        let (w, h) = (96u32, 96u32);
        let data = (0..w * h)
            .map(|i| {
                let (x, y) = ((i % w) as f32, (i / w) as f32);
                let r = ((x - 48.0).powi(2) + (y - 40.0).powi(2)).sqrt();
                if r < 7.0 {
                    px(1.0, 1.0, 0.97) // white-hot core
                } else if r < 10.0 {
                    px(1.0, 0.55, 0.1) // saturated orange edge of the flame
                } else if (80.0..83.0).contains(&y) && (10.0..20.0).contains(&x) {
                    px(0.8, 0.35, 0.1) // saturated glint on the rim, far from the flame
                } else if y == 20.0 && (70.0..80.0).contains(&x) {
                    px(1.0, 1.0, 1.0) // one-pixel specular reflection of the flame
                } else if (8.0..88.0).contains(&x) && (12.0..88.0).contains(&y) {
                    px(0.6, 0.5, 0.5) // the pale lit plate
                } else {
                    px(0.02, 0.02, 0.02)
                }
            })
            .collect();
        let f = RgbaFrame::from_vec(Size::new(w, h).unwrap(), data).unwrap();
        let p = MaskParams::default();
        let m = flame_mask(&f, &p, true);
        let at = |x: u32, y: u32| m.get_pixel(x, y)[0] > 0;
        assert!(
            at(48, 40) && at(48, 31),
            "the core and its orange edge are flame"
        );
        assert!(at(75, 20), "the thin reflection is kept");
        assert!(
            !at(15, 81),
            "the saturated glint away from the flame is not flame"
        );
        assert!(!at(20, 60) && !at(80, 70), "the lit plate is not flame");
        assert!(mask_area(&m) < 600, "{} px", mask_area(&m));
        // Without isolation the plate is kept.
        assert!(flame_mask(&f, &p, false).get_pixel(20, 60)[0] > 0);
    }

    /// Issue 14: two separate tongues (the second dimmer) are both kept; a lit patch as
    /// bright as the threshold but with a soft edge (the candle's wax glowing through its
    /// jar) is dropped.
    #[test]
    fn isolation_keeps_separate_tongues_drops_a_lit_island() {
        let (w, h) = (120usize, 80usize);
        let dist = |x: usize, y: usize, cx: f32, cy: f32| {
            ((x as f32 - cx).powi(2) + (y as f32 - cy).powi(2)).sqrt()
        };
        let luma: Vec<u8> = (0..w * h)
            .map(|i| {
                let (x, y) = (i % w, i / w);
                let (a, b, c) = (
                    dist(x, y, 30.0, 40.0),
                    dist(x, y, 75.0, 40.0),
                    dist(x, y, 105.0, 62.0),
                );
                if a < 10.0 {
                    (255.0 - 4.0 * a) as u8 // the main tongue
                } else if b < 8.0 {
                    (240.0 - 4.0 * b) as u8 // a separate, dimmer tongue
                } else if c < 12.5 {
                    (215.0 - 10.0 * c) as u8 // a lit island fading smoothly into the surface
                } else if (5..115).contains(&x) && (10..75).contains(&y) {
                    90 // the lit surface
                } else {
                    0
                }
            })
            .collect();
        let lv = isolate_levels(&luma, w as u32, h as u32, 0.3, 0.1).unwrap();
        assert!(
            lv.chosen <= 200,
            "the island passes the threshold {}",
            lv.chosen
        );
        let m = isolate_flame(&luma, w as u32, h as u32, 0.3, 0.1, true);
        let at = |x: u32, y: u32| m.get_pixel(x, y)[0] > 0;
        assert!(at(30, 40) && at(75, 40), "both tongues are kept");
        assert!(!at(105, 62), "the lit island is dropped");
        // Without `lit_islands` (the default) it is kept.
        let m = isolate_flame(&luma, w as u32, h as u32, 0.3, 0.1, false);
        assert!(m.get_pixel(105, 62)[0] > 0);
    }

    /// Issue 14: on a synthetic campfire (several tongues), isolation keeps every
    /// separate part of the plain mask that reaches the frame's peak brightness.
    #[test]
    fn isolation_keeps_every_tongue_of_a_synthetic_campfire() {
        use crate::synthetic::{synthetic_frame, FlameStyle, SyntheticParams};
        let sp = SyntheticParams {
            size: ignis_core::Size::new(320, 180).unwrap(),
            frames: 8,
            style: FlameStyle::Campfire,
            seed: 5,
        };
        let p = MaskParams {
            isolate_lit_islands: true,
            ..Default::default()
        };
        let mut tongues = 0;
        for t in 0..8 {
            let f = synthetic_frame(&sp, t).unwrap();
            let l = luma8(&f);
            let vmax = *l.iter().max().unwrap();
            let plain = flame_mask(&f, &p, false);
            let iso = flame_mask(&f, &p, true);
            let mut whole = plain.clone();
            // Each part of the plain mask holding a pixel within 8 levels of the peak.
            let n = whole.as_raw().len();
            for start in 0..n {
                if whole.as_raw()[start] == 0 {
                    continue;
                }
                let part = grow_into(
                    &mut whole.as_raw().iter().map(|&v| v > 0).collect::<Vec<_>>(),
                    vec![start],
                    320,
                );
                let idx: Vec<usize> = (0..n).filter(|&i| part.as_raw()[i] > 0).collect();
                for &i in &idx {
                    whole.as_mut()[i] = 0;
                }
                if idx.iter().any(|&i| l[i] + 8 >= vmax) {
                    tongues += 1;
                    assert!(
                        idx.iter().any(|&i| iso.as_raw()[i] > 0),
                        "frame {t}: a tongue of {} px was dropped",
                        idx.len()
                    );
                }
            }
        }
        assert!(
            tongues > 8,
            "the synthetic campfire has separate tongues ({tongues})"
        );
    }

    /// The bucketed searches find what bisecting the whole tables finds, for every value
    /// (a sweep of bit patterns over `0..=1`, the tables' own values and their neighbours,
    /// and values outside `0..=1`, −0.0 and NaN).
    #[test]
    fn bucketed_searches_equal_bisection() {
        let t = srgb_tables();
        let lin_ref = |c: f32| t.lin.partition_point(|&v| v < c);
        let bound_ref = |c: f32| t.bound[1..].partition_point(|&b| b <= c);
        let mut xs: Vec<f32> = (0..=ONE_BITS).step_by(101).map(f32::from_bits).collect();
        for &v in t.lin.iter().chain(&t.bound) {
            let bits = v.to_bits();
            xs.extend((bits.saturating_sub(3)..=bits + 3).map(f32::from_bits));
        }
        xs.extend([
            -0.0,
            -1e-9,
            -0.5,
            1.0,
            1.000_000_1,
            2.0,
            f32::INFINITY,
            f32::NAN,
        ]);
        for c in xs {
            let enc = if lin_ref(c) < 256 && t.lin[lin_ref(c)].to_bits() == c.to_bits() {
                t.enc[lin_ref(c)]
            } else {
                linear_to_srgb(c)
            };
            assert_eq!(srgb_encode(c).to_bits(), enc.to_bits(), "{c}");
            let k = bound_ref(c);
            let near = |b: f32| (c - b).abs() <= b * 1e-4 + 1e-9;
            let code = if near(t.bound[k.max(1)]) || (k < 255 && near(t.bound[k + 1])) {
                (linear_to_srgb(c) * 255.0).round() as u8
            } else {
                k as u8
            };
            assert_eq!(srgb_encode8(c), code, "{c}");
        }
    }

    #[test]
    fn srgb_tables_agree_with_the_formula() {
        let t = srgb_tables();
        for k in 0..256 {
            assert_eq!(srgb_encode(t.lin[k]), linear_to_srgb(t.lin[k]));
        }
        // A dense sweep, the half-way values and a few ulps either side of them.
        let mut xs: Vec<f32> = (0..=200_000).map(|i| i as f32 / 200_000.0).collect();
        for &b in &t.bound {
            let bits = b.to_bits();
            xs.extend((bits.saturating_sub(8)..bits + 8).map(f32::from_bits));
        }
        for x in xs.into_iter().filter(|x| (0.0..=1.0).contains(x)) {
            assert_eq!(srgb_encode(x), linear_to_srgb(x), "{x}");
            assert_eq!(
                srgb_encode8(x),
                (linear_to_srgb(x) * 255.0).round() as u8,
                "{x}"
            );
        }
    }

    #[test]
    fn the_white_ignores_hot_pixels_and_dark_frames() {
        let frame = |levels: &[(u8, usize)]| {
            let mut v = vec![0u8; 10_000];
            let mut i = 0;
            for &(l, n) in levels {
                v[i..i + n].fill(l);
                i += n;
            }
            v
        };
        // 15 hot pixels at 255 and a flame of 100 pixels at 120: the white is 120
        let flame = frame(&[(255, 15), (120, 100)]);
        assert_eq!(clip_white(std::slice::from_ref(&flame)), 120.0 / 255.0);
        // dark frames and one with the flame: the flame's
        let dark = frame(&[(40, 5000)]);
        let mut frames = vec![dark.clone(); 8];
        frames.extend([flame, dark]);
        assert_eq!(clip_white(&frames), 120.0 / 255.0);
        assert_eq!(clip_white(&[]), 0.0);
        // a frame of fewer than 16 pixels is read at its darkest
        assert_eq!(clip_white(&[vec![200, 50]]), 50.0 / 255.0);
    }

    #[test]
    fn defaults_validate() {
        MaskParams::default().validate().unwrap();
        let bad = MaskParams {
            layers: vec![],
            ..Default::default()
        };
        assert!(bad.validate().is_err());
    }
}
