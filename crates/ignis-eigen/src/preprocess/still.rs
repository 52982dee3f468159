//! Still lights: bright things in the shot that are not fire (a lamp, a lit window, a
//! white sign), found by what they do over the clip, and kept out of the flame mask.
//!
//! Not in the thesis: its footage is a flame on black, where everything bright is fire.
//! On a cluttered shot the HSV mask and [`crate::mask::isolate_flame`] keep anything as
//! bright as the flame; a lamp at full white even becomes a seed of the isolation. No
//! single frame tells a lamp from a flame's white-hot core, but the clip does: a flame
//! moves, so the pixels around it change by many levels from frame to frame, while a lamp
//! and its surroundings stay where they are.
//!
//! Over the frames the planning pass samples (spread over the clip), a pixel is **still
//! and lit** when it is at least the isolation floor bright in every sample and its
//! value varies by less than [`STILL_RANGE`] levels, and **flickering** when it reaches
//! the floor in some sample and varies by at least that. A still light is an 8-connected
//! region of still, lit pixels with no flickering pixel within `r` (4 % of the frame's
//! longer side, at least 3 px) nor inside its box. A flame's saturated core is still and
//! lit too, but its moving edge flickers right beside it; a steady ember at the edge of a
//! coal bed lies within `r` of the flames (at 1.5 % one of `campfire.mp4`'s did not: it
//! would have been cut out of the fire); a large still region wrapped around moving light
//! would blank it through its box. A lamp closer than `r` to the fire stays in the mask.
//! Each still light's bounding box, grown by a quarter of `r` (at least 3 px: the mask's
//! morphology and smoothing reach 3 px), is stored in the clip's pose ([`StillLights`])
//! and every frame's mask ignores those boxes (the mask, the isolation's luminance, and,
//! without isolation, the grey image). A clip where nothing flickers gets none: nothing
//! there tells a lamp from a steady flame. Everything is relative to the clip's own
//! samples: nothing is tuned to a clip.

use image::GrayImage;
use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Levels (8-bit sRGB value) a still light varies by at most over the samples; a pixel
/// that varies by this much or more flickers. Compression noise on a static lamp stays a
/// few levels; a flame's edge crosses it by a hundred.
pub const STILL_RANGE: u8 = 40;

/// Samples needed before anything is called still (fewer say too little about motion).
pub const MIN_SAMPLES: usize = 8;

/// Most still lights a clip stores (the largest are kept).
pub const MAX_LIGHTS: usize = 32;

/// Smallest still light, in pixels (a speck of noise is not worth a box).
const MIN_AREA: usize = 9;

/// The boxes of a clip's still lights, `[x0, y0, x1, y1)` in source pixels (at most
/// [`MAX_LIGHTS`]). Stored in the database's manifest as `"still_lights": [[x0, y0, x1,
/// y1], …]`; a fixed array keeps [`crate::pose::ClipPose`] `Copy`.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct StillLights {
    len: u8,
    boxes: [[u32; 4]; MAX_LIGHTS],
}

impl Default for StillLights {
    fn default() -> Self {
        StillLights {
            len: 0,
            boxes: [[0; 4]; MAX_LIGHTS],
        }
    }
}

impl std::fmt::Debug for StillLights {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_list().entries(self.boxes()).finish()
    }
}

impl StillLights {
    /// From boxes (the first [`MAX_LIGHTS`] are kept).
    pub fn new(boxes: &[[u32; 4]]) -> StillLights {
        let mut s = StillLights::default();
        for b in boxes.iter().take(MAX_LIGHTS) {
            s.boxes[s.len as usize] = *b;
            s.len += 1;
        }
        s
    }

    pub fn boxes(&self) -> &[[u32; 4]] {
        &self.boxes[..self.len as usize]
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Sets every pixel of a `w`-wide row-major image inside a box to `zero`.
    pub fn clear<T: Copy>(&self, data: &mut [T], w: usize, zero: T) {
        if w == 0 {
            return;
        }
        let h = data.len() / w;
        for &[x0, y0, x1, y1] in self.boxes() {
            let (x0, x1) = ((x0 as usize).min(w), (x1 as usize).min(w));
            for y in (y0 as usize).min(h)..(y1 as usize).min(h) {
                data[y * w + x0..y * w + x1].fill(zero);
            }
        }
    }
}

impl Serialize for StillLights {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        self.boxes().serialize(s)
    }
}

impl<'de> Deserialize<'de> for StillLights {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let v: Vec<[u32; 4]> = Vec::deserialize(d)?;
        if v.len() > MAX_LIGHTS {
            return Err(serde::de::Error::custom(format!(
                "still_lights: {} boxes, at most {MAX_LIGHTS}",
                v.len()
            )));
        }
        if let Some(b) = v.iter().find(|b| b[0] > b[2] || b[1] > b[3]) {
            return Err(serde::de::Error::custom(format!(
                "still_lights: box {b:?} is not [x0, y0, x1, y1] with x0 ≤ x1, y0 ≤ y1"
            )));
        }
        Ok(StillLights::new(&v))
    }
}

/// The still lights of a clip from `samples` (8-bit sRGB values, one `Vec` per sampled
/// frame, each `w × h`) with the isolation `floor` (`0..1`). Empty with fewer than
/// [`MIN_SAMPLES`] samples or samples of the wrong size. Deterministic; O(pixels ×
/// samples).
pub fn still_lights(samples: &[Vec<u8>], w: u32, h: u32, floor: f32) -> StillLights {
    let n = w as usize * h as usize;
    if samples.len() < MIN_SAMPLES || n == 0 || samples.iter().any(|s| s.len() != n) {
        return StillLights::default();
    }
    let floor = (floor * 255.0).round().clamp(1.0, 255.0) as u8;
    let (mut lo, mut hi) = (vec![u8::MAX; n], vec![0u8; n]);
    for s in samples {
        for ((l, h), &v) in lo.iter_mut().zip(hi.iter_mut()).zip(s) {
            *l = (*l).min(v);
            *h = (*h).max(v);
        }
    }
    let mut still = GrayImage::new(w, h);
    let mut flicker = GrayImage::new(w, h);
    for (i, (&l, &h)) in lo.iter().zip(&hi).enumerate() {
        if h - l >= STILL_RANGE {
            if h >= floor {
                flicker.as_mut()[i] = 255;
            }
        } else if l >= floor {
            still.as_mut()[i] = 255;
        }
    }
    // Where nothing moves, nothing tells a lamp from a steady flame: keep everything.
    if flicker.as_raw().iter().filter(|&&v| v > 0).count() < MIN_AREA {
        return StillLights::default();
    }
    let r = ((0.04 * w.max(h) as f64).round() as u32).clamp(3, 255);
    let near =
        imageproc::morphology::dilate(&flicker, imageproc::distance_transform::Norm::LInf, r as u8);
    let labels = imageproc::region_labelling::connected_components(
        &still,
        imageproc::region_labelling::Connectivity::Eight,
        image::Luma([0u8]),
    );
    // Per region: bounding box, area, and whether a flickering pixel is within `r`.
    let count = labels.as_raw().iter().max().map_or(0, |&m| m as usize);
    let mut regions = vec![([u32::MAX, u32::MAX, 0, 0], 0usize, false); count];
    for (i, (&l, &nb)) in labels.as_raw().iter().zip(near.as_raw()).enumerate() {
        let Some(reg) = (l as usize).checked_sub(1).map(|k| &mut regions[k]) else {
            continue;
        };
        let (x, y) = ((i % w as usize) as u32, (i / w as usize) as u32);
        let b = &mut reg.0;
        *b = [b[0].min(x), b[1].min(y), b[2].max(x + 1), b[3].max(y + 1)];
        reg.1 += 1;
        reg.2 |= nb > 0;
    }
    let grow = (r / 4).max(3);
    let grown = |b: &[u32; 4]| {
        [
            b[0].saturating_sub(grow),
            b[1].saturating_sub(grow),
            (b[2] + grow).min(w),
            (b[3] + grow).min(h),
        ]
    };
    // A box must hold no flicker at all (a large still region wrapped around moving light
    // would blank it through its box): counted on a summed-area table.
    let sat = summed_area(&flicker);
    let flickers_in = |b: [u32; 4]| {
        let at = |x: u32, y: u32| sat[y as usize * (w as usize + 1) + x as usize];
        at(b[2], b[3]) + at(b[0], b[1]) - at(b[0], b[3]) - at(b[2], b[1]) > 0
    };
    let mut lights: Vec<_> = regions
        .into_iter()
        .filter(|(b, area, near)| !near && *area >= MIN_AREA && !flickers_in(grown(b)))
        .collect();
    // Largest first; ties by position (deterministic).
    lights.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    let boxes: Vec<[u32; 4]> = lights
        .iter()
        .take(MAX_LIGHTS)
        .map(|(b, _, _)| grown(b))
        .collect();
    StillLights::new(&boxes)
}

/// Summed-area table of a mask's set pixels, `(w + 1) × (h + 1)`, row-major.
fn summed_area(m: &GrayImage) -> Vec<u32> {
    let (w, h) = (m.width() as usize, m.height() as usize);
    let mut s = vec![0u32; (w + 1) * (h + 1)];
    for y in 0..h {
        let mut row = 0u32;
        for x in 0..w {
            row += (m.as_raw()[y * w + x] > 0) as u32;
            s[(y + 1) * (w + 1) + x + 1] = s[y * (w + 1) + x + 1] + row;
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 120×80 clip: a flame (a blob moving and changing size) on the left, a lamp
    /// (a steady white box) on the right, compression-like noise of ±3 levels.
    fn clip(frames: usize, lamp: bool) -> Vec<Vec<u8>> {
        let (w, h) = (120usize, 80usize);
        let mut rng = ignis_core::Rng::new(7);
        (0..frames)
            .map(|k| {
                let t = k as f32;
                let (cx, cy, rad) = (
                    30.0 + 6.0 * (t * 0.9).sin(),
                    45.0,
                    12.0 + 5.0 * (t * 1.7).cos(),
                );
                (0..w * h)
                    .map(|i| {
                        let (x, y) = ((i % w) as f32, (i / w) as f32);
                        let d = ((x - cx).powi(2) + ((y - cy) * 0.6).powi(2)).sqrt();
                        let mut v = if d < rad * 0.4 {
                            255.0 // the white-hot core, still
                        } else if d < rad {
                            230.0 - 120.0 * (d / rad)
                        } else {
                            10.0
                        };
                        if lamp && (90..104).contains(&(i % w)) && (10..22).contains(&(i / w)) {
                            v = 250.0;
                        }
                        (v + rng.uniform(-3.0, 3.0) as f32).clamp(0.0, 255.0) as u8
                    })
                    .collect()
            })
            .collect()
    }

    #[test]
    fn a_lamp_is_still_a_flame_is_not() {
        let s = still_lights(&clip(24, true), 120, 80, 0.3);
        assert_eq!(s.boxes().len(), 1, "{s:?}");
        let [x0, y0, x1, y1] = s.boxes()[0];
        assert!(
            x0 <= 90 && y0 <= 10 && x1 >= 104 && y1 >= 22,
            "the lamp is covered: {s:?}"
        );
        assert!(x0 > 60, "the flame (x < 50) is not: {s:?}");
        // Without the lamp: nothing is still, even the flame's saturated core.
        assert!(still_lights(&clip(24, false), 120, 80, 0.3).is_empty());
        // Too few samples: nothing is called still.
        assert!(still_lights(&clip(MIN_SAMPLES - 1, true), 120, 80, 0.3).is_empty());
        // Nothing moves (a frozen clip): nothing tells the lamp from the flame.
        let frozen = vec![clip(1, true).remove(0); 24];
        assert!(still_lights(&frozen, 120, 80, 0.3).is_empty());
    }

    /// A still lit ring (a window frame) around a moving light, farther than `r` from it:
    /// its box would hold the moving light, so it is not a still light.
    #[test]
    fn a_box_never_holds_flicker() {
        let (w, h) = (120usize, 80usize);
        let frames: Vec<Vec<u8>> = (0..16)
            .map(|k| {
                (0..w * h)
                    .map(|i| {
                        let (x, y) = ((i % w) as i32, (i / w) as i32);
                        let ring = (x - 60).abs().max((y - 40).abs());
                        let blob = (x - 58 - (k % 4)).abs().max((y - 40).abs()) < 4;
                        if blob && k % 2 == 0 {
                            250
                        } else if (30..33).contains(&ring) {
                            240
                        } else {
                            5
                        }
                    })
                    .collect()
            })
            .collect();
        assert!(still_lights(&frames, w as u32, h as u32, 0.3).is_empty());
    }

    #[test]
    fn clear_blanks_the_boxes_only() {
        let s = StillLights::new(&[[1, 1, 3, 2], [4, 0, 9, 9]]);
        let mut d = vec![1u8; 5 * 3];
        s.clear(&mut d, 5, 0);
        assert_eq!(d, [1, 1, 1, 1, 0, 1, 0, 0, 1, 0, 1, 1, 1, 1, 0]);
    }

    #[test]
    fn the_search_can_be_turned_off_in_the_toml() {
        let p = crate::PreprocessParams::from_toml("[mask]\nstill_lights = false\n").unwrap();
        assert!(!p.mask.still_lights);
        assert!(crate::PreprocessParams::default().mask.still_lights);
    }

    #[test]
    fn serialises_as_a_list_of_boxes() {
        let s = StillLights::new(&[[1, 2, 3, 4]]);
        let j = serde_json::to_string(&s).unwrap();
        assert_eq!(j, "[[1,2,3,4]]");
        assert_eq!(serde_json::from_str::<StillLights>(&j).unwrap(), s);
        assert!(serde_json::from_str::<StillLights>("[[3,2,1,4]]").is_err());
        let many = format!("[{}]", vec!["[0,0,1,1]"; MAX_LIGHTS + 1].join(","));
        assert!(serde_json::from_str::<StillLights>(&many).is_err());
    }
}
