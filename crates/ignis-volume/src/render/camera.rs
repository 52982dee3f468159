//! The pinhole camera: its settings and the basis it looks along.

use crate::error::{Result, VolumeError};
use crate::lattice::{cross, normalize, sub, V3};
use serde::{Deserialize, Serialize};

/// A pinhole camera; world `z` is up.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Camera {
    /// Eye position, world units. Default `[0, −7, 1.5]`.
    pub position: [f32; 3],
    /// Point looked at. Default `[0, 0, 1.5]`.
    pub target: [f32; 3],
    /// Field of view across the frame's shorter side, degrees (0, 170): the vertical one
    /// in a landscape or square frame, the horizontal one in a portrait frame, so a tall
    /// frame shows what a square one does with more above and below, and a fire framed
    /// for a square is not cut at the sides of a tall cell. Default 40.
    pub fov: f32,
}

impl Default for Camera {
    fn default() -> Self {
        Camera {
            position: [0.0, -7.0, 1.5],
            target: [0.0, 0.0, 1.5],
            fov: 40.0,
        }
    }
}

impl Camera {
    /// Checks the field of view and that position ≠ target and the view is not vertical.
    pub fn validate(&self) -> Result<()> {
        if !(self.fov > 0.0 && self.fov < 170.0) {
            return Err(VolumeError::bad(
                "camera.fov",
                format!("{} degrees; use (0, 170)", self.fov),
            ));
        }
        let f = normalize(sub(self.target, self.position))
            .ok_or_else(|| VolumeError::bad("camera.target", "must differ from camera.position"))?;
        if normalize(cross(f, [0.0, 0.0, 1.0])).is_none() {
            return Err(VolumeError::bad(
                "camera.target",
                "the view must not be exactly vertical (z is up)",
            ));
        }
        Ok(())
    }

    /// Forward, right and up unit vectors.
    pub(super) fn basis(&self) -> (V3, V3, V3) {
        let f = normalize(sub(self.target, self.position)).unwrap_or([0.0, 1.0, 0.0]);
        let r = normalize(cross(f, [0.0, 0.0, 1.0])).unwrap_or([1.0, 0.0, 0.0]);
        let u = cross(r, f);
        (f, r, u)
    }

    /// Half the view's height at unit distance in a `size` image: `tan(fov / 2)`, times
    /// height ÷ width in a portrait frame (where `fov` spans the width).
    pub(crate) fn half_height(&self, size: ignis_core::Size) -> f32 {
        let tan = (self.fov.to_radians() * 0.5).tan();
        let (w, h) = (size.width as f32, size.height as f32);
        if h > w {
            tan * h / w
        } else {
            tan
        }
    }

    /// Where world point `p` appears in a `size` image, in pixels from the top-left
    /// corner (pixel `(x, y)`'s centre is at `(x + 0.5, y + 0.5)`, as the renderer's rays
    /// go); `None` at or behind the camera plane.
    pub(crate) fn project(&self, p: V3, size: ignis_core::Size) -> Option<[f32; 2]> {
        let (f, r, u) = self.basis();
        let d = sub(p, self.position);
        let z = crate::lattice::dot(d, f);
        if !(z > 1e-6) {
            return None;
        }
        let tan = self.half_height(size);
        let (w, h) = (size.width as f32, size.height as f32);
        let sx = crate::lattice::dot(d, r) / z / (tan * (w / h));
        let sy = crate::lattice::dot(d, u) / z / tan;
        Some([(sx + 1.0) * 0.5 * w, (1.0 - sy) * 0.5 * h])
    }
}
