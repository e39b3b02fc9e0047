//! The NDF at the footprint a renderer sees, and the simplest model for it (data_formats/scale.md).
//!
//! A renderer whose pixel covers a footprint `F` of the surface draws the low-passed surface
//! `h_F = K_F * h` and carries the slope variation inside each footprint in its NDF. Tokuyoshi's NDF
//! filtering adds the kernel's slope covariance to the 2x2 roughness matrix (Tokuyoshi eq. 3, 10, 13);
//! here that covariance is measured from the scan itself.
//!
//! - [`filter`]: normalized separable Gaussian convolution of fields with holes;
//! - [`footprint`]: slopes, resolved slopes `s_F` and within-footprint covariances `Sigma_w`, `Sigma_F`;
//! - [`roughness`] (in `models`): the roughness matrix algebra (Tokuyoshi eq. 3, 10, 13, 15-18) and the ellipsoid's
//!   slope form through `A^T A`;
//! - [`scene`]: the footprints a scene implies.

pub mod analyze;
pub mod fields;
pub mod filter;
pub mod fitter;
pub mod footprint;
pub mod ndf_at;
#[cfg(feature = "plot")]
pub mod plot;
pub mod report;
/// The roughness matrix algebra now lives in [`crate::models::roughness`]; this path is kept for old callers.
pub use crate::models::roughness;
pub mod scene;

/// The fitter of `src/fit/` behind [`analyze::Fitter`].
pub fn default_fitter() -> fitter::FitFitter {
    fitter::FitFitter::default()
}
