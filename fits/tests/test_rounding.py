"""The height rounding in the model (ndfitpy.rounding) against its definition, computed another way.

Independent sources: the moments of a difference of two uniform roundings (closed form), a Monte Carlo
average over simulated rounding errors, and central differences for the gradient.
"""

import math

import numpy as np
import pytest

from ndfitpy import models
from ndfitpy.rounding import Rounding, seen_log_d_and_grad


@pytest.mark.parametrize("scheme", ["central", "triangles"])
def test_rule_moments_are_those_of_the_rounding(scheme):
    lx, ly = 0.02, 0.03
    e, w = Rounding((lx, ly), scheme).offsets()
    assert w.sum() == pytest.approx(1.0, abs=1e-14)
    # A difference of two uniforms on (-1/2, 1/2): variance 1/6; triangles share the corner, covariance 1/12.
    cov = (w[:, None, None] * e[:, :, None] * e[:, None, :]).sum(0)
    c = lx * ly / 12.0 if scheme == "triangles" else 0.0
    assert np.allclose(cov, [[lx * lx / 6.0, c], [c, ly * ly / 6.0]], rtol=1e-9, atol=0.0)
    assert np.allclose((w[:, None] * e).sum(0), 0.0, atol=1e-18)
    # Odd third moments vanish (both schemes are symmetric under u -> -u).
    assert (w * e[:, 0] ** 3).sum() == pytest.approx(0.0, abs=1e-18)


@pytest.mark.parametrize("scheme", ["central", "triangles"])
def test_seen_d_is_the_average_over_simulated_roundings(scheme):
    rng = np.random.default_rng(1)
    model, params = "ggx-aniso", [0.2, 0.1, 0.4]
    lx, ly = 0.05, 0.04
    r = Rounding((lx, ly), scheme)
    s = np.array([[0.0, 0.0], [0.1, -0.05], [-0.25, 0.1], [0.4, 0.3]])
    m = np.column_stack([-s[:, 0], -s[:, 1], np.ones(len(s))])
    m /= np.linalg.norm(m, axis=1)[:, None]
    got = np.exp(seen_log_d_and_grad(models.log_d_and_grad, model, params, m, r, False)[0])
    # Monte Carlo over the heights' rounding errors themselves.
    n = 400_000
    u = rng.uniform(-0.5, 0.5, size=(n, 4))
    if scheme == "central":
        e = np.column_stack([(u[:, 0] - u[:, 1]) * lx, (u[:, 2] - u[:, 3]) * ly])
    else:
        e = np.column_stack([(u[:, 1] - u[:, 0]) * lx, (u[:, 2] - u[:, 0]) * ly])
    for k in range(len(s)):
        q = s[k] + e
        t = 1.0 + (q * q).sum(1)
        mq = np.column_stack([-q[:, 0], -q[:, 1], np.ones(n)]) / np.sqrt(t)[:, None]
        p22 = models.d(model, params, mq) / t**2
        want = p22.mean() * (1.0 + (s[k] ** 2).sum()) ** 2
        se = p22.std() / math.sqrt(n) * (1.0 + (s[k] ** 2).sum()) ** 2
        # The rule is exact for cubics in each u; the quartic remainder is far below 1e-3 at this lattice.
        assert abs(got[k] - want) < 5 * se + 1e-3 * want, (k, got[k], want, se)
    # And the smoothing moves D: without it the peak would be higher by about the kernel's share.
    assert got[0] < models.d(model, params, m[:1])[0]


def test_seen_gradient_matches_central_differences():
    r = Rounding((0.03, 0.02), "central")
    m = np.array([[0.1, 0.05, 1.0], [-0.3, 0.2, 1.0], [0.0, 0.0, 1.0]])
    m /= np.linalg.norm(m, axis=1)[:, None]
    for model, p in [("ggx-aniso", [0.2, 0.1, 0.4]), ("beckmann", [0.15]), ("student-aniso", [0.2, 0.1, 0.4, 2.5])]:
        if model not in models.PARAM_NAMES:
            continue
        p = np.array(p, dtype=float)
        _, g = seen_log_d_and_grad(models.log_d_and_grad, model, p, m, r, True)
        for j in range(len(p)):
            h = 1e-6 * max(1.0, abs(p[j]))
            pp, pm = p.copy(), p.copy()
            pp[j] += h
            pm[j] -= h
            fp = seen_log_d_and_grad(models.log_d_and_grad, model, pp, m, r, False)[0]
            fm = seen_log_d_and_grad(models.log_d_and_grad, model, pm, m, r, False)[0]
            assert np.allclose((fp - fm) / (2 * h), g[:, j], rtol=1e-5, atol=1e-6), (model, j)


def test_bad_rounding_is_refused():
    with pytest.raises(ValueError):
        Rounding((0.0, 0.1))
    with pytest.raises(ValueError):
        Rounding((0.1, 0.1), "hexagons")
