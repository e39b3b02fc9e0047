//! Running the job over every scan: `jobs` workers, each scan isolated (panics caught, no shared
//! mutable state), each result written to disk atomically as soon as it is done, resumable.
//!
//! Determinism: every scan's job runs inside its worker's own one-thread rayon pool, so any rayon
//! parallelism inside the pipeline (NDF histograms, reductions) splits its work the same way whatever
//! `--jobs` is; with the summary ordered by key, results are bit-identical for any number of jobs.
//! Memory: only the scans in flight hold their data; finished scans leave a small [`Brief`].

use std::cell::Cell;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Mutex, Once};
use std::time::Instant;

use serde_json::Value;

use super::compare::{compare, Baseline, Current, Tolerances};
use super::entry::{fnv1a64, Entry, ResumeKey, Status};
use super::job::{Job, JobContext, JobFailure};
use super::spec::ScanSpec;
use crate::error::{Error, Result};
use crate::io::atomic::{sync_tree, write_atomic_unsynced};

/// Folder (under the output folder) of the per-scan records.
pub const RECORDS_DIR: &str = "scans";
/// Folder (under the output folder) of the per-scan fit JSON files.
pub const FITS_DIR: &str = "fits";

/// How to run a batch.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// The output folder (created if absent).
    pub out_dir: PathBuf,
    /// Number of scans fitted at once (>= 1).
    pub jobs: usize,
    /// Reuse finished scans whose record matches (same settings, options, baseline entry and file).
    pub resume: bool,
    /// Everything about the run's settings that changes results (model, options, version), hashed
    /// into each scan's resume key.
    pub settings: String,
    /// Tolerances of the baseline comparison.
    pub tolerances: Tolerances,
    /// The per-scan files the job writes besides the fit, as `(kind, suffix)` of
    /// [`JobContext::extra_path`] (e.g. `("ndf", ".ndf.csv")`): `--resume` fits a scan again when one
    /// of them is missing (they cannot be rebuilt from its record).
    pub extras: Vec<(String, String)>,
}

/// The small per-scan summary kept in memory: the entry without its fit, plus the fit's headline numbers.
#[derive(Debug, Clone, PartialEq)]
pub struct Brief {
    /// The entry, with `fit` and `resume` removed.
    pub entry: Entry,
    /// Fitted model id.
    pub model: Option<String>,
    /// Fitted parameters in the fit's order (name, value).
    pub params: Vec<(String, f64)>,
    /// Their standard errors by name.
    pub stderr: std::collections::BTreeMap<String, f64>,
    /// The fit's termination reason, when it reports one.
    pub termination: Option<String>,
    /// The fit's number of evaluations, when it reports it.
    pub evaluations: Option<u64>,
    /// The fit's reduced chi-square, when it reports it.
    pub reduced_chi2: Option<f64>,
    /// The fit's verdict (`quality.verdict`: ok, misfit, unresolved), when it reports one.
    pub fit_verdict: Option<String>,
    /// `auto`'s answer (`selection.answer`: a model id, `measured`, `mirror`, `mirror+ggx`).
    pub answer: Option<String>,
    /// `auto`'s regime (`optics.regime`: geometric, mixed, wave).
    pub regime: Option<String>,
    /// Whether this result was reused from an earlier run (`--resume`).
    pub reused: bool,
}

/// One finished scan, for progress display.
#[derive(Debug, Clone, Copy)]
pub struct Progress<'a> {
    /// The finished scan.
    pub brief: &'a Brief,
    /// Scans finished so far (this one included).
    pub done: usize,
    /// Scans in the run.
    pub total: usize,
}

/// The result of a run.
#[derive(Debug, Clone, PartialEq)]
pub struct RunOutcome {
    /// One brief per scan, ordered by key.
    pub briefs: Vec<Brief>,
    /// Baseline keys this run did not contain.
    pub missing: Vec<String>,
}

/// Counts of a run's outcomes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Counts {
    /// Scans in the run.
    pub scans: usize,
    /// Fitted.
    pub ok: usize,
    /// Not read or not fitted.
    pub error: usize,
    /// Regressed against the baseline.
    pub regressed: usize,
    /// Improved against the baseline.
    pub improved: usize,
    /// With a parameter beyond its tolerance.
    pub params_changed: usize,
    /// In the baseline but not in this run.
    pub missing: usize,
    /// Fits by verdict (`quality.verdict`).
    pub verdicts: VerdictCounts,
    /// Reused by `--resume` (not written to `summary.json`: a resumed run's summary equals an
    /// uninterrupted one's).
    #[serde(skip)]
    pub reused: usize,
}

/// Fitted scans by the fit's verdict ([`crate::fit::verdict::Verdict`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct VerdictCounts {
    /// The model describes the data within the data's own dispersion.
    pub ok: usize,
    /// The model does not describe the data.
    pub misfit: usize,
    /// The scan cannot resolve the NDF.
    pub unresolved: usize,
}

impl RunOutcome {
    /// Counts of the outcomes.
    pub fn counts(&self) -> Counts {
        let mut c = Counts { scans: self.briefs.len(), missing: self.missing.len(), ..Counts::default() };
        for b in &self.briefs {
            match b.entry.status {
                Status::Ok => c.ok += 1,
                Status::Error => c.error += 1,
            }
            if let Some(cmp) = &b.entry.baseline {
                c.regressed += usize::from(cmp.regressed);
                c.improved += usize::from(cmp.verdict == super::compare::Verdict::Improved);
                c.params_changed += usize::from(!cmp.param_changes.is_empty());
            }
            c.reused += usize::from(b.reused);
            match b.fit_verdict.as_deref() {
                Some("ok") => c.verdicts.ok += 1,
                Some("misfit") => c.verdicts.misfit += 1,
                Some("unresolved") => c.verdicts.unresolved += 1,
                _ => {}
            }
        }
        c
    }

    /// The exit status of the contract: 2 when some scan could not be read or fitted, else 1 when some
    /// fit regressed (or, unless `allow_missing`, some baseline scan is missing from the run), else 0.
    pub fn exit_code(&self, allow_missing: bool) -> u8 {
        let c = self.counts();
        if c.error > 0 {
            2
        } else if c.regressed > 0 || (!allow_missing && c.missing > 0) {
            1
        } else {
            0
        }
    }
}

thread_local! {
    /// Set while a scan's job runs on this thread, so the panic hook stays quiet and records where.
    static IN_JOB: Cell<bool> = const { Cell::new(false) };
    static PANIC_AT: Cell<Option<String>> = const { Cell::new(None) };
}

/// Install (once per process) a panic hook that silences panics inside batch jobs (they become
/// `error` entries with their message and location) and defers to the previous hook otherwise.
pub fn install_panic_hook() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        let prev = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if IN_JOB.with(Cell::get) {
                PANIC_AT.with(|p| p.set(info.location().map(|l| format!("{}:{}", l.file(), l.line()))));
            } else {
                prev(info);
            }
        }));
    });
}

/// Run `job` over `specs` (keys must be unique) and write every per-scan record; see the module docs.
/// The summary files are written separately ([`super::summary`]). Errors only for failures of the run
/// itself (the output folder cannot be written); a scan's failure is its `error` entry.
pub fn run(
    specs: &[ScanSpec],
    baseline: Option<&Baseline>,
    job: &Job<'_>,
    opts: &RunOptions,
    progress: &(dyn Fn(Progress<'_>) + Sync),
) -> Result<RunOutcome> {
    if opts.jobs == 0 {
        return Err(Error::invalid("--jobs must be at least 1"));
    }
    let mut keys: Vec<&str> = specs.iter().map(|s| s.key.as_str()).collect();
    keys.sort_unstable();
    if let Some(w) = keys.windows(2).find(|w| w[0] == w[1]) {
        return Err(Error::invalid(format!("scan '{}' is listed twice", w[0])));
    }
    check_output_names(specs)?;
    std::fs::create_dir_all(&opts.out_dir).map_err(|e| Error::io(e).with_path(&opts.out_dir))?;
    if opts.resume {
        remove_stale_temps(&opts.out_dir);
    }

    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let stop = AtomicBool::new(false);
    let slots: Mutex<Vec<Option<Brief>>> = Mutex::new(vec![None; specs.len()]);
    let fatal: Mutex<Option<Error>> = Mutex::new(None);
    let workers = opts.jobs.min(specs.len()).max(1);
    std::thread::scope(|s| {
        for w in 0..workers {
            let (next, done, stop, slots, fatal) = (&next, &done, &stop, &slots, &fatal);
            std::thread::Builder::new()
                .name(format!("ndfit-batch-{w}"))
                .spawn_scoped(s, move || {
                    // One-thread pool: rayon inside a job splits work identically for any --jobs.
                    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().ok();
                    loop {
                        if stop.load(Ordering::Relaxed) {
                            break;
                        }
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        let Some(spec) = specs.get(i) else { break };
                        let base = baseline.and_then(|b| b.entries.get(&spec.key));
                        let r = run_one(spec, baseline.is_some(), base, job, opts, pool.as_ref());
                        match r {
                            Ok(brief) => {
                                let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                                progress(Progress { brief: &brief, done: n, total: specs.len() });
                                if let Ok(mut g) = slots.lock() {
                                    g[i] = Some(brief);
                                }
                            }
                            Err(e) => {
                                stop.store(true, Ordering::Relaxed);
                                if let Ok(mut g) = fatal.lock() {
                                    g.get_or_insert(e);
                                }
                            }
                        }
                    }
                })
                .map_err(Error::io)
                .ok();
        }
    });
    // Per-scan files are renamed into place unsynced (complete or absent after any crash or kill); one
    // sync of the output folder makes them durable against power loss before the run reports.
    let synced = sync_tree(&opts.out_dir);
    if let Some(e) = fatal.into_inner().ok().flatten() {
        return Err(e);
    }
    synced?;
    let slots = slots.into_inner().map_err(|_| Error::new(crate::ErrorKind::Numerical, "a batch worker panicked"))?;
    let mut briefs = Vec::with_capacity(specs.len());
    for (spec, b) in specs.iter().zip(slots) {
        briefs.push(b.ok_or_else(|| Error::new(crate::ErrorKind::Io, "batch worker stopped early").with_path(&spec.file))?);
    }
    briefs.sort_by(|a, b| a.entry.path.cmp(&b.entry.path));
    let missing = match baseline {
        Some(b) => {
            let have: std::collections::BTreeSet<&str> = specs.iter().map(|s| s.key.as_str()).collect();
            b.entries.keys().filter(|k| !have.contains(k.as_str())).cloned().collect()
        }
        None => Vec::new(),
    };
    Ok(RunOutcome { briefs, missing })
}

/// Path of a scan's record.
pub fn record_path(out_dir: &Path, spec: &ScanSpec) -> PathBuf {
    with_suffix(out_dir.join(RECORDS_DIR).join(spec.out_rel()), ".json")
}

/// Path of a scan's fit JSON.
pub fn fit_path(out_dir: &Path, spec: &ScanSpec) -> PathBuf {
    with_suffix(out_dir.join(FITS_DIR).join(spec.out_rel()), ".fit.json")
}

fn with_suffix(p: PathBuf, suffix: &str) -> PathBuf {
    let mut s = p.into_os_string();
    s.push(suffix);
    PathBuf::from(s)
}

/// The resume key of a scan under these settings and this baseline entry.
fn resume_key(spec: &ScanSpec, base: Option<&super::compare::BaselineEntry>, opts: &RunOptions) -> ResumeKey {
    let mut text = opts.settings.clone();
    text.push('\n');
    text.push_str(&serde_json::to_string(spec).unwrap_or_default());
    text.push('\n');
    text.push_str(&serde_json::to_string(&base).unwrap_or_default());
    text.push('\n');
    text.push_str(&serde_json::to_string(&opts.tolerances).unwrap_or_default());
    let meta = std::fs::metadata(&spec.file).ok();
    ResumeKey {
        job: format!("{:016x}", fnv1a64(text.as_bytes())),
        size: meta.as_ref().map(|m| m.len()),
        mtime_ns: meta.and_then(|m| m.modified().ok()).and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok()).map(|d| d.as_nanos()),
    }
}

/// Fit one scan (or reuse its record) and write its files.
fn run_one(
    spec: &ScanSpec,
    has_baseline: bool,
    base: Option<&super::compare::BaselineEntry>,
    job: &Job<'_>,
    opts: &RunOptions,
    pool: Option<&rayon::ThreadPool>,
) -> Result<Brief> {
    let key = resume_key(spec, base, opts);
    let rec_path = record_path(&opts.out_dir, spec);
    let out_rel = spec.out_rel();
    let ctx = JobContext { out_dir: &opts.out_dir, out_rel: &out_rel, baseline: base };
    if opts.resume {
        let extras_present = |e: &Entry| e.fit.is_none() || opts.extras.iter().all(|(kind, suffix)| ctx.extra_path(kind, suffix).exists());
        if let Some(entry) = read_record(&rec_path).filter(|e| e.resume.as_ref() == Some(&key) && e.path == spec.key && extras_present(e)) {
            // The record holds the fit: a per-scan fit file deleted since, or left incomplete by a power
            // loss before the run's sync, is written again from it.
            if let Some(fit) = &entry.fit {
                let p = fit_path(&opts.out_dir, spec);
                let complete = std::fs::read(&p).is_ok_and(|b| serde_json::from_slice::<serde::de::IgnoredAny>(&b).is_ok());
                if !complete {
                    write_fit(&p, fit)?;
                }
            }
            return Ok(brief_of(entry, true));
        }
    }
    let t0 = Instant::now();
    let call = || guarded(|| job(spec, &ctx));
    let result = match pool {
        Some(p) => p.install(call),
        None => call(),
    };
    let time_s = t0.elapsed().as_secs_f64();
    let mut entry = Entry {
        path: spec.key.clone(),
        status: Status::Ok,
        fit: None,
        error: None,
        error_kind: None,
        quality: None,
        baseline: None,
        file: spec.file.display().to_string(),
        time_s,
        resume: Some(key),
    };
    let mut same_bins = None;
    match result {
        Ok(out) => {
            entry.fit = Some(out.fit);
            entry.quality = out.quality;
            same_bins = out.baseline_on_same_bins;
        }
        Err(f) => {
            entry.status = Status::Error;
            entry.error = Some(f.message);
            entry.error_kind = Some(f.kind);
        }
    }
    if has_baseline {
        let cur = Current { status: entry.status, fit: entry.fit.as_ref(), quality: entry.quality, baseline_on_same_bins: same_bins };
        entry.baseline = Some(compare(cur, base, &opts.tolerances));
    }
    if let Some(fit) = &entry.fit {
        write_fit(&fit_path(&opts.out_dir, spec), fit)?;
    }
    make_parent(&rec_path)?;
    // The record goes last: its presence means the scan's files are complete (what --resume trusts).
    write_atomic_unsynced(&rec_path, |w| serde_json::to_writer(&mut *w, &entry).map_err(|e| Error::io(e.into())))?;
    Ok(brief_of(entry, false))
}

fn write_fit(p: &Path, fit: &Value) -> Result<()> {
    make_parent(p)?;
    write_atomic_unsynced(p, |w| {
        serde_json::to_writer_pretty(&mut *w, fit).map_err(|e| Error::io(e.into()))?;
        w.write_all(b"\n").map_err(Error::io)
    })
}

fn make_parent(p: &Path) -> Result<()> {
    match p.parent() {
        Some(d) => std::fs::create_dir_all(d).map_err(|e| Error::io(e).with_path(d)),
        None => Ok(()),
    }
}

/// Run `f`, turning a panic into a `panic` failure with its message and location.
fn guarded<T>(f: impl FnOnce() -> std::result::Result<T, JobFailure>) -> std::result::Result<T, JobFailure> {
    IN_JOB.with(|c| c.set(true));
    let r = catch_unwind(AssertUnwindSafe(f));
    IN_JOB.with(|c| c.set(false));
    match r {
        Ok(r) => r,
        Err(payload) => {
            let msg = payload
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| payload.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "non-text panic payload".to_string());
            let at = PANIC_AT.with(Cell::take).map(|l| format!(" at {l}")).unwrap_or_default();
            Err(JobFailure::new("panic", format!("internal error (panic{at}): {msg}")))
        }
    }
}

/// A finished record, or `None` when absent or unreadable (then the scan is run again).
pub fn read_record(path: &Path) -> Option<Entry> {
    let bytes = std::fs::read(path).ok()?;
    serde_json::from_slice(&bytes).ok()
}

/// The small summary of an entry.
pub fn brief_of(mut entry: Entry, reused: bool) -> Brief {
    let fit = entry.fit.take();
    entry.resume = None;
    let f = fit.as_ref();
    let get = |k: &str| f.and_then(|f| f.get(k));
    let model = get("model").and_then(Value::as_str).map(str::to_string);
    let params = get("params")
        .and_then(Value::as_object)
        .map(|o| o.iter().filter_map(|(k, v)| v.as_f64().map(|x| (k.clone(), x))).collect())
        .unwrap_or_default();
    let stderr = f.map(super::compare::stderr_of).unwrap_or_default();
    let find = |keys: &[&str]| -> Option<&Value> {
        keys.iter().find_map(|k| {
            let mut v = f;
            for part in k.split('.') {
                v = v.and_then(|x| x.get(part));
            }
            v
        })
    };
    let termination = find(&["solver.termination", "termination"]).map(|v| v.as_str().map(str::to_string).unwrap_or_else(|| v.to_string()));
    let evaluations = find(&["solver.evaluations", "evaluations"]).and_then(Value::as_u64);
    let reduced_chi2 = find(&["quality.reduced_chi2", "reduced_chi2"]).and_then(Value::as_f64);
    let fit_verdict = find(&["quality.verdict"]).and_then(Value::as_str).map(str::to_string);
    let answer = find(&["selection.answer"]).and_then(Value::as_str).map(str::to_string);
    let regime = find(&["optics.regime"]).and_then(Value::as_str).map(str::to_string);
    Brief { entry, model, params, stderr, termination, evaluations, reduced_chi2, fit_verdict, answer, regime, reused }
}

/// Remove temporary files an interrupted run left (write_atomic names them `.<name>.<random>.tmp`).
/// Refuse distinct keys whose output files would be the same (`a:b.x3p` and `a_b.x3p`, `x/../y` and
/// `x/_/y`, `a//b` and `a/b`): one scan's results would overwrite the other's. Both scans are named.
pub fn check_output_names(specs: &[ScanSpec]) -> Result<()> {
    let mut seen: std::collections::HashMap<PathBuf, &ScanSpec> = std::collections::HashMap::with_capacity(specs.len());
    for s in specs {
        if let Some(other) = seen.insert(s.out_rel(), s) {
            return Err(Error::invalid(format!(
                "scans '{}' ({}) and '{}' ({}) would write the same output files ({}); rename one (or give distinct ids in a manifest)",
                other.key,
                other.file.display(),
                s.key,
                s.file.display(),
                s.out_rel().display()
            )));
        }
    }
    Ok(())
}

/// The name of the lock file a batch holds in its output folder.
pub const LOCK_FILE: &str = ".ndfit-batch.lock";

/// An exclusive lock on a batch output folder, held until dropped: two batches never write one folder.
#[derive(Debug)]
pub struct OutDirLock {
    _file: std::fs::File,
}

/// Create `dir` if needed and lock it for this batch; a second batch on the same folder is refused with
/// one line instead of mixing its results into the first one's.
pub fn lock_out_dir(dir: &Path) -> Result<OutDirLock> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(e).with_path(dir))?;
    let path = dir.join(LOCK_FILE);
    let file =
        std::fs::OpenOptions::new().create(true).truncate(false).write(true).open(&path).map_err(|e| Error::io(e).with_path(&path))?;
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        // SAFETY: flock on the descriptor of a file this function owns; the lock ends when it is closed.
        if unsafe { libc::flock(file.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) } != 0 {
            return Err(Error::new(
                crate::ErrorKind::Io,
                "another ndfit batch is writing this output folder (it holds .ndfit-batch.lock); wait for it or choose another -o",
            )
            .with_path(dir));
        }
    }
    Ok(OutDirLock { _file: file })
}

fn remove_stale_temps(dir: &Path) {
    let Ok(rd) = std::fs::read_dir(dir) else { return };
    for e in rd.flatten() {
        let p = e.path();
        let name = e.file_name().to_string_lossy().into_owned();
        match e.file_type() {
            Ok(t) if t.is_dir() => remove_stale_temps(&p),
            Ok(t) if t.is_file() && name.starts_with('.') && name.ends_with(".tmp") => {
                let _ = std::fs::remove_file(&p);
            }
            _ => {}
        }
    }
}
