//! `ndfit batch DIR|MANIFEST.csv -o OUT_DIR [--model MODEL] [--jobs N] [--baseline FILE] [--resume]`:
//! fit every scan, write `OUT_DIR/summary.json` and `summary.csv`, compare against a baseline, and exit
//! 0 (clean), 1 (some fit regressed) or 2 (some scan could not be read or fitted). See
//! `data_formats/batch.md`.

mod job;
mod worker;

use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use anyhow::Context;
use ndfit::batch::{self, summary, Baseline, RunOptions, ScanSpec, Tolerances};

pub use job::JobConfig;

/// How each scan's job is isolated from the others.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum Isolate {
    /// In this process, on a worker thread; a panic is caught and becomes the scan's error entry.
    Thread,
    /// In a child `ndfit` process per scan: also survives aborts, stack overflows and crashes, and
    /// enforces `--timeout`. Costs one process start per scan.
    Process,
}

/// Arguments of `ndfit batch`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A folder of scans (searched recursively; files recognised by format) or a manifest CSV with a
    /// `path` column and per-scan options (see data_formats/batch.md).
    #[arg(required_unless_present = "worker")]
    pub input: Option<PathBuf>,
    /// Output folder: summary.json, summary.csv, fits/, scans/ (per-scan records), optional ndf/.
    #[arg(short = 'o', long = "out", required_unless_present = "worker")]
    pub out: Option<PathBuf>,
    /// Model to fit, as `ndfit fit --model`. A manifest's `model` column overrides it per scan.
    #[arg(
        long,
        default_value = "auto",
        help = format!("{} A manifest's `model` column overrides it per scan; --tolerance goes with the scan options after `--`.",
            super::model_help())
    )]
    pub model: String,
    /// Scans fitted at once (default: the number of cores). Results do not depend on it.
    #[arg(long, short = 'j')]
    pub jobs: Option<usize>,
    /// An earlier run's summary.json to compare against: exit 1 when some fit regressed.
    #[arg(long)]
    pub baseline: Option<PathBuf>,
    /// Skip scans whose record in OUT_DIR is finished and still matches (same settings, file, baseline).
    #[arg(long)]
    pub resume: bool,
    /// Absolute tolerance on the quality measure kl (nats; 5e-5 is a 1% RMS change of D).
    #[arg(long, default_value_t = Tolerances::default().kl_abs)]
    pub tol_kl: f64,
    /// Tolerance on kl relative to the baseline's kl.
    #[arg(long, default_value_t = Tolerances::default().kl_rel)]
    pub tol_kl_rel: f64,
    /// A parameter changed when it moved by more than this many combined standard errors.
    #[arg(long, default_value_t = Tolerances::default().param_sigma)]
    pub tol_sigma: f64,
    /// Count parameter changes beyond --tol-sigma as regressions (exit 1), not only report them.
    #[arg(long)]
    pub params_regress: bool,
    /// Do not count baseline scans missing from this run as a regression.
    #[arg(long)]
    pub allow_missing: bool,
    /// Print every scan in the regression table, not only those that differ.
    #[arg(long)]
    pub table_all: bool,
    /// Also write each scan's empirical NDF as OUT_DIR/ndf/<path>.ndf.csv.
    #[arg(long)]
    pub write_ndf: bool,
    /// Also plot each scan's data against its fit as OUT_DIR/plots/<path>.png.
    #[arg(long)]
    pub plots: bool,
    /// Isolation of each scan's job.
    #[arg(long, value_enum, default_value = "thread")]
    pub isolate: Isolate,
    /// With --isolate process: give up on a scan after this many seconds (an `error` entry).
    #[arg(long)]
    pub timeout: Option<f64>,
    /// Options applied to every scan: reading and preprocessing (--dx, --dy, --z-scale, --format, --form,
    /// --crop, --subsample), the NDF (--normals, --ndf-cells, --target-count) and the fit (--objective,
    /// --solver, --extra-starts, --max-theta, --na, --tail, --tolerance, --preset) and auto's render choice
    /// (--scene, --render-tolerance, --material), e.g.
    /// `-- --dx 1e-6 --form poly2`.
    #[arg(last = true)]
    pub scan_options: Vec<String>,
    /// Internal: run one scan's job from a request on standard input (used by --isolate process).
    #[arg(long, hide = true)]
    pub worker: bool,
    /// Testing aid: sleep this many milliseconds in each scan's job (to interrupt a batch midway).
    #[arg(long, hide = true, default_value_t = 0)]
    pub debug_delay_ms: u64,
    /// Testing aid: abort the process inside the job of the scan with this key (shows what
    /// --isolate process survives).
    #[arg(long, hide = true)]
    pub debug_abort: Option<String>,
}

/// Run `ndfit batch`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    batch::install_panic_hook();
    if args.worker {
        return worker::serve();
    }
    let (Some(input), Some(out)) = (args.input.clone(), args.out.clone()) else {
        anyhow::bail!("batch needs an input folder or manifest and -o OUT_DIR");
    };
    let model = args.model.clone();
    check_model(&model).context("--model")?;
    let jobs = match args.jobs {
        Some(0) => anyhow::bail!("--jobs must be at least 1"),
        Some(n) => n,
        None => std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1),
    };
    if let Some(t) = args.timeout {
        anyhow::ensure!(t.is_finite() && t > 0.0, "--timeout must be a positive number of seconds");
        anyhow::ensure!(Duration::try_from_secs_f64(t).is_ok_and(|d| d.as_secs() < 1 << 40), "--timeout {t} is too long a time");
        anyhow::ensure!(args.isolate == Isolate::Process, "--timeout needs --isolate process");
    }
    let tolerances = Tolerances {
        kl_abs: args.tol_kl,
        kl_rel: args.tol_kl_rel,
        param_sigma: args.tol_sigma,
        params_regress: args.params_regress,
        ..Tolerances::default()
    };
    anyhow::ensure!(
        [tolerances.kl_abs, tolerances.kl_rel, tolerances.param_sigma].iter().all(|t| t.is_finite() && *t >= 0.0),
        "tolerances must be finite and non-negative"
    );

    let specs = collect_specs(&input, &out)?;
    anyhow::ensure!(!specs.is_empty(), "{}: no scans found", input.display());
    batch::runner::check_output_names(&specs)?;
    let _lock = batch::runner::lock_out_dir(&out)?;
    let cfg = JobConfig {
        model: model.clone(),
        scan_options: args.scan_options.clone(),
        write_ndf: args.write_ndf,
        plots: args.plots,
        debug_delay_ms: args.debug_delay_ms,
        debug_abort: args.debug_abort.clone(),
    };
    // Every per-scan option is checked before anything runs, so a typo fails the run at once.
    for s in &specs {
        job::parse_scan_options(&cfg, s).map_err(|f| anyhow::anyhow!("{}", f.message))?;
        if let Some(m) = &s.model {
            check_model(m).with_context(|| format!("{}: model", s.key))?;
        }
    }
    let baseline = match &args.baseline {
        Some(p) => Some(Baseline::read(p)?),
        None => None,
    };
    let settings = serde_json::json!({
        "ndfit": env!("CARGO_PKG_VERSION"),
        "config": cfg.settings(),
        "baseline": baseline.is_some(),
    })
    .to_string();
    let mut extras = Vec::new();
    if args.write_ndf {
        extras.push(("ndf".to_string(), ".ndf.csv".to_string()));
    }
    if args.plots {
        extras.push(("plots".to_string(), ".png".to_string()));
    }
    let opts = RunOptions { out_dir: out.clone(), jobs, resume: args.resume, settings, tolerances, extras };

    let bar = progress_bar(specs.len() as u64);
    let progress = |p: batch::runner::Progress<'_>| {
        let e = &p.brief.entry;
        let what = match (&e.error, p.brief.reused) {
            (Some(_), _) => format!("error {}", e.path),
            (None, true) => format!("ok (resumed) {}", e.path),
            (None, false) => format!("ok {} ({:.2} s)", e.path, e.time_s),
        };
        match &bar {
            Some(b) => {
                b.set_message(e.path.clone());
                b.inc(1);
            }
            None => eprintln!("ndfit batch: [{}/{}] {what}", p.done, p.total),
        }
    };
    let timeout = args.timeout.map(Duration::from_secs_f64);
    let outcome = match args.isolate {
        Isolate::Thread => batch::run(&specs, baseline.as_ref(), &|s, c| job::fit_scan(&cfg, s, c), &opts, &progress)?,
        Isolate::Process => {
            let exe = std::env::current_exe().context("cannot find the ndfit executable for --isolate process")?;
            batch::run(&specs, baseline.as_ref(), &|s, c| worker::run_in_child(&exe, &cfg, s, c, timeout), &opts, &progress)?
        }
    };
    if let Some(b) = &bar {
        b.finish_and_clear();
    }

    let allow_missing = args.allow_missing || baseline.is_none();
    let code = outcome.exit_code(allow_missing);
    let header = summary::Header {
        schema: summary::SCHEMA,
        ndfit_version: env!("CARGO_PKG_VERSION"),
        input: input.display().to_string(),
        model,
        baseline: args.baseline.as_ref().map(|p| p.display().to_string()),
        tolerances,
        counts: outcome.counts(),
        exit_status: code,
        missing_from_run: outcome.missing.clone(),
    };
    summary::write_summary_json(&out, &header, &outcome)?;
    summary::write_summary_csv(&out, &outcome)?;

    // The summary is written: a closed standard output only loses the table, never the exit status.
    let table = if baseline.is_some() {
        summary::regression_table(&outcome, args.table_all)
    } else {
        let c = outcome.counts();
        format!("{} scans: {} ok, {} error\n", c.scans, c.ok, c.error)
    };
    match super::write_stdout(table.as_bytes()) {
        Err(e) if e.downcast_ref::<super::StdoutClosed>().is_none() => return Err(e),
        _ => {}
    }
    for b in outcome.briefs.iter().filter(|b| b.entry.error.is_some()) {
        eprintln!("ndfit: {}", super::one_line(b.entry.error.as_deref().unwrap_or_default()));
    }
    if !allow_missing && !outcome.missing.is_empty() {
        eprintln!("ndfit batch: {} baseline scan(s) missing from this run (--allow-missing to accept)", outcome.missing.len());
    }
    Ok(ExitCode::from(code))
}

/// The scans of a folder (walked) or a manifest (`.csv` file). The output folder is never walked.
fn collect_specs(input: &Path, out: &Path) -> anyhow::Result<Vec<ScanSpec>> {
    if input.is_file() {
        return Ok(batch::manifest::read_manifest(input)?);
    }
    Ok(batch::discover::walk(input, &[out.to_path_buf()], &detect_by_content)?)
}

/// Whether a file without a scan extension is a scan by its content: the readers' magic-byte detection
/// on its first 512 bytes (the extension is deliberately not passed, so only content counts). Files whose
/// extension says they are something else (documents, archives, our own outputs) are never scans.
fn detect_by_content(path: &Path) -> bool {
    const NOT_SCANS: &[&str] = &["json", "md", "txt", "csv", "zip", "pdf", "html", "png", "log", "toml", "yaml", "yml", "py", "rs", "sh"];
    let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    if NOT_SCANS.contains(&ext.as_str()) {
        return false;
    }
    let mut head = [0u8; 512];
    let n = match std::fs::File::open(path).and_then(|mut f| std::io::Read::read(&mut f, &mut head)) {
        Ok(n) => n,
        Err(_) => return false,
    };
    ndfit::io::detect(Path::new(""), &head[..n]).is_some()
}

fn check_model(m: &str) -> anyhow::Result<()> {
    m.parse::<ndfit::models::ModelChoice>().map(|_| ()).map_err(|e| anyhow::anyhow!("{}", e.message()))
}

/// An indicatif bar on a terminal; `None` (plain lines) otherwise.
fn progress_bar(n: u64) -> Option<indicatif::ProgressBar> {
    if !std::io::stderr().is_terminal() {
        return None;
    }
    let b = indicatif::ProgressBar::new(n);
    if let Ok(style) = indicatif::ProgressStyle::with_template("{bar:30} {pos}/{len} scans, {elapsed} elapsed, eta {eta}  {wide_msg}") {
        b.set_style(style);
    }
    Some(b)
}
