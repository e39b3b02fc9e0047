//! The empirical route: the NDF as seen at footprint F (data_formats/scale.md eq. S1, sec. 4, 7).
//!
//! Every valid point `x0` contributes `k` slopes `s_F(x0) + L(x0) z` with `L L^T = Sigma_w(x0)` and `z`
//! standard normal from a seeded generator, so the result is reproducible. The slopes are binned the way
//! `src/ndf` bins a scan's slopes.

use nalgebra::{Matrix2, Vector2};
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;

use super::footprint::FootprintField;
use crate::error::{Error, ErrorKind, Result};
use crate::ndf::grid::MAX_CELLS_ACROSS;
use crate::ndf::{BinGrid, EmpiricalNdf, NdfOptions, SlopeFrame};

/// Which covariance blurs each footprint's resolved slope (data_formats/scale.md sec. 3).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Blur {
    /// Each footprint's own `Sigma_w(x0)` (eq. S1): what a renderer with per-pixel covariances (LEAN
    /// mapping) shows.
    PerFootprint,
    /// The one mean covariance `Sigma_F` for every footprint (eq. S1'): Tokuyoshi's single kernel.
    Mean,
}

/// Slopes drawn from (S1) at every valid point of a footprint field; `blur = false` gives the resolved
/// slopes `s_F` alone (the NDF of the filtered surface, the analytic route's input).
pub fn sample_slopes(ff: &FootprintField, per_point: usize, blur: bool, seed: u64) -> Vec<Vector2<f64>> {
    sample_slopes_with(ff, per_point, blur.then_some(Blur::PerFootprint), seed)
}

/// [`sample_slopes`] with a choice of blur (`None`: the resolved slopes alone).
pub fn sample_slopes_with(ff: &FootprintField, per_point: usize, blur: Option<Blur>, seed: u64) -> Vec<Vector2<f64>> {
    let pts = ff.valid_points();
    let mean_l = {
        let n = pts.len().max(1) as f64;
        chol2(&(pts.iter().map(|&p| ff.sigma_w(p)).fold(Matrix2::zeros(), |a, b| a + b) / n))
    };
    let blur_kind = blur;
    let blur = blur.is_some();
    let k = if blur { per_point.max(1) } else { 1 };
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let mut out = Vec::with_capacity(pts.len() * k);
    for &p in &pts {
        let c = ff.s_f(p);
        if !blur {
            out.push(c);
            continue;
        }
        let l = match blur_kind {
            Some(Blur::Mean) => mean_l,
            _ => chol2(&ff.sigma_w(p)),
        };
        for _ in 0..k {
            let z = Vector2::new(rng.sample::<f64, _>(StandardNormal), rng.sample::<f64, _>(StandardNormal));
            out.push(c + l * z);
        }
    }
    out
}

/// `n` slopes drawn from the centred Gaussian `N(0, cov)` (seeded): the kernel of Tokuyoshi eq. 3 as a
/// sample, so that a model can be fitted to the kernel itself (the kernel in the model's own units,
/// data_formats/scale.md sec. 4a).
pub fn gaussian_slopes(cov: &Matrix2<f64>, n: usize, seed: u64) -> Vec<Vector2<f64>> {
    let l = chol2(cov);
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    (0..n).map(|_| l * Vector2::new(rng.sample::<f64, _>(StandardNormal), rng.sample::<f64, _>(StandardNormal))).collect()
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
    /// Mardia's kurtosis `E[|z|^4]` of the whitened slopes: 8 for any bivariate Gaussian (its sampling
    /// spread is `~sqrt(64 / n)`), larger for heavy tails (0 when the covariance is degenerate).
    pub kurtosis: f64,
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
        let mut q = 0.0;
        for v in s {
            let z = w * (v - mean);
            q += z.norm_squared().powi(2);
            t[0] += z[0] * z[0] * z[0];
            t[1] += z[0] * z[0] * z[1];
            t[2] += z[0] * z[1] * z[1];
            t[3] += z[1] * z[1] * z[1];
        }
        let t = t.map(|x| x / n);
        ((t[0] * t[0] + 3.0 * t[1] * t[1] + 3.0 * t[2] * t[2] + t[3] * t[3]).sqrt(), q / n)
    } else {
        (0.0, 0.0)
    };
    let (skewness, kurtosis) = skewness;
    Ok(SlopeMoments { n: s.len(), mean, cov, skewness, kurtosis })
}

/// Samples used for the robust binning frame (a strided subsample), as in `src/ndf`.
const FRAME_SUBSAMPLE: usize = 1 << 17;

/// Bin slopes into an empirical NDF with the binning of `src/ndf` (robust whitened frame, Lambert
/// equal-area disk that covers every slope, per-bin projected solid angles by quadrature), so the fitter
/// sees the NDF at F exactly as it sees a scan's NDF. `cells_across` as in [`NdfOptions`] (None: chosen
/// from the sample count; an even count is raised to the next odd one).
pub fn bin_slopes(slopes: &[Vector2<f64>], cells_across: Option<usize>) -> Result<EmpiricalNdf> {
    bin_slopes_on(slopes, cells_across, None)
}

/// Per-bin counts of `slopes` on the bins of an NDF made by [`bin_slopes`] (same frame and grid), for
/// split-half noise estimates. Slopes outside every bin are not counted.
pub fn counts_on(ndf: &EmpiricalNdf, slopes: &[Vector2<f64>]) -> Vec<u64> {
    let mut counts = vec![0u64; ndf.bins.len()];
    if ndf.grid.n == 0 {
        return counts;
    }
    for s in slopes {
        let c = ndf.grid.cell_of(ndf.frame.to_lambert(s[0], s[1])) as u32;
        if let Ok(k) = ndf.bin_cells.binary_search(&c) {
            counts[k] += 1;
        }
    }
    counts
}

fn bin_slopes_on(slopes: &[Vector2<f64>], cells_across: Option<usize>, frame: Option<SlopeFrame>) -> Result<EmpiricalNdf> {
    if slopes.is_empty() {
        return Err(Error::new(ErrorKind::BadData, "no slopes to bin"));
    }
    if let Some(c) = cells_across {
        if !(3..=MAX_CELLS_ACROSS).contains(&c) {
            return Err(Error::invalid(format!("bins across must be in 3..={MAX_CELLS_ACROSS}, got {c}")));
        }
    }
    let frame = frame.unwrap_or_else(|| {
        let stride = (slopes.len() / FRAME_SUBSAMPLE).max(1);
        let mut sub: Vec<[f64; 2]> = slopes.iter().step_by(stride).map(|s| [s[0], s[1]]).collect();
        SlopeFrame::robust(&mut sub)
    });
    let opts = NdfOptions { cells_across: cells_across.map(|c| c | 1), ..NdfOptions::default() };
    let grid = BinGrid::new(opts.cells_for(slopes.len() as u64));
    let mut counts = vec![0u64; grid.cells()];
    for s in slopes {
        counts[grid.cell_of(frame.to_lambert(s[0], s[1]))] += 1;
    }
    let n = slopes.len() as u64;
    let m = slope_moments(slopes).ok();
    let (bins, bin_cells) = crate::ndf::build_bins(&frame, &grid, &counts, n, None);
    let mut ndf = EmpiricalNdf::from_bins(bins, n);
    ndf.frame = frame;
    ndf.grid = grid;
    ndf.bin_cells = bin_cells;
    if let Some(m) = m {
        ndf.slope_mean = [m.mean[0], m.mean[1]];
        ndf.slope_cov = [[m.cov[(0, 0)], m.cov[(0, 1)]], [m.cov[(1, 0)], m.cov[(1, 1)]]];
    }
    Ok(ndf)
}
