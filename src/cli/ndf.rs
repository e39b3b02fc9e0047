//! `ndfit ndf SCAN [-o NDF.csv|NDF.json] [--exr D.exr] [--png PREFIX]`: the empirical NDF of a scan (CSV on
//! standard output without `-o`).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use ndfit::ndf::{self, EmpiricalNdf, NdfOptions, NormalScheme};
use ndfit::pipeline::check::{self, Spelling};
use ndfit::scan::InputInfo;
use ndfit::{Options, Pipeline};

use super::scan_args::ScanArgs;

/// How the empirical NDF is built; `ndfit fit` flattens these too.
#[derive(Debug, Clone, clap::Args)]
pub struct NdfArgs {
    /// Normals: central (central differences, default) or triangles (exact Gauss map of the
    /// triangulated surface, two facets per grid cell).
    #[arg(long, default_value = "central")]
    pub normals: String,
    /// Cells across the Lambert disk of the whitened hemisphere (odd, 3-1023). Default: chosen from the
    /// number of samples so that bins hold about --target-count samples on average (15-255).
    #[arg(long, allow_hyphen_values = true)]
    pub ndf_cells: Option<usize>,
    /// Mean samples per bin aimed at when --ndf-cells is not given.
    #[arg(long, default_value_t = ndfit::ndf::DEFAULT_TARGET_COUNT, allow_hyphen_values = true)]
    pub target_count: f64,
}

impl NdfArgs {
    /// The library options these flags ask for.
    pub fn options(&self) -> anyhow::Result<NdfOptions> {
        let scheme: NormalScheme = self.normals.parse()?;
        Ok(check::ndf_options(scheme, self.ndf_cells, Some(self.target_count), Spelling::Flag)?)
    }
}

/// Arguments of `ndfit ndf`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    scan: ScanArgs,
    #[command(flatten)]
    ndf: NdfArgs,
    /// Output file: `.csv` (one row per bin) or `.json` (`ndfit.ndf/1`); see data_formats/ndf_csv.md.
    /// Without it the CSV goes to standard output.
    #[arg(short, long)]
    output: Option<PathBuf>,
    /// Also write an OpenEXR image of D over the orthographically projected hemisphere.
    #[arg(long)]
    exr: Option<PathBuf>,
    /// Size of the EXR image in pixels.
    #[arg(long, default_value_t = 512)]
    exr_size: usize,
    /// Also write PNG plots: PREFIX.map.png (false-colour log D) and PREFIX.slices.png.
    #[arg(long)]
    png: Option<PathBuf>,
}

/// The `input` block of the JSON output.
fn input_json(i: &InputInfo) -> serde_json::Value {
    serde_json::json!({
        "path": i.path, "format": i.format,
        "nx": i.nx, "ny": i.ny, "dx": i.dx, "dy": i.dy, "invalid": i.invalid,
    })
}

/// Write the NDF to `out` by extension.
pub fn write_ndf(out: &Path, ndf: &EmpiricalNdf, input: serde_json::Value) -> anyhow::Result<()> {
    let ext = out.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase());
    match ext.as_deref() {
        Some("csv") => ndf::write_csv(out, ndf)?,
        Some("json") => ndf::write_json(out, ndf, input)?,
        _ => anyhow::bail!("{}: output must end in .csv or .json", out.display()),
    }
    Ok(())
}

/// Run `ndfit ndf`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let opts = args.ndf.options()?;
    // Check the output names before the work, so a typo fails fast and nothing is half-written.
    if let Some(out) = &args.output {
        let ext = out.extension().and_then(|e| e.to_str()).map(|e| e.to_ascii_lowercase());
        anyhow::ensure!(matches!(ext.as_deref(), Some("csv" | "json")), "{}: output must end in .csv or .json", out.display());
    }
    let pngs: Vec<PathBuf> =
        args.png.iter().flat_map(|p| ["map", "slices"].map(|s| PathBuf::from(format!("{}.{s}.png", p.display())))).collect();
    args.scan.check_outputs(args.output.as_deref().into_iter().chain(args.exr.as_deref()).chain(pngs.iter().map(|p| p.as_path())))?;
    let pipeline = Pipeline::new(Options {
        read: args.scan.how.read_options(),
        preprocess: args.scan.how.preprocess(),
        ndf: opts,
        ..Options::default()
    });
    let (input, ndf) = pipeline.ndf_path(&args.scan.scan)?;
    for w in &ndf.warnings {
        eprintln!("ndfit: {}: warning: {w}", args.scan.scan.display());
    }
    // The optional outputs first: a plot that fails leaves no NDF file behind that looks like success.
    if let Some(exr) = &args.exr {
        ndf::write_exr(exr, &ndf, args.exr_size)?;
    }
    if let Some(prefix) = &args.png {
        let name = args.scan.scan.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let p = |suffix: &str| PathBuf::from(format!("{}.{suffix}.png", prefix.display()));
        ndf::plot_map(&p("map"), &ndf, &format!("empirical NDF of {name} ({} normals)", ndf.scheme.as_str()))
            .with_context(|| format!("{}", p("map").display()))?;
        ndf::plot_slices(&p("slices"), &ndf, &format!("{name}: D through the peak"))
            .with_context(|| format!("{}", p("slices").display()))?;
    }
    let _p = ndfit::phases::phase("write");
    match &args.output {
        Some(out) => write_ndf(out, &ndf, input_json(&input))?,
        None => {
            let mut csv = Vec::new();
            ndf::write_csv_to(&mut csv, &ndf)?;
            super::write_stdout(&csv)?;
        }
    }
    eprintln!(
        "ndfit ndf: {} samples ({} skipped) in {} bins ({} x {} Lambert cells, {} normals)",
        ndf.n_samples,
        ndf.n_skipped,
        ndf.bins.len(),
        ndf.grid.n,
        ndf.grid.n,
        ndf.scheme.as_str()
    );
    Ok(ExitCode::SUCCESS)
}
