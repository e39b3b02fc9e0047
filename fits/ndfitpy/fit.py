"""Fit an analytic NDF to empirical NDF bins with nlopt (data_formats/objective.md objectives).

Search coordinates: ln(alpha) for every roughness (alpha spans 1e-4..10, and ln keeps it positive and evenly
scaled), the angles in radians, the logit of a mixture weight, and for a Student-t tail a bounded logistic in
ln(gamma - 1) (gamma_of_u says why). Stopping criteria are explicit (nlopt sets none by default): ``xtol_abs`` on
every coordinate (a relative x tolerance would never be met by an angle near 0), ``ftol_rel`` on the objective and
a ``maxeval`` cap. Methods:

- ``bobyqa`` (LN_BOBYQA) / ``sbplx`` (LN_SBPLX): derivative-free;
- ``lbfgs`` (LD_LBFGS): with the analytic gradient of objective.py (LD_SLSQP was tried and dropped: on these
  objectives, whose gradients reach 1e6, it stopped after one evaluation with FTOL_REACHED);
- ``bobyqa+lbfgs`` (default): BOBYQA, then L-BFGS polishing its result; the best point seen is kept.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Dict, List, Optional

import nlopt
import numpy as np

from . import mixtures, models
from . import objective as obj
from .bins import Bins

METHODS = ("bobyqa", "sbplx", "lbfgs", "bobyqa+lbfgs")
_ALGO = {"bobyqa": nlopt.LN_BOBYQA, "sbplx": nlopt.LN_SBPLX, "lbfgs": nlopt.LD_LBFGS}

# Search box. Roughness: the contract's range is 1e-4..10; the box is wider so that the range's ends are not on it.
LN_ALPHA_MIN, LN_ALPHA_MAX = math.log(1e-6), math.log(1e3)
# Tilt: |theta_x|, |theta_y| < 1.5 rad keeps Walter eq. 3's Euler angles away from gimbal lock at pi/2.
TILT_MAX = 1.5


@dataclass
class Stopping:
    """nlopt stopping criteria of one local run."""

    xtol_abs: float = 1e-10  #: on ln(alpha) (so relative on alpha) and on angles (rad)
    ftol_rel: float = 1e-13  #: relative change of the objective
    maxeval: int = 4000  #: evaluations per local run


@dataclass
class FitResult:
    """The outcome of one fit."""

    model: str
    params: Dict[str, float]
    objective: str
    value: float
    method: str
    evaluations: int
    seconds: float
    status: str
    starts: List[dict] = field(default_factory=list)

    @property
    def param_array(self) -> np.ndarray:
        """The parameters in models.PARAM_NAMES order."""
        return models.params_to_array(self.model, self.params)


def _is_log(model: str) -> np.ndarray:
    return np.array([n.startswith("alpha") for n in models.PARAM_NAMES[model]])


def _is_weight(model: str) -> np.ndarray:
    return np.array([n == "weight" for n in models.PARAM_NAMES[model]])


def _is_gamma(model: str) -> np.ndarray:
    return np.array([n == "gamma" for n in models.PARAM_NAMES[model]])


#: Bound of a mixture weight's logit in the search (weights within 1e-13 of 0 or 1), and of gamma's u (gamma within
#: 6e-13 of 3/2 and 1e-12 relative of its largest value).
LOGIT_MAX = 30.0

# gamma's search coordinate: ln(gamma - 1) runs over (_LG0, _LG1) as the logistic of u.
_LG0 = math.log(models.STUDENT_GAMMA_MIN - 1.0)
_LG1 = math.log(models.STUDENT_GAMMA_MAX - 1.0)


def _logistic(u):
    return 0.5 * (1.0 + np.tanh(0.5 * np.asarray(u, dtype=float)))  # 1/(1 + e^-u) without overflow


def gamma_of_u(u):
    """Student-t tail exponent of search coordinate u: ln(gamma - 1) = _LG0 + (_LG1 - _LG0) / (1 + e^-u), so gamma
    lies in (STUDENT_GAMMA_MIN, STUDENT_GAMMA_MAX) for every real u.

    Why this map: the normals' information about gamma per unit of ln(gamma - 1) is largest near 3/2 and falls
    as sqrt(2)/gamma once the lobe turns Beckmann; the logistic's slope in ln(gamma - 1), (_LG1 - _LG0) s (1 - s),
    grows from 0.65 at gamma = 2 to 1.7 at 5 and 2.7 at 30, which evens that out, so a unit step of u moves D by
    about as much anywhere from gamma 2 to 10, like a unit step of ln(alpha) (fits/README.md gives the Fisher
    information per unit u against a logistic in gamma - 3/2)."""
    return 1.0 + np.exp(_LG0 + (_LG1 - _LG0) * _logistic(u))


def gamma_du(u):
    """d gamma / d u of gamma_of_u: (gamma - 1) (_LG1 - _LG0) s (1 - s), s the logistic of u."""
    return (gamma_of_u(u) - 1.0) * (_LG1 - _LG0) * _logistic(u) * _logistic(-np.asarray(u, dtype=float))


def u_of_gamma(gamma):
    """The inverse of gamma_of_u; a gamma at (or beyond) either end maps to +-LOGIT_MAX."""
    with np.errstate(invalid="ignore", divide="ignore"):
        t = (np.log(np.asarray(gamma, dtype=float) - 1.0) - _LG0) / (_LG1 - _LG0)
    t = np.clip(np.nan_to_num(t, nan=0.0), 1e-300, 1.0 - 2.0**-53)  # guard: finite logit at and beyond the ends
    return np.clip(np.log(t) - np.log1p(-t), -LOGIT_MAX, LOGIT_MAX)


def to_search(model: str, params) -> np.ndarray:
    """Natural parameters to search coordinates (ln alpha, angles, logit of a mixture weight, gamma's u)."""
    p = models.params_to_array(model, params).copy()
    lg = _is_log(model)
    p[lg] = np.log(p[lg])
    wt = _is_weight(model)
    p[wt] = np.log(p[wt] / (1.0 - p[wt]))
    gm = _is_gamma(model)
    p[gm] = u_of_gamma(p[gm])
    return p


def from_search(model: str, x) -> np.ndarray:
    """Search coordinates to natural parameters."""
    p = np.array(x, dtype=float)
    lg = _is_log(model)
    p[lg] = np.exp(p[lg])
    wt = _is_weight(model)
    p[wt] = 1.0 / (1.0 + np.exp(-p[wt]))
    gm = _is_gamma(model)
    p[gm] = gamma_of_u(p[gm])
    return p


def search_objective(model: str, bins: Bins, objective: str, x, want_grad: bool = False):
    """The objective at search coordinates ``x``, and with ``want_grad`` its gradient in x (the chain rule through
    from_search's maps)."""
    x = np.asarray(x, dtype=float)
    p = from_search(model, x)
    if not want_grad:
        return obj.objective(objective, model, p, bins)
    val, g = obj.objective(objective, model, p, bins, want_grad=True)
    g = np.where(_is_log(model), g * p, g)  # d/d ln(alpha) = alpha d/d alpha
    g = np.where(_is_weight(model), g * p * (1.0 - p), g)  # d/d logit(w) = w (1 - w) d/dw
    gm = _is_gamma(model)
    g[gm] = g[gm] * gamma_du(x[gm])
    return val, g


def wrap_theta_z(t: float) -> float:
    """theta_z mapped into (-pi/2, pi/2]: every model here is unchanged by theta_z -> theta_z + pi (Rz(pi) flips
    the signs of x and y, and each D is even in them when the tilt is zero; the ellipsoid also flips its tilt)."""
    w = math.fmod(t + 0.5 * math.pi, math.pi)
    if w <= 0.0:
        w += math.pi
    return w - 0.5 * math.pi


# ---------------------------------------------------------------------------------------------------------
# Starting point from the data's slopes


def _weighted_quantile(x: np.ndarray, w: np.ndarray, q: float) -> float:
    order = np.argsort(x)
    cw = np.cumsum(w[order])
    i = int(np.searchsorted(cw, q * cw[-1]))
    return float(x[order[min(i, len(x) - 1)]])


def slope_moments(bins: Bins, core: float = 0.5):
    """Robust slope statistics of the bins' counts: centre (weighted medians), shape matrix (covariance of the
    core fraction ``core`` by Mahalanobis radius, which keeps an elliptical distribution's shape), and the weighted
    median Mahalanobis radius under the unit-determinant shape."""
    b = bins.used()
    pos = b.count > 0
    m = b.m[pos]
    w = b.count[pos]
    z = np.maximum(m[:, 2], 1e-12)  # guard: a bin on the horizon has an infinite slope; cap it
    s = np.column_stack([-m[:, 0] / z, -m[:, 1] / z])
    s0 = np.array([_weighted_quantile(s[:, 0], w, 0.5), _weighted_quantile(s[:, 1], w, 0.5)])
    dlt = s - s0
    shape = np.eye(2)
    for _ in range(4):
        r2 = np.einsum("ij,jk,ik->i", dlt, np.linalg.inv(shape), dlt)
        cut = _weighted_quantile(r2, w, core)
        sel = r2 <= cut
        if np.count_nonzero(sel) < 3 or w[sel].sum() <= 0:
            break
        ds, ws = dlt[sel], w[sel]
        cov = (ds * ws[:, None]).T @ ds / ws.sum()
        det = np.linalg.det(cov)
        # Guard: with all mass in one or two bins the covariance is singular; keep the previous shape then.
        if not (det > 0.0 and np.all(np.isfinite(cov))):
            break
        shape = cov / math.sqrt(det)
    r = np.sqrt(np.einsum("ij,jk,ik->i", dlt, np.linalg.inv(shape), dlt))
    r_med = _weighted_quantile(r, w, 0.5)
    # Guard: a distribution narrower than the central bin gives r_med = 0; use the bin's own slope as the scale.
    if not r_med > 0.0:
        r_med = max(float(np.min(np.hypot(s[:, 0], s[:, 1])[np.hypot(s[:, 0], s[:, 1]) > 0], initial=1e-3)), 1e-5)
    return s0, shape, r_med


def initial_guess(bins: Bins, model: str) -> np.ndarray:
    """A starting point from slope_moments: for GGX the median slope radius is alpha (P22 of Heitz eq. 70 has
    CDF r^2/(r^2 + alpha^2)), for Beckmann it is alpha sqrt(ln 2) (Heitz eq. 67); the shape matrix gives the
    anisotropy ratio and theta_z; the ellipsoid starts untilted (tilts are found from there, see fit())."""
    models.check_model(model)
    _, shape, r_med = slope_moments(bins)
    t_med = math.sqrt(math.log(2.0)) if model.startswith("beckmann") else 1.0
    a_geo = r_med / t_med
    lam, vec = np.linalg.eigh(shape)  # ascending; shape has unit determinant
    lam = np.maximum(lam, 1e-12)
    v = vec[:, 1]  # major axis, the alpha_x direction
    ratio = math.sqrt(lam[1] / lam[0])
    ax, ay = a_geo * math.sqrt(ratio), a_geo / math.sqrt(ratio)
    # In the frame s' = Rz s the major axis is x: Rz(tz) v = e_x, i.e. v = (cos tz, -sin tz).
    tz = wrap_theta_z(-math.atan2(v[1], v[0]))
    if model in ("ggx", "beckmann"):
        return np.array([a_geo])
    if model in ("ggx-aniso", "beckmann-aniso"):
        return np.array([ax, ay, tz])
    return np.array([ax, ay, 0.0, 0.0, tz])


def _bounds(model: str, x0: np.ndarray):
    lg = _is_log(model)
    wt = _is_weight(model) | _is_gamma(model)  # both logistic coordinates, bounded alike
    mix = model in mixtures.PARENT
    ln_alpha_min = math.log(mixtures.ALPHA_FLOOR) if mix else LN_ALPHA_MIN
    ln_alpha_max = math.log(mixtures.LOBE_ALPHA_MAX) if mix else LN_ALPHA_MAX
    lb = np.where(lg, ln_alpha_min, np.where(wt, -LOGIT_MAX, -TILT_MAX))
    ub = np.where(lg, ln_alpha_max, np.where(wt, LOGIT_MAX, TILT_MAX))
    names = models.PARAM_NAMES[model]
    if "theta_z" in names:
        # theta_z has period pi, so an equivalent optimum lies within pi/2 of any start: +-pi leaves slack.
        i = names.index("theta_z")
        lb[i], ub[i] = x0[i] - math.pi, x0[i] + math.pi
    x0 = np.clip(x0, lb, ub)
    return lb, ub, x0


def _scales(model: str, x0: np.ndarray) -> np.ndarray:
    """Per-coordinate scale of one local run: 1 for ln(alpha) and theta_z; for the tilts the lobe's width
    sqrt(alpha_x alpha_y) (a tilt moves the lobe's centre by about the tilt in slope units), so that every
    coordinate moves D by a similar amount per unit step. Conditions L-BFGS and sizes BOBYQA's trust region."""
    sc = np.ones(len(x0))
    names = models.PARAM_NAMES[model]
    if "theta_x" in names:
        width = min(1.0, max(1e-6, math.exp(0.5 * (x0[0] + x0[1]))))
        sc[names.index("theta_x")] = sc[names.index("theta_y")] = width
    return sc


def _local(model: str, bins: Bins, objective: str, x0: np.ndarray, method: str, stop: Stopping):
    """One nlopt run from x0 (search coordinates); returns (best x, best f, evaluations, nlopt status name).

    nlopt works on y = x / scale (_scales); xtol_abs applies to y, i.e. to the tilts relative to the lobe width.
    """
    n = len(x0)
    lb, ub, x0 = _bounds(model, x0)
    sc = _scales(model, x0)
    best = {"x": x0.copy(), "f": math.inf, "n": 0}
    lg = _is_log(model)

    def f(y, grad):
        try:
            return _eval(np.asarray(y) * sc, grad)
        except Exception as e:  # nlopt would turn it into its own error; keep it to re-raise
            best["error"] = e
            raise nlopt.ForcedStop() from e

    def _eval(x, grad):
        best["n"] += 1
        if grad.size > 0:
            val, g = search_objective(model, bins, objective, x, want_grad=True)
            g = g * sc  # d/dy = scale d/dx
            # Guard: an overflowed gradient would derail L-BFGS; zero it and let the line search shrink the step.
            grad[:] = np.where(np.isfinite(g), g, 0.0)
        else:
            val = search_objective(model, bins, objective, x)
        if not math.isfinite(val):
            val = 1e300  # guard: nlopt needs a finite value to reject a step
        if val < best["f"]:
            best["f"], best["x"] = val, np.array(x, dtype=float)
        return float(val)

    opt = nlopt.opt(_ALGO[method], n)
    opt.set_lower_bounds((lb / sc).tolist())
    opt.set_upper_bounds((ub / sc).tolist())
    opt.set_min_objective(f)
    opt.set_xtol_abs(stop.xtol_abs)
    opt.set_ftol_rel(stop.ftol_rel)
    opt.set_maxeval(stop.maxeval)
    if method in ("bobyqa", "sbplx"):
        # First trust radius: 35% in alpha, 20% in gamma - 1 at gamma = 2, ~6 degrees in theta_z, a third of the
        # lobe width in tilt (<= 0.1 rad).
        step = np.where(lg | _is_gamma(model), 0.3, 0.1)
        names = models.PARAM_NAMES[model]
        if "theta_x" in names:
            for k in ("theta_x", "theta_y"):
                i = names.index(k)
                step[i] = min(0.3, 0.1 / sc[i])
        opt.set_initial_step(step.tolist())
    status = "ok"
    try:
        opt.optimize((x0 / sc).tolist())
        code = opt.last_optimize_result()
        status = {
            nlopt.SUCCESS: "success",
            nlopt.STOPVAL_REACHED: "stopval",
            nlopt.FTOL_REACHED: "ftol",
            nlopt.XTOL_REACHED: "xtol",
            nlopt.MAXEVAL_REACHED: "maxeval",
            nlopt.MAXTIME_REACHED: "maxtime",
        }.get(code, str(code))
    except nlopt.RoundoffLimited:
        status = "roundoff"  # the best point seen is still a valid result
    except Exception as e:  # nlopt's generic failure (e.g. L-BFGS's line search started at an optimum)
        if "error" in best:
            raise best["error"]
        status = f"stopped ({type(e).__name__})"  # the best point seen is still valid
    return best["x"], best["f"], best["n"], status


def _polish(model, bins, objective, x, fv, stop):
    """L-BFGS from x, restarted (fresh Hessian model) while a restart still gains more than ftol_rel."""
    n_total, statuses = 0, []
    for _ in range(4):
        x2, f2, n2, s2 = _local(model, bins, objective, x, "lbfgs", stop)
        n_total += n2
        statuses.append(s2)
        gain = fv - f2
        if f2 < fv:
            x, fv = x2, f2
        if not gain > stop.ftol_rel * abs(fv):
            break
    return x, fv, n_total, "+".join(statuses)


def _run(model, bins, objective, x0_nat, method, stop):
    x0 = to_search(model, x0_nat)
    if method == "bobyqa+lbfgs":
        # BOBYQA only has to bring L-BFGS into the basin: looser tolerances there, the tight ones for L-BFGS.
        rough = Stopping(xtol_abs=max(stop.xtol_abs, 1e-7), ftol_rel=max(stop.ftol_rel, 1e-10), maxeval=stop.maxeval)
        x1, f1, n1, s1 = _local(model, bins, objective, x0, "bobyqa", rough)
        x2, f2, n2, s2 = _polish(model, bins, objective, x1, f1, stop)
        return x2, f2, n1 + n2, f"bobyqa:{s1},lbfgs:{s2}"
    if method == "lbfgs":
        x, fv, ne, st = _polish(model, bins, objective, x0, math.inf, stop)
        return x, fv, ne, f"lbfgs:{st}"
    x, fv, ne, st = _local(model, bins, objective, x0, method, stop)
    return x, fv, ne, f"{method}:{st}"


def _tilt_start(bins: Bins, aniso: np.ndarray) -> np.ndarray:
    """Ellipsoid start whose slope-density centre (synthetic.ellipsoid_slope_quadric) matches the data's median
    slope, from a ggx-aniso solution."""
    s_target, _, _ = slope_moments(bins)
    return _tilt_for_centre(aniso, s_target)


def _tilt_for_centre(aniso: np.ndarray, s_target: np.ndarray) -> np.ndarray:
    """The ellipsoid (alphas and theta_z of ``aniso``) whose slope-density centre is ``s_target``: a few Newton steps on
    the tilts with a finite-difference Jacobian."""
    from .synthetic import ellipsoid_slope_quadric

    p = np.array([aniso[0], aniso[1], 0.0, 0.0, aniso[2]])

    def centre(t):
        q = p.copy()
        q[2:4] = t
        return ellipsoid_slope_quadric(models.ellipsoid_matrix(*q))[0]

    t = np.zeros(2)
    for _ in range(8):
        c = centre(t)
        r = c - s_target
        if np.linalg.norm(r) < 1e-9:
            break
        h = 1e-6
        jac = np.column_stack([(centre(t + h * e) - centre(t - h * e)) / (2 * h) for e in np.eye(2)])
        try:
            step = np.linalg.solve(jac, r)
        except np.linalg.LinAlgError:
            break
        t = np.clip(t - step, -1.0, 1.0)
    p[2:4] = t
    return p


def fit(
    bins: Bins,
    model: str,
    objective: str = "poisson",
    method: str = "bobyqa+lbfgs",
    x0=None,
    stop: Optional[Stopping] = None,
) -> FitResult:
    """Fit ``model`` to ``bins``; the result's ``value`` is the objective at the returned parameters.

    Without ``x0`` the start comes from initial_guess(); the ellipsoid is fitted in stages: ggx-aniso first, then
    the ellipsoid from that solution untilted and from a tilt matching the data's median slope, keeping the best.
    """
    models.check_model(model)
    if method not in METHODS:
        raise ValueError(f"unknown method '{method}' (expected one of {', '.join(METHODS)})")
    if objective not in obj.OBJECTIVES:
        raise ValueError(f"unknown objective '{objective}' (expected one of {', '.join(obj.OBJECTIVES)})")
    stop = stop or Stopping()
    t_start = time.perf_counter()
    starts: List[np.ndarray] = []
    ridges = set()
    evaluations = 0
    if x0 is not None:
        starts.append(models.params_to_array(model, x0))
    elif model in mixtures.PARENT:
        pre = fit(bins, mixtures.PARENT[model], objective, method, stop=stop)
        evaluations += pre.evaluations
        starts.extend(mixtures.starts(model, pre.param_array))
        starts.extend(
            mixtures.data_starts(model, pre.param_array, bins, obj.log_expected, lambda a, c: _tilt_for_centre(a, c)[2:4])
        )
        ridge = mixtures.ridge_starts(model, pre.param_array, bins, obj.log_expected, models.log_d)
        ridges = set(range(len(starts), len(starts) + len(ridge)))
        starts.extend(ridge)
    elif model in models.STUDENTS:
        # Grown from this module's own GGX fit of the same bins: GGX is the STD at gamma = 2.
        pre = fit(bins, "ggx" if model == "student" else "ggx-aniso", objective, method, stop=stop)
        evaluations += pre.evaluations
        starts.append(np.append(pre.param_array, 2.0))
    elif model == "ellipsoid":
        pre = fit(bins, "ggx-aniso", objective, method, stop=stop)
        evaluations += pre.evaluations
        a = pre.param_array
        starts.append(np.array([a[0], a[1], 0.0, 0.0, a[2]]))
        tilted = _tilt_start(bins, a)
        if np.any(np.abs(tilted[2:4]) > 1e-6):
            starts.append(tilted)
    else:
        starts.append(initial_guess(bins, model))
    best = None
    log = []
    for k, s in enumerate(starts):
        # The ridges (a lobe at the alpha floor across one axis) go to L-BFGS alone: BOBYQA's quadratic models creep
        # from such a start for their whole budget (4,000 evaluations, 10 s on a 8,000-bin scan) where it fails.
        m = "lbfgs" if k in ridges and method == "bobyqa+lbfgs" else method
        x, fv, ne, st = _run(model, bins, objective, s, m, stop)
        evaluations += ne
        log.append({"start": s.tolist(), "value": fv, "status": st})
        if best is None or fv < best[1]:
            best = (x, fv, st)
    if model in mixtures.PARENT:
        reg = obj.region(bins)
        z = reg.m[:, 2]
        s_max = float(np.max(np.sqrt(np.maximum(1.0 - z * z, 0.0)) / z)) if len(z) else 0.0
        end = mixtures.valley_end(model, from_search(model, best[0]), s_max)
        if end is not None:
            x, fv, ne, st = _run(model, bins, objective, end, "lbfgs", stop)
            evaluations += ne
            log.append({"start": end.tolist(), "value": fv, "status": st})
            if fv <= best[1]:
                best = (x, fv, st)
    p = from_search(model, best[0])
    names = models.PARAM_NAMES[model]
    if "theta_z" in names:
        i = names.index("theta_z")
        w = wrap_theta_z(p[i])
        if model in ("ellipsoid", "ellipsoid+ggx") and w != p[i] and abs(round((w - p[i]) / math.pi)) % 2 == 1:
            p[2], p[3] = -p[2], -p[3]  # theta_z + pi with negated tilts is the same ellipsoid (canonical.py)
        p[i] = w
    value = obj.objective(objective, model, p, bins)
    if model in mixtures.PARENT and x0 is None and not value < pre.value - mixtures.price(model, float(bins.used().count.sum())):
        p = mixtures.as_parent(model, pre.param_array)
        value = obj.objective(objective, model, p, bins)
    return FitResult(
        model=model,
        params=models.params_to_dict(model, p),
        objective=objective,
        value=float(value),
        method=f"nlopt {method}",
        evaluations=evaluations,
        seconds=time.perf_counter() - t_start,
        status=best[2],
        starts=log,
    )
