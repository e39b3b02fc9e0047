//! The conductors `--material` names, by their complex index of refraction `n + i k`.
//!
//! The indices come from the Lorentz-Drude model of Rakic, Djurisic, Elazar and Majewski, "Optical
//! properties of metallic films for vertical-cavity optoelectronic devices", Applied Optics 37(22),
//! 5271-5283 (1998), eq. 3 with the parameters of their Tables 1 and 2 (valid from 0.1 to 5 eV, i.e. the
//! whole visible range): `eps(w) = 1 - f0 wp^2 / (w (w + i G0)) + sum_j f_j wp^2 / (w_j^2 - w^2 - i w G_j)`,
//! `n + i k = sqrt(eps)`, photon energies in eV.

use nalgebra::Complex;

/// `hc` in eV nm: a wavelength in nm is `HC / E`.
const HC_EV_NM: f64 = 1_239.841_98;

/// A reflecting material of the table.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Material {
    /// A perfect mirror conductor: `F = 1` at every angle and wavelength.
    None,
    /// Aluminium.
    Al,
    /// Silver.
    Ag,
    /// Gold.
    Au,
    /// Copper.
    Cu,
    /// Chromium.
    Cr,
}

/// Rakic et al. (1998) Lorentz-Drude parameters: `wp` (eV), `f0`, `G0` (eV), then `(f_j, G_j, w_j)` (eV).
struct LorentzDrude {
    wp: f64,
    f0: f64,
    g0: f64,
    osc: &'static [(f64, f64, f64)],
}

/// Table 1 (`f0`, `G0`, `wp`) and Table 2 (oscillators) of Rakic et al. (1998).
fn parameters(m: Material) -> Option<LorentzDrude> {
    let p = match m {
        Material::None => return None,
        Material::Ag => LorentzDrude {
            wp: 9.01,
            f0: 0.845,
            g0: 0.048,
            osc: &[(0.065, 3.886, 0.816), (0.124, 0.452, 4.481), (0.011, 0.065, 8.185), (0.840, 0.916, 9.083), (5.646, 2.419, 20.29)],
        },
        Material::Au => LorentzDrude {
            wp: 9.03,
            f0: 0.760,
            g0: 0.053,
            osc: &[(0.024, 0.241, 0.415), (0.010, 0.345, 0.830), (0.071, 0.870, 2.969), (0.601, 2.494, 4.304), (4.384, 2.214, 13.32)],
        },
        Material::Cu => LorentzDrude {
            wp: 10.83,
            f0: 0.575,
            g0: 0.030,
            osc: &[(0.061, 0.378, 0.291), (0.104, 1.056, 2.957), (0.723, 3.213, 5.300), (0.638, 4.305, 11.18)],
        },
        Material::Al => LorentzDrude {
            wp: 14.98,
            f0: 0.523,
            g0: 0.047,
            osc: &[(0.227, 0.333, 0.162), (0.050, 0.312, 1.544), (0.166, 1.351, 1.808), (0.030, 3.382, 3.473)],
        },
        Material::Cr => LorentzDrude {
            wp: 10.75,
            f0: 0.168,
            g0: 0.047,
            osc: &[(0.151, 3.175, 0.121), (0.150, 1.305, 0.543), (1.149, 2.676, 1.970), (0.825, 1.335, 8.775)],
        },
    };
    Some(p)
}

impl Material {
    /// Every material, in the order `--material` lists them.
    pub const ALL: [Material; 6] = [Material::None, Material::Al, Material::Ag, Material::Au, Material::Cu, Material::Cr];

    /// The name as `--material` spells it.
    pub fn as_str(self) -> &'static str {
        match self {
            Material::None => "none",
            Material::Al => "Al",
            Material::Ag => "Ag",
            Material::Au => "Au",
            Material::Cu => "Cu",
            Material::Cr => "Cr",
        }
    }

    /// The complex index `n + i k` at `lambda_nm` (`None` for the perfect mirror).
    pub fn eta(self, lambda_nm: f64) -> Option<Complex<f64>> {
        let p = parameters(self)?;
        let w = HC_EV_NM / lambda_nm;
        let i = Complex::new(0.0, 1.0);
        let wp2 = p.wp * p.wp;
        let mut eps = Complex::new(1.0, 0.0) - p.f0 * wp2 / (w * (w + i * p.g0));
        for &(f, g, wj) in p.osc {
            eps += f * wp2 / (Complex::new(wj * wj - w * w, 0.0) - i * w * g);
        }
        // The root with k >= 0 (an absorbing medium).
        let r = eps.sqrt();
        Some(if r.im < 0.0 { -r } else { r })
    }

    /// Unpolarized Fresnel reflectance at the cosine `cos_i` between the incident direction and the facet
    /// normal, at `lambda_nm` (1 for the perfect mirror).
    pub fn fresnel(self, cos_i: f64, lambda_nm: f64) -> f64 {
        self.eta(lambda_nm).map_or(1.0, |eta| crate::models::fresnel::fresnel_conductor(cos_i, eta))
    }
}

impl std::str::FromStr for Material {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Self> {
        Material::ALL
            .into_iter()
            .find(|m| m.as_str().eq_ignore_ascii_case(s))
            .ok_or_else(|| crate::Error::invalid(format!("unknown material '{s}' (expected none, Al, Ag, Au, Cu or Cr)")))
    }
}
