//! Integration tests: the CLI as CONTRACT.md describes it, across commands.

use std::process::Command;

use crate::common::ndfit_bin;

/// `--version` names the package version; `--help` lists the contract's commands (`export` is added on
/// another branch).
#[test]
fn version_and_the_contract_commands_are_listed() {
    let o = Command::new(ndfit_bin()).arg("--version").output().expect("runs");
    assert!(o.status.success());
    let v = String::from_utf8_lossy(&o.stdout);
    assert!(v.contains(env!("CARGO_PKG_VERSION")), "version line {v:?}");
    let o = Command::new(ndfit_bin()).arg("--help").output().expect("runs");
    assert!(o.status.success());
    let help = String::from_utf8_lossy(&o.stdout);
    for cmd in ["fit", "info", "ndf", "eval", "batch"] {
        assert!(help.lines().any(|l| l.trim_start().starts_with(&format!("{cmd} "))), "`{cmd}` missing from --help:\n{help}");
    }
}

/// CONTRACT.md "Any failure": for a scan that does not exist, every scan-reading command exits non-zero
/// with exactly one line on stderr naming the file, and writes no output file.
#[test]
fn a_missing_scan_gives_one_line_naming_it_and_no_output() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scan = dir.path().join("no-such-scan.x3p");
    let out_of = |ext: &str| dir.path().join(format!("out.{ext}"));
    let cases: [(&str, Option<&str>); 3] = [("fit", Some("json")), ("ndf", Some("csv")), ("info", None)];
    for (cmd, ext) in cases {
        let mut c = Command::new(ndfit_bin());
        c.arg(cmd).arg(&scan);
        if let Some(ext) = ext {
            c.arg("-o").arg(out_of(ext));
        }
        let o = c.output().expect("runs");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{cmd}: exit 0 on a missing scan");
        assert_eq!(err.trim_end().lines().count(), 1, "{cmd}: stderr {err:?}");
        assert!(err.contains("no-such-scan.x3p"), "{cmd}: the line must name the file: {err:?}");
        assert!(!err.contains("panicked"), "{cmd}: {err:?}");
        if let Some(ext) = ext {
            assert!(!out_of(ext).exists(), "{cmd}: wrote an output file");
        }
    }
}

/// `NDFIT_PHASES` (docs/PERFORMANCE.md, "Scaling with cores"): `ndfit fit` prints one line per phase of
/// the pipeline, in the order they ran, none overlapping the next (they run one after the other; the
/// times are printed to 0.01 ms), all within the command's span, and covering most of it (the rest is
/// argument parsing and the summary line). Without the variable, no such line.
#[test]
fn phases_are_printed_in_order_without_overlap_only_when_asked() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scan = dir.path().join("s.x3p");
    let o = Command::new(ndfit_bin()).args(["synth", "--nx", "256", "--ny", "256"]).arg(&scan).output().expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let fit = |phases: bool| {
        let mut c = Command::new(ndfit_bin());
        c.arg("fit").arg(&scan).args(["--model", "ggx-aniso", "-o"]).arg(dir.path().join("f.json"));
        if phases {
            c.env("NDFIT_PHASES", "1");
        } else {
            c.env_remove("NDFIT_PHASES");
        }
        let o = c.output().expect("runs");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    assert!(!fit(false).contains("phase"), "phase lines without NDFIT_PHASES");
    let err = fit(true);
    let mut spans = Vec::new();
    let mut end = None;
    for line in err.lines() {
        let w: Vec<&str> = line.split_whitespace().collect();
        match w.as_slice() {
            ["ndfit:", "phase", name, "at", s, "ms", "took", d, "ms"] => {
                spans.push((name.to_string(), s.parse::<f64>().expect("start"), d.parse::<f64>().expect("duration")))
            }
            ["ndfit:", "phases", "end", "at", e, "ms"] => end = Some(e.parse::<f64>().expect("end")),
            _ => {}
        }
    }
    let end = end.expect("a closing `phases end` line");
    let names: Vec<&str> = spans.iter().map(|s| s.0.as_str()).collect();
    for want in ["read", "form", "despike", "ndf.frame", "ndf.histogram", "ndf.bins", "fit.session", "fit.solve", "fit.report", "write"] {
        assert!(names.contains(&want), "no `{want}` phase in {names:?}");
    }
    for pair in spans.windows(2) {
        let ((a, sa, da), (b, sb, _)) = (&pair[0], &pair[1]);
        assert!(sa <= sb, "{a} at {sa} listed before {b} at {sb}");
        assert!(sa + da <= sb + 0.02, "{a} ({sa} + {da} ms) overlaps {b} at {sb} ms");
    }
    let (last, s, d) = spans.last().expect("phases");
    assert!(s + d <= end + 0.02, "{last} ends after the command's end {end}");
    let covered: f64 = spans.iter().map(|s| s.2).sum();
    assert!(covered > 0.5 * end && covered <= end + 0.1, "the phases cover {covered} ms of {end}");
}

/// A `misfit` fit ends with the way on: for a named model, `--model auto`, and for any, the command that
/// tabulates the scan's own NDF for a renderer, which runs as printed and writes the file. A fit within
/// the tolerance says neither. Real metal under `auto` (st_x3p-2, `misfit` with every rung) names the ladder.
#[test]
fn a_misfit_names_the_measured_route_and_it_runs_needs_shared() {
    let dir = tempfile::tempdir().expect("tempdir");
    let scan = dir.path().join("g.x3p");
    let o = Command::new(ndfit_bin())
        .args(["synth", "--surface", "gaussian", "--sigma-x", "0.3", "--sigma-y", "0.1", "--nx", "256", "--ny", "256"])
        .arg(&scan)
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let fit = |scan: &std::path::Path, model: &str, form: &str| {
        let o = Command::new(ndfit_bin())
            .arg("fit")
            .arg(scan)
            .args(["--model", model, "--form", form, "-o"])
            .arg(dir.path().join("f.json"))
            .output()
            .expect("runs");
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.path().join("f.json")).expect("fit written")).expect("json");
        (v["quality"]["verdict"].as_str().expect("verdict").to_string(), String::from_utf8_lossy(&o.stderr).into_owned())
    };
    // An isotropic lobe on a 3:1 anisotropic Gaussian surface: far beyond the tolerance.
    let (verdict, err) = fit(&scan, "ggx", "none");
    assert_eq!(verdict, "misfit", "{err}");
    let hint = err.lines().find(|l| l.contains("export --to rgl")).unwrap_or_else(|| panic!("no measured route in: {err}"));
    assert!(hint.contains("ggx is not within the tolerance (`--model auto` tries the others)"), "{hint}");
    // The printed command runs as printed (NAME made a path) and writes the tabulated BSDF.
    let cmd = hint.split('`').find(|s| s.starts_with("ndfit export")).expect("a command in backticks");
    let out = dir.path().join("g.bsdf");
    let args: Vec<String> =
        cmd.split_whitespace().skip(1).map(|a| if a == "NAME.bsdf" { out.display().to_string() } else { a.to_string() }).collect();
    let o = Command::new(ndfit_bin()).args(&args).output().expect("runs");
    assert!(o.status.success() && std::fs::metadata(&out).expect("written").len() > 0, "{}", String::from_utf8_lossy(&o.stderr));
    // The truth's own family: within the tolerance, no hint.
    let (verdict, err) = fit(&scan, "beckmann-aniso", "none");
    assert_eq!(verdict, "ok", "{err}");
    assert!(!err.contains("export --to rgl"), "{err}");
    let Some(scans) = crate::common::shared_scans("a_misfit_names_the_measured_route_and_it_runs_needs_shared") else { return };
    // A scan no lobe renders like (the render choice answers `measured`): the command that writes its table.
    let scan = scans.join("hamby44_Unknown-Bullet_E-Land_1.x3p");
    let (verdict, err) = fit(&scan, "auto", "plane");
    assert_eq!(verdict, "misfit", "{err}");
    assert!(err.contains("no lobe renders within mean FLIP"), "{err}");
    assert!(err.contains(&format!("`ndfit export {} --to rgl -o OUT.bsdf`", scan.display())), "{err}");
}

/// `export --to rgl` of a scan takes the reading and fit flags of `ndfit fit`: a raw `.npy` grid without
/// `--dx` is refused in one line naming the flag (and nothing is written); with `--dx` and `--z-scale` the
/// measured table is written, and a misfit's hint says to pass those options on.
#[test]
fn export_of_a_scan_takes_the_reading_options() {
    let dir = tempfile::tempdir().expect("tempdir");
    let s = ndfit::synth::SynthSettings { nx: 200, ny: 160, seed: 4, ..Default::default() };
    let gp = ndfit::synth::GaussianParams { sigma_x: 0.3, sigma_y: 0.1, ..Default::default() };
    let (hf, _) = ndfit::synth::gaussian_surface(&s, &gp).expect("synth");
    // A little-endian float64 .npy in C order, through the readers' own test header.
    let mut npy = crate::readers::gen::npy_header("<f8", false, hf.ny, hf.nx);
    npy.extend(hf.z.iter().flat_map(|v| v.to_le_bytes()));
    let scan = dir.path().join("g.npy");
    std::fs::write(&scan, npy).expect("write npy");
    let out = dir.path().join("g.bsdf");
    let export = |flags: &[&str]| {
        Command::new(ndfit_bin()).arg("export").arg(&scan).args(["--to", "rgl", "-o"]).arg(&out).args(flags).output().expect("runs")
    };
    let o = export(&["--z-scale", "1"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.trim().lines().count() == 1 && err.contains("--dx"), "{err}");
    assert!(!out.exists(), "a refused export wrote {}", out.display());
    let o = export(&["--dx", &hf.dx.to_string(), "--z-scale", "1", "--form", "none"]);
    assert!(o.status.success() && std::fs::metadata(&out).expect("written").len() > 0, "{}", String::from_utf8_lossy(&o.stderr));
    let o = Command::new(ndfit_bin())
        .arg("fit")
        .arg(&scan)
        .args(["--dx", &hf.dx.to_string(), "--z-scale", "1", "--form", "none", "--model", "ggx", "-o"])
        .arg(dir.path().join("f.json"))
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success() && err.contains("with the reading and fit options given here"), "{err}");
}

/// `ndfit compare`: on a Gaussian surface (Beckmann truth) the lobes that render closest to the scan's
/// table are Beckmann lobes, and the GGX lobes, whose tails glow where the scan has none, score far worse;
/// the answer line names the answer, and the picture is a PNG of three panels under a title.
#[test]
fn compare_ranks_the_lobes_by_their_render() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("g.x3p");
    let o = Command::new(ndfit_bin())
        .args(["synth", "--surface", "gaussian", "--sigma-x", "0.25", "--sigma-y", "0.15", "--nx", "256", "--ny", "256", "--seed", "8"])
        .arg(&scan)
        .output()
        .expect("runs");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let prefix = dir.path().join("pic");
    let o = Command::new(ndfit_bin())
        .arg("compare")
        .arg(&scan)
        .args(["--scene", "point", "--json", "--png"])
        .arg(&prefix)
        .output()
        .expect("runs");
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{err}");
    let doc: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let mut scores: Vec<(String, f64)> = doc["candidates"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| (c["model"].as_str().unwrap().to_string(), c["worst"].as_f64().unwrap()))
        .collect();
    scores.sort_by(|a, b| a.1.total_cmp(&b.1));
    assert!(scores[0].0.starts_with("beckmann") || scores[0].0.starts_with("student"), "{doc}");
    let ggx = scores.iter().find(|s| s.0 == "ggx-aniso").unwrap().1;
    assert!(ggx > 3.0 * scores[0].1, "{doc}");
    let answer = doc["answer"].as_str().unwrap();
    assert!(err.contains(&format!("answer {answer}")), "{err}");
    assert_eq!(doc["lobe"].as_str().unwrap(), if answer == "measured" { scores[0].0.as_str() } else { answer }, "{doc}");
    let png = image::open(dir.path().join("pic.point.png")).expect("a PNG").to_rgb8();
    assert!(png.width() > 3 * 256 && png.height() >= 256, "{}x{}", png.width(), png.height());
    assert!(!dir.path().join("pic.broad.png").exists());
}
