//! Cost of `ndfit scale` (data_formats/scale.md) on a synthetic 256 x 256 Gaussian scan, against a
//! baseline in the same run: the plain empirical NDF of the scan plus one ellipsoid fit (what `ndfit fit`
//! does). So the cost reads as a ratio: one footprint with one model (both routes: filtering, blur
//! samples, two NDFs, two fits, the kernel's GGX fit) against the baseline, and the whole default
//! command (five models) at three footprints. Run: `cargo bench --bench scale`.

use criterion::{criterion_group, criterion_main, Criterion};
use ndfit::fit::{fit_model, FitOptions};
use ndfit::models::ModelId;
use ndfit::ndf::{empirical_ndf, NdfOptions};
use ndfit::scale::{analyze, Fitter, ScaleOptions};
use ndfit::synth::{gaussian_surface, GaussianParams, SynthSettings};

fn bench_scale(c: &mut Criterion) {
    let n = 256;
    let dx = 1e-6;
    let s = SynthSettings { nx: n, ny: n, dx, dy: dx, seed: 1, ..Default::default() };
    let p = GaussianParams { sigma_x: 0.2, sigma_y: 0.1, theta_z: 0.3, corr_length: 6e-6 };
    let (hf, _) = gaussian_surface(&s, &p).expect("valid settings");
    let fitter = ndfit::scale::default_fitter();
    let mut g = c.benchmark_group("scale_256");
    g.sample_size(10);
    g.bench_function("baseline_ndf_plus_ellipsoid_fit", |b| {
        b.iter(|| {
            let ndf = empirical_ndf(&hf, &NdfOptions::default()).expect("valid scan");
            fit_model(&ndf, ModelId::Ellipsoid, &FitOptions::default()).expect("fit")
        })
    });
    let one = ScaleOptions { footprints: vec![8.0 * dx], models: vec![ModelId::Ellipsoid], ..Default::default() };
    g.bench_function("scale_1_footprint_ellipsoid", |b| b.iter(|| analyze(&hf, &one, Some(&fitter as &dyn Fitter)).expect("scale")));
    let all = ScaleOptions { footprints: vec![2.0 * dx, 8.0 * dx, 32.0 * dx], ..Default::default() };
    g.bench_function("scale_3_footprints_all_models", |b| b.iter(|| analyze(&hf, &all, Some(&fitter as &dyn Fitter)).expect("scale")));
    g.finish();
}

criterion_group!(benches, bench_scale);
criterion_main!(benches);
