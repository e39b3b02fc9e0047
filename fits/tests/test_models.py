"""The numpy model code against closed forms from the papers (never against the Rust output)."""

import math

import numpy as np
import pytest

from ndfitpy import models, synthetic

ALL_CASES = [
    ("ggx", [1e-4]),
    ("ggx", [0.3]),
    ("ggx", [10.0]),
    ("ggx-aniso", [0.2, 0.5, 0.4]),
    ("ggx-aniso", [0.01, 0.4, -1.2]),
    ("beckmann", [1e-4]),
    ("beckmann", [0.3]),
    ("beckmann", [3.0]),
    ("beckmann-aniso", [0.2, 0.5, 0.4]),
    ("beckmann-aniso", [0.05, 0.6, 2.0]),
    ("ellipsoid", [0.2, 0.5, 0.3, -0.2, 0.4]),
    ("ellipsoid", [0.05, 0.02, 0.6, 0.1, -0.3]),
    ("ellipsoid", [1.5, 0.7, -0.4, 0.5, 1.0]),
]


def _random_dirs(n, seed, zmin=1e-3):
    rng = np.random.default_rng(seed)
    v = rng.standard_normal((n, 3))
    v[:, 2] = np.abs(v[:, 2]) + zmin
    return v / np.linalg.norm(v, axis=1)[:, None]


def test_rotations_are_walter_eq3():
    """Rx, Ry, Rz entry by entry as printed in Walter et al. eq. 3; R orthonormal with det 1."""
    tx, ty, tz = 0.3, -0.7, 1.1
    cx, sx, cy, sy, cz, sz = math.cos(tx), math.sin(tx), math.cos(ty), math.sin(ty), math.cos(tz), math.sin(tz)
    np.testing.assert_array_equal(models.rot_x(tx), [[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    np.testing.assert_array_equal(models.rot_y(ty), [[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    np.testing.assert_array_equal(models.rot_z(tz), [[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    r = models.rotation(tx, ty, tz)
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-15)
    assert abs(np.linalg.det(r) - 1.0) < 1e-15
    # Walter sec. 1: with theta_x = theta_y = 0, A n = n and ||A n|| = 1.
    a = models.ellipsoid_matrix(0.3, 0.1, 0.0, 0.0, tz)
    np.testing.assert_allclose(a @ [0, 0, 1], [0, 0, 1], atol=1e-16)


def _slope_space_integral(model, params, n_r=400, n_phi=400):
    """Integral of P22(s) = D(m(s)) cos^4 over the slope plane (Heitz eq. 63-64).

    Substitution s = s0 + L t, an affine map (exact for any s0, L, Jacobian |det L|) that puts the lobe near
    the unit disc: L = Rz^T diag(alpha_x, alpha_y), s0 the ellipsoid's slope centre. Then polar coordinates with
    |t| = tan(psi) so the infinite plane maps to psi in [0, pi/2): Gauss-Legendre in psi, the periodic
    trapezoid rule in phi (spectrally accurate for a smooth periodic integrand)."""
    p = models.params_to_array(model, params)
    if model in ("ggx", "beckmann"):
        ax, ay, tz = p[0], p[0], 0.0
    elif model == "ellipsoid":
        ax, ay, tz = p[0], p[1], p[4]
    else:
        ax, ay, tz = p
    lmat = models.rot_z(tz)[:2, :2].T @ np.diag([ax, ay])
    s0 = np.zeros(2)
    if model == "ellipsoid":
        s0, q, _ = synthetic.ellipsoid_slope_quadric(models.matrix_a(model, p))
        lmat = np.linalg.inv(np.linalg.cholesky(q).T)
    x, w = np.polynomial.legendre.leggauss(n_r)
    psi = (x + 1.0) * math.pi / 4.0
    wpsi = w * math.pi / 4.0
    r = np.tan(psi)
    dr = 1.0 / np.cos(psi) ** 2
    phi = (np.arange(n_phi) + 0.5) * 2.0 * math.pi / n_phi
    rr, pp = np.meshgrid(r, phi, indexing="ij")
    t = np.column_stack([(rr * np.cos(pp)).ravel(), (rr * np.sin(pp)).ravel()])
    s = s0 + t @ lmat.T
    f = models.slope_density(model, p, s).reshape(rr.shape)
    jac = abs(np.linalg.det(lmat))
    return float(np.sum(f * rr * (wpsi * dr)[:, None]) * 2.0 * math.pi / n_phi * jac)


@pytest.mark.parametrize("model,params", ALL_CASES)
def test_normalization_in_slope_space(model, params):
    """Heitz eq. 9 in slope space: the integral of P22 = D cos^4 over all slopes is 1 (eq. 63).

    Tolerance 1e-10: the quadrature's own error, measured by doubling both node counts, is below 1e-13 for
    these cases; any wrong constant (pi, 2, alpha, ||A n||) is off by far more."""
    integral = _slope_space_integral(model, params)
    assert abs(integral - 1.0) < 1e-10, integral


# The hemisphere quadrature below is polar around n: lobes much narrower in one direction than the ring
# spacing (alpha 0.01 next to 0.4) or far off n are out of its reach, so it takes the moderate cases; the
# slope-space test above covers all of them.
HEMI_CASES = [c for c in ALL_CASES if c[1] not in ([0.01, 0.4, -1.2], [0.05, 0.02, 0.6, 0.1, -0.3])]


@pytest.mark.parametrize("model,params", HEMI_CASES)
def test_normalization_on_the_hemisphere(model, params):
    """Heitz eq. 9 directly: the integral of D(m) cos(theta) over the hemisphere, theta mapped by
    tan(theta) = c tan(psi); a second, independent quadrature of the same statement."""
    p = models.params_to_array(model, params)
    c = float(np.sqrt(p[0] * (p[1] if model not in ("ggx", "beckmann") else p[0])))
    x, w = np.polynomial.legendre.leggauss(600)
    psi = (x + 1.0) * math.pi / 4.0
    wpsi = w * math.pi / 4.0
    th = np.arctan(c * np.tan(psi))
    dth = c / np.cos(psi) ** 2 / (1.0 + (c * np.tan(psi)) ** 2)
    nphi = 400
    ph = (np.arange(nphi) + 0.5) * 2.0 * math.pi / nphi
    tt, pp = np.meshgrid(th, ph, indexing="ij")
    m = np.column_stack([(np.sin(tt) * np.cos(pp)).ravel(), (np.sin(tt) * np.sin(pp)).ravel(), np.cos(tt).ravel()])
    dd = models.d(model, p, m).reshape(tt.shape)
    integral = float(np.sum(dd * np.cos(tt) * np.sin(tt) * (wpsi * dth)[:, None]) * 2.0 * math.pi / nphi)
    assert abs(integral - 1.0) < 1e-6, integral


def _heitz_eq85(ax, ay, tz, m):
    """Anisotropic GGX, Heitz eq. 85, in the frame m' = Rz(theta_z) m, written with theta_m and phi_m."""
    mp = m @ models.rot_z(tz).T
    theta = np.arccos(np.clip(mp[:, 2], -1, 1))
    phi = np.arctan2(mp[:, 1], mp[:, 0])
    t2 = np.tan(theta) ** 2
    return 1.0 / (
        math.pi * ax * ay * np.cos(theta) ** 4 * (1.0 + t2 * (np.cos(phi) ** 2 / ax**2 + np.sin(phi) ** 2 / ay**2)) ** 2
    )


def test_ggx_is_the_untilted_ellipsoid():
    """Walter sec. 1 / 4.2: the ellipsoid with R = Rz is GTR2aniso (Heitz eq. 85) and with alpha_x = alpha_y GGX
    (Heitz eq. 71); the model ids ggx and ggx-aniso give the same values."""
    m = _random_dirs(2000, 1, zmin=1e-2)
    for ax, ay, tz in [(0.3, 0.3, 0.0), (0.2, 0.5, 0.4), (0.01, 0.7, -1.3), (2.0, 0.5, 3.0)]:
        ref = _heitz_eq85(ax, ay, tz, m)
        np.testing.assert_allclose(models.d("ellipsoid", [ax, ay, 0.0, 0.0, tz], m), ref, rtol=1e-11)
        np.testing.assert_allclose(models.d("ggx-aniso", [ax, ay, tz], m), ref, rtol=1e-11)
    a = 0.27
    theta = np.arccos(m[:, 2])
    eq71 = 1.0 / (math.pi * a * a * np.cos(theta) ** 4 * (1.0 + np.tan(theta) ** 2 / a**2) ** 2)
    np.testing.assert_allclose(models.d("ggx", [a], m), eq71, rtol=1e-11)


def test_beckmann_is_the_gaussian_slope_density():
    """Heitz eq. 81 and footnote 3: Beckmann's P22 is the bivariate normal with covariance
    Sigma = Rz^T diag(alpha_x^2, alpha_y^2) Rz / 2 in the scan frame (s' = Rz s)."""
    rng = np.random.default_rng(2)
    for ax, ay, tz in [(0.3, 0.3, 0.0), (0.2, 0.5, 0.4), (0.05, 0.6, 2.0), (1e-3, 2e-3, -0.3)]:
        s = rng.standard_normal((500, 2)) * max(ax, ay)
        rz = models.rot_z(tz)[:2, :2]
        sigma = rz.T @ np.diag([ax * ax, ay * ay]) @ rz / 2.0
        si = np.linalg.inv(sigma)
        log_gauss = -0.5 * np.einsum("ij,jk,ik->i", s, si, s) - math.log(2.0 * math.pi * math.sqrt(np.linalg.det(sigma)))
        # Compared as logarithms: the density spans 1e-300..1e3 here and denormals carry few digits.
        np.testing.assert_allclose(models.log_slope_density("beckmann-aniso", [ax, ay, tz], s), log_gauss, rtol=1e-12, atol=1e-10)
        if ax == ay:
            np.testing.assert_allclose(models.log_slope_density("beckmann", [ax], s), log_gauss, rtol=1e-12, atol=1e-10)


def test_ellipsoid_slope_density_is_a_sheared_ggx():
    """Completing the square in ||A^-T (-s, 1)||^2 (synthetic.ellipsoid_slope_quadric) gives the Student-like
    P22 of Heitz eq. 84, stretched by Q and sheared to the centre s0 (Heitz sec. 5.5). Its normalization in
    closed form, c = sqrt(det Q) / pi, is Walter eq. 1's 1 / (pi |A| ||A n||) constant: checks eq. 26."""
    rng = np.random.default_rng(3)
    for p in ([0.2, 0.5, 0.3, -0.2, 0.4], [0.05, 0.02, 0.6, 0.1, -0.3], [1.5, 0.7, -0.4, 0.5, 1.0]):
        a = models.ellipsoid_matrix(*p)
        s0, q, c = synthetic.ellipsoid_slope_quadric(a)
        assert c == pytest.approx(math.sqrt(np.linalg.det(q)) / math.pi, rel=1e-12)
        s = s0 + rng.standard_normal((400, 2)) * 0.5
        ds = s - s0
        ref = c / (1.0 + np.einsum("ij,jk,ik->i", ds, q, ds)) ** 2
        np.testing.assert_allclose(models.slope_density("ellipsoid", p, s), ref, rtol=1e-10)


def test_matrix_form_and_its_invariances():
    """Walter eq. 1 from any A: equal to the parameter form, and unchanged by c A and Q A (sec. 1)."""
    m = _random_dirs(1000, 4)
    p = [0.2, 0.5, 0.3, -0.2, 0.4]
    a = models.ellipsoid_matrix(*p)
    ref = models.log_d("ellipsoid", p, m)
    np.testing.assert_allclose(models.log_d_matrix(a, m), ref, rtol=1e-12, atol=1e-12)
    qmat = models.rotation(1.0, -2.0, 0.5)
    np.testing.assert_allclose(models.log_d_matrix(3.7 * qmat @ a, m), ref, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("model,params", ALL_CASES)
def test_gradient_matches_central_differences(model, params):
    """d ln D / d params against central differences. Step h = 1e-6 (relative for alphas): truncation error
    ~ h^2 |f'''| < 1e-10 and roundoff ~ eps |ln D| / h < 1e-8 for these values, so rtol 1e-5 with atol 1e-5
    (scaled by the gradient's size) leaves a margin of 100 over both and still catches any wrong term."""
    p = np.array(params, dtype=float)
    m = _random_dirs(300, 5, zmin=0.05)
    _, g = models.log_d_and_grad(model, p, m)
    names = models.PARAM_NAMES[model]
    for j, name in enumerate(names):
        h = 1e-6 * (p[j] if name.startswith("alpha") else 1.0)
        pp, pm = p.copy(), p.copy()
        pp[j] += h
        pm[j] -= h
        fd = (models.log_d(model, pp, m) - models.log_d(model, pm, m)) / (2 * h)
        scale = np.max(np.abs(fd)) + 1.0
        np.testing.assert_allclose(g[:, j], fd, rtol=1e-5, atol=1e-5 * scale, err_msg=f"{model} {name}")


@pytest.mark.parametrize("model", models.MODELS)
def test_extremes_no_nan(model):
    """alpha 1e-4 to 10, grazing directions, the pole and below the horizon: finite ln D above the horizon,
    D = 0 (ln D = -inf) at and below it (the X+ indicator), never NaN."""
    n = len(models.PARAM_NAMES[model])
    m = np.array([[0, 0, 1], [1, 0, 1e-9], [0.6, 0.8, 1e-12], [1, 0, 0], [0.3, 0.4, -0.5], [1e-9, 0, 1]], dtype=float)
    for alpha in (1e-4, 1e-2, 1.0, 10.0):
        p = {1: [alpha], 3: [alpha, 3 * alpha, 0.7], 5: [alpha, 3 * alpha, 0.5, -0.4, 0.7]}[n]
        ld, g = models.log_d_and_grad(model, p, m)
        assert not np.any(np.isnan(ld)) and not np.any(np.isnan(g))
        assert np.all(np.isfinite(ld[[0, 1, 2, 5]]))
        assert ld[3] == -np.inf and ld[4] == -np.inf


def test_bad_parameters_are_refused():
    with pytest.raises(ValueError, match="alpha"):
        models.log_d("ggx", [0.0], [[0, 0, 1]])
    with pytest.raises(ValueError, match="unknown model"):
        models.log_d("phong", [1.0], [[0, 0, 1]])
    with pytest.raises(ValueError, match="non-finite"):
        models.log_d("beckmann", [float("nan")], [[0, 0, 1]])
