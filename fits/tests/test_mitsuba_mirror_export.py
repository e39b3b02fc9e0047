"""`ndfit export --to mitsuba` of a mirror answer, loaded by the real Mitsuba 3 (PyPI wheel, scalar_rgb).

The fit document is written here with the mirror shares of Gaussian heights, `s = exp(-(2 k sigma cos t)^2)`.
The snippet (a `blendbsdf` of a `conductor` and the haze's `roughconductor`) must load as it is; off the
mirror direction it must evaluate to `weight` times the haze's `roughconductor` alone (the delta
contributes nothing there), and a share `1 - weight` of its samples must be the delta reflection, with
`weight` the cosine-weighted hemispherical mean of `1 - s` at 550 nm computed here by quadrature. A mirror
alone loads as a `conductor` whose every sample is the delta. Runs the ndfit binary (`NDFIT` or
target/release/ndfit); skips only when that binary is absent.
"""

import json
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

SIGMA = 40e-9
ALPHA = 0.05


def share(theta_deg, lam_nm):
    k = 2.0 * math.pi / (lam_nm * 1e-9)
    return math.exp(-((2.0 * k * SIGMA * math.cos(math.radians(theta_deg))) ** 2))


def fit_doc(answer):
    spec = [{"theta_deg": t, "wavelength_nm": l, "weight": share(t, l)} for l in (450.0, 550.0, 650.0) for t in (0.0, 30.0, 45.0, 60.0, 75.0)]
    optics = {"regime": "wave", "wavelength_nm": [450.0, 550.0, 650.0], "coherence_m": 1.8925e-05, "specular": spec}
    if answer != "mirror":
        optics["haze"] = {"model": "ggx", "params": {"alpha": ALPHA}}
    return {"schema": "ndfit.fit/1", "model": "ggx", "params": {"alpha": 0.3}, "selection": {"answer": answer}, "optics": optics}


def export(tmp_path, answer):
    path = tmp_path / "m.json"
    path.write_text(json.dumps(fit_doc(answer)))
    p = subprocess.run([NDFIT, "export", path, "--to", "mitsuba"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    # The snippet's root element, with the scene-format version Mitsuba asks of a document's root.
    return mi.load_string(p.stdout.replace("<bsdf type=", '<bsdf version="3.0.0" type=', 1))


def mean_haze(lam_nm, n=100000):
    t = (np.arange(n) + 0.5) * (0.5 * math.pi / n)
    k = 2.0 * math.pi / (lam_nm * 1e-9)
    s = np.exp(-((2.0 * k * SIGMA * np.cos(t)) ** 2))
    return float(np.sum((1.0 - s) * 2.0 * np.cos(t) * np.sin(t)) * (0.5 * math.pi / n))


def interaction(theta_deg):
    si = mi.SurfaceInteraction3f()
    si.wi = mi.Vector3f(math.sin(math.radians(theta_deg)), 0.0, math.cos(math.radians(theta_deg)))
    return si


def delta_share(bsdf, si, n=400):
    """The share of samples that are the delta reflection, over a regular grid of the lobe choice."""
    ctx = mi.BSDFContext()
    hits = 0
    for i in range(n):
        bs, _ = bsdf.sample(ctx, si, (i + 0.5) / n, mi.Point2f(0.3, 0.6))
        hits += mi.has_flag(bs.sampled_type, mi.BSDFFlags.DeltaReflection)
    return hits / n


def test_mirror_and_haze_load_and_blend(tmp_path):
    bsdf = export(tmp_path, "mirror+ggx")
    weight = mean_haze(550.0)
    haze = mi.load_dict({"type": "roughconductor", "distribution": "ggx", "alpha_u": ALPHA, "alpha_v": ALPHA})
    ctx = mi.BSDFContext()
    for theta in (0.0, 30.0, 60.0):
        si = interaction(theta)
        for off in (2.0, 5.0, 10.0):
            t = math.radians(theta + off)
            wo = mi.Vector3f(-math.sin(t), 0.0, math.cos(t))
            got, want = bsdf.eval(ctx, si, wo)[0], haze.eval(ctx, si, wo)[0]
            assert abs(got - weight * want) <= 1e-5 * weight * want, (theta, off, got, want, weight)
        assert abs(delta_share(bsdf, si) - (1.0 - weight)) <= 1.0 / 400 + 1e-12


def test_mirror_alone_is_a_delta(tmp_path):
    bsdf = export(tmp_path, "mirror")
    assert delta_share(bsdf, interaction(40.0)) == 1.0
