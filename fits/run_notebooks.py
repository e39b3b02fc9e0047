#!/usr/bin/env python3
"""Execute every notebook of a folder top to bottom (nbclient); optionally write them back with their outputs.

    python fits/run_notebooks.py notebooks            # execute in memory; nothing is written back (CI)
    python fits/run_notebooks.py --write notebooks    # execute, and write each notebook back with its outputs

The notebooks are committed executed, so a reader sees their figures and tables on the repository's web page
without running anything (`notebooks/build_notebooks.py` writes their cells; `--write` then puts the outputs
back). `--write` keeps outputs and execution counts and nothing of the run itself: the cell and notebook
metadata stay as they were (no timestamps, no kernel version), consecutive pieces of one stream are joined,
and a notebook is replaced only when every cell ran and its text changed.

Notebooks run with the repository root as working directory, so `NDFIT` (the ndfit binary; default
target/release/ndfit) may be relative to it. The last line sums up: `notebooks: N passed, M failed`.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import copy
import glob
import os
import re
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)


def join_streams(outputs: list) -> list:
    """Consecutive stream outputs of one name as one output: how output is split depends on flush timing."""
    joined = []
    for out in outputs:
        prev = joined[-1] if joined else None
        if out.output_type == "stream" and prev is not None and prev.output_type == "stream" and prev.name == out.name:
            prev.text += out.text
        else:
            joined.append(out)
    return joined


def write_back(nb, path: str) -> bool:
    """Write ``nb`` over ``path`` through a temporary file beside it; True when the text changed."""
    import nbformat

    text = nbformat.writes(nb)
    text += "" if text.endswith("\n") else "\n"  # as nbformat.write ends the file
    with open(path, encoding="utf-8") as fh:
        if fh.read() == text:
            return False
    tmp = path + ".tmp"
    with open(tmp, "w", encoding="utf-8") as fh:
        fh.write(text)
    os.replace(tmp, path)
    return True


def execute(path: str, timeout: int, out_dir: str = "", write: bool = False) -> str:
    """Run one notebook; returns '' or a one-line error.

    With ``out_dir`` the executed copy is written there (also after a failure, to look at); with ``write`` it
    replaces ``path``, only when every cell ran.
    """
    import nbformat
    from nbclient import NotebookClient
    from nbclient.exceptions import CellExecutionError, CellTimeoutError

    nb = nbformat.read(path, as_version=4)
    # What the run would add to the metadata (kernel version, per-cell timestamps) is put back as it was.
    metadata = copy.deepcopy(nb.metadata)
    cell_metadata = [copy.deepcopy(c.metadata) for c in nb.cells]
    client = NotebookClient(
        nb, timeout=timeout, kernel_name="python3", record_timing=False, resources={"metadata": {"path": REPO}}
    )
    err = ""
    try:
        client.execute()
    except CellExecutionError as e:
        # The kernel's traceback is coloured for a terminal: its escape codes would garble the one line.
        lines = [ln for ln in re.sub(r"\x1b\[[0-9;]*m", "", str(e)).splitlines() if ln.strip()]
        err = lines[-1] if lines else "cell failed"
    except CellTimeoutError:
        err = f"a cell ran longer than {timeout} s"
    except Exception as e:  # kernel died, bad JSON, ...
        err = f"{type(e).__name__}: {e}".splitlines()[0]
    nb.metadata = metadata
    for cell, meta in zip(nb.cells, cell_metadata):
        cell.metadata = meta
        if cell.cell_type == "code":
            cell.outputs = join_streams(cell.outputs)
    if out_dir:
        os.makedirs(out_dir, exist_ok=True)
        nbformat.write(nb, os.path.join(out_dir, os.path.basename(path)))
    if write and not err:
        write_back(nb, path)
    return err


def timed_execute(path: str, timeout: int, out_dir: str, write: bool):
    """`execute` and the seconds it took."""
    t0 = time.perf_counter()
    err = execute(path, timeout, out_dir, write)
    return err, time.perf_counter() - t0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("folder")
    ap.add_argument("--write", action="store_true", help="write each notebook back with its outputs (when all its cells ran)")
    ap.add_argument("--timeout", type=int, default=900, help="seconds per cell")
    ap.add_argument("--out", default="", help="write the executed notebooks (with outputs) into this folder")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                    help="notebooks run side by side, each in its own kernel (default: one per core)")
    args = ap.parse_args(argv)
    paths = sorted(glob.glob(os.path.join(args.folder, "*.ipynb")))
    if not paths:
        print(f"run_notebooks: {args.folder}: no notebooks", file=sys.stderr)
        return 2
    os.environ.setdefault("NDFIT", "target/release/ndfit")
    failed = 0
    # Each notebook runs in its own worker process and kernel; the lines come out in the notebooks' order.
    with concurrent.futures.ProcessPoolExecutor(max_workers=max(1, min(args.jobs, len(paths)))) as pool:
        runs = [(p, pool.submit(timed_execute, p, args.timeout, args.out, args.write)) for p in paths]
        for p, run in runs:
            try:
                err, dt = run.result()
            except Exception as e:  # noqa: BLE001 (a worker that died fails its notebook, not the others)
                err, dt = f"the run died: {type(e).__name__}: {e}", float("nan")
            if err:
                failed += 1
                print(f"FAIL {p} ({dt:.0f} s): {err}", flush=True)
            else:
                print(f"ok   {p} ({dt:.0f} s)", flush=True)
    print(f"notebooks: {len(paths) - failed} passed, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
