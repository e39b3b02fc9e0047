//! `ndfit eval FIT.json`: a fitted model's D(m) (and G1(u, m)) at directions read as CSV from stdin.

use std::io::Read;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{anyhow, Context};
use nalgebra::Vector3;
use ndfit::models::{Model, Ndf};

/// Arguments of `ndfit eval`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// A fit result (`ndfit.fit/1`) or any JSON object with `model` and `params` (or `matrix_a` for the
    /// ellipsoid). Standard input carries CSV with the header `mx,my,mz` or `mx,my,mz,ux,uy,uz`; standard
    /// output gets `d` or `d,g1` (directions are normalized before use).
    pub fit: PathBuf,
}

/// Run `ndfit eval`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let path = args.fit.display().to_string();
    let text = std::fs::read_to_string(&args.fit).with_context(|| format!("{path}: cannot read"))?;
    let json: serde_json::Value = serde_json::from_str(&text).map_err(|e| anyhow!("{path}: not valid JSON ({e})"))?;
    let model = Model::from_json(&json).map_err(|e| anyhow!("{path}: {}", e.message()))?;

    let mut input = String::new();
    std::io::stdin().read_to_string(&mut input).map_err(|e| anyhow!("<stdin>: cannot read ({e})"))?;
    let out = eval_csv(&model, &input).map_err(|e| anyhow!("<stdin>: {e}"))?;
    super::write_stdout(out.as_bytes())?;
    Ok(ExitCode::SUCCESS)
}

/// Evaluate every row; the whole output is built before anything is written, so a bad row leaves no
/// partial output behind.
fn eval_csv(model: &Model, input: &str) -> Result<String, String> {
    let mut lines = input.lines().enumerate().filter(|(_, l)| !l.trim().is_empty());
    let (_, header) = lines.next().ok_or("empty input: expected the header 'mx,my,mz' or 'mx,my,mz,ux,uy,uz'")?;
    let cols: Vec<&str> = header.trim().trim_start_matches('\u{feff}').split(',').map(|c| c.trim().trim_matches('"')).collect();
    let with_u = match cols.as_slice() {
        ["mx", "my", "mz"] => false,
        ["mx", "my", "mz", "ux", "uy", "uz"] => true,
        _ => return Err(format!("line 1: header must be 'mx,my,mz' or 'mx,my,mz,ux,uy,uz', got '{}'", header.trim())),
    };
    let width = if with_u { 6 } else { 3 };
    let mut out = String::from(if with_u { "d,g1\n" } else { "d\n" });
    for (i, line) in lines {
        let lineno = i + 1;
        let fields: Vec<&str> = line.trim().split(',').map(str::trim).collect();
        if fields.len() != width {
            return Err(format!("line {lineno}: expected {width} numbers, got {} fields", fields.len()));
        }
        let mut v = [0.0f64; 6];
        for (k, f) in fields.iter().enumerate() {
            let x: f64 = f.parse().map_err(|_| format!("line {lineno}: '{f}' is not a number"))?;
            if !x.is_finite() {
                return Err(format!("line {lineno}: '{f}' is not finite"));
            }
            v[k] = x;
        }
        let m = unit(Vector3::new(v[0], v[1], v[2])).ok_or(format!("line {lineno}: m is the zero vector"))?;
        out.push_str(&fmt(model.d(m)));
        if with_u {
            let u = unit(Vector3::new(v[3], v[4], v[5])).ok_or(format!("line {lineno}: u is the zero vector"))?;
            out.push(',');
            out.push_str(&fmt(model.g1(u, m)));
        }
        out.push('\n');
    }
    Ok(out)
}

fn unit(v: Vector3<f64>) -> Option<Vector3<f64>> {
    // Scaled by its largest component first, so a tiny (denormal) or huge vector keeps its direction;
    // only the zero vector has none.
    let s = v.amax();
    if !(s > 0.0 && s.is_finite()) {
        return None;
    }
    let w = v / s;
    let n = w.norm();
    (n > 0.0 && n.is_finite()).then(|| w / n)
}

/// Shortest round-trip decimal; exponent form outside `[1e-5, 1e16)` so tiny values stay short.
fn fmt(x: f64) -> String {
    if x == 0.0 || (1e-5..1e16).contains(&x.abs()) {
        format!("{x}")
    } else {
        format!("{x:e}")
    }
}
