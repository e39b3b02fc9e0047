//! Fit heights held in memory as an `ndarray` (as a numpy array would hand them over): no file, no copy
//! of the heights for a standard-layout array.
//!
//!     cargo run --release --example fit_array

use ndarray::Array2;
use ndfit::models::ModelId;
use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};
use ndfit::{ModelChoice, Options, Pipeline, Scan};

fn main() -> ndfit::Result<()> {
    // A (ny, nx) array of heights in metres, rows along y; here a synthetic surface whose NDF is the
    // ellipsoid NDF with these parameters, so the fit can be compared with the truth.
    let truth = EllipsoidParams { alpha_x: 0.25, alpha_y: 0.12, theta_x: 0.1, theta_y: -0.05, theta_z: 0.5, ..Default::default() };
    let (surface, _) = ellipsoid_surface(&SynthSettings { nx: 512, ny: 512, ..Default::default() }, &truth)?;
    let heights: Array2<f64> = surface.heights().to_owned();

    // Borrow the array (no copy); the grid spacing is 1 micrometre along x and y.
    let scan = Scan::from_view(heights.view(), 1e-6, 1e-6)?;
    assert!(scan.z.is_borrowed());
    // The synthetic surface has no form to remove; a measured one keeps the default (mean plane).
    let options = Options {
        preprocess: ndfit::preprocess::Preprocess { form: ndfit::preprocess::FormRemoval::None, ..Default::default() },
        model: ModelChoice::Model(ModelId::Ellipsoid),
        ..Options::default()
    };
    let outcome = Pipeline::new(options).run(scan, "array")?;
    let p = &outcome.fit.params;
    println!("{:>8} {:>9} {:>9}", "param", "truth", "fit");
    for (name, t) in [
        ("alpha_x", truth.alpha_x),
        ("alpha_y", truth.alpha_y),
        ("theta_x", truth.theta_x),
        ("theta_y", truth.theta_y),
        ("theta_z", truth.theta_z),
    ] {
        println!("{name:>8} {t:9.4} {:9.4}", p[name]);
    }
    // theta_z: the alpha_x axis lies along (cos theta_z, -sin theta_z) in the scan frame (azimuth -theta_z).
    println!("alpha_x axis at azimuth {:.4} rad from +x; verdict {}", -p["theta_z"], outcome.fit.quality.verdict);
    Ok(())
}
