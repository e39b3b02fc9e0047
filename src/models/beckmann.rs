//! The Beckmann distribution, isotropic and anisotropic (Heitz eq. 68, 82).

use nalgebra::Vector3;

use super::{checked_alpha, rotate_z, Ndf};
use crate::error::Result;

/// Anisotropic Beckmann rotated by `theta_z` (same convention as [`super::Ggx`]); isotropic when
/// `alpha_x == alpha_y`. A Gaussian surface of slope standard deviations `sigma` has `alpha = sqrt(2) sigma`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Beckmann {
    /// Roughness along the local x axis.
    pub alpha_x: f64,
    /// Roughness along the local y axis.
    pub alpha_y: f64,
    /// Rotation in the tangent plane (radians).
    pub theta_z: f64,
}

impl Beckmann {
    /// A Beckmann distribution; alphas below [`super::ALPHA_MIN`] are raised to it.
    pub fn new(alpha_x: f64, alpha_y: f64, theta_z: f64) -> Result<Self> {
        Ok(Beckmann { alpha_x: checked_alpha("alpha_x", alpha_x)?, alpha_y: checked_alpha("alpha_y", alpha_y)?, theta_z })
    }
}

impl Ndf for Beckmann {
    /// `D(m) = exp(-(x'^2/ax^2 + y'^2/ay^2) / z^2) / (pi ax ay z^4)` with `m' = Rz m` (Heitz eq. 82).
    fn d(&self, m: Vector3<f64>) -> f64 {
        // At and below the horizon the slope is infinite and D is 0 (the exponential wins over 1/z^4).
        if m.z <= 0.0 {
            return 0.0;
        }
        let l = rotate_z(self.theta_z, m);
        let z2 = l.z * l.z;
        let e = ((l.x / self.alpha_x).powi(2) + (l.y / self.alpha_y).powi(2)) / z2;
        (-e).exp() / (std::f64::consts::PI * self.alpha_x * self.alpha_y * z2 * z2)
    }
}
