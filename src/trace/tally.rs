//! What the tracer counts: outgoing directions binned into a table, energy by bounce order, the masking
//! samples; per block of rays, summed in block order so a seed gives the same figures on any number
//! of threads.

use std::f64::consts::{FRAC_PI_2, PI};

/// Rec. 709 luminance weights of the three channels.
pub const LUMA: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// The outgoing-direction table: `n_theta x n_phi` bins, uniform in `u_theta = sqrt(2 theta / pi)` (finer
/// near the normal, where sharp lobes are, as the RGL tables) and in `phi` over `[-pi, pi)` (`phi = 0`
/// the scan's `+x`). Bin `k = it * n_phi + ip`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct DirTable {
    /// Bins in elevation.
    pub n_theta: usize,
    /// Bins in azimuth.
    pub n_phi: usize,
}

impl DirTable {
    /// Number of bins.
    pub fn len(&self) -> usize {
        self.n_theta * self.n_phi
    }

    /// Whether the table has no bin.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Elevation (radians) of edge `k` (`0..=n_theta`).
    pub fn theta_edge(&self, k: usize) -> f64 {
        let u = k as f64 / self.n_theta as f64;
        u * u * FRAC_PI_2
    }

    /// Azimuth (radians) of edge `k` (`0..=n_phi`).
    pub fn phi_edge(&self, k: usize) -> f64 {
        -PI + 2.0 * PI * k as f64 / self.n_phi as f64
    }

    /// The bin of a unit direction above the horizon.
    #[inline]
    pub fn bin(&self, w: [f64; 3]) -> Option<usize> {
        warp(w).map(|(u, p)| self.bin_at(u, p))
    }

    /// The bin at the warped coordinates `(u_theta, u_phi)` of [`warp`].
    #[inline]
    pub(crate) fn bin_at(&self, u: f64, p: f64) -> usize {
        let it = ((u * self.n_theta as f64) as usize).min(self.n_theta - 1);
        let ip = ((p * self.n_phi as f64) as usize).min(self.n_phi - 1);
        it * self.n_phi + ip
    }

    /// Projected solid angle `int cos(theta) dw` of bin `k` (exact).
    pub fn proj_solid_angle(&self, k: usize) -> f64 {
        let it = k / self.n_phi;
        let (a, b) = (self.theta_edge(it).sin(), self.theta_edge(it + 1).sin());
        0.5 * (b * b - a * a) * 2.0 * PI / self.n_phi as f64
    }

    /// Centre direction of bin `k` (middle of its `u_theta` and `phi` ranges).
    pub fn centre(&self, k: usize) -> [f64; 3] {
        let (it, ip) = (k / self.n_phi, k % self.n_phi);
        let u = (it as f64 + 0.5) / self.n_theta as f64;
        let theta = u * u * FRAC_PI_2;
        let phi = -PI + 2.0 * PI * (ip as f64 + 0.5) / self.n_phi as f64;
        [theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos()]
    }
}

impl std::str::FromStr for DirTable {
    type Err = crate::Error;
    /// `THETAxPHI` bins (for example `32x64`), as `--bins` spells them; the ranges are checked by
    /// [`TraceOptions::validate`](crate::trace::TraceOptions::validate).
    fn from_str(s: &str) -> crate::Result<Self> {
        let bad = || crate::Error::invalid(format!("{s:?} is not THETAxPHI bins (for example 32x64)"));
        let (a, b) = s.split_once('x').ok_or_else(bad)?;
        Ok(DirTable { n_theta: a.trim().parse().map_err(|_| bad())?, n_phi: b.trim().parse().map_err(|_| bad())? })
    }
}

/// The warped coordinates of a unit direction above the horizon: `u_theta = sqrt(2 theta / pi)` and
/// `u_phi = (phi + pi) / 2 pi`, both in `[0, 1]` (the tables' and the RGL warp's); `None` on or below
/// the horizon.
#[inline]
pub(crate) fn warp(w: [f64; 3]) -> Option<(f64, f64)> {
    // Below (or on) the horizon no bin holds the direction.
    if !(w[2] > 0.0) {
        return None;
    }
    let theta = w[2].min(1.0).acos();
    Some(((theta / FRAC_PI_2).sqrt(), (w[1].atan2(w[0]) + PI) / (2.0 * PI)))
}

/// Sums per bin: three channels and the square of the luminance (for the noise).
pub type Bin = [f64; 4];

/// One incidence's sums over a block of rays (or over all of them, once merged).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Tally {
    /// Energy leaving after one bounce, per outgoing bin.
    pub single: Vec<Bin>,
    /// Energy leaving after two or more bounces.
    pub multi: Vec<Bin>,
    /// The microfacet model's single scattering (one sample per path, at its start point).
    pub pred: Vec<Bin>,
    /// Energy leaving after bounce `k + 1`, per channel.
    pub by_bounce: Vec<[f64; 3]>,
    /// Energy still on the surface after the last bounce, or lost by a numerical leak.
    pub lost: [f64; 3],
    /// Energy that left an open grid sideways (included in the bins).
    pub side: [f64; 3],
    /// Paths that landed on a measured cell (the normalization).
    pub landed: u64,
    /// Rays that met no measured cell first (a filled hole, a seam, or off an open grid's side).
    pub not_landed: u64,
    /// Hits after the first on cells with a filled corner or on a seam.
    pub filled_hits: u64,
    /// Hits after the first, all told.
    pub later_hits: u64,
    /// Prediction samples on measured cells.
    pub pred_samples: u64,
    /// Masking sums: weight, weight when visible, their squares; the same split by facets tilted toward
    /// the direction (`[2]`) and away from it (`[1]`) (index 0: all).
    pub g1: [[f64; 4]; 3],
}

impl Tally {
    /// An empty tally for `bins` outgoing bins and `bounces` orders.
    pub fn new(bins: usize, bounces: usize) -> Tally {
        Tally {
            single: vec![[0.0; 4]; bins],
            multi: vec![[0.0; 4]; bins],
            pred: vec![[0.0; 4]; bins],
            by_bounce: vec![[0.0; 3]; bounces],
            lost: [0.0; 3],
            side: [0.0; 3],
            landed: 0,
            not_landed: 0,
            filled_hits: 0,
            later_hits: 0,
            pred_samples: 0,
            g1: [[0.0; 4]; 3],
        }
    }

    /// Add `other` into `self`.
    pub fn add(&mut self, other: &Tally) {
        let add_bins = |a: &mut Vec<Bin>, b: &Vec<Bin>| {
            for (x, y) in a.iter_mut().zip(b) {
                for c in 0..4 {
                    x[c] += y[c];
                }
            }
        };
        add_bins(&mut self.single, &other.single);
        add_bins(&mut self.multi, &other.multi);
        add_bins(&mut self.pred, &other.pred);
        for (x, y) in self.by_bounce.iter_mut().zip(&other.by_bounce) {
            for c in 0..3 {
                x[c] += y[c];
            }
        }
        for c in 0..3 {
            self.lost[c] += other.lost[c];
            self.side[c] += other.side[c];
        }
        self.landed += other.landed;
        self.not_landed += other.not_landed;
        self.filled_hits += other.filled_hits;
        self.later_hits += other.later_hits;
        self.pred_samples += other.pred_samples;
        for (x, y) in self.g1.iter_mut().zip(&other.g1) {
            for c in 0..4 {
                x[c] += y[c];
            }
        }
    }
}

/// Add weight `w` (per channel) into bin `b`.
#[inline]
pub(crate) fn deposit(table: &mut [Bin], b: usize, w: [f64; 3]) {
    let l = lum(w);
    let x = &mut table[b];
    x[0] += w[0];
    x[1] += w[1];
    x[2] += w[2];
    x[3] += l * l;
}

/// Luminance of a channel triple.
#[inline]
pub fn lum(w: [f64; 3]) -> f64 {
    LUMA[0] * w[0] + LUMA[1] * w[1] + LUMA[2] * w[2]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bins_tile_the_hemisphere_by_projected_solid_angle() {
        let t = DirTable { n_theta: 7, n_phi: 5 };
        let total: f64 = (0..t.len()).map(|k| t.proj_solid_angle(k)).sum();
        assert!((total - PI).abs() < 1e-12, "{total}");
        for k in 0..t.len() {
            assert_eq!(t.bin(t.centre(k)), Some(k));
        }
    }
}
