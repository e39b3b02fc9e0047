//! The per-scan job of a batch: the library's [`Pipeline`] (read, preprocess, empirical NDF, fit), then
//! the score of the fit and of the baseline's model on the same bins.

use std::path::Path;

use serde_json::Value;

use super::compare::BaselineEntry;
use super::job::JobOutput;
use super::quality::{model_of_fit, quality_in};
use crate::error::{Error, ErrorKind, Result};
use crate::ndf::EmpiricalNdf;
use crate::pipeline::{Options, Outcome, Pipeline};

/// Everything the pipeline needs besides the file: the library's one set of [`Options`].
pub type PipelineOptions = Options;

/// The result of [`fit_scan`] with the NDF kept, for callers that write it.
#[derive(Debug, Clone)]
pub struct PipelineResult {
    /// What the runner needs.
    pub output: JobOutput,
    /// The scan's empirical NDF.
    pub ndf: EmpiricalNdf,
}

/// Read `path`, preprocess, build its NDF, fit, and score the fit (and the baseline's model, on the same
/// bins). Every error names `path`.
pub fn fit_scan(path: &Path, opts: &Options, baseline: Option<&BaselineEntry>) -> Result<PipelineResult> {
    let Outcome { ndf, fit } = Pipeline::new(opts.clone()).run_path(path)?;
    let fit =
        serde_json::to_value(&fit).map_err(|e| Error::new(ErrorKind::Numerical, format!("fit result is not JSON: {e}")).with_path(path))?;
    let output = score(fit, &ndf, baseline).map_err(|e| e.with_path(path))?;
    Ok(PipelineResult { output, ndf })
}

/// Score a fit JSON against `ndf`, and the baseline entry's model on the same bins.
pub fn score(fit: Value, ndf: &EmpiricalNdf, baseline: Option<&BaselineEntry>) -> Result<JobOutput> {
    let fitted = model_of_fit(&fit)?;
    // The fit's own region (objective.md), for the baseline's model too: the same bins for both.
    let max_theta = super::quality::max_theta_of_fit(&fit);
    let rule = super::quality::tail_rule_of_fit(&fit).to_string();
    let q = quality_in(ndf, &fitted, max_theta, &rule)?;
    // A baseline model this version cannot evaluate falls back to its stored quality (basis "stored").
    let same_bins =
        baseline.and_then(|b| b.fit_json()).and_then(|f| model_of_fit(&f).ok()).and_then(|m| quality_in(ndf, &m, max_theta, &rule).ok());
    Ok(JobOutput { fit, quality: Some(q), baseline_on_same_bins: same_bins })
}
