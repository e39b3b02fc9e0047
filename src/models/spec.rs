//! JSON <-> [`Model`]: the `model` / `params` / `matrix_a` keys of the fit result (`ndfit.fit/1`,
//! CONTRACT.md), read leniently so any JSON object with a model and its parameters works (a synth truth
//! file, a hand-written file, a fit result of another schema version).

use nalgebra::Matrix3;
use serde_json::{Map, Value};

use super::{Ellipsoid, Model, ModelId};
use crate::error::{Error, Result};

impl Model {
    /// Read a model from a JSON object with `model` (a contract id) and `params` (an object keyed by the
    /// names of [`ModelId::param_names`], or an array in that order). For `ellipsoid`, `matrix_a` (3x3,
    /// row-major) alone is accepted too; when both are present `params` wins. Unknown keys and the
    /// `schema` are ignored. When the top level lacks `model`, the first nested object that has both
    /// `model` and `params` (or `matrix_a`) is read (e.g. `{"truth": {...}}`).
    pub fn from_json(v: &Value) -> Result<Model> {
        let obj = v.as_object().ok_or_else(|| Error::invalid("expected a JSON object with 'model' and 'params'"))?;
        let obj = if obj.contains_key("model") {
            obj
        } else {
            obj.values()
                .filter_map(Value::as_object)
                .find(|o| o.contains_key("model") && (o.contains_key("params") || o.contains_key("matrix_a")))
                .ok_or_else(|| Error::invalid("no 'model' key in the JSON object"))?
        };
        let id_str = obj.get("model").and_then(Value::as_str).ok_or_else(|| Error::invalid("'model' must be a string (a model id)"))?;
        let id: ModelId = id_str.parse()?;
        match obj.get("params") {
            Some(p) => {
                let values = read_params(id, p)?;
                Model::from_params(id, &values)
            }
            None if id == ModelId::Ellipsoid && obj.contains_key("matrix_a") => {
                let a = read_matrix(&obj["matrix_a"])?;
                Ok(Model::Ellipsoid(Ellipsoid::from_matrix(a)?))
            }
            None => Err(Error::invalid(format!("model {id}: no 'params' key"))),
        }
    }

    /// The JSON fields `model`, `params` (object keyed by parameter name) and, for the ellipsoid special
    /// cases, `matrix_a` (row-major, `matrix_a[r][c]`), all of the CANONICAL form of the model
    /// ([`Model::canonical`]), as the contract asks every printed result to be.
    pub fn to_json_fields(&self) -> Map<String, Value> {
        let c = self.canonical();
        let mut out = Map::new();
        out.insert("model".into(), Value::from(c.id().as_str()));
        let params: Map<String, Value> =
            c.id().param_names().iter().zip(c.params()).map(|(n, v)| ((*n).to_string(), Value::from(v))).collect();
        out.insert("params".into(), Value::Object(params));
        if let Some(a) = c.matrix_a() {
            let rows: Vec<Value> = (0..3).map(|r| Value::from((0..3).map(|col| a[(r, col)]).collect::<Vec<f64>>())).collect();
            out.insert("matrix_a".into(), Value::Array(rows));
        }
        out
    }
}

fn number(v: &Value, what: &str) -> Result<f64> {
    v.as_f64().ok_or_else(|| Error::invalid(format!("{what} must be a number, got {v}")))
}

fn read_params(id: ModelId, p: &Value) -> Result<Vec<f64>> {
    let names = id.param_names();
    match p {
        Value::Object(o) => names
            .iter()
            .map(|n| {
                let v = o.get(*n).ok_or_else(|| Error::invalid(format!("model {id}: params.{n} is missing")))?;
                number(v, &format!("params.{n}"))
            })
            .collect(),
        Value::Array(a) if a.len() == names.len() => a.iter().zip(names).map(|(v, n)| number(v, &format!("params.{n}"))).collect(),
        _ => Err(Error::invalid(format!(
            "model {id}: 'params' must be an object with {} (or an array of {} numbers)",
            names.join(", "),
            names.len()
        ))),
    }
}

fn read_matrix(v: &Value) -> Result<Matrix3<f64>> {
    let bad = || Error::invalid("'matrix_a' must be a 3x3 array of numbers (row-major)");
    let rows = v.as_array().filter(|r| r.len() == 3).ok_or_else(bad)?;
    let mut a = Matrix3::zeros();
    for (r, row) in rows.iter().enumerate() {
        let cols = row.as_array().filter(|c| c.len() == 3).ok_or_else(bad)?;
        for (c, x) in cols.iter().enumerate() {
            a[(r, c)] = number(x, &format!("matrix_a[{r}][{c}]"))?;
        }
    }
    Ok(a)
}
