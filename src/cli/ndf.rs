//! `ndfit ndf`.

use std::process::ExitCode;

/// Arguments of `ndfit ndf`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Run `ndfit ndf`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let _ = args;
    anyhow::bail!("'ndfit ndf' is not implemented yet")
}
