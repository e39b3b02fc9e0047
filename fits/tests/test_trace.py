"""`ndfit trace` (src/trace/) against the independent numpy tracer (ndfitpy/trace.py) on a small scan.

`ndfit synth` writes a 64 x 64 Gaussian surface (RMS slope 0.4, correlation length 6 cells: masking and
shadowing are strong at grazing incidence); both sides trace the same heights (`--form none --despike
none`; the X3P read by ndfitpy's own reader) as two triangles per cell, periodic, and compare per
incidence:

- `g1_smith` (exact sums over the same triangles on both sides): within 1e-9 relative;
- `g1`: ndfit's shadow-ray estimate against the numpy landing-rate estimate, within 4 combined standard
  errors (ndfit's `g1_stderr`, the binomial error of the landing rate here);
- the first bounce's albedo (`albedo_by_bounce[0]`, `--bounces 1`, F = 1: the share of landed rays whose
  reflection leaves unblocked) within 4 combined binomial standard errors.

Runs the ndfit binary (`NDFIT` or target/release/ndfit); skips only when that binary is absent. About
10 s on 2 cores; `pytest -s` prints the figures.
"""

import json
import os
import subprocess

import numpy as np
import pytest

from ndfitpy.trace import Surface, trace_incidence
from ndfitpy.x3p import read_x3p

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
NDFIT = os.environ.get("NDFIT", os.path.join(ROOT, "target", "release", "ndfit"))
NDFIT = NDFIT if os.path.isabs(NDFIT) else os.path.join(ROOT, NDFIT)

pytestmark = pytest.mark.skipif(
    not os.access(NDFIT, os.X_OK), reason=f"SKIP: no ndfit binary at {NDFIT} (cargo build --release, or set NDFIT)"
)

INCIDENCES = [0.0, 40.0, 70.0, 80.0]
AZIMUTH = 30.0
NDFIT_RAYS = 1 << 18
NUMPY_RAYS = 1 << 17
SIGMAS = 4.0


def _run(*args):
    p = subprocess.run([NDFIT, *map(str, args)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return p


@pytest.fixture(scope="module")
def traced(tmp_path_factory):
    d = tmp_path_factory.mktemp("trace")
    scan = d / "gauss.x3p"
    _run("synth", scan, "--surface", "gaussian", "--nx", 64, "--ny", 64, "--sigma-x", 0.4, "--corr-length", 6e-6, "--seed", 3)
    out = d / "trace.json"
    _run(
        "trace", scan, "--form", "none", "--despike", "none", "--incidence", ",".join(map(str, INCIDENCES)),
        "--azimuth", AZIMUTH, "--bounces", 1, "--rays", NDFIT_RAYS, "--seed", 5, "--quiet", "-o", out,
    )
    doc = json.loads(out.read_text())
    hm = read_x3p(scan)
    assert not np.isnan(hm.z).any()
    s = Surface(hm.z, hm.dx, hm.dy)
    rng = np.random.default_rng(20260)
    ours = [trace_incidence(s, t, AZIMUTH, NUMPY_RAYS, rng) for t in INCIDENCES]
    return doc, ours


def test_the_report_describes_the_same_surface(traced):
    doc, _ = traced
    assert doc["schema"] == "ndfit.trace/1"
    assert (doc["surface"]["nx"], doc["surface"]["ny"], doc["surface"]["border"]) == (64, 64, "periodic")
    assert doc["surface"]["landing_share"] == pytest.approx(63 * 63 / 64 / 64, rel=1e-12)
    assert [r["theta_deg"] for r in doc["incidences"]] == INCIDENCES
    assert all(r["phi_deg"] == AZIMUTH for r in doc["incidences"])


def test_smith_g1_of_the_traced_triangles_matches_exactly(traced):
    doc, ours = traced
    for r, o in zip(doc["incidences"], ours):
        assert r["g1_smith"] == pytest.approx(o.g1_smith, rel=1e-9), r["theta_deg"]


def test_traced_masking_agrees_within_monte_carlo_noise(traced):
    doc, ours = traced
    for r, o in zip(doc["incidences"], ours):
        sd = np.hypot(r["g1_stderr"], o.g1_stderr)
        print(f"G1 {r['theta_deg']:4.0f} deg: ndfit {r['g1']:.5f} +- {r['g1_stderr']:.5f}, numpy {o.g1:.5f} +- "
              f"{o.g1_stderr:.5f} ({abs(r['g1'] - o.g1) / max(sd, 1e-300):.1f} sigma); Smith {o.g1_smith:.5f}")
        # At normal incidence every facet faces the light and is seen: ndfit's estimate is exactly 1.
        assert abs(r["g1"] - o.g1) <= SIGMAS * sd + 1e-12, r["theta_deg"]
    # The check has teeth: at 80 deg the masking is far from 1.
    assert ours[-1].g1 < 0.8


def test_first_bounce_albedo_agrees_within_monte_carlo_noise(traced):
    doc, ours = traced
    for r, o in zip(doc["incidences"], ours):
        a = r["albedo_by_bounce"][0]
        assert r["albedo"] == pytest.approx(a, rel=1e-12)  # one bounce followed
        assert r["single"]["albedo_traced"] == pytest.approx(a, rel=1e-12)
        sd_ndfit = np.sqrt(a * (1 - a) / r["landed"])  # F = 1: each landed path leaves (1) or not (0)
        sd = np.hypot(sd_ndfit, o.single_stderr)
        print(f"first bounce {r['theta_deg']:4.0f} deg: ndfit {a:.5f} +- {sd_ndfit:.5f}, numpy {o.single:.5f} +- "
              f"{o.single_stderr:.5f} ({abs(a - o.single) / sd:.1f} sigma; {o.blocked_long} grazing counted blocked)")
        assert abs(a - o.single) <= SIGMAS * sd, r["theta_deg"]
        # Rays counted blocked without tracing them to the end must be negligible beside the noise.
        assert o.blocked_long / o.landed < sd
    # The check has teeth: a tenth or more of the first bounces are blocked.
    assert min(o.single for o in ours) < 0.9
