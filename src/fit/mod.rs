//! Fitting analytic NDFs to an empirical NDF with Levenberg-Marquardt.
//!
//! - `params`: the unbounded parameterization (`alpha = ALPHA_MIN + exp(u)`, free angles) and why;
//! - `lnd`: `ln D` of every model (Walter et al. eq. 1-3, Heitz eq. 82) with its analytic gradient;
//! - `objective`: the residuals of `data_formats/objective.md` (Poisson deviance, or count-weighted
//!   log D);
//! - `problem`, `solve`: the LM problem and the solvers (LM, argmin's Nelder-Mead and L-BFGS);
//! - `start`: closed-form starting points from the slope distribution;
//! - canonical form: [`crate::models::Model::canonical`] (the models module's convention);
//! - [`covariance`]: standard errors and correlations from `(J^T J)^+` scaled by the residual variance;
//! - `report`: the `ndfit.fit/1` JSON; `metric`: the NDF difference metric;
//! - `synthetic`: binned NDFs with known truth (test and benchmark fixtures); `plot`: data vs fit.
//!
//! Entry points: [`fit_model`] for one model, [`fit_auto`] for model selection.

pub(crate) mod covariance;
pub(crate) mod lnd;
pub(crate) mod lnd_mixture;
pub(crate) mod metric;
pub(crate) mod mixture;
pub(crate) mod objective;
pub(crate) mod options;
pub(crate) mod params;
#[cfg(feature = "plot")]
pub(crate) mod plot;
pub(crate) mod problem;
pub(crate) mod qbic;
pub(crate) mod report;
pub(crate) mod solve;
pub(crate) mod start;
pub(crate) mod synthetic;
pub(crate) mod tail;
pub(crate) mod verdict;

#[cfg(test)]
mod tests;

use std::collections::BTreeMap;
use std::time::Instant;

use nalgebra::DMatrix;

pub use covariance::{covariance, Covariance};
pub use metric::{delta, delta_to_model};
pub use objective::Bin;
pub use objective::Rounding;
pub use objective::DEFAULT_MAX_THETA_DEG;
pub use objective::{FitData, Objective};
pub use options::MAX_EXTRA_STARTS;
#[cfg(feature = "plot")]
pub use plot::plot_fit;
pub use report::{Candidate, FitReport, Haze, Optics, Quality, Selection, SolverInfo, SpecularShare, Timings};
pub use solve::{Solver, Tolerances};
pub use synthetic::{binned_ndf, expected, Grid};
pub use tail::{tail_cut, usable, TailCut, TailRule, MIN_ALONE_SHARE};
pub use verdict::{data_dispersion, judge, Evidence, Verdict, DEFAULT_TOLERANCE};

use crate::error::{Error, ErrorKind, Result};
use crate::models::table::Form;
use crate::models::{Model, ModelId, Role};
use crate::ndf::EmpiricalNdf;

/// Largest standard error of `theta_z` (radians) reported as a number. The axes of a lobe are located by
/// its anisotropy: with the anisotropy written as a 2-vector `e (cos 2 theta_z, sin 2 theta_z)` of
/// per-component standard error `s_e`, `se(theta_z) = s_e / (2 e) = 1 / (2 r)` with `r = e / s_e` the
/// anisotropy in standard errors. `theta_z` counts as identified when `r >= 3`, i.e. `se <= 1/6`: for an
/// isotropic truth `r` is Rayleigh distributed, so a chance anisotropy passes with probability
/// `exp(-9/2) = 1.1%` (at `pi/4`, `r = 0.64`, it would pass 81% of the time).
pub const THETA_Z_SE_MAX: f64 = 1.0 / 6.0;

/// How to fit.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FitOptions {
    /// The residuals (objective.md); Poisson by default.
    pub objective: Objective,
    /// The local optimizer; LM by default.
    pub solver: Solver,
    /// Stopping rules.
    pub tolerances: Tolerances,
    /// Extra skew starts for the ellipsoid beyond the two default ones (zero skew, and the skew of the
    /// mean normal), taken in order from `(+-0.3, 0), (0, +-0.3)`; at most 4.
    pub extra_starts: usize,
    /// Largest polar angle (radians) of the bins the objective uses; the model is normalized over them
    /// (objective.md). Default [`objective::DEFAULT_MAX_THETA_DEG`].
    pub max_theta: f64,
    /// The tail rule (`tail`, objective.md): by default the whitened core of a lone lobe whose rim the
    /// sampling leaves unresolved, else only the unresolved bins ([`tail::TailRule::Rim`]).
    pub tail: tail::TailRule,
    /// The NDF error beyond counting noise a renderer cannot show ([`verdict::DEFAULT_TOLERANCE`]): the
    /// verdict's `misfit` lies beyond it, and `auto` climbs to a richer model only while the current one
    /// exceeds it.
    pub tolerance: f64,
}

impl Default for FitOptions {
    fn default() -> Self {
        FitOptions {
            objective: Objective::Poisson,
            solver: Solver::Lm,
            tolerances: Tolerances::default(),
            extra_starts: 0,
            max_theta: objective::DEFAULT_MAX_THETA_DEG.to_radians(),
            tail: tail::TailRule::Rim,
            tolerance: verdict::DEFAULT_TOLERANCE,
        }
    }
}

/// A fit at the canonical optimum, before it becomes a report.
#[derive(Debug, Clone)]
struct Fitted {
    id: ModelId,
    /// Canonical internal parameters.
    x: Vec<f64>,
    f: f64,
    local: solve::Local,
    evaluations: usize,
    start_objectives: Vec<f64>,
    best_start: usize,
    warnings: Vec<String>,
    /// All samples in one bin: a delta NDF, reported at the alpha floor with no standard errors.
    delta: bool,
}

/// Fewest fine bins for which the solver first runs on the 2 x 2-merged bins
/// ([`FitData::coarsened`]): below it a fine evaluation is already cheap.
pub const COARSE_PASS_MIN_BINS: usize = 2000;

/// The data of one fit session: the bins and their slope summary.
struct Session {
    data: FitData,
    /// The same region on bins merged 2 x 2, for the first pass of the solver (large NDFs only).
    coarse: Option<FitData>,
    summary: start::SlopeSummary,
}

impl Session {
    fn new(ndf: &EmpiricalNdf, opts: &FitOptions) -> Result<Session> {
        opts.validate()?;
        let data = FitData::with_tail(ndf, opts.objective, opts.max_theta, opts.tail)?;
        // Independent reads of the region's bins, each with serial sums in its own order: side by side.
        let (summary, coarse) = rayon::join(
            || start::summarize(&data),
            || if data.bins.len() >= COARSE_PASS_MIN_BINS { data.coarsened(ndf, 50) } else { None },
        );
        Ok(Session { data, coarse, summary })
    }
}

/// Run the solver on `data` from every start (contract parameters): the index and result of the best
/// finite one, and every start's objective; evaluations are added to `evaluations`. The starts run side
/// by side (each solve is independent of the others and its sums over bins run in bin order, so the
/// result is the same bit for bit as one after the other; the best is the first of the lowest, in the
/// starts' order).
fn best_of_starts(
    data: &FitData,
    id: ModelId,
    starts: &[Vec<f64>],
    opts: &FitOptions,
    evaluations: &mut usize,
) -> Result<(usize, Option<solve::Local>, Vec<f64>)> {
    use rayon::prelude::*;
    let solved: Vec<Result<solve::Local>> =
        starts.par_iter().map(|p0| solve::minimize(data, id, &params::to_internal(id, p0), opts.solver, opts.tolerances)).collect();
    let mut best: Option<(usize, solve::Local)> = None;
    let mut objs = Vec::with_capacity(starts.len());
    for (i, local) in solved.into_iter().enumerate() {
        let local = local?;
        *evaluations += local.evaluations;
        objs.push(local.f);
        if local.f.is_finite() && local.x.iter().all(|v| v.is_finite()) && best.as_ref().is_none_or(|(_, b)| local.f < b.f) {
            best = Some((i, local));
        }
    }
    Ok(match best {
        Some((i, l)) => (i, Some(l), objs),
        None => (0, None, objs),
    })
}

/// Run the solver from every start (contract parameters) and keep the best, canonicalized.
fn fit_from(s: &Session, id: ModelId, starts: &[Vec<f64>], opts: &FitOptions) -> Result<Fitted> {
    // Large NDFs: every start runs on the merged bins (a quarter of the cost per evaluation), and only
    // the best is polished on the fine bins, from close to its optimum. Should that polish end outside
    // the model's domain or not finite (a coarse pass that ran off), the starts are rerun on the fine bins.
    let usable = |l: &solve::Local| {
        l.f.is_finite() && l.x.iter().all(|v| v.is_finite()) && Model::from_params(id, &params::to_public(id, &l.x)).is_ok()
    };
    let mut evaluations = 0;
    let mut polished = None;
    if let Some(coarse) = &s.coarse {
        let (i, l, objs) = best_of_starts(coarse, id, starts, opts, &mut evaluations)?;
        if let Some(l) = l {
            let fine = solve::minimize(&s.data, id, &l.x, opts.solver, opts.tolerances)?;
            evaluations += fine.evaluations;
            if usable(&fine) {
                polished = Some((i, fine, objs));
            }
        }
    }
    let (best_start, local, start_objectives) = match polished {
        Some(p) => p,
        None => {
            let (i, l, objs) = best_of_starts(&s.data, id, starts, opts, &mut evaluations)?;
            let l = l.ok_or_else(|| {
                Error::new(ErrorKind::Numerical, format!("no usable {id} fit: the objective was not finite from any start"))
            })?;
            (i, l, objs)
        }
    };
    let mut warnings = Vec::new();
    if !local.converged {
        warnings.push(format!("{id}: the {} solver stopped without converging ({})", opts.solver.as_str(), local.termination));
    }
    // Canonical form: the same distribution, so the objective must not change beyond rounding.
    let xc = Model::from_params(id, &params::to_public(id, &local.x))
        .map(|m| params::to_internal(id, &m.canonical().params()))
        .unwrap_or_else(|_| local.x.clone());
    let mut r = vec![0.0; s.data.bins.len()];
    let fc = problem::residuals_into(&s.data, id, &xc, &mut r);
    let same = |f: f64| f.is_finite() && (f - local.f).abs() <= 1e-8 * local.f.abs().max(1.0);
    // An undetermined angle (theta_z of a nearly isotropic lobe) can drift to huge values where its
    // float reduction mod pi is inexact, so the canonical point differs slightly: polish from there with
    // the same solver and canonicalize again.
    let polished = if same(fc) {
        None
    } else {
        solve::minimize(&s.data, id, &xc, opts.solver, opts.tolerances).ok().and_then(|pl| {
            let x2 =
                Model::from_params(id, &params::to_public(id, &pl.x)).ok().map(|m| params::to_internal(id, &m.canonical().params()))?;
            let f2 = problem::residuals_into(&s.data, id, &x2, &mut r);
            (f2.is_finite() && f2 <= local.f + 1e-8 * local.f.abs().max(1.0)).then_some((x2, f2))
        })
    };
    let (x, f) = if same(fc) {
        (xc, fc)
    } else if let Some((x2, f2)) = polished {
        (x2, f2)
    } else {
        warnings.push(format!("{id}: canonical form changed the objective ({} -> {fc}); kept the solver's parameters", local.f));
        (local.x.clone(), local.f)
    };
    Ok(Fitted { id, x, f, local, evaluations, start_objectives, best_start, warnings, delta: false })
}

/// The fit of a delta NDF (every sample in one bin, e.g. a plane after form removal): no lobe width can
/// be measured, so the alphas are the models' floor [`crate::models::ALPHA_MIN`] and the lobe points at
/// the bin (for the ellipsoid through its skew; the other models are centred on n by definition); a tail
/// is GGX's, a mixture's weight one half.
fn delta_fit(s: &Session, id: ModelId) -> Fitted {
    let (tx, ty) = start::skew_start(&s.summary, 0.0);
    let a = crate::models::ALPHA_MIN;
    let p: Vec<f64> = id
        .spec()
        .roles
        .iter()
        .map(|&(role, _)| match role {
            Role::Alpha | Role::AlphaX | Role::AlphaY => a,
            Role::ThetaX => tx,
            Role::ThetaY => ty,
            Role::ThetaZ => 0.0,
            Role::Gamma => 2.0,
            Role::Weight => 0.5,
        })
        .collect();
    let x = params::to_internal(id, &p);
    let mut r = vec![0.0; s.data.bins.len()];
    let f = problem::residuals_into(&s.data, id, &x, &mut r);
    let termination = "delta NDF: every sample in one bin; alpha set to the model floor".to_string();
    let local = solve::Local { x: x.clone(), f, termination, converged: true, evaluations: 0 };
    Fitted { id, x, f, local, evaluations: 0, start_objectives: vec![f], best_start: 0, warnings: Vec::new(), delta: true }
}

/// Public parameters of a fit.
fn public(fit: &Fitted) -> Vec<f64> {
    params::to_public(fit.id, &fit.x)
}

/// Fit a one-parameter model (closed-form start).
fn fit_iso(s: &Session, id: ModelId, opts: &FitOptions) -> Result<Fitted> {
    fit_from(s, id, &[start::closed_form(id, &s.summary)], opts)
}

/// Fit a model from its closed-form start and, given its parent's fit, from the parent's optimum: each
/// parameter the parent has (an isotropic `alpha` stands for both axes) at the parent's value, the others at
/// their closed-form start (`theta_z` from the slopes, a tail at GGX's `gamma = 2`).
fn fit_grown(s: &Session, id: ModelId, parent: Option<&Fitted>, opts: &FitOptions) -> Result<Fitted> {
    let closed = start::closed_form(id, &s.summary);
    let mut starts = vec![closed.clone()];
    if let Some(parent) = parent {
        let ps = parent.id.spec();
        let g = ps.parts(&public(parent), 0);
        let has = |r: Role| ps.slot(r, 0).is_some() || (matches!(r, Role::AlphaX | Role::AlphaY) && ps.slot(Role::Alpha, 0).is_some());
        let grown = id
            .spec()
            .roles
            .iter()
            .zip(&closed)
            .map(|(&(role, _), &c)| match role {
                Role::Alpha | Role::AlphaX if has(role) => g.alpha_x,
                Role::AlphaY if has(role) => g.alpha_y,
                Role::ThetaX if has(role) => g.theta_x,
                Role::ThetaY if has(role) => g.theta_y,
                Role::ThetaZ if has(role) => g.theta_z,
                Role::Gamma if has(role) => g.gamma.unwrap_or(c),
                _ => c,
            })
            .collect();
        starts.push(grown);
    }
    fit_from(s, id, &starts, opts)
}

/// Fit the ellipsoid from the GTR2aniso optimum with zero skew, with the mean normal's skew, and the
/// requested extra skews.
fn fit_ellipsoid(s: &Session, id: ModelId, aniso: &Fitted, opts: &FitOptions) -> Result<Fitted> {
    // A GTR2aniso optimum outside the model's domain (a lobe whose peak lies outside the region, which the
    // centred model can only flatten) starts nothing: the closed-form start from the slopes does.
    let mut p = public(aniso);
    if Model::from_params(aniso.id, &p).is_err() {
        p = start::closed_form(aniso.id, &s.summary);
    }
    let (ax, ay, tz) = (p[0], p[1], p[2]);
    let (tx, ty) = start::skew_start(&s.summary, tz);
    let mut starts = vec![vec![ax, ay, 0.0, 0.0, tz]];
    // The mean-normal skew start is skipped when it is the zero-skew start to 0.01 rad.
    if tx.hypot(ty) > 0.01 {
        starts.push(vec![ax, ay, tx, ty, tz]);
    }
    for (sx, sy) in [(0.3, 0.0), (-0.3, 0.0), (0.0, 0.3), (0.0, -0.3)].into_iter().take(opts.extra_starts) {
        starts.push(vec![ax, ay, sx, sy, tz]);
    }
    fit_from(s, id, &starts, opts)
}

/// Relative tolerance of the GTR2aniso pass that only starts the ellipsoid (`aniso_start`): measured
/// on the 1024^2 bench scene, 1e-6 instead of 1e-10 cut the fit's residual bin evaluations by a fifth
/// (103k -> 82k), and over the synthetic and real scans moved the ellipsoid's parameters by at most
/// 2.7e-8 relative (the final fine pass runs at the full tolerance).
pub const START_PASS_REL_TOL: f64 = 1e-6;

/// The GTR2aniso fit that only starts the ellipsoid (`fit_model(.., Ellipsoid)`), on the merged bins
/// alone: its optimum is a start, which the ellipsoid's own passes (merged, then fine) move anyway, so
/// polishing it on the fine bins (about a third of the fit's bin evaluations at 1024^2) changed the
/// ellipsoid's fitted parameters by at most 6e-9 relative over the synthetic and real scans.
/// `None` without merged bins or when that pass gives no usable optimum (the caller then runs the full
/// GTR2aniso fit).
fn aniso_start(s: &Session, id: ModelId, opts: &FitOptions) -> Result<Option<Fitted>> {
    let Some(coarse) = &s.coarse else { return Ok(None) };
    let mut evaluations = 0;
    // Only a start: converged to START_PASS_REL_TOL (or the caller's looser tolerance).
    let mut o = *opts;
    o.tolerances.rel = o.tolerances.rel.max(START_PASS_REL_TOL);
    let opts = &o;
    let (best_start, l, start_objectives) = best_of_starts(coarse, id, &[start::closed_form(id, &s.summary)], opts, &mut evaluations)?;
    Ok(l.filter(|l| Model::from_params(id, &params::to_public(id, &l.x)).is_ok()).map(|local| Fitted {
        id,
        x: local.x.clone(),
        f: local.f,
        local,
        evaluations,
        start_objectives,
        best_start,
        warnings: Vec::new(),
        delta: false,
    }))
}

/// Fit `id` with the chain of simpler fits it starts from (the table's parents).
fn fit_chain(s: &Session, id: ModelId, opts: &FitOptions) -> Result<Fitted> {
    if s.data.k_nonzero == 1 {
        return Ok(delta_fit(s, id));
    }
    let spec = id.spec();
    if spec.is_mixture() {
        return mixture::fit_mixture_chain(s, id, opts);
    }
    match (spec.lobes[0].form, spec.parent) {
        (_, None) => fit_iso(s, id, opts),
        (Form::Full, Some(parent)) => {
            // The closed-form start of the parent suffices here (its own pre-fit only matters when its
            // start is poor, and the ellipsoid stage has its own starts).
            let aniso = match aniso_start(s, parent, opts)? {
                Some(a) => a,
                None => fit_grown(s, parent, None, opts)?,
            };
            fit_ellipsoid(s, id, &aniso, opts)
        }
        (_, Some(parent)) => fit_grown(s, id, Some(&fit_chain(s, parent, opts)?), opts),
    }
}

fn names(id: ModelId, v: &[f64]) -> BTreeMap<String, f64> {
    id.param_names().iter().zip(v).map(|(n, x)| (n.to_string(), *x)).collect()
}

/// Turn a fit into a report: covariance, goodness of fit, matrix A, flags.
fn build_report(ndf: &EmpiricalNdf, s: &Session, fit: Fitted, opts: &FitOptions, fit_ms: f64) -> Result<FitReport> {
    let id = fit.id;
    let p = id.n_params();
    let pv = public(&fit);
    let model = Model::from_params(id, &pv)?;
    let mut warnings = fit.warnings.clone();
    let k = s.data.k_nonzero;
    // The total count in the region is fixed (the normalization is profiled out): one dof fewer.
    let dof = k as i64 - p as i64 - 1;
    let reduced = (dof > 0).then(|| fit.f / dof as f64);
    // Standard errors scale with the residual variance (objective.md); with no dof, unscaled.
    let s2 = reduced.unwrap_or(1.0);
    let g = params::public_derivative(id, &fit.x);
    let se_of = |c: &covariance::Covariance, a: usize| g[a].abs() * c.cov[(a, a)].max(0.0).sqrt();
    // The standard errors and the NDF error against the data read the fit and the NDF alone, each with
    // its sums in its own order: side by side (their serial parts overlap, the results are the same).
    let errors = || {
        let mut r = vec![0.0; s.data.bins.len()];
        let mut j = DMatrix::zeros(s.data.bins.len(), p);
        problem::jacobian_into(&s.data, id, &fit.x, &mut r, &mut j);
        let cov0 = covariance::covariance(&j, s2);
        // theta_z of a nearly isotropic lobe: the anisotropy that locates the axes is below 3 of its
        // standard errors (THETA_Z_SE_MAX), so the angle is noise, not a measurement with an uncertainty.
        let tz_free: Vec<bool> =
            (0..p).map(|a| id.param_names()[a] == "theta_z" && !cov0.undetermined[a] && !(se_of(&cov0, a) <= THETA_Z_SE_MAX)).collect();
        // The other parameters' errors are then those at the reported theta_z (its column dropped): an
        // unlocated theta_z trades off against the skew angles, which would otherwise inherit its spread.
        let cov = if tz_free.iter().any(|t| *t) {
            for (a, _) in tz_free.iter().enumerate().filter(|(_, t)| **t) {
                j.column_mut(a).fill(0.0);
            }
            covariance::covariance(&j, s2)
        } else {
            cov0.clone()
        };
        (cov0, tz_free, cov)
    };
    // The error against the data of the model as the bins see it (smoothed by a modelled rounding), and
    // its counting noise (used only when that error is defined).
    let seen = objective::Seen { model: &model, rounding: s.data.rounding.as_ref() };
    let against_data = || {
        rayon::join(
            || rayon::join(|| verdict::data_dispersion(ndf, s.data.max_theta), || metric::delta_to_data(&seen, ndf)),
            || metric::counting_noise2(&seen, ndf),
        )
    };
    let ((cov0, tz_free, cov), ((dispersion, delta_data), noise2)) = rayon::join(errors, against_data);
    let tz_se: Vec<f64> = (0..p).map(|a| se_of(&cov0, a)).collect();
    let unident: Vec<bool> = (0..p).map(|a| !fit.delta && (cov0.undetermined[a] || tz_free[a])).collect();
    let se: Vec<Option<f64>> = (0..p).map(|a| (!unident[a] && !fit.delta).then(|| se_of(&cov, a))).collect();
    let correlation: Vec<Vec<Option<f64>>> = (0..p)
        .map(|a| {
            (0..p)
                .map(|b| {
                    let ok = !unident[a] && !unident[b] && !fit.delta;
                    let den = (cov.cov[(a, a)] * cov.cov[(b, b)]).sqrt();
                    // The sign of g (always positive) does not change correlations.
                    (ok && den > 0.0).then(|| (cov.cov[(a, b)] / den).clamp(-1.0, 1.0))
                })
                .collect()
        })
        .collect();
    let mut unidentified = Vec::new();
    for (a, u) in unident.iter().enumerate() {
        let name = id.param_names()[a];
        if cov0.undetermined[a] && !fit.delta {
            warnings
                .push(format!("{id}: {name} is not determined by the data (a null direction of the Jacobian; its standard error is null)"));
        } else if *u {
            warnings.push(format!(
                "{id}: {name} is not identified: its standard error {:.3} rad exceeds 1/6 (the anisotropy that locates the axes is below 3 standard errors: a nearly isotropic lobe); the value is kept, its standard error is reported as null",
                tz_se[a]
            ));
        }
        if *u {
            unidentified.push(name.to_string());
        }
    }
    let max_count = ndf.bins.iter().map(|b| b.count).max().unwrap_or(0) as f64;
    let specular = max_count > 0.5 * s.data.n_total;
    if specular {
        warnings.push("specular: over half of the normals fall in one NDF bin; alpha is bounded by the bin size, not measured".into());
    }
    let delta_excess = delta_data.and_then(|d| verdict::excess_delta(d, noise2));
    let evidence = verdict::Evidence {
        n_params: p,
        n_samples: s.data.n,
        n_samples_total: s.data.n_total,
        n_bins_nonzero: k,
        reduced_chi2: reduced,
        dispersion,
        delta_excess,
        specular,
        converged: fit.local.converged || fit.delta,
        tolerance: opts.tolerance,
    };
    let (verdict, reasons) = verdict::judge(ndf, &evidence);
    // Every warning of the NDF stage reaches the fit; a verdict other than ok says why there too.
    let mut warnings: Vec<String> = ndf.warnings.iter().cloned().chain(warnings).collect();
    // An `ok` fit's reason (a difference within the tolerance) stays in `quality.reasons` alone.
    let new: Vec<String> =
        reasons.iter().filter(|r| verdict != verdict::Verdict::Ok && !warnings.contains(r)).map(|r| format!("{verdict}: {r}")).collect();
    warnings.extend(new);
    let matrix_a =
        model.matrix_a().map(|a| [[a[(0, 0)], a[(0, 1)], a[(0, 2)]], [a[(1, 0)], a[(1, 1)], a[(1, 2)]], [a[(2, 0)], a[(2, 1)], a[(2, 2)]]]);
    Ok(FitReport {
        schema: report::SCHEMA.to_string(),
        model: id,
        params: names(id, &pv),
        matrix_a,
        axes: model.canonical().axes(),
        input: None,
        rounding: s.data.rounding.clone(),
        std_errors: id.param_names().iter().zip(&se).map(|(n, v)| (n.to_string(), *v)).collect(),
        unidentified,
        param_order: id.param_names().iter().map(|n| n.to_string()).collect(),
        correlation,
        specular,
        quality: Quality {
            objective: opts.objective.as_str().into(),
            objective_value: fit.f,
            dof,
            reduced_chi2: reduced,
            n_bins: s.data.n_residual_bins,
            n_bins_nonzero: k,
            n_samples: s.data.n,
            n_samples_total: s.data.n_total,
            max_theta_deg: s.data.max_theta.to_degrees(),
            tail: Some(s.data.tail.clone()),
            delta_data,
            rank: cov.rank,
            condition: cov.condition.is_finite().then_some(cov.condition),
            dispersion,
            delta_excess,
            verdict,
            reasons,
        },
        solver: SolverInfo {
            name: opts.solver.as_str().into(),
            termination: fit.local.termination.clone(),
            converged: fit.local.converged,
            evaluations: fit.evaluations,
            starts: fit.start_objectives.len(),
            best_start: fit.best_start,
            start_objectives: fit.start_objectives.clone(),
        },
        timings: Timings { read_ms: None, ndf_ms: None, fit_ms, optics_ms: None },
        selection: None,
        optics: None,
        warnings,
    })
}

/// Fit model `id` to `ndf`. The result is canonical; non-convergence is reported in the result
/// (`solver.converged`, `warnings`), an error only when no usable fit exists.
pub fn fit_model(ndf: &EmpiricalNdf, id: ModelId, opts: &FitOptions) -> Result<FitReport> {
    let t0 = Instant::now();
    let phase = crate::phases::phase("fit.session");
    let s = Session::new(ndf, opts)?;
    drop(phase);
    let phase = crate::phases::phase("fit.solve");
    let fit = fit_chain(&s, id, opts)?;
    drop(phase);
    let _p = crate::phases::phase("fit.report");
    build_report(ndf, &s, fit, opts, 0.0).map(|mut r| {
        r.timings.fit_ms = t0.elapsed().as_secs_f64() * 1e3;
        r
    })
}

/// Choose the model a scene requires: the ladder of the models the table puts in `auto`, climbed one
/// step at a time (a rung, its depth in the table's parent tree, and within it a parameter count) while no
/// model fitted so far is within the tolerance on the NDF error beyond counting noise
/// ([`FitOptions::tolerance`], `verdict::excess_delta`); the models of a step are fitted side by side.
///
/// The choice is the rule `scale` uses (`verdict::select`), at the scan's own footprint: the candidates
/// ordered simplest first (rung, then parameters, then error), the first within the tolerance, or when
/// every model is visibly off, the first whose error exceeds the smallest by no more than the tolerance
/// (in quadrature): the simplest a renderer cannot tell from the closest. The likelihood is a guard, not the
/// decider: a model enters the choice only when its quasi-likelihood BIC (`qbic`, `F / c_data + p ln N`
/// with the data's own overdispersion) is below its parent's, so the data support its added parameters.
pub fn fit_auto(ndf: &EmpiricalNdf, opts: &FitOptions) -> Result<FitReport> {
    ladder(ndf, opts, true, None)
}

/// [`fit_auto`] with the answer decided above the fit by `judge` (the pipeline's render choice): the
/// report holds the lobe it answers with, or its closest lobe when it answers with none. When it answers
/// with none and the ladder stopped early (a model within the NDF tolerance), the whole ladder is fitted
/// and offered again.
pub fn fit_auto_with(ndf: &EmpiricalNdf, opts: &FitOptions, judge: &dyn Decide) -> Result<FitReport> {
    ladder(ndf, opts, true, Some(judge))
}

/// [`fit_auto`] on the one-lobe rungs alone, for a scan that light sees as a mirror (the answer's own
/// module, `answer::optics`): the ladder then describes the slopes and decides nothing a renderer shows,
/// and a second lobe, the costliest fits of the ladder, would only describe them in more detail. The
/// two-lobe models are listed in `selection.not_fitted`, and the ladder's sentence says why.
pub fn fit_auto_one_lobe(ndf: &EmpiricalNdf, opts: &FitOptions) -> Result<FitReport> {
    Ladder { lazy: true, one_lobe: true }.run(ndf, opts, None)
}

/// One lobe `auto` fitted, as a [`Decide`] judge sees it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Offered {
    /// The fitted lobe.
    pub model: Model,
    /// Whether the likelihood guard supports its parameters (an unsupported lobe is not an answer).
    pub supported: bool,
    /// Its NDF error against the data (`quality.delta_data`).
    pub delta_data: Option<f64>,
}

/// A judge's answer: `answer` indexes the offered lobe a renderer should use (`None`: no lobe, the scan's
/// own table), `reported` the lobe the fit report holds (the answer, else the closest).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Decision {
    /// The answer's index among the offered lobes, or `None` for the table.
    pub answer: Option<usize>,
    /// The index of the lobe the report holds.
    pub reported: usize,
}

/// What decides `auto`'s answer among the fitted lobes (the render choice, `answer::choice`): called with
/// the ladder's lobes simplest first (rung, parameters, NDF error).
pub trait Decide: Sync {
    /// The answer among `offered` (never empty), for an NDF whose bins the fit trusted up to
    /// `max_theta_deg`.
    fn decide(&self, offered: &[Offered], max_theta_deg: f64) -> Result<Decision>;
}

/// The lobe that fills a scan's table beyond its trusted bins and under its noisy ones: of `deltas` (the
/// lobes' NDF errors, simplest first), the smallest, the first on a tie; the first when none is known.
pub fn table_lobe(deltas: &[Option<f64>]) -> usize {
    let key = |k: usize| deltas[k].filter(|d| d.is_finite()).unwrap_or(f64::INFINITY);
    (0..deltas.len()).fold(0, |best, k| if key(k) < key(best) { k } else { best })
}

/// A fitted candidate of `auto`, or why it is left out: parameters outside the model's domain, or no fit.
fn candidate(r: Result<Fitted>) -> (Option<Fitted>, Option<String>) {
    match r {
        Ok(f) if Model::from_params(f.id, &public(&f)).is_ok() => (Some(f), None),
        Ok(f) => (None, Some(format!("{}: fitted parameters out of the model's domain; candidate dropped", f.id))),
        Err(e) => (None, Some(format!("candidate dropped: {e}"))),
    }
}

/// A model's rung in the `auto` ladder: its depth in the table's parent tree.
pub fn rung(id: ModelId) -> usize {
    std::iter::successors(id.parent(), |p| p.parent()).count()
}

/// Fit `id` on its rung from its parent's fit, the way [`fit_chain`] grows it; a model whose parent is
/// not in the ladder brings its own chain.
fn fit_on_rung(s: &Session, id: ModelId, parent: Option<&Fitted>, opts: &FitOptions) -> Result<Fitted> {
    let spec = id.spec();
    match parent {
        None if spec.parent.is_none() => fit_grown(s, id, None, opts),
        None => fit_chain(s, id, opts),
        Some(p) if spec.is_mixture() => mixture::fit_mixture(s, id, p, opts),
        Some(p) if spec.lobes[0].form == Form::Full => fit_ellipsoid(s, id, p, opts),
        Some(p) => fit_grown(s, id, Some(p), opts),
    }
}

/// [`fit_auto`], lazily (`lazy`: a step is fitted only while no model before it is within the tolerance)
/// or fitting every step; the choice is the same (the steps after the first model within the tolerance
/// come after it in the order of the choice). Public so a test can hold the two to the same choice.
pub fn fit_auto_pruned(ndf: &EmpiricalNdf, opts: &FitOptions, lazy: bool) -> Result<FitReport> {
    ladder(ndf, opts, lazy, None)
}

/// The ladder of [`fit_auto_pruned`], its answer decided by `judge` when there is one.
fn ladder(ndf: &EmpiricalNdf, opts: &FitOptions, lazy: bool, judge: Option<&dyn Decide>) -> Result<FitReport> {
    Ladder { lazy, one_lobe: false }.run(ndf, opts, judge)
}

/// How far the ladder climbs: `lazy`, a step only while no model before it is within the tolerance;
/// `one_lobe`, the one-lobe rungs alone ([`fit_auto_one_lobe`]).
#[derive(Debug, Clone, Copy)]
struct Ladder {
    lazy: bool,
    one_lobe: bool,
}

impl Ladder {
    fn run(self, ndf: &EmpiricalNdf, opts: &FitOptions, judge: Option<&dyn Decide>) -> Result<FitReport> {
        let Ladder { lazy, one_lobe } = self;
        let t0 = Instant::now();
        let phase = crate::phases::phase("fit.session");
        let s = Session::new(ndf, opts)?;
        drop(phase);
        // The ladder's fits, their reports and the choice.
        let _p = crate::phases::phase("fit.ladder");
        // A candidate that cannot be fitted is left out (and said so); only when none is usable is it an error.
        let mut warnings = Vec::new();
        // A delta NDF: every model is at its floor; the simplest wins (only the first rung is fitted).
        let delta = s.data.k_nonzero == 1;
        // The ladder's steps: its models grouped by rung, then by parameter count, simplest first (the order
        // of the choice, so a step left out can only hold models the choice would rank after one within the
        // tolerance).
        let mut steps: Vec<(usize, usize)> =
            ModelId::EVERY.iter().filter(|id| id.spec().in_auto).map(|&id| (rung(id), id.n_params())).collect();
        steps.sort();
        steps.dedup();
        let k = s.data.k_nonzero;
        let n = s.data.n;
        let mut fits: Vec<Fitted> = Vec::new();
        let mut deltas: Vec<Option<f64>> = Vec::new();
        let mut errors: Vec<Option<f64>> = Vec::new();
        let mut not_fitted: Vec<ModelId> = Vec::new();
        let mut second_lobes: Vec<ModelId> = Vec::new();
        let mut c_data = 1.0;
        for (r, p) in steps {
            let (here, two): (Vec<ModelId>, Vec<ModelId>) = ModelId::EVERY
                .iter()
                .copied()
                .filter(|id| id.spec().in_auto && (rung(*id), id.n_params()) == (r, p))
                .partition(|id| !(one_lobe && id.spec().is_mixture()));
            second_lobes.extend(two);
            if here.is_empty() {
                continue;
            }
            // Climb only while it pays: no model so far is within the tolerance.
            let within = errors.iter().zip(&fits).any(|(e, f)| e.is_some_and(|e| e <= opts.tolerance) && guard_ok(&fits, f, c_data, n));
            if (lazy && within) || (delta && r > 0) {
                not_fitted.extend(here);
                continue;
            }
            let parents: Vec<Option<&Fitted>> = here.iter().map(|id| id.parent().and_then(|p| fits.iter().find(|f| f.id == p))).collect();
            // A model whose parent is in the ladder but was not fitted (dropped) cannot grow from it.
            let fitted: Vec<Option<(Option<Fitted>, Option<String>)>> = {
                use rayon::prelude::*;
                here.par_iter()
                    .zip(parents.par_iter())
                    .map(|(&id, &p)| {
                        let orphan = id.parent().is_some_and(|q| q.spec().in_auto) && p.is_none();
                        if delta {
                            Some((Some(delta_fit(&s, id)), None))
                        } else if orphan {
                            None
                        } else {
                            Some(candidate(fit_on_rung(&s, id, p, opts)))
                        }
                    })
                    .collect()
            };
            for (id, f) in here.iter().zip(fitted) {
                let Some((f, w)) = f else {
                    warnings.push(format!("{id}: not fitted, its parent {} gave no usable fit", id.parent().map_or("", |p| p.as_str())));
                    continue;
                };
                warnings.extend(w);
                if let Some(f) = f {
                    let m = Model::from_params(f.id, &public(&f)).ok();
                    let seen = m.as_ref().map(|m| objective::Seen { model: m, rounding: s.data.rounding.as_ref() });
                    let d = seen.as_ref().and_then(|m| metric::delta_to_data(m, ndf));
                    deltas.push(d);
                    errors.push(d.and_then(|d| verdict::excess_delta(d, metric::counting_noise2(seen.as_ref()?, ndf))));
                    fits.push(f);
                }
            }
            if r == 0 {
                // The guard's overdispersion: the data's own, or (no dispersion split) the first rung's.
                let c_first = qbic::overdispersion(fits.iter().filter_map(|f| reduced(f, k)));
                c_data = mixture::data_c(ndf, &s, c_first);
            }
            // No model can leave less than the data's noise, so the smallest deviance per dof so far bounds it:
            // on a smooth surface the dispersion split reads tens and would refuse every added parameter.
            let c_fits = fits.iter().filter_map(|f| reduced(f, k)).fold(f64::INFINITY, f64::min);
            c_data = c_data.min(c_fits).max(1.0);
        }
        if fits.is_empty() {
            return Err(Error::new(ErrorKind::Numerical, format!("no model could be fitted ({})", warnings.join("; "))));
        }
        let idx = |id: ModelId| fits.iter().position(|f| f.id == id);
        let supported: Vec<bool> = fits.iter().map(|f| guard_ok(&fits, f, c_data, n)).collect();
        // Simplest first: rung, parameters, error (unknown errors last), then the table's order.
        let mut order: Vec<usize> = (0..fits.len()).collect();
        let key = |i: usize| errors[i].filter(|e| e.is_finite()).unwrap_or(f64::INFINITY);
        order.sort_by(|&a, &b| {
            (rung(fits[a].id), fits[a].id.n_params())
                .cmp(&(rung(fits[b].id), fits[b].id.n_params()))
                .then(key(a).total_cmp(&key(b)))
                .then(fits[a].id.cmp(&fits[b].id))
        });
        let priced: Vec<f64> = order.iter().map(|&i| if supported[i] { key(i) } else { f64::INFINITY }).collect();
        let (by_ndf, within) = match verdict::select(&priced, opts.tolerance) {
            Some((j, w)) => (order[j], w),
            // No error is known (a delta NDF, or no bin with a count): the simplest supported model.
            None => (order.iter().copied().find(|&i| supported[i]).unwrap_or(order[0]), false),
        };
        let chosen = match judge {
            None => by_ndf,
            Some(judge) => {
                let offered: Vec<Offered> = order
                    .iter()
                    .map(|&i| {
                        Ok(Offered {
                            model: Model::from_params(fits[i].id, &public(&fits[i]))?,
                            supported: supported[i],
                            delta_data: deltas[i],
                        })
                    })
                    .collect::<Result<_>>()?;
                let decision = judge.decide(&offered, s.data.max_theta.to_degrees())?;
                // No lobe fitted so far renders close enough, and the ladder stopped early: fit it whole.
                if decision.answer.is_none() && lazy && !not_fitted.is_empty() && !delta {
                    drop(_p);
                    return Ladder { lazy: false, ..self }.run(ndf, opts, Some(judge));
                }
                order[decision.reported.min(order.len() - 1)]
            }
        };
        let table = order[table_lobe(&order.iter().map(|&i| deltas[i]).collect::<Vec<_>>())];
        let table_id = fits[table].id;
        let c = qbic::overdispersion(fits.iter().filter_map(|f| reduced(f, k)));
        let crit: Vec<f64> = fits.iter().map(|f| qbic::qbic(f.f, c, f.id.n_params(), n)).collect();
        let crit_data: Vec<f64> = fits.iter().map(|f| qbic::qbic(f.f, c_data, f.id.n_params(), n)).collect();
        let candidates: Vec<Candidate> = order
            .iter()
            .map(|&i| {
                let f = &fits[i];
                let par = f.id.parent();
                let pi = par.and_then(idx);
                Candidate {
                    model: f.id,
                    params: names(f.id, &public(f)),
                    n_params: f.id.n_params(),
                    objective_value: f.f,
                    reduced_chi2: reduced(f, k),
                    delta_data: deltas[i],
                    criterion: crit[i],
                    parent: par,
                    d_criterion: pi.map(|j| crit[i] - crit[j]),
                    d_delta_data: pi.and_then(|j| Some(deltas[i]? - deltas[j]?)),
                    converged: f.local.converged,
                    qbic_data: Some(crit_data[i]),
                    deviance_per_dof: reduced(f, k),
                    gain_per_param: pi.map(|j| {
                        let dp = (f.id.n_params() as f64 - fits[j].id.n_params() as f64).max(1.0);
                        (fits[j].f - f.f) / (c_data * dp)
                    }),
                    rung: Some(rung(f.id)),
                    delta_excess: errors[i],
                    effect: pi.and_then(|j| Some(errors[j]? - errors[i]?)),
                    supported: Some(supported[i]),
                    render_error: None,
                }
            })
            .collect();
        let summary = ladder_summary(&fits, &errors, &supported, by_ndf, within, opts.tolerance, [&not_fitted, &second_lobes]);
        not_fitted.extend(second_lobes);
        let best = fits.into_iter().nth(chosen).expect("chosen indexes the fits");
        let mut rep = build_report(ndf, &s, best, opts, 0.0)?;
        rep.warnings.extend(warnings);
        rep.selection = Some(Selection {
            criterion: "qbic".into(),
            overdispersion: c,
            candidates,
            data_overdispersion: Some(c_data),
            ladder: Some(summary),
            tolerance: Some(opts.tolerance),
            not_fitted,
            answer: None,
            render_error: None,
            render_tolerance: None,
            render_noise: None,
            scenes: Vec::new(),
            table_lobe: Some(table_id),
        });
        rep.timings.fit_ms = t0.elapsed().as_secs_f64() * 1e3;
        Ok(rep)
    }
}

/// `F / (K - p - 1)`, when there are degrees of freedom.
fn reduced(f: &Fitted, k: usize) -> Option<f64> {
    let dof = k as f64 - f.id.n_params() as f64 - 1.0;
    (dof > 0.0).then(|| f.f / dof)
}

/// The likelihood guard: a model whose parent was fitted enters the choice only when its criterion
/// `F / c_data + p ln N` is below the parent's (the data support the added parameters).
fn guard_ok(fits: &[Fitted], f: &Fitted, c_data: f64, n: f64) -> bool {
    match f.id.parent().and_then(|p| fits.iter().find(|g| g.id == p)) {
        Some(p) => qbic::qbic(f.f, c_data, f.id.n_params(), n) < qbic::qbic(p.f, c_data, p.id.n_params(), n),
        None => true,
    }
}

/// One sentence on the ladder: the choice and why, what each rung bought, and what was not fitted.
fn ladder_summary(
    fits: &[Fitted],
    errors: &[Option<f64>],
    supported: &[bool],
    chosen: usize,
    within: bool,
    tolerance: f64,
    [not_fitted, second_lobes]: [&[ModelId]; 2],
) -> String {
    let pct = |e: Option<f64>| e.map_or("unknown".to_string(), |e| format!("{:.1}%", 100.0 * e));
    let id = fits[chosen].id;
    let mut out = if within {
        format!(
            "{id} (rung {}): NDF error beyond counting noise {}, within the tolerance {:.1}%",
            rung(id),
            pct(errors[chosen]),
            100.0 * tolerance
        )
    } else {
        match errors[chosen] {
            Some(e) => format!(
                "{id} (rung {}): no model is within the tolerance {:.1}%; {id}, NDF error beyond counting noise {:.1}%, is the simplest within the tolerance of the closest",
                rung(id),
                100.0 * tolerance,
                100.0 * e
            ),
            None => format!("{id}: no NDF error could be measured; the simplest model is kept"),
        }
    };
    let effects: Vec<String> = fits
        .iter()
        .enumerate()
        .filter_map(|(i, f)| {
            let p = f.id.parent()?;
            let j = fits.iter().position(|g| g.id == p)?;
            let guard = if supported[i] { "" } else { ", not supported by the likelihood" };
            Some(format!(
                "{} over {p}: {}{guard}",
                f.id,
                errors[j].zip(errors[i]).map_or("unknown".into(), |(a, b)| format!("{:+.1}%", 100.0 * (b - a)))
            ))
        })
        .collect();
    if !effects.is_empty() {
        out += &format!("; each rung's effect on the error: {}", effects.join(", "));
    }
    if !not_fitted.is_empty() {
        let ids: Vec<&str> = not_fitted.iter().map(|m| m.as_str()).collect();
        out += &format!("; not fitted (a model below them is within the tolerance, or the NDF is a delta): {}", ids.join(", "));
    }
    if !second_lobes.is_empty() {
        let ids: Vec<&str> = second_lobes.iter().map(|m| m.as_str()).collect();
        out += &format!(
            "; not fitted (light sees a mirror: the lobes describe the slopes, and a second lobe nothing a renderer shows): {}",
            ids.join(", ")
        );
    }
    out
}
