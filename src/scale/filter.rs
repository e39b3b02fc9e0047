//! Normalized Gaussian convolution of fields with holes (data_formats/scale.md sec. 6).
//!
//! For a field `f` with validity `w` (1 valid, 0 masked), `K*f := (K*(w f)) / (K*w)`: masked points never
//! contribute and are never filled. Separable: rows, then columns, rayon over rows.

use rayon::prelude::*;

use crate::error::{Error, Result};

/// Truncation of the Gaussian kernel in standard deviations. Outside `+-5 sigma` lie 5.7e-7 of the mass
/// and 1.6e-5 of the variance per axis, so the truncated kernel's covariance is `sigma^2` to 2e-5.
pub const KERNEL_RADIUS_SIGMAS: f64 = 5.0;

/// Smallest share of the kernel's mass that must fall on valid points for a filtered value to be kept.
/// Below it the normalized estimate extrapolates from one side of an edge or hole.
pub const MIN_VALID_MASS: f64 = 0.5;

/// A normalized, truncated 1-D Gaussian with standard deviation `sigma` samples (taps `-r..=r`).
///
/// `sigma <= 0` is the identity (a single tap): a footprint below the grid spacing resolves everything.
pub fn gaussian_taps(sigma: f64) -> Result<Vec<f64>> {
    if !sigma.is_finite() || sigma < 0.0 {
        return Err(Error::invalid(format!("kernel standard deviation must be finite and >= 0, got {sigma}")));
    }
    // Below a tenth of a sample the neighbours' weights are < exp(-50): the kernel is a delta.
    if sigma < 0.1 {
        return Ok(vec![1.0]);
    }
    let r = (KERNEL_RADIUS_SIGMAS * sigma).ceil() as usize;
    let taps: Vec<f64> = (0..=2 * r)
        .map(|k| {
            let t = k as f64 - r as f64;
            (-0.5 * t * t / (sigma * sigma)).exp()
        })
        .collect();
    let sum: f64 = taps.iter().sum();
    Ok(taps.into_iter().map(|t| t / sum).collect())
}

/// Several fields on one grid, filtered together with the same kernel and mask.
///
/// `fields[c][i * nx + j]` is channel `c` at row `i`, column `j`; NaN marks a masked point. A point is
/// masked in the output when it is masked in *any* input channel, or when the valid kernel mass around it
/// is below [`MIN_VALID_MASS`].
pub fn filter_channels(nx: usize, ny: usize, fields: &[Vec<f64>], sigma_x: f64, sigma_y: f64) -> Result<Vec<Vec<f64>>> {
    let n = nx.checked_mul(ny).ok_or_else(|| Error::invalid("grid size overflows"))?;
    if fields.iter().any(|f| f.len() != n) {
        return Err(Error::invalid(format!("filter: every channel must have {nx} x {ny} values")));
    }
    let kx = gaussian_taps(sigma_x)?;
    let ky = gaussian_taps(sigma_y)?;
    let nc = fields.len();
    // The common mask: a point is valid only if every channel is finite there.
    let w: Vec<f64> = (0..n).map(|p| if fields.iter().all(|f| f[p].is_finite()) { 1.0 } else { 0.0 }).collect();
    // Interleave [w, w f_0, w f_1, ...] per point so one pass filters all of them.
    let stride = nc + 1;
    let mut buf = vec![0.0; n * stride];
    buf.par_chunks_mut(nx * stride).enumerate().for_each(|(i, row)| {
        for j in 0..nx {
            let p = i * nx + j;
            let o = j * stride;
            row[o] = w[p];
            for c in 0..nc {
                row[o + 1 + c] = if w[p] > 0.0 { fields[c][p] } else { 0.0 };
            }
        }
    });
    // Rows (along x).
    let rx = kx.len() / 2;
    let mut tmp = vec![0.0; n * stride];
    tmp.par_chunks_mut(nx * stride).enumerate().for_each(|(i, out)| {
        let src = &buf[i * nx * stride..(i + 1) * nx * stride];
        for j in 0..nx {
            let lo = j.saturating_sub(rx);
            let hi = (j + rx).min(nx - 1);
            for jj in lo..=hi {
                let k = kx[jj + rx - j];
                for c in 0..stride {
                    out[j * stride + c] += k * src[jj * stride + c];
                }
            }
        }
    });
    // Columns (along y): each output row gathers from the rows around it.
    let ry = ky.len() / 2;
    let mut out2 = vec![0.0; n * stride];
    out2.par_chunks_mut(nx * stride).enumerate().for_each(|(i, out)| {
        let lo = i.saturating_sub(ry);
        let hi = (i + ry).min(ny - 1);
        for ii in lo..=hi {
            let k = ky[ii + ry - i];
            let src = &tmp[ii * nx * stride..(ii + 1) * nx * stride];
            for (o, s) in out.iter_mut().zip(src) {
                *o += k * s;
            }
        }
    });
    let mut result = vec![vec![f64::NAN; n]; nc];
    for p in 0..n {
        let mass = out2[p * stride];
        if w[p] > 0.0 && mass >= MIN_VALID_MASS {
            for (c, r) in result.iter_mut().enumerate() {
                r[p] = out2[p * stride + 1 + c] / mass;
            }
        }
    }
    Ok(result)
}

/// Filter one field (see `filter_channels`).
pub fn filter_field(nx: usize, ny: usize, field: &[f64], sigma_x: f64, sigma_y: f64) -> Result<Vec<f64>> {
    let mut r = filter_channels(nx, ny, &[field.to_vec()], sigma_x, sigma_y)?;
    Ok(r.pop().expect("one channel in, one channel out"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Direct 2-D normalized convolution, the definition written out (no separability).
    fn direct(nx: usize, ny: usize, f: &[f64], sx: f64, sy: f64) -> Vec<f64> {
        let kx = gaussian_taps(sx).unwrap();
        let ky = gaussian_taps(sy).unwrap();
        let (rx, ry) = (kx.len() as isize / 2, ky.len() as isize / 2);
        let mut out = vec![f64::NAN; nx * ny];
        for i in 0..ny as isize {
            for j in 0..nx as isize {
                if !f[(i * nx as isize + j) as usize].is_finite() {
                    continue;
                }
                let (mut num, mut den) = (0.0, 0.0);
                for di in -ry..=ry {
                    for dj in -rx..=rx {
                        let (ii, jj) = (i + di, j + dj);
                        if ii < 0 || jj < 0 || ii >= ny as isize || jj >= nx as isize {
                            continue;
                        }
                        let v = f[(ii * nx as isize + jj) as usize];
                        if v.is_finite() {
                            let k = kx[(dj + rx) as usize] * ky[(di + ry) as usize];
                            num += k * v;
                            den += k;
                        }
                    }
                }
                if den >= MIN_VALID_MASS {
                    out[(i * nx as isize + j) as usize] = num / den;
                }
            }
        }
        out
    }

    #[test]
    fn separable_matches_direct_with_holes() {
        let (nx, ny) = (23, 17);
        let mut f: Vec<f64> = (0..nx * ny).map(|p| ((p * 7919) % 101) as f64 * 0.01 - 0.3).collect();
        for p in [0, 5, 40, 41, 42, 100, 200, 201, 390] {
            f[p] = f64::NAN;
        }
        let a = filter_field(nx, ny, &f, 1.7, 2.3).unwrap();
        let b = direct(nx, ny, &f, 1.7, 2.3);
        for p in 0..nx * ny {
            assert_eq!(a[p].is_nan(), b[p].is_nan(), "mask differs at {p}");
            if a[p].is_finite() {
                // Same sums in a different order: agreement to a few ulps of values O(1).
                assert!((a[p] - b[p]).abs() < 1e-13, "{p}: {} vs {}", a[p], b[p]);
            }
        }
        // Holes are never filled.
        for p in [0, 5, 40, 41, 42, 100, 200, 201, 390] {
            assert!(a[p].is_nan());
        }
    }

    #[test]
    fn preserves_constants_and_planes() {
        // Normalized convolution reproduces a constant exactly; a symmetric kernel reproduces a plane
        // exactly wherever the window is complete.
        let (nx, ny) = (40, 30);
        let c = vec![2.5; nx * ny];
        let fc = filter_field(nx, ny, &c, 3.0, 3.0).unwrap();
        // Corners hold only a quarter of the kernel's mass: masked (MIN_VALID_MASS); the rest is exact.
        assert!(fc.iter().filter(|v| v.is_finite()).all(|v| (v - 2.5).abs() < 1e-14));
        assert!(fc[15 * nx + 20].is_finite() && fc[0].is_nan());
        let plane: Vec<f64> = (0..nx * ny).map(|p| 0.3 * (p % nx) as f64 - 0.2 * (p / nx) as f64).collect();
        let fp = filter_field(nx, ny, &plane, 2.0, 2.0).unwrap();
        // Complete windows: 5 sigma = 10 samples from every edge.
        for i in 10..ny - 10 {
            for j in 10..nx - 10 {
                assert!((fp[i * nx + j] - plane[i * nx + j]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn taps_have_the_asked_variance() {
        // The discrete truncated Gaussian's variance equals sigma^2 up to the truncation (1.6e-5 relative
        // at 5 sigma) and the sampling error (Poisson summation: first alias term exp(-2 pi^2 sigma^2),
        // 3e-9 at sigma = 1 sample), so 1e-4 relative holds with margin.
        for sigma in [1.0, 2.5, 7.0] {
            let t = gaussian_taps(sigma).unwrap();
            let r = (t.len() / 2) as f64;
            let var: f64 = t.iter().enumerate().map(|(k, w)| w * (k as f64 - r).powi(2)).sum();
            assert!((var / (sigma * sigma) - 1.0).abs() < 1e-4, "sigma {sigma}: var {var}");
        }
        assert_eq!(gaussian_taps(0.0).unwrap(), vec![1.0]);
        assert!(gaussian_taps(f64::NAN).is_err());
    }
}
