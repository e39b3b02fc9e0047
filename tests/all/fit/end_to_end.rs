//! Scan -> empirical NDF -> fit, on synthetic scans with known truth (`ndfit::synth`), including the
//! extremes of issue #5.

use ndfit::fit::{fit_model, FitOptions};
use ndfit::models::ModelId;
use ndfit::ndf::NormalScheme;
use ndfit::ndf::{empirical_ndf, NdfOptions};
use ndfit::synth::{ellipsoid_surface, gaussian_surface, tilted_planes, EllipsoidParams, GaussianParams, PlaneFacet, SynthSettings};

use super::fixtures::delta_to_truth;

fn settings(n: usize, seed: u64) -> SynthSettings {
    SynthSettings { nx: n, ny: n, seed, ..SynthSettings::default() }
}

/// Fit an ellipsoid scan and return `delta(D_fit; D_true)`.
fn ellipsoid_case(p: [f64; 5], n: usize, offset: f64, scheme: ndfit::ndf::NormalScheme) -> (f64, ndfit::fit::FitReport) {
    let ep = EllipsoidParams { alpha_x: p[0], alpha_y: p[1], theta_x: p[2], theta_y: p[3], theta_z: p[4], ..EllipsoidParams::default() };
    let s = SynthSettings { offset, ..settings(n, 7) };
    let (hf, truth) = ellipsoid_surface(&s, &ep).expect("synth");
    let truth = truth.to_model().expect("truth model");
    let ndf = empirical_ndf(&hf, &NdfOptions { scheme, ..NdfOptions::default() }).expect("ndf");
    let rep = fit_model(&ndf, ModelId::Ellipsoid, &FitOptions::default()).expect("fit");
    assert!(rep.param_vec().iter().all(|v| v.is_finite()));
    let d = delta_to_truth(&rep.to_model().expect("model"), &truth);
    eprintln!(
        "{p:?} n={n} offset={offset} {scheme:?}: fit {:?} se {:?} delta {d:.2e} chi2r {:?}",
        rep.param_vec(),
        rep.std_error_vec(),
        rep.quality.reduced_chi2
    );
    // A single-lobe truth that the fit recovers must be trusted (data_formats/objective.md, "The verdict").
    assert_eq!(rep.quality.verdict, ndfit::fit::Verdict::Ok, "{p:?}: {:?}", rep.quality.reasons);
    (d, rep)
}

/// The accuracy target on the scan pipeline: 0.5%.
const DELTA_MAX: f64 = 0.005;

#[test]
fn ellipsoid_scans_at_1024_squared_fit_within_half_a_percent() {
    // Near-mirror (alpha 0.005), narrow isotropic, and a huge height offset (0.5 m on micrometre detail).
    for (p, offset) in [([0.02, 0.02, 0.0, 0.0, 0.0], 0.0), ([0.005, 0.005, 0.0, 0.0, 0.0], 0.0), ([0.02, 0.02, 0.0, 0.0, 0.0], 0.5)] {
        let (d, rep) = ellipsoid_case(p, 1024, offset, NormalScheme::Central);
        assert!(d <= DELTA_MAX, "{p:?} offset {offset}: delta {d}");
        assert!(rep.std_error_vec()[..2].iter().all(|s| s.is_finite()));
    }
}

#[test]
fn ellipsoid_scans_rough_and_skewed_at_1024_squared() {
    // The grid of a synthetic cap loses the grazing normals near its footprint rim (slopes -> infinity),
    // so the data's tail is short; the default fit region (bins within 70 deg, model normalized over
    // them, objective.md) leaves that tail out. Measured (measure_max_theta_on_ellipsoid_scans): 0.10%,
    // 0.34%, 0.21% here, against 0.89%, 3.3%, 0.61% with the whole hemisphere.
    for p in [[0.3, 0.1, 0.3, -0.2, 0.8], [1.5, 0.15, -0.5, 0.5, -1.0], [0.1, 0.05, 0.55, -0.55, 0.3]] {
        let (d, _) = ellipsoid_case(p, 1024, 0.0, NormalScheme::Central);
        assert!(d <= DELTA_MAX, "{p:?}: delta {d}");
    }
}

#[test]
fn flat_tilted_plane_is_a_finite_specular_fit() {
    // A plane has a delta NDF: after plane removal every normal is n. The fit must give a finite alpha at
    // the resolution floor, flagged specular, with no NaN anywhere in the report.
    let s = SynthSettings { nx: 256, ny: 256, ..SynthSettings::default() };
    let (hf, _) = tilted_planes(&s, &[PlaneFacet { slope: [0.3, -0.1], weight: 1.0 }]).expect("plane");
    let ndf = empirical_ndf(&hf, &NdfOptions::default()).expect("ndf");
    for id in [ModelId::Ggx, ModelId::Ellipsoid] {
        let mut rep = fit_model(&ndf, id, &FitOptions::default()).expect("a plane is a usable fit");
        rep.input = Some(ndfit::scan::InputInfo::new(std::path::Path::new("plane"), &hf));
        assert!(rep.specular, "{id}: not flagged specular");
        assert_eq!(rep.quality.verdict, ndfit::fit::Verdict::Unresolved, "{id}: a lobe inside one bin is not resolved");
        let v = serde_json::to_value(&rep).expect("json");
        super::schema::assert_valid(&v);
        assert!(rep.param_vec().iter().all(|x| x.is_finite()), "{id}: {:?}", rep.param_vec());
        // The parameter map puts the floor at ALPHA_MIN (1 + 1e-12) (params::u_of).
        assert!((rep.param_vec()[0] / ndfit::models::ALPHA_MIN - 1.0).abs() < 1e-9, "{id}: a delta NDF is at the alpha floor");
        assert!(rep.std_error_vec().iter().all(|s| s.is_nan()), "{id}: no standard error for an unmeasured width");
    }
}

#[test]
fn gaussian_scan_fits_beckmann_aniso_to_sqrt2_rms_slope() {
    // Gaussian random surface with prescribed slope covariance: alpha = sqrt(2) sigma (Heitz footnote 3).
    // Compare with the RMS slopes of the scan itself along the fitted axes (the realization's own truth),
    // within 1%, and with the prescribed axis within 0.01 rad.
    let g = GaussianParams { sigma_x: 0.2, sigma_y: 0.08, theta_z: 0.4, corr_length: 8e-6 };
    let (hf, _) = gaussian_surface(&settings(1024, 3), &g).expect("synth");
    let ndf = empirical_ndf(&hf, &NdfOptions::default()).expect("ndf");
    let rep = fit_model(&ndf, ModelId::BeckmannAniso, &FitOptions::default()).expect("fit");
    let p = rep.param_vec();
    // RMS slope along the fitted axes from the NDF's own slope covariance (projected-area weighted).
    let c = ndf.slope_cov;
    let (s, co) = p[2].sin_cos();
    // Local axis x in the scan frame is (cos tz, -sin tz) (m' = Rz m).
    let var_x = co * co * c[0][0] - 2.0 * s * co * c[0][1] + s * s * c[1][1];
    let var_y = s * s * c[0][0] + 2.0 * s * co * c[0][1] + co * co * c[1][1];
    let (ax, ay) = ((2.0 * var_x).sqrt(), (2.0 * var_y).sqrt());
    eprintln!("gaussian: fit {p:?}, sqrt2 rms slopes ({ax}, {ay}), prescribed ({}, {})", 0.2 * 2f64.sqrt(), 0.08 * 2f64.sqrt());
    assert!((p[0] / ax - 1.0).abs() < 0.01 && (p[1] / ay - 1.0).abs() < 0.01, "{p:?} vs ({ax}, {ay})");
    assert!(super::fixtures::angle_diff(p[2], 0.4, std::f64::consts::PI).abs() < 0.01, "theta_z {}", p[2]);
    assert_eq!(rep.quality.verdict, ndfit::fit::Verdict::Ok, "{:?}", rep.quality.reasons);
}
