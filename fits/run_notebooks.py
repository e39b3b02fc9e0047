#!/usr/bin/env python3
"""Execute every notebook of a folder top to bottom (nbclient), or write them back with their outputs.

    python fits/run_notebooks.py notebooks            # execute in memory; nothing is written back (CI)
    python fits/run_notebooks.py --write notebooks    # execute and write each back with its outputs
    python fits/run_notebooks.py --strip notebooks    # remove outputs and execution counts, in place

The notebooks are committed with their outputs (figures and tables), so that a reader sees them on the
repository's web page; `--write` records the digest of the cells' sources beside the outputs
(`metadata.ndfit.source_sha256`, see source_digest), which fits/tests/test_notebooks_outputs.py checks
against the sources, so outputs left over from edited cells are caught. Run timings are not kept.

Notebooks run with the repository root as working directory, so `NDFIT` (the ndfit binary; default
target/release/ndfit) may be relative to it. The last line sums up: `notebooks: N passed, M failed`.
"""

from __future__ import annotations

import argparse
import glob
import os
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)


def strip(path: str) -> bool:
    """Remove outputs, execution counts and run metadata; True when the file changed."""
    import nbformat

    nb = nbformat.read(path, as_version=4)
    before = nbformat.writes(nb)
    for cell in nb.cells:
        if cell.cell_type == "code":
            cell.outputs = []
            cell.execution_count = None
        cell.metadata.pop("execution", None)
    nb.metadata.pop("widgets", None)
    nb.metadata.pop("ndfit", None)
    after = nbformat.writes(nb)
    if after != before:
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(after)
        return True
    return False


def source_digest(nb) -> str:
    """SHA-256 of every cell's type and source, in order: what the outputs were computed from."""
    import hashlib

    h = hashlib.sha256()
    for cell in nb.cells:
        src = cell.source if isinstance(cell.source, str) else "".join(cell.source)
        h.update(cell.cell_type.encode() + b"\0" + src.encode("utf-8") + b"\0")
    return h.hexdigest()


def execute(path: str, timeout: int, out_dir: str = "", write: bool = False) -> str:
    """Run one notebook; returns '' or a one-line error. With ``out_dir`` the executed copy is written there;
    with ``write`` it replaces ``path`` (only when every cell ran), with the digest of its sources."""
    import nbformat
    from nbclient import NotebookClient
    from nbclient.exceptions import CellExecutionError, CellTimeoutError

    nb = nbformat.read(path, as_version=4)
    client = NotebookClient(nb, timeout=timeout, kernel_name="python3", resources={"metadata": {"path": REPO}})
    try:
        client.execute()
    except CellExecutionError as e:
        lines = [ln for ln in str(e).splitlines() if ln.strip()]
        return lines[-1] if lines else "cell failed"
    except CellTimeoutError:
        return f"a cell ran longer than {timeout} s"
    except Exception as e:  # kernel died, bad JSON, ...
        return f"{type(e).__name__}: {e}".splitlines()[0]
    finally:
        if out_dir:
            os.makedirs(out_dir, exist_ok=True)
            nbformat.write(nb, os.path.join(out_dir, os.path.basename(path)))
    if write:
        for cell in nb.cells:
            cell.metadata.pop("execution", None)
        nb.metadata.setdefault("ndfit", {})["source_sha256"] = source_digest(nb)
        tmp = path + ".tmp"
        with open(tmp, "w", encoding="utf-8") as fh:
            nbformat.write(nb, fh)
        os.replace(tmp, path)
    return ""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder")
    ap.add_argument("--strip", action="store_true", help="strip outputs in place instead of executing")
    ap.add_argument("--write", action="store_true", help="write each executed notebook back with its outputs")
    ap.add_argument("--timeout", type=int, default=900, help="seconds per cell")
    ap.add_argument("--out", default="", help="write the executed notebooks (with outputs) into this folder")
    args = ap.parse_args(argv)
    paths = sorted(glob.glob(os.path.join(args.folder, "*.ipynb")))
    if not paths:
        print(f"run_notebooks: {args.folder}: no notebooks", file=sys.stderr)
        return 2
    if args.strip:
        for p in paths:
            print(("stripped " if strip(p) else "clean    ") + p)
        return 0
    os.environ.setdefault("NDFIT", "target/release/ndfit")
    failed = 0
    for p in paths:
        t0 = time.perf_counter()
        err = execute(p, args.timeout, args.out, args.write)
        dt = time.perf_counter() - t0
        if err:
            failed += 1
            print(f"FAIL {p} ({dt:.0f} s): {err}")
        else:
            print(f"ok   {p} ({dt:.0f} s)")
    print(f"notebooks: {len(paths) - failed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
