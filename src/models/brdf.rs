//! The microfacet BRDF (Walter et al. eq. 4; Heitz eq. 29 / Tokuyoshi eq. 1) with any model of
//! [`super::Model`], a conductor Fresnel term and a choice of masking-shadowing function.

use nalgebra::{Complex, Vector3};

use super::{fresnel_conductor, Model, Ndf};

/// The masking-shadowing function `G(psi, omega, m)` of the BRDF.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MaskingShadowing {
    /// `G1(psi, m) G1(omega, m)` (Walter et al. eq. 5, Heitz eq. 98). The default: the ellipsoid's energy
    /// bound (eq. 49-52) is proven for this form.
    #[default]
    Separable,
    /// Height-correlated `X+(psi.m) X+(omega.m) / (1 + Lambda(psi) + Lambda(omega))` (Heitz eq. 99); for the
    /// ellipsoid with the `Lambda` of [`Model::lambda`].
    HeightCorrelated,
}

/// A microfacet BRDF for reflection: `f = D(h) G(psi, omega, h) F(psi.h) / (4 |psi.n| |omega.n|)`, with
/// `h = (psi + omega) / |psi + omega|` (Walter et al. eq. 4).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MicrofacetBrdf {
    /// The NDF (and its masking).
    pub model: Model,
    /// Complex index of refraction of the conductor (see [`super::fresnel::checked_eta`]); `None` means
    /// `F = 1` (a perfect mirror per facet, used by furnace tests).
    pub eta: Option<Complex<f64>>,
    /// Which `G` to use.
    pub masking: MaskingShadowing,
}

impl MicrofacetBrdf {
    /// The masking-shadowing term `G(psi, omega, m)`.
    pub fn g2(&self, psi: Vector3<f64>, omega: Vector3<f64>, m: Vector3<f64>) -> f64 {
        match self.masking {
            MaskingShadowing::Separable => self.model.g1(psi, m) * self.model.g1(omega, m),
            MaskingShadowing::HeightCorrelated => {
                // Heitz eq. 99: the X+ factors, then 1/(1 + L1 + L2); L saturates at f64::MAX, giving 0.
                if !(psi.dot(&m) > 0.0 && omega.dot(&m) > 0.0) || psi.z == 0.0 || omega.z == 0.0 {
                    return 0.0;
                }
                1.0 / (1.0 + self.model.lambda(psi) + self.model.lambda(omega))
            }
        }
    }

    /// `F(psi.h)`: the conductor Fresnel term, or 1.
    pub fn fresnel(&self, cos_theta: f64) -> f64 {
        self.eta.map_or(1.0, |eta| fresnel_conductor(cos_theta, eta))
    }

    /// Walter et al. eq. 4 for incident `psi` and outgoing `omega` (unit vectors). 0 unless both are above
    /// the horizon (reflection only) and `psi != -omega`.
    pub fn eval(&self, psi: Vector3<f64>, omega: Vector3<f64>) -> f64 {
        // Reflection only; on the horizon the 1/(psi.n omega.n) factor is infinite while G is 0: the limit is 0.
        if !(psi.z > 0.0 && omega.z > 0.0) {
            return 0.0;
        }
        let h = psi + omega;
        let hn = h.norm();
        let h = h / hn;
        let g = self.g2(psi, omega, h);
        // Nothing visible: 0 whatever D and F are (and no work for them).
        if g == 0.0 {
            return 0.0;
        }
        self.model.d(h) * g * self.fresnel(psi.dot(&h)) / (4.0 * psi.z * omega.z)
    }
}
