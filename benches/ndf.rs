//! Throughput of the empirical NDF on a 4096 x 4096 scan (16.8 M points), both normal schemes, with
//! the automatic grid (255 cells across) and a small one (31), to separate the per-point pass from the
//! per-bin quadrature. Run: `cargo bench --bench ndf`. Throughput is reported in points (grid samples)
//! per second.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use ndfit::ndf::{empirical_ndf, NdfOptions, NormalScheme};
use ndfit::synth::{gaussian_surface, GaussianParams, SynthSettings};

fn bench_ndf(c: &mut Criterion) {
    let n = 4096;
    let s = SynthSettings { nx: n, ny: n, dx: 1e-6, dy: 1e-6, seed: 1, ..Default::default() };
    let p = GaussianParams { sigma_x: 0.2, sigma_y: 0.1, theta_z: 0.3, corr_length: 6e-6 };
    let (hf, _) = gaussian_surface(&s, &p).expect("valid settings");
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
    g.finish();
}

criterion_group!(benches, bench_ndf);
criterion_main!(benches);
