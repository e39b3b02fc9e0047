#!/usr/bin/env python3
"""Measure the Python binding against the CLI (docs/PERFORMANCE.md, "Python package"); not a test.

    fits/.venv/bin/python python/bench/measure.py [--size 1024] [--scans 64] [--scan-size 512] [--repeat 5]

1. Overhead: one fit of a SIZE^2 synthetic scan (`ndfit synth --surface gaussian`), `ndfit fit SCAN -o FILE`
   (a process per run, as a user runs it) against `ndfit.fit(path)` plus writing `to_json()` in this
   process, and against a fresh `python -c "import ndfit; ..."` process (interpreter start and import
   included). Median and min of REPEAT runs each, alternated.
2. Throughput: SCANS synthetic scans of SCAN_SIZE^2, `ndfit batch DIR --jobs 2` against
   `ndfit.dask.fit_many(paths, n_workers=2)` (a 2-worker LocalCluster started and closed by the call; also
   with `processes=False`, worker threads) and against the same call on an already running 2-worker cluster. The rows are checked equal to the batch's.
Needs the `ndfit` binary ($NDFIT or target/release/ndfit) and the package installed (`pip install ./`).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time

import ndfit

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def cli(ndfit_bin, *args):
    subprocess.run([ndfit_bin, *map(str, args)], check=True, capture_output=True)


def timed(f):
    t = time.perf_counter()
    f()
    return time.perf_counter() - t


def overhead(ndfit_bin, work, size, repeat):
    scan = os.path.join(work, f"g{size}.x3p")
    cli(ndfit_bin, "synth", scan, "--surface", "gaussian", "--nx", size, "--ny", size, "--sigma-x", "0.25", "--sigma-y", "0.15", "--theta-z", "0.3")
    out_cli, out_py = os.path.join(work, "cli.json"), os.path.join(work, "py.json")

    def py_fit():
        text = ndfit.fit(scan).to_json()
        with open(out_py, "w") as fh:
            fh.write(text)

    code = f"import ndfit; open({out_py!r}, 'w').write(ndfit.fit({scan!r}).to_json())"
    runs = {"cli": [], "py": [], "py_proc": []}
    py_fit(), cli(ndfit_bin, "fit", scan, "-q", "-o", out_cli)  # warm the page cache
    for _ in range(repeat):
        runs["cli"].append(timed(lambda: cli(ndfit_bin, "fit", scan, "-q", "-o", out_cli)))
        runs["py"].append(timed(py_fit))
        runs["py_proc"].append(timed(lambda: subprocess.run([sys.executable, "-c", code], check=True)))
    a, b = json.load(open(out_cli)), json.load(open(out_py))
    assert a["params"] == b["params"], "the binding's fit differs from the CLI's"
    med = {k: statistics.median(v) for k, v in runs.items()}
    print(f"one {size}^2 fit ({a['model']}), median of {repeat} (min):")
    for k, label in (("cli", "ndfit fit (process)"), ("py", "ndfit.fit + to_json (in process)"), ("py_proc", "python -c 'import ndfit; ...'")):
        print(f"  {label:<36} {med[k]*1e3:8.1f} ms ({min(runs[k])*1e3:.1f})  {100*(med[k]/med['cli']-1):+6.1f}% vs CLI")
    # The GIL is released while the library works: a pure-Python thread keeps counting during a fit (with
    # the GIL held it could not run at all), and two Python threads fitting at once against one after the
    # other (only faster when a second core is free).
    import threading

    count, stop = [0], threading.Event()

    def counter():
        while not stop.is_set():
            count[0] += 1

    t = threading.Thread(target=counter)
    t.start()
    before = count[0]
    dt = timed(lambda: ndfit.fit(scan, threads=1))
    during = count[0] - before
    stop.set()
    t.join()
    print(f"  a Python thread counted to {during} during one {dt*1e3:.0f} ms fit (GIL released)")

    def two_threads():
        ts = [threading.Thread(target=lambda: ndfit.fit(scan, threads=1)) for _ in range(2)]
        [t.start() for t in ts]
        [t.join() for t in ts]

    seq = statistics.median(timed(lambda: (ndfit.fit(scan, threads=1), ndfit.fit(scan, threads=1))) for _ in range(repeat))
    par = statistics.median(timed(two_threads) for _ in range(repeat))
    print(f"  two fits (threads=1 each): one after the other {seq*1e3:.1f} ms, in two Python threads {par*1e3:.1f} ms ({seq/par:.2f}x)")
    return med


def throughput(ndfit_bin, work, n, size):
    from dask.distributed import Client, LocalCluster

    from ndfit.dask import fit_many

    d = os.path.join(work, "scans")
    os.makedirs(d, exist_ok=True)
    for i in range(n):
        surf = ["--surface", "gaussian", "--sigma-x", f"{0.1 + 0.004 * i:.3f}", "--sigma-y", "0.12", "--theta-z", f"{0.05 * i:.2f}"]
        if i % 4 == 3:
            surf = ["--surface", "ellipsoid", "--alpha-x", f"{0.2 + 0.003 * i:.3f}", "--alpha-y", "0.15"]
        cli(ndfit_bin, "synth", os.path.join(d, f"s{i:03d}.x3p"), "--nx", size, "--ny", size, "--seed", i + 1, *surf)
    paths = sorted(os.path.join(d, f) for f in os.listdir(d) if f.endswith(".x3p"))
    out = os.path.join(work, "batch_out")
    t_batch = timed(lambda: subprocess.run([ndfit_bin, "batch", d, "-o", out, "--jobs", "2"], check=True, capture_output=True))
    res = {}
    t_own = timed(lambda: res.setdefault("own", fit_many(paths, n_workers=2)))
    t_threads = timed(lambda: res.setdefault("threads", fit_many(paths, n_workers=2, processes=False)))
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as cluster, Client(cluster) as client:
        client.run(lambda: __import__("ndfit"))
        t_running = timed(lambda: res.setdefault("running", fit_many(paths, client=client)))
    entries = {e["path"]: e for e in json.load(open(os.path.join(out, "summary.json")))["entries"]}
    for df in res.values():
        for row in df.to_dict("records"):
            fit = entries[os.path.basename(row["path"])]["fit"]
            assert row["model"] == fit["model"] and all(row[k] == v for k, v in fit["params"].items())
    print(f"{n} scans of {size}^2, 2 workers (rows equal to the batch's):")
    for label, t in (("ndfit batch --jobs 2", t_batch), ("fit_many, own LocalCluster", t_own), ("fit_many, own, processes=False", t_threads), ("fit_many, running cluster", t_running)):
        print(f"  {label:<30} {t:7.2f} s  {n / t:6.2f} scans/s  {100*(t/t_batch-1):+6.1f}% vs batch")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--scans", type=int, default=64)
    ap.add_argument("--scan-size", type=int, default=512)
    ap.add_argument("--skip-overhead", action="store_true")
    ap.add_argument("--skip-throughput", action="store_true")
    a = ap.parse_args()
    ndfit_bin = os.environ.get("NDFIT") or os.path.join(REPO, "target", "release", "ndfit")
    print(f"ndfit {ndfit.__version__}, {os.cpu_count()} cores, binary {ndfit_bin}")
    with tempfile.TemporaryDirectory(prefix="ndfit-measure-") as work:
        if not a.skip_overhead:
            overhead(ndfit_bin, work, a.size, a.repeat)
        if not a.skip_throughput:
            throughput(ndfit_bin, work, a.scans, a.scan_size)


if __name__ == "__main__":
    main()
