//! Recovery of synthetic truth.
