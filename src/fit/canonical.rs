//! The canonical form of fitted parameters, so every result ndfit prints names one distribution one way.
//!
//! D of the ellipsoid depends on A only through `A^T A` up to scale (Walter et al. eq. 1:
//! `|A| ||A n|| ||A^-T m||^4` is invariant under `A -> Q A` with Q orthogonal and under `A -> k A`), so
//! several labelings of the axes describe one distribution. The convention here:
//! - the eigen-axis of `A^T A` nearest n is the third axis (its eigenvalue is scaled to 1), which makes
//!   `|theta_x|, |theta_y|` smallest;
//! - `alpha_x >= alpha_y` (ties keep the first axis), and `theta_z` is folded into `(-pi/2, pi/2]`;
//! - the anisotropic GGX and Beckmann use the same rule (`theta_z` has period pi).

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::{Matrix3, SymmetricEigen};

use crate::models::ellipsoid::rotation_xyz;
use crate::models::ModelId;

/// Fold an angle of period pi into `(-pi/2, pi/2]`.
pub fn fold_half_turn(t: f64) -> f64 {
    let mut a = t.rem_euclid(PI);
    if a > FRAC_PI_2 {
        a -= PI;
    }
    a
}

/// Canonical contract parameters of model `id` (see the module doc). Parameters are in the order of
/// [`ModelId::param_names`].
pub fn canonical_params(id: ModelId, p: &[f64]) -> Vec<f64> {
    match id {
        ModelId::Ggx | ModelId::Beckmann => p.to_vec(),
        ModelId::GgxAniso | ModelId::BeckmannAniso => {
            let (ax, ay, tz) = (p[0], p[1], p[2]);
            if ax >= ay {
                vec![ax, ay, fold_half_turn(tz)]
            } else {
                // Swapping the axes is a quarter turn of the local frame (m' = Rz m).
                vec![ay, ax, fold_half_turn(tz + FRAC_PI_2)]
            }
        }
        ModelId::Ellipsoid => canonical_ellipsoid(p),
    }
}

/// Canonical `[alpha_x, alpha_y, theta_x, theta_y, theta_z]` of `A = S R`.
fn canonical_ellipsoid(p: &[f64]) -> Vec<f64> {
    let s = Matrix3::from_diagonal(&nalgebra::Vector3::new(p[0], p[1], 1.0));
    let a = s * rotation_xyz(p[2], p[3], p[4]);
    // M = A^T A = R^T S^2 R: the rows of R are its eigenvectors, S^2 its eigenvalues.
    let eig = SymmetricEigen::new(a.transpose() * a);
    let k = (0..3)
        .max_by(|&i, &j| eig.eigenvectors[(2, i)].abs().total_cmp(&eig.eigenvectors[(2, j)].abs()))
        .expect("three eigenvectors");
    let mut others: Vec<usize> = (0..3).filter(|&i| i != k).collect();
    // alpha_x >= alpha_y.
    if eig.eigenvalues[others[0]] < eig.eigenvalues[others[1]] {
        others.swap(0, 1);
    }
    let lk = eig.eigenvalues[k];
    let col = |i: usize| eig.eigenvectors.column(i).into_owned();
    let mut r3 = col(k);
    if r3.z < 0.0 {
        r3 = -r3;
    }
    let mut r1 = col(others[0]);
    let mut r2 = r3.cross(&r1);
    let mut best: Option<[f64; 5]> = None;
    for _ in 0..2 {
        let r = Matrix3::from_rows(&[r1.transpose(), r2.transpose(), r3.transpose()]);
        // R = Rx Ry Rz: column 3 = (sy, -sx cy, cx cy), row 1 = (cy cz, -cy sz, sy).
        let ty = r[(0, 2)].clamp(-1.0, 1.0).asin();
        let tx = (-r[(1, 2)]).atan2(r[(2, 2)]);
        let tz = (-r[(0, 1)]).atan2(r[(0, 0)]);
        let ax = (eig.eigenvalues[others[0]] / lk).max(0.0).sqrt();
        let ay = (eig.eigenvalues[others[1]] / lk).max(0.0).sqrt();
        let cand = [ax, ay, tx, ty, tz];
        if tz > -FRAC_PI_2 && tz <= FRAC_PI_2 {
            return cand.to_vec();
        }
        best.get_or_insert(cand);
        r1 = -r1;
        r2 = -r2;
    }
    let mut b = best.expect("one candidate was stored").to_vec();
    b[4] = fold_half_turn(b[4]);
    b
}
