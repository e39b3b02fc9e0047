//! The NDF difference metric of `data_formats/objective.md`:
//! `delta(D; D_ref) = sqrt( E_{m ~ D_ref(m)(m.n)} [ (D(m)/D_ref(m) - 1)^2 ] )`, by quadrature.

use nalgebra::Vector3;

use crate::models::{Model, Ndf};
use crate::ndf::EmpiricalNdf;

/// `delta` by quadrature on directions `m_k` with projected solid angles `W_k`:
/// weights `w_k = D_ref(m_k) W_k`, `delta = sqrt( sum w_k (D/D_ref - 1)^2 / sum w_k )`.
/// Nodes where `D_ref` is 0 carry no weight. Returns `None` when no node has weight.
pub fn delta<F, G>(d: F, d_ref: G, nodes: impl IntoIterator<Item = (Vector3<f64>, f64)>) -> Option<f64>
where
    F: Fn(&Vector3<f64>) -> f64,
    G: Fn(&Vector3<f64>) -> f64,
{
    let (mut num, mut den) = (0.0, 0.0);
    for (m, w) in nodes {
        let r = d_ref(&m);
        if r > 0.0 && w > 0.0 && r.is_finite() {
            let wk = r * w;
            num += wk * (d(&m) / r - 1.0).powi(2);
            den += wk;
        }
    }
    (den > 0.0).then(|| (num / den).sqrt())
}

/// `delta(D; D_ref)` between two models, by quadrature on a 256-cell grid matched to the reference
/// (how fits are scored against synthetic truth in the tests and examples).
pub fn delta_to_model(d: &Model, reference: &Model) -> Option<f64> {
    let grid = super::synthetic::Grid::for_model(reference, 256);
    let (bins, _) = super::synthetic::expected(reference, &grid, 1.0);
    delta(|m| d.d(*m), |m| reference.d(*m), bins.iter().map(|b| (b.m, b.proj_solid_angle)))
}

/// `delta(D_model; D_empirical)` over the bins of `ndf` (the fit error against the data; it includes
/// the counting noise of the bins, about `sqrt(K_eff / N)`).
pub fn delta_to_data(model: &Model, ndf: &EmpiricalNdf) -> Option<f64> {
    let n: f64 = ndf.bins.iter().map(|b| b.count as f64).sum();
    // Guard: an NDF without counts has no reference distribution.
    if n <= 0.0 {
        return None;
    }
    let mut num = 0.0;
    let mut den = 0.0;
    for b in ndf.bins.iter().filter(|b| b.count > 0 && b.proj_solid_angle > 0.0) {
        // w_k = d_k W_k = c_k / N, and D/d_k with d_k = c_k / (N W_k).
        let wk = b.count as f64 / n;
        let dk = b.count as f64 / (n * b.proj_solid_angle);
        num += wk * (model.d(b.m) / dk - 1.0).powi(2);
        den += wk;
    }
    (den > 0.0).then(|| (num / den).sqrt())
}
