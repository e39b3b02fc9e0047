//! `ndfit export FIT.json --to mitsuba|pbrt|blender|openpbr|materialx [--json]`: a fit as a renderer's
//! parameters, or its mirror answer as the renderer's smooth conductor and haze (the math is in
//! `ndfit::export`); `ndfit export FIT.json|SCAN --to rgl -o OUT.bsdf`: the fit or the scan's own NDF as a
//! tabulated BSDF (`ndfit::export::rgl`).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{anyhow, bail, Context};
use ndfit::export::rgl::{self, Flavour, Material, RglOptions};
use ndfit::export::{export, export_mirror, MirrorAnswer, Target};
use ndfit::models::{Model, Ndf};

use super::fit_args::FitHow;
use super::scan_args::ReadArgs;

/// Arguments of `ndfit export`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A fit result (`ndfit.fit/1`) or any JSON object with `model` and `params`; with `--to rgl` also a
    /// scan, whose own NDF is tabulated.
    pub fit: PathBuf,
    /// The renderer: mitsuba (roughconductor), pbrt (conductor, pbrt-v4), blender (a Python script: Principled
    /// BSDF for GGX, Glossy BSDF for Beckmann), openpbr (OpenPBR Surface), materialx (conductor_bsdf), or rgl
    /// (a tabulated BSDF file for Mitsuba 3's `measured` and pbrt-v4's `measured`, written to `-o`). A fit
    /// whose answer is a mirror (`mirror`, `mirror+ggx`) is written as the renderer's smooth conductor,
    /// blended with its haze lobe.
    #[arg(long = "to", value_name = "RENDERER")]
    pub to: String,
    /// Print one JSON object (the contract's keys, plus `note` and `approximation` when the fit had to be
    /// approximated) instead of a snippet in the renderer's syntax.
    #[arg(long)]
    pub json: bool,
    /// The tabulated BSDF to write (`--to rgl` only; written atomically).
    #[arg(short = 'o', long)]
    pub output: Option<PathBuf>,
    /// `--to rgl`: the conductor: none (a perfect mirror, F = 1), Al, Ag, Au, Cu or Cr.
    #[arg(long, default_value = "none")]
    pub material: String,
    /// `--to rgl`: the table's resolution and channels.
    #[command(flatten, next_help_heading = "The table (--to rgl)")]
    pub table: TableArgs,
    /// `--to rgl` of a scan: how it is read, preprocessed, binned and fitted (the flags of `ndfit fit`,
    /// `auto` as the fit the tabulated NDF's tails come from); unused for a fit file.
    #[command(flatten, next_help_heading = "Reading, binning and fitting a scan (--to rgl of a scan; as ndfit fit)")]
    pub read: ReadArgs,
    #[command(flatten)]
    pub how: FitHow,
}

/// An RGL table's resolution and channels, the flags `ndfit export --to rgl` and `ndfit trace --to rgl`
/// share.
#[derive(Debug, Clone, clap::Args)]
pub struct TableArgs {
    /// Write `spectra` with `wavelengths` (pbrt-v4, Mitsuba's spectral variants) instead of `rgb`
    /// (Mitsuba's RGB variants, which refuse a file with wavelengths).
    #[arg(long)]
    pub spectral: bool,
    /// Incident elevations, 0 to 90 degrees [default: 12 for export, 16 for trace --to rgl].
    #[arg(long)]
    pub theta_i: Option<usize>,
    /// Incident azimuths over the full turn, both ends included [default: 25 for export, 17 for trace --to
    /// rgl].
    #[arg(long)]
    pub phi_i: Option<usize>,
    /// Nodes per axis of the NDF grid (8 to 512); by default the smallest of 64, 128, 256 and 512 at which
    /// the renderer's interpolation reproduces the NDF to 1% down to 1e-4 of its peak (the projected-area
    /// grid takes at most 64).
    #[arg(long)]
    pub ndf_res: Option<usize>,
    /// Nodes per axis of the sampling warps and the reflectance [default: 88 for export, 64 for trace --to
    /// rgl]. The file's size grows with its square times theta_i x phi_i: 46 MB for RGB at export's
    /// defaults, 22 MB at trace's; what each resolution gives near grazing outgoing directions is in
    /// data_formats/rgl.md, "The tails".
    #[arg(long)]
    pub warp_res: Option<usize>,
}

impl TableArgs {
    /// The table these flags ask for, of the conductor `material`, `defaults` where a flag is not given.
    pub fn options(&self, material: Material, defaults: RglOptions) -> RglOptions {
        RglOptions {
            theta_i: self.theta_i.unwrap_or(defaults.theta_i),
            phi_i: self.phi_i.unwrap_or(defaults.phi_i),
            ndf_res: self.ndf_res.or(defaults.ndf_res),
            warp_res: self.warp_res.unwrap_or(defaults.warp_res),
            material,
            flavour: if self.spectral { Flavour::Spectral } else { Flavour::Rgb },
        }
    }
}

/// Run `ndfit export`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let path = args.fit.display().to_string();
    if args.to == "rgl" {
        return run_rgl(&args, &path);
    }
    if args.output.is_some() {
        bail!("{path}: -o is for --to rgl (the other renderers' exports go to standard output)");
    }
    let target: Target =
        args.to.parse().map_err(|e: ndfit::Error| anyhow!("{path}: --to: {}; or rgl for a tabulated BSDF", e.message()))?;
    let json = read_json(&args.fit, &path)?;
    // The fit region of the fit, over which an approximation is fitted and measured.
    let max_theta = json.pointer("/quality/max_theta_deg").and_then(|v| v.as_f64()).unwrap_or(90.0);
    let name = args.fit.file_name().map_or(path.clone(), |n| n.to_string_lossy().into_owned());
    // A mirror answer is the optics' material, not the ladder's model.
    if let Some(answer) = MirrorAnswer::from_json(&json).map_err(|e| anyhow!("{path}: {}", e.message()))? {
        let out = export_mirror(&answer, target, max_theta).map_err(|e| anyhow!("{path}: {}", e.message()))?;
        for note in out.notes() {
            eprintln!("ndfit: {path}: {note}");
        }
        // What the blend's approximation shows in the render.
        let error = ndfit::answer::blend_render_error(&answer, &out).map_err(|e| anyhow!("{path}: {}", e.message()))?;
        if let Some(e) = &error {
            let scenes: Vec<String> = e.per_scene.iter().map(|(s, v)| format!("{s} {v:.4}")).collect();
            eprintln!(
                "ndfit: {path}: {}'s blend renders within mean HDR-FLIP {:.4} of the answer with its listed shares ({}; both with F = 1)",
                target.as_str(),
                e.worst,
                scenes.join(", ")
            );
        }
        // Renderers that load a table can have the haze the scan's heights predict instead of its lobe.
        if answer.haze.is_some() && matches!(target, Target::Mitsuba | Target::Pbrt) {
            let scan = json.pointer("/input/path").and_then(|v| v.as_str()).unwrap_or("SCAN");
            eprintln!(
                "ndfit: {path}: the haze as the scan's heights predict it (wave optics; not a lobe) is a table {} loads: `ndfit wave {scan} --to rgl --with-mirror -o HAZE.bsdf` writes it and prints this blend with it",
                if target == Target::Mitsuba { "Mitsuba 3 (its spectral variants)" } else { "pbrt-v4" }
            );
        }
        let json = || {
            let mut v = out.to_json();
            if let (Some(e), Some(m)) = (&error, v.as_object_mut()) {
                let mut r: serde_json::Map<String, serde_json::Value> = e.per_scene.iter().map(|(s, x)| (s.clone(), (*x).into())).collect();
                r.insert("worst".into(), e.worst.into());
                m.insert("render_error".into(), r.into());
            }
            v
        };
        return emit(args.json, &path, json, || out.snippet(&name));
    }
    let model = Model::from_json(&json).map_err(|e| anyhow!("{path}: not a fit result: {}", e.message()))?;
    if let Model::Mixture(x) = &model {
        let out = ndfit::export::export_mixture(x, target, max_theta).map_err(|e| anyhow!("{path}: {}", e.message()))?;
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

/// `--to rgl`: tabulate a fit file's model, or a scan's regularized empirical NDF, and write the tensor file.
fn run_rgl(args: &Args, path: &str) -> anyhow::Result<ExitCode> {
    let fit = if looks_like_json(&args.fit)? { Some(read_json(&args.fit, path)?) } else { None };
    // A mirror answer is refused before the table's own flags are checked: no flag would make it a table.
    if let Some(a) = fit.as_ref().map(MirrorAnswer::from_json).transpose().map_err(|e| anyhow!("{path}: {}", e.message()))?.flatten() {
        bail!("{path}: the answer is {}, a mirror's delta reflection, which an RGL table cannot hold; export it with --to mitsuba (or pbrt, blender, openpbr, materialx)", a.answer);
    }
    let Some(out) = &args.output else { bail!("{path}: --to rgl writes a file: give it with -o OUT.bsdf") };
    if args.json {
        bail!("{path}: --json is not for --to rgl (the table is a binary file)");
    }
    let material: Material = args.material.parse().map_err(|e: ndfit::Error| anyhow!("{path}: --material: {}", e.message()))?;
    let opts = args.table.options(material, RglOptions::default());
    ndfit::io::protect_input(&args.fit);
    ndfit::io::check_output(out)?;
    let name = args.fit.file_name().map_or(path.to_string(), |n| n.to_string_lossy().into_owned());
    let tail = format!(
        "Smith masking-shadowing (separable) from the tabulated NDF; conductor {}; phi = 0 and the tangent u along the scan's +x",
        material_text(material)
    );
    let fail = |e: ndfit::Error| anyhow!("{path}: {}", e.message());
    let table = if let Some(json) = &fit {
        let model = Model::from_json(json).map_err(|e| anyhow!("{path}: not a fit result: {}", e.message()))?;
        let description = format!("ndfit tabulated {} model of {name} {}; {tail}", model.id(), params_text(&model));
        rgl::tabulate(&|m| model.d(m), &description, &opts, false).map_err(fail)?
    } else {
        let options = args.how.options(&args.read, ndfit::ModelChoice::Auto, &args.fit)?;
        let (outcome, fit, max_theta) = scan_table_ndf(options, &args.fit)?;
        let reg = rgl::Regularized::new(&outcome.ndf, &fit, max_theta);
        let description = format!(
            "ndfit measured NDF of the scan {name}: {}; fitted {} {}; {tail}",
            reg.describe(max_theta),
            fit.id(),
            params_text(&fit)
        );
        rgl::tabulate_guided(&|m| reg.d(m), &|m| fit.d(m), &description, &opts, true).map_err(fail)?
    };
    let bytes = table.tensor.to_bytes();
    ndfit::io::write_bytes_atomic(out, &bytes)?;
    eprintln!(
        "ndfit: {path}: wrote {} ({} bytes; NDF grid {n}^2, read back within {:.2}% down to {:.0e} of its peak)",
        out.display(),
        bytes.len(),
        100.0 * table.ndf_error,
        rgl::SIGNIFICANT,
        n = table.ndf_res
    );
    if table.ndf_error > rgl::NDF_TOLERANCE {
        eprintln!(
            "ndfit: {path}: the NDF is too narrow for a grid of {}^2 nodes: a renderer reads it {:.1}% off in places (512, the largest, is the format's limit here)",
            table.ndf_res,
            100.0 * table.ndf_error
        );
    }
    Ok(ExitCode::SUCCESS)
}

/// What `--to rgl` of a scan tabulates: the pipeline's outcome (the empirical NDF and the fit), the lobe
/// whose tails fill the NDF ([`ndfit::fit::FitReport::table_model`]) and the fit region (degrees), for
/// [`rgl::Regularized`]. `ndfit trace --to rgl` lays its reflectance on the same NDF.
pub(super) fn scan_table_ndf(options: ndfit::Options, scan: &Path) -> anyhow::Result<(ndfit::Outcome, Model, f64)> {
    // The table is the scan's NDF filled by the ladder's closest lobe whatever the render answers, so
    // the render choice need not run here.
    let options = ndfit::Options { render: None, ..options };
    let outcome = ndfit::Pipeline::new(options).run_path(scan)?;
    let fit = outcome.fit.table_model()?;
    let max_theta = outcome.fit.quality.max_theta_deg;
    Ok((outcome, fit, max_theta))
}

/// The fit file's JSON document.
fn read_json(p: &Path, path: &str) -> anyhow::Result<serde_json::Value> {
    let text = std::fs::read_to_string(p).with_context(|| format!("{path}: cannot read"))?;
    serde_json::from_str(&text).map_err(|e| anyhow!("{path}: not valid JSON ({e})"))
}

/// Whether the file's first non-blank byte opens a JSON object (a fit), rather than a scan.
fn looks_like_json(p: &Path) -> anyhow::Result<bool> {
    use std::io::Read;
    let mut head = [0u8; 256];
    let n = std::fs::File::open(p).and_then(|mut f| f.read(&mut head)).with_context(|| format!("{}: cannot read", p.display()))?;
    Ok(head[..n].iter().find(|b| !b.is_ascii_whitespace()) == Some(&b'{'))
}

/// `(name = value, ...)` of a model's parameters.
pub(super) fn params_text(m: &Model) -> String {
    let names = m.id().param_names();
    let vals = m.params();
    let parts: Vec<String> = names.iter().zip(&vals).map(|(n, v)| format!("{n} = {v:.6}")).collect();
    format!("({})", parts.join(", "))
}

/// The material as the description states it.
pub(super) fn material_text(m: Material) -> String {
    match m {
        Material::None => "none (F = 1)".into(),
        _ => format!("{} (complex index: {})", m.as_str(), m.source()),
    }
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
