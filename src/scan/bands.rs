//! Heights read in row bands: the way every pass over a scan after reading sees it.
//!
//! A [`BandSource`] hands out rows `lo..hi` as a [`Band`], which is a [`HeightRows`] whose row `i` is
//! row `i` of the whole grid (global indices, global `nx`, `ny`), so the stencil kernels run on a band
//! unchanged. A scan in memory or memory-mapped hands out views of its own rows (no copy); a scan whose
//! form is removed lazily ([`crate::preprocess::Prepared`]) computes the residual rows of each band into
//! a small buffer, with the arithmetic the whole-scan form removal uses, so every value is the same bit
//! for bit. Passes take bands of [`band_rows`] rows (about [`BAND_BYTES`]), so their working memory is
//! a few bands per thread whatever the scan's size.
//!
//! A memory-mapped scan larger than [`release_threshold`] is read as a tiled scan: the pages of each band
//! are released back to the page cache (`madvise(MADV_DONTNEED)`) when the band is dropped, so the
//! process's resident memory does not grow with the scan (a page read again is faulted back in from the
//! unchanged file).

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};
use std::sync::OnceLock;

use super::Scan;

/// Row access to a grid of stored heights, generic over the stored float type: the NDF pass runs over
/// [`Scan`] (f64) and [`crate::ndf::HeightsF32`] (f32 storage) with the same kernel. Every
/// height is widened to f64 before it is differenced.
pub trait HeightRows: Sync {
    /// The stored float type.
    type T: Copy + Into<f64> + Sync;
    /// Columns.
    fn nx(&self) -> usize;
    /// Rows.
    fn ny(&self) -> usize;
    /// Spacing along x (m).
    fn dx(&self) -> f64;
    /// Spacing along y (m).
    fn dy(&self) -> f64;
    /// Row `i`.
    fn row(&self, i: usize) -> &[Self::T];
    /// The height quantum found before form removal, when the heights were on a lattice then
    /// ([`super::ScanMeta::height_quantum`]); `None` lets the NDF look for one itself.
    fn known_quantum(&self) -> Option<f64> {
        None
    }
}

impl HeightRows for Scan<'_> {
    type T = f64;
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
    fn row(&self, i: usize) -> &[f64] {
        Scan::row(self, i)
    }
    fn known_quantum(&self) -> Option<f64> {
        self.meta.height_quantum
    }
}

/// Bytes of heights a band aims at: a few bands per thread stay in the L2 cache.
pub const BAND_BYTES: usize = 1 << 20;

/// Rows per band for rows of `nx` values of `bytes` bytes each (at least 4), or the rows set by
/// [`set_band_rows`].
pub fn band_rows(nx: usize, bytes: usize) -> usize {
    match BAND_ROWS.load(Ordering::Relaxed) {
        0 => (BAND_BYTES / (nx.max(1) * bytes.max(1))).max(4),
        r => r,
    }
}

/// Rows per band set for this process (0: from [`BAND_BYTES`]).
static BAND_ROWS: AtomicUsize = AtomicUsize::new(0);

/// Set the rows per band for this process (`None`: from `BAND_BYTES`); tests use a row or two to
/// put band edges everywhere. Only speed and memory change with it, never a result.
pub fn set_band_rows(rows: Option<usize>) {
    BAND_ROWS.store(rows.map_or(0, |r| r.max(1)), Ordering::Relaxed);
}

/// Mapped scans above this many bytes of heights release each band's pages after use (0: never set,
/// the default [`DEFAULT_RELEASE_BYTES`]).
static RELEASE_BYTES: AtomicU64 = AtomicU64::new(0);

/// The default tiling threshold: scans whose heights take more than this are read as tiled scans.
pub const DEFAULT_RELEASE_BYTES: u64 = 1 << 30;

/// The tiling threshold in bytes ([`set_release_threshold`], or [`DEFAULT_RELEASE_BYTES`]).
pub fn release_threshold() -> u64 {
    match RELEASE_BYTES.load(Ordering::Relaxed) {
        0 => DEFAULT_RELEASE_BYTES,
        b => b,
    }
}

/// Set the tiling threshold for this process (`None`: the default). Only memory use changes with it,
/// never a result.
pub fn set_release_threshold(bytes: Option<u64>) {
    RELEASE_BYTES.store(bytes.map_or(0, |b| b.max(1)), Ordering::Relaxed);
}

/// Called with the bytes of heights of every band of a tiled scan when it is done (a progress bar).
static TILED_PROGRESS: OnceLock<Box<dyn Fn(u64) + Send + Sync>> = OnceLock::new();

/// Report the progress of passes over tiled scans to `f` (the bytes of heights of each band read, as
/// they are done; several passes read every band). Set once per process (later calls are ignored).
pub fn set_tiled_progress(f: impl Fn(u64) + Send + Sync + 'static) {
    let _ = TILED_PROGRESS.set(Box::new(f));
}

/// Report `bytes` of a tiled scan's heights read (to [`set_tiled_progress`]'s function, if any).
pub(crate) fn report_tiled_progress(bytes: u64) {
    if let Some(f) = TILED_PROGRESS.get() {
        f(bytes);
    }
}

/// Bytes around a band that are released with it ([`BandSource::band`] of a tiled scan): a page-cache
/// folio mapped by a fault can reach this far.
const FAULT_AROUND: usize = 2 << 20;

/// The grid a [`BandSource`] covers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GridShape {
    /// Columns.
    pub nx: usize,
    /// Rows.
    pub ny: usize,
    /// Spacing along x (m).
    pub dx: f64,
    /// Spacing along y (m).
    pub dy: f64,
    /// [`HeightRows::known_quantum`].
    pub quantum: Option<f64>,
}

/// Rows `lo..hi` of a grid, handed out by a [`BandSource`]: row `i` of the band is row `i` of the whole grid.
pub struct Band<'b, T> {
    z: &'b [T],
    lo: usize,
    shape: GridShape,
    /// Release these bytes (start address, length) when dropped (a tiled, mapped scan).
    release: Option<(usize, usize)>,
}

impl<'b, T> Band<'b, T> {
    /// Rows `lo..lo + z.len() / nx` of the grid `shape`, held in `z`.
    pub fn new(z: &'b [T], lo: usize, shape: GridShape) -> Self {
        debug_assert_eq!(z.len() % shape.nx.max(1), 0);
        Band { z, lo, shape, release: None }
    }

    /// The first row held.
    pub fn lo(&self) -> usize {
        self.lo
    }

    /// One past the last row held.
    pub fn hi(&self) -> usize {
        self.lo + self.z.len() / self.shape.nx.max(1)
    }

    /// The held rows as one row-major slice.
    pub fn values(&self) -> &[T] {
        self.z
    }
}

impl<T> Drop for Band<'_, T> {
    fn drop(&mut self) {
        if let Some((start, len)) = self.release {
            super::heights::release_pages(start as *const u8, len);
            report_tiled_progress(std::mem::size_of_val(self.z) as u64);
        }
    }
}

impl<T: Copy + Into<f64> + Sync> HeightRows for Band<'_, T> {
    type T = T;
    fn nx(&self) -> usize {
        self.shape.nx
    }
    fn ny(&self) -> usize {
        self.shape.ny
    }
    fn dx(&self) -> f64 {
        self.shape.dx
    }
    fn dy(&self) -> f64 {
        self.shape.dy
    }
    #[inline(always)]
    fn row(&self, i: usize) -> &[T] {
        let nx = self.shape.nx;
        &self.z[(i - self.lo) * nx..(i - self.lo + 1) * nx]
    }
    fn known_quantum(&self) -> Option<f64> {
        self.shape.quantum
    }
}

/// Heights handed out in row bands: rows `lo..hi` with global row indices, so the stencil kernels run on a
/// band unchanged; a scan in memory hands out views of its rows, a lazily preprocessed one computes each
/// band's residual rows into a small buffer. Passes over bands need a few bands of memory per thread.
pub trait BandSource: Sync {
    /// The stored float type.
    type T: Copy + Into<f64> + Sync + Send + 'static;
    /// The grid.
    fn shape(&self) -> GridShape;
    /// Rows `lo..hi` (`lo < hi <= ny`): a view of stored rows, or computed into `buf`.
    fn band<'b>(&'b self, lo: usize, hi: usize, buf: &'b mut Vec<Self::T>) -> Band<'b, Self::T>;
    /// The same heights up to a plane, read with no arithmetic per band: a source each of whose slopes
    /// (by any [`crate::ndf::NormalScheme`], all exact on a plane) exceeds this one's by the returned constant
    /// `grad h`, up to rounding. Passes that need only slopes (the histogram and the resolution test)
    /// read it and subtract the constant: the plane is folded into the slopes, not removed from every
    /// height. `None` (the default): read this source itself.
    fn plane_folded(&self) -> Option<(RawMasked<'_>, [f64; 2])> {
        None
    }
    /// Rows per band for passes over the whole grid.
    fn band_rows(&self) -> usize {
        band_rows(self.shape().nx, std::mem::size_of::<Self::T>())
    }
    /// The grid's shape as a `HeightRows` that holds no row (for the shape-only helpers of
    /// [`crate::ndf::NormalScheme`]).
    fn outline(&self) -> Band<'static, Self::T> {
        Band::new(&[], 0, self.shape())
    }
}

impl Scan<'_> {
    /// Whether passes read this scan as a tiled scan (mapped, above `release_threshold`): each band's
    /// pages are released after use, so nothing may read its rows outside a band.
    pub fn is_tiled(&self) -> bool {
        self.z.is_mapped() && (self.z.len() as u64).saturating_mul(8) > release_threshold()
    }
}

impl BandSource for Scan<'_> {
    type T = f64;
    fn shape(&self) -> GridShape {
        GridShape { nx: self.nx, ny: self.ny, dx: self.dx, dy: self.dy, quantum: self.meta.height_quantum }
    }
    #[inline]
    fn band<'b>(&'b self, lo: usize, hi: usize, _buf: &'b mut Vec<f64>) -> Band<'b, f64> {
        let mut b = Band::new(&self.z[lo * self.nx..hi * self.nx], lo, self.shape());
        if self.is_tiled() {
            // The kernel maps pages around a faulting one (fault-around, and whole large folios of the
            // page cache, up to 2 MiB): release that much beyond the band on either side too, within
            // the heights, or those pages would stay mapped.
            let all = self.z.as_ptr() as usize..self.z.as_ptr() as usize + self.z.len() * 8;
            let start = (b.z.as_ptr() as usize).saturating_sub(FAULT_AROUND).max(all.start);
            let end = (b.z.as_ptr() as usize + b.z.len() * 8 + FAULT_AROUND).min(all.end);
            b.release = Some((start, end - start));
        }
        b
    }
}

/// The heights as read with some points masked and no form removed: what a scan whose form is a plane
/// hands to the passes that need only slopes ([`BandSource::plane_folded`]). A band with no masked point
/// is a view of the stored rows (no copy, no arithmetic).
pub struct RawMasked<'p> {
    raw: &'p Scan<'p>,
    masked: &'p [usize],
}

impl<'p> RawMasked<'p> {
    /// The heights of `raw` with the points `masked` (sorted flat indices `i * nx + j`) read as NaN.
    pub fn new(raw: &'p Scan<'p>, masked: &'p [usize]) -> Self {
        RawMasked { raw, masked }
    }
}

impl BandSource for RawMasked<'_> {
    type T = f64;
    fn shape(&self) -> GridShape {
        self.raw.shape()
    }
    fn band<'b>(&'b self, lo: usize, hi: usize, buf: &'b mut Vec<f64>) -> Band<'b, f64> {
        masked_band(self.raw, None::<fn(usize, &[f64], &mut Vec<f64>)>, self.masked, lo, hi, buf)
    }
}

/// Rows `lo..hi` of `raw`, each pushed onto `buf` by `rows` (`rows(i, row, buf)`; `None`: as stored), with
/// the points `masked` (sorted flat indices) set to NaN: a view of the stored rows when there is nothing to
/// change.
pub fn masked_band<'b>(
    raw: &'b Scan<'_>,
    rows: Option<impl Fn(usize, &[f64], &mut Vec<f64>)>,
    masked: &[usize],
    lo: usize,
    hi: usize,
    buf: &'b mut Vec<f64>,
) -> Band<'b, f64> {
    let nx = raw.nx;
    let m = masked.partition_point(|&k| k < lo * nx)..masked.partition_point(|&k| k < hi * nx);
    if rows.is_none() && m.is_empty() {
        return raw.band(lo, hi, buf);
    }
    buf.clear();
    buf.reserve(nx * (hi - lo));
    {
        let mut rbuf = Vec::new();
        let band = raw.band(lo, hi, &mut rbuf);
        match rows {
            Some(f) => (lo..hi).for_each(|i| f(i, band.row(i), buf)),
            None => buf.extend_from_slice(band.values()),
        }
    }
    for &k in &masked[m] {
        buf[k - lo * nx] = f64::NAN;
    }
    Band::new(buf, lo, raw.shape())
}

/// The bands `[lo, hi)` of `rows` (each at most `step` rows), in order.
pub fn bands_of(rows: std::ops::Range<usize>, step: usize) -> impl Iterator<Item = std::ops::Range<usize>> + Clone {
    let end = rows.end;
    let step = step.max(1);
    rows.step_by(step).map(move |lo| lo..(lo + step).min(end))
}
