//! `ndfit compare SCAN`: will a renderer show the difference? Every lobe `auto` fitted, rendered against
//! the scan's own table in the default scenes and scored by FLIP; the answer (the simplest lobe within the
//! tolerance, else the table) and, per scene, a PNG of the two renders and the FLIP map.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{anyhow, bail};
use ndfit::export::choice::{decide, default_scenes, picture, TableBrdf};
use ndfit::export::rgl::{self, AnalyticBrdf, Material, NdfGrids};
use ndfit::models::{Model, Ndf};

use super::fit_args::FitHow;
use super::scan_args::ReadArgs;

/// Arguments of `ndfit compare`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// The scan.
    pub scan: PathBuf,
    /// The largest mean FLIP, in every scene, at which a lobe counts as what the scan renders like.
    #[arg(long = "render-tolerance", default_value_t = 0.03)]
    pub render_tolerance: f64,
    /// The conductor of both renders: none (F = 1), Al, Ag, Au, Cu or Cr.
    #[arg(long, default_value = "Al")]
    pub material: String,
    /// Write `PREFIX.SCENE.png` per default scene: the table's render, the answer's (or the closest
    /// lobe's) and the FLIP map.
    #[arg(long, value_name = "PREFIX")]
    pub png: Option<PathBuf>,
    /// The scenes, comma-separated: point (the sphere under a point light), broad (under a 25-degree cap
    /// light); data_formats/render.md states them.
    #[arg(long, value_delimiter = ',', default_value = "point,broad")]
    pub scene: Vec<String>,
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
    if !(args.render_tolerance.is_finite() && args.render_tolerance > 0.0) {
        bail!("{path}: --render-tolerance must be a positive number, got {}", args.render_tolerance);
    }
    let material: Material = args.material.parse().map_err(|e: ndfit::Error| anyhow!("{path}: --material: {}", e.message()))?;
    let mut scenes = Vec::new();
    for name in &args.scene {
        match default_scenes().into_iter().find(|s| s.name == name.trim()) {
            Some(s) if !scenes.contains(&s) => scenes.push(s),
            Some(_) => {}
            None => bail!("{path}: --scene: unknown scene '{name}' (point or broad)"),
        }
    }
    let pngs: Vec<PathBuf> = match &args.png {
        Some(prefix) => scenes
            .iter()
            .map(|s| {
                let mut out = prefix.clone().into_os_string();
                out.push(format!(".{}.png", s.name));
                PathBuf::from(out)
            })
            .collect(),
        None => Vec::new(),
    };
    for p in &pngs {
        ndfit::io::check_output(p)?;
    }
    let options = args.how.options(&args.read, ndfit::ModelChoice::Auto, &args.scan)?;
    let outcome = ndfit::Pipeline::new(options).run_path(&args.scan)?;
    let fit = outcome.fit.to_model().map_err(fail)?;
    // Every lobe the ladder fitted, simplest first; the fit alone when there was no ladder.
    let mut candidates: Vec<Model> = Vec::new();
    if let Some(sel) = &outcome.fit.selection {
        for c in &sel.candidates {
            let p: Vec<f64> = c.model.param_names().iter().map(|n| c.params.get(*n).copied().unwrap_or(f64::NAN)).collect();
            if let Ok(m) = Model::from_params(c.model, &p) {
                candidates.push(m);
            }
        }
    }
    if candidates.is_empty() {
        candidates.push(fit);
    }
    let reg = rgl::Regularized::new(&outcome.ndf, &fit, outcome.fit.quality.max_theta_deg);
    let grids = NdfGrids::new(&|m| reg.d(m), &|m| fit.d(m), None, true).map_err(fail)?;
    let table = TableBrdf { grids: &grids, material };
    let choice = decide(&table, &candidates, material, &scenes, args.render_tolerance).map_err(fail)?;
    let reported = candidates[choice.reported()];
    let answer = choice.answer.map_or("measured".to_string(), |k| candidates[k].id().as_str().to_string());
    let mut render_error: BTreeMap<String, f64> = BTreeMap::new();
    for (name, v) in choice.scenes.iter().zip(&choice.scores[choice.reported()].per_scene) {
        render_error.insert(name.to_string(), *v);
    }
    render_error.insert("worst".into(), choice.scores[choice.reported()].worst);

    for (s, out) in scenes.iter().zip(&pngs) {
        let a = s.scene.render(&table).map_err(fail)?;
        let b = s.scene.render(&AnalyticBrdf { model: reported, material }).map_err(fail)?;
        let title = format!("{}: the scan's table against {} ({} scene)", args.scan.display(), reported.id(), s.name);
        let bytes = picture(&a, &b, &title).map_err(fail)?;
        ndfit::io::write_bytes_atomic(out, &bytes)?;
    }
    let line = match choice.answer {
        Some(_) => format!("a renderer cannot tell {answer} from the scan (worst FLIP {:.4} <= {})", render_error["worst"], choice.tolerance),
        None => format!(
            "no lobe renders within FLIP {} of the scan's table (closest: {}, worst FLIP {:.4}); the material is the table: ndfit export {} --to rgl -o OUT.bsdf",
            choice.tolerance,
            reported.id(),
            render_error["worst"],
            args.scan.display()
        ),
    };
    if args.json {
        let scores: Vec<serde_json::Value> = candidates
            .iter()
            .zip(&choice.scores)
            .map(|(m, s)| serde_json::json!({"model": m.id().as_str(), "render_error": s.per_scene, "worst": s.worst}))
            .collect();
        let doc = serde_json::json!({
            "answer": answer,
            "lobe": reported.id().as_str(),
            "render_error": render_error,
            "tolerance": choice.tolerance,
            "scenes": choice.scenes,
            "candidates": scores,
        });
        let mut s = serde_json::to_string_pretty(&doc).map_err(|e| anyhow!("{path}: {e}"))?;
        s.push('\n');
        super::write_stdout(s.as_bytes())?;
    }
    eprintln!("ndfit: {path}: answer {answer}: {line}");
    Ok(ExitCode::SUCCESS)
}
