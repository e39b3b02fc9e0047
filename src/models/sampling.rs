//! Exact, rejection-free sampling of the ellipsoid's visible normals: Walter et al. sec. 4.1, steps a-e
//! (eq. 34-48, "version 3"). Also samples GGX / GTR2aniso through their ellipsoid form (sec. 4.2).
//!
//! With `u = n` it samples `D(m) (m.n)` exactly (eq. 33 with `A_l(n, n) = A_e(n)`), which is how a
//! synthetic surface with a given ellipsoid NDF can draw its normals.

use nalgebra::Vector3;

use super::Ellipsoid;

/// Concentric map of the unit square to the unit disk (Shirley and Chiu 1997; Walter et al. eq. 34-37).
pub fn concentric_disk(xi1: f64, xi2: f64) -> (f64, f64) {
    let a = 2.0 * xi1 - 1.0;
    let b = 2.0 * xi2 - 1.0;
    // Both at the centre: eq. 36-37 would divide 0 by 0 (Walter et al. ask for this check).
    if a == 0.0 && b == 0.0 {
        return (0.0, 0.0);
    }
    let q = std::f64::consts::FRAC_PI_4;
    if a.abs() > b.abs() {
        let t = q * b / a;
        (a * t.cos(), a * t.sin())
    } else {
        let t = q * a / b;
        (b * t.sin(), b * t.cos())
    }
}

/// An orthonormal basis `(b1, b2)` with `b1 x b2 = n` for a unit `n` (Frisvad 2012).
pub fn frisvad_basis(n: Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    // Frisvad's formula divides by 1 + n.z; near n = -z use the fixed basis his paper gives.
    if n.z < -0.999_999_9 {
        return (Vector3::new(0.0, -1.0, 0.0), Vector3::new(-1.0, 0.0, 0.0));
    }
    let a = 1.0 / (1.0 + n.z);
    let b = -n.x * n.y * a;
    (Vector3::new(1.0 - n.x * n.x * a, b, -n.x), Vector3::new(b, 1.0 - n.y * n.y * a, -n.y))
}

impl Ellipsoid {
    /// Sample a microfacet normal `m` with the visible-normal pdf of eq. 33 for the direction `u` (the
    /// known direction psi), from two uniform numbers in `[0, 1)`. Steps (a)-(d) of sec. 4.1, eq. 34-46.
    /// `None` when the lune is empty (`u = -n`) or `u` is not a finite non-zero vector.
    pub fn sample_visible_normal(&self, u: Vector3<f64>, xi: [f64; 2]) -> Option<Vector3<f64>> {
        let a = self.a();
        let au = a * u;
        let an = a * Vector3::z();
        let (nu, nn) = (au.norm(), an.norm());
        // A zero or non-finite u has no direction to sample for.
        if !(nu > 0.0 && nu.is_finite()) {
            return None;
        }
        let e3 = au / nu; // eq. 42
        let n_s = an / nn;
        // (a) point on the unit disk (eq. 34-37).
        let (xa, ya) = concentric_disk(xi[0], xi[1]);
        // (b) compress to the crescent (eq. 38-41); s = (1 + cos theta_l) / 2 = |e3 + n_s|^2 / 4 exactly.
        let s = 0.25 * (e3 + n_s).norm_squared();
        // s = 0: Au opposite An (u = -n), the lune and its crescent are empty.
        if !(s > 0.0) {
            return None;
        }
        let xb = s * xa + (1.0 - s) * (1.0 - ya * ya).max(0.0).sqrt();
        let yb = ya;
        // Rounding can push the point a few ulps outside the unit disk.
        let zb = (1.0 - xb * xb - yb * yb).max(0.0).sqrt();
        // (c) basis: e2 along Au x An (eq. 43), e1 = e2 x e3 (eq. 44), pointing towards An.
        let c = e3.cross(&n_s);
        let cn = c.norm();
        let (e1, e2) = if cn > 1e-9 {
            let e2 = c / cn;
            (e2.cross(&e3), e2)
        } else {
            // u and n collinear: s = 1 up to 1e-18, the crescent is the whole disk and any basis works
            // (Walter et al. suggest Frisvad 2012).
            frisvad_basis(e3)
        };
        // (d) back to the ellipsoid (eq. 45-46).
        let pc = e1 * xb + e2 * yb + e3 * zb;
        let m = a.transpose() * pc;
        let mut m = m / m.norm();
        // On the lune's rim m.n = 0 exactly; rounding may leave it an ulp below the horizon.
        if m.z < 0.0 {
            m.z = 0.0;
            m /= m.norm();
        }
        Some(m)
    }

    /// Step (e): sample the reflected direction `omega = 2 (psi.m) m - psi` (eq. 47) with the pdf of
    /// eq. 48 ([`Ellipsoid::pdf_reflected`]). Returns `(omega, m)`.
    pub fn sample_reflected(&self, psi: Vector3<f64>, xi: [f64; 2]) -> Option<(Vector3<f64>, Vector3<f64>)> {
        let m = self.sample_visible_normal(psi, xi)?;
        let omega = m * (2.0 * psi.dot(&m)) - psi;
        Some((omega, m))
    }
}
