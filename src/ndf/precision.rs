//! f32 storage of the heights for the NDF pass (the benchmark's "f32 versus f64 storage" knob).
//!
//! The heights are stored as `f32(h - mean)`, the mean of the valid heights taken in f64 first: a
//! constant offset (0.5 m of stage height over 100 nm of detail) would otherwise leave the detail in
//! the last bits of an f32 (ulp of 0.5 is 6e-8 m). Every stored height is widened back to f64 before it
//! is differenced, so the only cost is the rounding of `h - mean` to 24 bits: a height error of at most
//! `|h - mean| 2^-24`, a slope error of at most `max |h - mean| 2^-24 / dx` (central differences,
//! two heights over `2 dx`; triangles: the same over `dx`, doubled), reported in [`F32Storage`] and
//! refused by [`super::empirical_ndf_f32`] when it exceeds [`MAX_ROUNDING_FRACTION`] of the slope scale.

use crate::scan::bands::{Band, BandSource, GridShape, HeightRows};
use crate::scan::Scan;

/// The largest slope rounding bound accepted, as a fraction of the robust slope scale (smallest
/// principal standard deviation of the binning frame): beyond it the f32 rounding would widen the NDF
/// by more than 1% in some direction, and the f64 path must be used.
pub const MAX_ROUNDING_FRACTION: f64 = 1e-2;

/// Which stored float type the NDF pass reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Precision {
    /// The heightfield's own f64 heights (default).
    #[default]
    F64,
    /// An f32 copy of `h - mean` ([`HeightsF32`]).
    F32,
}

/// A grid of heights stored as f32 after removing their mean in f64.
#[derive(Debug, Clone, PartialEq)]
pub struct HeightsF32 {
    /// Columns.
    pub nx: usize,
    /// Rows.
    pub ny: usize,
    /// Spacing along x (m).
    pub dx: f64,
    /// Spacing along y (m).
    pub dy: f64,
    /// `f32(h - offset)`, row-major; NaN marks an invalid point.
    pub z: Vec<f32>,
    /// The removed mean of the valid heights (m), 0 when none is valid.
    pub offset: f64,
    /// `max |h - offset|` over the valid heights (m).
    pub max_deviation: f64,
    /// Number of invalid points.
    pub invalid: usize,
}

impl HeightsF32 {
    /// The f32 copy of a heightfield (mean removed in f64 first).
    pub fn from_heightfield(hf: &Scan) -> Self {
        let (mut sum, mut n) = (0.0f64, 0usize);
        for &h in hf.z.iter().filter(|h| !h.is_nan()) {
            sum += h;
            n += 1;
        }
        let offset = if n > 0 { sum / n as f64 } else { 0.0 };
        let mut max_deviation = 0.0f64;
        let z: Vec<f32> =
            hf.z.iter()
                .map(|&h| {
                    let d = h - offset;
                    if d.abs() > max_deviation {
                        max_deviation = d.abs();
                    }
                    d as f32
                })
                .collect();
        HeightsF32 { nx: hf.nx, ny: hf.ny, dx: hf.dx, dy: hf.dy, z, offset, max_deviation, invalid: hf.z.len() - n }
    }

    /// Bound on the slope error from the f32 rounding (see the module documentation).
    pub fn slope_rounding_bound(&self, scheme: super::NormalScheme) -> f64 {
        let ulp = self.max_deviation * f64::from(f32::EPSILON) * 0.5;
        let k = match scheme {
            super::NormalScheme::Central => 1.0,
            super::NormalScheme::Triangles => 2.0,
        };
        k * ulp / self.dx.min(self.dy)
    }
}

impl HeightRows for HeightsF32 {
    type T = f32;
    fn nx(&self) -> usize {
        self.nx
    }
    fn ny(&self) -> usize {
        self.ny
    }
    fn dx(&self) -> f64 {
        self.dx
    }
    fn dy(&self) -> f64 {
        self.dy
    }
    #[inline(always)]
    fn row(&self, i: usize) -> &[f32] {
        &self.z[i * self.nx..(i + 1) * self.nx]
    }
}

/// What the f32 storage cost, reported with the NDF.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct F32Storage {
    /// The mean height removed in f64 before the conversion (m).
    pub offset: f64,
    /// `max |h - offset|` (m).
    pub max_deviation: f64,
    /// Bound on the slope error from the rounding ([`HeightsF32::slope_rounding_bound`]).
    pub slope_rounding_bound: f64,
    /// The bound over the smallest robust slope standard deviation of the binning frame.
    pub fraction_of_slope_scale: f64,
}

impl BandSource for HeightsF32 {
    type T = f32;
    fn shape(&self) -> GridShape {
        GridShape { nx: self.nx, ny: self.ny, dx: self.dx, dy: self.dy, quantum: None }
    }
    #[inline]
    fn band<'b>(&'b self, lo: usize, hi: usize, _buf: &'b mut Vec<f32>) -> Band<'b, f32> {
        Band::new(&self.z[lo * self.nx..hi * self.nx], lo, self.shape())
    }
}
