//! The two-lobe mixtures against independent sources: normalization and the Smith masking by adaptive
//! quadrature (written in models/quad.rs), `ndfit eval` against the lobes mixed by hand, and the Mitsuba
//! export's blend evaluated with Mitsuba's own GGX formula.

use std::io::Write;
use std::process::{Command, Stdio};

use nalgebra::Vector3;
use ndfit::models::{Model, ModelId, Ndf};

use super::quad::{hemisphere_integral, slope_frame};
use crate::common::ndfit_bin;

fn model(id: ModelId, p: &[f64]) -> Model {
    Model::from_params(id, p).expect("valid parameters")
}

/// Each lobe normalized (Heitz eq. 9) makes the mixture normalized: the integral of `D (m.n)` is 1.
/// Quadrature in the frame of the wider lobe, asked for 1e-10 relative.
#[test]
fn mixtures_integrate_to_one() {
    for (id, p, frame) in [
        (ModelId::Ggx2, vec![0.05, 0.03, 0.4, 0.3, 0.7, 0.8], [0.4, 0.3, 0.0, 0.0, 0.7]),
        (ModelId::Beckmann2, vec![0.1, 0.08, 0.5, 0.2, -0.4, 0.3], [0.5, 0.2, 0.0, 0.0, -0.4]),
        (ModelId::EllipsoidGgx, vec![0.1, 0.05, 0.2, -0.1, 0.3, 0.6, 0.9], [0.6, 0.6, 0.0, 0.0, 0.0]),
    ] {
        let m = model(id, &p);
        let (w0, l) = slope_frame(frame[0], frame[1], frame[2], frame[3], frame[4]);
        let (val, err) = hemisphere_integral(|v| m.d(v), |_| 1.0, w0, l, 1e-10);
        assert!(err < 1e-7, "{id}: quadrature did not converge ({err:e})");
        assert!((val - 1.0).abs() < 1e-6, "{id} {p:?}: integral of D cos = {val}");
    }
}

/// Smith: `1 + Lambda(u) = integral of D(m) <u, m>+ dm / (u.n)` (Heitz eq. 43 with the projected-area
/// identity, eq. 9 of the masked surface) for the unskewed mixtures, by quadrature; and `G1 = 1 / (1 + Lambda)`.
#[test]
fn mixture_smith_lambda_is_the_projected_area() {
    for (id, p, frame) in [
        (ModelId::Ggx2, vec![0.05, 0.03, 0.4, 0.3, 0.7, 0.8], [0.4, 0.3, 0.0, 0.0, 0.7]),
        (ModelId::Beckmann2, vec![0.1, 0.08, 0.5, 0.2, -0.4, 0.3], [0.5, 0.2, 0.0, 0.0, -0.4]),
    ] {
        let m = model(id, &p);
        let (w0, l) = slope_frame(frame[0], frame[1], frame[2], frame[3], frame[4]);
        for theta in [20f64, 50.0, 70.0, 80.0] {
            for phi in [0.3f64, 1.9] {
                let t = theta.to_radians();
                let u = Vector3::new(t.sin() * phi.cos(), t.sin() * phi.sin(), t.cos());
                let (proj, err) = hemisphere_integral(|v| m.d(v), |v| u.dot(&v).max(0.0) / v.z, w0, l, 1e-9);
                assert!(err < 1e-6 * proj, "{id}: quadrature did not converge");
                let want = proj / u.z - 1.0;
                let got = m.lambda(u);
                assert!((got - want).abs() < 1e-6 * (1.0 + want), "{id} u={u:?}: Lambda {got} vs quadrature {want}");
                let g1 = m.g1(u, Vector3::z());
                assert!((g1 - 1.0 / (1.0 + want)).abs() < 1e-6, "{id}: G1");
            }
        }
    }
}

fn run(cmd: &[&str], json: &serde_json::Value, stdin: &str) -> (i32, String, String) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("fit.json");
    std::fs::write(&path, serde_json::to_string(json).unwrap()).unwrap();
    let mut child = Command::new(ndfit_bin())
        .args(cmd)
        .arg(&path)
        .args(if cmd[0] == "export" { vec!["--to", "mitsuba", "--json"] } else { vec![] })
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let _ = child.stdin.take().unwrap().write_all(stdin.as_bytes());
    let out = child.wait_with_output().unwrap();
    (out.status.code().unwrap_or(-1), String::from_utf8(out.stdout).unwrap(), String::from_utf8(out.stderr).unwrap())
}

/// `ndfit eval` of a `ggx2` fit: D is the two GTR2aniso lobes mixed by hand, G1 the Smith form with the
/// weighted mean of the lobes' Lambdas.
#[test]
fn eval_cli_of_a_mixture() {
    let p = [0.1, 0.05, 0.45, 0.3, 0.4, 0.85];
    let json = serde_json::json!({"model": "ggx2", "params": {"alpha_x1": p[0], "alpha_y1": p[1], "alpha_x2": p[2], "alpha_y2": p[3], "theta_z": p[4], "weight": p[5]}});
    let (l1, l2) = (model(ModelId::GgxAniso, &[p[0], p[1], p[4]]), model(ModelId::GgxAniso, &[p[2], p[3], p[4]]));
    let dirs = [
        (Vector3::new(0.1, -0.2, 1.0).normalize(), Vector3::new(0.5, 0.3, 0.6).normalize()),
        (Vector3::z(), Vector3::new(-0.8, 0.1, 0.3).normalize()),
    ];
    let stdin: String = std::iter::once("mx,my,mz,ux,uy,uz".to_string())
        .chain(dirs.iter().map(|(m, u)| format!("{},{},{},{},{},{}", m.x, m.y, m.z, u.x, u.y, u.z)))
        .collect::<Vec<_>>()
        .join("\n");
    let (code, out, err) = run(&["eval"], &json, &stdin);
    assert_eq!(code, 0, "{err}");
    let rows: Vec<Vec<f64>> = out.lines().skip(1).map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    for ((m, u), row) in dirs.iter().zip(&rows) {
        let d = p[5] * l1.d(*m) + (1.0 - p[5]) * l2.d(*m);
        let lam = p[5] * l1.lambda(*u) + (1.0 - p[5]) * l2.lambda(*u);
        assert!((row[0] / d - 1.0).abs() < 1e-12, "D {} vs {d}", row[0]);
        assert!((row[1] - 1.0 / (1.0 + lam)).abs() < 1e-12, "G1 {} vs {}", row[1], 1.0 / (1.0 + lam));
    }
}

/// `ndfit export --to mitsuba --json` of a `ggx2` fit: Mitsuba's `blendbsdf` gives `(1 - weight)` to the
/// first nested BSDF and `weight` to the second; each `roughconductor` evaluates
/// `1 / (pi au av (x^2/au^2 + y^2/av^2 + z^2)^2)` in the frame of the tangent at `tangent_angle`. The blend's D
/// equals the fit's everywhere.
#[test]
fn mitsuba_blend_of_a_mixture_is_the_fitted_d() {
    let p = [0.1, 0.05, 0.45, 0.3, 0.4, 0.85];
    let json = serde_json::json!({"model": "ggx2", "params": {"alpha_x1": p[0], "alpha_y1": p[1], "alpha_x2": p[2], "alpha_y2": p[3], "theta_z": p[4], "weight": p[5]}});
    let (code, out, err) = run(&["export"], &json, "");
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v["blend"], "blendbsdf");
    let t = v["tangent_angle"].as_f64().unwrap();
    let w = v["weight"].as_f64().unwrap();
    let lobe = |b: &serde_json::Value, m: Vector3<f64>| {
        let (au, av) = (b["alpha_u"].as_f64().unwrap(), b["alpha_v"].as_f64().unwrap());
        let (s, c) = t.sin_cos();
        let (x, y) = ((c * m.x + s * m.y) / au, (-s * m.x + c * m.y) / av);
        1.0 / (std::f64::consts::PI * au * av * (x * x + y * y + m.z * m.z).powi(2))
    };
    let fit = model(ModelId::Ggx2, &p);
    for (mx, my) in [(0.0, 0.0), (0.1, 0.05), (-0.3, 0.2), (0.5, -0.4), (0.02, 0.3)] {
        let m = Vector3::new(mx, my, 1.0).normalize();
        let blend = (1.0 - w) * lobe(&v["bsdfs"][0], m) + w * lobe(&v["bsdfs"][1], m);
        assert!((blend / fit.d(m) - 1.0).abs() < 1e-12, "at {m:?}: blend {blend} vs fit {}", fit.d(m));
    }
}
