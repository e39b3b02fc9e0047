"""The committed notebooks carry no outputs (CI executes them; outputs stay out of git)."""

import glob
import json
import os

import pytest

NOTEBOOKS = sorted(glob.glob(os.path.join(os.path.dirname(__file__), "..", "..", "notebooks", "*.ipynb")))


@pytest.mark.skipif(not NOTEBOOKS, reason="no notebooks folder beside fits/")
@pytest.mark.parametrize("path", NOTEBOOKS, ids=os.path.basename)
def test_notebook_has_no_outputs(path):
    nb = json.load(open(path, encoding="utf-8"))
    for cell in nb["cells"]:
        if cell["cell_type"] == "code":
            assert cell.get("outputs") == [] and cell.get("execution_count") is None, (
                f"{path}: outputs present; run: fits/.venv/bin/python fits/run_notebooks.py --strip notebooks"
            )
