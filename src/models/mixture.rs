//! Two-lobe mixtures: a sharp core and a wide tail, `D = w D1 + (1 - w) D2`.
//!
//! Each lobe is normalized on its own (Heitz eq. 9), so with `w` in `(0, 1)` the mixture is normalized
//! too. Masking is exact Smith for the mixture: the Smith `Lambda` is a linear functional of the slope
//! distribution (Heitz eq. 43, 72, 86: `Lambda(u) = (1/mu) integral (u.m)- ... P22`) and the slope
//! distribution of a mixture is the mixture of the slope distributions (`P22 = D cos^4`), so
//! `Lambda = w Lambda1 + (1 - w) Lambda2` and `G1 = X+(u.m) / (1 + Lambda)`. For an ellipsoid lobe its
//! `Lambda` is the one implied by Walter et al. eq. 32 (projected areas are linear in D as well).
//!
//! The three ids and their parameters (`weight` is the first lobe's share):
//! - `ggx2`: two GTR2aniso lobes sharing one tangent frame (one `theta_z`; a renderer's blend of two
//!   BSDFs has one tangent per surface): `alpha_x1, alpha_y1, alpha_x2, alpha_y2, theta_z, weight`; both
//!   lobes' `alpha_x` axes lie along `(cos theta_z, -sin theta_z)` in the scan frame (azimuth `-theta_z`);
//! - `beckmann2`: the same with anisotropic Beckmann lobes;
//! - `ellipsoid+ggx`: a skewed ellipsoid core (Walter et al. eq. 1-3) with an isotropic GGX tail,
//!   symmetric about n: `alpha_x1, alpha_y1, theta_x, theta_y, theta_z, alpha2, weight`.
//!
//! Canonical form: for `ggx2`/`beckmann2` the narrower lobe (smaller `alpha_x alpha_y`, the area of its
//! slope ellipse) comes first (swapping the lobes turns `w` into `1 - w`); then the first lobe has
//! `alpha_x1 >= alpha_y1` (both lobes' alphas swap together, `theta_z + pi/2`), or, when its alphas tie,
//! the second lobe does; `theta_z` in `(-pi/2, pi/2]`, 0 when both lobes are isotropic. For
//! `ellipsoid+ggx` the core is first by construction and is canonicalized as an ellipsoid
//! ([`Ellipsoid::canonical`]); the isotropic tail has no frame to follow.

use nalgebra::{Matrix2, Vector3};

use super::roughness::add_kernel_matrix;
use super::{canonical, smith_g1, Beckmann, Ellipsoid, Ggx, Masking, Model, Ndf};
use crate::error::{Error, Result};

/// One lobe of a mixture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Lobe {
    /// GGX (GTR2aniso; isotropic when the alphas tie).
    Ggx(Ggx),
    /// Beckmann.
    Beckmann(Beckmann),
    /// The ellipsoid NDF.
    Ellipsoid(Ellipsoid),
}

impl Lobe {
    /// The lobe's `D(m)`.
    #[inline]
    pub fn d(&self, m: Vector3<f64>) -> f64 {
        match self {
            Lobe::Ggx(g) => g.d(m),
            Lobe::Beckmann(b) => b.d(m),
            Lobe::Ellipsoid(e) => e.d(m),
        }
    }

    /// The lobe's Smith `Lambda(u)` (Walter et al. eq. 32's for the ellipsoid).
    pub fn lambda(&self, u: Vector3<f64>) -> f64 {
        match self {
            Lobe::Ggx(g) => g.lambda(u),
            Lobe::Beckmann(b) => b.lambda(u),
            Lobe::Ellipsoid(e) => e.lambda(u),
        }
    }

    /// The area of the lobe's slope ellipse in units of `pi`: `alpha_x alpha_y` (the width that orders
    /// the lobes).
    pub fn width(&self) -> f64 {
        match self {
            Lobe::Ggx(g) => g.alpha_x * g.alpha_y,
            Lobe::Beckmann(b) => b.alpha_x * b.alpha_y,
            Lobe::Ellipsoid(e) => e.params()[0] * e.params()[1],
        }
    }
}

/// The mixture kinds (model ids `ggx2`, `beckmann2`, `ellipsoid+ggx`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MixtureKind {
    /// Two GTR2aniso lobes, one frame.
    Ggx2,
    /// Two anisotropic Beckmann lobes, one frame.
    Beckmann2,
    /// An ellipsoid core and an isotropic GGX tail.
    EllipsoidGgx,
}

/// `w D1 + (1 - w) D2` (module docs).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mixture {
    /// Which mixture.
    pub kind: MixtureKind,
    /// The first lobe (the narrower one, or the ellipsoid core).
    pub lobe1: Lobe,
    /// The second lobe (the tail).
    pub lobe2: Lobe,
    /// The first lobe's weight, in `(0, 1)`.
    pub weight: f64,
}

fn checked_weight(w: f64) -> Result<f64> {
    if !(w > 0.0 && w < 1.0) {
        return Err(Error::invalid(format!("weight must lie in (0, 1), got {w}")));
    }
    Ok(w)
}

impl Mixture {
    /// The mixture of `kind` from its parameters in the order of the module docs.
    pub fn from_params(kind: MixtureKind, p: &[f64]) -> Result<Mixture> {
        let n = match kind {
            MixtureKind::Ggx2 | MixtureKind::Beckmann2 => 6,
            MixtureKind::EllipsoidGgx => 7,
        };
        if p.len() != n {
            return Err(Error::invalid(format!("a mixture of this kind takes {n} parameters, got {}", p.len())));
        }
        Ok(match kind {
            MixtureKind::Ggx2 => Mixture {
                kind,
                lobe1: Lobe::Ggx(Ggx::new(p[0], p[1], p[4])?),
                lobe2: Lobe::Ggx(Ggx::new(p[2], p[3], p[4])?),
                weight: checked_weight(p[5])?,
            },
            MixtureKind::Beckmann2 => Mixture {
                kind,
                lobe1: Lobe::Beckmann(Beckmann::new(p[0], p[1], p[4])?),
                lobe2: Lobe::Beckmann(Beckmann::new(p[2], p[3], p[4])?),
                weight: checked_weight(p[5])?,
            },
            MixtureKind::EllipsoidGgx => Mixture {
                kind,
                lobe1: Lobe::Ellipsoid(Ellipsoid::from_params(p[0], p[1], p[2], p[3], p[4])?),
                lobe2: Lobe::Ggx(Ggx::new(p[5], p[5], 0.0)?),
                weight: checked_weight(p[6])?,
            },
        })
    }

    /// The parameters in the order of the module docs.
    pub fn params(&self) -> Vec<f64> {
        match (self.lobe1, self.lobe2) {
            (Lobe::Ggx(a), Lobe::Ggx(b)) => vec![a.alpha_x, a.alpha_y, b.alpha_x, b.alpha_y, a.theta_z, self.weight],
            (Lobe::Beckmann(a), Lobe::Beckmann(b)) => vec![a.alpha_x, a.alpha_y, b.alpha_x, b.alpha_y, a.theta_z, self.weight],
            (Lobe::Ellipsoid(e), Lobe::Ggx(t)) => {
                let c = e.params();
                vec![c[0], c[1], c[2], c[3], c[4], t.alpha_x, self.weight]
            }
            // Not constructible through from_params; the lobes' own parameters in order.
            _ => vec![f64::NAN],
        }
    }

    /// The same distribution in canonical parameters (module docs).
    pub fn canonical(&self) -> Mixture {
        if self.kind == MixtureKind::EllipsoidGgx {
            let lobe1 = match self.lobe1 {
                Lobe::Ellipsoid(e) => Lobe::Ellipsoid(e.canonical()),
                l => l,
            };
            return Mixture { lobe1, ..*self };
        }
        let p = self.params();
        let (mut ax1, mut ay1, mut ax2, mut ay2, mut tz, mut w) = (p[0], p[1], p[2], p[3], p[4], p[5]);
        if ax2 * ay2 < ax1 * ay1 {
            (ax1, ay1, ax2, ay2, w) = (ax2, ay2, ax1, ay1, 1.0 - w);
        }
        let tie = |a: f64, b: f64| (a - b).abs() <= canonical::TIE * a.max(b);
        let swap = if !tie(ax1, ay1) { ax1 < ay1 } else { !tie(ax2, ay2) && ax2 < ay2 };
        if swap {
            (ax1, ay1, ax2, ay2, tz) = (ay1, ax1, ay2, ax2, tz + 0.5 * std::f64::consts::PI);
        }
        tz = if tie(ax1, ay1) && tie(ax2, ay2) { 0.0 } else { canonical::fold_half_turn(tz) };
        let q = [ax1, ay1, ax2, ay2, tz, w];
        // Every value came from a valid mixture: the alphas and the weight stay in their domains.
        Mixture::from_params(self.kind, &q).unwrap_or(*self)
    }
}

impl Ndf for Mixture {
    #[inline]
    fn d(&self, m: Vector3<f64>) -> f64 {
        self.weight * self.lobe1.d(m) + (1.0 - self.weight) * self.lobe2.d(m)
    }
}

impl Masking for Mixture {
    fn lambda(&self, u: Vector3<f64>) -> f64 {
        let l = self.weight * self.lobe1.lambda(u) + (1.0 - self.weight) * self.lobe2.lambda(u);
        // Both saturate at f64::MAX on the horizon; keep the sum finite.
        l.min(f64::MAX)
    }
    fn g1(&self, u: Vector3<f64>, m: Vector3<f64>) -> f64 {
        smith_g1(self.lambda(u), u, m)
    }
}

// Filtering a mixture by a footprint's slope kernel: the kernel convolves the slope distribution, and
// convolution is linear, so the filtered mixture is the mixture of the filtered lobes with the same weight
// (each lobe by Tokuyoshi eq. 3, [`add_kernel_matrix`]). `ggx2` and `beckmann2` share one tangent frame;
// a kernel whose axes are not the frame's turns the two lobes' axes by different angles, which the
// shared frame cannot hold: that is refused, naming it.

/// Largest difference (radians) between the filtered lobes' `theta_z` that still counts as one frame.
const FRAME_TOL: f64 = 1e-6;

fn lobe_model(l: &Lobe, aniso: bool) -> Model {
    match *l {
        Lobe::Ggx(g) if aniso => Model::GgxAniso(g),
        Lobe::Ggx(g) => Model::Ggx(g),
        Lobe::Beckmann(b) => Model::BeckmannAniso(b),
        Lobe::Ellipsoid(e) => Model::Ellipsoid(e),
    }
}

/// The mixture whose lobes' roughness matrices are each `A2 + K` (see above).
pub fn add_kernel_matrix_mixture(x: &Mixture, k: &Matrix2<f64>) -> Result<Model> {
    let aniso2 = x.kind != MixtureKind::EllipsoidGgx;
    let m1 = add_kernel_matrix(&lobe_model(&x.lobe1, true), k)?;
    let m2 = add_kernel_matrix(&lobe_model(&x.lobe2, aniso2), k)?;
    let p1 = m1.params();
    let p2 = m2.params();
    let p = match x.kind {
        MixtureKind::Ggx2 | MixtureKind::Beckmann2 => {
            // Each filtered lobe in its own canonical labeling; bring the second into the first's frame.
            let (ax1, ay1, tz1) = (p1[0], p1[1], p1[2]);
            let (mut ax2, mut ay2, tz2) = (p2[0], p2[1], p2[2]);
            let tie2 = (ax2 - ay2).abs() <= 1e-9 * ax2.max(ay2);
            let d = crate::models::canonical::fold_half_turn(tz2 - tz1);
            if !tie2 {
                if (d.abs() - 0.5 * std::f64::consts::PI).abs() <= FRAME_TOL {
                    (ax2, ay2) = (ay2, ax2);
                } else if d.abs() > FRAME_TOL {
                    return Err(Error::invalid(format!(
                        "{}: the footprint's kernel turns the two lobes' axes apart ({d:.3e} rad), which one shared tangent frame cannot hold",
                        Model::Mixture(*x).id()
                    )));
                }
            }
            vec![ax1, ay1, ax2, ay2, tz1, x.weight]
        }
        MixtureKind::EllipsoidGgx => vec![p1[0], p1[1], p1[2], p1[3], p1[4], p2[0], x.weight],
    };
    Model::from_params(Model::Mixture(*x).id(), &p)
}
