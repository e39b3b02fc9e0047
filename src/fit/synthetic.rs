//! Binned NDFs with known truth, for tests and benchmarks of the fitter independent of any heightfield:
//! bins over the hemisphere, expected counts from the analytic D integrated over each bin, and Poisson
//! counts drawn with a fixed seed.
//!
//! The bins are square cells of the Lambert azimuthal equal-area map of a whitened normal `m'`
//! (`p = sqrt(2/(1+m'_z)) (m'_x, m'_y)`, disk of radius sqrt 2, `d omega' = d^2 p`), with the slopes
//! `s = mean + L s'`, `s' = -m'_xy / m'_z` (the layout the NDF engineer's notes suggest). Per cell, by
//! 4x4 Gauss-Legendre quadrature in `p`, with `d^2 s = |L| d omega' / cos^3 theta'` and
//! `D cos(theta) d omega = P22(s) d^2 s = D cos^4(theta) d^2 s` (Heitz eq. 64):
//! - `W_k = integral of cos^4(theta) |L| / cos^3(theta') d^2 p` (the projected solid angle),
//! - `E_k = N * integral of D(m) cos^4(theta) |L| / cos^3(theta') d^2 p`.

use nalgebra::Vector3;
use rand::SeedableRng;
use rand_distr::{Distribution, Poisson};

use crate::models::{Model, Ndf};
use crate::ndf::{EmpiricalNdf, NdfBin};

/// The binning grid: `n x n` cells of the equal-area map of `s' = L^-1 (s - mean)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Grid {
    /// Centre of the slope distribution.
    pub mean: [f64; 2],
    /// Stretch `L` (row-major 2x2), `s = mean + L s'`.
    pub l: [[f64; 2]; 2],
    /// Cells per side.
    pub n: usize,
}

impl Grid {
    /// A grid matched to `model`: centred on the slope of its peak (the ellipsoid's third axis, row 3 of
    /// R in Walter et al. eq. 3) and stretched by its alphas along its principal axes.
    pub fn for_model(model: &Model, n: usize) -> Grid {
        // A mixture's grid follows its wider (last) lobe, which spans the core too.
        let spec = model.id().spec();
        let g = spec.parts(&model.params(), spec.lobes.len() - 1);
        let (ax, ay, tx, ty, tz) = (g.alpha_x, g.alpha_y, g.theta_x, g.theta_y, g.theta_z);
        let r = crate::models::ellipsoid::rotation_xyz(tx, ty, tz);
        let axis = r.row(2);
        let mean = [-axis[0] / axis[2], -axis[1] / axis[2]];
        // L = Rz(tz)^T diag(ax, ay): local slopes s_loc = Rz s are stretched by the alphas.
        let (s, c) = tz.sin_cos();
        let l = [[c * ax, s * ay], [-s * ax, c * ay]];
        Grid { mean, l, n }
    }

    fn det(&self) -> f64 {
        (self.l[0][0] * self.l[1][1] - self.l[0][1] * self.l[1][0]).abs()
    }

    /// Direction `m` and quadrature factor `cos^4(theta) |L| / cos^3(theta')` at map point `p`
    /// (`None` outside the disk).
    fn at(&self, px: f64, py: f64) -> Option<(Vector3<f64>, f64)> {
        let r2 = px * px + py * py;
        let mz = 1.0 - 0.5 * r2;
        // Guard: at the rim m'_z -> 0 and s' -> infinity; the factor tends to 0 there, so drop it.
        if mz <= 1e-12 {
            return None;
        }
        let k = (1.0 - 0.25 * r2).max(0.0).sqrt();
        let (spx, spy) = (-px * k / mz, -py * k / mz);
        let sx = self.mean[0] + self.l[0][0] * spx + self.l[0][1] * spy;
        let sy = self.mean[1] + self.l[1][0] * spx + self.l[1][1] * spy;
        let m = Vector3::new(-sx, -sy, 1.0).normalize();
        let c4 = m.z.powi(4);
        Some((m, c4 * self.det() / (mz * mz * mz)))
    }
}

/// 4-point Gauss-Legendre nodes and weights on [-1, 1].
const GL4: [(f64, f64); 4] = [
    (-0.861_136_311_594_052_6, 0.347_854_845_137_453_9),
    (-0.339_981_043_584_856_3, 0.652_145_154_862_546_1),
    (0.339_981_043_584_856_3, 0.652_145_154_862_546_1),
    (0.861_136_311_594_052_6, 0.347_854_845_137_453_9),
];

/// The bins of `grid` (count 0) with the expected count `N * integral of D cos` of `model` in each.
pub fn expected(model: &Model, grid: &Grid, n_samples: f64) -> (Vec<NdfBin>, Vec<f64>) {
    let h = 2.0 * std::f64::consts::SQRT_2 / grid.n as f64;
    let mut bins = Vec::with_capacity(grid.n * grid.n);
    let mut e = Vec::with_capacity(grid.n * grid.n);
    for i in 0..grid.n {
        for j in 0..grid.n {
            let (x0, y0) = (-std::f64::consts::SQRT_2 + j as f64 * h, -std::f64::consts::SQRT_2 + i as f64 * h);
            // Cells that cross the rim of the disk get a finer rule (16x16 sub-cells, each with the 4x4
            // Gauss-Legendre rule), so their partial area is integrated to well below the counting noise.
            let corners_in =
                [(0.0, 0.0), (h, 0.0), (0.0, h), (h, h)].iter().filter(|(a, b)| (x0 + a).powi(2) + (y0 + b).powi(2) < 2.0).count();
            let sub = match corners_in {
                0 if (x0 + 0.5 * h).hypot(y0 + 0.5 * h) > std::f64::consts::SQRT_2 + h => continue,
                4 => 1,
                _ => 16,
            };
            let hs = h / sub as f64;
            let (mut w, mut ek, mut sa) = (0.0, 0.0, 0.0);
            let mut msum = Vector3::zeros();
            for si in 0..sub {
                for sj in 0..sub {
                    let (cx, cy) = (x0 + (sj as f64 + 0.5) * hs, y0 + (si as f64 + 0.5) * hs);
                    for (u, wu) in GL4 {
                        for (v, wv) in GL4 {
                            if let Some((m, f)) = grid.at(cx + 0.5 * hs * u, cy + 0.5 * hs * v) {
                                let q = wu * wv * 0.25 * hs * hs;
                                w += q * f;
                                ek += q * f * model.d(m);
                                sa += q * f / m.z;
                                msum += m * (q * f);
                            }
                        }
                    }
                }
            }
            // The bin's direction: the cell centre's when it is on the disk, else the projected-area
            // weighted mean direction of the part on the disk.
            let mc = match grid.at(x0 + 0.5 * h, y0 + 0.5 * h) {
                Some((m, _)) => m,
                None => msum.normalize(),
            };
            if w > 0.0 && mc.iter().all(|v| v.is_finite()) {
                bins.push(NdfBin { m: mc, d: 0.0, stderr: 0.0, count: 0, solid_angle: sa, proj_solid_angle: w });
                e.push(n_samples * ek);
            }
        }
    }
    (bins, e)
}

/// An empirical NDF of `model` on `grid`: Poisson counts around the expected counts of `n_samples`
/// samples, drawn with `seed`; `d`, `stderr` per `data_formats/ndf_csv.md`.
pub fn binned_ndf(model: &Model, grid: &Grid, n_samples: f64, seed: u64) -> EmpiricalNdf {
    let (mut bins, e) = expected(model, grid, n_samples);
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    for (b, &ek) in bins.iter_mut().zip(&e) {
        // Poisson::new rejects lambda = 0 (and an underflowed expectation is a zero count anyway).
        b.count = if ek > 0.0 { Poisson::new(ek).map(|p| p.sample(&mut rng) as u64).unwrap_or(0) } else { 0 };
    }
    finish(bins)
}

/// Fill `d` and `stderr` from the counts (ndf_csv.md) and total them.
pub fn finish(mut bins: Vec<NdfBin>) -> EmpiricalNdf {
    let n: u64 = bins.iter().map(|b| b.count).sum();
    let nf = n.max(1) as f64;
    for b in &mut bins {
        b.d = b.count as f64 / (nf * b.proj_solid_angle);
        b.stderr = (b.count.max(1) as f64).sqrt() / (nf * b.proj_solid_angle);
    }
    EmpiricalNdf::from_bins(bins, n)
}
