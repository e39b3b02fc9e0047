"""`ndfit export --to mitsuba --json` against the real Mitsuba 3 (PyPI wheel, scalar_rgb variant).

Mitsuba's own `MicrofacetDistribution(type, alpha_u, alpha_v).eval(m_local)` with the exported parameters,
`m_local` the scan-frame direction expressed in the exported tangent frame (u at azimuth `tangent_angle`
from +x, v = n x u, n = +z), must equal `ndfit eval` of the fit to float32 precision. Runs the ndfit binary
(`NDFIT` or target/release/ndfit); skips only when that binary is absent.
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


def directions(n=600, max_deg=80.0):
    """Golden-angle spiral over the cap theta <= max_deg."""
    i = np.arange(n) + 0.5
    z = 1.0 - i / n * (1.0 - math.cos(math.radians(max_deg)))
    r = np.sqrt(1.0 - z * z)
    p = math.pi * (3.0 - math.sqrt(5.0)) * np.arange(n)
    return np.stack([r * np.cos(p), r * np.sin(p), z], axis=1)


def ndfit(*args, stdin=None):
    p = subprocess.run([NDFIT, *map(str, args)], input=stdin, capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return p.stdout, p.stderr


def ndfit_d(fit_path, m):
    csv = "mx,my,mz\n" + "\n".join(",".join(repr(float(x)) for x in row) for row in m) + "\n"
    out, _ = ndfit("eval", fit_path, stdin=csv)
    lines = out.split()
    assert lines[0] == "d"
    return np.array([float(x) for x in lines[1:]])


def mitsuba_d(exported, m):
    kind = {"ggx": mi.MicrofacetType.GGX, "beckmann": mi.MicrofacetType.Beckmann}[exported["distribution"]]
    dist = mi.MicrofacetDistribution(kind, exported["alpha_u"], exported["alpha_v"])
    t = exported["tangent_angle"]
    u = np.array([math.cos(t), math.sin(t), 0.0])
    v = np.array([-math.sin(t), math.cos(t), 0.0])
    out = []
    for row in m:
        local = mi.Vector3f(float(row @ u), float(row @ v), float(row[2]))
        out.append(float(dist.eval(local)))
    return np.array(out)


CASES = {
    # The example: theta_z = -1.043, the rough axis at +1.043 rad.
    "ggx-aniso": {"model": "ggx-aniso", "params": {"alpha_x": 0.4, "alpha_y": 0.1, "theta_z": -1.043}},
    "ggx": {"model": "ggx", "params": {"alpha": 0.15}},
    "beckmann-aniso": {"model": "beckmann-aniso", "params": {"alpha_x": 0.35, "alpha_y": 0.2, "theta_z": 0.6}},
    "ellipsoid-no-skew": {"model": "ellipsoid", "params": {"alpha_x": 0.25, "alpha_y": 0.08, "theta_x": 0.0, "theta_y": 0.0, "theta_z": 2.5}},
}


@pytest.mark.parametrize("name", sorted(CASES))
def test_mitsuba_eval_equals_ndfit(tmp_path, name):
    fit = tmp_path / f"{name}.json"
    fit.write_text(json.dumps(CASES[name]))
    out, err = ndfit("export", fit, "--to", "mitsuba", "--json")
    exported = json.loads(out)
    assert exported["plugin"] == "roughconductor"
    assert "note" not in exported and err == "", err
    m = directions()
    want = ndfit_d(fit, m)
    got = mitsuba_d(exported, m)
    # Mitsuba returns 0 where D cos(theta) <= 1e-20 (its guard against float32 underflow; Beckmann's far
    # tail): compare above it, and check the cut below it.
    ok = want * m[:, 2] > 1e-19
    assert np.all(got[~ok] * m[~ok, 2] <= 1.01e-19)
    want, got = want[ok], got[ok]
    # float32: the inputs carry 6e-8 relative each; Beckmann's exponent scales that by its size.
    scale = 1.0 + np.abs(np.log(want))
    rel = np.abs(got - want) / want / scale
    print(name, "largest relative difference / (1 + |ln D|):", rel.max(), "over", ok.sum(), "directions")
    assert rel.max() < 2e-6, (name, rel.max())


def test_mitsuba_tangent_frame_of_a_fitted_approximation(tmp_path):
    """A skewed ellipsoid is approximated by a fitted GGX: Mitsuba with the exported parameters equals
    ndfit's D of the lobe the export names (ggx-aniso with theta_z = -tangent_angle)."""
    fit = tmp_path / "skew.json"
    fit.write_text(json.dumps({"model": "ellipsoid", "params": {"alpha_x": 0.3, "alpha_y": 0.12, "theta_x": 0.1,
                                                                 "theta_y": -0.08, "theta_z": 0.5}}))
    out, err = ndfit("export", fit, "--to", "mitsuba", "--json")
    exported = json.loads(out)
    assert "approximated" in err and exported["note"].startswith("approximated")
    assert exported["approximation"]["delta_reverse"] > 0
    lobe = tmp_path / "lobe.json"
    lobe.write_text(json.dumps({"model": "ggx-aniso", "params": {"alpha_x": exported["alpha_u"], "alpha_y": exported["alpha_v"],
                                                                 "theta_z": -exported["tangent_angle"]}}))
    m = directions()
    want = ndfit_d(lobe, m)
    got = mitsuba_d(exported, m)
    assert (np.abs(got - want) / want).max() < 2e-6
