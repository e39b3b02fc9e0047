//! The real per-scan job of `ndfit batch`: parse the scan's options like `ndfit fit`, read and
//! preprocess, build the empirical NDF, fit, and score the fit (and the baseline's) on its bins.

use std::path::PathBuf;

use clap::Parser;
use ndfit::batch::pipeline::{self, PipelineOptions};
use ndfit::batch::{JobContext, JobFailure, JobOutput, ScanSpec};
use serde_json::Value;

use crate::ndfit_cli::scan_args::ScanArgs;

/// The run-level settings every scan's job shares (serializable: the child worker gets them too).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct JobConfig {
    /// The run's model (a scan's manifest `model` overrides it).
    pub model: String,
    /// Options for every scan (after `--`), before the scan's own.
    pub scan_options: Vec<String>,
    /// Write each scan's empirical NDF CSV.
    pub write_ndf: bool,
    /// Testing aid: sleep in each job (milliseconds).
    pub debug_delay_ms: u64,
    /// Testing aid: abort the process in the job of the scan with this key.
    pub debug_abort: Option<String>,
}

impl JobConfig {
    /// The settings that change results (for the resume key): everything but the testing aids.
    pub fn settings(&self) -> Value {
        serde_json::json!({"model": self.model, "scan_options": self.scan_options, "write_ndf": self.write_ndf})
    }
}

/// The per-scan options, parsed exactly like `ndfit fit`'s scan options.
#[derive(Debug, Parser)]
#[command(no_binary_name = true, disable_help_flag = true)]
pub struct PerScan {
    #[command(flatten)]
    pub scan: ScanArgs,
}

/// Parse the run's and the scan's options for `spec`.
pub fn parse_scan_options(cfg: &JobConfig, spec: &ScanSpec) -> Result<PerScan, JobFailure> {
    let mut argv: Vec<String> = vec![spec.file.display().to_string()];
    argv.extend(cfg.scan_options.iter().cloned());
    argv.extend(spec.options.iter().cloned());
    PerScan::try_parse_from(&argv).map_err(|e| {
        let text = e.to_string();
        let first = text.lines().find(|l| !l.trim().is_empty()).unwrap_or("bad options").trim().trim_start_matches("error: ");
        JobFailure::new("invalid_input", format!("{}: options {:?}: {first}", spec.key, &argv[1..]))
    })
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
    let path: PathBuf = per.scan.scan.clone();
    let opts = PipelineOptions {
        read: per.scan.read_options(),
        preprocess: per.scan.preprocess(),
        ndf: Default::default(),
        model: spec.model.clone().unwrap_or_else(|| cfg.model.clone()),
    };
    let r = pipeline::fit_scan(&path, &opts, ctx.baseline)?;
    if cfg.write_ndf {
        let _ = ctx.extra_path("ndf", ".ndf.csv");
    }
    Ok(r.output)
}
