//! `ndfit scale`.

use std::process::ExitCode;

/// Arguments of `ndfit scale`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Run `ndfit scale`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let _ = args;
    anyhow::bail!("'ndfit scale' is not implemented yet")
}
