//! The command-line layer: parse arguments, resolve them into ready library objects, run, report.
//!
//! Errors reach the user as one line on standard error, `ndfit: <file>: <problem>`, with a non-zero exit.
//! Each subcommand lives in its own file with its `Args` and its `run`.

use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod batch;
mod bench;
mod convert;
mod demo;
mod eval;
mod export;
mod fit;
mod info;
mod ndf;
mod scale;
mod scan_args;
mod synth;

/// Measured microgeometry to microfacet parameters: empirical NDFs of heightfield scans and fits of the
/// Ellipsoid, GGX and Beckmann NDFs.
#[derive(Debug, Parser)]
#[command(name = "ndfit", version, about, long_about = None, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the whole pipeline on a built-in synthetic scan (no files needed): synth, NDF, fit.
    Demo(demo::Args),
    /// Describe a scan: format, grid, spacing, invalid points, height range, Sq and Sdq.
    Info(info::Args),
    /// Convert any supported scan to X3P (heights kept as measured unless --form is given).
    Convert(convert::Args),
    /// Compute the empirical NDF of a scan.
    Ndf(ndf::Args),
    /// Fit an analytic NDF to a scan.
    Fit(fit::Args),
    /// Evaluate a fitted model's D (and G1) at directions read as CSV from standard input.
    Eval(eval::Args),
    /// A fit as a renderer's material parameters (Mitsuba 3, pbrt-v4, Blender, OpenPBR, MaterialX).
    Export(export::Args),
    /// Write a synthetic scan with known truth.
    Synth(synth::Args),
    /// Fit every scan in a folder and compare against a baseline.
    Batch(batch::Args),
    /// Measure the speed/accuracy trade of every knob.
    Bench(bench::Args),
    /// The NDF at the footprints a renderer sees, and the simplest model for them.
    Scale(scale::Args),
}

/// Parse, run, and turn any error into one line and a non-zero exit.
pub fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Demo(a) => demo::run(a),
        Command::Info(a) => info::run(a),
        Command::Convert(a) => convert::run(a),
        Command::Ndf(a) => ndf::run(a),
        Command::Fit(a) => fit::run(a),
        Command::Eval(a) => eval::run(a),
        Command::Export(a) => export::run(a),
        Command::Synth(a) => synth::run(a),
        Command::Batch(a) => batch::run(a),
        Command::Bench(a) => bench::run(a),
        Command::Scale(a) => scale::run(a),
    };
    match result {
        Ok(code) => code,
        Err(err) => {
            // One line: the chain joined, so the file and the cause are both named.
            let msg = err.chain().map(|e| e.to_string()).collect::<Vec<_>>().join(": ");
            eprintln!("ndfit: {msg}");
            ExitCode::from(2)
        }
    }
}
