//! The sweep: which points are measured (one knob at a time around the defaults, plus the sizes and
//! the presets), and the measured row of each.

use std::path::Path;

use super::accuracy::{delta_ndf, param_errors, RefNodes};
use super::knobs::{Binning, Knobs, Storage};
use super::pipeline::{self, Outcome, StageTimes};
use super::presets::Preset;
use super::scene::Scene;
use crate::error::{Error, ErrorKind, Result};
use crate::fit::Solver;
use crate::models::ModelId;
use crate::ndf::NormalScheme;

/// Sizes and repetitions of a sweep.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// Scan sides for the size sweep (cost model in scan size).
    pub sizes: Vec<usize>,
    /// Scan side on which every other knob is swept (and the Pareto front drawn).
    pub knob_size: usize,
    /// Repetitions of each point (the median time is reported).
    pub repeats: usize,
    /// Fixed bin counts across the disk for the bin-count cost model.
    pub cells: Vec<usize>,
}

impl Plan {
    /// The quick plan: small scans, one repetition (seconds; what the test runs).
    pub fn quick() -> Plan {
        Plan { sizes: vec![128, 256], knob_size: 256, repeats: 1, cells: vec![31, 63, 127] }
    }

    /// The full plan of `docs/PERFORMANCE.md`: 512^2 to 8192^2, knobs at 2048^2, three repetitions.
    pub fn full() -> Plan {
        Plan { sizes: vec![512, 1024, 2048, 4096, 8192], knob_size: 2048, repeats: 3, cells: vec![31, 63, 127, 255, 511] }
    }

    /// Every point of the plan with its group (the knob it varies).
    pub fn points(&self) -> Vec<(String, Knobs)> {
        let mut out = Vec::new();
        // Every knob moves from the balanced preset (the knee); `defaults` is the library's NDF default.
        for &s in &self.sizes {
            out.push(("size".to_string(), Preset::Balanced.bench_knobs(s)));
            out.push(("size_ndf".to_string(), Knobs { model: None, ..Preset::Balanced.bench_knobs(s) }));
        }
        let base = Preset::Balanced.bench_knobs(self.knob_size);
        out.push(("defaults".into(), Knobs { size: self.knob_size, ..Knobs::default() }));
        for stride in [2, 4, 8] {
            out.push(("stride".into(), Knobs { stride, ..base.clone() }));
        }
        for t in [16.0, 64.0, 1024.0, 4096.0] {
            out.push(("target_count".into(), Knobs { target_count: t, max_cells: None, ..base.clone() }));
        }
        out.push(("target_count".into(), Knobs { max_cells: None, ..base.clone() }));
        for &c in &self.cells {
            out.push(("cells".into(), Knobs { cells: Some(c), ..base.clone() }));
        }
        out.push(("scheme".into(), Knobs { scheme: NormalScheme::Triangles, ..base.clone() }));
        out.push(("binning".into(), Knobs { binning: Binning::Plain, ..base.clone() }));
        out.push(("storage".into(), Knobs { storage: Storage::F32, ..base.clone() }));
        for solver in [Solver::Lbfgs, Solver::NelderMead] {
            out.push(("solver".into(), Knobs { solver, ..base.clone() }));
        }
        for tol in [1e-3, 1e-6, 1e-12] {
            out.push(("tol".into(), Knobs { tol, ..base.clone() }));
        }
        out.push(("starts".into(), Knobs { extra_starts: 4, ..base.clone() }));
        for m in [ModelId::Ggx, ModelId::GgxAniso, ModelId::BeckmannAniso] {
            out.push(("model".into(), Knobs { model: Some(m), ..base.clone() }));
        }
        for p in Preset::ALL {
            out.push((format!("preset_{}", p.as_str()), p.bench_knobs(self.knob_size)));
        }
        out
    }
}

/// One measured point: the knobs, the median stage times, memory, and accuracy against the truth.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Row {
    /// The knob this point varies (`size`, `stride`, `cells`, ..., `preset_<name>`).
    pub group: String,
    /// Scan side.
    pub size: usize,
    /// Subsampling stride.
    pub stride: usize,
    /// Normal scheme.
    pub scheme: String,
    /// Binning scheme.
    pub binning: String,
    /// Cells across (a number, or `auto<target count>`).
    pub cells: String,
    /// Model fitted (empty: NDF only).
    pub model: String,
    /// Solver.
    pub solver: String,
    /// Relative tolerance.
    pub tol: f64,
    /// Extra ellipsoid starts.
    pub extra_starts: usize,
    /// Storage of the heights for the NDF pass (`f64`, `f32`).
    #[serde(default = "default_storage")]
    pub storage: String,
    /// Samples (normals) binned.
    pub samples: u64,
    /// Bins with `W > 0` (every bin the fit sees).
    pub bins: usize,
    /// Median read time (ms).
    pub t_read_ms: f64,
    /// Median subsample time (ms).
    pub t_subsample_ms: f64,
    /// Median time of the conversion to the NDF's storage (ms; 0 for f64).
    #[serde(default)]
    pub t_convert_ms: f64,
    /// Median NDF time (ms).
    pub t_ndf_ms: f64,
    /// Median fit time (ms).
    pub t_fit_ms: f64,
    /// Median whole-pipeline time (ms).
    pub t_total_ms: f64,
    /// NDF throughput: samples per second of the NDF stage, in millions.
    pub ndf_mpts_per_s: f64,
    /// Peak resident memory of the pipeline above its start (MiB; empty when unavailable). With
    /// [`Isolation::Child`] the start is a fresh process, so this is the pipeline's own footprint.
    pub peak_mib: Option<f64>,
    /// Peak of the NDF stage above the pipeline's start (MiB).
    pub peak_ndf_mib: Option<f64>,
    /// `delta(D_empirical; D_truth)` on the NDF's bins.
    pub ndf_delta: Option<f64>,
    /// `delta(D_fit; D_truth)` on the fixed reference nodes.
    pub fit_delta: Option<f64>,
    /// Largest relative alpha error (ellipsoid fits only).
    pub alpha_err: Option<f64>,
    /// Largest angle error in radians (ellipsoid fits only).
    pub angle_err: Option<f64>,
    /// Whether the solver converged.
    pub converged: Option<bool>,
    /// Residual evaluations of the solver.
    pub evaluations: Option<usize>,
    /// The fit's objective (Poisson deviance) at its optimum: solvers of one NDF compare on it.
    #[serde(default)]
    pub objective: Option<f64>,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        f64::NAN
    } else if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Median of each stage over runs.
pub fn median_times(runs: &[StageTimes]) -> StageTimes {
    let m = |f: fn(&StageTimes) -> f64| median(runs.iter().map(f).collect());
    StageTimes { read: m(|t| t.read), subsample: m(|t| t.subsample), convert: m(|t| t.convert), ndf: m(|t| t.ndf), fit: m(|t| t.fit) }
}

fn default_storage() -> String {
    Storage::F64.as_str().into()
}

const MIB: f64 = 1024.0 * 1024.0;

/// Measure one point `repeats` times on `scene` and turn it into a row.
pub fn measure(group: &str, knobs: &Knobs, scene: &Scene, nodes: &RefNodes, repeats: usize) -> Result<Row> {
    let ro = scene.read_options();
    let mut runs = Vec::with_capacity(repeats.max(1));
    let mut first: Option<Outcome> = None;
    for _ in 0..repeats.max(1) {
        let o = pipeline::run(&scene.path, &ro, knobs)?;
        runs.push(o.times);
        first.get_or_insert(o);
    }
    let o = first.expect("at least one run was made");
    let t = median_times(&runs);
    let fit_model = o.fit.as_ref().and_then(|r| r.to_model().ok());
    let perr = fit_model.as_ref().and_then(|m| param_errors(m, &scene.truth));
    Ok(Row {
        group: group.to_string(),
        size: knobs.size,
        stride: knobs.stride,
        scheme: knobs.scheme.as_str().into(),
        binning: knobs.binning.as_str().into(),
        cells: knobs.cells_label(),
        model: knobs.model.map_or(String::new(), |m| m.as_str().to_string()),
        solver: knobs.solver.as_str().into(),
        tol: knobs.tol,
        extra_starts: knobs.extra_starts,
        storage: knobs.storage.as_str().into(),
        samples: o.ndf.n_samples,
        bins: o.ndf.bins.iter().filter(|b| b.proj_solid_angle > 0.0).count(),
        t_read_ms: t.read,
        t_subsample_ms: t.subsample,
        t_convert_ms: t.convert,
        t_ndf_ms: t.ndf,
        t_fit_ms: t.fit,
        t_total_ms: t.total(),
        ndf_mpts_per_s: o.ndf.n_samples as f64 / (t.ndf * 1e3),
        peak_mib: o.peaks.total().map(|b| b as f64 / MIB),
        peak_ndf_mib: o.peaks.ndf.map(|b| b as f64 / MIB),
        ndf_delta: delta_ndf(&o.ndf, &scene.truth),
        fit_delta: fit_model.as_ref().and_then(|m| nodes.delta_model(m, &scene.truth)),
        alpha_err: perr.map(|p| p.0),
        angle_err: perr.map(|p| p.1),
        converged: o.fit.as_ref().map(|r| r.solver.converged),
        evaluations: o.fit.as_ref().map(|r| r.solver.evaluations),
        objective: o.fit.as_ref().map(|r| r.quality.objective_value),
    })
}

/// How each point is measured.
#[derive(Debug, Clone, PartialEq)]
pub enum Isolation {
    /// In this process (peaks then count only fresh pages: memory the allocator kept from an earlier
    /// point is reused without raising `VmHWM`, so small scans read low).
    InProcess,
    /// In a fresh child process per point, this executable run as `EXE bench --child-point JSON`, so
    /// each point's peak memory starts from an empty heap.
    Child(std::path::PathBuf),
}

/// What a child process is handed: one point, its scan and the reference frame of the fit error.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ChildPoint {
    /// Group label.
    pub group: String,
    /// Knobs.
    pub knobs: Knobs,
    /// The scene's NPY file.
    pub path: std::path::PathBuf,
    /// Repetitions.
    pub repeats: usize,
    /// Frame of the reference nodes.
    pub frame: crate::ndf::SlopeFrame,
}

/// Run a [`ChildPoint`] (in the child): the scene's truth is [`super::scene::truth_params`].
pub fn run_child_point(p: &ChildPoint) -> Result<Row> {
    let scene = Scene::open(&p.path, p.knobs.size)?;
    let nodes = RefNodes::new(&p.frame, REF_CELLS);
    measure(&p.group, &p.knobs, &scene, &nodes, p.repeats)
}

fn measure_isolated(
    iso: &Isolation,
    group: &str,
    k: &Knobs,
    scene: &Scene,
    nodes: &RefNodes,
    frame: &crate::ndf::SlopeFrame,
    repeats: usize,
) -> Result<Row> {
    match iso {
        Isolation::InProcess => measure(group, k, scene, nodes, repeats),
        Isolation::Child(exe) => {
            let cp = ChildPoint { group: group.into(), knobs: k.clone(), path: scene.path.clone(), repeats, frame: *frame };
            let arg = serde_json::to_string(&cp).map_err(|e| Error::invalid(format!("child point: {e}")))?;
            let out = std::process::Command::new(exe)
                .args(["bench", "--child-point", &arg])
                .output()
                .map_err(|e| Error::new(ErrorKind::Io, format!("cannot run {}: {e}", exe.display())))?;
            if !out.status.success() {
                let err = String::from_utf8_lossy(&out.stderr);
                return Err(Error::new(ErrorKind::Numerical, format!("point {group} failed: {}", err.trim())));
            }
            serde_json::from_slice(&out.stdout).map_err(|e| Error::new(ErrorKind::BadData, format!("child output: {e}")))
        }
    }
}

/// Run every point of `plan`, writing the scans into `dir` (removed after use unless `keep`);
/// `progress` is told each row.
pub fn run(plan: &Plan, dir: &Path, iso: &Isolation, keep: bool, mut progress: impl FnMut(&Row)) -> Result<Vec<Row>> {
    let points = plan.points();
    let mut sizes: Vec<usize> = points.iter().map(|p| p.1.size).collect();
    sizes.sort_unstable();
    sizes.dedup();
    let mut rows = Vec::with_capacity(points.len());
    let mut reference: Option<(RefNodes, crate::ndf::SlopeFrame)> = None;
    for size in sizes {
        let scene = Scene::create(dir, size)?;
        // The reference nodes follow the lobe: the robust frame of the first scan's default NDF.
        if reference.is_none() {
            let o = pipeline::run(&scene.path, &scene.read_options(), &Knobs { size, model: None, ..Knobs::default() })?;
            reference = Some((RefNodes::new(&o.ndf.frame, REF_CELLS), o.ndf.frame));
        }
        let (nodes, frame) = reference.as_ref().expect("set just above");
        for (group, k) in points.iter().filter(|p| p.1.size == size) {
            let row = measure_isolated(iso, group, k, &scene, nodes, frame, plan.repeats)?;
            progress(&row);
            rows.push(row);
        }
        // Keep the disk use of the sweep to one scan at a time.
        if !keep {
            let _ = std::fs::remove_file(&scene.path);
        }
    }
    Ok(rows)
}

/// Cells across the reference grid of the fit error: finer than any automatic NDF grid of the sweep
/// (at most [`crate::ndf::MAX_AUTO_CELLS`] = 255), so the quadrature of delta is not the limit.
pub const REF_CELLS: usize = 301;
