"""Synthetic empirical NDFs made in numpy, for tests and for checking the fitter without the Rust binary.

Two independent routes to counts:

- ``sample_slopes``: draw microfacet slopes from each model's slope density P22 written in closed form from
  the papers (Beckmann: the Gaussian of Heitz eq. 81 and footnote 3; GGX / ellipsoid: the Student-like density
  of Heitz eq. 84, sheared and stretched as Heitz sec. 5.5 describes; for the tilted ellipsoid the centre and the
  quadric come from completing the square in ||A^-T m||^2 of Walter eq. 1), then bin them. A heightfield on a
  regular grid counts every sample with the same projected area, so binned slopes are exactly what
  ``ndfit ndf`` counts (Heitz eq. 64: D cos^4 = P22).
- ``expected_counts``: E_k = N D(m_k) W_k of data_formats/objective.md, optionally with Poisson noise.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from . import models
from .bins import Bins


@dataclass
class Grid:
    """A (theta, phi) tiling of the upper hemisphere."""

    theta_edges: np.ndarray  #: (T+1,) from 0 to pi/2
    n_phi: int  #: bins per ring, phi from -pi to pi

    def bins(self, count=None) -> Bins:
        """The grid as Bins (central direction at the mid angles), with ``count`` (zeros if None)."""
        t0, t1 = self.theta_edges[:-1], self.theta_edges[1:]
        tm = 0.5 * (t0 + t1)
        dphi = 2.0 * math.pi / self.n_phi
        pm = -math.pi + dphi * (np.arange(self.n_phi) + 0.5)
        tt, pp = np.meshgrid(tm, pm, indexing="ij")
        m = np.column_stack([(np.sin(tt) * np.cos(pp)).ravel(), (np.sin(tt) * np.sin(pp)).ravel(), np.cos(tt).ravel()])
        # Exact cell integrals: W = dphi (sin^2 t1 - sin^2 t0) / 2, Omega = dphi (cos t0 - cos t1).
        w = np.repeat(dphi * 0.5 * (np.sin(t1) ** 2 - np.sin(t0) ** 2), self.n_phi)
        om = np.repeat(dphi * (np.cos(t0) - np.cos(t1)), self.n_phi)
        c = np.zeros(len(m)) if count is None else np.asarray(count, dtype=float)
        n = max(float(c.sum()), 1.0)
        return Bins(m=m, count=c, proj_solid_angle=w, d=c / (n * w), solid_angle=om, path="<synthetic>")

    def index(self, slopes: np.ndarray) -> np.ndarray:
        """The flat bin index of each slope (x, y) (the normal is (-x, -y, 1) normalized, Heitz eq. 62)."""
        r = np.hypot(slopes[:, 0], slopes[:, 1])
        theta = np.arctan(r)
        phi = np.arctan2(-slopes[:, 1], -slopes[:, 0])
        it = np.clip(np.searchsorted(self.theta_edges, theta, side="right") - 1, 0, len(self.theta_edges) - 2)
        ip = np.clip(np.floor((phi + math.pi) / (2.0 * math.pi) * self.n_phi).astype(int), 0, self.n_phi - 1)
        return it * self.n_phi + ip


def grid_for(scale: float, n_theta: int = 96, n_phi: int = 96) -> Grid:
    """A grid whose rings are dense where slopes are about ``scale``: tan(theta) = scale u/(1-u), u uniform."""
    u = np.linspace(0.0, 1.0, n_theta + 1)
    with np.errstate(divide="ignore"):
        t = np.where(u < 1.0, np.arctan(scale * u / np.maximum(1.0 - u, 1e-300)), 0.5 * math.pi)
    t[-1] = 0.5 * math.pi
    return Grid(theta_edges=t, n_phi=n_phi)


def _ggx_unit_slopes(n: int, rng: np.random.Generator) -> np.ndarray:
    """Slopes of isotropic GGX with alpha = 1, P22 = 1 / (pi (1 + r^2)^2) (Heitz eq. 70): CDF(r) = r^2/(1+r^2)."""
    u = rng.random(n)
    r = np.sqrt(u / (1.0 - u))
    phi = rng.random(n) * 2.0 * math.pi
    return np.column_stack([r * np.cos(phi), r * np.sin(phi)])


def ellipsoid_slope_quadric(a: np.ndarray):
    """Centre s0, quadric Q and constant c of the ellipsoid's slope density P22(s) = c / (1 + (s-s0)^T Q (s-s0))^2.

    With w = (-s, 1): ||A^-T w||^2 = w^T M w, M = A^-1 A^-T. Writing M = [[P, b], [b^T, m33]] gives
    s^T P s - 2 b.s + m33 = (s - s0)^T P (s - s0) + k with s0 = P^-1 b, k = m33 - b^T P^-1 b. Walter eq. 1 with
    Heitz eq. 64 (cos^4 cancels) then gives P22 = 1 / (pi |A| ||A n|| k^2 (1 + (s-s0)^T (P/k) (s-s0))^2).
    """
    a = np.asarray(a, dtype=float)
    ai = np.linalg.inv(a)
    mm = ai @ ai.T
    p = mm[:2, :2]
    b = mm[:2, 2]
    s0 = np.linalg.solve(p, b)
    k = float(mm[2, 2] - b @ s0)
    q = p / k
    c = 1.0 / (math.pi * abs(np.linalg.det(a)) * np.linalg.norm(a[:, 2]) * k * k)
    return s0, q, c


def sample_slopes(model: str, params, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` slopes (x, y) drawn from the model's slope density P22 (see the module notes)."""
    p = models.params_to_array(model, params)
    if model in ("beckmann", "beckmann-aniso"):
        ax, ay, tz = (p[0], p[0], 0.0) if model == "beckmann" else (p[0], p[1], p[2])
        # Heitz eq. 81 in the frame s' = Rz s: independent Gaussians of variance alpha^2 / 2 (footnote 3).
        sp = rng.standard_normal((n, 2)) * np.array([ax, ay]) / math.sqrt(2.0)
        rz2 = models.rot_z(tz)[:2, :2]
        return sp @ rz2  # s = Rz^T s'  (rows: s^T = s'^T Rz)
    a = models.matrix_a(model, p)
    s0, q, _ = ellipsoid_slope_quadric(a)
    # t = L^T (s - s0) with Q = L L^T turns the quadric into |t|^2, t isotropic GGX with alpha = 1.
    l = np.linalg.cholesky(q)
    t = _ggx_unit_slopes(n, rng)
    return s0 + np.linalg.solve(l.T, t.T).T


def sampled_bins(model: str, params, n: int, grid: Grid, seed: int = 0) -> Bins:
    """Bins of ``n`` slopes sampled from the model (a multinomial histogram, like a scan's NDF)."""
    rng = np.random.default_rng(seed)
    counts = np.zeros(len(grid.theta_edges[:-1]) * grid.n_phi)
    chunk = 1 << 20
    left = n
    while left > 0:
        k = min(chunk, left)
        idx = grid.index(sample_slopes(model, params, k, rng))
        counts += np.bincount(idx, minlength=len(counts))
        left -= k
    return grid.bins(counts)


def expected_counts(model: str, params, n: float, grid: Grid, poisson_seed=None) -> Bins:
    """Bins with counts E_k = N D(m_k) W_k (objective.md), Poisson-noised when ``poisson_seed`` is given."""
    b = grid.bins()
    e = n * models.d(model, params, b.m) * b.proj_solid_angle
    if poisson_seed is not None:
        e = np.random.default_rng(poisson_seed).poisson(e).astype(float)
    return grid.bins(e)
