//! Whole-process measurements: a command's wall time and the peak resident memory of its child, run
//! interleaved with the commands it is compared against.
//!
//! A comparison such as "ndfit against `unzip -p`" is only fair when both are whole processes (start-up,
//! dynamic loading, page faults and exit included) measured in the same run under the same machine load.
//! [`interleave`] therefore runs the commands round-robin (A B C A B C ...), so a burst of other load hits
//! every command alike, and reports medians. The child's peak resident set comes from the kernel's
//! accounting (`wait4(2)`'s `ru_maxrss`); [`run_pool`] runs a set of commands at most `jobs` at once (the
//! floor of a parallel batch). [`loadavg`] gives the machine's other load for the record.

use std::ffi::OsString;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use crate::error::{Error, ErrorKind, Result};

/// One command line to measure.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Cmd {
    /// Short name in reports (`ndfit fit`, `unzip -p`, ...).
    pub label: String,
    /// Program and arguments.
    pub argv: Vec<OsString>,
    /// Where stdout goes: `None` discards it, a path receives it (truncated per run).
    pub stdout: Option<PathBuf>,
}

impl Cmd {
    /// A command whose output is discarded.
    pub fn new<I, S>(label: &str, argv: I) -> Cmd
    where
        I: IntoIterator<Item = S>,
        S: Into<OsString>,
    {
        Cmd { label: label.to_string(), argv: argv.into_iter().map(Into::into).collect(), stdout: None }
    }

    fn display(&self) -> String {
        self.argv.iter().map(|a| a.to_string_lossy().into_owned()).collect::<Vec<_>>().join(" ")
    }
}

/// One run of one command.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sample {
    /// Wall time from spawn to reaped exit (s).
    pub wall_s: f64,
    /// User + system CPU time of the child (s); `None` where `wait4` is unavailable.
    pub cpu_s: Option<f64>,
    /// Peak resident set of the child (bytes); `None` where `wait4` is unavailable.
    pub peak_rss: Option<u64>,
    /// The measuring process's own peak resident set when it spawned the child (bytes). Linux carries the
    /// spawning process's high-water mark into the child's `ru_maxrss` across `exec`, so a child peak at
    /// or below this figure only says "at most this much".
    #[serde(default)]
    pub rss_floor: Option<u64>,
}

impl Sample {
    /// The child's peak resident set when it is a real figure (above [`Sample::rss_floor`]).
    pub fn peak_above_floor(&self) -> Option<u64> {
        self.peak_rss.filter(|&p| self.rss_floor.is_none_or(|f| p > f))
    }
}

/// Spawn `cmd`, wait for it, and return its wall time, CPU time and peak memory. A non-zero exit is an
/// error naming the command (a failed run is never a time).
pub fn run_once(cmd: &Cmd) -> Result<Sample> {
    let (prog, args) = cmd.argv.split_first().ok_or_else(|| Error::invalid(format!("{}: empty command", cmd.label)))?;
    let mut c = Command::new(prog);
    c.args(args).stdin(Stdio::null()).stderr(Stdio::piped());
    match &cmd.stdout {
        None => c.stdout(Stdio::null()),
        Some(p) => c.stdout(Stdio::from(std::fs::File::create(p).map_err(|e| Error::io(e).with_path(p))?)),
    };
    // Lower this process's high-water mark to its current resident set first: the child inherits it.
    super::mem::reset_peak();
    let rss_floor = super::mem::peak_rss();
    let start = Instant::now();
    let mut child = c.spawn().map_err(|e| Error::new(ErrorKind::Io, format!("{}: cannot start `{}`: {e}", cmd.label, cmd.display())))?;
    // Drain stderr on a thread so a chatty child cannot block on a full pipe while we wait for it.
    let mut err_pipe = child.stderr.take();
    let drain = std::thread::spawn(move || {
        let mut s = String::new();
        if let Some(p) = err_pipe.as_mut() {
            let _ = std::io::Read::read_to_string(p, &mut s);
        }
        s
    });
    let (ok, code, cpu_s, peak_rss) = wait(&mut child)?;
    let wall_s = start.elapsed().as_secs_f64();
    let stderr = drain.join().unwrap_or_default();
    if !ok {
        let last = stderr.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("").trim();
        return Err(Error::new(ErrorKind::Io, format!("{}: `{}` failed ({code}): {last}", cmd.label, cmd.display())));
    }
    Ok(Sample { wall_s, cpu_s, peak_rss, rss_floor })
}

/// Reap `child` with `wait4(2)` for its resource usage: (success, status text, CPU s, peak RSS bytes).
#[cfg(target_os = "linux")]
fn wait(child: &mut std::process::Child) -> Result<(bool, String, Option<f64>, Option<u64>)> {
    let pid = child.id() as libc::pid_t;
    let mut status: libc::c_int = 0;
    // SAFETY: rusage is plain old data, fully written by a successful wait4.
    let mut ru: libc::rusage = unsafe { std::mem::zeroed() };
    loop {
        // SAFETY: pid is our own unreaped child; status and ru point to live locals.
        let r = unsafe { libc::wait4(pid, &mut status, 0, &mut ru) };
        if r == pid {
            break;
        }
        let e = std::io::Error::last_os_error();
        if e.kind() != std::io::ErrorKind::Interrupted {
            return Err(Error::io(e));
        }
    }
    let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    let cpu = tv(ru.ru_utime) + tv(ru.ru_stime);
    // ru_maxrss is in kilobytes on Linux.
    let rss = (ru.ru_maxrss as u64) * 1024;
    let ok = libc::WIFEXITED(status) && libc::WEXITSTATUS(status) == 0;
    let code = if libc::WIFEXITED(status) {
        format!("exit {}", libc::WEXITSTATUS(status))
    } else if libc::WIFSIGNALED(status) {
        format!("signal {}", libc::WTERMSIG(status))
    } else {
        format!("status {status}")
    };
    Ok((ok, code, Some(cpu), Some(rss)))
}

#[cfg(not(target_os = "linux"))]
fn wait(child: &mut std::process::Child) -> Result<(bool, String, Option<f64>, Option<u64>)> {
    let st = child.wait().map_err(Error::io)?;
    Ok((st.success(), format!("{st}"), None, None))
}

/// The runs of one command and their medians.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Measured {
    /// The command's (or pool's) name.
    pub label: String,
    /// The command line as run.
    pub command: String,
    /// Median wall time (ms).
    pub median_ms: f64,
    /// Fastest run (ms).
    pub min_ms: f64,
    /// Slowest run (ms).
    pub max_ms: f64,
    /// Median CPU time of the child (ms).
    pub median_cpu_ms: Option<f64>,
    /// Median peak resident set (bytes).
    pub median_peak_rss: Option<u64>,
    /// Largest peak resident set over the runs (bytes).
    pub max_peak_rss: Option<u64>,
    /// Largest [`Sample::rss_floor`] over the runs: peaks at or below it are upper bounds only.
    pub rss_floor: Option<u64>,
    /// Every run, in the order measured.
    pub samples: Vec<Sample>,
}

impl Measured {
    /// The medians of `samples` of the command `label`.
    pub fn from_samples(label: &str, command: String, samples: Vec<Sample>) -> Measured {
        let walls: Vec<f64> = samples.iter().map(|s| s.wall_s * 1e3).collect();
        let cpus: Option<Vec<f64>> = samples.iter().map(|s| s.cpu_s.map(|c| c * 1e3)).collect();
        let rss: Option<Vec<f64>> = samples.iter().map(|s| s.peak_rss.map(|r| r as f64)).collect();
        Measured {
            label: label.to_string(),
            command,
            median_ms: median(&walls),
            min_ms: walls.iter().copied().fold(f64::INFINITY, f64::min),
            max_ms: walls.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            median_cpu_ms: cpus.map(|c| median(&c)),
            median_peak_rss: rss.as_ref().map(|r| median(r) as u64),
            max_peak_rss: rss.map(|r| r.iter().copied().fold(0.0, f64::max) as u64),
            rss_floor: samples.iter().filter_map(|s| s.rss_floor).max(),
            samples,
        }
    }
}

/// The median of `v` (mean of the middle two for an even count; NaN when empty).
pub fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let n = s.len();
    if n % 2 == 1 {
        s[n / 2]
    } else {
        0.5 * (s[n / 2 - 1] + s[n / 2])
    }
}

/// Run every command `repeats` times, round-robin (one run of each command per round), after `warmup`
/// unrecorded rounds (page cache, dynamic loader). `on_sample` sees each recorded run as it ends.
pub fn interleave(cmds: &[Cmd], repeats: usize, warmup: usize, mut on_sample: impl FnMut(&Cmd, &Sample)) -> Result<Vec<Measured>> {
    let mut samples: Vec<Vec<Sample>> = vec![Vec::with_capacity(repeats); cmds.len()];
    for round in 0..warmup + repeats {
        for (c, out) in cmds.iter().zip(samples.iter_mut()) {
            let s = run_once(c)?;
            if round >= warmup {
                on_sample(c, &s);
                out.push(s);
            }
        }
    }
    Ok(cmds.iter().zip(samples).map(|(c, s)| Measured::from_samples(&c.label, c.display(), s)).collect())
}

/// Run all of `cmds` with at most `jobs` running at once (each worker takes the next command when its
/// last one ends). The sample is the whole set: wall time until the last exits, summed CPU time, and the
/// largest single peak resident set.
pub fn run_pool(cmds: &[Cmd], jobs: usize) -> Result<Sample> {
    let jobs = jobs.max(1).min(cmds.len().max(1));
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Result<Sample>>> = Mutex::new(Vec::with_capacity(cmds.len()));
    let start = Instant::now();
    std::thread::scope(|s| {
        for _ in 0..jobs {
            s.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::Relaxed);
                let Some(c) = cmds.get(i) else { break };
                let r = run_once(c);
                let failed = r.is_err();
                results.lock().unwrap_or_else(|e| e.into_inner()).push(r);
                if failed {
                    // Stop handing out work: the set has failed.
                    next.store(cmds.len(), Ordering::Relaxed);
                    break;
                }
            });
        }
    });
    let wall_s = start.elapsed().as_secs_f64();
    let results = results.into_inner().unwrap_or_else(|e| e.into_inner());
    let mut cpu = Some(0.0);
    let mut rss = Some(0u64);
    let mut floor = Some(0u64);
    for r in results {
        let s = r?;
        cpu = cpu.zip(s.cpu_s).map(|(a, b)| a + b);
        rss = rss.zip(s.peak_rss).map(|(a, b)| a.max(b));
        floor = floor.zip(s.rss_floor).map(|(a, b)| a.max(b));
    }
    Ok(Sample { wall_s, cpu_s: cpu, peak_rss: rss, rss_floor: floor })
}

/// A named set of commands run as a pool of `jobs` (one "command" of [`interleave_pools`]).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Pool {
    /// Name in reports.
    pub label: String,
    /// Commands running at once.
    pub jobs: usize,
    /// The commands, started in this order.
    pub cmds: Vec<Cmd>,
}

/// [`interleave`] for pools: every pool run `repeats` times round-robin after `warmup` unrecorded rounds.
pub fn interleave_pools(pools: &[Pool], repeats: usize, warmup: usize, mut on_sample: impl FnMut(&Pool, &Sample)) -> Result<Vec<Measured>> {
    let mut samples: Vec<Vec<Sample>> = vec![Vec::with_capacity(repeats); pools.len()];
    for round in 0..warmup + repeats {
        for (p, out) in pools.iter().zip(samples.iter_mut()) {
            let s = run_pool(&p.cmds, p.jobs)?;
            if round >= warmup {
                on_sample(p, &s);
                out.push(s);
            }
        }
    }
    Ok(pools
        .iter()
        .zip(samples)
        .map(|(p, s)| {
            let first = p.cmds.first().map(Cmd::display).unwrap_or_default();
            Measured::from_samples(&p.label, format!("{} commands, {} at once; first: {first}", p.cmds.len(), p.jobs), s)
        })
        .collect())
}

/// The 1, 5 and 15 minute load averages (`None` without `/proc`).
pub fn loadavg() -> Option<[f64; 3]> {
    let s = std::fs::read_to_string("/proc/loadavg").ok()?;
    let mut it = s.split_whitespace().map(|v| v.parse::<f64>().ok());
    Some([it.next()??, it.next()??, it.next()??])
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_and_even_counts() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 3.0, 2.0]), 2.5);
        assert!(median(&[]).is_nan());
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn child_peak_rss_sees_what_the_child_touched() {
        // A child that fills 64 MiB of memory must report a peak of at least that, and the parent's own
        // memory must not leak into the child's figure (a fresh `true` stays far below it).
        let big = Cmd::new("head", ["sh", "-c", "head -c 67108864 /dev/zero | tail -c 1 >/dev/null"]);
        let s = run_once(&big);
        let Ok(s) = s else {
            eprintln!("SKIP: sh/head/tail unavailable");
            return;
        };
        // `tail -c 1` on a pipe keeps only the tail; the peak of the set is `sh`'s or a tool's own.
        assert!(s.peak_rss.unwrap() > 0);
        let python = ["python3", "-c", "b = bytearray(64 << 20); b[::4096] = b'x' * len(b[::4096])"];
        match run_once(&Cmd::new("py", python)) {
            Ok(p) => assert!(p.peak_rss.unwrap() >= 64 << 20, "peak {:?}", p.peak_rss),
            Err(_) => eprintln!("SKIP: python3 unavailable"),
        }
        // What `true` reports is the test process's resident set when it spawned (other tests run beside
        // this one and hold memory), not that set's earlier peak.
        let t = run_once(&Cmd::new("true", ["true"])).unwrap();
        assert!(t.peak_rss.unwrap() < t.rss_floor.unwrap_or(0) + (32 << 20), "peak {:?}, floor {:?}", t.peak_rss, t.rss_floor);
    }

    #[test]
    fn failures_are_errors_naming_the_command() {
        let e = run_once(&Cmd::new("fails", ["sh", "-c", "echo boom >&2; exit 3"])).unwrap_err().to_string();
        assert!(e.contains("fails") && e.contains("exit 3") && e.contains("boom"), "{e}");
        let e = run_once(&Cmd::new("missing", ["/nonexistent/program"])).unwrap_err().to_string();
        assert!(e.contains("missing"), "{e}");
    }

    #[test]
    fn pool_runs_every_command_and_overlaps_them() {
        // Two commands that each wait for the other's mark can only both finish when they run at once.
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a"), dir.path().join("b"));
        let waiter = |mine: &std::path::Path, other: &std::path::Path| {
            let script = format!(
                "touch '{}'; i=0; while [ ! -e '{}' ]; do i=$((i+1)); [ $i -gt 2000 ] && exit 9; sleep 0.01; done",
                mine.display(),
                other.display()
            );
            Cmd::new("waiter", ["sh".to_string(), "-c".to_string(), script])
        };
        let cmds = vec![waiter(&a, &b), waiter(&b, &a)];
        let s = run_pool(&cmds, 2).unwrap();
        assert!(s.wall_s > 0.0 && s.cpu_s.is_none_or(|c| c >= 0.0));
        // Every command of a pool runs: four markers from four commands, one at a time.
        let cmds: Vec<Cmd> =
            (0..4).map(|i| Cmd::new("touch", ["touch".into(), dir.path().join(format!("m{i}")).into_os_string()])).collect();
        run_pool(&cmds, 1).unwrap();
        assert!((0..4).all(|i| dir.path().join(format!("m{i}")).exists()));
        let m = interleave(&cmds[..2], 3, 1, |_, _| {}).unwrap();
        assert_eq!(m.len(), 2);
        assert!(m.iter().all(|m| m.samples.len() == 3 && m.min_ms <= m.median_ms && m.median_ms <= m.max_ms));
    }
}
