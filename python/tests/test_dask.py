"""ndfit.dask.fit_many on a 2-worker LocalCluster against `ndfit batch --jobs 2` on the same scans: the same
rows (status, model, every parameter bit for bit, verdict, the error line of a broken scan)."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import ndfit
from conftest import real_scan_files, run_cli

pd = pytest.importorskip("pandas")
distributed = pytest.importorskip("dask.distributed")
from ndfit.dask import COLUMNS, PARAM_COLUMNS, fit_many  # noqa: E402


@pytest.fixture(scope="module")
def cluster():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as c:
        yield c


@pytest.fixture(scope="module")
def batch_dir(synth_dir, tmp_path_factory):
    """The synthetic scans, a truncated X3P and a file of the wrong content, in one folder."""
    d = tmp_path_factory.mktemp("batch_in")
    for f in sorted(synth_dir.glob("*.x3p")):
        shutil.copy(f, d / f.name)
    (d / "broken.x3p").write_bytes(b"PK\x03\x04" + b"\x00" * 64)
    (d / "sub").mkdir()
    (d / "sub" / "noise.plu").write_bytes(os.urandom(2000))
    shutil.copy(synth_dir / "gauss.x3p", d / "sub" / "gauss_copy.x3p")
    return d


def run_batch(ndfit_bin, root, out, *args):
    r = run_cli(ndfit_bin, "batch", root, "-o", out, "--jobs", "2", *args, check=False)
    assert r.returncode in (0, 2), r.stderr
    with open(out / "summary.json") as fh:
        return {e["path"]: e for e in json.load(fh)["entries"]}


def assert_rows_match_batch(df, root, entries):
    assert list(df.columns) == COLUMNS
    keys = [os.path.relpath(p, root).replace(os.sep, "/") for p in df["path"]]
    assert sorted(keys) == sorted(entries), (keys, list(entries))
    for key, row in zip(keys, df.to_dict("records")):
        e = entries[key]
        assert row["status"] == e["status"], (key, row, e.get("error"))
        if e["status"] == "error":
            assert row["error"] == e["error"] and row["error_kind"] == e["error_kind"], (row, e)
            assert pd.isna(row["model"])
            continue
        fit = e["fit"]
        assert row["model"] == fit["model"], key
        for name, v in fit["params"].items():
            assert row[name] == v, (key, name, row[name], v)  # the same fit: bit for bit
        for name in set(PARAM_COLUMNS) - set(fit["params"]):
            assert math.isnan(row[name]), (key, name)
        assert row["verdict"] == fit["quality"]["verdict"]
        # auto's answer and regime (None where a model was named).
        assert row["answer"] == (fit.get("selection") or {}).get("answer"), key
        assert row["regime"] == (fit.get("optics") or {}).get("regime"), key
        assert row["reduced_chi2"] == fit["quality"]["reduced_chi2"]
        assert pd.isna(row["error"]) and pd.isna(row["error_kind"])


def test_fit_many_equals_batch_with_a_failing_scan(cluster, batch_dir, ndfit_bin, tmp_path):
    entries = run_batch(ndfit_bin, batch_dir, tmp_path / "out")
    paths = sorted(str(p) for p in batch_dir.rglob("*") if p.is_file())
    with distributed.Client(cluster) as client:
        df = fit_many(paths, client=client)
    assert list(df["path"]) == paths  # the order of the input, not of completion
    assert (df["status"] == "error").sum() == 2 and (df["status"] == "ok").sum() == len(paths) - 2
    assert_rows_match_batch(df, batch_dir, entries)


def test_fit_many_options_and_scheduler_address(cluster, batch_dir, ndfit_bin, tmp_path):
    """Options reach every scan as `-- FLAGS` reach batch's; a scheduler address works as a client."""
    entries = run_batch(ndfit_bin, batch_dir, tmp_path / "out", "--model", "ggx-aniso", "--", "--form", "poly2", "--ndf-cells", "31")
    paths = [str(batch_dir / k) for k in sorted(entries)]
    df = fit_many(paths, model="ggx-aniso", client=cluster.scheduler_address, form="poly2", ndf_cells=31)
    assert_rows_match_batch(df, batch_dir, entries)
    with pytest.raises(TypeError, match="fit_many"):
        fit_many(paths, client=cluster.scheduler_address, no_such_option=3)


def test_fit_many_own_local_cluster_on_real_scans(shared_scans, ndfit_bin, tmp_path):
    """client=None starts (and closes) a LocalCluster of its own; the shared real scans as `ndfit batch`."""
    entries = run_batch(ndfit_bin, shared_scans, tmp_path / "out")
    files = real_scan_files(shared_scans)
    assert len(entries) == len(files)
    df = fit_many(files, n_workers=2)
    assert (df["status"] == "ok").all(), df[df["status"] != "ok"]["error"].tolist()
    assert_rows_match_batch(df, shared_scans, entries)
    # The same rows in this process, without Dask (one thread per fit, as in the workers).
    for p, row in zip(files, df.to_dict("records")):
        f = ndfit.fit(str(p), threads=1)
        assert f.model == row["model"] and all(row[k] == v for k, v in f.params.items())


def test_fit_many_worker_threads_equal_batch(batch_dir, ndfit_bin, tmp_path):
    """processes=False: the LocalCluster's workers are threads of this process; the same rows."""
    entries = run_batch(ndfit_bin, batch_dir, tmp_path / "out", "--model", "ellipsoid")
    paths = [str(batch_dir / k) for k in sorted(entries)]
    df = fit_many(paths, model="ellipsoid", n_workers=2, processes=False)
    assert_rows_match_batch(df, batch_dir, entries)


def readme_fit_many_lines() -> str:
    """The README's `fit_many` lines, as written there (from `import glob` to the `df = fit_many(` line)."""
    text = (Path(__file__).resolve().parents[2] / "README.md").read_text(encoding="utf-8")
    lines = text.splitlines()
    start = lines.index("import glob")
    end = next(k for k in range(start, len(lines)) if lines[k].startswith("df = fit_many("))
    return "\n".join(lines[start : end + 1]) + "\n"


def test_readme_fit_many_runs_as_a_plain_script(synth_dir, ndfit_bin, tmp_path):
    """The README's lines pasted at the top level of a file (no `if __name__ == "__main__":`) and run with
    `python file.py` return the fits `ndfit fit` makes of the same scans with the same options."""
    scans = tmp_path / "scans"
    scans.mkdir()
    for f in sorted(synth_dir.glob("*.x3p")):
        shutil.copy(f, scans / f.name)
    script = tmp_path / "file.py"
    script.write_text(readme_fit_many_lines() + 'import json\njson.dump(df.to_dict("records"), open("rows.json", "w"))\n', encoding="utf-8")
    r = subprocess.run([sys.executable, str(script)], cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr[-3000:]
    rows = json.loads((tmp_path / "rows.json").read_text())
    assert [os.path.basename(row["path"]) for row in rows] == sorted(f.name for f in synth_dir.glob("*.x3p"))
    for row in rows:
        assert row["status"] == "ok", row
        out = tmp_path / (os.path.basename(row["path"]) + ".json")
        run_cli(ndfit_bin, "fit", tmp_path / row["path"], "--model", "auto", "--form", "poly2", "-o", out)
        fit = json.loads(out.read_text())
        assert row["model"] == fit["model"], row["path"]
        for name, v in fit["params"].items():
            assert row[name] == v, (row["path"], name, row[name], v)  # the same fit: bit for bit
        assert row["verdict"] == fit["quality"]["verdict"]
