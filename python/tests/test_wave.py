"""ndfit.wave against `ndfit wave` on the same scan and options: the same `ndfit.wave/1` document byte for
byte (the patches are summed in order: the same bits on any thread count) and the same diffuse-BRDF grid as
the `.npy` that `--grid N --grid-out` writes, bit for bit; from a path, a read Scan and a numpy array (used in
place); bad options raise NdfitError with the CLI's line."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

import ndfit
from conftest import run_cli
from test_api import cli_error

DX = 5e-7  # m: a 16-sample patch at 8 um
RAW = ["--dx", str(DX), "--z-scale", "1"]  # the .npy holds metres, without a spacing
RAW_KW = dict(dx=DX, z_scale=1.0)


def surface(nx: int = 96, ny: int = 80, seed: int = 5) -> np.ndarray:
    """A smooth random surface in metres (RMS 40 nm, correlation of a few samples) with one hole."""
    rng = np.random.default_rng(seed)
    f = np.fft.fft2(rng.standard_normal((ny, nx)))
    ky, kx = np.fft.fftfreq(ny)[:, None], np.fft.fftfreq(nx)[None, :]
    z = np.real(np.fft.ifft2(f * np.exp(-0.5 * (2 * np.pi * 2.5) ** 2 * (kx**2 + ky**2))))
    z *= 40e-9 / z.std()
    z[17, 23] = np.nan
    return np.ascontiguousarray(z)


@pytest.fixture(scope="module")
def heights() -> np.ndarray:
    return surface()


@pytest.fixture(scope="module")
def npy(tmp_path_factory, heights) -> str:
    p = tmp_path_factory.mktemp("wave") / "surface.npy"
    np.save(p, heights)
    return str(p)


# (CLI flags, the same options for ndfit.wave); every case adds RAW / RAW_KW for the .npy.
CASES = [
    (["--wavelength", "500,600", "--incidence", "0,40", "--coherence", "8", "--grid", "16"],
     dict(wavelength_nm=[500, 600], incidence_deg=[0, 40], coherence_um=8, grid=16)),
    (["--wavelength", "550", "--incidence", "60", "--azimuth", "30", "--coherence", "6", "--material", "Al", "--level-ratio", "1.3",
      "--form", "none", "--despike", "none", "--grid", "9"],
     dict(wavelength_nm=550.0, incidence_deg=60.0, azimuth_deg=30, coherence_um=6, material="Al", level_ratio=1.3, form="none",
          despike="none", grid=9)),
    # Every default: 450/550/650 nm, 0-75 degrees, sunlight's coherence (38 samples: 4 patches, a warning).
    (["--grid", "8"], dict(grid=8)),
]


def cli_wave(ndfit_bin, tmp_path, scan, *flags):
    out, prefix = tmp_path / "cli.wave.json", tmp_path / "cli.grid"
    run_cli(ndfit_bin, "wave", scan, "--quiet", *RAW, "-o", out, "--grid-out", prefix, *flags)
    return out.read_text(), np.load(str(prefix) + ".npy")


@pytest.mark.parametrize("flags,opts", CASES, ids=[" ".join(c[0]) for c in CASES])
def test_wave_matches_cli_byte_for_byte(ndfit_bin, tmp_path, npy, flags, opts):
    cli, cli_grid = cli_wave(ndfit_bin, tmp_path, npy, *flags)
    w = ndfit.wave(npy, threads=1, **RAW_KW, **opts)
    assert w.to_json() == cli
    doc = json.loads(cli)
    assert w.to_dict() == doc
    assert w.records == doc["records"] and w.patches == doc["patches"] and w.warnings == doc["warnings"]
    assert len(w) == len(doc["records"])
    n = opts["grid"]
    assert w.grid.dtype == np.float64 and w.grid.shape == cli_grid.shape
    assert w.grid.shape[2:] == (n, n) and w.grid.shape[0] * w.grid.shape[1] == len(w)
    assert w.grid.tobytes() == cli_grid.tobytes()  # bit for bit
    # A scan read first, on every core, is the file computed directly.
    again = ndfit.wave(ndfit.read(npy, **RAW_KW), **opts)
    assert again.to_json() == cli and again.grid.tobytes() == cli_grid.tobytes()


def test_numpy_array_in_place(ndfit_bin, tmp_path, npy, heights):
    flags = ["--wavelength", "633", "--incidence", "0,20,70", "--coherence", "10", "--form", "none", "--despike", "none"]
    cli, cli_grid = cli_wave(ndfit_bin, tmp_path, npy, *flags, "--grid", "12")
    scan = ndfit.Scan(heights, DX)
    assert np.shares_memory(scan.heights, heights)  # the array itself, not a copy
    w = ndfit.wave(scan, wavelength_nm=633, incidence_deg=(0, 20, 70), coherence_um=10, form="none", despike="none", grid=12)
    assert w.to_json() == cli and w.grid.tobytes() == cli_grid.tobytes()
    assert not w.grid.flags.writeable
    # Without `grid`, no grid; the records are the document's, wavelengths outer.
    w = ndfit.wave(scan, wavelength_nm=np.array([450.0, 650.0]), incidence_deg=[10, 50], coherence_um=10)
    assert w.grid is None
    assert [(r["wavelength_nm"], r["theta_deg"]) for r in w.records] == [(450, 10), (450, 50), (650, 10), (650, 50)]
    for r in w.records:
        assert 0.0 <= r["specular"] <= 1.0 and r["diffuse_albedo"] >= 0.0
    assert "4 records" in repr(w)


def test_bad_input_raises_the_cli_line(ndfit_bin, tmp_path, npy, heights):
    def both(flags, **kwargs):
        with pytest.raises(ndfit.NdfitError) as ei:
            ndfit.wave(npy, **RAW_KW, **kwargs)
        assert str(ei.value) == cli_error(ndfit_bin, "wave", npy, *RAW, "--quiet", *flags)
        assert ei.value.kind == "invalid_input"
        return str(ei.value)

    assert both(["--wavelength", "0"], wavelength_nm=0).endswith("wavelength 0 nm is not a positive number")
    both(["--wavelength", "550,-1"], wavelength_nm=[550, -1])
    both(["--wavelength", "NaN"], wavelength_nm=math.nan)
    assert "larger than the scan" in both(["--coherence", "100"], coherence_um=100)
    assert "at least 4 per side" in both(["--coherence", "1.5"], coherence_um=1.5)
    both(["--coherence", "0"], coherence_um=0)
    both(["--incidence", "10,95"], incidence_deg=[10, 95])
    both(["--level-ratio", "3"], level_ratio=3)
    # The grid: the CLI's check, with the keyword's name.
    cli = cli_error(ndfit_bin, "wave", npy, *RAW, "--quiet", "--grid", "0")
    for n in (0, -3, 5000):
        with pytest.raises(ndfit.NdfitError) as ei:
            ndfit.wave(npy, **RAW_KW, grid=n)
        assert str(ei.value) == f"{npy}: grid {n} is outside 1..=4096" and ei.value.kind == "invalid_input"
    assert cli == f"{npy}: --grid 0 is outside 1..=4096"
    # An array's errors name `<array>`.
    with pytest.raises(ndfit.NdfitError, match=r"^<array>: the coherence patch .* is larger than the scan"):
        ndfit.wave(ndfit.Scan(heights, DX), coherence_um=100)
    missing = str(tmp_path / "missing.x3p")
    with pytest.raises(ndfit.NdfitError) as ei:
        ndfit.wave(missing)
    assert str(ei.value) == cli_error(ndfit_bin, "wave", missing) and ei.value.kind == "io"
    for kwargs, pattern in [
        (dict(material="Zn"), "unknown material 'Zn'"),
        (dict(wavelength_nm="blue"), "wavelength_nm must be a number or a sequence"),
        (dict(incidence_deg=[0, "x"]), "incidence_deg must be a number or a sequence"),
        (dict(form="sphere"), "unknown form"),
        (dict(threads=0), "threads must be at least 1"),
    ]:
        with pytest.raises(ndfit.NdfitError, match=pattern):
            ndfit.wave(npy, **RAW_KW, **kwargs)


def test_fit_carries_the_regime_and_a_mirror_answer():
    # White heights of 0.1 nm RMS at 0.5 um: the mirror share at 450 nm and normal incidence is
    # exp(-(4 pi 0.1 / 450)^2) = 0.99992 (less the patches' own spread): light sees a mirror.
    z = np.random.default_rng(3).normal(0.0, 1e-10, (256, 256))
    fit = ndfit.fit(ndfit.Scan(z, dx=DX))
    assert fit.regime == "wave" and fit.answer == "mirror"
    o = fit.optics
    assert len(o["specular"]) == 15 and all(s["weight"] > 0.99 for s in o["specular"])
    doc = json.loads(fit.to_json())
    assert doc["optics"]["regime"] == "wave" and doc["selection"]["answer"] == "mirror"
    one = ndfit.fit(ndfit.Scan(z, dx=DX), model="ggx")
    assert one.regime is None and one.answer is None
