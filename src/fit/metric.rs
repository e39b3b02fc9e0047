//! The NDF difference metric of `data_formats/objective.md`:
//! `delta(D; D_ref) = sqrt( E_{m ~ D_ref(m)(m.n)} [ (D(m)/D_ref(m) - 1)^2 ] )`, by quadrature.

use nalgebra::Vector3;

use crate::models::{Model, Ndf};
use crate::ndf::{BinGrid, EmpiricalNdf, QuadOrder, SlopeFrame};

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

/// Fixed quadrature nodes `(m_k, W_k)` over the hemisphere, the same for every point of a sweep so that
/// the fit errors of different knobs are measured on identical directions.
#[derive(Debug, Clone)]
pub struct RefNodes {
    /// Central direction and projected solid angle of each cell.
    pub nodes: Vec<(Vector3<f64>, f64)>,
}

impl RefNodes {
    /// A `cells x cells` grid over the Lambert disk of `frame` (a frame that follows the lobe, so the
    /// cells resolve it), each cell's `W` by the same Gauss-Legendre rule the NDF uses and its node at
    /// the `W`-weighted centroid. `sum W_k = pi`, the projected solid angle of the hemisphere.
    pub fn new(frame: &SlopeFrame, cells: usize) -> RefNodes {
        let grid = BinGrid::new(cells);
        let mut nodes = Vec::with_capacity(grid.cells());
        let rim = frame.rim_shape();
        for c in 0..grid.cells() {
            if !grid.meets_disk(c) {
                continue;
            }
            let (mut w, mut px, mut py) = (0.0, 0.0, 0.0);
            grid.quadrature(c, QuadOrder::Standard, &rim, |p, wt| {
                let dw = frame.proj_density(p) * wt;
                w += dw;
                px += p[0] * dw;
                py += p[1] * dw;
            });
            if w > 0.0 {
                nodes.push((frame.normal_at([px / w, py / w]), w));
            }
        }
        RefNodes { nodes }
    }

    /// Sum of the projected solid angles (pi for a grid covering the hemisphere).
    pub fn total(&self) -> f64 {
        self.nodes.iter().map(|n| n.1).sum()
    }

    /// `delta(D_model; D_truth)` on these nodes.
    pub fn delta_model(&self, model: &Model, truth: &Model) -> Option<f64> {
        delta(|m| model.d(*m), |m| truth.d(*m), self.nodes.iter().copied())
    }
}
