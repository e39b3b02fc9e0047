//! `ndfit bench --wave`: `ndfit wave` against the independent numpy implementation
//! (`fits/ndfitpy/wave.py`), as whole processes in the same run, and the accuracy cost of the
//! `--level-ratio` knob.
//!
//! - **Speed and memory.** A synthetic Gaussian scan ([`WavePlan::full`]: 4096^2 at 0.1 um, RMS slope
//!   0.05 per axis, correlation length 2 um; periodic spectral synthesis, `synth::gaussian_surface`) is
//!   written as a float64 NPY, then `ndfit wave` and `python -m ndfitpy.wave` run on it with the same
//!   settings (3 wavelengths, 3 incidences, default coherence, no form removal), round-robin
//!   ([`super::process::interleave`]), medians of `repeats` runs after one unrecorded run of each. The
//!   unrecorded ndfit run carries `--report-memory`: its peak resident set (`VmHWM` of the process
//!   itself) is set against the heights' bytes (`8 nx ny`). The same on real scans (plane removed by both),
//!   where they exist.
//! - **The level ratio.** `ndfit wave --level-ratio R --grid 32 --grid-out` at each ratio of the plan,
//!   the first the reference: the time, and the largest relative difference of each record's
//!   `diffuse_albedo` and of the grid (against each wavelength and incidence's largest cell) from the
//!   reference's.

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use super::process::{interleave, loadavg, run_once, Cmd, Measured};
use crate::error::{Error, ErrorKind, Result};
use crate::synth::{gaussian_surface, GaussianParams, SynthSettings};

/// Aim of the speed-up: numpy's time over ndfit's on the synthetic scan of [`TARGET_SIZE`] (2 cores).
pub const TARGET_RATIO: f64 = 3.0;
/// Aim of the memory: ndfit's peak resident set over the heights' bytes on the synthetic scan.
pub const TARGET_MEMORY: f64 = 3.0;
/// Scan side at which the aims are judged (other sizes are reported, not judged).
pub const TARGET_SIZE: usize = 4096;

/// What to measure.
#[derive(Debug, Clone, serde::Serialize)]
pub struct WavePlan {
    /// Side of the synthetic speed scan.
    pub size: usize,
    /// Side of the synthetic scan of the level-ratio sweep (the speed scan itself when equal).
    pub level_size: usize,
    /// Spacing of the synthetic scans (m): `lambda / (2 dx)` must exceed 2 at 450 nm for the band to cover
    /// every outgoing direction from every incidence.
    pub dx: f64,
    /// RMS slope per axis of the synthetic scans.
    pub sigma: f64,
    /// Correlation length of the synthetic scans (m).
    pub corr_length: f64,
    /// Recorded runs per command (medians reported).
    pub repeats: usize,
    /// Wavelengths (nm).
    pub wavelengths_nm: Vec<f64>,
    /// Incidences (degrees).
    pub incidences_deg: Vec<f64>,
    /// Level ratios of the sweep; the first is the reference.
    pub level_ratios: Vec<f64>,
    /// Cells per side of the compared grid.
    pub grid: usize,
    /// Real scans timed against numpy (missing files are skipped with a note); the first present one is
    /// also swept over the level ratios.
    pub scans: Vec<PathBuf>,
    /// The ndfit executable measured.
    pub ndfit: PathBuf,
    /// Python with numpy (none: ndfit alone).
    pub python: Option<PathBuf>,
    /// The folder holding the `ndfitpy` package (put first on Python's path).
    pub fits: PathBuf,
}

impl WavePlan {
    /// The standard measurement: 4096^2, three runs each, the level sweep on 2048^2 and the shared
    /// scans `st_x3p-2.x3p` and `st_plu-1.plu`.
    pub fn full(ndfit: PathBuf, python: Option<PathBuf>) -> WavePlan {
        WavePlan {
            size: 4096,
            level_size: 2048,
            dx: 1e-7,
            sigma: 0.05,
            corr_length: 2e-6,
            repeats: 3,
            wavelengths_nm: vec![450.0, 550.0, 650.0],
            incidences_deg: vec![0.0, 45.0, 75.0],
            level_ratios: vec![1.02, 1.05, 1.1, 1.2, 1.4],
            grid: 32,
            scans: default_scans(),
            python,
            fits: default_fits(),
            ndfit,
        }
    }

    /// The same at 2048^2 (speed and level sweep on one scan), one run each.
    pub fn quick(ndfit: PathBuf, python: Option<PathBuf>) -> WavePlan {
        WavePlan { size: 2048, level_size: 2048, repeats: 1, ..WavePlan::full(ndfit, python) }
    }

    /// Check the plan's numbers.
    pub fn check(&self) -> Result<()> {
        let bad = |m: String| Err(Error::new(ErrorKind::InvalidInput, format!("--wave: {m}")));
        if !(16..=16384).contains(&self.size) || !(16..=16384).contains(&self.level_size) {
            return bad(format!("scan sides {} and {} must be 16 to 16384", self.size, self.level_size));
        }
        if self.repeats == 0 {
            return bad("at least one run per command".into());
        }
        if self.level_ratios.is_empty() || self.level_ratios.iter().any(|&r| !(r > 1.0 && r <= 2.0)) {
            return bad(format!("level ratios {:?} must each lie in (1, 2]", self.level_ratios));
        }
        if !(1..=4096).contains(&self.grid) {
            return bad(format!("grid {} is outside 1..=4096", self.grid));
        }
        Ok(())
    }
}

/// The shared real scans (`../shared/data/scans/` from the current folder, else beside the crate).
pub fn default_scans() -> Vec<PathBuf> {
    let local = PathBuf::from("../shared/data/scans");
    let dir = if local.is_dir() { local } else { Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/scans") };
    ["st_x3p-2.x3p", "st_plu-1.plu"].iter().map(|n| dir.join(n)).collect()
}

/// `fits/` under the current folder, else beside the crate's sources.
pub fn default_fits() -> PathBuf {
    let local = PathBuf::from("fits");
    if local.join("ndfitpy/wave.py").is_file() {
        local
    } else {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("fits")
    }
}

/// The Python of `fits/.venv` when there is one.
pub fn default_python() -> Option<PathBuf> {
    let p = default_fits().join(".venv/bin/python");
    p.is_file().then_some(p)
}

/// One scan timed: ndfit against numpy.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SpeedRow {
    /// `synthetic` or the file's name.
    pub scan: String,
    /// The file measured.
    pub path: PathBuf,
    /// `[nx, ny]` (from ndfit's report).
    pub grid: [usize; 2],
    /// Spacing (m).
    pub spacing_m: [f64; 2],
    /// Bytes of the heights as float64, `8 nx ny`.
    pub heights_bytes: u64,
    /// Coherence patches averaged, and their side in samples.
    pub patches: usize,
    /// Patch side in samples (x, y).
    pub patch_samples: [usize; 2],
    /// `v_z` levels computed.
    pub levels: usize,
    /// ndfit's runs.
    pub ndfit: Measured,
    /// numpy's runs.
    pub numpy: Option<Measured>,
    /// numpy's median time over ndfit's.
    pub ratio: Option<f64>,
    /// ndfit's peak resident set from `--report-memory` (bytes; `VmHWM` of the process itself).
    pub ndfit_peak_rss: Option<u64>,
    /// [`SpeedRow::ndfit_peak_rss`] over [`SpeedRow::heights_bytes`].
    pub memory_over_heights: Option<f64>,
    /// Whether the ratio reaches [`TARGET_RATIO`] (`None`: not the synthetic scan of [`TARGET_SIZE`], or no numpy).
    pub ratio_met: Option<bool>,
    /// Whether the memory stays within [`TARGET_MEMORY`] (`None`: not judged).
    pub memory_met: Option<bool>,
    /// Largest relative difference of `diffuse_albedo` between ndfit's and numpy's records.
    pub numpy_diffuse_rel_diff: Option<f64>,
    /// Largest absolute difference of `specular` between them.
    pub numpy_specular_abs_diff: Option<f64>,
}

/// One level ratio against the reference.
#[derive(Debug, Clone, serde::Serialize)]
pub struct LevelPoint {
    /// `--level-ratio`.
    pub level_ratio: f64,
    /// Levels computed.
    pub levels: usize,
    /// The runs (ndfit with `--grid N --grid-out`).
    pub time: Measured,
    /// The reference's median time over this one's.
    pub speedup: f64,
    /// Largest `|d - d_ref| / d_ref` of the records' `diffuse_albedo`.
    pub diffuse_rel_diff: f64,
    /// Largest `|s - s_ref|` of the records' `specular`.
    pub specular_abs_diff: f64,
    /// Largest `|g - g_ref|` over the grid's cells, over the largest `g_ref` of the same wavelength and
    /// incidence.
    pub grid_rel_diff: f64,
}

/// The level-ratio sweep on one scan.
#[derive(Debug, Clone, serde::Serialize)]
pub struct LevelSweep {
    /// `synthetic` or the file's name.
    pub scan: String,
    /// `[nx, ny]`.
    pub grid: [usize; 2],
    /// One per ratio, the reference first.
    pub points: Vec<LevelPoint>,
}

/// What `--wave` writes (`wave.json`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct WaveBench {
    /// `ndfit.bench.wave/1`.
    pub schema: &'static str,
    /// The plan.
    pub plan: WavePlan,
    /// Cores the machine offers.
    pub threads: usize,
    /// `/proc/loadavg` when the run started.
    pub loadavg_start: Option<[f64; 3]>,
    /// `/proc/loadavg` when it ended.
    pub loadavg_end: Option<[f64; 3]>,
    /// The speed rows: the synthetic scan first, then the real scans found.
    pub speed: Vec<SpeedRow>,
    /// The level-ratio sweeps.
    pub level_ratio: Vec<LevelSweep>,
    /// What was skipped and why.
    pub notes: Vec<String>,
    /// Wall time of the whole run (s).
    pub wall_s: f64,
}

/// Write the synthetic scan of side `n` as `dir/gaussian_<n>.npy` (kept when already there).
pub fn write_scan(plan: &WavePlan, dir: &Path, n: usize) -> Result<PathBuf> {
    let path = dir.join(format!("gaussian_{n}.npy"));
    if path.is_file() {
        return Ok(path);
    }
    let s = SynthSettings { nx: n, ny: n, dx: plan.dx, dy: plan.dx, seed: 11, ..Default::default() };
    let p = GaussianParams { sigma_x: plan.sigma, sigma_y: plan.sigma, theta_z: 0.0, corr_length: plan.corr_length };
    let hf = gaussian_surface(&s, &p)?.0;
    super::scene::write_npy_f64(&path, &hf)?;
    Ok(path)
}

fn join(v: &[f64]) -> String {
    v.iter().map(|x| x.to_string()).collect::<Vec<_>>().join(",")
}

/// How a scan is read: an NPY needs its spacing and unit, and keeps its heights as written.
fn read_args(scan: &Path, dx: f64) -> (Vec<OsString>, bool) {
    if scan.extension().is_some_and(|e| e.eq_ignore_ascii_case("npy")) {
        (vec!["--dx".into(), dx.to_string().into(), "--z-scale".into(), "1".into()], true)
    } else {
        (Vec::new(), false)
    }
}

/// `ndfit wave SCAN ...` with the plan's wavelengths and incidences, writing `out`.
fn ndfit_cmd(plan: &WavePlan, scan: &Path, out: &Path, extra: &[OsString]) -> Cmd {
    let (mut argv, npy) = read_args(scan, plan.dx);
    argv.splice(0..0, [plan.ndfit.clone().into_os_string(), "wave".into(), scan.as_os_str().to_owned()]);
    let form = if npy { "none" } else { "plane" };
    for a in ["--form", form, "--despike", "none", "--quiet", "--wavelength"] {
        argv.push(a.into());
    }
    argv.push(join(&plan.wavelengths_nm).into());
    argv.push("--incidence".into());
    argv.push(join(&plan.incidences_deg).into());
    argv.extend(extra.iter().cloned());
    argv.push("-o".into());
    argv.push(out.as_os_str().to_owned());
    Cmd::new("ndfit wave", argv)
}

/// `python -m ndfitpy.wave SCAN ...` with the same settings (the package's folder put first on the path).
fn numpy_cmd(plan: &WavePlan, python: &Path, scan: &Path, out: &Path) -> Cmd {
    let (read, npy) = read_args(scan, plan.dx);
    let mut argv: Vec<OsString> = vec![
        python.as_os_str().to_owned(),
        "-c".into(),
        "import runpy, sys; sys.path.insert(0, sys.argv.pop(1)); runpy.run_module('ndfitpy.wave', run_name='__main__', alter_sys=True)"
            .into(),
        plan.fits.as_os_str().to_owned(),
        scan.as_os_str().to_owned(),
    ];
    argv.extend(read);
    argv.push("--form".into());
    argv.push(if npy { "none" } else { "plane" }.into());
    argv.push("--wavelength".into());
    argv.push(join(&plan.wavelengths_nm).into());
    argv.push("--incidence".into());
    argv.push(join(&plan.incidences_deg).into());
    argv.push("-o".into());
    argv.push(out.as_os_str().to_owned());
    Cmd::new("numpy ndfitpy.wave", argv)
}

/// Run `cmd` once with `--report-memory`, returning the peak resident set it prints (bytes).
fn peak_of(cmd: &Cmd) -> Result<Option<u64>> {
    let (prog, args) = cmd.argv.split_first().ok_or_else(|| Error::invalid("empty command"))?;
    let out = std::process::Command::new(prog)
        .args(args)
        .arg("--report-memory")
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::null())
        .output()
        .map_err(|e| Error::new(ErrorKind::Io, format!("{}: cannot start: {e}", cmd.label)))?;
    let err = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        let last = err.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("").trim();
        return Err(Error::new(ErrorKind::Io, format!("{} failed ({}): {last}", cmd.label, out.status)));
    }
    Ok(parse_peak(&err))
}

/// The figure of `ndfit: peak resident memory 80.7 MiB` (bytes).
fn parse_peak(stderr: &str) -> Option<u64> {
    let line = stderr.lines().find_map(|l| l.trim().strip_prefix("ndfit: peak resident memory "))?;
    let mib: f64 = line.strip_suffix("MiB")?.trim().parse().ok()?;
    Some((mib * 1024.0 * 1024.0) as u64)
}

fn read_json(path: &Path) -> Result<serde_json::Value> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(e).with_path(path))?;
    serde_json::from_slice(&bytes).map_err(|e| Error::corrupt(format!("not JSON ({e})")).with_path(path))
}

/// `(diffuse_albedo, specular)` of each record.
fn records(v: &serde_json::Value) -> Vec<(f64, f64)> {
    let f = |r: &serde_json::Value, k: &str| r[k].as_f64().unwrap_or(f64::NAN);
    v["records"].as_array().map(|a| a.iter().map(|r| (f(r, "diffuse_albedo"), f(r, "specular"))).collect()).unwrap_or_default()
}

/// Largest relative difference of the diffuse albedos and largest absolute difference of the mirror
/// shares, record by record (NaN when the counts differ).
fn record_diffs(a: &[(f64, f64)], reference: &[(f64, f64)]) -> (f64, f64) {
    if a.len() != reference.len() || a.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let mut rel = 0.0f64;
    let mut abs = 0.0f64;
    for (x, r) in a.iter().zip(reference) {
        rel = rel.max((x.0 - r.0).abs() / r.0.abs().max(1e-300));
        abs = abs.max((x.1 - r.1).abs());
    }
    (rel, abs)
}

/// A float64 NPY: its shape and values (C order).
pub fn read_npy_f64(path: &Path) -> Result<(Vec<usize>, Vec<f64>)> {
    let b = std::fs::read(path).map_err(|e| Error::io(e).with_path(path))?;
    let bad = |m: &str| Error::corrupt(m.to_string()).with_path(path);
    if b.len() < 10 || &b[..6] != b"\x93NUMPY" {
        return Err(bad("not an NPY file"));
    }
    let (hlen, start) = match b[6] {
        1 => (u16::from_le_bytes([b[8], b[9]]) as usize, 10),
        _ if b.len() >= 12 => (u32::from_le_bytes([b[8], b[9], b[10], b[11]]) as usize, 12),
        _ => return Err(bad("truncated NPY header")),
    };
    let header = std::str::from_utf8(b.get(start..start + hlen).ok_or_else(|| bad("truncated NPY header"))?)
        .map_err(|_| bad("NPY header is not text"))?;
    if !header.contains("'<f8'") || header.contains("'fortran_order': True") {
        return Err(bad("not a C-ordered little-endian float64 NPY"));
    }
    let shape_text = header.split("'shape':").nth(1).and_then(|s| s.split('(').nth(1)).and_then(|s| s.split(')').next());
    let shape: Vec<usize> = shape_text
        .ok_or_else(|| bad("NPY header has no shape"))?
        .split(',')
        .filter(|s| !s.trim().is_empty())
        .map(|s| s.trim().parse().map_err(|_| bad("NPY shape is not numbers")))
        .collect::<Result<_>>()?;
    let n: usize = shape.iter().product();
    let data = b.get(start + hlen..start + hlen + 8 * n).ok_or_else(|| bad("NPY data shorter than its shape"))?;
    Ok((shape, data.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().expect("8 bytes"))).collect()))
}

/// Largest `|g - g_ref|` over each `N x N` slice's largest `|g_ref|`.
fn grid_diff(g: &[f64], reference: &[f64], cells: usize) -> f64 {
    if g.len() != reference.len() || cells == 0 || g.is_empty() {
        return f64::NAN;
    }
    let mut worst = 0.0f64;
    for (a, r) in g.chunks(cells).zip(reference.chunks(cells)) {
        let peak = r.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let d = a.iter().zip(r).fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
        if peak > 0.0 {
            worst = worst.max(d / peak);
        } else if d > 0.0 {
            worst = f64::INFINITY;
        }
    }
    worst
}

fn mib(b: Option<u64>) -> String {
    b.map_or("-".into(), |b| format!("{:.1}", b as f64 / (1024.0 * 1024.0)))
}

fn file_label(p: &Path) -> String {
    p.file_name().map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into_owned())
}

/// Time ndfit against numpy on `scan`.
fn speed_row(plan: &WavePlan, work: &Path, label: &str, scan: &Path, judged: bool, log: &mut impl FnMut(&str)) -> Result<SpeedRow> {
    let (nd_out, py_out) = (work.join("ndfit_wave.json"), work.join("numpy_wave.json"));
    let nd = ndfit_cmd(plan, scan, &nd_out, &[]);
    // The unrecorded runs: ndfit's with --report-memory (its own peak), numpy's to warm the page cache.
    let peak = peak_of(&nd)?;
    let mut cmds = vec![nd];
    if let Some(py) = &plan.python {
        let c = numpy_cmd(plan, py, scan, &py_out);
        run_once(&c)?;
        cmds.push(c);
    }
    let measured = interleave(&cmds, plan.repeats, 0, |c, s| {
        log(&format!(
            "wave {label:<14} {:<20} {:>9.1} ms  CPU {:>9.1} ms  {:>7} MiB",
            c.label,
            s.wall_s * 1e3,
            s.cpu_s.unwrap_or(f64::NAN) * 1e3,
            mib(s.peak_rss)
        ))
    })?;
    let report = read_json(&nd_out)?;
    let us = |k: &serde_json::Value| k.as_u64().unwrap_or(0) as usize;
    let grid = [us(&report["grid"][0]), us(&report["grid"][1])];
    let spacing_m = [report["spacing_m"][0].as_f64().unwrap_or(f64::NAN), report["spacing_m"][1].as_f64().unwrap_or(f64::NAN)];
    let heights_bytes = 8 * grid[0] as u64 * grid[1] as u64;
    let mut it = measured.into_iter();
    let ndfit = it.next().ok_or_else(|| Error::invalid("no ndfit runs"))?;
    let numpy = it.next();
    let ratio = numpy.as_ref().map(|n| n.median_ms / ndfit.median_ms);
    let (diff, spec) = if numpy.is_some() {
        let (a, b) = record_diffs(&records(&report), &records(&read_json(&py_out)?));
        (Some(a), Some(b))
    } else {
        (None, None)
    };
    let memory_over_heights = peak.map(|p| p as f64 / heights_bytes as f64);
    Ok(SpeedRow {
        scan: label.to_string(),
        path: scan.to_path_buf(),
        grid,
        spacing_m,
        heights_bytes,
        patches: us(&report["patches"]["used"]),
        patch_samples: [us(&report["patches"]["samples"][0]), us(&report["patches"]["samples"][1])],
        levels: us(&report["levels"]),
        ratio_met: if judged { ratio.map(|r| r >= TARGET_RATIO) } else { None },
        memory_met: if judged { memory_over_heights.map(|m| m <= TARGET_MEMORY) } else { None },
        ndfit,
        numpy,
        ratio,
        ndfit_peak_rss: peak,
        memory_over_heights,
        numpy_diffuse_rel_diff: diff,
        numpy_specular_abs_diff: spec,
    })
}

/// The level-ratio sweep on `scan`.
fn level_sweep(plan: &WavePlan, work: &Path, label: &str, scan: &Path, log: &mut impl FnMut(&str)) -> Result<LevelSweep> {
    let cmds: Vec<Cmd> = plan
        .level_ratios
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let extra: Vec<OsString> = vec![
                "--level-ratio".into(),
                r.to_string().into(),
                "--grid".into(),
                plan.grid.to_string().into(),
                "--grid-out".into(),
                work.join(format!("level{i}")).into_os_string(),
            ];
            let mut c = ndfit_cmd(plan, scan, &work.join(format!("level{i}.json")), &extra);
            c.label = format!("--level-ratio {r}");
            c
        })
        .collect();
    // One unrecorded round warms the page cache and writes every output.
    let measured = interleave(&cmds, plan.repeats, 1, |c, s| log(&format!("wave {label:<14} {:<20} {:>9.1} ms", c.label, s.wall_s * 1e3)))?;
    let load = |i: usize| -> Result<(serde_json::Value, Vec<f64>)> {
        let v = read_json(&work.join(format!("level{i}.json")))?;
        let (_, g) = read_npy_f64(&work.join(format!("level{i}.npy")))?;
        Ok((v, g))
    };
    let (ref_json, ref_grid) = load(0)?;
    let ref_records = records(&ref_json);
    let grid = [ref_json["grid"][0].as_u64().unwrap_or(0) as usize, ref_json["grid"][1].as_u64().unwrap_or(0) as usize];
    let ref_ms = measured[0].median_ms;
    let mut points = Vec::new();
    for (i, (m, &r)) in measured.into_iter().zip(&plan.level_ratios).enumerate() {
        let (v, g) = load(i)?;
        let (diffuse_rel_diff, specular_abs_diff) = record_diffs(&records(&v), &ref_records);
        points.push(LevelPoint {
            level_ratio: r,
            levels: v["levels"].as_u64().unwrap_or(0) as usize,
            speedup: ref_ms / m.median_ms,
            time: m,
            diffuse_rel_diff,
            specular_abs_diff,
            grid_rel_diff: grid_diff(&g, &ref_grid, plan.grid * plan.grid),
        });
    }
    Ok(LevelSweep { scan: label.to_string(), grid, points })
}

/// Run the plan in `work` (scans and outputs; the synthetic scans are kept there), reporting each run on `log`.
pub fn run(plan: &WavePlan, work: &Path, mut log: impl FnMut(&str)) -> Result<WaveBench> {
    plan.check()?;
    let started = std::time::Instant::now();
    std::fs::create_dir_all(work).map_err(|e| Error::io(e).with_path(work))?;
    let load0 = loadavg();
    let mut notes = Vec::new();
    if plan.python.is_none() {
        notes.push("no Python with numpy (fits/.venv or --numpy): ndfit alone, no ratios".to_string());
    }
    let real: Vec<&PathBuf> = plan
        .scans
        .iter()
        .filter(|p| {
            let ok = p.is_file();
            if !ok {
                notes.push(format!("{}: not found, skipped (the shared scans live in ../shared)", p.display()));
            }
            ok
        })
        .collect();
    for n in &notes {
        log(n);
    }

    log(&format!("wave: writing the {0}x{0} synthetic scan", plan.size));
    let synth = write_scan(plan, work, plan.size)?;
    let mut speed = vec![speed_row(plan, work, "synthetic", &synth, plan.size == TARGET_SIZE, &mut log)?];
    for p in &real {
        speed.push(speed_row(plan, work, &file_label(p), p, false, &mut log)?);
    }

    let level_scan = if plan.level_size == plan.size { synth.clone() } else { write_scan(plan, work, plan.level_size)? };
    let mut level_ratio = vec![level_sweep(plan, work, "synthetic", &level_scan, &mut log)?];
    if let Some(p) = real.first() {
        level_ratio.push(level_sweep(plan, work, &file_label(p), p, &mut log)?);
    }
    Ok(WaveBench {
        schema: "ndfit.bench.wave/1",
        plan: plan.clone(),
        threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
        loadavg_start: load0,
        loadavg_end: loadavg(),
        speed,
        level_ratio,
        notes,
        wall_s: started.elapsed().as_secs_f64(),
    })
}

/// The Markdown tables of a run (`wave.md`).
pub fn markdown(b: &WaveBench) -> String {
    let load = |l: Option<[f64; 3]>| l.map_or("-".to_string(), |l| format!("{:.2} {:.2} {:.2}", l[0], l[1], l[2]));
    let opt = |v: Option<f64>, f: &dyn Fn(f64) -> String| v.map_or("-".to_string(), f);
    let met = |m: Option<bool>| match m {
        Some(true) => "met",
        Some(false) => "NOT MET",
        None => "not judged",
    };
    let p = &b.plan;
    let mut s = format!(
        "`ndfit wave` against `python -m ndfitpy.wave` (numpy), whole processes, median of {} run(s) each after one unrecorded run; \
         wavelengths {} nm, incidences {} deg, default coherence; {} cores; load average {} at the start, {} at the end.\n\n\
         | scan | grid | patches (samples) | levels | ndfit (ms) | ndfit CPU (ms) | numpy (ms) | numpy / ndfit | ndfit peak (MiB) | heights (MiB) | peak / heights | numpy peak (MiB) | diffuse albedo vs numpy |\n\
         | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
        p.repeats,
        join(&p.wavelengths_nm),
        join(&p.incidences_deg),
        b.threads,
        load(b.loadavg_start),
        load(b.loadavg_end)
    );
    for r in &b.speed {
        s += &format!(
            "| {} | {}x{} | {} ({}x{}) | {} | {:.0} | {} | {} | {} | {} | {:.1} | {} | {} | {} |\n",
            r.scan,
            r.grid[0],
            r.grid[1],
            r.patches,
            r.patch_samples[0],
            r.patch_samples[1],
            r.levels,
            r.ndfit.median_ms,
            opt(r.ndfit.median_cpu_ms, &|c| format!("{c:.0}")),
            opt(r.numpy.as_ref().map(|n| n.median_ms), &|t| format!("{t:.0}")),
            opt(r.ratio, &|x| format!("{x:.2}x")),
            mib(r.ndfit_peak_rss),
            r.heights_bytes as f64 / (1024.0 * 1024.0),
            opt(r.memory_over_heights, &|x| format!("{x:.2}x")),
            mib(r.numpy.as_ref().and_then(|n| n.median_peak_rss)),
            opt(r.numpy_diffuse_rel_diff, &|x| format!("{x:.1e}")),
        );
    }
    if let Some(r) = b.speed.first() {
        s += &format!(
            "\nSynthetic {}^2: numpy / ndfit {} (aim >= {TARGET_RATIO}x at {TARGET_SIZE}^2: {}); ndfit's peak / heights {} (aim <= {TARGET_MEMORY}x: {}).\n",
            r.grid[0],
            opt(r.ratio, &|x| format!("{x:.2}x")),
            met(r.ratio_met),
            opt(r.memory_over_heights, &|x| format!("{x:.2}x")),
            met(r.memory_met)
        );
    }
    for l in &b.level_ratio {
        s += &format!(
            "\n`--level-ratio` on {} ({}x{}), against {} (with `--grid {} --grid-out`):\n\n\
             | level ratio | levels | median (ms) | speed-up | diffuse albedo, max rel. diff | specular, max abs. diff | grid, max diff / peak |\n\
             | --- | --- | --- | --- | --- | --- | --- |\n",
            l.scan,
            l.grid[0],
            l.grid[1],
            p.level_ratios[0],
            p.grid
        );
        for q in &l.points {
            s += &format!(
                "| {} | {} | {:.0} | {:.2}x | {:.1e} | {:.1e} | {:.1e} |\n",
                q.level_ratio, q.levels, q.time.median_ms, q.speedup, q.diffuse_rel_diff, q.specular_abs_diff, q.grid_rel_diff
            );
        }
    }
    for n in &b.notes {
        s += &format!("\nNote: {n}\n");
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn peak_line_parses_and_grids_compare_per_slice() {
        assert_eq!(parse_peak("ndfit: wave: x\nndfit: peak resident memory 1.5 MiB\n"), Some(1572864));
        assert_eq!(parse_peak("nothing"), None);
        // Two slices of two cells: the second slice's difference counts against its own peak.
        assert_eq!(grid_diff(&[1.0, 0.0, 10.0, 1.5], &[1.0, 0.0, 10.0, 1.0], 2), 0.05);
        assert!(grid_diff(&[1.0], &[1.0, 2.0], 2).is_nan());
        assert_eq!(record_diffs(&[(1.1, 0.5)], &[(1.0, 0.4)]).0, 1.1 / 1.0 - 1.0);
    }

    #[test]
    fn npy_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let hf = crate::Heightfield::new(3, 2, 1.0, 1.0, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        let p = dir.path().join("a.npy");
        super::super::scene::write_npy_f64(&p, &hf).unwrap();
        let (shape, v) = read_npy_f64(&p).unwrap();
        assert_eq!(shape, vec![2, 3]);
        assert_eq!(v, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]);
    }
}
