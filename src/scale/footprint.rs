//! Slopes of a heightfield and their statistics under a footprint kernel (data_formats/scale.md sec. 1-3).
//!
//! For a footprint `F` the kernel is a Gaussian of standard deviation `sigma_K = F / 2` on the surface
//! (Tokuyoshi eq. 2 uses a screen-space kernel variance of 0.25 pixel^2). At each valid point `x0`:
//! the resolved slope `s_F = K*s` (the slope of `h_F = K*h`) and the within-footprint covariance
//! `Sigma_w = K*(s s^T) - s_F s_F^T`. Their mean `Sigma_F` is the covariance the analytic route adds to a
//! roughness matrix (Tokuyoshi eq. 3).

use nalgebra::{Matrix2, Vector2};
use rayon::prelude::*;

use super::filter::filter_channels;
use crate::error::{Error, ErrorKind, Result};
use crate::scan::Heightfield;

/// Central-difference slopes `(dh/dx, dh/dy)` at every sample (NaN where a neighbour is missing or at the
/// border). Microfacet normal `m = (-s_x, -s_y, 1)/|..|` (CONTRACT.md; Heitz eq. 61-62).
pub fn slope_field(hf: &Heightfield) -> (Vec<f64>, Vec<f64>) {
    let (nx, ny) = (hf.nx, hf.ny);
    let mut sx = vec![f64::NAN; nx * ny];
    let mut sy = vec![f64::NAN; nx * ny];
    sx.par_chunks_mut(nx).zip(sy.par_chunks_mut(nx)).enumerate().for_each(|(i, (rx, ry))| {
        if i == 0 || i + 1 >= ny {
            return;
        }
        for j in 1..nx.saturating_sub(1) {
            let c = hf.at(i, j);
            let (l, r) = (hf.at(i, j - 1), hf.at(i, j + 1));
            let (d, u) = (hf.at(i - 1, j), hf.at(i + 1, j));
            // NaN propagates: a stencil touching a hole gives no slope (holes are never filled).
            if c.is_finite() {
                rx[j] = (r - l) / (2.0 * hf.dx);
                ry[j] = (u - d) / (2.0 * hf.dy);
            }
        }
    });
    (sx, sy)
}

/// Kernel standard deviation on the surface for a footprint `f` (metres): `F / 2` (Tokuyoshi eq. 2).
pub fn kernel_sigma(footprint: f64) -> f64 {
    0.5 * footprint
}

/// Per-point footprint statistics: resolved slopes and within-footprint covariances (NaN where masked).
#[derive(Debug, Clone)]
pub struct FootprintField {
    /// Columns.
    pub nx: usize,
    /// Rows.
    pub ny: usize,
    /// Resolved slope x component `s_F,x = (K*s_x)`.
    pub sfx: Vec<f64>,
    /// Resolved slope y component.
    pub sfy: Vec<f64>,
    /// Within-footprint covariance, xx.
    pub wxx: Vec<f64>,
    /// Within-footprint covariance, xy.
    pub wxy: Vec<f64>,
    /// Within-footprint covariance, yy.
    pub wyy: Vec<f64>,
}

impl FootprintField {
    /// Indices of points where every statistic is defined.
    pub fn valid_points(&self) -> Vec<usize> {
        (0..self.nx * self.ny).filter(|&p| self.sfx[p].is_finite() && self.wxx[p].is_finite()).collect()
    }

    /// `Sigma_w` at point `p`.
    pub fn sigma_w(&self, p: usize) -> Matrix2<f64> {
        Matrix2::new(self.wxx[p], self.wxy[p], self.wxy[p], self.wyy[p])
    }

    /// `s_F` at point `p`.
    pub fn s_f(&self, p: usize) -> Vector2<f64> {
        Vector2::new(self.sfx[p], self.sfy[p])
    }
}

/// The footprint statistics of a slope field `(sx, sy)` for a kernel of standard deviation `sigma`
/// metres on a grid of spacing `(dx, dy)`.
pub fn footprint_field(nx: usize, ny: usize, dx: f64, dy: f64, sx: &[f64], sy: &[f64], sigma: f64) -> Result<FootprintField> {
    if !(sigma.is_finite() && sigma >= 0.0) {
        return Err(Error::invalid(format!("footprint kernel sigma must be finite and >= 0, got {sigma}")));
    }
    // Kernel taps are allocated per axis: refuse a kernel wider than the grid itself (it could only
    // average the whole scan, and its size would come from user input unchecked).
    let (sgx, sgy) = (sigma / dx, sigma / dy);
    if sgx > 4.0 * nx as f64 || sgy > 4.0 * ny as f64 {
        return Err(Error::new(
            ErrorKind::InvalidInput,
            format!("footprint kernel sigma {sigma:.3e} m is more than 4x the scan's extent; use a smaller footprint"),
        ));
    }
    let xx: Vec<f64> = sx.iter().map(|v| v * v).collect();
    let xy: Vec<f64> = sx.iter().zip(sy).map(|(a, b)| a * b).collect();
    let yy: Vec<f64> = sy.iter().map(|v| v * v).collect();
    let ch = vec![sx.to_vec(), sy.to_vec(), xx, xy, yy];
    let mut f = filter_channels(nx, ny, &ch, sgx, sgy)?;
    let (m2yy, m2xy, m2xx) = (f.pop().expect("5 channels"), f.pop().expect("5 channels"), f.pop().expect("5 channels"));
    let (sfy, sfx) = (f.pop().expect("5 channels"), f.pop().expect("5 channels"));
    let n = nx * ny;
    let mut wxx = vec![f64::NAN; n];
    let mut wxy = vec![f64::NAN; n];
    let mut wyy = vec![f64::NAN; n];
    for p in 0..n {
        if !sfx[p].is_finite() {
            continue;
        }
        let (a, b, c) = (m2xx[p] - sfx[p] * sfx[p], m2xy[p] - sfx[p] * sfy[p], m2yy[p] - sfy[p] * sfy[p]);
        // E[s^2] - E[s]^2 cancels catastrophically when the footprint holds one slope: clamp to the PSD
        // part so rounding never yields a negative variance.
        let m = psd_part(Matrix2::new(a, b, b, c));
        wxx[p] = m[(0, 0)];
        wxy[p] = m[(0, 1)];
        wyy[p] = m[(1, 1)];
    }
    Ok(FootprintField { nx, ny, sfx, sfy, wxx, wxy, wyy })
}

pub use crate::models::roughness::psd_part;

/// Scalar summary of one footprint: the matrices the two routes need.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct FootprintStats {
    /// Footprint `F` (metres).
    pub footprint: f64,
    /// Kernel standard deviation `F / 2` (metres).
    pub sigma_k: f64,
    /// Points where all statistics are defined.
    pub n_points: usize,
    /// `Sigma_F`: mean within-footprint slope covariance (data_formats/scale.md S2).
    pub sigma_f: Matrix2<f64>,
    /// `Cov(s_F)`: covariance of the resolved slopes.
    pub cov_resolved: Matrix2<f64>,
    /// Mean resolved slope.
    pub mean_resolved: Vector2<f64>,
    /// Covariance of the unfiltered slopes over the same points.
    pub cov_slopes: Matrix2<f64>,
}

/// Mean and covariance of the vectors `v(p)` over `pts`.
pub fn mean_cov(pts: &[usize], v: impl Fn(usize) -> Vector2<f64>) -> (Vector2<f64>, Matrix2<f64>) {
    let n = pts.len().max(1) as f64;
    let mean = pts.iter().map(|&p| v(p)).fold(Vector2::zeros(), |a, b| a + b) / n;
    let cov = pts.iter().map(|&p| {
        let d = v(p) - mean;
        d * d.transpose()
    });
    (mean, cov.fold(Matrix2::zeros(), |a, b| a + b) / n)
}

/// Summarize a footprint field over all its valid points (with the unfiltered slopes `sx, sy` for the
/// law-of-total-covariance check).
pub fn footprint_stats(ff: &FootprintField, sx: &[f64], sy: &[f64], footprint: f64) -> Result<FootprintStats> {
    footprint_stats_over(ff, sx, sy, footprint, &ff.valid_points())
}

/// [`footprint_stats`] over the given points only (those of them where every statistic is defined).
pub fn footprint_stats_over(ff: &FootprintField, sx: &[f64], sy: &[f64], footprint: f64, points: &[usize]) -> Result<FootprintStats> {
    let pts: Vec<usize> = points
        .iter()
        .copied()
        .filter(|&p| p < ff.sfx.len() && ff.sfx[p].is_finite() && ff.wxx[p].is_finite() && sx[p].is_finite())
        .collect();
    if pts.len() < 16 {
        return Err(Error::new(
            ErrorKind::BadData,
            format!("footprint {footprint:.3e} m leaves {} valid points (need at least 16)", pts.len()),
        ));
    }
    let n = pts.len() as f64;
    let sigma_f = pts.iter().map(|&p| ff.sigma_w(p)).fold(Matrix2::zeros(), |a, b| a + b) / n;
    let (mean_resolved, cov_resolved) = mean_cov(&pts, |p| ff.s_f(p));
    let (_, cov_slopes) = mean_cov(&pts, |p| Vector2::new(sx[p], sy[p]));
    Ok(FootprintStats {
        footprint,
        sigma_k: kernel_sigma(footprint),
        n_points: pts.len(),
        sigma_f,
        cov_resolved,
        mean_resolved,
        cov_slopes,
    })
}
