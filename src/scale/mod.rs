//! The NDF at the footprint a renderer sees, and the simplest model for it (data_formats/scale.md).
//!
//! A renderer whose pixel covers a footprint `F` of the surface draws the low-passed surface
//! `h_F = K_F * h` and carries the slope variation inside each footprint in its NDF. Tokuyoshi's NDF
//! filtering adds the kernel's slope covariance to the 2x2 roughness matrix (Tokuyoshi eq. 3, 10, 13);
//! here that covariance is measured from the scan itself.
//!
//! - `filter`: normalized separable Gaussian convolution of fields with holes;
//! - `footprint`: slopes, resolved slopes `s_F` and within-footprint covariances `Sigma_w`, `Sigma_F`;
//! - `roughness` (in `models`): the roughness matrix algebra (Tokuyoshi eq. 3, 10, 13, 15-18) and the ellipsoid's
//!   slope form through `A^T A`;
//! - `scene`: the footprints a scene implies.

pub(crate) mod analyze;
pub(crate) mod fields;
pub(crate) mod filter;
pub(crate) mod fitter;
pub(crate) mod footprint;
pub(crate) mod ndf_at;
#[cfg(feature = "plot")]
pub(crate) mod plot;
pub(crate) mod report;
/// The roughness matrix algebra now lives in [`crate::models::roughness`]; this path is kept for old callers.
pub(crate) use crate::models::roughness;
pub use analyze::{analyze, model_skew, recommend, Fitted, Fitter, FootprintResult, ScaleOptions};
pub use analyze::{Candidate, Delta, GgxKernel, ModelAtFootprint, Recommendation, RouteResult};
pub use fields::Mode;
pub use fields::{BumpField, FourierSurface};
pub use filter::{filter_field, gaussian_taps};
pub use fitter::FitFitter;
pub use footprint::{footprint_field, footprint_stats, footprint_stats_over, kernel_sigma, slope_field};
pub use footprint::{FootprintField, FootprintStats};
pub use ndf_at::SlopeMoments;
pub use ndf_at::{bin_slopes, sample_slopes, sample_slopes_with, slope_moments, Blur};
#[cfg(feature = "plot")]
pub use plot::write_plot;
pub use report::{footprint_json, report_json, write_csv, CSV_HEADER};
pub use roughness::{model_from_slope_form, SlopeForm};
pub use scene::parse_scene;
pub use scene::FootprintRange;
pub(crate) mod scene;

/// The fitter of `src/fit/` behind [`analyze::Fitter`].
pub fn default_fitter() -> fitter::FitFitter {
    fitter::FitFitter::default()
}
