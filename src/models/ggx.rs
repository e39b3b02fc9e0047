//! GGX / Trowbridge-Reitz and its anisotropic form GTR2aniso (Burley 2012; Walter et al. sec. 4.2), in
//! Heitz's slope-space form (Heitz eq. 70-72 isotropic, 84-86 anisotropic).

use nalgebra::{Vector2, Vector3};

use super::{checked_alpha, checked_angle, rotate_z, smith_g1, Ellipsoid, GgxMatrix, Masking, Ndf};
use crate::error::Result;

/// Anisotropic GGX rotated by `theta_z` in the tangent plane; isotropic when `alpha_x == alpha_y`.
///
/// It is the ellipsoid with `theta_x = theta_y = 0` (Walter et al. sec. 4.2), and `theta_z` has the
/// ellipsoid's meaning: the local frame is `m' = Rz(theta_z) m`, in which the slopes are axis-aligned
/// with roughness `alpha_x` along x and `alpha_y` along y.
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
    /// A GGX distribution; alphas below [`super::ALPHA_MIN`] are raised to it, alphas above
    /// [`super::ALPHA_MAX`] and non-finite values are refused.
    pub fn new(alpha_x: f64, alpha_y: f64, theta_z: f64) -> Result<Self> {
        Ok(Ggx {
            alpha_x: checked_alpha("alpha_x", alpha_x)?,
            alpha_y: checked_alpha("alpha_y", alpha_y)?,
            theta_z: checked_angle("theta_z", theta_z)?,
        })
    }

    /// The same distribution as an [`Ellipsoid`] (Walter et al. sec. 4.2: `R = Rz(theta_z)`).
    pub fn to_ellipsoid(&self) -> Ellipsoid {
        Ellipsoid::from_params(self.alpha_x, self.alpha_y, 0.0, 0.0, self.theta_z).expect("alphas and theta_z were checked on construction")
    }

    /// The same distribution with Tokuyoshi's 2x2 roughness matrix (Tokuyoshi eq. 17-18).
    pub fn to_matrix(&self) -> GgxMatrix {
        GgxMatrix::from_ggx(self)
    }

    /// The distribution of slopes `P22(x, y)` of Heitz eq. 84 (eq. 70 when isotropic), in the scan frame:
    /// the slope is rotated into the local frame first (Heitz eq. 88-90 with the rotation of eq. 3).
    pub fn p22(&self, slope: Vector2<f64>) -> f64 {
        let l = rotate_z(self.theta_z, Vector3::new(slope.x, slope.y, 0.0));
        let r2 = (l.x / self.alpha_x).powi(2) + (l.y / self.alpha_y).powi(2);
        let q = 1.0 + r2;
        // q^2 overflows past 1e154; P22 < 1e-290 from q = 1e150 on, so 0 is exact to f64 precision.
        if !q.is_finite() || q > 1e150 {
            return 0.0;
        }
        1.0 / (std::f64::consts::PI * self.alpha_x * self.alpha_y * q * q)
    }

    /// The projected roughness `alpha_o` in the azimuth of `u` (Heitz eq. 80), for `u` off the normal,
    /// computed without angles as `sqrt(ax^2 ux'^2 + ay^2 uy'^2) / sqrt(ux^2 + uy^2)` with `u' = Rz u`.
    /// For `u` exactly along the normal the azimuth is undefined and `alpha_x` is returned.
    pub fn alpha_o(&self, u: Vector3<f64>) -> f64 {
        projected_roughness(self.alpha_x, self.alpha_y, self.theta_z, u)
    }
}

/// Heitz eq. 80 in the rotated frame of eq. 3, shared by GGX and Beckmann.
pub(crate) fn projected_roughness(ax: f64, ay: f64, theta_z: f64, u: Vector3<f64>) -> f64 {
    let l = rotate_z(theta_z, u);
    let s2 = l.x * l.x + l.y * l.y;
    // Along the normal the azimuth phi_o of eq. 80 is undefined (and a = inf makes it irrelevant).
    if s2 == 0.0 {
        return ax;
    }
    ((ax * l.x).powi(2) + (ay * l.y).powi(2)).sqrt() / s2.sqrt()
}

/// `(alpha_o tan(theta_o))^2 = (ax^2 ux'^2 + ay^2 uy'^2) / uz^2 = 1/a^2` of Heitz eq. 72/86 and 69/83.
#[inline]
pub(crate) fn inv_a2(ax: f64, ay: f64, theta_z: f64, u: Vector3<f64>) -> f64 {
    let l = rotate_z(theta_z, u);
    ((ax * l.x).powi(2) + (ay * l.y).powi(2)) / (u.z * u.z)
}

/// Smith's `Lambda(u)` of a lobe of slopes stretched by `(ax, ay)` and turned by `theta_z`, which depends
/// on `u` only through `w = 1/a^2` ([`inv_a2`]; Heitz sec. 5.3), with the guards every such lobe shares;
/// `lambda_of_w` is the lobe's own `Lambda(w)` for a finite `w > 0`.
#[inline]
pub(crate) fn smith_lambda(ax: f64, ay: f64, theta_z: f64, u: Vector3<f64>, lambda_of_w: impl FnOnce(f64) -> f64) -> f64 {
    let w = inv_a2(ax, ay, theta_z, u);
    // On the horizon a = 0 (w = inf, or 0/0 for a zero vector) and Lambda = +inf: saturate (see Masking::lambda).
    if !w.is_finite() || w == 0.0 && u.z == 0.0 {
        return f64::MAX;
    }
    // Along the normal a = inf: nothing is masked.
    if w == 0.0 {
        return 0.0;
    }
    lambda_of_w(w)
}

impl Ndf for Ggx {
    /// Heitz eq. 85 (eq. 71 isotropic) multiplied through by `cos^4`:
    /// `D(m) = X+(m.n) / (pi ax ay (x'^2/ax^2 + y'^2/ay^2 + z^2)^2)` with `m' = Rz m` (Burley eq. 13,
    /// Tokuyoshi eq. 15). This form has no `tan` and stays finite on the horizon.
    fn d(&self, m: Vector3<f64>) -> f64 {
        if m.z < 0.0 {
            return 0.0;
        }
        let l = rotate_z(self.theta_z, m);
        let q = (l.x / self.alpha_x).powi(2) + (l.y / self.alpha_y).powi(2) + l.z * l.z;
        1.0 / (std::f64::consts::PI * self.alpha_x * self.alpha_y * q * q)
    }
}

impl Masking for Ggx {
    /// Heitz eq. 86 (eq. 72 isotropic): `Lambda = (-1 + sqrt(1 + 1/a^2)) / 2`, `a = 1/(alpha_o tan theta_o)`,
    /// evaluated as `w / (2 (1 + sqrt(1 + w)))` with `w = 1/a^2` (no cancellation near the normal).
    fn lambda(&self, u: Vector3<f64>) -> f64 {
        smith_lambda(self.alpha_x, self.alpha_y, self.theta_z, u, |w| w / (2.0 * (1.0 + (1.0 + w).sqrt())))
    }

    /// Heitz eq. 43: `X+(u.m) / (1 + Lambda(u))`.
    fn g1(&self, u: Vector3<f64>, m: Vector3<f64>) -> f64 {
        smith_g1(self.lambda(u), u, m)
    }
}
