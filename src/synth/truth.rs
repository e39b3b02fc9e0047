//! The truth written beside a synthetic scan (`SCAN.truth.json`, schema `ndfit.synth/1`).

use serde::{Deserialize, Serialize};

use crate::error::{Error, Result};
use crate::models::{Model, ModelId};

/// One facet of a piecewise-planar surface: its normal and its share of the projected area.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FacetTruth {
    /// Slope `grad h` of the facet (Heitz eq. 61).
    pub slope: [f64; 2],
    /// Unit normal `(-slope, 1) / |...|`.
    pub m: [f64; 3],
    /// Fraction of the grid's columns the facet covers (its share of projected area).
    pub weight: f64,
    /// First and one-past-last column of the facet's strip.
    pub columns: [usize; 2],
}

/// What a synthetic scan is known to be.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Truth {
    /// Always `ndfit.synth/1`.
    pub schema: String,
    /// The contract model id whose NDF the surface has (`ellipsoid`, `beckmann-aniso`), or `planes`
    /// for a piecewise-planar surface (a sum of delta NDFs: see `facets`; no contract model).
    pub model: String,
    /// The model's parameters by contract name, in contract order.
    pub params: serde_json::Map<String, serde_json::Value>,
    /// Walter et al.'s A (row-major) when the model is an ellipsoid special case.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub matrix_a: Option<[[f64; 3]; 3]>,
    /// Generator id: `ellipsoid`, `gaussian` or `planes`.
    pub generator: String,
    /// Everything the generator was given (grid, seed, noise, holes, offset and its own parameters).
    pub settings: serde_json::Value,
    /// Derived facts for checks, per generator (for example the footprint's projected area, the
    /// realized slope covariances of the Gaussian surface per normal scheme).
    pub derived: serde_json::Value,
    /// The facets of a `planes` surface.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub facets: Option<Vec<FacetTruth>>,
    /// The scan file it describes (`path`, `format`, `nx`, `ny`, `dx`, `dy`), as in `ndfit.fit/1`;
    /// filled in by `ndfit synth`.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub input: Option<serde_json::Value>,
}

impl Truth {
    /// A truth for a contract model.
    pub(crate) fn for_model(model: &Model, generator: &str, settings: serde_json::Value, derived: serde_json::Value) -> Self {
        let id = model.id();
        let params = id.param_names().iter().zip(model.params()).map(|(k, v)| (k.to_string(), serde_json::Value::from(v))).collect();
        let matrix_a = model.matrix_a().map(|a| {
            let mut out = [[0.0; 3]; 3];
            for (r, row) in out.iter_mut().enumerate() {
                for (c, v) in row.iter_mut().enumerate() {
                    *v = a[(r, c)];
                }
            }
            out
        });
        Truth {
            schema: "ndfit.synth/1".into(),
            model: id.as_str().into(),
            params,
            matrix_a,
            generator: generator.into(),
            settings,
            derived,
            facets: None,
            input: None,
        }
    }

    /// The analytic model, for the contract models (not for `planes`).
    pub fn to_model(&self) -> Result<Model> {
        let id: ModelId = self.model.parse()?;
        let p = id
            .param_names()
            .iter()
            .map(|k| {
                self.params
                    .get(*k)
                    .and_then(|v| v.as_f64())
                    .ok_or_else(|| Error::invalid(format!("truth: parameter '{k}' missing or not a number")))
            })
            .collect::<Result<Vec<f64>>>()?;
        Model::from_params(id, &p)
    }

    /// Pretty JSON text.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a Truth holds only finite numbers and strings")
    }
}
