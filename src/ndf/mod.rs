//! The empirical NDF: the projected-area-weighted density of microfacet normals of a heightfield
//! (Walter et al. sec. 2; Heitz sec. 2.2, eq. 9 and 64).

use nalgebra::Vector3;

use crate::error::{Error, ErrorKind, Result};
use crate::heightfield::Heightfield;

/// One bin of the empirical NDF.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct NdfBin {
    /// The bin's central direction (unit vector, `m.z > 0`).
    pub m: Vector3<f64>,
    /// D at the bin: projected-area fraction in the bin divided by the bin's projected solid angle.
    pub d: f64,
    /// Standard error of `d` (Poisson on the count).
    pub stderr: f64,
    /// Number of samples (stencils or facets) in the bin.
    pub count: u64,
    /// Solid angle of the bin (sr).
    pub solid_angle: f64,
    /// Projected solid angle of the bin, the integral of `m.n` over it (sr).
    pub proj_solid_angle: f64,
}

/// An empirical NDF: bins covering the hemisphere with `sum(d * proj_solid_angle) = 1`.
#[derive(Debug, Clone, PartialEq)]
pub struct EmpiricalNdf {
    /// All bins, empty ones included.
    pub bins: Vec<NdfBin>,
    /// Number of samples binned.
    pub n_samples: u64,
}

/// How the empirical NDF is computed.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct NdfOptions {}

/// Compute the empirical NDF of `hf`.
pub fn empirical_ndf(hf: &Heightfield, opts: &NdfOptions) -> Result<EmpiricalNdf> {
    let _ = (hf, opts);
    Err(Error::new(ErrorKind::Unsupported, "empirical NDF not implemented yet"))
}
