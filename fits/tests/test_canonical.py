"""Canonical parameters: same D, unique representative, and the documented choices."""

import math

import numpy as np
import pytest

from ndfitpy import canonical, models


def _dirs(n=800, seed=0):
    rng = np.random.default_rng(seed)
    v = rng.standard_normal((n, 3))
    v[:, 2] = np.abs(v[:, 2]) + 1e-3
    return v / np.linalg.norm(v, axis=1)[:, None]


def _random_ellipsoids(n, seed):
    rng = np.random.default_rng(seed)
    out = []
    for _ in range(n):
        ax, ay = np.exp(rng.uniform(np.log(1e-3), np.log(3.0), 2))
        tx, ty = rng.uniform(-0.6, 0.6, 2)
        tz = rng.uniform(-4.0, 4.0)
        out.append([ax, ay, tx, ty, tz])
    return out


@pytest.mark.parametrize("p", _random_ellipsoids(40, 1))
def test_canonical_ellipsoid_keeps_d_and_is_in_range(p):
    """The canonical parameters describe the same D (compared as ln D, rtol 1e-9: eigen-decomposition round
    trip costs a few ulps times the condition number alpha_max/alpha_min <= 3000) and satisfy the rules."""
    m = _dirs()
    c = canonical.canonical("ellipsoid", p)
    cp = models.params_to_array("ellipsoid", c)
    np.testing.assert_allclose(models.log_d("ellipsoid", cp, m), models.log_d("ellipsoid", p, m), rtol=1e-9, atol=1e-9)
    assert cp[0] >= cp[1] > 0
    assert -math.pi / 2 < cp[4] <= math.pi / 2
    # Small tilts stay small: the third axis is the one nearest n (|tilt| < 0.6 rad in, so < 0.6*sqrt(2) out).
    assert abs(cp[2]) < 0.85 and abs(cp[3]) < 0.85
    # Idempotent.
    c2 = models.params_to_array("ellipsoid", canonical.canonical("ellipsoid", cp))
    np.testing.assert_allclose(c2, cp, atol=1e-9)


def test_canonical_is_identity_inside_the_canonical_region():
    for p in ([0.5, 0.2, 0.3, -0.2, 0.4], [0.1, 0.1 - 1e-3, 0.0, 0.0, 0.0], [2.0, 0.01, -0.4, 0.5, 1.5]):
        np.testing.assert_allclose(
            models.params_to_array("ellipsoid", canonical.canonical("ellipsoid", p)), p, atol=1e-10
        )


def test_equivalent_parameterizations_meet():
    """Walter sec. 1: cA and QA give the same D. Two equivalent forms in parameters: (tx, ty, tz) and
    (-tx, -ty, tz + pi) (left factor Rz(pi)), and (ax, ay, tz) vs (ay, ax, tz + pi/2) untilted."""
    p = np.array([0.3, 0.1, 0.2, -0.15, 0.7])
    q = np.array([0.3, 0.1, -0.2, 0.15, 0.7 + math.pi])
    a = canonical.canonical_from_matrix(models.ellipsoid_matrix(*p))
    np.testing.assert_allclose(models.params_to_array("ellipsoid", canonical.canonical("ellipsoid", q)), a, atol=1e-10)
    qa = 2.5 * models.rotation(0.4, -1.0, 2.0) @ models.ellipsoid_matrix(*p)
    np.testing.assert_allclose(canonical.canonical_from_matrix(qa), a, atol=1e-10)
    u = canonical.canonical("ellipsoid", [0.1, 0.3, 0.0, 0.0, 0.2])
    np.testing.assert_allclose(list(u.values()), [0.3, 0.1, 0.0, 0.0, 0.2 + math.pi / 2 - math.pi], atol=1e-10)
    for model in ("ggx-aniso", "beckmann-aniso"):
        c = canonical.canonical(model, [0.1, 0.3, 0.2])
        np.testing.assert_allclose(list(c.values()), [0.3, 0.1, 0.2 + math.pi / 2 - math.pi], atol=1e-12)
        m = _dirs()
        np.testing.assert_allclose(
            models.log_d(model, list(c.values()), m), models.log_d(model, [0.1, 0.3, 0.2], m), rtol=1e-12
        )


def test_euler_angles_round_trip():
    rng = np.random.default_rng(5)
    for _ in range(50):
        t = rng.uniform([-1.5, -1.5, -3.1], [1.5, 1.5, 3.1])
        np.testing.assert_allclose(canonical.euler_xyz(models.rotation(*t)), t, atol=1e-12)


def test_isotropic_models_are_already_canonical():
    assert canonical.canonical("ggx", [0.2]) == {"alpha": 0.2}
    assert canonical.canonical("beckmann", {"alpha": 0.4}) == {"alpha": 0.4}
