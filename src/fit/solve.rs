//! One local minimization from one start, with the solver chosen: Levenberg-Marquardt (the default) or
//! argmin's Nelder-Mead and L-BFGS on the same objective, so the choice of LM is measured.

use argmin::core::{CostFunction, Executor, Gradient, State, TerminationReason as ArgReason, TerminationStatus};
use argmin::solver::linesearch::MoreThuenteLineSearch;
use argmin::solver::neldermead::NelderMead;
use argmin::solver::quasinewton::LBFGS;
use levenberg_marquardt::LevenbergMarquardt;
use nalgebra::{DMatrix, DVector};

use super::objective::FitData;
use super::problem::{jacobian_into, residuals_into, Problem};
use crate::error::{Error, ErrorKind, Result};
use crate::models::ModelId;

/// The local optimizer.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Solver {
    /// Levenberg-Marquardt (`levenberg-marquardt` crate, a MINPACK port) with the analytic Jacobian.
    #[default]
    Lm,
    /// argmin's Nelder-Mead simplex on `sum r^2` (no derivatives).
    NelderMead,
    /// argmin's L-BFGS with More-Thuente line search on `sum r^2`, gradient `2 J^T r`.
    Lbfgs,
}

impl Solver {
    /// The name used on the command line and in the JSON.
    pub fn as_str(self) -> &'static str {
        match self {
            Solver::Lm => "lm",
            Solver::NelderMead => "nelder-mead",
            Solver::Lbfgs => "lbfgs",
        }
    }
}

impl std::str::FromStr for Solver {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "lm" => Ok(Solver::Lm),
            "nelder-mead" => Ok(Solver::NelderMead),
            "lbfgs" => Ok(Solver::Lbfgs),
            _ => Err(Error::invalid(format!("unknown solver '{s}' (expected lm, nelder-mead or lbfgs)"))),
        }
    }
}

/// Stopping rules shared by the solvers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tolerances {
    /// Relative tolerance on the objective and on the parameters (LM `ftol`, `xtol`; L-BFGS cost).
    pub rel: f64,
    /// LM `patience` (evaluations are limited to `patience * (p + 1)`); iterations for argmin.
    pub max_iter: usize,
}

impl Default for Tolerances {
    fn default() -> Self {
        // 1e-10 relative on a deviance of order K is far below the O(1) changes that matter statistically
        // (a standard error moves the deviance by 1), yet well above f64 rounding of a K-term sum.
        Tolerances { rel: 1e-10, max_iter: 200 }
    }
}

/// The outcome of one local minimization.
#[derive(Debug, Clone, PartialEq)]
pub struct Local {
    /// Internal parameters at the end.
    pub x: Vec<f64>,
    /// Objective `sum r^2` there.
    pub f: f64,
    /// Solver's termination reason, as text.
    pub termination: String,
    /// Whether the solver reports convergence.
    pub converged: bool,
    /// Objective (residual) evaluations.
    pub evaluations: usize,
}

/// Minimize from `x0` with `solver`.
pub fn minimize(data: &FitData, id: ModelId, x0: &[f64], solver: Solver, tol: Tolerances) -> Result<Local> {
    match solver {
        Solver::Lm => lm(data, id, x0, tol),
        Solver::NelderMead => nelder_mead(data, id, x0, tol),
        Solver::Lbfgs => lbfgs(data, id, x0, tol),
    }
}

fn lm(data: &FitData, id: ModelId, x0: &[f64], tol: Tolerances) -> Result<Local> {
    let problem = Problem { data, id, x: DVector::from_column_slice(x0) };
    let (problem, report) = LevenbergMarquardt::new()
        .with_ftol(tol.rel)
        .with_xtol(tol.rel)
        .with_gtol(0.0)
        .with_patience(tol.max_iter)
        .minimize(problem);
    let x = problem.x.as_slice().to_vec();
    let mut r = vec![0.0; data.bins.len()];
    let f = residuals_into(data, id, &x, &mut r);
    Ok(Local {
        x,
        f,
        termination: format!("{:?}", report.termination),
        converged: report.termination.was_successful(),
        evaluations: report.number_of_evaluations,
    })
}

/// `sum r^2` and its gradient for argmin.
struct Cost<'a> {
    data: &'a FitData,
    id: ModelId,
    /// Residual evaluations (cost and gradient), counted here so every solver reports the same thing.
    evals: std::cell::Cell<usize>,
}

impl CostFunction for Cost<'_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, x: &Vec<f64>) -> std::result::Result<f64, argmin::core::Error> {
        self.evals.set(self.evals.get() + 1);
        let mut r = vec![0.0; self.data.bins.len()];
        let f = residuals_into(self.data, self.id, x, &mut r);
        // A non-finite objective (never expected: the parameterization keeps D positive) becomes +inf
        // so the simplex and line search retreat instead of propagating NaN.
        Ok(if f.is_finite() { f } else { f64::INFINITY })
    }
}

impl Gradient for Cost<'_> {
    type Param = Vec<f64>;
    type Gradient = Vec<f64>;
    fn gradient(&self, x: &Vec<f64>) -> std::result::Result<Vec<f64>, argmin::core::Error> {
        self.evals.set(self.evals.get() + 1);
        let mut r = vec![0.0; self.data.bins.len()];
        let mut j = DMatrix::zeros(self.data.bins.len(), x.len());
        jacobian_into(self.data, self.id, x, &mut r, &mut j);
        let g = j.transpose() * DVector::from_vec(r) * 2.0;
        Ok(g.as_slice().to_vec())
    }
}

fn arg_err(e: argmin::core::Error) -> Error {
    Error::new(ErrorKind::Numerical, format!("argmin solver failed: {e}"))
}

fn finish<S: State<Param = Vec<f64>, Float = f64>>(data: &FitData, id: ModelId, state: &S, evaluations: usize) -> Result<Local> {
    let x = state.get_best_param().cloned().ok_or_else(|| Error::new(ErrorKind::Numerical, "argmin returned no parameters"))?;
    let mut r = vec![0.0; data.bins.len()];
    let f = residuals_into(data, id, &x, &mut r);
    let status = state.get_termination_status();
    let converged = matches!(status, TerminationStatus::Terminated(ArgReason::SolverConverged));
    Ok(Local { x, f, termination: format!("{status:?}"), converged, evaluations })
}

fn nelder_mead(data: &FitData, id: ModelId, x0: &[f64], tol: Tolerances) -> Result<Local> {
    // Initial simplex: steps of 0.1 in log alpha (10%) and 0.05 rad, the scale of a rough first guess.
    let mut simplex = vec![x0.to_vec()];
    for i in 0..x0.len() {
        let mut v = x0.to_vec();
        v[i] += if super::params::alpha_slots(id).contains(&i) { 0.1 } else { 0.05 };
        simplex.push(v);
    }
    let solver = NelderMead::new(simplex).with_sd_tolerance(tol.rel).map_err(arg_err)?;
    let res = Executor::new(Cost { data, id, evals: Default::default() }, solver)
        .configure(|s| s.max_iters(50 * tol.max_iter as u64))
        .run()
        .map_err(arg_err)?;
    let evals = res.problem.problem.as_ref().map_or(0, |c| c.evals.get());
    finish(data, id, &res.state, evals)
}

fn lbfgs(data: &FitData, id: ModelId, x0: &[f64], tol: Tolerances) -> Result<Local> {
    let ls = MoreThuenteLineSearch::new();
    let solver = LBFGS::new(ls, 7).with_tolerance_cost(tol.rel).map_err(arg_err)?.with_tolerance_grad(1e-8).map_err(arg_err)?;
    let res = Executor::new(Cost { data, id, evals: Default::default() }, solver)
        .configure(|s| s.param(x0.to_vec()).max_iters(5 * tol.max_iter as u64))
        .run()
        .map_err(arg_err)?;
    let evals = res.problem.problem.as_ref().map_or(0, |c| c.evals.get());
    finish(data, id, &res.state, evals)
}
