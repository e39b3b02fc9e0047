"""An independent numpy tracer of a heightfield's microgeometry: the cross-check of ``ndfit trace``.

Written from the surface's description (docs/TRACE.md, CONTRACT.md "Tracing the microgeometry"), not from
ndfit's code: cell ``(i, j)`` spans columns ``j..j+1`` and rows ``i..i+1`` and is two planar triangles split
along the diagonal ``u = v`` (``u >= v``: corners 00, 10, 11; else 00, 01, 11); the grid is periodic (column
``nx - 1`` joins column 0); the wrap cells (last row or column) are no landing cells.

Intersection, all rays at once: along a ray ``o + t d`` the height of the surface is linear between two
consecutive crossings of the lines ``X = k``, ``Y = k`` and ``X - Y = k`` (cell units), so the ray meets the
surface in the first interval where ``z(t) - h(t)`` turns from positive to non-positive, exactly (linear
interpolation inside that interval). Rays are grouped by how many lines they cross, so a few grazing rays
do not size every array.

What it estimates (all per landed ray, ``F = 1``):

- ``g1``: masking from the landing rate. Rays from ``wi`` land uniformly on the visible projected area, so
  ``G1 = cos(theta) P_land A / (A_valid sigma_valid(wi))`` with ``sigma`` the exact mean of
  ``<wi.m>+ / m.z`` over the landing cells' triangles: a different estimator from ndfit's shadow rays,
  of the same quantity (visible over facing projected area of the landing cells).
- ``g1_smith = cos(theta) / sigma_valid(wi)`` (Heitz 2014 eq. 22, 43), exact.
- ``single``: the share of landed rays whose specular reflection leaves the surface unblocked, the albedo
  of the first bounce; and its outgoing directions, binned by ``single_counts`` in the layout of ``ndfit
  trace --bins`` (``bin_index``): the one-bounce BRDF per bin is the count over ``landed`` over the bin's
  projected solid angle.
- ``model_table``: the microfacet model's single scattering per bin, summed exactly over the triangles
  (no sampling), with the moments that give the noise of a Monte Carlo estimate of it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# Most breakpoints times rays held at once (memory: a few arrays of this many float64).
_CHUNK_ELEMS = 1 << 22
# A ray that rises above the highest point only after this many cells is counted as blocked (on a
# periodic surface it has passed over the whole scan many times; the count is reported).
_MAX_CELLS = 20000


@dataclass
class Surface:
    """Heights ``h[i, j]`` (row ``i`` along y, metres) on a periodic grid of spacing ``dx``, ``dy``."""

    h: np.ndarray
    dx: float
    dy: float

    @property
    def ny(self) -> int:
        return self.h.shape[0]

    @property
    def nx(self) -> int:
        return self.h.shape[1]

    def corners(self, i, j):
        """``h00, h10, h01, h11`` of cells ``(i, j)`` (integer arrays, wrapped)."""
        i = np.mod(i, self.ny)
        j = np.mod(j, self.nx)
        i1 = np.mod(i + 1, self.ny)
        j1 = np.mod(j + 1, self.nx)
        return self.h[i, j], self.h[i, j1], self.h[i1, j], self.h[i1, j1]

    def height(self, x, y):
        """Surface height at cell coordinates ``(X, Y)`` (any real values: the grid repeats)."""
        fj = np.floor(x)
        fi = np.floor(y)
        u = x - fj
        v = y - fi
        h00, h10, h01, h11 = self.corners(fi.astype(np.int64), fj.astype(np.int64))
        return np.where(u >= v, h00 + (h10 - h00) * u + (h11 - h10) * v, h00 + (h11 - h01) * u + (h01 - h00) * v)

    def normals(self, i, j, tri):
        """Unit normals (physical) of triangles ``tri`` of cells ``(i, j)``, shape ``(..., 3)``."""
        h00, h10, h01, h11 = self.corners(i, j)
        sx = np.where(tri == 0, h10 - h00, h11 - h01) / self.dx
        sy = np.where(tri == 0, h11 - h10, h01 - h00) / self.dy
        m = np.stack([-sx, -sy, np.ones_like(sx)], axis=-1)
        return m / np.linalg.norm(m, axis=-1, keepdims=True)

    def all_normals(self, landing_only=True):
        """Normals of both triangles of every cell (of the landing cells only by default), ``(N, 3)``."""
        ii, jj = np.meshgrid(np.arange(self.ny), np.arange(self.nx), indexing="ij")
        if landing_only:
            keep = (ii < self.ny - 1) & (jj < self.nx - 1)
            ii, jj = ii[keep], jj[keep]
        ii, jj = ii.ravel(), jj.ravel()
        return np.concatenate([self.normals(ii, jj, np.zeros_like(ii)), self.normals(ii, jj, np.ones_like(ii))])

    def sigma(self, w, landing_only=True) -> float:
        """Projected area per unit macro area towards ``w``: mean of ``<w.m>+ / m.z`` over the triangles."""
        m = self.all_normals(landing_only)
        return float(np.mean(np.clip(m @ np.asarray(w, float), 0.0, None) / m[:, 2]))


def direction(theta_deg: float, phi_deg: float = 0.0) -> np.ndarray:
    """Unit vector of elevation ``theta`` and azimuth ``phi`` (degrees)."""
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.array([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)])


def _crossings(o, d, k):
    """The first ``k`` parameters ``t > 0`` where ``o + t d`` crosses an integer (per ray), ``inf`` when
    ``d == 0``."""
    n = np.arange(k)[None, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        pos = (np.floor(o)[:, None] + 1 + n - o[:, None]) / d[:, None]
        neg = (np.ceil(o)[:, None] - 1 - n - o[:, None]) / d[:, None]
    t = np.where(d[:, None] > 0, pos, neg)
    return np.where(d[:, None] == 0, np.inf, t)


def _first_hit_chunk(s: Surface, o, d, t_end, start_on_surface):
    """First crossing of each ray ``o + t d`` (cell units in x, y; metres in z) over ``(0, t_end]``.
    Returns ``(hit, t)``; ``t`` is NaN where there is no hit."""
    diag = d[:, 0] - d[:, 1]
    span = t_end * np.maximum(np.abs(d[:, 0]), np.maximum(np.abs(d[:, 1]), np.abs(diag)))
    k = int(np.ceil(span.max())) + 2
    ts = np.concatenate(
        [
            np.zeros((len(o), 1)),
            _crossings(o[:, 0], d[:, 0], k),
            _crossings(o[:, 1], d[:, 1], k),
            _crossings(o[:, 0] - o[:, 1], diag, k),
            t_end[:, None],
        ],
        axis=1,
    )
    ts = np.sort(np.minimum(ts, t_end[:, None]), axis=1)
    x = o[:, 0:1] + ts * d[:, 0:1]
    y = o[:, 1:2] + ts * d[:, 1:2]
    f = o[:, 2:3] + ts * d[:, 2:3] - s.height(x, y)
    if start_on_surface:
        # The ray leaves its own triangle upwards: no crossing in the first interval.
        f[:, 0] = np.maximum(f[:, 0], 0.0)
    below = f[:, 1:] <= 0.0
    hit = below.any(axis=1)
    n = np.argmax(below, axis=1) + 1
    r = np.arange(len(o))
    fa, fb = f[r, n - 1], f[r, n]
    ta, tb = ts[r, n - 1], ts[r, n]
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(fa > 0, fa / (fa - fb), 0.0)
    t = np.where(hit, ta + (tb - ta) * frac, np.nan)
    return hit, t


def first_hit(s: Surface, o, d, t_end, start_on_surface=False):
    """First crossing of every ray, vectorized in groups of similar length. Returns ``(hit, t)``."""
    o, d, t_end = np.asarray(o, float), np.asarray(d, float), np.asarray(t_end, float)
    span = t_end * np.maximum(np.abs(d[:, 0]), np.maximum(np.abs(d[:, 1]), np.abs(d[:, 0] - d[:, 1])))
    hit = np.zeros(len(o), bool)
    t = np.full(len(o), np.nan)
    long = span > _MAX_CELLS
    hit[long] = True  # counted as blocked: see _MAX_CELLS
    order = np.argsort(np.where(long, -1.0, span), kind="stable")
    order = order[np.count_nonzero(long):]
    width = lambda r: 3 * (int(np.ceil(span[r])) + 2) + 2  # breakpoints per ray
    a = 0
    while a < len(order):
        # Sorted by length: a group is sized by its last (longest) ray.
        b = min(len(order), a + max(1, _CHUNK_ELEMS // width(order[a])))
        b = min(b, a + max(1, _CHUNK_ELEMS // width(order[b - 1])))
        idx = order[a:b]
        hit[idx], t[idx] = _first_hit_chunk(s, o[idx], d[idx], t_end[idx], start_on_surface)
        a = b
    return hit, t, int(np.count_nonzero(long))


def _to_grid(s: Surface, w):
    return np.stack([w[..., 0] / s.dx, w[..., 1] / s.dy, w[..., 2]], axis=-1)


@dataclass
class IncidenceResult:
    theta_deg: float
    rays: int
    landed: int
    g1: float
    g1_stderr: float
    g1_smith: float
    single: float
    single_stderr: float
    out_dirs: np.ndarray  # (n, 3) outgoing directions of the first bounces that leave
    blocked_long: int  # reflected rays counted as blocked because they stay below the top too long


def trace_incidence(s: Surface, theta_deg: float, phi_deg: float, rays: int, rng) -> IncidenceResult:
    """Trace ``rays`` paths from direction ``(theta, phi)``: landing, one specular reflection, its exit."""
    wi = direction(theta_deg, phi_deg)
    nx, ny = s.nx, s.ny
    zmin, zmax = float(s.h.min()), float(s.h.max())
    z_top = zmax + 1e-3 * ((zmax - zmin) + min(s.dx, s.dy))
    o = np.stack([rng.random(rays) * nx, rng.random(rays) * ny, np.full(rays, z_top)], axis=1)
    d = np.broadcast_to(_to_grid(s, -wi), (rays, 3)).copy()
    t_end = np.full(rays, (z_top - zmin) / wi[2] * (1 + 1e-9) + 1e-12)
    hit, t, _ = first_hit(s, o, d, t_end)
    assert hit.all(), "a ray from above passed below the lowest point without meeting the surface"
    p = o + t[:, None] * d
    # The triangle hit: just before the crossing (inside the interval that crosses).
    q = o + (t - 1e-9 * np.maximum(t, 1.0))[:, None] * d
    j = np.floor(q[:, 0]).astype(np.int64)
    i = np.floor(q[:, 1]).astype(np.int64)
    tri = np.where(q[:, 0] - j >= q[:, 1] - i, 0, 1)
    j, i = np.mod(j, nx), np.mod(i, ny)
    landed = (i < ny - 1) & (j < nx - 1)
    n_land = int(np.count_nonzero(landed))
    # Masking from the landing rate (module docstring).
    sig = s.sigma(wi)
    area_ratio = (nx * ny) / ((nx - 1) * (ny - 1))
    p_land = n_land / rays
    g1 = wi[2] * p_land * area_ratio / sig
    g1_se = wi[2] * np.sqrt(p_land * (1 - p_land) / rays) * area_ratio / sig
    # One reflection of the landed rays, and whether it leaves.
    m = s.normals(i[landed], j[landed], tri[landed])
    din = -wi
    c = -(m @ din)
    out = din[None, :] + 2 * c[:, None] * m
    up = (c > 0) & (out[:, 2] > 0)
    leaves = np.zeros(n_land, bool)
    pu, ou = p[landed][up], out[up]
    t2_end = (zmax - pu[:, 2]) / ou[:, 2] * (1 + 1e-9) + 1e-12
    hit2, _, long = first_hit(s, pu, _to_grid(s, ou), np.maximum(t2_end, 1e-12), start_on_surface=True)
    leaves[np.flatnonzero(up)] = ~hit2
    single = np.count_nonzero(leaves) / max(n_land, 1)
    return IncidenceResult(
        theta_deg=theta_deg,
        rays=rays,
        landed=n_land,
        g1=float(g1),
        g1_stderr=float(g1_se),
        g1_smith=float(wi[2] / sig),
        single=float(single),
        single_stderr=float(np.sqrt(single * (1 - single) / max(n_land, 1))),
        out_dirs=out[leaves],
        blocked_long=long,
    )



def bin_index(w, n_theta: int, n_phi: int) -> np.ndarray:
    """The outgoing bin ``it * n_phi + ip`` of unit directions ``w`` (``(n, 3)``, above the horizon): bins
    uniform in ``u = sqrt(2 theta / pi)`` (``n_theta``) and in ``phi`` over ``[-pi, pi)`` (``n_phi``, 0 along
    the scan's +x), the layout of ``ndfit trace --bins THETAxPHI``."""
    w = np.asarray(w, float)
    theta = np.arccos(np.clip(w[:, 2], -1.0, 1.0))
    it = np.minimum((np.sqrt(theta / (np.pi / 2)) * n_theta).astype(np.int64), n_theta - 1)
    ip = np.minimum(((np.arctan2(w[:, 1], w[:, 0]) + np.pi) / (2 * np.pi) * n_phi).astype(np.int64), n_phi - 1)
    return it * n_phi + ip


def single_counts(res: IncidenceResult, n_theta: int, n_phi: int) -> np.ndarray:
    """How many of the landed paths leave after one bounce into each bin (``n_theta * n_phi``); the first
    bounce's energy per bin is this over ``res.landed`` (F = 1)."""
    return np.bincount(bin_index(res.out_dirs, n_theta, n_phi), minlength=n_theta * n_phi)


@dataclass
class ModelTable:
    """The microfacet model's single scattering per outgoing bin (flat, ``n_theta * n_phi``), from the
    distribution of one sample ``a 1[bin]`` at a uniform point of the landing cells (see ``model_table``)."""

    mean: np.ndarray  # E[a 1_k]: the bin's energy per unit incident energy
    second: np.ndarray  # E[a^2 1_k]
    share: np.ndarray  # P(a sample reflects into bin k)
    wmax: np.ndarray  # the largest a reflected into bin k (0 when none)


def model_table(s: Surface, wi, n_theta: int, n_phi: int) -> ModelTable:
    """The microfacet model's single scattering per bin, exactly, over the landing cells' triangles.

    ``int_bin f(wi, o) cos_o do`` with ``f = D G2 / (4 cos_i cos_o)`` (F = 1), ``D`` the triangles' NDF
    (each triangle a half cell of macro area) and Smith's height-correlated ``G2 = 1 / (1 + Lambda(wi) +
    Lambda(o))``, ``1 + Lambda(w) = sigma(w) / cos`` (Heitz 2014 eq. 43, 99), clipped at ``Lambda >= 0``.
    By ``do = 4 <wi.m> dm`` it is the mean over the triangles of ``a = <wi.m> / (m.z cos_i) G2(wi, o)`` in
    the bin of the mirror direction ``o``; its other moments give the noise of a Monte Carlo estimate from
    uniform points of the landing cells (``N`` of them: variance ``(second - mean^2) / N``).
    """
    wi = np.asarray(wi, float)
    m = s.all_normals(landing_only=True)
    c = m @ wi
    o = 2 * c[:, None] * m - wi[None, :]
    ok = (c > 0) & (o[:, 2] > 0)
    m_ok, o_ok = m[ok], o[ok]
    lam_i = max(s.sigma(wi) / wi[2] - 1.0, 0.0)
    lam_o = np.maximum(_sigma_many(m, o_ok) / o_ok[:, 2] - 1.0, 0.0)
    a = c[ok] / (m_ok[:, 2] * wi[2]) / (1.0 + lam_i + lam_o)
    k = bin_index(o_ok, n_theta, n_phi)
    nb = n_theta * n_phi
    wmax = np.zeros(nb)
    np.maximum.at(wmax, k, a)
    n = len(m)
    return ModelTable(np.bincount(k, a, nb) / n, np.bincount(k, a * a, nb) / n, np.bincount(k, None, nb) / n, wmax)


def _sigma_many(m, w, chunk: int = 1024) -> np.ndarray:
    """``sigma(w) = mean over the triangles of <w.m>+ / m.z`` at many directions ``w``, exactly.

    With ``q = m / m.z = (-sx, -sy, 1)``, ``<w.q>+ = w.q + <-w.q>+``: the first term's mean is linear in
    ``w``, and ``-w.q > 0`` only on triangles whose slope ``|s|`` exceeds ``cot(theta_w)``, so each group of
    directions (sorted by elevation) sums the clipped part over the steep triangles alone."""
    q = m / m[:, 2:3]
    steep = np.hypot(q[:, 0], q[:, 1])
    q = q[np.argsort(-steep)]
    steep = -np.sort(-steep)
    out = w @ q.mean(axis=0)
    order = np.argsort(w[:, 2], kind="stable")[::-1]  # elevation ascending
    for a in range(0, len(order), chunk):
        idx = order[a : a + chunk]
        wz = w[idx, 2].min()
        cot = wz / np.sqrt(max(1.0 - wz * wz, 1e-300))
        n = int(np.count_nonzero(steep > cot * (1 - 1e-12)))
        if n:
            out[idx] += np.clip(-(w[idx] @ q[:n].T), 0.0, None).sum(axis=1) / len(q)
    return out
