//! The Fresnel reflectance of a conductor from its complex index of refraction (Walter et al. eq. 4 asks
//! for "the standard fresnel equations based on the material's complex index of refraction").

use nalgebra::Complex;

use crate::error::{Error, Result};

/// A complex index of refraction `eta = n + i k` relative to the outside medium, checked: finite,
/// `n > 0`, `k >= 0`.
pub fn checked_eta(n: f64, k: f64) -> Result<Complex<f64>> {
    if !(n.is_finite() && k.is_finite() && n > 0.0 && k >= 0.0) {
        return Err(Error::invalid(format!("complex index of refraction needs finite n > 0 and k >= 0, got {n} + {k}i")));
    }
    Ok(Complex::new(n, k))
}

/// Unpolarized Fresnel reflectance of a conductor for the cosine `cos_theta_i` of the angle between the
/// incident direction and the facet normal, `eta = n + i k` (the exact equations with a complex Snell law,
/// as pbrt-v4's `FrComplex`):
/// `sin^2 t = sin^2 i / eta^2`, `cos t = sqrt(1 - sin^2 t)`, `r_par = (eta cos i - cos t)/(eta cos i + cos t)`,
/// `r_perp = (cos i - eta cos t)/(cos i + eta cos t)`, `F = (|r_par|^2 + |r_perp|^2) / 2`.
/// `cos_theta_i` is clamped into `[0, 1]`. The result is in `[0, 1]`.
pub fn fresnel_conductor(cos_theta_i: f64, eta: Complex<f64>) -> f64 {
    // Directions past grazing (or rounding just above 1) are clamped to the valid range of a cosine.
    let ci = if cos_theta_i.is_nan() { 0.0 } else { cos_theta_i.clamp(0.0, 1.0) };
    let sin2_i = 1.0 - ci * ci;
    let sin2_t = Complex::new(sin2_i, 0.0) / (eta * eta);
    let cos_t = (Complex::new(1.0, 0.0) - sin2_t).sqrt();
    let ci_c = Complex::new(ci, 0.0);
    let den_par = eta * ci_c + cos_t;
    let den_perp = ci_c + eta * cos_t;
    // Both denominators vanish only at grazing incidence with eta = 1, where the grazing limit F = 1 holds.
    if den_par.norm_sqr() == 0.0 || den_perp.norm_sqr() == 0.0 {
        return 1.0;
    }
    let r_par = (eta * ci_c - cos_t) / den_par;
    let r_perp = (ci_c - eta * cos_t) / den_perp;
    // |r|^2 <= 1 exactly; rounding near grazing incidence can exceed it by an ulp.
    (0.5 * (r_par.norm_sqr() + r_perp.norm_sqr())).clamp(0.0, 1.0)
}
