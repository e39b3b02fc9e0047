//! Measurement tool (not a test): splits the end-to-end fit error of a 1024^2 synthetic ellipsoid scan into
//! binning (the midpoint rule of objective.md against exact bin integrals) and NDF estimation.
//!
//!     cargo run --release --example diagnose_midpoint

use ndfit::fit::delta_to_model;
use ndfit::fit::{fit_model, FitOptions};
use ndfit::models::{Model, ModelId, Ndf};
use ndfit::ndf::{empirical_ndf, NdfOptions};
use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};

fn settings(n: usize, seed: u64) -> SynthSettings {
    SynthSettings { nx: n, ny: n, seed, ..SynthSettings::default() }
}

/// `delta(D_fit; D_true)` (objective.md) by quadrature on a fine grid matched to the truth.
fn delta_to_truth(fit: &Model, truth: &Model) -> f64 {
    delta_to_model(fit, truth).expect("truth has mass")
}

fn main() {
    let p = [0.3, 0.1, 0.3, -0.2, 0.8];
    let ep = EllipsoidParams { alpha_x: p[0], alpha_y: p[1], theta_x: p[2], theta_y: p[3], theta_z: p[4], ..EllipsoidParams::default() };
    let (hf, truth) = ellipsoid_surface(&settings(1024, 7), &ep).expect("synth");
    let truth = truth.to_model().expect("truth");
    let ndf = empirical_ndf(&hf, &NdfOptions::default()).expect("ndf");
    // Same bins, counts = exact bin integrals of the truth (no estimation error, no noise).
    let mut exact = ndf.clone();
    let n = ndf.n_samples as f64;
    for (k, b) in exact.bins.iter_mut().enumerate() {
        b.count = (n * 1e4 * ndf.bin_integral(k, ndfit::ndf::QuadOrder::Fine(4), |m| truth.d(m)).unwrap()).round() as u64;
    }
    exact.n_samples = exact.bins.iter().map(|b| b.count).sum();
    let rep = fit_model(&exact, ModelId::Ellipsoid, &FitOptions::default()).expect("fit");
    eprintln!(
        "bins {} exact-count fit {:?} delta {:.2e}",
        ndf.bins.len(),
        rep.param_vec(),
        delta_to_truth(&rep.to_model().unwrap(), &truth)
    );
    let mid: f64 = ndf
        .bins
        .iter()
        .enumerate()
        .map(|(k, b)| {
            let ex = ndf.bin_integral(k, ndfit::ndf::QuadOrder::Fine(4), |m| truth.d(m)).unwrap();
            ex * (truth.d(b.m) * b.proj_solid_angle / ex - 1.0).powi(2)
        })
        .sum::<f64>()
        .sqrt();
    let est = ndfit::fit::delta(|m| ndf.d_at(*m), |m| truth.d(*m), ndf.bins.iter().map(|b| (b.m, b.proj_solid_angle)));
    eprintln!("midpoint rms rel err {mid:.2e}; delta(D_emp; D_true) on bins {est:?}");
}
