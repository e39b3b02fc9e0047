//! Measurement tool (not a test): the tail rules on synthetic scans of known NDF (data_formats/objective.md,
//! "The tail the scan cannot resolve", the table of the `rim` rule): per scan, the `rim` rule's test (the
//! share of unresolved normals alone in majority-unresolved bins) and the NDF error against the truth
//! with each rule (in parentheses the share of the normals it left out).
//! `cargo run --release --example tail_rules`; `SET=two,256,gauss,hard` picks the scans (default all).
//! - `two`: two anisotropic GGX caps side by side, NaN between (alphas 0.12/0.05 on a 1024^2 block, and
//!   0.55/0.30 on a block `W2` as wide), fitted with `ggx2` against their mixture;
//! - `256`: the caps of the batch regression set; `hard`: the hard-end set at 1024^2 and three rougher
//!   caps, fitted with `ellipsoid`; `gauss`: Gaussian random surfaces (anisotropic Beckmann truth),
//!   fitted with `beckmann-aniso`.

use ndfit::fit::delta_to_model;
use ndfit::fit::TailRule;
use ndfit::fit::{fit_model, FitOptions};
use ndfit::models::{Model, ModelId};
use ndfit::ndf::{empirical_ndf, NdfOptions};
use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings, HARD_END_SET};
use ndfit::Heightfield;

fn cap(nx: usize, ny: usize, p: [f64; 5]) -> (Heightfield, Model) {
    let ep = EllipsoidParams { alpha_x: p[0], alpha_y: p[1], theta_x: p[2], theta_y: p[3], theta_z: p[4], ..EllipsoidParams::default() };
    let (hf, t) = ellipsoid_surface(&SynthSettings { nx, ny, seed: 7, ..SynthSettings::default() }, &ep).unwrap();
    (hf, t.to_model().unwrap())
}

/// The two caps, the wide one on a block `w2` times as wide as the narrow one's; the mixture truth.
fn two_caps(w2: f64) -> (Heightfield, Model, f64) {
    let ny = 1024;
    let (a, _) = cap(ny, ny, [0.12, 0.05, 0.0, 0.0, 0.0]);
    let n2 = (ny as f64 * w2) as usize;
    let (b, _) = cap(n2, ny, [0.55, 0.30, 0.0, 0.0, 0.0]);
    let gap = 4;
    let nx = ny + gap + n2;
    let mut z = vec![f64::NAN; nx * ny];
    for i in 0..ny {
        z[i * nx..i * nx + ny].copy_from_slice(&a.z[i * ny..(i + 1) * ny]);
        z[i * nx + ny + gap..(i + 1) * nx].copy_from_slice(&b.z[i * n2..(i + 1) * n2]);
    }
    let count = |h: &Heightfield| h.z.iter().filter(|v| v.is_finite()).count() as f64;
    let w = count(&a) / (count(&a) + count(&b));
    let hf = Heightfield::new(nx, ny, a.dx, a.dy, z).unwrap();
    (hf, Model::from_params(ModelId::Ggx2, &[0.12, 0.05, 0.55, 0.30, 0.0, w]).unwrap(), w)
}

fn row(name: &str, hf: &Heightfield, truth: &Model, id: ModelId) {
    let ndf = empirical_ndf(hf, &NdfOptions::default()).unwrap();
    let mut line = format!("| {name} |");
    for (i, rule) in [TailRule::Rim, TailRule::Core, TailRule::Unresolved, TailRule::All].into_iter().enumerate() {
        let rep = fit_model(&ndf, id, &FitOptions { tail: rule, ..FitOptions::default() }).unwrap();
        let t = rep.quality.tail.clone().unwrap_or_else(ndfit::fit::TailCut::none);
        if i == 0 {
            line += &format!(" {:.2} | {} |", t.unresolved_alone_fraction, t.rule);
        }
        let d = delta_to_model(&rep.to_model().unwrap(), truth).unwrap();
        line += &format!(" {:.3}% ({:.3}) |", 100.0 * d, t.excluded_fraction);
    }
    println!("{line}");
}

fn main() {
    let set = std::env::var("SET").unwrap_or("two,256,gauss,hard".into());
    println!("| truth | alone | rim cuts | rim (default) | core | unresolved | all |");
    println!("| --- | --- | --- | --- | --- | --- | --- |");
    if set.contains("two") {
        for w2 in [0.27, 0.4, 0.51] {
            let (hf, truth, w) = two_caps(w2);
            row(&format!("two caps, narrow weight {w:.3}, ggx2"), &hf, &truth, ModelId::Ggx2);
        }
    }
    let caps256 = [
        [0.05, 0.05, 0.0, 0.0, 0.0],
        [0.3, 0.3, 0.0, 0.0, 0.0],
        [1.2, 1.2, 0.0, 0.0, 0.0],
        [0.4, 0.1, 0.0, 0.0, 0.6],
        [0.25, 0.25, 0.45, 0.0, 0.0],
        [0.35, 0.2, 0.0, -0.35, 1.0],
    ];
    if set.contains("256") {
        for p in caps256 {
            let (hf, t) = cap(256, 256, p);
            row(&format!("cap {p:?}, 256^2"), &hf, &t, ModelId::Ellipsoid);
        }
    }
    if set.contains("gauss") {
        for (corr, sx, sy) in [(8e-6, 0.2, 0.2), (32e-6, 0.2, 0.1), (64e-6, 0.3, 0.15)] {
            let gp = ndfit::synth::GaussianParams { sigma_x: sx, sigma_y: sy, theta_z: 0.3, corr_length: corr };
            let s = SynthSettings { nx: 1024, ny: 1024, seed: 7, ..SynthSettings::default() };
            let (hf, t) = ndfit::synth::gaussian_surface(&s, &gp).unwrap();
            row(
                &format!("Gaussian, sigma {sx}/{sy}, corr {} dx, 1024^2", corr / 1e-6),
                &hf,
                &t.to_model().unwrap(),
                ModelId::BeckmannAniso,
            );
        }
    }
    if set.contains("hard") {
        let extra = [[0.3, 0.1, 0.3, -0.2, 0.8], [1.5, 0.15, -0.5, 0.5, -1.0], [0.9, 0.5, 0.0, 0.0, 0.2]];
        for p in HARD_END_SET.iter().chain(&extra) {
            let (hf, t) = cap(1024, 1024, *p);
            row(&format!("cap {p:?}, 1024^2"), &hf, &t, ModelId::Ellipsoid);
        }
    }
}
