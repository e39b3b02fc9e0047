//! The NDF difference metric of `data_formats/objective.md`:
//! `delta(D; D_ref) = sqrt( E_{m ~ D_ref(m)(m.n)} [ (D(m)/D_ref(m) - 1)^2 ] )`, by quadrature.

use nalgebra::Vector3;
use rayon::prelude::*;

use crate::models::{Model, Ndf};
use crate::ndf::{BinGrid, EmpiricalNdf, NdfBin, QuadOrder, SlopeFrame};

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
/// the counting noise of the bins, [`counting_noise2`]).
pub fn delta_to_data(model: &(impl Ndf + Sync), ndf: &EmpiricalNdf) -> Option<f64> {
    let n: f64 = ndf.bins.iter().map(|b| b.count as f64).sum();
    // Guard: an NDF without counts has no reference distribution.
    if n <= 0.0 {
        return None;
    }
    let held = |b: &&NdfBin| b.count > 0 && b.proj_solid_angle > 0.0;
    // The model on every thread, the sums in bin order (the same bits for any thread count).
    let d: Vec<f64> = ndf.bins.par_iter().filter(held).map(|b| model.d(b.m)).collect();
    let mut num = 0.0;
    let mut den = 0.0;
    for (b, d) in ndf.bins.iter().filter(held).zip(d) {
        // w_k = d_k W_k = c_k / N, and D/d_k with d_k = c_k / (N W_k).
        let wk = b.count as f64 / n;
        let dk = b.count as f64 / (n * b.proj_solid_angle);
        num += wk * (d / dk - 1.0).powi(2);
        den += wk;
    }
    (den > 0.0).then(|| (num / den).sqrt())
}

/// The square of the counting noise in [`delta_to_data`] were `model` the truth: its expectation of
/// `delta_data^2` under Poisson counts `lambda_k = N D(m_k) W_k` in every bin,
/// `(1/N) sum_k E[(lambda_k - c_k)^2 / c_k; c_k >= 1]` ([`poisson_relative_noise`]). About `K / N` where
/// every bin holds many normals, less where bins hold one or two (an empty bin has no weight), so a
/// model's error is not hidden by noise that sparse bins do not have. `None` for an NDF without counts.
pub fn counting_noise2(model: &(impl Ndf + Sync), ndf: &EmpiricalNdf) -> Option<f64> {
    let n: f64 = ndf.bins.iter().map(|b| b.count as f64).sum();
    // Guard: an NDF without counts has no noise to speak of.
    if n <= 0.0 {
        return None;
    }
    let terms: Vec<f64> = ndf
        .bins
        .par_iter()
        .filter(|b| b.proj_solid_angle > 0.0)
        .map(|b| poisson_relative_noise(n * model.d(b.m) * b.proj_solid_angle))
        .collect();
    let sum: f64 = terms.iter().sum();
    Some(sum / n)
}

/// `E[(lambda - c)^2 / c; c >= 1]` for a Poisson count `c` of mean `lambda`: the series up to a mean of
/// 50, past it the expansion `1 + 2 / lambda` (its next term is below 1e-3 there).
pub fn poisson_relative_noise(lambda: f64) -> f64 {
    // Guard: no expected count (or a non-finite model value), no populated bin and no noise.
    if !(lambda > 0.0 && lambda.is_finite()) {
        return 0.0;
    }
    if lambda > 50.0 {
        return 1.0 + 2.0 / lambda;
    }
    let c_max = (lambda + 12.0 * lambda.sqrt() + 25.0) as u32;
    let (mut p, mut sum) = ((-lambda).exp(), 0.0);
    for c in 1..=c_max {
        let c = c as f64;
        p *= lambda / c;
        sum += p * (lambda - c).powi(2) / c;
    }
    sum
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
    #[cfg(test)]
    pub fn total(&self) -> f64 {
        self.nodes.iter().map(|n| n.1).sum()
    }

    /// `delta(D_model; D_truth)` on these nodes.
    #[cfg(feature = "cli")]
    pub fn delta_model(&self, model: &Model, truth: &Model) -> Option<f64> {
        delta(|m| model.d(*m), |m| truth.d(*m), self.nodes.iter().copied())
    }
}
