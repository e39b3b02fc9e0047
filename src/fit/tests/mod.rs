//! Unit tests of the fitter's internals: the parameter maps and the analytic Jacobians against central
//! differences (the public behaviour is tested in `tests/all/fit/`).
//!
//! Tolerance of the central differences: with step `h` they err by `h^2 |f'''| / 6` (truncation) plus
//! `eps |f| / h` (rounding); with `h = 1e-5`, `|ln D| < 30` and `|f'''| < 1e4` over the test domains that
//! is below 2e-6, so `2e-5 (1 + |g|)` cannot hide a wrong term (those are O(|g|)) yet is safe.

use nalgebra::{DMatrix, Vector3};

use super::lnd::LnD;
use super::objective::FitData;
use super::problem::{jacobian_into, residuals_into};
use crate::models::{Model, ModelId};

mod bound;
mod jacobian;
mod mixture;

/// The central-difference step.
const H: f64 = 1e-5;

/// A model from its id and contract parameters.
fn model(id: ModelId, p: &[f64]) -> Model {
    Model::from_params(id, p).expect("valid test parameters")
}

/// `x` with parameter `p` moved by `d`.
fn moved(x: &[f64], p: usize, d: f64) -> Vec<f64> {
    let mut y = x.to_vec();
    y[p] += d;
    y
}

/// The analytic gradient of `ln D` at internal parameters `x` and direction `dir` against central
/// differences of `ln D` itself; returns `ln D` as `value_grad` gives it.
fn assert_ln_d_gradient(id: ModelId, x: &[f64], dir: &Vector3<f64>) -> f64 {
    let mut g = vec![0.0; x.len()];
    let v = LnD::new(id, x).value_grad(dir, &mut g);
    for (j, &gj) in g.iter().enumerate() {
        let fd = (LnD::new(id, &moved(x, j, H)).value(dir) - LnD::new(id, &moved(x, j, -H)).value(dir)) / (2.0 * H);
        assert!((fd - gj).abs() < 2e-5 * (1.0 + gj.abs()), "{id} x={x:?} m={dir:?} param {j}: analytic {gj} vs FD {fd}");
    }
    v
}

/// The residuals' analytic Jacobian on `data` at internal parameters `x` against central differences of
/// the residuals (`what` names the case in a failure). The Poisson residual has a kink in its second
/// derivative only where `c = 0` and `E -> 0` (`sqrt(2E)`); the tolerance is relative to `|r|` and `|J|`.
fn assert_residual_jacobian(data: &FitData, id: ModelId, x: &[f64], what: &str) {
    let k = data.bins.len();
    let mut r = vec![0.0; k];
    let mut j = DMatrix::zeros(k, x.len());
    jacobian_into(data, id, x, &mut r, &mut j);
    for p in 0..x.len() {
        let (mut rp, mut rm) = (vec![0.0; k], vec![0.0; k]);
        residuals_into(data, id, &moved(x, p, H), &mut rp);
        residuals_into(data, id, &moved(x, p, -H), &mut rm);
        for b in 0..k {
            let fd = (rp[b] - rm[b]) / (2.0 * H);
            let tol = 2e-5 * (1.0 + j[(b, p)].abs() + r[b].abs());
            assert!((fd - j[(b, p)]).abs() < tol, "{what} {id} bin {b} param {p}: {} vs {fd}", j[(b, p)]);
        }
    }
}
