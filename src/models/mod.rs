//! Analytic normal distribution functions (NDFs) and their masking functions.
//!
//! Papers (texts in `../shared/seeds/`, equation numbers cited throughout):
//! - Walter, Dong, Marschner, Greenberg, *The Ellipsoid Normal Distribution Function* (2014, rev. 2016):
//!   the ellipsoid NDF, its G1, projected areas and exact visible-normal sampling.
//! - Heitz, *Understanding the Masking-Shadowing Function in Microfacet-Based BRDFs* (JCGT 2014):
//!   normalization (eq. 9), slope space (eq. 61-64), Smith Lambda for GGX and Beckmann (eq. 69-86).
//! - Tokuyoshi, *Error Reduction and Simplification for Shading Anti-Aliasing*: the 2x2 roughness matrix
//!   and non-axis-aligned anisotropic GGX (eq. 15-18).
//! - Tokuyoshi and Harada, *Derivation of a Squared Ellipsoidal Lobe Function*.
//!
//! Every model is a small `Copy` value type whose methods read like the formulas. All directions are unit
//! vectors in the scan frame of CONTRACT.md (macro normal `n = +z`).

pub mod beckmann;
pub mod ellipsoid;
pub mod ggx;

pub use beckmann::Beckmann;
pub use ellipsoid::Ellipsoid;
pub use ggx::Ggx;

use nalgebra::{Matrix3, Vector3};

use crate::error::{Error, Result};

/// Smallest roughness any model accepts. Below it `alpha^2` nears the f64 spacing of 1 in the
/// denominators `mz^2 + (slope/alpha)^2`, and a renderer cannot tell the lobe from a mirror anyway
/// (pbrt-v4 uses the same floor for the same reason).
pub const ALPHA_MIN: f64 = 1e-4;

/// The model ids of the contract.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize)]
pub enum ModelId {
    /// Isotropic GGX / Trowbridge-Reitz: `alpha`.
    #[serde(rename = "ggx")]
    Ggx,
    /// GTR2aniso rotated by `theta_z`: `alpha_x`, `alpha_y`, `theta_z`.
    #[serde(rename = "ggx-aniso")]
    GgxAniso,
    /// Isotropic Beckmann: `alpha`.
    #[serde(rename = "beckmann")]
    Beckmann,
    /// Anisotropic Beckmann rotated by `theta_z`: `alpha_x`, `alpha_y`, `theta_z`.
    #[serde(rename = "beckmann-aniso")]
    BeckmannAniso,
    /// The ellipsoid NDF, A = S R (Walter et al. eq. 2-3): `alpha_x`, `alpha_y`, `theta_x`, `theta_y`, `theta_z`.
    #[serde(rename = "ellipsoid")]
    Ellipsoid,
}

impl ModelId {
    /// Every model id, simplest first.
    pub const ALL: [ModelId; 5] =
        [ModelId::Ggx, ModelId::Beckmann, ModelId::GgxAniso, ModelId::BeckmannAniso, ModelId::Ellipsoid];

    /// The id as the contract spells it.
    pub fn as_str(self) -> &'static str {
        match self {
            ModelId::Ggx => "ggx",
            ModelId::GgxAniso => "ggx-aniso",
            ModelId::Beckmann => "beckmann",
            ModelId::BeckmannAniso => "beckmann-aniso",
            ModelId::Ellipsoid => "ellipsoid",
        }
    }

    /// The parameter names, in the order `Model::params` returns them.
    pub fn param_names(self) -> &'static [&'static str] {
        match self {
            ModelId::Ggx | ModelId::Beckmann => &["alpha"],
            ModelId::GgxAniso | ModelId::BeckmannAniso => &["alpha_x", "alpha_y", "theta_z"],
            ModelId::Ellipsoid => &["alpha_x", "alpha_y", "theta_x", "theta_y", "theta_z"],
        }
    }

    /// Number of free parameters.
    pub fn n_params(self) -> usize {
        self.param_names().len()
    }

    /// Whether the model is a special case of the ellipsoid (and so has a matrix A).
    pub fn has_matrix_a(self) -> bool {
        matches!(self, ModelId::Ggx | ModelId::GgxAniso | ModelId::Ellipsoid)
    }
}

impl std::fmt::Display for ModelId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for ModelId {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        ModelId::ALL
            .into_iter()
            .find(|id| id.as_str() == s)
            .ok_or_else(|| Error::invalid(format!("unknown model '{s}' (expected ggx, ggx-aniso, beckmann, beckmann-aniso or ellipsoid)")))
    }
}

/// The common interface of the analytic NDFs.
pub trait Ndf {
    /// The NDF `D(m)` (1/sr), zero below the horizon; normalized so that the integral of
    /// `D(m) (m.n)` over the hemisphere is 1 (Heitz eq. 9).
    fn d(&self, m: Vector3<f64>) -> f64;
}

/// One fitted or hand-written model: the id and its parameters, as one value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Model {
    /// `ggx`.
    Ggx(Ggx),
    /// `ggx-aniso`.
    GgxAniso(Ggx),
    /// `beckmann`.
    Beckmann(Beckmann),
    /// `beckmann-aniso`.
    BeckmannAniso(Beckmann),
    /// `ellipsoid`.
    Ellipsoid(Ellipsoid),
}

impl Model {
    /// Build a model from its id and parameters in the order of [`ModelId::param_names`].
    pub fn from_params(id: ModelId, p: &[f64]) -> Result<Model> {
        if p.len() != id.n_params() {
            return Err(Error::invalid(format!("model {id} takes {} parameters, got {}", id.n_params(), p.len())));
        }
        if let Some(bad) = p.iter().find(|v| !v.is_finite()) {
            return Err(Error::invalid(format!("model {id}: parameter {bad} is not finite")));
        }
        Ok(match id {
            ModelId::Ggx => Model::Ggx(Ggx::new(p[0], p[0], 0.0)?),
            ModelId::GgxAniso => Model::GgxAniso(Ggx::new(p[0], p[1], p[2])?),
            ModelId::Beckmann => Model::Beckmann(Beckmann::new(p[0], p[0], 0.0)?),
            ModelId::BeckmannAniso => Model::BeckmannAniso(Beckmann::new(p[0], p[1], p[2])?),
            ModelId::Ellipsoid => Model::Ellipsoid(Ellipsoid::from_params(p[0], p[1], p[2], p[3], p[4])?),
        })
    }

    /// The model's id.
    pub fn id(&self) -> ModelId {
        match self {
            Model::Ggx(_) => ModelId::Ggx,
            Model::GgxAniso(_) => ModelId::GgxAniso,
            Model::Beckmann(_) => ModelId::Beckmann,
            Model::BeckmannAniso(_) => ModelId::BeckmannAniso,
            Model::Ellipsoid(_) => ModelId::Ellipsoid,
        }
    }

    /// The parameters in the order of [`ModelId::param_names`].
    pub fn params(&self) -> Vec<f64> {
        match self {
            Model::Ggx(g) => vec![g.alpha_x],
            Model::GgxAniso(g) => vec![g.alpha_x, g.alpha_y, g.theta_z],
            Model::Beckmann(b) => vec![b.alpha_x],
            Model::BeckmannAniso(b) => vec![b.alpha_x, b.alpha_y, b.theta_z],
            Model::Ellipsoid(e) => e.params().to_vec(),
        }
    }

    /// The ellipsoid matrix A (row-major in the scan frame) for the models that are ellipsoid special
    /// cases; `None` for Beckmann.
    pub fn matrix_a(&self) -> Option<Matrix3<f64>> {
        match self {
            Model::Ggx(g) | Model::GgxAniso(g) => Some(g.to_ellipsoid().a()),
            Model::Ellipsoid(e) => Some(e.a()),
            Model::Beckmann(_) | Model::BeckmannAniso(_) => None,
        }
    }
}

impl Ndf for Model {
    fn d(&self, m: Vector3<f64>) -> f64 {
        match self {
            Model::Ggx(g) | Model::GgxAniso(g) => g.d(m),
            Model::Beckmann(b) | Model::BeckmannAniso(b) => b.d(m),
            Model::Ellipsoid(e) => e.d(m),
        }
    }
}

/// Check that an alpha is usable: finite and positive. Values below [`ALPHA_MIN`] are raised to it.
pub(crate) fn checked_alpha(name: &str, a: f64) -> Result<f64> {
    if !(a.is_finite() && a > 0.0) {
        return Err(Error::invalid(format!("{name} must be finite and positive, got {a}")));
    }
    Ok(a.max(ALPHA_MIN))
}

/// `Rz(theta) m`: the tangent-plane rotation of Walter et al. eq. 3, shared by the axis-aligned models
/// so that `theta_z` means the same thing in every model.
#[inline]
pub(crate) fn rotate_z(theta_z: f64, m: Vector3<f64>) -> Vector3<f64> {
    let (s, c) = theta_z.sin_cos();
    Vector3::new(c * m.x - s * m.y, s * m.x + c * m.y, m.z)
}
