"""The numpy pipeline of the end-to-end cross-check against closed forms and second algorithms."""

import math

import numpy as np
import pytest

from ndfitpy import endtoend
from ndfitpy.empirical import SlopeGrid, central_slopes, empirical_ndf, proj_solid_angle_primitive, rect_proj_solid_angle, remove_plane
from ndfitpy.lambert import LambertGrid
from ndfitpy.scanio import read_gsf, read_npy, write_gsf
from ndfitpy.x3p import HeightMap


def test_primitive_has_the_projected_solid_angle_density():
    """d2F/dxdy = (1 + x^2 + y^2)^-2 by central differences (Heitz eq. 64: (m.n) dw = cos^4 theta ds)."""
    h = 1e-3
    for x, y in [(0.0, 0.0), (0.3, -1.2), (2.5, 0.7), (-4.0, -3.0)]:
        f = proj_solid_angle_primitive
        mixed = (f(x + h, y + h) - f(x + h, y - h) - f(x - h, y + h) + f(x - h, y - h)) / (4 * h * h)
        assert mixed == pytest.approx((1 + x * x + y * y) ** -2, rel=1e-5)


def test_rect_integrals_tile_the_hemisphere_and_match_quadrature():
    """The whole slope plane is the hemisphere: W -> pi; a rectangle agrees with 2-D Gauss-Legendre."""
    big = 1e7
    assert rect_proj_solid_angle(-big, big, -big, big) == pytest.approx(math.pi, rel=1e-6)
    x, w = np.polynomial.legendre.leggauss(40)
    x0, x1, y0, y1 = -0.3, 0.9, 0.2, 1.7
    xs = x0 + (x1 - x0) * (x + 1) / 2
    ys = y0 + (y1 - y0) * (x + 1) / 2
    q = np.sum(np.outer(w, w) / (1 + xs[:, None] ** 2 + ys[None, :] ** 2) ** 2) * (x1 - x0) * (y1 - y0) / 4
    assert rect_proj_solid_angle(x0, x1, y0, y1) == pytest.approx(q, rel=1e-12)


def test_central_slopes_of_a_plane_and_its_removal():
    """A plane z = 3 + 0.2 x - 0.5 y has slopes (0.2, -0.5) at every interior point with valid neighbours; NaN
    points remove the stencils that touch them; plane removal leaves zero slopes."""
    ny, nx, dx, dy = 7, 9, 0.5, 0.25
    yy, xx = np.mgrid[0:ny, 0:nx]
    z = 3 + 0.2 * xx * dx - 0.5 * yy * dy
    z[3, 4] = np.nan
    s = central_slopes(HeightMap(z=z, dx=dx, dy=dy))
    assert len(s) == (ny - 2) * (nx - 2) - 5  # the NaN point itself and its four neighbours' stencils
    assert np.allclose(s, [0.2, -0.5], atol=1e-12)
    flat = remove_plane(HeightMap(z=z, dx=dx, dy=dy))
    assert np.allclose(central_slopes(flat), 0.0, atol=1e-12)


def test_slope_grid_normalizes_and_counts_every_sample_inside():
    rng = np.random.default_rng(3)
    s = rng.normal(0.1, 0.2, size=(20000, 2))
    g = SlopeGrid.around(s)
    b = g.bins(s)
    inside = np.sum(b.count)
    assert b.n_samples == len(s) and inside <= len(s) and inside > 0.999 * len(s)
    assert np.sum(b.d * b.proj_solid_angle) == pytest.approx(inside / len(s), rel=1e-12)


def test_lambert_jacobian_matches_finite_differences_and_tiles_the_hemisphere():
    doc = {"frame": {"center": [0.3, -0.2], "whiten": [[4.0, -1.0], [-1.0, 3.0]], "unwhiten": None},
           "options": {"cells_across": 15}}
    wh = np.array(doc["frame"]["whiten"])
    doc["frame"]["unwhiten"] = np.linalg.inv(wh).tolist()
    g = LambertGrid.from_ndf_json(doc)

    def mxy(p):
        r2 = np.sum(p * p, axis=1)
        m1 = p * np.sqrt(1 - r2 / 4)[:, None]
        s = g.center + (m1 / (1 - r2 / 2)[:, None]) @ g.unwhiten.T
        return -s / np.sqrt(1 + np.sum(s * s, axis=1))[:, None]

    p = np.array([[0.1, 0.2], [-0.7, 0.4], [1.0, -0.6]])
    h = 1e-6
    jx = (mxy(p + [h, 0]) - mxy(p - [h, 0])) / (2 * h)
    jy = (mxy(p + [0, h]) - mxy(p - [0, h])) / (2 * h)
    fd = np.abs(jx[:, 0] * jy[:, 1] - jx[:, 1] * jy[:, 0])
    jac, _ = g.jacobian(p)
    assert np.allclose(jac, fd, rtol=1e-7)
    # Each direction's cell: the Lambert point of its slope falls in it.
    cells = g.cell_of(np.array([[0.3, -0.2]]))
    assert cells[0] == (g.n // 2) * g.n + g.n // 2


def test_compare_ndfs_finds_the_same_counts_and_flags_a_wrong_w():
    """ndfit's cells rebuilt from a frame: counting the same slopes twice agrees exactly; a W scaled by 1e-3 on
    the verified cells is flagged."""
    rng = np.random.default_rng(5)
    s = rng.normal([0.1, -0.05], 0.15, size=(40000, 2))
    fr = {"center": [0.1, -0.05], "whiten": (np.eye(2) / 0.15).tolist(), "unwhiten": (np.eye(2) * 0.15).tolist()}
    g = LambertGrid.from_ndf_json({"frame": fr, "options": {"cells_across": 21}})
    cells = np.arange(g.n * g.n)
    row, col = np.divmod(cells, g.n)
    centre = np.column_stack([-math.sqrt(2) + (col + 0.5) * g.h, -math.sqrt(2) + (row + 0.5) * g.h])
    keep = np.hypot(centre[:, 0], centre[:, 1]) < math.sqrt(2) * 0.9
    w, om, ok = g.interior_integrals(cells[keep])
    count = np.bincount(g.cell_of(s), minlength=g.n * g.n)[keep]
    # Bin centres as ndfit writes them: directions; here the cell centres mapped back (inverse Lambert).
    pc = centre[keep]
    r2 = np.sum(pc * pc, axis=1)
    sl = g.center + (pc * np.sqrt(1 - r2 / 4)[:, None] / (1 - r2 / 2)[:, None]) @ g.unwhiten.T
    q = np.sqrt(1 + np.sum(sl * sl, axis=1))
    m = np.column_stack([-sl / q[:, None], 1 / q])
    n = float(count.sum())
    bins = [{"m": list(mm), "count": float(c), "proj_solid_angle": float(ww), "solid_angle": float(oo),
             "stderr": math.sqrt(max(c, 1)) / (n * ww)} for mm, c, ww, oo in zip(m, count, w, om)]
    inside = s[np.isin(g.cell_of(s), cells[keep])]
    doc = {"frame": fr, "options": {"cells_across": 21}, "n_samples": n, "bins": bins}
    good = endtoend.compare_ndfs(inside, doc)
    assert good["moved"] == 0 and good["w_err"] < 1e-12 and good["z_max"] < 1e-9
    for b in bins:
        b["proj_solid_angle"] *= 1.001
    bad = endtoend.compare_ndfs(inside, doc)
    assert bad["w_err"] > 9e-4 and bad["moved"] == 0


def test_gsf_and_npy_round_trip(tmp_path):
    z = np.arange(12, dtype=float).reshape(3, 4) * 1e-6
    z[1, 2] = np.nan
    hm = HeightMap(z=z, dx=2e-6, dy=3e-6)
    write_gsf(str(tmp_path / "a.gsf"), hm)
    back = read_gsf(str(tmp_path / "a.gsf"))
    assert back.dx == pytest.approx(2e-6) and back.dy == pytest.approx(3e-6)
    assert np.array_equal(np.isnan(back.z), np.isnan(z))
    assert np.allclose(back.z[~np.isnan(z)], z[~np.isnan(z)].astype(np.float32))
    np.save(tmp_path / "a.npy", z / 1e-6)
    n = read_npy(str(tmp_path / "a.npy"), dx=1e-6, z_scale=1e-6)
    assert np.array_equal(np.isnan(n.z), np.isnan(z)) and np.allclose(n.z[~np.isnan(z)], z[~np.isnan(z)])
    with pytest.raises(ValueError, match="a.npy"):
        read_gsf(str(tmp_path / "a.npy"))


def test_empirical_ndf_of_a_tilted_plane_is_one_cell():
    yy, xx = np.mgrid[0:20, 0:30]
    hm = HeightMap(z=0.1 * xx * 1e-6 + 0.05 * yy * 1e-6, dx=1e-6, dy=1e-6)
    s, b = empirical_ndf(hm, "none")
    assert np.allclose(s, [0.1, 0.05]) and np.count_nonzero(b.count) == 1
    s, b = empirical_ndf(hm, "plane")
    assert np.allclose(s, 0.0, atol=1e-9)
