//! Measurement tool (not a test): the hard-end synthetic set of docs/ACCURACY.md. Ellipsoid caps with
//! anisotropy up to 10:1, alpha down to 0.02 and skew up to 0.4 rad; per truth the NDF error of the
//! ellipsoid fit against the truth with the default tail rule (`core`), with every bin and with the
//! `unresolved` rule, the error of the despiked fit of the same
//! scan with 0.05% spikes of +-50 Sq against the clean scan's fit, and with an aperture of 45 degrees
//! (points steeper than 45 degrees dropped) the error against the truth over max_theta 45 and 40
//! degrees (default tail rule). Then what no fit region removes (objective.md, "What the core leaves"):
//! the default fit of the truth's bin integrals (no sampling: the midpoint rule's error on these bins),
//! and the spread of the default fit over 16 phases of the sample lattice (exact slopes).
//!
//!     cargo run --release --example hard_end            # 1024^2
//!     N=2048 cargo run --release --example hard_end

use ndfit::fit::delta_to_model;
use ndfit::fit::TailRule;
use ndfit::fit::{fit_model, FitOptions};
use ndfit::models::{Model, ModelId};
use ndfit::ndf::{empirical_ndf, NdfOptions};
use ndfit::preprocess::{despike, Despike};
use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings, HARD_END_SET};
use ndfit::Heightfield;

#[path = "support/floor.rs"]
mod floor;

/// The ellipsoid fit, or the error's message.
fn fit(hf: &Heightfield, opts: &FitOptions) -> Result<Model, String> {
    let ndf = empirical_ndf(hf, &NdfOptions::default()).map_err(|e| e.to_string())?;
    fit_model(&ndf, ModelId::Ellipsoid, opts).and_then(|r| r.to_model()).map_err(|e| e.to_string())
}

fn main() {
    let n: usize = std::env::var("N").ok().map(|s| s.parse().expect("N")).unwrap_or(1024);
    println!("| truth (ax, ay, tx, ty, tz), {n}^2 | default (--tail core) | --tail all | --tail unresolved | spikes, despiked (not) vs clean fit | NA 45: max_theta 45 / 40 | bin integrals (default) | 16 lattice phases: median (min-max) |");
    println!("| --- | --- | --- | --- | --- | --- | --- | --- |");
    for p in HARD_END_SET {
        let ep =
            EllipsoidParams { alpha_x: p[0], alpha_y: p[1], theta_x: p[2], theta_y: p[3], theta_z: p[4], ..EllipsoidParams::default() };
        let s = SynthSettings { nx: n, ny: n, seed: 7, ..SynthSettings::default() };
        let (hf, truth) = ellipsoid_surface(&s, &ep).expect("synth");
        let truth = truth.to_model().expect("truth");
        let ndf = empirical_ndf(&hf, &NdfOptions::default()).expect("ndf");
        let integrals = floor::fit_error(&floor::bin_integral_counts(&ndf, &truth), &truth, TailRule::Core);
        let g = ndfit::synth::EllipsoidGeometry::new(&ep, &s).expect("geometry");
        let (lo, med, hi) = floor::phase_spread(&ndf, &g, &s, &truth);
        let d = |m: &Result<Model, String>, r: &Result<Model, String>| match (m, r) {
            (Ok(m), Ok(r)) => format!("{:.3}%", 100.0 * delta_to_model(m, r).expect("delta")),
            (Err(e), _) | (_, Err(e)) => format!("failed ({e})"),
        };
        let truth = Ok(truth);
        let clean = fit(&hf, &FitOptions::default());
        let all = fit(&hf, &FitOptions { tail: TailRule::All, ..FitOptions::default() });
        let cut = fit(&hf, &FitOptions { tail: TailRule::Unresolved, ..FitOptions::default() });
        // Spikes: 0.05% of the valid points, +-50 Sq, at sites of a congruential walk.
        let valid: Vec<usize> = (0..hf.z.len()).filter(|&k| hf.z[k].is_finite()).collect();
        let mean = valid.iter().map(|&k| hf.z[k]).sum::<f64>() / valid.len() as f64;
        let sq = (valid.iter().map(|&k| (hf.z[k] - mean).powi(2)).sum::<f64>() / valid.len() as f64).sqrt();
        let mut spiky = hf.clone();
        let mut x: u64 = 0x9e37_79b9_7f4a_7c15;
        for i in 0..(valid.len() as f64 * 5e-4).round() as usize {
            x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            spiky.z[valid[(x >> 33) as usize % valid.len()]] += if i % 2 == 0 { 50.0 * sq } else { -50.0 * sq };
        }
        let raw = fit(&spiky, &FitOptions::default());
        despike(&mut spiky, Despike::Median);
        let despiked = fit(&spiky, &FitOptions::default());
        // Aperture 45 degrees: every point whose central-difference slope exceeds 1 is a dropout.
        let mut na = hf.clone();
        for i in 1..n - 1 {
            for j in 1..n - 1 {
                let sx = (hf.z[i * n + j + 1] - hf.z[i * n + j - 1]) / (2.0 * hf.dx);
                let sy = (hf.z[(i + 1) * n + j] - hf.z[(i - 1) * n + j]) / (2.0 * hf.dy);
                if sx.hypot(sy) > 1.0 {
                    na.z[i * n + j] = f64::NAN;
                }
            }
        }
        let o45 = FitOptions { max_theta: 45f64.to_radians(), ..FitOptions::default() };
        let na45 = fit(&na, &o45);
        let na40 = fit(&na, &FitOptions { max_theta: 40f64.to_radians(), ..FitOptions::default() });
        println!(
            "| {p:?} | {} | {} | {} | {} ({}) | {} / {} | {:.3}% | {:.3}% ({:.3}-{:.3}%) |",
            d(&clean, &truth),
            d(&all, &truth),
            d(&cut, &truth),
            d(&despiked, &clean),
            d(&raw, &clean),
            d(&na45, &truth),
            d(&na40, &truth),
            100.0 * integrals,
            100.0 * med,
            100.0 * lo,
            100.0 * hi
        );
    }
}
