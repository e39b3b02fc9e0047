//! Arguments shared by every command that reads a scan: the path, raw-format options, preprocessing.

use std::path::PathBuf;

use ndfit::io::ReadOptions;
use ndfit::preprocess::{Crop, FormRemoval, Preprocess};

/// The scan to read and how to read and preprocess it.
#[derive(Debug, Clone, clap::Args)]
pub struct ScanArgs {
    /// The scan file (format detected from content, then extension).
    pub scan: PathBuf,
    #[command(flatten)]
    pub how: ReadArgs,
}

/// How a scan is read and preprocessed (the flags of every command that reads one).
#[derive(Debug, Clone, clap::Args)]
pub struct ReadArgs {
    /// Spacing along x in metres, for formats that carry none.
    #[arg(long, allow_hyphen_values = true)]
    pub dx: Option<f64>,
    /// Spacing along y in metres (default: --dx).
    #[arg(long, allow_hyphen_values = true)]
    pub dy: Option<f64>,
    /// Metres per stored height unit, for formats that carry no height unit.
    #[arg(long, allow_hyphen_values = true)]
    pub z_scale: Option<f64>,
    /// Force the format instead of detecting it (x3p, plu, sur, opd, metropro, al3d, tmd, ascii, xyz,
    /// csv, gsf, npy, exr, png, tiff).
    #[arg(long)]
    pub format: Option<String>,
    /// Form removed before anything else is computed: none, plane (least squares, the default),
    /// poly2, poly3 (least-squares polynomials in x and y) or cylinder (axis in the xy plane).
    #[arg(long)]
    pub form: Option<FormRemoval>,
    /// Keep only a window of the grid, in samples: NXxNY+X+Y (columns X..X+NX, rows Y..Y+NY).
    #[arg(long)]
    pub crop: Option<Crop>,
    /// Keep every N-th point along x and y (after the crop; no averaging).
    #[arg(long, default_value_t = 1, allow_hyphen_values = true)]
    pub subsample: usize,
    /// Spike removal after the form removal: `median` (default; isolated height outliers masked,
    /// reported in the fit JSON's input.despike) or `none`.
    #[arg(long, default_value = "median")]
    pub despike: ndfit::preprocess::Despike,
}

impl ReadArgs {
    /// The reader options these arguments ask for.
    pub fn read_options(&self) -> ReadOptions {
        ReadOptions { dx: self.dx, dy: self.dy, z_scale: self.z_scale, format: self.format.clone() }
    }

    /// The preprocessing these arguments ask for.
    pub fn preprocess(&self) -> Preprocess {
        Preprocess { form: self.form.unwrap_or(FormRemoval::Plane), crop: self.crop, subsample: self.subsample, despike: self.despike }
    }
}

impl ScanArgs {
    /// Record the scan as this process's input and refuse any of `outputs` that is a directory or the
    /// scan itself, before any work (each write checks again).
    pub fn check_outputs<'a>(&self, outputs: impl IntoIterator<Item = &'a std::path::Path>) -> anyhow::Result<()> {
        ndfit::io::protect_input(&self.scan);
        for o in outputs {
            ndfit::io::check_output(o)?;
        }
        Ok(())
    }

    /// Read the scan as stored (no preprocessing).
    pub fn load_raw(&self) -> anyhow::Result<ndfit::Heightfield> {
        Ok(ndfit::read(&self.scan, &self.how.read_options())?)
    }

    /// Read the scan AND preprocess it (crop, subsample, form removal), the way every command wants it
    /// (the pipeline's first stage, [`ndfit::pipeline::read_preprocessed`]).
    pub fn load(&self) -> anyhow::Result<ndfit::Heightfield> {
        Ok(ndfit::pipeline::read_preprocessed(&self.scan, &self.how.read_options(), &self.how.preprocess())?)
    }
}
