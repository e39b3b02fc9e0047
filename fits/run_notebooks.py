#!/usr/bin/env python3
"""Execute every notebook of a folder top to bottom (nbclient), or strip their outputs.

    python fits/run_notebooks.py notebooks            # execute in memory; nothing is written back
    python fits/run_notebooks.py --strip notebooks    # remove outputs and execution counts, in place

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
    after = nbformat.writes(nb)
    if after != before:
        with open(path, "w", encoding="utf-8") as fh:
            fh.write(after)
        return True
    return False


def execute(path: str, timeout: int, out_dir: str = "") -> str:
    """Run one notebook; returns '' or a one-line error. With ``out_dir`` the executed copy is written there."""
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
    return ""


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder")
    ap.add_argument("--strip", action="store_true", help="strip outputs in place instead of executing")
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
        err = execute(p, args.timeout, args.out)
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
