//! The least-squares problem handed to the `levenberg-marquardt` crate (and, through the same residual
//! code, to the argmin solvers): residuals of [`super::objective`] with the analytic Jacobian of
//! [`super::lnd`].
//!
//! Per bin and evaluation the residual pass costs one logarithm (`ln q` inside `ln D`), one exponential
//! (the normalization `S`) and one square root; `E_k` comes from the normalization's own terms and
//! `h = c (exp(l) - 1 - l)` from `E_k / c_k` (a series near `l = 0`). The Jacobian at the point of the
//! last residual pass (always so inside LM: it asks for the Jacobian after accepting a step) reuses that
//! pass and adds the gradients of `ln D`, which need no transcendental function.
//!
//! For large regions LM is handed `p + 1` compressed residuals with the same normal equations instead of
//! one per bin (`compress`), so its pivoted QR no longer runs over every bin.
//!
//! The per-bin work (`ln D`, its gradient, the exponentials and residuals) runs on rayon's threads in
//! chunks of [`PAR_CHUNK`] bins; every sum over bins (`S`, the objective, `gbar`, the normal equations)
//! is then taken on the calling thread in bin order, so results are bit for bit those of one thread,
//! whatever the thread count.

use std::cell::RefCell;
use std::sync::atomic::{AtomicUsize, Ordering};

use levenberg_marquardt::LeastSquaresProblem;
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use rayon::prelude::*;

use super::lnd::LnD;
use super::objective::{poisson_residual, residual, FitData, Objective};
use crate::models::ModelId;

/// Bins evaluated by the residual pass since the last reset (profiling: the cost of a fit in bin
/// evaluations, independent of the machine; one relaxed add per call).
pub static RESIDUAL_BIN_EVALS: AtomicUsize = AtomicUsize::new(0);
/// Bins evaluated by the Jacobian pass since the last reset (as [`RESIDUAL_BIN_EVALS`]).
pub static JACOBIAN_BIN_EVALS: AtomicUsize = AtomicUsize::new(0);

/// Bins per task of the residual and Jacobian passes: enough `ln D` work to outweigh rayon's per-task
/// cost, small enough that the merged bins of a large scan still give every thread tasks; a region of
/// fewer bins is one task, run on the calling thread.
const PAR_CHUNK: usize = 512;

/// Scratch of the residual and Jacobian passes, reused across evaluations (no allocation per
/// evaluation), holding the last residual pass for the Jacobian at the same point.
#[derive(Debug, Clone, Default)]
pub struct Workspace {
    /// `ln(D_k W_k)`.
    a: Vec<f64>,
    /// `D_k W_k / S`, the weights of the profiled normalization's gradient.
    p: Vec<f64>,
    /// `d r_k / d ln E_k`.
    dr: Vec<f64>,
    /// Residuals of the last pass.
    r: Vec<f64>,
    /// The point of the last residual pass with a finite objective, and that objective.
    at: Option<(Vec<f64>, f64)>,
    /// Compressed mode ([`Problem`]): the full Jacobian of the last residual pass (bins x params).
    jac: DMatrix<f64>,
    /// Compressed mode: the `(p + 1) x p` Jacobian handed to LM for the last residual pass (`None`
    /// when the full Jacobian was not finite).
    jac_c: Option<DMatrix<f64>>,
}

impl Workspace {
    /// The objective `sum r^2` of the last residual pass when it was at `x` (bit for bit).
    pub fn objective_at(&self, x: &[f64]) -> Option<f64> {
        self.at.as_ref().filter(|(ax, _)| ax.as_slice() == x).map(|(_, f)| *f)
    }
}

/// Residual pass at `x` into `ws` (residuals in `ws.r`); returns the objective `sum r^2`, non-finite
/// when the model has no mass in the region.
///
/// objective.md: `ln S` by log-sum-exp over `a_k = ln D(m_k) + ln W_k` (no extreme lobe overflows or
/// underflows it), `E_k = N_in exp(a_k - shift) / sum_j exp(a_j - shift)`, `l_k = ln(E_k / c_k)`.
fn residual_pass(data: &FitData, id: ModelId, x: &[f64], ws: &mut Workspace) -> f64 {
    RESIDUAL_BIN_EVALS.fetch_add(data.bins.len(), Ordering::Relaxed);
    let nb = data.bins.len();
    ws.at = None;
    ws.a.resize(nb, 0.0);
    ws.p.resize(nb, 0.0);
    ws.dr.resize(nb, 0.0);
    ws.r.resize(nb, 0.0);
    let f = LnD::new(id, x);
    // The maximum is exact in any order (NaN terms are skipped, as a serial fold skips them).
    let shift =
        ws.a.par_chunks_mut(PAR_CHUNK)
            .enumerate()
            .map(|(c, a)| {
                let k0 = c * PAR_CHUNK;
                let bins = &data.bins[k0..k0 + a.len()];
                let mut top = f64::NEG_INFINITY;
                match &data.rounding {
                    None => {
                        for (a, bin) in a.iter_mut().zip(bins) {
                            *a = f.value(&bin.m) + bin.ln_w;
                            top = top.max(*a);
                        }
                    }
                    Some(rounding) => {
                        for ((a, bin), pts) in a.iter_mut().zip(bins).zip(&rounding.points[k0..]) {
                            *a = smoothed(pts.map(|(m, lw)| f.value(&m) + lw)).0 + bin.ln_w;
                            top = top.max(*a);
                        }
                    }
                }
                top
            })
            .reduce(|| f64::NEG_INFINITY, f64::max);
    // Guard: a model with no finite mass anywhere in R; the caller reports a failed evaluation.
    if !shift.is_finite() {
        ws.r.fill(f64::NAN);
        return f64::NAN;
    }
    ws.p.par_chunks_mut(PAR_CHUNK).zip(ws.a.par_chunks(PAR_CHUNK)).for_each(|(p, a)| {
        for (p, a) in p.iter_mut().zip(a) {
            *p = (a - shift).exp();
        }
    });
    let s: f64 = ws.p.iter().sum();
    // s >= 1 (the largest term is exp(0)) unless NaN crept in: then ln_s is NaN and so is the result.
    let ln_s = shift + s.ln();
    let inv_s = 1.0 / s;
    let ln_n = data.n.ln();
    (ws.r.par_chunks_mut(PAR_CHUNK), ws.dr.par_chunks_mut(PAR_CHUNK), ws.p.par_chunks_mut(PAR_CHUNK), ws.a.par_chunks(PAR_CHUNK))
        .into_par_iter()
        .enumerate()
        .for_each(|(c, (r, dr, p, a))| {
            let bins = &data.bins[c * PAR_CHUNK..];
            for ((((r, dr), p), a), bin) in r.iter_mut().zip(dr).zip(p).zip(a).zip(bins) {
                *p *= inv_s;
                (*r, *dr) = match data.objective {
                    Objective::Poisson => poisson_residual(bin.c, data.n * *p, a - ln_s + (ln_n - bin.ln_c)),
                    Objective::Logd => residual(Objective::Logd, bin, a - bin.ln_w - ln_s),
                };
            }
        });
    let sum: f64 = ws.r.iter().map(|v| v * v).sum();
    if ln_s.is_finite() && sum.is_finite() {
        ws.at = Some((x.to_vec(), sum));
        sum
    } else if ln_s.is_finite() {
        sum
    } else {
        f64::NAN
    }
}

/// Jacobian at `x` (column-major, bins x params) into `jac`, residuals in `ws.r`; reuses the residual
/// pass in `ws` when it was at `x`.
///
/// With `g_k = d ln D(m_k) / d x` and the normalization profiled out, `d ln E_k / d x = g_k - gbar`,
/// `gbar = sum_j D_j W_j g_j / S` (the rank-one term of the conditional likelihood), so
/// `J_k = (d r_k / d ln E_k) (g_k - gbar)`.
fn jacobian_pass(data: &FitData, id: ModelId, x: &[f64], jac: &mut DMatrix<f64>, ws: &mut Workspace) {
    if ws.objective_at(x).is_none() {
        residual_pass(data, id, x, ws);
    }
    JACOBIAN_BIN_EVALS.fetch_add(data.bins.len(), Ordering::Relaxed);
    let f = LnD::new(id, x);
    let np = x.len();
    let nb = data.bins.len();
    let js = jac.as_mut_slice();
    // Each chunk of bins writes its rows of every column.
    chunk_rows(js, nb, np).into_par_iter().enumerate().for_each(|(c, mut cols)| {
        let k0 = c * PAR_CHUNK;
        let mut g = [0.0; 8];
        let mut gq = [0.0; 8];
        for i in 0..cols.first().map_or(0, |col| col.len()) {
            let (k, bin) = (k0 + i, &data.bins[k0 + i]);
            match &data.rounding {
                None => f.grad(&bin.m, &mut g[..np]),
                Some(rounding) => {
                    // The gradient of the smoothed ln D: the points' gradients weighted by their shares.
                    let pts = &rounding.points[k];
                    let (_, w) = smoothed(pts.map(|(m, lw)| f.value(&m) + lw));
                    g[..np].fill(0.0);
                    for ((m, _), wq) in pts.iter().zip(w) {
                        f.grad(m, &mut gq[..np]);
                        for (gj, gqj) in g[..np].iter_mut().zip(&gq[..np]) {
                            *gj += wq * gqj;
                        }
                    }
                }
            }
            for (col, gj) in cols.iter_mut().zip(&g[..np]) {
                col[i] = *gj;
            }
        }
    });
    let mut gbar = [0.0; 8];
    for (k, pk) in ws.p.iter().enumerate() {
        for (j, gb) in gbar[..np].iter_mut().enumerate() {
            *gb += pk * js[j * nb + k];
        }
    }
    // Every column's rows of a chunk in one task (one parallel pass, not one per column).
    chunk_rows(js, nb, np).into_par_iter().zip(ws.dr.par_chunks(PAR_CHUNK)).for_each(|(mut cols, dr)| {
        for (col, gb) in cols.iter_mut().zip(&gbar[..np]) {
            for (jk, dr) in col.iter_mut().zip(dr) {
                *jk = dr * (*jk - gb);
            }
        }
    });
}

/// The rows of a column-major `nb x np` matrix `js` by chunks of [`PAR_CHUNK`] bins: per chunk, its rows
/// of every column (the columns split at the same bins).
fn chunk_rows(js: &mut [f64], nb: usize, np: usize) -> Vec<Vec<&mut [f64]>> {
    let mut parts: Vec<Vec<&mut [f64]>> = (0..nb.div_ceil(PAR_CHUNK)).map(|_| Vec::with_capacity(np)).collect();
    for col in js.chunks_exact_mut(nb) {
        for (part, rows) in parts.iter_mut().zip(col.chunks_mut(PAR_CHUNK)) {
            part.push(rows);
        }
    }
    parts
}

/// `ln sum_q exp(v_q)` of the rounding rule's terms `v_q = ln D(m_q) + ln w_q`
/// ([`super::objective::Rounding`]), and each term's share `exp(v_q) / sum` (the weights of its gradient).
#[inline]
fn smoothed<const N: usize>(v: [f64; N]) -> (f64, [f64; N]) {
    let top = v.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    // Guard: no finite term (the model has no mass at any point); the caller reports the pass.
    if !top.is_finite() {
        return (top, [1.0 / N as f64; N]);
    }
    let e = v.map(|t| (t - top).exp());
    let s: f64 = e.iter().sum();
    (top + s.ln(), e.map(|t| t / s))
}

/// `sum_k a_k b_k` in four interleaved partial sums (so the loop pipelines and vectorizes; the order
/// is fixed, so the result is deterministic).
fn dot(a: &[f64], b: &[f64]) -> f64 {
    let mut acc = [0.0; 4];
    let (ca, cb) = (a.chunks_exact(4), b.chunks_exact(4));
    let (ra, rb) = (ca.remainder(), cb.remainder());
    for (x, y) in ca.zip(cb) {
        for i in 0..4 {
            acc[i] += x[i] * y[i];
        }
    }
    let tail: f64 = ra.iter().zip(rb).map(|(x, y)| x * y).sum();
    (acc[0] + acc[1]) + (acc[2] + acc[3]) + tail
}

/// The compressed residuals of [`Problem`] at the point of the last residual pass in `ws` (after a
/// Jacobian pass into `ws.jac`), with the matching `(p + 1) x p` Jacobian into `ws.jac_c`.
///
/// With `G = J^T J = V diag(l) V^T` (symmetric eigendecomposition) and `b = J^T r`: `J' = [diag(sqrt l)
/// V^T; 0]` and `r' = [diag(1/sqrt l) V^T b; sqrt(|r|^2 - |that|^2)]` (components of null directions 0).
/// Then `J'^T J' = G`, `J'^T r' = b` (within the range of `J`) and `|r'| = |r|`: everything
/// Levenberg-Marquardt computes from `(J, r)` (the normal equations of its steps, the scaled column
/// norms, `|J p|`, the residual norms) is unchanged, while its pivoted QR runs on `p + 1` rows instead
/// of one per bin (that QR was a third of a 1024^2 ellipsoid fit).
fn compress(ws: &mut Workspace, sum: f64, rc: &mut [f64]) {
    let np = ws.jac.ncols();
    let nb = ws.jac.nrows();
    let js = ws.jac.as_slice();
    let mut g = nalgebra::DMatrix::<f64>::zeros(np, np);
    let mut b = nalgebra::DVector::<f64>::zeros(np);
    let col = |i: usize| &js[i * nb..(i + 1) * nb];
    // Each dot product (of two columns, or `None`: of a column and the residuals) on its own thread, each
    // in its fixed order: the same sums as one thread's, in one parallel pass.
    let pairs: Vec<(usize, Option<usize>)> =
        (0..np).flat_map(|i| (0..=i).map(move |j| (i, Some(j)))).chain((0..np).map(|i| (i, None))).collect();
    let dots: Vec<f64> = pairs.par_iter().map(|&(i, j)| dot(col(i), j.map_or(&ws.r[..], col))).collect();
    for (&(i, j), &v) in pairs.iter().zip(&dots) {
        match j {
            Some(j) => (g[(i, j)], g[(j, i)]) = (v, v),
            None => b[i] = v,
        }
    }
    rc.fill(0.0);
    // Guard: a non-finite Jacobian (an overflowing lobe) is reported to LM when it asks for the Jacobian
    // here; the residuals keep their norm so the step's acceptance test is still right.
    if !g.iter().chain(b.iter()).all(|v| v.is_finite()) {
        rc[np] = sum.sqrt();
        ws.jac_c = None;
        return;
    }
    let eig = nalgebra::SymmetricEigen::new(g);
    let lmax = eig.eigenvalues.iter().fold(0.0f64, |a, v| a.max(*v));
    let mut jc = ws.jac_c.take().filter(|m| m.shape() == (np + 1, np)).unwrap_or_else(|| DMatrix::zeros(np + 1, np));
    jc.fill(0.0);
    let mut top = 0.0;
    for (k, &l) in eig.eigenvalues.iter().enumerate() {
        // Guard: eigenvalues at rounding level of the largest are null directions (an undetermined
        // theta_z of an isotropic lobe): no component, as the pivoted QR would treat them.
        if !(l > lmax * 1e-14) {
            continue;
        }
        let sl = l.sqrt();
        let v = eig.eigenvectors.column(k);
        for j in 0..np {
            jc[(k, j)] = sl * v[j];
        }
        let c = v.dot(&b) / sl;
        rc[k] = c;
        top += c * c;
    }
    // |r|^2 - |projection|^2 >= 0 up to rounding.
    rc[np] = (sum - top).max(0.0).sqrt();
    ws.jac_c = Some(jc);
}

/// Residuals into `r` (length = bins) at internal vector `x`; returns the objective `sum r^2`
/// (non-finite when the model has no mass in the region).
pub fn residuals_into(data: &FitData, id: ModelId, x: &[f64], r: &mut [f64]) -> f64 {
    let mut ws = Workspace::default();
    let f = residual_pass(data, id, x, &mut ws);
    r.copy_from_slice(&ws.r);
    f
}

/// Residuals and the Jacobian (column-major, bins x params) at `x`. Buffers are the caller's.
pub fn jacobian_into(data: &FitData, id: ModelId, x: &[f64], r: &mut [f64], jac: &mut DMatrix<f64>) {
    let mut ws = Workspace::default();
    jacobian_pass(data, id, x, jac, &mut ws);
    r.copy_from_slice(&ws.r);
}

/// The LM problem: a model id, the data and the current internal parameters.
#[derive(Debug, Clone)]
pub struct Problem<'a> {
    /// The data.
    pub data: &'a FitData,
    /// The model being fitted.
    pub id: ModelId,
    /// Current internal parameters.
    pub x: DVector<f64>,
    /// Scratch, and the last residual pass for the Jacobian at the same point.
    ws: RefCell<Workspace>,
    /// LM sees `p + 1` compressed residuals instead of one per bin ([`compress`]): as
    /// [`FitData::lm_compressed`] says.
    compressed: bool,
}

/// Fewest fine bins of a region for which [`Problem`] hands LM compressed residuals (on the fine and the
/// merged bins): the fits that the merged-bin pass also targets ([`super::COARSE_PASS_MIN_BINS`]).
/// Below it a fit takes a few milliseconds anyway, and its LM path (so its stopping point within the
/// tolerance) stays that of the uncompressed problem: compressing every fit moved some flat
/// GTR2aniso/Beckmann-aniso optima of small scans by up to 4e-6 relative (objective lower by 1e-12 to
/// 1e-11 relative, i.e. within the stopping tolerance).
pub const COMPRESS_MIN_BINS: usize = super::COARSE_PASS_MIN_BINS;

impl<'a> Problem<'a> {
    /// The problem of fitting `id` to `data` from internal vector `x0`.
    pub fn new(data: &'a FitData, id: ModelId, x0: &[f64]) -> Problem<'a> {
        let compressed = data.lm_compressed;
        Problem { data, id, x: DVector::from_column_slice(x0), ws: RefCell::new(Workspace::default()), compressed }
    }

    /// The same problem with compression (`compress`) forced on or off (tests).
    #[cfg(test)]
    pub fn with_compression(mut self, on: bool) -> Problem<'a> {
        self.compressed = on;
        self
    }

    /// The objective at the current parameters: from the last residual pass when it was there, else
    /// evaluated.
    pub fn objective(&self) -> f64 {
        let mut ws = self.ws.borrow_mut();
        match ws.objective_at(self.x.as_slice()) {
            Some(f) => f,
            None => residual_pass(self.data, self.id, self.x.as_slice(), &mut ws),
        }
    }
}

impl LeastSquaresProblem<f64, Dyn, Dyn> for Problem<'_> {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;

    fn set_params(&mut self, x: &DVector<f64>) {
        self.x.copy_from(x);
    }

    fn params(&self) -> DVector<f64> {
        self.x.clone()
    }

    fn residuals(&self) -> Option<DVector<f64>> {
        let mut ws = self.ws.borrow_mut();
        let x = self.x.as_slice();
        let f = residual_pass(self.data, self.id, x, &mut ws);
        // A non-finite objective is reported to LM as a failed evaluation, never passed on as NaN.
        if !f.is_finite() {
            return None;
        }
        if !self.compressed {
            return Some(DVector::from_column_slice(&ws.r));
        }
        let np = x.len();
        let mut jac = std::mem::take(&mut ws.jac);
        if jac.shape() != (self.data.bins.len(), np) {
            jac = DMatrix::zeros(self.data.bins.len(), np);
        }
        jacobian_pass(self.data, self.id, x, &mut jac, &mut ws);
        ws.jac = jac;
        let mut rc = DVector::zeros(np + 1);
        compress(&mut ws, f, rc.as_mut_slice());
        Some(rc)
    }

    fn jacobian(&self) -> Option<DMatrix<f64>> {
        if self.compressed {
            // LM asks for the Jacobian at the point of its last accepted residuals: that pass's.
            let needs_pass = self.ws.borrow().objective_at(self.x.as_slice()).is_none();
            if needs_pass {
                self.residuals()?;
            }
            return self.ws.borrow().jac_c.clone();
        }
        let mut j = DMatrix::zeros(self.data.bins.len(), self.x.len());
        jacobian_pass(self.data, self.id, self.x.as_slice(), &mut j, &mut self.ws.borrow_mut());
        j.iter().all(|v| v.is_finite()).then_some(j)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::params::to_internal;
    use crate::fit::synthetic::{binned_ndf, Grid};
    use crate::models::{Model, Ndf};

    fn data(objective: Objective) -> (FitData, Vec<f64>) {
        let truth = Model::from_params(ModelId::Ellipsoid, &[0.3, 0.12, 0.2, -0.3, 0.6]).expect("valid truth");
        let ndf = binned_ndf(&truth, &Grid::for_model(&truth, 41), 1e5, 5);
        // A 60 deg region: part of the mass is outside, so the normalization S matters.
        let data = FitData::new(&ndf, objective, 60f64.to_radians()).expect("fit data");
        (data, to_internal(ModelId::Ellipsoid, &[0.25, 0.2, 0.1, -0.2, 0.7]))
    }

    /// The residual pass against the definition of objective.md evaluated directly from the model's own
    /// `D` (Walter et al. eq. 1): `E_k = N_in D_k W_k / sum_j D_j W_j`, deviance `2 sum (E - c + c ln(c/E))`.
    /// The direct sum loses ~eps c |ln c| per bin to cancellation: with N_in ~ 1e5 that is < 1e-9 absolute
    /// against a deviance of ~1e4, so 1e-10 relative is a real check (a wrong term moves it by O(1)).
    #[test]
    fn objective_matches_the_direct_definition() {
        let (data, x) = data(Objective::Poisson);
        let m = Model::from_params(ModelId::Ellipsoid, &crate::fit::params::to_public(ModelId::Ellipsoid, &x)).expect("model");
        let s: f64 = data.bins.iter().map(|b| m.d(b.m) * b.w).sum();
        let direct: f64 = data
            .bins
            .iter()
            .map(|b| {
                let e = data.n * m.d(b.m) * b.w / s;
                2.0 * (e - b.c + if b.c > 0.0 { b.c * (b.c / e).ln() } else { 0.0 })
            })
            .sum();
        let mut r = vec![0.0; data.bins.len()];
        let f = residuals_into(&data, ModelId::Ellipsoid, &x, &mut r);
        assert!((f - direct).abs() <= 1e-10 * direct, "{f} vs {direct}");
    }

    /// The compressed problem has the same normal equations as the full one: `J'^T J' = J^T J`,
    /// `J'^T r' = J^T r` and `|r'| = |r|`, each to 1e-12 relative (sums of ~1e3 products in a different
    /// order, and an eigendecomposition of a 5 x 5 matrix with condition < 1e6: ~1e-13).
    #[test]
    fn compressed_residuals_keep_the_normal_equations() {
        let (data, x) = data(Objective::Poisson);
        let k = data.bins.len();
        let (mut r, mut j) = (vec![0.0; k], DMatrix::zeros(k, x.len()));
        jacobian_into(&data, ModelId::Ellipsoid, &x, &mut r, &mut j);
        let p = Problem::new(&data, ModelId::Ellipsoid, &x).with_compression(true);
        let rc = p.residuals().expect("finite residuals");
        let jc = p.jacobian().expect("finite Jacobian");
        assert_eq!(jc.shape(), (x.len() + 1, x.len()));
        let (g, gc) = (j.transpose() * &j, jc.transpose() * &jc);
        let gmax = g.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        assert!((g - gc).iter().all(|d| d.abs() <= 1e-12 * gmax), "J^T J differs");
        let (b, bc) = (j.transpose() * DVector::from_vec(r.clone()), jc.transpose() * &rc);
        let bmax = b.iter().fold(0.0f64, |a, v| a.max(v.abs()));
        assert!((b - bc).iter().all(|d| d.abs() <= 1e-12 * bmax), "J^T r differs");
        let n2: f64 = r.iter().map(|v| v * v).sum();
        assert!((rc.norm_squared() - n2).abs() <= 1e-12 * n2);
        // The Jacobian asked for after a residual pass elsewhere is recomputed at x: identical.
        let mut p = p;
        let mut y = x.clone();
        y[2] += 0.05;
        p.set_params(&DVector::from_column_slice(&y));
        p.residuals().expect("finite residuals");
        p.set_params(&DVector::from_column_slice(&x));
        assert_eq!(p.jacobian().expect("finite Jacobian"), jc);
    }

    /// LM on the compressed problem reaches the full problem's optimum: the objective to 1e-9 relative
    /// (both stop at 1e-10 relative changes) and the parameters to 1e-4 (flat directions of a deviance
    /// of ~1e4 move ~sqrt(1e-10 f) / curvature, far below the standard errors).
    #[test]
    fn compressed_lm_reaches_the_same_optimum() {
        use levenberg_marquardt::LevenbergMarquardt;
        let (data, x0) = data(Objective::Poisson);
        let run = |on: bool| {
            let p = Problem::new(&data, ModelId::Ellipsoid, &x0).with_compression(on);
            let (p, rep) = LevenbergMarquardt::new().with_ftol(1e-10).with_xtol(1e-10).with_gtol(0.0).minimize(p);
            assert!(rep.termination.was_successful(), "{:?}", rep.termination);
            (p.objective(), p.x.as_slice().to_vec())
        };
        let (f0, x_full) = run(false);
        let (f1, x_comp) = run(true);
        assert!((f0 - f1).abs() <= 1e-9 * f0, "{f0} vs {f1}");
        for (a, b) in x_full.iter().zip(&x_comp) {
            assert!((a - b).abs() <= 1e-4, "{x_full:?} vs {x_comp:?}");
        }
    }

    /// Inside LM the Jacobian reuses the last residual pass: it must equal a fresh evaluation bit for bit,
    /// whether the pass it finds is at the same point (reused) or elsewhere (recomputed).
    #[test]
    fn cached_jacobian_equals_a_fresh_one_bit_for_bit() {
        for objective in [Objective::Poisson, Objective::Logd] {
            let (data, x) = data(objective);
            let k = data.bins.len();
            let (mut r, mut fresh) = (vec![0.0; k], DMatrix::zeros(k, x.len()));
            jacobian_into(&data, ModelId::Ellipsoid, &x, &mut r, &mut fresh);
            let mut p = Problem::new(&data, ModelId::Ellipsoid, &x).with_compression(false);
            let res = p.residuals().expect("finite residuals");
            assert_eq!(res.as_slice(), r.as_slice());
            assert_eq!(p.jacobian().expect("finite Jacobian"), fresh);
            // A residual pass elsewhere, then the Jacobian back at x: recomputed, still identical.
            let mut y = x.clone();
            y[0] += 0.1;
            p.set_params(&DVector::from_column_slice(&y));
            p.residuals().expect("finite residuals");
            p.set_params(&DVector::from_column_slice(&x));
            assert_eq!(p.jacobian().expect("finite Jacobian"), fresh);
            assert_eq!(p.objective(), r.iter().map(|v| v * v).sum::<f64>());
        }
    }
}
