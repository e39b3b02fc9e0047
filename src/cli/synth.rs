//! `ndfit synth`.

use std::process::ExitCode;

/// Arguments of `ndfit synth`.
#[derive(Debug, clap::Args)]
pub struct Args {}

/// Run `ndfit synth`.
pub fn run(args: Args) -> anyhow::Result<ExitCode> {
    let _ = args;
    anyhow::bail!("'ndfit synth' is not implemented yet")
}
