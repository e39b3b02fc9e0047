//! `ndfit wave SCAN --to rgl -o OUT.bsdf`: the diffuse BRDF as a tabulated material (in progress).

use std::process::ExitCode;

/// Run `ndfit wave --to rgl`.
pub fn run(a: &super::wave::Args) -> anyhow::Result<ExitCode> {
    anyhow::bail!("{}: --to rgl is not written yet", a.scan.scan.display())
}
