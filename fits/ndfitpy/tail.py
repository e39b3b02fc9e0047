"""The unresolved-tail cut of the fit region (data_formats/objective.md, "The tail the scan cannot resolve").

Implemented from that text, on the CSV's ``unresolved`` column: the bins where over half of the normals are
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
    cut = Bins(
        m=bins.m[keep],
        count=c[keep],
        proj_solid_angle=bins.proj_solid_angle[keep],
        d=None if bins.d is None else bins.d[keep],
        solid_angle=None if bins.solid_angle is None else bins.solid_angle[keep],
        path=bins.path,
        n_total=bins.n_samples,
    )
    return cut, TailInfo("unresolved", share, int(out.sum()), float(c[out].sum()))
