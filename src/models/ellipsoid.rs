//! The Ellipsoid NDF of Walter, Dong, Marschner and Greenberg (2014, rev. 2016).

use nalgebra::{Matrix3, Vector3};

use super::{checked_alpha, Ndf};
use crate::error::{Error, Result};

/// The ellipsoid NDF for a shape matrix A (Walter et al. eq. 1), with n = +z.
///
/// Stores A with the quantities eq. 1 needs precomputed: `A^-T`, `|A|` and `||A n||`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipsoid {
    a: Matrix3<f64>,
    a_inv_t: Matrix3<f64>,
    det_a: f64,
    an_norm: f64,
    params: [f64; 5],
}

impl Ellipsoid {
    /// `A = S R` with `S = diag(alpha_x, alpha_y, 1)` and `R = Rx(theta_x) Ry(theta_y) Rz(theta_z)`
    /// (Walter et al. eq. 2-3).
    pub fn from_params(alpha_x: f64, alpha_y: f64, theta_x: f64, theta_y: f64, theta_z: f64) -> Result<Self> {
        let ax = checked_alpha("alpha_x", alpha_x)?;
        let ay = checked_alpha("alpha_y", alpha_y)?;
        for (name, t) in [("theta_x", theta_x), ("theta_y", theta_y), ("theta_z", theta_z)] {
            if !t.is_finite() {
                return Err(Error::invalid(format!("{name} must be finite, got {t}")));
            }
        }
        let s = Matrix3::from_diagonal(&Vector3::new(ax, ay, 1.0));
        let a = s * rotation_xyz(theta_x, theta_y, theta_z);
        let mut e = Self::from_matrix(a)?;
        e.params = [ax, ay, theta_x, theta_y, theta_z];
        Ok(e)
    }

    /// An ellipsoid from any invertible A. The parameters reported by [`Ellipsoid::params`] are those
    /// of the constructor used; a general A has none until converted to canonical form.
    pub fn from_matrix(a: Matrix3<f64>) -> Result<Self> {
        let det_a = a.determinant();
        let a_inv = a.try_inverse().filter(|_| det_a.is_finite() && det_a != 0.0);
        let a_inv = a_inv.ok_or_else(|| Error::invalid("ellipsoid matrix A is singular"))?;
        let an_norm = (a * Vector3::z()).norm();
        Ok(Ellipsoid { a, a_inv_t: a_inv.transpose(), det_a: det_a.abs(), an_norm, params: [f64::NAN; 5] })
    }

    /// The shape matrix A.
    pub fn a(&self) -> Matrix3<f64> {
        self.a
    }

    /// `[alpha_x, alpha_y, theta_x, theta_y, theta_z]` as constructed.
    pub fn params(&self) -> [f64; 5] {
        self.params
    }
}

impl Ndf for Ellipsoid {
    /// Walter et al. eq. 1: `D(m) = X+(m.n) / (pi |A| ||A n|| ||A^-T m||^4)`.
    fn d(&self, m: Vector3<f64>) -> f64 {
        if m.z < 0.0 {
            return 0.0;
        }
        let q = (self.a_inv_t * m).norm_squared();
        1.0 / (std::f64::consts::PI * self.det_a * self.an_norm * q * q)
    }
}

/// `R = Rx(theta_x) Ry(theta_y) Rz(theta_z)` (Walter et al. eq. 3).
pub fn rotation_xyz(theta_x: f64, theta_y: f64, theta_z: f64) -> Matrix3<f64> {
    let (sx, cx) = theta_x.sin_cos();
    let (sy, cy) = theta_y.sin_cos();
    let (sz, cz) = theta_z.sin_cos();
    let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, cx, -sx, 0.0, sx, cx);
    let ry = Matrix3::new(cy, 0.0, sy, 0.0, 1.0, 0.0, -sy, 0.0, cy);
    let rz = Matrix3::new(cz, -sz, 0.0, sz, cz, 0.0, 0.0, 0.0, 1.0);
    rx * ry * rz
}
