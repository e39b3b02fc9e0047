"""The fit objectives and the NDF difference metric of data_formats/objective.md, in numpy.

Symbols as there: bins k with count c_k, direction m_k, projected solid angle W_k. The fit region R: bins with
W_k > 0 and a central direction within max_theta (default 70 deg) of n; N_in = sum_{k in R} c_k; expected counts
E_k = N_in D(m_k) W_k / S with S = sum_{j in R} D(m_j) W_j (the likelihood conditional on the normals falling in R,
midpoint rule); on a quantized scan D is the lobe smoothed by the height rounding (ndfitpy.rounding).
"""

from __future__ import annotations

import math

import numpy as np

from . import models, rounding
from .bins import Bins

OBJECTIVES = ("poisson", "logd")

#: The default largest polar angle of the fit region (objective.md), the same as the Rust fitter's.
DEFAULT_MAX_THETA_DEG = 70.0

# No floor on ln E: a lobe far too narrow for the data has ln E ~ -1e4 at occupied bins, and the deviance term
# 2 c (E/c - 1 - ln(E/c)) ~ -2 c ln E is computed from ln E directly, so it stays finite and exact. A floor
# (as an earlier version had) would cap that penalty and let absurdly narrow lobes look good.


def _prep(bins: Bins) -> Bins:
    return bins.used() if np.any(bins.proj_solid_angle <= 0.0) else bins


def region(bins: Bins, max_theta_deg: float = DEFAULT_MAX_THETA_DEG) -> Bins:
    """The fit region R: bins with W_k > 0 and m_z >= cos(max_theta) (objective.md); its n_samples is N_in."""
    b = _prep(bins)
    cos_max = math.cos(math.radians(min(float(max_theta_deg), 90.0)))
    keep = b.m[:, 2] >= cos_max * np.linalg.norm(b.m, axis=1)
    if not np.any(keep & (b.count > 0)):
        raise ValueError(f"{bins.path}: no normal within max_theta = {max_theta_deg:g} deg of n")
    return Bins(m=b.m[keep], count=b.count[keep], proj_solid_angle=b.proj_solid_angle[keep], path=b.path,
                rounding=b.rounding)


def log_d_seen(model: str, params, b: Bins, want_grad: bool = False):
    """ln D of ``model`` as the bins ``b`` count it (smoothed by their height rounding, ndfitpy.rounding), and
    its gradient."""
    return rounding.seen_log_d_and_grad(models.log_d_and_grad, model, params, b.m, b.rounding, want_grad)


def _log_norm(logd: np.ndarray, w: np.ndarray):
    """ln S = ln sum_k D_k W_k (log-sum-exp) and the weights D_k W_k / S."""
    lw = logd + np.log(w)
    top = float(np.max(lw))
    p = np.exp(lw - top)
    tot = float(p.sum())
    return top + math.log(tot), p / tot


def log_expected(model: str, params, bins: Bins, want_grad: bool = False, max_theta_deg: float = DEFAULT_MAX_THETA_DEG):
    """ln E_k = ln N_in + ln D(m_k) + ln W_k - ln S over the region R, and d ln E / d params
    (= g_k - sum_j (D_j W_j / S) g_j with g = d ln D / d params)."""
    b = region(bins, max_theta_deg)
    logd, g = log_d_seen(model, params, b, want_grad)
    ln_s, wts = _log_norm(logd, b.proj_solid_angle)
    ln_e = math.log(b.n_samples) + logd + np.log(b.proj_solid_angle) - ln_s
    if want_grad:
        g = g - wts @ g
    return b, ln_e, g


def poisson_deviance(model: str, params, bins: Bins, want_grad: bool = False):
    """F = sum_k 2 (E_k - c_k + c_k ln(c_k / E_k)) (objective.md, `poisson`); with want_grad also dF/dparams.

    Per bin with c > 0 the term is 2 c (x - 1 - ln x), x = E/c, computed as 2 c (expm1(z) - z) with
    z = ln E - ln c, which is accurate near the optimum where x ~ 1. dF/dp = sum_k 2 (E_k - c_k) d ln D_k / dp.
    """
    b, ln_e, g = log_expected(model, params, bins, want_grad)
    e, terms = _deviance_terms(ln_e, b.count)
    f = float(terms.sum())
    if not want_grad:
        return f
    grad = 2.0 * ((e - b.count) @ g)
    return f, grad


def _deviance_terms(ln_e: np.ndarray, c: np.ndarray):
    """E_k and the per-bin deviance 2 (E - c + c ln(c/E)); inf where the model has no mass (ln E = -inf) at an
    occupied bin (the X+ factor: a bin below the horizon of the model)."""
    with np.errstate(over="ignore"):
        e = np.exp(ln_e)  # underflows to 0 harmlessly; the occupied bins use ln E below
    pos = c > 0
    terms = 2.0 * e  # empty bins: 2 E
    z = ln_e[pos] - np.log(c[pos])
    with np.errstate(over="ignore", invalid="ignore"):
        t = 2.0 * c[pos] * (np.expm1(z) - z)
    terms[pos] = np.where(np.isnan(t), np.inf, t)  # z = -inf gives inf - inf; the deviance is +inf there
    return e, terms


def poisson_residuals(model: str, params, bins: Bins) -> np.ndarray:
    """r_k = sign(c_k - E_k) sqrt(2 (E_k - c_k + c_k ln(c_k/E_k))) (objective.md), so F = sum r_k^2."""
    b, ln_e, _ = log_expected(model, params, bins)
    e, t = _deviance_terms(ln_e, b.count)
    return np.sign(b.count - e) * np.sqrt(np.maximum(t, 0.0))


def logd_objective(model: str, params, bins: Bins, want_grad: bool = False, min_count: float = 10.0):
    """F = sum_{k in R, c_k >= 10} c_k (ln D(m_k) - ln S - ln d_k)^2 with d_k = c_k / (N_in W_k) (objective.md,
    `logd`; S and N_in over the whole region R)."""
    b = region(bins)
    sel = b.count >= min_count
    if not np.any(sel):
        raise ValueError(f"{bins.path}: objective 'logd' needs bins with count >= {min_count:g}; there are none")
    logd_all, g_all = log_d_seen(model, params, b, want_grad)
    ln_s, wts = _log_norm(logd_all, b.proj_solid_angle)
    c, w = b.count[sel], b.proj_solid_angle[sel]
    ln_data = np.log(c) - math.log(b.n_samples) - np.log(w)
    r = logd_all[sel] - ln_s - ln_data
    f = float(np.sum(c * r * r))
    if not want_grad:
        return f
    g = g_all[sel] - wts @ g_all
    return f, 2.0 * ((c * r) @ g)


def objective(name: str, model: str, params, bins: Bins, want_grad: bool = False):
    """Dispatch to the objective ``name`` (``poisson`` or ``logd``)."""
    if name == "poisson":
        return poisson_deviance(model, params, bins, want_grad)
    if name == "logd":
        return logd_objective(model, params, bins, want_grad)
    raise ValueError(f"unknown objective '{name}' (expected one of {', '.join(OBJECTIVES)})")


def dof(model: str, bins: Bins) -> int:
    """K - p - 1: K bins of the region with c_k > 0, minus the model's parameter count, minus one for the
    region's fixed total (objective.md)."""
    b = region(bins)
    return int(np.count_nonzero(b.count > 0)) - len(models.PARAM_NAMES[model]) - 1


def delta(log_d: np.ndarray, log_d_ref: np.ndarray, proj_solid_angle: np.ndarray) -> float:
    """delta(D; D_ref) = sqrt(sum_k w_k (D_k/Dref_k - 1)^2 / sum_k w_k), w_k = Dref_k W_k (objective.md).

    Takes ln D and ln D_ref at the quadrature directions so that tiny values keep their ratio.
    """
    log_d = np.asarray(log_d, dtype=float)
    log_d_ref = np.asarray(log_d_ref, dtype=float)
    w_proj = np.asarray(proj_solid_angle, dtype=float)
    ok = (w_proj > 0.0) & np.isfinite(log_d_ref)
    if not np.any(ok):
        raise ValueError("delta: the reference NDF has no mass on the quadrature directions")
    # Scale the weights by the largest one before exponentiating: sum w is then >= the largest weight, > 0.
    lw = log_d_ref[ok] + np.log(w_proj[ok])
    w = np.exp(lw - lw.max())
    ratio = np.exp(np.clip(log_d[ok] - log_d_ref[ok], -300.0, 300.0))  # guard: (ratio - 1)^2 must not overflow
    return float(math.sqrt(np.sum(w * (ratio - 1.0) ** 2) / np.sum(w)))


def model_delta(model: str, params, model_ref: str, params_ref, bins: Bins) -> float:
    """delta between two models on the bins (objective.md's metric with the bins as quadrature)."""
    b = _prep(bins)
    return delta(models.log_d(model, params, b.m), models.log_d(model_ref, params_ref, b.m), b.proj_solid_angle)


def standard_errors(model: str, params, bins: Bins, scale: float = 1.0):
    """Standard errors of the parameters: the inverse Fisher information of Poisson counts,
    I = sum_k E_k g_k g_k^T with g_k = d ln E_k / d params, times ``scale`` (objective.md: scaled by
    reduced_chi2, since neighbouring normals are correlated). None when I is singular (e.g. theta_z of an
    isotropic lobe)."""
    _, ln_e, g = log_expected(model, params, bins, want_grad=True)
    e = np.exp(ln_e)
    info = (g * e[:, None]).T @ g
    try:
        cov = np.linalg.inv(info) * max(scale, 0.0)
    except np.linalg.LinAlgError:
        return None
    diag = np.diag(cov)
    if not np.all(np.isfinite(diag)) or np.any(diag < 0):
        return None
    return np.sqrt(diag)
