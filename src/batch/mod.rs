//! Batch regression of fit quality over many scans (`ndfit batch`).
//!
//! A run walks a folder ([`discover::walk`]) or reads a manifest ([`manifest::read_manifest`]) into
//! [`ScanSpec`]s, fits each with a per-scan [`Job`] passed in by the caller ([`runner::run`]), writes
//! each scan's record and fit as soon as it is done, compares against a baseline summary
//! (`compare`), and writes `summary.json`, `summary.csv` and a regression table ([`summary`]).
//! Layout and rules: `data_formats/batch.md`.

pub(crate) mod compare;
pub mod discover;
pub(crate) mod entry;
pub(crate) mod job;
pub mod manifest;
pub mod pipeline;
pub(crate) mod quality;
pub mod runner;
pub(crate) mod spec;
pub mod summary;

pub use compare::{Baseline, BaselineEntry, Comparison, Tolerances, Verdict};
pub use compare::{Basis, ParamChange};
pub use entry::ResumeKey;
pub use entry::{Entry, Status};
pub use job::{Job, JobContext, JobFailure, JobOutput};
pub use quality::{model_of_fit, quality, Quality};
pub use runner::{install_panic_hook, run, Brief, Counts, RunOptions, RunOutcome};
pub use spec::ScanSpec;
