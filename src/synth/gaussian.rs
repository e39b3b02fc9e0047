//! Gaussian random surfaces with a prescribed anisotropic slope covariance, by spectral synthesis.
//!
//! The NDF of a Gaussian surface with slope covariance `Sigma` is the anisotropic Beckmann distribution
//! with `Sigma = Q^-1 / 2` (Heitz eq. 88 and its footnote 3), i.e. `alpha = sqrt(2) sigma` per principal
//! axis, rotated by `theta_z` as in the contract's `beckmann-aniso`: `Sigma = Rz^T diag(sigma_x^2, sigma_y^2) Rz`.
//!
//! Construction: `h = IFFT(H)` on a periodic power-of-two grid with a Hermitian spectrum
//! `H_k = a_k exp(i phi_k)`, random phases `phi_k` and deterministic amplitudes `a_k^2 ~ S(k)`, a Gaussian
//! spectrum `S(k) = exp(-l^2 k^T B k / 4)` (Gaussian autocorrelation of length `l`). Because the
//! amplitudes are deterministic, Parseval gives the realized covariance of the central-difference slopes
//! over the periodic grid exactly: `M = P^-2 sum_k a_k^2 g_k g_k^T` with `g_k = (sin(k_x dx)/dx,
//! sin(k_y dy)/dy)`. `B` is iterated so that `M` has the shape of `Sigma`, then the amplitudes are scaled
//! so that `M = Sigma` to rounding. The slopes are linear in `h`, so (over the random phases) they are
//! Gaussian; each realization's histogram is Gaussian up to the finite number of independent modes,
//! about `(grid extent / l)^2`.

use rayon::prelude::*;
use serde_json::json;

use super::fft::fft2;
use super::{SynthSettings, Truth};
use crate::error::{Error, Result};
use crate::models::{Beckmann, Model};
use crate::scan::Heightfield;
use rand::RngExt;

/// Parameters of a Gaussian surface.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GaussianParams {
    /// RMS slope along the local x axis (`alpha_x = sqrt(2) sigma_x`).
    pub sigma_x: f64,
    /// RMS slope along the local y axis.
    pub sigma_y: f64,
    /// Rotation of the local axes (radians), as `theta_z` of `beckmann-aniso`.
    pub theta_z: f64,
    /// Correlation length (m): the geometric mean of the Gaussian autocorrelation lengths along the
    /// principal axes. At least a few grid spacings keeps central differences close to true slopes.
    pub corr_length: f64,
}

impl Default for GaussianParams {
    fn default() -> Self {
        GaussianParams { sigma_x: 0.2, sigma_y: 0.2, theta_z: 0.0, corr_length: 8e-6 }
    }
}

type Sym2 = [[f64; 2]; 2];

fn inv2(m: Sym2) -> Sym2 {
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    [[m[1][1] / det, -m[0][1] / det], [-m[1][0] / det, m[0][0] / det]]
}

/// The realized slope covariances of the periodic field with amplitudes `a2` (already `|H_k|^2`):
/// central differences, and the lower and upper triangles of the triangulated scheme.
struct Covariances {
    central: Sym2,
    lower: Sym2,
    upper: Sym2,
}

/// Wavenumber of frequency index `f` on a periodic axis of `n` samples spaced `d`.
fn wavenumber(f: usize, n: usize, d: f64) -> f64 {
    let f = if f <= n / 2 { f as f64 } else { f as f64 - n as f64 };
    2.0 * std::f64::consts::PI * f / (n as f64 * d)
}

/// `S(k) = exp(-l^2 k^T B k / 4)` on the grid, zero at DC and on the Nyquist lines (which have no
/// Hermitian partner and no central-difference slope).
fn spectrum(px: usize, py: usize, dx: f64, dy: f64, l: f64, b: Sym2) -> Vec<f64> {
    let mut s = vec![0.0; px * py];
    s.par_chunks_mut(px).enumerate().for_each(|(fy, row)| {
        let ky = wavenumber(fy, py, dy);
        for (fx, v) in row.iter_mut().enumerate() {
            if (fx == 0 && fy == 0) || fx == px / 2 || fy == py / 2 {
                continue;
            }
            let kx = wavenumber(fx, px, dx);
            let q = b[0][0] * kx * kx + 2.0 * b[0][1] * kx * ky + b[1][1] * ky * ky;
            *v = (-0.25 * l * l * q).exp();
        }
    });
    s
}

fn covariances(a2: &[f64], px: usize, py: usize, dx: f64, dy: f64) -> Covariances {
    let norm = 1.0 / ((px * py) as f64).powi(2);
    let sums = a2
        .par_chunks(px)
        .enumerate()
        .map(|(fy, row)| {
            let b = wavenumber(fy, py, dy) * dy;
            let mut acc = [0.0f64; 9];
            for (fx, &w) in row.iter().enumerate() {
                if w == 0.0 {
                    continue;
                }
                let a = wavenumber(fx, px, dx) * dx;
                let (sa, sb) = (a.sin() / dx, b.sin() / dy);
                acc[0] += w * sa * sa;
                acc[1] += w * sa * sb;
                acc[2] += w * sb * sb;
                // Forward differences: x slope (e^{ia} - 1)/dx, y slope (e^{ib} - 1)/dy; the upper triangle's
                // x slope is shifted by one row (e^{ib}) and its y slope by one column (e^{ia}).
                let (ex, ey) = ((a.cos() - 1.0, a.sin()), (b.cos() - 1.0, b.sin()));
                let fx2 = (ex.0 * ex.0 + ex.1 * ex.1) / (dx * dx);
                let fy2 = (ey.0 * ey.0 + ey.1 * ey.1) / (dy * dy);
                // Re[X conj(Y)] for X = ex, Y = ey (lower), X = ex e^{ib}, Y = ey e^{ia} (upper).
                let lower = (ex.0 * ey.0 + ex.1 * ey.1) / (dx * dy);
                let (c, s) = ((b - a).cos(), (b - a).sin());
                // ex conj(ey) e^{i(b-a)}.
                let re_xy = ex.0 * ey.0 + ex.1 * ey.1;
                let im_xy = ex.1 * ey.0 - ex.0 * ey.1;
                let upper = (re_xy * c - im_xy * s) / (dx * dy);
                acc[3] += w * fx2;
                acc[4] += w * lower;
                acc[5] += w * fy2;
                acc[6] += w * upper;
            }
            acc
        })
        .collect::<Vec<_>>()
        // Rows summed in order: a parallel reduce's tree follows work stealing, and the scale it
        // feeds must not change the heights from run to run.
        .into_iter()
        .fold([0.0; 9], |mut x, y| {
            for k in 0..9 {
                x[k] += y[k];
            }
            x
        });
    let s = |v: f64| v * norm;
    Covariances {
        central: [[s(sums[0]), s(sums[1])], [s(sums[1]), s(sums[2])]],
        lower: [[s(sums[3]), s(sums[4])], [s(sums[4]), s(sums[5])]],
        upper: [[s(sums[3]), s(sums[6])], [s(sums[6]), s(sums[5])]],
    }
}

/// The Gaussian surface of `p` on the grid of `s` and its truth (model `beckmann-aniso`).
pub fn gaussian_surface(s: &SynthSettings, p: &GaussianParams) -> Result<(Heightfield, Truth)> {
    s.check()?;
    // The spectral synthesis holds complex FFT buffers besides the heights: more than the readers'
    // per-point estimate (measured peak at 4096^2: 55 bytes per point).
    let points = (s.nx as u64).saturating_mul(s.ny as u64);
    crate::budget::check_bytes(points.saturating_mul(64), &format!("the gaussian synthetic grid of {} x {} points", s.nx, s.ny))?;
    for (name, v) in [("sigma_x", p.sigma_x), ("sigma_y", p.sigma_y), ("corr_length", p.corr_length)] {
        if !(v.is_finite() && v > 0.0) {
            return Err(Error::invalid(format!("{name} must be finite and positive, got {v}")));
        }
    }
    if !p.theta_z.is_finite() {
        return Err(Error::invalid(format!("theta_z must be finite, got {}", p.theta_z)));
    }
    let model = Beckmann::new(std::f64::consts::SQRT_2 * p.sigma_x, std::f64::consts::SQRT_2 * p.sigma_y, p.theta_z)?;
    // Target Sigma = Rz^T diag Rz (contract convention: the model reads m' = Rz m).
    let (sn, cs) = p.theta_z.sin_cos();
    let (vx, vy) = (p.sigma_x * p.sigma_x, p.sigma_y * p.sigma_y);
    let target: Sym2 = [[cs * cs * vx + sn * sn * vy, cs * sn * (vy - vx)], [cs * sn * (vy - vx), sn * sn * vx + cs * cs * vy]];
    let (px, py) = (s.nx.next_power_of_two(), s.ny.next_power_of_two());

    // Shape iteration: B^-1 starts proportional to Sigma (det B = 1) and is corrected until the discrete
    // covariance has Sigma's shape (relative residual < 1e-12 or 30 rounds).
    let tr_t = target[0][0] + target[1][1];
    let det_t = target[0][0] * target[1][1] - target[0][1] * target[0][1];
    let mut binv: Sym2 = target.map(|r| r.map(|v| v / det_t.sqrt()));
    let mut amp2 = Vec::new();
    let mut cov = None;
    for _ in 0..30 {
        amp2 = spectrum(px, py, s.dx, s.dy, p.corr_length, inv2(binv));
        let c = covariances(&amp2, px, py, s.dx, s.dy);
        let m = c.central;
        let tr_m = m[0][0] + m[1][1];
        if !(tr_m > 0.0 && tr_m.is_finite()) {
            return Err(Error::invalid(format!(
                "correlation length {} m is too long or too short for the grid: no slope variance",
                p.corr_length
            )));
        }
        let tr_b = binv[0][0] + binv[1][1];
        let mut resid = 0.0f64;
        for i in 0..2 {
            for j in 0..2 {
                let r = target[i][j] / tr_t - m[i][j] / tr_m;
                resid = resid.max(r.abs());
                binv[i][j] += r * tr_b;
            }
        }
        cov = Some(c);
        if resid < 1e-12 {
            break;
        }
    }
    let c = cov.ok_or_else(|| Error::invalid("spectral synthesis did not run"))?;
    // Scale so the realized central-difference covariance equals Sigma.
    let scale = tr_t / (c.central[0][0] + c.central[1][1]);
    let sc = |m: Sym2| m.map(|r| r.map(|v| v * scale));
    let (central, lower, upper) = (sc(c.central), sc(c.lower), sc(c.upper));

    // Hermitian random-phase spectrum.
    let mut rng = s.rng(0);
    let n = px * py;
    let (mut re, mut im) = (vec![0.0; n], vec![0.0; n]);
    for fy in 0..py {
        for fx in 0..px {
            let idx = fy * px + fx;
            let neg = ((py - fy) % py) * px + (px - fx) % px;
            let a = (amp2[idx] * scale).sqrt();
            if idx < neg {
                let phi = 2.0 * std::f64::consts::PI * rng.random::<f64>();
                re[idx] = a * phi.cos();
                im[idx] = a * phi.sin();
            } else if idx > neg {
                re[idx] = re[neg];
                im[idx] = -im[neg];
            }
        }
    }
    fft2(&mut re, &mut im, px, py, true);
    let inv_n = 1.0 / n as f64;
    let mut z = Vec::with_capacity(s.nx * s.ny);
    for i in 0..s.ny {
        z.extend(re[i * px..i * px + s.nx].iter().map(|v| v * inv_n));
    }
    drop((re, im));
    let hf = s.finish(z)?;
    let settings = json!({"grid": s, "gaussian": p, "fft_grid": [px, py]});
    let derived = json!({
        "slope_cov_target": target,
        "slope_cov_central": central,
        "slope_cov_triangles_lower": lower,
        "slope_cov_triangles_upper": upper,
        "periodic": px == s.nx && py == s.ny,
    });
    Ok((hf, Truth::for_model(&Model::BeckmannAniso(model), "gaussian", settings, derived)))
}
