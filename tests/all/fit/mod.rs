//! Integration tests of the fitter (`ndfit::fit`): Jacobians against central differences, recovery of
//! synthetic truth, coverage of the reported standard errors, extremes, model selection, the JSON schema
//! and the CLI.

pub(crate) mod fixtures;

mod auto;
mod cli;
mod compare;
mod covariance;
mod end_to_end;
mod mixture;
mod recovery;
mod schema;
mod student;
mod threads;
