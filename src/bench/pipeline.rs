//! One run of the pipeline scan -> (subsample) -> empirical NDF -> fit, timed per stage, with the peak
//! resident memory of each stage.

use std::path::Path;
use std::time::Instant;

use super::knobs::Knobs;
use super::mem;
use crate::error::Result;
use crate::fit::{fit_model, FitReport};
use crate::io::{read_scan, ReadOptions};
use crate::ndf::{empirical_ndf, EmpiricalNdf};
use crate::preprocess::subsample;

/// Wall-clock time of each stage (ms).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct StageTimes {
    /// Reading the file into a heightfield.
    pub read: f64,
    /// Subsampling (0 at stride 1).
    pub subsample: f64,
    /// Normals, robust frame, histogram and bin integrals.
    pub ndf: f64,
    /// The fit (0 without a model).
    pub fit: f64,
}

impl StageTimes {
    /// The whole pipeline.
    pub fn total(&self) -> f64 {
        self.read + self.subsample + self.ndf + self.fit
    }
}

/// Peak resident memory of each stage above the resident set at the pipeline's start (bytes).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct StagePeaks {
    /// Reading and subsampling.
    pub read: Option<u64>,
    /// The empirical NDF (the heightfield still held).
    pub ndf: Option<u64>,
    /// The fit (the heightfield dropped).
    pub fit: Option<u64>,
}

impl StagePeaks {
    /// The largest stage peak: the pipeline's peak.
    pub fn total(&self) -> Option<u64> {
        [self.read, self.ndf, self.fit].into_iter().flatten().max()
    }
}

/// What one run produced.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// Stage times.
    pub times: StageTimes,
    /// Stage peaks.
    pub peaks: StagePeaks,
    /// The empirical NDF.
    pub ndf: EmpiricalNdf,
    /// The fit, when the knobs name a model.
    pub fit: Option<FitReport>,
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Run the pipeline on `path` with `knobs`.
pub fn run(path: &Path, read_opts: &ReadOptions, knobs: &Knobs) -> Result<Outcome> {
    let mut times = StageTimes::default();
    let mut peaks = StagePeaks::default();
    let tracking = mem::reset_peak();
    let base = mem::current_rss();
    let above = |p: Option<u64>| match (tracking, base, p) {
        (true, Some(b), Some(p)) => Some(p.saturating_sub(b)),
        _ => None,
    };

    let t = Instant::now();
    let mut hf = read_scan(path, read_opts)?;
    times.read = ms(t);
    if knobs.stride > 1 {
        let t = Instant::now();
        hf = subsample(&hf, knobs.stride)?;
        times.subsample = ms(t);
    }
    peaks.read = above(mem::peak_rss());

    mem::reset_peak();
    let t = Instant::now();
    // The bin count of a capped automatic grid needs the sample count: the valid points estimate it.
    let opts = knobs.ndf_options(hf.valid_count() as u64);
    let ndf = empirical_ndf(&hf, &opts)?;
    times.ndf = ms(t);
    peaks.ndf = above(mem::peak_rss());
    drop(hf);

    let fit = match knobs.model {
        Some(id) => {
            mem::reset_peak();
            let t = Instant::now();
            let r = fit_model(&ndf, id, &knobs.fit_options())?;
            times.fit = ms(t);
            peaks.fit = above(mem::peak_rss());
            Some(r)
        }
        None => None,
    };
    Ok(Outcome { times, peaks, ndf, fit })
}
