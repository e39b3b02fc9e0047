//! `ndfit fit`.

use std::process::ExitCode;

/// Arguments of `ndfit fit`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Run `ndfit fit`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let _ = args;
    anyhow::bail!("'ndfit fit' is not implemented yet")
}
