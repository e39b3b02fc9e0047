//! `ndfit wave SCAN [--wavelength NM,..] [--incidence DEG,..] [--coherence UM] [-o OUT.json]`: the scan's
//! scalar-diffraction BRDF (docs/WAVE.md): the mirror share and the diffuse albedo per wavelength and
//! incidence in `ndfit.wave/1`; `--grid-out PREFIX` writes the diffuse BRDF on an N x N grid of the
//! projected disk (`PREFIX.npy`); `--to rgl -o OUT.bsdf` writes the diffuse part as a tabulated material.
//! The scan is read and preprocessed as `ndfit fit` reads it (plane removed by default).

use std::io::IsTerminal;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use ndfit::export::rgl::Material;
use ndfit::wave::{wave, WaveOptions, DEFAULT_LEVEL_RATIO};

use super::scan_args::ScanArgs;

/// Arguments of `ndfit wave`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    pub scan: ScanArgs,
    /// Wavelengths in nm, comma-separated.
    #[arg(long, value_delimiter = ',', default_value = "450,550,650", allow_hyphen_values = true)]
    pub wavelength: Vec<f64>,
    /// Incident elevations in degrees from the normal, comma-separated (each in [0, 89.9]).
    #[arg(long, value_delimiter = ',', default_value = "0,30,45,60,75", allow_hyphen_values = true)]
    pub incidence: Vec<f64>,
    /// Incident azimuth in degrees (0 = the scan's +x, 90 = +y).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    pub azimuth: f64,
    /// Side of the patch over which the light is coherent, in micrometres (default: sunlight's coherence
    /// area at 550 nm, 18.9 um; docs/WAVE.md).
    #[arg(long, value_name = "UM", allow_hyphen_values = true)]
    pub coherence: Option<f64>,
    /// The conductor whose Fresnel factor `albedo` includes: none (1), Al, Ag, Au, Cu, Cr.
    #[arg(long, default_value = "none")]
    pub material: Material,
    /// Cells per side of the grid written by --grid-out.
    #[arg(long, default_value_t = 64, allow_hyphen_values = true)]
    pub grid: i64,
    /// Write the diffuse BRDF (1/sr, material none) on the N x N grid of the projected outgoing disk as
    /// PREFIX.npy: float64, shape (wavelengths, incidences, N, N).
    #[arg(long, value_name = "PREFIX")]
    pub grid_out: Option<PathBuf>,
    /// Largest ratio between neighbouring v_z levels (smaller: more levels, slower, closer).
    #[arg(long, default_value_t = DEFAULT_LEVEL_RATIO)]
    pub level_ratio: f64,
    /// Output JSON (`ndfit.wave/1`; without it the JSON goes to standard output), or with `--to rgl` the table.
    #[arg(short = 'o', long)]
    pub out: Option<PathBuf>,
    /// What to write: json (the report) or rgl (the diffuse BRDF as a tabulated material, to -o).
    #[arg(long = "to", default_value = "json", value_name = "FORMAT")]
    pub to: String,
    /// No summary line on standard error.
    #[arg(long)]
    pub quiet: bool,
    #[command(flatten, next_help_heading = "The diffuse BRDF as a material (--to rgl)")]
    pub rgl: super::wave_rgl::RglArgs,
}

impl Args {
    /// The library options these arguments ask for.
    pub fn options(&self) -> anyhow::Result<WaveOptions> {
        let opts = WaveOptions {
            wavelengths_nm: self.wavelength.clone(),
            incidences_deg: self.incidence.clone(),
            azimuth_deg: self.azimuth,
            coherence_m: self.coherence.map(|um| um * 1e-6),
            material: self.material,
            level_ratio: self.level_ratio,
        };
        opts.validate().with_context(|| self.scan.scan.display().to_string())?;
        Ok(opts)
    }
}

/// Run `ndfit wave`.
pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    let name = a.scan.scan.display().to_string();
    match a.to.as_str() {
        "json" => {}
        "rgl" => return super::wave_rgl::run(&a),
        other => anyhow::bail!("{name}: --to: {other:?} is not json or rgl"),
    }
    // Every option is checked before the scan is read, and the outputs before any work.
    let opts = a.options()?;
    if !(1..=4096).contains(&a.grid) {
        anyhow::bail!("{name}: --grid {} is outside 1..=4096", a.grid);
    }
    let npy = a.grid_out.as_ref().map(|p| {
        let mut s = p.clone().into_os_string();
        s.push(".npy");
        PathBuf::from(s)
    });
    a.scan.check_outputs(a.out.as_deref().into_iter().chain(npy.as_deref()))?;
    let scan = a.scan.load()?;
    let bar = patch_bar(a.quiet);
    let progress = |done: usize, total: usize| show(&bar, done, total);
    let (report, d) = wave(&scan, &opts, Some(&progress)).with_context(|| name.clone())?;
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    if let Some(p) = &npy {
        ndfit::wave::write_grid_npy(p, &d, &opts.wavelengths_nm, &opts.incidences_deg, opts.azimuth_deg, a.grid as usize)?;
    }
    let json = serde_json::to_string_pretty(&report)? + "\n";
    match &a.out {
        Some(path) => ndfit::io::write_atomic(path, |w| w.write_all(json.as_bytes()).map_err(ndfit::Error::io))?,
        None => super::write_stdout(json.as_bytes())?,
    }
    if !a.quiet {
        eprintln!("ndfit: wave: {}", summary(&report));
        for w in &report.warnings {
            eprintln!("ndfit: wave: note: {w}");
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// One line: the mirror share at each incidence of the middle wavelength, and the patches.
fn summary(r: &ndfit::wave::WaveReport) -> String {
    let mid = r.records[r.records.len() / 2].wavelength_nm;
    let shares: Vec<String> =
        r.records.iter().filter(|x| x.wavelength_nm == mid).map(|x| format!("{:.3} at {} deg", x.specular, x.theta_deg)).collect();
    format!("mirror share at {mid} nm {} ({} patches of {:.1} um)", shares.join(", "), r.patches.used, r.patches.coherence_m * 1e6)
}

/// The coherence patches' progress bar, on standard error when it is a terminal and not `quiet`.
pub(super) fn patch_bar(quiet: bool) -> Option<indicatif::ProgressBar> {
    (std::io::stderr().is_terminal() && !quiet).then(|| {
        let b = indicatif::ProgressBar::new(0);
        if let Ok(style) = indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} coherence patches ({eta} left)") {
            b.set_style(style);
        }
        b
    })
}

/// Show `done` of `total` patches on `bar`.
pub(super) fn show(bar: &Option<indicatif::ProgressBar>, done: usize, total: usize) {
    if let Some(b) = bar {
        b.set_length(total as u64);
        b.set_position(done as u64);
    }
}
