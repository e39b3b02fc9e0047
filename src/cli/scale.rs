//! `ndfit scale SCAN --footprint F[,F...] [--scene SPEC]`: the NDF as seen at a renderer's footprints, by
//! two routes, and the simplest model for a scene (data_formats/scale.md).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::anyhow;
use ndfit::models::ModelId;
use ndfit::pipeline::check::Spelling;
use ndfit::pipeline::scale::recommend_rendered;
use ndfit::scale::Blur;
use ndfit::scale::{analyze, recommend, Fitter, ScaleOptions};
use ndfit::scale::{report_json, write_csv};
use serde_json::json;

use super::scan_args::ScanArgs;

/// Arguments of `ndfit scale`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub scan: ScanArgs,
    /// Footprints in metres (the width of one pixel on the surface), comma-separated.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true)]
    pub footprint: Vec<f64>,
    /// The footprints a scene implies, as key=value pairs: footprint=LO..HI, or distance=LO..HI with
    /// fov_deg= and pixels=, or with pixel_pitch= and focal=; optional max_incidence_deg=.
    /// Adds log-spaced footprints over that range and recommends a model for them.
    #[arg(long)]
    pub scene: Option<String>,
    /// Number of log-spaced footprints evaluated across the scene's range.
    #[arg(long, default_value_t = 5)]
    pub scene_steps: usize,
    /// Models to carry through (comma-separated ids; default all, the two-lobe mixtures included).
    #[arg(long, value_delimiter = ',')]
    pub models: Vec<String>,
    /// Largest acceptable model error delta_model at the scene's footprints.
    #[arg(long, default_value_t = 0.1)]
    pub tolerance: f64,
    /// Blur samples per point for the empirical route (Monte Carlo noise only; see data_formats/scale.md).
    #[arg(long, default_value_t = 4)]
    pub samples_per_point: usize,
    /// Cells across the NDF's Lambert disk (odd; default: chosen from the sample count as `ndfit ndf` does).
    #[arg(long)]
    pub bins: Option<usize>,
    /// Blur of each footprint's resolved slope: per-footprint (its own within-footprint covariance,
    /// scale.md eq. S1) or mean (one mean covariance Sigma_F for all, Tokuyoshi's single kernel, S1').
    #[arg(long, default_value = "per-footprint", value_parser = parse_blur)]
    pub blur: Blur,
    /// Seed of the blur samples (the same seed gives the same result).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// The render rule's scenes (as `ndfit fit --scene`: point, broad, each with :light=, :view=, :cap=,
    /// :size=; window): at each footprint every model is rendered against the NDF seen there, and the answer is
    /// the simplest within --render-tolerance at every footprint; `none` keeps the NDF error's rule alone.
    #[arg(long = "render-scene", default_value = "point,broad")]
    pub render_scene: String,
    /// The largest mean FLIP beyond a footprint table's own noise, in every scene, at which a model passes
    /// (data_formats/render.md, "The tolerance").
    #[arg(long = "render-tolerance", default_value_t = ndfit::answer::choice::DEFAULT_RENDER_TOLERANCE)]
    pub render_tolerance: f64,
    /// The conductor of the renders: none (F = 1), Al, Ag, Au, Cu or Cr.
    #[arg(long, default_value = "Al")]
    pub material: String,
    /// Output directory for scale.json, scale.csv and scale.png; without it the JSON goes to stdout.
    #[arg(short = 'o', long)]
    pub out: Option<PathBuf>,
}

fn parse_blur(s: &str) -> Result<Blur, String> {
    match s {
        "per-footprint" => Ok(Blur::PerFootprint),
        "mean" => Ok(Blur::Mean),
        o => Err(format!("unknown blur {o:?}: use per-footprint or mean")),
    }
}

/// Run `ndfit scale`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let path = args.scan.scan.display().to_string();
    if let Some(f) = args.footprint.iter().find(|f| !(f.is_finite() && **f > 0.0)) {
        anyhow::bail!("--footprint must be positive metres, got {f}");
    }
    if !(args.tolerance.is_finite() && args.tolerance > 0.0) {
        anyhow::bail!("--tolerance must be positive, got {}", args.tolerance);
    }
    if !(1..=50).contains(&args.scene_steps) {
        anyhow::bail!("--scene-steps must be in 1..=50, got {}", args.scene_steps);
    }
    let scene = args.scene.as_deref().map(ndfit::scale::parse_scene).transpose().map_err(|e| anyhow!("--scene: {e}"))?;
    let render = ndfit::pipeline::check::render(&args.render_scene, args.render_tolerance, &args.material, Spelling::Flag)
        .map_err(|e| anyhow!("{}", e.message().replacen("--scene", "--render-scene", 1)))?;
    let scene_fps = scene.map(|r| r.log_spaced(args.scene_steps)).unwrap_or_default();
    if args.footprint.is_empty() && scene_fps.is_empty() {
        anyhow::bail!("give --footprint METRES[,METRES...] or --scene");
    }
    let models: Vec<ModelId> = if args.models.is_empty() {
        ModelId::EVERY.to_vec()
    } else {
        args.models.iter().map(|s| s.trim().parse::<ModelId>()).collect::<Result<_, _>>().map_err(|e| anyhow!("--models: {e}"))?
    };
    let mut footprints: Vec<f64> = args.footprint.iter().chain(&scene_fps).copied().collect();
    footprints.sort_by(f64::total_cmp);
    footprints.dedup();

    let hf = args.scan.load()?;
    let opts =
        ScaleOptions { footprints, models, samples_per_point: args.samples_per_point, bins: args.bins, seed: args.seed, blur: args.blur };
    let fitter = ndfit::scale::default_fitter();
    let results = analyze(&hf, &opts, Some(&fitter as &dyn Fitter)).map_err(|e| anyhow!("{path}: {e}"))?;
    // The recommendation covers the scene's footprints, or every footprint given when there is no scene.
    let rec_fps: Vec<f64> = if scene_fps.is_empty() { args.footprint.clone() } else { scene_fps.clone() };
    let rec_results: Vec<_> = results.iter().filter(|r| rec_fps.contains(&r.stats.footprint)).cloned().collect();
    let rec = recommend(&rec_results, args.tolerance);
    let rendered = match &render {
        Some(r) if !rec_results.is_empty() => Some(recommend_rendered(&rec_results, &rec, r).map_err(|e| anyhow!("{path}: {e}"))?),
        _ => None,
    };

    let input = json!({"path": path, "format": hf.meta.format, "nx": hf.nx, "ny": hf.ny, "dx": hf.dx, "dy": hf.dy});
    let options = json!({
        "footprints_m": opts.footprints,
        "scene": args.scene,
        "scene_range_m": scene.map(|r| [r.lo, r.hi]),
        "models": opts.models.iter().map(|m| m.as_str()).collect::<Vec<_>>(),
        "tolerance": args.tolerance,
        "samples_per_point": opts.samples_per_point,
        "bins": opts.bins,
        "seed": opts.seed,
        "blur": opts.blur,
        "fitter": "ndfit::fit::fit_model (Levenberg-Marquardt, Poisson deviance)",
        "render_scene": args.render_scene,
        "render_tolerance": render.as_ref().map(|r| r.tolerance),
        "material": render.as_ref().map(|r| r.material.as_str()),
    });
    let mut report = report_json(input, options, &results, Some(&rec));
    if let (Some(r), Some(map)) = (&rendered, report.as_object_mut()) {
        map.insert("render_recommendation".into(), serde_json::to_value(r)?);
    }
    let text = serde_json::to_string_pretty(&report)? + "\n";
    match &args.out {
        None => super::write_stdout(text.as_bytes())?,
        Some(dir) => {
            std::fs::create_dir_all(dir).map_err(|e| anyhow!("{}: cannot create directory ({e})", dir.display()))?;
            ndfit::io::write_bytes_atomic(&dir.join("scale.json"), text.as_bytes())?;
            ndfit::io::write_atomic(&dir.join("scale.csv"), |w| write_csv(w, &results))?;
            ndfit::scale::write_plot(&dir.join("scale.png"), &results)?;
            eprintln!("{}", rec.explanation);
            if let Some(r) = &rendered {
                eprintln!("{}", r.explanation);
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}
