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
    /// Vertical field of view, degrees (0, 170). Default 40.
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
}
