//! `--isolate process`: each scan's job runs in a child `ndfit batch --worker` process, so an abort,
//! a stack overflow or a crash inside any dependency costs only that scan, and `--timeout` can stop a
//! scan that hangs. The request (settings, scan, baseline entry) goes to the child's standard input as
//! JSON; the child answers on standard output with one JSON object.

use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Stdio};
use std::time::{Duration, Instant};

use ndfit::batch::{BaselineEntry, JobContext, JobFailure, JobOutput, Quality, ScanSpec};
use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::job::{fit_scan, JobConfig};

#[derive(Serialize, Deserialize)]
struct Request {
    config: JobConfig,
    spec: ScanSpec,
    out_dir: PathBuf,
    out_rel: PathBuf,
    baseline: Option<BaselineEntry>,
}

#[derive(Serialize, Deserialize)]
#[serde(tag = "result", rename_all = "snake_case")]
enum Response {
    Ok { fit: Value, quality: Option<Quality>, baseline_on_same_bins: Option<Quality> },
    Error { kind: String, message: String },
}

/// The child side: read one request from stdin, run the job (panics caught as in thread mode), answer.
pub fn serve() -> anyhow::Result<ExitCode> {
    let mut text = String::new();
    std::io::stdin().read_to_string(&mut text)?;
    let req: Request = serde_json::from_str(&text).map_err(|e| anyhow::anyhow!("batch worker: bad request: {e}"))?;
    let ctx = JobContext { out_dir: &req.out_dir, out_rel: &req.out_rel, baseline: req.baseline.as_ref() };
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| fit_scan(&req.config, &req.spec, &ctx)));
    let resp = match r {
        Ok(Ok(o)) => Response::Ok { fit: o.fit, quality: o.quality, baseline_on_same_bins: o.baseline_on_same_bins },
        Ok(Err(f)) => Response::Error { kind: f.kind, message: f.message },
        Err(p) => {
            let msg = p.downcast_ref::<&str>().map(|s| s.to_string()).or_else(|| p.downcast_ref::<String>().cloned());
            Response::Error { kind: "panic".into(), message: format!("internal error (panic): {}", msg.unwrap_or_default()) }
        }
    };
    let mut out = std::io::stdout().lock();
    serde_json::to_writer(&mut out, &resp)?;
    out.write_all(b"\n")?;
    Ok(ExitCode::SUCCESS)
}

/// The parent side: run `spec` in a child process, enforcing `timeout`.
pub fn run_in_child(
    exe: &Path,
    cfg: &JobConfig,
    spec: &ScanSpec,
    ctx: &JobContext<'_>,
    timeout: Option<Duration>,
) -> Result<JobOutput, JobFailure> {
    let req = Request {
        config: cfg.clone(),
        spec: spec.clone(),
        out_dir: ctx.out_dir.to_path_buf(),
        out_rel: ctx.out_rel.to_path_buf(),
        baseline: ctx.baseline.cloned(),
    };
    let body = serde_json::to_vec(&req).map_err(|e| JobFailure::new("io", format!("batch worker request: {e}")))?;
    let mut child = Command::new(exe)
        .args(["batch", "--worker"])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .map_err(|e| JobFailure::new("io", format!("{}: cannot start a worker process: {e}", spec.key)))?;
    // Writer and readers on their own threads: no pipe can fill up and deadlock the child.
    let mut stdin = child.stdin.take();
    let writer = std::thread::spawn(move || {
        if let Some(s) = stdin.as_mut() {
            let _ = s.write_all(&body);
        }
    });
    let mut stdout = child.stdout.take();
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        if let Some(o) = stdout.as_mut() {
            let _ = o.read_to_string(&mut s);
        }
        s
    });
    let mut stderr = child.stderr.take();
    let err_reader = std::thread::spawn(move || {
        let mut s = String::new();
        if let Some(o) = stderr.as_mut() {
            let _ = o.read_to_string(&mut s);
        }
        s
    });
    let t0 = Instant::now();
    let status = loop {
        match child.try_wait() {
            Ok(Some(st)) => break st,
            Ok(None) => {
                if timeout.is_some_and(|t| t0.elapsed() > t) {
                    let _ = child.kill();
                    let _ = child.wait();
                    let _ = (writer.join(), reader.join(), err_reader.join());
                    return Err(JobFailure::new(
                        "timeout",
                        format!("{}: no result after {:.1} s (worker killed)", spec.key, t0.elapsed().as_secs_f64()),
                    ));
                }
                std::thread::sleep(Duration::from_millis(5));
            }
            Err(e) => return Err(JobFailure::new("io", format!("{}: waiting for the worker: {e}", spec.key))),
        }
    };
    let _ = writer.join();
    let out = reader.join().unwrap_or_default();
    let err = err_reader.join().unwrap_or_default();
    if let Ok(resp) = serde_json::from_str::<Response>(out.trim()) {
        return match resp {
            Response::Ok { fit, quality, baseline_on_same_bins } => Ok(JobOutput { fit, quality, baseline_on_same_bins }),
            Response::Error { kind, message } => Err(JobFailure { kind, message }),
        };
    }
    let how = describe_exit(&status);
    let last = err.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("").trim().to_string();
    Err(JobFailure::new(
        "crash",
        format!("{}: worker process {how}{}", spec.key, if last.is_empty() { String::new() } else { format!(": {last}") }),
    ))
}

fn describe_exit(status: &std::process::ExitStatus) -> String {
    #[cfg(unix)]
    {
        use std::os::unix::process::ExitStatusExt;
        if let Some(sig) = status.signal() {
            let name = match sig {
                6 => " (SIGABRT)",
                9 => " (SIGKILL)",
                11 => " (SIGSEGV)",
                _ => "",
            };
            return format!("killed by signal {sig}{name}");
        }
    }
    format!("exited with {status} without a result")
}
