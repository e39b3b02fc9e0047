//! Fit every scan of a folder with one pipeline, several at once, and print one line per scan (the
//! regression runner with baselines and resume is `ndfit batch`).
//!
//!     cargo run --release --example batch -- FOLDER
//!
//! Without an argument it fits three synthetic X3P scans written to a temporary directory.

use std::path::PathBuf;

use rayon::prelude::*;

use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};
use ndfit::{Options, Pipeline};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let tmp = tempfile::tempdir()?;
    let dir = match std::env::args_os().nth(1) {
        Some(d) => PathBuf::from(d),
        None => {
            for (k, a) in [0.1, 0.2, 0.35].into_iter().enumerate() {
                let truth = EllipsoidParams { alpha_x: a, alpha_y: a * 0.6, theta_z: 0.3, ..Default::default() };
                let (scan, _) = ellipsoid_surface(&SynthSettings { nx: 256, ny: 256, seed: k as u64 + 1, ..Default::default() }, &truth)?;
                ndfit::io::write_x3p(&tmp.path().join(format!("scan{k}.x3p")), &scan)?;
            }
            tmp.path().to_path_buf()
        }
    };
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)?.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.is_file()).collect();
    files.sort();
    let pipeline = Pipeline::new(Options::default());
    // One scan per task; a scan that fails is reported with its path and does not stop the others.
    let lines: Vec<String> = files
        .par_iter()
        .map(|f| match pipeline.run_path(f) {
            Ok(o) => {
                let params: Vec<String> = o.fit.params.iter().map(|(k, v)| format!("{k}={v:.4}")).collect();
                format!("{}: {} {} (verdict {})", f.display(), o.fit.model, params.join(" "), o.fit.quality.verdict)
            }
            Err(e) => format!("{e}"),
        })
        .collect();
    for l in lines {
        println!("{l}");
    }
    Ok(())
}
