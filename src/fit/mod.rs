//! Fitting analytic NDFs to an empirical NDF with Levenberg-Marquardt.
