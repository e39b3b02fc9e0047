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
    let cases: Vec<(String, Vec<&str>, &str)> = vec![
        (w("empty.x3p", b""), vec![], "empty"),
        (w("trunc.x3p", &x3p[..x3p.len() / 2]), vec![], "zip"),
        (w("lying.sur", &flipped), vec![], "SUR"),
        (w("allnan.gsf", &nan_gsf), vec![], "all 35 points"),
        (w("noise.bin", &[1, 2, 3, 250]), vec![], "unknown scan format"),
        (w("raw.npy", &gen::npy()), vec![], "--z-scale"),
        (w("raw2.npy", &gen::npy()), vec!["--z-scale", "1e-9"], "--dx"),
        (dir.path().join("missing.x3p").to_str().expect("utf8").to_string(), vec![], "No such file"),
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
