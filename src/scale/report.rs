//! `ndfit scale` output: JSON (`ndfit.scale/1`), CSV and the numbers the plot draws
//! (data_formats/scale.md sec. 10).

use std::io::Write;

use nalgebra::Matrix2;
use serde_json::{json, Value};

use super::analyze::{model_skew, FootprintResult, Recommendation, RouteResult};
use crate::error::{Error, Result};
use crate::models::Model;

fn mat2(m: &Matrix2<f64>) -> Value {
    json!([[m[(0, 0)], m[(0, 1)]], [m[(1, 0)], m[(1, 1)]]])
}

/// A finite number or JSON null (NaN and infinities are not JSON).
fn num(v: f64) -> Value {
    if v.is_finite() {
        json!(v)
    } else {
        Value::Null
    }
}

/// `{"model": id, "params": {...}, "matrix_a": [...]}` of a model.
pub fn model_json(m: &Model) -> Value {
    let id = m.id();
    let params: serde_json::Map<String, Value> = id.param_names().iter().zip(m.params()).map(|(k, v)| (k.to_string(), num(v))).collect();
    let mut o = json!({"model": id.as_str(), "params": params, "skew_offset": num(model_skew(m))});
    if let Some(a) = m.matrix_a() {
        o["matrix_a"] = json!((0..3).map(|r| (0..3).map(|c| a[(r, c)]).collect::<Vec<_>>()).collect::<Vec<_>>());
    }
    o
}

fn route_json(r: &RouteResult) -> Value {
    let mut o = match &r.model {
        Some(m) => model_json(m),
        None => json!({}),
    };
    o["source"] = json!(r.source);
    if let Some(d) = r.delta {
        o["delta"] = num(d.delta);
        o["delta_noise"] = num(d.noise);
        o["delta_model"] = num(d.excess);
    }
    if let Some(ic) = r.ic {
        o["ic"] = num(ic);
    }
    if let Some(e) = &r.error {
        o["error"] = json!(e);
    }
    o
}

/// One footprint's JSON object.
pub fn footprint_json(r: &FootprintResult) -> Value {
    let s = &r.stats;
    let models: Vec<Value> = r
        .models
        .iter()
        .map(|m| {
            let mut o = json!({
                "model": m.id.as_str(),
                "empirical": route_json(&m.empirical),
                "analytic": route_json(&m.analytic),
            });
            if let Some(g) = m.route_gap {
                o["route_gap"] = num(g);
            }
            o["analytic_trusted"] = json!(m.analytic_trusted());
            o["analytic_caveats"] = json!(m.analytic_caveats);
            if let Some((e10, e13)) = m.tokuyoshi_iso {
                o["tokuyoshi_eq10_alpha"] = num(e10);
                o["tokuyoshi_eq13_alpha"] = num(e13);
            }
            o
        })
        .collect();
    let mom = |m: &super::ndf_at::SlopeMoments| json!({"n": m.n, "mean": [m.mean[0], m.mean[1]], "cov": mat2(&m.cov), "skewness": num(m.skewness), "kurtosis": num(m.kurtosis)});
    json!({
        "footprint_m": s.footprint,
        "kernel_sigma_m": s.sigma_k,
        "n_points": s.n_points,
        "sigma_f": mat2(&s.sigma_f),
        "cov_resolved": mat2(&s.cov_resolved),
        "cov_slopes": mat2(&s.cov_slopes),
        "pixel_roughness": r.pixel_roughness.map(|(ax, ay, tz)| json!({"matrix": mat2(&(2.0 * s.sigma_f)), "alpha_x": ax, "alpha_y": ay, "theta_z": tz})),
        "moments_at_footprint": mom(&r.at_f),
        "moments_resolved": mom(&r.resolved),
        "sigma_w_spread": num(r.sigma_w_spread),
        "theory_notes": r.theory_notes,
        "n_independent": num(r.n_independent),
        "ggx_kernel": r.ggx_kernel.map(|k| json!({"matrix": mat2(&k.matrix), "kappa": num(k.ratio)})),
        "analytic_summary": r.analytic_summary,
        "models": models,
    })
}

/// The whole report. `input` is the scan description (path, format, grid), `options` the settings used.
pub fn report_json(input: Value, options: Value, results: &[FootprintResult], rec: Option<&Recommendation>) -> Value {
    json!({
        "schema": "ndfit.scale/1",
        "definition": "NDF as seen at footprint F: the slopes of the low-passed surface h_F = K_F * h, each blurred by a Gaussian of its footprint's within-footprint slope covariance (data_formats/scale.md eq. S1). Empirical route: that distribution sampled, binned and fitted. Analytic route: the model fitted to h_F's NDF plus the kernel in its roughness matrix: twice the mean within-footprint covariance Sigma_F for Beckmann (Tokuyoshi eq. 3), the GGX fitted to that Gaussian kernel for GGX-shaped models (GGX's roughness is no variance). Kernel: Gaussian with sigma = F/2 (Tokuyoshi eq. 2). The routes agree exactly only for Beckmann on Gaussian statistics with one kernel covariance; for GGX and the ellipsoid the sum is an approximation (Tokuyoshi sec. 2); skewed or heavy-tailed slopes and strongly varying within-footprint covariances break the theory. Per model and footprint, analytic_trusted and analytic_caveats say whether the analytic route can be trusted and why not; route_gap says how far the routes lie apart.",
        "input": input,
        "options": options,
        "footprints": results.iter().map(footprint_json).collect::<Vec<_>>(),
        "recommendation": rec.map(|r| serde_json::to_value(r).unwrap_or(Value::Null)),
    })
}

/// CSV header of [`write_csv`].
pub const CSV_HEADER: &str =
    "footprint_m,model,route,source,alpha_x,alpha_y,theta_x,theta_y,theta_z,skew_offset,delta,delta_noise,delta_model,ic";

/// One row per footprint, model and route. Parameters a model lacks are empty (isotropic: `alpha_x =
/// alpha_y = alpha`; aniso: no `theta_x`, `theta_y`).
pub fn write_csv(w: &mut dyn Write, results: &[FootprintResult]) -> Result<()> {
    let mut out = String::new();
    out.push_str(CSV_HEADER);
    out.push('\n');
    let f = |v: Option<f64>| v.filter(|x| x.is_finite()).map(|x| format!("{x:.10e}")).unwrap_or_default();
    for r in results {
        for m in &r.models {
            for (route, rr) in [("empirical", &m.empirical), ("analytic", &m.analytic)] {
                let p = rr.model.map(|m| m.params()).unwrap_or_default();
                let (ax, ay, tx, ty, tz) = match p.len() {
                    1 => (Some(p[0]), Some(p[0]), None, None, None),
                    3 => (Some(p[0]), Some(p[1]), None, None, Some(p[2])),
                    5 => (Some(p[0]), Some(p[1]), Some(p[2]), Some(p[3]), Some(p[4])),
                    _ => (None, None, None, None, None),
                };
                out.push_str(&format!(
                    "{:.10e},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
                    r.stats.footprint,
                    m.id,
                    route,
                    rr.source,
                    f(ax),
                    f(ay),
                    f(tx),
                    f(ty),
                    f(tz),
                    f(rr.model.map(|m| model_skew(&m))),
                    f(rr.delta.map(|d| d.delta)),
                    f(rr.delta.map(|d| d.noise)),
                    f(rr.delta.map(|d| d.excess)),
                    f(rr.ic),
                ));
            }
        }
    }
    w.write_all(out.as_bytes()).map_err(Error::io)
}
