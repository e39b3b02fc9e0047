//! Comparing a run against a baseline (the `summary.json` of an earlier run).
//!
//! The rule (documented in `data_formats/batch.md`): a scan **regresses** when its new fit describes
//! its data worse than the baseline's fit did, beyond a tolerance. "Describes its data" is measured by
//! `kl` ([`super::quality()`]: the deviance per sample, the binned KL divergence of the model from the
//! empirical NDF), and both fits are scored on the **same bins**: the baseline's model and parameters
//! are re-evaluated against this run's empirical NDF of the scan. So the comparison is exact (no noise
//! from different binnings), works across models (a `ggx` fit against an `ellipsoid` baseline), and does
//! not trust either run's self-reported objective. When the baseline model cannot be re-evaluated, the
//! baseline's stored `kl` is used instead (`basis: "stored"`).
//!
//! `delta_kl = kl - kl_baseline`; tolerance `tol = max(kl_abs, kl_rel * kl_baseline)`; regressed when
//! `delta_kl > tol`, improved when `delta_kl < -tol`. A relative density error `eps` costs about
//! `eps^2 / 2` nats, so the default `kl_abs = 5e-5` is a 1% RMS change of D; `kl_rel = 0.05` keeps a
//! poor baseline (a real surface that no model fits closely) from flagging 5%-sized wobbles of its misfit.
//!
//! Parameters are compared too (same model only, canonical form): `z = |p - p_b| / sqrt(se^2 + se_b^2)`
//! with the fits' standard errors; a parameter **changed** when `z > param_sigma` (angles `theta_*`
//! wrapped to the nearest equivalent, period pi for `theta_z`). Without standard errors the fallback is
//! a relative change above `param_rel` for alphas and an absolute one above `angle_abs` radians.
//! Changes are reported; they count as regressions only with `params_regress`.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::entry::Status;
use super::quality::Quality;
use crate::error::{Error, Result};

/// Tolerances of the comparison (the CLI's `--tol-*` options).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Tolerances {
    /// Absolute tolerance on `kl` (nats). Default 5e-5: a 1% RMS change of D.
    pub kl_abs: f64,
    /// Tolerance on `kl` relative to the baseline's `kl`. Default 0.05.
    pub kl_rel: f64,
    /// A parameter changed when it moved by more than this many combined standard errors. Default 3.
    pub param_sigma: f64,
    /// Without standard errors: relative change of an alpha that counts. Default 1e-3.
    pub param_rel: f64,
    /// Without standard errors: absolute change of an angle (radians) that counts. Default 1e-3.
    pub angle_abs: f64,
    /// Count parameter changes as regressions (default false: they are reported only).
    pub params_regress: bool,
}

impl Default for Tolerances {
    fn default() -> Self {
        Tolerances { kl_abs: 5e-5, kl_rel: 0.05, param_sigma: 3.0, param_rel: 1e-3, angle_abs: 1e-3, params_regress: false }
    }
}

/// What the baseline knew about one scan: only the small part the comparison needs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct BaselineEntry {
    /// `ok` or `error` in the baseline.
    pub status: Status,
    /// The baseline fit's model id.
    pub model: Option<String>,
    /// The baseline fit's parameters by name.
    pub params: BTreeMap<String, f64>,
    /// Their standard errors by name, when the fit reported them.
    pub stderr: BTreeMap<String, f64>,
    /// The baseline's own scoring (used when its model cannot be re-evaluated).
    pub quality: Option<Quality>,
    /// The baseline fit's verdict was `unresolved`.
    pub unresolved: bool,
}

impl BaselineEntry {
    /// The part of a fit JSON the comparison needs.
    pub fn from_fit(status: Status, fit: Option<&Value>, quality: Option<Quality>) -> Self {
        let model = fit.and_then(|f| f.get("model")).and_then(Value::as_str).map(str::to_string);
        let params = fit.map(|f| numbers(f.get("params"))).unwrap_or_default();
        let stderr = fit.map(stderr_of).unwrap_or_default();
        let verdict = fit.and_then(|f| f.get("verdict").or_else(|| f.pointer("/quality/verdict"))).and_then(Value::as_str);
        BaselineEntry { status, model, params, stderr, quality, unresolved: verdict == Some("unresolved") }
    }

    /// A fit JSON with just `model` and `params`, for re-evaluating the baseline model.
    pub fn fit_json(&self) -> Option<Value> {
        let model = self.model.as_ref()?;
        Some(serde_json::json!({"model": model, "params": self.params}))
    }
}

/// Numbers of a JSON object by key (non-numbers skipped).
fn numbers(v: Option<&Value>) -> BTreeMap<String, f64> {
    v.and_then(Value::as_object).map(|o| o.iter().filter_map(|(k, v)| v.as_f64().map(|x| (k.clone(), x))).collect()).unwrap_or_default()
}

/// The standard errors a fit JSON reports, by parameter name: `std_errors` of `ndfit.fit/1` (an object
/// by name; `null` for an undetermined parameter, which is then left out), or `stderr`.
pub fn stderr_of(fit: &Value) -> BTreeMap<String, f64> {
    for path in [&["std_errors"][..], &["stderr"]] {
        let mut v = Some(fit);
        for k in path {
            v = v.and_then(|x| x.get(*k));
        }
        let m = numbers(v);
        if !m.is_empty() {
            return m;
        }
    }
    BTreeMap::new()
}

/// A baseline: entries by key.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Baseline {
    /// Entries by scan key.
    pub entries: BTreeMap<String, BaselineEntry>,
}

#[derive(Deserialize)]
struct RawSummary {
    entries: Vec<RawEntry>,
}

#[derive(Deserialize)]
struct RawEntry {
    path: String,
    status: Status,
    #[serde(default, deserialize_with = "lite_fit")]
    fit: Option<LiteFit>,
    #[serde(default)]
    quality: Option<Quality>,
}

struct LiteFit(Value);

/// Keep only `model`, `params` and the standard errors of each fit while parsing, so a baseline of many
/// scans costs a few numbers per scan in memory, not its whole fit reports.
fn lite_fit<'de, D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Option<LiteFit>, D::Error> {
    let v: Option<Value> = Option::deserialize(d)?;
    Ok(v.map(|f| {
        let stderr = stderr_of(&f);
        let verdict = f.pointer("/quality/verdict").cloned();
        LiteFit(serde_json::json!({"model": f.get("model"), "params": f.get("params"), "stderr": stderr, "verdict": verdict}))
    }))
}

impl Baseline {
    /// Read a baseline `summary.json`.
    pub fn read(path: &Path) -> Result<Baseline> {
        let f = std::fs::File::open(path).map_err(|e| Error::io(e).with_path(path))?;
        let raw: RawSummary = serde_json::from_reader(std::io::BufReader::new(f))
            .map_err(|e| Error::corrupt(format!("not a batch summary.json: {e}")).with_path(path))?;
        let mut entries = BTreeMap::new();
        for e in raw.entries {
            let fit = e.fit.map(|f| f.0);
            let be = BaselineEntry::from_fit(e.status, fit.as_ref(), e.quality);
            if entries.insert(e.path.clone(), be).is_some() {
                return Err(Error::corrupt(format!("scan '{}' appears twice", e.path)).with_path(path));
            }
        }
        Ok(Baseline { entries })
    }
}

/// Verdict of one scan against its baseline entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Within tolerance of the baseline.
    Same,
    /// Describes its data better than the baseline, beyond the tolerance.
    Improved,
    /// Describes its data worse than the baseline, beyond the tolerance.
    Regressed,
    /// Not in the baseline.
    New,
    /// Failed in the baseline, fitted now.
    Fixed,
    /// Fitted in the baseline, fails now (also an `error` entry: exit 2).
    Broken,
    /// Failed in both.
    StillError,
    /// The baseline entry has no usable quality to compare with.
    Unscored,
    /// The baseline's fit was `unresolved` (the scan cannot resolve its NDF): not a regression target.
    BaselineUnresolved,
}

/// How the baseline's quality was obtained.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Basis {
    /// The baseline model re-evaluated on this run's bins (exact comparison).
    SameBins,
    /// The baseline's stored quality (its own bins).
    Stored,
}

/// A parameter that moved beyond its tolerance.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ParamChange {
    /// Parameter name.
    pub name: String,
    /// Baseline value.
    pub baseline: f64,
    /// New value.
    pub value: f64,
    /// `value - baseline` (angles wrapped to the nearest equivalent).
    pub diff: f64,
    /// Combined standard error `sqrt(se^2 + se_b^2)`, when both fits reported one.
    pub sigma: Option<f64>,
    /// `|diff| / sigma`.
    pub z: Option<f64>,
}

/// The comparison of one scan with its baseline entry (stored in its `summary.json` entry).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Comparison {
    /// The verdict.
    pub verdict: Verdict,
    /// Whether this entry counts as a regression for the exit status.
    pub regressed: bool,
    /// The baseline's model id.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub baseline_model: Option<String>,
    /// How `kl_baseline` was obtained.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub basis: Option<Basis>,
    /// The baseline fit's `kl`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kl_baseline: Option<f64>,
    /// This fit's `kl`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub kl: Option<f64>,
    /// `kl - kl_baseline`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delta_kl: Option<f64>,
    /// The tolerance `delta_kl` was held to.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tolerance: Option<f64>,
    /// Parameters beyond their tolerance (same model only).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub param_changes: Vec<ParamChange>,
}

/// The current run's side of a comparison.
#[derive(Debug, Clone, Copy)]
pub struct Current<'a> {
    /// Whether the scan was fitted.
    pub status: Status,
    /// The fit JSON.
    pub fit: Option<&'a Value>,
    /// This fit's quality.
    pub quality: Option<Quality>,
    /// The baseline model's quality on this run's bins, when it could be evaluated.
    pub baseline_on_same_bins: Option<Quality>,
}

/// Compare a scan's result with its baseline entry (`None`: not in the baseline).
pub fn compare(cur: Current<'_>, base: Option<&BaselineEntry>, tol: &Tolerances) -> Comparison {
    let mut c = Comparison {
        verdict: Verdict::New,
        regressed: false,
        baseline_model: base.and_then(|b| b.model.clone()),
        basis: None,
        kl_baseline: None,
        kl: cur.quality.map(|q| q.kl),
        delta_kl: None,
        tolerance: None,
        param_changes: Vec::new(),
    };
    let Some(base) = base else { return c };
    c.verdict = match (base.status, cur.status) {
        (Status::Error, Status::Error) => Verdict::StillError,
        (Status::Error, Status::Ok) => Verdict::Fixed,
        (Status::Ok, Status::Error) => Verdict::Broken,
        (Status::Ok, Status::Ok) => Verdict::Unscored,
    };
    if c.verdict != Verdict::Unscored {
        return c;
    }
    if base.unresolved {
        c.verdict = Verdict::BaselineUnresolved;
        return c;
    }
    let (kl_b, basis) = match (cur.baseline_on_same_bins, base.quality) {
        (Some(q), _) => (Some(q.kl), Some(Basis::SameBins)),
        (None, Some(q)) => (Some(q.kl), Some(Basis::Stored)),
        (None, None) => (None, None),
    };
    c.basis = basis;
    c.kl_baseline = kl_b;
    if let (Some(kl), Some(kl_b)) = (c.kl, kl_b) {
        let t = tol.kl_abs.max(tol.kl_rel * kl_b);
        let d = kl - kl_b;
        c.delta_kl = Some(d);
        c.tolerance = Some(t);
        // NaN compares false both ways, so a NaN quality is "same"; quality() never returns NaN.
        c.verdict = if d > t {
            Verdict::Regressed
        } else if d < -t {
            Verdict::Improved
        } else {
            Verdict::Same
        };
    }
    if let Some(fit) = cur.fit {
        if fit.get("model").and_then(Value::as_str) == base.model.as_deref() {
            c.param_changes = param_changes(fit, base, tol);
        }
    }
    c.regressed = c.verdict == Verdict::Regressed || (tol.params_regress && !c.param_changes.is_empty());
    c
}

/// The parameters of `fit` that moved beyond their tolerance from `base` (same model).
fn param_changes(fit: &Value, base: &BaselineEntry, tol: &Tolerances) -> Vec<ParamChange> {
    let params = numbers(fit.get("params"));
    let se = stderr_of(fit);
    let mut out = Vec::new();
    for (name, &v) in &params {
        let Some(&b) = base.params.get(name) else { continue };
        let is_angle = name.starts_with("theta");
        let mut diff = v - b;
        if name == "theta_z" {
            // theta_z and theta_z + pi are the same ellipsoid (A = S R, eq. 2-3, is even in the axes).
            diff -= std::f64::consts::PI * (diff / std::f64::consts::PI).round();
        }
        let sigma = match (se.get(name), base.stderr.get(name)) {
            (Some(&s), Some(&sb)) if s.is_finite() && sb.is_finite() && (s > 0.0 || sb > 0.0) => Some(s.hypot(sb)),
            _ => None,
        };
        let z = sigma.map(|s| diff.abs() / s);
        let changed = match z {
            Some(z) => z > tol.param_sigma,
            None if is_angle => diff.abs() > tol.angle_abs,
            None => diff.abs() > tol.param_rel * b.abs(),
        };
        if changed {
            out.push(ParamChange { name: name.clone(), baseline: b, value: v, diff, sigma, z });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn q(kl: f64) -> Quality {
        Quality { deviance: 0.0, kl, ndf_delta: 0.0, n_samples: 1, n_bins: 1 }
    }

    fn base(kl: f64, fit: Value) -> BaselineEntry {
        BaselineEntry::from_fit(Status::Ok, Some(&fit), Some(q(kl)))
    }

    fn cur<'a>(fit: &'a Value, kl: f64, kl_b_same: Option<f64>) -> Current<'a> {
        Current { status: Status::Ok, fit: Some(fit), quality: Some(q(kl)), baseline_on_same_bins: kl_b_same.map(q) }
    }

    #[test]
    fn verdict_follows_the_tolerance_rule() {
        let t = Tolerances::default();
        let f = json!({"model": "ggx", "params": {"alpha": 0.1}});
        let b = base(0.010, f.clone());
        // tol = max(5e-5, 0.05 * 0.010) = 5e-4 on the same-bins baseline 0.010.
        let c = compare(cur(&f, 0.0104, Some(0.010)), Some(&b), &t);
        assert_eq!((c.verdict, c.regressed, c.basis), (Verdict::Same, false, Some(Basis::SameBins)));
        assert!((c.tolerance.unwrap() - 5e-4).abs() < 1e-15);
        let c = compare(cur(&f, 0.0106, Some(0.010)), Some(&b), &t);
        assert_eq!((c.verdict, c.regressed), (Verdict::Regressed, true));
        let c = compare(cur(&f, 0.0094, Some(0.010)), Some(&b), &t);
        assert_eq!(c.verdict, Verdict::Improved);
        // Small baseline: the absolute floor 5e-5 governs.
        let c = compare(cur(&f, 1e-5 + 6e-5, Some(1e-5)), Some(&b), &t);
        assert_eq!(c.verdict, Verdict::Regressed);
        // Without a same-bins score the stored one is used.
        let c = compare(cur(&f, 0.0104, None), Some(&b), &t);
        assert_eq!((c.verdict, c.basis), (Verdict::Same, Some(Basis::Stored)));
    }

    #[test]
    fn status_changes_and_new_scans() {
        let t = Tolerances::default();
        let f = json!({"model": "ggx", "params": {"alpha": 0.1}});
        assert_eq!(compare(cur(&f, 0.0, None), None, &t).verdict, Verdict::New);
        let be = BaselineEntry::from_fit(Status::Error, None, None);
        assert_eq!(compare(cur(&f, 0.0, None), Some(&be), &t).verdict, Verdict::Fixed);
        let err = Current { status: Status::Error, fit: None, quality: None, baseline_on_same_bins: None };
        assert_eq!(compare(err, Some(&base(0.1, f.clone())), &t).verdict, Verdict::Broken);
        assert_eq!(compare(err, Some(&be), &t).verdict, Verdict::StillError);
        // No quality on either side: unscored, not a regression.
        let bq = BaselineEntry::from_fit(Status::Ok, Some(&f), None);
        let c = compare(Current { quality: None, ..cur(&f, 0.0, None) }, Some(&bq), &t);
        assert_eq!((c.verdict, c.regressed), (Verdict::Unscored, false));
    }

    #[test]
    fn parameters_compare_in_standard_errors_with_wrapped_theta_z() {
        let mut t = Tolerances::default();
        let pi = std::f64::consts::PI;
        let b = base(
            0.01,
            json!({"model": "ggx-aniso", "params": {"alpha_x": 0.2, "alpha_y": 0.1, "theta_z": pi / 2.0 - 0.01},
                   "stderr": {"alpha_x": 0.001, "alpha_y": 0.001, "theta_z": 0.01}}),
        );
        // theta_z moved across the fold: -pi/2 + 0.01 is 0.02 rad away, z = 0.02/sqrt(2e-4) = 1.41 < 3.
        // alpha_x moved 0.005 = 3.54 sigma: changed. alpha_y moved 0.004 = 2.83 sigma: not.
        let f = json!({"model": "ggx-aniso", "params": {"alpha_x": 0.205, "alpha_y": 0.104, "theta_z": -pi / 2.0 + 0.01},
                       "stderr": {"alpha_x": 0.001, "alpha_y": 0.001, "theta_z": 0.01}});
        let c = compare(cur(&f, 0.01, Some(0.01)), Some(&b), &t);
        assert_eq!(c.param_changes.len(), 1, "{:?}", c.param_changes);
        let pc = &c.param_changes[0];
        assert_eq!(pc.name, "alpha_x");
        assert!((pc.z.unwrap() - 0.005 / 2f64.sqrt() / 0.001).abs() < 1e-9);
        assert!(!c.regressed);
        t.params_regress = true;
        assert!(compare(cur(&f, 0.01, Some(0.01)), Some(&b), &t).regressed);
        // Without standard errors: relative 1e-3 on alphas, 1e-3 rad on angles.
        let b2 = base(0.01, json!({"model": "ggx", "params": {"alpha": 0.1}}));
        let f2 = json!({"model": "ggx", "params": {"alpha": 0.10011}});
        assert_eq!(compare(cur(&f2, 0.01, None), Some(&b2), &Tolerances::default()).param_changes.len(), 1);
        let f3 = json!({"model": "ggx", "params": {"alpha": 0.10009}});
        assert!(compare(cur(&f3, 0.01, None), Some(&b2), &Tolerances::default()).param_changes.is_empty());
        // Different models: parameters are not compared.
        let f4 = json!({"model": "beckmann", "params": {"alpha": 0.5}});
        assert!(compare(cur(&f4, 0.01, None), Some(&b2), &Tolerances::default()).param_changes.is_empty());
    }

    #[test]
    fn baseline_reads_only_what_it_needs_and_rejects_junk() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("summary.json");
        let s = json!({"schema": "ndfit.batch/1", "entries": [
            {"path": "a.x3p", "status": "ok", "fit": {"model": "ggx", "params": {"alpha": 0.3}, "stderr": {"alpha": 0.01}, "big": [1, 2, 3]},
             "quality": {"deviance": 1.0, "kl": 0.5, "ndf_delta": 0.1, "n_samples": 1, "n_bins": 1}},
            {"path": "b.x3p", "status": "error", "error": "bad"}]});
        std::fs::write(&p, s.to_string()).unwrap();
        let b = Baseline::read(&p).unwrap();
        assert_eq!(b.entries.len(), 2);
        let a = &b.entries["a.x3p"];
        assert_eq!(a.model.as_deref(), Some("ggx"));
        assert_eq!(a.params["alpha"], 0.3);
        assert_eq!(a.stderr["alpha"], 0.01);
        assert_eq!(a.quality.unwrap().kl, 0.5);
        assert_eq!(b.entries["b.x3p"].status, Status::Error);
        std::fs::write(&p, "[1,2]").unwrap();
        let e = Baseline::read(&p).unwrap_err();
        assert!(e.to_string().contains("summary.json") && e.to_string().contains("not a batch summary"), "{e}");
    }
}
