//! The per-scan job the runner calls: read, preprocess, NDF, fit, score. The runner does not know how;
//! it receives the job as a function, so its machinery is tested with fake jobs and the CLI passes the
//! real pipeline (or a child-process wrapper around it).

use std::path::{Path, PathBuf};

use serde_json::Value;

use super::compare::BaselineEntry;
use super::quality::Quality;
use super::spec::ScanSpec;

/// What a job learns about its scan's place in the run.
#[derive(Debug, Clone, Copy)]
pub struct JobContext<'a> {
    /// The run's output folder; a job may write optional files (NDF, plots) below it, atomically.
    pub out_dir: &'a Path,
    /// This scan's relative output path (from [`ScanSpec::out_rel`]); extra files go to
    /// `out_dir/<kind>/<out_rel>.<ext>`.
    pub out_rel: &'a Path,
    /// The baseline's entry for this scan, if any: the job scores the baseline model on its own bins.
    pub baseline: Option<&'a BaselineEntry>,
}

impl JobContext<'_> {
    /// `out_dir/<kind>/<out_rel><suffix>`, e.g. `extra_path("ndf", ".ndf.csv")`.
    pub fn extra_path(&self, kind: &str, suffix: &str) -> PathBuf {
        let mut name = self.out_rel.as_os_str().to_owned();
        name.push(suffix);
        self.out_dir.join(kind).join(name)
    }
}

/// A fitted scan.
#[derive(Debug, Clone, PartialEq)]
pub struct JobOutput {
    /// The fit JSON (`ndfit.fit/1`).
    pub fit: Value,
    /// The fit scored against the scan's empirical NDF ([`super::quality::quality`]).
    pub quality: Option<Quality>,
    /// The baseline's model scored against the same NDF, when the context had a baseline fit.
    pub baseline_on_same_bins: Option<Quality>,
}

/// Why a scan failed: a coarse kind and one line of text naming the file and the problem.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct JobFailure {
    /// `ndfit::ErrorKind` in snake case, or `panic`, `crash`, `timeout`.
    pub kind: String,
    /// One line.
    pub message: String,
}

impl JobFailure {
    /// A failure of `kind` with `message` (newlines are folded into `; ` to keep it one line).
    pub fn new(kind: impl Into<String>, message: impl AsRef<str>) -> Self {
        let message = message.as_ref().trim().lines().map(str::trim).collect::<Vec<_>>().join("; ");
        JobFailure { kind: kind.into(), message }
    }
}

impl From<crate::Error> for JobFailure {
    fn from(e: crate::Error) -> Self {
        let kind = serde_json::to_value(e.kind()).ok().and_then(|v| v.as_str().map(str::to_string)).unwrap_or_default();
        JobFailure::new(kind, e.to_string())
    }
}

/// The per-scan job: must be callable from several threads at once and keep no state between scans.
pub type Job<'a> = dyn Fn(&ScanSpec, &JobContext<'_>) -> Result<JobOutput, JobFailure> + Sync + 'a;
