//! Surface statistics of a heightfield, over its valid points only (ISO 25178-2 areal parameters).
//!
//! - `Sq`: RMS height after removing the least-squares mean plane (population mean over valid points).
//! - `Sdq`: RMS gradient with central differences on the plane-removed heights, over interior points
//!   whose four neighbours are valid: exactly the stencil the empirical NDF uses (slopes per Heitz
//!   eq. 61-62), so no invalid point is ever filled in. Called `Sdq_central` in the peer readings.

use crate::error::Result;
use crate::preprocess::form::{fit_polynomial, remove_plane};
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

/// Compute [`SurfaceStats`] of `hf` (which must have at least one valid point).
pub fn surface_stats(hf: &Heightfield) -> Result<SurfaceStats> {
    let valid = hf.valid_count();
    let invalid = hf.z.len() - valid;
    let (mut lo, mut hi, mut sum) = (f64::INFINITY, f64::NEG_INFINITY, 0.0);
    for &h in hf.z.iter().filter(|h| !h.is_nan()) {
        lo = lo.min(h);
        hi = hi.max(h);
        sum += h;
    }
    let r = remove_plane(hf)?;
    let sq = (r.iter().filter(|h| !h.is_nan()).map(|h| h * h).sum::<f64>() / valid as f64).sqrt();
    let (sdq, sdq_points) = sdq_central(&r, hf.nx, hf.ny, hf.dx, hf.dy);
    Ok(SurfaceStats { valid, invalid, z_min: lo, z_max: hi, z_mean: sum / valid as f64, sq, sdq, sdq_points })
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

/// RMS central-difference gradient of `z` (row-major `nx` x `ny`) over interior points whose four
/// neighbours are valid; returns (Sdq, number of points). NaN and 0 when there is no such point.
pub fn sdq_central(z: &[f64], nx: usize, ny: usize, dx: f64, dy: f64) -> (f64, usize) {
    let (mut acc, mut n) = (0.0, 0usize);
    for i in 1..ny.saturating_sub(1) {
        let row = |i: usize| &z[i * nx..(i + 1) * nx];
        add_gradients([row(i - 1), row(i), row(i + 1)], dx, dy, &mut acc, &mut n);
    }
    if n == 0 {
        (f64::NAN, 0)
    } else {
        ((acc / n as f64).sqrt(), n)
    }
}

/// [`surface_stats`] of heights read in row bands ([`BandSource`], e.g. a [`crate::preprocess::Prepared`]
/// scan whose heights stay memory-mapped): the same numbers, bit for bit (the same sums in the same
/// order, the plane fitted by the same `fit_polynomial`), with working memory
/// of a few bands, so that `ndfit info` on a tiled scan never holds the heights or their residual.
pub fn surface_stats_of<S: BandSource<T = f64>>(src: &S) -> Result<SurfaceStats> {
    let GridShape { nx, ny, dx, dy, .. } = src.shape();
    let step = src.band_rows();
    let mut buf = Vec::new();
    let (mut valid, mut lo, mut hi, mut sum) = (0usize, f64::INFINITY, f64::NEG_INFINITY, 0.0);
    for b in bands_of(0..ny, step) {
        for &h in src.band(b.start, b.end, &mut buf).values().iter().filter(|h| !h.is_nan()) {
            valid += 1;
            lo = lo.min(h);
            hi = hi.max(h);
            sum += h;
        }
    }
    let form = fit_polynomial(src, 1)?;
    // The residual of each band with one row more on either side (the central differences' neighbours).
    let (mut sq, mut acc, mut n) = (0.0, 0.0, 0usize);
    let mut r = Vec::new();
    for b in bands_of(0..ny, step) {
        let (rlo, rhi) = (b.start.saturating_sub(1), (b.end + 1).min(ny));
        let band = src.band(rlo, rhi, &mut buf);
        r.clear();
        (rlo..rhi).for_each(|i| form.residual_row(i, band.row(i), &mut r));
        let row = |i: usize| &r[(i - rlo) * nx..(i - rlo + 1) * nx];
        for i in b {
            for h in row(i).iter().filter(|h| !h.is_nan()) {
                sq += h * h;
            }
            if i == 0 || i + 1 >= ny {
                continue;
            }
            add_gradients([row(i - 1), row(i), row(i + 1)], dx, dy, &mut acc, &mut n);
        }
    }
    let (sdq, sdq_points) = if n == 0 { (f64::NAN, 0) } else { ((acc / n as f64).sqrt(), n) };
    let sq = (sq / valid as f64).sqrt();
    Ok(SurfaceStats { valid, invalid: nx * ny - valid, z_min: lo, z_max: hi, z_mean: sum / valid as f64, sq, sdq, sdq_points })
}
