//! Analytic normal distribution functions (NDFs) and their masking functions.
//!
//! Papers (equation numbers cited throughout):
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
//!
//! Files, one job each: `ellipsoid` (D, G1, projected areas, pdf), `sampling` (Walter sec. 4.1),
//! `canonical` (one labeling per distribution), `ggx` and `beckmann` (Heitz's slope-space forms and
//! Smith Lambda), `roughness_matrix` (Tokuyoshi's 2x2 form), `fresnel`, `brdf` (Walter eq. 4 with
//! separable or height-correlated G2), `sel` (Tokuyoshi-Harada lobe), `spec` (JSON <-> [`Model`]).
//!
//! Conventions shared by every model: `D = 0` below the horizon; `G1` in `[0, 1]`; `Lambda >= 0`, saturated at
//! `f64::MAX` exactly on the horizon (its true value is `+inf`), so no public function returns NaN or an
//! infinity for finite inputs; alphas in `[ALPHA_MIN, ALPHA_MAX]` (below raised, above refused).

// The `!(x > 0.0)` guards are deliberate: they also catch NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub(crate) mod axes;
pub(crate) mod beckmann;
pub(crate) mod brdf;
pub(crate) mod canonical;
pub(crate) mod ellipsoid;
pub(crate) mod fresnel;
pub(crate) mod ggx;
pub(crate) mod mixture;
pub(crate) mod roughness;
pub(crate) mod roughness_matrix;
pub(crate) mod sampling;
pub(crate) mod sel;
pub(crate) mod spec;
pub(crate) mod student;
pub(crate) mod table;

pub use axes::LobeAxes;
pub use beckmann::Beckmann;
pub use brdf::{MaskingShadowing, MicrofacetBrdf};
pub use ellipsoid::rotation_xyz;
pub use ellipsoid::Ellipsoid;
pub use fresnel::checked_eta;
pub use fresnel::fresnel_conductor;
pub use ggx::Ggx;
pub use mixture::{Lobe, Mixture, MixtureKind};
pub use roughness_matrix::{disk_to_slope_jacobian, GgxMatrix};
pub use sampling::{concentric_disk, frisvad_basis};
pub use sel::SquaredEllipsoidalLobe;
pub use student::Student;
pub use table::{Form, Kernel, LobeSpec, Parts};
pub use table::{ModelId, ModelSpec, Role};

use nalgebra::{Matrix3, Vector3};

use crate::error::{Error, Result};

/// Smallest roughness any model accepts. Below it `alpha^2` nears the f64 spacing of 1 in the
/// denominators `mz^2 + (slope/alpha)^2`, and a renderer cannot tell the lobe from a mirror anyway
/// (pbrt-v4 uses the same floor for the same reason).
pub const ALPHA_MIN: f64 = 1e-4;

/// Largest roughness any model accepts. Above it the lobe is flat to better than 1e-12 over the
/// hemisphere (nothing left to fit), and `alpha^4` still sits far inside the f64 range.
pub const ALPHA_MAX: f64 = 1e6;

/// The microfacet distribution of a renderer lobe: the analytic families renderers implement.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Distribution {
    /// GGX / Trowbridge-Reitz.
    Ggx,
    /// Beckmann.
    Beckmann,
}

impl Distribution {
    /// `ggx` or `beckmann`, as Mitsuba spells it.
    pub fn as_str(self) -> &'static str {
        match self {
            Distribution::Ggx => "ggx",
            Distribution::Beckmann => "beckmann",
        }
    }
}

impl ModelId {
    /// The mixture kind of a mixture id.
    pub fn mixture_kind(self) -> Option<MixtureKind> {
        match self {
            ModelId::Ggx2 => Some(MixtureKind::Ggx2),
            ModelId::Beckmann2 => Some(MixtureKind::Beckmann2),
            ModelId::EllipsoidGgx => Some(MixtureKind::EllipsoidGgx),
            ModelId::Ggx
            | ModelId::Beckmann
            | ModelId::Student
            | ModelId::GgxAniso
            | ModelId::BeckmannAniso
            | ModelId::StudentAniso
            | ModelId::Ellipsoid => None,
        }
    }

    /// Whether the id is a two-lobe mixture.
    pub fn is_mixture(self) -> bool {
        self.spec().is_mixture()
    }

    /// The id as the contract spells it.
    pub fn as_str(self) -> &'static str {
        self.spec().name
    }

    /// The parameter names, in the order `Model::params` returns them.
    pub fn param_names(self) -> &'static [&'static str] {
        self.spec().names
    }

    /// Number of free parameters.
    pub fn n_params(self) -> usize {
        self.spec().names.len()
    }

    /// Whether the model is a special case of the ellipsoid (and so has a matrix A).
    pub fn has_matrix_a(self) -> bool {
        self.spec().matrix_a
    }

    /// The model whose fit starts this one, and which it must improve on in `auto`.
    pub fn parent(self) -> Option<ModelId> {
        self.spec().parent
    }
}

impl serde::Serialize for ModelId {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

impl<'de> serde::Deserialize<'de> for ModelId {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        let s = <std::borrow::Cow<'de, str>>::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

impl std::fmt::Display for ModelId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// What `--model` asks for: one model, or `auto` (fit the nested models and choose by the criterion).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ModelChoice {
    /// Choose among the candidates ([`crate::fit::fit_auto`]).
    Auto,
    /// Fit this model.
    Model(ModelId),
}

impl std::str::FromStr for ModelChoice {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        if s == "auto" {
            return Ok(ModelChoice::Auto);
        }
        s.parse::<ModelId>()
            .map(ModelChoice::Model)
            .map_err(|_| Error::invalid(format!("unknown model '{s}' (expected auto, {})", ModelId::name_list())))
    }
}

impl std::str::FromStr for ModelId {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        ModelId::EVERY
            .iter()
            .copied()
            .find(|id| id.as_str() == s || id.spec().aliases.contains(&s))
            .ok_or_else(|| Error::invalid(format!("unknown model '{s}' (expected {})", ModelId::name_list())))
    }
}

/// The common interface of the analytic NDFs.
pub trait Ndf {
    /// The NDF `D(m)` (1/sr), zero below the horizon; normalized so that the integral of
    /// `D(m) (m.n)` over the hemisphere is 1 (Heitz eq. 9).
    fn d(&self, m: Vector3<f64>) -> f64;
}

/// Masking of the models with a Smith-type masking function (Heitz eq. 43): `G1 = X+(u.m) / (1 + Lambda(u))`.
pub trait Masking {
    /// The Smith `Lambda(u)` (Heitz eq. 43, 69-86), `>= 0`, finite. Exactly on the horizon the true value is
    /// `+inf`; it saturates at `f64::MAX` there so callers never see an infinity. Below the horizon GGX and
    /// Beckmann give `Lambda` of the mirrored direction `(ux, uy, -uz)` (Tokuyoshi eq. 16 uses `|o_z|`); the
    /// ellipsoid follows Walter et al. eq. 32 with `|u.n|` as printed.
    fn lambda(&self, u: Vector3<f64>) -> f64;

    /// The masking function `G1(u, m)` in `[0, 1]`.
    fn g1(&self, u: Vector3<f64>, m: Vector3<f64>) -> f64;
}

/// One fitted or hand-written model: the id and its parameters, as one value.
// A mixture holds two lobes (each up to an ellipsoid with its matrices), so it is the largest variant; a
// box would take `Copy` from every model for no measurable gain (models are copied a few times per fit).
#[allow(clippy::large_enum_variant)]
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
    /// `student`.
    Student(Student),
    /// `student-aniso`.
    StudentAniso(Student),
    /// `ellipsoid`.
    Ellipsoid(Ellipsoid),
    /// `ggx2`, `beckmann2`, `ellipsoid+ggx`.
    Mixture(Mixture),
}

impl Model {
    /// Build a model from its id and parameters in the order of [`ModelId::param_names`].
    pub fn from_params(id: ModelId, p: &[f64]) -> Result<Model> {
        if p.len() != id.n_params() {
            return Err(Error::invalid(format!("model {id} takes {} parameters, got {}", id.n_params(), p.len())));
        }
        if let Some((name, bad)) = id.param_names().iter().zip(p).find(|(_, v)| !v.is_finite()) {
            return Err(Error::invalid(format!("model {id}: {name} = {bad} is not finite")));
        }
        // Every roughness is checked under the name the JSON gives it (the lobe types name their own axes).
        let spec = id.spec();
        for ((name, &(role, _)), &v) in spec.names.iter().zip(spec.roles).zip(p) {
            if role.is_alpha() {
                checked_alpha(name, v)?;
            }
        }
        let g = spec.parts(p, 0);
        Ok(match id {
            ModelId::Ggx => Model::Ggx(Ggx::new(g.alpha_x, g.alpha_x, 0.0)?),
            ModelId::GgxAniso => Model::GgxAniso(Ggx::new(g.alpha_x, g.alpha_y, g.theta_z)?),
            ModelId::Beckmann => Model::Beckmann(Beckmann::new(g.alpha_x, g.alpha_x, 0.0)?),
            ModelId::BeckmannAniso => Model::BeckmannAniso(Beckmann::new(g.alpha_x, g.alpha_y, g.theta_z)?),
            ModelId::Student => Model::Student(Student::new(g.alpha_x, g.alpha_x, 0.0, g.gamma.unwrap_or(f64::NAN))?),
            ModelId::StudentAniso => Model::StudentAniso(Student::new(g.alpha_x, g.alpha_y, g.theta_z, g.gamma.unwrap_or(f64::NAN))?),
            ModelId::Ellipsoid => Model::Ellipsoid(Ellipsoid::from_params(g.alpha_x, g.alpha_y, g.theta_x, g.theta_y, g.theta_z)?),
            ModelId::Ggx2 => Model::Mixture(Mixture::from_params(MixtureKind::Ggx2, p)?),
            ModelId::Beckmann2 => Model::Mixture(Mixture::from_params(MixtureKind::Beckmann2, p)?),
            ModelId::EllipsoidGgx => Model::Mixture(Mixture::from_params(MixtureKind::EllipsoidGgx, p)?),
        })
    }

    /// The model's id.
    pub fn id(&self) -> ModelId {
        match self {
            Model::Ggx(_) => ModelId::Ggx,
            Model::GgxAniso(_) => ModelId::GgxAniso,
            Model::Beckmann(_) => ModelId::Beckmann,
            Model::BeckmannAniso(_) => ModelId::BeckmannAniso,
            Model::Student(_) => ModelId::Student,
            Model::StudentAniso(_) => ModelId::StudentAniso,
            Model::Ellipsoid(_) => ModelId::Ellipsoid,
            Model::Mixture(x) => match x.kind {
                MixtureKind::Ggx2 => ModelId::Ggx2,
                MixtureKind::Beckmann2 => ModelId::Beckmann2,
                MixtureKind::EllipsoidGgx => ModelId::EllipsoidGgx,
            },
        }
    }

    /// The parameters in the order of [`ModelId::param_names`].
    pub fn params(&self) -> Vec<f64> {
        match self {
            Model::Ggx(g) => vec![g.alpha_x],
            Model::GgxAniso(g) => vec![g.alpha_x, g.alpha_y, g.theta_z],
            Model::Beckmann(b) => vec![b.alpha_x],
            Model::BeckmannAniso(b) => vec![b.alpha_x, b.alpha_y, b.theta_z],
            Model::Student(t) => vec![t.alpha_x, t.gamma],
            Model::StudentAniso(t) => vec![t.alpha_x, t.alpha_y, t.theta_z, t.gamma],
            Model::Ellipsoid(e) => e.params().to_vec(),
            Model::Mixture(x) => x.params(),
        }
    }

    /// The ellipsoid matrix A (row-major in the scan frame) for the models that are ellipsoid special
    /// cases; `None` for Beckmann.
    pub fn matrix_a(&self) -> Option<Matrix3<f64>> {
        match self {
            Model::Ggx(g) | Model::GgxAniso(g) => Some(g.to_ellipsoid().a()),
            Model::Ellipsoid(e) => Some(e.a()),
            Model::Beckmann(_) | Model::BeckmannAniso(_) | Model::Student(_) | Model::StudentAniso(_) | Model::Mixture(_) => None,
        }
    }
}

impl Model {
    /// `G1(u, m)`: Walter et al. eq. 6 for the ellipsoid, the Smith form `X+(u.m) / (1 + Lambda(u))` of
    /// Heitz eq. 43 for GGX and Beckmann. Always in `[0, 1]`. For a `ggx`/`ggx-aniso` model both forms agree.
    pub fn g1(&self, u: Vector3<f64>, m: Vector3<f64>) -> f64 {
        match self {
            Model::Ggx(g) | Model::GgxAniso(g) => g.g1(u, m),
            Model::Beckmann(b) | Model::BeckmannAniso(b) => b.g1(u, m),
            Model::Student(t) | Model::StudentAniso(t) => t.g1(u, m),
            Model::Ellipsoid(e) => e.g1(u, m),
            Model::Mixture(x) => x.g1(u, m),
        }
    }

    /// Whether [`Model::g1`] is the Smith form `X+(u.m) / (1 + Lambda(u))`, so that `Lambda(u)` can be
    /// taken once for many `m`: not the ellipsoid's (Walter et al. eq. 6) nor a mixture's.
    pub fn smith_masking(&self) -> bool {
        match self {
            Model::Ggx(_)
            | Model::GgxAniso(_)
            | Model::Beckmann(_)
            | Model::BeckmannAniso(_)
            | Model::Student(_)
            | Model::StudentAniso(_) => true,
            Model::Ellipsoid(_) | Model::Mixture(_) => false,
        }
    }

    /// The Smith `Lambda(u)` (Heitz eq. 72/86 for GGX, 69/83 for Beckmann). For the ellipsoid, whose masking
    /// has no closed-form Smith integral, it is the `Lambda` implied by Walter et al. eq. 32,
    /// `1/G1 - 1 = max(0, A_l(u,n) / (A_e(n) |u.n|) - 1)`, exact Smith when `theta_x = theta_y = 0`.
    /// Saturates at `f64::MAX` on the horizon (see [`Masking::lambda`]).
    pub fn lambda(&self, u: Vector3<f64>) -> f64 {
        match self {
            Model::Ggx(g) | Model::GgxAniso(g) => g.lambda(u),
            Model::Beckmann(b) | Model::BeckmannAniso(b) => b.lambda(u),
            Model::Student(t) | Model::StudentAniso(t) => t.lambda(u),
            Model::Ellipsoid(e) => e.lambda(u),
            Model::Mixture(x) => x.lambda(u),
        }
    }

    /// The same distribution in canonical parameters (see `canonical`): `ggx` unchanged; `ggx-aniso` and
    /// `beckmann-aniso` with `alpha_x >= alpha_y` and `theta_z` in `(-pi/2, pi/2]` (`theta_z = 0` when the
    /// alphas tie); the ellipsoid by [`Ellipsoid::canonical`]. The id is kept.
    pub fn canonical(&self) -> Model {
        match *self {
            Model::Ggx(g) => Model::Ggx(g),
            Model::GgxAniso(g) => {
                let (ax, ay, tz) = canonical::canonical_aniso(g.alpha_x, g.alpha_y, g.theta_z);
                Model::GgxAniso(Ggx { alpha_x: ax, alpha_y: ay, theta_z: tz })
            }
            Model::Beckmann(b) => Model::Beckmann(b),
            Model::BeckmannAniso(b) => {
                let (ax, ay, tz) = canonical::canonical_aniso(b.alpha_x, b.alpha_y, b.theta_z);
                Model::BeckmannAniso(Beckmann { alpha_x: ax, alpha_y: ay, theta_z: tz })
            }
            Model::Student(t) => Model::Student(t),
            Model::StudentAniso(t) => Model::StudentAniso(t.canonical()),
            Model::Ellipsoid(e) => Model::Ellipsoid(e.canonical()),
            Model::Mixture(x) => Model::Mixture(x.canonical()),
        }
    }

    /// A visible normal for direction `u`, sampled exactly by Walter et al. sec. 4.1 (eq. 34-46) for the
    /// ellipsoid special cases; `None` for Beckmann (no exact sampler here) and for an empty lune (`u = -n`).
    /// With `u = n` the density is `D(m) (m.n)`.
    pub fn sample_visible_normal(&self, u: Vector3<f64>, xi: [f64; 2]) -> Option<Vector3<f64>> {
        self.ellipsoid()?.sample_visible_normal(u, xi)
    }

    /// The density of [`Model::sample_visible_normal`] (Walter et al. eq. 33); `None` for Beckmann.
    pub fn pdf_visible_normal(&self, u: Vector3<f64>, m: Vector3<f64>) -> Option<f64> {
        Some(self.ellipsoid()?.pdf_visible_normal(u, m))
    }

    /// The ellipsoid form of the models that are ellipsoid special cases (`None` for Beckmann).
    pub fn ellipsoid(&self) -> Option<Ellipsoid> {
        match self {
            Model::Ggx(g) | Model::GgxAniso(g) => Some(g.to_ellipsoid()),
            Model::Ellipsoid(e) => Some(*e),
            Model::Beckmann(_) | Model::BeckmannAniso(_) | Model::Student(_) | Model::StudentAniso(_) | Model::Mixture(_) => None,
        }
    }
}

impl Masking for Model {
    fn lambda(&self, u: Vector3<f64>) -> f64 {
        Model::lambda(self, u)
    }
    fn g1(&self, u: Vector3<f64>, m: Vector3<f64>) -> f64 {
        Model::g1(self, u, m)
    }
}

impl Ndf for Model {
    fn d(&self, m: Vector3<f64>) -> f64 {
        match self {
            Model::Ggx(g) | Model::GgxAniso(g) => g.d(m),
            Model::Beckmann(b) | Model::BeckmannAniso(b) => b.d(m),
            Model::Student(t) | Model::StudentAniso(t) => t.d(m),
            Model::Ellipsoid(e) => e.d(m),
            Model::Mixture(x) => x.d(m),
        }
    }
}

/// Check that an alpha is usable: finite, positive and at most [`ALPHA_MAX`]. Values below [`ALPHA_MIN`]
/// are raised to it.
pub(crate) fn checked_alpha(name: &str, a: f64) -> Result<f64> {
    if !(a.is_finite() && a > 0.0) {
        return Err(Error::invalid(format!("{name} must be finite and positive, got {a}")));
    }
    if a > ALPHA_MAX {
        return Err(Error::invalid(format!("{name} = {a} exceeds the largest supported roughness {ALPHA_MAX}")));
    }
    Ok(a.max(ALPHA_MIN))
}

/// Check that an angle parameter is finite.
pub(crate) fn checked_angle(name: &str, t: f64) -> Result<f64> {
    if !t.is_finite() {
        return Err(Error::invalid(format!("{name} must be finite, got {t}")));
    }
    Ok(t)
}

/// `1 / (1 + Lambda)` with the horizon guard: exactly on the horizon `Lambda` is infinite and G1 is 0.
#[inline]
pub(crate) fn smith_g1(lambda: f64, u: Vector3<f64>, m: Vector3<f64>) -> f64 {
    // u on the horizon (or not finite): Lambda = +inf in exact arithmetic, so no facet is visible.
    if u.z == 0.0 || !(u.dot(&m) > 0.0) {
        return 0.0;
    }
    1.0 / (1.0 + lambda)
}

/// `Rz(theta) m`: the tangent-plane rotation of Walter et al. eq. 3, shared by the axis-aligned models
/// so that `theta_z` means the same thing in every model.
#[inline]
pub(crate) fn rotate_z(theta_z: f64, m: Vector3<f64>) -> Vector3<f64> {
    // No turn (every isotropic lobe): `m` itself, what `c = 1, s = 0` give up to the sign of a zero.
    if theta_z == 0.0 {
        return m;
    }
    let (s, c) = theta_z.sin_cos();
    Vector3::new(c * m.x - s * m.y, s * m.x + c * m.y, m.z)
}
