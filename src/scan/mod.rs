//! The one in-memory scan type every reader produces and every later stage consumes.
//!
//! Frame (CONTRACT.md): sample `(i, j)` (row `i`, column `j`) sits at `x = x0 + j*dx`, `y = y0 + i*dy`,
//! `z = h[i][j]`, all in metres; row index grows with y, column index with x; the macro normal is `+z`.
//! Invalid points are stored as NaN and are never read as heights.

pub mod heights;

use std::collections::BTreeMap;

use crate::error::{Error, Result};
pub use heights::Heights;

/// What a reader learned about the file besides the heights (for `ndfit info`).
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ScanMeta {
    /// Format id (`x3p`, `plu`, `sur`, `opd`, `metropro`, `al3d`, `tmd`, `ascii`, `xyz`, `csv`, `gsf`,
    /// `npy`, `exr`, `png`, `tiff`, `synthetic`).
    pub format: String,
    /// Height unit of the file before conversion to metres, as the file names it (informational).
    pub file_z_unit: Option<String>,
    /// Lateral unit of the file before conversion to metres (informational).
    pub file_xy_unit: Option<String>,
    /// Instrument and measurement metadata the file carries, as key/value text (manufacturer, model,
    /// serial, objective, date, comment ...). Kept verbatim; nothing is invented.
    pub instrument: BTreeMap<String, String>,
    /// Step `q` of the height lattice `z0 + k q` the stored heights sit on, found before any form removal
    /// (which shifts a lattice off `k q`); `None` for continuous heights. Crop and subsampling keep it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub height_quantum: Option<f64>,
    /// The grid as stored in the file (columns, rows), before any crop or subsampling.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file_grid: Option<[usize; 2]>,
    /// What spike removal masked ([`crate::preprocess::despike`]), when it ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub despike: Option<crate::preprocess::DespikeReport>,
}

/// A regular grid of heights in metres with a validity mask (NaN = invalid).
#[derive(Debug, Clone, PartialEq)]
pub struct Heightfield {
    /// Number of columns (samples along x).
    pub nx: usize,
    /// Number of rows (samples along y).
    pub ny: usize,
    /// Spacing along x in metres (> 0).
    pub dx: f64,
    /// Spacing along y in metres (> 0).
    pub dy: f64,
    /// x of column 0 in metres.
    pub x0: f64,
    /// y of row 0 in metres.
    pub y0: f64,
    /// Heights in metres, row-major: `z[i * nx + j]`; NaN marks an invalid point. Derefs to `[f64]`;
    /// may be a zero-copy view of the scan file until first written ([`Heights`]).
    pub z: Heights,
    /// File metadata.
    pub meta: ScanMeta,
}

impl Heightfield {
    /// A heightfield from row-major heights, checking the shape and spacing.
    pub fn new(nx: usize, ny: usize, dx: f64, dy: f64, z: Vec<f64>) -> Result<Self> {
        if nx == 0 || ny == 0 {
            return Err(Error::invalid(format!("empty grid {nx} x {ny}")));
        }
        let n = nx.checked_mul(ny).ok_or_else(|| Error::invalid("grid size overflows"))?;
        if z.len() != n {
            return Err(Error::invalid(format!("{} heights for a {nx} x {ny} grid", z.len())));
        }
        if !(dx.is_finite() && dx > 0.0 && dy.is_finite() && dy > 0.0) {
            return Err(Error::invalid(format!("spacing must be finite and positive, got dx={dx}, dy={dy}")));
        }
        // Infinities are not heights either: mask them like NaN so no later stage sees them.
        // (In place, writing only where needed: readers of large files pass through here.)
        let mut z = z;
        for h in z.iter_mut().filter(|h| h.is_infinite()) {
            *h = f64::NAN;
        }
        Ok(Heightfield { nx, ny, dx, dy, x0: 0.0, y0: 0.0, z: z.into(), meta: ScanMeta::default() })
    }

    /// [`Heightfield::new`] for readers whose heights are already finite or NaN (no infinities):
    /// skips the masking pass over the data, which matters for files of hundreds of megabytes.
    pub(crate) fn new_finite_or_nan(nx: usize, ny: usize, dx: f64, dy: f64, z: impl Into<Heights>) -> Result<Self> {
        let z: Heights = z.into();
        debug_assert!(z.iter().all(|h| !h.is_infinite()));
        let n = nx.checked_mul(ny).ok_or_else(|| Error::invalid("grid size overflows"))?;
        if nx == 0 || ny == 0 || z.len() != n {
            return Err(Error::invalid(format!("{} heights for a {nx} x {ny} grid", z.len())));
        }
        if !(dx.is_finite() && dx > 0.0 && dy.is_finite() && dy > 0.0) {
            return Err(Error::invalid(format!("spacing must be finite and positive, got dx={dx}, dy={dy}")));
        }
        Ok(Heightfield { nx, ny, dx, dy, x0: 0.0, y0: 0.0, z, meta: ScanMeta::default() })
    }

    /// Height at row `i`, column `j` (NaN when invalid).
    #[inline]
    pub fn at(&self, i: usize, j: usize) -> f64 {
        self.z[i * self.nx + j]
    }

    /// Row `i` as a slice.
    #[inline]
    pub fn row(&self, i: usize) -> &[f64] {
        &self.z[i * self.nx..(i + 1) * self.nx]
    }

    /// Number of invalid (masked) points.
    pub fn invalid_count(&self) -> usize {
        self.z.iter().filter(|h| h.is_nan()).count()
    }

    /// Number of valid points.
    pub fn valid_count(&self) -> usize {
        self.z.len() - self.invalid_count()
    }
}
