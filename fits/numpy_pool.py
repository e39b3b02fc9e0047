#!/usr/bin/env python3
"""numpy + nlopt over many X3P scans in a process pool: the batch a user would otherwise write.

Each worker reads an X3P with ``zipfile`` + ``numpy`` (``main.xml`` for the grid, spacing and Z type,
``bindata/data.bin`` inflated by Python's zlib), then runs ``numpy_pipeline.py``'s gradient, histogram and
nlopt ellipsoid fit. ``ndfit bench --process --numpy PYTHON`` times this as a whole process beside
``ndfit batch --jobs N`` on the same files (docs/PERFORMANCE.md).

Usage: numpy_pool.py --jobs N SCAN.x3p...
Prints one JSON object: scans fitted, and the first scan's parameters.
"""

import argparse
import json
import multiprocessing
import os
import re
import sys
import zipfile

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import numpy_pipeline as pipe  # noqa: E402

DTYPES = {"D": "<f8", "F": "<f4", "L": "<i4", "I": "<i2"}


def tag(xml, path):
    """Text of the first element along ``path`` (tag names, namespaces ignored)."""
    pat = "".join(r"<(?:\w+:)?%s\b[^>]*>.*?" % p for p in path[:-1])
    m = re.search(pat + r"<(?:\w+:)?%s\b[^>]*>([^<]*)<" % path[-1], xml, re.S)
    return m.group(1).strip() if m else None


def read_x3p(path):
    with zipfile.ZipFile(path) as z:
        xml = z.read("main.xml").decode("utf-8")
        nx = int(tag(xml, ["MatrixDimension", "SizeX"]))
        ny = int(tag(xml, ["MatrixDimension", "SizeY"]))
        dx = float(tag(xml, ["CX", "Increment"]))
        zt = tag(xml, ["CZ", "DataType"])
        inc = float(tag(xml, ["CZ", "Increment"]) or 1.0)
        off = float(tag(xml, ["CZ", "Offset"]) or 0.0)
        h = np.frombuffer(z.read("bindata/data.bin"), dtype=DTYPES[zt]).astype(np.float64).reshape(ny, nx)
    if inc != 1.0 or off != 0.0:
        h = off + inc * h
    return h, dx


def one(path):
    h, dx = read_x3p(path)
    sx, sy = pipe.slopes(h, dx)
    c, m, w, n = pipe.histogram(sx, sy, 128)
    params, f, evals = pipe.fit(c, m, w, n, sx, sy)
    return params


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scans", nargs="+")
    ap.add_argument("--jobs", type=int, default=2)
    a = ap.parse_args()
    if a.jobs <= 1:
        fits = [one(p) for p in a.scans]
    else:
        with multiprocessing.Pool(a.jobs) as pool:
            fits = pool.map(one, a.scans, chunksize=1)
    json.dump({"scans": len(fits), "first": fits[0]}, sys.stdout)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
