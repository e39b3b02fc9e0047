//! Filtering a two-lobe mixture ([`crate::models::mixture`]): a footprint's slope kernel convolves the
//! slope distribution, and convolution is linear, so the filtered mixture is the mixture of the filtered
//! lobes with the same weight (each lobe by Tokuyoshi eq. 3, [`super::roughness::add_kernel_matrix`]).
//!
//! `ggx2` and `beckmann2` share one tangent frame; a kernel whose axes are not the frame's turns the two
//! lobes' axes by different angles, which the shared frame cannot hold: that is refused, naming it.

use nalgebra::Matrix2;

use super::roughness::add_kernel_matrix;
use crate::error::{Error, Result};
use crate::models::{Lobe, Mixture, MixtureKind, Model};

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

/// The mixture whose lobes' roughness matrices are each `A2 + K` (see the module docs).
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
