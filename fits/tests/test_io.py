"""Reading the NDF CSV (data_formats/ndf_csv.md), writing ndfit.fit/1 JSON, and the command line."""

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from ndfitpy import fitjson, models, synthetic
from ndfitpy.bins import read_ndf_csv, write_ndf_csv
from ndfitpy.fit import fit


@pytest.fixture()
def bins():
    return synthetic.sampled_bins("ggx-aniso", [0.2, 0.3, 0.4], 50_000, synthetic.grid_for(0.3, 24, 32), seed=1)


def test_round_trip(tmp_path, bins):
    p = tmp_path / "ndf.csv"
    write_ndf_csv(p, bins)
    b = read_ndf_csv(p)
    np.testing.assert_allclose(b.m, bins.m, rtol=0, atol=1e-16)
    np.testing.assert_array_equal(b.count, bins.count)
    np.testing.assert_allclose(b.proj_solid_angle, bins.proj_solid_angle, rtol=1e-16)
    # d as the format defines it: count / (n_samples * proj_solid_angle)
    np.testing.assert_allclose(b.d, bins.count / (bins.n_samples * bins.proj_solid_angle), rtol=1e-15)


def test_columns_are_selected_by_name(tmp_path):
    p = tmp_path / "ndf.csv"
    p.write_text(
        "count,extra,proj_solid_angle,d,mz,my,mx\n"
        "5,foo,1.0,1.59,1.0,0.0,0.0\n"
        "0,bar,2.0,0.0,0.6,0.8,0.0\n"
    )
    b = read_ndf_csv(p)
    np.testing.assert_array_equal(b.m, [[0, 0, 1], [0, 0.8, 0.6]])
    np.testing.assert_array_equal(b.count, [5, 0])
    np.testing.assert_array_equal(b.proj_solid_angle, [1.0, 2.0])


HEADER = "mx,my,mz,d,count,proj_solid_angle\n"


@pytest.mark.parametrize(
    "text,needle",
    [
        ("", "empty file"),
        ("mx,my,mz,d\n0,0,1,1\n", "lacks column(s) count, proj_solid_angle"),
        (HEADER, "no bins"),
        (HEADER + "0,0,1,1,3,abc\n", "not a number"),
        (HEADER + "0,0,1,1,3,nan\n", "not finite"),
        (HEADER + "0,0,1,1,-3,1\n", "non-negative integer"),
        (HEADER + "0,0,1,1,2.5,1\n", "non-negative integer"),
        (HEADER + "0,0,2,1,3,1\n", "not a unit vector"),
        (HEADER + "0,0,1,1,3,-1\n", "negative"),
        (HEADER + "0,0,1,1,0,1\n", "every bin is empty"),
        (HEADER + "0,0,1,1,3,9\n", "sums to"),
        (HEADER + "0,0,1\n", "fields"),
    ],
)
def test_bad_files_give_one_clear_error(tmp_path, text, needle):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(ValueError) as e:
        read_ndf_csv(p)
    msg = str(e.value)
    assert str(p) in msg and needle in msg and "\n" not in msg


def test_missing_file(tmp_path):
    with pytest.raises(ValueError, match="cannot open"):
        read_ndf_csv(tmp_path / "nope.csv")


def test_fit_json_has_the_contract_keys(tmp_path, bins):
    res = fit(bins, "ggx-aniso")
    out = tmp_path / "fit.json"
    fitjson.write_fit(out, res, bins, {"nx": 10})
    doc = fitjson.read_fit(out)
    for key in ("schema", "model", "params", "matrix_a", "input", "objective", "quality", "std_errors"):
        assert key in doc
    assert doc["schema"] == "ndfit.fit/1" and doc["input"]["nx"] == 10
    assert set(doc["params"]) == {"alpha_x", "alpha_y", "theta_z"}
    # matrix_a describes the same D as the params (Walter eq. 1 from A vs from the parameters).
    m = bins.m[bins.m[:, 2] > 0.05]
    np.testing.assert_allclose(
        models.log_d_matrix(np.array(doc["matrix_a"]), m), models.log_d("ggx-aniso", doc["params"], m), rtol=1e-12
    )
    assert doc["objective"]["value"] == pytest.approx(res.value)
    assert not [f for f in os.listdir(tmp_path) if f.startswith(".tmp-")]


def test_beckmann_json_has_no_matrix(tmp_path, bins):
    res = fit(bins, "beckmann")
    doc = fitjson.write_fit(tmp_path / "b.json", res, bins)
    assert "matrix_a" not in doc


@pytest.mark.parametrize(
    "doc,needle",
    [
        ({"schema": "x"}, "schema"),
        ({"schema": "ndfit.fit/1", "model": "ggx", "params": {"alpha": 0.1}}, "missing required key 'input'"),
        ({"schema": "ndfit.fit/1", "model": "ggx", "params": {"alpha": 0.1}, "input": {}}, "matrix_a"),
        ({"schema": "ndfit.fit/1", "model": "nope", "params": {}, "input": {}}, "unknown model"),
        ({"schema": "ndfit.fit/1", "model": "ggx", "params": {"a": 1}, "input": {}}, "params"),
    ],
)
def test_read_fit_rejects_bad_documents(tmp_path, doc, needle):
    p = tmp_path / "f.json"
    p.write_text(json.dumps(doc))
    with pytest.raises(ValueError, match=needle):
        fitjson.read_fit(p)


def test_command_line(tmp_path, bins):
    csv = tmp_path / "ndf.csv"
    write_ndf_csv(csv, bins)
    out = tmp_path / "fit.json"
    r = subprocess.run(
        [sys.executable, "-m", "ndfitpy", "fit", str(csv), "--model", "ggx", "-o", str(out)],
        capture_output=True, text=True,
    )
    assert r.returncode == 0, r.stderr
    assert json.loads(out.read_text())["model"] == "ggx"
    r = subprocess.run([sys.executable, "-m", "ndfitpy", "canonical", str(out)], capture_output=True, text=True)
    assert r.returncode == 0 and "alpha" in r.stdout
    bad = tmp_path / "bad.csv"
    bad.write_text("x\n")
    r = subprocess.run(
        [sys.executable, "-m", "ndfitpy", "fit", str(bad), "--model", "ggx", "-o", str(tmp_path / "o.json")],
        capture_output=True, text=True,
    )
    assert r.returncode == 2
    assert r.stderr.count("\n") == 1 and str(bad) in r.stderr
    assert not (tmp_path / "o.json").exists()


def test_command_line_fits_the_student_lobes(tmp_path):
    """`--model student-aniso` from the command line: Poisson counts of a Student-t truth with a heavy tail
    (gamma 1.8) give back the truth's gamma and axes, and the document names the model and its parameters."""
    truth = [0.25, 0.12, 0.4, 1.8]
    bins = synthetic.expected_counts("student-aniso", truth, 1e6, synthetic.grid_for(0.25, 48, 64), poisson_seed=5)
    csv, out = tmp_path / "ndf.csv", tmp_path / "fit.json"
    write_ndf_csv(csv, bins)
    r = subprocess.run(
        [sys.executable, "-m", "ndfitpy", "fit", str(csv), "--model", "student-aniso", "-o", str(out)],
        capture_output=True, text=True,
    )
    assert r.returncode == 0, r.stderr
    doc = json.loads(out.read_text())
    assert doc["model"] == "student-aniso"
    p = doc["params"]
    assert abs(p["gamma"] / truth[3] - 1) < 0.05, p
    assert abs(p["alpha_x"] / truth[0] - 1) < 0.05 and abs(p["alpha_y"] / truth[1] - 1) < 0.05, p


def test_standard_errors_match_the_spread_of_repeated_fits():
    """The Fisher standard error of alpha against the empirical spread of 12 fits of independent samples
    (relative standard error of a 12-sample standard deviation: 1/sqrt(22) ~ 21%, so within 50%)."""
    alphas = []
    se = None
    for seed in range(12):
        b = synthetic.sampled_bins("ggx", [0.2], 20_000, synthetic.grid_for(0.2, 32, 32), seed=100 + seed)
        r = fit(b, "ggx", method="lbfgs")
        alphas.append(r.params["alpha"])
        if se is None:
            from ndfitpy import objective as obj
            se = obj.standard_errors("ggx", r.params, b)[0]
    spread = float(np.std(alphas, ddof=1))
    assert 0.5 * se < spread < 1.5 * se, (spread, se)


def test_rows_without_projected_area_are_ignored_but_counted(tmp_path):
    """A square grid over a disk has cells outside it (W = 0): their direction may be anything, even NaN;
    they are left out of the objective but their count (if any) stays in N (ndf_csv.md: N = sum of count)."""
    p = tmp_path / "ndf.csv"
    p.write_text(HEADER + "0,0,1,1,7,1.0\nnan,nan,nan,nan,0,0\n0,0.6,0.8,0.5,3,2.0\n")
    b = read_ndf_csv(p)
    assert b.n_samples == 10 and len(b.used()) == 2 and b.used().n_samples == 10
