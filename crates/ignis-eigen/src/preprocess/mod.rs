//! The pre-processing pipeline of thesis chapter 3, configured in TOML: mask → contours →
//! hole removal → Hermite background removal → pose normalisation → grayscale training
//! frame (optionally resized, §7.1.2).
//!
//! Source: eigenfires-thesis.txt §3.2–3.4, §4.2 (common frame size), §7.1.2 (training on
//! resized frames while the full-resolution pre-processed frames are kept for output).
//!
//! Pixel conventions: input [`RgbaFrame`]s and output [`GrayFrame`]s are linear light
//! (luminance with Rec. 709 weights); masks are 8-bit, 255 = flame.

pub mod contour;
pub mod flame_colour;
pub mod hermite;
pub mod mask;
pub mod pose;
pub mod still;
pub use flame_colour::FlameColour;
use still::StillLights;

use crate::contour::{contour_tree, draw_contours, fill_contours, remove_holes, ContourParams};
use crate::error::{EigenError, Result};
use crate::hermite::{hermite_darken_rgba, hermite_darken_rgba_in, HermiteParams};
use crate::mask::{flame_mask_without, hsv_mask, mask_area, mask_edges, MaskParams};
use crate::pose::{lean_angle, mask_extent, resize, warp, ClipPose, MaskExtent, PoseParams};
use ignis_core::{GrayFrame, RgbaFrame, Size};
use image::GrayImage;
use serde::{Deserialize, Serialize};

/// Every pre-processing setting. Parsed from TOML with [`PreprocessParams::from_toml`];
/// every field has a default that works on flames filmed on a dark background.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PreprocessParams {
    /// HSV ranges, morphology, smoothing (§3.2.1).
    pub mask: MaskParams,
    /// Hole removal and simplification (§3.2.2–3.2.3).
    pub contours: ContourParams,
    /// Background and smoke removal (§3.3).
    pub hermite: HermiteParams,
    /// Centring, scaling, rotation, common frame size (§3.4).
    pub pose: PoseParams,
    /// Size of the frames the PCA is trained on (§7.1.2), or `"auto"` (default): the
    /// common frame's aspect with about `train_pixels` pixels (never more than the frame
    /// itself). With a fixed `pose.frame_size`, `"auto"` trains at that size.
    #[serde(default, with = "crate::pose::size_str::auto")]
    pub train_size: Option<Size>,
    /// Pixels of an automatic training size. Default 17136 (the thesis's 102x168).
    #[serde(default = "default_train_pixels")]
    pub train_pixels: usize,
    /// Frames sampled (evenly over the range) to find each clip's pose. Default 24.
    #[serde(default = "default_pose_samples")]
    pub pose_samples: usize,
}

impl Default for PreprocessParams {
    fn default() -> Self {
        PreprocessParams {
            mask: MaskParams::default(),
            contours: ContourParams::default(),
            hermite: HermiteParams::default(),
            pose: PoseParams::default(),
            train_size: None,
            train_pixels: default_train_pixels(),
            pose_samples: default_pose_samples(),
        }
    }
}

fn default_train_pixels() -> usize {
    102 * 168
}
fn default_pose_samples() -> usize {
    24
}

impl PreprocessParams {
    /// The defaults with training at `train_size` and a common frame size of
    /// `frame_size`.
    pub fn with_sizes(frame_size: Size, train_size: Option<Size>) -> Self {
        let mut p = PreprocessParams {
            train_size,
            ..Default::default()
        };
        p.pose.frame_size = Some(frame_size);
        p
    }

    /// The training size for a common frame of `frame` pixels: `train_size` when given,
    /// else the frame's aspect with about `train_pixels` pixels when the frame is
    /// automatic, else the frame itself.
    pub fn auto_train_size(&self, frame: Size) -> Size {
        if let Some(t) = self.train_size {
            return t;
        }
        if self.pose.frame_size.is_some() {
            return frame;
        }
        let k = (self.train_pixels as f64 / frame.pixels() as f64)
            .sqrt()
            .min(1.0);
        let w = ((frame.width as f64 * k).round() as u32).clamp(1, frame.width);
        let h = ((frame.height as f64 * k).round() as u32).clamp(1, frame.height);
        Size {
            width: w,
            height: h,
        }
    }

    /// Parses TOML (tables `[mask]`, `[contours]`, `[hermite]`, `[pose]`, keys
    /// `train_size = "102x168"`, `pose_samples`), then validates.
    pub fn from_toml(text: &str) -> Result<Self> {
        let p: PreprocessParams = toml::from_str(text)
            .map_err(|e| EigenError::bad("pre-processing config", e.to_string()))?;
        p.validate()?;
        Ok(p)
    }

    /// The settings as TOML (what `ignis eigen preprocess --print-config` prints).
    pub fn to_toml(&self) -> String {
        toml::to_string_pretty(self).expect("plain data serialises")
    }

    /// Checks every setting.
    pub fn validate(&self) -> Result<()> {
        self.mask.validate()?;
        self.contours.validate()?;
        self.hermite.validate()?;
        self.pose.validate()?;
        if let Some(s) = self.train_size {
            Size::new(s.width, s.height)?;
        }
        if self.train_pixels < 64 || self.train_pixels > 4_000_000 {
            return Err(EigenError::bad(
                "train_pixels",
                "must be within 64..=4000000",
            ));
        }
        if self.pose_samples == 0 {
            return Err(EigenError::bad("pose_samples", "must be at least 1"));
        }
        Ok(())
    }

    /// The size of the training frames (for resolved settings, as stored in a manifest).
    pub fn training_size(&self) -> Size {
        self.auto_train_size(self.pose.frame())
    }
}

/// The mask of one frame after contours and hole removal, with what pose needs.
#[derive(Clone, Debug)]
pub struct FrameMask {
    /// The filled contour mask (255 = flame interior).
    pub mask: GrayImage,
    /// Lean angle from the weighted least-squares line (radians, 0 = upright).
    pub angle: Option<f32>,
    /// Extent of the flame, `None` when nothing is left.
    pub extent: Option<MaskExtent>,
}

/// §3.2: mask (with flame isolation when `isolate`), contour tree, hole removal, fill.
/// With `pose.rotate`, the lean angle is measured only on a single upright flame (one
/// outer contour at least 1.5× as tall as wide): a sheet or wall of fire is never
/// rotated.
pub fn frame_mask(frame: &RgbaFrame, p: &PreprocessParams, isolate: bool) -> FrameMask {
    frame_mask_without(frame, p, isolate, &StillLights::default())
}

/// [`frame_mask`] of a frame of a clip with `still` lights ([`crate::still`]), which the
/// mask ignores ([`crate::mask::flame_mask_without`]).
pub fn frame_mask_without(
    frame: &RgbaFrame,
    p: &PreprocessParams,
    isolate: bool,
    still: &StillLights,
) -> FrameMask {
    let m = flame_mask_without(frame, &p.mask, isolate, still);
    let nodes = contour_tree(&m);
    let area = frame.width() as f64 * frame.height() as f64;
    let keep = remove_holes(&nodes, &p.contours, area);
    let filled = fill_contours(
        frame.width(),
        frame.height(),
        &nodes,
        &keep,
        p.contours.simplify_epsilon,
    );
    let extent = mask_extent(&filled);
    let outer = nodes
        .iter()
        .zip(&keep)
        .filter(|(n, &k)| k && !n.is_hole)
        .count();
    let upright_single = outer == 1 && extent.is_some_and(|e| e.height >= 1.5 * e.width);
    let angle = if p.pose.rotate && upright_single {
        lean_angle(&nodes, &keep).map(|a| a.0)
    } else {
        None
    };
    FrameMask {
        extent,
        mask: filled,
        angle,
    }
}

/// One pre-processed frame.
#[derive(Clone, Debug)]
pub struct Processed {
    /// At `pose.frame_size`: the full-resolution pre-processed frame (§7.1.2).
    pub frame: GrayFrame,
    /// At the training size (what the PCA sees).
    pub train: GrayFrame,
    /// Rotation applied (radians), 0 without `pose.rotate`.
    pub angle: f32,
    /// Pixels left in the mask.
    pub mask_pixels: usize,
    /// The binary mask (0/255) at the source size, before pose normalisation.
    pub mask: GrayImage,
}

/// Runs the whole per-frame pipeline with a clip pose already found.
pub fn preprocess_frame(frame: &RgbaFrame, pose: &ClipPose, p: &PreprocessParams) -> Processed {
    let (src, mask) = source_grey_and_mask(frame, pose, p);
    let out = warp(&src.grey, pose, src.angle, &p.pose);
    let train = resize(&out, p.training_size());
    Processed {
        frame: out,
        train,
        angle: src.angle,
        mask_pixels: src.mask_pixels,
        mask,
    }
}

/// A pre-processed frame at the source's own size and position (before pose
/// normalisation): what §7.1.2 output shows for a database frame.
#[derive(Clone, Debug)]
pub struct SourceGrey {
    /// Hermite-cleaned luminance, the isolated flame's surroundings removed.
    pub grey: GrayFrame,
    /// Soft flame matte from the mask (1 inside, feathered over a few pixels).
    pub matte: GrayFrame,
    /// Rotation pose normalisation applies (radians).
    pub angle: f32,
    pub mask_pixels: usize,
}

/// §3.2–3.3 at the source size: mask, Hermite darkening, and, on a clip with flame
/// isolation, everything outside the feathered mask removed (Hermite alone keeps
/// anything brighter than `i_max`, e.g. a lit jar).
pub fn source_grey(frame: &RgbaFrame, pose: &ClipPose, p: &PreprocessParams) -> SourceGrey {
    source_grey_and_mask(frame, pose, p).0
}

/// [`source_grey`] and the binary mask it came from (what training stores).
fn source_grey_and_mask(
    frame: &RgbaFrame,
    pose: &ClipPose,
    p: &PreprocessParams,
) -> (SourceGrey, GrayImage) {
    let fm = frame_mask_without(frame, p, pose.isolate, &pose.still_lights);
    let mut sg = source_grey_with_mask(frame, &fm.mask, pose, p);
    sg.angle = fm.angle.unwrap_or(0.0);
    (sg, fm.mask)
}

/// [`source_grey`] from a mask already made (stored at training, see
/// [`crate::db::masks`]): the same Hermite darkening, matte and isolation; `angle` is 0
/// (the caller has the database's). Identical to [`source_grey`] when `mask` is
/// [`frame_mask`]'s for this frame.
pub fn source_grey_with_mask(
    frame: &RgbaFrame,
    mask: &GrayImage,
    pose: &ClipPose,
    p: &PreprocessParams,
) -> SourceGrey {
    let (matte, area) = feather_in(mask, frame.width().max(frame.height()));
    let grey = match (pose.isolate, area) {
        (true, Some(b)) => hermite_darken_rgba_in(frame, mask, &matte, b, &p.hermite),
        // Nothing to keep: every pixel is multiplied by a matte of 0.
        (true, None) => GrayFrame::new(frame.size()),
        (false, _) => hermite_darken_rgba(frame, mask, None, &p.hermite),
    };
    let grey = without_still_lights(grey, pose);
    SourceGrey {
        grey,
        matte,
        angle: 0.0,
        mask_pixels: mask_area(mask),
    }
}

/// `grey` with the clip's still lights blanked: without isolation the Hermite darkening
/// keeps anything brighter than `i_max`, a lamp too (with isolation the grey is already
/// cut to the mask, which leaves them out).
fn without_still_lights(mut grey: GrayFrame, pose: &ClipPose) -> GrayFrame {
    if !pose.isolate && !pose.still_lights.is_empty() {
        let w = grey.width() as usize;
        pose.still_lights.clear(grey.data_mut(), w, 0.0);
    }
    grey
}

/// [`source_grey_with_mask`] for renders: the feather's blur at half resolution
/// ([`feather_half_in`], within [`FEATHER_HALF_TOLERANCE`] of the matte training made),
/// and an 8-bit frame ([`crate::footage::SourceFrame::Srgb8`]) read as it is where the
/// isolation keeps pixels (bit for bit the result on the frame in linear light).
pub fn source_grey_with_mask_src(
    frame: &crate::footage::SourceFrame,
    mask: &GrayImage,
    pose: &ClipPose,
    p: &PreprocessParams,
) -> SourceGrey {
    use crate::footage::SourceFrame;
    let size = frame.size();
    let (matte, area) = feather_half_in(mask, size.width.max(size.height));
    let grey = match (pose.isolate, area, frame) {
        (true, Some(b), SourceFrame::Srgb8 { bytes, .. }) => {
            crate::hermite::hermite_darken_srgb8_in(size, bytes, mask, &matte, b, &p.hermite)
        }
        (true, Some(b), SourceFrame::Linear(f)) => {
            hermite_darken_rgba_in(f, mask, &matte, b, &p.hermite)
        }
        // Nothing to keep: every pixel is multiplied by a matte of 0.
        (true, None, _) => GrayFrame::new(size),
        (false, _, _) => hermite_darken_rgba(&frame.to_linear(), mask, None, &p.hermite),
    };
    let grey = without_still_lights(grey, pose);
    SourceGrey {
        grey,
        matte,
        angle: 0.0,
        mask_pixels: mask_area(mask),
    }
}

/// A soft matte from a binary mask: 1 inside the mask, and outside it the mask dilated by
/// and blurred over about 1 % of the frame's longer side (at least 2 px), so the flame's
/// glow fades out instead of being cut.
///
/// Computed on the mask's bounding box grown by the dilation and twice the blur's reach
/// (everything farther is 0 either way), so a small flame in a large frame costs little;
/// the result is the same as over the whole frame.
pub fn feather(mask: &GrayImage, longer: u32) -> GrayFrame {
    feather_in(mask, longer).0
}

/// The feather's dilation reach for frames whose longer side is `longer` pixels: 1 %,
/// 2 to 40 px.
fn feather_reach(longer: u32) -> u8 {
    ((longer as f32 * 0.01).round() as u8).clamp(2, 40)
}

fn mask_size(mask: &GrayImage) -> Size {
    Size {
        width: mask.width(),
        height: mask.height(),
    }
}

/// The part of `mask` the feather of reach `r` can change, and its box `(x0, y0, x1, y1)`
/// (end-exclusive): the mask's bounds widened by the dilation's reach `r`, the blur's
/// reach ⌈2σ⌉ = r (σ = r/2) twice, and a little slack. `None` for an empty mask.
fn feather_crop(mask: &GrayImage, r: u8) -> Option<(GrayImage, (u32, u32, u32, u32))> {
    let e = mask_bounds(mask)?;
    let m = 3 * r as u32 + 2;
    let (x0, y0) = (e.0.saturating_sub(m), e.1.saturating_sub(m));
    let (x1, y1) = (
        (e.2 + m + 1).min(mask.width()),
        (e.3 + m + 1).min(mask.height()),
    );
    let (w, cw) = (mask.width() as usize, (x1 - x0) as usize);
    let mut data = Vec::with_capacity(cw * (y1 - y0) as usize);
    for y in y0 as usize..y1 as usize {
        let at = y * w + x0 as usize;
        data.extend_from_slice(&mask.as_raw()[at..at + cw]);
    }
    let crop = GrayImage::from_raw(x1 - x0, y1 - y0, data).expect("the box's bytes");
    Some((crop, (x0, y0, x1, y1)))
}

/// [`feather`], and the box `(x0, y0, x1, y1)` (end-exclusive) outside which it is 0;
/// `None` for an empty mask (all 0).
fn feather_in(mask: &GrayImage, longer: u32) -> (GrayFrame, Option<(u32, u32, u32, u32)>) {
    let r = feather_reach(longer);
    let mut out = GrayFrame::new(mask_size(mask));
    let Some((crop, (x0, y0, x1, y1))) = feather_crop(mask, r) else {
        return (out, None);
    };
    let d = dilate_l2(&crop, r);
    let b = gaussian_blur_u8(&d, r as f32 * 0.5);
    let size = out.size();
    let (cw, w) = ((x1 - x0) as usize, size.width as usize);
    for (cy, (brow, mrow)) in b
        .as_raw()
        .chunks_exact(cw)
        .zip(crop.as_raw().chunks_exact(cw))
        .enumerate()
    {
        let at = (y0 as usize + cy) * w + x0 as usize;
        for ((o, &v), &mv) in out.data_mut()[at..at + cw].iter_mut().zip(brow).zip(mrow) {
            *o = if mv > 0 { 1.0 } else { v as f32 / 255.0 };
        }
    }
    (out, Some((x0, y0, x1, y1)))
}

/// [`feather_in`] for renders, with the Gaussian at half resolution: the exact dilation
/// of the mask's box, averaged over 2×2 blocks, blurred there with σ reduced so the
/// averaging and the bilinear doubling back (variance ¼ + ¾ px²) keep the total σ², then
/// doubled bilinearly; 1 inside the mask as in [`feather_in`]. Within
/// [`FEATHER_HALF_TOLERANCE`] of [`feather_in`] on every pixel (test
/// `half_resolution_feather_is_within_tolerance`); the same box. Frames whose dilation
/// reach is under 8 px (longer side under 750 px) get [`feather_in`] itself (cheap
/// there, and the half-resolution blur's kernel would be too coarse).
pub fn feather_half_in(mask: &GrayImage, longer: u32) -> (GrayFrame, Option<(u32, u32, u32, u32)>) {
    let r = feather_reach(longer);
    if r < 8 {
        return feather_in(mask, longer);
    }
    let size = mask_size(mask);
    let Some((crop, (x0, y0, x1, y1))) = feather_crop(mask, r) else {
        return (GrayFrame::new(size), None);
    };
    let d = dilate_l2(&crop, r);
    let (cw, ch) = ((x1 - x0) as usize, (y1 - y0) as usize);
    let (hw, hh) = (cw.div_ceil(2), ch.div_ceil(2));
    let dr = d.as_raw();
    // 2×2 block means (rounded), the last column and row clamped.
    let mut hd = Vec::with_capacity(hw * hh);
    for v in 0..hh {
        let (ra, rb) = (
            &dr[2 * v * cw..][..cw],
            &dr[(2 * v + 1).min(ch - 1) * cw..][..cw],
        );
        hd.extend((0..hw).map(|u| {
            let (u, u1) = (2 * u, (2 * u + 1).min(cw - 1));
            let sum = ra[u] as u32 + ra[u1] as u32 + rb[u] as u32 + rb[u1] as u32;
            ((sum + 2) / 4) as u8
        }));
    }
    let half = GrayImage::from_raw(hw as u32, hh as u32, hd).expect("hw × hh bytes");
    let sigma = r as f32 * 0.5;
    let b = gaussian_blur_u8(&half, (sigma * sigma - 1.0).max(0.25).sqrt() * 0.5);
    let br = b.as_raw();
    // Bilinear doubling: full pixel x samples half position x/2 − 1/4, i.e. weights
    // (1/4, 3/4) on half pixels (q−1, q) for x = 2q and (3/4, 1/4) on (q, q+1) for 2q+1.
    let taps = |x: usize, n: usize| -> (usize, usize, f32) {
        let q = x / 2;
        if x.is_multiple_of(2) {
            (q.saturating_sub(1), q, 0.25)
        } else {
            (q, (q + 1).min(n - 1), 0.75)
        }
    };
    let xt: Vec<(usize, usize, f32)> = (0..cw).map(|x| taps(x, hw)).collect();
    let w = size.width as usize;
    let mut row = vec![0.0f32; hw];
    // Written once, row by row (0 outside the box), never zero-filled first.
    let mut out = Vec::with_capacity(size.pixels());
    out.resize(y0 as usize * w, 0.0);
    for cy in 0..ch {
        out.resize(out.len() + w, 0.0);
        let (ya, yb, fy) = taps(cy, hh);
        for (o, (&a, &c)) in row.iter_mut().zip(
            br[ya * hw..ya * hw + hw]
                .iter()
                .zip(&br[yb * hw..yb * hw + hw]),
        ) {
            *o = a as f32 * fy + c as f32 * (1.0 - fy);
        }
        let at = (y0 as usize + cy) * w + x0 as usize;
        let mrow = &crop.as_raw()[cy * cw..cy * cw + cw];
        for ((o, &(xa, xb, fx)), &mv) in out[at..at + cw].iter_mut().zip(&xt).zip(mrow) {
            *o = if mv > 0 {
                1.0
            } else {
                (row[xa] * fx + row[xb] * (1.0 - fx)) * (1.0 / 255.0)
            };
        }
    }
    out.resize(size.pixels(), 0.0);
    let out = GrayFrame::from_vec(size, out).expect("the frame's pixels");
    (out, Some((x0, y0, x1, y1)))
}

/// Largest difference of [`feather_half_in`] from [`feather_in`] on any pixel (matte
/// units, 0..1). Measured: 0.034 where the feather meets the frame's edge (clamping at
/// half resolution), at most 0.016 inside the frame.
pub const FEATHER_HALF_TOLERANCE: f32 = 0.04;

/// `imageproc::filter::gaussian_blur_f32` on a grey image, bit for bit (the same kernel,
/// the same order of sums, clamp-to-edge, truncation to 8 bits after each pass), with
/// whole runs of pixels summed at once so the compiler vectorises it.
///
/// Where a pixel's whole window holds one value `q` (inside or outside a mask, the bulk
/// of a feather's box) its sum is the same sequence of operations for every such pixel,
/// so it is read from a table of the 256 possible results ([`flat_sums`]); only pixels
/// whose window holds a change of value are summed. Exact for any image.
fn gaussian_blur_u8(img: &GrayImage, sigma: f32) -> GrayImage {
    let kernel = gaussian_kernel_u8(sigma);
    let kr = kernel.len() / 2;
    let (w, h) = (img.width() as usize, img.height() as usize);
    if w == 0 || h == 0 {
        return img.clone();
    }
    let table = flat_sums(&kernel);
    // Horizontal: each row padded by its edge values; x needs summing when a change of
    // value between t−1 and t lies in its window (t ∈ [x−kr+1, x+kr]).
    let mut tmp = vec![0u8; w * h];
    let mut pad = vec![0.0f32; w + 2 * kr];
    let mut acc = vec![0.0f32; w];
    let mut busy = vec![false; w];
    for (src, dst) in img.as_raw().chunks_exact(w).zip(tmp.chunks_exact_mut(w)) {
        busy.fill(false);
        for t in 1..w {
            if src[t] != src[t - 1] {
                busy[t.saturating_sub(kr)..(t + kr).min(w)].fill(true);
            }
        }
        for (d, &v) in dst.iter_mut().zip(src) {
            *d = table[v as usize];
        }
        for (a, b) in runs(&busy) {
            for (j, p) in pad[a..b + 2 * kr].iter_mut().enumerate() {
                *p = src[(a + j).saturating_sub(kr).min(w - 1)] as f32;
            }
            let acc = &mut acc[a..b];
            acc.fill(0.0);
            for (i, &k) in kernel.iter().enumerate() {
                for (s, &p) in acc.iter_mut().zip(&pad[a + i..b + i]) {
                    *s += p * k;
                }
            }
            for (d, &s) in dst[a..b].iter_mut().zip(acc.iter()) {
                *d = s as u8;
            }
        }
    }
    // Vertical: rows clamped to the image; x needs summing when some pair of rows
    // (s, s+1) with s ∈ [y−kr, y+kr−1] differs there (a sliding count of such pairs).
    let row = |y: usize| &tmp[y * w..y * w + w];
    let mut changes = vec![0u16; w];
    let pair = |s: usize, cnt: &mut [u16], add: bool| {
        if s + 1 < h {
            for ((c, &a), &b) in cnt.iter_mut().zip(row(s)).zip(row(s + 1)) {
                let d = (a != b) as u16;
                *c = if add { *c + d } else { *c - d };
            }
        }
    };
    for s in 0..kr.min(h) {
        pair(s, &mut changes, true);
    }
    let mut out = GrayImage::new(w as u32, h as u32);
    for (y, dst) in out.chunks_exact_mut(w).enumerate() {
        // The window of pairs [y−kr, y+kr−1]: add y+kr−1, drop y−kr−1.
        if y > 0 {
            pair(y + kr - 1, &mut changes, true);
            if y > kr {
                pair(y - kr - 1, &mut changes, false);
            }
        }
        for (d, &v) in dst.iter_mut().zip(row(y)) {
            *d = table[v as usize];
        }
        for (b, &c) in busy.iter_mut().zip(&changes) {
            *b = c > 0;
        }
        for (a, b) in runs(&busy) {
            let acc = &mut acc[a..b];
            acc.fill(0.0);
            for (i, &k) in kernel.iter().enumerate() {
                let sy = (y + i).saturating_sub(kr).min(h - 1);
                for (s, &p) in acc.iter_mut().zip(&row(sy)[a..b]) {
                    *s += p as f32 * k;
                }
            }
            for (d, &s) in dst[a..b].iter_mut().zip(acc.iter()) {
                *d = s as u8;
            }
        }
    }
    out
}

/// imageproc's Gaussian kernel for `sigma`: radius ⌈2σ⌉, normalised to sum 1.
fn gaussian_kernel_u8(sigma: f32) -> Vec<f32> {
    let pdf = |x: f32| {
        (sigma * (2.0 * std::f32::consts::PI).sqrt()).recip()
            * (-x.powi(2) / (2.0 * sigma.powi(2))).exp()
    };
    let kr = (2.0 * sigma).ceil() as usize;
    let mut kernel = vec![0.0f32; 2 * kr + 1];
    for i in 0..kr + 1 {
        let v = pdf(i as f32);
        kernel[kr + i] = v;
        kernel[kr - i] = v;
    }
    let sum: f32 = kernel.iter().sum();
    kernel.iter_mut().for_each(|x| *x /= sum);
    kernel
}

/// For each value `q`, the 8-bit result of summing `q × k` over `kernel` in order from
/// 0.0 — what [`gaussian_blur_u8`] computes for a window of `q`s.
fn flat_sums(kernel: &[f32]) -> [u8; 256] {
    std::array::from_fn(|q| {
        let mut a = 0.0f32;
        for &k in kernel {
            a += q as f32 * k;
        }
        a as u8
    })
}

/// The maximal runs `(start, end)` of `true` in `flags` (no allocation: called per row).
fn runs(flags: &[bool]) -> impl Iterator<Item = (usize, usize)> + '_ {
    let mut x = 0;
    std::iter::from_fn(move || {
        let a = x + flags.get(x..)?.iter().position(|&f| f)?;
        let b = flags[a..]
            .iter()
            .position(|&f| !f)
            .map_or(flags.len(), |e| a + e);
        x = b;
        Some((a, b))
    })
}

/// `imageproc::morphology::dilate(img, Norm::L2, r)`, exactly: 255 where a non-zero pixel
/// lies within Euclidean distance `r` (`dx² + dy² ≤ r²`), else 0. (imageproc clamps
/// distances at 255, so at `r = 255` every pixel is set.)
///
/// Each row's runs of set pixels are found once; an output row is then the union of the
/// runs of the rows `dy` away (|dy| ≤ r), each widened by the disc's half-chord
/// `⌊√(r² − dy²)⌋` — a few intervals per row, merged and filled, instead of imageproc's
/// floating-point distance transform or a pass over every row in reach.
pub(crate) fn dilate_l2(img: &GrayImage, r: u8) -> GrayImage {
    let (w, h) = (img.width() as usize, img.height() as usize);
    if w == 0 || h == 0 {
        return GrayImage::new(w as u32, h as u32);
    }
    if r == u8::MAX {
        return GrayImage::from_pixel(w as u32, h as u32, image::Luma([255]));
    }
    let r = r as usize;
    // Runs `[a, b)` of set pixels, row by row (`first[y]..first[y + 1]`).
    let mut spans: Vec<(usize, usize)> = Vec::new();
    let mut first = Vec::with_capacity(h + 1);
    for row in img.as_raw().chunks_exact(w) {
        first.push(spans.len());
        let mut x = 0;
        while let Some(a) = first_set(&row[x..]) {
            let a = x + a;
            let b = row[a..].iter().position(|&v| v == 0).map_or(w, |e| a + e);
            spans.push((a, b));
            x = b;
        }
    }
    first.push(spans.len());
    // Half-chord of the disc at each vertical offset (|dy| ≤ r).
    let chord: Vec<usize> = (0..=r)
        .map(|dy| {
            let mut c = 0;
            while (c + 1) * (c + 1) + dy * dy <= r * r {
                c += 1;
            }
            c
        })
        .collect();
    let mut data = Vec::with_capacity(w * h);
    let mut iv: Vec<(usize, usize)> = Vec::new();
    for y in 0..h {
        iv.clear();
        for sy in y.saturating_sub(r)..=(y + r).min(h - 1) {
            let c = chord[sy.abs_diff(y)];
            iv.extend(
                spans[first[sy]..first[sy + 1]]
                    .iter()
                    .map(|&(a, b)| (a.saturating_sub(c), (b + c).min(w))),
            );
        }
        iv.sort_unstable();
        let at = data.len();
        data.resize(at + w, 0u8);
        let row = &mut data[at..];
        let mut end = 0;
        for &(a, b) in &iv {
            let a = a.max(end);
            if b > a {
                row[a..b].fill(255);
                end = b;
            }
        }
    }
    GrayImage::from_raw(w as u32, h as u32, data).expect("w × h bytes")
}

/// `imageproc::morphology::erode(img, Norm::L2, r)`, exactly: 0 where a zero pixel lies
/// within Euclidean distance `r`, else 255 — the complement of [`dilate_l2`] of the zero
/// pixels.
pub(crate) fn erode_l2(img: &GrayImage, r: u8) -> GrayImage {
    let flip = |g: &GrayImage| {
        let data = g.as_raw().iter().map(|&v| if v == 0 { 255 } else { 0 });
        GrayImage::from_raw(g.width(), g.height(), data.collect()).expect("w × h bytes")
    };
    flip(&dilate_l2(&flip(img), r))
}

/// Bytes per block of [`first_set`] / [`last_set`].
const SCAN: usize = 32;

/// Index of the first non-zero byte of `row`: whole blocks are tested with an OR of their
/// bytes (vectorised), only the block that holds one is searched byte by byte.
fn first_set(row: &[u8]) -> Option<usize> {
    let blk = row
        .chunks(SCAN)
        .position(|c| c.iter().fold(0u8, |a, &v| a | v) != 0)?;
    let at = blk * SCAN;
    row[at..].iter().position(|&v| v > 0).map(|i| at + i)
}

/// Index of the last non-zero byte of `row` (as [`first_set`], from the end).
fn last_set(row: &[u8]) -> Option<usize> {
    let n = row.len();
    let blk = row
        .rchunks(SCAN)
        .position(|c| c.iter().fold(0u8, |a, &v| a | v) != 0)?;
    let end = n - blk * SCAN;
    row[..end].iter().rposition(|&v| v > 0)
}

/// The inclusive bounds `(x0, y0, x1, y1)` of a mask's non-zero pixels; `None` if empty.
fn mask_bounds(mask: &GrayImage) -> Option<(u32, u32, u32, u32)> {
    let w = mask.width() as usize;
    let mut b: Option<(u32, u32, u32, u32)> = None;
    for (y, row) in mask.as_raw().chunks_exact(w.max(1)).enumerate() {
        let Some(a) = first_set(row) else {
            continue;
        };
        let z = last_set(row).expect("a set byte exists");
        let (a, z, y) = (a as u32, z as u32, y as u32);
        b = Some(match b {
            None => (a, y, z, y),
            Some((x0, y0, x1, _)) => (x0.min(a), y0, x1.max(z), y),
        });
    }
    b
}

/// [`feather`] over the whole frame, as it was first written: the reference the
/// bounding-box version is tested against.
#[cfg(test)]
fn feather_whole(mask: &GrayImage, longer: u32) -> GrayFrame {
    let r = feather_reach(longer);
    let d = imageproc::morphology::dilate(mask, imageproc::distance_transform::Norm::L2, r);
    let b = imageproc::filter::gaussian_blur_f32(&d, r as f32 * 0.5);
    let size = Size {
        width: mask.width(),
        height: mask.height(),
    };
    GrayFrame::from_vec(
        size,
        b.as_raw()
            .iter()
            .zip(mask.as_raw())
            .map(|(&v, &m)| if m > 0 { 1.0 } else { v as f32 / 255.0 })
            .collect(),
    )
    .expect("same size")
}

/// Every stage of the pipeline for one frame, for `ignis eigen preprocess`.
#[derive(Clone, Debug)]
pub struct FrameStages {
    /// `(stage name, image)` in pipeline order; images are linear-light grey RGBA at the
    /// source size, except `normalised` (frame size) and `train` (training size).
    pub images: Vec<(&'static str, RgbaFrame)>,
    pub processed: Processed,
}

fn mask_rgba(m: &GrayImage) -> RgbaFrame {
    let size = Size {
        width: m.width(),
        height: m.height(),
    };
    GrayFrame::from_vec(size, m.as_raw().iter().map(|&v| v as f32 / 255.0).collect())
        .expect("same size")
        .to_rgba()
}

/// Runs the pipeline keeping every intermediate image: `1-hsv`, `2-mask` (after
/// morphology and smoothing), `3-edges` (Canny), `4-contours` (kept contours bright,
/// removed ones dim), `5-filled`, `6-gray`, `7-hermite`, `8-normalised`, `9-train`.
pub fn preprocess_stages(frame: &RgbaFrame, pose: &ClipPose, p: &PreprocessParams) -> FrameStages {
    let raw = hsv_mask(frame, &p.mask.layers);
    let m = flame_mask_without(frame, &p.mask, pose.isolate, &pose.still_lights);
    let nodes = contour_tree(&m);
    let keep = remove_holes(
        &nodes,
        &p.contours,
        frame.width() as f64 * frame.height() as f64,
    );
    let lines = draw_contours(frame.width(), frame.height(), &nodes, &keep);
    let filled = fill_contours(
        frame.width(),
        frame.height(),
        &nodes,
        &keep,
        p.contours.simplify_epsilon,
    );
    let gray = frame.luminance();
    let herm = source_grey(frame, pose, p).grey;
    let processed = preprocess_frame(frame, pose, p);
    let images = vec![
        ("1-hsv", mask_rgba(&raw)),
        ("2-mask", mask_rgba(&m)),
        ("3-edges", mask_rgba(&mask_edges(&m, &p.mask))),
        ("4-contours", mask_rgba(&lines)),
        ("5-filled", mask_rgba(&filled)),
        ("6-gray", gray.to_rgba()),
        ("7-hermite", herm.to_rgba()),
        ("8-normalised", processed.frame.to_rgba()),
        ("9-train", processed.train.to_rgba()),
    ];
    FrameStages { images, processed }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::synthetic::{synthetic_clip, SyntheticParams};

    /// The row-wise Gaussian is imageproc's, bit for bit, for every radius the feather
    /// uses and images narrower than the kernel.
    #[test]
    fn gaussian_blur_u8_equals_imageproc() {
        for (w, h) in [(61u32, 37u32), (5, 3), (1, 9)] {
            let img = GrayImage::from_fn(w, h, |x, y| {
                image::Luma([((x * 37 + y * 91 + x * y * 7) % 256) as u8])
            });
            // the feather's radii, and the mask smoothing's sigmas (`mask.smooth_sigma`,
            // default 1, any value in 0..=50)
            let fractional = [0.05, 0.3, 0.7, 1.3, 2.2, 3.7, 25.0, 49.9, 50.0];
            for s in (2..=40u8).map(|r| r as f32 * 0.5).chain(fractional) {
                assert_eq!(
                    gaussian_blur_u8(&img, s),
                    imageproc::filter::gaussian_blur_f32(&img, s),
                    "{w}x{h} sigma {s}"
                );
            }
        }
    }

    /// The same on images made of flat regions (where the blur reads its table): blobs of
    /// 255 on 0, steps of several values, a constant image, lone pixels near edges.
    #[test]
    fn gaussian_blur_u8_on_flat_regions_equals_imageproc() {
        let (w, h) = (90u32, 70u32);
        let shapes: Vec<GrayImage> = vec![
            GrayImage::from_fn(w, h, |x, y| {
                let d = (x as i32 - 40).pow(2) + (y as i32 - 30).pow(2);
                image::Luma([if d <= 400 { 255 } else { 0 }])
            }),
            GrayImage::from_fn(w, h, |x, y| {
                image::Luma([((x / 23 + y / 17) * 60 % 256) as u8])
            }),
            GrayImage::from_pixel(w, h, image::Luma([200])),
            GrayImage::from_fn(w, h, |x, y| {
                image::Luma([
                    if (x, y) == (0, 5) || (x, y) == (89, 69) || (x, y) == (45, 0) {
                        255
                    } else {
                        7
                    },
                ])
            }),
            GrayImage::from_fn(3, 50, |_, y| image::Luma([if y > 25 { 255 } else { 0 }])),
        ];
        for img in &shapes {
            for r in [2u8, 3, 5, 19, 40] {
                let s = r as f32 * 0.5;
                assert_eq!(
                    gaussian_blur_u8(img, s),
                    imageproc::filter::gaussian_blur_f32(img, s),
                    "{}x{} sigma {s}",
                    img.width(),
                    img.height()
                );
            }
        }
    }

    /// The row-sweep dilation is imageproc's L2 dilation, pixel for pixel: random sparse
    /// and dense masks, single pixels at the borders, empty masks, every feather radius.
    /// The half-resolution feather of renders is within `FEATHER_HALF_TOLERANCE` of the
    /// exact one on every pixel, with the same box: a disc, a ragged flame with a hole,
    /// a one-pixel line, a mask touching the frame's corner, at three frame sizes.
    #[test]
    fn half_resolution_feather_is_within_tolerance() {
        let mut worst = 0.0f32;
        for (w, h) in [(800u32, 600u32), (1080, 1920), (1920, 1080)] {
            let s = w.max(h) as f32 / 1000.0;
            let shapes: [&dyn Fn(f32, f32) -> bool; 4] = [
                &|x, y| (x - 0.5 * w as f32).hypot(y - 0.6 * h as f32) < 90.0 * s,
                &|x, y| {
                    let (dx, dy) = (x - 0.4 * w as f32, y - 0.5 * h as f32);
                    let rr =
                        150.0 * s * (1.0 + 0.3 * (dy * 0.05 / s).sin() + 0.2 * (dx * 0.11).sin());
                    dx.abs() * 2.0 + dy.abs() < rr && dx.hypot(dy + 20.0 * s) > 25.0 * s
                },
                &|x, _| (x - 0.3 * w as f32).abs() < 0.6,
                &|x, y| x + y < 60.0 * s,
            ];
            for f in shapes {
                let m = GrayImage::from_fn(w, h, |x, y| {
                    image::Luma([if f(x as f32 + 0.5, y as f32 + 0.5) {
                        255
                    } else {
                        0
                    }])
                });
                let longer = w.max(h);
                let (a, ba) = feather_in(&m, longer);
                let (b, bb) = feather_half_in(&m, longer);
                assert_eq!(ba, bb);
                let mut wmax = (0.0f32, 0usize);
                for (i, (&p, &q)) in a.data().iter().zip(b.data()).enumerate() {
                    if (p - q).abs() > wmax.0 {
                        wmax = ((p - q).abs(), i);
                    }
                    worst = worst.max((p - q).abs());
                }
                let i = wmax.1;
                println!(
                    "{w}x{h}: largest difference {} at ({}, {})",
                    wmax.0,
                    i % w as usize,
                    i / w as usize
                );
            }
        }
        println!("half-resolution feather: largest difference {worst}");
        assert!(worst <= FEATHER_HALF_TOLERANCE, "{worst}");
        // Small frames: the exact feather.
        let m = GrayImage::from_fn(600, 400, |x, y| {
            image::Luma([((x as i32 - 50).pow(2) + (y as i32 - 40).pow(2) < 200) as u8 * 255])
        });
        assert_eq!(feather_half_in(&m, 600).0, feather_in(&m, 600).0);
        assert!(feather_half_in(&GrayImage::new(500, 400), 500).1.is_none());
    }

    /// The block searches find what a byte-by-byte search finds.
    #[test]
    fn first_and_last_set_equal_the_plain_search() {
        for n in [0usize, 1, 31, 32, 33, 70, 200] {
            for set in [None, Some(0), Some(n / 2), Some(n.saturating_sub(1))] {
                for extra in [None, Some(n / 3)] {
                    let mut row = vec![0u8; n];
                    for i in [set, extra].into_iter().flatten().filter(|&i| i < n) {
                        row[i] = 7;
                    }
                    assert_eq!(first_set(&row), row.iter().position(|&v| v > 0), "{n}");
                    assert_eq!(last_set(&row), row.iter().rposition(|&v| v > 0), "{n}");
                }
            }
        }
    }

    #[test]
    fn dilate_and_erode_l2_equal_imageproc() {
        let mut seed = 7u64;
        let mut rnd = move || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 33) as u32
        };
        for (w, h, density) in [(97u32, 61u32, 400u32), (50, 80, 30), (7, 5, 10), (1, 30, 5)] {
            let img = GrayImage::from_fn(w, h, |_, _| {
                image::Luma([if rnd() % density == 0 { 200 } else { 0 }])
            });
            let corner = GrayImage::from_fn(w, h, |x, y| {
                image::Luma([if (x, y) == (w - 1, 0) || (x, y) == (0, h - 1) {
                    9
                } else {
                    0
                }])
            });
            let empty = GrayImage::new(w, h);
            let full = GrayImage::from_pixel(w, h, image::Luma([1]));
            let holes = GrayImage::from_fn(w, h, |_, _| {
                image::Luma([if rnd() % density == 0 { 0 } else { 77 }])
            });
            use imageproc::distance_transform::Norm::L2;
            use imageproc::morphology as mo;
            for m in [&img, &corner, &empty, &full, &holes] {
                for r in [0u8, 1, 2, 3, 7, 19, 40, 255] {
                    assert_eq!(dilate_l2(m, r), mo::dilate(m, L2, r), "{w}x{h} r {r}");
                    assert_eq!(erode_l2(m, r), mo::erode(m, L2, r), "{w}x{h} r {r}");
                }
            }
        }
    }

    /// The bounding-box feather is the whole-frame feather, bit for bit: blobs inside,
    /// at the edges and corners, two far apart, an empty mask; small and large radii.
    #[test]
    fn feather_on_the_bounding_box_equals_the_whole_frame() {
        let (w, h) = (150u32, 90u32);
        let blob = |cx: i32, cy: i32, rr: i32| {
            move |x: u32, y: u32| (x as i32 - cx).pow(2) + (y as i32 - cy).pow(2) <= rr * rr
        };
        let shapes: Vec<Box<dyn Fn(u32, u32) -> bool>> = vec![
            Box::new(blob(75, 45, 10)),
            Box::new(blob(0, 0, 6)),
            Box::new(blob(149, 89, 4)),
            Box::new(|x, y| blob(20, 70, 5)(x, y) || blob(130, 10, 3)(x, y)),
            Box::new(|x, _| x == 149),
            Box::new(|_, _| false),
        ];
        for f in &shapes {
            let m = GrayImage::from_fn(w, h, |x, y| image::Luma([if f(x, y) { 255 } else { 0 }]));
            for longer in [150, 700, 4000] {
                let a = feather(&m, longer);
                let b = feather_whole(&m, longer);
                assert!(
                    a.data()
                        .iter()
                        .zip(b.data())
                        .all(|(p, q)| p.to_bits() == q.to_bits()),
                    "longer {longer}"
                );
            }
        }
    }

    #[test]
    fn toml_roundtrip_and_defaults() {
        let p = PreprocessParams::default();
        let text = toml::to_string(&p).unwrap();
        assert_eq!(PreprocessParams::from_toml(&text).unwrap(), p);
        let q = PreprocessParams::from_toml(
            "train_size = \"64x96\"\n[hermite]\ni_min = 0.2\n[[mask.layers]]\nv = [0.5, 1.0]\n",
        )
        .unwrap();
        assert_eq!(
            q.train_size,
            Some(Size {
                width: 64,
                height: 96
            })
        );
        assert_eq!(q.hermite.i_min, 0.2);
        assert_eq!(q.mask.layers.len(), 1);
        assert!(PreprocessParams::from_toml("[hermite]\ni_min = 0.9\ni_max = 0.1\n").is_err());
        assert!(PreprocessParams::from_toml("bogus = 1\n").is_err());
    }

    #[test]
    fn pipeline_on_synthetic() {
        let frames = synthetic_clip(&SyntheticParams {
            frames: 2,
            ..Default::default()
        })
        .unwrap();
        let p = PreprocessParams::with_sizes(
            Size::new(48, 80).unwrap(),
            Some(Size::new(24, 40).unwrap()),
        );
        let fm = frame_mask(&frames[0], &p, false);
        let e = fm.extent.expect("flame found");
        let pose = crate::pose::clip_pose("synthetic", &[Some(e)], &p.pose).unwrap();
        let st = preprocess_stages(&frames[0], &pose, &p);
        assert_eq!(st.images.len(), 9);
        assert_eq!(st.processed.train.size(), Size::new(24, 40).unwrap());
        assert!(st.processed.train.max() > 0.3);
        // The glow far from the flame is removed.
        let h = &st.images[6].1;
        assert_eq!(h.get(2, 2)[0], 0.0);
    }
}
