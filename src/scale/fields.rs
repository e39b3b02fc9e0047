//! Synthetic surfaces whose footprint statistics are known in closed form, for tests and demos.
//!
//! - [`FourierSurface`]: a periodic sum of cosines with random phases on integer wave numbers of the
//!   period. On a grid spanning whole periods the sample averages of products of distinct modes vanish
//!   exactly, so the covariance of central-difference slopes, of Gaussian-filtered slopes and the
//!   footprint covariance `Sigma_F` are closed-form sums over modes (no statistical error). With many
//!   modes the surface is Gaussian to good approximation (central limit theorem).
//! - [`BumpField`]: identical rotated ellipsoid caps on a square lattice: a strongly skewed NDF whose skew
//!   must fade once a footprint covers many bumps.

use nalgebra::{Matrix2, Matrix3, Vector2, Vector3};
use rand::{RngExt, SeedableRng};
use rand_distr::StandardNormal;

use crate::error::{Error, Result};
use crate::models::ellipsoid::rotation_xyz;
use crate::scan::Heightfield;

/// One cosine mode `amp * cos(kx x + ky y + phase)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mode {
    /// Wave number along x (rad/m).
    pub kx: f64,
    /// Wave number along y (rad/m).
    pub ky: f64,
    /// Amplitude (m).
    pub amp: f64,
    /// Phase (rad).
    pub phase: f64,
}

/// A periodic random-phase surface on an `n x n` grid of spacing `dx` (period `L = n dx` both ways).
#[derive(Debug, Clone, PartialEq)]
pub struct FourierSurface {
    /// Samples per period along each axis.
    pub n: usize,
    /// Grid spacing (m).
    pub dx: f64,
    /// The modes, all distinct up to sign and below the Nyquist limit.
    pub modes: Vec<Mode>,
}

impl FourierSurface {
    /// `n_modes` modes with wave vectors drawn from a Gaussian spectrum of correlation lengths
    /// `(corr_x, corr_y)` rotated by `theta` (rounded to the period's lattice), equal amplitudes scaled so
    /// that the continuous surface's RMS slope magnitude is `rms_slope`.
    pub fn gaussian_spectrum(n: usize, dx: f64, n_modes: usize, corr: (f64, f64), theta: f64, rms_slope: f64, seed: u64) -> Result<Self> {
        if n < 8 || n_modes == 0 || !(dx > 0.0 && corr.0 > 0.0 && corr.1 > 0.0 && rms_slope > 0.0) {
            return Err(Error::invalid("FourierSurface: need n >= 8, modes > 0 and positive lengths"));
        }
        let l = n as f64 * dx;
        let k0 = 2.0 * std::f64::consts::PI / l;
        let nyq = (n / 2) as i64 - 1;
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let (s, c) = theta.sin_cos();
        let mut seen = std::collections::BTreeSet::new();
        let mut modes = Vec::new();
        let mut tries = 0usize;
        while modes.len() < n_modes && tries < 100 * n_modes {
            tries += 1;
            let (u, v): (f64, f64) = (rng.sample(StandardNormal), rng.sample(StandardNormal));
            let (u, v) = (u / corr.0, v / corr.1);
            let (kx, ky) = (c * u - s * v, s * u + c * v);
            let (mut ix, mut iy) = ((kx / k0).round() as i64, (ky / k0).round() as i64);
            // k and -k are one mode: keep the representative with the first non-zero component positive.
            if ix < 0 || (ix == 0 && iy < 0) {
                ix = -ix;
                iy = -iy;
            }
            if (ix == 0 && iy == 0) || ix.abs() > nyq || iy.abs() > nyq || !seen.insert((ix, iy)) {
                continue;
            }
            let phase = rng.random::<f64>() * 2.0 * std::f64::consts::PI;
            modes.push(Mode { kx: ix as f64 * k0, ky: iy as f64 * k0, amp: 1.0, phase });
        }
        if modes.is_empty() {
            return Err(Error::invalid("FourierSurface: no mode fits the grid (correlation length vs spacing)"));
        }
        // Continuous slope variance of one mode: amp^2 |k|^2 / 2.
        let var: f64 = modes.iter().map(|m| 0.5 * (m.kx * m.kx + m.ky * m.ky)).sum();
        let a = rms_slope / var.sqrt();
        for m in &mut modes {
            m.amp = a;
        }
        Ok(FourierSurface { n, dx, modes })
    }

    /// Heights on the grid extended by `pad` samples on every side (the surface is periodic, so the
    /// padding is its exact continuation): `(n + 2 pad)^2` samples, sample `(i, j)` at
    /// `x = (j - pad) dx`, `y = (i - pad) dx`.
    pub fn heightfield(&self, pad: usize) -> Result<Heightfield> {
        let m = self.n + 2 * pad;
        let coords: Vec<f64> = (0..m).map(|i| (i as f64 - pad as f64) * self.dx).collect();
        let mut z = vec![0.0; m * m];
        for md in &self.modes {
            // cos(kx x + ky y + p) = Re(e^{i kx x} e^{i (ky y + p)}), separable per row and column.
            let cx: Vec<(f64, f64)> = coords.iter().map(|x| (md.kx * x).sin_cos()).collect();
            for (i, y) in coords.iter().enumerate() {
                let (sy, cy) = (md.ky * y + md.phase).sin_cos();
                let row = &mut z[i * m..(i + 1) * m];
                for (h, (sx, cxx)) in row.iter_mut().zip(&cx) {
                    *h += md.amp * (cxx * cy - sx * sy);
                }
            }
        }
        let mut hf = Heightfield::new(m, m, self.dx, self.dx, z)?;
        hf.meta.format = "synthetic".into();
        Ok(hf)
    }

    /// Flat indices of the central `n x n` block of [`FourierSurface::heightfield`]`(pad)`.
    pub fn central_points(&self, pad: usize) -> Vec<usize> {
        let m = self.n + 2 * pad;
        (pad..pad + self.n).flat_map(|i| (pad..pad + self.n).map(move |j| i * m + j)).collect()
    }

    /// Exact covariance over one period of the central-difference slopes after a separable filter with
    /// taps `tx`, `ty` (pass `&[1.0]` for none): `sum_k amp^2 / 2 T(k)^2 g(k) g(k)^T` with
    /// `g = (sin(kx dx)/dx, sin(ky dx)/dx)` (central difference of a cosine) and
    /// `T = (sum_j tx_j cos(kx j dx)) (sum_j ty_j cos(ky j dx))` (symmetric taps).
    pub fn slope_cov(&self, tx: &[f64], ty: &[f64]) -> Matrix2<f64> {
        let transfer = |t: &[f64], k: f64| -> f64 {
            let r = (t.len() / 2) as f64;
            t.iter().enumerate().map(|(j, w)| w * (k * (j as f64 - r) * self.dx).cos()).sum()
        };
        self.modes.iter().fold(Matrix2::zeros(), |acc, m| {
            let g = Vector2::new((m.kx * self.dx).sin() / self.dx, (m.ky * self.dx).sin() / self.dx);
            let t = transfer(tx, m.kx) * transfer(ty, m.ky);
            acc + 0.5 * m.amp * m.amp * t * t * g * g.transpose()
        })
    }
}

/// Identical ellipsoid caps on a square lattice: each cell holds the part above `z = 0` of an ellipsoid
/// with semi-axes `(a, b, c)`, rotated by `R = Rx Ry Rz` and centred at height `-depth` in the cell
/// centre; `h = 0` between caps.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BumpField {
    /// Lattice period (m).
    pub period: f64,
    /// Semi-axes (m).
    pub semi_axes: Vector3<f64>,
    /// `(theta_x, theta_y, theta_z)` of the rotation (radians).
    pub angles: Vector3<f64>,
    /// Depth of the ellipsoid centre below the ground (m).
    pub depth: f64,
}

impl BumpField {
    /// Heights on an `n x n` grid of spacing `dx`, or an error when a cap would not fit in its cell.
    pub fn heightfield(&self, n: usize, dx: f64) -> Result<Heightfield> {
        let r = rotation_xyz(self.angles[0], self.angles[1], self.angles[2]);
        let s = Matrix3::from_diagonal(&self.semi_axes.map(|v| 1.0 / (v * v)));
        let q = r.transpose() * s * r; // p^T Q p = 1 on the ellipsoid surface
                                       // The cap's horizontal extent: the ellipsoid's shadow radius bounds it; it must fit in the cell.
        if self.semi_axes.max() >= 0.5 * self.period || self.depth < 0.0 {
            return Err(Error::invalid("BumpField: every semi-axis must be below half the period, depth >= 0"));
        }
        let mut z = vec![0.0; n * n];
        for i in 0..n {
            for j in 0..n {
                let (x, y) = (j as f64 * dx, i as f64 * dx);
                // Position relative to the nearest cell centre.
                let u = x - (x / self.period).floor() * self.period - 0.5 * self.period;
                let v = y - (y / self.period).floor() * self.period - 0.5 * self.period;
                // Solve Q33 w^2 + 2 w (Q13 u + Q23 v) + (Q11 u^2 + 2 Q12 u v + Q22 v^2 - 1) = 0 for the top w.
                let b = q[(0, 2)] * u + q[(1, 2)] * v;
                let c = q[(0, 0)] * u * u + 2.0 * q[(0, 1)] * u * v + q[(1, 1)] * v * v - 1.0;
                let disc = b * b - q[(2, 2)] * c;
                if disc > 0.0 {
                    let w = (-b + disc.sqrt()) / q[(2, 2)] - self.depth;
                    z[i * n + j] = w.max(0.0);
                }
            }
        }
        let mut hf = Heightfield::new(n, n, dx, dx, z)?;
        hf.meta.format = "synthetic".into();
        Ok(hf)
    }
}
