//! The model table is the one declaration of every model: the names other parts of the project spell by
//! hand (the Python stubs, the independent nlopt twin in `fits/`) must agree with it, parameter for parameter.

use std::collections::BTreeMap;
use std::path::Path;

use ndfit::models::{Model, ModelId};

/// `"name": ("p1", "p2", ...)` entries of a Python dict literal, in file order.
fn python_param_names(src: &str) -> BTreeMap<String, Vec<String>> {
    let mut out = BTreeMap::new();
    for line in src.lines().map(str::trim) {
        let Some(rest) = line.strip_prefix('"') else { continue };
        let Some((name, tail)) = rest.split_once("\": (") else { continue };
        let Some(list) = tail.strip_suffix("),") else { continue };
        let params: Vec<String> = list.split(',').map(|p| p.trim().trim_matches('"').to_string()).filter(|p| !p.is_empty()).collect();
        out.insert(name.to_string(), params);
    }
    out
}

fn read(rel: &str) -> String {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join(rel);
    std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Every model of the table has its nlopt twin in `fits/ndfitpy` with the same parameters in the same
/// order, and the twin knows no model the table lacks.
#[test]
fn the_nlopt_twin_has_every_model_with_its_parameters() {
    let mut twin = python_param_names(&read("fits/ndfitpy/models.py"));
    twin.extend(python_param_names(&read("fits/ndfitpy/mixtures.py")));
    for id in ModelId::EVERY {
        let want: Vec<String> = id.param_names().iter().map(|s| s.to_string()).collect();
        assert_eq!(twin.get(id.as_str()), Some(&want), "fits/ndfitpy: {id}");
    }
    for name in twin.keys() {
        assert!(name.parse::<ModelId>().is_ok(), "fits/ndfitpy knows {name}, the table does not");
    }
}

/// The Python stubs' `_Model` literal is `auto` and the table's names, in the table's order.
#[test]
fn the_python_stubs_list_the_table() {
    let pyi = read("python/ndfit/_ndfit.pyi");
    let line = pyi.lines().find(|l| l.starts_with("_Model = Literal[")).expect("_Model in the stubs");
    let inner = line.trim_start_matches("_Model = Literal[").trim_end_matches(']');
    let got: Vec<&str> = inner.split(',').map(|s| s.trim().trim_matches('"')).collect();
    let want: Vec<&str> = std::iter::once("auto").chain(ModelId::EVERY.iter().map(|id| id.as_str())).collect();
    assert_eq!(got, want);
}

/// Names and aliases parse to their model, and a model rebuilt from its own parameters is itself.
/// `fit_many`'s DataFrame has a column for every parameter name of the table (a model fills its own).
#[test]
fn the_dask_frame_has_a_column_for_every_parameter() {
    let src = read("python/ndfit/dask.py");
    let line = src.lines().find(|l| l.starts_with("PARAM_COLUMNS = [")).expect("PARAM_COLUMNS in dask.py");
    let columns: Vec<&str> = line.split('"').skip(1).step_by(2).collect();
    for id in ModelId::EVERY {
        for name in id.param_names() {
            assert!(columns.contains(name), "{id}: parameter {name} has no column in python/ndfit/dask.py PARAM_COLUMNS {columns:?}");
        }
    }
}

#[test]
fn names_parse_and_parameters_round_trip() {
    for id in ModelId::EVERY {
        assert_eq!(id.as_str().parse::<ModelId>().unwrap(), *id);
        for alias in id.spec().aliases {
            assert_eq!(alias.parse::<ModelId>().unwrap(), *id, "alias {alias}");
        }
        assert_eq!(serde_json::to_value(id).unwrap(), serde_json::Value::from(id.as_str()));
        let back: ModelId = serde_json::from_value(serde_json::Value::from(id.as_str())).unwrap();
        assert_eq!(back, *id);
    }
    let e = "nope".parse::<ModelId>().unwrap_err().to_string();
    for id in ModelId::EVERY {
        assert!(e.contains(id.as_str()), "{e}");
    }
    // A valid parameter vector of each model, from the table's roles.
    for id in ModelId::EVERY {
        let p: Vec<f64> = id
            .spec()
            .roles
            .iter()
            .enumerate()
            .map(|(i, (r, _))| match r {
                ndfit::models::Role::Weight => 0.3,
                ndfit::models::Role::Gamma => 3.5,
                r if r.is_alpha() => 0.1 + 0.05 * i as f64,
                _ => 0.1,
            })
            .collect();
        let m = Model::from_params(*id, &p).unwrap_or_else(|e| panic!("{id}: {e}"));
        assert_eq!(m.id(), *id);
        assert_eq!(m.params(), p, "{id}");
    }
}
