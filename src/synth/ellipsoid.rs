//! The visible upper surface of an arbitrarily rotated ellipsoid, whose NDF is exactly the ellipsoid NDF.
//!
//! Walter et al. define the ellipsoid implicitly, `p^T A^T A p = C_e^2` (eq. 8), with normal
//! `m = A^T A p / |A^T A p|` (eq. 15, 22). With `Q = A^T A` and `p = (x, y, z)`, eq. 8 is a quadratic
//! in z, `q33 z^2 + 2 b z + c = 0` with `b = q13 x + q23 y` and `c = q11 x^2 + 2 q12 x y + q22 y^2 - C^2`.
//! Its larger root `z = (-b + sqrt(b^2 - q33 c)) / q33` is the surface seen from `+z`; there
//! `(Q p)_z = b + q33 z = sqrt(b^2 - q33 c) >= 0`, so the heightfield is exactly the half of the ellipsoid
//! with `m.n >= 0`, the half that defines the NDF (sec. 2.3, "Manufacturability"), bounded by the
//! silhouette `m.n = 0` (eq. 23). Its projected area is `A_perp(n) = pi C^2 |A n| / |A|` (eq. 26), and its
//! projected-area density of normals is `D(m)` of eq. 1 (eq. 9 with eq. 20 and 26).
//! Points off the footprint `b^2 - q33 c < 0` are invalid (NaN).

use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use serde_json::json;

use super::{SynthSettings, Truth};
use crate::error::{Error, Result};
use crate::models::{Ellipsoid, Model};
use crate::scan::Heightfield;

/// The hard-end truths `[alpha_x, alpha_y, theta_x, theta_y, theta_z]` of docs/ACCURACY.md: anisotropy to
/// 10:1, alpha down to 0.02, skew to 0.4 rad, and a round cap whose tail the sampling resolves (last).
pub const HARD_END_SET: [[f64; 5]; 7] = [
    [0.35, 0.05, 0.16, 0.0, 0.3],
    [0.2, 0.02, 0.0, 0.4, 0.0],
    [0.5, 0.05, -0.4, 0.1, 1.0],
    [0.1, 0.02, 0.2, 0.2, -0.7],
    [0.05, 0.05, 0.4, 0.0, 0.0],
    [0.02, 0.02, 0.3, -0.3, 0.0],
    [0.2, 0.2, 0.0, 0.0, 0.0],
];

/// Parameters of the ellipsoid surface (contract names, Walter et al. eq. 2-3).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EllipsoidParams {
    /// Roughness along the ellipsoid's local x axis.
    pub alpha_x: f64,
    /// Roughness along the local y axis.
    pub alpha_y: f64,
    /// Rotation about x (radians).
    pub theta_x: f64,
    /// Rotation about y (radians).
    pub theta_y: f64,
    /// Rotation about z (radians).
    pub theta_z: f64,
    /// Fraction of the grid's half-extent the footprint's bounding box fills (0 < fill <= 1).
    pub fill: f64,
}

impl Default for EllipsoidParams {
    fn default() -> Self {
        EllipsoidParams { alpha_x: 0.3, alpha_y: 0.3, theta_x: 0.0, theta_y: 0.0, theta_z: 0.0, fill: 0.96 }
    }
}

/// The ellipsoid's geometry on a grid: `Q = A^T A`, the size `C` and the footprint.
#[derive(Debug, Clone, Copy)]
pub struct EllipsoidGeometry {
    /// `Q = A^T A`.
    pub q: Matrix3<f64>,
    /// The size constant `C_e` (m) of eq. 8.
    pub c: f64,
    /// Projected area of the upper half, `pi C^2 |A n| / |A|` (eq. 26), in m^2.
    pub proj_area: f64,
    /// The model.
    pub model: Ellipsoid,
}

impl EllipsoidGeometry {
    /// Geometry sized so that the footprint fills `fill` of the grid's half-extents.
    pub fn new(p: &EllipsoidParams, s: &SynthSettings) -> Result<Self> {
        if !(p.fill > 0.0 && p.fill <= 1.0) {
            return Err(Error::invalid(format!("fill must be in (0, 1], got {}", p.fill)));
        }
        let model = Ellipsoid::from_params(p.alpha_x, p.alpha_y, p.theta_x, p.theta_y, p.theta_z)?;
        let a = model.a();
        let q = a.transpose() * a;
        // Footprint: b^2 - q33 c >= 0  <=>  v^T M v <= q33 C^2 with M = q33 Q_xy - q_z q_z^T (a Schur
        // complement, positive definite for invertible A). Its half-extent along x is sqrt(q33 C^2 (M^-1)_11).
        let m11 = q[(2, 2)] * q[(0, 0)] - q[(0, 2)] * q[(0, 2)];
        let m12 = q[(2, 2)] * q[(0, 1)] - q[(0, 2)] * q[(1, 2)];
        let m22 = q[(2, 2)] * q[(1, 1)] - q[(1, 2)] * q[(1, 2)];
        let det = m11 * m22 - m12 * m12;
        if !(det > 0.0 && det.is_finite()) {
            return Err(Error::invalid("ellipsoid footprint is degenerate (A nearly singular)"));
        }
        let (inv11, inv22) = (m22 / det, m11 / det);
        let half_x = 0.5 * (s.nx as f64 - 1.0) * s.dx * p.fill;
        let half_y = 0.5 * (s.ny as f64 - 1.0) * s.dy * p.fill;
        let c = (half_x / (q[(2, 2)] * inv11).sqrt()).min(half_y / (q[(2, 2)] * inv22).sqrt());
        let an = (a * Vector3::z()).norm();
        let proj_area = std::f64::consts::PI * c * c * an / a.determinant().abs();
        Ok(EllipsoidGeometry { q, c, proj_area, model })
    }

    /// Height of the upper surface at `(x, y)` from the centre, or `None` off the footprint.
    #[inline]
    pub fn height(&self, x: f64, y: f64) -> Option<f64> {
        let q = &self.q;
        let b = q[(0, 2)] * x + q[(1, 2)] * y;
        let c = q[(0, 0)] * x * x + 2.0 * q[(0, 1)] * x * y + q[(1, 1)] * y * y - self.c * self.c;
        let disc = b * b - q[(2, 2)] * c;
        // Guard: the silhouette itself (disc = 0) has a vertical tangent, no finite slope; only the open
        // footprint is surface.
        if disc > 0.0 {
            Some((disc.sqrt() - b) / q[(2, 2)])
        } else {
            None
        }
    }

    /// The exact slope `grad h` at `(x, y)` on the footprint: `-(Q p)_xy / (Q p)_z` (eq. 15, 22).
    pub fn slope(&self, x: f64, y: f64) -> Option<[f64; 2]> {
        let z = self.height(x, y)?;
        let g = self.q * Vector3::new(x, y, z);
        Some([-g.x / g.z, -g.y / g.z])
    }

    /// Where the normal `m` sits on the surface: `p = C Q^-1 m / sqrt(m^T Q^-1 m)` (inverting eq. 22),
    /// and how deep inside the footprint that is, as `1 - v^T M v / (q33 C^2)` (1 at the centre, 0 on
    /// the silhouette).
    pub fn point_of(&self, m: Vector3<f64>) -> Option<(Vector3<f64>, f64)> {
        let qi = self.q.try_inverse()?;
        let u = qi * m;
        let k = m.dot(&u);
        if !(k > 0.0) {
            return None;
        }
        let p = u * (self.c / k.sqrt());
        let q = &self.q;
        let (x, y) = (p.x, p.y);
        let vmv = q[(2, 2)] * (q[(0, 0)] * x * x + 2.0 * q[(0, 1)] * x * y + q[(1, 1)] * y * y) - (q[(0, 2)] * x + q[(1, 2)] * y).powi(2);
        Some((p, 1.0 - vmv / (q[(2, 2)] * self.c * self.c)))
    }
}

/// The ellipsoid surface of `p` on the grid of `s`, centred, and its truth (model `ellipsoid`).
pub fn ellipsoid_surface(s: &SynthSettings, p: &EllipsoidParams) -> Result<(Heightfield, Truth)> {
    s.check()?;
    let g = EllipsoidGeometry::new(p, s)?;
    let mut z = vec![f64::NAN; s.nx * s.ny];
    z.par_chunks_mut(s.nx).enumerate().for_each(|(i, row)| {
        let y = s.yc(i);
        for (j, v) in row.iter_mut().enumerate() {
            if let Some(h) = g.height(s.xc(j), y) {
                *v = h;
            }
        }
    });
    let hf = s.finish(z)?;
    let settings = json!({"grid": s, "ellipsoid": p});
    let derived = json!({
        "c_e": g.c,
        "proj_area": g.proj_area,
        "footprint_samples": g.proj_area / (s.dx * s.dy),
        "peak_height": g.height(0.0, 0.0),
    });
    Ok((hf, Truth::for_model(&Model::Ellipsoid(g.model), "ellipsoid", settings, derived)))
}
