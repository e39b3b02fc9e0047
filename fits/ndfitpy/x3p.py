"""An ISO 25178-72 (X3P) height-map reader (stdlib zipfile/xml + numpy), written from the standard's layout.

Reads the main.xml grid description (namespace-agnostic, main.xml possibly in a sub-folder) and the point data:
a binary ``DataLink`` (Z data types I, L, F, D, little-endian, x varying fastest) or an inline ``DataList`` of
``Datum`` elements. ``z = Offset + Increment * stored`` on CZ. Invalid points become NaN: NaN or infinite values,
empty ``<Datum/>`` entries, and 0 bits of the optional ``ValidPointsLink`` bit array (one bit per point, least
significant bit first). It is the independent reader of the end-to-end cross-check (``endtoend.py``): the shared
X3P scans and ``ndfit synth`` output.
"""

from __future__ import annotations

import posixpath
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass

import numpy as np

_DTYPES = {"I": "<i2", "L": "<i4", "F": "<f4", "D": "<f8"}


@dataclass
class HeightMap:
    """Heights z[row, col] (metres as stored), row along y, column along x, with spacings in metres."""

    z: np.ndarray
    dx: float
    dy: float


def _local(tag: str) -> str:
    return tag.rsplit("}", 1)[-1]


def _find(root, *path):
    node = root
    for name in path:
        nxt = None
        for child in node:
            if _local(child.tag) == name:
                nxt = child
                break
        if nxt is None:
            return None
        node = nxt
    return node


def _text(root, *path, default=None):
    node = _find(root, *path)
    return node.text.strip() if node is not None and node.text and node.text.strip() else default


def read_x3p(path: str) -> HeightMap:
    """Read an X3P file; ValueError('<path>: <problem>') when it is not one this reader handles."""
    try:
        zf = zipfile.ZipFile(path)
    except (OSError, zipfile.BadZipFile) as e:
        raise ValueError(f"{path}: not an X3P (zip) file: {e}") from None
    with zf:
        mains = [n for n in zf.namelist() if posixpath.basename(n) == "main.xml" and not n.startswith("__MACOSX")]
        if not mains:
            raise ValueError(f"{path}: no main.xml in the archive")
        base = posixpath.dirname(mains[0])
        root = ET.fromstring(zf.read(mains[0]))
        nx = int(_text(root, "Record3", "MatrixDimension", "SizeX", default="0"))
        ny = int(_text(root, "Record3", "MatrixDimension", "SizeY", default="0"))
        if nx <= 0 or ny <= 0 or nx * ny > 1 << 28:
            raise ValueError(f"{path}: implausible grid {nx} x {ny}")
        dt = _text(root, "Record1", "Axes", "CZ", "DataType", default="D")
        if dt not in _DTYPES:
            raise ValueError(f"{path}: Z data type {dt!r} not handled")
        inc = float(_text(root, "Record1", "Axes", "CZ", "Increment", default="1") or 1)
        off = float(_text(root, "Record1", "Axes", "CZ", "Offset", default="0") or 0)
        dx = float(_text(root, "Record1", "Axes", "CX", "Increment", default="nan"))
        dy = float(_text(root, "Record1", "Axes", "CY", "Increment", default="nan"))
        link = _text(root, "Record3", "DataLink", "PointDataLink")
        valid_link = _text(root, "Record3", "ValidPointsLink")
        if link is None:
            lst = _find(root, "Record3", "DataList")
            if lst is None:
                raise ValueError(f"{path}: neither a PointDataLink nor a DataList in main.xml")
            vals = [(d.text or "").strip() for d in lst if _local(d.tag) == "Datum"]
            if len(vals) < nx * ny:
                raise ValueError(f"{path}: DataList has {len(vals)} entries, the grid needs {nx * ny}")
            z = np.array([float(v) if v else np.nan for v in vals[: nx * ny]], dtype=float).reshape(ny, nx)
            raw = None
        else:
            raw = zf.read(posixpath.join(base, link))
        valid = zf.read(posixpath.join(base, valid_link)) if valid_link else None
    if raw is not None:
        need = nx * ny * np.dtype(_DTYPES[dt]).itemsize
        if len(raw) < need:
            raise ValueError(f"{path}: point data has {len(raw)} bytes, the grid needs {need}")
        z = np.frombuffer(raw[:need], dtype=_DTYPES[dt]).astype(float).reshape(ny, nx)
    if inc != 1.0 or off != 0.0:
        z = z * inc + off
    z = np.where(np.isfinite(z), z, np.nan)
    if valid is not None:
        bits = np.unpackbits(np.frombuffer(valid, dtype=np.uint8), bitorder="little")
        if bits.size < nx * ny:
            raise ValueError(f"{path}: valid-points bit array has {bits.size} bits, the grid needs {nx * ny}")
        z = np.where(bits[: nx * ny].reshape(ny, nx) == 1, z, np.nan)
    return HeightMap(z=z, dx=dx, dy=dy)
