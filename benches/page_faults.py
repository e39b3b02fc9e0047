#!/usr/bin/env python3
"""What a machine charges for fresh memory and for durable output (docs/PERFORMANCE.md, "Scaling with
cores"); a calibration, not a test. Needs numpy.

    python3 benches/page_faults.py [MIB]

1. Page faults: K threads of one process, each writing one value per 4 KiB page of MIB MiB of fresh
   memory (numpy releases the GIL while it writes), at K = 1, 2, 4, ... up to the cores; the best of three.
   Flat times mean faults proceed in parallel; times growing with K mean the address space serializes
   them, which caps every phase that fills fresh buffers on many threads.
2. Durable output: write 5 MB (an NDF CSV of a 4096^2 scan) to a file and fsync it, as ndfit's atomic
   writer does; the best of five.
"""

import os
import sys
import tempfile
import threading
import time

import numpy as np


def touch(mib):
    a = np.empty(mib << 17, np.float64)  # fresh pages
    a[::512] = 1.0  # one write per 4 KiB page
    return a


def threads(k, mib):
    t = time.perf_counter()
    ts = [threading.Thread(target=touch, args=(mib,)) for _ in range(k)]
    for x in ts:
        x.start()
    for x in ts:
        x.join()
    return time.perf_counter() - t


def fsync_5mb(folder):
    data = os.urandom(5 << 20)
    best = float("inf")
    for _ in range(5):
        with tempfile.NamedTemporaryFile(dir=folder) as f:
            t = time.perf_counter()
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
            best = min(best, time.perf_counter() - t)
    return best


def main():
    mib = int(sys.argv[1]) if len(sys.argv) > 1 else 128
    pages = mib * 256
    cores = os.cpu_count() or 1
    k = 1
    while k <= cores:
        t = min(threads(k, mib) for _ in range(3))
        print(f"{k:2d} thread(s) x {mib} MiB of fresh pages: {t * 1e3:7.1f} ms, {t / pages * 1e6:.2f} us per page of one thread")
        k *= 2
    print(f"5 MB written and fsynced: {fsync_5mb(os.getcwd()) * 1e3:.1f} ms")


if __name__ == "__main__":
    main()
