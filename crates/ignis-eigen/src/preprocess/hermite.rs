//! Hermite background and smoke removal.
//!
//! Source: eigenfires-thesis.txt §3.3.1, Figure 20. With `S = (I − I_min)/(I_max − I_min)`
//! clamped to `0..=1`, a pixel is multiplied by the Hermite basis function
//! `h(S) = 3S² − 2S³`: pixels above `I_max` are kept, pixels below `I_min` become black,
//! pixels in between are darkened smoothly. Pixels inside the flame's contour mask are
//! left untouched (Figure 20d).
//!
//! Departure: the thesis's equation is not legible in our copy; "the second Hermite basis
//! function" is read as h₀₁(S) = 3S² − 2S³, the one that rises from 0 at S=0 to 1 at S=1
//! with zero slope at both ends, which is what the text describes. The thresholds are on
//! the **sRGB-encoded** luminance in `0..=1` (the thesis's 110 and 220 are 0.43 and 0.86);
//! the frame itself stays linear light.

use crate::error::{EigenError, Result};
use ignis_core::palette::linear_to_srgb;
use ignis_core::GrayFrame;
use image::GrayImage;
use serde::{Deserialize, Serialize};

/// Settings of [`hermite_darken`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct HermiteParams {
    /// Below this (sRGB-encoded, `0..1`) a pixel outside the contour becomes black.
    /// Default 0.15.
    pub i_min: f32,
    /// Above this a pixel is kept. Must be > `i_min`. Default 0.55.
    pub i_max: f32,
    /// Leave pixels inside the contour mask untouched. Default true.
    pub protect_interior: bool,
}

impl Default for HermiteParams {
    fn default() -> Self {
        HermiteParams {
            i_min: 0.15,
            i_max: 0.55,
            protect_interior: true,
        }
    }
}

impl HermiteParams {
    pub fn validate(&self) -> Result<()> {
        if !((0.0..1.0).contains(&self.i_min) && self.i_max > self.i_min && self.i_max <= 1.0) {
            return Err(EigenError::bad(
                "hermite",
                format!(
                    "needs 0 <= i_min < i_max <= 1 (got i_min={}, i_max={})",
                    self.i_min, self.i_max
                ),
            ));
        }
        Ok(())
    }
}

/// The Hermite basis function h₀₁(s) = 3s² − 2s³ on `s` clamped to `0..=1`.
#[inline]
pub fn hermite_h01(s: f32) -> f32 {
    let s = s.clamp(0.0, 1.0);
    s * s * (3.0 - 2.0 * s)
}

/// Darkens `gray` (linear luminance) outside `mask` (255 = protected) per §3.3.1.
/// `mask` may be `None` (nothing protected).
pub fn hermite_darken(gray: &GrayFrame, mask: Option<&GrayImage>, p: &HermiteParams) -> GrayFrame {
    let mut out = gray.clone();
    let span = p.i_max - p.i_min;
    let protect = if p.protect_interior {
        mask.map(|m| m.as_raw().as_slice())
    } else {
        None
    };
    for (i, v) in out.data_mut().iter_mut().enumerate() {
        if protect.is_some_and(|m| m.get(i).is_some_and(|&b| b > 0)) {
            continue;
        }
        let s = (linear_to_srgb(*v) - p.i_min) / span;
        *v *= hermite_h01(s);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use ignis_core::palette::srgb_to_linear;
    use ignis_core::Size;

    #[test]
    fn hermite_keeps_darkens_and_protects() {
        let p = HermiteParams::default();
        let vals = [
            srgb_to_linear(0.9),
            srgb_to_linear(0.1),
            srgb_to_linear(0.35),
            srgb_to_linear(0.1),
        ];
        let g = GrayFrame::from_vec(Size::new(4, 1).unwrap(), vals.to_vec()).unwrap();
        let m = GrayImage::from_raw(4, 1, vec![0, 0, 0, 255]).unwrap();
        let o = hermite_darken(&g, Some(&m), &p);
        assert_eq!(o.data()[0], vals[0]);
        assert_eq!(o.data()[1], 0.0);
        assert!(o.data()[2] > 0.0 && o.data()[2] < vals[2]);
        assert_eq!(o.data()[3], vals[3]); // protected
        assert_eq!(hermite_h01(0.5), 0.5);
    }
}
