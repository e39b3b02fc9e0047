"""ndfit.fit / ndfit.ndf against the `ndfit` binary on the same scans and options: the same parameters (to
1e-12; in fact bit for bit) and the same `ndfit.fit/1` document byte for byte apart from the timings."""

from __future__ import annotations

import csv
import json
import re

import numpy as np
import pytest

import ndfit
from conftest import real_scan_files, run_cli

TIMING = re.compile(r'("(?:read_ms|ndf_ms|fit_ms|optics_ms)": )[-+0-9.eE]+')


def without_timings(text: str) -> str:
    return TIMING.sub(r"\1T", text)


def cli_fit(ndfit_bin, tmp_path, scan, *args):
    out = tmp_path / "cli.fit.json"
    run_cli(ndfit_bin, "fit", scan, "-q", "-o", out, *args)
    return out.read_text()


def assert_same_fit(cli_text: str, fit: "ndfit.Fit"):
    py_text = fit.to_json()
    cli = json.loads(cli_text)
    assert fit.model == cli["model"]
    assert set(fit.params) == set(cli["params"])
    for k, v in cli["params"].items():
        assert abs(fit.params[k] - v) <= 1e-12 * max(1.0, abs(v)), (k, fit.params[k], v)
    assert fit.std_errors == cli["std_errors"]
    # The whole document, byte for byte, once the wall-clock times are masked.
    assert without_timings(py_text) == without_timings(cli_text)
    assert set(cli["timings"]) == set(json.loads(py_text)["timings"])


# (file, CLI flags, the same options for ndfit.fit)
SYNTH_CASES = [
    ("ell_aniso.x3p", ["--model", "ellipsoid", "--form", "none"], dict(model="ellipsoid", form="none")),
    ("ell_skew.x3p", ["--model", "auto", "--form", "none", "--max-theta", "60"], dict(model="auto", form="none", max_theta=60)),
    ("gauss.x3p", ["--model", "beckmann-aniso", "--normals", "triangles", "--ndf-cells", "41"],
     dict(model="beckmann-aniso", normals="triangles", ndf_cells=41)),
    ("gauss.x3p", ["--preset", "fast", "--objective", "logd"], dict(preset="fast", objective="logd")),
    ("gauss_holes.x3p", ["--model", "ggx-aniso", "--crop", "150x120+10+20", "--subsample", "2", "--form", "poly2", "--extra-starts", "2"],
     dict(model="ggx-aniso", crop="150x120+10+20", subsample=2, form="poly2", extra_starts=2)),
    ("ell_aniso.x3p", ["--model", "ggx", "--solver", "nelder-mead", "--target-count", "100"], dict(model="ggx", solver="nelder-mead", target_count=100)),
    ("ell_skew.x3p", ["--model", "ellipsoid", "--na", "0.8", "--tail", "unresolved", "--despike", "none"],
     dict(model="ellipsoid", na=0.8, tail="unresolved", despike="none")),
    ("gauss.x3p", ["--model", "ggx2"], dict(model="ggx2")),
]


@pytest.mark.parametrize("name,flags,opts", SYNTH_CASES, ids=[f"{c[0]}:{' '.join(c[1])}" for c in SYNTH_CASES])
def test_fit_matches_cli_on_synthetic_scans(synth_dir, ndfit_bin, tmp_path, name, flags, opts):
    scan = str(synth_dir / name)
    assert_same_fit(cli_fit(ndfit_bin, tmp_path, scan, *flags), ndfit.fit(scan, **opts))


def test_fit_of_a_read_scan_matches_cli(synth_dir, ndfit_bin, tmp_path):
    """A Scan read first and fitted later is the file fitted directly (input.path keeps the file's path)."""
    scan = str(synth_dir / "gauss_holes.x3p")
    s = ndfit.read(scan)
    assert_same_fit(cli_fit(ndfit_bin, tmp_path, scan, "--model", "beckmann-aniso"), ndfit.fit(s, model="beckmann-aniso"))
    assert_same_fit(cli_fit(ndfit_bin, tmp_path, scan, "--preset", "accurate", "--crop", "100x100+5+5"),
                    ndfit.fit(s, preset="accurate", crop="100x100+5+5"))


def test_fit_matches_cli_on_every_shared_real_scan(shared_scans, ndfit_bin, tmp_path):
    files = real_scan_files(shared_scans)
    assert len(files) >= 10, files
    for f in files:
        assert_same_fit(cli_fit(ndfit_bin, tmp_path, str(f)), ndfit.fit(str(f)))


def test_ndf_matches_cli_csv(synth_dir, ndfit_bin, tmp_path):
    scan = str(synth_dir / "gauss_holes.x3p")
    out = tmp_path / "ndf.csv"
    run_cli(ndfit_bin, "ndf", scan, "-o", out, "--normals", "triangles", "--form", "poly3")
    with open(out) as fh:
        rows = list(csv.DictReader(fh))
    e = ndfit.ndf(scan, normals="triangles", form="poly3")
    assert len(e) == len(rows) > 100
    col = lambda k: np.array([float(r[k]) for r in rows])  # noqa: E731
    # The CSV prints every digit (`{:e}` is the shortest round-trip form): equality is exact.
    np.testing.assert_array_equal(e.m, np.stack([col("mx"), col("my"), col("mz")], axis=1))
    for k in ("d", "stderr", "solid_angle", "proj_solid_angle"):
        np.testing.assert_array_equal(getattr(e, k), col(k), err_msg=k)
    np.testing.assert_array_equal(e.count, np.array([int(r["count"]) for r in rows], dtype=np.uint64))
    assert e.n_samples == int(e.count.sum())
    assert e.normals == "triangles"


def test_na_and_max_theta_must_agree(synth_dir):
    scan = str(synth_dir / "gauss.x3p")
    with pytest.raises(ndfit.NdfitError, match="disagree"):
        ndfit.fit(scan, model="ggx", na=0.5, max_theta=45)
    with pytest.raises(ndfit.NdfitError, match="despike"):
        ndfit.fit(scan, model="ggx", despike="mean")


def test_a_profile_fits_as_the_cli_fits_it(ndfit_bin, tmp_path):
    # One row of smooth heights (a profilometer's trace): ndfit.fit answers it as the CLI does, byte for byte,
    # the profile's warning first.
    rng = np.random.default_rng(5)
    kernel = np.exp(-0.5 * (np.arange(-30, 31) / 6.0) ** 2)
    z = np.convolve(rng.normal(size=1100), kernel, mode="valid")[:1024] * 1e-7
    npy = tmp_path / "profile.npy"
    np.save(npy, z[None, :])
    cli = cli_fit(ndfit_bin, tmp_path, npy, "--z-scale", "1", "--dx", "1e-6")
    fit = ndfit.fit(str(npy), z_scale=1.0, dx=1e-6)
    assert_same_fit(cli, fit)
    doc = json.loads(cli)
    assert doc["warnings"][0].startswith("profile: a profile (1 row of 1024 samples)")
    assert fit.answer is not None and fit.quality["verdict"] != "ok"
