"""`ndfit trace` (src/trace/) against the independent numpy tracer (ndfitpy/trace.py) on a small scan.

`ndfit synth` writes a 64 x 64 Gaussian surface (RMS slope 0.4, correlation length 6 cells: masking and
shadowing are strong at grazing incidence); both sides trace the same heights (`--form none --despike
none`; the X3P read by ndfitpy's own reader) as two triangles per cell, periodic, F = 1, and compare per
incidence:

- `g1_smith` (exact sums over the same triangles on both sides): within 1e-9 relative;
- `g1`: ndfit's shadow-ray estimate against the numpy landing-rate estimate, within 4 combined standard
  errors (ndfit's `g1_stderr`, the binomial error of the landing rate here);
- the first bounce's albedo (`albedo_by_bounce[0]`, `--bounces 1`: the share of landed rays whose
  reflection leaves unblocked) within 4 combined binomial standard errors;
- the one-bounce BRDF bin by bin (`--tables`, `--bins 16x32`), and ndfit's `model` table against the
  model summed exactly over the triangles (see the two tests' docstrings for the statistics).

Runs the ndfit binary (`NDFIT` or target/release/ndfit); skips only when that binary is absent. About
12 CPU-seconds, most of them numpy's own paths; `pytest -s` prints the figures.
"""

import csv
import json
import math
import os
import subprocess

import numpy as np
import pytest

from ndfitpy.trace import Surface, bin_index, direction, model_table, single_counts, trace_incidence
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
BINS = (16, 32)
# False-alarm probability allowed to each per-bin assertion below, over all its bins and incidences.
ALPHA = 1e-4
# Bins expected to hold fewer samples than this (in the smaller of the two samples) are pooled.
N_MIN = 25


def _run(*args):
    p = subprocess.run([NDFIT, *map(str, args)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return p


@pytest.fixture(scope="module")
def traced_all(tmp_path_factory):
    d = tmp_path_factory.mktemp("trace")
    scan = d / "gauss.x3p"
    _run("synth", scan, "--surface", "gaussian", "--nx", 64, "--ny", 64, "--sigma-x", 0.4, "--corr-length", 6e-6, "--seed", 3)
    out = d / "trace.json"
    tables = d / "tables.csv"
    _run(
        "trace", scan, "--form", "none", "--despike", "none", "--incidence", ",".join(map(str, INCIDENCES)),
        "--azimuth", AZIMUTH, "--bounces", 1, "--rays", NDFIT_RAYS, "--seed", 5, "--quiet", "-o", out,
        "--bins", f"{BINS[0]}x{BINS[1]}", "--tables", tables,
    )
    doc = json.loads(out.read_text())
    hm = read_x3p(scan)
    assert not np.isnan(hm.z).any()
    s = Surface(hm.z, hm.dx, hm.dy)
    rng = np.random.default_rng(20260)
    ours = [trace_incidence(s, t, AZIMUTH, NUMPY_RAYS, rng) for t in INCIDENCES]
    with open(tables, newline="") as f:
        rows = list(csv.DictReader(f))
    return doc, ours, rows, s


@pytest.fixture(scope="module")
def traced(traced_all):
    doc, ours, _, _ = traced_all
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


def _normal_isf2(p):
    """``b`` with ``P(|Z| > b) = p`` for a standard normal ``Z`` (bisection on ``erfc``)."""
    lo, hi = 0.0, 40.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if math.erfc(mid / math.sqrt(2)) > p else (lo, mid)
    return hi


def _chi2_band(dof, alpha):
    """Chi-square per degree of freedom: the quantiles at ``alpha / 2`` and ``1 - alpha / 2``
    (Wilson-Hilferty: ``(chi2 / dof)^(1/3)`` is normal of mean ``1 - 2 / (9 dof)``, variance ``2 / (9 dof)``)."""
    z, v = _normal_isf2(alpha), 2.0 / (9.0 * dof)
    return (1 - v - z * math.sqrt(v)) ** 3, (1 - v + z * math.sqrt(v)) ** 3


def _column(rows, inc, name):
    """Column ``name`` of incidence ``inc`` of the `--tables` CSV, in bin order."""
    part = [r for r in rows if int(r["incidence"]) == inc]
    assert [int(r["bin"]) for r in part] == list(range(BINS[0] * BINS[1]))
    return np.array([float(r[name]) for r in part])


def test_the_tables_lay_out_the_bins_as_numpy_does(traced_all):
    """The CSV's bins are numpy's: centres fall in their own bin, edges at ``theta = (k / n)^2 pi / 2`` and
    ``phi = -pi + 2 pi k / n``, projected solid angles ``(sin^2 hi - sin^2 lo) pi / n_phi``, and the energies
    add up to the JSON's."""
    doc, _, rows, _ = traced_all
    assert len(rows) == len(INCIDENCES) * BINS[0] * BINS[1]
    nt, nph = BINS
    for inc, r in enumerate(doc["incidences"]):
        it, ip = _column(rows, inc, "i_theta").astype(int), _column(rows, inc, "i_phi").astype(int)
        assert (it * nph + ip == np.arange(nt * nph)).all()
        o = np.stack([_column(rows, inc, c) for c in ("ox", "oy", "oz")], axis=1)
        assert (bin_index(o, nt, nph) == np.arange(nt * nph)).all()
        lo, hi = (it / nt) ** 2 * np.pi / 2, ((it + 1) / nt) ** 2 * np.pi / 2
        assert np.allclose(np.radians(_column(rows, inc, "theta_lo_deg")), lo, rtol=0, atol=1e-12)
        phi_hi = -np.pi + 2 * np.pi * (ip + 1) / nph
        assert np.allclose(np.radians(_column(rows, inc, "phi_hi_deg")), phi_hi, rtol=0, atol=1e-12)
        omega = (np.sin(hi) ** 2 - np.sin(lo) ** 2) * np.pi / nph
        assert np.allclose(_column(rows, inc, "proj_solid_angle"), omega, rtol=1e-12, atol=0)
        assert _column(rows, inc, "single").sum() == pytest.approx(r["albedo_by_bounce"][0], rel=1e-12)
        assert _column(rows, inc, "model").sum() == pytest.approx(r["single"]["albedo_model"], rel=1e-12)
        assert not _column(rows, inc, "multi").any()  # one bounce followed
        assert _column(rows, inc, "theta_i_deg")[0] == r["theta_deg"]


def _homogeneity(c1, n1, c2, n2, n_min):
    """Two multinomial samples of the same law? ``c1``, ``c2``: counts per bin out of ``n1``, ``n2`` draws.
    Bins expected to hold at least ``n_min`` draws in the smaller sample are categories of their own; the
    other bins and the draws in no bin form one more. Returns ``(z per category, Pearson's chi2, dof, the
    bins compared alone)``."""
    p = (c1 + c2) / (n1 + n2)
    keep = min(n1, n2) * p >= n_min
    a1 = np.array([*c1[keep], n1 - c1[keep].sum()])
    a2 = np.array([*c2[keep], n2 - c2[keep].sum()])
    pp = (a1 + a2) / (n1 + n2)
    assert min(n1, n2) * pp[-1] >= n_min  # the pooled category is well filled too
    d = a1 / n1 - a2 / n2
    z = d / np.sqrt(pp * (1 - pp) * (1 / n1 + 1 / n2))
    chi2 = float(np.sum(d * d / (pp * (1 / n1 + 1 / n2))))
    return z, chi2, len(a1) - 1, keep


def test_one_bounce_brdf_agrees_bin_by_bin(traced_all):
    """The first bounce's BRDF per outgoing bin, ndfit's table against numpy's own paths.

    With F = 1 each landed path leaves after one bounce into one bin or is blocked, so the counts are
    multinomial on both sides: ndfit's ``single * landed`` (integers), numpy's binned directions. The BRDF
    over bin k is ``c_k / (n Omega_k)``; both tracing the same surface, the difference of the two has
    variance ``p (1 - p) (1 / n1 + 1 / n2)`` with ``p`` the pooled share ``(c1 + c2) / (n1 + n2)`` (Omega
    cancels in ``z``). Categories: each bin expected to hold at least N_MIN paths in the smaller sample,
    alone; the other bins and the paths that did not leave pooled in one. Pearson's homogeneity statistic over
    the C categories is chi-square with C - 1 degrees of freedom (added over the incidences); it must lie
    within the two-sided Wilson-Hilferty band of false-alarm ALPHA. Every ``|z| <= b`` with
    ``P(|Z| > b) = ALPHA / (2 M)`` for the M categories (Bonferroni); the halving covers the normal
    approximation's tail: summing the two Poisson laws exactly, at 25 or more expected counts and sample
    sizes in ratio 2, the two-sided tail beyond 4 to 5.5 sigma is at most 1.7 times the normal one.
    """
    doc, ours, rows, _ = traced_all
    nt, nph = BINS
    zs, chi2, dof, mirrored, pooled_share = [], 0.0, 0, [0.0, 0], []
    for inc, (r, o) in enumerate(zip(doc["incidences"], ours)):
        n1, n2 = r["landed"], o.landed
        e1 = _column(rows, inc, "single") * n1
        c1 = np.round(e1)
        assert np.abs(e1 - c1).max() < 1e-6  # F = 1: a path's energy is 1, in one bin
        c2 = single_counts(o, nt, nph).astype(float)
        z, x2, k, keep = _homogeneity(c1, n1, c2, n2, N_MIN)
        pooled = int(np.count_nonzero(~keep & (c1 + c2 > 0)))
        pooled_share.append((c1 + c2)[~keep].sum() / (c1 + c2).sum())
        print(f"one-bounce BRDF {r['theta_deg']:4.0f} deg: {len(z)} categories ({pooled} sparse bins pooled, "
              f"{100 * pooled_share[-1]:.2f}% of the paths that leave), "
              f"chi2/dof {x2 / k:.3f}, max |z| {np.abs(z).max():.2f}")
        zs.append(z)
        chi2, dof = chi2 + x2, dof + k
        # The same numpy paths with the azimuth mirrored (y -> -y): a sign error in the frame.
        flip = o.out_dirs * np.array([1.0, -1.0, 1.0])
        cf = np.bincount(bin_index(flip, nt, nph), minlength=nt * nph).astype(float)
        _, xf, kf, _ = _homogeneity(c1, n1, cf, n2, N_MIN)
        mirrored = [mirrored[0] + xf, mirrored[1] + kf]
    z = np.concatenate(zs)
    lo, hi = _chi2_band(dof, ALPHA)
    bound = _normal_isf2(ALPHA / (2 * len(z)))
    print(f"one-bounce BRDF, all incidences: {len(z)} categories, chi2/dof {chi2 / dof:.3f} (band {lo:.3f}-{hi:.3f}),"
          f" max |z| {np.abs(z).max():.2f} (bound {bound:.2f}); mirrored azimuth: chi2/dof "
          f"{mirrored[0] / mirrored[1]:.1f}")
    assert lo <= chi2 / dof <= hi
    assert np.abs(z).max() <= bound
    # The check has teeth: nearly all the reflected energy is compared bin by bin, and a mirrored frame
    # fails it.
    assert max(pooled_share) < 0.01
    assert mirrored[0] / mirrored[1] > 2 * hi


def _bernstein(n, var, wdev, alpha):
    """``b`` with ``P(|mean - E| > b sd) <= alpha`` for the mean of ``n`` independent samples of variance
    ``var`` and ``|sample - E| <= wdev`` (Bernstein's inequality, ``sd = sqrt(var / n)``)."""
    lg = math.log(2.0 / alpha)
    t = (2 * lg * wdev / 3 + np.sqrt((2 * lg * wdev / 3) ** 2 + 8 * lg * n * var)) / 2
    return t / np.sqrt(n * var)


def test_model_table_matches_the_exact_sum(traced_all):
    """ndfit's `model` table (the microfacet model's single scattering) against the same model summed
    exactly over the triangles by numpy (``model_table``: no noise, Lambda exact where ndfit interpolates
    Lambda(o) in a table, an approximation bounded here by the noise).

    ndfit samples the model once per path at its start point, uniform on the landing cells: its energy in
    bin k is the mean of N independent samples ``a 1_k`` (N ~ rays x landing share; the count itself is not
    reported, its binomial spread changes the variance by 0.1%). ``z = (model - E) / sqrt(V / N)`` with the
    exact mean E and variance V. Categories: each bin where N P(bin) >= N_MIN alone, the others pooled (the
    moments add over disjoint bins). ``sum z^2`` has mean the number of categories and is close to
    chi-square (the bins' covariance ``-E_j E_k / N`` aside): band as above. Tail: each sample deviates from
    E by at most B (the bin's largest weight, or E), so Bernstein's inequality gives each category its own
    bound ``b_k`` with ``P(|z_k| > b_k) <= ALPHA / M`` over the M categories, with no normal approximation.
    """
    doc, _, rows, s = traced_all
    nt, nph = BINS
    share = doc["surface"]["landing_share"]
    zs, bs = [], []
    for inc, r in enumerate(doc["incidences"]):
        mt = model_table(s, direction(r["theta_deg"], r["phi_deg"]), nt, nph)
        n = r["rays"] * share
        keep = n * mt.share >= N_MIN
        mean = np.array([*mt.mean[keep], mt.mean[~keep].sum()])
        second = np.array([*mt.second[keep], mt.second[~keep].sum()])
        wmax = np.array([*mt.wmax[keep], mt.wmax[~keep].max(initial=0.0)])
        got_all = _column(rows, inc, "model")
        assert not got_all[mt.share == 0].any()  # no triangle reflects there: no sample can
        got = np.array([*got_all[keep], got_all[~keep].sum()])
        if n * mt.share[~keep].sum() < N_MIN:  # the pooled bin too sparse: left out
            mean, second, wmax, got = mean[:-1], second[:-1], wmax[:-1], got[:-1]
        var = second - mean**2
        z = (got - mean) / np.sqrt(var / n)
        zs.append(z)
        bs.append((n, var, np.maximum(wmax - mean, mean)))
        print(f"model table {r['theta_deg']:4.0f} deg: {len(z)} categories "
              f"({int(np.count_nonzero(~keep & (mt.share > 0)))} sparse bins pooled), "
              f"chi2/dof {np.mean(z**2):.3f}, max |z| {np.abs(z).max():.2f}; albedo exact {mt.mean.sum():.5f}, "
              f"ndfit {got_all.sum():.5f}")
    z = np.concatenate(zs)
    m = len(z)
    bound = np.concatenate([_bernstein(n, v, w, ALPHA / m) for n, v, w in bs])
    lo, hi = _chi2_band(m, ALPHA)
    print(f"model table, all incidences: {m} categories, chi2/dof {np.mean(z**2):.3f} (band {lo:.3f}-{hi:.3f}), "
          f"max |z| {np.abs(z).max():.2f}, max |z| / bound {np.max(np.abs(z) / bound):.2f} (bounds "
          f"{bound.min():.2f}-{bound.max():.2f})")
    assert lo <= np.mean(z**2) <= hi
    assert (np.abs(z) <= bound).all()
