//! The fit result as the contract's `ndfit.fit/1` JSON (documented key by key in `data_formats/fit.md`,
//! schema in `data_formats/fit.schema.json`).

use std::collections::BTreeMap;

use crate::models::ModelId;
use crate::scan::InputInfo;

/// The schema id of a fit result.
pub const SCHEMA: &str = "ndfit.fit/1";

/// How well the model describes the data.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Quality {
    /// `poisson` or `logd` (objective.md).
    pub objective: String,
    /// The objective `F = sum r_k^2` at the optimum (the Poisson deviance, or the weighted log-D sum).
    pub objective_value: f64,
    /// Degrees of freedom `K - p - 1` (the region's total count is fixed).
    pub dof: i64,
    /// `F / (K - p - 1)`; near 1 for independent Poisson counts, larger for correlated normals.
    pub reduced_chi2: Option<f64>,
    /// Bins in the objective.
    pub n_bins: usize,
    /// Bins with a non-zero count (`K`).
    pub n_bins_nonzero: usize,
    /// Count `N_in` inside the fitted region (bins within `max_theta_deg`).
    pub n_samples: f64,
    /// Count `N` of the whole NDF (the normals beyond `max_theta_deg` are `n_samples_total - n_samples`).
    pub n_samples_total: f64,
    /// Largest polar angle of the bins in the objective (degrees; objective.md).
    pub max_theta_deg: f64,
    /// The bins the tail cut left out of the region (objective.md, "The tail the scan cannot resolve").
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tail: Option<super::tail::TailCut>,
    /// `delta(D_fit; D_empirical)` over the bins (objective.md), counting noise included.
    pub delta_data: Option<f64>,
    /// Numerical rank of the Jacobian at the optimum (= parameter count when all are determined).
    pub rank: usize,
    /// Condition number of the column-scaled `J^T J` (absent when rank deficient).
    pub condition: Option<f64>,
    /// The data's own overdispersion of the region's bin counts, from two interleaved halves of the scan
    /// ([`super::verdict::data_dispersion`]); `reduced_chi2` near it means the model explains the data
    /// as well as the data explain themselves.
    #[serde(default)]
    pub dispersion: Option<f64>,
    /// `delta_data` with the counting noise taken out (`sqrt(delta_data^2 - dispersion K / N)`): the
    /// model's own NDF error against the data (`excess_delta`).
    #[serde(default)]
    pub delta_excess: Option<f64>,
    /// `ok`, `misfit` or `unresolved` (`verdict`).
    #[serde(default)]
    pub verdict: super::verdict::Verdict,
    /// Why the verdict is not `ok` (one line each); for `ok`, a difference the counts show that is within
    /// the tolerance, or nothing.
    #[serde(default)]
    pub reasons: Vec<String>,
}

/// What the solver did.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SolverInfo {
    /// `lm`, `nelder-mead` or `lbfgs`.
    pub name: String,
    /// The termination reason of the best start, as the solver names it.
    pub termination: String,
    /// Whether the solver reports convergence for the best start.
    pub converged: bool,
    /// Objective evaluations, summed over all starts.
    pub evaluations: usize,
    /// Number of starting points tried.
    pub starts: usize,
    /// Index of the start that gave the best objective.
    pub best_start: usize,
    /// Best objective of every start, in order (shows whether the problem was multimodal). A start that
    /// never reached a finite objective is infinite here and `null` in the JSON (JSON has no infinity).
    #[serde(deserialize_with = "null_as_infinite")]
    pub start_objectives: Vec<f64>,
}

/// Read `start_objectives` back: serde_json writes a non-finite float as `null`.
fn null_as_infinite<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Vec<f64>, D::Error> {
    let v: Vec<Option<f64>> = serde::Deserialize::deserialize(d)?;
    Ok(v.into_iter().map(|x| x.unwrap_or(f64::INFINITY)).collect())
}

/// Wall-clock times in milliseconds.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Timings {
    /// Reading and preprocessing the scan (filled in by `Pipeline`; absent when the stages are called apart).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub read_ms: Option<f64>,
    /// Building the empirical NDF (filled in by `Pipeline`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ndf_ms: Option<f64>,
    /// The fit (all starts, covariance, for `auto` all candidate models).
    pub fit_ms: f64,
    /// `auto`'s optics: the mirror share over the coherence patches, and a mirror's haze (filled in by
    /// `Pipeline`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub optics_ms: Option<f64>,
}

/// One candidate of `--model auto`.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Candidate {
    /// Model id.
    pub model: ModelId,
    /// Canonical parameters.
    pub params: BTreeMap<String, f64>,
    /// Parameter count `p`.
    pub n_params: usize,
    /// Objective at the optimum.
    pub objective_value: f64,
    /// Reduced chi-square.
    pub reduced_chi2: Option<f64>,
    /// `delta(D_fit; D_empirical)`.
    pub delta_data: Option<f64>,
    /// The information criterion (see [`Selection::criterion`]); lower is better.
    pub criterion: f64,
    /// The model this one extends (the model table's parent), if any.
    pub parent: Option<ModelId>,
    /// `criterion - criterion(parent)`: negative when the extra parameters pay for themselves.
    pub d_criterion: Option<f64>,
    /// `delta_data - delta_data(parent)`: what the extra parameters buy in fit error.
    pub d_delta_data: Option<f64>,
    /// Whether the solver converged.
    pub converged: bool,
    /// The ladder's criterion `F / c_data + p ln N` with the data's own overdispersion `c_data`
    /// ([`Selection::data_overdispersion`]; objective.md, "Mixtures and the ladder"); lower is better.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub qbic_data: Option<f64>,
    /// Deviance per degree of freedom, `F / (K - p - 1)` (as `reduced_chi2`, named for the ladder table).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub deviance_per_dof: Option<f64>,
    /// What each parameter added over `parent` buys: `(F_parent - F) / (c_data (p - p_parent))`, to be set
    /// against its price `ln N` in the criterion.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gain_per_param: Option<f64>,
    /// The model's rung in the ladder: its depth in the model table's parent tree.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rung: Option<usize>,
    /// The NDF error beyond counting noise (`quality.delta_excess` of this candidate), what the choice is
    /// priced in.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delta_excess: Option<f64>,
    /// What the rung buys: `delta_excess(parent) - delta_excess`, the drop in NDF error beyond noise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub effect: Option<f64>,
    /// The likelihood guard: `qbic_data` below the parent's (the data support the added parameters); a
    /// candidate without it is not chosen.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub supported: Option<bool>,
    /// The render choice's score of this lobe: mean HDR-FLIP against the scan's table per scene, and
    /// `worst`; absent for a lobe not rendered (the choice stops at the first lobe within its tolerance).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub render_error: Option<BTreeMap<String, f64>>,
}

/// Model selection of `--model auto`: the ladder of the model table priced in the NDF error beyond
/// counting noise, with the likelihood as a guard (`crate::fit::fit_auto`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Selection {
    /// The criterion: `qbic` = `F / c + p ln N` (BIC with the quasi-likelihood overdispersion `c`).
    pub criterion: String,
    /// The overdispersion `c = max(1, smallest reduced_chi2 among the candidates)` (`fit::qbic`).
    pub overdispersion: f64,
    /// Every model fitted, simplest first (the single lobes, then the mixtures).
    pub candidates: Vec<Candidate>,
    /// The ladder's overdispersion `c_data = max(1, quality.dispersion)` (the data's own, from the odd/even
    /// block split), or `overdispersion` when the NDF has no split.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub data_overdispersion: Option<f64>,
    /// One sentence: the model chosen and why, the effect of each rung, the rungs not fitted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ladder: Option<String>,
    /// The tolerance on the NDF error beyond counting noise the choice used (`--tolerance`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<f64>,
    /// The models of the ladder not fitted: a model on a rung below them was within the tolerance, or (the
    /// two-lobe models) light sees the scan as a mirror and the ladder only describes its slopes.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub not_fitted: Vec<ModelId>,
    /// The model a renderer should use (the render choice): a model id, or `measured` when no lobe renders
    /// within `render_tolerance` of the scan's own table (then `ndfit export SCAN --to rgl` is the
    /// material, and `model` holds the closest lobe).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub answer: Option<String>,
    /// The render difference of `model` (the answer's lobe, or the closest) against the scan's table: mean
    /// HDR-FLIP per scene, and `worst`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub render_error: Option<BTreeMap<String, f64>>,
    /// The largest FLIP beyond the table's own noise, in every scene, at which a lobe is the answer.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub render_tolerance: Option<f64>,
    /// Per scene, the FLIP the scan table's own counting noise shows (half the FLIP between the tables of
    /// the scan's two halves): a lobe is held to `render_tolerance` beyond it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub render_noise: Option<BTreeMap<String, f64>>,
    /// The render choice's scenes (`point`, `broad`, or a stated scene; data_formats/render.md).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub scenes: Vec<String>,
    /// The lobe that fills the scan's table beyond its trusted bins (the candidate with the smallest NDF
    /// error against the data; [`crate::fit::table_lobe`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table_lobe: Option<ModelId>,
}

/// The mirror share at one incidence and wavelength.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SpecularShare {
    /// Incidence (degrees from the normal).
    pub theta_deg: f64,
    /// Wavelength (nm).
    pub wavelength_nm: f64,
    /// The coherent share of the incident light: reflected as a mirror, Fresnel excluded.
    pub weight: f64,
}

/// The haze lobe of a mirror answer: a lobe fitted to the diffuse part of the wave BRDF.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Haze {
    /// The lobe's model.
    pub model: ModelId,
    /// Its parameters by name.
    pub params: BTreeMap<String, f64>,
    /// Share of the light it carries at normal incidence and the middle wavelength (Fresnel excluded).
    pub albedo: f64,
}

/// What light sees of the scan ([`crate::answer`]): the regime and the mirror share by incidence and
/// wavelength (wave optics on the scan's coherence patches).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Optics {
    /// `geometric`, `mixed` or `wave`.
    pub regime: String,
    /// The wavelengths of `specular` (nm).
    pub wavelength_nm: Vec<f64>,
    /// The side of the coherence patch (m).
    pub coherence_m: f64,
    /// The mirror share at each incidence and wavelength.
    pub specular: Vec<SpecularShare>,
    /// The regime's reason, in one sentence.
    pub why: String,
    /// The haze of a mirror answer.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub haze: Option<Haze>,
    /// The patches: used, skipped, tilt and slope RMS (degrees), incoherent floor, light beyond the band.
    #[serde(default)]
    pub patches: BTreeMap<String, f64>,
    /// What the scan does not resolve (a coherence patch under its spacing or over its size).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub note: Option<String>,
}

/// A fit result (`ndfit.fit/1`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FitReport {
    /// Always `SCHEMA`.
    pub schema: String,
    /// The model id (for `auto`, the model chosen).
    pub model: ModelId,
    /// Canonical parameters by name (radians for angles).
    pub params: BTreeMap<String, f64>,
    /// Row-major A in the scan frame, for models that are ellipsoid special cases.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub matrix_a: Option<[[f64; 3]; 3]>,
    /// The anisotropic models' axes in the scan frame (the `alpha_x` direction lies at azimuth `-theta_z`,
    /// along `(cos theta_z, -sin theta_z)`); see `axes`.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub axes: Option<crate::models::LobeAxes>,
    /// The input scan (set by the caller that read it).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub input: Option<InputInfo>,
    /// The height rounding the fit modelled (a quantized scan; objective.md, "Quantized heights").
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub rounding: Option<super::objective::Rounding>,
    /// Standard errors by parameter name; `null` for a parameter the data do not determine.
    pub std_errors: BTreeMap<String, Option<f64>>,
    /// Parameters the data do not identify, with their standard errors `null`: a null direction of the
    /// Jacobian, or `theta_z` of a nearly isotropic lobe (standard error above
    /// [`super::THETA_Z_SE_MAX`]). Their value in `params` is a valid but arbitrary choice, and the other
    /// parameters' errors are those at that value.
    #[serde(default)]
    pub unidentified: Vec<String>,
    /// Parameter names in the order of the rows and columns of `correlation`.
    pub param_order: Vec<String>,
    /// Correlation matrix of the parameters (`null` entries for undetermined parameters).
    pub correlation: Vec<Vec<Option<f64>>>,
    /// The lobe is not resolved by the NDF's bins (over half of the samples in one bin): a mirror-like
    /// surface whose alpha is an upper bound set by the binning, not a measurement.
    pub specular: bool,
    /// Goodness of fit.
    pub quality: Quality,
    /// Solver details.
    pub solver: SolverInfo,
    /// Wall-clock times.
    pub timings: Timings,
    /// For `--model auto`: every candidate and the criterion.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub selection: Option<Selection>,
    /// For `auto`: what light sees of the scan, geometric or wave optics (shared/CONTRACT.md "Wave
    /// optics"; [`crate::answer`]).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub optics: Option<Optics>,
    /// Anything the user should know (non-convergence, undetermined parameters, specular data).
    pub warnings: Vec<String>,
}

impl FitReport {
    /// The parameters in the order of [`ModelId::param_names`].
    pub fn param_vec(&self) -> Vec<f64> {
        self.model.param_names().iter().map(|n| self.params.get(*n).copied().unwrap_or(f64::NAN)).collect()
    }

    /// The standard errors in the order of [`ModelId::param_names`] (NaN when undetermined).
    pub fn std_error_vec(&self) -> Vec<f64> {
        self.model.param_names().iter().map(|n| self.std_errors.get(*n).copied().flatten().unwrap_or(f64::NAN)).collect()
    }

    /// The fitted model as a [`crate::models::Model`].
    pub fn to_model(&self) -> crate::Result<crate::models::Model> {
        crate::models::Model::from_params(self.model, &self.param_vec())
    }

    /// The lobe that fills the scan's table beyond its trusted bins (`selection.table_lobe`'s candidate
    /// for `auto`), else the fitted model: the scan's table is the same whichever lobe the render chose.
    pub fn table_model(&self) -> crate::Result<crate::models::Model> {
        let sel = self.selection.as_ref();
        match sel.and_then(|s| s.candidates.iter().find(|c| Some(c.model) == s.table_lobe)) {
            Some(c) => {
                let p: Vec<f64> = c.model.param_names().iter().map(|n| c.params.get(*n).copied().unwrap_or(f64::NAN)).collect();
                crate::models::Model::from_params(c.model, &p)
            }
            None => self.to_model(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::SolverInfo;

    /// A start that failed is written as `null` (serde_json's non-finite float) and read back infinite,
    /// so a fit file with one reads again (batch `--resume`, the tests' own reader).
    #[test]
    fn a_failed_start_round_trips_through_null() {
        let info = SolverInfo {
            name: "lm".into(),
            termination: "Converged".into(),
            converged: true,
            evaluations: 3,
            starts: 2,
            best_start: 0,
            start_objectives: vec![1.5, f64::INFINITY],
        };
        let text = serde_json::to_string(&info).unwrap();
        assert!(text.contains("\"start_objectives\":[1.5,null]"), "{text}");
        let back: SolverInfo = serde_json::from_str(&text).unwrap();
        assert_eq!(back.start_objectives, vec![1.5, f64::INFINITY]);
    }
}
