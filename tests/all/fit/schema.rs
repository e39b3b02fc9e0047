//! Every fit result validates against `data_formats/fit.schema.json` (and the schema rejects what the
//! contract forbids).

use serde_json::Value;

/// The compiled schema.
pub fn validator() -> jsonschema::Validator {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/data_formats/fit.schema.json");
    let text = std::fs::read_to_string(path).expect("schema file is in the repo");
    let schema: Value = serde_json::from_str(&text).expect("schema is JSON");
    jsonschema::validator_for(&schema).expect("schema compiles")
}

/// Assert `v` validates, listing every violation otherwise.
pub fn assert_valid(v: &Value) {
    let val = validator();
    let errs: Vec<String> = val.iter_errors(v).map(|e| format!("{} at {}", e, e.instance_path())).collect();
    assert!(errs.is_empty(), "schema violations: {errs:?}\n{v:#}");
}

#[test]
fn library_reports_of_every_model_validate() {
    use ndfit::fit::{fit_auto, fit_model, FitOptions};
    use ndfit::models::ModelId;
    use ndfit::scan::InputInfo;
    let truth = super::fixtures::model(ModelId::Ellipsoid, &[0.3, 0.1, 0.1, -0.1, 0.4]);
    let ndf = ndfit::fit::binned_ndf(&truth, &ndfit::fit::Grid::for_model(&truth, 63), 2e5, 9);
    let input = InputInfo {
        path: "x.x3p".into(),
        format: "x3p".into(),
        nx: 10,
        ny: 10,
        dx: 1e-6,
        dy: 1e-6,
        invalid: 0,
        file_invalid: 0,
        spikes: 0,
        file_grid: None,
        despike: None,
    };
    let mut reports: Vec<_> = ModelId::singles().map(|id| fit_model(&ndf, id, &FitOptions::default()).expect("fit")).collect();
    reports.push(fit_auto(&ndf, &FitOptions::default()).expect("auto"));
    for mut r in reports {
        r.input = Some(input.clone());
        let v = serde_json::to_value(&r).expect("serializes");
        assert_valid(&v);
        // Round trip through the serde types.
        let back: ndfit::fit::FitReport = serde_json::from_value(v).expect("deserializes");
        assert_eq!(back.model, r.model);
    }
}

#[test]
fn schema_rejects_contract_violations() {
    let val = validator();
    let good: Value = serde_json::json!({
        "schema": "ndfit.fit/1", "model": "ellipsoid",
        "params": {"alpha_x": 0.21, "alpha_y": 0.13, "theta_x": 0.02, "theta_y": -0.01, "theta_z": 0.6},
        "matrix_a": [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
        "input": {"path": "scan.x3p", "format": "x3p", "nx": 1024, "ny": 1024, "dx": 1e-7, "dy": 1e-7}
    });
    assert!(val.is_valid(&good), "the contract's own example must validate");
    let mut no_input = good.clone();
    no_input.as_object_mut().unwrap().remove("input");
    assert!(!val.is_valid(&no_input));
    let mut missing_param = good.clone();
    missing_param["params"].as_object_mut().unwrap().remove("theta_y");
    assert!(!val.is_valid(&missing_param));
    let mut no_a = good.clone();
    no_a.as_object_mut().unwrap().remove("matrix_a");
    assert!(!val.is_valid(&no_a));
    let mut beck = no_a.clone();
    beck["model"] = "beckmann".into();
    beck["params"] = serde_json::json!({"alpha": 0.2});
    assert!(val.is_valid(&beck), "a Beckmann fit may omit matrix_a");
    let mut neg = beck.clone();
    neg["params"]["alpha"] = (-0.1).into();
    assert!(!val.is_valid(&neg));
}
