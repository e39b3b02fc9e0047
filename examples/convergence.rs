//! Measurement tool (not a test): the convergence study of docs/ACCURACY.md. NDF error of the ellipsoid fit
//! against the truth of synthetic ellipsoid caps (no form removal, default binning) as the scan resolution
//! grows, for central differences with the default tail rule (`core`) and with every bin (`--tail all`), and
//! for triangles; and the default and every-bin fits of the truth's bin integrals on the same bins (no
//! sampling: the midpoint rule's own error, objective.md "What the core leaves").
//!
//!     cargo run --release --example convergence
//!
//! `SIZES=128,256,512` sets the grid sizes. "Across" is the footprint's narrowest full width in samples
//! (valid points along the grid row and column through the centre, the smaller).

use ndfit::fit::delta_to_model;
use ndfit::fit::TailRule;
use ndfit::fit::{fit_model, FitOptions};
use ndfit::models::ModelId;
use ndfit::ndf::{empirical_ndf, NdfOptions, NormalScheme};
use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};

#[path = "support/floor.rs"]
mod floor;

fn main() {
    let cases = [[0.3, 0.3, 0.0, 0.0, 0.0], [0.05, 0.05, 0.4, 0.0, 0.0], [0.35, 0.05, 0.16, 0.0, 0.3], [0.5, 0.05, -0.4, 0.1, 1.0]];
    let sizes: Vec<usize> = std::env::var("SIZES")
        .ok()
        .map(|s| s.split(',').map(|t| t.parse().expect("size")).collect())
        .unwrap_or(vec![128, 256, 512, 1024, 2048]);
    println!("| truth (ax, ay, tx, ty, tz) | grid | across | central, default (cut) | central, --tail all | triangles | bin integrals: default / all |");
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    for p in cases {
        for &n in &sizes {
            let ep =
                EllipsoidParams { alpha_x: p[0], alpha_y: p[1], theta_x: p[2], theta_y: p[3], theta_z: p[4], ..EllipsoidParams::default() };
            let (hf, truth) = ellipsoid_surface(&SynthSettings { nx: n, ny: n, seed: 7, ..SynthSettings::default() }, &ep).expect("synth");
            let truth = truth.to_model().expect("truth");
            let row = (0..n).filter(|&j| hf.z[(n / 2) * n + j].is_finite()).count();
            let col = (0..n).filter(|&i| hf.z[i * n + n / 2].is_finite()).count();
            let err = |scheme: NormalScheme, tail: TailRule| -> (f64, f64) {
                let ndf = empirical_ndf(&hf, &NdfOptions { scheme, ..NdfOptions::default() }).expect("ndf");
                let rep = fit_model(&ndf, ModelId::Ellipsoid, &FitOptions { tail, ..FitOptions::default() }).expect("fit");
                let cutf = rep.quality.tail.as_ref().map_or(0.0, |t| t.excluded_fraction);
                (delta_to_model(&rep.to_model().expect("model"), &truth).expect("delta"), cutf)
            };
            let (ct, f) = err(NormalScheme::Central, TailRule::Core);
            let (c, _) = err(NormalScheme::Central, TailRule::All);
            let (t, _) = err(NormalScheme::Triangles, TailRule::All);
            let ndf = empirical_ndf(&hf, &NdfOptions::default()).expect("ndf");
            let integ = floor::bin_integral_counts(&ndf, &truth);
            let (fc, fa) = (floor::fit_error(&integ, &truth, TailRule::Core), floor::fit_error(&integ, &truth, TailRule::All));
            println!(
                "| {p:?} | {n}^2 | {} | {:.3}% ({:.1}%) | {:.3}% | {:.3}% | {:.3}% / {:.3}% |",
                row.min(col),
                100.0 * ct,
                100.0 * f,
                100.0 * c,
                100.0 * t,
                100.0 * fc,
                100.0 * fa
            );
        }
    }
}
