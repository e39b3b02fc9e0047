//! # ndfit
//!
//! Empirical normal distribution functions (NDFs) of measured heightfield scans, and fits of analytic
//! NDFs to them: above all the five-parameter Ellipsoid NDF of Walter, Dong, Marschner and Greenberg,
//! with Levenberg-Marquardt.
//!
//! The layers, each apart from the next:
//! - [`models`]: pure math of the analytic NDFs (no I/O);
//! - [`io`]: readers and writers of scan files, into one [`Heightfield`] type;
//! - [`preprocess`], [`ndf`]: form removal, normals and the binned empirical NDF;
//! - [`fit`]: least-squares fits, model selection and uncertainty;
//! - [`synth`]: synthetic scans with known truth;
//! - [`export`]: the parameters of renderers (Mitsuba 3, pbrt-v4, Blender, OpenPBR, MaterialX) for a fit;
//! - [`batch`], [`scale`], [`bench`]: the batch regression runner, footprint filtering, measurements;
//! - the `ndfit` binary (`src/cli/`) is a thin layer that parses arguments into these.

#![warn(missing_docs)]

pub mod batch;
pub mod bench;
pub mod budget;
pub mod error;
pub mod export;
pub mod fit;
pub mod io;
pub mod models;
pub mod ndf;
pub mod plot;
pub mod preprocess;
pub mod scale;
pub mod scan;
pub mod stats;
pub mod synth;

pub use error::{Error, ErrorKind, Result};
pub use scan::{Heightfield, ScanMeta};

/// Old home of the scan type, kept so existing paths compile; the type lives in [`scan`].
pub mod heightfield {
    pub use crate::scan::{Heightfield, ScanMeta};
}

/// Old home of the heights storage, kept so existing paths compile; it lives in [`scan::heights`].
pub mod heights {
    pub use crate::scan::heights::Heights;
}
