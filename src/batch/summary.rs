//! The run's summary files, `summary.json` and `summary.csv`, and the regression table for stdout.
//!
//! `summary.json` is streamed: its entries are copied one at a time from the per-scan records on disk,
//! so writing it never holds more than one fit in memory. One entry per line keeps diffs of checked-in
//! baselines readable.

use std::fmt::Write as _;
use std::path::Path;

use serde::Serialize;

use super::compare::{Tolerances, Verdict};
use super::entry::Status;
use super::runner::{read_record, Brief, Counts, RunOutcome};
use super::spec::key_to_rel;
use crate::error::{Error, ErrorKind, Result};
use crate::io::write_atomic;

/// Schema id of `summary.json`.
pub const SCHEMA: &str = "ndfit.batch/1";

/// The run-level fields of `summary.json` (everything but `entries`). Nothing here depends on `--jobs`.
#[derive(Debug, Clone, Serialize)]
pub struct Header {
    /// [`SCHEMA`].
    pub schema: &'static str,
    /// Version of ndfit that ran.
    pub ndfit_version: &'static str,
    /// The folder or manifest the scans came from, as given.
    pub input: String,
    /// The run's model (`--model`).
    pub model: String,
    /// The baseline file, when one was given.
    pub baseline: Option<String>,
    /// The comparison's tolerances.
    pub tolerances: Tolerances,
    /// Counts of the outcomes.
    pub counts: Counts,
    /// The exit status of the run (0 clean, 1 regressed, 2 some scan not read or fitted).
    pub exit_status: u8,
    /// Baseline scans missing from this run.
    pub missing_from_run: Vec<String>,
}

/// Write `out_dir/summary.json`: the header, then `entries` from the per-scan records, ordered by key.
pub fn write_summary_json(out_dir: &Path, header: &Header, outcome: &RunOutcome) -> Result<()> {
    let path = out_dir.join("summary.json");
    // The header in its declared order (schema first), pretty; then the entries, one per line.
    let head = serde_json::to_string_pretty(header).map_err(|e| Error::io(e.into()))?;
    let head = head.trim_end().strip_suffix('}').unwrap_or(&head).trim_end().to_string();
    write_atomic(&path, |w| {
        w.write_all(head.as_bytes()).map_err(Error::io)?;
        w.write_all(b",\n").map_err(Error::io)?;
        w.write_all(b"  \"entries\": [").map_err(Error::io)?;
        for (i, b) in outcome.briefs.iter().enumerate() {
            let rec = out_dir.join(super::runner::RECORDS_DIR).join(key_to_rel(&b.entry.path));
            let mut rec = rec.into_os_string();
            rec.push(".json");
            let mut entry =
                read_record(Path::new(&rec)).ok_or_else(|| Error::corrupt("per-scan record vanished or is unreadable").with_path(&rec))?;
            entry.resume = None;
            let sep = if i == 0 { "\n    " } else { ",\n    " };
            write!(w, "{sep}{}", json(&entry)?).map_err(Error::io)?;
        }
        w.write_all(b"\n  ]\n}\n").map_err(Error::io)
    })
}

fn json<T: Serialize + ?Sized>(v: &T) -> Result<String> {
    serde_json::to_string(v).map_err(|e| Error::io(e.into()))
}

/// Parameter columns of `summary.csv`: the union of every model's parameter names.
const PARAMS: &[&str] = &["alpha", "alpha_x", "alpha_y", "theta_x", "theta_y", "theta_z"];

/// Write `out_dir/summary.csv`: one row per scan with parameters, standard errors, goodness of fit,
/// termination, time and error (columns in `data_formats/batch.md`).
pub fn write_summary_csv(out_dir: &Path, outcome: &RunOutcome) -> Result<()> {
    let path = out_dir.join("summary.csv");
    write_atomic(&path, |w| {
        let mut c = csv::Writer::from_writer(w);
        let mut head: Vec<String> = ["path", "status", "model"].map(String::from).to_vec();
        head.extend(PARAMS.iter().map(|p| p.to_string()));
        head.extend(PARAMS.iter().map(|p| format!("stderr_{p}")));
        head.extend(
            [
                "kl",
                "deviance",
                "ndf_delta",
                "n_samples",
                "n_bins",
                "reduced_chi2",
                "fit_verdict",
                "answer",
                "regime",
                "termination",
                "evaluations",
                "time_s",
                "verdict",
                "baseline_model",
                "kl_baseline",
                "delta_kl",
                "params_changed",
                "error_kind",
                "error",
            ]
            .map(String::from),
        );
        c.write_record(&head).map_err(csv_err)?;
        for b in &outcome.briefs {
            c.write_record(csv_row(b)).map_err(csv_err)?;
        }
        c.flush().map_err(Error::io)
    })
}

fn csv_err(e: csv::Error) -> Error {
    Error::new(ErrorKind::Io, e.to_string())
}

fn num(x: Option<f64>) -> String {
    x.map(|v| format!("{v:e}")).unwrap_or_default()
}

fn csv_row(b: &Brief) -> Vec<String> {
    let e = &b.entry;
    let status = match e.status {
        Status::Ok => "ok",
        Status::Error => "error",
    };
    let mut row = vec![e.path.clone(), status.to_string(), b.model.clone().unwrap_or_default()];
    let param = |n: &str| b.params.iter().find(|(k, _)| k == n).map(|(_, v)| *v);
    row.extend(PARAMS.iter().map(|p| num(param(p))));
    row.extend(PARAMS.iter().map(|p| num(b.stderr.get(*p).copied())));
    let q = e.quality;
    let cmp = e.baseline.as_ref();
    row.extend([
        num(q.map(|q| q.kl)),
        num(q.map(|q| q.deviance)),
        num(q.map(|q| q.ndf_delta)),
        q.map(|q| q.n_samples.to_string()).unwrap_or_default(),
        q.map(|q| q.n_bins.to_string()).unwrap_or_default(),
        num(b.reduced_chi2),
        b.fit_verdict.clone().unwrap_or_default(),
        b.answer.clone().unwrap_or_default(),
        b.regime.clone().unwrap_or_default(),
        b.termination.clone().unwrap_or_default(),
        b.evaluations.map(|n| n.to_string()).unwrap_or_default(),
        format!("{:.6}", e.time_s),
        cmp.map(|c| verdict_str(c.verdict).to_string()).unwrap_or_default(),
        cmp.and_then(|c| c.baseline_model.clone()).unwrap_or_default(),
        num(cmp.and_then(|c| c.kl_baseline)),
        num(cmp.and_then(|c| c.delta_kl)),
        cmp.map(|c| c.param_changes.iter().map(|p| p.name.as_str()).collect::<Vec<_>>().join(" ")).unwrap_or_default(),
        e.error_kind.clone().unwrap_or_default(),
        e.error.clone().unwrap_or_default(),
    ]);
    row
}

/// The verdict as written in tables and CSV.
pub fn verdict_str(v: Verdict) -> &'static str {
    match v {
        Verdict::Same => "same",
        Verdict::Improved => "improved",
        Verdict::Regressed => "regressed",
        Verdict::New => "new",
        Verdict::Fixed => "fixed",
        Verdict::Broken => "broken",
        Verdict::StillError => "still_error",
        Verdict::Unscored => "unscored",
        Verdict::BaselineUnresolved => "baseline_unresolved",
    }
}

/// The readable regression table for stdout: one row per scan that is not simply `same` (or every
/// scan with `all`), then a totals line.
pub fn regression_table(outcome: &RunOutcome, all: bool) -> String {
    let mut rows: Vec<[String; 7]> = Vec::new();
    for b in &outcome.briefs {
        let e = &b.entry;
        let Some(c) = &e.baseline else { continue };
        let flagged = c.verdict != Verdict::Same || !c.param_changes.is_empty() || e.status == Status::Error;
        if !(all || flagged) {
            continue;
        }
        let verdict = if c.regressed { "REGRESSED".to_string() } else { verdict_str(c.verdict).to_string() };
        let models = format!(
            "{} -> {}",
            c.baseline_model.as_deref().unwrap_or("-"),
            b.model.as_deref().unwrap_or(if e.status == Status::Error { "error" } else { "-" })
        );
        let params = if c.param_changes.is_empty() {
            e.error.clone().unwrap_or_else(|| "-".into())
        } else {
            c.param_changes
                .iter()
                .map(|p| match p.z {
                    Some(z) => format!("{} {:+.3e} ({z:.1} sigma)", p.name, p.diff),
                    None => format!("{} {:+.3e}", p.name, p.diff),
                })
                .collect::<Vec<_>>()
                .join(", ")
        };
        rows.push([verdict, e.path.clone(), models, num3(c.kl_baseline), num3(c.kl), signed(c.delta_kl), params]);
    }
    for m in &outcome.missing {
        rows.push(["MISSING".into(), m.clone(), "-".into(), "-".into(), "-".into(), "-".into(), "in the baseline, not in this run".into()]);
    }
    let head = ["verdict", "path", "model (baseline -> now)", "kl baseline", "kl now", "delta kl", "parameters changed / error"];
    let mut width = head.map(str::len);
    for r in &rows {
        for (w, c) in width.iter_mut().zip(r.iter()) {
            *w = (*w).max(c.chars().count());
        }
    }
    let mut out = String::new();
    if !rows.is_empty() {
        let line = |cells: &[&str]| {
            let mut s = String::new();
            for (i, c) in cells.iter().enumerate() {
                if i + 1 == cells.len() {
                    s.push_str(c);
                } else {
                    let _ = write!(s, "{c:<w$}  ", w = width[i]);
                }
            }
            s.trim_end().to_string()
        };
        out.push_str(&line(&head));
        out.push('\n');
        for r in &rows {
            out.push_str(&line(&r.iter().map(String::as_str).collect::<Vec<_>>()));
            out.push('\n');
        }
    }
    let c = outcome.counts();
    let _ = writeln!(
        out,
        "{} scans: {} ok, {} error, {} regressed, {} improved, {} with parameter changes, {} missing from this run; fits: {} ok, {} misfit, {} unresolved",
        c.scans, c.ok, c.error, c.regressed, c.improved, c.params_changed, c.missing, c.verdicts.ok, c.verdicts.misfit, c.verdicts.unresolved
    );
    out
}

fn num3(x: Option<f64>) -> String {
    x.map(|v| format!("{v:.4e}")).unwrap_or_else(|| "-".into())
}

fn signed(x: Option<f64>) -> String {
    x.map(|v| format!("{v:+.3e}")).unwrap_or_else(|| "-".into())
}
