//! The Beckmann distribution, isotropic and anisotropic (Heitz eq. 67-69, 81-83).

use nalgebra::{Vector2, Vector3};

use super::ggx::{projected_roughness, smith_lambda};
use super::{checked_alpha, checked_angle, rotate_z, smith_g1, Masking, Ndf};
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
    /// A Beckmann distribution; alphas below [`super::ALPHA_MIN`] are raised to it, alphas above
    /// [`super::ALPHA_MAX`] and non-finite values are refused.
    pub fn new(alpha_x: f64, alpha_y: f64, theta_z: f64) -> Result<Self> {
        Ok(Beckmann {
            alpha_x: checked_alpha("alpha_x", alpha_x)?,
            alpha_y: checked_alpha("alpha_y", alpha_y)?,
            theta_z: checked_angle("theta_z", theta_z)?,
        })
    }

    /// The Gaussian distribution of slopes `P22` of Heitz eq. 81 (eq. 67 isotropic), slope in the scan frame.
    pub fn p22(&self, slope: Vector2<f64>) -> f64 {
        let l = rotate_z(self.theta_z, Vector3::new(slope.x, slope.y, 0.0));
        let e = (l.x / self.alpha_x).powi(2) + (l.y / self.alpha_y).powi(2);
        (-e).exp() / (std::f64::consts::PI * self.alpha_x * self.alpha_y)
    }

    /// The projected roughness `alpha_o` of Heitz eq. 80 in the azimuth of `u`.
    pub fn alpha_o(&self, u: Vector3<f64>) -> f64 {
        projected_roughness(self.alpha_x, self.alpha_y, self.theta_z, u)
    }
}

impl Ndf for Beckmann {
    /// Heitz eq. 82 (eq. 68 isotropic): `D(m) = exp(-tan^2(theta) (cos^2 phi/ax^2 + sin^2 phi/ay^2)) /
    /// (pi ax ay cos^4 theta)` with `m' = Rz m`, i.e. `P22(slope) / cos^4` (eq. 64).
    fn d(&self, m: Vector3<f64>) -> f64 {
        // At and below the horizon the slope is infinite and D is 0 (the exponential wins over 1/z^4).
        if m.z <= 0.0 {
            return 0.0;
        }
        let l = rotate_z(self.theta_z, m);
        let z2 = l.z * l.z;
        let e = ((l.x / self.alpha_x).powi(2) + (l.y / self.alpha_y).powi(2)) / z2;
        // exp(-e) / z^4 in the log domain: for m.z ~ 1e-100, z^4 underflows to 0 and exp(-e) to 0 (0/0);
        // the exponent -e - 4 ln z is finite and correctly very negative.
        let expo = -e - 4.0 * l.z.ln();
        // NaN only for a non-finite m (0 * inf in the slope); such an m has no density.
        if expo.is_nan() {
            return 0.0;
        }
        expo.exp() / (std::f64::consts::PI * self.alpha_x * self.alpha_y)
    }
}

impl Masking for Beckmann {
    /// Heitz eq. 83 (eq. 69 isotropic) with the exact erf:
    /// `Lambda = (erf(a) - 1)/2 + exp(-a^2)/(2 a sqrt(pi))`, `a = 1/(alpha_o tan theta_o)` (eq. 80),
    /// evaluated as `(exp(-a^2)/(a sqrt(pi)) - erfc(a)) / 2` so that `erf(a) - 1` does not cancel.
    fn lambda(&self, u: Vector3<f64>) -> f64 {
        smith_lambda(self.alpha_x, self.alpha_y, self.theta_z, u, |w| {
            let a = 1.0 / w.sqrt();
            // Past a = 26.6 both terms underflow; Lambda < 1e-300 there.
            if a > 26.0 {
                return 0.0;
            }
            let l = ((-a * a).exp() / (a * std::f64::consts::PI.sqrt()) - libm::erfc(a)) / 2.0;
            if !l.is_finite() {
                return f64::MAX; // a so small that 1/a overflowed: the grazing limit
            }
            // The two terms nearly cancel for large a; rounding may leave an ulp below 0.
            l.max(0.0)
        })
    }

    /// Heitz eq. 43: `X+(u.m) / (1 + Lambda(u))`.
    fn g1(&self, u: Vector3<f64>, m: Vector3<f64>) -> f64 {
        smith_g1(self.lambda(u), u, m)
    }
}
