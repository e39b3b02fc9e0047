//! Reading close to the hardware's limit (issue #8): a 4096 x 4096 float64 NPY (the `ndfit bench`
//! ellipsoid scene, about half NaN) and a 4096 x 4096 float64 X3P (data.bin stored, not deflated) are
//! read by `ndfit::io::read_scan` and, in the same run, by a plain `std::fs::read` of the same file;
//! the medians and their ratio are printed at the end. `NDFIT_BENCH_N` changes the grid size.
//!
//! Run: `cargo bench --bench read`.

use std::hint::black_box;
use std::path::Path;
use std::time::Instant;

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use ndfit::bench::scene::Scene;
use ndfit::io::{read_scan, write_x3p, ReadOptions};
use ndfit::Heightfield;

fn grid_size() -> usize {
    std::env::var("NDFIT_BENCH_N").ok().and_then(|s| s.parse().ok()).unwrap_or(4096)
}

fn secs(f: impl FnOnce()) -> f64 {
    let s = Instant::now();
    f();
    s.elapsed().as_secs_f64()
}

/// Criterion group for one file, then 11 interleaved timings of `std::fs::read` and `read_scan`
/// (so load from other processes hits both alike; page cache warm) and their medians.
fn compare(c: &mut Criterion, label: &str, path: &Path, opts: &ReadOptions) {
    let bytes = std::fs::metadata(path).expect("metadata").len();
    let mut g = c.benchmark_group(label);
    g.throughput(Throughput::Bytes(bytes));
    g.sample_size(10);
    g.bench_function("std_fs_read", |b| b.iter(|| black_box(std::fs::read(path).expect("read").len())));
    g.bench_function("ndfit_read_scan", |b| b.iter(|| black_box(read_scan(path, opts).expect("read").nx)));
    g.finish();

    let (mut plain_t, mut ours_t) = (Vec::new(), Vec::new());
    for _ in 0..11 {
        plain_t.push(secs(|| drop(black_box(std::fs::read(path).expect("read")))));
        ours_t.push(secs(|| drop(black_box(read_scan(path, opts).expect("read")))));
    }
    plain_t.sort_by(f64::total_cmp);
    ours_t.sort_by(f64::total_cmp);
    let (plain, ours) = (plain_t[5], ours_t[5]);
    eprintln!(
        "{label} ({:.1} MB): std::fs::read {:.1} ms ({:.2} GB/s), read_scan {:.1} ms ({:.2} GB/s), ratio {:.2}",
        bytes as f64 / 1e6,
        plain * 1e3,
        bytes as f64 / plain / 1e9,
        ours * 1e3,
        bytes as f64 / ours / 1e9,
        ours / plain
    );
}

fn read_bench(c: &mut Criterion) {
    let n = grid_size();
    let dir = tempfile::tempdir().expect("tempdir");

    let scene = Scene::create(dir.path(), n).expect("npy scene");
    compare(c, &format!("read_npy_{n}x{n}_f64_ellipsoid"), &scene.path, &scene.read_options());

    let path = dir.path().join("big.x3p");
    let z: Vec<f64> = (0..n * n).map(|k| (k as f64 * 1e-3).sin() * 1e-6).collect();
    let hf = Heightfield::new(n, n, 1e-7, 1e-7, z).expect("grid");
    write_x3p(&path, &hf).expect("write");
    drop(hf);
    compare(c, &format!("read_x3p_{n}x{n}_f64_stored"), &path, &ReadOptions::default());
}

criterion_group!(benches, read_bench);
criterion_main!(benches);
