//! `ndfit bench --answer`: what `auto`'s answer costs against one fit, as whole processes in the same run.
//!
//! Per scan, `ndfit fit SCAN` (model `auto`: the optics, the ladder and the render choice), `ndfit fit SCAN
//! --scene none` (the same ladder decided by the NDF error alone: what `auto` costs before any render) and
//! `ndfit fit SCAN --model ggx-aniso` run round-robin ([`super::process::interleave`]), medians of `repeats`
//! runs after one unrecorded run of each; the ratio of the medians is the cost of the answer (the aim:
//! [`TARGET_RATIO`]), and where the regime is geometric the ladder's ratio is the part of it no faster
//! render can remove (elsewhere `auto` fits the one-lobe rungs beside the optics, while `--scene none`, which
//! skips the optics, fits the whole ladder: no part of `auto`, not reported). The scans: the shared real scans, and fresh truths written for this run with a seed
//! drawn from the clock (a rough Gaussian surface, an ellipsoid cap, a polished surface of 0.1 nm heights),
//! so that no figure is met only on scans the bench holds. The `auto` run's own report gives its regime,
//! its answer and the optics' share of the time (`timings.optics_ms`).

use std::ffi::OsString;
use std::path::{Path, PathBuf};

use super::process::{interleave, loadavg, Cmd};
use crate::error::{Error, Result};
use crate::synth::{ellipsoid_surface, gaussian_surface, GaussianParams, SynthSettings};

/// Aim: `auto` (optics and render included) over one `ggx-aniso` fit, as whole processes.
pub const TARGET_RATIO: f64 = 3.0;

/// What to measure.
#[derive(Debug, Clone, serde::Serialize)]
pub struct AnswerPlan {
    /// The shared scans (missing ones are skipped with a note).
    pub scans: Vec<PathBuf>,
    /// Side of the fresh synthetic truths.
    pub size: usize,
    /// Seed of the fresh truths (from the clock unless given).
    pub seed: u64,
    /// Recorded runs per command (medians reported).
    pub repeats: usize,
    /// The ndfit executable measured.
    pub ndfit: PathBuf,
}

/// One scan's measurement.
#[derive(Debug, Clone, serde::Serialize)]
pub struct AnswerRow {
    /// The file's name, or the truth's.
    pub scan: String,
    /// Median wall time of `ndfit fit SCAN` (auto, ms).
    pub auto_ms: f64,
    /// Median wall time of `ndfit fit SCAN --model ggx-aniso` (ms).
    pub ggx_aniso_ms: f64,
    /// Median wall time of `ndfit fit SCAN --scene none` (the ladder without the render choice, ms), where
    /// the regime is geometric (module docs).
    pub ladder_ms: Option<f64>,
    /// `ladder_ms / ggx_aniso_ms`.
    pub ladder_ratio: Option<f64>,
    /// `auto_ms / ggx_aniso_ms`.
    pub ratio: f64,
    /// The auto run's `timings.optics_ms`.
    pub optics_ms: Option<f64>,
    /// Its `optics.regime`.
    pub regime: Option<String>,
    /// Its `selection.answer`.
    pub answer: Option<String>,
}

/// The whole measurement.
#[derive(Debug, Clone, serde::Serialize)]
pub struct AnswerBench {
    /// `ndfit.bench.answer/1`.
    pub schema: &'static str,
    /// The plan.
    pub plan: AnswerPlan,
    /// The machine's load average at the start and the end.
    pub loadavg: [Option<[f64; 3]>; 2],
    /// One row per scan.
    pub rows: Vec<AnswerRow>,
    /// Scans skipped, and why.
    pub notes: Vec<String>,
}

/// The fresh truths: `(name, file)` written into `work`.
fn truths(plan: &AnswerPlan, work: &Path) -> Result<Vec<(String, PathBuf, f64)>> {
    let n = plan.size;
    let mut out = Vec::new();
    let s = SynthSettings { nx: n, ny: n, dx: 1e-6, dy: 1e-6, seed: plan.seed, ..Default::default() };
    let rough = gaussian_surface(&s, &GaussianParams { sigma_x: 0.25, sigma_y: 0.15, theta_z: 0.4, corr_length: 8e-6 })?.0;
    out.push(("gaussian (rough)".to_string(), rough, 1e-6));
    let cap = ellipsoid_surface(&s, &super::scene::truth_params())?.0;
    out.push(("ellipsoid cap".to_string(), cap, 1e-6));
    // Heights of 0.1 nm RMS at 0.5 um: a mirror to light (white noise from the seed).
    let mut state = plan.seed | 1;
    let z: Vec<f64> = (0..n * n)
        .map(|_| {
            // xorshift64*: twelve uniforms in [0, 1) less 6 have unit variance (Irwin-Hall), a bell.
            let mut u = 0.0;
            for _ in 0..12 {
                state ^= state >> 12;
                state ^= state << 25;
                state ^= state >> 27;
                u += (state.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64;
            }
            1e-10 * (u - 6.0)
        })
        .collect();
    out.push(("polished (0.1 nm)".to_string(), crate::Heightfield::new(n, n, 0.5e-6, 0.5e-6, z)?, 0.5e-6));
    out.into_iter()
        .map(|(name, hf, dx)| {
            let path = work.join(format!("{}.npy", name.split(' ').next().unwrap_or("truth")));
            super::scene::write_npy_f64(&path, &hf)?;
            Ok((name, path, dx))
        })
        .collect()
}

/// `ndfit fit SCAN [extra] -o out -q`, an NPY with its spacing.
fn fit_cmd(plan: &AnswerPlan, label: &str, scan: &Path, dx: Option<f64>, out: &Path, extra: &[&str]) -> Cmd {
    let mut argv: Vec<OsString> = vec![plan.ndfit.clone().into_os_string(), "fit".into(), scan.as_os_str().to_owned()];
    if let Some(dx) = dx {
        argv.extend(["--dx".into(), dx.to_string().into(), "--z-scale".into(), "1".into()]);
    }
    argv.extend(extra.iter().map(OsString::from));
    argv.extend(["-q".into(), "-o".into(), out.as_os_str().to_owned()]);
    Cmd { label: label.to_string(), argv, stdout: None }
}

/// Measure `scan` (module docs).
fn row(plan: &AnswerPlan, work: &Path, name: &str, scan: &Path, dx: Option<f64>) -> Result<AnswerRow> {
    let (auto_out, one_out) = (work.join("auto.json"), work.join("one.json"));
    let ladder_out = work.join("ladder.json");
    let cmds = [
        fit_cmd(plan, "auto", scan, dx, &auto_out, &[]),
        fit_cmd(plan, "ggx-aniso", scan, dx, &one_out, &["--model", "ggx-aniso"]),
        fit_cmd(plan, "ladder", scan, dx, &ladder_out, &["--scene", "none"]),
    ];
    let m = interleave(&cmds, plan.repeats, 1, |_, _| {})?;
    let doc: serde_json::Value = std::fs::read(&auto_out)
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
        .ok_or_else(|| Error::invalid(format!("{name}: the auto run wrote no report")).with_path(&auto_out))?;
    let text = |p: &str| doc.pointer(p).and_then(|v| v.as_str()).map(str::to_string);
    let geometric = text("/optics/regime").as_deref() == Some("geometric");
    Ok(AnswerRow {
        scan: name.to_string(),
        auto_ms: m[0].median_ms,
        ggx_aniso_ms: m[1].median_ms,
        ratio: m[0].median_ms / m[1].median_ms,
        ladder_ms: geometric.then_some(m[2].median_ms),
        ladder_ratio: geometric.then(|| m[2].median_ms / m[1].median_ms),
        optics_ms: doc.pointer("/timings/optics_ms").and_then(|v| v.as_f64()),
        regime: text("/optics/regime"),
        answer: text("/selection/answer"),
    })
}

/// Run the measurement in `work`; `log` hears each scan as it is done.
pub fn run(plan: &AnswerPlan, work: &Path, mut log: impl FnMut(&str)) -> Result<AnswerBench> {
    if plan.repeats == 0 || !(64..=4096).contains(&plan.size) {
        return Err(Error::invalid(format!(
            "--answer: repeats {} must be at least 1 and the size {} in 64..=4096",
            plan.repeats, plan.size
        )));
    }
    std::fs::create_dir_all(work).map_err(|e| Error::io(e).with_path(work))?;
    let load0 = loadavg();
    let mut notes = Vec::new();
    let mut rows = Vec::new();
    for p in &plan.scans {
        if !p.is_file() {
            notes.push(format!("{}: not found, skipped (the shared scans live in ../shared)", p.display()));
            continue;
        }
        let name = p.file_name().map_or_else(|| p.display().to_string(), |n| n.to_string_lossy().into_owned());
        rows.push(row(plan, work, &name, p, None)?);
        log(&line(rows.last().unwrap_or_else(|| unreachable!())));
    }
    for (name, path, dx) in truths(plan, work)? {
        rows.push(row(plan, work, &format!("{name}, seed {}", plan.seed), &path, Some(dx))?);
        log(&line(rows.last().unwrap_or_else(|| unreachable!())));
    }
    Ok(AnswerBench { schema: "ndfit.bench.answer/1", plan: plan.clone(), loadavg: [load0, loadavg()], rows, notes })
}

fn line(r: &AnswerRow) -> String {
    format!(
        "answer: {}: auto {:.0} ms, ggx-aniso {:.0} ms, {:.1}x{} ({}, {})",
        r.scan,
        r.auto_ms,
        r.ggx_aniso_ms,
        r.ratio,
        r.ladder_ms.zip(r.ladder_ratio).map_or(String::new(), |(ms, x)| format!("; the ladder alone {ms:.0} ms, {x:.1}x")),
        r.regime.as_deref().unwrap_or("-"),
        r.answer.as_deref().unwrap_or("-")
    )
}

/// The report as a Markdown table, with the median and worst ratio against [`TARGET_RATIO`], and how many
/// scans the ladder alone (no render) already takes beyond it.
pub fn markdown(b: &AnswerBench) -> String {
    let mut s = String::from(
        "| scan | regime | answer | auto (ms) | of which optics (ms) | ggx-aniso (ms) | ratio | the ladder alone (ms) | its ratio |\n\
         | --- | --- | --- | --- | --- | --- | --- | --- | --- |\n",
    );
    for r in &b.rows {
        s.push_str(&format!(
            "| {} | {} | {} | {:.0} | {} | {:.0} | {:.1}x | {} | {} |\n",
            r.scan,
            r.regime.as_deref().unwrap_or("-"),
            r.answer.as_deref().unwrap_or("-"),
            r.auto_ms,
            r.optics_ms.map_or("-".to_string(), |o| format!("{o:.1}")),
            r.ggx_aniso_ms,
            r.ratio,
            r.ladder_ms.map_or("-".to_string(), |v| format!("{v:.0}")),
            r.ladder_ratio.map_or("-".to_string(), |v| format!("{v:.1}x"))
        ));
    }
    let mut ratios: Vec<f64> = b.rows.iter().map(|r| r.ratio).collect();
    ratios.sort_by(f64::total_cmp);
    if let (Some(worst), false) = (ratios.last(), ratios.is_empty()) {
        let median = ratios[ratios.len() / 2];
        let met = if *worst <= TARGET_RATIO { "met" } else { "NOT MET" };
        s.push_str(&format!("\nMedian {median:.1}x, worst {worst:.1}x against the aim of {TARGET_RATIO}x: {met}.\n"));
        let geometric: Vec<&AnswerRow> = b.rows.iter().filter(|r| r.ladder_ratio.is_some()).collect();
        let over: Vec<&str> = geometric.iter().filter(|r| r.ladder_ratio > Some(TARGET_RATIO)).map(|r| r.scan.as_str()).collect();
        s.push_str(&format!(
            "Where the regime is geometric, the ladder alone, before any render, takes more than {TARGET_RATIO}x on {} of {} scans{}.\n",
            over.len(),
            geometric.len(),
            if over.is_empty() { String::new() } else { format!(" ({})", over.join(", ")) }
        ));
    }
    for n in &b.notes {
        s.push_str(&format!("\n- {n}"));
    }
    s
}
