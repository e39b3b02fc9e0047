//! Synthetic surfaces against their own definitions, checked by independent computations: the
//! ellipsoid's implicit equation (Walter et al. eq. 8) and normal (eq. 22), its footprint area (eq. 26)
//! against a count of grid points, the Gaussian surface's slope covariance measured directly on the
//! heights, the planes' exact heights, and the truth JSON.

use nalgebra::Vector3;
use ndfit::models::Ndf;
use ndfit::synth::EllipsoidGeometry;
use ndfit::synth::{ellipsoid_surface, gaussian_surface, tilted_planes, EllipsoidParams, GaussianParams, PlaneFacet, SynthSettings, Truth};

/// Every valid height lies on the ellipsoid p^T A^T A p = C^2 (eq. 8), on the half with (A^T A p)_z >= 0,
/// and the number of valid points matches the projected area pi C^2 |A n| / |A| (eq. 26) divided by the
/// pixel area, within the lattice-point error of an ellipse (bounded by its perimeter in pixels).
#[test]
fn ellipsoid_heights_satisfy_the_implicit_equation() {
    let s = SynthSettings { nx: 400, ny: 300, ..Default::default() };
    let p = EllipsoidParams { alpha_x: 0.2, alpha_y: 0.5, theta_x: 0.4, theta_y: -0.3, theta_z: 1.0, fill: 0.9 };
    let (hf, truth) = ellipsoid_surface(&s, &p).expect("valid");
    let g = EllipsoidGeometry::new(&p, &s).expect("valid");
    let a = truth.matrix_a.expect("ellipsoid truth has A");
    let am = nalgebra::Matrix3::from_fn(|r, c| a[r][c]);
    assert!((am - g.model.a()).abs().max() < 1e-15);
    let mut valid = 0usize;
    for i in 0..s.ny {
        for j in 0..s.nx {
            let z = hf.at(i, j);
            if z.is_nan() {
                continue;
            }
            valid += 1;
            let pnt = Vector3::new(s.xc(j), s.yc(i), z);
            let ap = am * pnt;
            assert!((ap.norm_squared() / (g.c * g.c) - 1.0).abs() < 1e-9);
            assert!((am.transpose() * ap).z >= 0.0);
        }
    }
    let n_area = g.proj_area / (s.dx * s.dy);
    // Perimeter of the footprint in pixels is below 2 pi times its larger half-extent (<= 200 px).
    let perimeter = 2.0 * std::f64::consts::PI * 200.0;
    assert!((valid as f64 - n_area).abs() < perimeter, "valid {valid} vs area {n_area}");
    assert!((valid as f64 - n_area).abs() / n_area < 0.01);
    // The analytic slope is the normal of eq. 22: m ~ A^T A p.
    let (x, y) = (s.xc(230), s.yc(140));
    let sl = g.slope(x, y).expect("inside the footprint");
    let z = g.height(x, y).expect("inside");
    let n = g.q * Vector3::new(x, y, z);
    let m = Vector3::new(-sl[0], -sl[1], 1.0).normalize();
    assert!((m - n.normalize()).norm() < 1e-12);
}

/// The realized central-difference slope covariance of a Gaussian surface, measured directly from the
/// heights of the periodic power-of-two grid (wrapping the stencils around), equals the prescribed
/// covariance to rounding; the mean slope is 0. This is Parseval's identity for the deterministic
/// amplitudes (see the generator's documentation), checked by a second algorithm.
#[test]
fn gaussian_surface_has_the_prescribed_slope_covariance() {
    let s = SynthSettings { nx: 256, ny: 128, dx: 1e-6, dy: 2e-6, seed: 11, ..Default::default() };
    let p = GaussianParams { sigma_x: 0.3, sigma_y: 0.1, theta_z: 0.6, corr_length: 6e-6 };
    let (hf, truth) = gaussian_surface(&s, &p).expect("valid");
    let (nx, ny) = (s.nx, s.ny);
    let (mut sx, mut sy, mut sxx, mut sxy, mut syy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for i in 0..ny {
        for j in 0..nx {
            let gx = (hf.at(i, (j + 1) % nx) - hf.at(i, (j + nx - 1) % nx)) / (2.0 * s.dx);
            let gy = (hf.at((i + 1) % ny, j) - hf.at((i + ny - 1) % ny, j)) / (2.0 * s.dy);
            sx += gx;
            sy += gy;
            sxx += gx * gx;
            sxy += gx * gy;
            syy += gy * gy;
        }
    }
    let n = (nx * ny) as f64;
    let (c, sn) = (p.theta_z.cos(), p.theta_z.sin());
    let (vx, vy) = (p.sigma_x.powi(2), p.sigma_y.powi(2));
    // Sigma = Rz^T diag Rz (contract convention of beckmann-aniso).
    let want = [[c * c * vx + sn * sn * vy, c * sn * (vy - vx)], [c * sn * (vy - vx), sn * sn * vx + c * c * vy]];
    let got = [[sxx / n, sxy / n], [sxy / n, syy / n]];
    for r in 0..2 {
        for k in 0..2 {
            assert!((got[r][k] - want[r][k]).abs() < 1e-9 * vx, "cov[{r}][{k}] {} vs {}", got[r][k], want[r][k]);
        }
    }
    assert!((sx / n).abs() < 1e-12 && (sy / n).abs() < 1e-12);
    // The truth is beckmann-aniso with alpha = sqrt 2 sigma (Heitz eq. 88 footnote 3), whose D evaluated
    // from the model equals the Gaussian slope density / m_z^4 (Heitz eq. 64) of Sigma.
    assert_eq!(truth.model, "beckmann-aniso");
    let model = truth.to_model().expect("contract model");
    let m = Vector3::new(0.1, -0.2, 1.0).normalize();
    let slope: [f64; 2] = [-m.x / m.z, -m.y / m.z];
    let det = want[0][0] * want[1][1] - want[0][1] * want[0][1];
    let q = (want[1][1] * slope[0].powi(2) - 2.0 * want[0][1] * slope[0] * slope[1] + want[0][0] * slope[1].powi(2)) / det;
    let d = (-0.5 * q).exp() / (2.0 * std::f64::consts::PI * det.sqrt() * m.z.powi(4));
    assert!((model.d(m) / d - 1.0).abs() < 1e-12, "{} vs {d}", model.d(m));
}

/// Plane strips have exactly the heights of their planes, and the facet table adds up.
#[test]
fn planes_have_exact_heights() {
    let s = SynthSettings { nx: 90, ny: 40, offset: 0.25, ..Default::default() };
    let f = [PlaneFacet { slope: [0.2, -0.1], weight: 1.0 }, PlaneFacet { slope: [-0.3, -0.1], weight: 2.0 }];
    let (hf, truth) = tilted_planes(&s, &f).expect("valid");
    let facets = truth.facets.expect("planes truth has facets");
    assert_eq!(facets[0].columns, [0, 30]);
    assert_eq!(facets[1].columns, [30, 90]);
    assert!((facets.iter().map(|f| f.weight).sum::<f64>() - 1.0).abs() < 1e-15);
    for fct in &facets {
        for i in 1..s.ny - 1 {
            for j in fct.columns[0] + 1..fct.columns[1] - 1 {
                let gx = (hf.at(i, j + 1) - hf.at(i, j - 1)) / (2.0 * s.dx);
                let gy = (hf.at(i + 1, j) - hf.at(i - 1, j)) / (2.0 * s.dy);
                // Heights of 0.25 m with slopes ~0.3 over 1 um: rounding of 0.25 (2.8e-17) over 2 um.
                assert!((gx - fct.slope[0]).abs() < 1e-10 && (gy - fct.slope[1]).abs() < 1e-10, "{gx} {gy}");
            }
        }
    }
}

/// Seeds reproduce scans exactly; holes and noise are independent streams (holes leave the other
/// points' heights bit-identical); bad settings are clear errors.
#[test]
fn seeds_noise_holes_and_bad_settings() {
    let s = SynthSettings { nx: 64, ny: 64, seed: 5, noise: 1e-9, ..Default::default() };
    let p = GaussianParams { corr_length: 4e-6, ..Default::default() };
    let (a, _) = gaussian_surface(&s, &p).expect("valid");
    let (b, _) = gaussian_surface(&s, &p).expect("valid");
    assert_eq!(a.z, b.z);
    let (h, _) = gaussian_surface(&SynthSettings { holes: 0.2, ..s.clone() }, &p).expect("valid");
    let masked = h.z.iter().filter(|v| v.is_nan()).count();
    // 4096 points at 20%: 819 +- 26; 5 sigma.
    assert!((masked as f64 - 819.2).abs() < 5.0 * 25.6, "{masked}");
    for (x, y) in a.z.iter().zip(&h.z) {
        assert!(y.is_nan() || x == y);
    }
    let (c, _) = gaussian_surface(&SynthSettings { seed: 6, ..s.clone() }, &p).expect("valid");
    assert_ne!(a.z, c.z);
    for bad in [
        SynthSettings { nx: 2, ..s.clone() },
        SynthSettings { dx: 0.0, ..s.clone() },
        SynthSettings { holes: 1.0, ..s.clone() },
        SynthSettings { noise: f64::NAN, ..s.clone() },
    ] {
        let e = gaussian_surface(&bad, &p).expect_err("bad settings");
        assert!(!e.message().is_empty());
    }
    assert!(ellipsoid_surface(&s, &EllipsoidParams { alpha_x: -1.0, ..Default::default() }).is_err());
    assert!(tilted_planes(&s, &[]).is_err());
}

/// The truth JSON carries schema, contract model, params by name and A, and reads back.
#[test]
fn truth_json_round_trips() {
    let s = SynthSettings { nx: 64, ny: 64, ..Default::default() };
    let (_, t) =
        ellipsoid_surface(&s, &EllipsoidParams { alpha_x: 0.2, alpha_y: 0.3, theta_x: 0.1, theta_y: 0.0, theta_z: 0.4, fill: 0.9 })
            .expect("valid");
    let text = t.to_json();
    let v: serde_json::Value = serde_json::from_str(&text).expect("valid JSON");
    assert_eq!(v["schema"], "ndfit.synth/1");
    assert_eq!(v["model"], "ellipsoid");
    let names: Vec<&String> = v["params"].as_object().expect("params").keys().collect();
    assert_eq!(names, ["alpha_x", "alpha_y", "theta_x", "theta_y", "theta_z"]);
    assert!(v["matrix_a"].is_array());
    let back: Truth = serde_json::from_str(&text).expect("reads back");
    assert_eq!(back, t);
}
