//! Model selection by the quasi-likelihood BIC, `QBIC = F / c + p ln N` (Burnham and Anderson's QAIC
//! with BIC's penalty): `F` the fit's objective (a deviance), `p` its free parameters, `N` the samples
//! binned, `c` the overdispersion. The one definition `fit_auto` and `scale` both use.

/// The overdispersion `c = max(1, smallest reduced chi-square among the candidates)`: neighbouring
/// normals of a real surface are correlated, so the deviance of even the right model is `c` times its
/// Poisson expectation; the best-fitting candidate measures that factor without over-fitting it. `1`
/// when no candidate has a finite reduced chi-square (no degrees of freedom left).
pub fn overdispersion(reduced_chi2: impl IntoIterator<Item = f64>) -> f64 {
    let c = reduced_chi2.into_iter().fold(f64::INFINITY, f64::min).max(1.0);
    if c.is_finite() {
        c
    } else {
        1.0
    }
}

/// `F / c + p ln N` with `c` from `overdispersion` (floored at 1) and `N` floored at 1.
pub fn qbic(objective: f64, c: f64, n_params: usize, n_samples: f64) -> f64 {
    objective / c.max(1.0) + n_params as f64 * n_samples.max(1.0).ln()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Hand values: the smallest reduced chi-square wins, below 1 it is 1, with none it is 1; the
    /// criterion is the textbook sum.
    #[test]
    fn overdispersion_and_criterion_by_hand() {
        assert_eq!(overdispersion([3.0, 2.5, 4.0]), 2.5);
        assert_eq!(overdispersion([0.7, 2.0]), 1.0);
        assert_eq!(overdispersion(std::iter::empty()), 1.0);
        assert_eq!(overdispersion([f64::INFINITY]), 1.0);
        let q = qbic(50.0, 2.5, 3, 1000.0);
        assert!((q - (20.0 + 3.0 * 1000f64.ln())).abs() < 1e-12);
        assert_eq!(qbic(5.0, 0.5, 0, 0.5), 5.0, "c and N are floored at 1");
    }
}
