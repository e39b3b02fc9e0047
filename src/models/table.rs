//! The model table: every fact of a model declared once, in its entry, and read everywhere else.
//!
//! An entry ([`ModelSpec`]) names the model as the contract spells it (and its aliases), lists its
//! parameters in order with their [`Role`]s, the lobes the fit's `ln D` evaluates ([`LobeSpec`]: kernel and
//! form), whether it has a matrix A, the fit its start grows from and its rung in the `auto` ladder. From
//! the roles follow the parameters' ranges and checks, the fit's internal maps (`fit::params`), the closed-form
//! and delta-fit starts, the lobe geometry that the roughness algebra, the axes, the synthetic grids and the
//! renderer export read; from the lobes follow the `ln D` kernels of the hot loop (`fit::lnd`) and the
//! renderer lobe a model exports to.
//!
//! Adding a model: its math file in `src/models/`, its entry here, its arms in the [`super::Model`] enum
//! (`models/mod.rs`), and its kernel in `fit/lnd.rs` if it brings a new `ln D` form.

use super::Distribution;

/// What a parameter is. The role fixes its range, its check, its map in the fit and its starts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// The one roughness of an isotropic lobe (both axes).
    Alpha,
    /// The roughness along the lobe's first axis, `(cos theta_z, -sin theta_z)` in the scan frame.
    AlphaX,
    /// The roughness along the lobe's second axis.
    AlphaY,
    /// The ellipsoid's tilt about x (Walter et al. eq. 3).
    ThetaX,
    /// The ellipsoid's tilt about y (Walter et al. eq. 3).
    ThetaY,
    /// The tangent-plane rotation `Rz(theta_z)` (Walter et al. eq. 3): `alpha_x` lies along
    /// `(cos theta_z, -sin theta_z)`, at azimuth `-theta_z`.
    ThetaZ,
    /// The Student-t tail exponent `gamma` (GGX at 2, Beckmann as it grows without bound).
    Gamma,
    /// The first lobe's share of a two-lobe mixture, in `(0, 1)`.
    Weight,
}

impl Role {
    /// Whether the parameter is a roughness.
    pub fn is_alpha(self) -> bool {
        matches!(self, Role::Alpha | Role::AlphaX | Role::AlphaY)
    }
}

/// The `ln D` family of one lobe (the fit's kernel).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kernel {
    /// GGX / Trowbridge-Reitz, and the ellipsoid (Walter et al. eq. 1) of which GGX is the centred case.
    Ggx,
    /// Beckmann (Heitz eq. 82).
    Beckmann,
    /// The Student-t slopes of Ribardiere et al. (`student`): a free tail, GGX at `gamma = 2`.
    Student,
}

impl Kernel {
    /// The renderer distribution that represents this kernel exactly, when one does.
    pub fn renderer(self) -> Option<Distribution> {
        match self {
            Kernel::Ggx => Some(Distribution::Ggx),
            Kernel::Beckmann => Some(Distribution::Beckmann),
            Kernel::Student => None,
        }
    }
}

/// The geometry a lobe's parameters span.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Form {
    /// One roughness, symmetric about `n`.
    Iso,
    /// Two roughnesses and `theta_z`.
    Aniso,
    /// The ellipsoid's five: two roughnesses and `theta_x`, `theta_y`, `theta_z`.
    Full,
}

/// One lobe as the fit evaluates it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LobeSpec {
    /// Its `ln D` family.
    pub kernel: Kernel,
    /// Its geometry.
    pub form: Form,
}

/// Which lobes a parameter belongs to: a bit per lobe (a mixture's shared `theta_z` has both).
pub type Lobes = u8;
/// The first (or only) lobe.
pub const L1: Lobes = 1;
/// The second lobe of a mixture.
pub const L2: Lobes = 2;
/// Both lobes (a shared tangent frame).
pub const BOTH: Lobes = 3;
/// No lobe (a mixture weight).
pub const NONE: Lobes = 0;

/// A lobe's geometry read from a parameter vector by the roles: the alphas, the three angles and the tail.
/// Absent parameters read as the lobe's defaults (`alpha_y = alpha_x`, angles 0, `gamma` none).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Parts {
    /// Roughness along the first axis.
    pub alpha_x: f64,
    /// Roughness along the second axis.
    pub alpha_y: f64,
    /// Tilt about x.
    pub theta_x: f64,
    /// Tilt about y.
    pub theta_y: f64,
    /// Tangent-plane rotation.
    pub theta_z: f64,
    /// Tail exponent, for a Student-t lobe.
    pub gamma: Option<f64>,
}

/// One model's entry.
#[derive(Debug, Clone, Copy)]
pub struct ModelSpec {
    /// The id as the contract spells it.
    pub name: &'static str,
    /// Other spellings accepted on input.
    pub aliases: &'static [&'static str],
    /// One line for help texts.
    pub about: &'static str,
    /// The parameter names, in the order of `params`.
    pub names: &'static [&'static str],
    /// Each parameter's role and lobes, in the same order.
    pub roles: &'static [(Role, Lobes)],
    /// The lobes, narrower (or core) first.
    pub lobes: &'static [LobeSpec],
    /// Whether the model is an ellipsoid special case, with a matrix A (CONTRACT.md).
    pub matrix_a: bool,
    /// The model whose fit starts this one; in `auto` it is the model this one must improve on.
    pub parent: Option<ModelId>,
    /// Whether `auto` considers the model.
    pub in_auto: bool,
}

impl ModelSpec {
    /// Whether the model has two lobes.
    pub fn is_mixture(&self) -> bool {
        self.lobes.len() == 2
    }

    /// Index of the first parameter with role `r` on lobe `lobe` (0 or 1), if any.
    pub fn slot(&self, r: Role, lobe: usize) -> Option<usize> {
        self.roles.iter().position(|&(q, l)| q == r && l & (1 << lobe) != 0)
    }

    /// Index of the first parameter with role `r` on any lobe.
    pub fn slot_any(&self, r: Role) -> Option<usize> {
        self.roles.iter().position(|&(q, _)| q == r)
    }

    /// Indices of the parameters of lobe `lobe`, in order.
    pub fn lobe_slots(&self, lobe: usize) -> impl Iterator<Item = usize> + '_ {
        self.roles.iter().enumerate().filter(move |(_, (_, l))| l & (1 << lobe) != 0).map(|(i, _)| i)
    }

    /// The geometry of lobe `lobe` in parameter vector `p` (module docs of `Parts`).
    pub fn parts(&self, p: &[f64], lobe: usize) -> Parts {
        let get = |r| self.slot(r, lobe).map(|i| p[i]);
        let alpha_x = get(Role::AlphaX).or(get(Role::Alpha)).unwrap_or(f64::NAN);
        Parts {
            alpha_x,
            alpha_y: get(Role::AlphaY).unwrap_or(alpha_x),
            theta_x: get(Role::ThetaX).unwrap_or(0.0),
            theta_y: get(Role::ThetaY).unwrap_or(0.0),
            theta_z: get(Role::ThetaZ).unwrap_or(0.0),
            gamma: get(Role::Gamma),
        }
    }

    /// `p` with lobe `lobe`'s geometry replaced by `g` (an isotropic lobe takes `alpha_x`).
    pub fn with_parts(&self, p: &[f64], lobe: usize, g: &Parts) -> Vec<f64> {
        let mut q = p.to_vec();
        for i in self.lobe_slots(lobe) {
            q[i] = match self.roles[i].0 {
                Role::Alpha | Role::AlphaX => g.alpha_x,
                Role::AlphaY => g.alpha_y,
                Role::ThetaX => g.theta_x,
                Role::ThetaY => g.theta_y,
                Role::ThetaZ => g.theta_z,
                Role::Gamma => g.gamma.unwrap_or(q[i]),
                Role::Weight => q[i],
            };
        }
        q
    }
}

/// Declares [`ModelId`] and [`SPECS`] together, one entry per model, so the two can never disagree.
macro_rules! model_table {
    ($( $(#[$doc:meta])* $variant:ident => $spec:expr, )*) => {
        /// The model ids of the contract (and the models added beside it), in the table's order.
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum ModelId {
            $( $(#[$doc])* $variant, )*
        }

        impl ModelId {
            /// Every model, in the table's order (simplest first, mixtures last).
            pub const EVERY: &'static [ModelId] = &[$(ModelId::$variant),*];
        }

        /// The entries, in the order of [`ModelId::EVERY`].
        pub static SPECS: &[ModelSpec] = &[$($spec),*];
    };
}

use Form::{Aniso, Full, Iso};
use Kernel::{Beckmann, Ggx, Student};
use Role::{Alpha, AlphaX, AlphaY, Gamma, ThetaX, ThetaY, ThetaZ, Weight};

const ANISO: &[(Role, Lobes)] = &[(AlphaX, L1), (AlphaY, L1), (ThetaZ, L1)];
const ANISO_NAMES: &[&str] = &["alpha_x", "alpha_y", "theta_z"];

model_table! {
    /// Isotropic GGX / Trowbridge-Reitz: `alpha`.
    Ggx => ModelSpec {
        name: "ggx", aliases: &["trowbridge-reitz"], about: "isotropic GGX / Trowbridge-Reitz",
        names: &["alpha"], roles: &[(Alpha, L1)], lobes: &[LobeSpec { kernel: Ggx, form: Iso }],
        matrix_a: true, parent: None, in_auto: true,
    },
    /// Isotropic Beckmann: `alpha`.
    Beckmann => ModelSpec {
        name: "beckmann", aliases: &[], about: "isotropic Beckmann",
        names: &["alpha"], roles: &[(Alpha, L1)], lobes: &[LobeSpec { kernel: Beckmann, form: Iso }],
        matrix_a: false, parent: None, in_auto: true,
    },
    /// Isotropic Student-t slopes (`student`): `alpha`, `gamma`.
    Student => ModelSpec {
        name: "student", aliases: &["std"], about: "isotropic Student-t slopes (STD), a free tail: GGX at gamma = 2, Beckmann as gamma grows",
        names: &["alpha", "gamma"], roles: &[(Alpha, L1), (Gamma, L1)], lobes: &[LobeSpec { kernel: Student, form: Iso }],
        matrix_a: false, parent: Some(ModelId::Ggx), in_auto: true,
    },
    /// GTR2aniso rotated by `theta_z`: `alpha_x`, `alpha_y`, `theta_z`.
    GgxAniso => ModelSpec {
        name: "ggx-aniso", aliases: &["gtr2aniso"], about: "anisotropic GGX, GTR2aniso, rotated by theta_z",
        names: ANISO_NAMES, roles: ANISO, lobes: &[LobeSpec { kernel: Ggx, form: Aniso }],
        matrix_a: true, parent: Some(ModelId::Ggx), in_auto: true,
    },
    /// Anisotropic Beckmann rotated by `theta_z`: `alpha_x`, `alpha_y`, `theta_z`.
    BeckmannAniso => ModelSpec {
        name: "beckmann-aniso", aliases: &[], about: "anisotropic Beckmann rotated by theta_z",
        names: ANISO_NAMES, roles: ANISO, lobes: &[LobeSpec { kernel: Beckmann, form: Aniso }],
        matrix_a: false, parent: Some(ModelId::Beckmann), in_auto: true,
    },
    /// Anisotropic Student-t slopes rotated by `theta_z`: `alpha_x`, `alpha_y`, `theta_z`, `gamma`.
    StudentAniso => ModelSpec {
        name: "student-aniso", aliases: &["std-aniso"], about: "anisotropic Student-t slopes rotated by theta_z, a free tail",
        names: &["alpha_x", "alpha_y", "theta_z", "gamma"], roles: &[(AlphaX, L1), (AlphaY, L1), (ThetaZ, L1), (Gamma, L1)],
        lobes: &[LobeSpec { kernel: Student, form: Aniso }],
        matrix_a: false, parent: Some(ModelId::GgxAniso), in_auto: true,
    },
    /// The ellipsoid NDF, A = S R (Walter et al. eq. 2-3): `alpha_x`, `alpha_y`, `theta_x`, `theta_y`, `theta_z`.
    Ellipsoid => ModelSpec {
        name: "ellipsoid", aliases: &[], about: "the ellipsoid NDF of Walter et al., A = S Rx Ry Rz",
        names: &["alpha_x", "alpha_y", "theta_x", "theta_y", "theta_z"],
        roles: &[(AlphaX, L1), (AlphaY, L1), (ThetaX, L1), (ThetaY, L1), (ThetaZ, L1)],
        lobes: &[LobeSpec { kernel: Ggx, form: Full }],
        matrix_a: true, parent: Some(ModelId::GgxAniso), in_auto: true,
    },
    /// Two GTR2aniso lobes sharing `theta_z` (`mixture`): `alpha_x1`, `alpha_y1`, `alpha_x2`,
    /// `alpha_y2`, `theta_z`, `weight`.
    Ggx2 => ModelSpec {
        name: "ggx2", aliases: &[], about: "two GGX lobes sharing one tangent frame",
        names: &["alpha_x1", "alpha_y1", "alpha_x2", "alpha_y2", "theta_z", "weight"],
        roles: &[(AlphaX, L1), (AlphaY, L1), (AlphaX, L2), (AlphaY, L2), (ThetaZ, BOTH), (Weight, NONE)],
        lobes: &[LobeSpec { kernel: Ggx, form: Aniso }, LobeSpec { kernel: Ggx, form: Aniso }],
        matrix_a: false, parent: Some(ModelId::GgxAniso), in_auto: true,
    },
    /// Two anisotropic Beckmann lobes sharing `theta_z`, parameters as `ggx2`.
    Beckmann2 => ModelSpec {
        name: "beckmann2", aliases: &[], about: "two Beckmann lobes sharing one tangent frame",
        names: &["alpha_x1", "alpha_y1", "alpha_x2", "alpha_y2", "theta_z", "weight"],
        roles: &[(AlphaX, L1), (AlphaY, L1), (AlphaX, L2), (AlphaY, L2), (ThetaZ, BOTH), (Weight, NONE)],
        lobes: &[LobeSpec { kernel: Beckmann, form: Aniso }, LobeSpec { kernel: Beckmann, form: Aniso }],
        matrix_a: false, parent: Some(ModelId::BeckmannAniso), in_auto: true,
    },
    /// An ellipsoid core and an isotropic GGX tail (`mixture`): `alpha_x1`, `alpha_y1`, `theta_x`,
    /// `theta_y`, `theta_z`, `alpha2`, `weight`.
    EllipsoidGgx => ModelSpec {
        name: "ellipsoid+ggx", aliases: &[], about: "an ellipsoid core and an isotropic GGX tail",
        names: &["alpha_x1", "alpha_y1", "theta_x", "theta_y", "theta_z", "alpha2", "weight"],
        roles: &[(AlphaX, L1), (AlphaY, L1), (ThetaX, L1), (ThetaY, L1), (ThetaZ, L1), (Alpha, L2), (Weight, NONE)],
        lobes: &[LobeSpec { kernel: Ggx, form: Full }, LobeSpec { kernel: Ggx, form: Iso }],
        matrix_a: false, parent: Some(ModelId::Ellipsoid), in_auto: true,
    },
}

impl ModelId {
    /// The model's entry.
    #[inline]
    pub fn spec(self) -> &'static ModelSpec {
        &SPECS[self as usize]
    }

    /// The single-lobe models, simplest first.
    pub fn singles() -> impl Iterator<Item = ModelId> {
        ModelId::EVERY.iter().copied().filter(|id| !id.is_mixture())
    }

    /// The two-lobe mixtures, simplest first.
    pub fn mixtures() -> impl Iterator<Item = ModelId> {
        ModelId::EVERY.iter().copied().filter(|id| id.is_mixture())
    }

    /// The contract names of every model, `, `-separated with a final `or` (for error messages).
    pub fn name_list() -> String {
        let names: Vec<&str> = ModelId::EVERY.iter().map(|id| id.as_str()).collect();
        match names.split_last() {
            Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
            _ => names.join(""),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every entry is consistent: one role per name, lobes in range, a parent earlier in the table.
    #[test]
    fn entries_are_consistent() {
        for (i, id) in ModelId::EVERY.iter().enumerate() {
            let s = id.spec();
            assert_eq!(*id as usize, i);
            assert_eq!(s.names.len(), s.roles.len(), "{}", s.name);
            assert!(matches!(s.lobes.len(), 1 | 2), "{}", s.name);
            for (k, &(role, lobes)) in s.roles.iter().enumerate() {
                assert!(lobes < (1 << s.lobes.len()), "{}: {}", s.name, s.names[k]);
                assert_eq!(lobes == NONE, role == Role::Weight, "{}: {}", s.name, s.names[k]);
            }
            if let Some(p) = s.parent {
                assert!((p as usize) < i, "{}: parent after it", s.name);
            }
            for l in 0..s.lobes.len() {
                let n = s.lobe_slots(l).count();
                let want = match s.lobes[l].form {
                    Form::Iso => 1,
                    Form::Aniso => 3,
                    Form::Full => 5,
                };
                let tail = s.slot(Role::Gamma, l).is_some() as usize;
                assert_eq!(n, want + tail, "{}: lobe {l}", s.name);
            }
        }
        let mut all: Vec<&str> = SPECS.iter().flat_map(|s| std::iter::once(s.name).chain(s.aliases.iter().copied())).collect();
        let n = all.len();
        all.sort();
        all.dedup();
        assert_eq!(all.len(), n, "a name or alias is used twice");
    }
}
