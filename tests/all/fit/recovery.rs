//! Recovery of synthetic truth from binned NDFs with Poisson counts (fixtures.rs): the accuracy target of
//! issue #5 (`delta(D_fit; D_true) <= 0.5%` at 1024^2 samples) and the coverage of the standard errors.

use ndfit::fit::{fit_model, FitOptions};
use ndfit::models::ModelId;

use super::fixtures::{angle_diff, delta_to_truth, model, ndf_of, ndf_on, N_1024};

/// The ellipsoid cases of the issue: alpha 0.02-1.5, anisotropy up to 10:1, skew up to +-0.5, any theta_z.
pub const ELLIPSOID_CASES: [[f64; 5]; 8] = [
    [0.02, 0.02, 0.0, 0.0, 0.0],
    [0.2, 0.02, 0.0, 0.0, 0.7],
    [0.3, 0.1, 0.5, -0.5, -1.2],
    [1.5, 0.15, 0.1, 0.3, 0.4],
    [1.5, 1.2, -0.5, 0.2, 1.5],
    [0.05, 0.04, -0.3, 0.5, -0.3],
    [0.8, 0.4, 0.25, -0.35, 2.5],
    [0.5, 0.5, 0.4, 0.4, 0.0],
];

/// Accuracy target of the issue: 0.5%.
const DELTA_MAX: f64 = 0.005;

#[test]
fn ellipsoid_fits_match_the_truth_at_1024_squared() {
    for (i, p) in ELLIPSOID_CASES.iter().enumerate() {
        let truth = model(ModelId::Ellipsoid, p);
        let ndf = ndf_of(&truth, N_1024, 100 + i as u64);
        let rep = fit_model(&ndf, ModelId::Ellipsoid, &FitOptions::default()).expect("fit");
        let fit = rep.to_model().expect("model");
        let d = delta_to_truth(&fit, &truth);
        let canon = truth.canonical().params();
        let got = rep.param_vec();
        let se = rep.std_error_vec();
        eprintln!(
            "case {i}: truth {canon:?}\n   fit {got:?}\n   se  {se:?}\n   delta {d:.2e} chi2r {:?} evals {} starts {:?}",
            rep.quality.reduced_chi2, rep.solver.evaluations, rep.solver.start_objectives
        );
        assert!(d <= DELTA_MAX, "case {i}: delta {d} > {DELTA_MAX}");
        assert!(got.iter().all(|v| v.is_finite()));
    }
}

#[test]
fn beckmann_aniso_recovers_sqrt2_rms_slope_and_axis() {
    // A Gaussian surface of slope standard deviations sigma along its principal axes has the anisotropic
    // Beckmann NDF with alpha = sqrt(2) sigma (Heitz footnote 3); the binned NDF here is that NDF.
    for (i, (sx, sy, phi)) in [(0.05, 0.02, 0.3), (0.3, 0.1, -1.0), (0.7, 0.5, 1.2)].into_iter().enumerate() {
        let (ax, ay) = (std::f64::consts::SQRT_2 * sx, std::f64::consts::SQRT_2 * sy);
        let truth = model(ModelId::BeckmannAniso, &[ax, ay, phi]);
        let ndf = ndf_of(&truth, N_1024, 200 + i as u64);
        let rep = fit_model(&ndf, ModelId::BeckmannAniso, &FitOptions::default()).expect("fit");
        let p = rep.param_vec();
        eprintln!("beckmann case {i}: truth ({ax}, {ay}, {phi}) fit {p:?} se {:?}", rep.std_error_vec());
        assert!((p[0] / ax - 1.0).abs() < 0.01 && (p[1] / ay - 1.0).abs() < 0.01, "case {i}: {p:?}");
        assert!(angle_diff(p[2], phi, std::f64::consts::PI).abs() < 0.01, "case {i}: theta_z {} vs {phi}", p[2]);
    }
}

#[test]
fn standard_errors_cover_the_truth() {
    // Over independent Poisson draws, |fit - truth| <= se should hold for about 68.3% of the parameters
    // and <= 2 se for about 95.4% if the reported errors are right. With 30 draws x 5 parameters = 150
    // (correlated within a draw, so count draws: effective n >= 30), the binomial standard deviation of
    // the 68.3% fraction is at most sqrt(0.683 * 0.317 / 30) = 0.085: accept 1-sigma coverage in
    // [0.683 - 3 * 0.085, 0.683 + 3 * 0.085] and 2-sigma coverage >= 0.954 - 3 * 0.038.
    let truth = model(ModelId::Ellipsoid, &[0.3, 0.12, 0.2, -0.3, 0.6]);
    let canon = truth.canonical().params();
    let (mut in1, mut in2, mut total) = (0usize, 0usize, 0usize);
    for seed in 0..30 {
        let ndf = ndf_on(&truth, 96, N_1024, 1000 + seed);
        let rep = fit_model(&ndf, ModelId::Ellipsoid, &FitOptions::default()).expect("fit");
        let p = rep.param_vec();
        let se = rep.std_error_vec();
        for j in 0..5 {
            let d = if j >= 2 { angle_diff(p[j], canon[j], std::f64::consts::PI) } else { p[j] - canon[j] };
            total += 1;
            in1 += (d.abs() <= se[j]) as usize;
            in2 += (d.abs() <= 2.0 * se[j]) as usize;
        }
    }
    let (c1, c2) = (in1 as f64 / total as f64, in2 as f64 / total as f64);
    eprintln!("coverage: 1 se {c1:.3}, 2 se {c2:.3} over {total}");
    assert!((0.683 - 0.255..=0.683 + 0.255).contains(&c1), "1-sigma coverage {c1}");
    assert!(c2 >= 0.954 - 0.114, "2-sigma coverage {c2}");
}

#[test]
fn theta_z_of_a_near_isotropic_lobe_is_reported_unidentified() {
    // An exactly isotropic truth has no theta_z: a Poisson draw gives a fitted anisotropy of the order
    // of the noise (r = e / s_e Rayleigh distributed), so theta_z's standard error 1 / (2 r) is mostly
    // above the 1/6 rad of THETA_Z_SE_MAX; it passes by chance with probability exp(-9/2) = 1.1% per draw,
    // so of 8 draws at most one may (P(>= 2 of 8) = 0.4%). Flagged ones must be null, not a number. A 10% anisotropy at the same N is measured (its se is about 1e-2 rad) and must
    // stay a number that covers the truth within 3 se.
    let iso = model(ModelId::Ellipsoid, &[0.3, 0.3, 0.2, -0.1, 0.0]);
    let mut flagged = 0;
    for seed in 0..8 {
        let mut rep = fit_model(&ndf_on(&iso, 96, N_1024, 50 + seed), ModelId::Ellipsoid, &FitOptions::default()).expect("fit");
        rep.input = Some(ndfit::scan::InputInfo {
            path: "synthetic".into(),
            format: "binned".into(),
            nx: 1024,
            ny: 1024,
            dx: 1e-6,
            dy: 1e-6,
            invalid: 0,
            file_invalid: 0,
            spikes: 0,
            file_grid: None,
            despike: None,
        });
        eprintln!("isotropic truth: fit {:?} se {:?} unidentified {:?}", rep.param_vec(), rep.std_error_vec(), rep.unidentified);
        if rep.unidentified.is_empty() {
            continue;
        }
        flagged += 1;
        assert_eq!(rep.unidentified, vec!["theta_z".to_string()], "seed {seed}");
        assert_eq!(rep.std_errors["theta_z"], None);
        // At the reported theta_z the skew angles are measured: their errors are of the order of the
        // alphas' relative errors (1e-3), not of theta_z's spread (0.1-1 rad).
        let se = rep.std_error_vec();
        assert!(se[..4].iter().all(|s| s.is_finite()) && se[2] < 0.01 && se[3] < 0.01, "{se:?}");
        let v = serde_json::to_value(&rep).expect("json");
        super::schema::assert_valid(&v);
    }
    assert!(flagged >= 7, "only {flagged} of 8 isotropic draws flagged theta_z");
    let aniso = model(ModelId::Ellipsoid, &[0.33, 0.3, 0.2, -0.1, 0.4]);
    let canon = aniso.canonical().params();
    let rep = fit_model(&ndf_on(&aniso, 96, N_1024, 60), ModelId::Ellipsoid, &FitOptions::default()).expect("fit");
    let se = rep.std_errors["theta_z"].expect("a 10% anisotropy identifies theta_z");
    assert!(rep.unidentified.is_empty());
    let d = angle_diff(rep.params["theta_z"], canon[4], std::f64::consts::PI);
    assert!(d.abs() <= 3.0 * se && se < THETA_SE_SANITY, "theta_z {} vs {} (se {se})", rep.params["theta_z"], canon[4]);
}

/// A measured theta_z at 10% anisotropy and N = 1024^2 has an se of order 1e-2 rad; 0.1 flags a gross
/// misreport.
const THETA_SE_SANITY: f64 = 0.1;
