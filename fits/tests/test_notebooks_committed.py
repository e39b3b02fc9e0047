"""The committed notebooks are the executed notebooks of notebooks/build_notebooks.py.

They carry their outputs (figures and tables, for a reader on the repository's web page), so two things must
hold: the cells are the ones build_notebooks.py writes (the outputs belong to the committed code), and the
outputs are those of one complete run: every code cell executed once, in order, none ended in an error, and
every cell that prints or plots has its output. CI executes the notebooks again (fits/run_notebooks.py).
"""

import ast
import glob
import importlib.util
import json
import os

import pytest

FOLDER = os.path.normpath(os.path.join(os.path.dirname(__file__), "..", "..", "notebooks"))
NOTEBOOKS = sorted(glob.glob(os.path.join(FOLDER, "*.ipynb")))
REDO = (
    "run: fits/.venv/bin/python notebooks/build_notebooks.py && "
    "NDFIT=target/release/ndfit fits/.venv/bin/python fits/run_notebooks.py --write notebooks"
)

pytestmark = pytest.mark.skipif(not NOTEBOOKS, reason="no notebooks folder beside fits/")


def builder():
    """notebooks/build_notebooks.py as a module (it needs nbformat, from fits[notebooks])."""
    pytest.importorskip("nbformat")
    spec = importlib.util.spec_from_file_location("build_notebooks", os.path.join(FOLDER, "build_notebooks.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def source(cell) -> str:
    s = cell["source"]
    return s if isinstance(s, str) else "".join(s)


def calls(tree) -> set:
    """Names called by the code that runs when ``tree`` runs (not inside the functions it defines)."""
    names, todo = set(), [tree]
    while todo:
        node = todo.pop()
        if isinstance(node, ast.Call):
            f = node.func
            names.add(f.id if isinstance(f, ast.Name) else f.attr if isinstance(f, ast.Attribute) else None)
        todo.extend(c for c in ast.iter_child_nodes(node) if not isinstance(c, (ast.FunctionDef, ast.Lambda, ast.ClassDef)))
    return names


def shows_something(tree, printers: set) -> bool:
    """Whether running ``tree`` calls print, a figure's show, or a function of the notebook that does."""
    return bool(calls(tree) & ({"print", "show"} | printers))


def printing_functions(cells: list) -> set:
    """Names of the functions the notebook defines that print or show, directly or through each other."""
    defs = {}
    for cell in cells:
        for node in ast.walk(ast.parse(source(cell))):
            if isinstance(node, ast.FunctionDef):
                defs[node.name] = ast.Module(body=node.body, type_ignores=[])
    printers = set()
    while True:
        more = {n for n, body in defs.items() if n not in printers and shows_something(body, printers)}
        if not more:
            return printers
        printers |= more


def test_the_committed_notebooks_are_those_build_notebooks_writes():
    b = builder()
    assert sorted(os.path.basename(p) for p in NOTEBOOKS) == sorted(b.NOTEBOOKS), (
        f"notebooks/*.ipynb and build_notebooks.NOTEBOOKS name different notebooks; {REDO}"
    )


@pytest.mark.parametrize("path", NOTEBOOKS, ids=os.path.basename)
def test_cells_are_those_of_build_notebooks(path):
    b = builder()
    want = [(c.cell_type, c.source) for c in b.notebook(os.path.basename(path)).cells]
    have = [(c["cell_type"], source(c)) for c in json.load(open(path, encoding="utf-8"))["cells"]]
    assert len(have) == len(want), f"{path}: {len(have)} cells, build_notebooks.py writes {len(want)}; {REDO}"
    for i, (h, w) in enumerate(zip(have, want)):
        assert h == w, f"{path}: cell {i} is not the one build_notebooks.py writes; {REDO}"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=os.path.basename)
def test_outputs_are_those_of_one_complete_run(path):
    cells = [c for c in json.load(open(path, encoding="utf-8"))["cells"] if c["cell_type"] == "code"]
    counts = [c.get("execution_count") for c in cells]
    assert counts == list(range(1, len(cells) + 1)), f"{path}: not one run top to bottom (execution counts {counts}); {REDO}"
    printers = printing_functions(cells)
    expected = 0
    for i, cell in enumerate(cells):
        for out in cell["outputs"]:
            assert out["output_type"] != "error", f"{path}: code cell {i} ended in {out.get('ename')}: {out.get('evalue')}; {REDO}"
        if shows_something(ast.parse(source(cell)), printers):
            expected += 1
            assert cell["outputs"], f"{path}: code cell {i} prints or plots but has no output; {REDO}"
    assert expected, f"{path}: no cell prints or plots, so the check above checked nothing"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=os.path.basename)
def test_figures_are_png_only(path):
    # One picture per figure: matplotlib's inline PNG (no SVG or PDF copy doubling the file).
    for cell in json.load(open(path, encoding="utf-8"))["cells"]:
        for out in cell.get("outputs", []):
            extra = {k for k in out.get("data", {}) if k.startswith("image/") or k == "application/pdf"} - {"image/png"}
            assert not extra, f"{path}: an output carries {sorted(extra)} besides the PNG"
