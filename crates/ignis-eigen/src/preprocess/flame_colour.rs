//! The flame's own colour, measured on the footage at training: what original colouring
//! tints the bloom with, so the glow around a blue gas flame is blue and the glow around a
//! white-hot flame is pale, not the fixed orange of a wood fire.
//!
//! Over every training frame, the footage's linear colour is summed over the pixels of the
//! pre-processing mask that are lit but not clipped (brightest channel in
//! `[MIN_LIT, CLIPPED)`): a clipped core is white whatever the flame's colour, and the
//! darkest masked pixels are mostly noise. Summing linear light weights each pixel by its
//! brightness, as the bloom it stands for does. The sum is scaled so its brightest
//! channel is 1 (only hue and saturation reach the bloom's HLS ramp). A flame clipped
//! everywhere falls back to the sum over all its masked pixels (white, which is right for
//! it). Deterministic: frames are added in order, pixels in row order, in `f64`.

use ignis_core::RgbaFrame;
use image::GrayImage;

/// Below this brightest channel (linear) a masked pixel is left out: noise, not colour.
const MIN_LIT: f32 = 0.02;
/// At or above this brightest channel (linear) a pixel is clipped: its colour is lost.
const CLIPPED: f32 = 0.95;

/// Running sums of a clip's flame colour ([`FlameColour::add`] per frame).
#[derive(Clone, Debug, Default)]
pub struct FlameColour {
    /// Masked, lit, unclipped pixels.
    lit: [f64; 3],
    /// Every masked pixel (the fallback for a flame clipped everywhere).
    all: [f64; 3],
}

impl FlameColour {
    /// Adds one frame: its linear colour `frame` and its mask `mask` (same size, 255 =
    /// flame). A mask of another size adds nothing.
    pub fn add(&mut self, frame: &RgbaFrame, mask: &GrayImage) {
        if mask.width() != frame.width() || mask.height() != frame.height() {
            return;
        }
        for (p, &m) in frame.data().iter().zip(mask.as_raw()) {
            if m == 0 {
                continue;
            }
            let top = p[0].max(p[1]).max(p[2]);
            if !top.is_finite() || top <= 0.0 {
                continue;
            }
            let unclipped = (MIN_LIT..CLIPPED).contains(&top);
            for (c, &v) in p[..3].iter().enumerate() {
                let v = v.max(0.0) as f64;
                self.all[c] += v;
                if unclipped {
                    self.lit[c] += v;
                }
            }
        }
    }

    /// The colour, brightest channel 1; `None` when no masked pixel was lit.
    pub fn colour(&self) -> Option<[f32; 3]> {
        let unit = |s: &[f64; 3]| {
            let top = s[0].max(s[1]).max(s[2]);
            (top > 0.0).then(|| s.map(|v| (v / top) as f32))
        };
        unit(&self.lit).or_else(|| unit(&self.all))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ignis_core::Size;

    fn frame(px: &[[f32; 4]], w: u32) -> RgbaFrame {
        let h = px.len() as u32 / w;
        RgbaFrame::from_vec(Size::new(w, h).unwrap(), px.to_vec()).unwrap()
    }

    #[test]
    fn the_colour_is_the_unclipped_flames_hue() {
        // A blue flame with a clipped white core, on an orange background outside the mask.
        let px = [
            [0.1, 0.3, 0.8, 1.0],
            [1.0, 1.0, 1.0, 1.0],
            [0.05, 0.15, 0.4, 1.0],
            [0.9, 0.4, 0.1, 1.0],
        ];
        let mask = GrayImage::from_raw(4, 1, vec![255, 255, 255, 0]).unwrap();
        let mut fc = FlameColour::default();
        fc.add(&frame(&px, 4), &mask);
        let c = fc.colour().unwrap();
        assert_eq!(c[2], 1.0);
        assert!(
            (c[0] - 0.125).abs() < 1e-6 && (c[1] - 0.375).abs() < 1e-6,
            "{c:?}"
        );
    }

    #[test]
    fn a_flame_clipped_everywhere_is_white_and_nothing_lit_is_none() {
        let px = [[1.0, 1.0, 1.0, 1.0], [0.0, 0.0, 0.0, 1.0]];
        let mut fc = FlameColour::default();
        fc.add(
            &frame(&px, 2),
            &GrayImage::from_raw(2, 1, vec![255, 255]).unwrap(),
        );
        assert_eq!(fc.colour(), Some([1.0, 1.0, 1.0]));
        let mut dark = FlameColour::default();
        dark.add(
            &frame(&px, 2),
            &GrayImage::from_raw(2, 1, vec![0, 255]).unwrap(),
        );
        assert_eq!(dark.colour(), None);
        // A mask of another size adds nothing.
        dark.add(&frame(&px, 2), &GrayImage::new(1, 1));
        assert_eq!(dark.colour(), None);
    }
}
