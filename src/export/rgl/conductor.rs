//! The conductors `--material` names, by their complex index of refraction `n + i k`.
//!
//! Gold and copper are the measured indices of Johnson and Christy, "Optical constants of the noble
//! metals", Phys. Rev. B 6(12), 4370-4379 (1972), Table I, interpolated linearly in photon energy: a
//! smooth model misses their interband absorption edge (gold 2.3-2.5 eV, copper 2.1 eV) by up to 0.15 in
//! reflectance. Silver, aluminium and chromium come from the Lorentz-Drude model of Rakic, Djurisic,
//! Elazar and Majewski, "Optical properties of metallic films for vertical-cavity optoelectronic devices",
//! Applied Optics 37(22), 5271-5283 (1998), eq. 3 with the parameters of their Tables 1 and 2 (valid from
//! 0.1 to 5 eV): `eps(w) = 1 - f0 wp^2 / (w (w + i G0)) + sum_j f_j wp^2 / (w_j^2 - w^2 - i w G_j)`,
//! `n + i k = sqrt(eps)`, photon energies in eV.

use std::sync::OnceLock;

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

/// Johnson & Christy (1972) Table I for gold: photon energy (eV), `n`, `k`, from 1.26 to 3.74 eV (984 to
/// 331 nm, the visible with a margin).
const AU_JC: [(f64, f64, f64); 21] = [
    (1.26, 0.22, 6.350),
    (1.39, 0.17, 5.663),
    (1.51, 0.16, 5.083),
    (1.64, 0.14, 4.542),
    (1.76, 0.13, 4.103),
    (1.88, 0.14, 3.697),
    (2.01, 0.21, 3.272),
    (2.13, 0.29, 2.863),
    (2.26, 0.43, 2.455),
    (2.38, 0.62, 2.081),
    (2.50, 1.04, 1.833),
    (2.63, 1.31, 1.849),
    (2.75, 1.38, 1.914),
    (2.88, 1.45, 1.948),
    (3.00, 1.46, 1.958),
    (3.12, 1.47, 1.952),
    (3.25, 1.46, 1.933),
    (3.37, 1.48, 1.895),
    (3.50, 1.50, 1.866),
    (3.62, 1.48, 1.871),
    (3.74, 1.48, 1.883),
];

/// Johnson & Christy (1972) Table I for copper, on the same energies as [`AU_JC`].
const CU_JC: [(f64, f64, f64); 21] = [
    (1.26, 0.32, 6.421),
    (1.39, 0.30, 5.768),
    (1.51, 0.26, 5.180),
    (1.64, 0.24, 4.665),
    (1.76, 0.21, 4.205),
    (1.88, 0.22, 3.747),
    (2.01, 0.30, 3.205),
    (2.13, 0.70, 2.704),
    (2.26, 1.02, 2.577),
    (2.38, 1.18, 2.608),
    (2.50, 1.22, 2.564),
    (2.63, 1.25, 2.483),
    (2.75, 1.24, 2.397),
    (2.88, 1.25, 2.305),
    (3.00, 1.28, 2.207),
    (3.12, 1.32, 2.116),
    (3.25, 1.33, 2.045),
    (3.37, 1.36, 1.975),
    (3.50, 1.37, 1.916),
    (3.62, 1.36, 1.864),
    (3.74, 1.34, 1.821),
];

/// `n + i k` of a measured table (energies ascending) at photon energy `e`, linear in energy between rows;
/// beyond the table the nearest row holds.
fn measured(table: &[(f64, f64, f64)], e: f64) -> Complex<f64> {
    let last = table.len() - 1;
    let e = e.clamp(table[0].0, table[last].0);
    let j = table.partition_point(|r| r.0 < e).clamp(1, last);
    let (a, b) = (table[j - 1], table[j]);
    let t = (e - a.0) / (b.0 - a.0);
    Complex::new(a.1 + t * (b.1 - a.1), a.2 + t * (b.2 - a.2))
}

/// Rakic et al. (1998) Lorentz-Drude parameters: `wp` (eV), `f0`, `G0` (eV), then `(f_j, G_j, w_j)` (eV).
struct LorentzDrude {
    wp: f64,
    f0: f64,
    g0: f64,
    osc: &'static [(f64, f64, f64)],
}

impl LorentzDrude {
    /// `n + i k` at photon energy `w` (eV): the root of eq. 3's `eps` with `k >= 0` (an absorbing medium).
    fn eta(&self, w: f64) -> Complex<f64> {
        let i = Complex::new(0.0, 1.0);
        let wp2 = self.wp * self.wp;
        let mut eps = Complex::new(1.0, 0.0) - self.f0 * wp2 / (w * (w + i * self.g0));
        for &(f, g, wj) in self.osc {
            eps += f * wp2 / (Complex::new(wj * wj - w * w, 0.0) - i * w * g);
        }
        let r = eps.sqrt();
        if r.im < 0.0 {
            -r
        } else {
            r
        }
    }
}

// Table 1 (`f0`, `G0`, `wp`) and Table 2 (oscillators) of Rakic et al. (1998).
const AG_LD: LorentzDrude = LorentzDrude {
    wp: 9.01,
    f0: 0.845,
    g0: 0.048,
    osc: &[(0.065, 3.886, 0.816), (0.124, 0.452, 4.481), (0.011, 0.065, 8.185), (0.840, 0.916, 9.083), (5.646, 2.419, 20.29)],
};
const AL_LD: LorentzDrude = LorentzDrude {
    wp: 14.98,
    f0: 0.523,
    g0: 0.047,
    osc: &[(0.227, 0.333, 0.162), (0.050, 0.312, 1.544), (0.166, 1.351, 1.808), (0.030, 3.382, 3.473)],
};
const CR_LD: LorentzDrude = LorentzDrude {
    wp: 10.75,
    f0: 0.168,
    g0: 0.047,
    osc: &[(0.151, 3.175, 0.121), (0.150, 1.305, 0.543), (1.149, 2.676, 1.970), (0.825, 1.335, 8.775)],
};

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
        let w = HC_EV_NM / lambda_nm;
        Some(match self {
            Material::None => return None,
            Material::Au => measured(&AU_JC, w),
            Material::Cu => measured(&CU_JC, w),
            Material::Ag => AG_LD.eta(w),
            Material::Al => AL_LD.eta(w),
            Material::Cr => CR_LD.eta(w),
        })
    }

    /// Where the complex index comes from, as a file's description cites it (empty for the mirror).
    pub fn source(self) -> &'static str {
        match self {
            Material::None => "",
            Material::Au | Material::Cu => "Johnson & Christy 1972, Table I",
            Material::Ag | Material::Al | Material::Cr => "Rakic et al. 1998 Lorentz-Drude model",
        }
    }

    /// Unpolarized Fresnel reflectance at the cosine `cos_i` between the incident direction and the facet
    /// normal, at `lambda_nm` (1 for the perfect mirror).
    pub fn fresnel(self, cos_i: f64, lambda_nm: f64) -> f64 {
        self.eta(lambda_nm).map_or(1.0, |eta| crate::models::fresnel::fresnel_conductor(cos_i, eta))
    }

    /// The complex index at the [`super::RGB_NM`] wavelengths (`None` for the mirror), computed once per
    /// material: the renderer and the tracer ask for it per shading point.
    pub fn eta_rgb(self) -> Option<[Complex<f64>; 3]> {
        static CACHE: [OnceLock<Option<[Complex<f64>; 3]>>; Material::ALL.len()] = [const { OnceLock::new() }; Material::ALL.len()];
        let k = Material::ALL.iter().position(|&m| m == self).unwrap_or(0);
        *CACHE[k].get_or_init(|| match self {
            Material::None => None,
            _ => Some(super::RGB_NM.map(|nm| self.eta(nm).unwrap_or(Complex::new(1.0, 0.0)))),
        })
    }

    /// The Fresnel reflectance at the cosine `cos_i` at the [`super::RGB_NM`] wavelengths (1 for the mirror).
    #[inline]
    pub fn fresnel_rgb(self, cos_i: f64) -> [f64; 3] {
        match self.eta_rgb() {
            None => [1.0; 3],
            Some(eta) => crate::models::fresnel::fresnel_conductor3(cos_i, &eta),
        }
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
