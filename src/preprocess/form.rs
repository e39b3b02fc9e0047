//! Least-squares form removal over the valid points: polynomials up to order 3 (order 1 is the mean
//! plane) and cylinders (bullet lands, turned parts).
//!
//! Polynomials are fitted in a Legendre basis `P_p(u) P_q(v)`, `p + q <= order`, on coordinates
//! scaled to `[-1, 1]` over the grid, with the mean height subtracted first: the normal equations stay
//! well conditioned even for heights with a huge absolute offset (a 76 mm stage height under
//! sub-micrometre roughness). NaN points take no part in the fit and stay NaN.

use nalgebra::{DMatrix, DVector};
use rayon::prelude::*;

use crate::error::{Error, ErrorKind, Result};
use crate::scan::bands::{BandSource, GridShape, HeightRows};
use crate::scan::Scan;

/// Legendre polynomials P_0..P_3 at `u`.
#[inline]
fn legendre(u: f64) -> [f64; 4] {
    [1.0, u, 0.5 * (3.0 * u * u - 1.0), 0.5 * (5.0 * u * u * u - 3.0 * u)]
}

/// Exponent pairs (p, q) with p + q <= order.
fn terms(order: usize) -> Vec<(usize, usize)> {
    let mut t = Vec::new();
    for s in 0..=order {
        for p in (0..=s).rev() {
            t.push((p, s - p));
        }
    }
    t
}

/// Grid coordinate `k` of `n` mapped to [-1, 1] (0 when the axis has a single sample).
#[inline]
fn scaled(k: usize, n: usize) -> f64 {
    if n > 1 {
        2.0 * k as f64 / (n - 1) as f64 - 1.0
    } else {
        0.0
    }
}

/// Rows per task of the parallel passes. Fixed (not derived from the thread count) and summed in row
/// order, so the fit is bit-identical whatever the number of threads (batch results must be).
const ROWS_PER_TASK: usize = 16;

/// Most terms of a polynomial form (order 3: 10).
const MAX_TERMS: usize = 10;

/// The least-squares polynomial of total degree `order` (0..=3) fitted to the valid heights, evaluated
/// on the whole grid (NaN where the input is NaN). Returns the residual heights.
///
/// Three passes over the heights, each split over the rayon threads by blocks of `ROWS_PER_TASK`
/// rows: the count and mean of the valid heights, the normal equations (fixed-size, upper triangle),
/// and the residuals (`fit_polynomial`, then `FormModel::residual`).
pub fn remove_polynomial(hf: &Scan, order: usize) -> Result<Vec<f64>> {
    Ok(fit_polynomial(hf, order)?.residual(hf))
}

/// A fitted polynomial form: what [`remove_polynomial`] subtracts, applied row by row
/// ([`FormModel::residual_row`]) so that the residual heights can be made one band at a time (the
/// form folded into each band's slopes, [`crate::preprocess::Prepared`]) with the same arithmetic, bit
/// for bit, as the whole-grid residual.
#[derive(Debug, Clone, PartialEq)]
pub struct FormModel {
    /// The mean of the valid heights, subtracted first.
    mean: f64,
    /// How many heights were valid (not NaN) in the fit.
    valid: usize,
    /// The largest magnitude of the valid heights.
    top: f64,
    kind: FormKind,
}

#[derive(Debug, Clone, PartialEq)]
enum FormKind {
    /// `c0 + c1 u + c2 v` ([`plane_fit`]'s fit): `u` per column, and per row `base = c0 + c2 v`, taken
    /// once here so that a residual point by point ([`FormModel::residual_at`]) costs no division.
    Plane { c: [f64; 3], u: Vec<f64>, base: Vec<f64> },
    /// `sum_k coef_k P_p(u) P_q(v)` over the terms `(p, q)`.
    Poly { coef: Vec<f64>, t: Vec<(usize, usize)>, lu: Vec<[f64; 4]>, lv: Vec<[f64; 4]> },
}

/// Independent partial sums per row in [`plane_row_sums`] (one 4-wide vector per sum).
const PLANE_LANES: usize = 4;

/// The plane fit's sums over one row of heights `h` at the scaled columns `u`: the count, `sum u`,
/// `sum u^2`, `sum r` and `sum u r` over the valid heights (`r = h - mean`), each in
/// [`PLANE_LANES`] partial sums by column (a NaN height adds `+0.0` to each).
/// On CPUs with AVX2 the lanes are one vector register per sum (the same IEEE operations, the same sums).
fn plane_row_sums(h: &[f64], u: &[f64], mean: f64) -> [f64; 5] {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { plane_row_sums_avx2(h, u, mean) };
    }
    plane_row_sums_body(h, u, mean)
}

/// [`plane_row_sums_body`] with the lanes in AVX2 registers. The compiler turns the body's selects into
/// a branch per point; here a valid height's terms are kept by an AND with its ordered-compare mask
/// (all ones, or zero for a NaN: `+0.0`, as the select gives). Multiplications and additions stay
/// separate (no FMA), so every lane is the body's, bit for bit.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn plane_row_sums_avx2(h: &[f64], u: &[f64], mean: f64) -> [f64; 5] {
    use std::arch::x86_64::*;
    const L: usize = PLANE_LANES;
    const _: () = assert!(L == 4);
    let u = &u[..h.len()];
    let (hc, uc) = (h.chunks_exact(L), u.chunks_exact(L));
    let (hr, ur) = (hc.remainder(), uc.remainder());
    let (one, mv) = (_mm256_set1_pd(1.0), _mm256_set1_pd(mean));
    let mut acc = [_mm256_setzero_pd(); 5];
    for (h4, u4) in hc.zip(uc) {
        // SAFETY: each chunk holds 4 f64 (`chunks_exact`); the loads are unaligned.
        let (hv, xv) = unsafe { (_mm256_loadu_pd(h4.as_ptr()), _mm256_loadu_pd(u4.as_ptr())) };
        let keep = _mm256_cmp_pd::<_CMP_ORD_Q>(hv, hv);
        let m = _mm256_and_pd(keep, one);
        let x = _mm256_and_pd(keep, xv);
        let r = _mm256_and_pd(keep, _mm256_sub_pd(hv, mv));
        acc[0] = _mm256_add_pd(acc[0], m);
        acc[1] = _mm256_add_pd(acc[1], x);
        acc[2] = _mm256_add_pd(acc[2], _mm256_mul_pd(x, x));
        acc[3] = _mm256_add_pd(acc[3], r);
        acc[4] = _mm256_add_pd(acc[4], _mm256_mul_pd(x, r));
    }
    let mut lanes = [[0.0f64; L]; 5];
    for (l, a) in lanes.iter_mut().zip(acc) {
        // SAFETY: `l` is 4 f64; the store is unaligned.
        unsafe { _mm256_storeu_pd(l.as_mut_ptr(), a) };
    }
    for (k, (&h, &x)) in hr.iter().zip(ur).enumerate() {
        plane_add(&mut lanes, k, h, x, mean);
    }
    lanes.map(|l| l.iter().sum::<f64>())
}

/// Add one point (height `h` at column `x`) to lane `k` of the plane's sums; a NaN height adds `+0.0`.
#[inline(always)]
fn plane_add(lanes: &mut [[f64; PLANE_LANES]; 5], k: usize, h: f64, x: f64, mean: f64) {
    let ok = !h.is_nan();
    let r = if ok { h - mean } else { 0.0 };
    let (m, x) = (if ok { 1.0 } else { 0.0 }, if ok { x } else { 0.0 });
    lanes[0][k] += m;
    lanes[1][k] += x;
    lanes[2][k] += x * x;
    lanes[3][k] += r;
    lanes[4][k] += x * r;
}

/// The portable loop of [`plane_row_sums`].
fn plane_row_sums_body(h: &[f64], u: &[f64], mean: f64) -> [f64; 5] {
    const L: usize = PLANE_LANES;
    let mut lanes = [[0.0f64; L]; 5];
    let (hc, uc) = (h.chunks_exact(L), u[..h.len()].chunks_exact(L));
    let (hr, ur) = (hc.remainder(), uc.remainder());
    for (h4, u4) in hc.zip(uc) {
        for k in 0..L {
            plane_add(&mut lanes, k, h4[k], u4[k], mean);
        }
    }
    for (k, (&h, &x)) in hr.iter().zip(ur).enumerate() {
        plane_add(&mut lanes, k, h, x, mean);
    }
    lanes.map(|l| l.iter().sum::<f64>())
}

/// Blocks of rows whose sums the mean's pass takes side by side ([`counts_and_sums`] is written for four).
const MEAN_CHAINS: usize = 4;
const _: () = assert!(MEAN_CHAINS == 4);

/// The count, the sum and the largest magnitude of the non-NaN values of each slice, as a serial
/// `filter` and `fold` gives them (each sum in its own order, bit for bit). A serial sum waits on each
/// addition; the sums of [`MEAN_CHAINS`] slices are taken side by side so that their additions overlap
/// (one slice per AVX2 lane where the CPU has it, [`chains_avx2`]).
/// A NaN adds `+0.0`, which leaves a sum that starts at `+0.0` unchanged (it is never `-0.0`), and
/// `max` skips it.
fn counts_and_sums(vals: &[&[f64]]) -> Vec<(usize, f64, f64)> {
    let mut out = vec![(0usize, 0.0f64, 0.0f64); vals.len()];
    let n = if vals.len() == MEAN_CHAINS { vals.iter().map(|v| v.len()).min().unwrap_or(0) } else { 0 };
    if n > 0 {
        let (mut k, mut s, mut m, first) = chains([&vals[0][..n], &vals[1][..n], &vals[2][..n], &vals[3][..n]]);
        let (a, b, c, d) = (&vals[0][first..n], &vals[1][first..n], &vals[2][first..n], &vals[3][first..n]);
        for (((&a, &b), &c), &d) in a.iter().zip(b).zip(c).zip(d) {
            for (q, v) in [a, b, c, d].into_iter().enumerate() {
                let ok = !v.is_nan();
                k[q] += ok as usize;
                s[q] += if ok { v } else { 0.0 };
                m[q] = m[q].max(v.abs());
            }
        }
        for (q, o) in out.iter_mut().enumerate() {
            *o = (k[q], s[q], m[q]);
        }
    }
    for (o, v) in out.iter_mut().zip(vals) {
        *o = v[n..].iter().filter(|h| !h.is_nan()).fold(*o, |(c, s, m), h| (c + 1, s + h, m.max(h.abs())));
    }
    out
}

/// Counts, sums and largest magnitudes of the four slices `v` (of one length) as far as [`chains_avx2`]
/// takes them where the CPU has AVX2, and the number of values taken (none elsewhere).
fn chains(v: [&[f64]; MEAN_CHAINS]) -> ([usize; MEAN_CHAINS], [f64; MEAN_CHAINS], [f64; MEAN_CHAINS], usize) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU supports AVX2 (checked just above).
        return unsafe { chains_avx2(v) };
    }
    let _ = v;
    ([0; MEAN_CHAINS], [0.0; MEAN_CHAINS], [0.0; MEAN_CHAINS], 0)
}

/// The loop of [`counts_and_sums`] over the first `4 floor(n / 4)` values of four slices of length `n`,
/// one slice per AVX2 lane: four values of each slice are loaded and transposed, then added in their
/// order. A NaN's lane is masked to `+0.0` by its ordered-compare mask (the select of the scalar loop),
/// `max` keeps the running value for a NaN, and nothing is contracted: each lane is the scalar loop's
/// count, sum and largest magnitude, bit for bit. Returns them and the number of values taken.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn chains_avx2(v: [&[f64]; MEAN_CHAINS]) -> ([usize; MEAN_CHAINS], [f64; MEAN_CHAINS], [f64; MEAN_CHAINS], usize) {
    use std::arch::x86_64::*;
    let n = v[0].len() / 4 * 4;
    let (mut s, mut m, mut k) = (_mm256_setzero_pd(), _mm256_setzero_pd(), _mm256_setzero_si256());
    let abs = _mm256_castsi256_pd(_mm256_set1_epi64x(i64::MAX));
    for i in (0..n).step_by(4) {
        // SAFETY: i + 4 <= n <= each slice's length.
        let r = v.map(|x| unsafe { _mm256_loadu_pd(x.as_ptr().add(i)) });
        let (t0, t1) = (_mm256_unpacklo_pd(r[0], r[1]), _mm256_unpackhi_pd(r[0], r[1]));
        let (t2, t3) = (_mm256_unpacklo_pd(r[2], r[3]), _mm256_unpackhi_pd(r[2], r[3]));
        // Value q of every slice, q = 0..4, in slice order across the lanes.
        let q = [
            _mm256_permute2f128_pd::<0x20>(t0, t2),
            _mm256_permute2f128_pd::<0x20>(t1, t3),
            _mm256_permute2f128_pd::<0x31>(t0, t2),
            _mm256_permute2f128_pd::<0x31>(t1, t3),
        ];
        for x in q {
            let ok = _mm256_cmp_pd::<_CMP_ORD_Q>(x, x);
            s = _mm256_add_pd(s, _mm256_and_pd(x, ok));
            k = _mm256_sub_epi64(k, _mm256_castpd_si256(ok));
            // maxpd gives its second operand when the first is NaN.
            m = _mm256_max_pd(_mm256_and_pd(x, abs), m);
        }
    }
    let (mut ks, mut ss, mut ms) = ([0i64; MEAN_CHAINS], [0.0; MEAN_CHAINS], [0.0; MEAN_CHAINS]);
    // SAFETY: each array holds four lanes.
    unsafe {
        _mm256_storeu_si256(ks.as_mut_ptr().cast(), k);
        _mm256_storeu_pd(ss.as_mut_ptr(), s);
        _mm256_storeu_pd(ms.as_mut_ptr(), m);
    }
    (ks.map(|c| c as usize), ss, ms, n)
}

/// A plane's residual: the height less the mean, less the plane `base + c1 u` (`base = c0 + c2 v`).
#[inline(always)]
fn plane_residual(h: f64, mean: f64, base: f64, c1: f64, u: f64) -> f64 {
    (h - mean) - (base + c1 * u)
}

impl FormModel {
    /// Row `i` of the residual: `out[j] = (h[j] - mean) - form(i, j)` (NaN stays NaN), appended.
    #[inline]
    pub fn residual_row(&self, i: usize, h: &[f64], out: &mut Vec<f64>) {
        let mean = self.mean;
        match &self.kind {
            FormKind::Plane { c, u, base } => {
                let base = base[i];
                out.extend(h.iter().zip(u).map(|(&h, &x)| plane_residual(h, mean, base, c[1], x)));
            }
            FormKind::Poly { .. } => out.extend(h.iter().enumerate().map(|(j, &h)| (h - mean) - self.poly_at(i, j))),
        }
    }

    /// The residual at row `i`, column `j` of the height `h` there: the value [`FormModel::residual_row`]
    /// gives, bit for bit.
    #[inline]
    pub fn residual_at(&self, i: usize, j: usize, h: f64) -> f64 {
        match &self.kind {
            FormKind::Plane { c, u, base } => plane_residual(h, self.mean, base[i], c[1], u[j]),
            FormKind::Poly { .. } => (h - self.mean) - self.poly_at(i, j),
        }
    }

    /// A polynomial form's value at row `i`, column `j` (less the mean).
    #[inline(always)]
    fn poly_at(&self, i: usize, j: usize) -> f64 {
        let FormKind::Poly { coef, t, lu, lv } = &self.kind else { return 0.0 };
        let mut f = 0.0;
        for (k, &(p, q)) in t.iter().enumerate() {
            f += coef[k] * lu[j][p] * lv[i][q];
        }
        f
    }

    /// For a plane, the sum of the magnitudes of its mean and coefficients (on the scaled axes `u`,
    /// `v` in [-1, 1]): bounds the plane's value anywhere on the grid, and so the rounding a residual
    /// carries. `None` for other forms.
    pub fn plane_magnitude(&self) -> Option<f64> {
        match &self.kind {
            FormKind::Plane { c, .. } => Some(self.mean.abs() + c.iter().map(|v| v.abs()).sum::<f64>()),
            FormKind::Poly { .. } => None,
        }
    }

    /// The largest magnitude of the fitted grid's valid heights, found by the fit's first pass.
    pub fn largest_height(&self) -> f64 {
        self.top
    }

    /// How many heights of the fitted grid are valid (not NaN), counted by the fit's first pass.
    pub fn valid(&self) -> usize {
        self.valid
    }

    /// The form's constant slope `grad form` (m/m) on a grid of spacing `dx`, `dy`, when it is a plane:
    /// every difference scheme is exact on a plane, so each slope of the residual is the slope of the raw
    /// heights minus this (up to rounding), and passes that need only slopes can read the raw heights.
    pub fn plane_slope(&self, dx: f64, dy: f64) -> Option<[f64; 2]> {
        match &self.kind {
            // `u = 2 j / (nx - 1) - 1` per column and `v = 2 i / (ny - 1) - 1` per row ([`scaled`]).
            FormKind::Plane { c, u, base } => {
                let per = |n: usize, d: f64| if n > 1 { 2.0 / ((n - 1) as f64 * d) } else { 0.0 };
                Some([c[1] * per(u.len(), dx), c[2] * per(base.len(), dy)])
            }
            FormKind::Poly { .. } => None,
        }
    }

    /// The residual heights of the whole grid `hf` (the form's own grid).
    pub fn residual<S: BandSource<T = f64>>(&self, hf: &S) -> Vec<f64> {
        let GridShape { nx, ny, .. } = hf.shape();
        let mut out = vec![0.0; nx * ny];
        let step = hf.band_rows();
        out.par_chunks_mut((nx * step).max(1)).enumerate().for_each(|(b, o)| {
            let lo = b * step;
            let hi = (lo + step).min(ny);
            let mut buf = Vec::new();
            let band = hf.band(lo, hi, &mut buf);
            let mut row = Vec::with_capacity(nx);
            for (i, o) in (lo..hi).zip(o.chunks_mut(nx.max(1))) {
                row.clear();
                self.residual_row(i, band.row(i), &mut row);
                o.copy_from_slice(&row);
            }
        });
        out
    }
}

/// Fit the least-squares polynomial of total degree `order` (0..=3) to the valid heights of `hf` (see
/// [`remove_polynomial`]); the heights are read in bands of rows and never copied.
pub fn fit_polynomial<S: BandSource<T = f64>>(hf: &S, order: usize) -> Result<FormModel> {
    polynomial_fit(hf, order, true)
}

/// [`fit_polynomial`]; `plane_path`: take [`plane_fit`] for the plane (off only to test it against
/// the general term loop).
fn polynomial_fit<S: BandSource<T = f64>>(src: &S, order: usize, plane_path: bool) -> Result<FormModel> {
    if order > 3 {
        return Err(Error::invalid(format!("polynomial form order {order} is above 3")));
    }
    let shape = src.shape();
    let (nx, ny) = (shape.nx, shape.ny);
    // An axis with one sample cannot carry a slope along it; drop those terms rather than solve a
    // singular system.
    let all = terms(order);
    let t: Vec<(usize, usize)> = all.into_iter().filter(|&(p, q)| (p == 0 || nx > 1) && (q == 0 || ny > 1)).collect();
    let m = t.len();
    let starts: Vec<usize> = (0..ny).step_by(ROWS_PER_TASK).collect();
    let rows_of = |i0: usize| i0..(i0 + ROWS_PER_TASK).min(ny);
    // Blocks taken MEAN_CHAINS at a time, their sums side by side (each in its own order).
    let sums: Vec<(usize, f64, f64)> = starts
        .par_chunks(MEAN_CHAINS)
        .flat_map_iter(|group| {
            let mut bufs: [Vec<f64>; MEAN_CHAINS] = Default::default();
            let bands: Vec<_> = group.iter().zip(bufs.iter_mut()).map(|(&i0, buf)| src.band(i0, rows_of(i0).end, buf)).collect();
            counts_and_sums(&bands.iter().map(|b| b.values()).collect::<Vec<_>>())
        })
        .collect();
    let valid: usize = sums.iter().map(|p| p.0).sum();
    if valid < m {
        return Err(Error::new(ErrorKind::BadData, format!("{valid} valid points cannot determine a {m}-term form of order {order}")));
    }
    let mean = sums.iter().map(|p| p.1).sum::<f64>() / valid as f64;
    let top = sums.iter().fold(0.0f64, |m, p| m.max(p.2));
    if plane_path && t == [(0, 0), (1, 0), (0, 1)] {
        return plane_fit(src, mean, valid, top);
    }
    let lu: Vec<[f64; 4]> = (0..nx).map(|j| legendre(scaled(j, nx))).collect();
    let lv: Vec<[f64; 4]> = (0..ny).map(|i| legendre(scaled(i, ny))).collect();
    let partial: Vec<([[f64; MAX_TERMS]; MAX_TERMS], [f64; MAX_TERMS])> = starts
        .par_iter()
        .map(|&i0| {
            let mut ata = [[0.0; MAX_TERMS]; MAX_TERMS];
            let mut atb = [0.0; MAX_TERMS];
            let mut row = [0.0; MAX_TERMS];
            let mut buf = Vec::new();
            let band = src.band(i0, rows_of(i0).end, &mut buf);
            for i in rows_of(i0) {
                for (j, &h) in band.row(i).iter().enumerate() {
                    if h.is_nan() {
                        continue;
                    }
                    let r = h - mean;
                    for (k, &(p, q)) in t.iter().enumerate() {
                        row[k] = lu[j][p] * lv[i][q];
                    }
                    for a in 0..m {
                        atb[a] += row[a] * r;
                        for b in a..m {
                            ata[a][b] += row[a] * row[b];
                        }
                    }
                }
            }
            (ata, atb)
        })
        .collect();
    let mut ata = DMatrix::<f64>::zeros(m, m);
    let mut atb = DVector::<f64>::zeros(m);
    for (pa, pb) in &partial {
        for a in 0..m {
            atb[a] += pb[a];
            for b in a..m {
                ata[(a, b)] += pa[a][b];
            }
        }
    }
    for a in 0..m {
        for b in 0..a {
            ata[(a, b)] = ata[(b, a)];
        }
    }
    // SVD with a relative cut-off: the valid points may not span the basis (a mask that leaves one
    // line of points); the minimum-norm solution is then still a least-squares fit.
    let svd = ata.svd(true, true);
    let smax = svd.singular_values.max();
    let coef = svd.solve(&atb, smax * 1e-12).map_err(|e| Error::new(ErrorKind::Numerical, format!("form fit failed: {e}")))?;
    Ok(FormModel { mean, valid, top, kind: FormKind::Poly { coef: coef.iter().copied().collect(), t, lu, lv } })
}

/// The plane case of [`fit_polynomial`] (basis `1, u, v`, both axes longer than one sample), the
/// default preprocessing of every command: the same fit, with per-row sums in place of the general
/// term loop, so that the pass runs in vector lanes (NaN points masked by a select).
///
/// Normal equations: a row `i` at `v_i` contributes `n, sum u, sum u^2, sum r, sum u r` over its valid
/// points (`r = h - mean`), and the `v` entries are those times `v_i` or `v_i^2`.
fn plane_fit<S: BandSource<T = f64>>(src: &S, mean: f64, valid: usize, top: f64) -> Result<FormModel> {
    let shape = src.shape();
    let (nx, ny) = (shape.nx, shape.ny);
    let u: Vec<f64> = (0..nx).map(|j| scaled(j, nx)).collect();
    let starts: Vec<usize> = (0..ny).step_by(ROWS_PER_TASK).collect();
    // [n, su, suu, sv, suv, svv, sr, sur, svr] per block, summed in block order below.
    let partial: Vec<[f64; 9]> = starts
        .par_iter()
        .map(|&i0| {
            let mut acc = [0.0; 9];
            let mut buf = Vec::new();
            let i1 = (i0 + ROWS_PER_TASK).min(ny);
            let band = src.band(i0, i1, &mut buf);
            for i in i0..i1 {
                let v = scaled(i, ny);
                let [n, su, suu, sr, sur] = plane_row_sums(band.row(i), &u, mean);
                for (a, b) in acc.iter_mut().zip([n, su, suu, v * n, v * su, v * v * n, sr, sur, v * sr]) {
                    *a += b;
                }
            }
            acc
        })
        .collect();
    let mut s = [0.0; 9];
    for p in &partial {
        for (a, b) in s.iter_mut().zip(p) {
            *a += b;
        }
    }
    let [n, su, suu, sv, suv, svv, sr, sur, svr] = s;
    let ata = nalgebra::Matrix3::new(n, su, sv, su, suu, suv, sv, suv, svv);
    let atb = nalgebra::Vector3::new(sr, sur, svr);
    // As in the general case: SVD with a relative cut-off, the minimum-norm fit when the valid points
    // do not span the plane (one line of points).
    let svd = ata.svd(true, true);
    let smax = svd.singular_values.max();
    let c = svd.solve(&atb, smax * 1e-12).map_err(|e| Error::new(ErrorKind::Numerical, format!("form fit failed: {e}")))?;
    let c = [c[0], c[1], c[2]];
    let base = (0..ny).map(|i| c[0] + c[2] * scaled(i, ny)).collect();
    Ok(FormModel { mean, valid, top, kind: FormKind::Plane { c, u, base } })
}

/// A fitted cylinder and the residual heights.
#[derive(Debug, Clone, PartialEq)]
pub struct CylinderFit {
    /// Heights minus the fitted cylinder (NaN where the input is NaN).
    pub residual: Vec<f64>,
    /// Radius in metres.
    pub radius: f64,
    /// Direction of the cylinder axis in the xy plane, radians from +x.
    pub axis_angle: f64,
    /// +1 for a convex cylinder (a bullet land), -1 for a concave one (a bore).
    pub convexity: f64,
}

/// Remove the least-squares cylinder whose axis lies parallel to the xy plane (at any azimuth, with
/// a linear tilt along it): `z = c0 + g s + sigma sqrt(R^2 - (t - tc)^2)`, with `t` across and `s`
/// along the axis. The azimuth and a starting radius come from the Hessian of a quadratic fit (the
/// axis is the direction of least curvature); `c0, g, tc, R` are then refined by damped Gauss-Newton
/// on the vertical residuals. This is not the `levenberg-marquardt` crate: that needs the whole
/// N x 5 Jacobian in memory (40 bytes per point) and stops at the first undefined residual, while
/// here the normal equations accumulate in a 5x5 and steps that leave the footprint are rejected.
pub fn remove_cylinder(hf: &Scan) -> Result<CylinderFit> {
    let pts: Vec<(f64, f64, f64)> = (0..hf.ny)
        .flat_map(|i| (0..hf.nx).map(move |j| (i, j)))
        .filter_map(|(i, j)| {
            let h = hf.z[i * hf.nx + j];
            (!h.is_nan()).then_some((j as f64 * hf.dx, i as f64 * hf.dy, h))
        })
        .collect();
    if pts.len() < 6 {
        return Err(Error::new(ErrorKind::BadData, format!("{} valid points cannot determine a cylinder", pts.len())));
    }
    let n = pts.len() as f64;
    let (xc, yc, zm) = pts.iter().fold((0.0, 0.0, 0.0), |a, p| (a.0 + p.0 / n, a.1 + p.1 / n, a.2 + p.2 / n));
    // Quadratic fit z - zm = a + bx + cy + d x^2 + e xy + f y^2 in metric coordinates about the centroid,
    // scaled by the half-extent for conditioning.
    let sx = ((hf.nx.max(2) - 1) as f64 * hf.dx).max(hf.dx) / 2.0;
    let sy = ((hf.ny.max(2) - 1) as f64 * hf.dy).max(hf.dy) / 2.0;
    let mut ata = DMatrix::<f64>::zeros(6, 6);
    let mut atb = DVector::<f64>::zeros(6);
    for &(x, y, z) in &pts {
        let (u, v) = ((x - xc) / sx, (y - yc) / sy);
        let row = [1.0, u, v, u * u, u * v, v * v];
        for a in 0..6 {
            atb[a] += row[a] * (z - zm);
            for b in 0..6 {
                ata[(a, b)] += row[a] * row[b];
            }
        }
    }
    let svd = ata.svd(true, true);
    let smax = svd.singular_values.max();
    let q = svd.solve(&atb, smax * 1e-12).map_err(|e| Error::new(ErrorKind::Numerical, format!("cylinder start fit failed: {e}")))?;
    let hxx = 2.0 * q[3] / (sx * sx);
    let hxy = q[4] / (sx * sy);
    let hyy = 2.0 * q[5] / (sy * sy);
    // Eigen-decomposition of the 2x2 Hessian.
    let tr = 0.5 * (hxx + hyy);
    let disc = (0.25 * (hxx - hyy).powi(2) + hxy * hxy).sqrt();
    let (l1, l2) = (tr + disc, tr - disc);
    let kappa = if l1.abs() >= l2.abs() { l1 } else { l2 };
    let width = (sx * sx + sy * sy).sqrt() * 2.0;
    // A cylinder needs curvature: with a radius beyond 1e6 widths the fit is a plane in disguise.
    if !(kappa.abs() * width * 1e6 > 1.0) {
        return Err(Error::new(
            ErrorKind::Numerical,
            "cylinder removal: the surface shows no curvature to fit a cylinder to; use plane removal",
        ));
    }
    // Across-axis direction: eigenvector of kappa.
    let (ex, ey) = if hxy.abs() > 1e-300 {
        let (a, b) = (kappa - hyy, hxy);
        let norm = (a * a + b * b).sqrt();
        (a / norm, b / norm)
    } else if (kappa - hxx).abs() <= (kappa - hyy).abs() {
        (1.0, 0.0)
    } else {
        (0.0, 1.0)
    };
    let sigma = if kappa < 0.0 { 1.0 } else { -1.0 };
    // Axis azimuth phi: the axis runs along (cos phi, sin phi); e = (ex, ey) is across it, so
    // e = (-sin phi, cos phi).
    let phi0 = (-ex).atan2(ey);
    let xyz: Vec<(f64, f64, f64)> = pts.iter().map(|&(x, y, z)| (x - xc, y - yc, z - zm)).collect();
    let across = |phi: f64, x: f64, y: f64| (-x * phi.sin() + y * phi.cos(), x * phi.cos() + y * phi.sin());
    let tmax = xyz.iter().fold(0.0f64, |m, p| m.max(across(phi0, p.0, p.1).0.abs()));
    // Start: apex over the slope-zero point of the quadratic along t, radius 1/|kappa|.
    let slope_t = (q[1] / sx) * ex + (q[2] / sy) * ey;
    let r0 = (1.0 / kappa.abs()).max(1.01 * tmax);
    let mut tc0 = -slope_t / kappa;
    if !tc0.is_finite() || tc0.abs() > r0 {
        tc0 = 0.0;
    }
    // Parameters: c0, g (tilt along the axis), tc, R, phi.
    let model = |p: &[f64; 5], x: f64, y: f64| -> Option<(f64, f64, f64, f64)> {
        let (t, s) = across(p[4], x, y);
        let w2 = p[3] * p[3] - (t - p[2]).powi(2);
        // Outside the cylinder's footprint the model is undefined; the step is rejected.
        (w2 > 0.0).then(|| (p[0] + p[1] * s + sigma * w2.sqrt(), t, s, w2.sqrt()))
    };
    let cost = |p: &[f64; 5]| -> f64 {
        let mut c = 0.0;
        for &(x, y, z) in &xyz {
            match model(p, x, y) {
                Some((f, ..)) => c += (z - f).powi(2),
                None => return f64::INFINITY,
            }
        }
        c
    };
    let mut p = [0.0, 0.0, tc0, r0, phi0];
    // c0 starts at the mean offset so the first cost is finite and sensible.
    p[0] = xyz
        .iter()
        .map(|&(x, y, z)| {
            let t = across(phi0, x, y).0;
            z - sigma * (r0 * r0 - (t - tc0).powi(2)).max(0.0).sqrt()
        })
        .sum::<f64>()
        / n;
    let mut c_now = cost(&p);
    let mut lambda = 1e-3;
    for _ in 0..500 {
        let mut jtj = nalgebra::Matrix5::<f64>::zeros();
        let mut jtr = nalgebra::Vector5::<f64>::zeros();
        for &(x, y, z) in &xyz {
            let Some((f, t, s, w)) = model(&p, x, y) else { continue };
            let dt = t - p[2];
            let jrow = nalgebra::Vector5::new(1.0, s, sigma * dt / w, sigma * p[3] / w, p[1] * t + sigma * dt * s / w);
            jtj += jrow * jrow.transpose();
            jtr += jrow * (z - f);
        }
        let mut improved = false;
        for _ in 0..40 {
            let mut a = jtj;
            for k in 0..5 {
                // Marquardt scaling; the floor keeps a zero diagonal (no tilt data) from freezing.
                a[(k, k)] += lambda * jtj[(k, k)].max(1e-300);
            }
            let Some(step) = a.lu().solve(&jtr) else { break };
            let trial = [p[0] + step[0], p[1] + step[1], p[2] + step[2], p[3] + step[3], p[4] + step[4]];
            let c_trial = cost(&trial);
            if c_trial < c_now {
                let rel = (c_now - c_trial) / c_now.max(f64::MIN_POSITIVE);
                p = trial;
                c_now = c_trial;
                lambda = (lambda * 0.3).max(1e-15);
                improved = rel > 1e-15;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    let r = p[3];
    let mut residual = Vec::with_capacity(hf.z.len());
    for i in 0..hf.ny {
        for j in 0..hf.nx {
            let h = hf.z[i * hf.nx + j];
            if h.is_nan() {
                residual.push(f64::NAN);
                continue;
            }
            let (t, s) = across(p[4], j as f64 * hf.dx - xc, i as f64 * hf.dy - yc);
            let w = (r * r - (t - p[2]).powi(2)).max(0.0).sqrt();
            residual.push(h - zm - (p[0] + p[1] * s + sigma * w));
        }
    }
    let axis_angle = p[4].rem_euclid(std::f64::consts::PI);
    Ok(CylinderFit { residual, radius: r, axis_angle, convexity: sigma })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scan::Heightfield;

    /// Values of many magnitudes and signs, with NaN holes (a deterministic sequence).
    fn values(n: usize, seed: u64) -> Vec<f64> {
        let mut x = seed;
        (0..n)
            .map(|k| {
                x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                let u = (x >> 11) as f64 / (1u64 << 53) as f64 - 0.5;
                if k % 17 == 3 {
                    f64::NAN
                } else {
                    u * 10f64.powi((k % 7) as i32 - 3) + 0.076
                }
            })
            .collect()
    }

    /// The mean's sums taken side by side (in AVX2 lanes where the CPU has them) are the serial
    /// filter-and-fold of each slice, bit for bit: equal and unequal lengths, a group shorter than
    /// [`MEAN_CHAINS`], empty slices.
    #[test]
    fn side_by_side_sums_equal_the_serial_ones() {
        let v = values(4000, 7);
        let serial = |s: &[f64]| {
            let (c, t) = s.iter().filter(|h| !h.is_nan()).fold((0usize, 0.0f64), |(c, t), h| (c + 1, t + h));
            (c, t, s.iter().filter(|h| !h.is_nan()).fold(0.0f64, |m, h| if h.abs() > m { h.abs() } else { m }))
        };
        for lens in [[500, 500, 500, 500], [500, 499, 37, 1000], [0, 10, 20, 30]] {
            let mut at = 0;
            let slices: Vec<&[f64]> = lens
                .iter()
                .map(|&l| {
                    at += l;
                    &v[at - l..at]
                })
                .collect();
            for group in [&slices[..], &slices[..3]] {
                let got = counts_and_sums(group);
                for (g, s) in got.iter().zip(group.iter()) {
                    let want = serial(s);
                    assert_eq!((g.0, g.1.to_bits(), g.2.to_bits()), (want.0, want.1.to_bits(), want.2.to_bits()), "{lens:?}");
                }
            }
        }
    }

    /// The plane's row sums compiled for AVX2 (where the CPU has it) equal the portable loop's, bit for
    /// bit, on rows of every length modulo the lane count, with holes; and both equal plain sums over
    /// the valid heights to rounding.
    #[test]
    fn plane_row_sums_match_the_portable_loop() {
        let v = values(1030, 11);
        let u: Vec<f64> = (0..1030).map(|j| scaled(j, 1030)).collect();
        for n in [0, 1, 3, 4, 5, 1027, 1030] {
            let got = plane_row_sums(&v[..n], &u[..n], 0.07);
            let want = plane_row_sums_body(&v[..n], &u[..n], 0.07);
            assert_eq!(got.map(f64::to_bits), want.map(f64::to_bits), "{n}");
            let valid = || v[..n].iter().zip(&u[..n]).filter(|(h, _)| !h.is_nan());
            let plain = [
                valid().count() as f64,
                valid().map(|(_, x)| x).sum::<f64>(),
                valid().map(|(_, x)| x * x).sum::<f64>(),
                valid().map(|(h, _)| h - 0.07).sum::<f64>(),
                valid().map(|(h, x)| x * (h - 0.07)).sum::<f64>(),
            ];
            let scale = valid().map(|(h, _)| (h - 0.07).abs() + 1.0).sum::<f64>();
            for (k, (g, p)) in got.iter().zip(plain).enumerate() {
                assert!((g - p).abs() <= 1e-12 * scale, "{n}: sum {k} {g} against {p}");
            }
        }
    }

    /// The plane path (`plane_fit`) gives the residuals of the general term loop to rounding: on a
    /// 76 mm stage height under a tilted plane and sub-micrometre roughness, with holes, on grids whose
    /// rows are not a multiple of the vector width or of the task's rows. Both are least squares on the
    /// same basis; the residuals agree to 1e-9 of the roughness (1e-16 m here), far below anything
    /// measured, and the plane they remove is the one that made the heights (to the roughness's own
    /// least-squares tilt).
    #[test]
    fn plane_path_matches_the_general_fit() {
        for (nx, ny) in [(37, 23), (64, 17), (5, 2)] {
            let mut z = Vec::with_capacity(nx * ny);
            for i in 0..ny {
                for j in 0..nx {
                    let rough = 1e-7 * (((i * 7919 + j * 104729) % 1009) as f64 / 1009.0 - 0.5);
                    let h = 0.076 + 3e-4 * j as f64 * 1e-6 - 2e-4 * i as f64 * 1e-6 + rough;
                    z.push(if (i * nx + j) % 11 == 3 { f64::NAN } else { h });
                }
            }
            let top = z.iter().filter(|h| !h.is_nan()).fold(0.0f64, |m, h| if h.abs() > m { h.abs() } else { m });
            let hf = Heightfield::new(nx, ny, 1e-6, 1e-6, z).expect("grid");
            let (fast, general) = (polynomial_fit(&hf, 1, true).expect("plane path"), polynomial_fit(&hf, 1, false).expect("general path"));
            assert_eq!((fast.largest_height(), general.largest_height()), (top, top), "{nx}x{ny}");
            let (fast, general) = (fast.residual(&hf), general.residual(&hf));
            for (k, (a, b)) in fast.iter().zip(&general).enumerate() {
                if b.is_nan() {
                    assert!(a.is_nan(), "{nx}x{ny} point {k}: hole must stay NaN");
                } else {
                    assert!((a - b).abs() <= 1e-16, "{nx}x{ny} point {k}: {a} vs {b}");
                    // The plane is gone: what is left is the roughness (|rough| <= 5e-8) and its tilt.
                    assert!(a.abs() < 1e-7, "{nx}x{ny} point {k}: residual {a}");
                }
            }
        }
    }
}
