"""The Python API itself: arrays in equal files in, zero-copy heights, model evaluation against closed
forms, and bad input raising NdfitError with one line naming the file."""

from __future__ import annotations

import json
import pickle

import numpy as np
import pytest

import ndfit
from conftest import run_cli


def gaussian_surface(ny, nx, seed, dx):
    """A smooth random surface (filtered white noise), metres, with some NaN holes."""
    rng = np.random.default_rng(seed)
    w = rng.standard_normal((ny, nx))
    k = np.fft.rfft2(w)
    fy = np.fft.fftfreq(ny)[:, None]
    fx = np.fft.rfftfreq(nx)[None, :]
    h = np.fft.irfft2(k * np.exp(-((fx / 0.06) ** 2 + (fy / 0.1) ** 2)), s=(ny, nx))
    h *= 0.2 * dx / np.std(np.diff(h, axis=1))
    h[rng.random((ny, nx)) < 0.02] = np.nan
    return h


def test_array_in_equals_file_in(tmp_path):
    dx, dy = 1e-6, 1.5e-6
    h = gaussian_surface(180, 200, 7, dx)
    path = tmp_path / "surface.npy"
    np.save(path, h)
    from_file = ndfit.fit(str(path), model="ggx-aniso", dx=dx, dy=dy, z_scale=1.0)
    from_array = ndfit.fit(ndfit.Scan(h, dx=dx, dy=dy), model="ggx-aniso")
    assert from_array.params == from_file.params
    assert from_array.std_errors == from_file.std_errors
    a, f = from_array.to_dict(), from_file.to_dict()
    assert a["input"]["path"] == "<array>" and f["input"]["path"] == str(path)
    assert a["input"]["format"] == "array" and f["input"]["format"] == "npy"
    for d in (a, f):
        d.pop("timings"), d.pop("input")
    assert a == f
    # The NDFs too, bin for bin; and a float32 / Fortran-ordered array is the same scan.
    e1, e2 = ndfit.ndf(str(path), dx=dx, dy=dy, z_scale=1.0), ndfit.ndf(ndfit.Scan(np.asfortranarray(h), dx=dx, dy=dy))
    np.testing.assert_array_equal(e1.count, e2.count)
    np.testing.assert_array_equal(e1.d, e2.d)
    h32 = h.astype(np.float32)
    s32 = ndfit.Scan(h32, dx=dx, dy=dy)
    np.testing.assert_array_equal(s32.heights, h32.astype(np.float64))


def test_heights_are_the_scan_buffer_not_a_copy(tmp_path):
    h = np.arange(12.0).reshape(3, 4) * 1e-7
    h[1, 2] = np.nan
    np.save(tmp_path / "s.npy", h)
    s = ndfit.read(str(tmp_path / "s.npy"), dx=2e-6, z_scale=1.0)
    a, b = s.heights, s.heights
    assert a.shape == (3, 4) and a.dtype == np.float64
    np.testing.assert_array_equal(a, h)
    # Two reads of the property share one buffer, owned by the scan (a float64 .npy: the file's map).
    assert a.ctypes.data == b.ctypes.data and a.base is s
    assert not a.flags.writeable
    with pytest.raises(ValueError):
        a[0, 0] = 1.0
    assert (s.nx, s.ny, s.shape, s.dx, s.dy, s.format, s.invalid) == (4, 3, (3, 4), 2e-6, 2e-6, "npy", 1)
    assert s.meta["format"] == "npy"
    # The array outlives the Python scan object that owned it.
    del s
    np.testing.assert_array_equal(a, h)


def test_a_float64_array_is_used_in_place():
    """Scan over a C-ordered float64 array: no copy in, none out; other arrays are converted once, and
    infinities are masked in a copy (the caller's array is never written)."""
    h = np.linspace(0, 1e-6, 64 * 48).reshape(48, 64)
    s = ndfit.Scan(h, dx=1e-6)
    assert np.shares_memory(s.heights, h) and not s.heights.flags.writeable
    assert s.shape == (48, 64) and s.format == "array" and s.path is None
    f32 = ndfit.Scan(h.astype(np.float32), dx=1e-6)
    assert not np.shares_memory(f32.heights, h)
    g = h.copy()
    g[3, 4] = np.inf
    si = ndfit.Scan(g, dx=1e-6)
    assert not np.shares_memory(si.heights, g) and np.isinf(g[3, 4]) and np.isnan(si.heights[3, 4])
    assert si.invalid == 1 and ndfit.Scan(h, dx=1e-6).invalid == 0
    # The masked copy fits as the array with NaN in place of the infinity.
    g2 = g.copy()
    g2[3, 4] = np.nan
    assert ndfit.fit(si, model="ggx", form="none").params == ndfit.fit(ndfit.Scan(g2, dx=1e-6), model="ggx", form="none").params


def test_read_x3p_meta_and_spacing(synth_dir):
    s = ndfit.read(str(synth_dir / "gauss_holes.x3p"))
    assert (s.nx, s.ny) == (200, 220)
    assert s.dx == pytest.approx(5e-7, rel=1e-12) and s.dy == pytest.approx(7e-7, rel=1e-12)
    assert s.format == "x3p" and s.meta["format"] == "x3p"
    assert 0.03 < np.isnan(s.heights).mean() < 0.07  # --holes 0.05


def ggx_d(alpha, m):
    """Isotropic GGX D (Walter et al. 2007 eq. 33), independently of the library."""
    cos2 = m[:, 2] ** 2
    tan2 = (1 - cos2) / cos2
    return alpha**2 / (np.pi * cos2**2 * (alpha**2 + tan2) ** 2)


def ggx_g1(alpha, u):
    """Smith G1 of isotropic GGX for m = n (Walter et al. 2007 eq. 34), independently of the library."""
    tan2 = (1 - u[:, 2] ** 2) / u[:, 2] ** 2
    return 2.0 / (1.0 + np.sqrt(1.0 + alpha**2 * tan2))


def unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def test_d_and_g1_against_closed_forms(synth_dir):
    f = ndfit.fit(str(synth_dir / "ell_aniso.x3p"), model="ggx", form="none")
    a = f.params["alpha"]
    assert 0.15 < a < 0.4
    rng = np.random.default_rng(1)
    m = unit(np.c_[rng.normal(size=(500, 2)) * 0.5, np.ones(500)])
    np.testing.assert_allclose(f.d(m), ggx_d(a, m), rtol=1e-12)
    assert f.d([0.0, 0.0, 1.0]) == pytest.approx(1 / (np.pi * a * a), rel=1e-12)
    np.testing.assert_allclose(f.g1(m, [0.0, 0.0, 1.0]), ggx_g1(a, m), rtol=1e-12)
    # Normalization (projected area): the integral of D(m) m.z over the hemisphere is 1 (midpoint rule in
    # theta, phi; D is radially symmetric, so phi only checks the evaluation).
    nt, nphi = 4000, 8
    th = (np.arange(nt) + 0.5) * (np.pi / 2) / nt
    ph = (np.arange(nphi) + 0.5) * 2 * np.pi / nphi
    T, P = np.meshgrid(th, ph, indexing="ij")
    dirs = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], axis=-1).reshape(-1, 3)
    integrand = f.d(dirs) * dirs[:, 2] * np.sin(T).ravel()
    assert integrand.sum() * (np.pi / 2 / nt) * (2 * np.pi / nphi) == pytest.approx(1.0, abs=1e-5)
    # GGX is an ellipsoid special case: A = diag(alpha, alpha, 1) (Walter et al. 2023 sec. 3).
    np.testing.assert_allclose(f.matrix_a, np.diag([a, a, 1.0]), atol=1e-15)
    with pytest.raises(ndfit.NdfitError, match="u has 2 rows but m has 3"):
        f.g1(m[:2], m[:3])
    with pytest.raises(ndfit.NdfitError, match=r"shape \(n, 3\)"):
        f.d(np.ones((4, 2)))


def test_fit_json_round_trips_and_pickles(synth_dir, ndfit_bin, tmp_path):
    scan = str(synth_dir / "ell_skew.x3p")
    out = tmp_path / "f.json"
    run_cli(ndfit_bin, "fit", scan, "--model", "ellipsoid", "--form", "none", "-q", "-o", out)
    f = ndfit.Fit.from_json(out.read_text())
    assert f.to_json() == out.read_text()
    assert f.model == "ellipsoid" and f.param_names == ["alpha_x", "alpha_y", "theta_x", "theta_y", "theta_z"]
    assert f.matrix_a.shape == (3, 3)
    g = pickle.loads(pickle.dumps(f))
    assert g.to_json() == f.to_json()
    m = unit([[0.1, 0.2, 1.0], [0.0, 0.0, 1.0]])
    np.testing.assert_array_equal(g.d(m), f.d(m))
    assert f.verdict in ("ok", "misfit", "unresolved") and f.verdict == json.loads(f.to_json())["quality"]["verdict"]


def cli_error(ndfit_bin, *args) -> str:
    r = run_cli(ndfit_bin, *args, check=False)
    assert r.returncode != 0
    line = r.stderr.strip().splitlines()[-1]
    assert line.startswith("ndfit: ")
    return line[len("ndfit: "):]


def test_bad_files_raise_the_cli_error(tmp_path, ndfit_bin):
    """Missing, truncated and foreign files: NdfitError with the very line the CLI prints."""
    missing = str(tmp_path / "missing.x3p")
    trunc = tmp_path / "trunc.x3p"
    trunc.write_bytes(b"PK\x03\x04" + b"\x00" * 40)
    junk = tmp_path / "notes.opd"
    junk.write_bytes(b"this is not a Wyko file at all\n" * 20)
    npy_no_dx = tmp_path / "nodx.npy"
    np.save(npy_no_dx, np.zeros((8, 8)))
    for path in (missing, str(trunc), str(junk), str(npy_no_dx)):
        expected = cli_error(ndfit_bin, "fit", path)
        for call in (ndfit.fit, ndfit.ndf, ndfit.read):
            with pytest.raises(ndfit.NdfitError) as ei:
                call(path)
            msg = str(ei.value)
            assert "\n" not in msg and msg.startswith(path + ": "), msg
            if call is not ndfit.read:
                assert msg == expected
        assert ei.value.kind in ("io", "unknown_format", "corrupt", "missing_option", "unsupported")
    with pytest.raises(ndfit.NdfitError) as ei:
        ndfit.read(missing)
    assert ei.value.kind == "io"


@pytest.mark.parametrize(
    "kwargs,pattern",
    [
        (dict(model="cooktorrance"), "model: "),
        (dict(form="sphere"), "unknown form"),
        (dict(ndf_cells=4), "must be odd"),
        (dict(ndf_cells=2001), "between 3 and 1023"),
        (dict(target_count=0.5), "at least 1"),
        (dict(max_theta=0.0), r"\(0, 90\]"),
        (dict(max_theta=120.0), r"\(0, 90\]"),
        (dict(extra_starts=5), "between 0 and 4"),
        (dict(objective="l2"), "objective: "),
        (dict(solver="newton"), "solver: "),
        (dict(normals="sobel"), "normals: "),
        (dict(crop="10x10"), "not NXxNY"),
        (dict(crop="500x500+0+0"), "crop"),
        (dict(subsample=0), "subsampl"),
        (dict(preset="turbo"), "preset: "),
        (dict(threads=0), "threads"),
    ],
)
def test_bad_options_raise(synth_dir, kwargs, pattern):
    with pytest.raises(ndfit.NdfitError, match=pattern):
        ndfit.fit(str(synth_dir / "gauss.x3p"), **kwargs)


def test_a_given_spacing_is_refused_even_where_the_file_carries_one(synth_dir):
    """A negative, zero or non-finite dx/dy is refused, also for an X3P (which carries its own spacing)."""
    for bad in [-1e-6, 0.0, float("nan"), float("inf")]:
        with pytest.raises(ndfit.NdfitError, match="--dx must be a finite positive length"):
            ndfit.read(str(synth_dir / "gauss.x3p"), dx=bad)
        with pytest.raises(ndfit.NdfitError, match="--dy must be a finite positive length"):
            ndfit.fit(str(synth_dir / "gauss.x3p"), dy=bad)


def test_bad_arrays_and_arguments_raise():
    with pytest.raises(ndfit.NdfitError, match="2D"):
        ndfit.Scan(np.zeros(10), dx=1e-6)
    for dx, dy in [(-1e-6, None), (0.0, None), (float("nan"), None), (1e-6, float("inf")), (1e-6, -1e-6)]:
        with pytest.raises(ndfit.NdfitError, match="spacing must be finite and positive"):
            ndfit.Scan(np.zeros((4, 4)), dx=dx, dy=dy)
    with pytest.raises(ndfit.NdfitError, match="not an array of numbers"):
        ndfit.Scan([["a", "b"], ["c", "d"]], dx=1e-6)
    with pytest.raises(ndfit.NdfitError, match="empty grid"):
        ndfit.Scan(np.zeros((0, 5)), dx=1e-6)
    s = ndfit.Scan(np.zeros((32, 32)), dx=1e-6)
    with pytest.raises(ndfit.NdfitError, match="already read"):
        ndfit.fit(s, dx=1e-6)
    with pytest.raises(ndfit.NdfitError, match="expected an ndfit.Scan or a path, got int"):
        ndfit.fit(42)
    # No valid point: the library's message, labelled <array> where a file would give its path.
    with pytest.raises(ndfit.NdfitError, match=r"^<array>: 0 valid points") as ei:
        ndfit.fit(ndfit.Scan(np.full((32, 32), np.nan), dx=1e-6))
    assert ei.value.kind == "bad_data"
    with pytest.raises(TypeError):
        ndfit.fit(s, no_such_option=1)
