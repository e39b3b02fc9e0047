//! Shared fixtures: synthetic binned NDFs with known truth and the accuracy metric against the truth.

use ndfit::fit::delta;
use ndfit::fit::{binned_ndf, Grid};
use ndfit::models::{Model, ModelId, Ndf};
use ndfit::ndf::EmpiricalNdf;

/// Samples of a 1024^2 scan.
pub const N_1024: f64 = 1024.0 * 1024.0;

/// Cells per side of the fixture grid. The equal-area map of the whitened normal squeezes the GGX slope
/// tail (1% of the mass beyond 10 alpha) into a thin ring at the rim, where the midpoint rule of
/// objective.md errs most: at 96 cells a narrow GGX lobe fitted to noise-free counts is 0.46% low in
/// alpha, at 192 cells 0.11% (measured; the error falls as h^2).
pub const GRID_N: usize = 192;

/// A model from its id and contract parameters.
pub fn model(id: ModelId, p: &[f64]) -> Model {
    Model::from_params(id, p).expect("valid test parameters")
}

/// A Poisson-noisy binned NDF of `truth` with `n` samples.
pub fn ndf_of(truth: &Model, n: f64, seed: u64) -> EmpiricalNdf {
    binned_ndf(truth, &Grid::for_model(truth, GRID_N), n, seed)
}

/// As [`ndf_of`] on a grid of `cells` per side (coarser grids for the many-draw statistics: at 96 cells the
/// midpoint bias of a moderately rough lobe stays below a tenth of its standard errors, measured by the
/// coverage test itself).
pub fn ndf_on(truth: &Model, cells: usize, n: f64, seed: u64) -> EmpiricalNdf {
    binned_ndf(truth, &Grid::for_model(truth, cells), n, seed)
}

/// `delta(D_fit; D_true)` (objective.md) by quadrature on a grid finer than the fixture's and matched
/// to the truth (so the nodes sample `D_true(m)(m.n)` densely where it has mass).
pub fn delta_to_truth(fit: &Model, truth: &Model) -> f64 {
    let (bins, _) = ndfit::fit::expected(truth, &Grid::for_model(truth, 256), 1.0);
    delta(|m| fit.d(*m), |m| truth.d(*m), bins.iter().map(|b| (b.m, b.proj_solid_angle))).expect("truth has mass")
}

/// Difference of two angles of period `period`, in (-period/2, period/2].
pub fn angle_diff(a: f64, b: f64, period: f64) -> f64 {
    let d = (a - b).rem_euclid(period);
    if d > 0.5 * period {
        d - period
    } else {
        d
    }
}
