"""The analytic NDFs ndfit fits, in numpy, written from the papers (not from the Rust code).

Frame: the macro normal is n = +z (/work/shared/CONTRACT.md). Every D here is normalized so that the
integral of D(m) (m.n) over the hemisphere is 1 (Heitz eq. 9).

Models and parameters (CONTRACT.md, "Models and parameters"):

- ``ellipsoid``: Walter et al. eq. 1, ``D(m) = X+(m.n) / (pi |A| ||A n|| ||A^-T m||^4)`` with
  ``A = S R`` (eq. 2), ``S = diag(alpha_x, alpha_y, 1)``, ``R = Rx(theta_x) Ry(theta_y) Rz(theta_z)`` (eq. 3).
- ``ggx-aniso`` / ``ggx``: the ellipsoid with ``theta_x = theta_y = 0`` (Walter sec. 1: GTR2aniso, and with
  ``alpha_x = alpha_y`` isotropic GGX, Heitz eq. 71 / 85).
- ``beckmann-aniso`` / ``beckmann``: Heitz eq. 82 evaluated in the local frame ``m' = Rz(theta_z) m`` (the same
  theta_z convention as the ellipsoid, where ``A^-T m = S^-1 R m``).
- ``student-aniso`` / ``student``: the Student-t slope distribution (Ribardiere et al. 2017, below) in the same
  local frame, with the tail exponent ``gamma`` (GGX at 2, Beckmann as it grows). Not in the contract's list
  (``MODELS``): ndfit's model table adds them; no matrix A (the lobe is not an ellipsoid).

Everything is computed as ln D first: Beckmann's exponential underflows for narrow lobes (alpha 1e-4), and the
fit's Poisson deviance needs ln E anyway.
"""

from __future__ import annotations

import math
from typing import Dict, Mapping, Sequence

import numpy as np

from . import mixtures as _mixtures

#: Parameter names of every model, in the order the fitter and the JSON use.
PARAM_NAMES: Dict[str, tuple] = {
    "ggx": ("alpha",),
    "ggx-aniso": ("alpha_x", "alpha_y", "theta_z"),
    "beckmann": ("alpha",),
    "beckmann-aniso": ("alpha_x", "alpha_y", "theta_z"),
    "ellipsoid": ("alpha_x", "alpha_y", "theta_x", "theta_y", "theta_z"),
    "student": ("alpha", "gamma"),
    "student-aniso": ("alpha_x", "alpha_y", "theta_z", "gamma"),
    **_mixtures.PARAM_NAMES,
}

#: The Student-t lobes (STD, Ribardiere et al. 2017): single lobes outside the contract's list.
STUDENTS = ("student", "student-aniso")

#: Parameter names of the STD lobes (a view of PARAM_NAMES).
STUDENT_PARAM_NAMES: Dict[str, tuple] = {k: PARAM_NAMES[k] for k in STUDENTS}

#: Every single-lobe model id of the contract.
MODELS = tuple(k for k in PARAM_NAMES if k not in _mixtures.PARAM_NAMES and k not in STUDENTS)

#: The two-lobe mixtures (mixtures.py).
MIXTURES = tuple(_mixtures.PARAM_NAMES)

#: Models that are special cases of the ellipsoid (they have a matrix A).
ELLIPSOID_FAMILY = ("ggx", "ggx-aniso", "ellipsoid")

_LN_PI = math.log(math.pi)


def check_model(model: str) -> None:
    """Raise ValueError unless ``model`` is a contract model id."""
    if model not in PARAM_NAMES:
        raise ValueError(f"unknown model '{model}' (expected one of {', '.join(MODELS)})")


def params_to_array(model: str, params) -> np.ndarray:
    """The parameters of ``model`` as a float array in PARAM_NAMES order (accepts a mapping or a sequence)."""
    check_model(model)
    names = PARAM_NAMES[model]
    if isinstance(params, Mapping):
        missing = [k for k in names if k not in params]
        if missing:
            raise ValueError(f"model '{model}' needs parameter(s) {', '.join(missing)}")
        arr = np.array([float(params[k]) for k in names], dtype=float)
    else:
        arr = np.asarray(params, dtype=float).reshape(-1)
        if arr.size != len(names):
            raise ValueError(f"model '{model}' has {len(names)} parameters, got {arr.size}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"model '{model}': non-finite parameter in {arr.tolist()}")
    return arr


def params_to_dict(model: str, values: Sequence[float]) -> Dict[str, float]:
    """Name the values of ``model``'s parameters."""
    arr = params_to_array(model, values)
    return {k: float(v) for k, v in zip(PARAM_NAMES[model], arr)}


def to_ellipsoid(model: str, params) -> np.ndarray:
    """The five ellipsoid parameters (alpha_x, alpha_y, theta_x, theta_y, theta_z) of an ellipsoid-family model."""
    p = params_to_array(model, params)
    if model == "ellipsoid":
        return p
    if model == "ggx-aniso":
        return np.array([p[0], p[1], 0.0, 0.0, p[2]])
    if model == "ggx":
        return np.array([p[0], p[0], 0.0, 0.0, 0.0])
    raise ValueError(f"model '{model}' is not an ellipsoid special case")


# ---------------------------------------------------------------------------------------------------------
# Rotations, Walter et al. eq. 3


def rot_x(t: float) -> np.ndarray:
    """Rx(theta_x) of Walter et al. eq. 3."""
    c, s = math.cos(t), math.sin(t)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(t: float) -> np.ndarray:
    """Ry(theta_y) of Walter et al. eq. 3."""
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(t: float) -> np.ndarray:
    """Rz(theta_z) of Walter et al. eq. 3."""
    c, s = math.cos(t), math.sin(t)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _drot_x(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[0.0, 0.0, 0.0], [0.0, -s, -c], [0.0, c, -s]])


def _drot_y(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[-s, 0.0, c], [0.0, 0.0, 0.0], [-c, 0.0, -s]])


def _drot_z(t: float) -> np.ndarray:
    c, s = math.cos(t), math.sin(t)
    return np.array([[-s, -c, 0.0], [c, -s, 0.0], [0.0, 0.0, 0.0]])


def rotation(theta_x: float, theta_y: float, theta_z: float) -> np.ndarray:
    """R = Rx(theta_x) Ry(theta_y) Rz(theta_z), Walter et al. eq. 3."""
    return rot_x(theta_x) @ rot_y(theta_y) @ rot_z(theta_z)


def ellipsoid_matrix(alpha_x: float, alpha_y: float, theta_x: float, theta_y: float, theta_z: float) -> np.ndarray:
    """A = S R of Walter et al. eq. 2-3."""
    return np.diag([alpha_x, alpha_y, 1.0]) @ rotation(theta_x, theta_y, theta_z)


def matrix_a(model: str, params):
    """The contract's ``matrix_a`` (A, row-major) of an ellipsoid-family model, or None for Beckmann."""
    if model not in ELLIPSOID_FAMILY:
        check_model(model)
        return None
    return ellipsoid_matrix(*to_ellipsoid(model, params))


# ---------------------------------------------------------------------------------------------------------
# ln D


def _as_dirs(m) -> np.ndarray:
    m = np.asarray(m, dtype=float)
    if m.ndim == 1:
        m = m.reshape(1, 3)
    if m.ndim != 2 or m.shape[1] != 3:
        raise ValueError(f"directions must have shape (K, 3), got {m.shape}")
    return m


def log_d_matrix(a: np.ndarray, m) -> np.ndarray:
    """ln D of Walter et al. eq. 1 for any non-singular 3x3 A (e.g. a fit's ``matrix_a``); -inf where m.n <= 0.

    ``D(m) = X+(m.n) / (pi |A| ||A n|| ||A^-T m||^4)``. Directions need not be unit length: they are normalized here
    (eq. 1 assumes ||m|| = 1).
    """
    m = _as_dirs(m)
    a = np.asarray(a, dtype=float)
    det = abs(float(np.linalg.det(a)))
    if not (det > 0.0 and math.isfinite(det)):
        raise ValueError("ellipsoid matrix A is singular")
    a_inv_t = np.linalg.inv(a).T
    norm = np.linalg.norm(m, axis=1)
    u = (m @ a_inv_t.T) / norm[:, None]
    an = float(np.linalg.norm(a[:, 2]))
    with np.errstate(divide="ignore"):
        out = -_LN_PI - math.log(det) - math.log(an) - 2.0 * np.log(np.einsum("ij,ij->i", u, u))
    out[m[:, 2] <= 0.0] = -np.inf
    return out


def _ellipsoid_log_d_grad(p: np.ndarray, m: np.ndarray, want_grad: bool):
    """ln D of the ellipsoid and its gradient in (alpha_x, alpha_y, theta_x, theta_y, theta_z).

    With u = R m and v = R n: ||A^-T m||^2 = ux^2/ax^2 + uy^2/ay^2 + uz^2 =: q (A^-T = S^-1 R since R is orthogonal)
    and ||A n||^2 = ax^2 vx^2 + ay^2 vy^2 + vz^2 =: s, |A| = ax ay (Walter eq. 2), so
    ln D = -ln pi - ln ax - ln ay - ln(s)/2 - 2 ln q.
    """
    ax, ay, tx, ty, tz = p
    rx, ry, rz = rot_x(tx), rot_y(ty), rot_z(tz)
    r = rx @ ry @ rz
    norm = np.linalg.norm(m, axis=1)
    mu = m / norm[:, None]
    u = mu @ r.T
    v = r[:, 2]
    inv2 = np.array([1.0 / (ax * ax), 1.0 / (ay * ay), 1.0])
    sc2 = np.array([ax * ax, ay * ay, 1.0])
    q = (u * u) @ inv2
    s = float(v @ (sc2 * v))
    logd = -_LN_PI - math.log(ax) - math.log(ay) - 0.5 * math.log(s) - 2.0 * np.log(q)
    below = mu[:, 2] <= 0.0
    logd[below] = -np.inf
    if not want_grad:
        return logd, None
    g = np.empty((m.shape[0], 5))
    g[:, 0] = -1.0 / ax - ax * v[0] ** 2 / s + 4.0 * u[:, 0] ** 2 / (ax**3 * q)
    g[:, 1] = -1.0 / ay - ay * v[1] ** 2 / s + 4.0 * u[:, 1] ** 2 / (ay**3 * q)
    drs = (_drot_x(tx) @ ry @ rz, rx @ _drot_y(ty) @ rz, rx @ ry @ _drot_z(tz))
    for j, dr in enumerate(drs):
        du = mu @ dr.T
        dv = dr[:, 2]
        ds = 2.0 * float(v @ (sc2 * dv))
        dq = 2.0 * (u * du) @ inv2
        g[:, 2 + j] = -0.5 * ds / s - 2.0 * dq / q
    g[below] = 0.0
    return logd, g


def _beckmann_log_d_grad(ax: float, ay: float, tz: float, m: np.ndarray, want_grad: bool):
    """ln D of Heitz eq. 82 in the frame m' = Rz(theta_z) m, and its gradient in (alpha_x, alpha_y, theta_z).

    tan^2(theta) cos^2(phi) = (m'x / mz)^2 and tan^2(theta) sin^2(phi) = (m'y / mz)^2, cos(theta) = mz / ||m||.
    """
    norm = np.linalg.norm(m, axis=1)
    mu = m / norm[:, None]
    rz = rot_z(tz)
    mp = mu @ rz.T
    z = mu[:, 2]
    below = z <= 0.0
    # Guard: below the horizon D is 0; divide by 1 there instead of 0 and overwrite the result with -inf.
    zs = np.where(below, 1.0, z)
    sx = mp[:, 0] / zs
    sy = mp[:, 1] / zs
    e = sx * sx / (ax * ax) + sy * sy / (ay * ay)
    logd = -_LN_PI - math.log(ax) - math.log(ay) - 4.0 * np.log(zs) - e
    logd[below] = -np.inf
    if not want_grad:
        return logd, None
    dmp = mu @ _drot_z(tz).T
    g = np.empty((m.shape[0], 3))
    g[:, 0] = -1.0 / ax + 2.0 * sx * sx / ax**3
    g[:, 1] = -1.0 / ay + 2.0 * sy * sy / ay**3
    g[:, 2] = -(2.0 * sx * dmp[:, 0] / zs / (ax * ax) + 2.0 * sy * dmp[:, 1] / zs / (ay * ay))
    g[below] = 0.0
    return logd, g


def log_d_and_grad(model: str, params, m, want_grad: bool = True):
    """ln D(m) of ``model`` and (if asked) its gradient d ln D / d params, shape (K, n_params).

    -inf (and a zero gradient row) where m.n <= 0 (the X+ factor of Walter eq. 1 and Heitz eq. 82).
    """
    p = params_to_array(model, params)
    if model in _mixtures.PARAM_NAMES:
        return _mixtures.log_d_and_grad(model, p, _as_dirs(m), want_grad, log_d_and_grad)
    if model in STUDENTS:
        return student_log_d_and_grad(model, p, m, want_grad)
    if model in ("ggx", "beckmann", "ggx-aniso", "beckmann-aniso") and not (p[0] > 0.0):
        raise ValueError(f"model '{model}': alpha must be > 0, got {p[0]}")
    if model in ("ggx-aniso", "beckmann-aniso", "ellipsoid") and not (p[0] > 0.0 and p[1] > 0.0):
        raise ValueError(f"model '{model}': alpha_x and alpha_y must be > 0, got {p[0]}, {p[1]}")
    m = _as_dirs(m)
    if model == "ellipsoid":
        return _ellipsoid_log_d_grad(p, m, want_grad)
    if model == "ggx-aniso":
        logd, g = _ellipsoid_log_d_grad(np.array([p[0], p[1], 0.0, 0.0, p[2]]), m, want_grad)
        return logd, (g[:, [0, 1, 4]] if want_grad else None)
    if model == "ggx":
        logd, g = _ellipsoid_log_d_grad(np.array([p[0], p[0], 0.0, 0.0, 0.0]), m, want_grad)
        return logd, ((g[:, 0] + g[:, 1])[:, None] if want_grad else None)
    if model == "beckmann-aniso":
        return _beckmann_log_d_grad(p[0], p[1], p[2], m, want_grad)
    if model == "beckmann":
        logd, g = _beckmann_log_d_grad(p[0], p[0], 0.0, m, want_grad)
        return logd, ((g[:, 0] + g[:, 1])[:, None] if want_grad else None)
    raise AssertionError("unreachable: check_model passed")


def log_d(model: str, params, m) -> np.ndarray:
    """ln D(m) of ``model`` at directions ``m`` (shape (K, 3) or (3,)); -inf below the horizon."""
    return log_d_and_grad(model, params, m, want_grad=False)[0]


def d(model: str, params, m) -> np.ndarray:
    """D(m) of ``model`` (1/sr) at directions ``m``."""
    return np.exp(log_d(model, params, m))


def log_slope_density(model: str, params, slopes) -> np.ndarray:
    """ln P22 of the model at slopes (x, y): ``ln D(m) + 4 ln cos(theta_m)``, m from the slope by Heitz eq. 62 / 64."""
    s = np.asarray(slopes, dtype=float).reshape(-1, 2)
    m = np.column_stack([-s[:, 0], -s[:, 1], np.ones(len(s))])
    return log_d(model, params, m) - 2.0 * np.log1p(s[:, 0] ** 2 + s[:, 1] ** 2)


def slope_density(model: str, params, slopes) -> np.ndarray:
    """P22 of the model at slopes (x, y): ``D(m) cos^4(theta_m)`` (Heitz eq. 64)."""
    return np.exp(log_slope_density(model, params, slopes))


# ---------------------------------------------------------------------------------------------------------
# The Student-t slope distribution (STD), Ribardiere, Bringier, Meneveaux and Simonot, Computer Graphics
# Forum 36(2), 2017: P22 = (gamma-1)^gamma / (pi ax ay (gamma - 1 + x'^2/ax^2 + y'^2/ay^2)^gamma) over the
# slopes of m' = Rz(theta_z) m, D = P22 / cos^4 (Heitz eq. 64). gamma = 2 is GGX, gamma -> inf Beckmann.
# Its ids are ``student`` (alpha, gamma) and ``student-aniso`` (alpha_x, alpha_y, theta_z, gamma); alpha_x lies
# along (cos theta_z, -sin theta_z) in the scan frame, as for ggx-aniso.

#: Exclusive lower bound of gamma: at 3/2 the mean slope, and with it Smith's Lambda, diverges.
STUDENT_GAMMA_MIN = 1.5

#: Largest gamma (the Rust model's bound): beyond it the lobe is Beckmann for any scan's counting noise.
STUDENT_GAMMA_MAX = 1e5


def _student_log_d_grad(ax: float, ay: float, tz: float, gamma: float, m: np.ndarray, want_grad: bool):
    """ln D of the STD lobe and its gradient in (alpha_x, alpha_y, theta_z, gamma).

    With the stretched slope squared e = (x'/ax)^2 + (y'/ay)^2 and p = gamma - 1, the paper's density reads
    P22 = (1 + e/p)^-gamma / (pi ax ay), so ln D = -ln pi - ln ax - ln ay - 4 ln cos - gamma ln(1 + e/p).
    """
    if not (gamma > STUDENT_GAMMA_MIN and math.isfinite(gamma)):
        raise ValueError(f"student: gamma must be finite and > {STUDENT_GAMMA_MIN}, got {gamma}")
    if not (ax > 0.0 and ay > 0.0):
        raise ValueError(f"student: alpha_x and alpha_y must be > 0, got {ax}, {ay}")
    p = gamma - 1.0
    norm = np.linalg.norm(m, axis=1)
    mu = m / norm[:, None]
    mp = mu @ rot_z(tz).T
    z = mu[:, 2]
    below = z <= 0.0
    zs = np.where(below, 1.0, z)
    sx = mp[:, 0] / zs
    sy = mp[:, 1] / zs
    e = sx * sx / (ax * ax) + sy * sy / (ay * ay)
    l1p = np.log1p(e / p)
    logd = -_LN_PI - math.log(ax) - math.log(ay) - 4.0 * np.log(zs) - gamma * l1p
    logd[below] = -np.inf
    if not want_grad:
        return logd, None
    # d ln D / d e = -gamma / (p + e).
    de = -gamma / (p + e)
    dmp = mu @ _drot_z(tz).T
    g = np.empty((m.shape[0], 4))
    g[:, 0] = -1.0 / ax + de * (-2.0 * sx * sx / ax**3)
    g[:, 1] = -1.0 / ay + de * (-2.0 * sy * sy / ay**3)
    g[:, 2] = de * (2.0 * sx * dmp[:, 0] / zs / (ax * ax) + 2.0 * sy * dmp[:, 1] / zs / (ay * ay))
    # d/dgamma of -gamma ln(1 + e/p), p = gamma - 1.
    g[:, 3] = -l1p + gamma * e / (p * (p + e))
    g[below] = 0.0
    return logd, g


def student_log_d_and_grad(model: str, params, m, want_grad: bool = True):
    """ln D and d ln D / d params of ``student`` (alpha, gamma) or ``student-aniso`` (alpha_x, alpha_y,
    theta_z, gamma); -inf (and a zero gradient row) where m.n <= 0."""
    if model not in STUDENT_PARAM_NAMES:
        raise ValueError(f"unknown model '{model}' (expected student or student-aniso)")
    p = np.asarray(params, dtype=float).reshape(-1)
    if p.size != len(STUDENT_PARAM_NAMES[model]) or not np.all(np.isfinite(p)):
        raise ValueError(f"model '{model}' takes {len(STUDENT_PARAM_NAMES[model])} finite parameters, got {p.tolist()}")
    m = _as_dirs(m)
    if model == "student":
        logd, g = _student_log_d_grad(p[0], p[0], 0.0, p[1], m, want_grad)
        return logd, (np.column_stack([g[:, 0] + g[:, 1], g[:, 3]]) if want_grad else None)
    return _student_log_d_grad(p[0], p[1], p[2], p[3], m, want_grad)


def student_d(model: str, params, m) -> np.ndarray:
    """D(m) (1/sr) of ``student`` or ``student-aniso`` at directions ``m``."""
    return np.exp(student_log_d_and_grad(model, params, m, want_grad=False)[0])
