"""The objectives and the delta metric of data_formats/objective.md against independent formulations."""

import math

import numpy as np
import pytest

from ndfitpy import models, synthetic
from ndfitpy import objective as obj

CASES = [
    ("ggx", [0.3]),
    ("ggx-aniso", [0.2, 0.5, 0.4]),
    ("beckmann", [0.25]),
    ("beckmann-aniso", [0.2, 0.4, -0.6]),
    ("ellipsoid", [0.2, 0.5, 0.3, -0.2, 0.4]),
]


def _data(seed=0, model="ellipsoid", params=(0.25, 0.35, 0.1, -0.05, 0.3)):
    grid = synthetic.grid_for(0.3, 40, 48)
    return synthetic.sampled_bins(model, list(params), 200_000, grid, seed=seed)


@pytest.mark.parametrize("model,params", CASES)
def test_deviance_is_twice_the_log_likelihood_ratio(model, params):
    """F = 2 (l(saturated) - l(model)) with the Poisson log-pmf l(E) = sum_k c ln E - E - ln c! (lgamma),
    the definition of the deviance, computed term by term in plain Python (rtol 1e-10: the sums have
    ~2000 terms of size <= 1e6, so double rounding stays below 1e-12 relative). Data drawn from the same
    family at other parameters, so that E > 0 in every occupied bin and no guard is involved."""
    b = _data(0, model, [v * 1.1 for v in params])
    f = obj.poisson_deviance(model, params, b)
    # The region and its conditional normalization (objective.md), computed here term by term.
    cos_max = math.cos(math.radians(obj.DEFAULT_MAX_THETA_DEG))
    inside = [k for k in range(len(b)) if b.proj_solid_angle[k] > 0 and b.m[k, 2] >= cos_max]
    assert 0 < len(inside) < len(b), "the test data must reach beyond max_theta"
    d = models.d(model, params, b.m)
    n = math.fsum(float(b.count[k]) for k in inside)
    s_norm = math.fsum(float(d[k] * b.proj_solid_angle[k]) for k in inside)
    ll_model = 0.0
    ll_sat = 0.0
    for k in inside:
        c, e = float(b.count[k]), n * d[k] * b.proj_solid_angle[k] / s_norm
        ll_model += (c * math.log(e) if c > 0 else 0.0) - e - math.lgamma(c + 1)
        ll_sat += (c * math.log(c) if c > 0 else 0.0) - c - math.lgamma(c + 1)
    assert f == pytest.approx(2.0 * (ll_sat - ll_model), rel=1e-10)
    r = obj.poisson_residuals(model, params, b)
    assert len(r) == len(inside)
    assert float(np.sum(r * r)) == pytest.approx(f, rel=1e-12)
    e = np.array([n * d[k] * b.proj_solid_angle[k] / s_norm for k in inside])
    cc = b.count[inside]
    big = np.abs(cc - e) > 1e-9
    assert np.all(np.sign(r[big]) == np.sign((cc - e)[big]))


@pytest.mark.parametrize("objective", ["poisson", "logd"])
@pytest.mark.parametrize("model,params", CASES)
def test_objective_gradient_matches_central_differences(objective, model, params):
    """dF/dparams against central differences (relative step 1e-6; F ~ 1e4..1e6 so roundoff is about
    eps F / h ~ 1e-4 absolute; rtol 1e-5 on gradients of size >= 1e2 leaves a margin of 10 over it)."""
    b = _data(1)
    p = np.array(params, dtype=float)
    _, g = obj.objective(objective, model, p, b, want_grad=True)
    for j, name in enumerate(models.PARAM_NAMES[model]):
        h = 1e-6 * (p[j] if name.startswith("alpha") else 1.0)
        pp, pm = p.copy(), p.copy()
        pp[j] += h
        pm[j] -= h
        fd = (obj.objective(objective, model, pp, b) - obj.objective(objective, model, pm, b)) / (2 * h)
        assert g[j] == pytest.approx(fd, rel=1e-5, abs=1e-3), (name, g[j], fd)


def test_logd_matches_its_definition():
    b = _data(2)
    p = [0.3, 0.3, 0.0]
    cos_max = math.cos(math.radians(obj.DEFAULT_MAX_THETA_DEG))
    reg = (b.proj_solid_angle > 0) & (b.m[:, 2] >= cos_max)
    d_all = models.d("ggx-aniso", p, b.m)
    n_in = float(b.count[reg].sum())
    s_norm = float(np.sum(d_all[reg] * b.proj_solid_angle[reg]))
    sel = reg & (b.count >= 10)
    d_data = b.count[sel] / (n_in * b.proj_solid_angle[sel])
    ref = float(np.sum(b.count[sel] * (np.log(d_all[sel] / s_norm) - np.log(d_data)) ** 2))
    assert obj.logd_objective("ggx-aniso", p, b) == pytest.approx(ref, rel=1e-12)


def test_zero_weight_bins_are_left_out():
    b = _data(3)
    f = obj.poisson_deviance("ggx", [0.3], b)
    w = b.proj_solid_angle.copy()
    w[:5] = 0.0
    b2 = synthetic.Bins(m=b.m, count=b.count.copy(), proj_solid_angle=w)
    b2.count[:5] = 0.0
    b3 = b2.used()
    assert len(b3) == len(b) - 5
    # With those bins' counts moved out of N too, the two agree exactly: same bins, same N.
    assert obj.poisson_deviance("ggx", [0.3], b2) == obj.poisson_deviance("ggx", [0.3], b3)
    assert math.isfinite(f)


def test_deviance_of_a_far_too_narrow_lobe_is_exact():
    """Beckmann lobes much narrower than the data: E underflows to 0 in most occupied bins, ln E reaches -1e5.
    The deviance must still be the exact 2 sum (E - c + c (ln c - ln E)), computed here in the log domain term
    by term, finite, and must keep ranking narrower lobes as worse (a floor on ln E would flatten that)."""
    b = _data(4)
    n = b.n_samples
    values = []
    for alpha in (1e-4, 1e-3, 1e-2):
        f, g = obj.poisson_deviance("beckmann", [alpha], b, want_grad=True)
        cos_max = math.cos(math.radians(obj.DEFAULT_MAX_THETA_DEG))
        reg = (b.proj_solid_angle > 0) & (b.m[:, 2] >= cos_max)
        ld = models.log_d("beckmann", [alpha], b.m[reg])
        n = float(b.count[reg].sum())
        lw = [l + math.log(w) for l, w in zip(ld, b.proj_solid_angle[reg])]
        top = max(lw)
        ln_s = top + math.log(math.fsum(math.exp(v - top) for v in lw))
        ref = 0.0
        for c, l, w in zip(b.count[reg], ld, b.proj_solid_angle[reg]):
            ln_e = math.log(n) + l + math.log(w) - ln_s
            e = math.exp(ln_e) if ln_e > -745 else 0.0
            ref += 2.0 * (e - c + (c * (math.log(c) - ln_e) if c > 0 else 0.0))
        assert f == pytest.approx(ref, rel=1e-12)
        assert math.isfinite(f) and np.all(np.isfinite(g))
        values.append(f)
    assert values[0] > values[1] > values[2]


def test_delta_of_a_scaled_ndf_is_the_scale():
    """delta(c D_ref; D_ref) = |c - 1| exactly (objective.md's formula with a constant ratio)."""
    b = _data(5)
    lr = models.log_d("ggx", [0.3], b.m)
    assert obj.delta(lr, lr, b.proj_solid_angle) == 0.0
    assert obj.delta(lr + math.log(1.002), lr, b.proj_solid_angle) == pytest.approx(0.002, rel=1e-9)


def test_delta_between_two_beckmann_lobes_matches_the_closed_form():
    """Isotropic Beckmann lobes, D_ref of roughness a and D of roughness b. In slope space (D cos dw = P22 ds,
    Heitz eq. 64) E_{D_ref}[(D/D_ref)^2] = integral of P_b^2 / P_a = (a^2 / b^4) / (2/b^2 - 1/a^2), a Gaussian
    integral of Heitz eq. 67; E_{D_ref}[D/D_ref] = 1, so delta^2 = that - 1. The bins' midpoint quadrature
    converges as h^2: relative error 1.5e-5 with 80 rings, 3.8e-6 with 160, 9.4e-7 with 320 (measured), so
    5e-5 at 160 rings is ten times the quadrature error."""
    a, bb = 0.30, 0.31
    e2 = (a * a / bb**4) / (2.0 / bb**2 - 1.0 / a**2)
    expected = math.sqrt(e2 - 1.0)
    grid = synthetic.grid_for(0.3, 160, 8)
    bins = grid.bins()
    got = obj.delta(models.log_d("beckmann", [bb], bins.m), models.log_d("beckmann", [a], bins.m), bins.proj_solid_angle)
    assert got == pytest.approx(expected, rel=5e-5)
