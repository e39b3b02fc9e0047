"""The numpy mixtures (ndfitpy.mixtures) against their definition: normalization by quadrature, the
gradient against central differences, and a fit that recovers a known mixture from exact expected counts."""

import math

import numpy as np
import pytest

from ndfitpy import models, synthetic
from ndfitpy.fit import fit

CASES = {
    "ggx2": [0.1, 0.06, 0.4, 0.3, 0.3, 0.8],
    "beckmann2": [0.1, 0.06, 0.4, 0.3, -0.5, 0.7],
    "ellipsoid+ggx": [0.12, 0.07, 0.1, -0.08, 0.5, 0.45, 0.75],
}


def _hemisphere(n=1200):
    """Midpoint nodes in (theta, phi) with their solid angles."""
    t = (np.arange(n) + 0.5) * (0.5 * math.pi / n)
    p = (np.arange(2 * n) + 0.5) * (2 * math.pi / (2 * n))
    tt, pp = np.meshgrid(t, p, indexing="ij")
    m = np.column_stack([(np.sin(tt) * np.cos(pp)).ravel(), (np.sin(tt) * np.sin(pp)).ravel(), np.cos(tt).ravel()])
    dw = (np.sin(tt) * (0.5 * math.pi / n) * (2 * math.pi / (2 * n))).ravel()
    return m, dw


@pytest.mark.parametrize("model", models.MIXTURES)
def test_mixture_integrates_to_one(model):
    m, dw = _hemisphere()
    total = float(np.sum(models.d(model, CASES[model], m) * m[:, 2] * dw))
    assert abs(total - 1.0) < 2e-3, total


@pytest.mark.parametrize("model", models.MIXTURES)
def test_mixture_gradient_matches_central_differences(model):
    rng = np.random.default_rng(3)
    m = rng.normal(size=(40, 3))
    m[:, 2] = np.abs(m[:, 2]) + 0.3
    m /= np.linalg.norm(m, axis=1)[:, None]
    p = np.array(CASES[model], dtype=float)
    _, g = models.log_d_and_grad(model, p, m)
    for j in range(len(p)):
        h = 1e-6 * max(1.0, abs(p[j]))
        pp, pm = p.copy(), p.copy()
        pp[j] += h
        pm[j] -= h
        fd = (models.log_d(model, pp, m) - models.log_d(model, pm, m)) / (2 * h)
        assert np.allclose(fd, g[:, j], rtol=1e-5, atol=1e-5), (model, j)


@pytest.mark.parametrize("model", ["ggx2", "ellipsoid+ggx"])
def test_fit_recovers_a_mixture_from_expected_counts(model):
    """Noise-free expected counts of a known mixture: the nlopt fit's NDF is within 0.1% of the truth."""
    from ndfitpy import objective as obj

    truth = CASES[model]
    bins = synthetic.expected_counts(model, truth, 1e6, synthetic.grid_for(0.4, 120, 120))
    res = fit(bins, model)
    d = obj.model_delta(model, res.params, model, truth, bins)
    assert d < 1e-3, (res.params, d)


def test_lobe_bound_is_the_search_box_and_valley_end_keeps_the_region():
    """Mixture lobes are searched up to LOBE_ALPHA_MAX (the Rust fitter's bound), and valley_end moves a flat lobe to
    it without changing D's shape over slopes up to tan 70 deg: checked by direct evaluation of both mixtures, their
    ratio constant there to the flat-lobe limit's 2 s^2 / alpha^2 (independent of how valley_end scales the odds)."""
    from ndfitpy import fit as fitmod, mixtures

    lb, ub, _ = fitmod._bounds("ggx2", fitmod.to_search("ggx2", CASES["ggx2"]))
    assert math.isclose(math.exp(ub[2]), mixtures.LOBE_ALPHA_MAX) and math.isclose(math.exp(ub[0]), mixtures.LOBE_ALPHA_MAX)
    p = np.array([0.15, 0.1, 80.0, 0.3, 0.2, 0.2])
    q = mixtures.valley_end("ggx2", p, math.tan(math.radians(70)))
    assert q[2] == mixtures.LOBE_ALPHA_MAX and q[3] == p[3] and q[5] < p[5]  # the widened (second) lobe gains weight
    s = np.linspace(-math.tan(math.radians(70)), math.tan(math.radians(70)), 41)
    sx, sy = np.meshgrid(s, s)
    keep = np.hypot(sx, sy) <= math.tan(math.radians(70))
    m = np.column_stack([-sx[keep], -sy[keep], np.ones(keep.sum())])
    m /= np.linalg.norm(m, axis=1)[:, None]
    ratio = models.d("ggx2", q, m) / models.d("ggx2", p, m)
    assert np.ptp(ratio) / ratio.mean() < 2 * 7.55 / 80.0**2, np.ptp(ratio) / ratio.mean()
    assert mixtures.valley_end("ggx2", q, 2.75) is None  # already at the bound
    assert mixtures.valley_end("ggx2", np.array(CASES["ggx2"]), 2.75) is None  # no flat lobe
    assert mixtures.valley_end("ggx2", p, 6.0) is None  # 80 is not flat to 1% over slopes up to 6
