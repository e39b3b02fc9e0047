//! The real per-scan job of `ndfit batch`: parse the scan's options like `ndfit fit`, read and
//! preprocess, build the empirical NDF, fit, and score the fit (and the baseline's) on its bins.

use std::path::PathBuf;

use clap::Parser;
use ndfit::batch::pipeline;
use ndfit::batch::{JobContext, JobFailure, JobOutput, ScanSpec};
use ndfit::ModelChoice;
use serde_json::Value;

use crate::ndfit_cli::fit_args::{parse_model, FitArgs};

/// The run-level settings every scan's job shares (serializable: the child worker gets them too).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct JobConfig {
    /// The run's model (a scan's manifest `model` overrides it).
    pub model: String,
    /// Options for every scan (after `--`), before the scan's own.
    pub scan_options: Vec<String>,
    /// Write each scan's empirical NDF CSV.
    pub write_ndf: bool,
    /// Write each scan's plot of data against fit.
    pub plots: bool,
    /// Testing aid: sleep in each job (milliseconds).
    pub debug_delay_ms: u64,
    /// Testing aid: abort the process in the job of the scan with this key.
    pub debug_abort: Option<String>,
}

impl JobConfig {
    /// The settings that change results (for the resume key): everything but the testing aids.
    pub fn settings(&self) -> Value {
        serde_json::json!({"model": self.model, "scan_options": self.scan_options, "write_ndf": self.write_ndf, "plots": self.plots})
    }
}

/// The per-scan options: exactly the flags of `ndfit fit` but the model and the outputs ([`FitArgs`]).
#[derive(Debug, Parser)]
#[command(no_binary_name = true, disable_help_flag = true, args_override_self = true)]
pub struct PerScan {
    #[command(flatten)]
    pub fit: FitArgs,
}

/// Parse the run's and the scan's options for `spec`.
pub fn parse_scan_options(cfg: &JobConfig, spec: &ScanSpec) -> Result<PerScan, JobFailure> {
    let mut argv: Vec<String> = vec![spec.file.display().to_string()];
    argv.extend(cfg.scan_options.iter().cloned());
    argv.extend(spec.options.iter().cloned());
    let fail = |msg: &str| JobFailure::new("invalid_input", format!("{}: options {:?}: {msg}", spec.key, &argv[1..]));
    let per = PerScan::try_parse_from(&argv).map_err(|e| {
        let text = e.to_string();
        fail(text.lines().find(|l| !l.trim().is_empty()).unwrap_or("bad options").trim().trim_start_matches("error: "))
    })?;
    // Values that parse but are out of range fail here too, before anything runs.
    per.fit.options(ModelChoice::Auto).map_err(|e| fail(e.message()))?;
    Ok(per)
}

/// Fit one scan. Failures name the file and the problem in one line.
pub fn fit_scan(cfg: &JobConfig, spec: &ScanSpec, ctx: &JobContext<'_>) -> Result<JobOutput, JobFailure> {
    if cfg.debug_delay_ms > 0 {
        std::thread::sleep(std::time::Duration::from_millis(cfg.debug_delay_ms));
    }
    if cfg.debug_abort.as_deref() == Some(spec.key.as_str()) {
        std::process::abort();
    }
    let per = parse_scan_options(cfg, spec)?;
    let path: PathBuf = per.fit.scan.scan.clone();
    let model = parse_model(spec.model.as_deref().unwrap_or(&cfg.model)).map_err(|e| e.with_path(&path))?;
    let mut opts = per.fit.options(model).map_err(|e| e.with_path(&path))?;
    // The NDF CSV carries the unresolved counts whatever the tail rule.
    if cfg.write_ndf {
        opts.ndf.resolution = Some(true);
    }
    let r = pipeline::fit_scan(&path, &opts, ctx.baseline)?;
    if cfg.write_ndf {
        let csv = ctx.extra_path("ndf", ".ndf.csv");
        if let Some(dir) = csv.parent() {
            std::fs::create_dir_all(dir).map_err(|e| ndfit::Error::io(e).with_path(dir))?;
        }
        ndfit::ndf::write_csv(&csv, &r.ndf).map_err(|e| e.with_path(&csv))?;
    }
    if cfg.plots {
        let model = ndfit::batch::model_of_fit(&r.output.fit).map_err(|e| e.with_path(&path))?;
        let png = ctx.extra_path("plots", ".png");
        if let Some(dir) = png.parent() {
            std::fs::create_dir_all(dir).map_err(|e| ndfit::Error::io(e).with_path(dir))?;
        }
        let title = format!("{}: {} fit", spec.key, model.id());
        ndfit::fit::plot_fit(&png, &r.ndf, &model, &title).map_err(|e| e.with_path(&png))?;
    }
    Ok(r.output)
}
