//! The same-run comparison with what a user would otherwise write: `fits/numpy_pipeline.py` (numpy
//! gradient + histogram + nlopt fit) run as a child process on the same NPY file, reported as ratios.

use std::path::{Path, PathBuf};
use std::process::Command;

use super::accuracy::RefNodes;
use super::knobs::Knobs;
use super::pipeline::{self, Outcome, StageTimes};
use super::presets::Preset;
use super::scene::{Scene, DX};
use super::sweep::median_times;
use crate::error::{Error, ErrorKind, Result};
use crate::models::{Model, ModelId};

/// What the numpy pipeline printed (times are medians over its repeats, in ms).
#[derive(Debug, Clone, PartialEq, serde::Deserialize, serde::Serialize)]
pub struct NumpyRun {
    /// `np.load`.
    pub t_load_ms: f64,
    /// `np.gradient` and the validity mask.
    pub t_gradient_ms: f64,
    /// Normals and `np.histogram2d`.
    pub t_histogram_ms: f64,
    /// The nlopt fit (0 without `--fit`).
    pub t_fit_ms: f64,
    /// Load + gradient + histogram.
    pub t_ndf_ms: f64,
    /// Everything.
    pub t_total_ms: f64,
    /// Normals binned.
    pub samples: u64,
    /// Bins inside the disk.
    pub bins: u64,
    /// Fitted ellipsoid parameters (with `--fit`).
    #[serde(default)]
    pub params: Option<std::collections::BTreeMap<String, f64>>,
    /// Objective evaluations of nlopt.
    #[serde(default)]
    pub evaluations: Option<u64>,
    /// numpy version.
    pub numpy: String,
    /// nlopt version.
    #[serde(default)]
    pub nlopt: Option<String>,
}

/// The speed-up targets against the numpy pipeline (numpy time / ndfit time, same run).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Target {
    /// Scan side at which the target applies (a comparison at another size is reported, not judged).
    pub size: usize,
    /// The ratio that must be reached.
    pub required: f64,
    /// The ratio aimed at (`None`: the requirement is the aim).
    pub aim: Option<f64>,
}

/// Scan -> empirical NDF at 4096^2: at least 10x numpy, 20x aimed at.
pub const NDF_TARGET: Target = Target { size: 4096, required: 10.0, aim: Some(20.0) };
/// Scan -> ellipsoid fit at 1024^2: at least 30x numpy + nlopt.
pub const FIT_TARGET: Target = Target { size: 1024, required: 30.0, aim: None };
/// Empirical NDF throughput: at least 150 million points per second (the NDF stage, scan grid points).
pub const THROUGHPUT_TARGET_MPTS: f64 = 150.0;

/// One same-run comparison.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Comparison {
    /// `ndf` (scan -> empirical NDF) or `fit` (scan -> ellipsoid fit).
    pub task: String,
    /// Scan side.
    pub size: usize,
    /// ndfit's median stage times (ms).
    pub ndfit: StageTimes,
    /// The numpy pipeline's.
    pub numpy: NumpyRun,
    /// numpy time / ndfit time for the task (the speed-up).
    pub ratio: f64,
    /// The speed-up target for this task.
    pub target: Target,
    /// Whether `ratio >= target.required` (`None`: not at the target's scan size, so not judged).
    pub met: Option<bool>,
    /// ndfit's NDF stage throughput in scan grid points per second (millions; read excluded).
    pub ndf_grid_mpts_per_s: f64,
    /// ndfit's NDF stage throughput in binned normals per second (millions).
    pub ndf_normals_mpts_per_s: f64,
    /// Bins across of the square histogram the numpy side used (ndfit's cells across, so both
    /// pipelines bin into about as many cells and their fits do the same work per evaluation).
    pub numpy_bins_across: usize,
    /// ndfit's fit error `delta(D_fit; D_truth)` (task `fit`).
    pub ndfit_fit_delta: Option<f64>,
    /// The numpy pipeline's fit error on the same nodes (task `fit`).
    pub numpy_fit_delta: Option<f64>,
    /// ndfit's settings: `defaults` (task `ndf`: what `ndfit ndf` does), `balanced` (task `fit`: what
    /// `ndfit fit` does, judged against the target) or `fast` (the same numpy run against the `fast`
    /// preset, for information: a user's cheapest choice, with both fits' errors beside it).
    pub preset: String,
}

/// The script: `fits/numpy_pipeline.py` under the current directory, else beside the crate's sources.
pub fn default_script() -> PathBuf {
    let local = PathBuf::from("fits/numpy_pipeline.py");
    if local.is_file() {
        local
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fits/numpy_pipeline.py")
    }
}

/// Run the numpy pipeline on `npy`.
pub fn run_numpy(python: &Path, script: &Path, npy: &Path, fit: bool, bins: usize, repeats: usize) -> Result<NumpyRun> {
    let mut cmd = Command::new(python);
    cmd.arg(script).arg(npy).arg("--dx").arg(DX.to_string()).arg("--repeat").arg(repeats.max(1).to_string());
    cmd.arg("--bins").arg(bins.to_string());
    if fit {
        cmd.arg("--fit");
    }
    let out = cmd.output().map_err(|e| Error::new(ErrorKind::Io, format!("cannot run {}: {e}", python.display())))?;
    if !out.status.success() {
        let err = String::from_utf8_lossy(&out.stderr);
        let last = err.lines().last().unwrap_or("no message");
        return Err(Error::new(ErrorKind::Io, format!("{} failed ({}): {last}", script.display(), out.status)));
    }
    serde_json::from_slice(&out.stdout).map_err(|e| Error::new(ErrorKind::BadData, format!("{}: unreadable output: {e}", script.display())))
}

/// Compare on `scene`: task `ndf` times read + NDF with the NDF defaults (what `ndfit ndf` writes),
/// task `fit` the whole pipeline to the ellipsoid with the `balanced` preset (what `ndfit fit` does),
/// and then, against the same numpy run, with the `fast` preset (not judged against the target).
pub fn compare(python: &Path, script: &Path, scene: &Scene, nodes: &RefNodes, fit: bool, repeats: usize) -> Result<Vec<Comparison>> {
    let knobs = if fit {
        Knobs { model: Some(ModelId::Ellipsoid), ..Preset::Balanced.bench_knobs(scene.size) }
    } else {
        Knobs { size: scene.size, model: None, ..Knobs::default() }
    };
    let (t, o) = timed_runs(scene, &knobs, repeats)?;
    // The numpy side bins into as many cells across the disk as ndfit did (at least 16, a sane histogram).
    let bins_across = o.ndf.grid.n.max(16);
    let np = run_numpy(python, script, &scene.path, fit, bins_across, repeats)?;
    let theirs = np.params.as_ref().and_then(|p| {
        let v: Option<Vec<f64>> = ModelId::Ellipsoid.param_names().iter().map(|k| p.get(*k).copied()).collect();
        Model::from_params(ModelId::Ellipsoid, &v?).ok()
    });
    let numpy_fit_delta = if fit { theirs.and_then(|m| nodes.delta_model(&m, &scene.truth)) } else { None };
    let row = |t: StageTimes, o: &Outcome, preset: &str| {
        let ratio = if fit { np.t_total_ms / t.total() } else { np.t_ndf_ms / (t.read + t.ndf) };
        let target = if fit { FIT_TARGET } else { NDF_TARGET };
        let judged = preset != "fast" && scene.size == target.size;
        Comparison {
            task: if fit { "fit" } else { "ndf" }.into(),
            size: scene.size,
            ndfit: t,
            numpy: np.clone(),
            ratio,
            target,
            met: judged.then_some(ratio >= target.required),
            ndf_grid_mpts_per_s: (scene.size * scene.size) as f64 / (t.ndf * 1e3),
            ndf_normals_mpts_per_s: o.ndf.n_samples as f64 / (t.ndf * 1e3),
            numpy_bins_across: bins_across,
            ndfit_fit_delta: o.fit.as_ref().and_then(|r| r.to_model().ok()).and_then(|m| nodes.delta_model(&m, &scene.truth)),
            numpy_fit_delta,
            preset: preset.into(),
        }
    };
    let mut out = vec![row(t, &o, if fit { "balanced" } else { "defaults" })];
    if fit {
        let fast = Knobs { model: Some(ModelId::Ellipsoid), ..Preset::Fast.bench_knobs(scene.size) };
        let (tf, of) = timed_runs(scene, &fast, repeats)?;
        out.push(row(tf, &of, "fast"));
    }
    Ok(out)
}

/// `repeats` runs of the pipeline: the median stage times and the last run's outcome.
fn timed_runs(scene: &Scene, knobs: &Knobs, repeats: usize) -> Result<(StageTimes, Outcome)> {
    let ro = scene.read_options();
    let mut runs = Vec::new();
    let mut last = None;
    for _ in 0..repeats.max(1) {
        let o = pipeline::run(&scene.path, &ro, knobs)?;
        runs.push(o.times);
        last = Some(o);
    }
    Ok((median_times(&runs), last.expect("at least one run was made")))
}
