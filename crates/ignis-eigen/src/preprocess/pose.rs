//! Pose normalisation: per-clip centring on the fuel and scaling to one training frame
//! size, and optional rotation from a weighted least-squares line fit to the contour.
//!
//! Source: eigenfires-thesis.txt §3.4 and §3.4.1, eq. (7)–(11), Figure 21; §4.2 (all clips
//! brought to one frame size, 410×670 in the thesis).
//!
//! Departures:
//! - The thesis centres and scales "via our user interface within a few clicks". Here it is
//!   automatic: over a sample of the clip's masks, the fuel is the median of each mask's
//!   lowest point (x: centroid of the lowest 10 % of the flame's rows), and the scale makes
//!   the 90th-percentile flame height fill `fill` of the frame height (limited so that the
//!   90th-percentile width fits the frame width). Both can be overridden per clip.
//! - The line of eq. (7) is fitted as `x = m·y + b` rather than `y = m·x + b`: flames are
//!   mostly vertical, where `y = m·x + b` is ill-conditioned (the "line constructed in
//!   another direction" problem the thesis remedies by hand). Weights grow linearly from 1
//!   at the tip to 3 at the root (remedy 3 of §3.4.1). The end points are the extreme
//!   perpendicular projections (eq. 9–11) of the contour points onto the line.

use crate::contour::ContourNode;
use crate::error::{EigenError, Result};
use crate::still::StillLights;
use ignis_core::{GrayFrame, Size};
use image::GrayImage;
use serde::{Deserialize, Serialize};

/// Settings of pose normalisation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PoseParams {
    /// The common frame size every clip is brought to, `"WIDTHxHEIGHT"`, or `"auto"`
    /// (default): the smallest frame that holds every clip at its own resolution, each
    /// clip placed bottom-centred at scale 1 (see [`auto_framing`]), so nothing is
    /// clipped or resampled. A fixed size (the thesis's 410x670, §4.2) centres and scales
    /// each clip on its fuel instead.
    #[serde(with = "size_str::auto")]
    pub frame_size: Option<Size>,
    /// Fraction of the frame height the clip's tall (90th-percentile) flame fills,
    /// `0.1..=1`. Default 0.85.
    pub fill: f32,
    /// Fraction of the frame height left below the fuel, `0..0.5`. Default 0.05.
    pub base_margin: f32,
    /// Rotate each frame upright around the fuel using the weighted least-squares line
    /// (§3.4.1); the angle is stored so it can be undone. Default false (the direction is
    /// one of the Eigenfires' main features, §3.4.1).
    pub rotate: bool,
}

impl Default for PoseParams {
    fn default() -> Self {
        PoseParams {
            frame_size: None,
            fill: 0.85,
            base_margin: 0.05,
            rotate: false,
        }
    }
}

/// The thesis's common frame size (§4.2), used where a fixed size is needed and none
/// was resolved.
pub const THESIS_FRAME: Size = Size {
    width: 410,
    height: 670,
};

impl PoseParams {
    /// The frame size (the thesis's 410x670 while `auto` is unresolved).
    pub fn frame(&self) -> Size {
        self.frame_size.unwrap_or(THESIS_FRAME)
    }

    pub fn validate(&self) -> Result<()> {
        if let Some(f) = self.frame_size {
            Size::new(f.width, f.height)?;
        }
        if !(0.1..=1.0).contains(&self.fill) {
            return Err(EigenError::bad("pose.fill", "must be within 0.1..=1"));
        }
        if !(0.0..0.5).contains(&self.base_margin) {
            return Err(EigenError::bad("pose.base_margin", "must be within 0..0.5"));
        }
        Ok(())
    }
}

/// A clip's placement: source pixel `(fuel_x, base_y)` maps to the bottom centre of the
/// frame (above the margin), and source distances are multiplied by `scale`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClipPose {
    /// Fuel x in source pixels.
    pub fuel_x: f32,
    /// Fuel (flame root) y in source pixels.
    pub base_y: f32,
    /// Output pixels per source pixel.
    pub scale: f32,
    /// Flame isolation on this clip ([`crate::mask::isolate_flame`]).
    #[serde(default)]
    pub isolate: bool,
    /// Still lights (a lamp, a lit window) every frame's mask ignores
    /// ([`crate::still`]); found when the clip is planned. Default none.
    #[serde(default, skip_serializing_if = "StillLights::is_empty")]
    pub still_lights: StillLights,
}

/// Automatic framing: the common frame is the smallest that holds every clip (`sizes`)
/// at its own resolution; each clip sits bottom-centred in it at scale 1, on whole
/// pixels (the warp is then an exact copy). Returns the frame and one pose per clip
/// (with `base_margin` 0).
pub fn auto_framing(sizes: &[Size]) -> (Size, Vec<ClipPose>) {
    let fw = sizes.iter().map(|s| s.width).max().unwrap_or(1).max(1);
    let fh = sizes.iter().map(|s| s.height).max().unwrap_or(1).max(1);
    let poses = sizes
        .iter()
        .map(|s| {
            let ox = (fw - s.width) / 2;
            ClipPose {
                fuel_x: fw as f32 / 2.0 - ox as f32,
                base_y: s.height as f32,
                scale: 1.0,
                isolate: false,
                still_lights: StillLights::default(),
            }
        })
        .collect();
    (
        Size {
            width: fw,
            height: fh,
        },
        poses,
    )
}

/// Where a clip of `source` size lands in the common frame under `pose` (`x, y, w, h`,
/// in frame pixels, clamped to the frame): the view an output of that clip shows.
pub fn clip_rect(source: Size, pose: &ClipPose, p: &PoseParams) -> (u32, u32, u32, u32) {
    let f = p.frame();
    let cx = f.width as f32 / 2.0;
    let by = f.height as f32 * (1.0 - p.base_margin);
    let x0 = (cx - pose.fuel_x * pose.scale).round().max(0.0);
    let y0 = (by - pose.base_y * pose.scale).round().max(0.0);
    let x1 = (cx + (source.width as f32 - pose.fuel_x) * pose.scale)
        .round()
        .min(f.width as f32);
    let y1 = (by + (source.height as f32 - pose.base_y) * pose.scale)
        .round()
        .min(f.height as f32);
    let (x0, y0) = (x0.min(f.width as f32 - 1.0), y0.min(f.height as f32 - 1.0));
    (
        x0 as u32,
        y0 as u32,
        ((x1 - x0).max(1.0)) as u32,
        ((y1 - y0).max(1.0)) as u32,
    )
}

/// What one mask says about the flame's placement.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MaskExtent {
    pub fuel_x: f32,
    pub base_y: f32,
    pub height: f32,
    pub width: f32,
}

/// Extent of the flame in a mask, `None` when the mask is empty.
pub fn mask_extent(mask: &GrayImage) -> Option<MaskExtent> {
    let (w, h) = mask.dimensions();
    let raw = mask.as_raw();
    let mut top = None;
    let mut bottom = 0;
    let (mut x0, mut x1) = (w, 0);
    for y in 0..h {
        let row = &raw[(y * w) as usize..((y + 1) * w) as usize];
        if let (Some(a), Some(b)) = (
            row.iter().position(|&v| v > 0),
            row.iter().rposition(|&v| v > 0),
        ) {
            top.get_or_insert(y);
            bottom = y;
            x0 = x0.min(a as u32);
            x1 = x1.max(b as u32);
        }
    }
    let top = top?;
    let height = (bottom - top + 1) as f32;
    let band = ((height * 0.1).ceil() as u32).max(1);
    let (mut sx, mut n) = (0.0f64, 0u64);
    for y in bottom + 1 - band.min(bottom + 1)..=bottom {
        for x in 0..w {
            if raw[(y * w + x) as usize] > 0 {
                sx += x as f64 + 0.5;
                n += 1;
            }
        }
    }
    Some(MaskExtent {
        fuel_x: (sx / n.max(1) as f64) as f32,
        base_y: bottom as f32 + 1.0,
        height,
        width: (x1 - x0 + 1) as f32,
    })
}

fn percentile(v: &mut [f32], q: f32) -> f32 {
    v.sort_by(|a, b| a.total_cmp(b));
    v[((v.len() - 1) as f32 * q).round() as usize]
}

/// The clip's pose from the extents of a sample of its masks (empty masks ignored).
/// Fails, naming `clip`, when every mask is empty.
pub fn clip_pose(clip: &str, extents: &[Option<MaskExtent>], p: &PoseParams) -> Result<ClipPose> {
    let e: Vec<MaskExtent> = extents.iter().flatten().copied().collect();
    if e.is_empty() {
        return Err(EigenError::clip(
            clip,
            "the mask removes every pixel in every sampled frame; widen the HSV ranges (e.g. lower the V minimum) or check the range",
        ));
    }
    let mut fx: Vec<f32> = e.iter().map(|m| m.fuel_x).collect();
    let mut by: Vec<f32> = e.iter().map(|m| m.base_y).collect();
    let mut hs: Vec<f32> = e.iter().map(|m| m.height).collect();
    let mut ws: Vec<f32> = e.iter().map(|m| m.width).collect();
    let (fw, fh) = (p.frame().width as f32, p.frame().height as f32);
    let h90 = percentile(&mut hs, 0.9).max(1.0);
    let w90 = percentile(&mut ws, 0.9).max(1.0);
    let scale = (p.fill * fh / h90).min(0.95 * fw / w90);
    Ok(ClipPose {
        fuel_x: percentile(&mut fx, 0.5),
        base_y: percentile(&mut by, 0.5),
        scale,
        isolate: false,
        still_lights: StillLights::default(),
    })
}

/// Weighted least-squares line `x = m·y + b` through the contour points (eq. 7), weights
/// from 1 at the tip to 3 at the root. Returns the lean angle in radians (positive =
/// the tip leans right, 0 = upright) and the root end point (eq. 9–11), or `None` when
/// there are fewer than 3 points.
pub fn lean_angle(nodes: &[ContourNode], keep: &[bool]) -> Option<(f32, [f32; 2])> {
    let pts: Vec<(f64, f64)> = nodes
        .iter()
        .zip(keep)
        .filter(|(n, &k)| k && !n.is_hole)
        .flat_map(|(n, _)| n.points.iter().map(|p| (p.x as f64, p.y as f64)))
        .collect();
    if pts.len() < 3 {
        return None;
    }
    let (ymin, ymax) = pts
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(p.1), b.max(p.1)));
    let span = (ymax - ymin).max(1.0);
    let (mut sw, mut swy, mut swx, mut swyy, mut swxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(x, y) in &pts {
        let w = 1.0 + 2.0 * (y - ymin) / span;
        sw += w;
        swy += w * y;
        swx += w * x;
        swyy += w * y * y;
        swxy += w * x * y;
    }
    let den = sw * swyy - swy * swy;
    if den.abs() < 1e-9 {
        return None;
    }
    let m = (sw * swxy - swy * swx) / den;
    let b = (swx - m * swy) / sw;
    // Root = the projection with the largest y. In x = m·y + b, projecting (x, y) onto the
    // line gives Y = (m·x + y − m·b) / (m² + 1) (eq. 10–11 with the roles of x, y swapped).
    let proj_y = |x: f64, y: f64| (m * x + y - m * b) / (m * m + 1.0);
    let root_y = pts
        .iter()
        .map(|&(x, y)| proj_y(x, y))
        .fold(f64::MIN, f64::max);
    let root = [(m * root_y + b) as f32, root_y as f32];
    // Going up (y decreasing) x changes by −m per pixel: the lean is atan(−m).
    Some(((-m).atan() as f32, root))
}

/// When `pose` at `angle` maps source pixels onto frame pixels one to one (scale 1, no
/// rotation, whole-pixel offset), the offset `(ox, oy)`: frame pixel `(u, v)` shows
/// source pixel `(u − ox, v − oy)`. Bilinear sampling is then an exact copy.
pub fn whole_pixel_offset(pose: &ClipPose, angle: f32, p: &PoseParams) -> Option<(i64, i64)> {
    if angle != 0.0 || pose.scale != 1.0 {
        return None;
    }
    let out = p.frame();
    let cx = out.width as f32 / 2.0;
    let by = out.height as f32 * (1.0 - p.base_margin);
    // sx − 0.5 = u + (fuel_x − cx), sy − 0.5 = v + (base_y − by)
    let (dx, dy) = (pose.fuel_x - cx, pose.base_y - by);
    if dx.fract() != 0.0 || dy.fract() != 0.0 {
        return None;
    }
    Some((-(dx as i64), -(dy as i64)))
}

/// Warps a source frame into the common frame size: translation and scale from `pose`,
/// then (if `angle` ≠ 0) a rotation by `−angle` around the fuel so the flame stands
/// upright. Bilinear sampling; outside the source is black.
pub fn warp(src: &GrayFrame, pose: &ClipPose, angle: f32, p: &PoseParams) -> GrayFrame {
    let out = p.frame();
    if let Some((ox, oy)) = whole_pixel_offset(pose, angle, p) {
        let (sw, sh) = (src.width() as i64, src.height() as i64);
        let d = src.data();
        return GrayFrame::from_fn(out, |u, v| {
            let (sx, sy) = (u as i64 - ox, v as i64 - oy);
            if sx >= 0 && sy >= 0 && sx < sw && sy < sh {
                d[(sy * sw + sx) as usize]
            } else {
                0.0
            }
        });
    }
    let cx = out.width as f32 / 2.0;
    let by = out.height as f32 * (1.0 - p.base_margin);
    let (s, c) = angle.sin_cos();
    let inv = 1.0 / pose.scale;
    GrayFrame::from_fn(out, |u, v| {
        let dx = (u as f32 + 0.5 - cx) * inv;
        let dy = (v as f32 + 0.5 - by) * inv;
        let sx = pose.fuel_x + c * dx - s * dy;
        let sy = pose.base_y + s * dx + c * dy;
        bilinear(src, sx - 0.5, sy - 0.5)
    })
}

/// Bilinear sample at continuous pixel coordinates (pixel centres at integers); black
/// outside.
pub fn bilinear(src: &GrayFrame, x: f32, y: f32) -> f32 {
    let (w, h) = (src.width() as i64, src.height() as i64);
    let (x0, y0) = (x.floor() as i64, y.floor() as i64);
    let (fx, fy) = (x - x0 as f32, y - y0 as f32);
    let d = src.data();
    let at = |xx: i64, yy: i64| {
        if xx < 0 || yy < 0 || xx >= w || yy >= h {
            0.0
        } else {
            d[(yy * w + xx) as usize]
        }
    };
    let a = at(x0, y0) * (1.0 - fx) + at(x0 + 1, y0) * fx;
    let b = at(x0, y0 + 1) * (1.0 - fx) + at(x0 + 1, y0 + 1) * fx;
    a * (1.0 - fy) + b * fy
}

/// Area-average resize (for the training frames of §7.1.2); exact box filter when
/// shrinking, bilinear when growing.
pub fn resize(src: &GrayFrame, size: Size) -> GrayFrame {
    if src.size() == size {
        return src.clone();
    }
    let (sw, sh) = (src.width() as f32, src.height() as f32);
    let (kx, ky) = (sw / size.width as f32, sh / size.height as f32);
    if kx < 1.0 || ky < 1.0 {
        return GrayFrame::from_fn(size, |u, v| {
            bilinear(
                src,
                (u as f32 + 0.5) * kx - 0.5,
                (v as f32 + 0.5) * ky - 0.5,
            )
        });
    }
    let d = src.data();
    let w = src.width() as usize;
    GrayFrame::from_fn(size, |u, v| {
        let (x0, x1) = (u as f32 * kx, (u + 1) as f32 * kx);
        let (y0, y1) = (v as f32 * ky, (v + 1) as f32 * ky);
        let (mut acc, mut wsum) = (0.0f32, 0.0f32);
        for yy in y0.floor() as usize..(y1.ceil() as usize).min(src.height() as usize) {
            let wy = (y1.min(yy as f32 + 1.0) - y0.max(yy as f32)).max(0.0);
            for xx in x0.floor() as usize..(x1.ceil() as usize).min(w) {
                let wx = (x1.min(xx as f32 + 1.0) - x0.max(xx as f32)).max(0.0);
                acc += d[yy * w + xx] * wx * wy;
                wsum += wx * wy;
            }
        }
        if wsum > 0.0 {
            acc / wsum
        } else {
            0.0
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::contour::{contour_tree, remove_holes, ContourParams};

    #[test]
    fn lean_of_a_slanted_bar() {
        // A bar leaning right by 45°: x = 40 - y + offsets.
        let m = GrayImage::from_fn(64, 64, |x, y| {
            let on = (y as i32 >= 10 && y < 50) && ((x as i32) - (60 - y as i32)).abs() <= 3;
            image::Luma([if on { 255 } else { 0 }])
        });
        let nodes = contour_tree(&m);
        let keep = remove_holes(&nodes, &ContourParams::default(), 4096.0);
        let (a, root) = lean_angle(&nodes, &keep).unwrap();
        assert!((a - std::f32::consts::FRAC_PI_4).abs() < 0.05, "angle {a}");
        assert!(root[1] > 45.0, "root {root:?}");
    }

    #[test]
    fn pose_centres_and_resize_preserves_mean() {
        let m = GrayImage::from_fn(40, 40, |x, y| {
            image::Luma([if (10..20).contains(&x) && (5..35).contains(&y) {
                255
            } else {
                0
            }])
        });
        let e = mask_extent(&m).unwrap();
        assert_eq!(
            (e.fuel_x, e.base_y, e.height, e.width),
            (15.0, 35.0, 30.0, 10.0)
        );
        let p = PoseParams {
            frame_size: Some(Size::new(20, 40).unwrap()),
            ..Default::default()
        };
        let pose = clip_pose("c", &[Some(e), None], &p).unwrap();
        assert!((pose.scale - 0.85 * 40.0 / 30.0).abs() < 1e-5);
        assert!(clip_pose("empty-clip", &[None], &p)
            .unwrap_err()
            .to_string()
            .contains("empty-clip"));
        let g = GrayFrame::from_fn(Size::new(40, 40).unwrap(), |x, y| {
            ((x * 7 + y * 3) % 11) as f32
        });
        let r = resize(&g, Size::new(10, 10).unwrap());
        assert!((r.mean() - g.mean()).abs() < 1e-3);
        let w = warp(&g, &pose, 0.0, &p);
        assert_eq!(w.size(), p.frame());
    }
}

/// Serde for a [`Size`] written `"410x670"` (a `{ width, height }` table is accepted too).
pub mod size_str {
    use ignis_core::Size;
    use serde::{Deserialize, Deserializer, Serializer};

    #[derive(Deserialize)]
    #[serde(untagged)]
    enum Raw {
        S(String),
        T { width: u32, height: u32 },
    }

    fn conv<E: serde::de::Error>(r: Raw) -> Result<Size, E> {
        match r {
            Raw::S(s) => s.parse().map_err(E::custom),
            Raw::T { width, height } => Size::new(width, height).map_err(E::custom),
        }
    }

    pub fn serialize<S: Serializer>(s: &Size, ser: S) -> Result<S::Ok, S::Error> {
        ser.serialize_str(&s.to_string())
    }
    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Size, D::Error> {
        conv(Raw::deserialize(d)?)
    }

    /// `Option<Size>` where `None` is written `"auto"` (and `"auto"` or nothing reads as
    /// `None`).
    pub mod auto {
        use super::*;
        pub fn serialize<S: Serializer>(s: &Option<Size>, ser: S) -> Result<S::Ok, S::Error> {
            match s {
                Some(s) => ser.serialize_str(&s.to_string()),
                None => ser.serialize_str("auto"),
            }
        }
        pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Size>, D::Error> {
            match Option::<Raw>::deserialize(d)? {
                None => Ok(None),
                Some(Raw::S(s)) if s.trim() == "auto" => Ok(None),
                Some(r) => conv(r).map(Some),
            }
        }
    }

    /// The same for `Option<Size>`.
    pub mod option {
        use super::*;
        pub fn serialize<S: Serializer>(s: &Option<Size>, ser: S) -> Result<S::Ok, S::Error> {
            match s {
                Some(s) => ser.serialize_str(&s.to_string()),
                None => ser.serialize_none(),
            }
        }
        pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Size>, D::Error> {
            Option::<Raw>::deserialize(d)?.map(conv).transpose()
        }
    }
}
