//! `ndfit convert IN OUT.x3p`: read any supported scan (optionally cropped, subsampled, form-removed)
//! and write it as X3P (float64 heights in metres, NaN for invalid points).

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::bail;

use super::scan_args::ScanArgs;

/// Arguments of `ndfit convert`.
#[derive(Debug, clap::Args)]
pub struct Args {
    #[command(flatten)]
    scan: ScanArgs,
    /// Output file; its extension must be .x3p.
    out: PathBuf,
}

/// Run `ndfit convert`. Unlike the other commands, no form is removed unless `--form` asks for one:
/// a conversion keeps the heights as measured.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let ext = args.out.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
    if ext.as_deref() != Some("x3p") {
        bail!("{}: only X3P output is written; name the output *.x3p", args.out.display());
    }
    let mut pre = args.scan.how.preprocess();
    if args.scan.how.form.is_none() {
        pre.form = ndfit::preprocess::FormRemoval::None;
    }
    args.scan.check_outputs([args.out.as_path()])?;
    let hf = args.scan.load_raw()?;
    let hf = ndfit::preprocess::apply(hf, &pre).map_err(|e| e.with_path(&args.scan.scan))?;
    ndfit::io::write_x3p(&args.out, &hf)?;
    eprintln!(
        "wrote {} ({} x {}, {} invalid) from {} ({})",
        args.out.display(),
        hf.nx,
        hf.ny,
        hf.invalid_count(),
        args.scan.scan.display(),
        hf.meta.format
    );
    Ok(ExitCode::SUCCESS)
}
