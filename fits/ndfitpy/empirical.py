"""The empirical NDF of a height map, computed in numpy from the contract alone (no ndfit code or output).

- Form: the least-squares plane ``z = a + b x + c y`` over the valid points is subtracted (``remove_plane``).
- Slopes: central differences, ``s = ((h[i,j+1] - h[i,j-1]) / 2dx, (h[i+1,j] - h[i-1,j]) / 2dy)`` at every interior
  point whose four neighbours and itself are valid; the normal is ``m = (-s_x, -s_y, 1) / |.|`` (CONTRACT.md,
  Heitz eq. 61-62). On a regular grid every sample has the same projected area, so counts are the weights.
- Bins (``SlopeGrid``): a square grid in slope space centred on the median slope, ``n x n`` cells of side ``h``.
  The projected solid angle of a slope rectangle is exact: ``(m.n) dw = ds_x ds_y / (1 + |s|^2)^2`` (Heitz eq. 64:
  ``P22(s) = D(m) cos^4 theta``), whose antiderivative in both variables is
  ``F(x, y) = (x / sqrt(1+x^2) atan(y / sqrt(1+x^2)) + y / sqrt(1+y^2) atan(x / sqrt(1+y^2))) / 2``,
  so ``W = F(x1,y1) - F(x0,y1) - F(x1,y0) + F(x0,y0)``. The central direction is the image of the cell's centre.
  ``d_k = c_k / (N W_k)`` with ``N`` all valid samples (Heitz eq. 9); samples outside the square count in ``N``
  but fall in no bin, which the fit's conditional likelihood (objective.md: any region ``R``) allows.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .bins import Bins
from .x3p import HeightMap


def remove_plane(hm: HeightMap) -> HeightMap:
    """Subtract the least-squares plane of the valid points (x = j dx, y = i dy)."""
    ny, nx = hm.z.shape
    ok = np.isfinite(hm.z)
    ii, jj = np.nonzero(ok)
    if ii.size < 3:
        raise ValueError("fewer than 3 valid points: no plane to remove")
    x = jj * hm.dx
    y = ii * hm.dy
    xm, ym = x.mean(), y.mean()
    a = np.column_stack([np.ones_like(x), x - xm, y - ym])
    coef, *_ = np.linalg.lstsq(a, hm.z[ok], rcond=None)
    xx = np.arange(nx) * hm.dx - xm
    yy = np.arange(ny) * hm.dy - ym
    plane = coef[0] + coef[1] * xx[None, :] + coef[2] * yy[:, None]
    return HeightMap(z=hm.z - plane, dx=hm.dx, dy=hm.dy)


def central_slopes(hm: HeightMap) -> np.ndarray:
    """(N, 2) slopes grad h by central differences at interior points with all five stencil points valid."""
    z = hm.z
    if z.shape[0] < 3 or z.shape[1] < 3:
        raise ValueError(f"a {z.shape[1]} x {z.shape[0]} grid has no interior point")
    sx = (z[1:-1, 2:] - z[1:-1, :-2]) / (2.0 * hm.dx)
    sy = (z[2:, 1:-1] - z[:-2, 1:-1]) / (2.0 * hm.dy)
    ok = np.isfinite(sx) & np.isfinite(sy) & np.isfinite(z[1:-1, 1:-1])
    return np.column_stack([sx[ok], sy[ok]])


def normals(slopes: np.ndarray) -> np.ndarray:
    """m = (-s_x, -s_y, 1) / |.| (CONTRACT.md)."""
    q = np.sqrt(1.0 + slopes[:, 0] ** 2 + slopes[:, 1] ** 2)
    return np.column_stack([-slopes[:, 0] / q, -slopes[:, 1] / q, 1.0 / q])


def proj_solid_angle_primitive(x, y):
    """F with d2F/dxdy = (1 + x^2 + y^2)^-2: the projected solid angle of the slope quadrant below (x, y)."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    qx = np.sqrt(1.0 + x * x)
    qy = np.sqrt(1.0 + y * y)
    return 0.5 * (x / qx * np.arctan(y / qx) + y / qy * np.arctan(x / qy))


def rect_proj_solid_angle(x0, x1, y0, y1):
    """Exact integral of m.n over the directions whose slopes lie in [x0, x1] x [y0, y1]."""
    f = proj_solid_angle_primitive
    return f(x1, y1) - f(x0, y1) - f(x1, y0) + f(x0, y0)


@dataclass
class SlopeGrid:
    """A square grid of ``n x n`` cells in slope space: cell (i, j) spans x0 + j h .. x0 + (j+1) h in s_x and
    y0 + i h .. in s_y."""

    x0: float
    y0: float
    h: float
    n: int

    @staticmethod
    def around(slopes: np.ndarray, target_count: float = 48.0, half_widths: float = 5.0) -> "SlopeGrid":
        """Centred on the median slope, half-width ``half_widths`` robust scales (IQR / 1.349 of the wider axis),
        at most out to 70 degrees from the median; cells across chosen for about ``target_count`` samples per
        occupied cell (15-255, odd)."""
        c = np.median(slopes, axis=0)
        q = np.percentile(slopes, [25.0, 75.0], axis=0)
        sigma = float(np.max((q[1] - q[0]) / 1.349))
        sigma = max(sigma, 1e-7)
        half = min(half_widths * sigma, math.tan(math.radians(70.0)) + float(np.max(np.abs(c))))
        n = int(np.clip(math.sqrt(len(slopes) / target_count * 4.0 / math.pi), 15, 255)) | 1
        h = 2.0 * half / n
        return SlopeGrid(x0=float(c[0] - half), y0=float(c[1] - half), h=h, n=n)

    def bins(self, slopes: np.ndarray) -> Bins:
        """Counts of ``slopes`` per cell, exact projected solid angles, central directions; N = all slopes."""
        j = np.floor((slopes[:, 0] - self.x0) / self.h).astype(np.int64)
        i = np.floor((slopes[:, 1] - self.y0) / self.h).astype(np.int64)
        inside = (i >= 0) & (i < self.n) & (j >= 0) & (j < self.n)
        count = np.bincount(i[inside] * self.n + j[inside], minlength=self.n * self.n).astype(float)
        ex = self.x0 + self.h * np.arange(self.n + 1)
        ey = self.y0 + self.h * np.arange(self.n + 1)
        x0, x1 = np.meshgrid(ex[:-1], ey[:-1])[0].ravel(), np.meshgrid(ex[1:], ey[:-1])[0].ravel()
        y0, y1 = np.meshgrid(ex[:-1], ey[:-1])[1].ravel(), np.meshgrid(ex[:-1], ey[1:])[1].ravel()
        w = rect_proj_solid_angle(x0, x1, y0, y1)
        sc = np.column_stack([0.5 * (x0 + x1), 0.5 * (y0 + y1)])
        m = normals(sc)
        n_total = float(len(slopes))
        return Bins(m=m, count=count, proj_solid_angle=w, d=count / (n_total * w), path="<numpy>", n_total=n_total)


def empirical_ndf(hm: HeightMap, form: str = "plane"):
    """(slopes, Bins) of a height map: plane removal (``form='plane'``) or none, central slopes, SlopeGrid bins."""
    if form == "plane":
        hm = remove_plane(hm)
    elif form != "none":
        raise ValueError(f"form '{form}' is not implemented here (plane, none)")
    s = central_slopes(hm)
    if len(s) == 0:
        raise ValueError("no valid central-difference stencil")
    return s, SlopeGrid.around(s).bins(s)
