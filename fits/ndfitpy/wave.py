"""An independent numpy implementation of the scalar-diffraction BRDF of docs/WAVE.md: the cross-check of ``ndfit wave``.

Written from docs/WAVE.md and CONTRACT.md ("Wave optics"), not from ndfit's code. With ``k = 2 pi / lambda``,
``v = k (w_i + w_o)``, Kirchhoff's factor ``Q = |w_i + w_o|^4 / (4 cos_i cos_o (cos_i + cos_o)^2)``:

- **Patches**: squares of ``P_x = round(C / dx)`` by ``P_y = round(C / dy)`` samples, ``floor(nx / P_x)`` by
  ``floor(ny / P_y)`` of them, the tiling centred (first column ``(nx - cols P_x) // 2``); Hann window
  ``w_j = sin^2(pi (j + 1/2) / P)`` per axis; mask ``m`` (1 where the height is finite); ``u = (w m)^2``;
  ``r = h - sum(u h) / sum(u)``. A patch with fewer than 90% valid points is skipped.
- **Fields** at a given ``v_z``: the mean field ``chi = sum(u exp(i v_z r)) / sum(u)`` and the diffuse field
  ``g = w m (exp(i v_z r) - chi)``, transformed by numpy's unscaled inverse DFT (``ifft2(norm="forward")``).
  All patches are stacked and transformed together, in blocks that bound the memory.
- **Levels**: per wavelength and incidence the interval of ``v_z`` over the propagating bins (widened to the
  mirror's ``2 k cos_i``); in ``t = ln v_z``, sorted and merged where one starts within ``ln(ratio)`` of the
  previous end; ``ceil((b - a) / ln(ratio))`` equal steps per merged interval. Between levels, a cubic
  Hermite whose node slopes are the derivative of the parabola through the node and its neighbours
  (one-sided at a merged interval's ends); outside the ladder the end value is held; a query that falls in
  the gap between two merged intervals (only the evanescent bins' ``k cos_i`` can) takes the nearer level,
  which docs/WAVE.md leaves unsaid. Bin intensities are clamped at 0, the mirror share to [0, 1].
- **Outputs**: ``specular`` = the interpolated ``sum_p |chi_p|^2 sum(u_p) / sum_p sum(u_p)`` at ``2 k cos_i``;
  each bin's share ``sum_p |G_p|^2 / (P_x P_y sum_p sum(u_p))`` at its own ``v_z``; its direction
  ``(x_o, y_o) = v_t / k - w_i.xy`` (``v_x = 2 pi s / (P_x dx)`` with the signed frequency ``s``);
  ``diffuse_albedo`` = sum of ``Q`` times the propagating bins' shares; ``evanescent`` = sum of the other
  bins' shares read at ``k cos_i``; ``beyond_band`` from the whole scan's central-difference slopes by
  geometric optics, facets weighted by ``(w_i . m) / (m_z cos_i)``; the grid spreads each propagating bin's
  energy (a box of ``lambda / (P_x dx)`` by ``lambda / (P_y dy)``) over the cells by overlap area, a
  separable sum computed as two matrix products.

Readers: X3P, GSF and NPY through ``scanio``; Wyko OPD, Sensofar PLU and Alicona AL3D here, written from the
layouts in data_formats/formats.md (``read_scan``).

Command line: ``python -m ndfitpy.wave SCAN --wavelength 450,550,650 --incidence 0,45,75 [--coherence UM]
[--form none|plane] [--grid N --grid-out PREFIX] -o OUT.json``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import struct
import sys
from dataclasses import dataclass, field
from typing import List, Optional, Sequence

import numpy as np

from .empirical import remove_plane
from .scanio import read_scan as _scanio_read
from .x3p import HeightMap

SUN_ANGULAR_RADIUS = 4.65e-3
DEFAULT_COHERENCE_M = 0.16 * 550e-9 / SUN_ANGULAR_RADIUS
DEFAULT_LEVEL_RATIO = 1.1
MIN_VALID_SHARE = 0.9
MIN_PATCH_SAMPLES = 4
# Complex samples held per block of patches (16 bytes each, a few arrays of it at once).
_BLOCK_ELEMS = 1 << 21


def direction(theta_deg: float, phi_deg: float) -> np.ndarray:
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return np.array([math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)])


def wavenumber(lambda_nm: float) -> float:
    return 2.0 * math.pi / (lambda_nm * 1e-9)


def kirchhoff_q(wi, wox, woy, woz):
    """``|w_i + w_o|^4 / (4 cos_i cos_o (cos_i + cos_o)^2)`` (arrays of outgoing components)."""
    sx, sy, sz = wi[0] + wox, wi[1] + woy, wi[2] + woz
    n2 = sx * sx + sy * sy + sz * sz
    return n2 * n2 / (4.0 * wi[2] * woz * sz * sz)


def _signed(n: int) -> np.ndarray:
    k = np.arange(n)
    return np.where(k < (n + 1) // 2, k, k - n)


def hann(n: int) -> np.ndarray:
    return np.sin(np.pi * (np.arange(n) + 0.5) / n) ** 2


# ---------------------------------------------------------------------------------------------------------
# Levels


@dataclass
class Ladder:
    """Levels of ``v_z`` (sorted), their logarithms ``t`` and the merged interval each belongs to."""

    vz: np.ndarray
    t: np.ndarray
    group: np.ndarray
    step: float

    @classmethod
    def covering(cls, intervals, ratio: float) -> "Ladder":
        step = math.log(ratio)
        iv = sorted(((math.log(a), math.log(b)) for a, b in intervals), key=lambda p: p[0])
        merged: List[List[float]] = []
        for a, b in iv:
            if merged and a <= merged[-1][1] + step:
                merged[-1][1] = max(merged[-1][1], b)
            else:
                merged.append([a, b])
        t, g = [], []
        for gi, (a, b) in enumerate(merged):
            n = max(int(math.ceil((b - a) / step)), 0)
            if n == 0:
                t.append(a)
                g.append(gi)
            else:
                t.extend(a + (b - a) * j / n for j in range(n + 1))
                g.extend([gi] * (n + 1))
        t = np.array(t)
        return cls(vz=np.exp(t), t=t, group=np.array(g), step=step)

    def __len__(self) -> int:
        return len(self.t)

    def weights(self, vz) -> tuple:
        """Node indices and weights, each of shape ``(4,) + vz.shape``, of the interpolant at ``vz``."""
        q = np.log(np.asarray(vz, dtype=float))
        T, G = self.t, self.group
        n = len(T)
        idx = np.zeros((4,) + q.shape, dtype=np.intp)
        w = np.zeros((4,) + q.shape)
        if n == 1:
            w[0] = 1.0
            return idx, w
        lo = ~(q > T[0])
        hi = q >= T[-1]
        j = np.clip(np.searchsorted(T, q, side="right") - 1, 0, n - 2)
        inside = ~lo & ~hi
        gap = inside & (G[j] != G[j + 1])
        cub = inside & ~gap
        # Held ends and gaps: one node, weight 1.
        idx[0] = np.where(lo, 0, np.where(hi, n - 1, j))
        w[0] = np.where(lo | hi, 1.0, 0.0)
        t0, t1 = T[j], T[j + 1]
        h = t1 - t0
        s = np.where(cub | gap, (q - t0) / np.where(h > 0, h, 1.0), 0.0)
        idx[0] = np.where(gap & (s >= 0.5), j + 1, idx[0])
        w[0] = np.where(gap, 1.0, w[0])
        # The cubic: nodes j-1, j, j+1, j+2 in slots 0..3.
        jm = np.maximum(j - 1, 0)
        jp2 = np.minimum(j + 2, n - 1)
        h00 = 2 * s**3 - 3 * s**2 + 1
        h10 = s**3 - 2 * s**2 + s
        h01 = -2 * s**3 + 3 * s**2
        h11 = s**3 - s**2
        left = (j > 0) & (G[jm] == G[j])  # node j has a joined left neighbour
        right2 = (j + 2 < n) & (G[jp2] == G[j + 1])  # node j+1 has a joined right neighbour
        # Slope at j (its right neighbour j+1 is joined): coefficients on j-1, j, j+1.
        hl = T[j] - T[jm]
        hr = h
        d = hl + hr
        safe = lambda x: np.where(x > 0, x, 1.0)  # noqa: E731
        a_m = np.where(left, -hr / safe(hl * d), 0.0)
        a_0 = np.where(left, (hr - hl) / safe(hl * hr), -1.0 / safe(hr))
        a_p = np.where(left, hl / safe(hr * d), 1.0 / safe(hr))
        # Slope at j+1 (its left neighbour j is joined): coefficients on j, j+1, j+2.
        hl2 = h
        hr2 = T[jp2] - T[j + 1]
        d2 = hl2 + hr2
        b_0 = np.where(right2, -hr2 / safe(hl2 * d2), -1.0 / safe(hl2))
        b_1 = np.where(right2, (hr2 - hl2) / safe(hl2 * hr2), 1.0 / safe(hl2))
        b_2 = np.where(right2, hl2 / safe(hr2 * d2), 0.0)
        c10, c11 = h10 * h, h11 * h
        wc = [a_m * c10, h00 + a_0 * c10 + b_0 * c11, h01 + a_p * c10 + b_1 * c11, b_2 * c11]
        ic = [jm, j, j + 1, jp2]
        for k in range(4):
            idx[k] = np.where(cub, ic[k], idx[k] if k == 0 else 0)
            w[k] = np.where(cub, wc[k], w[k] if k == 0 else 0.0)
        return idx, w

    def interpolate(self, values: np.ndarray, vz) -> np.ndarray:
        """``values`` (levels first, any trailing shape broadcast against ``vz``'s) at ``vz``."""
        idx, w = self.weights(vz)
        if values.ndim == 1:
            return (w * values[idx]).sum(axis=0)
        idx = np.broadcast_to(idx, (4,) + values.shape[1:])
        return (w * np.take_along_axis(values, idx, axis=0)).sum(axis=0)


# ---------------------------------------------------------------------------------------------------------
# The patch sums


@dataclass
class Diffraction:
    """The patch-summed diffraction of one scan (docs/WAVE.md), ready to be read at its wavelengths and incidences."""

    heights: np.ndarray
    dx: float
    dy: float
    coherence_m: float
    px: int
    py: int
    cols: int
    rows: int
    x0: int
    y0: int
    ladder: Ladder
    spectra: np.ndarray  # (levels, P_y, P_x): sum over patches of |G|^2, axis 0 = ky, axis 1 = kx
    coherent: np.ndarray  # (levels,): sum over patches of |chi|^2 sum(u)
    weight: float  # sum over patches of sum(u)
    used: int
    skipped: int
    tilt_rms_deg: float
    wavelengths_nm: List[float] = field(default_factory=list)
    incidences_deg: List[float] = field(default_factory=list)
    azimuth_deg: float = 0.0

    @property
    def levels(self) -> np.ndarray:
        return self.ladder.vz

    def band(self, lambda_nm: float):
        lam = lambda_nm * 1e-9
        return lam / (2.0 * self.dx), lam / (2.0 * self.dy)

    def specular(self, lambda_nm: float, cos_i: float) -> float:
        vz = 2.0 * wavenumber(lambda_nm) * cos_i
        return float(np.clip(self.ladder.interpolate(self.coherent / self.weight, vz), 0.0, 1.0))

    def bins(self, lambda_nm: float, theta_deg: float, phi_deg: Optional[float] = None) -> dict:
        """Every FFT bin seen from one wavelength and incidence, arrays of shape ``(P_y, P_x)``:
        ``x``, ``y`` (the outgoing direction's projection), ``prop`` (propagates), ``cos_o``, ``q`` (Kirchhoff's
        factor, 0 where evanescent), ``share`` (the bin's share before ``Q``: at its own ``v_z`` where it
        propagates, at ``k cos_i`` elsewhere) and ``energy`` (``q * share``, 0 where evanescent)."""
        phi = self.azimuth_deg if phi_deg is None else phi_deg
        wi = direction(theta_deg, phi)
        x, y, r2, k = _bin_xy(self.px, self.py, self.dx, self.dy, lambda_nm, wi)
        prop = r2 < 1.0
        cos_o = np.sqrt(np.where(prop, 1.0 - r2, 1.0))
        vz = np.where(prop, k * (wi[2] + cos_o), k * wi[2])
        inten = np.maximum(self.ladder.interpolate(self.spectra, vz), 0.0)
        share = inten / (self.px * self.py * self.weight)
        q = np.where(prop, kirchhoff_q(wi, x, y, cos_o), 0.0)
        return {"x": x, "y": y, "prop": prop, "cos_o": np.where(prop, cos_o, 0.0), "q": q, "share": share,
                "energy": q * share, "wi": wi}


def _bin_xy(px, py, dx, dy, lambda_nm, wi):
    k = wavenumber(lambda_nm)
    vx = 2.0 * math.pi * _signed(px) / (px * dx)
    vy = 2.0 * math.pi * _signed(py) / (py * dy)
    x = (vx / k - wi[0])[None, :] * np.ones((py, 1))
    y = (vy / k - wi[1])[:, None] * np.ones((1, px))
    return x, y, x * x + y * y, k


def _vz_interval(px, py, dx, dy, lambda_nm, wi):
    x, y, r2, k = _bin_xy(px, py, dx, dy, lambda_nm, wi)
    prop = r2 < 1.0
    mirror = 2.0 * k * wi[2]
    if not prop.any():
        return None
    vz = k * (wi[2] + np.sqrt(1.0 - r2[prop]))
    return min(vz.min(), mirror), max(vz.max(), mirror)


def tiling(nx: int, ny: int, dx: float, dy: float, coherence_m: float):
    """``(P_x, P_y, cols, rows, x0, y0)`` of docs/WAVE.md "Coherence patches"; ValueError where none fits."""
    px, py = math.floor(coherence_m / dx + 0.5), math.floor(coherence_m / dy + 0.5)
    if px < MIN_PATCH_SAMPLES or py < MIN_PATCH_SAMPLES:
        raise ValueError(f"the coherence patch ({coherence_m * 1e6:.4g} um) is {px} x {py} samples: at least "
                         f"{MIN_PATCH_SAMPLES} per side are needed")
    if px > nx or py > ny:
        raise ValueError(f"the coherence patch ({px} x {py} samples) is larger than the scan ({nx} x {ny})")
    cols, rows = nx // px, ny // py
    return px, py, cols, rows, (nx - cols * px) // 2, (ny - rows * py) // 2


def diffraction(heights, dx, dy, wavelengths_nm, incidences_deg, azimuth_deg=0.0, coherence_m=None,
                level_ratio=DEFAULT_LEVEL_RATIO, block_elems=_BLOCK_ELEMS) -> Diffraction:
    """Tile ``heights`` (float64 ``(ny, nx)``, metres, NaN = invalid, form already removed) into coherence
    patches and sum their spectra at the ``v_z`` levels the wavelengths and incidences need."""
    h = np.asarray(heights, dtype=float)
    if h.ndim != 2:
        raise ValueError(f"heights must be 2-D, got shape {h.shape}")
    wavelengths_nm = [float(v) for v in np.atleast_1d(wavelengths_nm)]
    incidences_deg = [float(v) for v in np.atleast_1d(incidences_deg)]
    if not wavelengths_nm or not all(v > 0 and math.isfinite(v) for v in wavelengths_nm):
        raise ValueError(f"wavelengths {wavelengths_nm} nm: give positive numbers")
    if not incidences_deg or not all(0.0 <= v <= 89.9 for v in incidences_deg):
        raise ValueError(f"incidences {incidences_deg} deg: each must lie in [0, 89.9]")
    if not (level_ratio > 1.0 and level_ratio <= 2.0):
        raise ValueError(f"level ratio {level_ratio} is outside (1, 2]")
    c = DEFAULT_COHERENCE_M if coherence_m is None else float(coherence_m)
    ny, nx = h.shape
    px, py, cols, rows, x0, y0 = tiling(nx, ny, dx, dy, c)

    intervals = []
    for lam in wavelengths_nm:
        for th in incidences_deg:
            iv = _vz_interval(px, py, dx, dy, lam, direction(th, azimuth_deg))
            if iv is not None:
                intervals.append(iv)
    ladder = Ladder.covering(intervals, level_ratio)
    nl = len(ladder)

    # All patches, row-major over (patch row, patch column).
    sub = h[y0:y0 + rows * py, x0:x0 + cols * px]
    stack = sub.reshape(rows, py, cols, px).transpose(0, 2, 1, 3).reshape(rows * cols, py, px)
    mask = np.isfinite(stack)
    nvalid = mask.sum(axis=(1, 2))
    keep = nvalid >= MIN_VALID_SHARE * (px * py)
    skipped = int((~keep).sum())
    stack, mask = stack[keep], mask[keep]
    used = stack.shape[0]
    if used == 0:
        raise ValueError(f"no coherence patch has {MIN_VALID_SHARE:.0%} valid points ({skipped} patches of {px} x {py})")

    win = hann(py)[:, None] * hann(px)[None, :]
    spectra = np.zeros((nl, py, px))
    coherent = np.zeros(nl)
    weight = 0.0
    tilt2 = 0.0
    xs = np.arange(px) * dx
    ys = np.arange(py) * dy
    block = max(1, block_elems // (px * py))
    for b0 in range(0, used, block):
        hb = stack[b0:b0 + block]
        mb = mask[b0:b0 + block]
        wm = np.where(mb, win, 0.0)
        u = wm * wm
        hz = np.where(mb, hb, 0.0)
        s1 = u.sum(axis=(1, 2))
        mean = (u * hz).sum(axis=(1, 2)) / s1
        r = np.where(mb, hz - mean[:, None, None], 0.0)
        weight += s1.sum()
        tilt2 += (s1 * _tilt2(u, hz, xs, ys)).sum()
        for li, vz in enumerate(ladder.vz):
            ph = vz * r
            cs, sn = np.cos(ph), np.sin(ph)
            cr = np.einsum("pij,pij->p", u, cs) / s1
            ci = np.einsum("pij,pij->p", u, sn) / s1
            coherent[li] += ((cr * cr + ci * ci) * s1).sum()
            g = np.empty(r.shape, dtype=complex)
            g.real = wm * (cs - cr[:, None, None])
            g.imag = wm * (sn - ci[:, None, None])
            sp = np.fft.ifft2(g, norm="forward")
            spectra[li] += (sp.real * sp.real + sp.imag * sp.imag).sum(axis=0)
    tilt = math.degrees(math.atan(math.sqrt(tilt2 / weight)))
    return Diffraction(heights=h, dx=float(dx), dy=float(dy), coherence_m=c, px=px, py=py, cols=cols, rows=rows,
                       x0=x0, y0=y0, ladder=ladder, spectra=spectra, coherent=coherent, weight=float(weight),
                       used=used, skipped=skipped, tilt_rms_deg=tilt, wavelengths_nm=wavelengths_nm,
                       incidences_deg=incidences_deg, azimuth_deg=float(azimuth_deg))


def _tilt2(u, hz, xs, ys):
    """Squared gradient ``a^2 + b^2`` of each patch's ``u``-weighted least-squares plane ``a x + b y + c``."""
    X = xs[None, None, :]
    Y = ys[None, :, None]
    sxx = (u * X * X).sum(axis=(1, 2))
    sxy = (u * X * Y).sum(axis=(1, 2))
    syy = (u * Y * Y).sum(axis=(1, 2))
    sx = (u * X).sum(axis=(1, 2))
    sy = (u * Y).sum(axis=(1, 2))
    s1 = u.sum(axis=(1, 2))
    sxz = (u * X * hz).sum(axis=(1, 2))
    syz = (u * Y * hz).sum(axis=(1, 2))
    sz = (u * hz).sum(axis=(1, 2))
    m = np.stack([np.stack([sxx, sxy, sx], -1), np.stack([sxy, syy, sy], -1), np.stack([sx, sy, s1], -1)], -2)
    rhs = np.stack([sxz, syz, sz], -1)
    ok = np.abs(np.linalg.det(m)) > 0
    out = np.zeros(len(s1))
    if ok.any():
        sol = np.linalg.solve(m[ok], rhs[ok][..., None])[..., 0]
        a, b = sol[:, 0], sol[:, 1]
        out[ok] = np.where(np.isfinite(a) & np.isfinite(b), a * a + b * b, 0.0)
    return out


# ---------------------------------------------------------------------------------------------------------
# Records, beyond the band, the grid


def facets(heights, dx, dy):
    """Unit normals ``(m_x, m_y, m_z)`` of the central-difference slopes at interior points where both are finite."""
    z = heights
    if z.shape[0] < 3 or z.shape[1] < 3:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    sx = (z[1:-1, 2:] - z[1:-1, :-2]) / (2.0 * dx)
    sy = (z[2:, 1:-1] - z[:-2, 1:-1]) / (2.0 * dy)
    ok = np.isfinite(sx) & np.isfinite(sy)
    sx, sy = sx[ok], sy[ok]
    norm = np.sqrt(sx * sx + sy * sy + 1.0)
    return -sx / norm, -sy / norm, 1.0 / norm


def beyond_band(heights, dx, dy, wi, band, normals=None) -> float:
    """Share of the light that specular reflection on the central-difference facets sends beyond ``band``."""
    mx, my, mz = facets(heights, dx, dy) if normals is None else normals
    c = wi[0] * mx + wi[1] * my + wi[2] * mz
    face = c > 0
    c, mx, my, mz = c[face], mx[face], my[face], mz[face]
    w = c / mz
    ox = 2.0 * c * mx - wi[0]
    oy = 2.0 * c * my - wi[1]
    out = (np.abs(ox + wi[0]) > band[0]) | (np.abs(oy + wi[1]) > band[1])
    total = w.sum()
    return float(w[out].sum() / total) if total > 0 else 0.0


def records(d: Diffraction, wavelengths_nm=None, incidences_deg=None, azimuth_deg=None) -> List[dict]:
    """One record per (wavelength, incidence), wavelengths outer, with the keys of ``ndfit wave``'s JSON
    (material none: ``albedo = specular + diffuse_albedo``)."""
    lams = d.wavelengths_nm if wavelengths_nm is None else list(wavelengths_nm)
    incs = d.incidences_deg if incidences_deg is None else list(incidences_deg)
    phi = d.azimuth_deg if azimuth_deg is None else float(azimuth_deg)
    out = []
    normals = facets(d.heights, d.dx, d.dy)
    for lam in lams:
        band = d.band(lam)
        for th in incs:
            b = d.bins(lam, th, phi)
            wi = b["wi"]
            spec = d.specular(lam, wi[2])
            diffuse = float(b["energy"][b["prop"]].sum())
            evan = float(b["share"][~b["prop"]].sum())
            out.append({
                "wavelength_nm": float(lam),
                "theta_deg": float(th),
                "phi_deg": phi,
                "specular": spec,
                "diffuse_albedo": diffuse,
                "albedo": spec + diffuse,
                "evanescent": evan,
                "band_limit": min(band),
                "beyond_band": beyond_band(d.heights, d.dx, d.dy, wi, band, normals),
                "angular_step_deg": math.degrees(math.asin(min(lam * 1e-9 / d.coherence_m, 1.0))),
            })
    return out


def _overlap(centres, half, n):
    """``(len(centres), n)``: length of ``[c - half, c + half]`` inside each of the ``n`` cells of ``[-1, 1]``."""
    edges = -1.0 + 2.0 * np.arange(n + 1) / n
    lo = np.maximum(edges[None, :-1], centres[:, None] - half)
    hi = np.minimum(edges[None, 1:], centres[:, None] + half)
    return np.maximum(hi - lo, 0.0)


def grid_one(d: Diffraction, lambda_nm: float, theta_deg: float, n: int, phi_deg: Optional[float] = None) -> np.ndarray:
    """The diffuse BRDF (1/sr) averaged over each cell of the ``n x n`` grid of the projected disk: row ``i``
    is ``y``, column ``j`` is ``x``."""
    b = d.bins(lambda_nm, theta_deg, phi_deg)
    lam = lambda_nm * 1e-9
    hx, hy = lam / (2.0 * d.px * d.dx), lam / (2.0 * d.py * d.dy)
    e = np.where(b["prop"], b["energy"], 0.0) / (4.0 * hx * hy)
    ox = _overlap(b["x"][0, :], hx, n)  # (P_x, n)
    oy = _overlap(b["y"][:, 0], hy, n)  # (P_y, n)
    g = oy.T @ e @ ox
    cell = 2.0 / n
    edges = -1.0 + cell * np.arange(n + 1)
    near = np.where(edges[:-1] > 0, edges[:-1], np.where(edges[1:] < 0, -edges[1:], 0.0))
    outside = np.hypot(near[:, None], near[None, :]) >= 1.0
    g = np.where(outside, 0.0, g / (cell * cell))
    return g


def grid(d: Diffraction, n: int, wavelengths_nm=None, incidences_deg=None, azimuth_deg=None) -> np.ndarray:
    """``(wavelengths, incidences, n, n)`` float64: docs/WAVE.md "The grid"."""
    lams = d.wavelengths_nm if wavelengths_nm is None else list(wavelengths_nm)
    incs = d.incidences_deg if incidences_deg is None else list(incidences_deg)
    out = np.zeros((len(lams), len(incs), n, n))
    for a, lam in enumerate(lams):
        for c, th in enumerate(incs):
            out[a, c] = grid_one(d, lam, th, n, azimuth_deg)
    return out


# ---------------------------------------------------------------------------------------------------------
# Readers of the formats scanio lacks (data_formats/formats.md)


def _read_opd(path: str) -> HeightMap:
    with open(path, "rb") as fh:
        raw = fh.read()
    if raw[2:11] != b"Directory":
        raise ValueError(f"{path}: not a Wyko OPD file (no 'Directory' at byte 2)")
    pos = 2
    _, _, dlen, _ = struct.unpack_from("<16shiH", raw, pos)
    nblocks = dlen // 24
    entries = []
    for b in range(nblocks):
        name, typ, length, _ = struct.unpack_from("<16shiH", raw, pos + 24 * b)
        entries.append((name.split(b"\0", 1)[0].decode("latin-1").strip(), typ, length))
    off = pos
    blocks = {}
    for name, typ, length in entries:
        if length > 0:
            blocks.setdefault(name, (off, typ, length))
            off += length
    data = None
    for key in ("RAW DATA", "RAW_DATA", "OPD", "Raw"):
        if key in blocks:
            data = blocks[key]
            break
    if data is None:
        raise ValueError(f"{path}: no height block")
    o = data[0]
    ncol, nrow, size = struct.unpack_from("<HHH", raw, o)
    dt = {1: "u1", 2: "<i2", 4: "<f4"}[size]
    v = np.frombuffer(raw, dtype=dt, count=ncol * nrow, offset=o + 6).astype(float).reshape(ncol, nrow)
    if size == 4:
        v[~np.isfinite(v) | (np.abs(v) >= 1e32)] = np.nan
    elif size == 2:
        v[v == 32767] = np.nan

    def scalar(name, default):
        if name not in blocks:
            return default
        bo, _, bl = blocks[name]
        if bl == 2:
            return float(struct.unpack_from("<h", raw, bo)[0])
        if bl >= 4:
            return float(struct.unpack_from("<f", raw, bo)[0])
        return default

    wl, mult = scalar("Wavelength", 1.0), scalar("Mult", 1.0)
    pix, aspect = scalar("Pixel_size", 1.0), scalar("Aspect", 1.0)
    z = v.T[::-1, :] * (wl / mult) * 1e-9  # column by column from the top; row 0 = each column's last value
    return HeightMap(z=np.ascontiguousarray(z), dx=pix * 1e-3, dy=pix * aspect * 1e-3)


def _read_plu(path: str) -> HeightMap:
    with open(path, "rb") as fh:
        raw = fh.read()
    mppx, mppy = struct.unpack_from("<ff", raw, 388 + 16)
    (mtype,) = struct.unpack_from("<I", raw, 428)
    if mtype != 3:
        raise ValueError(f"{path}: measurement type {mtype} is not a topography")
    rows, cols = struct.unpack_from("<II", raw, 500)
    z = np.frombuffer(raw, dtype="<f4", count=rows * cols, offset=508).astype(float).reshape(rows, cols)
    z = np.where(z == 1000001.0, np.nan, z) * 1e-6
    return HeightMap(z=z, dx=mppx * 1e-6, dy=mppy * 1e-6)


def _read_al3d(path: str) -> HeightMap:
    with open(path, "rb") as fh:
        raw = fh.read()
    if raw[:17] != b"AliconaImaging\x00\r\n":
        raise ValueError(f"{path}: not an Alicona AL3D file")

    def tag(i):
        at = 17 + 52 * i
        key, val = raw[at:at + 20], raw[at + 20:at + 50]
        return key.split(b"\0", 1)[0].decode("latin-1"), val.split(b"\0", 1)[0].decode("latin-1").strip()

    tags = dict(tag(i) for i in range(2))  # Version, TagCount
    tags.update(tag(2 + i) for i in range(int(tags.get("TagCount", 0))))
    nx, ny = int(tags["Cols"]), int(tags["Rows"])
    off = int(tags["DepthImageOffset"])
    stride = nx
    tex = int(tags.get("TextureImageOffset", 0) or 0)
    padded = (nx + 7) // 8 * 8
    if tex > off and tex - off == padded * ny * 4:
        stride = padded
    z = np.frombuffer(raw, dtype="<f4", count=stride * ny, offset=off).reshape(ny, stride)[:, :nx]
    bad = ~np.isfinite(z)
    if "InvalidPixelValue" in tags:
        bad |= z == np.float32(float(tags["InvalidPixelValue"]))
    z = np.where(bad, np.nan, z.astype(float))
    return HeightMap(z=z, dx=float(tags["PixelSizeXMeter"]), dy=float(tags["PixelSizeYMeter"]))


def read_scan(path: str, dx: Optional[float] = None, dy: Optional[float] = None, z_scale: float = 1.0) -> HeightMap:
    """X3P, GSF, NPY (scanio), Wyko OPD, Sensofar PLU, Alicona AL3D (here)."""
    ext = os.path.splitext(path)[1].lower()
    if ext == ".opd":
        return _read_opd(path)
    if ext in (".plu", ".apx"):
        return _read_plu(path)
    if ext == ".al3d":
        return _read_al3d(path)
    if ext == ".npy":
        if dx is None:
            raise ValueError(f"{path}: NPY carries no spacing; give --dx")
        from .scanio import read_npy
        return read_npy(path, dx, dy, z_scale=z_scale)
    return _scanio_read(path, dx=dx, z_scale=z_scale)


# ---------------------------------------------------------------------------------------------------------
# Command line


def _floats(text: str) -> List[float]:
    return [float(v) for v in text.split(",") if v.strip()]


def run(path, wavelengths_nm, incidences_deg, azimuth_deg=0.0, coherence_m=None, form="plane", dx=None, dy=None,
        z_scale=1.0, level_ratio=DEFAULT_LEVEL_RATIO, grid_n=None):
    """Read, remove the form, compute: ``(document, grid or None, Diffraction)``."""
    hm = read_scan(path, dx=dx, dy=dy, z_scale=z_scale)
    if form == "plane":
        hm = remove_plane(hm)
    elif form != "none":
        raise ValueError(f"form '{form}' is not none or plane")
    d = diffraction(hm.z, hm.dx, hm.dy, wavelengths_nm, incidences_deg, azimuth_deg, coherence_m, level_ratio)
    doc = {
        "records": records(d),
        "patches": {"coherence_m": d.coherence_m, "samples": [d.px, d.py], "used": d.used, "skipped": d.skipped,
                    "tilt_rms_deg": d.tilt_rms_deg},
        "levels": len(d.ladder),
    }
    g = grid(d, grid_n) if grid_n else None
    return doc, g, d


def _write_atomic(path: str, data: bytes) -> None:
    tmp = f"{path}.tmp{os.getpid()}"
    with open(tmp, "wb") as fh:
        fh.write(data)
    os.replace(tmp, path)


def main(argv: Optional[Sequence[str]] = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m ndfitpy.wave", description=__doc__.split("\n\n")[0])
    ap.add_argument("scan")
    ap.add_argument("--wavelength", default="450,550,650", help="nm, comma-separated")
    ap.add_argument("--incidence", default="0,30,45,60,75", help="degrees, comma-separated")
    ap.add_argument("--azimuth", type=float, default=0.0)
    ap.add_argument("--coherence", type=float, default=None, help="patch side in micrometres")
    ap.add_argument("--form", choices=["none", "plane"], default="plane")
    ap.add_argument("--dx", type=float, default=None, help="spacing along x (m), for .npy")
    ap.add_argument("--dy", type=float, default=None, help="spacing along y (m), default --dx")
    ap.add_argument("--z-scale", type=float, default=1.0, help="metres per stored unit, for .npy")
    ap.add_argument("--level-ratio", type=float, default=DEFAULT_LEVEL_RATIO)
    ap.add_argument("--grid", type=int, default=64)
    ap.add_argument("--grid-out", default=None, help="write PREFIX.npy")
    ap.add_argument("-o", "--out", default=None)
    a = ap.parse_args(argv)
    try:
        doc, g, _ = run(a.scan, _floats(a.wavelength), _floats(a.incidence), a.azimuth,
                        None if a.coherence is None else a.coherence * 1e-6, a.form, a.dx, a.dy, a.z_scale,
                        a.level_ratio, a.grid if a.grid_out else None)
    except (ValueError, OSError) as e:
        print(f"ndfitpy.wave: {e}", file=sys.stderr)
        return 2
    text = json.dumps(doc, indent=1) + "\n"
    if a.out:
        _write_atomic(a.out, text.encode())
    else:
        sys.stdout.write(text)
    if g is not None:
        import io
        buf = io.BytesIO()
        np.save(buf, g)
        _write_atomic(a.grid_out + ".npy", buf.getvalue())
    return 0


if __name__ == "__main__":
    sys.exit(main())
