//! Measurement tool (not a test): NDF error against truth of synthetic ellipsoid caps with the unresolved-tail
//! cut off and on, per resolution tolerance (the table of data_formats/objective.md, "The tail the scan
//! cannot resolve"). `cargo run --release --example measure_tails`; `N=256 SET256=1` for the batch set,
//! `TOLS=0.005,0.01` the tolerances.

use ndfit::fit::metric::delta_to_model;
use ndfit::fit::tail::TailRule;
use ndfit::fit::{fit_model, FitOptions};
use ndfit::models::ModelId;
use ndfit::ndf::{empirical_ndf, NdfOptions};
use ndfit::synth::{ellipsoid::EllipsoidParams, ellipsoid::HARD_END_SET, ellipsoid_surface, SynthSettings};

fn main() {
    // The hard-end caps without the round one, then three rougher ones.
    let extra = [[0.3, 0.1, 0.3, -0.2, 0.8], [1.5, 0.15, -0.5, 0.5, -1.0], [0.9, 0.5, 0.0, 0.0, 0.2]];
    let cases: Vec<[f64; 5]> = HARD_END_SET[..6].iter().chain(&extra).copied().collect();
    let cases256 = [
        [0.05, 0.05, 0.0, 0.0, 0.0],
        [0.3, 0.3, 0.0, 0.0, 0.0],
        [1.2, 1.2, 0.0, 0.0, 0.0],
        [0.4, 0.1, 0.0, 0.0, 0.6],
        [0.25, 0.25, 0.45, 0.0, 0.0],
        [0.35, 0.2, 0.0, -0.35, 1.0],
    ];
    let cases: Vec<[f64; 5]> = if std::env::var("SET256").is_ok() { cases256.to_vec() } else { cases };
    let n: usize = std::env::var("N").ok().map(|s| s.parse().unwrap()).unwrap_or(1024);
    let tols: Vec<f64> =
        std::env::var("TOLS").ok().map(|s| s.split(',').map(|t| t.parse().unwrap()).collect()).unwrap_or(vec![0.002, 0.005, 0.01]);
    for p in cases {
        let ep =
            EllipsoidParams { alpha_x: p[0], alpha_y: p[1], theta_x: p[2], theta_y: p[3], theta_z: p[4], ..EllipsoidParams::default() };
        let (hf, truth) = ellipsoid_surface(&SynthSettings { nx: n, ny: n, seed: 7, ..SynthSettings::default() }, &ep).unwrap();
        let truth = truth.to_model().unwrap();
        let mut ndf = empirical_ndf(&hf, &NdfOptions::default()).unwrap();
        let rep = fit_model(&ndf, ModelId::Ellipsoid, &FitOptions { tail: TailRule::All, ..FitOptions::default() }).unwrap();
        let mut line =
            format!("{p:?} bins {}: off {:.3}%", ndf.bins.len(), 100.0 * delta_to_model(&rep.to_model().unwrap(), &truth).unwrap());
        for &t in &tols {
            ndf.resolution_tolerance = t;
            ndfit::ndf::resolution::assess(&hf, &mut ndf);
            let rep = fit_model(&ndf, ModelId::Ellipsoid, &FitOptions { tail: TailRule::Unresolved, ..FitOptions::default() }).unwrap();
            let d = delta_to_model(&rep.to_model().unwrap(), &truth).unwrap();
            line += &format!(" {t}:{:.3}% (cut {:.3})", d * 100.0, rep.quality.tail.as_ref().unwrap().excluded_fraction);
        }
        println!("{line}");
    }
}
