//! `ndfit eval`.

use std::process::ExitCode;

/// Arguments of `ndfit eval`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Run `ndfit eval`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let _ = args;
    anyhow::bail!("'ndfit eval' is not implemented yet")
}
