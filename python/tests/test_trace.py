"""ndfit.trace against `ndfit trace` on the same scan and options: the same `ndfit.trace/1` document byte
for byte (a seed gives the same trace on any number of threads), from a path and from a read Scan; the
binned tables add up to the document's energies; bad input raises NdfitError with the CLI's line."""

from __future__ import annotations

import json

import numpy as np
import pytest

import ndfit
from conftest import run_cli
from test_api import cli_error

LUMA = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709, the luminance the document reports

# (CLI flags, the same options for ndfit.trace)
CASES = [
    (["--incidence", "0,50", "--rays", "40000", "--seed", "7", "--bounces", "8"], dict(incidence=[0, 50], rays=40000, seed=7, bounces=8)),
    (
        ["--incidence", "65", "--azimuth", "30", "--material", "Al", "--rays", "30000", "--bins", "16x24", "--border", "open",
         "--form", "none", "--despike", "none", "--tolerance", "0.1"],
        dict(incidence=65.0, azimuth=30, material="Al", rays=30000, bins="16x24", border="open", form="none", despike="none",
             tolerance=0.1),
    ),
]


def cli_trace(ndfit_bin, tmp_path, scan, *flags) -> str:
    out = tmp_path / "cli.trace.json"
    run_cli(ndfit_bin, "trace", scan, "--quiet", "-o", out, *flags)
    return out.read_text()


@pytest.mark.parametrize("flags,opts", CASES, ids=[" ".join(c[0]) for c in CASES])
def test_trace_matches_cli_byte_for_byte(synth_dir, ndfit_bin, tmp_path, flags, opts):
    scan = str(synth_dir / "gauss_holes.x3p")
    cli = cli_trace(ndfit_bin, tmp_path, scan, *flags)
    t = ndfit.trace(scan, threads=1, **opts)
    assert t.to_json() == cli
    assert t.to_dict() == json.loads(cli)
    # A scan read first is the file traced directly.
    assert ndfit.trace(ndfit.read(scan), **opts).to_json() == cli


def test_tables_add_up_to_the_document(synth_dir):
    t = ndfit.trace(str(synth_dir / "gauss.x3p"), incidence=[0, 60], rays=20000, bounces=4, bins="12x20")
    assert len(t) == 2 and t.bins == (12, 20)
    psa = t.proj_solid_angle()
    assert psa.shape == (12, 20) and abs(psa.sum() - np.pi) < 1e-12
    for k, rec in enumerate(t.incidences):
        tab = t.tables(k)
        assert tab["single"].shape == (12, 20, 3) and tab["var_total"].shape == (12, 20)
        single = float((tab["single"].sum(axis=(0, 1)) * LUMA).sum())
        multi = float((tab["multi"].sum(axis=(0, 1)) * LUMA).sum())
        model = float((tab["model"].sum(axis=(0, 1)) * LUMA).sum())
        assert single == pytest.approx(rec["albedo_by_bounce"][0], rel=1e-12)
        assert single + multi == pytest.approx(rec["albedo"], rel=1e-12)
        assert model == pytest.approx(rec["single"]["albedo_model"], rel=1e-12)
    with pytest.raises(ndfit.NdfitError, match="out of range"):
        t.tables(2)
    assert t.verdict["verdict"] in ("holds", "does_not_hold")


def test_bad_input_raises_the_cli_line(synth_dir, ndfit_bin, tmp_path):
    scan = str(synth_dir / "gauss.x3p")
    missing = str(tmp_path / "missing.x3p")
    with pytest.raises(ndfit.NdfitError) as ei:
        ndfit.trace(missing)
    assert str(ei.value) == cli_error(ndfit_bin, "trace", missing) and ei.value.kind == "io"
    with pytest.raises(ndfit.NdfitError) as ei:
        ndfit.trace(scan, incidence=[10, 95])
    assert str(ei.value) == cli_error(ndfit_bin, "trace", scan, "--incidence", "10,95")
    for kwargs, pattern in [
        (dict(material="Zn"), "unknown material 'Zn'"),
        (dict(bins="3"), "is not THETAxPHI bins"),
        (dict(border="mirror"), "unknown border"),
        (dict(bounces=0), r"bounces must be in \[1, 1000\]"),
        (dict(incidence="forty"), "incidence must be a number or a sequence"),
        (dict(form="sphere"), "unknown form"),
    ]:
        with pytest.raises(ndfit.NdfitError, match=pattern):
            ndfit.trace(scan, **kwargs)
