//! Non-axis-aligned anisotropic GGX with Tokuyoshi's 2x2 roughness matrix (Tokuyoshi eq. 3, 17-18;
//! Heitz eq. 88-93 with `Q^-1` the roughness matrix).

use nalgebra::{Matrix2, Vector2, Vector3};

use super::{canonical, smith_g1, Ggx, Masking, Ndf, ALPHA_MAX, ALPHA_MIN};
use crate::error::{Error, Result};

/// GGX written with a symmetric positive-definite 2x2 roughness matrix `A` (Tokuyoshi eq. 17):
/// `D(h) = X+(h_z) / (pi sqrt(det A) ([hx, hy] A^-1 [hx, hy]^T + hz^2)^2)`.
///
/// For axis-aligned GGX `A = diag(alpha_x^2, alpha_y^2)`; a rotated one (our `theta_z`, local frame
/// `m' = Rz(theta_z) m`) has `A = Rz^T diag(alpha_x^2, alpha_y^2) Rz`. Filtering the NDF by a Gaussian
/// slope kernel of covariance `Sigma` adds `2 Sigma` (Tokuyoshi eq. 3).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GgxMatrix {
    a: Matrix2<f64>,
    a_inv: Matrix2<f64>,
    sqrt_det: f64,
}

impl GgxMatrix {
    /// A roughness matrix; it must be finite, symmetric (to 1e-12 relative) and positive definite with
    /// eigenvalues in `[ALPHA_MIN^2, ALPHA_MAX^2]` (the same alpha range as every model).
    pub fn new(a: Matrix2<f64>) -> Result<Self> {
        if a.iter().any(|v| !v.is_finite()) {
            return Err(Error::invalid("roughness matrix has a non-finite entry"));
        }
        let scale = a.abs().max();
        if (a[(0, 1)] - a[(1, 0)]).abs() > 1e-12 * scale {
            return Err(Error::invalid("roughness matrix is not symmetric"));
        }
        let a = (a + a.transpose()) * 0.5;
        let (l1, l2, _) = sym2_eigen(&a);
        // Eigenvalues are alpha^2 along the principal axes; outside the alpha range the model is refused.
        if !(l2 >= ALPHA_MIN * ALPHA_MIN * (1.0 - 1e-9) && l1 <= ALPHA_MAX * ALPHA_MAX) {
            return Err(Error::invalid(format!(
                "roughness matrix eigenvalues {l2:e}, {l1:e} are outside [{:e}, {:e}]",
                ALPHA_MIN * ALPHA_MIN,
                ALPHA_MAX * ALPHA_MAX
            )));
        }
        let det = a[(0, 0)] * a[(1, 1)] - a[(0, 1)] * a[(1, 0)];
        let a_inv = Matrix2::new(a[(1, 1)], -a[(0, 1)], -a[(1, 0)], a[(0, 0)]) / det;
        Ok(GgxMatrix { a, a_inv, sqrt_det: det.sqrt() })
    }

    /// The roughness matrix of a (rotated) GGX: `Rz^T diag(ax^2, ay^2) Rz` (2x2 block of eq. 3's `Rz`).
    pub fn from_ggx(g: &Ggx) -> Self {
        let a = Self::matrix_from_params(g.alpha_x, g.alpha_y, g.theta_z);
        let det = g.alpha_x.powi(2) * g.alpha_y.powi(2);
        let a_inv = Matrix2::new(a[(1, 1)], -a[(0, 1)], -a[(1, 0)], a[(0, 0)]) / det;
        GgxMatrix { a, a_inv, sqrt_det: g.alpha_x * g.alpha_y }
    }

    /// `A = Rz^T diag(alpha_x^2, alpha_y^2) Rz` for the contract's `theta_z` (the local frame is
    /// `m' = Rz(theta_z) m`, so `s' = Rz s` and `s'^T diag(1/alpha^2) s' = s^T A^-1 s`: Tokuyoshi eq. 15 ->
    /// 17). Exactly symmetric. The one place the crate builds a roughness matrix from parameters.
    pub fn matrix_from_params(alpha_x: f64, alpha_y: f64, theta_z: f64) -> Matrix2<f64> {
        let (s, c) = theta_z.sin_cos();
        let rz = Matrix2::new(c, -s, s, c);
        let a = rz.transpose() * Matrix2::from_diagonal(&Vector2::new(alpha_x * alpha_x, alpha_y * alpha_y)) * rz;
        (a + a.transpose()) * 0.5
    }

    /// Inverse of [`GgxMatrix::matrix_from_params`] in the canonical form (`alpha_x >= alpha_y`,
    /// `theta_z` in `(-pi/2, pi/2]`, `theta_z = 0` when the alphas tie; models/canonical.rs): the
    /// eigenvalues of `A` are `alpha^2`, the eigenvector of the larger is the local x axis. `None` when `A`
    /// is not finite or not positive definite. No alpha range check (see [`GgxMatrix::new`]).
    pub fn params_from_matrix(a: &Matrix2<f64>) -> Option<(f64, f64, f64)> {
        if a.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let (_, l2, _) = sym2_eigen(&((a + a.transpose()) * 0.5));
        // A non-positive eigenvalue has no alpha: the matrix is no roughness matrix.
        if !(l2 > 0.0) {
            return None;
        }
        Some(params_unchecked(&((a + a.transpose()) * 0.5)))
    }

    /// Eigenvalues `l1 >= l2` of a symmetric 2x2 matrix and the unit eigenvector of `l1`, in closed form
    /// (stable when the eigenvalues differ by orders of magnitude or `A` is nearly diagonal).
    pub fn eigen(a: &Matrix2<f64>) -> (f64, f64, Vector2<f64>) {
        sym2_eigen(a)
    }

    /// The roughness matrix `A`.
    pub fn matrix(&self) -> Matrix2<f64> {
        self.a
    }

    /// The NDF filtered by a Gaussian slope kernel of covariance `sigma`: `A + 2 Sigma` (Tokuyoshi eq. 3).
    pub fn with_kernel_covariance(&self, sigma: Matrix2<f64>) -> Result<Self> {
        GgxMatrix::new(self.a + sigma * 2.0)
    }

    /// Back to `alpha_x >= alpha_y`, `theta_z` in `(-pi/2, pi/2]` (the canonical [`Ggx`]): the eigenvalues
    /// of `A` are `alpha^2` and the eigenvector of the larger one is the local x axis.
    pub fn to_ggx(&self) -> Ggx {
        let (ax, ay, tz) = params_unchecked(&self.a);
        Ggx { alpha_x: ax.max(ALPHA_MIN), alpha_y: ay.max(ALPHA_MIN), theta_z: tz }
    }
}

/// Canonical `(alpha_x, alpha_y, theta_z)` of a symmetric `A` whose eigenvalues are checked elsewhere.
fn params_unchecked(a: &Matrix2<f64>) -> (f64, f64, f64) {
    let (l1, l2, v1) = sym2_eigen(a);
    // Local x axis in the scan frame is (cos tz, -sin tz) (row 1 of Rz), so tz = atan2(-v1.y, v1.x).
    let tz = (-v1.y).atan2(v1.x);
    // Callers check positive definiteness; max(0) only absorbs rounding of a tiny l2.
    canonical::canonical_aniso(l1.max(0.0).sqrt(), l2.max(0.0).sqrt(), tz)
}

/// Eigenvalues `l1 >= l2` of a symmetric 2x2 matrix and the unit eigenvector of `l1` (closed form).
pub(crate) fn sym2_eigen(a: &Matrix2<f64>) -> (f64, f64, Vector2<f64>) {
    let (p, q, r) = (a[(0, 0)], a[(0, 1)], a[(1, 1)]);
    let mean = 0.5 * (p + r);
    let half_diff = 0.5 * (p - r);
    let rad = half_diff.hypot(q);
    let l1 = mean + rad;
    // mean - rad cancels when the eigenvalues differ by orders of magnitude; det / l1 does not.
    let l2 = if l1 > 0.0 { (p * r - q * q) / l1 } else { mean - rad };
    // Eigenvector of l1: angle phi with tan(2 phi) = 2q / (p - r); atan2 keeps it stable when q ~ 0.
    let phi = 0.5 * q.atan2(half_diff);
    (l1, l2, Vector2::new(phi.cos(), phi.sin()))
}

impl Ndf for GgxMatrix {
    /// Tokuyoshi eq. 17.
    fn d(&self, h: Vector3<f64>) -> f64 {
        if h.z < 0.0 {
            return 0.0;
        }
        let t = Vector2::new(h.x, h.y);
        let q = (t.transpose() * self.a_inv * t)[(0, 0)] + h.z * h.z;
        1.0 / (std::f64::consts::PI * self.sqrt_det * q * q)
    }
}

impl Masking for GgxMatrix {
    /// Tokuyoshi eq. 18: `Lambda = -1/2 + sqrt([ox, oy] A [ox, oy]^T + oz^2) / (2 |oz|)`, evaluated as
    /// `s / (2 |oz| (sqrt(s + oz^2) + |oz|))` with `s = [ox, oy] A [ox, oy]^T` (no cancellation).
    fn lambda(&self, o: Vector3<f64>) -> f64 {
        let t = Vector2::new(o.x, o.y);
        // A positive definite gives s >= 0; max(0) absorbs rounding for o along the normal.
        let s = (t.transpose() * self.a * t)[(0, 0)].max(0.0);
        let z = o.z.abs();
        let l = s / (2.0 * z * ((s + z * z).sqrt() + z));
        // On the horizon (z = 0) Lambda = +inf (or 0/0 along no direction at all): saturate.
        if !l.is_finite() {
            return if s == 0.0 && z > 0.0 { 0.0 } else { f64::MAX };
        }
        l
    }

    /// Tokuyoshi appendix A: `G1 = X+(o.h) / (1 + Lambda(o))`.
    fn g1(&self, o: Vector3<f64>, h: Vector3<f64>) -> f64 {
        smith_g1(self.lambda(o), o, h)
    }
}

/// The Jacobian of the map from the projected unit disk `(hx, hy)` to slope space
/// `(-hx/hz, -hy/hz)` (Tokuyoshi eq. 24-25): `-1/hz^3 [[1 - hy^2, hx hy], [hx hy, 1 - hx^2]]`, with
/// `hz = sqrt(1 - hx^2 - hy^2)`. Its determinant is `1/hz^4`; with the disk's `d(disk) = hz d(omega)`
/// (Tokuyoshi eq. 9) this is Heitz eq. 64, `P22 = D cos^4`. `None` on or outside the rim (`hz = 0`).
pub fn disk_to_slope_jacobian(hx: f64, hy: f64) -> Option<Matrix2<f64>> {
    let hz2 = 1.0 - hx * hx - hy * hy;
    // On the rim the slope is infinite; outside it there is no hemisphere point.
    if !(hz2 > 0.0) {
        return None;
    }
    let hz = hz2.sqrt();
    Some(Matrix2::new(1.0 - hy * hy, hx * hy, hx * hy, 1.0 - hx * hx) * (-1.0 / (hz2 * hz)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn params_round_trip_against_nalgebra_eigen() {
        // The closed-form eigen-decomposition against nalgebra's iterative symmetric_eigen (a second
        // algorithm) for the larger eigenvalue (1e-12 relative) and against the construction's alpha^2 for
        // both: the smaller one is conditioned by l1 / l2 (rounding of the entries, ~eps l1, is all of
        // it), so 10 eps l1 / l2 relative. params -> matrix -> params recovers the canonical parameters
        // (rounding of a 2x2 product: 1e-12).
        for &(ax, ay, tz) in &[(0.3, 0.1, 0.6), (0.05, 0.2, -1.2), (1e-4, 10.0, 0.3), (0.5, 0.5, 0.0), (0.2, 0.19, 1.5)] {
            let a = GgxMatrix::matrix_from_params(ax, ay, tz);
            let e = a.symmetric_eigen();
            let hi = e.eigenvalues.max();
            let (l1, l2, v1) = GgxMatrix::eigen(&a);
            let (big, small) = (f64::max(ax, ay).powi(2), f64::min(ax, ay).powi(2));
            assert!((l1 / hi - 1.0).abs() < 1e-12 && (l1 / big - 1.0).abs() < 1e-12, "{ax} {ay} {tz}: {l1} vs {hi}");
            assert!((l2 / small - 1.0).abs() < 10.0 * f64::EPSILON * big / small + 1e-12, "{ax} {ay} {tz}: {l2} vs {small}");
            assert!(((a * v1) - v1 * l1).norm() < 1e-12 * hi);
            let (bx, by, t2) = GgxMatrix::params_from_matrix(&a).unwrap();
            assert!(bx >= by && t2.abs() <= std::f64::consts::FRAC_PI_2 + 1e-12);
            let b = GgxMatrix::matrix_from_params(bx, by, t2);
            assert!((a - b).norm() < 1e-12 * a.norm(), "{a} vs {b}");
        }
        assert!(GgxMatrix::params_from_matrix(&Matrix2::new(1.0, 0.0, 0.0, -1e-3)).is_none());
        assert!(GgxMatrix::params_from_matrix(&Matrix2::new(f64::NAN, 0.0, 0.0, 1.0)).is_none());
    }
}
