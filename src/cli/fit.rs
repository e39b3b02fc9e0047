//! `ndfit fit SCAN`: read, preprocess, build the empirical NDF, fit, write `ndfit.fit/1` JSON.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::anyhow;
use ndfit::fit::{fit_auto, fit_model, FitOptions, InputInfo, Objective, Solver};
use ndfit::ndf::empirical_ndf;

use super::scan_args::ScanArgs;

/// Arguments of `ndfit fit`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    scan: ScanArgs,
    /// Model id (ggx, ggx-aniso, beckmann, beckmann-aniso, ellipsoid) or `auto` (fit the nested models and
    /// choose by the quasi-likelihood BIC).
    #[arg(long, default_value = "auto")]
    model: String,
    /// Output JSON (written atomically); standard output when absent.
    #[arg(short = 'o', long)]
    output: Option<PathBuf>,
    /// Residuals: `poisson` (deviance of the bin counts) or `logd` (count-weighted log D); see
    /// data_formats/objective.md.
    #[arg(long, default_value = "poisson")]
    objective: String,
    /// Local optimizer: `lm` (Levenberg-Marquardt), `nelder-mead` or `lbfgs` (argmin).
    #[arg(long, default_value = "lm")]
    solver: String,
    /// Extra skew starts for the ellipsoid (0-4) beyond the default two.
    #[arg(long, default_value_t = 0)]
    extra_starts: usize,
    /// Largest polar angle (degrees, 0-90] of the NDF bins the fit uses; the model is normalized over
    /// them (data_formats/objective.md). Lower it to the instrument's numerical aperture
    /// (asin(NA)) when the scan cannot see steeper slopes. Default 70.
    #[arg(long)]
    max_theta: Option<f64>,
    /// The objective's numerical aperture NA (0-1]: sets --max-theta to asin(NA); both given must agree.
    #[arg(long)]
    na: Option<f64>,
    /// The tail: `all` (default) keeps every bin within --max-theta; `unresolved` leaves out the bins
    /// where most normals are not resolved by the sampling (data_formats/objective.md).
    #[arg(long, default_value = "all")]
    tail: String,
    /// Plot of the data against the fit, with residuals (PNG).
    #[arg(long)]
    plot: Option<PathBuf>,
    #[command(flatten)]
    ndf: super::ndf::NdfArgs,
    /// Speed/accuracy preset measured in docs/PERFORMANCE.md (`balanced` = the defaults). Sets the
    /// subsampling stride (on top of --subsample; the kept points are all that is read, and the form is
    /// removed from them), the NDF's normals and bins (unless --ndf-cells), the tolerance and the starts.
    #[arg(long, value_enum)]
    preset: Option<ndfit::bench::Preset>,
    /// No summary line on standard error (warnings and a verdict other than `ok` are still said).
    #[arg(short = 'q', long)]
    quiet: bool,
}

/// Run `ndfit fit`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let path = args.scan.scan.display().to_string();
    let opts = FitOptions {
        objective: args.objective.parse::<Objective>().map_err(|e| anyhow!("--objective: {}", e.message()))?,
        solver: args.solver.parse::<Solver>().map_err(|e| anyhow!("--solver: {}", e.message()))?,
        extra_starts: args.extra_starts,
        max_theta: max_theta_deg(args.max_theta, args.na)?.to_radians(),
        cut_unresolved: match args.tail.as_str() {
            "unresolved" => true,
            "all" => false,
            other => anyhow::bail!("--tail {other:?}: use unresolved or all"),
        },
        ..FitOptions::default()
    };
    anyhow::ensure!(args.extra_starts <= 4, "--extra-starts {} must be between 0 and 4", args.extra_starts);
    let model = match args.model.parse::<ndfit::models::ModelChoice>().map_err(|e| anyhow!("--model: {}", e.message()))? {
        ndfit::models::ModelChoice::Auto => None,
        ndfit::models::ModelChoice::Model(id) => Some(id),
    };
    let mut ndf_opts = args.ndf.options()?;
    let mut opts = opts;

    args.scan.check_outputs(args.output.iter().chain(&args.plot).map(|p| p.as_path()))?;
    let t0 = Instant::now();
    // The preset's stride subsamples as it reads (the form is then removed from the kept points).
    let hf = args.scan.load_with_stride(args.preset.map_or(1, |p| p.stride()))?;
    if let Some(p) = args.preset {
        // The preset's knobs (src/bench/presets.rs); an explicit --ndf-cells still wins.
        let po = p.ndf_options(if p.needs_sample_count() { hf.valid_count() as u64 } else { 0 });
        ndf_opts = ndfit::ndf::NdfOptions { cells_across: args.ndf.ndf_cells.or(po.cells_across), ..po };
        let pf = p.fit_options();
        opts.tolerances = pf.tolerances;
        opts.extra_starts = opts.extra_starts.max(pf.extra_starts);
    }
    let t1 = Instant::now();
    let ndf = empirical_ndf(&hf, &ndf_opts).map_err(|e| e.with_path(&args.scan.scan))?;
    let t2 = Instant::now();
    let result = match model {
        Some(id) => fit_model(&ndf, id, &opts),
        None => fit_auto(&ndf, &opts),
    };
    let mut report = result.map_err(|e| e.with_path(&args.scan.scan))?;
    report.input = Some(InputInfo::new(&args.scan.scan, &hf));
    report.timings.read_ms = Some((t1 - t0).as_secs_f64() * 1e3);
    report.timings.ndf_ms = Some((t2 - t1).as_secs_f64() * 1e3);
    for w in &report.warnings {
        eprintln!("ndfit: {path}: warning: {w}");
    }
    if let Some(png) = &args.plot {
        let m = report.to_model()?;
        let name = args.scan.scan.file_name().map_or(path.clone(), |n| n.to_string_lossy().into_owned());
        let title = format!("{name}: {} fit", report.model);
        ndfit::fit::plot::plot_fit(png, &ndf, &m, &title)?;
    }
    let mut json = serde_json::to_string_pretty(&report).map_err(|e| anyhow!("{path}: cannot serialize the result ({e})"))?;
    json.push('\n');
    match &args.output {
        Some(out) => ndfit::io::write_bytes_atomic(out, json.as_bytes())?,
        None => super::write_stdout(json.as_bytes())?,
    }
    if !args.quiet {
        eprintln!("ndfit: {path}: {}", summary_line(&report));
    }
    Ok(ExitCode::SUCCESS)
}

/// The fit region's largest polar angle (degrees) from `--max-theta` and `--na` (`asin(NA)`); both
/// given must agree to 1e-6 degrees.
pub fn max_theta_deg(max_theta: Option<f64>, na: Option<f64>) -> anyhow::Result<f64> {
    if let Some(t) = max_theta {
        anyhow::ensure!(t > 0.0 && t <= 90.0, "--max-theta {t} must be in (0, 90] degrees");
    }
    let from_na = match na {
        Some(a) => {
            anyhow::ensure!(a > 0.0 && a <= 1.0, "--na {a} must be in (0, 1]");
            Some(a.asin().to_degrees())
        }
        None => None,
    };
    match (max_theta, from_na) {
        (Some(t), Some(n)) if (t - n).abs() > 1e-6 => {
            anyhow::bail!("--max-theta {t} and --na disagree: the aperture sets max_theta = asin(NA) = {n:.6} degrees")
        }
        (Some(t), _) => Ok(t),
        (None, Some(n)) => Ok(n),
        (None, None) => Ok(ndfit::fit::objective::DEFAULT_MAX_THETA_DEG),
    }
}

/// One line on a fit: the model, its main parameters and the verdict.
pub fn summary_line(report: &ndfit::fit::FitReport) -> String {
    let params: Vec<String> = report.model.param_names().iter().map(|n| format!("{n}={:.4}", report.params.get(*n).copied().unwrap_or(f64::NAN))).collect();
    let q = &report.quality;
    let chi = q.reduced_chi2.map_or(String::new(), |c| format!(", deviance/dof {c:.3}"));
    let disp = q.dispersion.map_or(String::new(), |d| format!(" (data's own dispersion {d:.3})"));
    // Walter et al. eq. 2-3: A = S Rz(theta_z) puts the alpha_x axis along (cos theta_z, -sin theta_z).
    let axis = report.params.get("theta_z").map_or(String::new(), |t| format!(" (alpha_x axis at azimuth {:.4} rad from +x)", -t));
    format!("{} {}{axis}{chi}{disp}: verdict {}", report.model, params.join(" "), q.verdict)
}
