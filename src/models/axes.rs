//! The principal axes of a lobe in the scan frame: which tangent direction `alpha_x` belongs to.
//!
//! Walter et al. eq. 2-3 write `A = S Rz(theta_z)` for an axis-aligned lobe, and D depends on
//! `||S^-1 R m||`, so the `alpha_x` axis is the direction `t` with `R t = e_x`: the first row of `R`,
//! `(cos theta_z, -sin theta_z, 0)`, at azimuth `-theta_z` (not `+theta_z`). GGX and Beckmann (Heitz
//! eq. 81-82, same rotation) follow the same rule.
//!
//! For the ellipsoid with skew (`theta_x`, `theta_y` not 0) the axes come from its slope distribution
//! (Heitz eq. 64, `P22(s) = D(m) / (1 + |s|^2)^2` with `m ~ (-s, 1)`): with `M = A^-1 A^-T = R^T S^-2 R` in
//! blocks `[[T, b], [b^T, e]]` (T the 2x2 tangent block), eq. 1 gives `P22 ~ ((s - s0)^T T (s - s0) + c)^-2`
//! with `s0 = T^-1 b` and `c = e - b^T T^-1 b`. That is a GGX slope distribution centred on `s0` (the peak,
//! the sheared lobe of Heitz sec. 5.3) with the 2x2 roughness matrix `Sigma = c T^-1` (Tokuyoshi eq. 15):
//! its eigenvectors are the axes, the square roots of its eigenvalues the widths along them. Without skew
//! `s0 = 0`, `c = 1` and `Sigma = Rz^T diag(alpha_x^2, alpha_y^2) Rz`, the rule above. The eigenvector
//! called `alpha_x` is the one nearer the tangent-plane projection of the first row of `R`.

use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};

use super::ellipsoid::rotation_xyz;
use super::table::Form;
use super::Model;

/// The axes of an anisotropic lobe, in the scan frame (`+z` the macro normal).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct LobeAxes {
    /// Unit tangent vector along which the lobe has the width `widths[0]` (the `alpha_x` direction).
    pub alpha_x: [f64; 3],
    /// Unit tangent vector of the `alpha_y` direction, `n x alpha_x` (right-handed).
    pub alpha_y: [f64; 3],
    /// Azimuth of `alpha_x` (radians, counter-clockwise from `+x` towards `+y`), in `(-pi, pi]`.
    pub alpha_x_azimuth: f64,
    /// Slope-space widths along the two axes: `alpha_x`, `alpha_y` for the axis-aligned models, the square
    /// roots of the eigenvalues of `Sigma` for a skewed ellipsoid.
    pub widths: [f64; 2],
    /// Unit direction of the lobe's peak in slope space, `(-s0, 1) / |...|` (`+z` without skew).
    pub peak: [f64; 3],
}

impl LobeAxes {
    /// Axes of an axis-aligned lobe `alpha_x`, `alpha_y` rotated by `theta_z` (Walter et al. eq. 3).
    pub fn aligned(alpha_x: f64, alpha_y: f64, theta_z: f64) -> LobeAxes {
        let (s, c) = theta_z.sin_cos();
        LobeAxes::from_parts(Vector2::new(c, -s), [alpha_x, alpha_y], Vector2::zeros())
    }

    /// Axes of the ellipsoid `A = S R` with parameters `[alpha_x, alpha_y, theta_x, theta_y, theta_z]`
    /// (module doc: eigenvectors of `Sigma = c T^-1`).
    pub fn ellipsoid(p: [f64; 5]) -> LobeAxes {
        let [ax, ay, tx, ty, tz] = p;
        let r = rotation_xyz(tx, ty, tz);
        let m: Matrix3<f64> = r.transpose() * Matrix3::from_diagonal(&Vector3::new(1.0 / (ax * ax), 1.0 / (ay * ay), 1.0)) * r;
        let t = Matrix2::new(m[(0, 0)], m[(0, 1)], m[(1, 0)], m[(1, 1)]);
        let b = Vector2::new(m[(0, 2)], m[(1, 2)]);
        // T is positive definite (a principal block of the positive definite M), so it inverts.
        let t_inv = t.try_inverse().unwrap_or_else(Matrix2::identity);
        let s0 = t_inv * b;
        let c = m[(2, 2)] - b.dot(&s0);
        let sigma = t_inv * c;
        let eig = nalgebra::SymmetricEigen::new(0.5 * (sigma + sigma.transpose()));
        let r1 = Vector2::new(r[(0, 0)], r[(0, 1)]);
        let (l0, l1) = (eig.eigenvalues[0].max(0.0), eig.eigenvalues[1].max(0.0));
        let (v0, v1) = (eig.eigenvectors.column(0).into_owned(), eig.eigenvectors.column(1).into_owned());
        // Tied widths: every tangent direction is an axis; keep the one the parameters name.
        let tie = (l0 - l1).abs() <= 1e-12 * l0.max(l1);
        let (mut ex, wx, wy) = if tie || v0.dot(&r1).abs() >= v1.dot(&r1).abs() {
            (if tie { r1 } else { v0 }, l0.sqrt(), l1.sqrt())
        } else {
            (v1, l1.sqrt(), l0.sqrt())
        };
        if ex.dot(&r1) < 0.0 {
            ex = -ex;
        }
        LobeAxes::from_parts(ex, [wx, wy], s0)
    }

    fn from_parts(ex: Vector2<f64>, widths: [f64; 2], s0: Vector2<f64>) -> LobeAxes {
        let n = ex.norm();
        // ex is a row of a rotation or a unit eigenvector; a zero projection means the x axis is +-n, which
        // the canonical form excludes. Fall back to +x rather than NaN.
        let ex = if n > 0.0 { ex / n } else { Vector2::new(1.0, 0.0) };
        let peak = Vector3::new(-s0.x, -s0.y, 1.0).normalize();
        LobeAxes {
            alpha_x: [ex.x, ex.y, 0.0],
            alpha_y: [-ex.y, ex.x, 0.0],
            alpha_x_azimuth: ex.y.atan2(ex.x),
            widths,
            peak: [peak.x, peak.y, peak.z],
        }
    }
}

impl Model {
    /// The axes of the anisotropic models as parameterized (call on [`Model::canonical`] for the canonical
    /// labeling), read from the first lobe's geometry (`table`; a mixture's frame is its first
    /// lobe's, shared by both lobes of `ggx2` and `beckmann2`); `None` when that lobe is isotropic.
    pub fn axes(&self) -> Option<LobeAxes> {
        let spec = self.id().spec();
        let g = spec.parts(&self.params(), 0);
        match spec.lobes[0].form {
            Form::Iso => None,
            Form::Aniso => Some(LobeAxes::aligned(g.alpha_x, g.alpha_y, g.theta_z)),
            Form::Full => Some(LobeAxes::ellipsoid([g.alpha_x, g.alpha_y, g.theta_x, g.theta_y, g.theta_z])),
        }
    }
}
