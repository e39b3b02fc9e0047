//! Fit a scan file with the library's one pipeline, as `ndfit fit FILE` does, and print the fit JSON.
//!
//!     cargo run --release --example fit_file -- SCAN.x3p
//!
//! Without an argument it writes a synthetic ellipsoid scan (X3P) to a temporary directory and fits that.

use std::path::PathBuf;

use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};
use ndfit::{Options, Pipeline};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = tempfile::tempdir()?;
    let path = match std::env::args_os().nth(1) {
        Some(p) => PathBuf::from(p),
        None => {
            let truth = EllipsoidParams { alpha_x: 0.3, alpha_y: 0.15, theta_z: 0.4, ..Default::default() };
            let (scan, _) = ellipsoid_surface(&SynthSettings { nx: 512, ny: 512, ..Default::default() }, &truth)?;
            let p = dir.path().join("synthetic.x3p");
            ndfit::io::write_x3p(&p, &scan)?;
            p
        }
    };
    // `Options::default()` is `ndfit fit`'s default: plane removed, automatic bins, `--model auto`.
    let outcome = Pipeline::new(Options::default()).run_path(&path)?;
    let fit = &outcome.fit;
    eprintln!("{}: {} fit, {} bins, verdict {}", path.display(), fit.model, outcome.ndf.bins.len(), fit.quality.verdict);
    // Walter et al.'s A = S Rz(theta_z) puts the alpha_x axis along (cos theta_z, -sin theta_z) in the scan
    // frame: at azimuth -theta_z.
    if let Some(t) = fit.params.get("theta_z") {
        eprintln!("alpha_x axis at azimuth {:.4} rad from +x", -t);
    }
    println!("{}", serde_json::to_string_pretty(fit)?);
    Ok(())
}
