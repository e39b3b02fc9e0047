//! GGX / Trowbridge-Reitz and its anisotropic form GTR2aniso (Burley 2012; Walter et al. sec. 4.2).

use nalgebra::Vector3;

use super::{checked_alpha, rotate_z, Ellipsoid, Ndf};
use crate::error::Result;

/// Anisotropic GGX rotated by `theta_z` in the tangent plane; isotropic when `alpha_x == alpha_y`.
///
/// It is the ellipsoid with `theta_x = theta_y = 0` (Walter et al. sec. 4.2), and `theta_z` has the
/// ellipsoid's meaning: the local frame is `m' = Rz(theta_z) m`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ggx {
    /// Roughness along the local x axis.
    pub alpha_x: f64,
    /// Roughness along the local y axis.
    pub alpha_y: f64,
    /// Rotation in the tangent plane (radians).
    pub theta_z: f64,
}

impl Ggx {
    /// A GGX distribution; alphas below [`super::ALPHA_MIN`] are raised to it.
    pub fn new(alpha_x: f64, alpha_y: f64, theta_z: f64) -> Result<Self> {
        Ok(Ggx { alpha_x: checked_alpha("alpha_x", alpha_x)?, alpha_y: checked_alpha("alpha_y", alpha_y)?, theta_z })
    }

    /// The same distribution as an [`Ellipsoid`].
    pub fn to_ellipsoid(&self) -> Ellipsoid {
        Ellipsoid::from_params(self.alpha_x, self.alpha_y, 0.0, 0.0, self.theta_z)
            .expect("alphas were checked on construction")
    }
}

impl Ndf for Ggx {
    /// `D(m) = 1 / (pi ax ay (x'^2/ax^2 + y'^2/ay^2 + z^2)^2)` with `m' = Rz m` (Burley eq. 13).
    fn d(&self, m: Vector3<f64>) -> f64 {
        if m.z < 0.0 {
            return 0.0;
        }
        let l = rotate_z(self.theta_z, m);
        let q = (l.x / self.alpha_x).powi(2) + (l.y / self.alpha_y).powi(2) + l.z * l.z;
        1.0 / (std::f64::consts::PI * self.alpha_x * self.alpha_y * q * q)
    }
}
