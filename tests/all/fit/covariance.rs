//! Covariance.
