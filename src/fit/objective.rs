//! The objective of `data_formats/objective.md`: per-bin residuals whose squares sum to the objective,
//! and their derivative with respect to `ln D` (the chain rule then gives the Jacobian from [`super::lnd`]).

use nalgebra::Vector3;
use rayon::prelude::*;

use crate::error::{Error, ErrorKind, Result};
use crate::models::Ndf;
use crate::ndf::quantum::{rounding_kernel, HeightQuantum, MAX_RESOLVED_STEP, MODELLED_STEP};
use crate::ndf::{EmpiricalNdf, NormalScheme};

/// Which residuals the fit minimizes (both defined in `data_formats/objective.md`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Objective {
    /// Poisson deviance of the bin counts (the likelihood-ratio statistic); every bin with `W > 0`.
    #[default]
    Poisson,
    /// Count-weighted least squares on `ln D` over bins with `c >= 10`.
    Logd,
}

impl Objective {
    /// The name used on the command line and in the JSON.
    pub fn as_str(self) -> &'static str {
        match self {
            Objective::Poisson => "poisson",
            Objective::Logd => "logd",
        }
    }
}

impl std::str::FromStr for Objective {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "poisson" => Ok(Objective::Poisson),
            "logd" => Ok(Objective::Logd),
            _ => Err(Error::invalid(format!("unknown objective '{s}' (expected poisson or logd)"))),
        }
    }
}

/// Minimum count of a bin in the `logd` objective (objective.md): below it `ln d` is too noisy (and
/// undefined at 0) for a Gaussian model of its error.
pub const LOGD_MIN_COUNT: f64 = 10.0;

/// Default largest polar angle of the bins the fit uses (degrees), see [`FitData::new`] and objective.md:
/// measured on the synthetic ellipsoid scans, whose grid loses the grazing normals near the footprint
/// rim (slopes -> infinity), as a real instrument's numerical aperture does.
pub const DEFAULT_MAX_THETA_DEG: f64 = 70.0;

/// One bin as the objective sees it, with per-bin constants precomputed once.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bin {
    /// Central direction (unit, `z > 0`).
    pub m: Vector3<f64>,
    /// Count `c_k`.
    pub c: f64,
    /// Projected solid angle `W_k` (sr).
    pub w: f64,
    /// `ln(N_in W_k)`, so `ln E_k = ln_nw + ln D(m_k) - ln S` (objective.md).
    pub ln_nw: f64,
    /// `ln c_k` (0 for an empty bin, where it is not used).
    pub ln_c: f64,
    /// `ln W_k` (precomputed: the normalization `S` needs it at every evaluation).
    pub ln_w: f64,
}

impl Bin {
    /// A bin from its direction (normalized here), count `c`, projected solid angle `w` and the region's
    /// count `n` (`N_in`).
    pub fn new(m: Vector3<f64>, c: f64, w: f64, n: f64) -> Bin {
        Bin { m: m.normalize(), c, w, ln_nw: (n * w).ln(), ln_c: if c > 0.0 { c.ln() } else { 0.0 }, ln_w: w.ln() }
    }
}

/// The bins a fit uses (objective.md): the region `R` of bins with `W_k > 0` and a central direction
/// within `max_theta` of n, with `N_in = sum_{k in R} c_k`. The model is normalized over `R`
/// (`S = sum_{k in R} D(m_k) W_k`), so the fit is the likelihood of the counts conditional on the
/// normals falling in `R`.
#[derive(Debug, Clone, PartialEq)]
pub struct FitData {
    /// Bins of the region `R` (for `logd`, those with `c_k < 10` are in `R`, so in `S`, but carry a zero
    /// residual).
    pub bins: Vec<Bin>,
    /// `N_in`, the count inside the region.
    pub n: f64,
    /// `N` of the whole NDF (every bin with `W_k > 0`).
    pub n_total: f64,
    /// Number of bins carrying a residual with `c_k > 0`.
    pub k_nonzero: usize,
    /// Number of bins carrying a residual (all of `R` for `poisson`, `c_k >= 10` for `logd`).
    pub n_residual_bins: usize,
    /// Largest polar angle of a bin centre (radians).
    pub max_theta: f64,
    /// The objective.
    pub objective: Objective,
    /// Whether Levenberg-Marquardt sees compressed residuals (`Problem`): set for a
    /// region of at least `COMPRESS_MIN_BINS` fine bins and inherited by its merged
    /// bins ([`FitData::coarsened`]), so one fit's passes all solve the same way.
    pub lm_compressed: bool,
    /// The tail bins left out of the region (`tail`; nothing cut for [`FitData::new`]).
    pub tail: super::tail::TailCut,
    /// The rounding of a quantized scan's heights, which every bin's model carries (`None` when the
    /// heights are not on a material lattice: then `D` is evaluated at `m_k` alone).
    pub rounding: Option<Rounding>,
}

/// The rounding of quantized heights in the model. Each slope is the true one plus the rounding error
/// of its heights ([`crate::ndf::quantum::rounding_kernel`], covariance `K`), so a bin's count
/// estimates the slope density `P22 = D m_z^4` (Heitz eq. 64) smoothed by that error, not `P22`
/// itself; a model evaluated at `m_k` alone fits a lobe wider by `K` (alpha by `r^2 / 12` relative at a
/// whitened step `r`). The bin's model is therefore the mean of `P22` over `s_k + L (u, v)` (`L L^T = K`)
/// by the product of the three-point Gauss rule of the unit-variance triangle density per axis (nodes 0
/// and `+-sqrt(12/5)`, weights 7/12 and 5/24; exact for polynomials of degree 5 in each of `u`, `v`),
/// which is the error's own law for central differences (two independent triangles):
/// `E_k = N W_k sum_q w_q D(m_q) (m_z(s_q) / m_z(s_k))^4` before the normalization.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Rounding {
    /// The height step `q` (m) of the scan.
    pub quantum: f64,
    /// The slope lattice's spacing along x and y.
    pub slope_step: [f64; 2],
    /// The covariance `K` of the slope error (per slope axis; x, y).
    pub kernel: [[f64; 2]; 2],
    /// Per bin of the region, the rule's directions `m_q` and `ln(w_q (m_z(s_q) / m_z(s_k))^4)`.
    #[serde(skip)]
    pub points: Vec<[(Vector3<f64>, f64); RULE_POINTS]>,
}

impl Rounding {
    /// The rule of the lattice `quantum` of `scheme` for `bins`; `None` for a lattice finer than
    /// `MODELLED_STEP` or coarser than `MAX_RESOLVED_STEP`, and for a kernel that is zero or not a
    /// finite positive definite matrix.
    pub fn new(quantum: &HeightQuantum, scheme: NormalScheme, bins: &[Bin]) -> Option<Rounding> {
        // Guard: a lattice too fine to matter is not modelled (its cost is nine lobe evaluations per bin),
        // nor one too coarse to resolve the NDF, where the errors depend on the slope (the fit is `unresolved`).
        let r = quantum.whitened_step[0].max(quantum.whitened_step[1]);
        if !(MODELLED_STEP..=MAX_RESOLVED_STEP).contains(&r) {
            return None;
        }
        let k = rounding_kernel(scheme, quantum.slope_step);
        let chol = cholesky(&k)?;
        let points = bins.iter().map(|b| rule(&chol, &b.m)).collect();
        Some(Rounding { quantum: quantum.quantum, slope_step: quantum.slope_step, kernel: k, points })
    }

    /// The kernel's lower Cholesky factor `L` (zero for a kernel that has none: then the rule is the point
    /// value, as for a rounding read back from a report of a degenerate lattice).
    fn chol(&self) -> [[f64; 2]; 2] {
        cholesky(&self.kernel).unwrap_or([[0.0; 2]; 2])
    }

    /// The same rule for other bins (the merged bins of [`FitData::coarsened`]).
    fn for_bins(&self, bins: &[Bin]) -> Rounding {
        let chol = self.chol();
        let points = bins.iter().map(|b| rule(&chol, &b.m)).collect();
        Rounding { quantum: self.quantum, slope_step: self.slope_step, kernel: self.kernel, points }
    }

    /// `D` of `model` as the bins see it at `m`: the rule's mean of `P22` around the slope of `m`, over
    /// `m_z^4`.
    pub fn seen_d(&self, model: &impl Ndf, m: Vector3<f64>) -> f64 {
        rule(&self.chol(), &m).iter().map(|(q, lw)| model.d(*q) * lw.exp()).sum()
    }
}

/// A model as the bins of its fit see it: smoothed by the height rounding where the fit models one
/// ([`Rounding`]), the model itself otherwise. The fit error against the data is measured on this.
#[derive(Debug, Clone, Copy)]
pub struct Seen<'a, N> {
    /// The fitted model.
    pub model: &'a N,
    /// The rounding the fit modelled, if any.
    pub rounding: Option<&'a Rounding>,
}

impl<N: Ndf> Ndf for Seen<'_, N> {
    fn d(&self, m: Vector3<f64>) -> f64 {
        match self.rounding {
            Some(r) => r.seen_d(self.model, m),
            None => self.model.d(m),
        }
    }
}

/// The lower Cholesky factor of a 2 x 2 covariance; `None` for one that is zero, not finite or not
/// positive definite (nothing to model, and no factor).
fn cholesky(k: &[[f64; 2]; 2]) -> Option<[[f64; 2]; 2]> {
    let l00 = k[0][0].sqrt();
    let l10 = k[1][0] / l00;
    let l11 = (k[1][1] - l10 * l10).sqrt();
    (l00 > 0.0 && l00.is_finite() && l11 > 0.0 && l11.is_finite()).then_some([[l00, 0.0], [l10, l11]])
}

/// Points of [`Rounding`]'s rule per bin.
pub const RULE_POINTS: usize = 9;

/// The rule's points around the bin direction `m` (unit, `z > 0`) for the kernel's Cholesky factor `l`.
fn rule(l: &[[f64; 2]; 2], m: &Vector3<f64>) -> [(Vector3<f64>, f64); RULE_POINTS] {
    // Slopes s = -(m_x, m_y) / m_z, and back: m = (-s_x, -s_y, 1) / sqrt(1 + |s|^2), so m_z^4 = (1 + |s|^2)^-2.
    let s = [-m.x / m.z, -m.y / m.z];
    let t0 = 1.0 + s[0] * s[0] + s[1] * s[1];
    let a = (12.0f64 / 5.0).sqrt();
    let node: [(f64, f64); 3] = [(0.0, 7.0 / 12.0), (a, 5.0 / 24.0), (-a, 5.0 / 24.0)];
    std::array::from_fn(|i| {
        let ((u, wu), (v, wv)) = (node[i / 3], node[i % 3]);
        let q = [s[0] + l[0][0] * u, s[1] + l[1][0] * u + l[1][1] * v];
        let t = 1.0 + q[0] * q[0] + q[1] * q[1];
        (Vector3::new(-q[0], -q[1], 1.0) / t.sqrt(), 2.0 * (t0 / t).ln() + (wu * wv).ln())
    })
}

impl FitData {
    /// Select and prepare the bins of `ndf` for `objective`, keeping bins whose central direction is
    /// within `max_theta` (radians; `>= pi/2` keeps the hemisphere) of n. Fails on an NDF with no counts
    /// in that region.
    pub fn new(ndf: &EmpiricalNdf, objective: Objective, max_theta: f64) -> Result<FitData> {
        FitData::with_tail(ndf, objective, max_theta, super::tail::TailRule::All)
    }

    /// [`FitData::new`] with the tail cut of `rule` (`tail`): the bins it leaves out also leave
    /// the region.
    pub fn with_tail(ndf: &EmpiricalNdf, objective: Objective, max_theta: f64, rule: super::tail::TailRule) -> Result<FitData> {
        if !(max_theta > 0.0) {
            return Err(Error::invalid(format!("max_theta must be positive, got {max_theta}")));
        }
        let usable = |b: &&crate::ndf::NdfBin| {
            // Bins at or below the horizon have no projected area and D = 0 there: not data.
            b.proj_solid_angle > 0.0 && b.proj_solid_angle.is_finite() && b.m.z > 0.0 && b.m.iter().all(|v| v.is_finite())
        };
        let n_total: f64 = ndf.bins.iter().filter(usable).map(|b| b.count as f64).sum();
        if n_total <= 0.0 {
            return Err(Error::new(ErrorKind::BadData, "the empirical NDF has no counts (no valid normals)"));
        }
        // Past pi/2 there are no bins (the horizon bounds them): the hemisphere.
        let max_theta = max_theta.min(std::f64::consts::FRAC_PI_2);
        let cos_max = max_theta.cos();
        let tail = super::tail::tail_cut(ndf, cos_max, rule);
        let cut = tail.bins_excluded > 0;
        let keep: Vec<bool> = (0..ndf.bins.len()).into_par_iter().map(|k| !(cut && tail.excludes(ndf, k))).collect();
        let inside = |(k, b): &(usize, &crate::ndf::NdfBin)| keep[*k] && b.m.z >= cos_max * b.m.norm();
        let usable = |(_, b): &(usize, &crate::ndf::NdfBin)| usable(b);
        // The region's bins by index, and their count summed in bin order.
        let region: Vec<usize> = ndf.bins.iter().enumerate().filter(usable).filter(inside).map(|(k, _)| k).collect();
        let n: f64 = region.iter().map(|&k| ndf.bins[k].count as f64).sum();
        if n <= 0.0 {
            return Err(Error::new(
                ErrorKind::BadData,
                format!("no normal within max_theta = {:.1} deg of the mean plane's normal", max_theta.to_degrees()),
            ));
        }
        // In bin order, built on every thread straight into place (an indexed collect: no pieces to join).
        let bins: Vec<Bin> = region
            .par_iter()
            .map(|&k| {
                let b = &ndf.bins[k];
                Bin::new(b.m, b.count as f64, b.proj_solid_angle, n)
            })
            .collect();
        let carries = |b: &&Bin| objective == Objective::Poisson || b.c >= LOGD_MIN_COUNT;
        let k_nonzero = bins.iter().filter(carries).filter(|b| b.c > 0.0).count();
        let n_residual_bins = bins.iter().filter(carries).count();
        if n_residual_bins == 0 {
            return Err(Error::new(ErrorKind::BadData, format!("no NDF bin qualifies for the {} objective", objective.as_str())));
        }
        let lm_compressed = bins.len() >= super::problem::COMPRESS_MIN_BINS;
        let rounding = ndf.quantization.as_ref().and_then(|q| Rounding::new(q, ndf.scheme, &bins));
        Ok(FitData { bins, n, n_total, k_nonzero, n_residual_bins, max_theta, objective, lm_compressed, tail, rounding })
    }

    /// The same region on a grid twice as coarse: the fine bins of `ndf` in the region merged 2 x 2 by
    /// their cell (counts and `W` summed, direction the `W`-weighted mean), for a cheap first pass of
    /// the solver (the optimum is then polished on the fine bins). `None` when the NDF has no grid or
    /// merging would leave fewer than `min_bins` bins.
    pub fn coarsened(&self, ndf: &EmpiricalNdf, min_bins: usize) -> Option<FitData> {
        let n = ndf.grid.n;
        if n == 0 || ndf.bin_cells.len() != ndf.bins.len() {
            return None;
        }
        let nc = n / 2 + 1;
        let mut acc: Vec<(f64, f64, Vector3<f64>)> = vec![(0.0, 0.0, Vector3::zeros()); nc * nc];
        let cos_max = self.max_theta.cos();
        let cut = self.tail.bins_excluded > 0;
        for (k, (b, &cell)) in ndf.bins.iter().zip(&ndf.bin_cells).enumerate() {
            let ok = b.proj_solid_angle > 0.0 && b.proj_solid_angle.is_finite() && b.m.z > 0.0 && b.m.iter().all(|v| v.is_finite());
            if !ok || b.m.z < cos_max * b.m.norm() || (cut && self.tail.excludes(ndf, k)) {
                continue;
            }
            let (ix, iy) = (cell as usize % n, cell as usize / n);
            let a = &mut acc[(iy / 2) * nc + ix / 2];
            a.0 += b.count as f64;
            a.1 += b.proj_solid_angle;
            a.2 += b.proj_solid_angle * b.m.normalize();
        }
        // The merged cells with area, in cell order, made into bins on every thread.
        let merged: Vec<_> = acc.into_iter().filter(|a| a.1 > 0.0).collect();
        let bins: Vec<Bin> = merged.into_par_iter().map(|(c, w, m)| Bin::new(m, c, w, self.n)).collect();
        if bins.len() < min_bins {
            return None;
        }
        let carries = |b: &&Bin| self.objective == Objective::Poisson || b.c >= LOGD_MIN_COUNT;
        let k_nonzero = bins.iter().filter(carries).filter(|b| b.c > 0.0).count();
        let n_residual_bins = bins.iter().filter(carries).count();
        (n_residual_bins > 0).then_some(FitData {
            n: self.n,
            n_total: self.n_total,
            k_nonzero,
            n_residual_bins,
            max_theta: self.max_theta,
            objective: self.objective,
            lm_compressed: self.lm_compressed,
            tail: self.tail.clone(),
            rounding: self.rounding.as_ref().map(|r| r.for_bins(&bins)),
            bins,
        })
    }

    /// `ln S = ln sum_k D(m_k) W_k` over the region from `ln D(m_k)` (one per bin; log-sum-exp, so that
    /// no extreme lobe overflows or underflows the sum).
    pub fn ln_norm(&self, ln_d: &[f64]) -> f64 {
        let shift = self.bins.iter().zip(ln_d).map(|(b, l)| l + b.ln_w).fold(f64::NEG_INFINITY, f64::max);
        // Guard: a model with no finite mass anywhere in R; the caller reports a failed evaluation.
        if !shift.is_finite() {
            return shift;
        }
        let s: f64 = self.bins.iter().zip(ln_d).map(|(b, l)| (l + b.ln_w - shift).exp()).sum();
        shift + s.ln()
    }
}

/// `exp(l) - 1 - l` given `l` and `el = exp(l)` (with `l = ln(E/c)`, `h = c (exp(l) - 1 - l)`), accurate
/// near `l = 0` where the direct form cancels: there a series in `l` alone, so no transcendental is needed
/// when the caller already has `E` (and so `el = E / c`).
#[inline]
fn expm1_minus(l: f64, el: f64) -> f64 {
    if l.abs() < 0.05 {
        // Taylor series to l^9: the first omitted term l^10/10! is below 2e-17 relative to l^2/2 here.
        let t = 1.0 / 5040.0 + l * (1.0 / 40320.0 + l * (1.0 / 362880.0));
        l * l * (0.5 + l * (1.0 / 6.0 + l * (1.0 / 24.0 + l * (1.0 / 120.0 + l * (1.0 / 720.0 + l * t)))))
    } else {
        // |l| >= 0.05: the result is >= 1.2e-3 while el carries tens of ulps (E and l may be computed
        // apart), so the relative error stays below ~1e-11.
        el - 1.0 - l
    }
}

/// The Poisson deviance residual of a bin with count `c` and expectation `e = E_k`, given
/// `l = ln(E_k / c_k)` (unused at `c = 0`): `r_k` and `d r_k / d ln E_k` (objective.md).
#[inline]
pub fn poisson_residual(c: f64, e: f64, l: f64) -> (f64, f64) {
    // h = E - c + c ln(c/E) = c (exp(l) - 1 - l) >= 0: accurate near l = 0 where E - c and c ln(c/E) cancel.
    let h = if c == 0.0 {
        e
    } else if l < 700.0 {
        c * expm1_minus(l, e / c)
    } else {
        // Guard: far above the data (l > 700) exp overflows; h is then E to all digits anyway.
        f64::INFINITY
    };
    let r = if c > e { (2.0 * h).sqrt() } else { -(2.0 * h).sqrt() };
    // dr/dlnD = (E - c)/r; at r = 0 its limit is -sqrt(c) (r ~ -(E-c)/sqrt(c) near E = c).
    let dr = if r != 0.0 { (e - c) / r } else { -c.sqrt() };
    (r, dr)
}

/// Residual `r_k` and `d r_k / d ln D(m_k)` for a bin given the normalized `ln D(m_k) - ln S`
/// (objective.md; `ln S = 0` is the unconditional `E_k = N D W`).
#[inline]
pub fn residual(objective: Objective, bin: &Bin, ln_d: f64) -> (f64, f64) {
    match objective {
        Objective::Poisson => {
            let ln_e = bin.ln_nw + ln_d;
            let l = ln_e - bin.ln_c;
            // At c = 0, l is not used and E = exp(ln E).
            let e = if bin.c == 0.0 { ln_e.exp() } else { bin.c * l.exp() };
            poisson_residual(bin.c, e, l)
        }
        // A region bin with too few counts for logd: no residual (it still counts in S).
        Objective::Logd if bin.c < LOGD_MIN_COUNT => (0.0, 0.0),
        Objective::Logd => {
            let sc = bin.c.sqrt();
            // ln d_k = ln(c_k / (N W_k)) = ln c_k - ln_nw.
            (sc * (ln_d - (bin.ln_c - bin.ln_nw)), sc)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `exp(l) - 1 - l` on both sides of the series threshold (0.05) against libm's `exp_m1(l) - l`, which
    /// is accurate to ~2 eps / |l| relative there (a cancellation of size l against l^2/2): 1e-12 relative
    /// covers that at |l| >= 1e-3, while a wrong series term would be off by > 1e-8.
    #[test]
    fn expm1_minus_matches_libm() {
        for l in [-0.3f64, -0.0500001, -0.05, -0.0499999, -0.01, -1e-3, 1e-3, 0.01, 0.0499999, 0.05, 0.0500001, 0.3, 2.0] {
            let want = l.exp_m1() - l;
            let got = expm1_minus(l, l.exp());
            assert!((got - want).abs() <= 1e-12 * want, "l = {l}: {got} vs {want}");
        }
        // Near 0, where exp_m1(l) - l cancels: the Taylor terms to l^4/24 (the next, l^5/120, is 1e-20
        // relative to l^2 at l = 1e-6), so a few ulps.
        let l = 1e-6f64;
        assert!((expm1_minus(l, l.exp()) - l * l * (0.5 + l / 6.0 + l * l / 24.0)).abs() <= 1e-15 * l * l);
    }

    /// The Poisson residual squares to the deviance term `2 (E - c + c ln(c/E))` (objective.md), evaluated
    /// directly, with the sign of `c - E`. The direct form cancels near `E = c` (terms of size `E + c`
    /// summing to `h`): its rounding, ~8 eps (E + c) absolute, is the tolerance besides 1e-12 relative.
    #[test]
    fn poisson_residual_is_the_deviance_term() {
        for (c, e) in [(10.0f64, 12.0f64), (10.0, 7.5), (3.0, 0.2), (1.0, 40.0), (0.0, 2.5), (100.0, 100.5)] {
            let l = if c > 0.0 { (e / c).ln() } else { 0.0 };
            let (r, dr) = poisson_residual(c, e, l);
            let h = e - c + if c > 0.0 { c * (c / e).ln() } else { 0.0 };
            let tol = 1e-12 * 2.0 * h + 16.0 * f64::EPSILON * (e + c);
            assert!((r * r - 2.0 * h).abs() <= tol, "c {c} e {e}: r^2 {} vs {}", r * r, 2.0 * h);
            assert_eq!(r > 0.0, c > e);
            // dr/dlnE = (E - c)/r: checked against a central difference in l (E = c e^l scales with it).
            if c > 0.0 {
                let hs = 1e-6f64;
                let rp = poisson_residual(c, e * hs.exp(), l + hs).0;
                let rm = poisson_residual(c, e * (-hs).exp(), l - hs).0;
                assert!(((rp - rm) / (2.0 * hs) - dr).abs() <= 1e-6 * dr.abs().max(1.0), "c {c} e {e}: {dr}");
            }
        }
    }
}
