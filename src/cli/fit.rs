//! `ndfit fit SCAN`: read, preprocess, build the empirical NDF, fit, write `ndfit.fit/1` JSON.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::anyhow;
use ndfit::Pipeline;

use super::fit_args::{parse_model, FitArgs};

/// Arguments of `ndfit fit`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    fit: FitArgs,
    /// Model id (the model table's names) or `auto`.
    #[arg(long, default_value = "auto", help = super::model_help())]
    model: String,
    /// Output JSON (written atomically); standard output when absent.
    #[arg(short = 'o', long)]
    output: Option<PathBuf>,
    /// Plot of the data against the fit, with residuals (PNG).
    #[arg(long)]
    plot: Option<PathBuf>,
    /// No summary line on standard error (warnings and a verdict other than `ok` are still said).
    #[arg(short = 'q', long)]
    quiet: bool,
}

/// Run `ndfit fit`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let scan = &args.fit.scan.scan;
    let path = scan.display().to_string();
    let model = parse_model(&args.model)?;
    let pipeline = Pipeline::new(args.fit.options(model)?);
    args.fit.scan.check_outputs(args.output.iter().chain(&args.plot).map(|p| p.as_path()))?;
    let ndfit::Outcome { ndf, fit: report } = pipeline.run_path(scan)?;
    for w in &report.warnings {
        eprintln!("ndfit: {path}: warning: {w}");
    }
    if let Some(png) = &args.plot {
        let m = report.to_model()?;
        let name = scan.file_name().map_or(path.clone(), |n| n.to_string_lossy().into_owned());
        let title = format!("{name}: {} fit", report.model);
        ndfit::fit::plot_fit(png, &ndf, &m, &title)?;
    }
    let _p = ndfit::phases::phase("write");
    let mut json = serde_json::to_string_pretty(&report).map_err(|e| anyhow!("{path}: cannot serialize the result ({e})"))?;
    json.push('\n');
    match &args.output {
        Some(out) => ndfit::io::write_bytes_atomic(out, json.as_bytes())?,
        None => super::write_stdout(json.as_bytes())?,
    }
    if !args.quiet {
        eprintln!("ndfit: {path}: {}", summary_line(&report));
        if let Some(hint) = measured_hint(&report, &path) {
            eprintln!("ndfit: {path}: {hint}");
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// Where no fitted model is within the tolerance (`misfit`), the way on: the scan's own NDF tabulated
/// for the renderers' measured materials, and, for one named model, `auto`'s ladder.
fn measured_hint(report: &ndfit::fit::FitReport, path: &str) -> Option<String> {
    if report.quality.verdict != ndfit::fit::Verdict::Misfit {
        return None;
    }
    // The render choice says it in its own reason (with the command).
    if let Some(r) = report.selection.as_ref().filter(|s| s.answer.is_some()).and_then(|_| report.quality.reasons.first()) {
        return Some(r.clone());
    }
    let lead = match report.selection {
        Some(_) => "no model of `auto`'s ladder is within the tolerance".to_string(),
        None => format!("{} is not within the tolerance (`--model auto` tries the others)", report.model),
    };
    Some(format!(
        "{lead}; `ndfit export --to rgl {path} -o NAME.bsdf`, with the reading and fit options given here, gives a renderer the measured NDF itself (Mitsuba 3's and pbrt-v4's `measured` material)"
    ))
}

/// One line on a fit: the model, its main parameters and the verdict.
pub fn summary_line(report: &ndfit::fit::FitReport) -> String {
    let params: Vec<String> =
        report.model.param_names().iter().map(|n| format!("{n}={:.4}", report.params.get(*n).copied().unwrap_or(f64::NAN))).collect();
    let q = &report.quality;
    let chi = q.reduced_chi2.map_or(String::new(), |c| format!(", deviance/dof {c:.3}"));
    let disp = q.dispersion.map_or(String::new(), |d| format!(" (data's own dispersion {d:.3})"));
    // Walter et al. eq. 2-3: A = S Rz(theta_z) puts the alpha_x axis along (cos theta_z, -sin theta_z).
    let axis = report.params.get("theta_z").map_or(String::new(), |t| format!(" (alpha_x axis at azimuth {:.4} rad from +x)", -t));
    // auto's answer: a mirror with its share and haze, or the render choice (a lobe, or the table) and the
    // lobe's worst FLIP against the table.
    let answer = report.selection.as_ref().and_then(|s| {
        let a = s.answer.as_deref()?;
        if let Some(o) = report.optics.as_ref().filter(|_| a.contains("mirror")) {
            return Some(format!(": answer {a} ({})", mirror_text(o, a.contains('+'))));
        }
        // Without renders (the choice could not run) the answer is the NDF's: the warnings say why.
        Some(match s.render_error.as_ref().and_then(|e| e.get("worst")) {
            Some(worst) => format!(": answer {a} (worst FLIP {worst:.4} against the scan's table)"),
            None => format!(": answer {a} (by the NDF alone)"),
        })
    });
    let optics = report.optics.as_ref().map_or(String::new(), |o| format!(": optics {}", o.regime));
    format!("{} {}{axis}{chi}{disp}{optics}{}: verdict {}", report.model, params.join(" "), answer.unwrap_or_default(), q.verdict)
}

/// A mirror answer in a few words: its share at 550 nm by incidence, and its haze where it has one.
fn mirror_text(o: &ndfit::fit::Optics, with_haze: bool) -> String {
    let shares: Vec<String> =
        o.specular.iter().filter(|s| s.wavelength_nm == 550.0).map(|s| format!("{:.3} at {} deg", s.weight, s.theta_deg)).collect();
    let haze = o.haze.as_ref().filter(|_| with_haze).map_or(String::new(), |h| {
        format!("; haze {} alpha {:.4} carrying {:.2}%", h.model, h.params.get("alpha").copied().unwrap_or(f64::NAN), h.albedo * 100.0)
    });
    format!("mirror share at 550 nm {}{haze}", shares.join(", "))
}
