//! # ndfit
//!
//! Empirical normal distribution functions (NDFs) of measured heightfield scans, and fits of analytic
//! NDFs to them: above all the five-parameter Ellipsoid NDF of Walter, Dong, Marschner and Greenberg,
//! with Levenberg-Marquardt; GGX and Beckmann (isotropic and anisotropic) beside it.
//!
//! ## The facade
//!
//! A [`Scan`] (heights in metres on a regular grid, NaN = invalid) goes through one [`Pipeline`]:
//! preprocess (form removal) -> empirical NDF -> fit, configured by [`Options`] (whose `Default` is what
//! `ndfit fit` does) and returning an [`Outcome`] (the NDF and the `ndfit.fit/1` report). A file is read
//! with [`read`] or [`Pipeline::run_path`]; heights already in memory (an `ndarray`, a numpy array) become
//! a scan with [`Scan::from_view`], without a copy.
//!
//! ```
//! use ndfit::models::ModelId;
//! use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};
//! use ndfit::{ModelChoice, Options, Pipeline, Scan};
//!
//! # fn main() -> ndfit::Result<()> {
//! // Heights in memory: a synthetic surface whose NDF is exactly GGX with alpha = 0.3 (an untilted,
//! // isotropic ellipsoid NDF is GGX), copied into a plain (ny, nx) array as a user would hold it.
//! let truth = EllipsoidParams { alpha_x: 0.3, alpha_y: 0.3, theta_x: 0.0, theta_y: 0.0, theta_z: 0.0, ..Default::default() };
//! let (surface, _) = ellipsoid_surface(&SynthSettings { nx: 256, ny: 256, ..Default::default() }, &truth)?;
//! let heights: ndarray::Array2<f64> = surface.heights().to_owned();
//!
//! // Scan (no copy) -> preprocess -> empirical NDF -> fit.
//! let scan = Scan::from_view(heights.view(), 1e-6, 1e-6)?;
//! let pipeline = Pipeline::new(Options { model: ModelChoice::Model(ModelId::Ggx), ..Options::default() });
//! let outcome = pipeline.run(scan, "in memory")?;
//! let alpha = outcome.fit.params["alpha"];
//! assert!((alpha - 0.3).abs() < 0.03, "alpha = {alpha}");
//! assert!((outcome.ndf.total() - 1.0).abs() < 1e-9); // sum D W = 1 (Heitz eq. 9)
//! # Ok(())
//! # }
//! ```
//!
//! ## The layers
//!
//! From the bottom up; a module uses only the layers below it (docs/ARCHITECTURE.md has the table, which
//! a test enforces, draws the data flow and says where new code goes):
//! - [`models`]: pure math of the analytic NDFs (no I/O), the roughness-matrix algebra included;
//! - [`scan`]: the one in-memory scan type and its row bands; [`io`]: readers and writers of scan files;
//! - [`ndf`], [`preprocess`]: normals and the binned empirical NDF; form removal and despiking;
//! - [`fit`]: least-squares fits, model selection (by the tolerance, with a QBIC guard) and uncertainty;
//! - [`pipeline`]: the facade above, its stages and the presets;
//! - [`synth`]: synthetic scans with known truth; [`export`]: renderer parameters for a fit;
//!   [`scale`]: the NDF at a renderer's footprint;
//! - with the `cli` feature (on by default): `batch` (the regression runner) and `bench` (measurements),
//!   and the `ndfit` binary (`src/cli/`), a thin layer that parses arguments into [`Options`]. The
//!   `plot` feature (part of `cli`) adds the PNG plots. `default-features = false` builds the library
//!   without clap, indicatif, anyhow or plotters.

#![deny(missing_docs)]
// Every type a public item hands out can be named by its user (it is re-exported where it lives).
#![deny(unnameable_types)]
// `!(x > 0.0)` guards are deliberate throughout: unlike `x <= 0.0` they also catch NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod answer;
#[cfg(feature = "cli")]
pub mod batch;
#[cfg(feature = "cli")]
pub mod bench;
pub mod budget;
pub mod error;
pub mod export;
pub mod fit;
/// The FLIP image-difference evaluator (LDR-FLIP and HDR-FLIP), to score renders of fitted lobes
/// against renders of a measured table.
pub mod flip;
pub mod io;
pub mod models;
pub mod ndf;
pub mod phases;
pub mod pipeline;
#[cfg(feature = "plot")]
pub mod plot;
pub mod preprocess;
pub mod render;
pub mod scale;
pub mod scan;
pub mod stats;
pub mod synth;
/// Geometric optics on the scan's own microgeometry (two triangles per cell, specular bounces), and the
/// microfacet model measured against it: does microfacet theory hold for this scan?
pub mod trace;
/// Wave optics on the scan's own heights: the scalar-diffraction BRDF averaged over coherence patches,
/// split into the mirror share and the diffuse BRDF (docs/WAVE.md).
pub mod wave;

pub use error::{Error, ErrorKind, Result};
pub use models::ModelChoice;
pub use pipeline::{read, Options, Outcome, Pipeline, Preset};
pub use scan::{Heightfield, Scan, ScanMeta};
