//! Which normals the sampling resolves (`data_formats/objective.md`, "The tail the scan cannot resolve").
//!
//! The central difference `s = (h[j+1] - h[j-1]) / 2dx` has the truncation error `-(dx^2 / 6) h'''`; the
//! difference over twice the step, `s2 = (h[j+2] - h[j-2]) / 4dx`, four times that. Richardson's
//! estimate of the first is therefore `e = (s2 - s) / 3`, from the data alone. A sample is **unresolved**
//! when its error, whitened by the robust frame ([`SlopeFrame`]), exceeds [`RESOLUTION_TOLERANCE`] of its
//! whitened slope radius (at least of one robust scale), or when the wider stencil leaves the valid data
//! (the rim of a bump, the edge of a dropout: there the error cannot be bounded). The NDF keeps, per bin,
//! how many of its normals are unresolved ([`super::EmpiricalNdf::unresolved`]); the fit leaves out the
//! bins where they are the majority.

use rayon::prelude::*;

use super::{BinGrid, HeightRows, SlopeFrame};

/// Largest relative slope error (whitened, against `max(|s'|, 1)`) of a resolved normal. A relative
/// error `eps` of the slopes that grows as `|s'|^4` (the rim of a bump, `h ~ sqrt(d)`) changes the
/// density by about `6 eps`; see objective.md for the measurement behind the value.
pub const RESOLUTION_TOLERANCE: f64 = 0.005;

/// Whether the central-difference sample at row `i`, column `j` of `hf` (whose 5-point stencil is
/// valid) is unresolved, given its slope `(sx, sy)`.
#[inline]
fn unresolved_at<H: HeightRows>(hf: &H, frame: &SlopeFrame, i: usize, j: usize, sx: f64, sy: f64, tol: f64) -> bool {
    let (nx, ny) = (hf.nx(), hf.ny());
    if j < 2 || j + 2 >= nx || i < 2 || i + 2 >= ny {
        return true;
    }
    let h = |i: usize, j: usize| -> f64 { hf.row(i)[j].into() };
    let (l2, r2, d2, u2) = (h(i, j - 2), h(i, j + 2), h(i - 2, j), h(i + 2, j));
    if !(l2.is_finite() && r2.is_finite() && d2.is_finite() && u2.is_finite()) {
        return true;
    }
    let ex = ((r2 - l2) / (4.0 * hf.dx()) - sx) / 3.0;
    let ey = ((u2 - d2) / (4.0 * hf.dy()) - sy) / 3.0;
    let w = &frame.whiten;
    let e = (w[0][0] * ex + w[0][1] * ey).hypot(w[1][0] * ex + w[1][1] * ey);
    let p = frame.to_whitened(sx, sy);
    !(e <= tol * p[0].hypot(p[1]).max(1.0))
}

/// Per grid cell of `grid` over `frame`: the central-difference normals counted and those unresolved
/// (tolerance `tol`, [`RESOLUTION_TOLERANCE`] by default).
pub fn cell_counts<H: HeightRows>(hf: &H, frame: &SlopeFrame, grid: &BinGrid, tol: f64) -> (Vec<u64>, Vec<u64>) {
    let (nx, ny) = (hf.nx(), hf.ny());
    let cells = grid.cells();
    let zero = || (vec![0u64; cells], vec![0u64; cells]);
    if nx < 3 || ny < 3 {
        return zero();
    }
    let (dx, dy) = (hf.dx(), hf.dy());
    (1..ny - 1)
        .into_par_iter()
        .fold(zero, |(mut all, mut bad), i| {
            let (rd, rc, ru) = (hf.row(i - 1), hf.row(i), hf.row(i + 1));
            for j in 1..nx - 1 {
                let (c, l, r, d, u): (f64, f64, f64, f64, f64) = (rc[j].into(), rc[j - 1].into(), rc[j + 1].into(), rd[j].into(), ru[j].into());
                if !(c.is_finite() && l.is_finite() && r.is_finite() && d.is_finite() && u.is_finite()) {
                    continue;
                }
                let (sx, sy) = ((r - l) / (2.0 * dx), (u - d) / (2.0 * dy));
                let k = grid.cell_of(frame.to_lambert(sx, sy));
                all[k] += 1;
                if unresolved_at(hf, frame, i, j, sx, sy, tol) {
                    bad[k] += 1;
                }
            }
            (all, bad)
        })
        .reduce(zero, |(mut a, mut b), (c, d)| {
            a.iter_mut().zip(&c).for_each(|(x, y)| *x += y);
            b.iter_mut().zip(&d).for_each(|(x, y)| *x += y);
            (a, b)
        })
}

/// Fill [`super::EmpiricalNdf::unresolved`] for an NDF of central differences counted from `hf` (other
/// schemes are left unassessed).
pub fn assess<H: HeightRows>(hf: &H, ndf: &mut super::EmpiricalNdf) {
    if ndf.scheme != super::NormalScheme::Central || ndf.grid.n == 0 {
        return;
    }
    let (_, bad) = cell_counts(hf, &ndf.frame, &ndf.grid, ndf.resolution_tolerance);
    ndf.unresolved = ndf.bin_cells.iter().map(|&c| bad[c as usize]).collect();
}
