"""The committed notebooks carry their outputs (figures and tables, for a reader on the web), made by one
clean run of the cells as they are now: every code cell executed, in order, with no error among the
outputs, and the digest of the cells' sources that `run_notebooks.py --write` recorded still that of the
sources (an edited cell without a re-run fails here). CI executes them again (run_notebooks.py)."""

import glob
import json
import os
import sys

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
NOTEBOOKS = sorted(glob.glob(os.path.join(HERE, "..", "..", "notebooks", "*.ipynb")))
sys.path.insert(0, os.path.join(HERE, ".."))

REDO = "run: NDFIT=target/release/ndfit fits/.venv/bin/python fits/run_notebooks.py --write notebooks"


@pytest.mark.skipif(not NOTEBOOKS, reason="no notebooks folder beside fits/")
@pytest.mark.parametrize("path", NOTEBOOKS, ids=os.path.basename)
def test_notebook_outputs_are_present_and_current(path):
    nbformat = pytest.importorskip("nbformat")

    from run_notebooks import source_digest

    nb = nbformat.read(path, as_version=4)
    code = [c for c in nb.cells if c.cell_type == "code"]
    assert code, path
    counts = [c.get("execution_count") for c in code]
    assert counts == list(range(1, len(code) + 1)), f"{path}: not one clean run top to bottom ({counts}); {REDO}"
    for c in code:
        for o in c.get("outputs", []):
            assert o.get("output_type") != "error", f"{path}: a cell ended in {o.get('ename')}: {o.get('evalue')}; {REDO}"
    assert any(c.get("outputs") for c in code), f"{path}: no outputs; {REDO}"
    recorded = nb.metadata.get("ndfit", {}).get("source_sha256")
    assert recorded == source_digest(nb), f"{path}: the cells changed since their outputs were made; {REDO}"


@pytest.mark.skipif(not NOTEBOOKS, reason="no notebooks folder beside fits/")
def test_notebooks_show_figures():
    """At least one figure (a PNG output) in the notebooks as a whole, and in every one that plots."""
    figures = 0
    for path in NOTEBOOKS:
        nb = json.load(open(path, encoding="utf-8"))
        plots = any("plt." in "".join(c["source"]) for c in nb["cells"] if c["cell_type"] == "code")
        pngs = sum("image/png" in o.get("data", {}) for c in nb["cells"] if c["cell_type"] == "code" for o in c.get("outputs", []))
        assert pngs or not plots, f"{path}: it plots but carries no figure; {REDO}"
        figures += pngs
    assert figures > 0
