//! Both routes to the NDF at each footprint, and the recommendation (data_formats/scale.md sec. 4, 9).

use nalgebra::Matrix2;

use super::footprint::{footprint_field, footprint_stats, kernel_sigma, slope_field, FootprintStats};
use super::ndf_at::{bin_slopes, counts_on, gaussian_slopes, sample_slopes, sample_slopes_with, slope_moments, Blur, SlopeMoments};
use crate::error::{Error, ErrorKind, Result};
use crate::models::roughness::{
    add_kernel_matrix, aniso_params, filter_isotropic, model_from_slope_form, skew_offset, slope_form, IsoRule, SlopeForm,
};
use crate::models::{Model, ModelId, Ndf};
use crate::ndf::{EmpiricalNdf, NdfOptions};
use crate::scan::Heightfield;

/// A fitted model and what the information criterion needs, as the fitting code reports them.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fitted {
    /// The fitted model.
    pub model: Model,
    /// The objective `F` at the optimum (Poisson deviance, objective.md), if known.
    pub objective: Option<f64>,
    /// `F / (K - p)`, if known.
    pub reduced_chi2: Option<f64>,
    /// Number of samples `N` binned.
    pub n_samples: f64,
}

pub use crate::fit::qbic::qbic;

/// Fits a model of a given kind to an empirical NDF (the fitter of `src/fit/`, or a test double).
pub trait Fitter: Sync {
    /// Fit a model of kind `id` to `ndf`.
    fn fit(&self, ndf: &EmpiricalNdf, id: ModelId) -> Result<Fitted>;
}

/// What `analyze` computes and how.
#[derive(Debug, Clone, PartialEq)]
pub struct ScaleOptions {
    /// Footprints `F` (metres), each > 0.
    pub footprints: Vec<f64>,
    /// Models to carry through both routes.
    pub models: Vec<ModelId>,
    /// Blur samples per point for the empirical route (data_formats/scale.md sec. 4).
    pub samples_per_point: usize,
    /// Cells across the NDF's Lambert disk (`src/ndf`); None chooses from the sample count.
    pub bins: Option<usize>,
    /// Seed of the blur samples.
    pub seed: u64,
    /// Per-footprint covariances (S1, default) or the one mean covariance (S1').
    pub blur: Blur,
}

impl Default for ScaleOptions {
    fn default() -> Self {
        ScaleOptions {
            footprints: vec![],
            // The single lobes a renderer implements (a lobe without one is priced against them by `fit`).
            models: ModelId::singles().filter(|id| id.spec().lobes[0].kernel.renderer().is_some()).collect(),
            samples_per_point: 4,
            bins: None,
            seed: 1,
            blur: Blur::PerFootprint,
        }
    }
}

/// The NDF difference metric of objective.md between a model and an empirical NDF (reference), and its
/// counting-noise floor and excess (data_formats/scale.md sec. 9).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Delta {
    /// `delta(D_model; D_emp)` over the non-empty bins.
    pub delta: f64,
    /// `sqrt(sum w/c / sum w)`: what Poisson noise alone gives (a lower bound: neighbouring slopes correlate).
    pub noise: f64,
    /// `sqrt(max(delta^2 - noise^2, 0))`: the model's own error.
    pub excess: f64,
}

/// [`Delta`] of `model` against `ndf`. `halves`: the counts of two disjoint halves of the samples on the
/// same bins (data_formats/scale.md sec. 9); their disagreement measures the histogram's noise including
/// the correlation of neighbouring slopes, which the Poisson term alone misses. The larger of the two
/// noise estimates is used.
pub fn delta(model: &impl Ndf, ndf: &EmpiricalNdf, halves: Option<(&[u64], &[u64])>) -> Delta {
    let n = ndf.n_samples.max(1) as f64;
    let (n1, n2) = halves.map_or((0.0, 0.0), |(a, b)| (a.iter().sum::<u64>() as f64, b.iter().sum::<u64>() as f64));
    let (mut sw, mut s2, mut sn, mut ss) = (0.0, 0.0, 0.0, 0.0);
    for (k, b) in ndf.bins.iter().enumerate() {
        if b.count == 0 || b.proj_solid_angle <= 0.0 {
            continue;
        }
        let w = b.count as f64 / n; // D_ref W_k
        let r = model.d(b.m) / b.d - 1.0;
        sw += w;
        s2 += w * r * r;
        sn += w / b.count as f64;
        if let Some((h1, h2)) = halves {
            if n1 > 0.0 && n2 > 0.0 {
                // Relative half-difference of the two halves' D in this bin: its square estimates the
                // relative variance of the full-sample D (each half has twice the variance of the whole).
                let (d1, d2) = (h1[k] as f64 / n1, h2[k] as f64 / n2);
                let rel = 0.5 * (d1 - d2) / (b.count as f64 / n);
                ss += w * rel * rel;
            }
        }
    }
    // No data: the metric is undefined; report infinity so no model passes on nothing.
    if sw <= 0.0 {
        return Delta { delta: f64::INFINITY, noise: 0.0, excess: f64::INFINITY };
    }
    let d2 = s2 / sw;
    let noise2 = (sn / sw).max(ss / sw);
    Delta { delta: d2.sqrt(), noise: noise2.sqrt(), excess: crate::fit::verdict::beyond_noise(d2, noise2) }
}

/// One route's result for one model at one footprint.
#[derive(Debug, Clone, PartialEq)]
pub struct RouteResult {
    /// The model (None when the route failed, see `error`).
    pub model: Option<Model>,
    /// Information criterion of the fit (empirical route).
    pub ic: Option<f64>,
    /// Error against the empirical NDF at F.
    pub delta: Option<Delta>,
    /// Where the model came from: `fit` (fitted at F), `fit+kernel` (fitted to `h_F`, plus `2 Sigma_F`),
    /// `moments+kernel` (moment estimate of `h_F`'s slopes, plus `2 Sigma_F`).
    pub source: &'static str,
    /// Why the route failed, if it did.
    pub error: Option<String>,
}

/// Both routes for one model at one footprint.
#[derive(Debug, Clone, PartialEq)]
pub struct ModelAtFootprint {
    /// The model kind.
    pub id: ModelId,
    /// Fit to the NDF at F.
    pub empirical: RouteResult,
    /// Tokuyoshi: fit to `h_F`'s NDF plus `2 Sigma_F`.
    pub analytic: RouteResult,
    /// For isotropic models: the filtered alpha by Tokuyoshi eq. 10 and eq. 13 from the analytic base.
    pub tokuyoshi_iso: Option<(f64, f64)>,
    /// `||A2_emp - A2_ana|| / ||A2_emp||` (Frobenius; `mu` included as `mu mu^T` for the ellipsoid):
    /// how far the two routes' slope forms lie apart.
    pub route_gap: Option<f64>,
    /// Why the analytic route cannot be trusted for this model at this footprint, in plain words; empty
    /// when every condition of its theory holds (data_formats/scale.md sec. 4, "Where the analytic route
    /// holds").
    pub analytic_caveats: Vec<String>,
}

impl ModelAtFootprint {
    /// The analytic route is trustworthy here: every condition of its theory holds (no caveat).
    pub fn analytic_trusted(&self) -> bool {
        self.analytic_caveats.is_empty()
    }
}

/// The kernel `N(0, Sigma_F)` expressed as a GGX roughness matrix: the GGX fitted to a sample of the
/// kernel itself (data_formats/scale.md sec. 4a). GGX's `A` is no covariance (GGX has no finite slope
/// variance), so Tokuyoshi's `2 Sigma` is in Beckmann units; a GGX fitted to a Gaussian of roughness
/// matrix `2 Sigma` has a roughness matrix `kappa 2 Sigma` with `kappa` about 0.55 under the Poisson
/// deviance, and adding `2 Sigma` to a GGX base over-filters by `1 / kappa` once the kernel dominates.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GgxKernel {
    /// Roughness matrix of the GGX fitted to the kernel.
    pub matrix: Matrix2<f64>,
    /// `kappa = tr(matrix) / tr(2 Sigma_F)`.
    pub ratio: f64,
}

/// Everything computed at one footprint.
#[derive(Debug, Clone, PartialEq)]
pub struct FootprintResult {
    /// Kernel covariances (S2, S3).
    pub stats: FootprintStats,
    /// Moments of the NDF at F (empirical route samples).
    pub at_f: SlopeMoments,
    /// Moments of the filtered surface's slopes `s_F`.
    pub resolved: SlopeMoments,
    /// `(alpha_x, alpha_y, theta_z)` of the pixel roughness matrix `2 Sigma_F` (scale.md sec. 3).
    pub pixel_roughness: Option<(f64, f64, f64)>,
    /// Per model.
    pub models: Vec<ModelAtFootprint>,
    /// The empirical NDF at F (kept for the recommendation and plots).
    pub ndf_at: EmpiricalNdf,
    /// Per bin of `ndf_at`, the count from the footprints of the scan's lower half (rows): a spatially
    /// disjoint split whose two halves measure the NDF's own noise.
    pub first_half: Vec<u64>,
    /// Coefficient of variation of `tr Sigma_w(x0)` over the points: large values make the mixture (S1)
    /// heavier-tailed than one Gaussian of covariance `Sigma_F` (scale.md sec. 4b).
    pub sigma_w_spread: f64,
    /// Where the Tokuyoshi route is not expected to match, in words (scale.md sec. 4).
    pub theory_notes: Vec<String>,
    /// The kernel in GGX units (None when no GGX-shaped model was run, the kernel is below the alpha
    /// range, or its fit failed; the GGX-shaped analytic routes then add Tokuyoshi's literal `2 Sigma_F`).
    pub ggx_kernel: Option<GgxKernel>,
    /// Independent footprints in the scan, about `n_points dx dy / (pi F^2)` (at least 1): the sample
    /// size behind the moments of `h_F`.
    pub n_independent: f64,
    /// The analytic route holds for these models here (scale.md sec. 4): a plain summary.
    pub analytic_summary: String,
}

/// Conditions of the analytic route's theory found violated at one footprint (scale.md sec. 4).
#[derive(Debug, Clone, Default)]
struct Violations {
    /// Applies to every model.
    all: Vec<String>,
    /// Applies to GGX-shaped models only (ggx, ggx-aniso, ellipsoid).
    ggx: Vec<String>,
}

/// Run both routes at every footprint of `opts` on a heightfield.
pub fn analyze(hf: &Heightfield, opts: &ScaleOptions, fitter: Option<&dyn Fitter>) -> Result<Vec<FootprintResult>> {
    if opts.footprints.is_empty() {
        return Err(Error::invalid("no footprint given"));
    }
    if let Some(f) = opts.footprints.iter().find(|f| !(f.is_finite() && **f >= 0.0)) {
        return Err(Error::invalid(format!("footprint must be finite and >= 0, got {f}")));
    }
    if !(1..=64).contains(&opts.samples_per_point) {
        return Err(Error::invalid(format!("samples per point must be in 1..=64, got {}", opts.samples_per_point)));
    }
    let (sx, sy) = slope_field(hf);
    if sx.iter().all(|v| !v.is_finite()) {
        return Err(Error::new(ErrorKind::BadData, "no valid slope: every 3x3 stencil touches a hole or the border"));
    }
    let mut out = Vec::with_capacity(opts.footprints.len());
    for (k, &fp) in opts.footprints.iter().enumerate() {
        let ff = footprint_field(hf.nx, hf.ny, hf.dx, hf.dy, &sx, &sy, kernel_sigma(fp))?;
        let stats = footprint_stats(&ff, &sx, &sy, fp)?;
        let seed = opts.seed.wrapping_add(k as u64);
        let s_res = sample_slopes(&ff, 1, false, seed);
        let s_at = sample_slopes_with(&ff, opts.samples_per_point, Some(opts.blur), seed);
        let resolved = slope_moments(&s_res)?;
        let at_f = slope_moments(&s_at)?;
        // One grid size for both NDFs, chosen from the number of footprints (as `ndfit ndf` chooses it
        // from the number of slopes), not from the blur samples: extra samples per point only lower
        // the Monte Carlo noise, they must not refine the bins a misspecified model is judged on.
        let cells = opts.bins.unwrap_or_else(|| NdfOptions::default().cells_for(s_res.len() as u64));
        let ndf_res = bin_slopes(&s_res, Some(cells))?;
        let ndf_at = bin_slopes(&s_at, Some(cells))?;
        // Split the samples into the footprints of the scan's lower and upper half (rows), spatially
        // disjoint, for the noise estimate of `delta`.
        let pts = ff.valid_points();
        let split = pts.iter().take_while(|&&p| p / hf.nx < hf.ny / 2).count() * opts.samples_per_point;
        let halves = (counts_on(&ndf_at, &s_at[..split]), counts_on(&ndf_at, &s_at[split..]));
        let first_half = halves.0.clone();
        let pixel_roughness = aniso_params(&(2.0 * stats.sigma_f)).ok();
        let traces: Vec<f64> = ff.valid_points().iter().map(|&p| ff.wxx[p] + ff.wyy[p]).collect();
        let tm = traces.iter().sum::<f64>() / traces.len().max(1) as f64;
        let tv = traces.iter().map(|t| (t - tm).powi(2)).sum::<f64>() / traces.len().max(1) as f64;
        // A footprint below the grid spacing has Sigma_w = 0 everywhere: no spread to speak of.
        let sigma_w_spread = if tm > 0.0 { tv.sqrt() / tm } else { 0.0 };
        // Independent footprints: one per kernel area pi (2 sigma_K)^2 = pi F^2 (at least one).
        let n_independent =
            (stats.n_points as f64 * hf.dx * hf.dy / (std::f64::consts::PI * fp * fp)).clamp(1.0, stats.n_points.max(1) as f64);
        // Share of the slope variance the kernel carries (S3); 0 for a flat scan.
        let share = if stats.cov_slopes.trace() > 0.0 { (stats.sigma_f.trace() / stats.cov_slopes.trace()).clamp(0.0, 1.0) } else { 0.0 };
        let viol = violations(&resolved, sigma_w_spread, share, opts.blur, n_independent);
        let mut theory_notes = viol.all.clone();
        theory_notes.extend(viol.ggx.iter().cloned());
        // GGX-shaped: a single lobe of the GGX kernel (the ellipsoid included), whose kernel is the GGX fitted to it.
        let ggx_family = |id: ModelId| {
            let s = id.spec();
            !s.is_mixture() && s.lobes[0].kernel == crate::models::table::Kernel::Ggx
        };
        let ggx_kernel = match fitter {
            Some(f) if opts.models.iter().any(|&id| ggx_family(id)) => {
                ggx_kernel(f, &stats.sigma_f, s_res.len(), cells, seed ^ 0x6b65_726e_656c)
            }
            _ => None,
        };
        if let Some(k) = ggx_kernel {
            theory_notes.push(format!(
                "GGX-shaped models (ggx, ggx-aniso, ellipsoid) add the kernel in their own units: the GGX fitted to the kernel N(0, Sigma_F) has kappa = {:.3} times Tokuyoshi's 2 Sigma_F (GGX's roughness is no variance)",
                k.ratio
            ));
        }
        let mut fitted: Vec<_> = opts
            .models
            .iter()
            .map(|&id| {
                let kernel = if ggx_family(id) { ggx_kernel.map(|k| k.matrix) } else { None };
                let ctx =
                    RouteCtx { stats: &stats, resolved: &resolved, ndf_res: &ndf_res, ndf_at: &ndf_at, halves: (&halves.0, &halves.1) };
                let mut m = model_at_footprint(id, &ctx, kernel, fitter);
                m.0.analytic_caveats =
                    caveats(&m.0, &viol, ggx_family(id), kernel.is_none() && stats.sigma_f.trace() > crate::models::ALPHA_MIN.powi(2));
                m
            })
            .collect();
        fill_ic(&mut fitted);
        let models: Vec<ModelAtFootprint> = fitted.into_iter().map(|(m, _)| m).collect();
        let analytic_summary = summary(&models);
        out.push(FootprintResult {
            stats,
            at_f,
            resolved,
            pixel_roughness,
            models,
            ndf_at,
            first_half,
            sigma_w_spread,
            theory_notes,
            ggx_kernel,
            n_independent,
            analytic_summary,
        });
    }
    Ok(out)
}

/// What one model's two routes need at one footprint.
struct RouteCtx<'a> {
    stats: &'a FootprintStats,
    resolved: &'a SlopeMoments,
    ndf_res: &'a EmpiricalNdf,
    ndf_at: &'a EmpiricalNdf,
    halves: (&'a [u64], &'a [u64]),
}

fn model_at_footprint(
    id: ModelId,
    ctx: &RouteCtx,
    ggx_kernel: Option<Matrix2<f64>>,
    fitter: Option<&dyn Fitter>,
) -> (ModelAtFootprint, Option<Fitted>) {
    let RouteCtx { stats, resolved, ndf_res, ndf_at, halves } = *ctx;
    let delta = |m: &Model| delta(m, ndf_at, Some(halves));
    let failed = |source, e: String| RouteResult { model: None, ic: None, delta: None, source, error: Some(e) };
    let empirical = match fitter.map(|f| f.fit(ndf_at, id)) {
        Some(Ok(f)) => {
            // The criterion needs the overdispersion of all candidates; `analyze` fills `ic` in.
            let r = RouteResult { model: Some(f.model), ic: None, delta: Some(delta(&f.model)), source: "fit", error: None };
            (r, Some(f))
        }
        Some(Err(e)) => (failed("fit", e.to_string()), None),
        None => (failed("fit", "no fitter available".into()), None),
    };
    let (empirical, fitted) = empirical;
    // Analytic route: base model of h_F, then + 2 Sigma_F (Tokuyoshi eq. 3).
    let base = match fitter.map(|f| f.fit(ndf_res, id)) {
        Some(Ok(f)) => Ok((f.model, if ggx_kernel.is_some() { "fit+ggx-kernel" } else { "fit+kernel" })),
        // The filtered surface can be too flat to fit (its NDF narrower than any model allows): fall back
        // on the moment estimate A = 2 Cov(s_F), the Beckmann maximum-likelihood value (scale.md sec. 4b).
        _ => model_from_slope_form(id, &SlopeForm { a2: 2.0 * resolved.cov, mu: resolved.mean })
            .map(|m| (m, if ggx_kernel.is_some() { "moments+ggx-kernel" } else { "moments+kernel" })),
    };
    let (analytic, tokuyoshi_iso) = match base {
        Ok((m, source)) => {
            let spec = m.id().spec();
            let iso = (!spec.is_mixture() && spec.lobes[0].form == crate::models::table::Form::Iso)
                .then(|| spec.parts(&m.params(), 0).alpha_x)
                .map(|a| (filter_isotropic(a, &stats.sigma_f, IsoRule::Eq10), filter_isotropic(a, &stats.sigma_f, IsoRule::Eq13)));
            // Tokuyoshi eq. 3: + 2 Sigma_F, or the same kernel in GGX units for GGX-shaped models (sec. 4a).
            let kernel = ggx_kernel.unwrap_or(2.0 * stats.sigma_f);
            match add_kernel_matrix(&m, &kernel) {
                Ok(f) => (RouteResult { model: Some(f), ic: None, delta: Some(delta(&f)), source, error: None }, iso),
                Err(e) => (failed(source, e.to_string()), iso),
            }
        }
        Err(e) => (failed("moments+kernel", e.to_string()), None),
    };
    let route_gap = match (empirical.model, analytic.model) {
        (Some(e), Some(a)) => match (slope_form(&e), slope_form(&a)) {
            (Ok(fe), Ok(fa)) => {
                let me = fe.a2 + fe.mu * fe.mu.transpose();
                let ma = fa.a2 + fa.mu * fa.mu.transpose();
                Some((me - ma).norm() / me.norm())
            }
            _ => None,
        },
        _ => None,
    };
    (ModelAtFootprint { id, empirical, analytic, tokuyoshi_iso, route_gap, analytic_caveats: Vec::new() }, fitted)
}

/// The GGX fitted to `n` samples of the kernel `N(0, Sigma_F)` on `cells` bins ([`GgxKernel`]). None when
/// the kernel is narrower than any model allows (a footprint below the grid spacing) or the fit fails.
fn ggx_kernel(fitter: &dyn Fitter, sigma_f: &Matrix2<f64>, n: usize, cells: usize, seed: u64) -> Option<GgxKernel> {
    let tr = sigma_f.trace();
    // Below ALPHA_MIN^2 the kernel is a mirror: nothing to fit, and nothing to add either.
    if !(tr.is_finite() && tr > crate::models::ALPHA_MIN.powi(2)) || n < 3 {
        return None;
    }
    let ndf = bin_slopes(&gaussian_slopes(sigma_f, n, seed), Some(cells)).ok()?;
    let m = fitter.fit(&ndf, ModelId::GgxAniso).ok()?.model;
    let a = slope_form(&m).ok()?.a2;
    Some(GgxKernel { matrix: a, ratio: a.trace() / (2.0 * tr) })
}

/// Indicative thresholds of the theory's conditions (scale.md sec. 4). Sampling spreads of a Gaussian's
/// moments from `n` independent samples: skewness (whitened third-moment norm) `sqrt(12 / n)`, Mardia
/// kurtosis `sqrt(64 / n)` around 8; a condition counts as violated only beyond 3 such spreads.
fn violations(resolved: &SlopeMoments, spread: f64, share: f64, blur: Blur, n_indep: f64) -> Violations {
    let mut v = Violations::default();
    let skew_lim = 0.3 + 3.0 * (12.0 / n_indep).sqrt();
    if resolved.skewness > skew_lim {
        v.all.push(format!(
            "the filtered surface's slopes are skewed (skewness {:.2} > {skew_lim:.2}): they are not Gaussian, so adding one Gaussian kernel to a fitted lobe is approximate (only the ellipsoid can follow skew)",
            resolved.skewness
        ));
    }
    // 10 is the Mardia kurtosis of a bivariate Student t with 12 degrees of freedom: clearly heavier than
    // a Gaussian (8), so the variance Sigma_F is carried by a few steep footprints a fitted lobe ignores.
    let kurt_lim = 10.0 + 3.0 * (64.0 / n_indep).sqrt();
    if resolved.kurtosis > kurt_lim {
        v.all.push(format!(
            "the filtered surface's slopes are heavy-tailed (kurtosis {:.1} > {kurt_lim:.1}, 8 for a Gaussian): their variance, which Sigma_F measures, sits in a few steep places, while a fitted lobe follows the bulk",
            resolved.kurtosis
        ));
    }
    // Per-footprint covariances (S1) make the NDF at F a scale mixture of Gaussians. Per axis, with the
    // resolved part Gaussian of variance R and within-footprint variances V of mean m and coefficient of
    // variation cv: E s^4 = 3 (R + m)^2 + 3 Var V, so the excess kurtosis is 3 (cv share)^2 with
    // share = m / (R + m) = tr Sigma_F / tr Cov(s) (cv taken from tr Sigma_w). GGX-shaped fits follow the
    // lobe's core and react to it first: on a Gaussian surface an excess of 0.4 already opens a route gap
    // of 0.13 for them (0.04 for Beckmann, data_formats/scale.md sec. 4b), hence 0.25 for them and 1
    // (the excess kurtosis of a Laplace-like tail) for every model.
    if blur == Blur::PerFootprint {
        let excess = 3.0 * (spread * share).powi(2);
        let words = |lim: f64| {
            format!(
                "the within-footprint covariance varies between footprints (coefficient of variation {spread:.2}, carrying {:.0} % of the slope variance): the NDF at F is a mixture with excess kurtosis {excess:.2} > {lim}, which one mean Sigma_F cannot reproduce",
                100.0 * share
            )
        };
        if excess > 1.0 {
            v.all.push(words(1.0));
        } else if excess > 0.25 {
            v.ggx.push(words(0.25) + " (GGX-shaped models follow the core)");
        }
    }
    v
}

/// The caveats of one model's analytic route: the footprint's violations plus the model's own.
fn caveats(m: &ModelAtFootprint, v: &Violations, ggx_shaped: bool, no_kernel_fit: bool) -> Vec<String> {
    let mut c = v.all.clone();
    if ggx_shaped {
        c.extend(v.ggx.iter().cloned());
    }
    let literal_ggx = ggx_shaped && no_kernel_fit;
    if m.analytic.error.is_some() {
        c.push("the analytic route failed".into());
    } else if m.analytic.source.starts_with("moments") {
        c.push("the filtered surface could not be fitted (too flat for the bins); its base is a moment estimate".into());
    }
    if literal_ggx {
        c.push("the kernel could not be fitted in GGX units; Tokuyoshi's literal A + 2 Sigma_F over-filters a GGX lobe".into());
    }
    c
}

/// One sentence: for which models the analytic route holds at this footprint.
fn summary(models: &[ModelAtFootprint]) -> String {
    let ok: Vec<&str> = models.iter().filter(|m| m.analytic_trusted()).map(|m| m.id.as_str()).collect();
    let bad: Vec<&str> = models.iter().filter(|m| !m.analytic_trusted()).map(|m| m.id.as_str()).collect();
    match (ok.is_empty(), bad.is_empty()) {
        (_, true) => "the analytic route (fit of the filtered surface plus the kernel) can be trusted for every model here".into(),
        (true, false) => {
            "the analytic route cannot be trusted here for any model (see each model's analytic_caveats); use the empirical route".into()
        }
        (false, false) => format!(
            "the analytic route can be trusted here for {} but not for {} (see analytic_caveats); use the empirical route for those",
            ok.join(", "),
            bad.join(", ")
        ),
    }
}

/// Fill in the QBIC of every empirical fit at one footprint (see [`qbic`]).
fn fill_ic(models: &mut [(ModelAtFootprint, Option<Fitted>)]) {
    let c = crate::fit::qbic::overdispersion(models.iter().filter_map(|(_, f)| f.and_then(|f| f.reduced_chi2)));
    for (m, f) in models.iter_mut() {
        if let Some(f) = f {
            if let Some(obj) = f.objective {
                m.empirical.ic = Some(qbic(obj, c, m.id.n_params(), f.n_samples));
            }
        }
    }
}

/// The scale-free skew (`sqrt(mu^T A2^-1 mu)`, roughness.rs) of a model.
pub fn model_skew(m: &Model) -> f64 {
    slope_form(m).map(|f| skew_offset(&f)).unwrap_or(f64::NAN)
}

/// The recommendation for a set of footprints (data_formats/scale.md sec. 9).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Recommendation {
    /// The chosen model, or None when no model meets the tolerance.
    pub model: Option<ModelId>,
    /// The tolerance on `delta_model`.
    pub tolerance: f64,
    /// Every candidate in the order considered: id, parameters, worst `delta_model` over the footprints,
    /// summed information criterion, and whether it passed.
    pub candidates: Vec<Candidate>,
    /// The reasoning in plain words.
    pub explanation: String,
}

/// One model's standing in the recommendation.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Candidate {
    /// Model id.
    pub model: ModelId,
    /// Number of parameters.
    pub n_params: usize,
    /// Largest `delta_model` over the footprints (infinite when a fit failed).
    pub worst_delta_model: f64,
    /// The footprint (metres) where the worst error occurs.
    pub worst_footprint: f64,
    /// Sum of the information criteria over the footprints, when every fit reported one.
    pub ic_sum: Option<f64>,
    /// `worst_delta_model <= tolerance`.
    pub passes: bool,
}

/// Choose the simplest model whose empirical-route error stays under `tolerance` at every footprint.
pub fn recommend(results: &[FootprintResult], tolerance: f64) -> Recommendation {
    let mut ids: Vec<ModelId> = results.iter().flat_map(|r| r.models.iter().map(|m| m.id)).collect();
    ids.sort();
    ids.dedup();
    let mut cands: Vec<Candidate> = ids
        .into_iter()
        .map(|id| {
            let (mut worst, mut at, mut ic, mut all_ic) = (f64::NEG_INFINITY, f64::NAN, 0.0, true);
            for r in results {
                let e = r.models.iter().find(|m| m.id == id).map(|m| &m.empirical);
                let d = e.and_then(|e| e.delta).map(|d| d.excess).unwrap_or(f64::INFINITY);
                if !(d <= worst) {
                    worst = d;
                    at = r.stats.footprint;
                }
                match e.and_then(|e| e.ic) {
                    Some(v) => ic += v,
                    None => all_ic = false,
                }
            }
            Candidate {
                model: id,
                n_params: id.n_params(),
                worst_delta_model: worst,
                worst_footprint: at,
                ic_sum: all_ic.then_some(ic),
                passes: worst <= tolerance,
            }
        })
        .collect();
    // Simplest first: fewer parameters, then the lower information criterion, then the id (a fixed order
    // makes the choice reproducible when criteria tie or are missing).
    cands.sort_by(|a, b| {
        a.n_params
            .cmp(&b.n_params)
            .then(a.ic_sum.unwrap_or(f64::INFINITY).total_cmp(&b.ic_sum.unwrap_or(f64::INFINITY)))
            .then(a.model.cmp(&b.model))
    });
    // The rule `auto` shares (fit::verdict::select); `scale` recommends only a model within the tolerance.
    let worst: Vec<f64> = cands.iter().map(|c| c.worst_delta_model).collect();
    let chosen = crate::fit::verdict::select(&worst, tolerance).filter(|&(_, within)| within).map(|(i, _)| cands[i].model);
    let mut words = Vec::new();
    let fps: Vec<String> = results.iter().map(|r| format!("{:.3e}", r.stats.footprint)).collect();
    let plural = |n: usize| if n == 1 { "" } else { "s" };
    words.push(match chosen {
        Some(m) => format!("Recommended model: {m}."),
        None => "No model meets the tolerance.".into(),
    });
    words.push(format!(
        "How it was chosen: at each footprint the scene implies ({} m; a footprint is the width of one pixel on the surface) the measured surface was filtered the way a renderer sees it, and every model was fitted to the resulting NDF. A model's error is delta_model, the root-mean-square relative difference between the model's NDF and the measured one, weighted by where the normals are, after removing the histogram's own counting noise (0.1 means the model is off by about 10 %). Models were tried from the simplest (fewest parameters; ties by the lower information criterion) to the most general; the first whose error stays at or below the tolerance {} at every footprint is recommended.",
        fps.join(", "),
        tolerance
    ));
    for c in &cands {
        if Some(c.model) == chosen {
            words.push(format!(
                "{} ({} parameter{}) is the simplest that passes: its worst error is {:.3} (about {:.0} %) at {:.3e} m.",
                c.model,
                c.n_params,
                plural(c.n_params),
                c.worst_delta_model,
                100.0 * c.worst_delta_model,
                c.worst_footprint
            ));
            break;
        }
        if c.worst_delta_model.is_finite() {
            words.push(format!(
                "{} ({} parameter{}) would cost an error of {:.3} (about {:.0} %) at {:.3e} m, above the tolerance: rejected.",
                c.model,
                c.n_params,
                plural(c.n_params),
                c.worst_delta_model,
                100.0 * c.worst_delta_model,
                c.worst_footprint
            ));
        } else {
            words.push(format!("{} was rejected: it could not be fitted at {:.3e} m.", c.model, c.worst_footprint));
        }
    }
    if let Some(m) = chosen {
        let later: Vec<String> = cands
            .iter()
            .skip_while(|c| c.model != m)
            .skip(1)
            .map(|c| format!("{} ({} parameter{}, worst error {:.3})", c.model, c.n_params, plural(c.n_params), c.worst_delta_model))
            .collect();
        if !later.is_empty() {
            words.push(format!(
                "Also fitted, not needed: {}. A model with more parameters (or as many and a worse information criterion) is not chosen once a simpler one meets the tolerance.",
                later.join(", ")
            ));
        }
    } else {
        let best =
            cands.iter().filter(|c| c.worst_delta_model.is_finite()).min_by(|a, b| a.worst_delta_model.total_cmp(&b.worst_delta_model));
        match best {
            Some(b) => words.push(format!(
                "The smallest worst-case error is {}'s, {:.3} at {:.3e} m; raise --tolerance above it or use that model with its reported error.",
                b.model, b.worst_delta_model, b.worst_footprint
            )),
            None => words.push("No model could be fitted; check the scan and the footprints.".into()),
        }
    }
    if let Some(s) = one_lobe_suffices(results, chosen, tolerance) {
        words.push(s);
    }
    words.push("The blur samples use a fixed seed (--seed), so the same scan and options give the same recommendation.".into());
    Recommendation { model: chosen, tolerance, candidates: cands, explanation: words.join(" ") }
}

/// When two lobes are recommended: the footprint from which on (every larger footprint too) a single lobe
/// meets the tolerance, in one sentence. Filtering convolves the slope distribution with the footprint's
/// kernel, which widens the sharp core most (relative to its width) until the tail no longer needs a lobe of
/// its own; a renderer working only at those footprints can use that single lobe.
fn one_lobe_suffices(results: &[FootprintResult], chosen: Option<ModelId>, tolerance: f64) -> Option<String> {
    if !chosen.is_some_and(|m| m.is_mixture()) {
        return None;
    }
    let mut order: Vec<&FootprintResult> = results.iter().collect();
    order.sort_by(|a, b| a.stats.footprint.total_cmp(&b.stats.footprint));
    let singles = |r: &FootprintResult| -> Vec<ModelId> {
        r.models.iter().filter(|m| !m.id.is_mixture() && m.empirical.delta.is_some_and(|d| d.excess <= tolerance)).map(|m| m.id).collect()
    };
    let mut from = None;
    for (i, r) in order.iter().enumerate().rev() {
        if singles(r).is_empty() {
            break;
        }
        from = Some(i);
    }
    let i = from?;
    let names: Vec<&str> = singles(order[i]).iter().map(|m| m.as_str()).collect();
    Some(if i == 0 {
        format!("One lobe would do too at every footprint here ({}), by its own error; the mixture is kept because the ranking above put it first.", names.join(", "))
    } else {
        format!(
            "From {:.3e} m on, one lobe suffices ({}): filtering by the footprint widens the sharp core until the tail needs no lobe of its own; below it only two lobes meet the tolerance.",
            order[i].stats.footprint,
            names.join(", ")
        )
    })
}
