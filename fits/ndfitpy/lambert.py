"""ndfit's bins rebuilt from their documented definition (data_formats/ndf_csv.md, "How the bins are made") and the
frame that ``ndfit ndf -o X.json`` reports, so that the numpy pipeline's normals can be counted in the very same
cells and each cell's projected solid angle integrated independently.

Cell of a slope ``s``: whitened ``s' = Whiten (s - c)``, stretched normal ``m' = (s', 1) / |.|``, Lambert
azimuthal equal-area point ``p = sqrt(2 / (1 + m'_z)) m'_xy`` on the disk ``|p| <= sqrt 2``, and the cell of an
``n x n`` square grid over ``[-sqrt 2, sqrt 2]^2`` (column from ``p_x``, row from ``p_y``). The projected solid
angle of a cell is ``W = integral |det d(m_x, m_y) / dp| d^2p`` (``(m.n) dw = dm_x dm_y``, the orthographic
projection), with the Jacobian composed here by the chain rule through the inverse Lambert map
(``m'_xy = p sqrt(1 - |p|^2/4)``, ``m'_z = 1 - |p|^2/2``), ``s = c + Unwhiten s'`` and ``m_xy = -s / sqrt(1+|s|^2)``;
the solid angle integrates the same divided by ``m_z``. Gauss-Legendre on cells wholly inside the disk; a cell
counts as verified when an 8 x 8 rule and 2 x 2 sub-cells of 8 x 8 agree to ``CONVERGED`` relative.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

SQRT2 = math.sqrt(2.0)
CONVERGED = 1e-10


@dataclass
class LambertGrid:
    center: np.ndarray  #: (2,) c
    whiten: np.ndarray  #: (2, 2)
    unwhiten: np.ndarray  #: (2, 2)
    n: int  #: cells across

    @staticmethod
    def from_ndf_json(doc: dict) -> "LambertGrid":
        fr = doc["frame"]
        return LambertGrid(center=np.asarray(fr["center"], float), whiten=np.asarray(fr["whiten"], float),
                           unwhiten=np.asarray(fr["unwhiten"], float), n=int(doc["options"]["cells_across"]))

    @property
    def h(self) -> float:
        return 2.0 * SQRT2 / self.n

    def lambert(self, slopes: np.ndarray) -> np.ndarray:
        sw = (slopes - self.center) @ self.whiten.T
        t = 1.0 + np.sum(sw * sw, axis=1)
        return sw * np.sqrt(2.0 / (t + np.sqrt(t)))[:, None]

    def cell_of(self, slopes: np.ndarray) -> np.ndarray:
        """Flat cell index row * n + column of each slope."""
        p = self.lambert(slopes)
        ij = np.clip(np.floor((p + SQRT2) / self.h).astype(np.int64), 0, self.n - 1)
        return ij[:, 1] * self.n + ij[:, 0]

    def jacobian(self, p: np.ndarray) -> np.ndarray:
        """(K,) |det d(m_x, m_y)/dp| and (K,) m_z at Lambert points p (K, 2) inside the disk."""
        r2 = np.sum(p * p, axis=1)
        g = np.sqrt(1.0 - 0.25 * r2)
        mz1 = 1.0 - 0.5 * r2
        mxy1 = p * g[:, None]
        eye = np.eye(2)[None]
        dmxy1 = g[:, None, None] * eye - np.einsum("ki,kj->kij", p, p) / (4.0 * g)[:, None, None]
        ds1 = dmxy1 / mz1[:, None, None] + np.einsum("ki,kj->kij", mxy1, p) / (mz1 ** 2)[:, None, None]
        s1 = mxy1 / mz1[:, None]
        s = self.center + s1 @ self.unwhiten.T
        ds = np.einsum("ab,kbj->kaj", self.unwhiten, ds1)
        q = np.sqrt(1.0 + np.sum(s * s, axis=1))
        dm = -(eye / q[:, None, None] - np.einsum("ki,kj->kij", s, s) / (q ** 3)[:, None, None])
        jac = np.einsum("kab,kbj->kaj", dm, ds)
        return np.abs(np.linalg.det(jac)), 1.0 / q

    def _rule(self, corners: np.ndarray, order: int):
        """(W, Omega) of axis-aligned squares with lower-left ``corners`` (K, 2) and side ``self.h``."""
        x, w = np.polynomial.legendre.leggauss(order)
        u = 0.5 * (x + 1.0)
        uu, vv = np.meshgrid(u, u)
        ww = np.outer(w, w).ravel() * 0.25
        nodes = corners[:, None, :] + self.h * np.stack([uu.ravel(), vv.ravel()], axis=1)[None]
        jac, mz = self.jacobian(nodes.reshape(-1, 2))
        jac = jac.reshape(len(corners), -1)
        mz = mz.reshape(len(corners), -1)
        area = self.h * self.h
        return area * (jac @ ww), area * ((jac / mz) @ ww)

    def interior_integrals(self, cells: np.ndarray, order: int = 8):
        """For the given flat cells: (W, Omega, verified) with verified = wholly inside the disk and converged."""
        row, col = np.divmod(cells, self.n)
        lo = np.column_stack([-SQRT2 + col * self.h, -SQRT2 + row * self.h])
        far = np.maximum(np.abs(lo), np.abs(lo + self.h))
        inside = np.hypot(far[:, 0], far[:, 1]) < SQRT2 * (1.0 - 1e-9)
        w = np.full(len(cells), np.nan)
        om = np.full(len(cells), np.nan)
        ok = np.zeros(len(cells), bool)
        if np.any(inside):
            c = lo[inside]
            w1, o1 = self._rule(c, order)
            half = LambertGrid(self.center, self.whiten, self.unwhiten, 2 * self.n)
            w2 = np.zeros(len(c))
            o2 = np.zeros(len(c))
            for dx in (0.0, 0.5):
                for dy in (0.0, 0.5):
                    a, b = half._rule(c + self.h * np.array([dx, dy]), order)
                    w2 += a
                    o2 += b
            conv = (np.abs(w2 - w1) <= CONVERGED * w2) & (np.abs(o2 - o1) <= CONVERGED * o2)
            w[inside], om[inside], ok[inside] = w2, o2, conv
        return w, om, ok
