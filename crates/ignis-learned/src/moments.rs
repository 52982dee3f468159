//! Geometric image moments and the global normalisation of a flame image.
//!
//! Source: stich-magnor-learning-flames.txt §3.1, eq. (1): `M_pq = ∫∫ xᵖ y^q I(x, y) dx dy`,
//! up to order 3.
//!
//! Conventions: `x` is the column and `y` the row of a pixel centre (row 0 at the top,
//! `y` grows downwards), so a pixel `(col, row)` sits at `(col + 0.5, row + 0.5)`.
//! Intensities are linear light.
//!
//! The normalisation ([`Pose`]) is: centroid `M10/M00, M01/M00`; main axis the major
//! eigenvector of the second-order central moments; its sign fixed so the axis points
//! up the image (flames burn upwards — the paper leaves the sign open); the flame height
//! `σ_v` the deviation along the main axis. The third-order moments give the skewness
//! along the main axis, reported for inspection (a flame's mass sits low with a long tail
//! upwards, so it is positive for an upright flame).

use ignis_core::GrayFrame;
use serde::{Deserialize, Serialize};

/// Raw geometric moments `M_pq`, `p + q ≤ 3`, indexed `m[p][q]`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Moments {
    pub m: [[f64; 4]; 4],
}

impl Moments {
    /// Moments of a grey image (eq. 1), summed in `f64`.
    pub fn of(frame: &GrayFrame) -> Moments {
        let mut m = [[0.0f64; 4]; 4];
        for (row, line) in frame.rows().enumerate() {
            let y = row as f64 + 0.5;
            // Per-row sums of I, xI, x²I, x³I, then combined with powers of y.
            let mut s = [0.0f64; 4];
            for (col, &v) in line.iter().enumerate() {
                let v = v as f64;
                if v == 0.0 {
                    continue;
                }
                let x = col as f64 + 0.5;
                let vx = v * x;
                let vxx = vx * x;
                s[0] += v;
                s[1] += vx;
                s[2] += vxx;
                s[3] += vxx * x;
            }
            let ys = [1.0, y, y * y, y * y * y];
            for p in 0..4 {
                for q in 0..4 - p {
                    m[p][q] += s[p] * ys[q];
                }
            }
        }
        Moments { m }
    }

    /// Total intensity `M00`.
    pub fn mass(&self) -> f64 {
        self.m[0][0]
    }

    /// Centroid `(M10/M00, M01/M00)`.
    pub fn centroid(&self) -> (f64, f64) {
        (self.m[1][0] / self.m[0][0], self.m[0][1] / self.m[0][0])
    }

    /// Normalised central moments `(μ20, μ11, μ02)/M00` (the covariance of the grey-value
    /// distribution).
    pub fn covariance(&self) -> (f64, f64, f64) {
        let (cx, cy) = self.centroid();
        let m00 = self.m[0][0];
        (
            self.m[2][0] / m00 - cx * cx,
            self.m[1][1] / m00 - cx * cy,
            self.m[0][2] / m00 - cy * cy,
        )
    }

    /// The global normalisation of the flame image, or `None` if it has no intensity.
    pub fn pose(&self) -> Option<Pose> {
        let m00 = self.m[0][0];
        if !(m00 > 0.0) || !m00.is_finite() {
            return None;
        }
        let (cx, cy) = self.centroid();
        let (sxx, sxy, syy) = self.covariance();
        // Major axis direction (cos θ, sin θ) in image coordinates.
        let theta = 0.5 * (2.0 * sxy).atan2(sxx - syy);
        let (mut ax, mut ay) = (theta.cos(), theta.sin());
        if ay > 0.0 {
            // Point up the image.
            ax = -ax;
            ay = -ay;
        }
        let tilt = ax.atan2(-ay);
        let tr = 0.5 * (sxx + syy);
        let disc = (0.25 * (sxx - syy).powi(2) + sxy * sxy).sqrt();
        let major = (tr + disc).max(0.0);
        let minor = (tr - disc).max(0.0);
        // Third-order central moment along the main axis v = (x−cx)·ax + (y−cy)·ay.
        let mu = |p: usize, q: usize| -> f64 {
            // Central moment μ_pq / M00 from raw moments (p + q = 3 here).
            let c = |a: usize, b: usize| self.m[a][b] / m00;
            match (p, q) {
                (3, 0) => c(3, 0) - 3.0 * cx * c(2, 0) + 2.0 * cx.powi(3),
                (0, 3) => c(0, 3) - 3.0 * cy * c(0, 2) + 2.0 * cy.powi(3),
                (2, 1) => c(2, 1) - 2.0 * cx * c(1, 1) - cy * c(2, 0) + 2.0 * cx * cx * cy,
                (1, 2) => c(1, 2) - 2.0 * cy * c(1, 1) - cx * c(0, 2) + 2.0 * cx * cy * cy,
                _ => 0.0,
            }
        };
        let m3 = mu(3, 0) * ax.powi(3)
            + 3.0 * mu(2, 1) * ax * ax * ay
            + 3.0 * mu(1, 2) * ax * ay * ay
            + mu(0, 3) * ay.powi(3);
        let sigma_v = major.sqrt();
        let skew = if sigma_v > 0.0 {
            m3 / sigma_v.powi(3)
        } else {
            0.0
        };
        Some(Pose {
            cx,
            cy,
            tilt,
            sigma_v,
            sigma_u: minor.sqrt(),
            skew,
            mass: m00,
        })
    }
}

/// Global normalisation of one flame image (all in source pixels).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Centroid, pixels.
    pub cx: f64,
    pub cy: f64,
    /// Angle of the main axis from image-up, radians, positive leaning right (towards +x).
    pub tilt: f64,
    /// Deviation of the grey-value distribution along the main axis, pixels (the flame
    /// height measure of §3.1).
    pub sigma_v: f64,
    /// Deviation across the main axis, pixels.
    pub sigma_u: f64,
    /// Skewness along the main axis (third-order moment / σ_v³), upwards positive.
    pub skew: f64,
    /// Total intensity `M00`.
    pub mass: f64,
}

impl Pose {
    /// Unit vector pointing up the flame (`v` axis), image coordinates.
    pub fn up(&self) -> (f64, f64) {
        (self.tilt.sin(), -self.tilt.cos())
    }
    /// Unit vector pointing right across the flame (`u` axis), image coordinates.
    pub fn right(&self) -> (f64, f64) {
        (self.tilt.cos(), self.tilt.sin())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ignis_core::Size;

    /// A teardrop-ish flame: base at (x0, y0), leaning by `tilt`, scaled by `s`.
    fn flame(x0: f64, y0: f64, s: f64, tilt: f64) -> GrayFrame {
        let size = Size::new(160, 160).unwrap();
        let (ux, uy) = (tilt.cos(), tilt.sin());
        let (vx, vy) = (tilt.sin(), -tilt.cos());
        GrayFrame::from_fn(size, |c, r| {
            let (dx, dy) = (c as f64 + 0.5 - x0, r as f64 + 0.5 - y0);
            let u = (dx * ux + dy * uy) / s;
            let v = (dx * vx + dy * vy) / s;
            if !(0.0..=60.0).contains(&v) {
                return 0.0;
            }
            let t = v / 60.0;
            let w = 9.0 * (1.0 - t).powf(0.8) * (0.3 + t).sqrt();
            ((-(u / w).powi(2)).exp() * (1.0 - 0.6 * t)) as f32
        })
    }

    #[test]
    fn moments_of_a_point() {
        let mut f = GrayFrame::new(Size::new(8, 8).unwrap());
        f.set(3, 5, 2.0);
        let m = Moments::of(&f);
        assert_eq!(m.mass(), 2.0);
        assert_eq!(m.centroid(), (3.5, 5.5));
        assert!((m.m[1][2] - 2.0 * 3.5 * 5.5 * 5.5).abs() < 1e-9);
        assert!(Moments::of(&GrayFrame::new(Size::new(4, 4).unwrap()))
            .pose()
            .is_none());
    }

    #[test]
    fn normalisation_recovers_shift_scale_and_rotation() {
        let base = Moments::of(&flame(70.0, 120.0, 1.0, 0.0)).pose().unwrap();
        assert!(
            base.tilt.abs() < 1e-6,
            "upright flame has tilt {}",
            base.tilt
        );
        assert!(base.skew > 0.0, "long tail upwards: skew {}", base.skew);
        let (shift, scale, rot) = ((6.0, -9.0), 1.3, 0.35f64);
        let moved = Moments::of(&flame(70.0 + shift.0, 120.0 + shift.1, scale, rot))
            .pose()
            .unwrap();
        // The base point moves by `shift`; the centroid sits at base + scale·R(rot)·(c − base).
        let (bx, by) = (base.cx - 70.0, base.cy - 120.0);
        let (ex, ey) = (
            70.0 + shift.0 + scale * (bx * rot.cos() - by * rot.sin()),
            120.0 + shift.1 + scale * (bx * rot.sin() + by * rot.cos()),
        );
        assert!(
            (moved.cx - ex).abs() < 0.3 && (moved.cy - ey).abs() < 0.3,
            "{moved:?} vs ({ex}, {ey})"
        );
        assert!(
            (moved.tilt - rot).abs() < 0.01,
            "tilt {} vs {rot}",
            moved.tilt
        );
        assert!((moved.sigma_v / base.sigma_v - scale).abs() < 0.01);
        assert!((moved.sigma_u / base.sigma_u - scale).abs() < 0.01);
        assert!((moved.skew - base.skew).abs() < 0.02);
    }
}
