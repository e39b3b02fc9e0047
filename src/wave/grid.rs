//! The diffuse BRDF on a grid of the projected outgoing disk, and what geometric optics of the slopes sends
//! beyond the band the spacing resolves.

use std::path::Path;

use rayon::prelude::*;

use super::{direction, Diffraction};
use crate::error::{Error, Result};
use crate::scan::Scan;

impl Diffraction {
    /// The diffuse BRDF (1/sr, Fresnel excluded) at `lambda_nm` from incidence `(theta_deg, phi_deg)`,
    /// averaged over each cell of an `n x n` grid on the projected outgoing disk: row `i` is
    /// `y = -1 + (2i+1)/n`, column `j` is `x = -1 + (2j+1)/n`, `(x, y) = (sin t_o cos p_o, sin t_o sin p_o)`.
    /// Each FFT bin's energy is spread over the cells its box overlaps, so a cell's energy is its value
    /// times `(2/n)^2` exactly; cells wholly outside the unit disk are 0.
    pub fn grid(&self, lambda_nm: f64, theta_deg: f64, phi_deg: f64, n: usize) -> Vec<f64> {
        let wi = direction(theta_deg, phi_deg);
        let l = lambda_nm * 1e-9;
        let (hx, hy) = (l / (2.0 * self.tiling.px as f64 * self.dx), l / (2.0 * self.tiling.py as f64 * self.dy));
        let cell = 2.0 / n as f64;
        let mut out = vec![0.0; n * n];
        let index = |v: f64| ((v + 1.0) / cell).floor();
        for b in self.bins(lambda_nm, wi) {
            let Some((_, q)) = b.wo else { continue };
            let e = q * b.share / (4.0 * hx * hy);
            let [x, y] = b.xy;
            let (j0, j1) = (index(x - hx).max(0.0) as usize, (index(x + hx).min(n as f64 - 1.0)).max(0.0) as usize);
            let (i0, i1) = (index(y - hy).max(0.0) as usize, (index(y + hy).min(n as f64 - 1.0)).max(0.0) as usize);
            for i in i0..=i1 {
                let (ylo, yhi) = (-1.0 + i as f64 * cell, -1.0 + (i + 1) as f64 * cell);
                let oy = (yhi.min(y + hy) - ylo.max(y - hy)).max(0.0);
                for j in j0..=j1 {
                    let (xlo, xhi) = (-1.0 + j as f64 * cell, -1.0 + (j + 1) as f64 * cell);
                    let ox = (xhi.min(x + hx) - xlo.max(x - hx)).max(0.0);
                    out[i * n + j] += e * ox * oy;
                }
            }
        }
        for i in 0..n {
            for j in 0..n {
                // The cell's nearest point to the centre.
                let near = |k: usize| {
                    let (lo, hi) = (-1.0 + k as f64 * cell, -1.0 + (k + 1) as f64 * cell);
                    if lo > 0.0 {
                        lo
                    } else if hi < 0.0 {
                        -hi
                    } else {
                        0.0
                    }
                };
                let v = &mut out[i * n + j];
                if near(i).hypot(near(j)) >= 1.0 {
                    *v = 0.0;
                } else {
                    *v /= cell * cell;
                }
            }
        }
        out
    }
}

/// The grids of every wavelength and incidence (wavelengths outer): a C-ordered array of shape
/// `(wavelengths, incidences, n, n)`, what `ndfit wave --grid-out` writes. `n` must be in `1..=4096`.
pub fn grids(d: &Diffraction, wavelengths_nm: &[f64], incidences_deg: &[f64], phi_deg: f64, n: usize) -> Result<Vec<f64>> {
    if n == 0 || n > 4096 {
        return Err(Error::invalid(format!("grid {n} is outside 1..=4096")));
    }
    let pairs: Vec<(f64, f64)> = wavelengths_nm.iter().flat_map(|&l| incidences_deg.iter().map(move |&t| (l, t))).collect();
    let grids: Vec<Vec<f64>> = pairs.par_iter().map(|&(l, t)| d.grid(l, t, phi_deg, n)).collect();
    Ok(grids.into_iter().flatten().collect())
}

/// Write [`grids`] as one `float64` `.npy`, atomically.
pub fn write_grid_npy(path: &Path, d: &Diffraction, wavelengths_nm: &[f64], incidences_deg: &[f64], phi_deg: f64, n: usize) -> Result<()> {
    let data = grids(d, wavelengths_nm, incidences_deg, phi_deg, n)?;
    let bytes = crate::io::npy_f64_bytes(&[wavelengths_nm.len(), incidences_deg.len(), n, n], &data);
    crate::io::write_bytes_atomic(path, &bytes)
}

/// The share of the light that single specular reflection on the scan's facets (central-difference
/// slopes) sends from each `(w_i, band)` of `cases` beyond its band (`|x_o + x_i|`, `|y_o + y_i|`), each facet
/// weighted by the projected area it shows the light, `(w_i . m) / (m_z cos_i)`. One pass over the heights;
/// rows summed in order (the same bits on any thread count).
pub(crate) fn geometric_beyond_band(scan: &Scan<'_>, cases: &[([f64; 3], [f64; 2])]) -> Vec<f64> {
    let (nx, ny) = (scan.nx, scan.ny);
    if nx < 3 || ny < 3 {
        return vec![0.0; cases.len()];
    }
    let rows: Vec<Vec<(f64, f64)>> = (1..ny - 1)
        .into_par_iter()
        .map(|i| {
            let (up, row, down) = (scan.row(i - 1), scan.row(i), scan.row(i + 1));
            let mut sums = vec![(0.0, 0.0); cases.len()];
            for j in 1..nx - 1 {
                let sx = (row[j + 1] - row[j - 1]) / (2.0 * scan.dx);
                let sy = (down[j] - up[j]) / (2.0 * scan.dy);
                if !(sx.is_finite() && sy.is_finite()) {
                    continue;
                }
                let norm = (sx * sx + sy * sy + 1.0).sqrt();
                let m = [-sx / norm, -sy / norm, 1.0 / norm];
                for ((wi, band), sum) in cases.iter().zip(sums.iter_mut()) {
                    let c = wi[0] * m[0] + wi[1] * m[1] + wi[2] * m[2];
                    if !(c > 0.0) {
                        continue;
                    }
                    let w = c / m[2];
                    sum.0 += w;
                    let wo = [2.0 * c * m[0] - wi[0], 2.0 * c * m[1] - wi[1]];
                    if (wo[0] + wi[0]).abs() > band[0] || (wo[1] + wi[1]).abs() > band[1] {
                        sum.1 += w;
                    }
                }
            }
            sums
        })
        .collect();
    (0..cases.len())
        .map(|k| {
            let (all, beyond) = rows.iter().fold((0.0, 0.0), |a, r| (a.0 + r[k].0, a.1 + r[k].1));
            if all > 0.0 {
                beyond / all
            } else {
                0.0
            }
        })
        .collect()
}
