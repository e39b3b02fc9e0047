"""The height rounding of a quantized scan in the model, derived here from the rounding itself.

Heights stored as integers times a step q carry each an error u q, u uniform on (-1/2, 1/2) and independent
from point to point. A slope is a difference of heights over a spacing, so its error is a difference of such
errors: for central differences e_x = (u1 - u2) l_x and e_y = (u3 - u4) l_y with the slope lattice
l = (q / 2dx, q / 2dy) (four different heights); for a triangle facet e_x = (u1 - u0) l_x and e_y = (u2 - u0) l_y
with l = (q / dx, q / dy) (the two differences share the corner u0). A bin therefore counts the slope density
P22 = D m_z^4 (Heitz eq. 64) averaged over that error, and its model is

    D_seen(m) = E_u[ D(m(s + e)) m_z(s + e)^4 ] / m_z(s)^4,   s the slope of m.

The expectation runs here over the uniforms themselves, two Gauss-Legendre points each (exact for cubics in every
u): 16 combinations for central differences (9 distinct slope errors), 8 for triangles (7 distinct).
This is not the Rust fitter's rule (four points from the Cholesky factor of the error's covariance), so the
cross-check compares two constructions of the same model.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Optional, Tuple

import numpy as np

SCHEMES = ("central", "triangles")

#: Gauss-Legendre nodes and weights on (-1/2, 1/2), two points: exact for cubics in each u.
_GL = ((-0.5 / math.sqrt(3.0), 0.5), (0.5 / math.sqrt(3.0), 0.5))


@dataclass(frozen=True)
class Rounding:
    """Heights rounded to a lattice: the slope lattice ``slope_step`` (l_x, l_y) and the normal ``scheme``."""

    slope_step: Tuple[float, float]
    scheme: str = "central"

    def __post_init__(self):
        if self.scheme not in SCHEMES:
            raise ValueError(f"rounding: unknown normal scheme '{self.scheme}' (expected one of {', '.join(SCHEMES)})")
        if not all(math.isfinite(v) and v > 0.0 for v in self.slope_step):
            raise ValueError(f"rounding: the slope step must be finite and > 0, got {self.slope_step}")

    def offsets(self) -> Tuple[np.ndarray, np.ndarray]:
        """The distinct slope errors (P, 2) of the rule and their weights (P,), summing to 1."""
        lx, ly = self.slope_step
        acc = {}
        n_u = 4 if self.scheme == "central" else 3
        for combo in itertools.product(_GL, repeat=n_u):
            u = [c[0] for c in combo]
            w = math.prod(c[1] for c in combo)
            if self.scheme == "central":
                e = ((u[0] - u[1]) * lx, (u[2] - u[3]) * ly)
            else:
                e = ((u[1] - u[0]) * lx, (u[2] - u[0]) * ly)
            key = (round(e[0] / lx, 12), round(e[1] / ly, 12))
            acc[key] = acc.get(key, 0.0) + w
        e = np.array([(k[0] * lx, k[1] * ly) for k in acc])
        return e, np.array(list(acc.values()))

    def covariance(self) -> np.ndarray:
        """The covariance of the slope error (exact, from the uniforms' variance 1/12)."""
        lx, ly = self.slope_step
        c = lx * ly / 12.0 if self.scheme == "triangles" else 0.0
        return np.array([[lx * lx / 6.0, c], [c, ly * ly / 6.0]])


def from_docs(ndf_doc: dict, fit_doc: dict) -> Optional[Rounding]:
    """The rounding an ``ndfit fit`` JSON states it modelled (its ``rounding``: the slope lattice), with the
    normal scheme of the matching ``ndfit ndf`` JSON (``options.normals``); None when the fit modelled none
    (an unquantized scan, or a lattice too fine to matter). The rule is built here, not read."""
    r = fit_doc.get("rounding")
    if not r:
        return None
    scheme = (ndf_doc.get("options") or {}).get("normals", "central")
    return Rounding(slope_step=(float(r["slope_step"][0]), float(r["slope_step"][1])), scheme=scheme)


def seen_log_d_and_grad(log_d_and_grad, model: str, params, m: np.ndarray, rounding: Optional[Rounding], want_grad: bool):
    """ln D_seen(m) and its gradient in the parameters; ``log_d_and_grad`` is the lobe's own (models.py).
    Without a rounding this is the lobe itself."""
    if rounding is None:
        return log_d_and_grad(model, params, m, want_grad)
    m = np.asarray(m, dtype=float)
    m = m / np.linalg.norm(m, axis=1)[:, None]
    z = m[:, 2]
    s = -m[:, :2] / z[:, None]
    t0 = 1.0 + np.sum(s * s, axis=1)
    e, w = rounding.offsets()
    k, p = len(m), len(w)
    # Every rule point of every bin in one evaluation: rows p * k + i.
    q = (s[None, :, :] + e[:, None, :]).reshape(p * k, 2)
    tq = 1.0 + np.sum(q * q, axis=1)
    mq = np.column_stack([-q[:, 0], -q[:, 1], np.ones(len(q))]) / np.sqrt(tq)[:, None]
    lq, gq = log_d_and_grad(model, params, mq, want_grad)
    # m_z^4 = (1 + |s|^2)^-2: the Jacobian of slopes to directions, relative to the bin's own slope.
    v = (lq + 2.0 * np.log(np.tile(t0, p) / tq)).reshape(p, k) + np.log(w)[:, None]
    top = np.max(v, axis=0)
    safe = np.where(np.isfinite(top), top, 0.0)
    ex = np.exp(v - safe)
    tot = ex.sum(axis=0)
    with np.errstate(divide="ignore"):
        logd = np.where(np.isfinite(top), safe + np.log(tot), -np.inf)
    if not want_grad:
        return logd, None
    share = np.where(tot > 0.0, ex / np.where(tot > 0.0, tot, 1.0), 0.0)
    g = np.einsum("pk,pkj->kj", share, gq.reshape(p, k, -1))
    return logd, g
