//! The one in-memory scan type every reader produces and every later stage consumes.
//!
//! Frame (CONTRACT.md): sample `(i, j)` (row `i`, column `j`) sits at `x = x0 + j*dx`, `y = y0 + i*dy`,
//! `z = h[i][j]`, all in metres; row index grows with y, column index with x; the macro normal is `+z`.
//! Invalid points are stored as NaN and are never read as heights.

pub(crate) mod bands;
pub(crate) mod heights;
mod input;

use std::collections::BTreeMap;

use crate::error::{Error, Result};
pub use bands::{set_band_rows, set_release_threshold, set_tiled_progress, BandSource};
pub use bands::{Band, GridShape, HeightRows, RawMasked};
pub use heights::Heights;
pub use input::InputInfo;

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
    pub despike: Option<DespikeReport>,
}

/// What the despiking did (the fit JSON's `input.despike`): the scan's metadata carries it from the
/// preprocessing to the report.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DespikeReport {
    /// `median`.
    pub method: String,
    /// Points masked.
    pub masked: usize,
    /// Of them, above their neighbours (the rest below).
    pub masked_high: usize,
    /// Why: the rule in one line.
    pub rule: String,
    /// The spread floor used (metres).
    pub floor: f64,
}

/// A regular grid of heights in metres with a validity mask (NaN = invalid): what every reader returns
/// and every stage reads. The heights are owned, a view of a memory-mapped file, or borrowed from the
/// caller for `'a` ([`Scan::from_view`]); the two borrowed kinds are copied on first write.
#[derive(Debug, Clone, PartialEq)]
pub struct Scan<'a> {
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
    pub z: Heights<'a>,
    /// File metadata.
    pub meta: ScanMeta,
}

/// The checks of [`Heightfield::new`] on a grid of `len` heights.
fn check_grid(nx: usize, ny: usize, dx: f64, dy: f64, len: usize) -> Result<()> {
    if nx == 0 || ny == 0 {
        return Err(Error::invalid(format!("empty grid {nx} x {ny}")));
    }
    if nx.checked_mul(ny) != Some(len) {
        return Err(Error::invalid(format!("{len} heights for a {nx} x {ny} grid")));
    }
    if !(dx.is_finite() && dx > 0.0 && dy.is_finite() && dy > 0.0) {
        return Err(Error::invalid(format!("spacing must be finite and positive, got dx={dx}, dy={dy}")));
    }
    Ok(())
}

/// A scan that owns (or maps) its heights: what the readers return. The type's name before it gained a
/// lifetime.
pub type Heightfield = Scan<'static>;

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
    pub(crate) fn new_finite_or_nan(nx: usize, ny: usize, dx: f64, dy: f64, z: impl Into<Heights<'static>>) -> Result<Self> {
        let z: Heights<'static> = z.into();
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
}

impl<'a> Scan<'a> {
    /// A scan over the caller's heights, rows along y (`h[[i, j]]` at `y = i dy`, `x = j dx`; NaN =
    /// invalid), without a copy when the view is in standard (C, row-major) layout. Other layouts (a
    /// transposed or strided view) are copied once, as is a view holding infinities (they are masked to
    /// NaN like every reader's). Later stages that edit heights (form removal) copy them first; the
    /// caller's array is never written.
    pub fn from_view(h: ndarray::ArrayView2<'a, f64>, dx: f64, dy: f64) -> Result<Scan<'a>> {
        let (ny, nx) = h.dim();
        match h.to_slice() {
            Some(z) if !z.iter().any(|v| v.is_infinite()) => {
                check_grid(nx, ny, dx, dy, z.len())?;
                Ok(Scan { nx, ny, dx, dy, x0: 0.0, y0: 0.0, z: Heights::borrowed(z), meta: ScanMeta::default() })
            }
            _ => Heightfield::new(nx, ny, dx, dy, h.iter().copied().collect()),
        }
    }

    /// The heights as an `(ny, nx)` array view (rows along y), without a copy.
    pub fn heights(&self) -> ndarray::ArrayView2<'_, f64> {
        ndarray::ArrayView2::from_shape((self.ny, self.nx), &self.z[..]).expect("a scan holds nx * ny heights")
    }

    /// The same scan with no borrow (borrowed heights are copied; owned and mapped ones are moved).
    pub fn into_owned(self) -> Scan<'static> {
        Scan { nx: self.nx, ny: self.ny, dx: self.dx, dy: self.dy, x0: self.x0, y0: self.y0, z: self.z.into_owned(), meta: self.meta }
    }
}

impl Scan<'_> {
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

    /// Every `step`-th point along both axes from the first (point picking, no averaging: averaging would
    /// mix invalid points into valid ones or invent values); the spacing grows by `step`, the metadata is
    /// kept ([`crate::preprocess::subsample`]).
    pub fn subsample(&self, step: usize) -> Result<Heightfield> {
        if step == 0 {
            return Err(Error::invalid("subsampling step must be at least 1"));
        }
        let nx = self.nx.div_ceil(step);
        let ny = self.ny.div_ceil(step);
        let mut z = Vec::with_capacity(nx * ny);
        for i in (0..self.ny).step_by(step) {
            z.extend(self.row(i).iter().step_by(step).copied());
        }
        let mut out = Heightfield::new(nx, ny, self.dx * step as f64, self.dy * step as f64, z)?;
        out.x0 = self.x0;
        out.y0 = self.y0;
        out.meta = self.meta.clone();
        Ok(out)
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A standard-layout view is borrowed in place (the scan's heights are the array's memory), reads
    /// back the same values through `heights()`, and is copied only when written or made owned.
    #[test]
    fn views_are_borrowed_without_a_copy_and_copied_on_write() {
        let a = ndarray::Array2::from_shape_fn((3, 4), |(i, j)| (10 * i + j) as f64 * 1e-9);
        let mut s = Scan::from_view(a.view(), 1e-6, 2e-6).expect("valid");
        assert!(s.z.is_borrowed());
        assert_eq!(s.z.as_ptr(), a.as_ptr(), "no copy");
        assert_eq!((s.nx, s.ny, s.dx, s.dy), (4, 3, 1e-6, 2e-6));
        assert_eq!(s.at(2, 1), a[[2, 1]]);
        assert_eq!(s.row(2), a.row(2).as_slice().expect("contiguous row"));
        assert_eq!(s.heights(), a.view());
        let owned = s.clone().into_owned();
        assert!(!owned.z.is_borrowed() && owned.z.as_ptr() != a.as_ptr());
        assert_eq!(owned.heights(), a.view());
        s.z[0] = 5.0;
        assert!(!s.z.is_borrowed());
        assert_eq!(a[[0, 0]], 0.0, "the caller's array is never written");
    }

    /// A transposed view is not row-major: it is copied in its logical order (row `i` of the view is
    /// row `i` of the scan); infinities are masked to NaN as every reader masks them; bad spacing and
    /// empty grids are refused like [`Heightfield::new`] refuses them.
    #[test]
    fn other_layouts_are_copied_and_checked() {
        let a = ndarray::Array2::from_shape_fn((3, 4), |(i, j)| (10 * i + j) as f64);
        let t = a.t();
        let s = Scan::from_view(t, 1.0, 1.0).expect("valid");
        assert!(!s.z.is_borrowed());
        assert_eq!((s.nx, s.ny), (3, 4));
        assert_eq!(s.heights(), t);
        let mut b = a.clone();
        b[[1, 2]] = f64::INFINITY;
        let s = Scan::from_view(b.view(), 1.0, 1.0).expect("valid");
        assert!(s.at(1, 2).is_nan() && s.invalid_count() == 1 && b[[1, 2]].is_infinite());
        assert!(Scan::from_view(a.view(), 0.0, 1.0).is_err());
        assert!(Scan::from_view(ndarray::Array2::<f64>::zeros((0, 4)).view(), 1.0, 1.0).is_err());
    }
}
