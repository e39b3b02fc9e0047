//! Integration tests: the analytic NDF models (`src/models`), checked against independent sources:
//! adaptive quadrature written here, closed forms from the papers typed in afresh, finite differences,
//! chi-square tests of the samplers, and hand-derived equivalent parameterizations.

mod quad;

mod brdf;
mod canonical;
mod equivalence;
mod eval_cli;
mod extremes;
mod masking;
mod mixture;
mod normalization;
mod sampling;
mod student;
mod table;
