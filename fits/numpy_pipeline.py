#!/usr/bin/env python3
"""The pipeline a user would otherwise write: numpy gradient + histogram + nlopt fit.

This is the reference `ndfit bench --numpy PYTHON` times in the same run as ndfit (docs/PERFORMANCE.md).
It is deliberately what a competent user writes in an afternoon, vectorized throughout, not a straw man:

1. ``np.load`` the float64 NPY height map (NaN = invalid);
2. slopes by ``np.gradient`` (central differences in the interior, the same stencil as ndfit's default);
3. unit normals ``m = (-sx, -sy, 1) / |.|`` and ``np.histogram2d`` of ``(m_x, m_y)`` over the unit disk.
   In these coordinates the projected solid angle of a bin is its area on the disk (orthographic
   projection: ``(m.n) dw = dm_x dm_y``), so ``D_k = c_k / (N W_k)`` with ``W_k`` = bin area (bins whose
   centre is outside the disk are dropped; the midpoint rule otherwise);
4. the Ellipsoid NDF of Walter et al. (eq. 1-3): ``D(m) = 1 / (pi |A| |A n| |A^-T m|^4)`` with
   ``A = S R``, fitted by minimizing the Poisson deviance of data_formats/objective.md with nlopt's
   derivative-free BOBYQA (``LN_BOBYQA``), alphas in log space, from the moment estimate of the slopes.

Usage: numpy_pipeline.py SCAN.npy --dx METRES [--fit] [--bins N] [--repeat R]
Prints one JSON object: median stage times (ms), counts, the fitted parameters, versions.
"""

import argparse
import json
import math
import sys
import time

import numpy as np


def load(path):
    return np.load(path)


def slopes(h, dx):
    gy, gx = np.gradient(h, dx)
    # np.gradient uses one-sided differences on the border; drop the border like ndfit's central stencil.
    sx = gx[1:-1, 1:-1].ravel()
    sy = gy[1:-1, 1:-1].ravel()
    ok = np.isfinite(sx) & np.isfinite(sy) & np.isfinite(h[1:-1, 1:-1].ravel())
    return sx[ok], sy[ok]


def histogram(sx, sy, bins):
    inv = 1.0 / np.sqrt(1.0 + sx * sx + sy * sy)
    mx = -sx * inv
    my = -sy * inv
    counts, xe, ye = np.histogram2d(mx, my, bins=bins, range=[[-1.0, 1.0], [-1.0, 1.0]])
    xc = 0.5 * (xe[:-1] + xe[1:])
    yc = 0.5 * (ye[:-1] + ye[1:])
    X, Y = np.meshgrid(xc, yc, indexing="ij")
    r2 = X * X + Y * Y
    inside = r2 < 1.0
    area = (xe[1] - xe[0]) * (ye[1] - ye[0])
    c = counts[inside]
    m = np.stack([X[inside], Y[inside], np.sqrt(1.0 - r2[inside])], axis=1)
    w = np.full(c.shape, area)
    return c, m, w, mx.size


def rotation(tx, ty, tz):
    cx, sx = math.cos(tx), math.sin(tx)
    cy, sy = math.cos(ty), math.sin(ty)
    cz, sz = math.cos(tz), math.sin(tz)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return rx @ ry @ rz


def ellipsoid_d(p, m):
    ax, ay, tx, ty, tz = p
    r = rotation(tx, ty, tz)
    a = np.diag([ax, ay, 1.0]) @ r
    a_inv_t = np.diag([1.0 / ax, 1.0 / ay, 1.0]) @ r
    an = np.linalg.norm(a[:, 2])
    q = np.sum((m @ a_inv_t.T) ** 2, axis=1)
    return 1.0 / (math.pi * ax * ay * an * q * q)


def fit(c, m, w, n, sx, sy):
    import nlopt

    def deviance(x, grad):
        p = (math.exp(x[0]), math.exp(x[1]), x[2], x[3], x[4])
        e = n * ellipsoid_d(p, m) * w
        e = np.maximum(e, 1e-300)
        t = np.where(c > 0, c * np.log(np.where(c > 0, c, 1.0) / e), 0.0)
        return float(np.sum(2.0 * (e - c + t)))

    # Start: RMS slopes (alpha ~ sqrt(2) sigma for Beckmann-like lobes), no skew, no rotation.
    x0 = [math.log(max(math.sqrt(2.0 * np.var(sx)), 1e-3)), math.log(max(math.sqrt(2.0 * np.var(sy)), 1e-3)), 0.0, 0.0, 0.0]
    opt = nlopt.opt(nlopt.LN_BOBYQA, 5)
    opt.set_min_objective(deviance)
    opt.set_lower_bounds([math.log(1e-4), math.log(1e-4), -1.5, -1.5, -math.pi])
    opt.set_upper_bounds([math.log(10.0), math.log(10.0), 1.5, 1.5, math.pi])
    opt.set_xtol_rel(1e-8)
    opt.set_ftol_rel(1e-10)
    opt.set_maxeval(20000)
    x = opt.optimize(x0)
    return {
        "alpha_x": math.exp(x[0]),
        "alpha_y": math.exp(x[1]),
        "theta_x": x[2],
        "theta_y": x[3],
        "theta_z": x[4],
    }, opt.last_optimum_value(), opt.get_numevals()


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("scan")
    ap.add_argument("--dx", type=float, required=True)
    ap.add_argument("--fit", action="store_true")
    ap.add_argument("--bins", type=int, default=128)
    ap.add_argument("--repeat", type=int, default=1)
    a = ap.parse_args()
    stages = {"load": [], "gradient": [], "histogram": [], "fit": []}
    out = {}
    for _ in range(max(1, a.repeat)):
        t = time.perf_counter()
        h = load(a.scan)
        t1 = time.perf_counter()
        sx, sy = slopes(h, a.dx)
        t2 = time.perf_counter()
        c, m, w, n = histogram(sx, sy, a.bins)
        t3 = time.perf_counter()
        stages["load"].append(t1 - t)
        stages["gradient"].append(t2 - t1)
        stages["histogram"].append(t3 - t2)
        out["samples"] = int(n)
        out["bins"] = int(c.size)
        if a.fit:
            t4 = time.perf_counter()
            params, f, evals = fit(c, m, w, n, sx, sy)
            stages["fit"].append(time.perf_counter() - t4)
            out["params"] = params
            out["objective"] = f
            out["evaluations"] = evals
        del h, sx, sy
    med = {k: 1e3 * float(np.median(v)) for k, v in stages.items() if v}
    out["t_load_ms"] = med["load"]
    out["t_gradient_ms"] = med["gradient"]
    out["t_histogram_ms"] = med["histogram"]
    out["t_fit_ms"] = med.get("fit", 0.0)
    out["t_ndf_ms"] = med["load"] + med["gradient"] + med["histogram"]
    out["t_total_ms"] = out["t_ndf_ms"] + out["t_fit_ms"]
    out["repeat"] = max(1, a.repeat)
    out["numpy"] = np.__version__
    try:
        import nlopt

        out["nlopt"] = nlopt.__version__
    except Exception:  # noqa: BLE001 - the NDF part runs without nlopt
        out["nlopt"] = None
    out["python"] = sys.version.split()[0]
    json.dump(out, sys.stdout)
    sys.stdout.write("\n")


if __name__ == "__main__":
    main()
