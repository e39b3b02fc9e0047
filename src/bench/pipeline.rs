//! One run of the pipeline scan -> (subsample) -> empirical NDF -> fit, timed per stage, with the peak
//! resident memory of each stage: the stage functions of [`crate::pipeline`], one at a time.

use std::path::Path;
use std::time::Instant;

use super::knobs::{Knobs, Storage};
use super::mem;
use crate::error::Result;
use crate::fit::FitReport;
use crate::io::ReadOptions;
use crate::models::ModelChoice;
use crate::ndf::{empirical_ndf_f32, EmpiricalNdf, HeightsF32};
use crate::pipeline::{self, read_preprocessed};
use crate::preprocess::{FormRemoval, Preprocess};

/// Wall-clock time of each stage (ms).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct StageTimes {
    /// Reading the file into a heightfield.
    pub read: f64,
    /// Subsampling apart from the read (0: the read subsamples as it reads, see [`run`]).
    pub subsample: f64,
    /// Converting the heights to the NDF's storage (0 for f64).
    #[serde(default)]
    pub convert: f64,
    /// Normals, robust frame, histogram and bin integrals.
    pub ndf: f64,
    /// The fit (0 without a model).
    pub fit: f64,
}

impl StageTimes {
    /// The whole pipeline.
    pub fn total(&self) -> f64 {
        self.read + self.subsample + self.convert + self.ndf + self.fit
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

    // The pipeline's own read stage, with the scan as stored (no form removal): a stride subsamples as it
    // reads (a large NPY file reads only the kept points); the time is the read's.
    let t = Instant::now();
    let pre = Preprocess { form: FormRemoval::None, crop: None, subsample: knobs.stride.max(1), despike: crate::preprocess::Despike::None };
    let hf = read_preprocessed(path, read_opts, &pre)?;
    times.read = ms(t);
    peaks.read = above(mem::peak_rss());

    // The bin count of a capped automatic grid needs the sample count: the valid points estimate it
    // (timed with the NDF stage, where the library's own automatic choice does the same work).
    let t = Instant::now();
    let samples = if knobs.needs_sample_count() { hf.valid_count() as u64 } else { 0 };
    let opts = knobs.ndf_options(samples);
    let t_opts = ms(t);
    let ndf = match knobs.storage {
        Storage::F64 => {
            mem::reset_peak();
            let t = Instant::now();
            let ndf = pipeline::ndf(&hf, &opts)?;
            times.ndf = t_opts + ms(t);
            peaks.ndf = above(mem::peak_rss());
            drop(hf);
            ndf
        }
        Storage::F32 => {
            // f32 storage as the NDF module keeps it (`HeightsF32`: f32(h - mean), mean in f64). The
            // readers produce f64, so the conversion briefly holds both (1.5x the f64 heights: counted in
            // this stage's peak); the f64 heights are dropped before the NDF pass reads the f32 copy.
            mem::reset_peak();
            let t = Instant::now();
            let h32 = HeightsF32::from_heightfield(&hf);
            drop(hf);
            times.convert = ms(t);
            let t = Instant::now();
            let ndf = empirical_ndf_f32(&h32, &opts)?;
            times.ndf = t_opts + ms(t);
            peaks.ndf = above(mem::peak_rss());
            ndf
        }
    };

    let fit = match knobs.model {
        Some(id) => {
            mem::reset_peak();
            let t = Instant::now();
            let r = pipeline::fit(&ndf, ModelChoice::Model(id), &knobs.fit_options())?;
            times.fit = ms(t);
            peaks.fit = above(mem::peak_rss());
            Some(r)
        }
        None => None,
    };
    Ok(Outcome { times, peaks, ndf, fit })
}
