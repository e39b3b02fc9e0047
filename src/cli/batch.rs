//! `ndfit batch`.

use std::process::ExitCode;

/// Arguments of `ndfit batch`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Run `ndfit batch`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let _ = args;
    anyhow::bail!("'ndfit batch' is not implemented yet")
}
