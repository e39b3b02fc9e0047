"""Scan readers of the end-to-end cross-check, written from the formats' own layouts, not from ndfit's code.

- X3P: ``x3p.read_x3p`` (ISO 25178-72);
- NPY: numpy's own ``np.load`` (raw format: spacing and height unit come from the caller, like ndfit's ``--dx``
  and ``--z-scale``);
- GSF (Gwyddion Simple Field 1.0): the magic line, ``Key = Value`` lines (``XRes``, ``YRes`` required; ``XReal``,
  ``YReal`` default 1), NUL padding to a multiple of 4 bytes, then float32 little-endian heights, x fastest.
  ``write_gsf`` writes that layout so both pipelines can read the same GSF file.

Every reader returns a ``HeightMap`` (heights in metres, row along y, NaN for invalid points) or raises
ValueError('<path>: <problem>').
"""

from __future__ import annotations

import os
from typing import Optional

import numpy as np

from .x3p import HeightMap, read_x3p

GSF_MAGIC = b"Gwyddion Simple Field 1.0\n"


def read_npy(path: str, dx: float, dy: Optional[float] = None, z_scale: float = 1.0) -> HeightMap:
    """A 2-D NPY array of heights (stored units x ``z_scale`` = metres); NaN marks invalid points."""
    try:
        a = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as e:
        raise ValueError(f"{path}: not a readable NPY file: {e}") from None
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if a.ndim != 2 or a.shape[0] < 1 or a.shape[1] < 1:
        raise ValueError(f"{path}: expected a 2-D height array, found shape {a.shape}")
    z = a.astype(float) * z_scale
    return HeightMap(z=np.where(np.isfinite(z), z, np.nan), dx=float(dx), dy=float(dx if dy is None else dy))


def read_gsf(path: str) -> HeightMap:
    """A Gwyddion Simple Field file."""
    with open(path, "rb") as fh:
        raw = fh.read()
    if not raw.startswith(GSF_MAGIC):
        raise ValueError(f"{path}: not a Gwyddion Simple Field (no '{GSF_MAGIC.decode().strip()}' line)")
    end = raw.find(b"\0", len(GSF_MAGIC))
    if end < 0:
        raise ValueError(f"{path}: header is not terminated by NUL padding")
    head = {}
    for line in raw[len(GSF_MAGIC):end].decode("utf-8", "replace").splitlines():
        if "=" in line:
            k, v = line.split("=", 1)
            head[k.strip()] = v.strip()
    try:
        nx, ny = int(head["XRes"]), int(head["YRes"])
        x_real, y_real = float(head.get("XReal", 1.0)), float(head.get("YReal", 1.0))
    except (KeyError, ValueError) as e:
        raise ValueError(f"{path}: header lacks a valid {e}") from None
    start = end + (4 - end % 4)  # at least one NUL, up to the next multiple of 4
    need = nx * ny * 4
    if nx < 1 or ny < 1 or len(raw) - start < need:
        raise ValueError(f"{path}: {nx} x {ny} float32 need {need} bytes, {max(len(raw) - start, 0)} present")
    z = np.frombuffer(raw[start:start + need], dtype="<f4").astype(float).reshape(ny, nx)
    return HeightMap(z=np.where(np.isfinite(z), z, np.nan), dx=x_real / nx, dy=y_real / ny)


def write_gsf(path: str, hm: HeightMap) -> None:
    """Write ``hm`` as GSF (float32 heights in metres); atomic (temporary file + rename)."""
    ny, nx = hm.z.shape
    head = GSF_MAGIC + (f"XRes = {nx}\nYRes = {ny}\nXReal = {hm.dx * nx!r}\nYReal = {hm.dy * ny!r}\n"
                        "XYUnits = m\nZUnits = m\n").encode()
    head += b"\0" * (4 - len(head) % 4)
    tmp = f"{path}.tmp{os.getpid()}"
    with open(tmp, "wb") as fh:
        fh.write(head)
        fh.write(hm.z.astype("<f4").tobytes())
    os.replace(tmp, path)


def read_scan(path: str, dx: Optional[float] = None, z_scale: float = 1.0) -> HeightMap:
    """Dispatch on the extension: .x3p, .gsf, .npy (the latter needs ``dx``)."""
    ext = os.path.splitext(path)[1].lower()
    if ext == ".x3p":
        return read_x3p(path)
    if ext == ".gsf":
        return read_gsf(path)
    if ext == ".npy":
        if dx is None:
            raise ValueError(f"{path}: NPY carries no spacing; give dx")
        return read_npy(path, dx, z_scale=z_scale)
    raise ValueError(f"{path}: extension '{ext}' is not one the independent readers handle (.x3p, .gsf, .npy)")
