//! `ndfit bench`: the speed/accuracy sweep, its CSV, the Pareto plot, the cost model and the same-run
//! comparison with the numpy + nlopt pipeline.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use ndfit::bench::accuracy::RefNodes;
use ndfit::bench::analysis::{cost_model, pareto_front};
use ndfit::bench::numpy::{compare, default_script, Comparison, THROUGHPUT_TARGET_MPTS};
use ndfit::bench::plot::{label_of, plot_pareto};
use ndfit::bench::scene::Scene;
use ndfit::bench::sweep::{self, Isolation, Plan, Row, REF_CELLS};
use ndfit::bench::{pipeline, Knobs};

/// Arguments of `ndfit bench`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Small scans, one repetition: seconds (the sanity run the tests use). Without it, the full sweep
    /// of docs/PERFORMANCE.md (512^2 to 8192^2, three repetitions; tens of minutes on 2 cores).
    #[arg(long)]
    pub quick: bool,
    /// Output folder: bench.csv, pareto.png, summary.json.
    #[arg(short, long, default_value = "bench_out")]
    pub out: PathBuf,
    /// Scan sides of the size sweep (comma-separated), instead of the plan's.
    #[arg(long, value_delimiter = ',')]
    pub sizes: Option<Vec<usize>>,
    /// Scan side of the knob sweep, instead of the plan's.
    #[arg(long)]
    pub knob_size: Option<usize>,
    /// Repetitions per point (median reported), instead of the plan's.
    #[arg(long)]
    pub repeats: Option<usize>,
    /// Python with numpy and nlopt: also run fits/numpy_pipeline.py on the same scans for the ratios.
    #[arg(long, value_name = "PYTHON")]
    pub numpy: Option<PathBuf>,
    /// The numpy pipeline script (default: fits/numpy_pipeline.py).
    #[arg(long)]
    pub numpy_script: Option<PathBuf>,
    /// Scan side of the scan -> NDF comparison (default 4096, quick 256).
    #[arg(long)]
    pub numpy_ndf_size: Option<usize>,
    /// Scan side of the scan -> ellipsoid fit comparison (default 1024, quick 128).
    #[arg(long)]
    pub numpy_fit_size: Option<usize>,
    /// Folder for the scans, kept there after the run (default: a temporary folder inside --out,
    /// removed).
    #[arg(long)]
    pub work_dir: Option<PathBuf>,
    /// Measure every point in this process instead of a fresh child process per point (faster to
    /// start; peak memory then undercounts what the allocator kept from earlier points).
    #[arg(long)]
    pub in_process: bool,
    /// Measure nothing: read an earlier run's bench.csv and redo the front, plot and cost model from it
    /// (writes pareto.png and front.json into --out).
    #[arg(long, value_name = "CSV")]
    pub from_csv: Option<PathBuf>,
    /// After the run (or with --from-csv), copy bench.csv, pareto.png and summary.json beside this page
    /// (as bench.csv, pareto.png, bench_summary.json) and regenerate its tables between the
    /// `<!-- bench:NAME -->` markers (`docs/PERFORMANCE.md`; see `ndfit::bench::report`).
    #[arg(long, value_name = "DOC")]
    pub update_doc: Option<PathBuf>,
    /// Whole processes instead of the sweep: `ndfit fit` and `ndfit batch --jobs 2` on deflated X3P scans
    /// against the floor of the input (`unzip -p` of the height data alone) and, with --numpy, the numpy
    /// pool, interleaved, medians and peak RSS (`ndfit::bench::floors`); writes process.json and process.md.
    #[arg(long)]
    pub process: bool,
    /// With --process: scan side (default 1024, quick 256).
    #[arg(long)]
    pub process_size: Option<usize>,
    /// With --process: scans in the batch set (default 64, quick 8).
    #[arg(long)]
    pub process_scans: Option<usize>,
    /// The tracer's throughput instead of the sweep (`ndfit::bench::trace`): one-bounce paths per second
    /// per core on a 2048^2 Gaussian scan (one thread, then every thread), and a 4096^2 scan at 16
    /// incidences with `ndfit trace`'s defaults; writes trace.json and trace.md (--quick: small scans).
    #[arg(long)]
    pub trace: bool,
    /// Wave optics instead of the sweep (`ndfit::bench::wave`): `ndfit wave` against the numpy
    /// `ndfitpy.wave` (Python: --numpy, else fits/.venv) as whole processes on a 4096^2 synthetic scan
    /// (0.1 um spacing) and the shared real scans, ndfit's peak memory against the heights' bytes, and the
    /// accuracy cost of `--level-ratio` (2048^2 and one real scan); writes wave.json and wave.md
    /// (--quick: 2048^2, one run each).
    #[arg(long)]
    pub wave: bool,
    /// What `auto`'s answer costs (`ndfit::bench::answer`): `ndfit fit SCAN` (auto: optics, ladder, render
    /// choice) and `ndfit fit SCAN --scene none` (the ladder alone) against `ndfit fit SCAN --model
    /// ggx-aniso` as whole processes, interleaved, on the shared real scans and fresh synthetic truths (seed
    /// from the clock); writes answer.json and answer.md
    #[arg(long)]
    pub answer: bool,
    /// With --answer: side of the fresh truths (default 512, quick 128).
    #[arg(long)]
    pub answer_size: Option<usize>,
    /// With --wave: side of the synthetic speed scan (default 4096, quick 2048).
    #[arg(long)]
    pub wave_size: Option<usize>,
    /// With --wave: side of the synthetic scan of the level-ratio sweep (default 2048).
    #[arg(long)]
    pub wave_level_size: Option<usize>,
    /// With --wave: the real scans, comma-separated, or `none` (default: ../shared/data/scans/st_x3p-2.x3p
    /// and st_plu-1.plu; missing ones are skipped with a note).
    #[arg(long, value_delimiter = ',')]
    pub wave_scans: Option<Vec<PathBuf>>,
    /// Internal: measure one point (JSON) and print its row as JSON (how the isolated sweep runs).
    #[arg(long, hide = true)]
    pub child_point: Option<String>,
}

/// Everything `summary.json` holds besides the CSV.
#[derive(Debug, serde::Serialize)]
struct Summary {
    schema: &'static str,
    quick: bool,
    machine: Machine,
    plan_sizes: Vec<usize>,
    knob_size: usize,
    repeats: usize,
    pareto_front: Vec<Row>,
    presets: Vec<Row>,
    balanced_vs_accurate_fit_delta: Option<f64>,
    cost_model: Vec<ndfit::bench::analysis::Exponent>,
    numpy: Vec<Comparison>,
    /// Wall time of the whole run (s).
    wall_s: f64,
}

#[derive(Debug, serde::Serialize)]
struct Machine {
    cpu: String,
    threads: usize,
    os: String,
    ndfit: &'static str,
    profile: &'static str,
    /// `/proc/loadavg` (1, 5, 15 minutes) when the run started and ended: the machine's other load.
    loadavg_start: Option<[f64; 3]>,
    loadavg_end: Option<[f64; 3]>,
}

/// The 1, 5 and 15 minute load averages (`None` without /proc).
fn loadavg() -> Option<[f64; 3]> {
    let s = std::fs::read_to_string("/proc/loadavg").ok()?;
    let mut it = s.split_whitespace().map(|v| v.parse::<f64>().ok());
    Some([it.next()??, it.next()??, it.next()??])
}

fn machine(loadavg_start: Option<[f64; 3]>) -> Machine {
    let cpu = std::fs::read_to_string("/proc/cpuinfo")
        .ok()
        .and_then(|s| s.lines().find(|l| l.starts_with("model name")).and_then(|l| l.split(':').nth(1)).map(|s| s.trim().to_string()))
        .unwrap_or_else(|| "unknown".into());
    Machine {
        cpu,
        threads: rayon::current_num_threads(),
        os: std::env::consts::OS.into(),
        ndfit: env!("CARGO_PKG_VERSION"),
        profile: if cfg!(debug_assertions) { "debug" } else { "release" },
        loadavg_start,
        loadavg_end: loadavg(),
    }
}

/// Run `ndfit bench`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    if let Some(json) = &args.child_point {
        let p: sweep::ChildPoint = serde_json::from_str(json).context("--child-point: unreadable point")?;
        let row = sweep::run_child_point(&p)?;
        super::write_stdout((serde_json::to_string(&row).context("row JSON")? + "\n").as_bytes())?;
        return Ok(ExitCode::SUCCESS);
    }
    if let Some(csv_in) = &args.from_csv {
        return replot(csv_in, &args.out, args.update_doc.as_deref());
    }
    if args.process {
        return process(&args);
    }
    if args.trace {
        return trace(&args);
    }
    if args.answer {
        return answer(&args);
    }
    if args.wave {
        return wave(&args);
    }
    let started = std::time::Instant::now();
    let load0 = loadavg();
    let mut plan = if args.quick { Plan::quick() } else { Plan::full() };
    if let Some(s) = &args.sizes {
        anyhow::ensure!(!s.is_empty() && s.iter().all(|&v| (16..=32768).contains(&v)), "--sizes: each side must be 16 to 32768");
        plan.sizes = s.clone();
    }
    if let Some(k) = args.knob_size {
        anyhow::ensure!((16..=32768).contains(&k), "--knob-size must be 16 to 32768");
        plan.knob_size = k;
    }
    if let Some(r) = args.repeats {
        anyhow::ensure!(r >= 1, "--repeats must be at least 1");
        plan.repeats = r;
    }
    std::fs::create_dir_all(&args.out).with_context(|| format!("{}: cannot create the output folder", args.out.display()))?;
    let tmp;
    let work = match &args.work_dir {
        Some(d) => {
            std::fs::create_dir_all(d).with_context(|| format!("{}: cannot create the work folder", d.display()))?;
            d.clone()
        }
        None => {
            tmp = tempfile::Builder::new().prefix(".bench-scans.").tempdir_in(&args.out).context("cannot create a temporary folder")?;
            tmp.path().to_path_buf()
        }
    };

    let stderr = std::io::stderr();
    let iso = if args.in_process {
        Isolation::InProcess
    } else {
        Isolation::Child(std::env::current_exe().context("cannot find the ndfit executable to run points in")?)
    };
    let rows = sweep::run(&plan, &work, &iso, args.work_dir.is_some(), |r| {
        let _ = writeln!(
            stderr.lock(),
            "{:>12} {:>5} {:<14} total {:>9.1} ms (read {:>7.1}, ndf {:>7.1}, fit {:>7.1})  {:>6.1} Mpts/s  ndf_delta {:<8} fit_delta {}",
            r.group,
            r.size,
            label_of(r),
            r.t_total_ms,
            r.t_read_ms,
            r.t_ndf_ms,
            r.t_fit_ms,
            r.ndf_mpts_per_s,
            fmt_opt(r.ndf_delta),
            fmt_opt(r.fit_delta)
        );
    })?;

    let csv_path = args.out.join("bench.csv");
    ndfit::io::write_atomic(&csv_path, |w| {
        let mut wr = csv::Writer::from_writer(w);
        for r in &rows {
            wr.serialize(r).map_err(|e| ndfit::Error::invalid(format!("CSV: {e}")))?;
        }
        wr.flush().map_err(ndfit::Error::io)?;
        Ok(())
    })?;

    // The front over the knob sweep at one size: every row of that size with a fit.
    let knob_rows: Vec<Row> = rows.iter().filter(|r| r.size == plan.knob_size && !r.model.is_empty()).cloned().collect();
    let front = pareto_front(&knob_rows, |r| r.t_total_ms, |r| r.fit_delta);
    let png = args.out.join("pareto.png");
    plot_pareto(&png, &knob_rows, &front, &format!("ndfit: time against fit error, {0}x{0} synthetic ellipsoid scan", plan.knob_size))?;
    let presets: Vec<Row> = rows.iter().filter(|r| r.group.starts_with("preset_")).cloned().collect();
    let get = |name: &str| presets.iter().find(|r| r.group == format!("preset_{name}")).and_then(|r| r.fit_delta);
    let bal_vs_acc = match (get("balanced"), get("accurate")) {
        (Some(b), Some(a)) if a > 0.0 => Some(b / a - 1.0),
        _ => None,
    };

    let mut comparisons = Vec::new();
    if let Some(py) = &args.numpy {
        let script = args.numpy_script.clone().unwrap_or_else(default_script);
        let ndf_size = args.numpy_ndf_size.unwrap_or(if args.quick { 256 } else { 4096 });
        let fit_size = args.numpy_fit_size.unwrap_or(if args.quick { 128 } else { 1024 });
        for (size, fit) in [(ndf_size, false), (fit_size, true)] {
            let scene = Scene::create(&work, size)?;
            let frame = pipeline::run(&scene.path, &scene.read_options(), &Knobs { size, model: None, ..Knobs::default() })?.ndf.frame;
            let nodes = RefNodes::new(&frame, REF_CELLS);
            for c in compare(py, &script, &scene, &nodes, fit, plan.repeats)? {
                eprintln!(
                    "numpy {:>4} {:>5} ({}): ndfit {:>9.1} ms, numpy {:>9.1} ms, ratio {:.1}x (target >= {}x{} at {}^2): {}  fit_delta ndfit {} numpy {}",
                    c.task,
                    c.size,
                    c.preset,
                    if fit { c.ndfit.total() } else { c.ndfit.read + c.ndfit.ndf },
                    if fit { c.numpy.t_total_ms } else { c.numpy.t_ndf_ms },
                    c.ratio,
                    c.target.required,
                    c.target.aim.map_or(String::new(), |a| format!(", aim {a}x")),
                    c.target.size,
                    match c.met {
                        Some(true) => "MET",
                        Some(false) => "NOT MET",
                        None if c.preset == "fast" => "not judged (fast preset, for information)",
                        None => "not judged at this size",
                    },
                    fmt_opt(c.ndfit_fit_delta),
                    fmt_opt(c.numpy_fit_delta)
                );
                if !fit {
                    eprintln!(
                        "ndf throughput {:>5}: {:.1} M grid points/s ({:.1} M normals/s) in the NDF stage (target >= {} M/s at 4096^2): {}",
                        c.size,
                        c.ndf_grid_mpts_per_s,
                        c.ndf_normals_mpts_per_s,
                        THROUGHPUT_TARGET_MPTS,
                        match (c.met, c.ndf_grid_mpts_per_s >= THROUGHPUT_TARGET_MPTS) {
                            (None, _) => "not judged at this size",
                            (_, true) => "MET",
                            (_, false) => "NOT MET",
                        }
                    );
                }
                comparisons.push(c);
            }
            if args.work_dir.is_none() {
                let _ = std::fs::remove_file(&scene.path);
            }
        }
    }

    let summary = Summary {
        schema: "ndfit.bench/1",
        quick: args.quick,
        machine: machine(load0),
        plan_sizes: plan.sizes.clone(),
        knob_size: plan.knob_size,
        repeats: plan.repeats,
        pareto_front: front.iter().map(|&i| knob_rows[i].clone()).collect(),
        presets,
        balanced_vs_accurate_fit_delta: bal_vs_acc,
        cost_model: cost_model(&rows),
        numpy: comparisons,
        wall_s: started.elapsed().as_secs_f64(),
    };
    let json = serde_json::to_string_pretty(&summary).context("summary JSON")?;
    ndfit::io::write_bytes_atomic(&args.out.join("summary.json"), json.as_bytes())?;
    for e in &summary.cost_model {
        eprintln!("cost model: {} ~ {}^{:.2} ({} points)", e.quantity, e.against, e.exponent, e.n);
    }
    eprintln!("wrote {}, {}, {}", csv_path.display(), png.display(), args.out.join("summary.json").display());
    if let Some(doc) = &args.update_doc {
        let value = serde_json::to_value(&summary).context("summary JSON")?;
        update_doc(doc, &rows, &value, &csv_path, &png, &args.out.join("summary.json"))?;
    }
    Ok(ExitCode::SUCCESS)
}

/// `--update-doc`: copy the run's files beside `doc` and regenerate its tables.
fn update_doc(
    doc: &std::path::Path,
    rows: &[Row],
    summary: &serde_json::Value,
    csv: &std::path::Path,
    png: &std::path::Path,
    json: &std::path::Path,
) -> anyhow::Result<()> {
    let dir = doc.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(std::path::Path::new("."));
    for (from, name) in [(csv, "bench.csv"), (png, "pareto.png"), (json, "bench_summary.json")] {
        let to = dir.join(name);
        // Copying a file onto itself (re-rendering the page's own files) would truncate it: skip.
        let same = std::fs::canonicalize(from).ok().zip(std::fs::canonicalize(&to).ok()).is_some_and(|(a, b)| a == b);
        if !same && from.is_file() {
            let bytes = std::fs::read(from).with_context(|| format!("{}: cannot read", from.display()))?;
            ndfit::io::write_bytes_atomic(&to, &bytes)?;
        }
    }
    let done = ndfit::bench::report::update_doc(doc, &ndfit::bench::report::render(rows, summary))?;
    eprintln!("updated {} (sections: {})", doc.display(), done.join(", "));
    Ok(())
}

/// `--from-csv`: the front, plot and cost model of an earlier run (and, with `--update-doc`, the page's
/// tables from it and the `summary.json` beside the CSV, when there is one).
fn replot(csv_in: &std::path::Path, out: &std::path::Path, doc: Option<&std::path::Path>) -> anyhow::Result<ExitCode> {
    let mut rd = csv::Reader::from_path(csv_in).with_context(|| format!("{}: cannot open", csv_in.display()))?;
    let rows: Vec<Row> = rd.deserialize().collect::<Result<_, _>>().with_context(|| format!("{}: not a bench.csv", csv_in.display()))?;
    let knob_size = rows
        .iter()
        .find(|r| r.group == "preset_balanced")
        .map(|r| r.size)
        .with_context(|| format!("{}: no preset_balanced row", csv_in.display()))?;
    std::fs::create_dir_all(out).with_context(|| format!("{}: cannot create the output folder", out.display()))?;
    let knob_rows: Vec<Row> = rows.iter().filter(|r| r.size == knob_size && !r.model.is_empty()).cloned().collect();
    let front = pareto_front(&knob_rows, |r| r.t_total_ms, |r| r.fit_delta);
    let png = out.join("pareto.png");
    plot_pareto(&png, &knob_rows, &front, &format!("ndfit: time against fit error, {knob_size}x{knob_size} synthetic ellipsoid scan"))?;
    let json = serde_json::json!({
        "pareto_front": front.iter().map(|&i| &knob_rows[i]).collect::<Vec<_>>(),
        "cost_model": cost_model(&rows),
    });
    ndfit::io::write_bytes_atomic(&out.join("front.json"), serde_json::to_string_pretty(&json).context("JSON")?.as_bytes())?;
    eprintln!("wrote {} and {}", png.display(), out.join("front.json").display());
    if let Some(doc) = doc {
        // The run's summary (machine, numpy comparison) sits beside its CSV: summary.json as written by
        // a run, or bench_summary.json as copied into docs/.
        let dir = csv_in.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(std::path::Path::new("."));
        let found = ["summary.json", "bench_summary.json"].iter().map(|n| dir.join(n)).find(|p| p.is_file());
        let mut summary: serde_json::Value = match &found {
            Some(p) => serde_json::from_slice(&std::fs::read(p).with_context(|| format!("{}: cannot read", p.display()))?)
                .with_context(|| format!("{}: not JSON", p.display()))?,
            None => serde_json::json!({}),
        };
        // The cost model is recomputed from the CSV (the summary may predate a change of the analysis).
        summary["cost_model"] = serde_json::to_value(cost_model(&rows)).context("JSON")?;
        // Without a summary nothing is copied as bench_summary.json (an empty path is no file).
        let js = found.unwrap_or_default();
        update_doc(doc, &rows, &summary, csv_in, &png, &js)?;
    }
    Ok(ExitCode::SUCCESS)
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map_or("-".into(), |v| format!("{v:.4}"))
}

/// `--process`: whole-process comparisons against the input's floor (`ndfit::bench::floors`).
fn process(args: &Args) -> anyhow::Result<ExitCode> {
    use ndfit::bench::floors;
    let script = args.numpy_script.clone().unwrap_or_else(default_script);
    let plan = floors::Plan {
        size: args.process_size.unwrap_or(if args.quick { 256 } else { 1024 }),
        scans: args.process_scans.unwrap_or(if args.quick { 8 } else { 64 }),
        repeats: args.repeats.unwrap_or(if args.quick { 3 } else { 11 }),
        batch_repeats: args.repeats.unwrap_or(if args.quick { 2 } else { 5 }),
        jobs: 2,
        python: args.numpy.clone(),
        numpy_pool: script.with_file_name("numpy_pool.py"),
        ndfit: std::env::current_exe().context("cannot find the ndfit executable")?,
    };
    floors::check(&plan)?;
    std::fs::create_dir_all(&args.out).with_context(|| format!("{}: cannot create the output folder", args.out.display()))?;
    let work = args.work_dir.clone().unwrap_or_else(|| args.out.join("process_scans"));
    let report = floors::run(&plan, &work, |l| eprintln!("{l}"))?;
    let md = floors::markdown(&report);
    ndfit::io::write_bytes_atomic(&args.out.join("process.json"), serde_json::to_string_pretty(&report).context("JSON")?.as_bytes())?;
    ndfit::io::write_bytes_atomic(&args.out.join("process.md"), md.as_bytes())?;
    eprint!("{md}");
    eprintln!("wrote {} and {}", args.out.join("process.json").display(), args.out.join("process.md").display());
    Ok(ExitCode::SUCCESS)
}

/// `--trace`: the tracer's throughput (`ndfit::bench::trace`).
fn trace(args: &Args) -> anyhow::Result<ExitCode> {
    use ndfit::bench::trace as tb;
    let plan = if args.quick { tb::TracePlan::quick() } else { tb::TracePlan::full() };
    std::fs::create_dir_all(&args.out).with_context(|| format!("{}: cannot create the output folder", args.out.display()))?;
    let b = tb::run(&plan, |l| eprintln!("{l}"))?;
    let md = tb::markdown(&b);
    ndfit::io::write_bytes_atomic(&args.out.join("trace.json"), serde_json::to_string_pretty(&b).context("JSON")?.as_bytes())?;
    ndfit::io::write_bytes_atomic(&args.out.join("trace.md"), md.as_bytes())?;
    eprint!("{md}");
    eprintln!("wrote {} and {}", args.out.join("trace.json").display(), args.out.join("trace.md").display());
    Ok(ExitCode::SUCCESS)
}

/// `--answer`: `auto` against one `ggx-aniso` fit (`ndfit::bench::answer`).
fn answer(args: &Args) -> anyhow::Result<ExitCode> {
    use ndfit::bench::answer as ab;
    let exe = std::env::current_exe().context("cannot find the ndfit executable")?;
    let dir = ndfit::bench::wave::default_scans().first().and_then(|p| p.parent().map(Path::to_path_buf));
    let mut scans: Vec<PathBuf> = match &dir {
        Some(d) if d.is_dir() => std::fs::read_dir(d)
            .with_context(|| d.display().to_string())?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|e| !matches!(e.to_str(), Some("json" | "md"))))
            .collect(),
        _ => Vec::new(),
    };
    scans.sort();
    let seed = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(1, |d| d.as_secs());
    let plan = ab::AnswerPlan {
        scans,
        size: args.answer_size.unwrap_or(if args.quick { 128 } else { 512 }),
        seed,
        repeats: args.repeats.unwrap_or(if args.quick { 1 } else { 3 }),
        ndfit: exe,
    };
    std::fs::create_dir_all(&args.out).with_context(|| format!("{}: cannot create the output folder", args.out.display()))?;
    let tmp = tempfile::Builder::new().prefix(".bench-answer.").tempdir_in(&args.out).context("cannot create a temporary folder")?;
    let work = args.work_dir.clone().unwrap_or_else(|| tmp.path().to_path_buf());
    let b = ab::run(&plan, &work, |l| eprintln!("{l}"))?;
    let md = ab::markdown(&b);
    ndfit::io::write_bytes_atomic(&args.out.join("answer.json"), serde_json::to_string_pretty(&b).context("JSON")?.as_bytes())?;
    ndfit::io::write_bytes_atomic(&args.out.join("answer.md"), md.as_bytes())?;
    eprint!("{md}");
    eprintln!("wrote {} and {}", args.out.join("answer.json").display(), args.out.join("answer.md").display());
    Ok(ExitCode::SUCCESS)
}

/// `--wave`: `ndfit wave` against numpy and the level ratio's trade (`ndfit::bench::wave`).
fn wave(args: &Args) -> anyhow::Result<ExitCode> {
    use ndfit::bench::wave as wb;
    let exe = std::env::current_exe().context("cannot find the ndfit executable")?;
    let python = args.numpy.clone().or_else(wb::default_python);
    let mut plan = if args.quick { wb::WavePlan::quick(exe, python) } else { wb::WavePlan::full(exe, python) };
    if let Some(n) = args.wave_size {
        plan.size = n;
    }
    if let Some(n) = args.wave_level_size {
        plan.level_size = n;
    }
    if let Some(r) = args.repeats {
        plan.repeats = r;
    }
    if let Some(s) = &args.wave_scans {
        plan.scans = s.iter().filter(|p| p.as_os_str() != "none" && !p.as_os_str().is_empty()).cloned().collect();
    }
    plan.check()?;
    std::fs::create_dir_all(&args.out).with_context(|| format!("{}: cannot create the output folder", args.out.display()))?;
    let tmp;
    let work = match &args.work_dir {
        Some(d) => d.clone(),
        None => {
            tmp = tempfile::Builder::new().prefix(".bench-wave.").tempdir_in(&args.out).context("cannot create a temporary folder")?;
            tmp.path().to_path_buf()
        }
    };
    let b = wb::run(&plan, &work, |l| eprintln!("{l}"))?;
    let md = wb::markdown(&b);
    ndfit::io::write_bytes_atomic(&args.out.join("wave.json"), serde_json::to_string_pretty(&b).context("JSON")?.as_bytes())?;
    ndfit::io::write_bytes_atomic(&args.out.join("wave.md"), md.as_bytes())?;
    eprint!("{md}");
    eprintln!("wrote {} and {}", args.out.join("wave.json").display(), args.out.join("wave.md").display());
    Ok(ExitCode::SUCCESS)
}
