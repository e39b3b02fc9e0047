//! Synthetic scans with known truth: the NDF each surface must produce is known in closed form.
//!
//! - [`ellipsoid_surface`]: the visible upper half of an ellipsoid (Walter et al. eq. 8, 22-23), whose
//!   NDF is exactly the ellipsoid NDF of eq. 1 with `n = +z`;
//! - [`gaussian_surface`]: a Gaussian random surface with a prescribed anisotropic slope covariance,
//!   whose NDF is anisotropic Beckmann with `alpha = sqrt(2) sigma` (Heitz footnote 3 to eq. 88);
//! - [`tilted_planes`]: one plane or several plane strips (a delta NDF, or a sum of deltas).
//!
//! Every generator takes [`SynthSettings`] (grid, spacing, seed, height noise, holes, height offset)
//! and returns the heightfield with its [`Truth`], which serializes as `SCAN.truth.json`
//! (`schema: "ndfit.synth/1"`, contract `model`, `params`, `matrix_a`).

pub(crate) mod ellipsoid;
pub(crate) mod fft;
pub(crate) mod gaussian;
pub(crate) mod planes;
mod truth;

pub use ellipsoid::{ellipsoid_surface, EllipsoidParams};
pub use ellipsoid::{EllipsoidGeometry, HARD_END_SET};
pub use gaussian::{gaussian_surface, GaussianParams};
pub use planes::{tilted_planes, PlaneFacet};
pub use truth::{FacetTruth, Truth};

use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, StandardNormal};

use crate::error::{Error, Result};
use crate::scan::Heightfield;

/// The random generator of every synthetic scan: xoshiro256++ (portable, so a seed gives the same
/// scan on every platform and version).
pub type SynthRng = rand::rngs::Xoshiro256PlusPlus;

/// Largest grid side a generator accepts (the FFT of a Gaussian surface pads to the next power of two).
pub const MAX_SIDE: usize = 1 << 15;

/// Grid and degradations common to every generator.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SynthSettings {
    /// Columns.
    pub nx: usize,
    /// Rows.
    pub ny: usize,
    /// Spacing along x (m).
    pub dx: f64,
    /// Spacing along y (m).
    pub dy: f64,
    /// Seed of the random generator (phases, noise, holes).
    pub seed: u64,
    /// Standard deviation of white Gaussian height noise added to every point (m); 0 for none.
    pub noise: f64,
    /// Fraction of points (0..1) masked invalid at random, independently.
    pub holes: f64,
    /// Constant added to every height (m), e.g. 0.5 to test huge offsets.
    pub offset: f64,
}

impl Default for SynthSettings {
    fn default() -> Self {
        SynthSettings { nx: 1024, ny: 1024, dx: 1e-6, dy: 1e-6, seed: 1, noise: 0.0, holes: 0.0, offset: 0.0 }
    }
}

impl SynthSettings {
    /// Check sizes and values; every generator calls this first.
    pub fn check(&self) -> Result<()> {
        if self.nx < 3 || self.ny < 3 || self.nx > MAX_SIDE || self.ny > MAX_SIDE {
            return Err(Error::invalid(format!("synthetic grid {} x {} must be between 3 and {MAX_SIDE} per side", self.nx, self.ny)));
        }
        crate::budget::check_points(self.nx, self.ny, "synthetic grid")?;
        if !(self.dx.is_finite() && self.dx > 0.0 && self.dy.is_finite() && self.dy > 0.0) {
            return Err(Error::invalid(format!("spacing must be finite and positive, got dx={}, dy={}", self.dx, self.dy)));
        }
        if !(self.noise.is_finite() && self.noise >= 0.0) {
            return Err(Error::invalid(format!("noise must be finite and >= 0, got {}", self.noise)));
        }
        if !(self.holes.is_finite() && (0.0..1.0).contains(&self.holes)) {
            return Err(Error::invalid(format!("holes must be a fraction in [0, 1), got {}", self.holes)));
        }
        if !self.offset.is_finite() {
            return Err(Error::invalid(format!("offset must be finite, got {}", self.offset)));
        }
        Ok(())
    }

    /// x of column `j` measured from the grid centre (m).
    pub fn xc(&self, j: usize) -> f64 {
        (j as f64 - 0.5 * (self.nx as f64 - 1.0)) * self.dx
    }

    /// y of row `i` measured from the grid centre (m).
    pub fn yc(&self, i: usize) -> f64 {
        (i as f64 - 0.5 * (self.ny as f64 - 1.0)) * self.dy
    }

    /// A generator seeded for stream `stream` (0: the surface itself, 1: noise, 2: holes), so that
    /// adding noise or holes leaves the surface, and holes the noise, unchanged.
    pub fn rng(&self, stream: u64) -> SynthRng {
        SynthRng::seed_from_u64(self.seed ^ stream.wrapping_mul(0x9E37_79B9_7F4A_7C15))
    }

    /// Wrap generated heights into a heightfield, then add noise, holes and the offset (in that
    /// order; masked points stay NaN).
    pub fn finish(&self, z: Vec<f64>) -> Result<Heightfield> {
        let mut hf = Heightfield::new(self.nx, self.ny, self.dx, self.dy, z)?;
        hf.x0 = self.xc(0);
        hf.y0 = self.yc(0);
        hf.meta.format = "synthetic".into();
        let (mut noise_rng, mut hole_rng) = (self.rng(1), self.rng(2));
        for h in hf.z.iter_mut() {
            if self.noise > 0.0 {
                let e: f64 = StandardNormal.sample(&mut noise_rng);
                *h += self.noise * e;
            }
            if self.holes > 0.0 && hole_rng.random::<f64>() < self.holes {
                *h = f64::NAN;
            }
            *h += self.offset;
        }
        Ok(hf)
    }
}
