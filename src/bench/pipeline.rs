//! One run of the pipeline scan -> (subsample) -> empirical NDF -> fit, timed per stage, with the peak
//! resident memory of each stage.

use std::path::Path;
use std::time::Instant;

use super::knobs::{Knobs, Storage};
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

/// The heights as `storage` keeps them, for the NDF pass.
///
/// f32: `f32(h - mean)` with the mean of the valid heights taken in f64, widened back to f64, which is
/// bit for bit what the f32 storage of the NDF engineer's branch differences (it widens every stored
/// height to f64 before differencing), so the **accuracy** columns of an f32 row are those of f32
/// storage. Until that branch is merged the bench runs the f64 kernel over the rounded heights, so the
/// f32 row's **time and memory** are not yet those of f32 storage (the NDF pass reads 8 bytes per
/// height, not 4); the rounding pass is timed as `convert`.
pub fn store_heights(mut hf: crate::heightfield::Heightfield, storage: Storage) -> crate::heightfield::Heightfield {
    if storage == Storage::F32 {
        let (sum, n) = hf.z.iter().filter(|h| !h.is_nan()).fold((0.0f64, 0usize), |a, &h| (a.0 + h, a.1 + 1));
        // Guard: no valid height leaves nothing to centre; the offset 0 keeps NaNs as they are.
        let mean = if n > 0 { sum / n as f64 } else { 0.0 };
        for h in hf.z.iter_mut() {
            *h = f64::from((*h - mean) as f32);
        }
    }
    hf
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

    if knobs.storage != Storage::F64 {
        let t = Instant::now();
        hf = store_heights(hf, knobs.storage);
        times.convert = ms(t);
    }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::heightfield::Heightfield;

    /// f32 storage keeps `h - mean` to f32 rounding (half an ulp: |error| <= |h - mean| 2^-24), mean
    /// taken in f64, so a 0.5 m stage offset over 100 nm of detail keeps the detail's differences to
    /// ~1e-15 m (the offset would leave only ~6e-8 m resolution in a plain f32); NaN stays NaN.
    #[test]
    fn f32_storage_rounds_around_the_mean() {
        let (nx, ny) = (16, 8);
        let z: Vec<f64> = (0..nx * ny).map(|i| if i == 5 { f64::NAN } else { 0.5 + 1e-7 * ((i as f64) * 0.37).sin() }).collect();
        let hf = Heightfield::new(nx, ny, 1e-6, 1e-6, z.clone()).expect("grid");
        let valid: Vec<f64> = z.iter().copied().filter(|v| !v.is_nan()).collect();
        let mean = valid.iter().sum::<f64>() / valid.len() as f64;
        let st = store_heights(hf.clone(), Storage::F32);
        assert!(st.z[5].is_nan());
        for (a, b) in st.z.iter().zip(&z).filter(|(_, b)| !b.is_nan()) {
            let d = b - mean;
            assert!((a - d).abs() <= d.abs() * 2f64.powi(-24), "{a} vs {d}");
        }
        // Differences of neighbours (what the slopes see) keep the 1e-7 m detail to 1e-6 relative.
        for i in 1..nx {
            let (ds, dz) = (st.z[i] - st.z[i - 1], z[i] - z[i - 1]);
            if i != 5 && i != 6 {
                assert!((ds - dz).abs() <= 1e-6 * 1e-7, "{ds} vs {dz}");
            }
        }
        assert_eq!(store_heights(hf.clone(), Storage::F64).z.iter().map(|v| v.to_bits()).collect::<Vec<_>>(), z.iter().map(|v| v.to_bits()).collect::<Vec<_>>());
    }
}
