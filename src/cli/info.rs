//! `ndfit info`.

use std::process::ExitCode;

/// Arguments of `ndfit info`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Run `ndfit info`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let _ = args;
    anyhow::bail!("'ndfit info' is not implemented yet")
}
