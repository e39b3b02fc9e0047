//! `ndfit demo`.

use std::process::ExitCode;

/// Arguments of `ndfit demo`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Run `ndfit demo`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let _ = args;
    anyhow::bail!("'ndfit demo' is not implemented yet")
}
