//! Measurement tool (not a test): the per-normal "unresolved" test (`ndf::resolution`) against exact
//! slopes, its false-positive and false-negative rates per normal and per bin (the table of
//! docs/ACCURACY.md, "Which normals the sampling resolves"). `cargo run --release --example
//! resolution_oracle`. Truths: ellipsoid caps (the exact gradient of Walter et al. eq. 15, 22) and
//! random-phase sums of plane waves (a Gaussian-like random surface with a closed-form gradient).

use ndfit::ndf::{confusion, Confusion};
use ndfit::ndf::{empirical_ndf, NdfOptions};
use ndfit::synth::{ellipsoid_surface, SynthSettings};
use ndfit::synth::{EllipsoidGeometry, EllipsoidParams, HARD_END_SET};
use ndfit::Heightfield;

#[path = "support/waves.rs"]
mod waves;

fn row(name: &str, hf: &Heightfield, exact: impl Fn(usize, usize) -> Option<[f64; 2]> + Sync + Send) {
    let ndf = empirical_ndf(hf, &NdfOptions::default()).unwrap();
    let c: Confusion = confusion(hf, &ndf, exact);
    println!(
        "| {name} | {:.4} | {:.4} | {:.5} | {:.4} | {} / {} | {:.4} | {:.4} |",
        ndf.unresolved_share.unwrap_or(f64::NAN),
        c.truly as f64 / c.normals as f64,
        c.fp_rate(),
        c.fn_rate(),
        c.bins_truly,
        c.bins,
        c.bin_fp_rate(),
        c.bin_fn_rate()
    );
}

fn main() {
    println!("| truth | flagged | truly unresolved | FP rate | FN rate | bins truly / all | bin FP | bin FN |");
    println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
    let caps256 = [[0.05, 0.05, 0.0, 0.0, 0.0], [0.4, 0.1, 0.0, 0.0, 0.6], [0.35, 0.2, 0.0, -0.35, 1.0]];
    let sets: Vec<(usize, [f64; 5])> = caps256.iter().map(|p| (256, *p)).chain(HARD_END_SET.iter().map(|p| (1024, *p))).collect();
    for (n, p) in sets {
        let s = SynthSettings { nx: n, ny: n, seed: 7, ..SynthSettings::default() };
        let ep =
            EllipsoidParams { alpha_x: p[0], alpha_y: p[1], theta_x: p[2], theta_y: p[3], theta_z: p[4], ..EllipsoidParams::default() };
        let (hf, _) = ellipsoid_surface(&s, &ep).unwrap();
        let g = EllipsoidGeometry::new(&ep, &s).unwrap();
        row(&format!("cap {p:?}, {n}^2"), &hf, |i, j| g.slope(s.xc(j), s.yc(i)));
    }
    for (lambda, n) in [(100.0, 1024), (40.0, 1024), (16.0, 1024), (8.0, 1024)] {
        let w = waves::Waves::new(lambda, 0.3, 11);
        let hf = w.surface(n, n);
        row(&format!("waves, wavelength {lambda} dx, {n}^2"), &hf, |i, j| Some(w.gradient(j as f64, i as f64)));
    }
}
