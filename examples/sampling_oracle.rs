//! Measurement tool (not a test): where the hard-end error comes from (data_formats/objective.md, "The tail
//! the scan cannot resolve"). Per cap of the hard-end set at 1024^2, the ellipsoid fit's NDF error against
//! the truth with the NDF counted from central differences, from the exact slopes (Walter et al. eq. 15, 22)
//! at the same samples, and from the exact slopes at every footprint sample; then, with the bins beyond
//! whitened Lambert radius `p_max` left out of the region, for central and exact-slope counts.
//!
//!     cargo run --release --example sampling_oracle

use ndfit::fit::delta_to_model;
use ndfit::fit::TailRule;
use ndfit::fit::{fit_model, FitOptions};
use ndfit::models::ModelId;
use ndfit::ndf::{empirical_ndf, EmpiricalNdf, NdfOptions};
use ndfit::synth::EllipsoidGeometry;
use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings, HARD_END_SET};

#[path = "support/floor.rs"]
mod floor;

/// The NDF `ndf` with its counts replaced by those of `slopes` (same bins, frame and `W`).
fn recount(ndf: &EmpiricalNdf, slopes: &[[f64; 2]]) -> EmpiricalNdf {
    let mut cnt = vec![0u64; ndf.grid.cells()];
    for s in slopes {
        cnt[ndf.grid.cell_of(ndf.frame.to_lambert(s[0], s[1]))] += 1;
    }
    let mut out = ndf.clone();
    let n = slopes.len() as f64;
    for (b, &c) in out.bins.iter_mut().zip(&ndf.bin_cells) {
        b.count = cnt[c as usize];
        b.d = b.count as f64 / (n * b.proj_solid_angle);
        b.stderr = (b.count as f64).sqrt() / (n * b.proj_solid_angle);
    }
    out.n_samples = slopes.len() as u64;
    out.counts_odd = out.bins.iter().map(|b| b.count / 2).collect();
    out
}

fn main() {
    let n = 1024;
    for p in HARD_END_SET {
        let ep =
            EllipsoidParams { alpha_x: p[0], alpha_y: p[1], theta_x: p[2], theta_y: p[3], theta_z: p[4], ..EllipsoidParams::default() };
        let s = SynthSettings { nx: n, ny: n, seed: 7, ..SynthSettings::default() };
        let (hf, truth) = ellipsoid_surface(&s, &ep).unwrap();
        let g = EllipsoidGeometry::new(&ep, &s).unwrap();
        let truth = truth.to_model().unwrap();
        let ndf = empirical_ndf(&hf, &NdfOptions::default()).unwrap();
        let fit = |nd: &EmpiricalNdf| {
            let r = fit_model(nd, ModelId::Ellipsoid, &FitOptions { tail: TailRule::All, ..FitOptions::default() }).unwrap();
            100.0 * delta_to_model(&r.to_model().unwrap(), &truth).unwrap()
        };
        let z = |i: usize, j: usize| hf.z[i * n + j];
        let (mut same, mut all) = (Vec::new(), Vec::new());
        for i in 0..n {
            for j in 0..n {
                let Some(sl) = g.slope(s.xc(j), s.yc(i)) else { continue };
                all.push(sl);
                if i >= 1 && j >= 1 && i + 1 < n && j + 1 < n && !(z(i, j - 1) + z(i, j + 1) + z(i - 1, j) + z(i + 1, j)).is_nan() {
                    same.push(sl);
                }
            }
        }
        let cut = |nd: &EmpiricalNdf, pmax: f64| {
            let o = floor::cut_beyond_radius(nd, pmax);
            let r = fit_model(&o, ModelId::Ellipsoid, &FitOptions { tail: TailRule::Unresolved, ..FitOptions::default() }).unwrap();
            100.0 * delta_to_model(&r.to_model().unwrap(), &truth).unwrap()
        };
        let ex = recount(&ndf, &all);
        println!(
            "{p:?}: central {:.3}%  exact-same-samples {:.3}%  exact-all-footprint {:.3}%  (n {} vs {})",
            fit(&ndf),
            fit(&recount(&ndf, &same)),
            fit(&recount(&ndf, &all)),
            same.len(),
            all.len()
        );
        for pm in [0.9, 1.0, 1.1, 1.2, 1.3] {
            println!("   p_max {pm}: central {:.3}% exact {:.3}%", cut(&ndf, pm), cut(&ex, pm));
        }
    }
}
