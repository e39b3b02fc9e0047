//! `ndfit batch` throughput with 1 and 2 jobs (it should scale with cores: each scan is independent),
//! and the batch's peak memory for a small and a 4x larger folder (it should stay bounded by the scans in
//! flight, not grow with the folder).
//!
//! Run: `cargo bench --bench batch`. The memory and scaling parts print lines before the criterion output.
//!
//! Why the scans are 512^2: at 256^2 a scan costs ~10 ms of CPU but its two atomic outputs cost two
//! `fsync`s of ~10 ms each on this machine's disk (measured with strace), so the batch measured the
//! disk's sync latency rather than the fitting; real scans are 1024^2 and larger. The scaling part also
//! reports the CPU time of the child batch (`cutime + cstime` of /proc/self/stat): equal CPU time with
//! 1 and 2 jobs means no work is duplicated and no stage is serialized by the jobs, so a wall-clock
//! speed-up below 2x is the machine's other load (a loaded 2-core machine grants each runnable thread a
//! share of about 2 / (load + 1) of a core), which the printed load average shows.

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

/// Side of the scans of the throughput and scaling parts (see the module doc).
const SIDE: usize = 512;

fn throughput(c: &mut Criterion) {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path().join("set");
    let n = 8;
    make_set(&dir, n, SIDE);
    let specs: Vec<ScanSpec> = discover::walk(&dir, &[], &|_: &Path| false).expect("walk");
    let opts = pipeline::PipelineOptions { model: ndfit::ModelChoice::Model(ndfit::models::ModelId::Ellipsoid), ..Default::default() };
    let job = |s: &ScanSpec, ctx: &JobContext<'_>| {
        pipeline::fit_scan(&s.file, &opts, ctx.baseline).map(|r| r.output).map_err(batch::JobFailure::from)
    };
    let mut g = c.benchmark_group(format!("batch_8_scans_{SIDE}sq_ellipsoid"));
    g.throughput(Throughput::Elements(n as u64));
    g.sample_size(10);
    g.measurement_time(Duration::from_secs(12));
    for jobs in [1usize, 2] {
        g.bench_function(format!("jobs_{jobs}"), |b| {
            b.iter(|| {
                let out = tempfile::tempdir().expect("out dir");
                let o = RunOptions {
                    out_dir: out.path().to_path_buf(),
                    jobs,
                    resume: false,
                    settings: String::new(),
                    tolerances: Tolerances::default(),
                    extras: Vec::new(),
                };
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

/// CPU time (s) of this process's waited-for children: `cutime + cstime` of /proc/self/stat, in clock
/// ticks of USER_HZ = 100 (Linux's fixed user-visible tick; 10 ms resolution, fine for runs of seconds).
fn children_cpu_s() -> Option<f64> {
    let s = std::fs::read_to_string("/proc/self/stat").ok()?;
    // Fields after the command name (which is in parentheses and may contain spaces).
    let rest = &s[s.rfind(')')? + 2..];
    let f: Vec<&str> = rest.split_whitespace().collect();
    // cutime and cstime are fields 16 and 17 of the line, 14 and 15 after the name and state.
    let (cu, cs): (f64, f64) = (f.get(13)?.parse().ok()?, f.get(14)?.parse().ok()?);
    Some((cu + cs) / 100.0)
}

/// `ndfit batch --jobs 1` and `--jobs 2` on the same folder, alternated `reps` times: median wall time,
/// CPU time and the cores actually used, with the load average.
fn scaling() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path().join("set");
    make_set(&dir, 8, SIDE);
    let mut res: [Vec<(f64, f64)>; 2] = [Vec::new(), Vec::new()];
    for _ in 0..5 {
        for jobs in [1usize, 2] {
            let out = tmp.path().join(format!("out{jobs}"));
            let _ = std::fs::remove_dir_all(&out);
            let cpu0 = children_cpu_s();
            let t = std::time::Instant::now();
            let ok = Command::new(env!("CARGO_BIN_EXE_ndfit"))
                .args(["batch", dir.to_str().expect("utf-8 temp path"), "-o", out.to_str().expect("utf-8 temp path")])
                .args(["--jobs", &jobs.to_string(), "--model", "ellipsoid"])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status()
                .is_ok_and(|s| s.success());
            let wall = t.elapsed().as_secs_f64();
            let cpu = match (cpu0, children_cpu_s()) {
                (Some(a), Some(b)) => b - a,
                _ => f64::NAN,
            };
            if ok {
                res[jobs - 1].push((wall, cpu));
            }
        }
    }
    let med = |v: &[(f64, f64)], k: usize| {
        let mut x: Vec<f64> = v.iter().map(|p| if k == 0 { p.0 } else { p.1 }).collect();
        x.sort_by(f64::total_cmp);
        x.get(x.len() / 2).copied().unwrap_or(f64::NAN)
    };
    let load = std::fs::read_to_string("/proc/loadavg").unwrap_or_default();
    let (w1, w2, c1, c2) = (med(&res[0], 0), med(&res[1], 0), med(&res[0], 1), med(&res[1], 1));
    println!(
        "scaling, `ndfit batch` over 8 scans of {SIDE}^2 (medians of {} and {} runs): 1 job {w1:.2} s wall / {c1:.2} s CPU ({:.2} cores), 2 jobs {w2:.2} s / {c2:.2} s ({:.2} cores): speed-up {:.2}x; load average {}",
        res[0].len(),
        res[1].len(),
        c1 / w1,
        c2 / w2,
        w1 / w2,
        load.split_whitespace().take(3).collect::<Vec<_>>().join(" ")
    );
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
    scaling();
    benches();
    Criterion::default().configure_from_args().final_summary();
}
