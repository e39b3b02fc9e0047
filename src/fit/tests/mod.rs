//! Unit tests of the fitter's internals: the parameter maps and the analytic Jacobians against central
//! differences (the public behaviour is tested in `tests/all/fit/`).

use crate::models::{Model, ModelId};

mod bound;
mod jacobian;
mod mixture;

/// A model from its id and contract parameters.
fn model(id: ModelId, p: &[f64]) -> Model {
    Model::from_params(id, p).expect("valid test parameters")
}
