"""Canonical parameters, so that two fits of the same NDF can be compared parameter by parameter.

The ellipsoid's D depends on A only through A^T A up to scale (Walter et al. sec. 1: cA and QA give the same D),
so (alpha_x, alpha_y, theta_x, theta_y, theta_z) are not unique. A^T A = R^T S^2 R: the rows r_i of R are the
principal axes of the ellipsoid (eq. 8) with eigenvalues alpha_x^2, alpha_y^2, 1. The canonical form:

1. the third axis r3 is the eigenvector nearest n (largest |r3.n|), pointing up; the matrix is scaled so that its
   eigenvalue is 1 (S's third entry). This keeps |theta_x|, |theta_y| smallest;
2. alpha_x >= alpha_y (the two in-plane axes are otherwise interchangeable: swapping them turns theta_z by pi/2);
3. theta_z in (-pi/2, pi/2] (negating r1 and r2 maps theta_z to theta_z + pi and negates both tilts);
4. the Euler angles of R = Rx Ry Rz (eq. 3): R[0,2] = sin(theta_y), R[1,2] = -sin(theta_x) cos(theta_y),
   R[2,2] = cos(theta_x) cos(theta_y), R[0,0] = cos(theta_y) cos(theta_z), R[0,1] = -cos(theta_y) sin(theta_z).

Beckmann-aniso, ggx-aniso and student-aniso use rules 2-3 (their tilt is 0 by definition); the isotropic models are
canonical.
"""

from __future__ import annotations

import math
from typing import Dict

import numpy as np

from . import mixtures, models
from .fit import wrap_theta_z


def euler_xyz(r: np.ndarray):
    """(theta_x, theta_y, theta_z) with r = Rx(theta_x) Ry(theta_y) Rz(theta_z) (Walter eq. 3), |theta_y| <= pi/2."""
    ty = math.asin(max(-1.0, min(1.0, float(r[0, 2]))))
    tx = math.atan2(-float(r[1, 2]), float(r[2, 2]))
    tz = math.atan2(-float(r[0, 1]), float(r[0, 0]))
    return tx, ty, tz


def canonical_from_matrix(a) -> np.ndarray:
    """Canonical (alpha_x, alpha_y, theta_x, theta_y, theta_z) of the ellipsoid with matrix A (module notes)."""
    a = np.asarray(a, dtype=float)
    mtm = a.T @ a
    lam, vec = np.linalg.eigh(0.5 * (mtm + mtm.T))
    if not (lam[0] > 0.0):
        raise ValueError("ellipsoid matrix A is singular")
    i3 = int(np.argmax(np.abs(vec[2, :])))
    rest = [i for i in range(3) if i != i3]
    i1, i2 = sorted(rest, key=lambda i: -lam[i])  # alpha_x >= alpha_y
    r3 = vec[:, i3] * (1.0 if vec[2, i3] >= 0.0 else -1.0)
    r1 = vec[:, i1] * (1.0 if vec[0, i1] >= 0.0 else -1.0)  # R[0,0] >= 0: theta_z in [-pi/2, pi/2]
    r2 = np.cross(r3, r1)  # right-handed: det R = +1
    r = np.vstack([r1, r2, r3])
    tx, ty, tz = euler_xyz(r)
    if tz <= -0.5 * math.pi + 1e-15:  # the interval is half-open: -pi/2 maps to +pi/2 with negated tilts
        tx, ty, tz = -tx, -ty, tz + math.pi
    ax = math.sqrt(lam[i1] / lam[i3])
    ay = math.sqrt(lam[i2] / lam[i3])
    return np.array([ax, ay, tx, ty, tz])


def _aniso(p: np.ndarray) -> np.ndarray:
    ax, ay, tz = p
    if ay > ax:
        ax, ay, tz = ay, ax, tz + 0.5 * math.pi
    return np.array([ax, ay, wrap_theta_z(tz)])


def canonical(model: str, params) -> Dict[str, float]:
    """Canonical parameters of ``model`` (module notes), as a name -> value mapping."""
    p = models.params_to_array(model, params)
    if model in ("ggx", "beckmann", "student"):
        return models.params_to_dict(model, p)
    if model in ("ggx-aniso", "beckmann-aniso"):
        return models.params_to_dict(model, _aniso(p))
    if model == "student-aniso":  # rules 2-3 on the lobe's axes; the tail exponent gamma is unchanged
        return models.params_to_dict(model, np.append(_aniso(p[:3]), p[3]))
    if model in mixtures.PARAM_NAMES:
        ell = lambda q: canonical_from_matrix(models.ellipsoid_matrix(*q))  # noqa: E731
        return models.params_to_dict(model, mixtures.canonical(model, p, ell))
    return models.params_to_dict(model, canonical_from_matrix(models.matrix_a(model, p)))
