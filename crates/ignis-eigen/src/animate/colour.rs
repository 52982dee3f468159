//! Colouring reconstructed Eigenfires from the original video: original colouring
//! (Algorithm 2), synthetic smoke and custom masks, plus the colour counterpart of the
//! pose warp so the original frames line up with the pre-processed grey frames.
//!
//! Source: /work/shared/seeds/eigenfires-thesis.txt §6.1.1 (Algorithm 2), §6.3 (producing
//! smoke), §6.4 (custom masks) and §7.1.2 (keeping the original video for the animation
//! stage). Synthetic colouring (§6.1.2) and bloom (§6.2) live in `ignis_core::colour` and
//! `ignis_core::post`; a bloom image tinted with them is Algorithm 2's `destination`.
//!
//! Pixel conventions: every frame is Ignis's linear-light `f32` with straight alpha
//! (`ignis_core::frame`). The thesis works on 8-bit values; here `0xff` is `1.0`.
//!
//! Departures from the thesis, and why:
//! - **Threshold units.** Algorithm 2's threshold (≈ 30 of 255 in the thesis) is compared
//!   with the grey image. The thesis's grey is 8-bit sRGB-coded; Ignis's is linear
//!   luminance. The default, [`THESIS_THRESHOLD`] = 0.0130, is 30/255 decoded with the sRGB
//!   curve, so the same pixels count as "above the threshold" (the convention
//!   [`crate::hermite`] uses for its thresholds too). The fade below it, `source /
//!   threshold`, is linear in linear light rather than in code values: it only concerns
//!   the darkest 30 code values, and it avoids a power function per pixel.
//! - **Saturation.** `saturate(v) = min(v, 0xff)` becomes `clamp(v, 0, 1)` per channel: as
//!   printed it clamps HDR values to 1, and the lower bound is what unsigned 8-bit values
//!   imply. Grey values below 0 (reconstruction noise) count as 0 for the same reason.
//!   Pixels above the threshold are copied unclamped, exactly as Algorithm 2 copies them.
//! - **Alpha** (the thesis has none) is treated as a fourth channel of Algorithm 2: copied
//!   from the original above the threshold, blended `scaleSrc · original + scaleDest ·
//!   destination + scaleDest · smoke` below it. With an empty destination the result is
//!   opaque where the fire was taken and fades out with the grey image; with a bloom
//!   destination whose alpha is `ignis_core::post::alpha_matte`, it fades into the glow.

use crate::error::{EigenError, Result};
use crate::footage::SourceFrame;
use crate::pose::{ClipPose, PoseParams};
use ignis_core::colour::SolidTintRamp;
use ignis_core::frame::LUMA;
use ignis_core::post::gaussian_blur;
use ignis_core::post::BloomRows;
use ignis_core::{CoreError, GrayFrame, RgbaFrame, Size};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::mem::MaybeUninit;

/// The thesis's threshold of 30 (of 255, sRGB-coded grey) as linear luminance:
/// `srgb_to_linear(30/255)` = 0.01298.
pub const THESIS_THRESHOLD: f32 = 0.0130;

/// Warps an original colour frame into the common frame exactly as
/// [`crate::pose::warp`] warps its grey frame (same translation, scale and rotation by
/// `−angle` about the fuel, same bilinear sampling), so that it lands pixel-aligned on the
/// pre-processed and reconstructed grey frames (§7.1.2).
///
/// All four channels are sampled with outside = 0, like the grey warp: RGB is black
/// outside the source and the alpha becomes the source's coverage (1 inside, 0 outside,
/// fractional on the one-pixel border). Because the warp is linear, the luminance of the
/// result equals the grey warp of the luminance up to rounding.
pub fn warp_rgba(src: &RgbaFrame, pose: &ClipPose, angle: f32, p: &PoseParams) -> RgbaFrame {
    let out = p.frame();
    if let Some((ox, oy)) = crate::pose::whole_pixel_offset(pose, angle, p) {
        // Scale 1, no rotation, whole-pixel offset: bilinear sampling is an exact copy.
        let (sw, sh) = (src.width() as i64, src.height() as i64);
        let mut data = vec![[0.0f32; 4]; out.pixels()];
        let ow = out.width as usize;
        data.par_chunks_mut(ow).enumerate().for_each(|(v, row)| {
            let sy = v as i64 - oy;
            if sy < 0 || sy >= sh {
                return;
            }
            let srow = &src.data()[(sy * sw) as usize..((sy + 1) * sw) as usize];
            for (u, o) in row.iter_mut().enumerate() {
                let sx = u as i64 - ox;
                if sx >= 0 && sx < sw {
                    *o = srow[sx as usize];
                }
            }
        });
        return RgbaFrame::from_vec(out, data).expect("frame_size pixels");
    }
    let cx = out.width as f32 / 2.0;
    let by = out.height as f32 * (1.0 - p.base_margin);
    let (s, c) = angle.sin_cos();
    let inv = 1.0 / pose.scale;
    let ow = out.width as usize;
    let mut data = vec![[0.0f32; 4]; out.pixels()];
    data.par_chunks_mut(ow).enumerate().for_each(|(v, row)| {
        for (u, o) in row.iter_mut().enumerate() {
            // the same expressions as `pose::warp`, so both sample the same points
            let dx = (u as f32 + 0.5 - cx) * inv;
            let dy = (v as f32 + 0.5 - by) * inv;
            let sx = pose.fuel_x + c * dx - s * dy;
            let sy = pose.base_y + s * dx + c * dy;
            *o = bilinear_rgba(src, sx - 0.5, sy - 0.5);
        }
    });
    RgbaFrame::from_vec(out, data).expect("frame_size pixels")
}

/// Bilinear sample of all four channels at continuous pixel coordinates (pixel centres
/// at integers); zero outside. The weights and order match [`crate::pose::bilinear`].
fn bilinear_rgba(src: &RgbaFrame, x: f32, y: f32) -> [f32; 4] {
    let (w, h) = (src.width() as i64, src.height() as i64);
    let (x0, y0) = (x.floor() as i64, y.floor() as i64);
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let d = src.data();
    let at = |xx: i64, yy: i64| {
        if xx < 0 || yy < 0 || xx >= w || yy >= h {
            [0.0; 4]
        } else {
            d[(yy * w + xx) as usize]
        }
    };
    let (p00, p10, p01, p11) = (
        at(x0, y0),
        at(x0 + 1, y0),
        at(x0, y0 + 1),
        at(x0 + 1, y0 + 1),
    );
    std::array::from_fn(|k| {
        let a = p00[k] * (1.0 - fx) + p10[k] * fx;
        let b = p01[k] * (1.0 - fx) + p11[k] * fx;
        a * (1.0 - fy) + b * fy
    })
}

/// How a custom mask (§6.4) enters original colouring.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum MaskMode {
    /// The custom mask is Algorithm 2's `source` instead of the reconstructed grey image
    /// (same threshold and fade).
    Replace,
    /// The custom mask is an extra layer that accepts more pixels from the original: the
    /// blend weight of the original is `max(scaleSrc, clamp(mask, 0, 1))`. A mask value of
    /// 1 takes the pixel as if it were above the threshold; a soft (feathered) mask value
    /// blends in between; 0 leaves the reconstructed image in charge.
    Add,
}

/// Settings of [`original_colouring`] (Algorithm 2).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct OriginalColour {
    /// Grey level (linear luminance, `0 < t ≤ 1`) above which the original colour is
    /// copied; below it colours fade out linearly. Default [`THESIS_THRESHOLD`] (0.013,
    /// the thesis's 30/255 on sRGB-coded grey). Raise it if reconstruction noise lets the
    /// original background through.
    pub threshold: f32,
    /// Add the smoke image below the threshold (Algorithm 2's `Enable_Smoke`); needs a
    /// smoke image. Default false.
    pub smoke: bool,
}

impl Default for OriginalColour {
    fn default() -> Self {
        OriginalColour {
            threshold: THESIS_THRESHOLD,
            smoke: false,
        }
    }
}

impl OriginalColour {
    pub fn validate(&self) -> Result<()> {
        if !(self.threshold > 0.0 && self.threshold <= 1.0) {
            return Err(EigenError::bad(
                "colour.threshold",
                format!(
                    "{} is outside 0 < threshold <= 1 (linear grey; the thesis's 30/255 \
                     is {THESIS_THRESHOLD})",
                    self.threshold
                ),
            ));
        }
        Ok(())
    }
}

fn check_size(what: &str, size: Size, expected: Size) -> Result<()> {
    if size != expected {
        return Err(CoreError::SizeMismatch(format!(
            "{what} is {size} but the grey source is {expected}; warp or resize it to the \
             common frame (colour::warp_rgba)"
        ))
        .into());
    }
    Ok(())
}

/// Original colouring, Algorithm 2 of §6.1.1, on every channel (alpha included, see the
/// module docs):
///
/// ```text
/// if source > threshold:  out = original
/// else:                   s = max(source, 0) / threshold
///                         out = clamp(s·original + (1−s)·destination + (1−s)·smoke, 0, 1)
/// ```
///
/// - `source`: the reconstructed grey frame (the mask).
/// - `original`: the original video frame, already in the common frame ([`warp_rgba`]).
/// - `destination`: `None` for the thesis's empty (all-zero) image, or a bloom image
///   (e.g. `ignis_core::post::bloom` tinted with `ignis_core::colour::synthetic_colour`).
/// - `smoke`: a [`synthetic_smoke`] image, added when `p.smoke` is set (ignored otherwise).
/// - `custom`: a custom mask and how to use it (§6.4, [`MaskMode`]); `None` when no mask
///   was rendered for this frame, so the reconstructed image is the mask.
///
/// Every frame must have the size of `source`; a mismatch is an error naming both sizes.
pub fn original_colouring(
    source: &GrayFrame,
    original: &RgbaFrame,
    destination: Option<&RgbaFrame>,
    smoke: Option<&RgbaFrame>,
    custom: Option<(&GrayFrame, MaskMode)>,
    p: &OriginalColour,
) -> Result<RgbaFrame> {
    let dest = destination.map_or(Destination::Empty, Destination::Image);
    original_colouring_to(source, original, dest, smoke, custom, p)
}

/// Algorithm 2's destination image for [`original_colouring_to`].
#[derive(Clone, Copy)]
pub enum Destination<'a> {
    /// The thesis's empty (all-zero) image.
    Empty,
    /// A colour image (e.g. a tinted bloom).
    Image(&'a RgbaFrame),
    /// `ignis_core::colour::synthetic_colour(bloom, &Tint::Solid(tint))`, made band by
    /// band as the colouring goes (the same values, without a whole frame of them).
    SolidTint(&'a GrayFrame, [f32; 3]),
    /// [`Destination::SolidTint`] of the bloom `ignis_core::post::bloom_rows` makes band
    /// by band (the same values, without a bloom frame either). The bloom must be of
    /// the grey `source` frame's size.
    SolidTintRows(&'a BloomRows<'a>, [f32; 3]),
}

/// The alpha the coloured pixels leave with (see [`original_colouring_matted`]).
#[derive(Clone, Copy)]
pub enum AlphaMatte<'a> {
    /// Algorithm 2's alpha.
    Keep,
    /// 1 everywhere.
    Opaque,
    /// The alpha matte of §6.2 on the grey `source` and the destination's bloom,
    /// `clamp(source + bloom, 0, 1)` (`ignis_core::post::alpha_matte`); with a `limit`
    /// matte (frames made from footage: the pre-processing matte), at least
    /// `min(limit, Algorithm 2's alpha)`. Needs a bloom destination
    /// ([`Destination::SolidTint`] or [`Destination::SolidTintRows`]).
    Glow(Option<&'a GrayFrame>),
}

/// Rows per band of [`Destination::SolidTint`].
const TINT_BAND: usize = 16;

/// [`original_colouring`] with any [`Destination`]; the result is the same as with the
/// destination image made first.
pub fn original_colouring_to(
    source: &GrayFrame,
    original: &RgbaFrame,
    destination: Destination<'_>,
    smoke: Option<&RgbaFrame>,
    custom: Option<(&GrayFrame, MaskMode)>,
    p: &OriginalColour,
) -> Result<RgbaFrame> {
    original_colouring_then(source, original, destination, smoke, custom, p, &|_, _| {})
}

/// A pass over a band of finished rows: `(index of its first pixel, the band's pixels)`.
pub type BandPass<'a> = dyn Fn(usize, &mut [[f32; 4]]) + Sync + 'a;

/// [`original_colouring_to`], with `then` run on each band of rows as soon as it is
/// coloured (while it is still in the cache), e.g. the alpha matte: one pass over the
/// frame instead of two. The output buffer is written once, never zeroed first.
pub fn original_colouring_then(
    source: &GrayFrame,
    original: &RgbaFrame,
    destination: Destination<'_>,
    smoke: Option<&RgbaFrame>,
    custom: Option<(&GrayFrame, MaskMode)>,
    p: &OriginalColour,
    then: &BandPass<'_>,
) -> Result<RgbaFrame> {
    let layers = Layers {
        original: Orig::Linear(original.data()),
        destination,
        smoke,
        custom,
        alpha: AlphaMatte::Keep,
    };
    colour_then(source, original.size(), layers, p, then)
}

/// [`original_colouring_then`] with the original as a rendering's source frame: 8-bit
/// footage ([`SourceFrame::Srgb8`]) is read as it is, through
/// [`crate::footage::srgb8_table`] — the same result as on the frame in linear light,
/// bit for bit, without converting it.
pub fn original_colouring_src_then(
    source: &GrayFrame,
    original: &SourceFrame,
    destination: Destination<'_>,
    smoke: Option<&RgbaFrame>,
    custom: Option<(&GrayFrame, MaskMode)>,
    p: &OriginalColour,
    then: &BandPass<'_>,
) -> Result<RgbaFrame> {
    let layers = Layers {
        original: Orig::of(original),
        destination,
        smoke,
        custom,
        alpha: AlphaMatte::Keep,
    };
    colour_then(source, original.size(), layers, p, then)
}

/// [`original_colouring_src_then`] with the alpha matte `alpha` applied to each pixel as
/// it is coloured (one pass, no second read of the frame): bit for bit Algorithm 2, then
/// the matte rule on the result.
#[allow(clippy::too_many_arguments)]
pub fn original_colouring_matted(
    source: &GrayFrame,
    original: &SourceFrame,
    destination: Destination<'_>,
    smoke: Option<&RgbaFrame>,
    custom: Option<(&GrayFrame, MaskMode)>,
    p: &OriginalColour,
    alpha: AlphaMatte<'_>,
) -> Result<RgbaFrame> {
    let layers = Layers {
        original: Orig::of(original),
        destination,
        smoke,
        custom,
        alpha,
    };
    colour_then(source, original.size(), layers, p, &|_, _| {})
}

/// The original frame's pixels: linear, or 8-bit sRGB RGBA bytes.
#[derive(Clone, Copy)]
enum Orig<'a> {
    Linear(&'a [[f32; 4]]),
    Srgb8(&'a [u8]),
}

impl<'a> Orig<'a> {
    fn of(f: &'a SourceFrame) -> Self {
        match f {
            SourceFrame::Linear(f) => Orig::Linear(f.data()),
            SourceFrame::Srgb8 { bytes, .. } => Orig::Srgb8(bytes),
        }
    }
}

/// Algorithm 2's layers besides the mask.
struct Layers<'a> {
    original: Orig<'a>,
    destination: Destination<'a>,
    smoke: Option<&'a RgbaFrame>,
    custom: Option<(&'a GrayFrame, MaskMode)>,
    alpha: AlphaMatte<'a>,
}

/// The checks and the banded pass of [`original_colouring_then`] (`orig_size`: the
/// original's size).
fn colour_then(
    source: &GrayFrame,
    orig_size: Size,
    layers: Layers<'_>,
    p: &OriginalColour,
    then: &BandPass<'_>,
) -> Result<RgbaFrame> {
    let Layers {
        original,
        destination,
        smoke,
        custom,
        alpha,
    } = layers;
    p.validate()?;
    let size = source.size();
    check_size("the original frame", orig_size, size)?;
    match destination {
        Destination::Empty => {}
        Destination::Image(d) => check_size("the destination (bloom) image", d.size(), size)?,
        Destination::SolidTint(b, _) => check_size("the bloom image", b.size(), size)?,
        Destination::SolidTintRows(b, _) => check_size("the bloom", b.source().size(), size)?,
    }
    if let AlphaMatte::Glow(limit) = alpha {
        if matches!(destination, Destination::Empty | Destination::Image(_)) {
            return Err(EigenError::bad(
                "matte",
                "the alpha matte from the bloom needs the bloom as the destination \
                 (Destination::SolidTint or SolidTintRows)",
            ));
        }
        if let Some(m) = limit {
            check_size("the footage matte", m.size(), size)?;
        }
    }
    if let Some((m, _)) = custom {
        check_size("the custom mask", m.size(), size)?;
    }
    let smoke = match (p.smoke, smoke) {
        (false, _) => None,
        (true, Some(s)) => {
            check_size("the smoke image", s.size(), size)?;
            Some(s)
        }
        (true, None) => {
            return Err(EigenError::bad(
                "colour.smoke",
                "smoke is enabled but no smoke image was given; pass one from \
                 colour::synthetic_smoke or disable smoke",
            ))
        }
    };
    // The mask Algorithm 2 thresholds, and the optional extra layer (MaskMode::Add).
    let (mask, extra) = match custom {
        Some((m, MaskMode::Replace)) => (m, None),
        Some((m, MaskMode::Add)) => (source, Some(m)),
        None => (source, None),
    };
    let w = size.width as usize;
    let n = size.pixels();
    let mut out: Vec<[f32; 4]> = Vec::with_capacity(n);
    let band = w.max(1) * TINT_BAND;
    out.spare_capacity_mut()[..n]
        .par_chunks_mut(band)
        .enumerate()
        .for_each_init(
            || (Vec::new(), Vec::new()),
            |(lit_rows, line), (b, rows)| {
                let span = b * band..b * band + rows.len();
                // The band's bloom, when the destination is one.
                let lit: Option<&[f32]> = match destination {
                    Destination::SolidTint(bloom, _) => Some(&bloom.data()[span.clone()]),
                    Destination::SolidTintRows(bloom, _) => {
                        lit_rows.resize(span.len(), 0.0);
                        bloom.rows_into(b * TINT_BAND, lit_rows, line);
                        Some(&lit_rows[..])
                    }
                    _ => None,
                };
                let dest = match (destination, lit) {
                    (Destination::Image(d), _) => Dest::Image(&d.data()[span.clone()]),
                    (Destination::SolidTint(_, tint), Some(l))
                    | (Destination::SolidTintRows(_, tint), Some(l)) => {
                        Dest::Solid(l, SolidTintRamp::new(tint))
                    }
                    _ => Dest::Empty,
                };
                let alpha = match (alpha, lit) {
                    (AlphaMatte::Glow(limit), Some(l)) => AlphaBand::Glow {
                        grey: &source.data()[span.clone()],
                        lit: l,
                        limit: limit.map(|m| &m.data()[span.clone()]),
                    },
                    (AlphaMatte::Opaque, _) => AlphaBand::Opaque,
                    _ => AlphaBand::Keep,
                };
                let px = Pixels {
                    mask: &mask.data()[span.clone()],
                    dest,
                    smoke: smoke.map(|s| &s.data()[span.clone()]),
                    extra: extra.map(|m| &m.data()[span.clone()]),
                    alpha,
                };
                match original {
                    Orig::Linear(o) => {
                        let o = &o[span.clone()];
                        colour_pixels(&px, |i| o[i], false, p.threshold, rows)
                    }
                    Orig::Srgb8(o) => {
                        let o = &o[span.start * 4..span.end * 4];
                        let t = crate::footage::srgb8_table();
                        colour_pixels(
                            &px,
                            |i| crate::footage::srgb8_pixel(t, &o[i * 4..i * 4 + 4]),
                            true,
                            p.threshold,
                            rows,
                        )
                    }
                }
                // SAFETY: `colour_pixels` wrote every pixel of `rows`, and `[f32; 4]` has
                // no invalid bit patterns or drop glue.
                let rows =
                    unsafe { &mut *(rows as *mut [MaybeUninit<[f32; 4]>] as *mut [[f32; 4]]) };
                then(span.start, rows);
            },
        );
    // SAFETY: every band of the first `n` elements was written above.
    unsafe { out.set_len(n) };
    Ok(RgbaFrame::from_vec(size, out)?)
}

/// A band's destination: none, an image, or a bloom coloured by a solid tint pixel by
/// pixel (`synthetic_colour`'s values).
enum Dest<'a> {
    Empty,
    Image(&'a [[f32; 4]]),
    Solid(&'a [f32], SolidTintRamp),
}

/// A band's [`AlphaMatte`].
enum AlphaBand<'a> {
    Keep,
    Opaque,
    Glow {
        grey: &'a [f32],
        lit: &'a [f32],
        limit: Option<&'a [f32]>,
    },
}

impl AlphaBand<'_> {
    /// The alpha of pixel `i`, whose Algorithm 2 alpha is `a`.
    #[inline(always)]
    fn at(&self, i: usize, a: f32) -> f32 {
        match self {
            AlphaBand::Keep => a,
            AlphaBand::Opaque => 1.0,
            AlphaBand::Glow { grey, lit, limit } => {
                let m = (grey[i] + lit[i]).clamp(0.0, 1.0);
                match limit {
                    Some(l) => m.max(l[i].min(a)),
                    None => m,
                }
            }
        }
    }
}

/// A band's layers for [`colour_pixels`].
struct Pixels<'a> {
    mask: &'a [f32],
    dest: Dest<'a>,
    smoke: Option<&'a [[f32; 4]]>,
    extra: Option<&'a [f32]>,
    alpha: AlphaBand<'a>,
}

/// Algorithm 2 on a run of pixels (see [`original_colouring`]), then the alpha matte;
/// `orig(i)` is the original's pixel `i` in linear light. With `nonneg` (every channel of
/// every original pixel is finite and ≥ +0, as 8-bit footage's are) the original is not
/// read where its weight `s` is ±0: `s × og` is then ±0 with the sign of `s`, which is
/// `s × 0.0` — the same value.
#[inline]
fn colour_pixels(
    px: &Pixels<'_>,
    orig: impl Fn(usize) -> [f32; 4],
    nonneg: bool,
    threshold: f32,
    out: &mut [MaybeUninit<[f32; 4]>],
) {
    let inv_t = 1.0 / threshold;
    let Pixels {
        mask,
        dest,
        smoke,
        extra,
        alpha,
    } = px;
    // Pixels outside the flame and its glow (mask and bloom both exactly +0, no smoke or
    // extra layer, 8-bit footage, which is not read there) all colour to one value: made
    // once by the same expression below, only their alpha is per pixel.
    let quiet_lit: Option<(&[f32], [f32; 4])> = match dest {
        Dest::Solid(b, ramp) if nonneg && smoke.is_none() && extra.is_none() => {
            let (s, og, k) = (0.0f32, [0.0f32; 4], [0.0f32; 4]);
            let (sd, d) = (1.0 - s, ramp.at(0.0));
            Some((
                b,
                std::array::from_fn(|c| (s * og[c] + sd * d[c] + k[c] * sd).clamp(0.0, 1.0)),
            ))
        }
        _ => None,
    };
    for (i, o) in out.iter_mut().enumerate() {
        if let Some((b, quiet)) = quiet_lit {
            if mask[i].to_bits() == 0 && b[i].to_bits() == 0 {
                let mut v = quiet;
                v[3] = alpha.at(i, v[3]);
                o.write(v);
                continue;
            }
        }
        let mut s = if mask[i] > threshold {
            1.0
        } else {
            mask[i].max(0.0) * inv_t
        };
        if let Some(e) = extra {
            s = s.max(e[i].clamp(0.0, 1.0));
        }
        let og = if nonneg && s == 0.0 {
            [0.0; 4]
        } else {
            orig(i)
        };
        let mut v = if s >= 1.0 {
            og
        } else {
            let sd = 1.0 - s;
            let d = match dest {
                Dest::Empty => [0.0; 4],
                Dest::Image(d) => d[i],
                Dest::Solid(b, ramp) => ramp.at(b[i]),
            };
            let k = smoke.map_or([0.0; 4], |k| k[i]);
            std::array::from_fn(|c| (s * og[c] + sd * d[c] + k[c] * sd).clamp(0.0, 1.0))
        };
        v[3] = alpha.at(i, v[3]);
        o.write(v);
    }
}

/// Settings of [`synthetic_smoke`] (§6.3).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SmokeParams {
    /// Differences below this (linear luminance, `0..=1`) are removed (step 3). Default
    /// 0.01, about 10 code values of sRGB-coded grey at the brightness of smoke.
    pub threshold: f32,
    /// σ of the "very small" Gaussian blur of step 4, in pixels (`0..=64`, 0 = none).
    /// Default 1.
    pub blur_sigma: f32,
    /// Linear RGB the difference is multiplied by (step 5, "e.g. dark gray"), each
    /// `0..=4`. Default 0.397 each: CSS `darkgray` (#A9A9A9) in linear light.
    pub colour: [f32; 3],
    /// Use `|current − next|` (more shared pixels of the next frame appear) instead of
    /// `current − next`. Default false.
    pub absolute: bool,
}

impl Default for SmokeParams {
    fn default() -> Self {
        SmokeParams {
            threshold: 0.01,
            blur_sigma: 1.0,
            colour: [0.397; 3],
            absolute: false,
        }
    }
}

impl SmokeParams {
    pub fn validate(&self) -> Result<()> {
        if !(0.0..=1.0).contains(&self.threshold) {
            return Err(EigenError::bad("smoke.threshold", "must be within 0..=1"));
        }
        if !(0.0..=64.0).contains(&self.blur_sigma) {
            return Err(EigenError::bad(
                "smoke.blur_sigma",
                "must be within 0..=64 pixels",
            ));
        }
        if !self.colour.iter().all(|c| (0.0..=4.0).contains(c)) {
            return Err(EigenError::bad(
                "smoke.colour",
                format!("{:?}: each component must be within 0..=4", self.colour),
            ));
        }
        Ok(())
    }
}

/// The synthetic smoke image of §6.3 from two consecutive original frames:
///
/// 1. luminance of `current` and `next`;
/// 2. `diff = current − next` (or `|current − next|` with `absolute`), clamped to `0..=1`
///    (the thesis's saturation);
/// 3. values below `threshold` become 0 (values above are kept, not set to 1);
/// 4. Gaussian blur with `blur_sigma` (exact, [`ignis_core::post::gaussian_blur`]);
/// 5. RGB = `diff × colour` ("multiply blending"); alpha = `diff` clamped to `0..=1`, the
///    smoke's density, so the image can also be composited on its own.
///
/// Pass the frames already in the common frame ([`warp_rgba`]) so the smoke lines up with
/// the reconstructed fire. For the last frame of a clip, where there is no next frame,
/// pass the **previous** frame as `next` (as the thesis does). For transitions, `next` is
/// the frame that follows `current` in the video.
pub fn synthetic_smoke(
    current: &RgbaFrame,
    next: &RgbaFrame,
    p: &SmokeParams,
) -> Result<RgbaFrame> {
    p.validate()?;
    if current.size() != next.size() {
        return Err(CoreError::SizeMismatch(format!(
            "smoke: the current frame is {} but the next frame is {}",
            current.size(),
            next.size()
        ))
        .into());
    }
    let size = current.size();
    let lum = |p: &[f32; 4]| LUMA[0] * p[0] + LUMA[1] * p[1] + LUMA[2] * p[2];
    let mut diff = vec![0.0f32; size.pixels()];
    diff.par_chunks_mut(size.width as usize)
        .zip(current.data().par_chunks(size.width as usize))
        .zip(next.data().par_chunks(size.width as usize))
        .for_each(|((d, c), n)| {
            for ((d, c), n) in d.iter_mut().zip(c).zip(n) {
                let v = lum(c) - lum(n);
                let v = if p.absolute { v.abs() } else { v }.clamp(0.0, 1.0);
                *d = if v < p.threshold { 0.0 } else { v };
            }
        });
    let diff = gaussian_blur(&GrayFrame::from_vec(size, diff)?, p.blur_sigma);
    let [r, g, b] = p.colour;
    let data = diff
        .data()
        .par_iter()
        .map(|&v| [v * r, v * g, v * b, v.clamp(0.0, 1.0)])
        .collect();
    Ok(RgbaFrame::from_vec(diff.size(), data)?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pose::warp;
    use ignis_core::colour::{synthetic_colour, Tint};

    fn size(w: u32, h: u32) -> Size {
        Size::new(w, h).unwrap()
    }

    /// A 1×n row of pixels from grey values.
    fn gray(v: &[f32]) -> GrayFrame {
        GrayFrame::from_vec(size(v.len() as u32, 1), v.to_vec()).unwrap()
    }

    fn rgba(v: &[[f32; 4]]) -> RgbaFrame {
        RgbaFrame::from_vec(size(v.len() as u32, 1), v.to_vec()).unwrap()
    }

    fn close(a: [f32; 4], b: [f32; 4]) -> bool {
        a.iter().zip(&b).all(|(x, y)| (x - y).abs() < 1e-6)
    }

    const T: f32 = 0.1;

    fn params(smoke: bool) -> OriginalColour {
        OriginalColour {
            threshold: T,
            smoke,
        }
    }

    #[test]
    fn warp_rgba_matches_the_grey_warp() {
        let src = RgbaFrame::from_vec(
            size(64, 48),
            (0..64 * 48)
                .map(|i| {
                    let (x, y) = ((i % 64) as f32, (i / 64) as f32);
                    [
                        (x * 0.37).sin().abs(),
                        (y * 0.21 + x * 0.05).cos().abs(),
                        ((x * y) * 0.01).fract(),
                        1.0,
                    ]
                })
                .collect(),
        )
        .unwrap();
        let pose = ClipPose {
            isolate: false,
            fuel_x: 30.5,
            base_y: 44.0,
            scale: 0.8,
            still_lights: Default::default(),
        };
        let p = PoseParams {
            frame_size: Some(size(40, 60)),
            ..Default::default()
        };
        let angle = 0.3;
        let colour = warp_rgba(&src, &pose, angle, &p);
        let grey = warp(&src.luminance(), &pose, angle, &p);
        assert_eq!(colour.size(), grey.size());
        let lum = colour.luminance();
        let mut covered = 0;
        for (i, (a, b)) in lum.data().iter().zip(grey.data()).enumerate() {
            assert!((a - b).abs() < 1e-5, "pixel {i}: {a} vs {b}");
            covered += (colour.data()[i][3] > 0.999) as usize;
        }
        // the frame shows both source pixels (alpha 1) and the outside (alpha 0)
        assert!(covered > 100, "{covered}");
        assert!(colour.data().iter().any(|p| p == &[0.0; 4]));
    }

    #[test]
    fn above_the_threshold_copies_the_original_exactly() {
        let orig = [0.9, 1.7, 0.3, 0.8]; // HDR green is copied, not clamped
        let out = original_colouring(
            &gray(&[T + 1e-4, 0.9]),
            &rgba(&[orig, orig]),
            Some(&rgba(&[[0.5; 4]; 2])),
            Some(&rgba(&[[0.5; 4]; 2])),
            None,
            &params(true),
        )
        .unwrap();
        assert_eq!(out.data(), &[orig, orig]);
    }

    #[test]
    fn below_the_threshold_blends_linearly() {
        let (o, d, k) = (
            [0.8, 0.4, 0.2, 1.0],
            [0.2, 0.1, 0.0, 0.6],
            [0.1, 0.1, 0.1, 0.2],
        );
        let run = |smoke_on: bool, dest: Option<&RgbaFrame>| {
            original_colouring(
                &gray(&[0.5 * T, 0.0, -0.3, T]),
                &rgba(&[o; 4]),
                dest,
                Some(&rgba(&[k; 4])),
                None,
                &params(smoke_on),
            )
            .unwrap()
        };
        let dest = rgba(&[d; 4]);
        // half the threshold: 0.5·orig + 0.5·dest (+ 0.5·smoke)
        let half: [f32; 4] = std::array::from_fn(|c| 0.5 * o[c] + 0.5 * d[c]);
        let out = run(false, Some(&dest));
        assert!(close(out.data()[0], half), "{:?}", out.data()[0]);
        let with_smoke = run(true, Some(&dest));
        let half_smoke: [f32; 4] = std::array::from_fn(|c| half[c] + 0.5 * k[c]);
        assert!(close(with_smoke.data()[0], half_smoke));
        // zero (and negative noise) is the destination alone; at the threshold, the
        // original (but through the blend branch)
        assert!(close(out.data()[1], d));
        assert!(close(out.data()[2], d));
        assert!(close(out.data()[3], o));
        // no destination = the thesis's empty image
        let empty = run(false, None);
        assert!(close(empty.data()[0], o.map(|v| 0.5 * v)));
        assert_eq!(empty.data()[1], [0.0; 4]);
    }

    #[test]
    fn the_blend_saturates() {
        let out = original_colouring(
            &gray(&[0.5 * T]),
            &rgba(&[[0.9, 0.9, 0.9, 1.0]]),
            Some(&rgba(&[[0.9, 1.5, 0.0, 1.0]])),
            Some(&rgba(&[[0.8, 0.0, 0.0, 0.0]])),
            None,
            &params(true),
        )
        .unwrap();
        // 0.45 + 0.45 + 0.4 = 1.3 → 1; 0.45 + 0.75 = 1.2 → 1; 0.45 stays
        assert!(
            close(out.data()[0], [1.0, 1.0, 0.45, 1.0]),
            "{:?}",
            out.data()
        );
    }

    #[test]
    fn custom_masks_replace_or_add() {
        let o = [0.7, 0.5, 0.3, 1.0];
        let d = [0.1, 0.1, 0.1, 0.5];
        // pixels: bright grey, dark grey, dark grey, dark grey
        let source = gray(&[0.5, 0.0, 0.0, 0.5 * T]);
        let mask = gray(&[0.0, 1.0, 0.5, 0.0]);
        let run = |mode| {
            original_colouring(
                &source,
                &rgba(&[o; 4]),
                Some(&rgba(&[d; 4])),
                None,
                Some((&mask, mode)),
                &params(false),
            )
            .unwrap()
        };
        let half = |a: [f32; 4], b: [f32; 4]| std::array::from_fn(|c| 0.5 * a[c] + 0.5 * b[c]);
        let add = run(MaskMode::Add);
        assert_eq!(add.data()[0], o, "bright grey still taken");
        assert_eq!(add.data()[1], o, "mask 1 takes a dark pixel");
        assert!(close(add.data()[2], half(o, d)), "mask 0.5 blends halfway");
        assert!(
            close(add.data()[3], half(o, d)),
            "mask 0 leaves the grey in charge"
        );
        let replace = run(MaskMode::Replace);
        assert!(close(replace.data()[0], d), "the grey image is ignored");
        assert_eq!(replace.data()[1], o);
        // 0.5 > threshold: the mask is thresholded like the grey image
        assert_eq!(replace.data()[2], o);
        assert!(close(replace.data()[3], d));
    }

    /// The tint made band by band inside the colouring gives the same bytes as the tinted
    /// bloom image made first, on frames taller than a band and not a multiple of it,
    /// with and without smoke and a custom mask.
    #[test]
    fn solid_tint_destination_equals_the_tinted_image() {
        let sz = size(37, 2 * TINT_BAND as u32 + 5);
        let wave =
            |x: u32, y: u32, k: f32| ((x as f32 * 0.37 + y as f32 * 0.11 + k).sin() + 1.0) * 0.5;
        let src = GrayFrame::from_fn(sz, |x, y| wave(x, y, 0.0) * 3.0 * T);
        let bloom = GrayFrame::from_fn(sz, |x, y| wave(x, y, 1.0) * 1.2);
        let orig = RgbaFrame::from_vec(
            sz,
            (0..sz.pixels())
                .map(|i| [0.3 + (i % 7) as f32 * 0.1, 0.2, (i % 3) as f32 * 0.3, 0.9])
                .collect(),
        )
        .unwrap();
        let smoke = RgbaFrame::from_vec(sz, vec![[0.05, 0.04, 0.03, 0.02]; sz.pixels()]).unwrap();
        let mask = GrayFrame::from_fn(sz, |x, y| wave(x, y, 2.0));
        let tint = [1.0, 0.42, 0.08];
        let image = synthetic_colour(&bloom, &Tint::Solid(tint)).unwrap();
        for with_smoke in [false, true] {
            for custom in [None, Some((&mask, MaskMode::Add))] {
                let p = OriginalColour {
                    threshold: T,
                    smoke: with_smoke,
                };
                let k = with_smoke.then_some(&smoke);
                let a = original_colouring(&src, &orig, Some(&image), k, custom, &p).unwrap();
                let b = original_colouring_to(
                    &src,
                    &orig,
                    Destination::SolidTint(&bloom, tint),
                    k,
                    custom,
                    &p,
                )
                .unwrap();
                let bits = |f: &RgbaFrame| -> Vec<u32> {
                    f.data().iter().flatten().map(|v| v.to_bits()).collect()
                };
                assert_eq!(bits(&a), bits(&b), "smoke {with_smoke}");
            }
        }
    }

    /// An 8-bit original (a rendering's source frame kept as sRGB bytes) colours to the
    /// same bytes as the frame converted to linear light, with every kind of destination,
    /// smoke and a custom mask; its size is checked like a linear one's.
    #[test]
    fn srgb8_original_equals_the_linear_original() {
        let sz = size(29, TINT_BAND as u32 + 9);
        let wave =
            |x: u32, y: u32, k: f32| ((x as f32 * 0.37 + y as f32 * 0.11 + k).sin() + 1.0) * 0.5;
        let src = GrayFrame::from_fn(sz, |x, y| wave(x, y, 0.0) * 3.0 * T);
        let bloom = GrayFrame::from_fn(sz, |x, y| wave(x, y, 1.0) * 1.2);
        let bytes: Vec<u8> = (0..sz.pixels() * 4).map(|i| (i * 37 % 256) as u8).collect();
        let src8 = SourceFrame::srgb8(sz, bytes).unwrap();
        let lin = src8.to_linear().into_owned();
        let smoke = RgbaFrame::from_vec(sz, vec![[0.05, 0.04, 0.03, 0.02]; sz.pixels()]).unwrap();
        let mask = GrayFrame::from_fn(sz, |x, y| wave(x, y, 2.0));
        let image = synthetic_colour(&bloom, &Tint::Solid([0.9, 0.3, 0.1])).unwrap();
        let dests = [
            Destination::Empty,
            Destination::Image(&image),
            Destination::SolidTint(&bloom, [1.0, 0.42, 0.08]),
        ];
        let bits = |f: &RgbaFrame| -> Vec<u32> {
            f.data().iter().flatten().map(|v| v.to_bits()).collect()
        };
        for dest in dests {
            for with_smoke in [false, true] {
                for custom in [None, Some((&mask, MaskMode::Add))] {
                    let p = OriginalColour {
                        threshold: T,
                        smoke: with_smoke,
                    };
                    let k = with_smoke.then_some(&smoke);
                    let none = |_: usize, _: &mut [[f32; 4]]| {};
                    let a = original_colouring_then(&src, &lin, dest, k, custom, &p, &none);
                    let b = original_colouring_src_then(&src, &src8, dest, k, custom, &p, &none);
                    assert_eq!(bits(&a.unwrap()), bits(&b.unwrap()));
                }
            }
        }
        let small = SourceFrame::srgb8(size(2, 2), vec![0; 16]).unwrap();
        let none = |_: usize, _: &mut [[f32; 4]]| {};
        let p = OriginalColour::default();
        let e = original_colouring_src_then(&src, &small, dests[0], None, None, &p, &none);
        assert!(e.unwrap_err().to_string().contains("2x2"));
        assert!(SourceFrame::srgb8(size(2, 2), vec![0; 15]).is_err());
    }

    /// Pixels outside the flame and its glow (grey and bloom exactly +0) take the shared
    /// quiet value on 8-bit footage; they colour bit for bit as the general rule does on
    /// the same frame in linear light (which never takes that path), with the footage
    /// matte's alpha per pixel, next to −0, negative and lit pixels.
    #[test]
    fn quiet_pixels_colour_as_the_general_rule() {
        let sz = size(64, 3 * TINT_BAND as u32);
        // A small flame in the middle; +0 elsewhere, with a few −0 and negative pixels.
        let src = GrayFrame::from_fn(sz, |x, y| {
            let (dx, dy) = (x as f32 - 32.0, y as f32 - 24.0);
            let r = (dx * dx + dy * dy).sqrt();
            match (x + y) % 29 {
                0 => -0.0,
                1 => -0.02,
                _ if r < 6.0 => 0.9 - r * 0.1,
                _ => 0.0,
            }
        });
        let bp = ignis_core::post::BloomParams {
            radius: 4.0,
            ..Default::default()
        };
        let bloom = ignis_core::post::bloom(&src, &bp).unwrap();
        let quiet = src
            .data()
            .iter()
            .zip(bloom.data())
            .filter(|(g, b)| g.to_bits() == 0 && b.to_bits() == 0)
            .count();
        assert!(quiet > sz.pixels() / 2, "{quiet} quiet pixels");
        let bytes: Vec<u8> = (0..sz.pixels() * 4).map(|i| (i * 53 % 256) as u8).collect();
        let src8 = SourceFrame::srgb8(sz, bytes).unwrap();
        let lin = SourceFrame::Linear(src8.to_linear().into_owned());
        let limit = GrayFrame::from_fn(sz, |x, y| ((x * 7 + y * 3) % 11) as f32 / 10.0);
        let bits = |f: &RgbaFrame| -> Vec<u32> {
            f.data().iter().flatten().map(|v| v.to_bits()).collect()
        };
        let p = OriginalColour {
            threshold: T,
            smoke: false,
        };
        for alpha in [
            AlphaMatte::Keep,
            AlphaMatte::Opaque,
            AlphaMatte::Glow(None),
            AlphaMatte::Glow(Some(&limit)),
        ] {
            let dest = Destination::SolidTint(&bloom, [1.0, 0.42, 0.08]);
            let fast = original_colouring_matted(&src, &src8, dest, None, None, &p, alpha).unwrap();
            let general =
                original_colouring_matted(&src, &lin, dest, None, None, &p, alpha).unwrap();
            assert_eq!(bits(&fast), bits(&general));
        }
    }

    /// The fused path (`original_colouring_matted`: the bloom's rows made band by band,
    /// the alpha matte per pixel) equals Algorithm 2 on the whole bloom frame followed by
    /// the matte rule `max(clamp(grey + bloom, 0, 1), min(limit, alpha))`, bit for bit:
    /// 8-bit and linear originals, a grey source with +0, −0, negative and above-threshold
    /// values (8-bit originals skip the read where the weight is 0), with and without the
    /// limit matte, smoke and a custom mask; opaque and kept alphas.
    #[test]
    fn matted_colouring_equals_colouring_then_the_matte() {
        let sz = size(37, 2 * TINT_BAND as u32 + 5);
        let wave =
            |x: u32, y: u32, k: f32| ((x as f32 * 0.37 + y as f32 * 0.11 + k).sin() + 1.0) * 0.5;
        let src = GrayFrame::from_fn(sz, |x, y| match (x + 3 * y) % 7 {
            0 => 0.0,
            1 => -0.0,
            2 => -0.01,
            _ => wave(x, y, 0.0) * 3.0 * T - T,
        });
        let bp = ignis_core::post::BloomParams {
            radius: 8.0,
            ..Default::default()
        };
        let bloom = ignis_core::post::bloom(&src, &bp).unwrap();
        let rows = ignis_core::post::bloom_rows(&src, &bp).unwrap();
        let bytes: Vec<u8> = (0..sz.pixels() * 4).map(|i| (i * 37 % 256) as u8).collect();
        let src8 = SourceFrame::srgb8(sz, bytes).unwrap();
        let lin = SourceFrame::Linear(src8.to_linear().into_owned());
        let smoke = RgbaFrame::from_vec(sz, vec![[0.05, 0.04, 0.03, 0.02]; sz.pixels()]).unwrap();
        let mask = GrayFrame::from_fn(sz, |x, y| wave(x, y, 2.0));
        let limit = GrayFrame::from_fn(sz, |x, y| wave(x, y, 4.0));
        let tint = [1.0, 0.42, 0.08];
        let bits = |f: &RgbaFrame| -> Vec<u32> {
            f.data().iter().flatten().map(|v| v.to_bits()).collect()
        };
        let none = |_: usize, _: &mut [[f32; 4]]| {};
        for orig in [&src8, &lin] {
            for with_smoke in [false, true] {
                for custom in [None, Some((&mask, MaskMode::Add))] {
                    let p = OriginalColour {
                        threshold: T,
                        smoke: with_smoke,
                    };
                    let k = with_smoke.then_some(&smoke);
                    let dest = Destination::SolidTint(&bloom, tint);
                    let plain = original_colouring_src_then(&src, orig, dest, k, custom, &p, &none)
                        .unwrap();
                    // The 8-bit shortcut (no read where the weight is ±0) changes nothing.
                    let from_linear =
                        original_colouring_src_then(&src, &lin, dest, k, custom, &p, &none)
                            .unwrap();
                    assert_eq!(bits(&plain), bits(&from_linear));
                    for alpha in [
                        AlphaMatte::Keep,
                        AlphaMatte::Opaque,
                        AlphaMatte::Glow(None),
                        AlphaMatte::Glow(Some(&limit)),
                    ] {
                        let mut want = plain.clone();
                        for (i, px) in want.data_mut().iter_mut().enumerate() {
                            let m = (src.data()[i] + bloom.data()[i]).clamp(0.0, 1.0);
                            px[3] = match alpha {
                                AlphaMatte::Keep => px[3],
                                AlphaMatte::Opaque => 1.0,
                                AlphaMatte::Glow(None) => m,
                                AlphaMatte::Glow(Some(l)) => m.max(l.data()[i].min(px[3])),
                            };
                        }
                        let got = original_colouring_matted(
                            &src,
                            orig,
                            Destination::SolidTintRows(&rows, tint),
                            k,
                            custom,
                            &p,
                            alpha,
                        )
                        .unwrap();
                        assert_eq!(bits(&got), bits(&want));
                    }
                }
            }
        }
        // The matte from the bloom needs a bloom destination.
        let p = OriginalColour::default();
        let e = original_colouring_matted(
            &src,
            &src8,
            Destination::Empty,
            None,
            None,
            &p,
            AlphaMatte::Glow(None),
        );
        assert!(e.unwrap_err().to_string().contains("bloom"));
    }

    #[test]
    fn bad_inputs_are_errors() {
        let g = GrayFrame::new(size(3, 2));
        let o = RgbaFrame::new(size(3, 2));
        let small = RgbaFrame::new(size(2, 2));
        let p = OriginalColour::default();
        let e = original_colouring(&g, &small, None, None, None, &p).unwrap_err();
        let msg = e.to_string();
        assert!(msg.contains("2x2") && msg.contains("3x2"), "{msg}");
        let e = original_colouring(&g, &o, Some(&small), None, None, &p).unwrap_err();
        assert!(e.to_string().contains("destination"), "{e}");
        let m = GrayFrame::new(size(3, 3));
        let e = original_colouring(&g, &o, None, None, Some((&m, MaskMode::Add)), &p)
            .unwrap_err()
            .to_string();
        assert!(e.contains("3x3") && e.contains("custom mask"), "{e}");
        let with_smoke = OriginalColour {
            smoke: true,
            ..p.clone()
        };
        assert!(original_colouring(&g, &o, None, None, None, &with_smoke).is_err());
        assert!(original_colouring(&g, &o, None, Some(&small), None, &with_smoke).is_err());
        // a smoke image is ignored (not even size-checked) when smoke is off
        assert!(original_colouring(&g, &o, None, Some(&small), None, &p).is_ok());
        let zero = OriginalColour {
            threshold: 0.0,
            ..p
        };
        assert!(original_colouring(&g, &o, None, None, None, &zero).is_err());
        assert!(synthetic_smoke(&o, &small, &SmokeParams::default())
            .unwrap_err()
            .to_string()
            .contains("2x2"));
    }

    /// Grey pixels as opaque RGBA (luminance = the value).
    fn grey_rgba(v: &[f32]) -> RgbaFrame {
        gray(v).to_rgba()
    }

    #[test]
    fn smoke_thresholds_signs_and_colours_the_difference() {
        let current = grey_rgba(&[0.50, 0.50, 0.30, 0.90, 0.0]);
        let next = grey_rgba(&[0.45, 0.495, 0.50, 0.10, 0.0]);
        let p = SmokeParams {
            threshold: 0.01,
            blur_sigma: 0.0,
            colour: [0.5, 0.25, 1.0],
            absolute: false,
        };
        let s = synthetic_smoke(&current, &next, &p).unwrap();
        let d = [0.05, 0.0, 0.0, 0.8, 0.0]; // 0.005 < threshold; 0.3 − 0.5 < 0
        for (px, &v) in s.data().iter().zip(&d) {
            assert!(close(*px, [0.5 * v, 0.25 * v, v, v]), "{px:?} vs {v}");
        }
        let abs = synthetic_smoke(
            &current,
            &next,
            &SmokeParams {
                absolute: true,
                ..p.clone()
            },
        )
        .unwrap();
        assert!((abs.data()[2][3] - 0.2).abs() < 1e-5, "|0.3 − 0.5|");
        assert_eq!(abs.data()[1][3], 0.0, "still below the threshold");
        // differences saturate at 1
        let hdr = synthetic_smoke(&grey_rgba(&[3.0]), &grey_rgba(&[0.0]), &p).unwrap();
        assert!(close(hdr.data()[0], [0.5, 0.25, 1.0, 1.0]));
    }

    #[test]
    fn smoke_blur_spreads_but_keeps_the_mass() {
        let mut cur = vec![0.0; 21];
        cur[10] = 0.5;
        let s = synthetic_smoke(
            &grey_rgba(&cur),
            &grey_rgba(&[0.0; 21]),
            &SmokeParams {
                colour: [1.0; 3],
                blur_sigma: 1.5,
                ..Default::default()
            },
        )
        .unwrap();
        let a: Vec<f32> = s.data().iter().map(|p| p[0]).collect();
        assert!(a[10] < 0.5 && a[9] > 0.0 && (a[9] - a[11]).abs() < 1e-6);
        assert!((a.iter().sum::<f32>() - 0.5).abs() < 1e-4);
        assert!(synthetic_smoke(
            &grey_rgba(&cur),
            &grey_rgba(&cur),
            &SmokeParams {
                blur_sigma: -1.0,
                ..Default::default()
            }
        )
        .is_err());
    }
}
