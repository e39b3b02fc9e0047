//! The microfacet model of the traced surface, and how the trace measures against it.
//!
//! The model is the one every BRDF ndfit exports is: `D` of the surface, Smith's masking from `D` alone,
//! one bounce. `D` here is the NDF of the surface the tracer sees (its triangles' normals, each
//! weighted by its projected area), so that the comparison measures the model's assumptions, not the
//! difference between two slope stencils. Smith's `Lambda` follows from the projected area
//! `sigma(w) = int D(m) <w.m> dm` (Heitz 2014 eq. 22, 43): `1 + Lambda(w) = sigma(w) / cos(theta)`, and
//! `G1(w) = cos(theta) / sigma(w)`. `sigma` of the incident directions is the exact sum over every
//! triangle of the measured cells; at other directions (the `Lambda(o)` of `G2`) it is read from a table
//! of the sum over a fixed sample of 2^16 triangles.

use rayon::prelude::*;

use super::surface::Surface;
use super::tally::{DirTable, Tally};
use super::tracer::{block_seed, TraceRng};
use rand::{RngExt, SeedableRng};

/// Triangles sampled for the `sigma` table.
const SIGMA_SAMPLE: usize = 1 << 16;
/// Nodes of the `sigma` table along `u_theta` and `u_phi`.
const SIGMA_NODES: [usize; 2] = [33, 65];

/// `sigma(w)` of the surface's exact NDF at each direction: `(1 / 2N) sum <w.m> / m.n` over the two
/// triangles of the `N` measured cells.
pub(crate) fn sigma_exact(s: &Surface, dirs: &[[f64; 3]]) -> Vec<f64> {
    // Per row, then summed in row order: the same sums on any number of threads.
    let rows: Vec<Vec<f64>> = (0..s.ncy)
        .into_par_iter()
        .map(|i| {
            let mut acc = vec![0.0; dirs.len()];
            for j in 0..s.ncx {
                if !s.is_valid(i, j) {
                    continue;
                }
                for tri in 0..2 {
                    let m = s.normal(i, j, tri);
                    for (a, w) in acc.iter_mut().zip(dirs) {
                        *a += (w[0] * m[0] + w[1] * m[1] + w[2] * m[2]).max(0.0) / m[2];
                    }
                }
            }
            acc
        })
        .collect();
    let mut sums = vec![0.0; dirs.len()];
    for r in &rows {
        for (a, v) in sums.iter_mut().zip(r) {
            *a += v;
        }
    }
    sums.into_iter().map(|v| v / (2 * s.valid_cells) as f64).collect()
}

/// `sigma` on a grid of directions `(u_theta, u_phi)` (the RGL warp: `theta = u^2 pi / 2`), bilinear
/// between nodes.
#[derive(Debug, Clone)]
pub(crate) struct SigmaTable {
    v: Vec<f64>,
}

fn node_dir(a: usize, b: usize) -> [f64; 3] {
    let u = a as f64 / (SIGMA_NODES[0] - 1) as f64;
    let theta = u * u * std::f64::consts::FRAC_PI_2;
    let phi = -std::f64::consts::PI + 2.0 * std::f64::consts::PI * b as f64 / (SIGMA_NODES[1] - 1) as f64;
    [theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()]
}

impl SigmaTable {
    /// The table from a sample of the surface's triangles (seeded: the same table for the same seed).
    pub fn new(s: &Surface, seed: u64) -> SigmaTable {
        let mut rng = TraceRng::seed_from_u64(block_seed(seed, usize::MAX, 0));
        let total = 2 * s.valid_cells;
        let mut normals = Vec::with_capacity(SIGMA_SAMPLE.min(total));
        if total <= SIGMA_SAMPLE {
            for i in 0..s.ncy {
                for j in 0..s.ncx {
                    if s.is_valid(i, j) {
                        normals.push(s.normal(i, j, 0));
                        normals.push(s.normal(i, j, 1));
                    }
                }
            }
        } else {
            while normals.len() < SIGMA_SAMPLE {
                let (x, y) = (rng.random::<f64>() * s.ncx as f64, rng.random::<f64>() * s.ncy as f64);
                let (i, j, tri) = s.locate(x, y);
                if s.is_valid(i, j) {
                    normals.push(s.normal(i, j, tri));
                }
            }
        }
        let n = normals.len() as f64;
        let v = (0..SIGMA_NODES[0] * SIGMA_NODES[1])
            .into_par_iter()
            .map(|k| {
                let w = node_dir(k / SIGMA_NODES[1], k % SIGMA_NODES[1]);
                normals.iter().map(|m| (w[0] * m[0] + w[1] * m[1] + w[2] * m[2]).max(0.0) / m[2]).sum::<f64>() / n
            })
            .collect();
        SigmaTable { v }
    }

    /// `sigma(w)` by bilinear interpolation.
    pub fn sigma(&self, w: [f64; 3]) -> f64 {
        let theta = w[2].clamp(-1.0, 1.0).acos().min(std::f64::consts::FRAC_PI_2);
        let u = (theta / std::f64::consts::FRAC_PI_2).sqrt();
        let p = (w[1].atan2(w[0]) + std::f64::consts::PI) / (2.0 * std::f64::consts::PI);
        self.sigma_at(u, p)
    }

    /// `sigma` at the warped coordinates `(u_theta, u_phi)` (`super::tally::warp`).
    #[inline]
    pub fn sigma_at(&self, u: f64, p: f64) -> f64 {
        let u = u * (SIGMA_NODES[0] - 1) as f64;
        let p = p * (SIGMA_NODES[1] - 1) as f64;
        let (a, b) = ((u as usize).min(SIGMA_NODES[0] - 2), (p as usize).min(SIGMA_NODES[1] - 2));
        let (ta, tb) = ((u - a as f64).clamp(0.0, 1.0), (p - b as f64).clamp(0.0, 1.0));
        let at = |a: usize, b: usize| self.v[a * SIGMA_NODES[1] + b];
        (1.0 - ta) * ((1.0 - tb) * at(a, b) + tb * at(a, b + 1)) + ta * ((1.0 - tb) * at(a + 1, b) + tb * at(a + 1, b + 1))
    }

    /// Smith's `Lambda(w) = sigma(w) / cos(theta) - 1` (never below 0: `sigma >= cos` on a heightfield,
    /// the table's sampling aside; `f64::MAX` at the horizon).
    pub fn lambda(&self, w: [f64; 3]) -> f64 {
        // On or below the horizon nothing is seen: Lambda is infinite.
        if !(w[2] > 0.0) {
            return f64::MAX;
        }
        (self.sigma(w) / w[2] - 1.0).max(0.0)
    }

    /// `Lambda(w)` of a direction above the horizon from its warped coordinates `(u, p)`.
    #[inline]
    pub fn lambda_at(&self, w: [f64; 3], u: f64, p: f64) -> f64 {
        (self.sigma_at(u, p) / w[2] - 1.0).max(0.0)
    }
}

/// The single-bounce trace against the microfacet model's single scattering at one incidence.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SingleComparison {
    /// Albedo of the first bounce, traced (luminance).
    pub albedo_traced: f64,
    /// Albedo of the microfacet model's single scattering (luminance).
    pub albedo_model: f64,
    /// `sum |e_traced - e_model| / sum e_model` over the outgoing bins (`e`: energy per bin): the share of
    /// the model's single-scattered energy that lands elsewhere in the trace.
    pub error: f64,
    /// What `error` would be from the Monte Carlo noise of both sides alone (`sum sqrt(2 / pi) sd`).
    pub noise: f64,
    /// Median of `|f_traced / f_model - 1|` over the bins where the model's BRDF is at least 1% of its peak.
    pub median_rel_error: f64,
    /// Bins in that median.
    pub bins_compared: usize,
}

/// Energy per bin (luminance) of `t`'s table normalized by `n`, and its variance.
fn energy(bins: &[[f64; 4]], n: u64) -> (Vec<f64>, Vec<f64>) {
    let n = n.max(1) as f64;
    bins.iter()
        .map(|b| {
            let e = super::tally::lum([b[0], b[1], b[2]]) / n;
            (e, ((b[3] / n - e * e) / n).max(0.0))
        })
        .unzip()
}

/// Compare one incidence's single bounce with the model.
pub(crate) fn compare(table: &DirTable, t: &Tally) -> SingleComparison {
    let (es, vs) = energy(&t.single, t.landed);
    let (ep, vp) = energy(&t.pred, t.pred_samples);
    let total_p: f64 = ep.iter().sum();
    let total_s: f64 = es.iter().sum();
    let (mut err, mut noise) = (0.0, 0.0);
    for k in 0..es.len() {
        err += (es[k] - ep[k]).abs();
        noise += (2.0 / std::f64::consts::PI).sqrt() * (vs[k] + vp[k]).sqrt();
    }
    let f_model: Vec<f64> = (0..ep.len()).map(|k| ep[k] / table.proj_solid_angle(k)).collect();
    let peak = f_model.iter().cloned().fold(0.0, f64::max);
    let mut rel: Vec<f64> =
        (0..ep.len()).filter(|&k| f_model[k] >= 0.01 * peak && ep[k] > 0.0).map(|k| (es[k] / ep[k] - 1.0).abs()).collect();
    rel.sort_by(f64::total_cmp);
    let median = if rel.is_empty() { f64::NAN } else { rel[rel.len() / 2] };
    let ratio = |a: f64| if total_p > 0.0 { a / total_p } else { f64::NAN };
    SingleComparison {
        albedo_traced: total_s,
        albedo_model: total_p,
        error: ratio(err),
        noise: ratio(noise),
        median_rel_error: median,
        bins_compared: rel.len(),
    }
}
