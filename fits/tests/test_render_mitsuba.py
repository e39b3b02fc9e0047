"""`ndfit render` against Mitsuba 3 rendering the same RGL table (`measured`) in the same scene: the unit
sphere (Mitsuba's `sphere`, identity transform, so the same tangent frame), an orthographic camera from
`-y` with `+z` up, a box pixel filter, a directional light, direct lighting only.

Runs the ndfit binary (`NDFIT` or target/release/ndfit); skips only when that binary is absent.
"""

import math
import os
import subprocess

import numpy as np
import pytest

import mitsuba as mi

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
NDFIT = os.environ.get("NDFIT", os.path.join(ROOT, "target", "release", "ndfit"))
NDFIT = NDFIT if os.path.isabs(NDFIT) else os.path.join(ROOT, NDFIT)

pytestmark = pytest.mark.skipif(
    not os.access(NDFIT, os.X_OK), reason=f"SKIP: no ndfit binary at {NDFIT} (cargo build --release, or set NDFIT)"
)

mi.set_variant("scalar_rgb")

FIT = '{"model": "ggx-aniso", "params": {"alpha_x": 0.3, "alpha_y": 0.12, "theta_z": 0.5}}'
SIZE = 48
EXTENT = 1.05


def ndfit(*args):
    p = subprocess.run([NDFIT, *map(str, args)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return p.stdout, p.stderr


def direction(theta_deg, phi_deg):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return [math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)]


def mitsuba_render(bsdf_path, light, spp, bsdf_samples):
    """ndfit's sphere scene in Mitsuba (orthographic camera from -y, +z up, direct light only) with the
    emitter `light`, the sphere's BSDF the table at `bsdf_path`."""
    emitter = {"type": "sphere", "center": [dist * c for c in light], "radius": dist * math.sin(delta),
               "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 1 / math.sin(delta) ** 2}}}
    b = mitsuba_render(table, emitter, spp, bsdf_samples=1)
    lum_a, lum_b = a.sum(-1), b.sum(-1)
    yy, xx = np.mgrid[0:SIZE, 0:SIZE]
    r = np.hypot((xx + 0.5) / SIZE * 2 * EXTENT - EXTENT, (yy + 0.5) / SIZE * 2 * EXTENT - EXTENT)
    lit = (lum_a > 0.05 * lum_a.max()) & (r < 0.95)
    rel = np.abs(lum_a[lit] - lum_b[lit]) / lum_b[lit]
    med, p90 = np.median(rel), np.percentile(rel, 90)
    print(f"broad scene: {lit.sum()} lit pixels, median {med:.2e}, 90th percentile {p90:.2e}")
    assert med < 0.01 and p90 < 0.03, (med, p90)
