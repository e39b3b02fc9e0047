//! The squared ellipsoidal lobe (SEL) of Tokuyoshi and Harada, *Derivation of a Squared Ellipsoidal Lobe
//! Function*: a closed-form anisotropic GGX-like lobe, the squared distance from the origin to an ellipsoid.

use nalgebra::{Matrix3, Vector3};

use super::ALPHA_MIN;
use crate::error::{Error, Result};

/// `K(w; Q, alpha_x, alpha_y) = 4 a^4 / ((U - v_z) + a^2 (U + v_z))^2` with `v = Q w`, `a = max(alpha_x, alpha_y)`,
/// `U = sqrt(a^2/alpha_x^2 v_x^2 + a^2/alpha_y^2 v_y^2 + v_z^2)` (the paper's final form). `K = 1` on the lobe
/// axis (`v = +z`); when `alpha_x = alpha_y = alpha` it is the squared spheroidal lobe
/// `pi alpha^2 D_GGX(cos(theta/2), alpha)` (its sec. 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SquaredEllipsoidalLobe {
    q: Matrix3<f64>,
    alpha_x: f64,
    alpha_y: f64,
}

impl SquaredEllipsoidalLobe {
    /// A lobe with orientation `q` (orthogonal: its rows are the lobe frame's axes, the third the lobe axis)
    /// and roughnesses in `(0, 1]` (the paper's range; below [`ALPHA_MIN`] raised to it).
    pub fn new(q: Matrix3<f64>, alpha_x: f64, alpha_y: f64) -> Result<Self> {
        if q.iter().any(|v| !v.is_finite()) || (q * q.transpose() - Matrix3::identity()).abs().max() > 1e-9 {
            return Err(Error::invalid("SEL orientation Q must be a finite orthogonal matrix"));
        }
        for (name, a) in [("alpha_x", alpha_x), ("alpha_y", alpha_y)] {
            if !(a.is_finite() && a > 0.0 && a <= 1.0) {
                return Err(Error::invalid(format!("SEL {name} must be in (0, 1], got {a}")));
            }
        }
        Ok(SquaredEllipsoidalLobe { q, alpha_x: alpha_x.max(ALPHA_MIN), alpha_y: alpha_y.max(ALPHA_MIN) })
    }

    /// `K(w)` in `[0, 1]` for a unit direction `w`.
    pub fn eval(&self, w: Vector3<f64>) -> f64 {
        let v = self.q * w;
        let a = self.alpha_x.max(self.alpha_y);
        let a2 = a * a;
        let t = (a / self.alpha_x * v.x).powi(2) + (a / self.alpha_y * v.y).powi(2);
        let u = (t + v.z * v.z).sqrt();
        // U - v_z cancels near the axis; (U^2 - v_z^2) / (U + v_z) is the same value without cancellation.
        let u_minus = if v.z > 0.0 { t / (u + v.z) } else { u - v.z };
        let den = u_minus + a2 * (u + v.z);
        // den = 0 only for w = 0: no direction, no lobe.
        if !(den > 0.0) {
            return 0.0;
        }
        (2.0 * a2 / den).powi(2)
    }
}
