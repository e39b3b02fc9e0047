//! `ndfit info` and `ndfit convert` through the binary: JSON keys and values, and bad input giving a
//! non-zero exit with exactly one stderr line naming the file and the problem.

use std::process::Command;

use ndfit::io::{read_scan, ReadOptions};

use super::gen;
use crate::common::{ndfit_bin, shared_scans};

fn run(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(ndfit_bin()).args(args).output().expect("ndfit runs");
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stdout).into(), String::from_utf8_lossy(&out.stderr).into())
}

#[test]
fn info_json_matches_the_library() {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("g.x3p");
    std::fs::write(&p, gen::x3p()).expect("write");
    let (code, out, err) = run(&["info", p.to_str().expect("utf8"), "--json"]);
    assert_eq!(code, 0, "stderr: {err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("one JSON object");
    assert_eq!(v["format"], "x3p");
    assert_eq!(v["nx"], gen::NX);
    assert_eq!(v["ny"], gen::NY);
    assert_eq!(v["dx"], 1e-6);
    assert_eq!(v["dy"], 2e-6);
    assert_eq!(v["invalid"], gen::HOLES.len());
    // Independent Sq: plane z = a + b x + c y by the normal equations in plain coordinates.
    let pts: Vec<(f64, f64, f64)> = (0..gen::NX * gen::NY)
        .filter(|k| !gen::HOLES.contains(k))
        .map(|k| ((k % gen::NX) as f64 * 1e-6, (k / gen::NX) as f64 * 2e-6, gen::stored(k / gen::NX, k % gen::NX) as f64 * 1e-9))
        .collect();
    let mut m = nalgebra::Matrix3::<f64>::zeros();
    let mut r = nalgebra::Vector3::<f64>::zeros();
    for &(x, y, z) in &pts {
        let row = nalgebra::Vector3::new(1.0, x, y);
        m += row * row.transpose();
        r += row * z;
    }
    let c = m.lu().solve(&r).expect("plane");
    let sq = (pts.iter().map(|&(x, y, z)| (z - c[0] - c[1] * x - c[2] * y).powi(2)).sum::<f64>() / pts.len() as f64).sqrt();
    let got = v["sq"].as_f64().expect("sq");
    // Two double-precision least-squares solutions of a 33-point problem agree to ~1e-12.
    assert!((got - sq).abs() < 1e-10 * sq, "sq {got} vs independent {sq}");
}

/// On a real scan, the JSON `sq` is SurfaceTopography's Sq_plane (peer_readings.json) in metres.
#[test]
fn info_json_sq_matches_the_peer_on_a_real_scan_needs_shared() {
    let Some(dir) = shared_scans("info_json_sq_matches_the_peer_on_a_real_scan_needs_shared") else { return };
    let p = dir.join("hamby44_downsampled_Barrel_1-Bullet_1-Land_1.x3p");
    let (code, out, err) = run(&["info", p.to_str().expect("utf8"), "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("JSON");
    let sq = v["sq"].as_f64().expect("sq");
    // peer_readings.json: Sq_plane_um = 38.64929092927883 (SurfaceTopography, x3pio, surfalize agree).
    assert!((sq - 38.64929092927883e-6).abs() < 1e-6 * 38.6e-6, "sq {sq}");
    assert_eq!(v["invalid"], 1384);
}

#[test]
fn bad_files_give_one_line_and_a_nonzero_exit() {
    let dir = tempfile::tempdir().expect("tempdir");
    let w = |name: &str, b: &[u8]| {
        let p = dir.path().join(name);
        std::fs::write(&p, b).expect("write");
        p.to_str().expect("utf8").to_string()
    };
    let x3p = gen::x3p();
    let mut flipped = gen::sur(false);
    flipped[108..112].copy_from_slice(&i32::MAX.to_le_bytes());
    let mut nan_gsf = gen::gsf();
    let n = gen::NX * gen::NY;
    let start = nan_gsf.len() - 4 * n;
    for k in 0..n {
        nan_gsf[start + 4 * k..start + 4 * k + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    }
    // The GSF file with one header field replaced by another of the same length (the data stay aligned).
    let gsf_with = |from: &[u8], to: &[u8]| {
        let mut b = gen::gsf();
        let at = b.windows(from.len()).position(|w| w == from).expect("field");
        b[at..at + to.len()].copy_from_slice(to);
        b
    };
    let cases: Vec<(String, Vec<&str>, &str)> = vec![
        (w("empty.x3p", b""), vec![], "empty"),
        (w("trunc.x3p", &x3p[..x3p.len() / 2]), vec![], "zip"),
        (w("lying.sur", &flipped), vec![], "SUR"),
        (w("allnan.gsf", &nan_gsf), vec![], "all 35 points"),
        (w("noise.bin", &[1, 2, 3, 250]), vec![], "unknown scan format"),
        (w("raw.npy", &gen::npy()), vec![], "--z-scale"),
        (w("raw2.npy", &gen::npy()), vec!["--z-scale", "1e-9"], "--dx"),
        (dir.path().join("missing.x3p").to_str().expect("utf8").to_string(), vec![], "No such file"),
        // A spacing that is negative, zero or not finite, given (even to a format that carries its own)
        // or carried by the file.
        (w("neg.x3p", &x3p), vec!["--dx", "-1e-6", "--json"], "--dx must be a finite positive length"),
        (w("zero.x3p", &x3p), vec!["--dy", "0"], "--dy must be a finite positive length"),
        (w("nan.npy", &gen::npy()), vec!["--z-scale", "1e-9", "--dx", "NaN"], "--dx must be a finite positive length"),
        (w("inf.npy", &gen::npy()), vec!["--z-scale", "1e-9", "--dx", "1e-6", "--dy", "inf"], "--dy must be a finite positive length"),
        (w("neg.gsf", &gsf_with(b"XReal = 14", b"XReal = -1")), vec![], "spacing must be finite and positive"),
        (w("zero.gsf", &gsf_with(b"YReal = 15", b"YReal = -0")), vec![], "spacing must be finite and positive"),
    ];
    for (path, extra, needle) in cases {
        let mut args = vec!["info", path.as_str()];
        args.extend(extra);
        let (code, out, err) = run(&args);
        assert_ne!(code, 0, "{path}: exit 0");
        assert!(out.is_empty(), "{path}: wrote to stdout: {out}");
        let lines: Vec<&str> = err.lines().collect();
        assert_eq!(lines.len(), 1, "{path}: stderr is not one line: {err:?}");
        assert!(lines[0].contains(&path), "{path}: line does not name the file: {}", lines[0]);
        assert!(lines[0].contains(needle), "{path}: {:?} lacks {needle:?}", lines[0]);
        assert!(!err.contains("panicked"), "{path}: {err}");
    }
}

#[test]
fn convert_writes_x3p_or_nothing() {
    let dir = tempfile::tempdir().expect("tempdir");
    let src = dir.path().join("g.sur");
    std::fs::write(&src, gen::sur(true)).expect("write");
    let out = dir.path().join("g.x3p");
    let (code, _, err) = run(&["convert", src.to_str().expect("utf8"), out.to_str().expect("utf8")]);
    assert_eq!(code, 0, "{err}");
    let a = read_scan(&src, &ReadOptions::default()).expect("source");
    let b = read_scan(&out, &ReadOptions::default()).expect("converted");
    assert_eq!((a.dx, a.dy, a.nx, a.ny), (b.dx, b.dy, b.nx, b.ny));
    for (x, y) in a.z.iter().zip(&b.z) {
        assert!(x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan()));
    }
    // A failing conversion leaves no output file behind.
    let bad = dir.path().join("bad.sur");
    std::fs::write(&bad, b"DIGITAL SURF").expect("write");
    let out2 = dir.path().join("bad.x3p");
    let (code, _, err) = run(&["convert", bad.to_str().expect("utf8"), out2.to_str().expect("utf8")]);
    assert_ne!(code, 0);
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(!out2.exists());
}

/// `info --json` reports the file as stored: `invalid` is the file's own invalid points, `sq` and `sdq`
/// those of its heights after the plane removal with nothing masked, on every shared scan that
/// SurfaceTopography reads (peer_readings.json: the same tolerances as the library's reading); the
/// points the default spike test would mask are apart, in `spikes`.
#[test]
fn info_json_agrees_with_surface_topography_on_every_scan_needs_shared() {
    let Some(dir) = shared_scans("info_json_agrees_with_surface_topography_on_every_scan_needs_shared") else { return };
    let text = std::fs::read_to_string(dir.join("peer_readings.json")).expect("readable");
    let json: serde_json::Value = serde_json::from_str(&text).expect("JSON");
    let mut checked = 0;
    for file in json["files"].as_array().expect("files") {
        let name = file["file"].as_str().expect("name");
        let readings = file["readings"].as_array().expect("readings");
        let Some(r) = readings.iter().find(|r| r["library"] == "SurfaceTopography" && r["ok"] == true) else { continue };
        let c = &r["common"];
        let p = dir.join(name);
        let (code, out, err) = run(&["info", p.to_str().expect("utf8"), "--json"]);
        assert_eq!(code, 0, "{name}: {err}");
        let v: serde_json::Value = serde_json::from_str(&out).expect("JSON");
        assert_eq!(v["invalid"].as_u64(), c["n_invalid"].as_u64(), "{name}: invalid against SurfaceTopography");
        let rel = |a: f64, b: f64| (a - b).abs() / b.abs();
        let (sq, want_sq) = (v["sq"].as_f64().expect("sq"), c["Sq_plane_um"].as_f64().expect("Sq") * 1e-6);
        assert!(rel(sq, want_sq) < 1e-6, "{name}: sq {sq} against {want_sq}");
        let (sdq, want_sdq) = (v["sdq"].as_f64().expect("sdq"), c["Sdq_central"].as_f64().expect("Sdq"));
        assert!(rel(sdq, want_sdq) < 1e-6, "{name}: sdq {sdq} against {want_sdq}");
        assert!(v["spikes"].as_u64().is_some(), "{name}: no spikes count");
        eprintln!("{name}: invalid {} as SurfaceTopography, spikes {} apart", v["invalid"], v["spikes"]);
        checked += 1;
    }
    assert_eq!(checked, 13, "SurfaceTopography reads 13 of the shared scans");
}

/// A smooth scan with known holes and known spikes (written here as NPY): `info` counts the holes as
/// `invalid` and the spikes apart as `spikes`, `--despike none` tests none, and the fit's `input` splits
/// its masked points the same way (`invalid = file_invalid + spikes`).
#[test]
fn info_and_fit_report_the_file_and_the_spikes_apart() {
    let (nx, ny) = (160, 150);
    let mut z: Vec<f64> = (0..nx * ny)
        .map(|k| {
            let (i, j) = ((k / nx) as f64, (k % nx) as f64);
            1e-7 * ((0.21 * j).sin() + (0.17 * i).cos() + 0.5 * (0.13 * (i - j)).sin())
        })
        .collect();
    let holes: Vec<usize> = (0..nx * ny).step_by(331).collect();
    // Spikes of 10 um amid 0.3 um of relief, away from the holes and the rim.
    let spikes: Vec<usize> = (0..nx * ny)
        .step_by(997)
        .filter(|&k| (2..ny - 2).contains(&(k / nx)) && (2..nx - 2).contains(&(k % nx)))
        .filter(|&k| holes.iter().all(|&h| (h / nx).abs_diff(k / nx) > 2 || (h % nx).abs_diff(k % nx) > 2))
        .collect();
    for &k in &holes {
        z[k] = f64::NAN;
    }
    for &k in &spikes {
        z[k] += 1e-5;
    }
    assert!(spikes.len() > 10, "{} spikes", spikes.len());
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join("spiky.npy");
    let mut b = gen::npy_header("<f8", false, ny, nx);
    z.iter().for_each(|v| b.extend(v.to_le_bytes()));
    std::fs::write(&p, b).expect("write");
    let ps = p.to_str().expect("utf8");
    let (code, out, err) = run(&["info", ps, "--dx", "1e-6", "--z-scale", "1", "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).expect("JSON");
    assert_eq!(v["invalid"].as_u64(), Some(holes.len() as u64));
    assert_eq!(v["spikes"].as_u64(), Some(spikes.len() as u64));
    let (code, out, err) = run(&["info", ps, "--dx", "1e-6", "--z-scale", "1", "--json", "--despike", "none"]);
    assert_eq!(code, 0, "{err}");
    let none: serde_json::Value = serde_json::from_str(&out).expect("JSON");
    assert_eq!((none["invalid"].as_u64(), none["spikes"].as_u64()), (Some(holes.len() as u64), Some(0)));
    assert_eq!(none["sq"], v["sq"], "sq is the file's, whatever the spike test");
    let fit = dir.path().join("fit.json");
    let (code, _, err) = run(&["fit", ps, "--dx", "1e-6", "--z-scale", "1", "--model", "beckmann", "-o", fit.to_str().expect("utf8")]);
    assert_eq!(code, 0, "{err}");
    let f: serde_json::Value = serde_json::from_slice(&std::fs::read(&fit).expect("fit JSON")).expect("JSON");
    let input = &f["input"];
    assert_eq!(input["file_invalid"].as_u64(), Some(holes.len() as u64));
    assert_eq!(input["spikes"].as_u64(), Some(spikes.len() as u64));
    assert_eq!(input["invalid"].as_u64(), Some((holes.len() + spikes.len()) as u64));
    assert_eq!(input["despike"]["masked"], input["spikes"]);
}
