//! Throughput and fixed cost of the empirical NDF. Run: `cargo bench --bench ndf`. Throughput is in
//! points of the scan's grid (not valid normals) per second.
//!
//! - `empirical_ndf_4096`: a fully valid 4096 x 4096 Gaussian surface (16.8 M points), both normal
//!   schemes, automatic grid (255 cells across) and a small one (31), f64 and f32 storage;
//! - `empirical_ndf_4096_ellipsoid`: the 4096^2 ellipsoid scan of the issue-8 sweep (72% valid);
//! - `empirical_ndf_1024_balanced`: the 1024^2 ellipsoid with the `balanced` preset's NDF (256 normals
//!   per bin, at most 63 cells), the fixed cost that matters for the scan -> fit target.
//!
//! On a shared machine wall-clock throughput says more about the load than about the code, so each
//! group also prints `cpu:` lines: points per CPU-second of the process over 10 runs (utime + stime
//! from `/proc/self/stat`, 10 ms ticks), and the wall time of the same runs with the load average.

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use ndfit::ndf::{empirical_ndf, empirical_ndf_f32, HeightsF32, NdfOptions, NormalScheme};
use ndfit::synth::{ellipsoid_surface, gaussian_surface, EllipsoidParams, GaussianParams, SynthSettings};
use std::time::Instant;

fn ellipsoid(n: usize) -> ndfit::Heightfield {
    let s = SynthSettings { nx: n, ny: n, dx: 1e-6, dy: 1e-6, seed: 1, ..Default::default() };
    let p = EllipsoidParams { alpha_x: 0.35, alpha_y: 0.18, theta_x: 0.15, theta_y: -0.1, theta_z: 0.6, ..Default::default() };
    ellipsoid_surface(&s, &p).expect("valid settings").0
}

/// CPU seconds (user + system) of this process so far, from `/proc/self/stat` (Linux; 0 elsewhere).
fn cpu_seconds() -> f64 {
    let Ok(stat) = std::fs::read_to_string("/proc/self/stat") else { return 0.0 };
    // Fields after the parenthesised command name: state is field 3, utime 14, stime 15.
    let Some(rest) = stat.rsplit_once(')').map(|(_, r)| r) else { return 0.0 };
    let f: Vec<&str> = rest.split_whitespace().collect();
    let tick = 100.0; // USER_HZ on Linux
    let t = |k: usize| f.get(k).and_then(|v| v.parse::<f64>().ok()).unwrap_or(0.0);
    (t(11) + t(12)) / tick
}

/// Print points per CPU-second and per wall-second of `runs` calls of `f`.
fn cpu_report(name: &str, points: usize, runs: usize, mut f: impl FnMut()) {
    f();
    let (c0, w0) = (cpu_seconds(), Instant::now());
    for _ in 0..runs {
        f();
    }
    let (cpu, wall) = (cpu_seconds() - c0, w0.elapsed().as_secs_f64());
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let load = load.split_whitespace().next().unwrap_or("?").to_string();
    println!(
        "cpu: {name}: {:.1} ms CPU per call, {:.0} M points per CPU-second; wall {:.1} ms per call, {:.0} M points/s (load {load})",
        1e3 * cpu / runs as f64,
        points as f64 * runs as f64 / cpu / 1e6,
        1e3 * wall / runs as f64,
        points as f64 * runs as f64 / wall / 1e6
    );
}

fn bench_ndf(c: &mut Criterion) {
    let n = 4096;
    let s = SynthSettings { nx: n, ny: n, dx: 1e-6, dy: 1e-6, seed: 1, ..Default::default() };
    let p = GaussianParams { sigma_x: 0.2, sigma_y: 0.1, theta_z: 0.3, corr_length: 6e-6 };
    let (hf, _) = gaussian_surface(&s, &p).expect("valid settings");
    let h32 = HeightsF32::from_heightfield(&hf);
    for scheme in [NormalScheme::Central, NormalScheme::Triangles] {
        let opts = NdfOptions { scheme, ..Default::default() };
        cpu_report(&format!("gaussian 4096 {} auto", scheme.as_str()), n * n, 10, || drop(empirical_ndf(&hf, &opts)));
    }
    cpu_report("gaussian 4096 central auto f32", n * n, 10, || drop(empirical_ndf_f32(&h32, &NdfOptions::default())));
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
    for scheme in [NormalScheme::Central, NormalScheme::Triangles] {
        let opts = NdfOptions { scheme, ..Default::default() };
        cpu_report(&format!("ellipsoid 4096 {} auto", scheme.as_str()), n * n, 10, || drop(empirical_ndf(&hf, &opts)));
    }
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
    cpu_report("ellipsoid 1024 balanced", n * n, 50, || drop(empirical_ndf(&hf, &opts)));
    g.bench_function("central", |b| b.iter(|| empirical_ndf(&hf, &opts).expect("valid scan")));
    let h32 = HeightsF32::from_heightfield(&hf);
    g.bench_function("central_f32", |b| b.iter(|| empirical_ndf_f32(&h32, &opts).expect("valid scan")));
    g.finish();
}

criterion_group!(benches, bench_ndf);
criterion_main!(benches);
