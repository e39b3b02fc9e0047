//! The Ellipsoid NDF of Walter, Dong, Marschner and Greenberg (2014, rev. 2016): D (eq. 1), A = S R
//! (eq. 2-3), projected areas of the ellipsoid and of the lune (eq. 26, 28), G1 (eq. 6, 32) and the
//! visible-normal pdf (eq. 33, 48). Sampling (sec. 4.1) is in [`super::sampling`], the canonical
//! parameters in [`super::canonical`].
//!
//! All areas use `C_e = 1` (eq. 30); only their ratios are ever used, in which `C_e` cancels.

use nalgebra::{Matrix3, Vector3};

use super::{canonical, checked_alpha, checked_angle, Ndf};
use crate::error::{Error, Result};

/// The ellipsoid NDF for a shape matrix A (Walter et al. eq. 1), with n = +z.
///
/// Always held as `A = S R` with `S = diag(alpha_x, alpha_y, 1)` and `R = Rx Ry Rz` (eq. 2-3), with the
/// quantities the formulas need precomputed: `A^-T = S^-1 R`, `|A| = alpha_x alpha_y` and `A n`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ellipsoid {
    a: Matrix3<f64>,
    a_inv_t: Matrix3<f64>,
    det_a: f64,
    an: Vector3<f64>,
    an_norm: f64,
    params: [f64; 5],
}

impl Ellipsoid {
    /// `A = S R` with `S = diag(alpha_x, alpha_y, 1)` and `R = Rx(theta_x) Ry(theta_y) Rz(theta_z)`
    /// (Walter et al. eq. 2-3). Alphas below [`super::ALPHA_MIN`] are raised to it; alphas above
    /// [`super::ALPHA_MAX`] and non-finite values are refused. Any finite angles are accepted (see
    /// [`Ellipsoid::canonical`] for the unique labeling).
    pub fn from_params(alpha_x: f64, alpha_y: f64, theta_x: f64, theta_y: f64, theta_z: f64) -> Result<Self> {
        let ax = checked_alpha("alpha_x", alpha_x)?;
        let ay = checked_alpha("alpha_y", alpha_y)?;
        let tx = checked_angle("theta_x", theta_x)?;
        let ty = checked_angle("theta_y", theta_y)?;
        let tz = checked_angle("theta_z", theta_z)?;
        Ok(Ellipsoid::build([ax, ay, tx, ty, tz]))
    }

    /// `A = S R` from parameters already known to be finite with positive alphas.
    fn build(p: [f64; 5]) -> Self {
        let [ax, ay, tx, ty, tz] = p;
        let r = rotation_xyz(tx, ty, tz);
        let s = Matrix3::from_diagonal(&Vector3::new(ax, ay, 1.0));
        let s_inv = Matrix3::from_diagonal(&Vector3::new(1.0 / ax, 1.0 / ay, 1.0));
        let a = s * r;
        let an = a.column(2).into_owned();
        Ellipsoid { a, a_inv_t: s_inv * r, det_a: ax * ay, an, an_norm: an.norm(), params: p }
    }

    /// An ellipsoid from any invertible A (eq. 1 depends on A only through `A^T A` up to scale). The result
    /// is the canonical equivalent (see `canonical::decompose`) with exactly the same D: [`Ellipsoid::a`]
    /// then returns `S R` of the canonical parameters, not the matrix given, and the alphas are not floored
    /// at [`super::ALPHA_MIN`] (they lie within `[1e-12, 1e12]`). A matrix whose smallest singular value is
    /// below `1e-12` times its largest (numerically singular), or that is not finite, is refused.
    pub fn from_matrix(a: Matrix3<f64>) -> Result<Self> {
        Ok(Ellipsoid::build(canonical::decompose(&a)?))
    }

    /// The shape matrix `A = S R`.
    pub fn a(&self) -> Matrix3<f64> {
        self.a
    }

    /// `[alpha_x, alpha_y, theta_x, theta_y, theta_z]` as constructed (after the alpha floor).
    pub fn params(&self) -> [f64; 5] {
        self.params
    }

    /// The same distribution with the canonical parameters (see `canonical::decompose`): the ellipsoid axis
    /// nearest `n` is the third axis, `alpha_x >= alpha_y`, `theta_z` in `(-pi/2, pi/2]`, `theta_z = 0` when
    /// the alphas tie. Idempotent.
    /// The canonical alphas keep D exactly: they are ratios of singular values and are not floored (an
    /// ellipsoid relabeled from `alpha = (1e-4, 10)` with a large tilt can have a canonical alpha of `1e-5`).
    pub fn canonical(&self) -> Ellipsoid {
        // The principal axes are the rows of R with singular values (alpha_x, alpha_y, 1): no SVD needed.
        let [ax, ay, tx, ty, tz] = self.params;
        match canonical::relabel(&rotation_xyz(tx, ty, tz), ax, ay) {
            Ok(p) => Ellipsoid::build(p),
            // A = S R with alphas in [ALPHA_MIN, ALPHA_MAX] has condition number <= 1e10 and is never refused.
            Err(_) => *self,
        }
    }

    /// `||A n||`: 1 exactly when `theta_x = theta_y = 0`.
    pub fn an_norm(&self) -> f64 {
        self.an_norm
    }

    /// The projected area of the ellipsoid along `u` (eq. 26, `C_e = 1`): `pi ||A u|| / |A|`.
    pub fn projected_area(&self, u: Vector3<f64>) -> f64 {
        std::f64::consts::PI * (self.a * u).norm() / self.det_a
    }

    /// The projected area along `u` of the ellipsoidal lune cut by the planes of `u` and `v` (eq. 28, `C_e = 1`):
    /// `pi (||Au|| ||Av|| + Au.Av) / (2 |A| ||Av||)`, evaluated as `pi ||Au|| |Au^ + Av^|^2 / (4 |A|)` with
    /// unit `Au^`, `Av^` (identical algebra, no cancellation when `Au` and `Av` are nearly opposite).
    /// (The text of eq. 28 prints `||A||` where the determinant `|A|` is meant, as eq. 26 and the check
    /// `A_l(u, u) = A_e(u)` show; `|A|` is used.)
    pub fn projected_area_lune(&self, u: Vector3<f64>, v: Vector3<f64>) -> f64 {
        let au = self.a * u;
        let av = self.a * v;
        let (nu, nv) = (au.norm(), av.norm());
        // A is invertible, so Au = 0 only for u = 0: no direction, no area.
        if nu == 0.0 || nv == 0.0 {
            return 0.0;
        }
        std::f64::consts::PI * nu * (au / nu + av / nv).norm_squared() / (4.0 * self.det_a)
    }

    /// `A_e(n) |u.n| / A_l(u, n)` (eq. 32 before the `min`), `= 2 ||An||^2 |u.n| / (||Au|| ||An|| + Au.An)`
    /// (eq. 6). `+inf` only for `u = -n`, where the lune is empty.
    fn visible_ratio(&self, u: Vector3<f64>) -> f64 {
        let au = self.a * u;
        let nu = au.norm();
        let k = (au / nu + self.an / self.an_norm).norm_squared();
        4.0 * self.an_norm * u.z.abs() / (nu * k)
    }

    /// The ellipsoid masking function, Walter et al. eq. 6 (eq. 32 with eq. 26, 28):
    /// `G1(u, m) = min(1, 2 ||An||^2 |u.n| / (||Au|| ||An|| + Au.An)) X+(u.m)`. In `[0, 1]`; 0 on the horizon.
    /// It is the Smith G1 of GGX when `theta_x = theta_y = 0` (sec. 4.2).
    pub fn g1(&self, u: Vector3<f64>, m: Vector3<f64>) -> f64 {
        // X+(u.m); written negated so that a NaN input gives 0 rather than NaN.
        if !(u.dot(&m) >= 0.0) {
            return 0.0;
        }
        let g = self.visible_ratio(u);
        // NaN only for a zero or non-finite u: no direction, nothing visible.
        if g.is_nan() {
            return 0.0;
        }
        g.min(1.0)
    }

    /// The `Lambda` implied by eq. 32, `max(0, A_l(u,n) / (A_e(n) |u.n|) - 1)`, so that `G1 = X+(u.m)/(1+Lambda)`
    /// (Heitz eq. 43). Exact Smith `Lambda` of GGX when `theta_x = theta_y = 0`. Saturates at `f64::MAX`
    /// on the horizon, where it is `+inf`.
    pub fn lambda(&self, u: Vector3<f64>) -> f64 {
        if u.z > 0.0 {
            // 1/g - 1 cancels near the normal. With c = An/|An|, beta = Au.c, tau^2 = |Au - beta c|^2 and the
            // skew term p = A(ux, uy, 0).c, the same quantity is (tau^2/(|Au| + beta) + 2p) / (2 |An| uz):
            // no cancellation when p = 0 (theta_x = theta_y = 0, where it is exactly Tokuyoshi eq. 16).
            let au = self.a * u;
            let c = self.an / self.an_norm;
            let beta = au.dot(&c);
            let tau2 = (au - c * beta).norm_squared();
            let nu = au.norm();
            let first = if beta > 0.0 { tau2 / (nu + beta) } else { nu - beta };
            let p = (self.a * Vector3::new(u.x, u.y, 0.0)).dot(&c);
            let l = (first + 2.0 * p) / (2.0 * self.an_norm * u.z);
            // Overflow for uz ~ 1e-308: the horizon limit. Negative (skewed A) means eq. 32's min(1, .) is
            // active and G1 = 1, i.e. Lambda = 0.
            return if l.is_finite() { l.max(0.0) } else { f64::MAX };
        }
        let g = self.visible_ratio(u);
        let l = 1.0 / g - 1.0;
        // g = 0 on the horizon: Lambda = +inf, saturated; NaN only for a zero u.
        if !l.is_finite() {
            return f64::MAX;
        }
        // Negative: the min(1, .) of eq. 32 is active (G1 = 1), Lambda = 0.
        l.max(0.0)
    }

    /// The visible-normal pdf of eq. 33 (solid angle measure on `m`):
    /// `p_h(m) = A_e(n) / A_l(u, n) X+(m.u) D(m) |m.u|`. Integrates to 1 over `m` for any `u` except `-n`.
    pub fn pdf_visible_normal(&self, u: Vector3<f64>, m: Vector3<f64>) -> f64 {
        let mu = m.dot(&u);
        // X+(m.u) of eq. 33 (a NaN input also lands here).
        if !(mu > 0.0) {
            return 0.0;
        }
        let ratio = self.area_ratio(u);
        ratio * self.d(m) * mu
    }

    /// `A_e(n) / A_l(u, n) = 4 ||An|| / (||Au|| |Au^ + An^|^2)`; 0 where the lune is empty (`u = -n`).
    fn area_ratio(&self, u: Vector3<f64>) -> f64 {
        let au = self.a * u;
        let nu = au.norm();
        let k = (au / nu + self.an / self.an_norm).norm_squared();
        let r = 4.0 * self.an_norm / (nu * k);
        // u = -n (empty lune) or u = 0: no visible normals, so no density.
        if r.is_finite() {
            r
        } else {
            0.0
        }
    }

    /// The pdf of the reflected direction `omega` for incident `psi` (eq. 48):
    /// `p_o(omega) = A_e(n) / (4 A_l(psi, n)) X+(m.psi) D(m)` with `m` the half vector. 0 when
    /// `psi + omega = 0` (no half vector).
    pub fn pdf_reflected(&self, psi: Vector3<f64>, omega: Vector3<f64>) -> f64 {
        let h = psi + omega;
        let hn = h.norm();
        // psi = -omega: the half vector is undefined and no reflection maps psi to omega.
        if !(hn > 0.0) {
            return 0.0;
        }
        let m = h / hn;
        // X+(m.psi) of eq. 48.
        if !(m.dot(&psi) > 0.0) {
            return 0.0;
        }
        0.25 * self.area_ratio(psi) * self.d(m)
    }

    /// The weight of a sample drawn by [`Ellipsoid::sample_reflected`] (eq. 49-50):
    /// `G1(psi, m) G1(omega, m) F / |psi.n| * A_l(psi, n) / A_e(n)`, which is `<= G1(omega, m) F <= 1` (eq. 51-52).
    /// `fresnel` is `F(psi.m)` in `[0, 1]`. Written as `G1(omega, m) F min(1, 1/r) X+(psi.m)` with
    /// `r = A_e(n) |psi.n| / A_l(psi, n)`, the same value, finite on the horizon (its limit there).
    /// 0 when `omega` is not above the horizon (the reflection BRDF is 0 there).
    pub fn sample_weight(&self, psi: Vector3<f64>, omega: Vector3<f64>, m: Vector3<f64>, fresnel: f64) -> f64 {
        // Back-facing m, or omega under the macrosurface (f_r of eq. 4 is 0 there, reflection only).
        if !(psi.dot(&m) >= 0.0) || !(omega.z > 0.0) {
            return 0.0;
        }
        let r = self.visible_ratio(psi);
        // G1(psi) / r = min(1, r) / r = min(1/r, 1); r = 0 on the horizon has the limit 1, r NaN only for u = 0.
        let f = if r.is_nan() {
            0.0
        } else if r > 1.0 {
            1.0 / r
        } else {
            1.0
        };
        // F is a reflectance: a caller's rounding outside [0, 1] must not lift the weight past 1 (eq. 52).
        self.g1(omega, m) * fresnel.clamp(0.0, 1.0) * f
    }
}

impl Ndf for Ellipsoid {
    /// Walter et al. eq. 1: `D(m) = X+(m.n) / (pi |A| ||A n|| ||A^-T m||^4)`. Finite everywhere on the
    /// hemisphere including the horizon (`||A^-T m||^2 >= 1 / max(alpha_x, alpha_y, 1)^2`).
    fn d(&self, m: Vector3<f64>) -> f64 {
        if m.z < 0.0 {
            return 0.0;
        }
        let q = (self.a_inv_t * m).norm_squared();
        1.0 / (std::f64::consts::PI * self.det_a * self.an_norm * q * q)
    }
}

impl super::Masking for Ellipsoid {
    /// [`Ellipsoid::lambda`].
    fn lambda(&self, u: Vector3<f64>) -> f64 {
        Ellipsoid::lambda(self, u)
    }
    /// [`Ellipsoid::g1`] (Walter et al. eq. 6).
    fn g1(&self, u: Vector3<f64>, m: Vector3<f64>) -> f64 {
        Ellipsoid::g1(self, u, m)
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

/// Guard used by callers that build an ellipsoid from untrusted matrices.
pub(crate) fn singular_error() -> Error {
    Error::invalid("ellipsoid matrix A is singular or nearly so (smallest/largest singular value < 1e-12)")
}
