//! Arguments shared by every command that reads a scan: the path, raw-format options, preprocessing.

use std::path::PathBuf;

use ndfit::io::ReadOptions;

/// The scan to read and how to read it.
#[derive(Debug, Clone, clap::Args)]
pub struct ScanArgs {
    /// The scan file (format detected from content, then extension).
    pub scan: PathBuf,
    /// Spacing along x in metres, for formats that carry none.
    #[arg(long)]
    pub dx: Option<f64>,
    /// Spacing along y in metres (default: --dx).
    #[arg(long)]
    pub dy: Option<f64>,
    /// Metres per stored height unit, for formats that carry no height unit.
    #[arg(long)]
    pub z_scale: Option<f64>,
    /// Force the format instead of detecting it.
    #[arg(long)]
    pub format: Option<String>,
}

impl ScanArgs {
    /// The reader options these arguments ask for.
    pub fn read_options(&self) -> ReadOptions {
        ReadOptions { dx: self.dx, dy: self.dy, z_scale: self.z_scale, format: self.format.clone() }
    }
}
