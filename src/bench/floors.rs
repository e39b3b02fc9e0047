//! `ndfit bench --process`: ndfit against the floor of its input, as whole processes in the same run.
//!
//! The floor of a deflated X3P is the time to inflate its height bytes alone: Info-ZIP's
//! `unzip -p SCAN bindata/data.bin > /dev/null`, a whole process like `ndfit fit`. For a batch it is the
//! same inflate over every scan, two processes at a time, beside `ndfit batch --jobs 2` and the numpy +
//! nlopt pool a user would otherwise write (`fits/numpy_pool.py`, which reads the X3P with zipfile +
//! numpy). Every command is run round-robin with the others (`interleave`), medians
//! reported with the load average before and after; peak memory is each child's `ru_maxrss`.

use std::path::{Path, PathBuf};

use super::process::{interleave, interleave_pools, loadavg, Cmd, Measured, Pool};
use crate::error::{Error, ErrorKind, Result};

/// What to measure.
#[derive(Debug, Clone)]
pub struct Plan {
    /// Scan side (the scans are `size` x `size` float64 ellipsoid scenes with noise, data.bin deflated).
    pub size: usize,
    /// Scans in the batch set.
    pub scans: usize,
    /// Runs per command (medians reported); the batch set runs `batch_repeats` times.
    pub repeats: usize,
    /// Runs of each batch-set command.
    pub batch_repeats: usize,
    /// Jobs of the batch and of both pools.
    pub jobs: usize,
    /// Python with numpy and nlopt for the numpy rows (none without).
    pub python: Option<PathBuf>,
    /// The numpy pool script.
    pub numpy_pool: PathBuf,
    /// The ndfit executable measured.
    pub ndfit: PathBuf,
}

/// One whole-process comparison: the measured commands and their ratios to the input's floor and to the numpy pool.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Report {
    /// `ndfit.bench.process/1`.
    pub schema: &'static str,
    /// Scan side, scans in the batch set, jobs.
    pub size: usize,
    /// Scans in the batch set.
    pub scans: usize,
    /// Jobs of the batch set.
    pub jobs: usize,
    /// Bytes of one scan's file and of its height data.
    pub file_bytes: u64,
    /// Bytes of one scan's inflated height data.
    pub data_bytes: u64,
    /// `/proc/loadavg` before and after.
    pub loadavg_start: Option<[f64; 3]>,
    /// `/proc/loadavg` after the run.
    pub loadavg_end: Option<[f64; 3]>,
    /// The single-scan commands.
    pub single: Vec<Measured>,
    /// The batch-set commands.
    pub batch: Vec<Measured>,
    /// `ndfit fit` over `unzip -p` (target at most 1.2).
    pub fit_over_floor: Option<f64>,
    /// `ndfit batch` over the paired `unzip -p` streams (target at most 1.3).
    pub batch_over_floor: Option<f64>,
    /// The numpy pool over `ndfit batch`.
    pub numpy_pool_over_batch: Option<f64>,
    /// numpy over `ndfit fit`, one scan.
    pub numpy_over_fit: Option<f64>,
    /// `ndfit fit --model auto` over one single-lobe fit, `ndfit fit --model ggx-aniso`, on the same
    /// single-lobe scan (target at most 3).
    pub auto_over_single: Option<f64>,
    /// The render choice's cost, `auto` less `auto --scene none`, over one single-lobe fit (target at most
    /// 1.5).
    pub render_over_single: Option<f64>,
}

/// Write the scans of `plan` into `work` (once: existing files are kept) and return the single scan
/// and the batch folder.
pub fn make_scans(plan: &Plan, work: &Path) -> Result<(PathBuf, PathBuf)> {
    let dir = work.join(format!("x3p_{}_deflated", plan.size));
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(e).with_path(&dir))?;
    let name = |k: usize| dir.join(format!("scan{k:03}.x3p"));
    for k in 0..plan.scans.max(1) {
        let out = name(k);
        if out.is_file() {
            continue;
        }
        let stored = work.join(format!(".stored{k}.x3p"));
        let size = plan.size.to_string();
        let seed = (k + 1).to_string();
        super::process::run_once(&Cmd::new(
            "ndfit synth",
            [
                plan.ndfit.as_os_str(),
                "synth".as_ref(),
                "--nx".as_ref(),
                size.as_ref(),
                "--ny".as_ref(),
                size.as_ref(),
                "--noise".as_ref(),
                "2e-9".as_ref(),
                "--seed".as_ref(),
                seed.as_ref(),
                stored.as_os_str(),
            ],
        ))?;
        deflate_x3p(&stored, &out)?;
        let _ = std::fs::remove_file(&stored);
        let _ = std::fs::remove_file(stored.with_extension("truth.json"));
    }
    Ok((name(0), dir))
}

/// Copy the X3P `src` to `dst` with every entry deflated (level 6, Info-ZIP's default), as instrument
/// software writes them.
pub fn deflate_x3p(src: &Path, dst: &Path) -> Result<()> {
    use std::io::{Read, Write};
    let f = std::fs::File::open(src).map_err(|e| Error::io(e).with_path(src))?;
    let mut zin = zip::ZipArchive::new(f).map_err(|e| Error::corrupt(format!("not a zip ({e})")).with_path(src))?;
    let zerr = |e: zip::result::ZipError| Error::invalid(format!("cannot build the zip ({e})")).with_path(dst);
    crate::io::write_atomic(dst, |w| {
        let mut buf = std::io::Cursor::new(Vec::new());
        {
            let mut zw = zip::ZipWriter::new(&mut buf);
            let opts =
                zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated).compression_level(Some(6));
            for i in 0..zin.len() {
                let mut e = zin.by_index(i).map_err(zerr)?;
                let name = e.name().map_err(zerr)?.into_owned();
                if e.is_dir() {
                    zw.add_directory(name, opts).map_err(zerr)?;
                    continue;
                }
                let mut data = Vec::new();
                e.read_to_end(&mut data).map_err(Error::io)?;
                zw.start_file(name, opts).map_err(zerr)?;
                zw.write_all(&data).map_err(Error::io)?;
            }
            zw.finish().map_err(zerr)?;
        }
        w.write_all(buf.get_ref()).map_err(Error::io)
    })
}

/// Whether `prog` runs (`prog -v`-style probe with the given argument).
fn available(prog: &str, arg: &str) -> bool {
    std::process::Command::new(prog)
        .arg(arg)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Run the plan in `work`, reporting each run on `log`.
pub fn run(plan: &Plan, work: &Path, mut log: impl FnMut(&str)) -> Result<Report> {
    let (scan, dir) = make_scans(plan, work)?;
    let file_bytes = std::fs::metadata(&scan).map_err(|e| Error::io(e).with_path(&scan))?.len();
    let data_bytes = (plan.size * plan.size * 8) as u64;
    let scans: Vec<PathBuf> = (0..plan.scans.max(1)).map(|k| dir.join(format!("scan{k:03}.x3p"))).collect();
    let unzip = available("unzip", "-v");
    if !unzip {
        log("unzip (Info-ZIP) not found: the floor rows are skipped");
    }
    let load0 = loadavg();

    // Single scan.
    let out_json = work.join("fit.json");
    let mut cmds = Vec::new();
    if unzip {
        cmds.push(Cmd::new("unzip -p (floor)", ["unzip".as_ref(), "-p".as_ref(), scan.as_os_str(), "bindata/data.bin".as_ref()]));
    }
    cmds.push(Cmd::new(
        "ndfit fit",
        [
            plan.ndfit.as_os_str(),
            "fit".as_ref(),
            scan.as_os_str(),
            "--model".as_ref(),
            "ellipsoid".as_ref(),
            "-o".as_ref(),
            out_json.as_os_str(),
        ],
    ));
    // `auto` against one single-lobe fit, whole processes: the scan is one ellipsoid cap. `auto` with and
    // without its render choice (`--scene none`): their difference is the render scoring's cost.
    for (label, model, scene) in
        [("ggx-aniso", "ggx-aniso", "point,broad"), ("auto", "auto", "point,broad"), ("auto --scene none", "auto", "none")]
    {
        cmds.push(Cmd::new(
            &format!("ndfit fit --model {label}"),
            [
                plan.ndfit.as_os_str(),
                "fit".as_ref(),
                scan.as_os_str(),
                "--model".as_ref(),
                model.as_ref(),
                "--scene".as_ref(),
                scene.as_ref(),
                "-o".as_ref(),
                out_json.as_os_str(),
            ],
        ));
    }
    cmds.push(Cmd::new("ndfit --version (start-up)", [plan.ndfit.as_os_str(), "--version".as_ref()]));
    if let Some(py) = &plan.python {
        let mut argv = vec![py.clone().into_os_string(), plan.numpy_pool.clone().into_os_string(), "--jobs".into(), "1".into()];
        argv.push(scan.clone().into_os_string());
        cmds.push(Cmd::new("numpy + nlopt", argv));
    }
    let single =
        interleave(&cmds, plan.repeats, 1, |c, s| log(&format!("{:<28} {:>8.1} ms  {:>7.1} MB", c.label, s.wall_s * 1e3, mb(s.peak_rss))))?;

    // Batch set.
    let out_dir = work.join("batch_out");
    let mut pools = Vec::new();
    if unzip {
        let floor: Vec<Cmd> = scans
            .iter()
            .map(|p| Cmd::new("unzip -p", ["unzip".as_ref(), "-p".as_ref(), p.as_os_str(), "bindata/data.bin".as_ref()]))
            .collect();
        pools.push(Pool { label: format!("unzip -p x{} ({} at once, floor)", scans.len(), plan.jobs), jobs: plan.jobs, cmds: floor });
    }
    let jobs = plan.jobs.to_string();
    let batch = Cmd::new(
        "ndfit batch",
        [
            plan.ndfit.as_os_str(),
            "batch".as_ref(),
            dir.as_os_str(),
            "--model".as_ref(),
            "ellipsoid".as_ref(),
            "--jobs".as_ref(),
            jobs.as_ref(),
            "-o".as_ref(),
            out_dir.as_os_str(),
        ],
    );
    pools.push(Pool { label: format!("ndfit batch --jobs {}", plan.jobs), jobs: 1, cmds: vec![batch] });
    if let Some(py) = &plan.python {
        let mut argv = vec![py.clone().into_os_string(), plan.numpy_pool.clone().into_os_string(), "--jobs".into(), jobs.clone().into()];
        argv.extend(scans.iter().map(|p| p.clone().into_os_string()));
        pools.push(Pool { label: format!("numpy + nlopt pool of {}", plan.jobs), jobs: 1, cmds: vec![Cmd::new("numpy pool", argv)] });
    }
    let batch = interleave_pools(&pools, plan.batch_repeats, 1, |p, s| {
        log(&format!("{:<40} {:>8.1} ms  {:>7.1} MB", p.label, s.wall_s * 1e3, mb(s.peak_rss)))
    })?;

    let find = |v: &[Measured], prefix: &str| v.iter().find(|m| m.label.starts_with(prefix)).map(|m| m.median_ms);
    let ratio = |a: Option<f64>, b: Option<f64>| a.zip(b).map(|(a, b)| a / b);
    Ok(Report {
        schema: "ndfit.bench.process/1",
        size: plan.size,
        scans: scans.len(),
        jobs: plan.jobs,
        file_bytes,
        data_bytes,
        loadavg_start: load0,
        loadavg_end: loadavg(),
        fit_over_floor: ratio(find(&single, "ndfit fit"), find(&single, "unzip")),
        numpy_over_fit: ratio(find(&single, "numpy"), find(&single, "ndfit fit")),
        batch_over_floor: ratio(find(&batch, "ndfit batch"), find(&batch, "unzip")),
        numpy_pool_over_batch: ratio(find(&batch, "numpy"), find(&batch, "ndfit batch")),
        auto_over_single: ratio(find(&single, "ndfit fit --model auto"), find(&single, "ndfit fit --model ggx-aniso")),
        render_over_single: ratio(
            find(&single, "ndfit fit --model auto").zip(find(&single, "ndfit fit --model auto --scene none")).map(|(a, b)| a - b),
            find(&single, "ndfit fit --model ggx-aniso"),
        ),
        single,
        batch,
    })
}

fn mb(b: Option<u64>) -> f64 {
    b.map_or(f64::NAN, |b| b as f64 / 1e6)
}

/// The report as the Markdown table of docs/PERFORMANCE.md.
pub fn markdown(r: &Report) -> String {
    let load = |l: Option<[f64; 3]>| l.map_or("-".to_string(), |l| format!("{:.2} {:.2} {:.2}", l[0], l[1], l[2]));
    let mut s = format!(
        "{0}^2 float64 X3P, data.bin deflated ({1:.1} MB file, {2:.1} MB of heights); load average {3} at the start, {4} at the end.\n\n\
         | command | median (ms) | min - max (ms) | CPU (ms) | child peak RSS (MB) | runs |\n| --- | --- | --- | --- | --- | --- |\n",
        r.size,
        r.file_bytes as f64 / 1e6,
        r.data_bytes as f64 / 1e6,
        load(r.loadavg_start),
        load(r.loadavg_end)
    );
    for m in r.single.iter().chain(&r.batch) {
        s += &format!(
            "| {} | {:.1} | {:.1} - {:.1} | {} | {} | {} |\n",
            m.label,
            m.median_ms,
            m.min_ms,
            m.max_ms,
            m.median_cpu_ms.map_or("-".into(), |c| format!("{c:.0}")),
            match (m.median_peak_rss, m.rss_floor) {
                (Some(p), Some(f)) if p <= f => format!("<= {:.1}", f as f64 / 1e6),
                (Some(p), _) => format!("{:.1}", p as f64 / 1e6),
                _ => "-".into(),
            },
            m.samples.len()
        );
    }
    let f = |v: Option<f64>| v.map_or("-".to_string(), |v| format!("{v:.2}x"));
    s += &format!(
        "\n`ndfit fit --model auto` / `ndfit fit --model ggx-aniso` (one single-lobe scan) {} (target <= 3x); the render choice (`auto` less `auto --scene none`) / `ggx-aniso` {} (target <= 1.5x).\n",
        f(r.auto_over_single),
        f(r.render_over_single)
    );
    s += &format!(
        "\nRatios of medians: `ndfit fit` / `unzip -p` {} (target <= 1.2x); `ndfit batch` / paired `unzip -p` over {} scans {} (target <= 1.3x); numpy pool / `ndfit batch` {}; numpy / `ndfit fit` (one scan) {}.\n",
        f(r.fit_over_floor),
        r.scans,
        f(r.batch_over_floor),
        f(r.numpy_pool_over_batch),
        f(r.numpy_over_fit)
    );
    s
}

/// Check a plan's numbers before running it.
pub fn check(plan: &Plan) -> Result<()> {
    if !(16..=8192).contains(&plan.size) || plan.scans == 0 || plan.repeats == 0 || plan.batch_repeats == 0 || plan.jobs == 0 {
        return Err(Error::new(ErrorKind::InvalidInput, "--process: size 16 to 8192, at least one scan, run and job"));
    }
    Ok(())
}
