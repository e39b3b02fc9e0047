//! Throughput and fixed cost of the empirical NDF. Run: `cargo bench --bench ndf`. Throughput is in
//! points of the scan's grid (not valid normals) per second.
//!
//! - `empirical_ndf_4096`: a fully valid 4096 x 4096 Gaussian surface (16.8 M points), both normal
//!   schemes, automatic grid (255 cells across) and a small one (31), f64 and f32 storage;
//! - `empirical_ndf_4096_ellipsoid`: the 4096^2 ellipsoid scan of the issue-8 sweep (72% valid);
//! - `empirical_ndf_1024_balanced`: the 1024^2 ellipsoid with the `balanced` preset's NDF (256 normals
//!   per bin, at most 63 cells), the fixed cost that matters for the scan -> fit target.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use ndfit::ndf::{empirical_ndf, empirical_ndf_f32, HeightsF32, NdfOptions, NormalScheme};
use ndfit::synth::{ellipsoid_surface, gaussian_surface, EllipsoidParams, GaussianParams, SynthSettings};

fn ellipsoid(n: usize) -> ndfit::Heightfield {
    let s = SynthSettings { nx: n, ny: n, dx: 1e-6, dy: 1e-6, seed: 1, ..Default::default() };
    let p = EllipsoidParams { alpha_x: 0.35, alpha_y: 0.18, theta_x: 0.15, theta_y: -0.1, theta_z: 0.6, ..Default::default() };
    ellipsoid_surface(&s, &p).expect("valid settings").0
}

fn bench_ndf(c: &mut Criterion) {
    let n = 4096;
    let s = SynthSettings { nx: n, ny: n, dx: 1e-6, dy: 1e-6, seed: 1, ..Default::default() };
    let p = GaussianParams { sigma_x: 0.2, sigma_y: 0.1, theta_z: 0.3, corr_length: 6e-6 };
    let (hf, _) = gaussian_surface(&s, &p).expect("valid settings");
    let h32 = HeightsF32::from_heightfield(&hf);
    let mut g = c.benchmark_group("empirical_ndf_4096");
    g.throughput(Throughput::Elements((n * n) as u64));
    g.sample_size(10);
    for scheme in [NormalScheme::Central, NormalScheme::Triangles] {
        for cells in [None, Some(31)] {
            let name = format!("{}_{}", scheme.as_str(), cells.map_or("auto".to_string(), |c| format!("{c}cells")));
            let opts = NdfOptions { scheme, cells_across: cells, ..Default::default() };
            g.bench_function(name, |b| b.iter(|| empirical_ndf(&hf, &opts).expect("valid scan")));
        }
    }
    let opts = NdfOptions::default();
    g.bench_function("central_auto_f32", |b| b.iter(|| empirical_ndf_f32(&h32, &opts).expect("valid scan")));
    g.finish();
    drop((hf, h32));

    let hf = ellipsoid(n);
    let mut g = c.benchmark_group("empirical_ndf_4096_ellipsoid");
    g.throughput(Throughput::Elements((n * n) as u64));
    g.sample_size(10);
    for scheme in [NormalScheme::Central, NormalScheme::Triangles] {
        let opts = NdfOptions { scheme, ..Default::default() };
        g.bench_function(scheme.as_str(), |b| b.iter(|| empirical_ndf(&hf, &opts).expect("valid scan")));
    }
    g.finish();
    drop(hf);

    let n = 1024;
    let hf = ellipsoid(n);
    let mut g = c.benchmark_group("empirical_ndf_1024_balanced");
    g.throughput(Throughput::Elements((n * n) as u64));
    g.sample_size(30);
    let auto = NdfOptions { target_count: 256.0, ..Default::default() };
    let opts = NdfOptions { cells_across: Some(auto.cells_for(hf.valid_count() as u64).min(63)), ..auto };
    g.bench_function("central", |b| b.iter(|| empirical_ndf(&hf, &opts).expect("valid scan")));
    let h32 = HeightsF32::from_heightfield(&hf);
    g.bench_function("central_f32", |b| b.iter(|| empirical_ndf_f32(&h32, &opts).expect("valid scan")));
    g.finish();
}

criterion_group!(benches, bench_ndf);
criterion_main!(benches);
