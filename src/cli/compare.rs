//! `ndfit compare SCAN`: will a renderer show the difference? `auto` with its render choice, then every
//! lobe the ladder fitted rendered against the scan's own table in the choice's scenes and scored by FLIP;
//! the answer (the simplest lobe within the tolerance, else the table) and, per scene, a PNG of the two
//! renders and the FLIP map.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{anyhow, bail};
use ndfit::answer::choice::{picture, RenderJudge};
use ndfit::export::rgl::AnalyticBrdf;
use ndfit::models::Model;

use super::fit_args::{FitHow, RenderArgs};
use super::scan_args::ReadArgs;

/// Arguments of `ndfit compare`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The scan.
    pub scan: PathBuf,
    #[command(flatten)]
    pub render: RenderArgs,
    /// Write `PREFIX.SCENE.png` per scene: the table's render, the answer's (or the closest lobe's) and
    /// the FLIP map.
    #[arg(long, value_name = "PREFIX")]
    pub png: Option<PathBuf>,
    /// Print the result as JSON on standard output.
    #[arg(long)]
    pub json: bool,
    #[command(flatten, next_help_heading = "Reading, binning and fitting the scan (as ndfit fit)")]
    pub read: ReadArgs,
    #[command(flatten)]
    pub how: FitHow,
}

/// Run `ndfit compare`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let path = args.scan.display().to_string();
    let fail = |e: ndfit::Error| anyhow!("{path}: {}", e.message());
    let Some(render) = args.render.options().map_err(fail)? else {
        bail!("{path}: --scene none: compare needs at least one scene");
    };
    // A scene's name may hold characters a file name should not (`point:light=30/0`): PNGs are numbered
    // after the first two defaults' names.
    let pngs: Vec<PathBuf> = match &args.png {
        Some(prefix) => render
            .scenes
            .iter()
            .enumerate()
            .map(|(k, s)| {
                let tag = if s.name.chars().all(|c| c.is_ascii_alphanumeric()) { s.name.clone() } else { format!("scene{}", k + 1) };
                let mut out = prefix.clone().into_os_string();
                out.push(format!(".{tag}.png"));
                PathBuf::from(out)
            })
            .collect(),
        None => Vec::new(),
    };
    for p in &pngs {
        ndfit::io::check_output(p)?;
    }
    let options = args.how.options(&args.read, ndfit::ModelChoice::Auto, &args.scan)?;
    let pipeline = ndfit::Pipeline::new(options.clone());
    let (input, ndf) = pipeline.ndf_path(&args.scan)?;
    let judge = RenderJudge::new(&ndf, render.clone());
    let mut report = ndfit::fit::fit_auto_with(&ndf, &options.fit_options(), &judge).map_err(fail)?;
    judge.apply(&mut report, &path).map_err(fail)?;
    report.input = Some(input);
    let sel = report.selection.clone().ok_or_else(|| anyhow!("{path}: auto gave no selection"))?;
    // Every lobe the ladder fitted, simplest first.
    let candidates: Vec<Model> = sel
        .candidates
        .iter()
        .filter_map(|c| {
            let p: Vec<f64> = c.model.param_names().iter().map(|n| c.params.get(*n).copied().unwrap_or(f64::NAN)).collect();
            Model::from_params(c.model, &p).ok()
        })
        .collect();
    let scores = judge.scores(&candidates).map_err(fail)?;
    let reported = report.to_model().map_err(fail)?;
    let answer = sel.answer.clone().unwrap_or_else(|| "measured".into());
    let render_error: BTreeMap<String, f64> = sel.render_error.clone().unwrap_or_default();
    let tables = judge.table_renders(&reported).map_err(fail)?;
    for ((s, out), table) in render.scenes.iter().zip(&pngs).zip(&tables) {
        let b = s.scene.render(&AnalyticBrdf { model: reported, material: render.material }).map_err(fail)?;
        let title = format!("{}: the scan's table against {} ({} scene)", args.scan.display(), reported.id(), s.name);
        let bytes = picture(table, &b, &title).map_err(fail)?;
        ndfit::io::write_bytes_atomic(out, &bytes)?;
    }
    let worst = render_error.get("worst").copied().unwrap_or(f64::NAN);
    let line = if answer != "measured" {
        format!("a renderer cannot tell {answer} from the scan (worst FLIP {worst:.4} <= {})", render.tolerance)
    } else {
        format!(
            "no lobe renders within FLIP {} of the scan's table (closest: {}, worst FLIP {worst:.4}); the material is the table: ndfit export {} --to rgl -o OUT.bsdf",
            render.tolerance,
            reported.id(),
            args.scan.display()
        )
    };
    if args.json {
        let names: Vec<&str> = render.scenes.iter().map(|s| s.name.as_str()).collect();
        let rows: Vec<serde_json::Value> = candidates
            .iter()
            .zip(&scores)
            .map(|(m, s)| serde_json::json!({"model": m.id().as_str(), "render_error": s.per_scene, "worst": s.worst}))
            .collect();
        let doc = serde_json::json!({
            "answer": answer,
            "lobe": reported.id().as_str(),
            "render_error": render_error,
            "tolerance": render.tolerance,
            "scenes": names,
            "candidates": rows,
            "verdict": report.quality.verdict,
        });
        let mut s = serde_json::to_string_pretty(&doc).map_err(|e| anyhow!("{path}: {e}"))?;
        s.push('\n');
        super::write_stdout(s.as_bytes())?;
    }
    eprintln!("ndfit: {path}: answer {answer}: {line}");
    Ok(ExitCode::SUCCESS)
}
