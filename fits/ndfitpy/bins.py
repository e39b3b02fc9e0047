"""Empirical NDF bins: the CSV that ``ndfit ndf`` writes (data_formats/ndf_csv.md), read with the stdlib and numpy.

Columns are selected by name; further columns are ignored. Every problem is a ValueError naming the file.
"""

from __future__ import annotations

import csv
import math
import os
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from .rounding import Rounding

REQUIRED = ("mx", "my", "mz", "d")
#: The columns the fit needs besides the contract's four (data_formats/ndf_csv.md).
FIT_COLUMNS = ("count", "proj_solid_angle")


@dataclass
class Bins:
    """An empirical NDF: one entry per bin (data_formats/ndf_csv.md)."""

    m: np.ndarray  #: (K, 3) central directions, unit vectors, n = +z
    count: np.ndarray  #: (K,) samples in the bin
    proj_solid_angle: np.ndarray  #: (K,) integral of m.n over the bin (sr)
    d: Optional[np.ndarray] = None  #: (K,) empirical D as written by ndfit (1/sr)
    solid_angle: Optional[np.ndarray] = None  #: (K,) solid angle (sr), when known
    path: str = "<memory>"
    extra: dict = field(default_factory=dict)
    n_total: Optional[float] = None  #: N when some counted rows were dropped (used()); else the sum of counts
    rounding: Optional[Rounding] = None  #: the height rounding of a quantized scan, which the model carries

    @property
    def n_samples(self) -> float:
        """N = sum of counts over every row of the file (every valid sample falls in exactly one bin)."""
        return float(self.count.sum()) if self.n_total is None else float(self.n_total)

    def __len__(self) -> int:
        return int(self.m.shape[0])

    def used(self) -> "Bins":
        """The bins with W_k > 0 (data_formats/objective.md leaves the others out)."""
        return self.subset(self.proj_solid_angle > 0.0)

    def subset(self, keep) -> "Bins":
        """The bins selected by the boolean mask ``keep``; ``n_total`` stays the whole NDF's count."""
        return Bins(
            m=self.m[keep],
            count=self.count[keep],
            proj_solid_angle=self.proj_solid_angle[keep],
            d=None if self.d is None else self.d[keep],
            solid_angle=None if self.solid_angle is None else self.solid_angle[keep],
            path=self.path,
            n_total=self.n_samples,
            rounding=self.rounding,
        )


def _parse_float(text: str, path: str, line: int, col: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"{path}: line {line}: column '{col}' is not a number: '{text}'") from None


def _unresolved(values, count, path):
    """The ``unresolved`` column as an array, or None when absent or not assessed (empty fields)."""
    if not values:
        return None
    u = np.asarray(values, dtype=float)
    if np.all(np.isnan(u)):
        return None
    bad = np.flatnonzero(~np.isfinite(u) | (u < 0) | (u > count) | (u != np.round(u)))
    if bad.size:
        raise ValueError(f"{path}: line {int(bad[0]) + 2}: unresolved must be an integer between 0 and count")
    return u


def read_ndf_csv(path: str) -> Bins:
    """Read an empirical NDF CSV; raise ValueError('<path>: <problem>') on anything malformed."""
    path = os.fspath(path)
    try:
        fh = open(path, newline="", encoding="utf-8")
    except OSError as e:
        raise ValueError(f"{path}: cannot open: {e.strerror or e}") from None
    with fh:
        reader = csv.reader(fh)
        try:
            header = next(reader)
        except StopIteration:
            raise ValueError(f"{path}: empty file, expected a header row with {','.join(REQUIRED)}") from None
        except (csv.Error, UnicodeDecodeError) as e:
            raise ValueError(f"{path}: not a CSV file: {e}") from None
        header = [h.strip() for h in header]
        missing = [c for c in REQUIRED + FIT_COLUMNS if c not in header]
        if missing:
            raise ValueError(f"{path}: header lacks column(s) {', '.join(missing)} (have: {','.join(header)})")
        want = list(REQUIRED + FIT_COLUMNS) + [c for c in ("solid_angle", "stderr") if c in header]
        idx = {c: header.index(c) for c in want}
        cols = {c: [] for c in want}
        # Optional: the unresolved normals per bin (empty fields when ndfit did not assess them).
        iu = header.index("unresolved") if "unresolved" in header else None
        unresolved = []
        try:
            for lineno, row in enumerate(reader, start=2):
                if not row or all(not x.strip() for x in row):
                    continue
                if len(row) < len(header):
                    raise ValueError(f"{path}: line {lineno}: {len(row)} fields, header has {len(header)}")
                for c, i in idx.items():
                    cols[c].append(_parse_float(row[i].strip(), path, lineno, c))
                if iu is not None:
                    t = row[iu].strip()
                    unresolved.append(_parse_float(t, path, lineno, "unresolved") if t else float("nan"))
        except (csv.Error, UnicodeDecodeError) as e:
            raise ValueError(f"{path}: not a CSV file: {e}") from None
    if not cols["mx"]:
        raise ValueError(f"{path}: no bins (only a header)")
    arr = {c: np.asarray(v, dtype=float) for c, v in cols.items()}
    for c in ("count", "proj_solid_angle"):
        bad = np.flatnonzero(~np.isfinite(arr[c]))
        if bad.size:
            raise ValueError(f"{path}: line {int(bad[0]) + 2}: column '{c}' is not finite")
    # Rows with W = 0 take no part (objective.md), so only their count matters; the others must be complete.
    live = arr["proj_solid_angle"] > 0
    for c in ("mx", "my", "mz", "d"):
        bad = np.flatnonzero(live & ~np.isfinite(arr[c]))
        if bad.size:
            raise ValueError(f"{path}: line {int(bad[0]) + 2}: column '{c}' is not finite")
    m = np.column_stack([arr["mx"], arr["my"], arr["mz"]])
    m[~live] = np.where(np.isfinite(m[~live]), m[~live], 0.0)
    norms = np.linalg.norm(m, axis=1)
    bad = np.flatnonzero(live & (np.abs(norms - 1.0) > 1e-6))
    if bad.size:
        raise ValueError(f"{path}: line {int(bad[0]) + 2}: (mx,my,mz) is not a unit vector (norm {norms[bad[0]]:.9g})")
    count = arr["count"]
    bad = np.flatnonzero((count < 0) | (count != np.round(count)))
    if bad.size:
        raise ValueError(f"{path}: line {int(bad[0]) + 2}: count must be a non-negative integer, got {count[bad[0]]}")
    w = arr["proj_solid_angle"]
    bad = np.flatnonzero(w < 0)
    if bad.size:
        raise ValueError(f"{path}: line {int(bad[0]) + 2}: proj_solid_angle is negative")
    if count.sum() <= 0:
        raise ValueError(f"{path}: every bin is empty (no valid samples)")
    total_w = float(w.sum())
    # The bins tile (at most) the hemisphere, whose projected solid angle is pi: more means a broken file.
    if not (0.0 < total_w <= 1.01 * math.pi):
        raise ValueError(f"{path}: proj_solid_angle sums to {total_w:.6g} sr; bins tiling the hemisphere sum to pi")
    return Bins(
        m=m,
        count=count,
        proj_solid_angle=w,
        d=arr["d"],
        solid_angle=arr.get("solid_angle"),
        path=path,
        extra={"stderr": arr.get("stderr"), "unresolved": _unresolved(unresolved, count, path)},
    )


def write_ndf_csv(path: str, bins: Bins) -> None:
    """Write bins in the data_formats/ndf_csv.md layout (for tests and examples; ndfit ndf writes the real ones)."""
    n = max(bins.n_samples, 1.0)
    w = bins.proj_solid_angle
    with np.errstate(divide="ignore", invalid="ignore"):
        d = np.where(w > 0, bins.count / (n * w), 0.0)
        se = np.where(w > 0, np.sqrt(np.maximum(bins.count, 1.0)) / (n * w), 0.0)
    om = bins.solid_angle if bins.solid_angle is not None else w
    lines = ["mx,my,mz,d,stderr,count,solid_angle,proj_solid_angle"]
    for k in range(len(bins)):
        mx, my, mz = bins.m[k]
        vals = (mx, my, mz, d[k], se[k])
        lines.append(
            ",".join(f"{float(v):.17g}" for v in vals)
            + f",{int(round(float(bins.count[k])))},{float(om[k]):.17g},{float(w[k]):.17g}"
        )
    with open(path, "w", encoding="utf-8") as fh:
        fh.write("\n".join(lines) + "\n")
