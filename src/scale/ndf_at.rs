//! The empirical route: the NDF as seen at footprint F (data_formats/scale.md eq. S1, sec. 4, 7).
//!
//! Every valid point `x0` contributes `k` slopes `s_F(x0) + L(x0) z` with `L L^T = Sigma_w(x0)` and `z`
//! standard normal from a seeded generator, so the result is reproducible. The slopes are binned on a
//! square grid over the projected unit disk, where a cell's projected solid angle is its area.

use nalgebra::{Matrix2, Vector2, Vector3};
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;

use super::footprint::FootprintField;
use crate::error::{Error, ErrorKind, Result};
use crate::ndf::{EmpiricalNdf, NdfBin};

/// Slopes drawn from (S1) at every valid point of a footprint field; `blur = false` gives the resolved
/// slopes `s_F` alone (the NDF of the filtered surface, the analytic route's input).
pub fn sample_slopes(ff: &FootprintField, per_point: usize, blur: bool, seed: u64) -> Vec<Vector2<f64>> {
    let pts = ff.valid_points();
    let k = if blur { per_point.max(1) } else { 1 };
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(pts.len() * k);
    for &p in &pts {
        let c = ff.s_f(p);
        if !blur {
            out.push(c);
            continue;
        }
        let l = chol2(&ff.sigma_w(p));
        for _ in 0..k {
            let z = Vector2::new(rng.sample::<f64, _>(StandardNormal), rng.sample::<f64, _>(StandardNormal));
            out.push(c + l * z);
        }
    }
    out
}

/// Lower Cholesky factor of a PSD 2x2 (zero where a variance is zero: a footprint with one slope).
fn chol2(m: &Matrix2<f64>) -> Matrix2<f64> {
    let a = m[(0, 0)].max(0.0).sqrt();
    let b = if a > 0.0 { m[(1, 0)] / a } else { 0.0 };
    let c = (m[(1, 1)] - b * b).max(0.0).sqrt();
    Matrix2::new(a, 0.0, b, c)
}

/// Mean, covariance and scale-free skewness of slopes: the Frobenius norm of the third-moment tensor of
/// the whitened slopes (0 for any symmetric distribution; for a Gaussian its sampling spread is
/// `~sqrt(12 / n)`).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SlopeMoments {
    /// Number of slopes.
    pub n: usize,
    /// Mean slope.
    pub mean: Vector2<f64>,
    /// Slope covariance.
    pub cov: Matrix2<f64>,
    /// `||E[z (x) z (x) z]||_F` with `z = Cov^-1/2 (s - mean)`.
    pub skewness: f64,
}

/// Moments of a slope sample.
pub fn slope_moments(s: &[Vector2<f64>]) -> Result<SlopeMoments> {
    if s.len() < 3 {
        return Err(Error::new(ErrorKind::BadData, format!("{} slopes are too few for moments", s.len())));
    }
    let n = s.len() as f64;
    let mean = s.iter().fold(Vector2::zeros(), |a, b| a + b) / n;
    let cov = s.iter().fold(Matrix2::zeros(), |a, b| {
        let d = b - mean;
        a + d * d.transpose()
    }) / n;
    let e = cov.symmetric_eigen();
    // A degenerate covariance has no whitening: the skewness is undefined, reported as 0 (all mass on a line).
    let skewness = if e.eigenvalues.min() > 0.0 {
        let w = e.eigenvectors * Matrix2::from_diagonal(&e.eigenvalues.map(|v| 1.0 / v.sqrt())) * e.eigenvectors.transpose();
        let mut t = [0.0f64; 4]; // xxx, xxy, xyy, yyy
        for v in s {
            let z = w * (v - mean);
            t[0] += z[0] * z[0] * z[0];
            t[1] += z[0] * z[0] * z[1];
            t[2] += z[0] * z[1] * z[1];
            t[3] += z[1] * z[1] * z[1];
        }
        let t = t.map(|x| x / n);
        (t[0] * t[0] + 3.0 * t[1] * t[1] + 3.0 * t[2] * t[2] + t[3] * t[3]).sqrt()
    } else {
        0.0
    };
    Ok(SlopeMoments { n: s.len(), mean, cov, skewness })
}

/// Bin slopes into an empirical NDF on an `nb x nb` grid over the square `[-r, r]^2` of the projected
/// disk, where `r` reaches the farthest sample (so no sample is dropped and the normalization of
/// Heitz eq. 9 holds). Cells wholly outside the disk are left out.
pub fn bin_slopes(slopes: &[Vector2<f64>], nb: usize) -> Result<EmpiricalNdf> {
    if slopes.is_empty() {
        return Err(Error::new(ErrorKind::BadData, "no slopes to bin"));
    }
    if !(4..=4096).contains(&nb) {
        return Err(Error::invalid(format!("bins per axis must be in 4..=4096, got {nb}")));
    }
    let proj = |s: &Vector2<f64>| -> Vector2<f64> { Vector2::new(-s[0], -s[1]) / (1.0 + s.norm_squared()).sqrt() };
    let rmax = slopes.iter().map(|s| proj(s).abs().max()).fold(0.0f64, f64::max);
    // Never below 1e-6 (a flat surface) and never past the rim; a 1.0001 margin keeps the farthest
    // sample inside the last cell.
    let r = (rmax * 1.0001).clamp(1e-6, 1.0);
    let h = 2.0 * r / nb as f64;
    let mut counts = vec![0u64; nb * nb];
    for s in slopes {
        let p = proj(s);
        let ix = (((p[0] + r) / h) as usize).min(nb - 1);
        let iy = (((p[1] + r) / h) as usize).min(nb - 1);
        counts[iy * nb + ix] += 1;
    }
    let n = slopes.len() as u64;
    let mut bins = Vec::with_capacity(nb * nb);
    const SUB: usize = 8; // sub-cells per axis for cells the rim cuts (area and 1/mz integral)
    for iy in 0..nb {
        for ix in 0..nb {
            let (x0, y0) = (-r + ix as f64 * h, -r + iy as f64 * h);
            let (mut area, mut sa, mut cx, mut cy) = (0.0, 0.0, 0.0, 0.0);
            let hs = h / SUB as f64;
            for a in 0..SUB {
                for b in 0..SUB {
                    let (x, y) = (x0 + (a as f64 + 0.5) * hs, y0 + (b as f64 + 0.5) * hs);
                    let q = 1.0 - x * x - y * y;
                    if q > 0.0 {
                        area += hs * hs;
                        sa += hs * hs / q.sqrt();
                        cx += x * hs * hs;
                        cy += y * hs * hs;
                    }
                }
            }
            if area <= 0.0 {
                if counts[iy * nb + ix] > 0 {
                    // Sub-cell sampling missed the sliver of disk this sample fell in: keep the sample by
                    // giving the cell the one sub-cell nearest the rim.
                    let (x, y) = (x0 + h / 2.0, y0 + h / 2.0);
                    let t = 0.999 / (x * x + y * y).sqrt();
                    area = hs * hs;
                    sa = area / (1.0 - 0.999f64.powi(2)).sqrt();
                    cx = x * t * area;
                    cy = y * t * area;
                } else {
                    continue;
                }
            }
            let (mx, my) = (cx / area, cy / area);
            let mz = (1.0 - mx * mx - my * my).max(0.0).sqrt();
            let c = counts[iy * nb + ix];
            let w = area;
            bins.push(NdfBin {
                m: Vector3::new(mx, my, mz),
                d: c as f64 / (n as f64 * w),
                stderr: (c.max(1) as f64).sqrt() / (n as f64 * w),
                count: c,
                solid_angle: sa,
                proj_solid_angle: w,
            });
        }
    }
    Ok(EmpiricalNdf { bins, n_samples: n })
}
