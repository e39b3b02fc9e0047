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

use super::bands::bands_of;
use super::{Band, BandSource, HeightRows, SlopeFrame};

/// Largest relative slope error (whitened, against `max(|s'|, 1)`) of a resolved normal. A relative
/// error `eps` of the slopes that grows as `|s'|^4` (the rim of a bump, `h ~ sqrt(d)`) changes the
/// density by about `6 eps`; see objective.md for the measurement behind the value.
pub const RESOLUTION_TOLERANCE: f64 = 0.005;

/// Whether the central-difference sample at row `i`, column `j` of `hf` (whose 5-point stencil is
/// valid) is unresolved, given its slope `(sx, sy)`.
#[inline(always)]
fn unresolved_at<H: HeightRows>(hf: &H, frame: &SlopeFrame, i: usize, j: usize, sx: f64, sy: f64, tol: f64) -> bool {
    let (nx, ny) = (hf.nx(), hf.ny());
    if j < 2 || j + 2 >= nx || i < 2 || i + 2 >= ny {
        return true;
    }
    let row = hf.row(i);
    let (l2, r2): (f64, f64) = (row[j - 2].into(), row[j + 2].into());
    let (d2, u2): (f64, f64) = (hf.row(i - 2)[j].into(), hf.row(i + 2)[j].into());
    let ex = ((r2 - l2) / (4.0 * hf.dx()) - sx) / 3.0;
    let ey = ((u2 - d2) / (4.0 * hf.dy()) - sy) / 3.0;
    let w = &frame.whiten;
    let (wx, wy) = (w[0][0] * ex + w[0][1] * ey, w[1][0] * ex + w[1][1] * ey);
    let p = frame.to_whitened(sx, sy);
    let r2s = (p[0] * p[0] + p[1] * p[1]).max(1.0);
    // Squared comparison; a NaN (the wide stencil leaves the valid data) counts as unresolved.
    !(wx * wx + wy * wy <= tol * tol * r2s)
}

/// Largest share of all normals unresolved for which the per-bin counts are kept (and the fit's tail cut
/// can apply). Beyond it the surface is rough at the sampling step itself: the Richardson estimate then
/// measures the surface, not a truncation error, and the NDF is by definition that of the pixel footprint.
pub const MAX_UNRESOLVED_SHARE: f64 = 0.25;

/// Visit every central-difference sample of `src` (bands of rows in parallel), folding
/// `f(acc, band, i, j, sx, sy)`; the band holds rows `i - 2 ..= i + 2` (within the grid).
fn fold_samples<S: BandSource, A: Send>(
    src: &S,
    zero: impl Fn() -> A + Sync + Send,
    f: impl Fn(&mut A, &Band<'_, S::T>, usize, usize, f64, f64) + Sync + Send,
    merge: impl Fn(A, A) -> A + Sync + Send,
) -> A {
    let shape = src.shape();
    let (nx, ny) = (shape.nx, shape.ny);
    if nx < 3 || ny < 3 {
        return zero();
    }
    let (dx, dy) = (shape.dx, shape.dy);
    let bands: Vec<std::ops::Range<usize>> = bands_of(1..ny - 1, src.band_rows()).collect();
    bands
        .into_par_iter()
        .fold(&zero, |mut acc, b| {
            let mut buf = Vec::new();
            let band = src.band(b.start.saturating_sub(2), (b.end + 2).min(ny), &mut buf);
            for i in b {
                let (rd, rc, ru) = (band.row(i - 1), band.row(i), band.row(i + 1));
                for j in 1..nx - 1 {
                    let (c, l, r, d, u): (f64, f64, f64, f64, f64) =
                        (rc[j].into(), rc[j - 1].into(), rc[j + 1].into(), rd[j].into(), ru[j].into());
                    if !(c.is_finite() && l.is_finite() && r.is_finite() && d.is_finite() && u.is_finite()) {
                        continue;
                    }
                    f(&mut acc, &band, i, j, (r - l) / (2.0 * dx), (u - d) / (2.0 * dy));
                }
            }
            acc
        })
        .reduce(&zero, merge)
}

/// Fill [`super::EmpiricalNdf::unresolved_share`] and, up to [`MAX_UNRESOLVED_SHARE`],
/// [`super::EmpiricalNdf::unresolved`] for an NDF of central differences counted from `hf` (other
/// schemes are left unassessed). Two passes: the share first (no binning), then the bins of the
/// unresolved normals only.
pub fn assess<S: BandSource>(src: &S, ndf: &mut super::EmpiricalNdf) {
    if ndf.scheme != super::NormalScheme::Central || ndf.grid.n == 0 {
        return;
    }
    let (frame, tol) = (ndf.frame, ndf.resolution_tolerance);
    let (all, bad) = fold_samples(
        src,
        || (0u64, 0u64),
        |a, hf, i, j, sx, sy| {
            a.0 += 1;
            a.1 += unresolved_at(hf, &frame, i, j, sx, sy, tol) as u64;
        },
        |a, b| (a.0 + b.0, a.1 + b.1),
    );
    let share = bad as f64 / all.max(1) as f64;
    ndf.unresolved_share = Some(share);
    ndf.unresolved = Vec::new();
    if !(share <= MAX_UNRESOLVED_SHARE) {
        return;
    }
    let grid = ndf.grid;
    let cells = fold_samples(
        src,
        || vec![0u64; grid.cells()],
        |c, hf, i, j, sx, sy| {
            if unresolved_at(hf, &frame, i, j, sx, sy, tol) {
                c[grid.cell_of(frame.to_lambert(sx, sy))] += 1;
            }
        },
        |mut a, b| {
            a.iter_mut().zip(&b).for_each(|(x, y)| *x += y);
            a
        },
    );
    ndf.unresolved = ndf.bin_cells.iter().map(|&c| cells[c as usize]).collect();
}
