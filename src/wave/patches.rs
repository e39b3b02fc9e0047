//! The coherence patches: tiling, the window, each patch's plane, and the patch-averaged spectra of the
//! diffuse field at every level of `v_z`.
//!
//! Patch `p` holds `P_x x P_y` samples; its window is `w = sin^2(pi (j + 1/2) / P)` along each axis
//! (Hann) times the validity mask `m`. With `u = (w m)^2` and `r = h - <h>_u` (heights about the
//! patch's weighted mean, so that no offset meets a phase), at a level `v_z`:
//! - the patch's mean field `chi = sum u exp(i v_z r) / sum u`: its reflection into the mirror direction
//!   within the patch's angular resolution, `|chi|^2` its share of the light (a patch tilted by more than
//!   that resolution sends its light elsewhere: into the diffuse part);
//! - the diffuse field `g = w m (exp(i v_z r) - chi)` and its spectrum `|FFT g|^2`, summed over patches.
//!
//! The patch's least-squares plane (weights `u`) is fitted only to report the patches' tilts.
//!
//! `chi` is the `u`-weighted mean, so the coherent and diffuse energies add up exactly (Parseval): a
//! masked point (weight 0) reflects the patch's mean field, adding no diffuse light.

use rayon::prelude::*;
use rustfft::num_complex::Complex;
use rustfft::{Fft, FftPlanner};
use std::sync::Arc;

use super::levels::Levels;
use crate::scan::Scan;

/// A patch with fewer valid samples than this share is skipped (counted in the report).
pub(crate) const MIN_VALID_SHARE: f64 = 0.9;
/// Patches per unit of parallel work; the sum runs in patch order whatever the thread count.
const CHUNK: usize = 4;

/// The tiling of the scan into patches.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Tiling {
    pub px: usize,
    pub py: usize,
    pub cols: usize,
    pub rows: usize,
    /// First column and row of the tiling (the patches are centred on the grid).
    pub j0: usize,
    pub i0: usize,
}

impl Tiling {
    pub fn new(nx: usize, ny: usize, px: usize, py: usize) -> Tiling {
        let (cols, rows) = (nx / px, ny / py);
        Tiling { px, py, cols, rows, j0: (nx - cols * px) / 2, i0: (ny - rows * py) / 2 }
    }
}

/// What the patches add up to.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Sums {
    /// Per level: `sum_p |FFT g_p|^2`, stored with the x frequency outer: `[kx * P_y + ky]`.
    pub spectra: Vec<Vec<f64>>,
    /// Per level: `sum_p |chi_p|^2 sum u_p`.
    pub coherent: Vec<f64>,
    /// `sum_p sum u_p`.
    pub weight: f64,
    pub used: usize,
    pub skipped: usize,
    /// Sum over used patches of `u`-weighted squared tilt `tan^2` of the patch's plane, and its weight.
    pub tilt2: f64,
    /// Sum over used patches of `sum u^2 / sum u`: with `weight`, the mirror share of incoherent patches.
    pub floor: f64,
}

impl Sums {
    fn zero(levels: usize, bins: usize) -> Sums {
        Sums {
            spectra: vec![vec![0.0; bins]; levels],
            coherent: vec![0.0; levels],
            weight: 0.0,
            used: 0,
            skipped: 0,
            tilt2: 0.0,
            floor: 0.0,
        }
    }

    fn add(&mut self, o: &Sums) {
        for (a, b) in self.spectra.iter_mut().zip(&o.spectra) {
            a.iter_mut().zip(b).for_each(|(x, y)| *x += y);
        }
        self.coherent.iter_mut().zip(&o.coherent).for_each(|(x, y)| *x += y);
        self.weight += o.weight;
        self.used += o.used;
        self.skipped += o.skipped;
        self.tilt2 += o.tilt2;
        self.floor += o.floor;
    }
}

/// The Hann window of `n` samples, never zero (sampled at the cell centres).
pub(crate) fn hann(n: usize) -> Vec<f64> {
    (0..n).map(|j| (std::f64::consts::PI * (j as f64 + 0.5) / n as f64).sin().powi(2)).collect()
}

/// Per-thread FFT plans and buffers.
struct Fft2 {
    row: Arc<dyn Fft<f64>>,
    col: Arc<dyn Fft<f64>>,
    buf: Vec<Complex<f64>>,
    /// One column.
    col_buf: Vec<Complex<f64>>,
    scratch: Vec<Complex<f64>>,
}

impl Fft2 {
    fn new(px: usize, py: usize) -> Fft2 {
        let mut planner = FftPlanner::new();
        // The inverse transform: sum g exp(+i v_t . x), the sign of the phase v_z h (see mod.rs).
        let row = planner.plan_fft_inverse(px);
        let col = planner.plan_fft_inverse(py);
        let s = row.get_inplace_scratch_len().max(col.get_inplace_scratch_len());
        let n = px * py;
        Fft2 { row, col, buf: vec![Complex::default(); n], col_buf: vec![Complex::default(); py], scratch: vec![Complex::default(); s] }
    }
}

/// A patch centred ([`centre`]): its heights about their weighted mean `r`, `u = (w m)^2` and `wm = w m`.
struct Patch {
    r: Vec<f64>,
    u: Vec<f64>,
    wm: Vec<f64>,
}

impl Patch {
    fn new(n: usize) -> Patch {
        Patch { r: vec![0.0; n], u: vec![0.0; n], wm: vec![0.0; n] }
    }
}

/// Sum every patch of `scan` at every level (rayon over chunks of patches, summed in order; a scan of one
/// chunk, too few patches to share out, has its levels side by side instead). Only the x frequencies
/// `columns` are transformed along y and summed; the other bins stay 0.
pub(crate) fn accumulate(
    scan: &Scan<'_>,
    tiling: Tiling,
    levels: &Levels,
    columns: &[usize],
    progress: Option<&(dyn Fn(usize, usize) + Sync)>,
) -> Sums {
    accumulate_as(scan, tiling, levels, columns, progress, tiling.cols * tiling.rows <= CHUNK)
}

/// [`accumulate`], the levels side by side when `by_levels` (a scan of one chunk), else the chunks.
fn accumulate_as(
    scan: &Scan<'_>,
    tiling: Tiling,
    levels: &Levels,
    columns: &[usize],
    progress: Option<&(dyn Fn(usize, usize) + Sync)>,
    by_levels: bool,
) -> Sums {
    let n_patches = tiling.cols * tiling.rows;
    let bins = tiling.px * tiling.py;
    let chunks: Vec<usize> = (0..n_patches.div_ceil(CHUNK)).collect();
    let wave = (rayon::current_num_threads() * 2).max(1);
    let (wx, wy) = (hann(tiling.px), hann(tiling.py));
    if by_levels && chunks.len() == 1 {
        // The chunk's sums are the total's: every sum is of non-negative terms, so adding them to zero
        // changes no bit.
        let part = by_level(scan, tiling, levels, columns, &wx, &wy);
        if let Some(f) = progress {
            f(n_patches, n_patches);
        }
        return part;
    }
    let mut total = Sums::zero(levels.len(), bins);
    for group in chunks.chunks(wave) {
        let parts: Vec<Sums> = group
            .par_iter()
            .map(|&c| {
                let (mut fft, mut centred) = (Fft2::new(tiling.px, tiling.py), Patch::new(bins));
                let mut sums = Sums::zero(levels.len(), bins);
                for p in c * CHUNK..((c + 1) * CHUNK).min(n_patches) {
                    if let Some(s1) = centre_patch(scan, tiling, p, &wx, &wy, &mut centred, &mut sums) {
                        for (l, &vz) in levels.vz.iter().enumerate() {
                            level(&mut fft, &centred, s1, vz, &mut sums.coherent[l], &mut sums.spectra[l], tiling, columns);
                        }
                    }
                }
                sums
            })
            .collect();
        for part in &parts {
            total.add(part);
        }
        if let Some(f) = progress {
            f(((group[group.len() - 1] + 1) * CHUNK).min(n_patches), n_patches);
        }
    }
    total
}

/// The sums of every patch of a scan of one chunk, each level's in its own task: a level's sums take the
/// same values in the same patch order as in [`accumulate`]'s chunks, so the result is theirs to the bit.
fn by_level(scan: &Scan<'_>, t: Tiling, levels: &Levels, columns: &[usize], wx: &[f64], wy: &[f64]) -> Sums {
    let bins = t.px * t.py;
    let mut sums = Sums::zero(0, bins);
    let mut patches = Vec::new();
    for p in 0..t.cols * t.rows {
        let mut c = Patch::new(bins);
        if let Some(s1) = centre_patch(scan, t, p, wx, wy, &mut c, &mut sums) {
            patches.push((c, s1));
        }
    }
    // One group of levels per thread, each with one set of FFT buffers (a patch's are megabytes).
    let threads = rayon::current_num_threads().clamp(1, levels.len().max(1));
    let done: Vec<Vec<(usize, f64, Vec<f64>)>> = (0..threads)
        .into_par_iter()
        .map(|g| {
            let mut fft = Fft2::new(t.px, t.py);
            (g..levels.len())
                .step_by(threads)
                .map(|l| {
                    let (mut coherent, mut spectrum) = (0.0, vec![0.0; bins]);
                    for (c, s1) in &patches {
                        level(&mut fft, c, *s1, levels.vz[l], &mut coherent, &mut spectrum, t, columns);
                    }
                    (l, coherent, spectrum)
                })
                .collect()
        })
        .collect();
    let mut per_level: Vec<(usize, f64, Vec<f64>)> = done.into_iter().flatten().collect();
    per_level.sort_by_key(|x| x.0);
    (sums.coherent, sums.spectra) = per_level.into_iter().map(|(_, c, s)| (c, s)).unzip();
    sums
}

/// Centre patch `p` (row-major over the tiling) into `c` and add its weights to `sums`; its `sum u`, or
/// `None` (counted as skipped) when too few of its points are valid.
fn centre_patch(scan: &Scan<'_>, t: Tiling, p: usize, wx: &[f64], wy: &[f64], c: &mut Patch, sums: &mut Sums) -> Option<f64> {
    let px = t.px;
    let (pi, pj) = (p / t.cols, p % t.cols);
    let (i0, j0) = (t.i0 + pi * t.py, t.j0 + pj * px);
    let row = |i: usize| &scan.row(i0 + i)[j0..j0 + px];
    let Some(k) = centre(row, px, [scan.dx, scan.dy], wx, wy, &mut c.r, &mut c.u, &mut c.wm) else {
        sums.skipped += 1;
        return None;
    };
    sums.used += 1;
    sums.weight += k.s1;
    sums.tilt2 += k.s1 * k.tan2;
    sums.floor += c.u.iter().map(|u| u * u).sum::<f64>() / k.s1;
    Some(k.s1)
}

/// Add one centred patch (weight sum `s1`) at level `vz` to that level's `coherent` sum and, at the x
/// frequencies `columns`, `spectrum`.
#[allow(clippy::too_many_arguments)]
fn level(f: &mut Fft2, c: &Patch, s1: f64, vz: f64, coherent: &mut f64, spectrum: &mut [f64], t: Tiling, columns: &[usize]) {
    let (px, py) = (t.px, t.py);
    let n = px * py;
    // The mean field chi and the diffuse field g.
    let (mut cr, mut ci) = (0.0, 0.0);
    for k in 0..n {
        let u = c.u[k];
        f.buf[k] = if u > 0.0 {
            let (s, co) = (vz * c.r[k]).sin_cos();
            cr += u * co;
            ci += u * s;
            Complex::new(co, s)
        } else {
            Complex::default()
        };
    }
    let chi = Complex::new(cr / s1, ci / s1);
    *coherent += chi.norm_sqr() * s1;
    for k in 0..n {
        let w = c.wm[k];
        if w > 0.0 {
            f.buf[k] = (f.buf[k] - chi) * w;
        }
    }
    // The rows, then each wanted column.
    f.row.process_with_scratch(&mut f.buf, &mut f.scratch);
    for &j in columns {
        for (i, v) in f.col_buf.iter_mut().enumerate() {
            *v = f.buf[i * px + j];
        }
        f.col.process_with_scratch(&mut f.col_buf, &mut f.scratch);
        for (a, v) in spectrum[j * py..(j + 1) * py].iter_mut().zip(&f.col_buf) {
            *a += v.norm_sqr();
        }
    }
}

/// A patch's heights about their `u`-weighted mean, and its plane.
pub(crate) struct Centred {
    /// `sum u`.
    pub s1: f64,
    /// The squared tilt `tan^2` of its `u`-weighted least-squares plane.
    pub tan2: f64,
}

/// Fill `r` (heights about the `u`-weighted mean), `u = (w m)^2` and `wm = w m` for the patch whose row
/// `i` is `row(i)` (`px` samples, `py = wy.len()` rows, spacing `d`); `None` when fewer than
/// [`MIN_VALID_SHARE`] of its points are valid.
#[allow(clippy::too_many_arguments)]
pub(crate) fn centre<'r>(
    row: impl Fn(usize) -> &'r [f64],
    px: usize,
    d: [f64; 2],
    wx: &[f64],
    wy: &[f64],
    r: &mut [f64],
    u: &mut [f64],
    wm: &mut [f64],
) -> Option<Centred> {
    let py = wy.len();
    // Coordinates from the patch centre, so that a huge height offset or position never meets a phase.
    let xc = |j: usize| (j as f64 - 0.5 * (px as f64 - 1.0)) * d[0];
    let yc = |i: usize| (i as f64 - 0.5 * (py as f64 - 1.0)) * d[1];
    let mut valid = 0usize;
    // Weighted plane fit: normal equations of (x, y, 1) with weights u, heights relative to the first
    // valid one (a huge offset cancels before any square is taken).
    let mut href = f64::NAN;
    let (mut sxx, mut sxy, mut syy, mut sx, mut sy, mut s1, mut sxz, mut syz, mut sz) = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0);
    for (i, &wyi) in wy.iter().enumerate() {
        for (j, &h) in row(i)[..px].iter().enumerate() {
            let k = i * px + j;
            if h.is_finite() {
                valid += 1;
                if href.is_nan() {
                    href = h;
                }
                let (x, y, z) = (xc(j), yc(i), h - href);
                let w = wx[j] * wyi;
                let uk = w * w;
                wm[k] = w;
                u[k] = uk;
                r[k] = z;
                sxx += uk * x * x;
                sxy += uk * x * y;
                syy += uk * y * y;
                sx += uk * x;
                sy += uk * y;
                s1 += uk;
                sxz += uk * x * z;
                syz += uk * y * z;
                sz += uk * z;
            } else {
                wm[k] = 0.0;
                u[k] = 0.0;
                r[k] = 0.0;
            }
        }
    }
    if (valid as f64) < MIN_VALID_SHARE * (px * py) as f64 {
        return None;
    }
    // The tilt is reported, not removed: a patch tilted by more than the angular resolution reflects
    // its light away from the mirror direction, into the diffuse part.
    let (a, b) = if sxx == 0.0 || syy == 0.0 {
        // A patch one sample across (a profile's) has no plane across it: its tilt is its line's along it.
        let (s2, sc, s2z) = if syy == 0.0 { (sxx, sx, sxz) } else { (syy, sy, syz) };
        let det = s1 * s2 - sc * sc;
        let t = if det > 0.0 { (s1 * s2z - sc * sz) / det } else { 0.0 };
        if syy == 0.0 {
            (t, 0.0)
        } else {
            (0.0, t)
        }
    } else {
        let m = nalgebra::Matrix3::new(sxx, sxy, sx, sxy, syy, sy, sx, sy, s1);
        let rhs = nalgebra::Vector3::new(sxz, syz, sz);
        match m.lu().solve(&rhs) {
            Some(v) if v.iter().all(|x| x.is_finite()) => (v[0], v[1]),
            _ => (0.0, 0.0),
        }
    };
    let mean = sz / s1;
    for (rk, &uk) in r[..px * py].iter_mut().zip(&u[..px * py]) {
        if uk > 0.0 {
            *rk -= mean;
        }
    }
    Some(Centred { s1, tan2: a * a + b * b })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scan of one chunk summed level by level equals, to the bit, the same scan summed by its chunk:
    /// one, three and four patches (one with a hole that skips it), at several levels.
    #[test]
    fn the_levels_side_by_side_sum_as_the_chunks_do() {
        let (nx, ny) = (64, 48);
        let mut z: Vec<f64> = (0..nx * ny).map(|k| 1e-7 * ((k % nx) as f64 * 0.37).sin() * ((k / nx) as f64 * 0.21).cos()).collect();
        // A hole that skips the second patch of the 2 x 2 tiling and the third of the 3 x 1, and leaves
        // masked points in the others.
        for i in 2..14 {
            for j in 40..60 {
                z[i * nx + j] = f64::NAN;
            }
        }
        let scan = Scan::new(nx, ny, 1e-7, 1e-7, z).expect("valid");
        let levels = Levels::covering(&[(1.1e7, 2.3e7)], 1.1);
        assert!(levels.len() > 4);
        for (px, py) in [(64, 48), (21, 48), (32, 24)] {
            let t = Tiling::new(nx, ny, px, py);
            let all: Vec<usize> = (0..px).collect();
            let a = accumulate_as(&scan, t, &levels, &all, None, true);
            let b = accumulate_as(&scan, t, &levels, &all, None, false);
            assert!(a.used + a.skipped == t.cols * t.rows && a.used > 0, "{px} x {py}: {} used", a.used);
            assert_eq!(a.skipped, usize::from(t.cols * t.rows > 1), "{px} x {py}");
            assert_eq!(a, b, "{px} x {py}");
        }
    }

    /// The sums of some x frequencies alone are the whole transform's at those frequencies, to the bit,
    /// and 0 elsewhere; every other sum is unchanged.
    #[test]
    fn a_few_columns_sum_as_the_whole_transform_does_there() {
        let (nx, ny) = (60, 40);
        let z: Vec<f64> = (0..nx * ny).map(|k| 2e-7 * ((k % nx) as f64 * 0.53).sin() + 1e-7 * ((k / nx) as f64 * 0.29).cos()).collect();
        let scan = Scan::new(nx, ny, 1e-7, 1e-7, z).expect("valid");
        let levels = Levels::covering(&[(1.1e7, 2.3e7)], 1.1);
        for (px, py) in [(60, 40), (20, 20)] {
            let t = Tiling::new(nx, ny, px, py);
            let all: Vec<usize> = (0..px).collect();
            let some = [0, 1, 2, 7, px - 2, px - 1];
            for by_levels in [true, false] {
                let whole = accumulate_as(&scan, t, &levels, &all, None, by_levels);
                let part = accumulate_as(&scan, t, &levels, &some, None, by_levels);
                assert_eq!((part.coherent.clone(), part.weight, part.used), (whole.coherent.clone(), whole.weight, whole.used));
                for (w, p) in whole.spectra.iter().zip(&part.spectra) {
                    for kx in 0..px {
                        let (w, p) = (&w[kx * py..(kx + 1) * py], &p[kx * py..(kx + 1) * py]);
                        if some.contains(&kx) {
                            assert!(w.iter().zip(p).all(|(a, b)| a.to_bits() == b.to_bits()), "{px} x {py}, column {kx}");
                        } else {
                            assert!(p.iter().all(|&v| v == 0.0) && w.iter().any(|&v| v > 0.0), "{px} x {py}, column {kx}");
                        }
                    }
                }
            }
        }
    }
}
