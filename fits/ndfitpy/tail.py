"""The tail cuts of the fit region (data_formats/objective.md, "The tail the scan cannot resolve").

Implemented from that text, on the CSV's ``unresolved`` column and the binning frame of the NDF's JSON. The
default ``rim`` rule (cut_rim) is the ``core`` cut for a lone lobe's unresolved rim and the ``unresolved`` cut
where another lobe's resolved normals fill the rim's bins; ``--tail core`` (cut_core) keeps the whitened
core |p| <= 1 when the sampling leaves an unresolved tail;
``--tail unresolved`` (cut_unresolved) leaves out the bins where over half of the normals are
unresolved (``2 u_k > c_k``) leave the region, unless over a quarter of all normals are unresolved (a surface
rough at the sampling step: nothing is cut). The model is then normalized over the bins that remain, which
is what fitting the remaining bins does (objective.py normalizes over the bins it is given).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .bins import Bins

#: Largest share of all normals unresolved for which the cut applies (objective.md, "Guard").
MAX_UNRESOLVED_SHARE = 0.25


@dataclass
class TailInfo:
    rule: str  #: "unresolved", "none" or "none (rough at the sampling step)"
    unresolved_fraction: float  #: unresolved normals / all normals
    bins_excluded: int  #: bins left out (every bin, not only those within max_theta)
    n_excluded: float  #: normals in them


def cut_unresolved(bins: Bins) -> tuple:
    """(bins without the unresolved ones, TailInfo). Bins without an ``unresolved`` column are returned as they are."""
    u = bins.extra.get("unresolved")
    if u is None:
        return bins, TailInfo("none", 0.0, 0, 0.0)
    c = bins.count
    share = float(u.sum()) / max(float(c.sum()), 1.0)
    if not share <= MAX_UNRESOLVED_SHARE:
        return bins, TailInfo("none (rough at the sampling step)", share, 0, 0.0)
    out = 2.0 * u > c
    keep = ~out
    cut = bins.subset(keep)
    return cut, TailInfo("unresolved", share, int(out.sum()), float(c[out].sum()))


#: The core rule (objective.md, "The tail the scan cannot resolve"): Lambert radius of the whitened core kept.
CORE_RADIUS = 1.0
#: Share of the region's normals in unresolved bins from which the core rule applies.
MIN_TAIL_SHARE = 0.005


def whitened_lambert_radius(m: np.ndarray, frame: dict) -> np.ndarray:
    """|p| of each direction (rows of ``m``) in the binning frame: the slope s = -m_xy / m_z, whitened
    s' = W (s - c), and the Lambert map of the stretched normal m' = (-s', 1) / sqrt(1 + |s'|^2),
    p = sqrt(2 / (1 + m'_z)) m'_xy, so |p| = sqrt(2 (1 - m'_z))."""
    s = -m[:, :2] / m[:, 2:3]
    w = np.asarray(frame["whiten"], dtype=float)
    c = np.asarray(frame["center"], dtype=float)
    sw = (s - c) @ w.T
    mz = 1.0 / np.sqrt(1.0 + (sw * sw).sum(axis=1))
    return np.sqrt(2.0 * (1.0 - mz))


def cut_core(bins: Bins, frame: dict, max_theta_deg: float = 70.0) -> tuple:
    """The ``core`` rule: when at least MIN_TAIL_SHARE of the normals within max_theta lie in bins where most
    normals are unresolved (and the scan is smooth at the sampling step), keep only the bins within
    CORE_RADIUS of the whitened frame's centre. Returns (bins, TailInfo)."""
    u = bins.extra.get("unresolved")
    if u is None:
        return bins, TailInfo("none", 0.0, 0, 0.0)
    c = bins.count
    share = float(u.sum()) / max(float(c.sum()), 1.0)
    if not share <= MAX_UNRESOLVED_SHARE:
        return bins, TailInfo("none (rough at the sampling step)", share, 0, 0.0)
    m = bins.m / np.linalg.norm(bins.m, axis=1, keepdims=True)
    inside = (m[:, 2] >= np.cos(np.radians(max_theta_deg))) & (bins.proj_solid_angle > 0)
    n_in = float(c[inside].sum())
    tail = float(c[inside & (2.0 * u > c)].sum()) / max(n_in, 1.0)
    if tail < MIN_TAIL_SHARE:
        return bins, TailInfo("none (tail resolved)", share, 0, 0.0)
    out = ~(whitened_lambert_radius(m, frame) <= CORE_RADIUS)
    keep = ~out
    cut = bins.subset(keep)
    return cut, TailInfo("core", share, int((out & inside).sum()), float(c[out & inside].sum()))


#: Share of the region's unresolved normals in bins they dominate from which the rim rule cuts the core.
MIN_ALONE_SHARE = 0.5


def cut_rim(bins: Bins, frame: dict, max_theta_deg: float = 70.0) -> tuple:
    """The default rule: with at least MIN_TAIL_SHARE of the normals within max_theta in majority-unresolved
    bins (and the scan smooth at the sampling step), the core cut (cut_core) when at least MIN_ALONE_SHARE of
    the unresolved normals within max_theta lie in such bins (a lone lobe's rim), else the unresolved cut
    (cut_unresolved: another lobe's resolved normals fill the rim's bins). Returns (bins, TailInfo) with the
    cut applied as the rule."""
    u = bins.extra.get("unresolved")
    if u is None:
        return bins, TailInfo("none", 0.0, 0, 0.0)
    c = bins.count
    share = float(u.sum()) / max(float(c.sum()), 1.0)
    if not share <= MAX_UNRESOLVED_SHARE:
        return bins, TailInfo("none (rough at the sampling step)", share, 0, 0.0)
    m = bins.m / np.linalg.norm(bins.m, axis=1, keepdims=True)
    inside = (m[:, 2] >= np.cos(np.radians(max_theta_deg))) & (bins.proj_solid_angle > 0)
    major = 2.0 * u > c
    tail = float(c[inside & major].sum()) / max(float(c[inside].sum()), 1.0)
    if tail < MIN_TAIL_SHARE:
        return bins, TailInfo("none (tail resolved)", share, 0, 0.0)
    u_in = float(u[inside].sum())
    alone = float(u[inside & major].sum()) / u_in if u_in > 0 else 0.0
    if alone >= MIN_ALONE_SHARE:
        return cut_core(bins, frame, max_theta_deg)
    keep = ~major
    return bins.subset(keep), TailInfo("unresolved", share, int((major & inside).sum()), float(c[major & inside].sum()))
