//! Surface statistics of a heightfield, over its valid points only (ISO 25178-2 areal parameters).
//!
//! - `Sq`: RMS height after removing the least-squares mean plane (population mean over valid points).
//! - `Sdq`: RMS gradient with central differences on the plane-removed heights, over interior points
//!   whose four neighbours are valid: exactly the stencil the empirical NDF uses (slopes per Heitz
//!   eq. 61-62), so no invalid point is ever filled in. Called `Sdq_central` in the peer readings.

use rayon::prelude::*;

use crate::error::Result;
use crate::preprocess::form::fit_polynomial;
use crate::scan::bands::{bands_of, BandSource, GridShape, HeightRows};
use crate::scan::Heightfield;

/// Statistics reported by `ndfit info`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SurfaceStats {
    /// Number of valid points.
    pub valid: usize,
    /// Number of invalid points.
    pub invalid: usize,
    /// Smallest valid height as read, metres.
    pub z_min: f64,
    /// Largest valid height as read, metres.
    pub z_max: f64,
    /// Mean valid height as read, metres.
    pub z_mean: f64,
    /// RMS height about the least-squares plane, metres.
    pub sq: f64,
    /// RMS slope from central differences on the plane-removed heights (dimensionless); NaN when no
    /// interior point has four valid neighbours.
    pub sdq: f64,
    /// Number of points that entered `sdq`.
    pub sdq_points: usize,
}

/// Rows per block of the sums: each block's sums run left to right, row by row, on one thread, and the
/// blocks' sums are added in row order, so the statistics are the same bit for bit on any number of
/// threads, for any band size, in memory or read band by band.
const SUM_ROWS: usize = 32;

/// Compute [`SurfaceStats`] of `hf` (which must have at least one valid point).
pub fn surface_stats(hf: &Heightfield) -> Result<SurfaceStats> {
    surface_stats_of(hf)
}

/// Add the squared central-difference gradients of the middle row of `[below, row, above]` (interior
/// points whose four neighbours are valid) to `acc`, counting them in `n`, left to right.
fn add_gradients([zd, zc, zu]: [&[f64]; 3], dx: f64, dy: f64, acc: &mut f64, n: &mut usize) {
    for j in 1..zc.len().saturating_sub(1) {
        let (l, r) = (zc[j - 1], zc[j + 1]);
        let (d, u) = (zd[j], zu[j]);
        if l.is_nan() || r.is_nan() || d.is_nan() || u.is_nan() {
            continue;
        }
        let gx = (r - l) / (2.0 * dx);
        let gy = (u - d) / (2.0 * dy);
        *acc += gx * gx + gy * gy;
        *n += 1;
    }
}

/// The gradients of the interior rows of `block` (rows `0` and `ny - 1` have no central difference),
/// `row(i)` giving row `i` and its neighbours: their sum of squares and count.
fn block_gradients<'r>(row: impl Fn(usize) -> &'r [f64], block: std::ops::Range<usize>, ny: usize, dx: f64, dy: f64) -> (f64, usize) {
    let (mut acc, mut n) = (0.0, 0usize);
    for i in block.filter(|&i| i > 0 && i + 1 < ny) {
        add_gradients([row(i - 1), row(i), row(i + 1)], dx, dy, &mut acc, &mut n);
    }
    (acc, n)
}

/// RMS central-difference gradient of `z` (row-major `nx` x `ny`) over interior points whose four
/// neighbours are valid; returns (Sdq, number of points). NaN and 0 when there is no such point. The
/// same sums, in the same blocks, as [`surface_stats`].
pub fn sdq_central(z: &[f64], nx: usize, ny: usize, dx: f64, dy: f64) -> (f64, usize) {
    let row = |i: usize| &z[i * nx..(i + 1) * nx];
    let blocks: Vec<_> = bands_of(0..ny, SUM_ROWS).collect();
    let parts: Vec<(f64, usize)> = blocks.into_par_iter().map(|b| block_gradients(row, b, ny, dx, dy)).collect();
    let (mut acc, mut n) = (0.0, 0usize);
    for (a, k) in parts {
        acc += a;
        n += k;
    }
    if n == 0 {
        (f64::NAN, 0)
    } else {
        ((acc / n as f64).sqrt(), n)
    }
}

/// [`surface_stats`] of heights read in row bands ([`BandSource`], e.g. a [`crate::preprocess::Prepared`]
/// scan whose heights stay memory-mapped), with working memory of a few bands per thread, so that
/// `ndfit info` on a tiled scan never holds the heights or their residual. Blocks of 32 rows
/// on every thread; the plane is fitted by `fit_polynomial`.
pub fn surface_stats_of<S: BandSource<T = f64>>(src: &S) -> Result<SurfaceStats> {
    let GridShape { nx, ny, dx, dy, .. } = src.shape();
    let blocks: Vec<_> = bands_of(0..ny, SUM_ROWS).collect();
    let firsts: Vec<(usize, f64, f64, f64)> = blocks
        .par_iter()
        .map_init(Vec::new, |buf, b| {
            let (mut valid, mut lo, mut hi, mut sum) = (0usize, f64::INFINITY, f64::NEG_INFINITY, 0.0);
            for &h in src.band(b.start, b.end, buf).values().iter().filter(|h| !h.is_nan()) {
                valid += 1;
                lo = lo.min(h);
                hi = hi.max(h);
                sum += h;
            }
            (valid, lo, hi, sum)
        })
        .collect();
    let (mut valid, mut lo, mut hi, mut sum) = (0usize, f64::INFINITY, f64::NEG_INFINITY, 0.0);
    for (v, l, h, s) in firsts {
        valid += v;
        lo = lo.min(l);
        hi = hi.max(h);
        sum += s;
    }
    let form = fit_polynomial(src, 1)?;
    // The residual of each block with one row more on either side (the central differences' neighbours).
    let seconds: Vec<(f64, f64, usize)> = blocks
        .par_iter()
        .map_init(
            || (Vec::new(), Vec::new()),
            |(buf, r), b| {
                let (rlo, rhi) = (b.start.saturating_sub(1), (b.end + 1).min(ny));
                let band = src.band(rlo, rhi, buf);
                r.clear();
                (rlo..rhi).for_each(|i| form.residual_row(i, band.row(i), r));
                let r: &[f64] = r;
                let row = |i: usize| &r[(i - rlo) * nx..(i - rlo + 1) * nx];
                let sq: f64 = b.clone().flat_map(row).filter(|h| !h.is_nan()).fold(0.0, |a, h| a + h * h);
                let (acc, n) = block_gradients(row, b.clone(), ny, dx, dy);
                (sq, acc, n)
            },
        )
        .collect();
    let (mut sq, mut acc, mut n) = (0.0, 0.0, 0usize);
    for (q, a, k) in seconds {
        sq += q;
        acc += a;
        n += k;
    }
    let (sdq, sdq_points) = if n == 0 { (f64::NAN, 0) } else { ((acc / n as f64).sqrt(), n) };
    let sq = (sq / valid as f64).sqrt();
    Ok(SurfaceStats { valid, invalid: nx * ny - valid, z_min: lo, z_max: hi, z_mean: sum / valid as f64, sq, sdq, sdq_points })
}
