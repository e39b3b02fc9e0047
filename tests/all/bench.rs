//! Integration tests: `ndfit bench --quick` (never timing: the CSV's shape, and its accuracy and
//! counts against independent truth), and the pieces of the bench library.

use std::path::Path;
use std::process::Command;

use ndfit::bench::sweep::Plan;
use ndfit::ndf::NormalScheme;
use ndfit::synth::{ellipsoid_surface, SynthSettings};

use crate::common::ndfit_bin;

fn run_quick(out: &Path) -> Vec<csv::StringRecord> {
    let o = Command::new(ndfit_bin()).args(["bench", "--quick", "-o"]).arg(out).output().expect("ndfit runs");
    assert!(o.status.success(), "ndfit bench --quick failed: {}", String::from_utf8_lossy(&o.stderr));
    let mut rd = csv::Reader::from_path(out.join("bench.csv")).expect("bench.csv written");
    let header = rd.headers().expect("header").clone();
    for col in ["group", "size", "samples", "t_total_ms", "peak_mib", "ndf_delta", "fit_delta", "alpha_err", "angle_err"] {
        assert!(header.iter().any(|h| h == col), "column {col} missing from {header:?}");
    }
    let mut rows = vec![header];
    rows.extend(rd.records().map(|r| r.expect("well-formed CSV row")));
    rows
}

fn col<'a>(rows: &'a [csv::StringRecord], r: &'a csv::StringRecord, name: &str) -> &'a str {
    let i = rows[0].iter().position(|h| h == name).expect("known column");
    &r[i]
}

fn num(rows: &[csv::StringRecord], r: &csv::StringRecord, name: &str) -> Option<f64> {
    let s = col(rows, r, name);
    (!s.is_empty()).then(|| s.parse().unwrap_or_else(|_| panic!("{name} = {s:?} is not a number")))
}

/// Valid central-difference stencils of the quick scene, counted here from the synthesized heights
/// (an independent count of what the NDF must have binned).
fn valid_central(size: usize, stride: usize) -> u64 {
    let s = SynthSettings { nx: size, ny: size, dx: 1e-6, dy: 1e-6, seed: 1, ..SynthSettings::default() };
    let (hf, _) = ellipsoid_surface(&s, &ndfit::bench::scene::truth_params()).expect("synth");
    let hf = ndfit::preprocess::subsample(&hf, stride).expect("subsample");
    let mut n = 0;
    for i in 1..hf.ny - 1 {
        for j in 1..hf.nx - 1 {
            if [hf.at(i, j), hf.at(i, j - 1), hf.at(i, j + 1), hf.at(i - 1, j), hf.at(i + 1, j)].iter().all(|v| v.is_finite()) {
                n += 1;
            }
        }
    }
    n
}

#[test]
fn quick_bench_csv_is_sane_against_truth() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rows = run_quick(dir.path());
    let plan = Plan::quick();
    assert_eq!(rows.len() - 1, plan.points().len(), "one row per planned point");
    for r in &rows[1..] {
        let group = col(&rows, r, "group");
        // Stage times are positive and add up to the total (up to the CSV's float printing).
        let parts: f64 =
            ["t_read_ms", "t_subsample_ms", "t_convert_ms", "t_ndf_ms", "t_fit_ms"].iter().map(|c| num(&rows, r, c).expect("time")).sum();
        let total = num(&rows, r, "t_total_ms").expect("total");
        assert!(total > 0.0 && (parts - total).abs() <= 1e-9 * total.max(1.0), "{group}: {parts} vs {total}");
        // The samples are the valid stencils of the (subsampled) scan, counted independently.
        let (size, stride) = (num(&rows, r, "size").expect("size") as usize, num(&rows, r, "stride").expect("stride") as usize);
        let samples = num(&rows, r, "samples").expect("samples") as u64;
        if col(&rows, r, "scheme") == NormalScheme::Central.as_str() {
            assert_eq!(samples, valid_central(size, stride), "{group} {size} stride {stride}");
        }
        // Peak memory holds at least the heightfield (8 bytes per point after subsampling).
        if let Some(peak) = num(&rows, r, "peak_mib") {
            let hf_mib = (size.div_ceil(stride)).pow(2) as f64 * 8.0 / (1024.0 * 1024.0);
            assert!(peak >= hf_mib, "{group}: peak {peak} MiB below the {hf_mib} MiB heightfield");
        }
        // Accuracy is a finite, non-negative distance whenever the NDF exists.
        let nd = num(&rows, r, "ndf_delta").expect("ndf_delta");
        assert!(nd.is_finite() && nd >= 0.0);
    }
    let find = |g: &str, size: usize| {
        rows[1..].iter().find(|r| col(&rows, r, "group") == g && num(&rows, r, "size") == Some(size as f64)).expect("row present")
    };
    // Defaults at 256^2 with the ellipsoid model: the truth is recovered. Tolerances: the empirical NDF
    // itself differs from the truth by ndf_delta (counting noise of ~30k normals in ~500 bins, ~0.1);
    // a 5-parameter fit averages that noise over all bins, so its error must be well below ndf_delta
    // (we require half), and alphas within 5 % / angles within 0.02 rad (several standard errors of
    // 30k normals, sigma_alpha/alpha ~ 1/sqrt(N) ~ 0.6 %).
    let d = find("size", 256);
    let (nd, fd) = (num(&rows, d, "ndf_delta").expect("ndf"), num(&rows, d, "fit_delta").expect("fit"));
    assert!(fd < 0.5 * nd, "fit_delta {fd} vs ndf_delta {nd}");
    assert!(num(&rows, d, "alpha_err").expect("alpha") < 0.05);
    assert!(num(&rows, d, "angle_err").expect("angle") < 0.02);
    // Model complexity: the skewed anisotropic truth is not a GGX; an isotropic GGX is far worse.
    let ggx = rows[1..].iter().find(|r| col(&rows, r, "model") == "ggx").expect("ggx row");
    assert!(num(&rows, ggx, "fit_delta").expect("ggx fit") > 5.0 * fd);
    // More normals, better NDF: ndf_delta falls with size (counting noise ~ 1/sqrt(N)).
    let small = find("size", 128);
    assert!(num(&rows, small, "ndf_delta").expect("ndf") > nd);
    // The plot is a PNG; the summary holds the front and the cost model.
    let png = std::fs::read(dir.path().join("pareto.png")).expect("pareto.png");
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n");
    let s: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.path().join("summary.json")).expect("summary")).expect("JSON");
    assert!(!s["pareto_front"].as_array().expect("front").is_empty());
    assert!(s["cost_model"].as_array().expect("cost model").iter().any(|e| e["against"] == "bins"));
    assert_eq!(s["presets"].as_array().expect("presets").len(), 3);
}

#[test]
fn bench_bad_arguments_fail_cleanly() {
    let dir = tempfile::tempdir().expect("tempdir");
    let o = Command::new(ndfit_bin()).args(["bench", "--quick", "--sizes", "4", "-o"]).arg(dir.path()).output().expect("runs");
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(err.trim().lines().count(), 1, "one line: {err}");
    assert!(err.contains("--sizes"), "{err}");
    assert!(!dir.path().join("bench.csv").exists());
    let o = Command::new(ndfit_bin()).args(["bench", "--child-point", "{not json"]).output().expect("runs");
    assert!(!o.status.success() && !String::from_utf8_lossy(&o.stderr).contains("panicked"));
}

/// `ndfit fit --preset` against the synthetic truth and against what docs/PERFORMANCE.md says each preset
/// is. A 1024^2 scan has ~500k normals; the fit error (NDF metric, `delta(D_fit; D_true)`) is the O(dx^2)
/// bias of the central slopes: documented 4.7e-4 at 1024^2 for the full-resolution fit and 7.7e-3 for the
/// surface sampled on a 256^2 grid, which is what `fast` (every 4th row and column) fits. Bounds: 1e-3 and
/// 1e-2 on delta; alphas within 0.2 % and 1 %, angles within 2e-3 and 1e-2 rad. Also what the presets are:
/// `balanced` is exactly the default fit (same parameters to the bit), `fast` counts 1/16 of the normals,
/// `accurate` tries more starts.
#[test]
fn fit_cli_presets_recover_truth() {
    let dir = tempfile::tempdir().expect("tempdir");
    let s = SynthSettings { nx: 1024, ny: 1024, dx: 1e-6, dy: 1e-6, seed: 1, ..SynthSettings::default() };
    let p = ndfit::bench::scene::truth_params();
    let (hf, truth) = ellipsoid_surface(&s, &p).expect("synth");
    let truth = truth.to_model().expect("truth model");
    let scan = dir.path().join("e.npy");
    ndfit::bench::scene::write_npy_f64(&scan, &hf).expect("npy");
    let run = |preset: Option<&str>| -> serde_json::Value {
        let mut c = Command::new(ndfit_bin());
        // No form removal: a plane fitted to the tilted ellipsoid cap would take its tilt out of the NDF.
        c.arg("fit").arg(&scan).args(["--dx", "1e-6", "--z-scale", "1", "--model", "ellipsoid", "--form", "none"]);
        if let Some(p) = preset {
            c.args(["--preset", p]);
        }
        let o = c.output().expect("runs");
        assert!(o.status.success(), "{preset:?}: {}", String::from_utf8_lossy(&o.stderr));
        serde_json::from_slice(&o.stdout).expect("fit JSON")
    };
    let default = run(None);
    let n_all = default["quality"]["n_samples_total"].as_f64().expect("n_samples_total");
    let want = [p.alpha_x, p.alpha_y, p.theta_x, p.theta_y, p.theta_z];
    let mut starts = Vec::new();
    for (preset, max_delta, alpha_tol, angle_tol) in
        [("fast", 1e-2, 1e-2, 1e-2), ("balanced", 1e-3, 2e-3, 2e-3), ("accurate", 1e-3, 2e-3, 2e-3)]
    {
        let v = run(Some(preset));
        let got: Vec<f64> =
            ["alpha_x", "alpha_y", "theta_x", "theta_y", "theta_z"].iter().map(|k| v["params"][k].as_f64().expect("param")).collect();
        let fit = ndfit::models::Model::from_params(ndfit::models::ModelId::Ellipsoid, &got).expect("valid fit");
        let d = crate::fit::fixtures::delta_to_truth(&fit, &truth);
        eprintln!("preset {preset}: {got:?} delta {d:.2e}");
        assert!(d <= max_delta, "{preset}: delta {d:.2e} > {max_delta:e}");
        for k in 0..2 {
            assert!((got[k] / want[k] - 1.0).abs() <= alpha_tol, "{preset}: alpha {} vs {}", got[k], want[k]);
        }
        for k in 2..5 {
            assert!((got[k] - want[k]).abs() <= angle_tol, "{preset}: angle {k} {} vs {}", got[k], want[k]);
        }
        let n = v["quality"]["n_samples_total"].as_f64().expect("n_samples_total");
        match preset {
            "fast" => assert!((n * 16.0 / n_all - 1.0).abs() < 0.02, "fast counts {n} of {n_all} normals, not 1/16"),
            "balanced" => assert_eq!(v["params"], default["params"], "balanced is the default fit"),
            _ => assert_eq!(n, n_all),
        }
        starts.push(v["solver"]["starts"].as_u64().expect("solver.starts"));
    }
    assert!(starts[2] > starts[1], "accurate tries more starts than balanced: {starts:?}");
}

#[test]
fn wave_bench_on_a_tiny_scan_writes_every_field() {
    // `--wave` in its quickest form: a 256^2 synthetic scan (one coherence patch), no real scans, one run
    // each. Never timing: the JSON's shape and what it must say about the scan.
    let dir = tempfile::tempdir().expect("tempdir");
    let o = Command::new(ndfit_bin())
        .args(["bench", "--wave", "--quick", "--wave-size", "256", "--wave-level-size", "256", "--wave-scans", "none", "-o"])
        .arg(dir.path())
        .output()
        .expect("ndfit runs");
    assert!(o.status.success(), "ndfit bench --wave failed: {}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.path().join("wave.json")).expect("wave.json")).expect("JSON");
    assert_eq!(v["schema"], "ndfit.bench.wave/1");
    assert!(dir.path().join("wave.md").is_file());
    let speed = v["speed"].as_array().expect("speed rows");
    assert_eq!(speed.len(), 1, "the synthetic scan alone");
    let s = &speed[0];
    assert_eq!(s["scan"], "synthetic");
    assert_eq!(s["grid"], serde_json::json!([256, 256]));
    assert_eq!(s["heights_bytes"], 256 * 256 * 8);
    // 0.1 um spacing, default coherence 18.9 um: one patch of 189 samples.
    assert_eq!(s["patch_samples"], serde_json::json!([189, 189]));
    assert_eq!(s["patches"], 1);
    assert!(s["levels"].as_u64().expect("levels") > 1);
    assert!(s["ndfit"]["median_ms"].as_f64().expect("time") > 0.0);
    assert_eq!(s["ndfit"]["samples"].as_array().expect("samples").len(), 1);
    // Not the judged size: reported, not judged.
    assert!(s["ratio_met"].is_null() && s["memory_met"].is_null());
    if cfg!(target_os = "linux") {
        let peak = s["ndfit_peak_rss"].as_u64().expect("peak from --report-memory");
        assert!(peak > 256 * 256 * 8, "the peak {peak} holds at least the heights");
        assert!(s["memory_over_heights"].as_f64().expect("ratio") > 1.0);
    }
    // With a Python (fits/.venv) the numpy peer ran on the same scan: a time, a ratio and the agreement.
    if !s["numpy"].is_null() {
        assert!(s["ratio"].as_f64().expect("ratio") > 0.0);
        assert!(s["numpy_diffuse_rel_diff"].as_f64().expect("agreement").is_finite());
    } else {
        assert!(s["ratio"].is_null());
    }
    let sweeps = v["level_ratio"].as_array().expect("level sweeps");
    assert_eq!(sweeps.len(), 1);
    let pts = sweeps[0]["points"].as_array().expect("points");
    let ratios: Vec<f64> = pts.iter().map(|p| p["level_ratio"].as_f64().expect("ratio")).collect();
    assert_eq!(ratios, vec![1.02, 1.05, 1.1, 1.2, 1.4]);
    // The reference against itself differs by nothing; coarser ratios need fewer levels.
    for k in ["diffuse_rel_diff", "specular_abs_diff", "grid_rel_diff"] {
        assert_eq!(pts[0][k].as_f64(), Some(0.0), "{k}");
        assert!(pts.iter().all(|p| p[k].as_f64().is_some_and(|x| x.is_finite() && x >= 0.0)), "{k}");
    }
    let levels: Vec<u64> = pts.iter().map(|p| p["levels"].as_u64().expect("levels")).collect();
    assert!(levels.windows(2).all(|w| w[0] > w[1]), "{levels:?}");
}

#[test]
fn answer_bench_on_fresh_truths_measures_both_commands_and_reads_the_regime() {
    // No shared scans: the three fresh truths of 64^2, one run each. The polished one is a mirror to light
    // (0.1 nm heights at 0.5 um: its mirror share at 450 nm, 0 deg, is exp(-(4 pi 0.1 / 450)^2) ~ 0.99992).
    let dir = tempfile::tempdir().unwrap();
    let plan =
        ndfit::bench::answer::AnswerPlan { scans: vec![dir.path().join("absent.x3p")], size: 64, seed: 7, repeats: 1, ndfit: ndfit_bin() };
    let b = ndfit::bench::answer::run(&plan, dir.path(), |_| {}).unwrap();
    assert_eq!(b.rows.len(), 3);
    assert_eq!(b.notes.len(), 1, "the absent scan is a note: {:?}", b.notes);
    for r in &b.rows {
        assert!(r.auto_ms > 0.0 && r.ggx_aniso_ms > 0.0 && (r.ratio - r.auto_ms / r.ggx_aniso_ms).abs() < 1e-12, "{r:?}");
        assert!(r.optics_ms.is_some_and(|o| o >= 0.0 && o <= r.auto_ms), "{r:?}");
        // The ladder alone is reported where auto renders (the geometric regime) and only there.
        assert_eq!(r.ladder_ms.is_some(), r.regime.as_deref() == Some("geometric"), "{r:?}");
        if let (Some(ms), Some(x)) = (r.ladder_ms, r.ladder_ratio) {
            assert!(ms > 0.0 && (x - ms / r.ggx_aniso_ms).abs() < 1e-12, "{r:?}");
        }
    }
    let polished = b.rows.iter().find(|r| r.scan.starts_with("polished")).unwrap();
    assert_eq!((polished.regime.as_deref(), polished.answer.as_deref()), (Some("wave"), Some("mirror")));
    let rough = b.rows.iter().find(|r| r.scan.starts_with("gaussian")).unwrap();
    assert_eq!(rough.regime.as_deref(), Some("geometric"));
    let md = ndfit::bench::answer::markdown(&b);
    assert!(md.contains("| polished (0.1 nm), seed 7 | wave | mirror |") && md.contains("against the aim of 3x"), "{md}");
    let geometric = b.rows.iter().filter(|r| r.ladder_ratio.is_some()).count();
    let over = b.rows.iter().filter(|r| r.ladder_ratio.is_some_and(|x| x > 3.0)).count();
    assert!(geometric >= 1 && md.contains(&format!("takes more than 3x on {over} of {geometric} scans")), "{md}");
}
