//! The tracer's throughput (`ndfit bench --trace`): one-bounce paths per second per core on
//! a synthetic Gaussian scan, and the wall time of a large scan at many incidences on every thread.
//!
//! The scans are made in memory (`synth::gaussian_surface`, RMS slope 0.3 per axis, correlation length
//! 8 cells, periodic), so no reading is timed. A path carries what `ndfit trace` does per path: the
//! landing ray, its bounces, one sample of the microfacet prediction and a quarter of a masking ray.
//! Per core: the same trace on a pool of one thread, timed by the wall clock and by the process's CPU
//! time (the machine's other load slows the first, hardly the second); on every thread, the same
//! paths again, which gives the parallel speed-up measured in the same run.

use std::time::Instant;

use crate::error::{Error, Result};
use crate::synth::{gaussian_surface, GaussianParams, SynthSettings};
use crate::trace::{trace, TraceOptions};

/// The targets the tracer is held to: one-bounce paths per second per core at 2048^2, and the wall time (s) of a
/// 4096^2 scan at 16 incidences on 2 cores.
pub const TARGET_PATHS_PER_CORE: f64 = 1e6;
/// See [`TARGET_PATHS_PER_CORE`].
pub const TARGET_WALL_S: f64 = 60.0;

/// What to measure.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TracePlan {
    /// Side of the throughput scan.
    pub size: usize,
    /// Incidences of the throughput run (degrees).
    pub incidences: Vec<f64>,
    /// Paths per incidence of the throughput run.
    pub rays: usize,
    /// Side of the large scan.
    pub large_size: usize,
    /// Its incidences (degrees).
    pub large_incidences: Vec<f64>,
    /// Repetitions of the per-core measurement (the best is kept: the machine's other load only slows).
    pub repeats: usize,
}

impl TracePlan {
    /// The standard measurement: 2048^2 one-bounce, 4096^2 at 16 incidences (0 to 75 degrees) with the
    /// defaults of `ndfit trace` (2^20 paths per incidence, 16 bounces).
    pub fn full() -> TracePlan {
        TracePlan {
            size: 2048,
            incidences: vec![0.0, 30.0, 60.0],
            rays: 1 << 21,
            large_size: 4096,
            large_incidences: (0..16).map(|k| 5.0 * k as f64).collect(),
            repeats: 3,
        }
    }

    /// Seconds: the same measurements on small scans.
    pub fn quick() -> TracePlan {
        TracePlan { size: 256, incidences: vec![0.0, 60.0], rays: 1 << 15, large_size: 512, large_incidences: vec![0.0, 40.0], repeats: 1 }
    }
}

/// One timed trace.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Timing {
    /// Threads of the pool.
    pub threads: usize,
    /// Paths traced (all incidences).
    pub paths: u64,
    /// Wall time (s).
    pub wall_s: f64,
    /// CPU time of the process over the run (s, user + system).
    pub cpu_s: f64,
    /// Paths per second of wall time.
    pub paths_per_s: f64,
    /// Paths per second of wall time per thread.
    pub paths_per_s_per_core: f64,
    /// Paths per second of CPU time (per core, whatever else the machine ran).
    pub paths_per_cpu_s: f64,
}

/// What `--trace` writes (`trace.json`).
#[derive(Debug, Clone, serde::Serialize)]
pub struct TraceBench {
    /// `ndfit.bench.trace/1`.
    pub schema: &'static str,
    /// The plan.
    pub plan: TracePlan,
    /// Threads of the machine's pool.
    pub threads: usize,
    /// One-bounce paths on one thread (best of the repeats).
    pub one_thread: Timing,
    /// The same on every thread.
    pub all_threads: Timing,
    /// The large scan on every thread with `ndfit trace`'s defaults.
    pub large: Timing,
    /// Whether the per-core target is met (by wall time on one thread).
    pub per_core_met: bool,
    /// Whether the large scan's target is met.
    pub large_met: bool,
}

/// The process's CPU time so far (s).
fn cpu_time() -> f64 {
    #[cfg(unix)]
    {
        let mut ru = std::mem::MaybeUninit::<libc::rusage>::zeroed();
        // SAFETY: getrusage writes the struct it is given; RUSAGE_SELF is always valid.
        if unsafe { libc::getrusage(libc::RUSAGE_SELF, ru.as_mut_ptr()) } == 0 {
            // SAFETY: initialized by the successful call.
            let ru = unsafe { ru.assume_init() };
            let s = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
            return s(ru.ru_utime) + s(ru.ru_stime);
        }
        0.0
    }
    #[cfg(not(unix))]
    0.0
}

fn scan(n: usize) -> Result<crate::Heightfield> {
    let s = SynthSettings { nx: n, ny: n, dx: 1e-6, dy: 1e-6, seed: 7, ..Default::default() };
    let p = GaussianParams { sigma_x: 0.3, sigma_y: 0.3, theta_z: 0.0, corr_length: 8e-6 };
    Ok(gaussian_surface(&s, &p)?.0)
}

fn timed(hf: &crate::Heightfield, o: &TraceOptions, threads: usize) -> Result<Timing> {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().map_err(|e| Error::invalid(format!("thread pool: {e}")))?;
    let (c0, t0) = (cpu_time(), Instant::now());
    let r = pool.install(|| trace(hf, o, None))?;
    let (wall, cpu) = (t0.elapsed().as_secs_f64(), cpu_time() - c0);
    let paths: u64 = r.incidences.iter().map(|i| i.rays).sum();
    Ok(Timing {
        threads,
        paths,
        wall_s: wall,
        cpu_s: cpu,
        paths_per_s: paths as f64 / wall,
        paths_per_s_per_core: paths as f64 / wall / threads as f64,
        paths_per_cpu_s: paths as f64 / cpu.max(1e-9),
    })
}

/// Run the plan; `log` gets one line per measurement.
pub fn run(plan: &TracePlan, log: impl Fn(&str)) -> Result<TraceBench> {
    let threads = rayon::current_num_threads();
    let hf = scan(plan.size)?;
    let o = TraceOptions { incidences_deg: plan.incidences.clone(), bounces: 1, rays: plan.rays, ..Default::default() };
    let line = |name: &str, t: &Timing| {
        log(&format!(
            "trace {name}: {} paths in {:.2} s wall ({:.2} s CPU) on {} thread(s): {:.3} M paths/s, {:.3} M/s per core, {:.3} M per CPU second",
            t.paths,
            t.wall_s,
            t.cpu_s,
            t.threads,
            t.paths_per_s / 1e6,
            t.paths_per_s_per_core / 1e6,
            t.paths_per_cpu_s / 1e6
        ))
    };
    let mut best: Option<Timing> = None;
    for _ in 0..plan.repeats.max(1) {
        let t = timed(&hf, &o, 1)?;
        line(&format!("{0}^2 one bounce", plan.size), &t);
        if best.as_ref().is_none_or(|b| t.wall_s < b.wall_s) {
            best = Some(t);
        }
    }
    let one = best.expect("at least one repeat");
    let all = timed(&hf, &o, threads)?;
    line(&format!("{0}^2 one bounce", plan.size), &all);
    drop(hf);
    let big = scan(plan.large_size)?;
    let lo = TraceOptions { incidences_deg: plan.large_incidences.clone(), ..Default::default() };
    let large = timed(&big, &lo, threads)?;
    line(&format!("{0}^2 at {1} incidences, {2} bounces", plan.large_size, plan.large_incidences.len(), lo.bounces), &large);
    let per_core_met = one.paths_per_s_per_core >= TARGET_PATHS_PER_CORE;
    let large_met = large.wall_s <= TARGET_WALL_S;
    Ok(TraceBench {
        schema: "ndfit.bench.trace/1",
        plan: plan.clone(),
        threads,
        one_thread: one,
        all_threads: all,
        large,
        per_core_met,
        large_met,
    })
}

/// The Markdown table of a run (`trace.md`).
pub fn markdown(b: &TraceBench) -> String {
    let row = |what: String, t: &Timing, target: &str| {
        format!(
            "| {what} | {} | {} | {:.2} | {:.2} | {:.3} | {:.3} | {target} |\n",
            t.threads,
            t.paths,
            t.wall_s,
            t.cpu_s,
            t.paths_per_s_per_core / 1e6,
            t.paths_per_cpu_s / 1e6
        )
    };
    let met = |m: bool| if m { "met" } else { "NOT MET" };
    let mut s = String::from(
        "| run | threads | paths | wall (s) | CPU (s) | M paths/s per core | M paths per CPU s | target |\n| --- | --- | --- | --- | --- | --- | --- | --- |\n",
    );
    s += &row(
        format!("{0}^2, one bounce, {1} incidences", b.plan.size, b.plan.incidences.len()),
        &b.one_thread,
        &format!(">= {} M/s per core: {}", TARGET_PATHS_PER_CORE / 1e6, met(b.per_core_met)),
    );
    s += &row(format!("{0}^2, one bounce, {1} incidences", b.plan.size, b.plan.incidences.len()), &b.all_threads, "");
    s += &row(
        format!("{0}^2, {1} incidences, defaults (16 bounces)", b.plan.large_size, b.plan.large_incidences.len()),
        &b.large,
        &format!("<= {TARGET_WALL_S} s: {}", met(b.large_met)),
    );
    s
}
