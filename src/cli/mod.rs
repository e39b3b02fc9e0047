//! The command-line layer: parse arguments, resolve them into ready library objects, run, report.
//!
//! Errors reach the user as one line on standard error, `ndfit: <file>: <problem>`, with a non-zero exit.
//! Each subcommand lives in its own file with its `Args` and its `run`.

use std::io::Write;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

mod batch;
mod bench;
mod compare;
mod convert;
mod demo;
mod eval;
mod export;
mod fit;
mod fit_args;
mod flip;
mod info;
mod ndf;
mod progress;
mod render;
mod scale;
mod scan_args;
mod synth;
mod trace;
mod trace_rgl;
mod wave;
mod wave_rgl;

/// Measured microgeometry to microfacet parameters: empirical NDFs of heightfield scans and fits of the
/// Ellipsoid, GGX and Beckmann NDFs.
#[derive(Debug, Parser)]
#[command(name = "ndfit", version, about, long_about = None, propagate_version = true)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// Memory budget for what a file declares (bytes, or with a K/M/G/T suffix of 1024s); files that
    /// need more are refused before anything is allocated [default: half of the available memory]
    #[arg(long, global = true, value_name = "BYTES", value_parser = parse_bytes)]
    max_memory: Option<u64>,
    /// When the command ends, print its peak resident memory on standard error (`VmHWM`, the process's
    /// own since it started; Linux only), to size a machine for a scan
    #[arg(long, global = true)]
    report_memory: bool,
}

/// `--max-memory`: a byte count with an optional binary suffix (`512M`, `4G`).
fn parse_bytes(s: &str) -> Result<u64, String> {
    let t = s.trim();
    let (num, mult) = match t.char_indices().last() {
        Some((i, c)) if c.is_ascii_alphabetic() => {
            let m: u64 = match c.to_ascii_uppercase() {
                'K' => 1 << 10,
                'M' => 1 << 20,
                'G' => 1 << 30,
                'T' => 1 << 40,
                'B' => 1,
                _ => return Err(format!("{s:?}: unknown unit (use K, M, G or T)")),
            };
            (&t[..i], m)
        }
        _ => (t, 1),
    };
    let v: f64 = num.trim().parse().map_err(|_| format!("{s:?} is not a size such as 4G or 512M"))?;
    let bytes = v * mult as f64;
    if !(1.0..1.8e19).contains(&bytes) {
        return Err(format!("{s:?} is not a size between 1 byte and 16 EiB"));
    }
    Ok(bytes as u64)
}

/// Standard output was closed by its reader (EPIPE): the command stops and exits 0, as Unix tools do.
#[derive(Debug)]
pub struct StdoutClosed;

impl std::fmt::Display for StdoutClosed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("<stdout>: closed by the reader")
    }
}

impl std::error::Error for StdoutClosed {}

/// Write `bytes` to standard output and flush. A closed pipe becomes [`StdoutClosed`] (exit 0, nothing
/// printed); any other failure (a full disk) one line naming standard output. Never panics, unlike
/// `println!`.
pub fn write_stdout(bytes: &[u8]) -> anyhow::Result<()> {
    let mut out = std::io::stdout().lock();
    match out.write_all(bytes).and_then(|_| out.flush()) {
        Ok(()) => Ok(()),
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Err(StdoutClosed.into()),
        Err(e) => Err(anyhow::anyhow!("<stdout>: cannot write ({e})")),
    }
}

/// Escape control characters (newlines, escapes, NULs) so text taken from a file cannot break the one
/// line an error message is.
pub fn one_line(s: &str) -> String {
    if !s.chars().any(char::is_control) {
        return s.to_string();
    }
    s.chars().map(|c| if c.is_control() { c.escape_default().to_string() } else { c.to_string() }).collect()
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
    /// Trace the scan's own microgeometry (geometric optics) and measure the microfacet model against it;
    /// with `--to rgl`, write the traced BRDF as a tabulated material.
    Trace(trace::Args),
    /// Render a fit's lobe or an RGL table on a sphere (point or broad light) to EXR or .npy.
    Render(render::Args),
    /// Will a renderer show the difference? Every lobe `auto` fitted rendered against the scan's own table,
    /// scored by FLIP: the answer (a lobe or the table) and the pictures.
    Compare(compare::Args),
    /// Wave optics on the scan's own heights: the mirror share and the diffuse BRDF by scalar diffraction,
    /// per wavelength and incidence; with `--to rgl`, the diffuse BRDF as a tabulated material.
    Wave(wave::Args),
    /// The FLIP difference of two renders (HDR-FLIP, or LDR-FLIP with --ldr): the mean and a magma map.
    Flip(flip::Args),
}

/// Parse, run, and turn any error into one line and a non-zero exit.
pub fn main() -> ExitCode {
    ndfit::phases::enabled();
    let cli = match Cli::try_parse() {
        Ok(c) => c,
        Err(e) => return usage_error(e),
    };
    ndfit::budget::set_max_memory(cli.max_memory);
    progress::install();
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
        Command::Trace(a) => trace::run(a),
        Command::Render(a) => render::run(a),
        Command::Flip(a) => flip::run(a),
        Command::Compare(a) => compare::run(a),
        Command::Wave(a) => wave::run(a),
    };
    progress::finish();
    print_phases();
    if cli.report_memory {
        match ndfit::bench::mem::peak_rss() {
            Some(b) => eprintln!("ndfit: peak resident memory {:.1} MiB", b as f64 / (1024.0 * 1024.0)),
            None => eprintln!("ndfit: peak resident memory is not known on this system"),
        }
    }
    match result {
        Ok(code) => code,
        Err(err) if err.downcast_ref::<StdoutClosed>().is_some() => ExitCode::SUCCESS,
        Err(err) => {
            // One line: the chain joined, so the file and the cause are both named.
            let msg = err.chain().map(|e| e.to_string()).collect::<Vec<_>>().join(": ");
            let _ = writeln!(std::io::stderr(), "ndfit: {}", one_line(&msg));
            ExitCode::from(2)
        }
    }
}

/// With `NDFIT_PHASES` set, the command's phases on standard error, one line each
/// (docs/PERFORMANCE.md, "Scaling with cores").
fn print_phases() {
    if !ndfit::phases::enabled() {
        return;
    }
    let (spans, end) = ndfit::phases::take();
    for s in &spans {
        eprintln!("ndfit: phase {} at {:.2} ms took {:.2} ms", s.name, s.start_ms, s.ms);
    }
    eprintln!("ndfit: phases end at {end:.2} ms");
}

/// Help and version go to standard output as clap prints them; an argument error becomes one line
/// (clap's first line, without its usage block) and exit status 2.
fn usage_error(e: clap::Error) -> ExitCode {
    use clap::error::ErrorKind as K;
    match e.kind() {
        K::DisplayHelp | K::DisplayVersion => {
            // A closed pipe after `--help | head` is not an error; a full disk is.
            match write_stdout(e.render().to_string().as_bytes()) {
                Err(err) if err.downcast_ref::<StdoutClosed>().is_none() => {
                    let _ = writeln!(std::io::stderr(), "ndfit: {err}");
                    ExitCode::from(2)
                }
                _ => ExitCode::SUCCESS,
            }
        }
        K::DisplayHelpOnMissingArgumentOrSubcommand => {
            let _ = write!(std::io::stderr(), "{}", e.render());
            ExitCode::from(2)
        }
        _ => {
            let text = e.render().to_string();
            let first = text.lines().find(|l| !l.trim().is_empty()).unwrap_or("invalid arguments");
            let first = first.trim_start_matches("error: ").trim();
            let _ = writeln!(std::io::stderr(), "ndfit: {} (see --help)", one_line(first));
            ExitCode::from(2)
        }
    }
}

/// The `--model` help, from the model table: every id with its one-line description, and `auto`.
pub(crate) fn model_help() -> String {
    let ids: Vec<String> = ndfit::models::ModelId::EVERY.iter().map(|id| format!("{} ({})", id.as_str(), id.spec().about)).collect();
    format!(
        "Model id: {}; or `auto`: climb these models rung by rung (one lobe, its richer forms, two lobes) while none fitted \
         is within --tolerance on the NDF error beyond counting noise, then take the simplest within it, or when none is, the \
         simplest whose error exceeds the smallest by no more than it (in quadrature); a model competes only if its quasi-likelihood BIC is below its \
         parent's (data_formats/objective.md, \"The tolerance\").",
        ids.join(", ")
    )
}
