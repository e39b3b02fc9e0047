"""The numpy STD lobe (Ribardiere et al. 2017) against independent sources: its normalization by quadrature,
the GGX case (gamma = 2), the Beckmann limit with its first-order rate, and its gradient by finite differences;
then its nlopt fit: gamma's search map, the search-space gradient by finite differences, and the recovery of
known lobes from Poisson counts. Never against the Rust output."""

import math

import numpy as np
import pytest

from ndfitpy import canonical, models, synthetic
from ndfitpy import fit as fitmod
from ndfitpy import objective as obj

CASES = [
    ("student", [0.3, 2.0]),
    ("student", [0.3, 1.6]),
    ("student", [0.05, 4.0]),
    ("student-aniso", [0.5, 0.2, 0.7, 1.6]),
    ("student-aniso", [0.05, 0.4, -2.1, 4.0]),
    ("student-aniso", [0.2, 0.6, 0.3, 50.0]),
    ("student-aniso", [1.5, 0.8, 1.2, 2.5]),
]


def _random_dirs(n, seed, zmin=1e-3):
    rng = np.random.default_rng(seed)
    v = rng.standard_normal((n, 3))
    v[:, 2] = np.abs(v[:, 2]) + zmin
    return v / np.linalg.norm(v, axis=1)[:, None]


def _lobe(model, p):
    return (p[0], p[0], 0.0, p[1]) if model == "student" else tuple(p)


def _hemisphere_integral(model, p, n_r=600, n_phi=256):
    """Integral of D(m) cos(theta_m) over the hemisphere, taken in slope space (d omega = cos^3 ds, so
    D cos d omega = D cos^4 ds, Heitz eq. 63-64) with s = L t, L = Rz^T diag(ax, ay), polar |t| = tan(psi)^k:
    Gauss-Legendre in psi, the periodic trapezoid rule in phi. The power k = max(1, 2/(2 gamma - 3)) makes the
    heavy tail (P22 ~ |s|^(-2 gamma)) vanish smoothly at psi = pi/2."""
    ax, ay, tz, gamma = _lobe(model, p)
    k = max(1.0, 2.0 / (2.0 * gamma - 3.0))
    lmat = models.rot_z(tz)[:2, :2].T @ np.diag([ax, ay])
    x, w = np.polynomial.legendre.leggauss(n_r)
    psi = (x + 1.0) * math.pi / 4.0
    wpsi = w * math.pi / 4.0
    tp = np.tan(psi)
    r = tp**k
    dr = k * tp ** (k - 1.0) / np.cos(psi) ** 2
    phi = (np.arange(n_phi) + 0.5) * 2.0 * math.pi / n_phi
    rr, pp = np.meshgrid(r, phi, indexing="ij")
    t = np.column_stack([(rr * np.cos(pp)).ravel(), (rr * np.sin(pp)).ravel()])
    s = t @ lmat.T
    mdir = np.column_stack([-s[:, 0], -s[:, 1], np.ones(len(s))])
    cos4 = 1.0 / (1.0 + s[:, 0] ** 2 + s[:, 1] ** 2) ** 2
    f = (models.student_d(model, p, mdir) * cos4).reshape(rr.shape)
    return float(np.sum(f * rr * (wpsi * dr)[:, None]) * 2.0 * math.pi / n_phi * abs(np.linalg.det(lmat)))


@pytest.mark.parametrize("model,params", CASES)
def test_normalized(model, params):
    assert abs(_hemisphere_integral(model, params) - 1.0) < 1e-6


def test_d_is_the_papers_density_over_cos4():
    """The density as printed, (g-1)^g / (pi ax ay (g - 1 + x'^2/ax^2 + y'^2/ay^2)^g) / cos^4."""
    m = _random_dirs(500, 1)
    ax, ay, tz, g = 0.3, 0.12, 0.9, 3.5
    mp = m @ models.rot_z(tz).T
    x, y = mp[:, 0] / m[:, 2], mp[:, 1] / m[:, 2]
    want = (g - 1.0) ** g / (math.pi * ax * ay * (g - 1.0 + x * x / ax**2 + y * y / ay**2) ** g) / m[:, 2] ** 4
    np.testing.assert_allclose(models.student_d("student-aniso", [ax, ay, tz, g], m), want, rtol=1e-12)


@pytest.mark.parametrize("ax,ay,tz", [(0.3, 0.3, 0.0), (0.5, 0.1, 0.8), (1e-3, 0.02, -1.0), (3.0, 0.7, 2.0)])
def test_gamma_two_is_ggx(ax, ay, tz):
    m = _random_dirs(2000, 2)
    got = models.student_d("student-aniso", [ax, ay, tz, 2.0], m)
    np.testing.assert_allclose(got, models.d("ggx-aniso", [ax, ay, tz], m), rtol=1e-12)
    if ax == ay:
        np.testing.assert_allclose(models.student_d("student", [ax, 2.0], m), models.d("ggx", [ax], m), rtol=1e-12)


def test_large_gamma_is_beckmann_at_rate_one_over_gamma():
    """D_std / D_beckmann - 1 = (e^2/2 - e) / (gamma - 1) + O(gamma^-2), e the stretched slope squared."""
    ax, ay, tz = 0.4, 0.15, 0.6
    m = _random_dirs(400, 3, zmin=0.3)
    mp = m @ models.rot_z(tz).T
    e = ((mp[:, 0] / ax) ** 2 + (mp[:, 1] / ay) ** 2) / m[:, 2] ** 2
    keep = e < 8.0
    b = models.d("beckmann-aniso", [ax, ay, tz], m[keep])
    for g in (1e2, 1e3, 1e4, models.STUDENT_GAMMA_MAX):
        p = g - 1.0
        rel = models.student_d("student-aniso", [ax, ay, tz, g], m[keep]) / b - 1.0
        ek = e[keep]
        first = (ek * ek / 2.0 - ek) / p
        bound = (ek**2 + ek**3 + ek**4) / p**2 + 1e-12
        assert np.all(np.abs(rel - first) <= bound), g


@pytest.mark.parametrize("model,params", CASES)
def test_gradient_matches_finite_differences(model, params):
    m = _random_dirs(300, 4, zmin=0.05)
    p = np.array(params, dtype=float)
    _, g = models.student_log_d_and_grad(model, p, m)
    for j in range(p.size):
        h = 1e-6 * max(abs(p[j]), 1e-2)
        up, dn = p.copy(), p.copy()
        up[j] += h
        dn[j] -= h
        f_up = models.student_log_d_and_grad(model, up, m, False)[0]
        f_dn = models.student_log_d_and_grad(model, dn, m, False)[0]
        fd = (f_up - f_dn) / (2 * h)
        np.testing.assert_allclose(g[:, j], fd, rtol=1e-6, atol=1e-6 * (1 + np.abs(fd).max()))


def test_bad_parameters_refused():
    m = _random_dirs(3, 5)
    for bad in ([0.3, 1.5], [0.3, 1.0], [0.3, float("nan")], [-0.3, 2.0]):
        with pytest.raises(ValueError):
            models.student_d("student", bad, m)
    with pytest.raises(ValueError):
        models.student_d("student-aniso", [0.3, 2.0], m)


# ---------------------------------------------------------------------------------------------------------
# The STD lobes in PARAM_NAMES and in the nlopt fit (ndfitpy.fit): gamma's search map, the search-space gradient,
# and the recovery of known lobes from Poisson counts.


def test_student_dispatches_like_the_other_models():
    """log_d / d go through student_log_d_and_grad; no matrix A (not an ellipsoid); outside the contract's MODELS."""
    m = _random_dirs(50, 6)
    for model, p in CASES:
        np.testing.assert_array_equal(models.log_d(model, p, m), models.student_log_d_and_grad(model, p, m, False)[0])
        assert models.matrix_a(model, p) is None
        with pytest.raises(ValueError, match="not an ellipsoid"):
            models.to_ellipsoid(model, p)
        assert models.PARAM_NAMES[model][-1] == "gamma"
    assert not set(models.STUDENTS) & set(models.MODELS)


@pytest.mark.parametrize("model", ["student", "student-aniso"])
def test_extremes_no_nan(model):
    """alpha 1e-4 to 10 and gamma at either end: finite ln D and gradient above the horizon, -inf at and below it."""
    m = np.array([[0, 0, 1], [1, 0, 1e-9], [0.6, 0.8, 1e-12], [1, 0, 0], [0.3, 0.4, -0.5], [1e-9, 0, 1]], dtype=float)
    for alpha in (1e-4, 1e-2, 1.0, 10.0):
        for gamma in (1.5 + 1e-12, 2.0, 1e5):
            p = [alpha, gamma] if model == "student" else [alpha, 3 * alpha, 0.7, gamma]
            ld, g = models.log_d_and_grad(model, p, m)
            assert np.all(np.isfinite(ld[[0, 1, 2, 5]])) and np.all(np.isfinite(g)), (alpha, gamma)
            assert ld[3] == -np.inf and ld[4] == -np.inf


def test_gamma_map_is_bounded_and_inverts():
    """gamma_of_u keeps gamma in (3/2, 1e5) for any u, u_of_gamma inverts it, and gamma_du is its derivative."""
    u = np.linspace(-fitmod.LOGIT_MAX, fitmod.LOGIT_MAX, 121)
    g = fitmod.gamma_of_u(u)
    assert np.all(g > models.STUDENT_GAMMA_MIN) and np.all(g < models.STUDENT_GAMMA_MAX)
    assert np.all(np.diff(g) > 0)
    inner = np.abs(u) <= 15.0  # beyond, gamma's last digits no longer resolve u to 1e-8
    np.testing.assert_allclose(fitmod.u_of_gamma(g[inner]), u[inner], rtol=0, atol=1e-8)
    for gamma in (1.5 + 1e-6, 1.7, 2.0, 4.0, 50.0, 9e4):
        assert fitmod.gamma_of_u(fitmod.u_of_gamma(gamma)) == pytest.approx(gamma, rel=1e-12)
    # Central differences: truncation ~ h^2/6 of the derivative, roundoff ~ 1e-16 gamma / h.
    h = 1e-4
    fd = (fitmod.gamma_of_u(u + h) - fitmod.gamma_of_u(u - h)) / (2 * h)
    assert np.all(np.abs(fitmod.gamma_du(u) - fd) <= 1e-6 * np.abs(fd) + 1e-10 * g)
    # Ends beyond the interval map to the search box's ends, not to NaN.
    assert fitmod.u_of_gamma(1.5) == pytest.approx(-fitmod.LOGIT_MAX)
    assert fitmod.u_of_gamma(1e6) == pytest.approx(fitmod.LOGIT_MAX)


SEARCH_CASES = [
    ("student", [0.3, 1.7], "poisson"),
    ("student", [0.05, 4.0], "poisson"),
    ("student", [0.3, 60.0], "logd"),
    ("student-aniso", [0.15, 0.4, 0.6, 1.7], "poisson"),
    ("student-aniso", [0.3, 0.12, -0.9, 4.0], "logd"),
]


@pytest.mark.parametrize("model,truth,objective", SEARCH_CASES)
def test_search_space_gradient_matches_central_differences(model, truth, objective):
    """The gradient nlopt's L-BFGS gets (chain rule through ln alpha and gamma's logistic map) against central
    differences of the objective in search coordinates, at a point off the optimum. Step 1e-5 on coordinates of
    order 1: truncation ~ h^2 |f'''| and roundoff ~ 1e-16 |F| / h stay far below rtol 1e-5 of the gradient."""
    scale = truth[0] if model == "student" else math.sqrt(truth[0] * truth[1])
    bins = synthetic.expected_counts(model, truth, 2e5, synthetic.grid_for(scale, 48, 64), poisson_seed=11)
    x = fitmod.to_search(model, truth) + np.linspace(0.05, -0.1, len(truth))
    _, g = fitmod.search_objective(model, bins, objective, x, want_grad=True)
    fd = np.empty_like(g)
    for j in range(len(x)):
        h = 1e-5
        up, dn = x.copy(), x.copy()
        up[j] += h
        dn[j] -= h
        fd[j] = (fitmod.search_objective(model, bins, objective, up) - fitmod.search_objective(model, bins, objective, dn)) / (2 * h)
    np.testing.assert_allclose(g, fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


def _z_scores(model, fitted, truth, bins):
    """(fitted - truth) / Fisher sigma in canonical parameters, theta_z modulo pi."""
    cf = models.params_to_array(model, canonical.canonical(model, fitted))
    ct = models.params_to_array(model, canonical.canonical(model, truth))
    dd = cf - ct
    names = models.PARAM_NAMES[model]
    if "theta_z" in names:
        i = names.index("theta_z")
        dd[i] = (dd[i] + math.pi / 2) % math.pi - math.pi / 2
    _, ln_e, g = obj.log_expected(model, cf, bins, want_grad=True)
    info = (g * np.exp(ln_e)[:, None]).T @ g
    return dd / np.sqrt(np.diag(np.linalg.inv(info)))


# (model, truth, grid scale): gamma 1.7 (a heavy tail) and 4 (between GGX and Beckmann), anisotropic with theta_z.
RECOVERY = [
    ("student", [0.3, 1.7], 0.3),
    ("student", [0.2, 4.0], 0.2),
    ("student-aniso", [0.15, 0.4, 0.6, 1.7], 0.3),
    ("student-aniso", [0.3, 0.12, -0.9, 4.0], 0.2),
]


@pytest.mark.parametrize("model,truth,scale", RECOVERY)
def test_nlopt_recovers_a_poisson_student_ndf(model, truth, scale):
    """Counts drawn as Poisson(E_k) with E_k = N D(m_k) W_k (N = 1e6) from known parameters on ndfitpy's bins: the
    midpoint rule is then the data's own model, so the fit is unbiased and every canonical parameter must lie
    within 5 Fisher standard errors of the truth (a missed gamma, e.g. one left at the GGX start of 2, is off by
    tens to hundreds), and the optimizer must do at least as well as the truth on its own objective."""
    bins = synthetic.expected_counts(model, truth, 1e6, synthetic.grid_for(scale, 96, 128), poisson_seed=3)
    res = fitmod.fit(bins, model)
    assert res.value <= obj.poisson_deviance(model, truth, bins) + 1e-9 * res.value
    z = _z_scores(model, res.params, truth, bins)
    assert np.all(np.abs(z) < 5.0), dict(zip(models.PARAM_NAMES[model], np.round(z, 2)))
    assert abs(res.params["gamma"] - truth[-1]) < 0.05 * truth[-1]
