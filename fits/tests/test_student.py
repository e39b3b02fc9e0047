"""The numpy STD lobe (Ribardiere et al. 2017) against independent sources: its normalization by quadrature,
the GGX case (gamma = 2), the Beckmann limit with its first-order rate, and its gradient by finite differences.
Never against the Rust output."""

import math

import numpy as np
import pytest

from ndfitpy import models

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
