//! The least-squares problem handed to the `levenberg-marquardt` crate (and, through the same residual
//! code, to the argmin solvers): residuals of [`super::objective`] with the analytic Jacobian of
//! [`super::lnd`].

use levenberg_marquardt::LeastSquaresProblem;
use nalgebra::{DMatrix, DVector, Dyn, Owned};

use super::lnd::LnD;
use super::objective::{residual, FitData};
use crate::models::ModelId;

/// Bins evaluated by [`residuals_into`] since the last reset (profiling: the cost of a fit in bin
/// evaluations, independent of the machine; one relaxed add per call).
pub static RESIDUAL_BIN_EVALS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
/// Bins evaluated by [`jacobian_into`] since the last reset (as [`RESIDUAL_BIN_EVALS`]).
pub static JACOBIAN_BIN_EVALS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// Residuals into `r` (length = bins) at internal vector `x`; returns the objective `sum r^2`
/// (non-finite when the model has no mass in the region).
///
/// Two passes (objective.md): `ln D(m_k)` into `r`, then `ln S` and the residuals of
/// `ln E_k = ln(N_in W_k) + ln D(m_k) - ln S`.
pub fn residuals_into(data: &FitData, id: ModelId, x: &[f64], r: &mut [f64]) -> f64 {
    RESIDUAL_BIN_EVALS.fetch_add(data.bins.len(), std::sync::atomic::Ordering::Relaxed);
    let f = LnD::new(id, x);
    for (rk, bin) in r.iter_mut().zip(&data.bins) {
        *rk = f.value(&bin.m);
    }
    let ln_s = data.ln_norm(r);
    let mut sum = 0.0;
    for (rk, bin) in r.iter_mut().zip(&data.bins) {
        let (v, _) = residual(data.objective, bin, *rk - ln_s);
        *rk = v;
        sum += v * v;
    }
    if ln_s.is_finite() {
        sum
    } else {
        f64::NAN
    }
}

/// Residuals and the Jacobian (column-major, bins x params) at `x`. Buffers are the caller's.
///
/// With `g_k = d ln D(m_k) / d x` and the normalization profiled out, `d ln E_k / d x = g_k - gbar`,
/// `gbar = sum_j D_j W_j g_j / S` (the rank-one term of the conditional likelihood), so
/// `J_k = (d r_k / d ln E_k) (g_k - gbar)`.
pub fn jacobian_into(data: &FitData, id: ModelId, x: &[f64], r: &mut [f64], jac: &mut DMatrix<f64>) {
    JACOBIAN_BIN_EVALS.fetch_add(data.bins.len(), std::sync::atomic::Ordering::Relaxed);
    let f = LnD::new(id, x);
    let p = x.len();
    let mut g = [0.0; 5];
    for (k, bin) in data.bins.iter().enumerate() {
        r[k] = f.value_grad(&bin.m, &mut g[..p]);
        for (j, gj) in g[..p].iter().enumerate() {
            jac[(k, j)] = *gj;
        }
    }
    let ln_s = data.ln_norm(r);
    let mut gbar = [0.0; 5];
    for (k, bin) in data.bins.iter().enumerate() {
        let wk = (r[k] - ln_s).exp() * bin.w;
        for (j, gb) in gbar[..p].iter_mut().enumerate() {
            *gb += wk * jac[(k, j)];
        }
    }
    for (k, bin) in data.bins.iter().enumerate() {
        let (v, dr) = residual(data.objective, bin, r[k] - ln_s);
        r[k] = v;
        for (j, gb) in gbar[..p].iter().enumerate() {
            jac[(k, j)] = dr * (jac[(k, j)] - gb);
        }
    }
}

/// The LM problem: a model id, the data and the current internal parameters.
#[derive(Debug, Clone)]
pub struct Problem<'a> {
    /// The data.
    pub data: &'a FitData,
    /// The model being fitted.
    pub id: ModelId,
    /// Current internal parameters.
    pub x: DVector<f64>,
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.x.copy_from(x);
    }

    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let mut r = DVector::zeros(self.data.bins.len());
        let f = residuals_into(self.data, self.id, self.x.as_slice(), r.as_mut_slice());
        // A non-finite objective is reported to LM as a failed evaluation, never passed on as NaN.
        f.is_finite().then_some(r)
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let mut r = vec![0.0; self.data.bins.len()];
        let mut j = DMatrix::zeros(self.data.bins.len(), self.x.len());
        jacobian_into(self.data, self.id, self.x.as_slice(), &mut r, &mut j);
        j.iter().all(|v| v.is_finite()).then_some(j)
    }
}
