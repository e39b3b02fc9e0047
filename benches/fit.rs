//! Speed of the fit (issue #5): scan -> fitted ellipsoid for a 1024^2 synthetic scan (target: well under
//! 100 ms), the fit alone, and the three solvers on the same NDF.

use criterion::{criterion_group, criterion_main, Criterion};
use ndfit::fit::{fit_auto, fit_model, FitOptions, Solver};
use ndfit::models::ModelId;
use ndfit::ndf::{empirical_ndf, NdfOptions};
use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};

fn bench(c: &mut Criterion) {
    let s = SynthSettings { nx: 1024, ny: 1024, seed: 5, ..SynthSettings::default() };
    let p = EllipsoidParams { alpha_x: 0.3, alpha_y: 0.1, theta_x: 0.2, theta_y: -0.2, theta_z: 0.6, ..EllipsoidParams::default() };
    let (hf, _) = ellipsoid_surface(&s, &p).expect("synth");
    let ndf = empirical_ndf(&hf, &NdfOptions::default()).expect("ndf");
    let mut g = c.benchmark_group("fit");
    g.sample_size(20);
    g.bench_function("scan1024_to_ellipsoid", |b| {
        b.iter(|| {
            let ndf = empirical_ndf(&hf, &NdfOptions::default()).expect("ndf");
            fit_model(&ndf, ModelId::Ellipsoid, &FitOptions::default()).expect("fit")
        })
    });
    g.bench_function("ndf1024_only", |b| b.iter(|| empirical_ndf(&hf, &NdfOptions::default()).expect("ndf")));
    for solver in [Solver::Lm, Solver::Lbfgs, Solver::NelderMead] {
        let opts = FitOptions { solver, ..FitOptions::default() };
        g.bench_function(format!("ellipsoid_fit_{}", solver.as_str()), |b| {
            b.iter(|| fit_model(&ndf, ModelId::Ellipsoid, &opts).expect("fit"))
        });
    }
    g.bench_function("auto_fit_lm", |b| b.iter(|| fit_auto(&ndf, &FitOptions::default()).expect("fit")));
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
