//! `ndfit bench`.

use std::process::ExitCode;

/// Arguments of `ndfit bench`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Run `ndfit bench`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let _ = args;
    anyhow::bail!("'ndfit bench' is not implemented yet")
}
