//! Parameter uncertainty from the Jacobian at the optimum: `C = s^2 (J^T J)^+` with `s^2` the residual
//! variance (reduced chi-square), through a rank-checked pseudo-inverse so that a direction the data do
//! not determine (theta_z of an isotropic lobe, the angles of a sphere) is reported as such, not as NaN
//! or as a huge number.

use nalgebra::{DMatrix, SymmetricEigen};

/// Eigenvalues of the scaled normal matrix below this fraction of the largest are treated as zero: with
/// f64 residuals, `J^T J` carries about 16 digits, and a condition number past 1e12 leaves fewer than 4
/// for the inverse, less than a standard error needs.
pub const RANK_RTOL: f64 = 1e-12;

/// Covariance of the internal parameters and what is determined.
#[derive(Debug, Clone, PartialEq)]
pub struct Covariance {
    /// `s^2 (J^T J)^+` (internal parameters).
    pub cov: DMatrix<f64>,
    /// Numerical rank of `J`.
    pub rank: usize,
    /// Condition number of the column-scaled `J^T J` (infinite when rank deficient).
    pub condition: f64,
    /// Per parameter: whether it has a component in the null space (its standard error is undefined).
    pub undetermined: Vec<bool>,
}

/// `s2 (J^T J)^+` for the Jacobian `j` (rows = residuals).
pub fn covariance(j: &DMatrix<f64>, s2: f64) -> Covariance {
    let p = j.ncols();
    let jtj = j.transpose() * j;
    // Column scaling: parameters of different units (log alpha, radians) on an equal footing.
    let d: Vec<f64> = (0..p).map(|i| jtj[(i, i)].sqrt()).collect();
    let mut scaled = DMatrix::zeros(p, p);
    for a in 0..p {
        for b in 0..p {
            // Guard: a column of zeros (the parameter does not act) stays zero instead of 0/0.
            scaled[(a, b)] = if d[a] > 0.0 && d[b] > 0.0 { jtj[(a, b)] / (d[a] * d[b]) } else { 0.0 };
        }
    }
    let eig = SymmetricEigen::new(scaled);
    let lmax = eig.eigenvalues.iter().cloned().fold(0.0_f64, f64::max);
    let mut pinv = DMatrix::zeros(p, p);
    let mut rank = 0;
    let mut lmin_kept = f64::INFINITY;
    let mut undetermined = vec![false; p];
    for (i, &l) in eig.eigenvalues.iter().enumerate() {
        let v = eig.eigenvectors.column(i);
        if lmax > 0.0 && l > RANK_RTOL * lmax {
            rank += 1;
            lmin_kept = lmin_kept.min(l);
            pinv += (v * v.transpose()) / l;
        } else {
            // A parameter with weight in a null direction has no finite standard error.
            for (a, u) in undetermined.iter_mut().enumerate() {
                if v[a].abs() > 1e-3 {
                    *u = true;
                }
            }
        }
    }
    for (a, u) in undetermined.iter_mut().enumerate() {
        if d[a] == 0.0 {
            *u = true;
        }
    }
    let mut cov = DMatrix::zeros(p, p);
    for a in 0..p {
        for b in 0..p {
            if d[a] > 0.0 && d[b] > 0.0 {
                cov[(a, b)] = s2 * pinv[(a, b)] / (d[a] * d[b]);
            }
        }
    }
    let condition = if rank == p { lmax / lmin_kept } else { f64::INFINITY };
    Covariance { cov, rank, condition, undetermined }
}
