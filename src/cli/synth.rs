//! `ndfit synth OUT.x3p --surface ellipsoid|gaussian|planes ...`: a synthetic scan with known truth,
//! written as X3P with its truth beside it (`OUT.truth.json`, schema `ndfit.synth/1`).

use std::path::PathBuf;
use std::process::ExitCode;

use ndfit::synth::{ellipsoid_surface, gaussian_surface, tilted_planes, EllipsoidParams, GaussianParams, PlaneFacet, SynthSettings};

/// Arguments of `ndfit synth`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Output scan (X3P).
    output: PathBuf,
    /// Where the truth goes (default: the output with extension `.truth.json`).
    #[arg(long)]
    truth: Option<PathBuf>,
    /// Surface: ellipsoid (upper half of a rotated ellipsoid; NDF = ellipsoid NDF), gaussian (Gaussian
    /// random surface; NDF = anisotropic Beckmann) or planes (tilted plane strips; delta NDFs).
    #[arg(long, default_value = "ellipsoid")]
    surface: String,
    /// Columns.
    #[arg(long, default_value_t = 1024)]
    nx: usize,
    /// Rows.
    #[arg(long, default_value_t = 1024)]
    ny: usize,
    /// Spacing along x (m).
    #[arg(long, default_value_t = 1e-6)]
    dx: f64,
    /// Spacing along y (m, default: --dx).
    #[arg(long)]
    dy: Option<f64>,
    /// Random seed (phases, noise, holes).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Standard deviation of white height noise (m).
    #[arg(long, default_value_t = 0.0)]
    noise: f64,
    /// Fraction of points masked invalid at random.
    #[arg(long, default_value_t = 0.0)]
    holes: f64,
    /// Constant added to every height (m).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    offset: f64,
    /// Ellipsoid: alpha_x.
    #[arg(long, default_value_t = 0.3)]
    alpha_x: f64,
    /// Ellipsoid: alpha_y (default: alpha_x).
    #[arg(long)]
    alpha_y: Option<f64>,
    /// Ellipsoid: theta_x (rad).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    theta_x: f64,
    /// Ellipsoid: theta_y (rad).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    theta_y: f64,
    /// Ellipsoid and gaussian: theta_z (rad); the alpha_x axis lies along (cos theta_z, -sin theta_z).
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    theta_z: f64,
    /// Ellipsoid: fraction of the grid the footprint fills.
    #[arg(long, default_value_t = 0.96)]
    fill: f64,
    /// Gaussian: RMS slope along local x.
    #[arg(long, default_value_t = 0.2)]
    sigma_x: f64,
    /// Gaussian: RMS slope along local y (default: sigma_x).
    #[arg(long)]
    sigma_y: Option<f64>,
    /// Gaussian: correlation length (m, default 8 dx).
    #[arg(long)]
    corr_length: Option<f64>,
    /// Planes: one facet `SX,SY[,WEIGHT]` (slope grad h and relative width); repeat for strips.
    #[arg(long, allow_hyphen_values = true)]
    plane: Vec<String>,
    /// Write the surface repeated N x N times (--nx by --ny is one tile; a spectral surface is periodic,
    /// so the copies join seamlessly), streamed row by row: scans larger than memory, for the tiled read.
    #[arg(long, default_value_t = 1)]
    repeat: usize,
}

fn parse_plane(s: &str) -> anyhow::Result<PlaneFacet> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|_| anyhow::anyhow!("--plane {s:?} is not SX,SY[,WEIGHT]"))?;
    match v.as_slice() {
        [sx, sy] => Ok(PlaneFacet { slope: [*sx, *sy], weight: 1.0 }),
        [sx, sy, w] => Ok(PlaneFacet { slope: [*sx, *sy], weight: *w }),
        _ => anyhow::bail!("--plane {s:?} is not SX,SY[,WEIGHT]"),
    }
}

/// Run `ndfit synth`.
pub fn run(a: Args) -> anyhow::Result<ExitCode> {
    let s = SynthSettings {
        nx: a.nx,
        ny: a.ny,
        dx: a.dx,
        dy: a.dy.unwrap_or(a.dx),
        seed: a.seed,
        noise: a.noise,
        holes: a.holes,
        offset: a.offset,
    };
    let (hf, mut truth) = match a.surface.as_str() {
        "ellipsoid" => {
            let p = EllipsoidParams {
                alpha_x: a.alpha_x,
                alpha_y: a.alpha_y.unwrap_or(a.alpha_x),
                theta_x: a.theta_x,
                theta_y: a.theta_y,
                theta_z: a.theta_z,
                fill: a.fill,
            };
            ellipsoid_surface(&s, &p)?
        }
        "gaussian" => {
            let p = GaussianParams {
                sigma_x: a.sigma_x,
                sigma_y: a.sigma_y.unwrap_or(a.sigma_x),
                theta_z: a.theta_z,
                corr_length: a.corr_length.unwrap_or(8.0 * a.dx),
            };
            gaussian_surface(&s, &p)?
        }
        "planes" => {
            let facets = if a.plane.is_empty() {
                vec![PlaneFacet { slope: [0.1, 0.0], weight: 1.0 }]
            } else {
                a.plane.iter().map(|p| parse_plane(p)).collect::<anyhow::Result<Vec<_>>>()?
            };
            tilted_planes(&s, &facets)?
        }
        other => anyhow::bail!("unknown --surface {other:?} (expected ellipsoid, gaussian or planes)"),
    };
    let truth_path = a.truth.clone().unwrap_or_else(|| a.output.with_extension("truth.json"));
    truth.input = Some(serde_json::json!({
        "path": a.output.display().to_string(), "format": "x3p", "nx": hf.nx * a.repeat.max(1), "ny": hf.ny * a.repeat.max(1), "dx": hf.dx, "dy": hf.dy,
    }));
    if a.repeat > 1 {
        // A periodic tile repeated: the scan is written row by row, never held whole.
        ndfit::io::write_x3p_repeated(&a.output, &hf, a.repeat, a.repeat)?;
    } else {
        ndfit::io::write_x3p(&a.output, &hf)?;
    }
    ndfit::io::write_bytes_atomic(&truth_path, truth.to_json().as_bytes())?;
    let k = a.repeat.max(1);
    eprintln!(
        "ndfit synth: {} ({} x {}, {} invalid) and {}",
        a.output.display(),
        hf.nx * k,
        hf.ny * k,
        hf.invalid_count() * k * k,
        truth_path.display()
    );
    Ok(ExitCode::SUCCESS)
}
