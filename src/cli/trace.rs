//! `ndfit trace SCAN --incidence 0,40,70 [-o OUT.json]`: trace the scan's own microgeometry with
//! geometric optics and measure the microfacet model against it (docs/TRACE.md). The scan is read and
//! preprocessed as `ndfit fit` reads it (plane removed by default); the verdict line goes to standard
//! error; `--plot OUT.png` draws the first bounce's BRDF and the masking against the model; `--tables
//! OUT.csv` writes the per-bin tables for outside checks. `--to rgl -o OUT.bsdf` writes the traced BRDF
//! as a tabulated material instead (`trace_rgl.rs`).

use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use ndfit::export::rgl::Material;
use ndfit::trace::{trace, Border, DirTable, TraceOptions};

use super::scan_args::ScanArgs;

/// Arguments of `ndfit trace`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub scan: ScanArgs,
    /// Incident elevations in degrees from the normal, comma-separated (each in [0, 89.9]).
    #[arg(long, value_delimiter = ',', default_value = "0,40,70", allow_hyphen_values = true)]
    pub incidence: Vec<f64>,
    /// Incident azimuth in degrees (0 = the scan's +x, 90 = +y).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub azimuth: f64,
    /// The conductor's Fresnel factor at each bounce: none (1, the white furnace), Al, Ag, Au, Cu, Cr.
    #[arg(long, default_value = "none")]
    pub material: Material,
    /// Largest number of bounces a path follows.
    #[arg(long, default_value_t = 16)]
    pub bounces: usize,
    /// Seed of the random generators (the same seed gives the same output on any number of threads).
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Paths per incidence.
    #[arg(long, default_value_t = 1 << 20)]
    pub rays: usize,
    /// Grid edges: periodic (the grid repeats; exact energy balance) or open (rays leave at the sides).
    #[arg(long, default_value = "periodic")]
    pub border: Border,
    /// Outgoing-direction bins: elevation x azimuth (for example 32x64).
    #[arg(long, default_value = "32x64", value_parser = parse_bins)]
    pub bins: DirTable,
    /// Largest single-bounce error beyond noise and multiple-scattering share for the verdict `holds`.
    #[arg(long, default_value_t = 0.05)]
    pub tolerance: f64,
    /// Output JSON (`ndfit.trace/1`; without it the JSON goes to standard output), or with `--to rgl` the
    /// table (written atomically).
    #[arg(short = 'o', long)]
    pub out: Option<PathBuf>,
    /// Also write a PNG: the first bounce's BRDF in the plane of incidence, traced against the
    /// microfacet model, and the traced masking G1 against Smith's over the incidences.
    #[arg(long, value_name = "OUT.png")]
    pub plot: Option<PathBuf>,
    /// Also write the per-bin tables as CSV, one row per incidence and outgoing bin: incidence,
    /// theta_i_deg, phi_i_deg, bin, i_theta, i_phi, theta_lo_deg, theta_hi_deg, phi_lo_deg, phi_hi_deg,
    /// theta_o_deg, phi_o_deg (the bin's centre), ox, oy, oz (its unit vector), proj_solid_angle, then the
    /// energies per landed path single (first bounce), multi (later bounces), model (the microfacet
    /// model's single scattering), each as _r, _g, _b and luminance (no suffix), and var_total (Monte
    /// Carlo variance of the luminance of single + multi). BRDF over a bin = energy / proj_solid_angle.
    #[arg(long, value_name = "OUT.csv")]
    pub tables: Option<PathBuf>,
    /// No verdict line on standard error.
    #[arg(long)]
    pub quiet: bool,
    /// What to write: json (the comparison, `ndfit.trace/1`) or rgl (the traced BRDF as a tabulated
    /// material for Mitsuba 3's and pbrt-v4's `measured`, written to -o; docs/TRACE.md).
    #[arg(long = "to", default_value = "json", value_name = "FORMAT")]
    pub to: String,
    #[command(flatten, next_help_heading = "The traced BRDF as a material (--to rgl)")]
    pub rgl: super::trace_rgl::RglArgs,
}

/// `THETAxPHI` bins.
fn parse_bins(s: &str) -> Result<DirTable, String> {
    s.parse::<DirTable>().map_err(|e| e.message().to_string())
}

/// Run `ndfit trace`.
pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    match a.to.as_str() {
        "json" => {}
        "rgl" => return super::trace_rgl::run(&a),
        other => anyhow::bail!("{}: --to: {other:?} is not json or rgl", a.scan.scan.display()),
    }
    let opts = TraceOptions {
        incidences_deg: a.incidence.clone(),
        azimuth_deg: a.azimuth,
        material: a.material,
        bounces: a.bounces,
        seed: a.seed,
        rays: a.rays,
        border: a.border,
        table: a.bins,
        tolerance: a.tolerance,
        spread_over_bin: false,
    };
    // Every option is checked before the scan is read, and the output before any work.
    opts.validate()?;
    a.scan.check_outputs(a.out.as_deref().into_iter().chain(a.plot.as_deref()).chain(a.tables.as_deref()))?;
    let scan = a.scan.load()?;
    let bar = (std::io::stderr().is_terminal() && !a.quiet).then(|| {
        let b = indicatif::ProgressBar::new((opts.rays * opts.incidences_deg.len()) as u64);
        if let Ok(style) = indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} paths ({per_sec}, {eta} left)") {
            b.set_style(style);
        }
        b
    });
    let progress = |done: u64, _total: u64| {
        if let Some(b) = &bar {
            b.set_position(done);
        }
    };
    let report = trace(&scan, &opts, Some(&progress)).with_context(|| a.scan.scan.display().to_string())?;
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    let json = serde_json::to_string_pretty(&report)? + "\n";
    match &a.out {
        Some(path) => ndfit::io::write_atomic(path, |w| w.write_all(json.as_bytes()).map_err(ndfit::Error::io))?,
        None => super::write_stdout(json.as_bytes())?,
    }
    if let Some(p) = &a.plot {
        ndfit::trace::write_plot(p, &report)?;
    }
    if let Some(p) = &a.tables {
        ndfit::trace::write_tables_csv(p, &report)?;
    }
    if !a.quiet {
        eprintln!("ndfit: trace: {}", report.verdict.line);
    }
    Ok(ExitCode::SUCCESS)
}
