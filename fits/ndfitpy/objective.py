"""The fit objectives and the NDF difference metric of data_formats/objective.md, in numpy.

Symbols as there: bins k with count c_k, direction m_k, projected solid angle W_k; N = sum_k c_k;
expected counts E_k = N D(m_k) W_k (midpoint rule); bins with W_k = 0 are left out.
"""

from __future__ import annotations

import math

import numpy as np

from . import models
from .bins import Bins

OBJECTIVES = ("poisson", "logd")

# No floor on ln E: a lobe far too narrow for the data has ln E ~ -1e4 at occupied bins, and the deviance term
# 2 c (E/c - 1 - ln(E/c)) ~ -2 c ln E is computed from ln E directly, so it stays finite and exact. A floor
# (as an earlier version had) would cap that penalty and let absurdly narrow lobes look good.


def _prep(bins: Bins) -> Bins:
    return bins.used() if np.any(bins.proj_solid_angle <= 0.0) else bins


def log_expected(model: str, params, bins: Bins, want_grad: bool = False):
    """ln E_k = ln N + ln D(m_k) + ln W_k over the bins with W_k > 0, and d ln E / d params."""
    b = _prep(bins)
    logd, g = models.log_d_and_grad(model, params, b.m, want_grad)
    ln_e = math.log(b.n_samples) + logd + np.log(b.proj_solid_angle)
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
    """F = sum_{c_k >= 10} c_k (ln D(m_k) - ln d_k)^2 with d_k = c_k / (N W_k) (objective.md, `logd`)."""
    b = _prep(bins)
    sel = b.count >= min_count
    if not np.any(sel):
        raise ValueError(f"{bins.path}: objective 'logd' needs bins with count >= {min_count:g}; there are none")
    m, c, w = b.m[sel], b.count[sel], b.proj_solid_angle[sel]
    logd, g = models.log_d_and_grad(model, params, m, want_grad)
    ln_data = np.log(c) - math.log(b.n_samples) - np.log(w)
    r = logd - ln_data
    f = float(np.sum(c * r * r))
    if not want_grad:
        return f
    return f, 2.0 * ((c * r) @ g)


def objective(name: str, model: str, params, bins: Bins, want_grad: bool = False):
    """Dispatch to the objective ``name`` (``poisson`` or ``logd``)."""
    if name == "poisson":
        return poisson_deviance(model, params, bins, want_grad)
    if name == "logd":
        return logd_objective(model, params, bins, want_grad)
    raise ValueError(f"unknown objective '{name}' (expected one of {', '.join(OBJECTIVES)})")


def dof(model: str, bins: Bins) -> int:
    """K - p: K bins with c_k > 0 (and W_k > 0) minus the model's parameter count (objective.md)."""
    b = _prep(bins)
    return int(np.count_nonzero(b.count > 0)) - len(models.PARAM_NAMES[model])


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
