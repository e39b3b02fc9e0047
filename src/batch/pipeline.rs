//! The standard per-scan pipeline of a batch: read, preprocess, empirical NDF, fit, score.

use std::path::Path;

use serde_json::Value;

use super::compare::BaselineEntry;
use super::job::JobOutput;
use super::quality::{model_of_fit, quality};
use crate::error::{Error, ErrorKind, Result};
use crate::fit::FitOptions;
use crate::models::ModelId;
use crate::scan::Heightfield;
use crate::io::ReadOptions;
use crate::ndf::{EmpiricalNdf, NdfOptions};
use crate::preprocess::Preprocess;

/// Everything the pipeline needs besides the file.
#[derive(Debug, Clone)]
pub struct PipelineOptions {
    /// How to read the file.
    pub read: ReadOptions,
    /// Preprocessing before normals are taken.
    pub preprocess: Preprocess,
    /// How the empirical NDF is built.
    pub ndf: NdfOptions,
    /// The model id, or `auto`.
    pub model: String,
    /// How to fit.
    pub fit: FitOptions,
}

impl Default for PipelineOptions {
    fn default() -> Self {
        PipelineOptions {
            read: ReadOptions::default(),
            preprocess: Preprocess::default(),
            ndf: NdfOptions::default(),
            model: "ellipsoid".into(),
            fit: FitOptions::default(),
        }
    }
}

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
pub fn fit_scan(path: &Path, opts: &PipelineOptions, baseline: Option<&BaselineEntry>) -> Result<PipelineResult> {
    let hf = crate::io::read_scan(path, &opts.read)?;
    let hf = crate::preprocess::apply(hf, &opts.preprocess).map_err(|e| e.with_path(path))?;
    let ndf = crate::ndf::empirical_ndf(&hf, &opts.ndf).map_err(|e| e.with_path(path))?;
    let fit = fit_json(path, &hf, &ndf, &opts.model, &opts.fit).map_err(|e| e.with_path(path))?;
    let output = score(fit, &ndf, baseline).map_err(|e| e.with_path(path))?;
    Ok(PipelineResult { output, ndf })
}

/// Score a fit JSON against `ndf`, and the baseline entry's model on the same bins.
pub fn score(fit: Value, ndf: &EmpiricalNdf, baseline: Option<&BaselineEntry>) -> Result<JobOutput> {
    let fitted = model_of_fit(&fit)?;
    // The fit's own region (objective.md), for the baseline's model too: the same bins for both.
    let max_theta = super::quality::max_theta_of_fit(&fit);
    let q = quality(ndf, &fitted, max_theta)?;
    // A baseline model this version cannot evaluate falls back to its stored quality (basis "stored").
    let same_bins =
        baseline.and_then(|b| b.fit_json()).and_then(|f| model_of_fit(&f).ok()).and_then(|m| quality(ndf, &m, max_theta).ok());
    Ok(JobOutput { fit, quality: Some(q), baseline_on_same_bins: same_bins })
}

/// The fit JSON (`ndfit.fit/1`) of `model` (an id or `auto`) on `ndf`, with the contract's `input`.
fn fit_json(path: &Path, hf: &Heightfield, ndf: &EmpiricalNdf, model: &str, fit: &FitOptions) -> Result<Value> {
    let mut report = if model == "auto" {
        crate::fit::fit_auto(ndf, fit)?
    } else {
        crate::fit::fit_model(ndf, model.parse::<ModelId>()?, fit)?
    };
    report.input = Some(crate::fit::InputInfo::new(path, hf));
    serde_json::to_value(&report).map_err(|e| Error::new(ErrorKind::Numerical, format!("fit result is not JSON: {e}")))
}

/// Write `ndf` as the CSV of `data_formats/ndf_csv.md` (`mx,my,mz,d,stderr,count,solid_angle,proj_solid_angle`),
/// atomically.
pub fn write_ndf_csv(path: &Path, ndf: &EmpiricalNdf) -> Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir).map_err(|e| Error::io(e).with_path(dir))?;
    }
    crate::io::write_atomic(path, |w| {
        let mut c = csv::Writer::from_writer(w);
        let err = |e: csv::Error| Error::new(ErrorKind::Io, e.to_string());
        c.write_record(["mx", "my", "mz", "d", "stderr", "count", "solid_angle", "proj_solid_angle"]).map_err(err)?;
        for b in &ndf.bins {
            c.write_record([
                format!("{:e}", b.m.x),
                format!("{:e}", b.m.y),
                format!("{:e}", b.m.z),
                format!("{:e}", b.d),
                format!("{:e}", b.stderr),
                b.count.to_string(),
                format!("{:e}", b.solid_angle),
                format!("{:e}", b.proj_solid_angle),
            ])
            .map_err(err)?;
        }
        c.flush().map_err(Error::io)
    })
}
