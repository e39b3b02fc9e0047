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
/// incident direction and the facet normal, `eta = n + i k`: the exact equations with a complex Snell law
/// (`r_par`, `r_perp` as pbrt-v4's `FrComplex`) in the real form of pbrt-v3's `FrConductor`, where
/// `a^2 + b^2 = |eta^2 - sin^2 i|` and `a = Re sqrt(eta^2 - sin^2 i)`:
/// `R_s = (a^2 + b^2 + cos^2 i - 2 a cos i) / (a^2 + b^2 + cos^2 i + 2 a cos i)`,
/// `R_p = R_s (cos^2 i (a^2 + b^2) + sin^4 i - 2 a cos i sin^2 i) / (... + 2 a cos i sin^2 i)`,
/// `F = (R_s + R_p) / 2`. Square roots only: no complex polar form on the renderer's inner loop.
/// `cos_theta_i` is clamped into `[0, 1]`. The result is in `[0, 1]`.
pub fn fresnel_conductor(cos_theta_i: f64, eta: Complex<f64>) -> f64 {
    // Directions past grazing (or rounding just above 1) are clamped to the valid range of a cosine.
    let ci = if cos_theta_i.is_nan() { 0.0 } else { cos_theta_i.clamp(0.0, 1.0) };
    let (cos2, sin2) = (ci * ci, 1.0 - ci * ci);
    let (n2, k2) = (eta.re * eta.re, eta.im * eta.im);
    let t0 = n2 - k2 - sin2;
    let a2b2 = (t0 * t0 + 4.0 * n2 * k2).sqrt();
    let a = (0.5 * (a2b2 + t0)).max(0.0).sqrt();
    let (t1, t2) = (a2b2 + cos2, 2.0 * ci * a);
    let (t3, t4) = (cos2 * a2b2 + sin2 * sin2, t2 * sin2);
    // Both denominators vanish only at grazing incidence with eta = 1, where the grazing limit F = 1 holds.
    if t1 + t2 <= 0.0 || t3 + t4 <= 0.0 {
        return 1.0;
    }
    let rs = (t1 - t2) / (t1 + t2);
    let rp = rs * (t3 - t4) / (t3 + t4);
    // |r|^2 <= 1 exactly; rounding near grazing incidence can exceed it by an ulp.
    (0.5 * (rs + rp)).clamp(0.0, 1.0)
}

/// [`fresnel_conductor`] at one cosine for three indices (a renderer's red, green and blue), the same
/// value per index; on x86-64 the first two are computed side by side in SSE2's two lanes (the same
/// operations in the same order, so the same bits), which takes a third off the square roots and
/// divisions of the renderer's inner loop.
#[inline]
pub fn fresnel_conductor3(cos_theta_i: f64, eta: &[Complex<f64>; 3]) -> [f64; 3] {
    #[cfg(target_arch = "x86_64")]
    {
        let [a, b] = fresnel_pair(cos_theta_i, eta[0], eta[1]);
        [a, b, fresnel_conductor(cos_theta_i, eta[2])]
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        eta.map(|e| fresnel_conductor(cos_theta_i, e))
    }
}

/// [`fresnel_conductor`] for two indices in the two lanes of an SSE2 register, step by step.
#[cfg(target_arch = "x86_64")]
#[inline]
fn fresnel_pair(cos_theta_i: f64, e0: Complex<f64>, e1: Complex<f64>) -> [f64; 2] {
    use std::arch::x86_64::*;
    let ci = if cos_theta_i.is_nan() { 0.0 } else { cos_theta_i.clamp(0.0, 1.0) };
    let (cos2, sin2) = (ci * ci, 1.0 - ci * ci);
    let (mut rs, mut rp, mut t12, mut t34) = ([0.0; 2], [0.0; 2], [0.0; 2], [0.0; 2]);
    // SAFETY: SSE2 is part of every x86-64 CPU; the stores write four local arrays of two lanes.
    unsafe {
        let pair = |a: f64, b: f64| _mm_set_pd(b, a);
        let all = |v: f64| _mm_set1_pd(v);
        let (re, im) = (pair(e0.re, e1.re), pair(e0.im, e1.im));
        let (n2, k2) = (_mm_mul_pd(re, re), _mm_mul_pd(im, im));
        let t0 = _mm_sub_pd(_mm_sub_pd(n2, k2), all(sin2));
        let a2b2 = _mm_sqrt_pd(_mm_add_pd(_mm_mul_pd(t0, t0), _mm_mul_pd(_mm_mul_pd(all(4.0), n2), k2)));
        // `max(x, 0)`: 0 for a NaN `x`, as `f64::max`.
        let a = _mm_sqrt_pd(_mm_max_pd(_mm_mul_pd(all(0.5), _mm_add_pd(a2b2, t0)), _mm_setzero_pd()));
        let (t1, t2) = (_mm_add_pd(a2b2, all(cos2)), _mm_mul_pd(all(2.0 * ci), a));
        let (t3, t4) = (_mm_add_pd(_mm_mul_pd(all(cos2), a2b2), all(sin2 * sin2)), _mm_mul_pd(t2, all(sin2)));
        let r_s = _mm_div_pd(_mm_sub_pd(t1, t2), _mm_add_pd(t1, t2));
        let r_p = _mm_div_pd(_mm_mul_pd(r_s, _mm_sub_pd(t3, t4)), _mm_add_pd(t3, t4));
        _mm_storeu_pd(rs.as_mut_ptr(), r_s);
        _mm_storeu_pd(rp.as_mut_ptr(), r_p);
        _mm_storeu_pd(t12.as_mut_ptr(), _mm_add_pd(t1, t2));
        _mm_storeu_pd(t34.as_mut_ptr(), _mm_add_pd(t3, t4));
    }
    // As `fresnel_conductor`: the grazing limit where a denominator vanishes, and rounding clamped.
    [0, 1].map(|k| if t12[k] <= 0.0 || t34[k] <= 0.0 { 1.0 } else { (0.5 * (rs[k] + rp[k])).clamp(0.0, 1.0) })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The complex form, term by term (pbrt-v4's `FrComplex`): the second algorithm the real form is
    /// checked against.
    fn complex_form(ci: f64, eta: Complex<f64>) -> f64 {
        let sin2_t = Complex::new(1.0 - ci * ci, 0.0) / (eta * eta);
        let cos_t = (Complex::new(1.0, 0.0) - sin2_t).sqrt();
        let ci_c = Complex::new(ci, 0.0);
        let r_par = (eta * ci_c - cos_t) / (eta * ci_c + cos_t);
        let r_perp = (ci_c - eta * cos_t) / (ci_c + eta * cos_t);
        0.5 * (r_par.norm_sqr() + r_perp.norm_sqr())
    }

    /// The real form equals the complex one for metals, weak absorbers and dielectrics, from normal to
    /// near-grazing incidence; normal incidence is `|eta - 1|^2 / |eta + 1|^2`, grazing is 1.
    #[test]
    fn real_form_matches_the_complex_equations() {
        let etas = [(1.1, 6.8), (0.05, 3.9), (0.27, 2.9), (3.2, 3.3), (1.5, 0.0), (2.4, 0.01), (0.9, 0.2)];
        for (n, k) in etas {
            let eta = Complex::new(n, k);
            for i in 0..=200 {
                let ci = (i as f64 / 200.0).max(1e-6);
                let (fast, slow) = (fresnel_conductor(ci, eta), complex_form(ci, eta));
                assert!((fast - slow).abs() < 1e-12, "eta {n}+{k}i cos {ci}: {fast} vs {slow}");
            }
            let normal = ((eta - 1.0) / (eta + 1.0)).norm_sqr();
            assert!((fresnel_conductor(1.0, eta) - normal).abs() < 1e-14);
            assert_eq!(fresnel_conductor(0.0, eta), 1.0);
        }
        assert_eq!(fresnel_conductor(0.0, Complex::new(1.0, 0.0)), 1.0);
        assert_eq!(fresnel_conductor(f64::NAN, Complex::new(1.1, 6.8)), 1.0);
    }

    /// Three indices at once are, bit for bit, each index alone: metals, a dielectric, the mirror-like
    /// `eta = 1` (its grazing limit), from below 0 to above 1 and NaN.
    #[test]
    fn three_at_once_equal_one_by_one() {
        let etas = [(1.1, 6.8), (0.05, 3.9), (0.27, 2.9), (3.2, 3.3), (1.5, 0.0), (1.0, 0.0), (0.9, 0.2)].map(|(n, k)| Complex::new(n, k));
        let mut cosines: Vec<f64> = (0..=400).map(|i| i as f64 / 400.0).collect();
        cosines.extend([-0.5, -0.0, 1e-300, 1e-9, 1.0 - 1e-16, 1.5, f64::NAN, f64::INFINITY]);
        for k in 0..etas.len() {
            let three = [etas[k], etas[(k + 1) % etas.len()], etas[(k + 2) % etas.len()]];
            for &c in &cosines {
                let want = three.map(|e| fresnel_conductor(c, e).to_bits());
                assert_eq!(fresnel_conductor3(c, &three).map(f64::to_bits), want, "{three:?} at {c}");
            }
        }
    }
}
