//! `ndfit eval FIT.json` (CONTRACT.md): CSV in, `d` / `d,g1` out, checked against eq. 1 and eq. 6 of
//! Walter et al. and Heitz eq. 71-72 typed here; lenient JSON; one-line errors with the line number.

use std::io::Write;
use std::process::{Command, Stdio};

use nalgebra::{Matrix3, Vector3};
use serde_json::json;

use crate::common::ndfit_bin;

fn run(json: &serde_json::Value, stdin: &str) -> (i32, String, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fit.json");
    std::fs::write(&path, serde_json::to_string(json).unwrap()).unwrap();
    run_path(&path, stdin)
}

fn run_path(path: &std::path::Path, stdin: &str) -> (i32, String, String) {
    let mut child = Command::new(ndfit_bin())
        .arg("eval")
        .arg(path)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The child may exit on a bad JSON before reading stdin: a broken pipe here is expected then.
    let _ = child.stdin.take().unwrap().write_all(stdin.as_bytes());
    let out = child.wait_with_output().unwrap();
    (out.status.code().unwrap_or(-1), String::from_utf8(out.stdout).unwrap(), String::from_utf8(out.stderr).unwrap())
}

fn parse(out: &str) -> (String, Vec<Vec<f64>>) {
    let mut lines = out.lines();
    let header = lines.next().unwrap().to_string();
    let rows = lines.map(|l| l.split(',').map(|x| x.parse::<f64>().unwrap()).collect()).collect();
    (header, rows)
}

/// Walter et al. eq. 1 and eq. 6 straight from A.
fn ellipsoid_d_g1(a: &Matrix3<f64>, m: Vector3<f64>, u: Vector3<f64>) -> (f64, f64) {
    let n = Vector3::z();
    let q = (a.try_inverse().unwrap().transpose() * m).norm();
    let an = a * n;
    let d = 1.0 / (std::f64::consts::PI * a.determinant().abs() * an.norm() * q.powi(4));
    let au = a * u;
    let g1 = (2.0 * an.norm_squared() * u.dot(&n).abs() / (au.norm() * an.norm() + au.dot(&an))).min(1.0);
    (d, if u.dot(&m) >= 0.0 { g1 } else { 0.0 })
}

const ROWS: &str = "mx,my,mz,ux,uy,uz\n0,0,1,0,0,1\n0.1,0.2,0.9,0.5,0,0.5\n-0.3,0.1,0.5,0.1,-0.7,0.3\n0.5,0.5,0.01,0.9,0.1,0.05\n";

#[test]
fn eval_ellipsoid_from_params_and_from_matrix_a() {
    let p = [0.21, 0.13, 0.02, -0.01, 0.6];
    // A = S Rx Ry Rz of the contract, built with nalgebra's rotations.
    let r = super::quad::rotation(p[2], p[3], p[4]);
    let a = Matrix3::from_diagonal(&Vector3::new(p[0], p[1], 1.0)) * r;
    let full = json!({
        "schema": "ndfit.fit/7", "model": "ellipsoid", "unknown": [1, 2],
        "params": {"alpha_x": p[0], "alpha_y": p[1], "theta_x": p[2], "theta_y": p[3], "theta_z": p[4]},
    });
    let rows_a: Vec<Vec<f64>> = (0..3).map(|i| (0..3).map(|j| a[(i, j)] * 3.0).collect()).collect();
    let only_a = json!({"model": "ellipsoid", "matrix_a": rows_a});
    for fit in [full, only_a] {
        let (code, out, err) = run(&fit, ROWS);
        assert_eq!(code, 0, "stderr: {err}");
        let (header, rows) = parse(&out);
        assert_eq!(header, "d,g1");
        assert_eq!(rows.len(), 4);
        for (line, row) in ROWS.lines().skip(1).zip(&rows) {
            let v: Vec<f64> = line.split(',').map(|x| x.parse().unwrap()).collect();
            let (m, u) = (Vector3::new(v[0], v[1], v[2]).normalize(), Vector3::new(v[3], v[4], v[5]).normalize());
            let (d, g1) = ellipsoid_d_g1(&a, m, u);
            assert!((row[0] - d).abs() < 1e-12 * d, "D: {} vs {d}", row[0]);
            assert!((row[1] - g1).abs() < 1e-12, "G1: {} vs {g1}", row[1]);
        }
    }
}

#[test]
fn eval_ggx_d_only_and_nested_truth_file() {
    let alpha: f64 = 0.3;
    // A synth truth file: model and params one level down, other keys around.
    let truth = json!({"schema": "ndfit.synth/1", "seed": 4, "truth": {"model": "ggx", "params": {"alpha": alpha}}});
    let (code, out, err) = run(&truth, "mx,my,mz\n0,0,1\n0.6,0,0.8\n");
    assert_eq!(code, 0, "stderr: {err}");
    let (header, rows) = parse(&out);
    assert_eq!(header, "d");
    // Heitz eq. 71.
    let eq71 = |c: f64| {
        let t2 = (1.0 - c * c) / (c * c);
        1.0 / (std::f64::consts::PI * alpha * alpha * c.powi(4) * (1.0 + t2 / (alpha * alpha)).powi(2))
    };
    assert!((rows[0][0] - eq71(1.0)).abs() < 1e-12 * eq71(1.0));
    assert!((rows[1][0] - eq71(0.8)).abs() < 1e-12 * eq71(0.8));
    // Smith G1 for beckmann: Heitz eq. 69 at theta_o = 60 degrees.
    let b = json!({"model": "beckmann", "params": {"alpha": alpha}});
    let (code, out, _) = run(&b, "mx,my,mz,ux,uy,uz\n0,0,1,0.8660254037844386,0,0.5\n");
    assert_eq!(code, 0);
    let a = 1.0 / (alpha * 3f64.sqrt());
    let lambda = (libm::erf(a) - 1.0) / 2.0 + (-a * a).exp() / (2.0 * a * std::f64::consts::PI.sqrt());
    let (_, rows) = parse(&out);
    assert!((rows[0][1] - 1.0 / (1.0 + lambda)).abs() < 1e-12, "{} vs {}", rows[0][1], 1.0 / (1.0 + lambda));
}

#[test]
fn eval_errors_are_one_line_with_the_line_number() {
    let fit = json!({"model": "ggx-aniso", "params": {"alpha_x": 0.2, "alpha_y": 0.1, "theta_z": 0.0}});
    for (input, needle) in [
        ("mx,my,mz\n0,0,1\n0.1,x,0.9\n", "line 3"),
        ("mx,my,mz\n0,0,1\n0.1,0.9\n", "line 3"),
        ("mx,my,mz,ux,uy,uz\n0,0,1,0,0\n", "line 2"),
        ("mx,my\n0,0\n", "header"),
        ("mx,my,mz\n0,0,0\n", "line 2"),
        ("mx,my,mz\n0,0,nan\n", "line 2"),
        ("", "empty"),
    ] {
        let (code, out, err) = run(&fit, input);
        assert_ne!(code, 0, "{input:?} accepted");
        assert!(out.is_empty(), "partial output for {input:?}: {out}");
        assert_eq!(err.trim().lines().count(), 1, "not one line: {err}");
        assert!(err.contains(needle), "{input:?}: '{err}' lacks '{needle}'");
    }
    for (bad, needle) in [
        (json!({"model": "ggx-aniso", "params": {"alpha_x": 0.2}}), "alpha_y"),
        (json!({"model": "phong", "params": {"alpha": 0.2}}), "unknown model"),
        (json!({"params": {"alpha": 0.2}}), "model"),
        (json!({"model": "ggx", "params": {"alpha": -1.0}}), "alpha"),
        (json!({"model": "ellipsoid", "matrix_a": [[1, 0, 0], [0, 1, 0], [0, 0, 0]]}), "singular"),
    ] {
        let (code, out, err) = run(&bad, "mx,my,mz\n0,0,1\n");
        assert_ne!(code, 0);
        assert!(out.is_empty());
        assert!(err.contains("fit.json") && err.contains(needle), "'{err}' lacks the file or '{needle}'");
        assert_eq!(err.trim().lines().count(), 1);
    }
    let (code, _, err) = run_path(std::path::Path::new("/nonexistent/fit.json"), "mx,my,mz\n");
    assert_ne!(code, 0);
    assert!(err.contains("/nonexistent/fit.json"));
}
