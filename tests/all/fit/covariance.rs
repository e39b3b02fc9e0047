//! The rank-checked covariance against closed forms and a second algorithm (LU inverse of J^T J).

use nalgebra::DMatrix;
use ndfit::fit::covariance;

#[test]
fn full_rank_matches_the_direct_inverse() {
    // J^T J = diag(1, 4) in closed form, so C = s2 diag(1, 1/4).
    let j = DMatrix::from_row_slice(3, 2, &[1.0, 0.0, 0.0, 2.0, 0.0, 0.0]);
    let c = covariance(&j, 2.0);
    assert_eq!(c.rank, 2);
    assert!((c.cov[(0, 0)] - 2.0).abs() < 1e-14 && (c.cov[(1, 1)] - 0.5).abs() < 1e-14 && c.cov[(0, 1)].abs() < 1e-14);
    // A correlated, badly scaled J (columns differ by 1e6): compare with the LU inverse.
    let j = DMatrix::from_row_slice(4, 3, &[1.0, 2e6, 0.3, 0.5, 1e6, 0.1, -1.0, 3e6, 0.7, 2.0, -1e6, 0.2]);
    let c = covariance(&j, 1.5);
    let want = (j.transpose() * &j).try_inverse().expect("invertible") * 1.5;
    for a in 0..3 {
        for b in 0..3 {
            assert!((c.cov[(a, b)] - want[(a, b)]).abs() <= 1e-8 * (want[(a, a)] * want[(b, b)]).sqrt(), "({a},{b})");
        }
    }
    assert!(c.undetermined.iter().all(|u| !u));
}

#[test]
fn degenerate_directions_are_reported_not_nan() {
    // Two identical columns: only their sum is determined; the third parameter is fine.
    let j = DMatrix::from_row_slice(3, 3, &[1.0, 1.0, 0.0, 2.0, 2.0, 0.0, 0.0, 0.0, 3.0]);
    let c = covariance(&j, 1.0);
    assert_eq!(c.rank, 2);
    assert_eq!(c.undetermined, vec![true, true, false]);
    assert!(c.cov.iter().all(|v| v.is_finite()));
    assert!((c.cov[(2, 2)] - 1.0 / 9.0).abs() < 1e-14);
    assert!(c.condition.is_infinite());
    // A parameter that does not act at all (zero column).
    let j = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 1.0, 0.0]);
    let c = covariance(&j, 1.0);
    assert_eq!(c.undetermined, vec![false, true]);
    assert!((c.cov[(0, 0)] - 0.5).abs() < 1e-14);
}
