//! The generated parts of `docs/PERFORMANCE.md`: markdown tables rendered from a run's rows and
//! `summary.json`, written between marker comments so that one command (`ndfit bench ... --update-doc
//! docs/PERFORMANCE.md`, or `--from-csv` to re-render an earlier run) refreshes every figure of the page
//! while the prose around them stays hand-written.
//!
//! A generated section is the text between `<!-- bench:NAME -->` and `<!-- /bench:NAME -->` (each on a
//! line of its own); sections missing from the page are left out, so the page decides what it shows.

use std::fmt::Write as _;
use std::path::Path;

use serde_json::Value;

use super::plot::label_of;
use super::sweep::Row;
use crate::error::{Error, ErrorKind, Result};

/// Every section this module renders: `(name, markdown)`.
pub fn render(rows: &[Row], summary: &Value) -> Vec<(&'static str, String)> {
    vec![
        ("machine", machine(summary)),
        ("presets", presets(rows)),
        ("solvers", solvers(rows)),
        ("cost_model", cost_model(summary)),
        ("numpy", numpy(summary)),
        ("points", points(rows)),
    ]
}

/// Replace every generated section of `doc` (markers as in the module doc) by its rendering; returns the
/// names of the sections replaced. The page is written atomically; an unterminated marker is an error.
pub fn update_doc(doc: &Path, sections: &[(&'static str, String)]) -> Result<Vec<&'static str>> {
    let text = std::fs::read_to_string(doc).map_err(|e| Error::io(e).with_path(doc))?;
    let mut out = text.clone();
    let mut done = Vec::new();
    for (name, body) in sections {
        let (open, close) = (format!("<!-- bench:{name} -->"), format!("<!-- /bench:{name} -->"));
        let Some(a) = out.find(&open) else { continue };
        let from = a + open.len();
        let b = out[from..]
            .find(&close)
            .map(|i| from + i)
            .ok_or_else(|| Error::new(ErrorKind::BadData, format!("marker {open} has no closing {close}")).with_path(doc))?;
        out.replace_range(from..b, &format!("\n{}\n", body.trim_end()));
        done.push(*name);
    }
    crate::io::write_bytes_atomic(doc, out.as_bytes())?;
    Ok(done)
}

fn sci(v: Option<f64>) -> String {
    v.map_or(String::new(), |v| format!("{v:.2e}"))
}

fn fix(v: Option<f64>, digits: usize) -> String {
    v.map_or(String::new(), |v| format!("{v:.digits$}"))
}

fn machine(s: &Value) -> String {
    let m = &s["machine"];
    let mut o = String::new();
    let _ = writeln!(
        o,
        "- CPU: {}, rayon threads: {}, build: {}, ndfit {}.",
        m["cpu"].as_str().unwrap_or("?"),
        m["threads"],
        m["profile"].as_str().unwrap_or("?"),
        m["ndfit"].as_str().unwrap_or("?")
    );
    let la =
        |k: &str| m[k].as_array().map(|a| a.iter().map(|v| format!("{:.2}", v.as_f64().unwrap_or(f64::NAN))).collect::<Vec<_>>().join(" "));
    if let (Some(a), Some(b)) = (la("loadavg_start"), la("loadavg_end")) {
        let _ = writeln!(o, "- Load average (1, 5, 15 min) at the start of the run: {a}; at the end: {b}.");
    }
    if let Some(w) = s["wall_s"].as_f64() {
        let _ = writeln!(o, "- Wall time of the whole run: {w:.0} s (repetitions per point: {}).", s["repeats"]);
    }
    o
}

fn presets(rows: &[Row]) -> String {
    let mut o = String::from(
        "| preset | knobs | bins | total ms | read | NDF | fit | peak MiB | fit delta | alpha err | angle err (rad) |\n|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows.iter().filter(|r| r.group.starts_with("preset_")) {
        let _ = writeln!(
            o,
            "| {} | stride {}, {}, bins {}, tol {:.0e}, +{} starts | {} | {:.1} | {:.1} | {:.1} | {:.1} | {} | {} | {} | {} |",
            r.group.trim_start_matches("preset_"),
            r.stride,
            r.scheme,
            r.cells,
            r.tol,
            r.extra_starts,
            r.bins,
            r.t_total_ms,
            r.t_read_ms,
            r.t_ndf_ms,
            r.t_fit_ms,
            fix(r.peak_mib, 1),
            sci(r.fit_delta),
            sci(r.alpha_err),
            sci(r.angle_err)
        );
    }
    let get = |g: &str| rows.iter().find(|r| r.group == g).and_then(|r| r.fit_delta);
    if let (Some(b), Some(a)) = (get("preset_balanced"), get("preset_accurate")) {
        let _ = writeln!(
            o,
            "\nBalanced against accurate, fit delta: {b:.3e} against {a:.3e} ({:+.1} %; issue #8 requires within 10 %).",
            100.0 * (b / a - 1.0)
        );
    }
    o
}

fn solvers(rows: &[Row]) -> String {
    let mut o = String::from(
        "| solver | fit ms | evaluations | converged | objective rel. to LM | fit delta | alpha err | angle err (rad) |\n|---|---|---|---|---|---|---|---|\n",
    );
    let lm = rows.iter().find(|r| r.group == "preset_balanced");
    let lm_f = lm.and_then(|r| r.objective);
    for r in lm.into_iter().chain(rows.iter().filter(|r| r.group == "solver")) {
        let rel = match (r.objective, lm_f) {
            (Some(f), Some(l)) if l > 0.0 => format!("{:+.1e}", f / l - 1.0),
            _ => String::new(),
        };
        let _ = writeln!(
            o,
            "| {} | {:.1} | {} | {} | {} | {} | {} | {} |",
            r.solver,
            r.t_fit_ms,
            r.evaluations.map_or(String::new(), |e| e.to_string()),
            r.converged.map_or(String::new(), |c| c.to_string()),
            rel,
            sci(r.fit_delta),
            sci(r.alpha_err),
            sci(r.angle_err)
        );
    }
    o
}

fn cost_model(s: &Value) -> String {
    let mut o = String::from("| quantity | against | exponent | points |\n|---|---|---|---|\n");
    for e in s["cost_model"].as_array().into_iter().flatten() {
        let _ = writeln!(
            o,
            "| {} | {} | {:.2} | {} |",
            e["quantity"].as_str().unwrap_or("?"),
            e["against"].as_str().unwrap_or("?"),
            e["exponent"].as_f64().unwrap_or(f64::NAN),
            e["n"]
        );
    }
    o
}

fn numpy(s: &Value) -> String {
    let cmp = s["numpy"].as_array().cloned().unwrap_or_default();
    if cmp.is_empty() {
        return "(no numpy comparison in this run: `ndfit bench --numpy PYTHON`)".into();
    }
    let f = |v: &Value| v.as_f64().unwrap_or(f64::NAN);
    let mut o = String::from(
        "| task | ndfit settings | size | ndfit ms (read / NDF / fit) | numpy ms (load / gradient / histogram / fit) | bins across | ratio numpy/ndfit | target | fit delta ndfit | fit delta numpy |\n|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for c in &cmp {
        let (n, p) = (&c["ndfit"], &c["numpy"]);
        let aim = c["target"]["aim"].as_f64().map_or(String::new(), |a| format!(", aim {a}x"));
        let verdict = match c["met"].as_bool() {
            Some(true) => "met".to_string(),
            Some(false) => "**not met**".to_string(),
            None if c["preset"] == "fast" => "not judged (the `fast` preset, for information)".to_string(),
            None => format!("not judged (the target is at {}^2)", c["target"]["size"]),
        };
        let _ = writeln!(
            o,
            "| {} | {} | {}^2 | {:.1} / {:.1} / {:.1} | {:.0} / {:.0} / {:.0} / {:.0} | {} | **{:.1}x** | >= {}x{aim}: {verdict} | {} | {} |",
            c["task"].as_str().unwrap_or("?"),
            c["preset"].as_str().unwrap_or("?"),
            c["size"],
            f(&n["read"]),
            f(&n["ndf"]),
            f(&n["fit"]),
            f(&p["t_load_ms"]),
            f(&p["t_gradient_ms"]),
            f(&p["t_histogram_ms"]),
            f(&p["t_fit_ms"]),
            c["numpy_bins_across"],
            f(&c["ratio"]),
            c["target"]["required"],
            sci(c["ndfit_fit_delta"].as_f64()),
            sci(c["numpy_fit_delta"].as_f64())
        );
    }
    for c in cmp.iter().filter(|c| c["task"] == "ndf") {
        let t = f(&c["ndf_grid_mpts_per_s"]);
        let _ = writeln!(
            o,
            "\nNDF stage throughput at {}^2 (same run, wall clock, read excluded): {t:.0} M grid points/s ({:.0} M normals/s); target >= 150 M/s: {}.",
            c["size"],
            f(&c["ndf_normals_mpts_per_s"]),
            match (c["met"].as_bool(), t >= 150.0) {
                (None, _) => "not judged at this size",
                (_, true) => "met",
                (_, false) => "**not met**",
            }
        );
    }
    o
}

fn points(rows: &[Row]) -> String {
    let mut o = String::from(
        "| group | size | knob | samples | bins | total ms | read | NDF | fit | NDF Mpts/s | peak MiB | NDF delta | fit delta | alpha err | angle err | evals |\n|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let _ = writeln!(
            o,
            "| {} | {} | {} | {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {:.1} | {} | {} | {} | {} | {} | {} |",
            r.group,
            r.size,
            label_of(r),
            r.samples,
            r.bins,
            r.t_total_ms,
            r.t_read_ms,
            r.t_ndf_ms,
            r.t_fit_ms,
            r.ndf_mpts_per_s,
            fix(r.peak_mib, 1),
            fix(r.ndf_delta, 4),
            sci(r.fit_delta),
            sci(r.alpha_err),
            sci(r.angle_err),
            r.evaluations.map_or(String::new(), |e| e.to_string())
        );
    }
    o
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every generated table of the committed run (`docs/bench.csv`, `docs/bench_summary.json`) is a
    /// markdown table: its delimiter row and every body row have as many cells as its header (a row with
    /// another count breaks the table on GitHub).
    #[test]
    fn generated_tables_have_one_cell_count() {
        let docs = Path::new(env!("CARGO_MANIFEST_DIR")).join("docs");
        let mut rd = csv::Reader::from_path(docs.join("bench.csv")).expect("docs/bench.csv");
        let rows: Vec<Row> = rd.deserialize().collect::<std::result::Result<_, _>>().expect("rows");
        let summary: Value = serde_json::from_slice(&std::fs::read(docs.join("bench_summary.json")).expect("summary")).expect("JSON");
        let cells = |l: &str| l.trim().trim_matches('|').split('|').count();
        let mut tables = 0;
        for (name, md) in render(&rows, &summary) {
            let lines: Vec<&str> = md.lines().collect();
            for block in lines.split(|l| !l.starts_with('|')).filter(|b| !b.is_empty()) {
                tables += 1;
                let n = cells(block[0]);
                assert!(block.len() >= 2 && block[1].starts_with("|---"), "{name}: no delimiter row");
                for l in block {
                    assert_eq!(cells(l), n, "{name}: {l}");
                }
            }
        }
        assert!(tables >= 5, "{tables} tables rendered");
    }

    /// Markers are replaced in place, text outside them is kept byte for byte, absent sections are
    /// skipped, and an unterminated marker fails without touching the page.
    #[test]
    fn update_doc_replaces_only_marked_sections() {
        let dir = tempfile::tempdir().expect("tempdir");
        let p = dir.path().join("doc.md");
        std::fs::write(&p, "intro\n<!-- bench:numpy -->\nold\n<!-- /bench:numpy -->\noutro\n").expect("write");
        let done = update_doc(&p, &[("numpy", "NEW\n".into()), ("points", "x".into())]).expect("update");
        assert_eq!(done, vec!["numpy"]);
        assert_eq!(std::fs::read_to_string(&p).expect("read"), "intro\n<!-- bench:numpy -->\nNEW\n<!-- /bench:numpy -->\noutro\n");
        std::fs::write(&p, "<!-- bench:numpy -->\nold\n").expect("write");
        assert!(update_doc(&p, &[("numpy", "NEW".into())]).is_err());
        assert_eq!(std::fs::read_to_string(&p).expect("read"), "<!-- bench:numpy -->\nold\n");
    }
}
