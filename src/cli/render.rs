//! `ndfit render INPUT [--scene point|broad|window] [--light THETA,PHI] [--view THETA,PHI] [--size N] -o OUT.exr|OUT.npy`:
//! a scene of `ndfit::render` (the sphere, or the plate under a window) with a fit's lobe (JSON; a mirror
//! answer as its mirror and haze) or an RGL table (`.bsdf`, evaluated as Mitsuba 3's `measured` does; a
//! wave BRDF's table with its mirror share as a mirror), written as OpenEXR or NumPy.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{anyhow, bail, Context};
use ndfit::export::rgl::{AnalyticBrdf, Material, Measured, TensorFile};
use ndfit::export::{MirrorAnswer, MirrorBrdf};
use ndfit::models::Model;
use ndfit::render::{direction, Brdf, Light, Scene, Stage, Window};

/// Arguments of `ndfit render`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A fit result (`ndfit fit -o`, or any JSON object with `model` and `params`) or an RGL tabulated BSDF
    /// (`ndfit export --to rgl`).
    pub input: PathBuf,
    /// point (a directional light), broad (a spherical-cap light of `--half-angle`) or window (a plate seen
    /// near grazing under a sharp-edged rectangular light; `--size` is its width, the height 3/5 of it).
    #[arg(long, default_value = "point")]
    pub scene: String,
    /// Direction toward the light, `THETA,PHI` in degrees in the sphere's frame (`z` its pole)
    /// [default: 60,-90, 30 degrees above the default view].
    #[arg(long, value_name = "THETA,PHI")]
    pub light: Option<String>,
    /// Direction toward the camera, `THETA,PHI` in degrees in the sphere's frame [default: 90,-90, the
    /// equator, pole up, the tangent s pointing right at the image's centre].
    #[arg(long, value_name = "THETA,PHI")]
    pub view: Option<String>,
    /// Pixels per side [default: 128 for point, 64 for broad; the width for window, 160].
    #[arg(long)]
    pub size: Option<usize>,
    /// `--scene broad`: the half-angle of the light's cone in degrees.
    #[arg(long, default_value_t = 25.0)]
    pub half_angle: f64,
    /// For a fit: the conductor (none, Al, Ag, Au, Cu or Cr); a table carries its own.
    #[arg(long)]
    pub material: Option<String>,
    /// With a wave BRDF's table (`ndfit wave SCAN --to rgl`): the scan's geometric table (`ndfit export SCAN
    /// --to rgl`) to join it with by incidence, the reference of a scan whose regime changes with the angle
    /// (the wave prediction where the mirror share is at least 0.5, the geometric table below 0.05, linear
    /// in the share between).
    #[arg(long, value_name = "GEOMETRIC.bsdf")]
    pub join: Option<PathBuf>,
    /// The image to write (`.exr` or `.npy`, written atomically).
    #[arg(short = 'o', long)]
    pub output: PathBuf,
}

/// Run `ndfit render`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let path = args.input.display().to_string();
    let out = &args.output;
    let ext = out.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    let as_npy = match ext.as_deref() {
        Some("npy") => true,
        Some("exr") => false,
        _ => bail!("{}: the output must end in .exr or .npy", out.display()),
    };
    let scene = scene(&args).map_err(|e| anyhow!("{path}: {e}"))?;
    scene.validate().map_err(|e| anyhow!("{path}: {}", e.message()))?;
    ndfit::io::protect_input(&args.input);
    ndfit::io::check_output(out)?;
    let bytes = std::fs::read(&args.input).with_context(|| format!("{path}: cannot read"))?;
    let brdf: Box<dyn Brdf> = if bytes.starts_with(b"tensor_file\0") {
        if args.material.is_some() {
            bail!("{path}: --material is for a fit; a table carries its conductor");
        }
        let t = TensorFile::parse(&bytes).map_err(|e| anyhow!("{path}: {}", e.message()))?;
        match (wave_conductor(&t), &args.join) {
            // The wave BRDF's table (`ndfit wave --to rgl`): its diffuse part and its mirror, what light sees.
            (Some(material), None) => Box::new(MirrorBrdf::wave(&t, material).map_err(|e| anyhow!("{path}: {}", e.message()))?),
            (Some(material), Some(geo)) => {
                let gp = geo.display().to_string();
                let bytes = std::fs::read(geo).with_context(|| format!("{gp}: cannot read"))?;
                let g = TensorFile::parse(&bytes).map_err(|e| anyhow!("{gp}: {}", e.message()))?;
                let ramp = [ndfit::answer::GEOMETRIC_SHARE, ndfit::answer::MIRROR_SHARE];
                Box::new(MirrorBrdf::joined(&t, &g, material, ramp).map_err(|e| anyhow!("{path} joined with {gp}: {}", e.message()))?)
            }
            (None, Some(_)) => {
                bail!("{path}: --join is for a wave BRDF's table (ndfit wave SCAN --to rgl); this table has no mirror share")
            }
            (None, None) => Box::new(Measured::new(&t).map_err(|e| anyhow!("{path}: {}", e.message()))?),
        }
    } else {
        if args.join.is_some() {
            bail!("{path}: --join is for a wave BRDF's table (ndfit wave SCAN --to rgl), not a fit");
        }
        let text = std::str::from_utf8(&bytes).map_err(|_| anyhow!("{path}: neither an RGL table nor a JSON fit (not UTF-8)"))?;
        let json: serde_json::Value =
            serde_json::from_str(text).map_err(|e| anyhow!("{path}: neither an RGL table nor valid JSON ({e})"))?;
        let material: Material =
            args.material.as_deref().unwrap_or("none").parse().map_err(|e: ndfit::Error| anyhow!("{path}: --material: {}", e.message()))?;
        // A mirror answer is drawn as it is exported: its mirror and its haze, not the ladder's lobe.
        match MirrorAnswer::from_json(&json).map_err(|e| anyhow!("{path}: {}", e.message()))? {
            Some(answer) => Box::new(MirrorBrdf::new(&answer, material)),
            None => {
                let model = Model::from_json(&json).map_err(|e| anyhow!("{path}: not a fit result: {}", e.message()))?;
                Box::new(AnalyticBrdf { model, material })
            }
        }
    };
    let image = scene.render(brdf.as_ref()).map_err(|e| anyhow!("{path}: {}", e.message()))?;
    let data = if as_npy { image.to_npy() } else { image.to_exr().map_err(|e| anyhow!("{}: {}", out.display(), e.message()))? };
    ndfit::io::write_bytes_atomic(out, &data)?;
    eprintln!("ndfit: {path}: wrote {} ({} x {})", out.display(), image.width, image.height);
    Ok(ExitCode::SUCCESS)
}

/// The conductor of a wave BRDF's table (one with a `mirror_share` field), named in its description as
/// `ndfit wave --to rgl` writes it; `None` for any other table.
fn wave_conductor(t: &TensorFile) -> Option<Material> {
    t.field("mirror_share")?;
    let text = String::from_utf8_lossy(&t.field("description")?.data).into_owned();
    let name = text.split("Fresnel of the conductor ").nth(1)?.split_whitespace().next()?;
    name.parse().ok()
}

/// The scene the flags describe.
fn scene(args: &Args) -> Result<Stage, String> {
    let mut scene = match args.scene.as_str() {
        "point" => Scene::point(),
        "broad" => Scene::broad(),
        "window" => {
            if args.light.is_some() || args.view.is_some() {
                return Err("--scene window: --light and --view are for the sphere scenes".into());
            }
            let width = args.size.unwrap_or(Window::default().width);
            return Ok(Stage::Window(Window { width, height: (width * 3).div_ceil(5), ..Window::default() }));
        }
        s => return Err(format!("--scene: unknown scene '{}' (expected point, broad or window)", super::one_line(s))),
    };
    if let Some(v) = &args.view {
        scene.camera.view = angles("--view", v)?;
    }
    if let Some(n) = args.size {
        scene.camera.size = n;
    }
    let light = args.light.as_deref().map(|l| angles("--light", l)).transpose()?;
    scene.light = match scene.light {
        Light::Point { dir, irradiance } => Light::Point { dir: light.unwrap_or(dir), irradiance },
        Light::Cap { dir, .. } => {
            let half_angle = args.half_angle.to_radians();
            if !(args.half_angle > 0.0 && args.half_angle <= 90.0) {
                return Err(format!("--half-angle {} must be in (0, 90] degrees", args.half_angle));
            }
            // The cap's radiance keeps a white Lambertian surface facing it at 1.
            Light::Cap { dir: light.unwrap_or(dir), half_angle, radiance: 1.0 / half_angle.sin().powi(2) }
        }
    };
    Ok(scene.into())
}

/// `THETA,PHI` in degrees as a unit vector.
fn angles(flag: &str, s: &str) -> Result<Vector, String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let nums: Vec<f64> = parts.iter().filter_map(|p| p.parse::<f64>().ok()).filter(|v| v.is_finite()).collect();
    if parts.len() != 2 || nums.len() != 2 {
        return Err(format!("{flag}: '{}' is not THETA,PHI in degrees (two numbers)", super::one_line(s)));
    }
    if !(0.0..=180.0).contains(&nums[0]) {
        return Err(format!("{flag}: theta {} must be in [0, 180] degrees", nums[0]));
    }
    Ok(direction(nums[0].to_radians(), nums[1].to_radians()))
}

type Vector = nalgebra::Vector3<f64>;
