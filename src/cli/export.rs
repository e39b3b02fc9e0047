//! `ndfit export FIT.json --to mitsuba|pbrt|blender|openpbr|materialx [--json]`: a fit as a renderer's
//! parameters (the math is in `ndfit::export`).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{anyhow, Context};
use ndfit::export::{export, Target};
use ndfit::models::Model;

/// Arguments of `ndfit export`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A fit result (`ndfit.fit/1`) or any JSON object with `model` and `params`.
    pub fit: PathBuf,
    /// The renderer: mitsuba (roughconductor), pbrt (conductor, pbrt-v4), blender (Principled BSDF),
    /// openpbr (OpenPBR Surface), materialx (conductor_bsdf).
    #[arg(long = "to", value_name = "RENDERER")]
    pub to: String,
    /// Print one JSON object (the contract's keys, plus `note` and `approximation` when the fit had to be
    /// approximated) instead of a snippet in the renderer's syntax.
    #[arg(long)]
    pub json: bool,
}

/// Run `ndfit export`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let path = args.fit.display().to_string();
    let target: Target = args.to.parse().map_err(|e: ndfit::Error| anyhow!("{path}: --to: {}", e.message()))?;
    let text = std::fs::read_to_string(&args.fit).with_context(|| format!("{path}: cannot read"))?;
    let json: serde_json::Value = serde_json::from_str(&text).map_err(|e| anyhow!("{path}: not valid JSON ({e})"))?;
    let model = Model::from_json(&json).map_err(|e| anyhow!("{path}: not a fit result: {}", e.message()))?;
    // The fit region of the fit, over which an approximation is fitted and measured.
    let max_theta = json.pointer("/quality/max_theta_deg").and_then(|v| v.as_f64()).unwrap_or(90.0);
    let name = args.fit.file_name().map_or(path.clone(), |n| n.to_string_lossy().into_owned());
    if let Model::Mixture(x) = &model {
        let out = ndfit::export::mixture::export_mixture(x, target, max_theta).map_err(|e| anyhow!("{path}: {}", e.message()))?;
        for note in [&out.core.note, &out.tail.note].into_iter().flatten() {
            eprintln!("ndfit: {path}: {note}");
        }
        return emit(args.json, &path, || out.to_json(), || out.snippet(&name));
    }
    let out = export(&model, target, max_theta).map_err(|e| anyhow!("{path}: {}", e.message()))?;
    if let Some(note) = &out.note {
        eprintln!("ndfit: {path}: {note}");
    }
    emit(args.json, &path, || out.to_json(), || out.snippet(&name))
}

/// Write the export to standard output: the JSON document with `--json`, the renderer's snippet otherwise.
fn emit(as_json: bool, path: &str, json: impl FnOnce() -> serde_json::Value, snippet: impl FnOnce() -> String) -> anyhow::Result<ExitCode> {
    let text = if as_json {
        let mut s = serde_json::to_string_pretty(&json()).map_err(|e| anyhow!("{path}: {e}"))?;
        s.push('\n');
        s
    } else {
        snippet()
    };
    super::write_stdout(text.as_bytes())?;
    Ok(ExitCode::SUCCESS)
}
