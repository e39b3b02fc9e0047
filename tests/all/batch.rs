//! Integration tests: the batch runner (`ndfit::batch`) with fake jobs (machinery: walk, manifest,
//! errors, panics, atomic writes, resume, baseline comparison, exit codes, --jobs independence), then
//! `ndfit batch` end to end on synthetic scans.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use ndfit::batch::{
    self, discover, summary, Baseline, JobContext, JobFailure, JobOutput, Quality, RunOptions, RunOutcome, ScanSpec, Tolerances,
};
use serde_json::{json, Value};

/// A fake scan file: the job reads it and returns what it says (`alpha`, `kl`), or fails or panics.
fn fake_scan(dir: &Path, name: &str, body: &str) {
    let p = dir.join(name);
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    std::fs::write(p, body).unwrap();
}

fn q(kl: f64) -> Quality {
    Quality { deviance: kl * 2e4, kl, ndf_delta: kl.sqrt(), n_samples: 10_000, n_bins: 100 }
}

/// The fake job: deterministic in the file's content, with a content-dependent sleep so completion order
/// differs from path order when several jobs run.
fn fake_job(spec: &ScanSpec, ctx: &JobContext<'_>) -> Result<JobOutput, JobFailure> {
    let text = std::fs::read_to_string(&spec.file).map_err(|e| JobFailure::new("io", format!("{}: {e}", spec.file.display())))?;
    if text.starts_with("PANIC") {
        let v: Vec<u8> = Vec::new();
        let _ = v[text.len()]; // index out of bounds: a panic inside "a dependency"
    }
    let v: Value =
        serde_json::from_str(&text).map_err(|e| JobFailure::new("corrupt", format!("{}: not a scan: {e}", spec.file.display())))?;
    let alpha = v["alpha"].as_f64().unwrap_or(0.1);
    let kl = v["kl"].as_f64().unwrap_or(1e-3);
    std::thread::sleep(std::time::Duration::from_millis((alpha * 100.0) as u64 % 40));
    let model = spec.model.clone().unwrap_or_else(|| v["model"].as_str().unwrap_or("ggx").to_string());
    // Same-bins score of the baseline model: the fake "data" says what any other model scores.
    let same_bins = ctx.baseline.and_then(|b| b.quality).map(|bq| q(v["kl_baseline_model"].as_f64().unwrap_or(bq.kl)));
    Ok(JobOutput {
        fit: json!({"schema": "ndfit.fit/1", "model": model, "params": {"alpha": alpha}, "stderr": {"alpha": 0.001},
                    "timings": {"total_s": 0.001}}),
        quality: Some(q(kl)),
        baseline_on_same_bins: same_bins,
    })
}

fn opts(out: &Path, jobs: usize) -> RunOptions {
    RunOptions {
        out_dir: out.to_path_buf(),
        jobs,
        resume: false,
        settings: "test".into(),
        tolerances: Tolerances::default(),
        extras: Vec::new(),
    }
}

fn run_dir(dir: &Path, o: &RunOptions, baseline: Option<&Baseline>, job: &batch::Job<'_>) -> RunOutcome {
    let specs = discover::walk(dir, std::slice::from_ref(&o.out_dir), &|_: &Path| false).unwrap();
    let outcome = batch::run(&specs, baseline, job, o, &|_| {}).unwrap();
    let header = summary::Header {
        schema: summary::SCHEMA,
        ndfit_version: "test",
        input: dir.display().to_string(),
        model: "ggx".into(),
        baseline: None,
        tolerances: o.tolerances,
        counts: outcome.counts(),
        exit_status: outcome.exit_code(true),
        missing_from_run: outcome.missing.clone(),
    };
    summary::write_summary_json(&o.out_dir, &header, &outcome).unwrap();
    summary::write_summary_csv(&o.out_dir, &outcome).unwrap();
    outcome
}

/// summary.json with everything that legitimately varies between runs (timings) removed.
fn stable_summary(out: &Path) -> Value {
    let mut v: Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    strip_times(&mut v);
    v
}

fn strip_times(v: &mut Value) {
    match v {
        Value::Object(o) => {
            o.retain(|k, _| !(k == "time_s" || k == "timings" || k.ends_with("_ms") || k == "input"));
            o.values_mut().for_each(strip_times);
        }
        Value::Array(a) => a.iter_mut().for_each(strip_times),
        _ => {}
    }
}

fn entries(out: &Path) -> BTreeMap<String, Value> {
    let v: Value = serde_json::from_slice(&std::fs::read(out.join("summary.json")).unwrap()).unwrap();
    v["entries"].as_array().unwrap().iter().map(|e| (e["path"].as_str().unwrap().to_string(), e.clone())).collect()
}

/// Every file under `dir` parses as what its name says (no half-written output), and no temp file is left.
fn assert_outputs_complete(dir: &Path) {
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            let name = e.file_name().to_string_lossy().into_owned();
            if p.is_dir() {
                stack.push(p);
                continue;
            }
            assert!(!name.ends_with(".tmp"), "temporary file left: {}", p.display());
            if name.ends_with(".json") {
                let bytes = std::fs::read(&p).unwrap();
                assert!(serde_json::from_slice::<Value>(&bytes).is_ok(), "half-written JSON {}", p.display());
            }
        }
    }
}

fn good_folder(dir: &Path) {
    fake_scan(dir, "a.x3p", r#"{"alpha": 0.31, "kl": 0.002}"#);
    fake_scan(dir, "sub/b.x3p", r#"{"alpha": 0.12, "kl": 0.001}"#);
    fake_scan(dir, "sub/deeper/c.plu", r#"{"alpha": 0.57, "kl": 0.004}"#);
    fake_scan(dir, "d.sur", r#"{"alpha": 0.05, "kl": 0.003}"#);
    fake_scan(dir, "notes.md", "not a scan");
}

#[test]
fn bad_and_panicking_scans_become_error_entries_and_the_batch_goes_on() {
    let t = tempfile::tempdir().unwrap();
    let (dir, out) = (t.path().join("in"), t.path().join("out"));
    good_folder(&dir);
    fake_scan(&dir, "corrupt.x3p", "PK\u{3}\u{4} truncated");
    fake_scan(&dir, "sub/panics.opd", "PANIC");
    batch::install_panic_hook();
    let o = run_dir(&dir, &opts(&out, 2), None, &fake_job);
    let c = o.counts();
    assert_eq!((c.scans, c.ok, c.error), (6, 4, 2), "{c:?}");
    assert_eq!(o.exit_code(true), 2);
    let e = entries(&out);
    assert_eq!(e.keys().cloned().collect::<Vec<_>>(), ["a.x3p", "corrupt.x3p", "d.sur", "sub/b.x3p", "sub/deeper/c.plu", "sub/panics.opd"]);
    assert_eq!(e["corrupt.x3p"]["status"], "error");
    assert!(e["corrupt.x3p"]["error"].as_str().unwrap().contains("corrupt.x3p"));
    assert_eq!(e["sub/panics.opd"]["error_kind"], "panic");
    let msg = e["sub/panics.opd"]["error"].as_str().unwrap();
    assert!(msg.contains("index out of bounds") && msg.contains("tests/all/batch.rs"), "{msg}");
    assert_eq!(e["a.x3p"]["status"], "ok");
    assert_eq!(e["a.x3p"]["fit"]["params"]["alpha"], 0.31);
    // Per-scan fit files mirror the folder layout; the CSV has one row per scan.
    let fit: Value = serde_json::from_slice(&std::fs::read(out.join("fits/sub/deeper/c.plu.fit.json")).unwrap()).unwrap();
    assert_eq!(fit["params"]["alpha"], 0.57);
    let csv = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    assert_eq!(csv.lines().count(), 7, "{csv}");
    assert!(csv.lines().next().unwrap().starts_with("path,status,model,alpha,"));
    assert_outputs_complete(&out);
}

#[test]
fn results_do_not_depend_on_jobs() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("in");
    for i in 0..12 {
        // Sleeps vary with alpha, so with 3 jobs completion order differs from path order.
        fake_scan(
            &dir,
            &format!("s{i:02}.x3p"),
            &format!(r#"{{"alpha": {}, "kl": {}}}"#, 0.37 * ((i * 7) % 12) as f64 / 12.0 + 0.01, 1e-3 * i as f64),
        );
    }
    let mut got = Vec::new();
    for jobs in [1, 2, 3] {
        let out = t.path().join(format!("out{jobs}"));
        run_dir(&dir, &opts(&out, jobs), None, &fake_job);
        got.push(stable_summary(&out));
        let csv = std::fs::read_to_string(out.join("summary.csv")).unwrap();
        let keys: Vec<&str> = csv.lines().skip(1).map(|l| l.split(',').next().unwrap()).collect();
        let mut sorted = keys.clone();
        sorted.sort();
        assert_eq!(keys, sorted, "CSV ordered by path");
    }
    assert_eq!(got[0], got[1]);
    assert_eq!(got[0], got[2]);
}

#[test]
fn resume_skips_finished_scans_and_reruns_changed_ones() {
    let t = tempfile::tempdir().unwrap();
    let (dir, out) = (t.path().join("in"), t.path().join("out"));
    good_folder(&dir);
    let calls = AtomicUsize::new(0);
    let counting = |s: &ScanSpec, c: &JobContext<'_>| {
        calls.fetch_add(1, Ordering::SeqCst);
        fake_job(s, c)
    };
    let mut o = opts(&out, 2);
    run_dir(&dir, &o, None, &counting);
    let full = stable_summary(&out);
    assert_eq!(calls.swap(0, Ordering::SeqCst), 4);

    // Simulate an interrupted run: one record and the summaries never written, a temp file left behind.
    std::fs::remove_file(out.join("scans/sub/b.x3p.json")).unwrap();
    std::fs::remove_file(out.join("summary.json")).unwrap();
    std::fs::write(out.join("scans/.a.x3p.json.XyZ123.tmp"), "{\"path\": \"a.x3").unwrap();
    o.resume = true;
    let r = run_dir(&dir, &o, None, &counting);
    assert_eq!(calls.swap(0, Ordering::SeqCst), 1, "only the unfinished scan runs again");
    assert_eq!(r.counts().reused, 3);
    assert_eq!(stable_summary(&out), full);
    assert_outputs_complete(&out);

    // A changed scan file, or changed settings, invalidate the finished record.
    std::thread::sleep(std::time::Duration::from_millis(20));
    fake_scan(&dir, "d.sur", r#"{"alpha": 0.06, "kl": 0.003}"#);
    run_dir(&dir, &o, None, &counting);
    assert_eq!(calls.swap(0, Ordering::SeqCst), 1);
    assert_eq!(entries(&out)["d.sur"]["fit"]["params"]["alpha"], 0.06);
    o.settings = "other model".into();
    run_dir(&dir, &o, None, &counting);
    assert_eq!(calls.swap(0, Ordering::SeqCst), 4);
}

#[test]
fn baseline_comparison_sets_the_exit_status() {
    let t = tempfile::tempdir().unwrap();
    let (dir, out0, out1) = (t.path().join("in"), t.path().join("base"), t.path().join("run"));
    good_folder(&dir);
    run_dir(&dir, &opts(&out0, 2), None, &fake_job);
    let base = Baseline::read(&out0.join("summary.json")).unwrap();
    assert_eq!(base.entries.len(), 4);

    // Against itself: every verdict "same", exit 0.
    let o = run_dir(&dir, &opts(&out1, 2), Some(&base), &fake_job);
    assert_eq!(o.exit_code(false), 0);
    assert!(entries(&out1).values().all(|e| e["baseline"]["verdict"] == "same"));

    // b got worse beyond tolerance (0.001 -> 0.0012 > max(5e-5, 5% of 0.001)), c slightly (within).
    fake_scan(&dir, "sub/b.x3p", r#"{"alpha": 0.12, "kl": 0.0012}"#);
    fake_scan(&dir, "sub/deeper/c.plu", r#"{"alpha": 0.57, "kl": 0.00415}"#);
    let o = run_dir(&dir, &opts(&out1, 2), Some(&base), &fake_job);
    assert_eq!(o.exit_code(false), 1);
    let e = entries(&out1);
    assert_eq!(e["sub/b.x3p"]["baseline"]["verdict"], "regressed");
    assert_eq!(e["sub/deeper/c.plu"]["baseline"]["verdict"], "same");
    let table = summary::regression_table(&o, false);
    assert!(table.contains("REGRESSED") && table.contains("sub/b.x3p"), "{table}");
    assert!(!table.contains("sub/deeper/c.plu"), "{table}");

    // A parameter beyond 3 combined standard errors is reported; with params_regress it regresses.
    fake_scan(&dir, "sub/b.x3p", r#"{"alpha": 0.13, "kl": 0.001}"#);
    let o = run_dir(&dir, &opts(&out1, 2), Some(&base), &fake_job);
    assert_eq!(o.exit_code(false), 0);
    assert_eq!(entries(&out1)["sub/b.x3p"]["baseline"]["param_changes"][0]["name"], "alpha");
    let mut strict = opts(&out1, 2);
    strict.tolerances.params_regress = true;
    assert_eq!(run_dir(&dir, &strict, Some(&base), &fake_job).exit_code(false), 1);

    // A scan gone from the folder is missing (exit 1 unless allowed); an unreadable one is exit 2.
    fake_scan(&dir, "sub/b.x3p", r#"{"alpha": 0.12, "kl": 0.001}"#);
    std::fs::remove_file(dir.join("d.sur")).unwrap();
    let o = run_dir(&dir, &opts(&out1, 2), Some(&base), &fake_job);
    assert_eq!(o.missing, ["d.sur"]);
    assert_eq!((o.exit_code(false), o.exit_code(true)), (1, 0));
    fake_scan(&dir, "d.sur", "garbage");
    let o = run_dir(&dir, &opts(&out1, 2), Some(&base), &fake_job);
    assert_eq!(o.exit_code(false), 2);
    assert_eq!(entries(&out1)["d.sur"]["baseline"]["verdict"], "broken");
}

#[test]
fn same_bins_score_decides_over_stored_quality() {
    // The baseline model re-scored on this run's bins is what counts: here the stored baseline kl
    // (0.001) would call the new fit (0.0012) a regression, but on the same bins the baseline model
    // scores 0.0013, so the new fit is better.
    let t = tempfile::tempdir().unwrap();
    let (dir, out0, out1) = (t.path().join("in"), t.path().join("base"), t.path().join("run"));
    fake_scan(&dir, "a.x3p", r#"{"alpha": 0.2, "kl": 0.001}"#);
    run_dir(&dir, &opts(&out0, 1), None, &fake_job);
    let base = Baseline::read(&out0.join("summary.json")).unwrap();
    fake_scan(&dir, "a.x3p", r#"{"alpha": 0.2, "kl": 0.0012, "kl_baseline_model": 0.0013}"#);
    let o = run_dir(&dir, &opts(&out1, 1), Some(&base), &fake_job);
    let e = entries(&out1);
    assert_eq!(e["a.x3p"]["baseline"]["basis"], "same_bins");
    assert_eq!(e["a.x3p"]["baseline"]["verdict"], "improved");
    assert_eq!(o.exit_code(false), 0);
}

#[test]
fn manifest_keys_and_options_reach_the_job() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("in");
    fake_scan(&dir, "raw/a.txt", r#"{"alpha": 0.2}"#);
    fake_scan(&dir, "list.csv", "path,id,dx,model\nraw/a.txt,first,1e-6,beckmann\nraw/a.txt,second,2e-6,\n");
    let specs = batch::manifest::read_manifest(&dir.join("list.csv")).unwrap();
    let seen = std::sync::Mutex::new(Vec::new());
    let job = |s: &ScanSpec, c: &JobContext<'_>| {
        seen.lock().unwrap().push((s.key.clone(), s.options.clone()));
        fake_job(s, c)
    };
    let out = t.path().join("out");
    let o = batch::run(&specs, None, &job, &opts(&out, 2), &|_| {}).unwrap();
    assert_eq!(o.briefs.iter().map(|b| b.entry.path.as_str()).collect::<Vec<_>>(), ["first", "second"]);
    assert_eq!(o.briefs[0].model.as_deref(), Some("beckmann"));
    assert_eq!(o.briefs[1].model.as_deref(), Some("ggx"));
    let mut seen = seen.into_inner().unwrap();
    seen.sort();
    assert_eq!(seen[0].1, ["--dx", "1e-6"]);
    assert_eq!(seen[1].1, ["--dx", "2e-6"]);
    assert!(out.join("scans/first.json").is_file() && out.join("fits/second.fit.json").is_file());
}

// ---- ndfit batch (the CLI) ----

use crate::common::ndfit_bin;
use std::process::{Command, Output};

fn ndfit(args: &[&str]) -> Output {
    Command::new(ndfit_bin()).args(args).output().expect("run ndfit")
}

fn p(path: &Path) -> &str {
    path.to_str().expect("utf-8 temp path")
}

#[test]
fn cli_process_isolation_survives_an_abort_and_reports_every_bad_scan() {
    let t = tempfile::tempdir().unwrap();
    let (dir, out) = (t.path().join("in"), t.path().join("out"));
    fake_scan(&dir, "a.x3p", "not a zip");
    fake_scan(&dir, "b/empty.x3p", "");
    fake_scan(&dir, "c.x3p", "PK\u{3}\u{4}");
    let o = ndfit(&["batch", p(&dir), "-o", p(&out), "--isolate", "process", "--debug-abort", "c.x3p", "--jobs", "2"]);
    assert_eq!(o.status.code(), Some(2), "stderr: {}", String::from_utf8_lossy(&o.stderr));
    let e = entries(&out);
    assert_eq!(e.len(), 3);
    assert!(e.values().all(|x| x["status"] == "error"));
    assert_eq!(e["c.x3p"]["error_kind"], "crash");
    assert!(e["c.x3p"]["error"].as_str().unwrap().contains("SIGABRT"), "{}", e["c.x3p"]);
    // The others fail in the reader, each naming its file.
    assert!(e["a.x3p"]["error"].as_str().unwrap().contains("a.x3p"));
    assert!(e["b/empty.x3p"]["error"].as_str().unwrap().contains("empty.x3p"));
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.lines().filter(|l| l.starts_with("ndfit: ")).count(), 3, "{err}");
    assert_outputs_complete(&out);
}

#[test]
fn cli_rejects_bad_invocations_with_one_line() {
    let t = tempfile::tempdir().unwrap();
    let (dir, out) = (t.path().join("in"), t.path().join("out"));
    std::fs::create_dir_all(&dir).unwrap();
    // An empty folder, a missing folder, a bad model, a bad per-scan option, a bad baseline.
    let cases: Vec<(Vec<String>, &str)> = vec![
        (vec![p(&dir).into()], "no scans"),
        (vec![p(&t.path().join("nope")).into()], "nope"),
        (vec![p(&dir).into(), "--model".into(), "phong".into()], "phong"),
    ];
    for (extra, needle) in cases {
        let mut args: Vec<String> = vec!["batch".into()];
        args.extend(extra);
        args.extend(["-o".into(), p(&out).into()]);
        let o = Command::new(ndfit_bin()).args(&args).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(err.lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(needle), "{args:?}: {err}");
    }
    fake_scan(&dir, "a.x3p", "x");
    let o = ndfit(&["batch", p(&dir), "-o", p(&out), "--", "--dx", "minus-one"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!((o.status.code(), err.lines().count()), (Some(2), 1), "{err}");
    assert!(err.contains("a.x3p") && err.contains("--dx"), "{err}");
    let bad = t.path().join("base.json");
    std::fs::write(&bad, "{\"entries\": 3}").unwrap();
    let o = ndfit(&["batch", p(&dir), "-o", p(&out), "--baseline", p(&bad)]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!((o.status.code(), err.lines().count()), (Some(2), 1), "{err}");
    assert!(err.contains("base.json"), "{err}");
    assert!(!out.join("summary.json").exists(), "no summary for a run that did not start");
}

/// Kill a running batch with SIGKILL midway, then `--resume`: the summary equals an uninterrupted run's.
#[test]
fn cli_killed_batch_resumes_to_the_same_summary() {
    let t = tempfile::tempdir().unwrap();
    let (dir, out_full, out_kill) = (t.path().join("in"), t.path().join("full"), t.path().join("killed"));
    let n = make_scan_set(&dir);
    let full = ndfit(&["batch", p(&dir), "-o", p(&out_full), "--jobs", "2"]);
    let code = full.status.code();

    // 150 ms per scan with one job: the kill lands while scans are still to do.
    let mut child = Command::new(ndfit_bin())
        .args(["batch", p(&dir), "-o", p(&out_kill), "--jobs", "1", "--debug-delay-ms", "150"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let records = |d: &Path| count_files(&d.join("scans"), ".json");
    let t0 = std::time::Instant::now();
    while records(&out_kill) < 2 && t0.elapsed().as_secs() < 60 {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    child.kill().unwrap(); // SIGKILL on Unix
    let st = child.wait().unwrap();
    assert!(!st.success());
    let done = records(&out_kill);
    assert!(done >= 2 && done < n, "kill landed midway: {done} of {n} finished");
    assert!(!out_kill.join("summary.json").exists());
    assert_outputs_complete(&out_kill);

    let resumed = ndfit(&["batch", p(&dir), "-o", p(&out_kill), "--jobs", "2", "--resume"]);
    assert_eq!(resumed.status.code(), code);
    assert_eq!(stable_summary(&out_kill), stable_summary(&out_full));
    assert_outputs_complete(&out_kill);
}

fn count_files(dir: &Path, suffix: &str) -> usize {
    let Ok(rd) = std::fs::read_dir(dir) else { return 0 };
    rd.flatten()
        .map(|e| {
            let p = e.path();
            if p.is_dir() {
                count_files(&p, suffix)
            } else {
                usize::from(e.file_name().to_string_lossy().ends_with(suffix) && !e.file_name().to_string_lossy().starts_with('.'))
            }
        })
        .sum()
}

/// A small set of real synthetic scans for the CLI tests (two sizes of the synthetic set); returns how many.
fn make_scan_set(dir: &Path) -> usize {
    synth_set(&dir.join("a"), 96).len() + synth_set(&dir.join("b"), 112).len()
}

// ---- end to end on synthetic scans ----

/// The synthetic regression set of the tests: visible upper halves of ellipsoids (their NDF is exactly
/// the ellipsoid NDF, so `ggx` describes the isotropic, unskewed one as well as `ellipsoid` does and the
/// others worse). Small grids keep the module fast. Returns the names, with `true` for the surfaces that
/// an isotropic GGX cannot describe (anisotropic or skewed).
fn synth_set(dir: &Path, n: usize) -> Vec<(&'static str, bool)> {
    use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};
    std::fs::create_dir_all(dir.join("skewed")).unwrap();
    let set: [(&str, [f64; 5], bool); 4] = [
        ("iso.x3p", [0.3, 0.3, 0.0, 0.0, 0.0], false),
        ("aniso.x3p", [0.4, 0.12, 0.0, 0.0, 0.5], true),
        ("skewed/x.x3p", [0.25, 0.25, 0.45, 0.0, 0.0], true),
        ("skewed/yz.x3p", [0.35, 0.2, 0.0, -0.35, 1.0], true),
    ];
    let s = SynthSettings { nx: n, ny: n, dx: 1e-6, dy: 1e-6, seed: 7, ..SynthSettings::default() };
    for (name, p, _) in &set {
        let e = EllipsoidParams { alpha_x: p[0], alpha_y: p[1], theta_x: p[2], theta_y: p[3], theta_z: p[4], ..EllipsoidParams::default() };
        let (hf, _) = ellipsoid_surface(&s, &e).unwrap();
        ndfit::io::write_x3p(&dir.join(name), &hf).unwrap();
    }
    set.iter().map(|(n, _, hard)| (*n, *hard)).collect()
}

#[test]
fn synthetic_set_corrupt_scan_own_baseline_and_ggx_regression() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("set");
    let set = synth_set(&dir, 160);
    // A corrupt scan: a good X3P cut in half.
    let good = std::fs::read(dir.join("iso.x3p")).unwrap();
    std::fs::write(dir.join("broken.x3p"), &good[..good.len() / 2]).unwrap();

    // 1. Exit 2; every good scan fitted; the corrupt one reported, by name, on stderr and in the summary.
    let base = t.path().join("base");
    let o = ndfit(&["batch", p(&dir), "-o", p(&base), "--model", "ellipsoid", "--jobs", "2"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    let e = entries(&base);
    assert_eq!(e.len(), set.len() + 1);
    assert_eq!(e["broken.x3p"]["status"], "error");
    assert!(e["broken.x3p"]["error"].as_str().unwrap().contains("broken.x3p"));
    assert!(err.lines().any(|l| l.starts_with("ndfit: ") && l.contains("broken.x3p")), "{err}");
    for (name, _) in &set {
        assert_eq!(e[*name]["status"], "ok", "{name}: {}", e[*name]);
        assert_eq!(e[*name]["fit"]["model"], "ellipsoid");
        // The batch's own score is a second implementation of objective.md: it must equal the fitter's
        // Poisson objective at the optimum (same bins, same formula) to rounding.
        let mine = e[*name]["quality"]["deviance"].as_f64().unwrap();
        let fitter = e[*name]["fit"]["quality"]["objective_value"].as_f64().unwrap();
        assert!((mine - fitter).abs() <= 1e-9 * fitter.abs(), "{name}: {mine} vs {fitter}");
    }
    std::fs::remove_file(dir.join("broken.x3p")).unwrap();
    let o = ndfit(&["batch", p(&dir), "-o", p(&base), "--model", "ellipsoid", "--jobs", "2", "--write-ndf", "--plots"]);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    // Optional per-scan outputs: the NDF CSV is normalized (sum d W = 1, Heitz eq. 9: an independent
    // check that the file holds the whole NDF) and the plot is a PNG.
    let csv = std::fs::read_to_string(base.join("ndf/skewed/x.x3p.ndf.csv")).unwrap();
    let mut rows = csv.lines();
    let head: Vec<&str> = rows.next().unwrap().split(',').collect();
    let (id, iw) = (head.iter().position(|h| *h == "d").unwrap(), head.iter().position(|h| *h == "proj_solid_angle").unwrap());
    let total: f64 = rows
        .map(|r| {
            let c: Vec<f64> = r.split(',').map(|x| x.parse().unwrap()).collect();
            c[id] * c[iw]
        })
        .sum();
    assert!((total - 1.0).abs() < 1e-9, "sum d W = {total}");
    assert!(std::fs::read(base.join("plots/aniso.x3p.png")).unwrap().starts_with(b"\x89PNG"));
    let baseline = base.join("summary.json");

    // 2. The same folder against its own baseline: exit 0, every verdict "same" with delta_kl = 0.
    let again = t.path().join("again");
    let o = ndfit(&["batch", p(&dir), "-o", p(&again), "--model", "ellipsoid", "--jobs", "1", "--baseline", p(&baseline)]);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stdout));
    for (name, v) in entries(&again) {
        assert_eq!(v["baseline"]["verdict"], "same", "{name}");
        assert_eq!(v["baseline"]["delta_kl"], 0.0, "{name}");
        assert_eq!(v["baseline"]["basis"], "same_bins", "{name}");
    }

    // 3. The same scans fitted with ggx against the ellipsoid baseline: exit 1, exactly the anisotropic
    //    and skewed scans regressed, named in the table on stdout.
    let ggx = t.path().join("ggx");
    let o = ndfit(&["batch", p(&dir), "-o", p(&ggx), "--model", "ggx", "--jobs", "2", "--baseline", p(&baseline)]);
    let table = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "{table}");
    let e = entries(&ggx);
    for (name, hard) in &set {
        let c = &e[*name]["baseline"];
        assert_eq!(c["regressed"], *hard, "{name}: {c}");
        let row = table.lines().find(|l| l.split_whitespace().nth(1) == Some(*name));
        assert_eq!(row.is_some_and(|r| r.starts_with("REGRESSED")), *hard, "{name}:\n{table}");
    }
    assert!(table.contains("ellipsoid -> ggx"), "{table}");
}

#[test]
fn synthetic_results_are_bit_identical_for_1_and_2_jobs() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("set");
    synth_set(&dir, 128);
    let mut sums = Vec::new();
    for jobs in ["1", "2"] {
        let out = t.path().join(format!("out{jobs}"));
        let o = ndfit(&["batch", p(&dir), "-o", p(&out), "--model", "auto", "--jobs", jobs]);
        assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
        sums.push(stable_summary(&out));
    }
    // serde_json compares f64 exactly: bit-identical parameters, errors, qualities.
    assert_eq!(sums[0], sums[1]);
}

/// A manifest over a real scan: per-scan columns reach the reader (`subsample` halves the grid) and the
/// per-scan `model` overrides `--model`.
#[test]
fn manifest_options_reach_the_pipeline_on_a_real_scan_needs_shared() {
    let Some(scans) = crate::common::shared_scans("batch::manifest_options_reach_the_pipeline_on_a_real_scan_needs_shared") else { return };
    let scan = scans.join("hamby44_downsampled_Barrel_1-Bullet_1-Land_1.x3p");
    let t = tempfile::tempdir().unwrap();
    let m = t.path().join("list.csv");
    let f = p(&scan);
    std::fs::write(&m, format!("# two readings of one scan\npath,id,subsample,model\n{f},full,,ggx\n{f},half,2,\n")).unwrap();
    let out = t.path().join("out");
    let o = ndfit(&["batch", p(&m), "-o", p(&out), "--model", "beckmann"]);
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let e = entries(&out);
    let (full, half) = (&e["full"]["fit"], &e["half"]["fit"]);
    assert_eq!((full["model"].as_str(), half["model"].as_str()), (Some("ggx"), Some("beckmann")));
    let nx = |v: &Value| v["input"]["nx"].as_u64().unwrap();
    let ny = |v: &Value| v["input"]["ny"].as_u64().unwrap();
    // Every 2nd point of n points is ceil(n / 2) points.
    assert_eq!((nx(half), ny(half)), (nx(full).div_ceil(2), ny(full).div_ceil(2)));
}

#[allow(dead_code)]
fn _unused(_: PathBuf) {}
