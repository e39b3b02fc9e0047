//! Measurement tool (not a test): the fit error against truth of 1024^2 synthetic ellipsoid scans for several
//! `max_theta` (the table of data_formats/objective.md that chose the default of 70 degrees).
//!
//!     cargo run --release --example measure_max_theta
//!
//! `NDFIT_THETAS=60,70,90` sets the angles; `NDFIT_BALANCED=1` uses the `balanced` preset's binning,
//! `NDFIT_BINNING=target,maxcells` another one.

use ndfit::fit::delta_to_model;
use ndfit::fit::{fit_model, FitOptions};
use ndfit::models::{Model, ModelId};
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
    let cases = [
        [0.02, 0.02, 0.0, 0.0, 0.0],
        [0.005, 0.005, 0.0, 0.0, 0.0],
        [0.3, 0.1, 0.3, -0.2, 0.8],
        [1.5, 0.15, -0.5, 0.5, -1.0],
        [0.1, 0.05, 0.55, -0.55, 0.3],
        [0.9, 0.5, 0.0, 0.0, 0.2],
    ];
    let thetas: Vec<f64> = std::env::var("NDFIT_THETAS")
        .ok()
        .map(|s| s.split(',').map(|t| t.parse().expect("theta")).collect())
        .unwrap_or(vec![60.0, 70.0, 75.0, 80.0, 85.0, 90.0]);
    for p in cases {
        let ep =
            EllipsoidParams { alpha_x: p[0], alpha_y: p[1], theta_x: p[2], theta_y: p[3], theta_z: p[4], ..EllipsoidParams::default() };
        let (hf, truth) = ellipsoid_surface(&settings(1024, 7), &ep).expect("synth");
        let truth = truth.to_model().expect("truth model");
        // NDFIT_BALANCED=1: the binning `ndfit fit` uses by default (Preset::Balanced).
        // NDFIT_BINNING=target,maxcells: another binning.
        let nopts = if std::env::var("NDFIT_BALANCED").is_ok() {
            ndfit::Preset::Balanced.ndf_options(hf.valid_count() as u64)
        } else if let Ok(b) = std::env::var("NDFIT_BINNING") {
            let v: Vec<f64> = b.split(',').map(|t| t.parse().expect("binning")).collect();
            let o = NdfOptions { target_count: v[0], ..NdfOptions::default() };
            NdfOptions { cells_across: Some(o.cells_for(hf.valid_count() as u64).min(v[1] as usize)), ..o }
        } else {
            NdfOptions::default()
        };
        let ndf = empirical_ndf(&hf, &nopts).expect("ndf");
        let mut line = format!("{p:?} bins {}:", ndf.bins.len());
        for &t in &thetas {
            match fit_model(&ndf, ModelId::Ellipsoid, &FitOptions { max_theta: t.to_radians(), ..FitOptions::default() }) {
                Ok(rep) => {
                    let d = delta_to_truth(&rep.to_model().expect("model"), &truth);
                    line += &format!(" {t}:{:.3}%", d * 100.0);
                }
                Err(e) => line += &format!(" {t}:FAILED({e})"),
            }
        }
        eprintln!("{line}");
    }
}
