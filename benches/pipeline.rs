//! Criterion benchmarks of the whole pipeline's hot paths on the synthetic ellipsoid scan of
//! `ndfit bench` (`cargo bench --bench pipeline`): NPY read, empirical NDF (throughput in normals),
//! ellipsoid fit, and scan -> fit end to end.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};

use ndfit::bench::scene::Scene;
use ndfit::bench::{pipeline, Knobs};
use ndfit::fit::{fit_model, FitOptions};
use ndfit::io::read_scan;
use ndfit::models::ModelId;
use ndfit::ndf::{empirical_ndf, NdfOptions};

fn pipeline_benches(c: &mut Criterion) {
    let dir = tempfile::tempdir().expect("a temporary folder for the scans");
    let mut g = c.benchmark_group("pipeline");
    g.sample_size(10);
    for size in [1024usize, 4096] {
        let scene = Scene::create(dir.path(), size).expect("synthetic scene");
        let ro = scene.read_options();
        g.throughput(Throughput::Bytes((size * size * 8) as u64));
        g.bench_with_input(BenchmarkId::new("read_npy", size), &size, |b, _| b.iter(|| read_scan(&scene.path, &ro).expect("read")));
        let hf = read_scan(&scene.path, &ro).expect("read");
        let ndf = empirical_ndf(&hf, &NdfOptions::default()).expect("ndf");
        g.throughput(Throughput::Elements(ndf.n_samples));
        g.bench_with_input(BenchmarkId::new("empirical_ndf", size), &size, |b, _| {
            b.iter(|| empirical_ndf(&hf, &NdfOptions::default()).expect("ndf"))
        });
        if size == 1024 {
            g.throughput(Throughput::Elements(ndf.bins.len() as u64));
            g.bench_function("fit_ellipsoid_1024", |b| {
                b.iter(|| fit_model(&ndf, ModelId::Ellipsoid, &FitOptions::default()).expect("fit"))
            });
            let k = Knobs { size, ..Knobs::default() };
            g.throughput(Throughput::Elements((size * size) as u64));
            g.bench_function("scan_to_fit_1024", |b| b.iter(|| pipeline::run(&scene.path, &ro, &k).expect("pipeline")));
        }
    }
    g.finish();
}

criterion_group!(benches, pipeline_benches);
criterion_main!(benches);
