//! `ndfit demo`: the main job on a built-in scan, with no files of the user's. It makes a synthetic
//! ellipsoid scan whose NDF is known exactly, builds its empirical NDF, fits the model, and prints the
//! truth beside the fit so a new user sees what ndfit does and how well.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use ndfit::fit;
use ndfit::models::{Model, ModelId, Ndf};
use ndfit::preprocess::{FormRemoval, Preprocess};
use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};
use ndfit::{Options, Outcome, Pipeline};

use super::fit_args::parse_model;

/// Arguments of `ndfit demo`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Grid side of the built-in scan (points per side).
    #[arg(long, default_value_t = 1024)]
    size: usize,
    /// Model to fit, or `auto` to let the information criterion choose.
    #[arg(long, default_value = "ellipsoid")]
    model: String,
    /// Write the fit JSON (`ndfit.fit/1`) here as well.
    #[arg(short = 'o', long)]
    output: Option<PathBuf>,
    /// Plot of the data against the fit, with residuals (PNG).
    #[arg(long)]
    plot: Option<PathBuf>,
}

/// The built-in surface: a skewed, anisotropic ellipsoid like a brushed and slightly tilted metal.
const TRUTH: EllipsoidParams = EllipsoidParams { alpha_x: 0.30, alpha_y: 0.12, theta_x: 0.15, theta_y: -0.10, theta_z: 0.50, fill: 0.96 };

/// The name the demo's scan goes by in the fit JSON and the verdict line.
const SCAN_NAME: &str = "<built-in demo scan>";

/// Run `ndfit demo`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let settings = SynthSettings { nx: args.size, ny: args.size, ..SynthSettings::default() };
    let t0 = Instant::now();
    let (hf, _truth) = ellipsoid_surface(&settings, &TRUTH)?;
    let truth =
        Model::from_params(ModelId::Ellipsoid, &[TRUTH.alpha_x, TRUTH.alpha_y, TRUTH.theta_x, TRUTH.theta_y, TRUTH.theta_z])?.canonical();
    let t1 = Instant::now();
    // The synthetic surface has no form to remove.
    let preprocess = Preprocess { form: FormRemoval::None, ..Preprocess::default() };
    let pipeline = Pipeline::new(Options { preprocess, model: parse_model(&args.model)?, ..Options::default() });
    let Outcome { ndf, fit: report } = pipeline.run(hf, SCAN_NAME)?;
    let ndf_ms = report.timings.ndf_ms.unwrap_or(0.0);
    let fitted = report.to_model()?;
    let nodes = ndf.bins.iter().map(|b| (b.m, b.proj_solid_angle));
    let delta = fit::delta(|m| fitted.d(*m), |m| truth.d(*m), nodes);

    // Built in memory and written at the end: a closed or full standard output ends the command cleanly.
    let mut out: Vec<u8> = Vec::new();
    let w = &mut out;
    let _ = writeln!(w, "ndfit demo: a synthetic {n} x {n} scan of an ellipsoid surface (Walter et al. 2014),", n = args.size);
    let _ = writeln!(w, "whose NDF is exactly the ellipsoid NDF below; ndfit measures it and fits it back.\n");
    let _ = writeln!(w, "{:>8}  {:>10}  {:>10}  {:>10}", "param", "truth", "fit", "std.err");
    let truth_params = truth.params();
    for (i, name) in report.model.param_names().iter().enumerate() {
        let t = if report.model == ModelId::Ellipsoid { format!("{:10.5}", truth_params[i]) } else { format!("{:>10}", "-") };
        let f = report.params.get(*name).copied().unwrap_or(f64::NAN);
        let se = report.std_errors.get(*name).copied().flatten().map_or("-".to_string(), |s| format!("{s:.2e}"));
        let _ = writeln!(w, "{name:>8}  {t}  {f:10.5}  {se:>10}");
    }
    let _ = writeln!(w, "\nmodel: {}   samples: {}   bins: {}", report.model, ndf.n_samples, ndf.bins.len());
    if let Some(d) = delta {
        let _ = writeln!(w, "NDF error against the truth, sqrt(E[(D_fit/D_true - 1)^2]): {:.3}%", 100.0 * d);
    }
    if let Some(rc) = report.quality.reduced_chi2 {
        let _ = writeln!(w, "reduced chi-square (Poisson deviance / dof): {rc:.3}");
    }
    let _ = writeln!(
        w,
        "time: synth {:.0} ms, NDF {:.0} ms, fit {:.0} ms; solver: {} ({} evaluations)",
        (t1 - t0).as_secs_f64() * 1e3,
        ndf_ms,
        report.timings.fit_ms,
        report.solver.termination,
        report.solver.evaluations
    );
    if let Some(png) = &args.plot {
        ndfit::fit::plot_fit(png, &ndf, &fitted, "ndfit demo: built-in ellipsoid scan")?;
        let _ = writeln!(w, "plot: {}", png.display());
    }
    if let Some(path) = &args.output {
        let mut json = serde_json::to_string_pretty(&report)?;
        json.push('\n');
        ndfit::io::write_bytes_atomic(path, json.as_bytes())?;
        let _ = writeln!(w, "fit JSON: {}", path.display());
    }
    let _ = writeln!(w, "\nNext: `ndfit fit YOUR_SCAN.x3p --model auto -o fit.json` (see README).");
    // Last, the warnings and the verdict line `ndfit fit` prints for every fit.
    for warning in &report.warnings {
        let _ = writeln!(w, "ndfit: {SCAN_NAME}: warning: {warning}");
    }
    let _ = writeln!(w, "ndfit: {SCAN_NAME}: {}", super::fit::summary_line(&report));
    super::write_stdout(&out)?;
    Ok(ExitCode::SUCCESS)
}
