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
use crate::models::student::GAMMA_MIN;
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
    /// argmin's L-BFGS with More-Thuente line search on `sum r^2` (scaled and restarted in phases,
    /// see `lbfgs`), gradient `2 J^T r`.
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
    let run = |x: &[f64]| match solver {
        Solver::Lm => lm(data, id, x, tol),
        Solver::NelderMead => nelder_mead(data, id, x, tol),
        Solver::Lbfgs => lbfgs(data, id, x, tol),
    };
    let local = run(x0)?;
    // A Student tail driven onto the flat end of its map (gamma at the Smith bound to within 1e-6, where
    // d gamma / d g vanishes) cannot come back by itself: rerun from just inside the bound, keep the better.
    let Some(i) = super::params::gamma_slot(id).filter(|&i| super::params::gamma_of(local.x[i]) - GAMMA_MIN < 1e-6) else {
        return Ok(local);
    };
    let mut x = local.x.clone();
    x[i] = super::params::g_of(GAMMA_MIN + 0.05);
    let again = run(&x)?;
    let evaluations = local.evaluations + again.evaluations;
    let best = if again.f < local.f { again } else { local };
    Ok(Local { evaluations, ..best })
}

fn lm(data: &FitData, id: ModelId, x0: &[f64], tol: Tolerances) -> Result<Local> {
    let problem = Problem::new(data, id, x0);
    let (problem, report) =
        LevenbergMarquardt::new().with_ftol(tol.rel).with_xtol(tol.rel).with_gtol(0.0).with_patience(tol.max_iter).minimize(problem);
    let x = problem.x.as_slice().to_vec();
    // Usually the last residual pass (LM ends on an accepted step), else evaluated.
    let f = problem.objective();
    Ok(Local {
        x,
        f,
        termination: format!("{:?}", report.termination),
        converged: report.termination.was_successful(),
        evaluations: report.number_of_evaluations,
    })
}

/// `scale * sum r^2` and its gradient for argmin.
///
/// The scale matters for L-BFGS: its first step is `-g` (no curvature known yet, argmin's `gamma = 1`),
/// and the deviance of a rough start is ~1e5 with gradients ~1e6 per radian of skew, so an unscaled first
/// step lands where `D` over- or underflows and the More-Thuente line search stops on the infinite cost
/// ("NaN or Inf encountered"). Divided by the objective at the phase's start, the cost is 1 there and
/// the gradient is the relative change per unit of parameter, O(1)-O(10): a unit first step is sane.
struct Cost<'a> {
    data: &'a FitData,
    id: ModelId,
    /// Factor applied to the objective and its gradient.
    scale: f64,
    /// Residual evaluations (cost and gradient), counted here so every solver reports the same thing.
    evals: &'a std::cell::Cell<usize>,
}

impl CostFunction for Cost<'_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, x: &Vec<f64>) -> std::result::Result<f64, argmin::core::Error> {
        self.evals.set(self.evals.get() + 1);
        let mut r = vec![0.0; self.data.bins.len()];
        let f = residuals_into(self.data, self.id, x, &mut r) * self.scale;
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
        // d(sum r^2)/dx = 2 J^T r (checked against central differences in the tests below).
        let g = j.transpose() * DVector::from_vec(r) * (2.0 * self.scale);
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

/// The phase driver shared by the argmin solvers: each phase runs `phase(cost, x)` on the deviance
/// divided by its value at the phase's start (see [`Cost`]), keeps the phase's best point when it is
/// better, and stops once a phase gains less than `tol.rel` relative (or after [`PHASES`]). That makes
/// argmin's absolute stopping criteria relative to the deviance near the optimum (the first phase's
/// scale is set by a poor start, often 100x the optimum) and restarts a solver that stopped on a
/// non-finite trial or a collapsed simplex.
fn phased(
    data: &FitData,
    id: ModelId,
    x0: &[f64],
    tol: Tolerances,
    name: &str,
    mut phase: impl FnMut(Cost<'_>, &[f64]) -> Result<Local>,
) -> Result<Local> {
    let evals = std::cell::Cell::new(1);
    let mut r = vec![0.0; data.bins.len()];
    let mut x = x0.to_vec();
    let mut f = residuals_into(data, id, &x, &mut r);
    if !f.is_finite() {
        return Err(Error::new(ErrorKind::Numerical, format!("{name}: the objective is not finite at the start")));
    }
    let mut termination = String::new();
    let mut converged = false;
    for _ in 0..PHASES {
        // Guard: a perfect fit (f = 0) has nothing to scale by; the unit scale is then as good as any.
        let scale = if f > 0.0 { 1.0 / f } else { 1.0 };
        let done = phase(Cost { data, id, scale, evals: &evals }, &x)?;
        termination = done.termination;
        converged = done.converged;
        let gained = f - done.f;
        if done.f.is_finite() && gained > 0.0 {
            x = done.x;
            f = done.f;
        }
        if !(gained > tol.rel * f) {
            break;
        }
    }
    Ok(Local { x, f, termination, converged, evaluations: evals.get() })
}

/// Nelder-Mead on the scaled deviance, in phases ([`phased`]): argmin's simplex criterion is absolute
/// (standard deviation of the vertex costs below `tol.rel`), which an unscaled deviance of ~1e5 never
/// meets (it ran its 10000 iterations in the `ggx-aniso` stage: 5.7 s for one 2048^2 fit); divided by
/// the cost at the phase's start it is relative. Each new phase rebuilds the simplex around the best
/// point (the usual cure for a collapsed simplex).
fn nelder_mead(data: &FitData, id: ModelId, x0: &[f64], tol: Tolerances) -> Result<Local> {
    phased(data, id, x0, tol, "Nelder-Mead", |cost, x| {
        // Initial simplex: steps of 0.1 in log alpha (10%) and 0.05 rad, the scale of a rough first guess.
        let mut simplex = vec![x.to_vec()];
        for i in 0..x.len() {
            let mut v = x.to_vec();
            v[i] += if super::params::alpha_slots(id).any(|a| a == i) { 0.1 } else { 0.05 };
            simplex.push(v);
        }
        let evals = cost.evals;
        let solver = NelderMead::new(simplex).with_sd_tolerance(tol.rel).map_err(arg_err)?;
        let res = Executor::new(cost, solver).configure(|s| s.max_iters(50 * tol.max_iter as u64)).run().map_err(arg_err)?;
        finish(data, id, &res.state, evals.get())
    })
}

/// L-BFGS memory: 10 pairs took fewer evaluations than 5 on the bench's ellipsoid (22 + 39 against
/// 26 + 45 cost + gradient calls; Hager-Zhang's line search took 90-140 cost calls, More-Thuente 22-48).
const LBFGS_MEMORY: usize = 10;
/// Most phases of L-BFGS and Nelder-Mead (each rescales the cost and restarts the solver).
const PHASES: usize = 6;

/// L-BFGS (More-Thuente line search) on the scaled deviance, in phases ([`phased`]): each phase stops
/// when the scaled cost changes by less than `tol.rel` in an iteration, i.e. the deviance by less than
/// `tol.rel` relative to where the phase began.
fn lbfgs(data: &FitData, id: ModelId, x0: &[f64], tol: Tolerances) -> Result<Local> {
    phased(data, id, x0, tol, "L-BFGS", |cost, x| {
        let evals = cost.evals;
        let solver = LBFGS::new(MoreThuenteLineSearch::new(), LBFGS_MEMORY)
            .with_tolerance_cost(tol.rel)
            .map_err(arg_err)?
            // The gradient criterion is off: the cost criterion above is the relative one.
            .with_tolerance_grad(0.0)
            .map_err(arg_err)?;
        let res =
            Executor::new(cost, solver).configure(|s| s.param(x.to_vec()).max_iters(5 * tol.max_iter as u64)).run().map_err(arg_err)?;
        finish(data, id, &res.state, evals.get())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::synthetic::{binned_ndf, Grid};
    use crate::fit::Objective;
    use crate::models::Model;

    fn data() -> (FitData, Vec<f64>) {
        let truth = Model::from_params(ModelId::Ellipsoid, &[0.3, 0.12, 0.2, -0.3, 0.6]).expect("valid truth");
        let ndf = binned_ndf(&truth, &Grid::for_model(&truth, 41), 1e6, 11);
        // The whole hemisphere: the solvers are compared on the same bins, whichever they are.
        let data = FitData::new(&ndf, Objective::Poisson, std::f64::consts::FRAC_PI_2).expect("fit data");
        // A start like the fit's own (the anisotropic lobe without skew), far from the optimum.
        (data, super::super::params::to_internal(ModelId::Ellipsoid, &[0.35, 0.2, 0.0, 0.0, 0.4]))
    }

    /// The gradient handed to argmin is the derivative of its cost: central differences with h = 1e-6
    /// have truncation error ~h^2 |f'''| and rounding ~eps |f| / h, both below 1e-6 of the gradient's
    /// scale here (f ~ 1e5, |g| ~ 1e5-1e6), so 1e-5 relative to the largest component is a real check.
    #[test]
    fn argmin_gradient_matches_central_differences() {
        let (data, x0) = data();
        let evals = std::cell::Cell::new(0);
        for scale in [1.0, 1e-5] {
            let c = Cost { data: &data, id: ModelId::Ellipsoid, scale, evals: &evals };
            let g = c.gradient(&x0).expect("gradient");
            let gmax = g.iter().fold(0.0f64, |a, v| a.max(v.abs()));
            for i in 0..x0.len() {
                let h = 1e-6;
                let (mut a, mut b) = (x0.clone(), x0.clone());
                a[i] += h;
                b[i] -= h;
                let fd = (c.cost(&a).expect("cost") - c.cost(&b).expect("cost")) / (2.0 * h);
                assert!((g[i] - fd).abs() <= 1e-5 * gmax, "scale {scale}, x[{i}]: analytic {} vs FD {fd}", g[i]);
            }
        }
    }

    /// Nelder-Mead reaches LM's optimum from the same start (deviance to 1e-8 relative).
    #[test]
    fn nelder_mead_reaches_the_lm_optimum() {
        let (data, x0) = data();
        let tol = Tolerances::default();
        let lm = minimize(&data, ModelId::Ellipsoid, &x0, Solver::Lm, tol).expect("lm");
        let nm = minimize(&data, ModelId::Ellipsoid, &x0, Solver::NelderMead, tol).expect("nelder-mead");
        assert!(nm.converged, "{}", nm.termination);
        assert!((nm.f - lm.f).abs() <= 1e-8 * lm.f, "Nelder-Mead {} vs LM {}", nm.f, lm.f);
    }

    /// L-BFGS reaches LM's optimum from the same start: the deviance to 1e-8 relative (the O(1) change
    /// that a standard error means is ~1e-3 of this deviance), and the parameters to 1e-4.
    #[test]
    fn lbfgs_reaches_the_lm_optimum() {
        let (data, x0) = data();
        let tol = Tolerances::default();
        let lm = minimize(&data, ModelId::Ellipsoid, &x0, Solver::Lm, tol).expect("lm");
        let lb = minimize(&data, ModelId::Ellipsoid, &x0, Solver::Lbfgs, tol).expect("lbfgs");
        assert!(lb.converged, "{}", lb.termination);
        assert!((lb.f - lm.f).abs() <= 1e-8 * lm.f, "L-BFGS {} vs LM {}", lb.f, lm.f);
        for (a, b) in lb.x.iter().zip(&lm.x) {
            assert!((a - b).abs() < 1e-4, "{:?} vs {:?}", lb.x, lm.x);
        }
        assert!(lb.evaluations > 1);
    }
}
