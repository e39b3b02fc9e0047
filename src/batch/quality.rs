//! How well a fitted model describes a scan's data, on a scale comparable across models and runs.
//!
//! Every measure here is computed by the batch itself from the empirical NDF and the fitted model's
//! `D(m)` (the fitter's self-reported objective is not trusted for the regression decision), following
//! `data_formats/objective.md`:
//! - `deviance`: the Poisson deviance `F = sum_k 2 (E_k - c_k + c_k ln(c_k/E_k))` over the fit region `R`
//!   (bins with `W_k > 0` within the fit's `max_theta` of n) with expected counts
//!   `E_k = N_in D(m_k) W_k / S`, `S = sum_{j in R} D(m_j) W_j` (midpoint rule, conditional on `R`);
//! - `kl = F / (2 N_in)`: the deviance per sample. With `sum E_k = N_in` it is exactly the binned Kullback-Leibler
//!   divergence `sum p_k ln(p_k / q_k)` of the model's bin probabilities `q_k` from the data's `p_k`, in
//!   nats: a quantity that does not grow with the scan size, so one tolerance serves every scan. A
//!   relative density error `eps(m)` small everywhere costs `kl ~ E[eps^2]/2`.
//! - `ndf_delta`: the NDF difference metric `delta(D_fit; D_emp)` of objective.md (reference: the
//!   empirical NDF, weights `d_k W_k` over bins with data), the RMS relative error of the fitted D.

use serde_json::Value;

use crate::error::{Error, Result};
use crate::models::{Model, ModelId, Ndf};
use crate::ndf::EmpiricalNdf;

/// Goodness of a model against one empirical NDF.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Quality {
    /// Poisson deviance `F` over all bins with `W_k > 0`.
    pub deviance: f64,
    /// `F / (2N)`: binned KL divergence of the model from the data (nats), the regression measure.
    pub kl: f64,
    /// NDF difference metric `delta(D_fit; D_emp)` (objective.md), dimensionless.
    pub ndf_delta: f64,
    /// Number of samples `N` in the NDF.
    pub n_samples: u64,
    /// Number of bins with data (`c_k > 0`), `K` of objective.md.
    pub n_bins: usize,
}

/// Score `model` against `ndf` on the fit region of polar angles up to `max_theta` (radians; `pi/2`: the
/// hemisphere). Errors only when the region holds no samples.
pub fn quality(ndf: &EmpiricalNdf, model: &dyn Ndf, max_theta: f64) -> Result<Quality> {
    quality_in(ndf, model, max_theta, "none")
}

/// [`quality`] on the region the fit's tail rule (`quality.tail.rule` of its JSON) left: `core` keeps the
/// bins whose centre lies within [`crate::fit::tail::CORE_RADIUS`] of the whitened Lambert disk,
/// `unresolved` drops the bins where most normals are unresolved (objective.md); any other rule keeps
/// every bin.
pub fn quality_in(ndf: &EmpiricalNdf, model: &dyn Ndf, max_theta: f64, tail_rule: &str) -> Result<Quality> {
    let cos_max = max_theta.min(std::f64::consts::FRAC_PI_2).cos();
    let kept = |k: usize, b: &crate::ndf::NdfBin| match tail_rule {
        "core" => !crate::fit::tail::outside_core(ndf, k),
        "unresolved" => ndf.unresolved.get(k).is_none_or(|&u| 2 * u <= b.count),
        _ => true,
    };
    // Bins without projected area carry no data and no model mass (objective.md).
    let region: Vec<&crate::ndf::NdfBin> = ndf
        .bins
        .iter()
        .enumerate()
        .filter(|&(k, b)| b.proj_solid_angle > 0.0 && b.m.z >= cos_max * b.m.norm() && kept(k, b))
        .map(|(_, b)| b)
        .collect();
    let n: u64 = region.iter().map(|b| b.count).sum();
    if n == 0 {
        return Err(Error::new(crate::ErrorKind::BadData, "the empirical NDF holds no samples in the fit region"));
    }
    let nf = n as f64;
    // A model that is NaN or negative somewhere is as wrong as a zero there.
    let dm = |m| {
        let d = model.d(m);
        if d.is_finite() && d > 0.0 {
            d
        } else {
            0.0
        }
    };
    let s_norm: f64 = region.iter().map(|b| dm(b.m) * b.proj_solid_angle).sum();
    let (mut dev, mut n_bins) = (0.0f64, 0usize);
    let (mut dw, mut dsum) = (0.0f64, 0.0f64);
    for b in region {
        let d = dm(b.m);
        // Zero mass under data gives an infinite deviance, which the floor keeps finite but enormous
        // (and comparable); with S = 0 every E is at that floor.
        let e = if s_norm > 0.0 { nf * d * b.proj_solid_angle / s_norm } else { 0.0 }.max(f64::MIN_POSITIVE);
        let c = b.count as f64;
        dev += if b.count == 0 { 2.0 * e } else { 2.0 * (e - c + c * (c.ln() - e.ln())) };
        if b.count > 0 {
            n_bins += 1;
            let d_emp = c / (nf * b.proj_solid_angle);
            let w = d_emp * b.proj_solid_angle;
            dw += w * (d / d_emp - 1.0).powi(2);
            dsum += w;
        }
    }
    // Rounding can leave a deviance of a perfect model a few ulps below zero.
    let dev = dev.max(0.0);
    Ok(Quality { deviance: dev, kl: dev / (2.0 * nf), ndf_delta: (dw / dsum).sqrt(), n_samples: n, n_bins })
}

/// The tail rule a fit JSON's region was cut by (`quality.tail.rule`; `none` when absent).
pub fn tail_rule_of_fit(fit: &Value) -> &str {
    fit.pointer("/quality/tail/rule").and_then(Value::as_str).unwrap_or("none")
}

/// The fit region a fit JSON was fitted on: `quality.max_theta_deg` in radians (the hemisphere for a fit
/// written before the key existed).
pub fn max_theta_of_fit(fit: &Value) -> f64 {
    fit.pointer("/quality/max_theta_deg").and_then(Value::as_f64).unwrap_or(90.0).to_radians()
}

/// The model a fit JSON (`ndfit.fit/1`) describes: its `model` id and its `params` by name.
pub fn model_of_fit(fit: &Value) -> Result<Model> {
    let id_str = fit.get("model").and_then(Value::as_str).ok_or_else(|| Error::corrupt("fit has no 'model'"))?;
    let id: ModelId = id_str.parse()?;
    let params = fit.get("params").ok_or_else(|| Error::corrupt("fit has no 'params'"))?;
    let p = id
        .param_names()
        .iter()
        .map(|name| {
            params
                .get(*name)
                .and_then(Value::as_f64)
                .ok_or_else(|| Error::corrupt(format!("fit of model {id} has no number 'params.{name}'")))
        })
        .collect::<Result<Vec<f64>>>()?;
    Model::from_params(id, &p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::Ggx;
    use crate::ndf::NdfBin;
    use nalgebra::Vector3;
    use std::f64::consts::PI;

    fn bin(count: u64, w: f64) -> NdfBin {
        NdfBin { m: Vector3::new(0.0, 0.0, 1.0), d: 0.0, stderr: 0.0, count, solid_angle: w, proj_solid_angle: w }
    }

    /// GGX with alpha = 1 is the uniform distribution `D = 1/pi` over the hemisphere (every unit m gives
    /// `x^2 + y^2 + z^2 = 1`), so the expected counts are `N W / pi`, set here by choosing W.
    #[test]
    fn deviance_and_kl_match_hand_computation() {
        let g = Ggx::new(1.0, 1.0, 0.0).unwrap();
        // N = 15; E = (8, 2, 5) from W = E pi / N; c = (10, 0, 5); plus a bin with W = 0 (ignored).
        let w = |e: f64| e * PI / 15.0;
        let ndf = EmpiricalNdf::from_bins(vec![bin(10, w(8.0)), bin(0, w(2.0)), bin(5, w(5.0)), bin(0, 0.0)], 15);
        let q = quality(&ndf, &g, PI / 2.0).unwrap();
        // Hand (S = sum D W = 15/15 = 1, so E = N D W): F = 2[(8 - 10 + 10 ln(10/8)) + 2 + 0] = 2[0.23143551314209755 + 2].
        let f = 2.0 * ((8.0 - 10.0 + 10.0 * (1.25f64).ln()) + 2.0);
        assert!((q.deviance - f).abs() < 1e-12 * f, "{} vs {f}", q.deviance);
        assert!((q.kl - f / 30.0).abs() < 1e-14);
        // KL of p = (10,0,5)/15 from q = (8,2,5)/15: (10/15) ln(10/8) = 0.1487...; equal to F/2N since sum E = N.
        let kl_direct = (10.0 / 15.0) * (10.0f64 / 8.0).ln();
        assert!((q.kl - kl_direct).abs() < 1e-12, "{} vs {kl_direct}", q.kl);
        assert_eq!(q.n_bins, 2);
        assert_eq!(q.n_samples, 15);
        // delta: weights d_k W_k = c_k/N: (10/15)(8/10 - 1)^2 + (5/15)(0)^2 over 1 => sqrt(0.04 * 2/3).
        assert!((q.ndf_delta - (0.04f64 * 2.0 / 3.0).sqrt()).abs() < 1e-12, "{}", q.ndf_delta);
    }

    #[test]
    fn perfect_model_scores_zero_and_zero_mass_stays_finite() {
        let g = Ggx::new(1.0, 1.0, 0.0).unwrap();
        let w = |e: f64| e * PI / 30.0;
        let ndf = EmpiricalNdf::from_bins(vec![bin(10, w(10.0)), bin(20, w(20.0))], 30);
        let q = quality(&ndf, &g, PI / 2.0).unwrap();
        assert!(q.deviance < 1e-12 && q.ndf_delta < 1e-12, "{q:?}");
        // A model with (numerically) no mass at the data, all of it in an empty bin: large, finite, not NaN.
        let narrow = Ggx::new(1e-4, 1e-4, 0.0).unwrap();
        let far = NdfBin { m: Vector3::new(0.8, 0.0, 0.6), ..bin(30, 0.1) };
        let q = quality(&EmpiricalNdf::from_bins(vec![far, bin(0, 0.1)], 30), &narrow, PI / 2.0).unwrap();
        assert!(q.deviance.is_finite() && q.deviance > 1e3, "{q:?}");
        // Outside the region (53 deg > 45 deg) the data do not count: no samples left.
        assert!(quality(&EmpiricalNdf::from_bins(vec![far], 30), &narrow, PI / 4.0).is_err());
        assert!(quality(&EmpiricalNdf::from_bins(vec![bin(0, 1.0)], 0), &g, PI / 2.0).is_err());
    }

    #[test]
    fn model_of_fit_reads_params_by_name() {
        let fit = serde_json::json!({"model": "ggx-aniso", "params": {"theta_z": 0.3, "alpha_x": 0.2, "alpha_y": 0.1}});
        let m = model_of_fit(&fit).unwrap();
        assert_eq!(m.id(), ModelId::GgxAniso);
        assert_eq!(m.params(), vec![0.2, 0.1, 0.3]);
        assert!(model_of_fit(&serde_json::json!({"model": "ggx", "params": {}})).is_err());
        assert!(model_of_fit(&serde_json::json!({"model": "nope", "params": {}})).is_err());
    }
}
