"""The package's layout promises: fits/ (the independent cross-check) never imports ndfit, and the stubs
name every public attribute of the compiled module."""

from __future__ import annotations

import ast
import inspect
from pathlib import Path

import ndfit
import ndfit._ndfit as core

REPO = Path(__file__).resolve().parents[2]


def test_fits_never_imports_ndfit():
    offenders = []
    for f in sorted((REPO / "fits").rglob("*.py")):
        if ".venv" in f.parts:
            continue
        for node in ast.walk(ast.parse(f.read_text(encoding="utf-8"), filename=str(f))):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module or ""]
            offenders += [f"{f.relative_to(REPO)}:{node.lineno}" for n in names if n == "ndfit" or n.startswith("ndfit.")]
    assert not offenders, offenders


def test_stubs_cover_the_compiled_module():
    stub = ast.parse((Path(ndfit.__file__).parent / "_ndfit.pyi").read_text())
    declared = {n.name for n in stub.body if isinstance(n, (ast.ClassDef, ast.FunctionDef))}
    declared |= {t.target.id for t in stub.body if isinstance(t, ast.AnnAssign)}
    public = {n for n in dir(core) if not n.startswith("_")} | {"__version__"}
    assert public <= declared, public - declared
    for cls in ("Scan", "Ndf", "Fit"):
        node = next(n for n in stub.body if isinstance(n, ast.ClassDef) and n.name == cls)
        names = {m.name for m in node.body if isinstance(m, ast.FunctionDef)}
        members = {n for n in dir(getattr(core, cls)) if not n.startswith("_")}
        assert members <= names, (cls, members - names)
    # The functions' keyword names in the stubs are the compiled signatures'.
    for fn in ("read", "ndf", "fit"):
        node = next(n for n in stub.body if isinstance(n, ast.FunctionDef) and n.name == fn)
        stub_args = [a.arg for a in node.args.args + node.args.kwonlyargs]
        assert stub_args == list(inspect.signature(getattr(core, fn)).parameters), fn
