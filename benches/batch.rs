//! `ndfit batch` throughput with 1 and 2 jobs (it should scale with cores: each scan is independent),
//! and the batch's peak memory for a small and a 4x larger folder (it should stay bounded by the scans in
//! flight, not grow with the folder).
//!
//! Run: `cargo bench --bench batch`. The memory part prints `peak RSS` lines before the criterion output.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::Duration;

use criterion::{criterion_group, Criterion, Throughput};
use ndfit::batch::{self, discover, pipeline, JobContext, RunOptions, ScanSpec, Tolerances};
use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};

/// `n` ellipsoid scans of `side`^2 with varied parameters, written as X3P under `dir`.
fn make_set(dir: &Path, n: usize, side: usize) {
    std::fs::create_dir_all(dir).expect("bench folder");
    let s = SynthSettings { nx: side, ny: side, dx: 1e-6, dy: 1e-6, seed: 3, ..SynthSettings::default() };
    for i in 0..n {
        let t = i as f64 / n.max(1) as f64;
        let p = EllipsoidParams {
            alpha_x: 0.1 + 0.5 * t,
            alpha_y: 0.08 + 0.2 * (1.0 - t),
            theta_x: 0.3 * (t - 0.5),
            theta_y: 0.0,
            theta_z: 3.0 * t,
            ..EllipsoidParams::default()
        };
        let (hf, _) = ellipsoid_surface(&s, &p).expect("synthetic scan");
        ndfit::io::write_x3p(&dir.join(format!("s{i:03}.x3p")), &hf).expect("write scan");
    }
}

fn throughput(c: &mut Criterion) {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path().join("set");
    let n = 8;
    make_set(&dir, n, 256);
    let specs: Vec<ScanSpec> = discover::walk(&dir, &[], &|_: &Path| false).expect("walk");
    let opts = pipeline::PipelineOptions { model: "ellipsoid".into(), ..Default::default() };
    let job = |s: &ScanSpec, ctx: &JobContext<'_>| {
        pipeline::fit_scan(&s.file, &opts, ctx.baseline).map(|r| r.output).map_err(batch::JobFailure::from)
    };
    let mut g = c.benchmark_group("batch_8_scans_256sq_ellipsoid");
    g.throughput(Throughput::Elements(n as u64));
    g.sample_size(10);
    g.measurement_time(Duration::from_secs(12));
    for jobs in [1usize, 2] {
        g.bench_function(format!("jobs_{jobs}"), |b| {
            b.iter(|| {
                let out = tempfile::tempdir().expect("out dir");
                let o = RunOptions { out_dir: out.path().to_path_buf(), jobs, resume: false, settings: String::new(), tolerances: Tolerances::default() };
                let r = batch::run(&specs, None, &job, &o, &|_| {}).expect("batch run");
                assert_eq!(r.counts().ok, n);
            })
        });
    }
    g.finish();
}

/// Peak resident memory (kB) of `ndfit batch` over `dir`, sampled from /proc every 2 ms.
fn peak_rss_kb(dir: &Path, out: &Path) -> Option<u64> {
    let mut child = Command::new(env!("CARGO_BIN_EXE_ndfit"))
        .args(["batch", dir.to_str()?, "-o", out.to_str()?, "--jobs", "2", "--model", "ellipsoid"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .ok()?;
    let status = format!("/proc/{}/status", child.id());
    let mut peak = 0;
    while child.try_wait().ok()?.is_none() {
        if let Ok(s) = std::fs::read_to_string(&status) {
            for l in s.lines().filter(|l| l.starts_with("VmHWM:")) {
                peak = peak.max(l.split_whitespace().nth(1).and_then(|v| v.parse().ok()).unwrap_or(0));
            }
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    Some(peak)
}

fn memory() {
    let tmp = tempfile::tempdir().expect("temp dir");
    for n in [6usize, 24] {
        let dir = tmp.path().join(format!("set{n}"));
        make_set(&dir, n, 384);
        match peak_rss_kb(&dir, &tmp.path().join(format!("out{n}"))) {
            Some(kb) => println!("peak RSS of `ndfit batch --jobs 2` over {n} scans of 384^2: {:.1} MB", kb as f64 / 1024.0),
            None => println!("peak RSS: not measurable here (no /proc)"),
        }
    }
}

criterion_group!(benches, throughput);

fn main() {
    memory();
    benches();
    Criterion::default().configure_from_args().final_summary();
}
