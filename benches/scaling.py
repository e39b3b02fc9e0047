#!/usr/bin/env python3
"""How ndfit scales with cores: whole processes at 1, 2, 4, ... threads or jobs (docs/PERFORMANCE.md,
"Scaling with cores"); a benchmark, not a test. Python's standard library only, so that it runs on any
machine the release binary runs on.

    python3 benches/scaling.py --ndfit target/release/ndfit [--base OTHER_NDFIT] [--out DIR] [--quick]

It makes its own data with `ndfit synth`: one SIZE^2 float64 X3P as ndfit writes it (stored), and SCANS
BATCH_SIZE^2 X3Ps with their entries deflated at level 6 (as instrument software writes them). Then,
every command interleaved with the others round by round (medians of REPEATS):
- `ndf` (default options, and `--form none --despike none`), `fit --model ggx-aniso` (with the stage
  timings of its JSON) and `info` (the reading pass) of the big scan at each thread count
  (`RAYON_NUM_THREADS`);
- `batch --model ggx-aniso --jobs J` over the deflated set at each job count, beside the input's floor:
  J processes at a time running `unzip -p SCAN bindata/data.bin` (Info-ZIP) over the same files where
  `unzip` is installed, and always J worker processes inflating the same entries with Python's zlib;
- `batch --model auto` at the most jobs, and one scan's `fit --model auto` against `--model ggx-aniso` at
  one thread and at the most threads (the price of `auto`).
With `--base` (and `--also TAG=PATH`), the single-scan commands and the batch at the fewest and the most
jobs also run with other binaries (the build before a change), in the same rounds; `--variant TAG=OF:VAR=VALUE`
runs the binary tagged OF again with one more environment variable set (an experiment's switch). The new binary runs
with `NDFIT_PHASES` set, so its tables also show each phase's time. First of all, the machine's own
ceiling: as many copies of a CPU-bound one-thread loop as there are threads, against one; then each
workload's own ceiling: as many one-thread `ndf` (or `fit`) processes of the big scan at once as there are
threads, against one alone (what the machine gives that very work when nothing in it is shared). Writes
scaling.json (every run) and scaling.md (the tables), and prints the tables.
"""

from __future__ import annotations

import argparse
import concurrent.futures as cf
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import time
import zipfile


def run(argv, env=None, stdout=subprocess.DEVNULL, phases=None):
    """Wall seconds of one whole process; raises on a non-zero exit. With `phases` (a dict), the
    `ndfit: phase NAME at S ms took D ms` lines of its standard error (`NDFIT_PHASES`) go there."""
    t = time.perf_counter()
    p = subprocess.run(argv, env=env, stdout=stdout, stderr=subprocess.PIPE)
    dt = time.perf_counter() - t
    if p.returncode != 0:
        raise SystemExit(f"scaling: {' '.join(map(str, argv))} exited {p.returncode}: {p.stderr.decode()[-400:]}")
    if phases is not None:
        for line in p.stderr.decode(errors="replace").splitlines():
            w = line.split()
            if len(w) == 9 and w[:2] == ["ndfit:", "phase"]:
                phases[w[2]] = phases.get(w[2], 0.0) + float(w[7])
            elif line.startswith("ndfit: phases end at "):
                phases["(end)"] = float(w[4])
    return dt


def deflate(src, dst):
    """Copy the X3P `src` to `dst` with every entry deflated at level 6."""
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst + ".part", "w", zipfile.ZIP_DEFLATED, compresslevel=6) as zout:
        for info in zin.infolist():
            zout.writestr(info.filename, zin.read(info))
    os.replace(dst + ".part", dst)


def make_data(ndfit, work, size, batch_size, scans):
    os.makedirs(work, exist_ok=True)
    big = os.path.join(work, f"big{size}.x3p")
    if not os.path.exists(big):
        run([ndfit, "synth", "--nx", str(size), "--ny", str(size), "--noise", "2e-9", big])
    folder = os.path.join(work, f"deflated{batch_size}")
    os.makedirs(folder, exist_ok=True)

    def one(k):
        out = os.path.join(folder, f"scan{k:03}.x3p")
        if os.path.exists(out):
            return
        stored = os.path.join(work, f".stored{k}.x3p")
        run([ndfit, "synth", "--nx", str(batch_size), "--ny", str(batch_size), "--noise", "2e-9", "--seed", str(k + 1), stored])
        deflate(stored, out)
        os.remove(stored)
        os.remove(stored[: -len(".x3p")] + ".truth.json")

    with cf.ThreadPoolExecutor(os.cpu_count()) as pool:
        list(pool.map(one, range(scans)))
    files = sorted(os.path.join(folder, f) for f in os.listdir(folder) if f.endswith(".x3p"))
    for f in [big, *files]:  # into the page cache: every round reads warm files
        with open(f, "rb") as fh:
            while fh.read(1 << 24):
                pass
    return big, folder, files


def floor_pool(files, jobs):
    """`unzip -p` of every file's height entry, `jobs` processes at a time (the batch's floor)."""
    t = time.perf_counter()
    with cf.ThreadPoolExecutor(jobs) as pool:
        list(pool.map(lambda f: run(["unzip", "-p", f, "bindata/data.bin"]), files))
    return time.perf_counter() - t


def _inflate_entry(path):
    """One worker's job in [`floor_zlib`]: the height entry inflated (zlib, CRC-32 checked), its size."""
    with zipfile.ZipFile(path) as z:
        return len(z.read("bindata/data.bin"))


def floor_zlib(files, jobs):
    """zlib's inflate of every file's height entry in `jobs` worker processes (started and warmed before the
    clock starts): the batch's floor where Info-ZIP's `unzip` is not installed, and beside it where it is
    (no process start per file, and zlib's inflate rather than Info-ZIP's own)."""
    import multiprocessing as mp
    with mp.get_context("fork").Pool(jobs) as pool:
        pool.map(_inflate_entry, files[:jobs], chunksize=1)
        t = time.perf_counter()
        pool.map(_inflate_entry, files, chunksize=1)
        return time.perf_counter() - t


def split_batches(ndfit, files, parts, scratch, env):
    """`parts` one-job `batch` processes at once, each over its share of the files (a manifest each):
    the batch's own ceiling, what the machine gives this work when no process shares anything."""
    procs = []
    for k in range(parts):
        manifest = os.path.join(scratch, f"part{k}.csv")
        with open(manifest, "w") as fh:
            fh.write("path\n" + "".join(os.path.abspath(f) + "\n" for f in files[k::parts]))
        out = os.path.join(scratch, f"part{k}_out")
        shutil.rmtree(out, ignore_errors=True)
        procs.append([ndfit, "batch", manifest, "-o", out, "--model", "ggx-aniso", "--jobs", "1"])
    t = time.perf_counter()
    running = [subprocess.Popen(p, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for p in procs]
    codes = [p.wait() for p in running]
    dt = time.perf_counter() - t
    if any(codes):
        raise SystemExit(f"scaling: the split batches exited {codes}")
    return dt


def cpu_ceiling(copies):
    """Seconds for `copies` simultaneous processes of the same CPU-bound one-thread loop (the machine's
    own parallel capacity: 16 copies taking as long as one means 16 independent cores)."""
    loop = "s = 0\nfor i in range(4_000_000):\n    s += i * i\n"
    t = time.perf_counter()
    procs = [subprocess.Popen([sys.executable, "-c", loop]) for _ in range(copies)]
    for p in procs:
        p.wait()
    return time.perf_counter() - t


def workload_ceiling(argv_of, copies, env):
    """Seconds for `copies` simultaneous one-thread processes of the same command (each its own output),
    as `cpu_ceiling` but with ndfit's own work: its memory traffic and vector units included."""
    t = time.perf_counter()
    procs = [subprocess.Popen(argv_of(k), env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL) for k in range(copies)]
    codes = [p.wait() for p in procs]
    if any(codes):
        raise SystemExit(f"scaling: the workload ceiling's processes exited {codes}")
    return time.perf_counter() - t


def machine_facts():
    """The CPU's topology and vector units as the machine reports them (`lscpu`, /proc/cpuinfo)."""
    facts = {}
    if shutil.which("lscpu"):
        p = subprocess.run(["lscpu"], capture_output=True, text=True)
        for line in p.stdout.splitlines():
            k, _, v = line.partition(":")
            if k.strip() in ("Thread(s) per core", "Core(s) per socket", "Socket(s)", "CPU MHz", "CPU max MHz", "L2 cache", "L3 cache", "NUMA node(s)"):
                facts[k.strip()] = v.strip()
    try:
        flags = next(l.split(":", 1)[1].split() for l in open("/proc/cpuinfo") if l.startswith("flags"))
        facts["vector"] = " ".join(f for f in ("avx2", "fma", "avx512f", "avx512vl", "avx512dq", "avx512bw") if f in flags)
    except (OSError, StopIteration):
        pass
    return facts


def ratio(a, b):
    return a / b if b else float("nan")


def med(v):
    return statistics.median(v) if v else float("nan")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ndfit", required=True)
    ap.add_argument("--base", help="a second ndfit binary timed beside --ndfit on the single-scan commands")
    ap.add_argument("--also", action="append", default=[], metavar="TAG=PATH", help="more binaries for the single-scan commands")
    ap.add_argument("--variant", action="append", default=[], metavar="TAG=OF:VAR=VALUE", help="the binary tagged OF (new, base or an --also) again, with one more environment variable")
    ap.add_argument("--out", default="scaling_out")
    ap.add_argument("--work", help="data folder (kept; default OUT/work)")
    ap.add_argument("--threads", default=None, help="comma-separated (default 1,2,4,... up to the cores)")
    ap.add_argument("--size", type=int, default=4096)
    ap.add_argument("--batch-size", type=int, default=1024)
    ap.add_argument("--scans", type=int, default=64)
    ap.add_argument("--repeats", type=int, default=7)
    ap.add_argument("--batch-repeats", type=int, default=3)
    ap.add_argument("--quick", action="store_true", help="small data, one repeat: a check that the script runs")
    ap.add_argument("--single-only", action="store_true", help="the single-scan commands alone (no batch, no auto)")
    ap.add_argument("--batch-only", action="store_true", help="the batch alone (no single-scan commands, no ceilings, no auto)")
    a = ap.parse_args()
    if a.quick:
        a.size, a.batch_size, a.scans, a.repeats, a.batch_repeats = 512, 128, 8, 1, 1
    if a.single_only:
        a.scans = 0
    cores = os.cpu_count() or 1
    threads = [int(t) for t in a.threads.split(",")] if a.threads else [t for t in (1, 2, 4, 8, 16, 32, 64) if t <= cores]
    if threads[-1] != cores and not a.threads:
        threads.append(cores)
    top = threads[-1]
    os.makedirs(a.out, exist_ok=True)
    work = a.work or os.path.join(a.out, "work")
    scratch = os.path.join(work, "scratch")
    os.makedirs(scratch, exist_ok=True)
    # Every binary by tag: its path and the environment variables it runs with beside the thread count.
    bins = {"new": (os.path.abspath(a.ndfit), {})}
    if a.base:
        bins["base"] = (os.path.abspath(a.base), {})
    for tb in a.also:
        tag, path = tb.split("=", 1)
        bins[tag] = (os.path.abspath(path), {})
    for tv in a.variant:
        tag, rest = tv.split("=", 1)
        of, setting = rest.split(":", 1)
        var, value = setting.split("=", 1)
        bins[tag] = (bins[of][0], {**bins[of][1], var: value})
    have_unzip = shutil.which("unzip") is not None
    res_ceiling = []

    t0 = time.perf_counter()
    for _ in range(3):
        for k in sorted({1, top}):
            res_ceiling.append({"copies": k, "s": cpu_ceiling(k)})
    big, folder, files = make_data(bins["new"][0], work, a.size, a.batch_size, a.scans)
    print(f"data ready in {time.perf_counter() - t0:.1f} s: {big}, {len(files)} deflated scans", flush=True)
    res = {"machine": {}, "single": [], "batch": [], "floor": [], "auto": [], "ceiling": res_ceiling}

    def save(res):
        """scaling.json as it stands: a run cut short keeps what it measured."""
        with open(os.path.join(a.out, "scaling.json.part"), "w") as fh:
            json.dump(res, fh, indent=1)
        os.replace(os.path.join(a.out, "scaling.json.part"), os.path.join(a.out, "scaling.json"))

    try:
        cpu = next(l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name"))
    except (OSError, StopIteration):
        cpu = platform.processor()
    res["machine"] = {"cpu": cpu, "cores": cores, **machine_facts(), "python": platform.python_version(), "size": a.size,
                      "batch_size": a.batch_size, "scans": a.scans, "loadavg_start": os.getloadavg()}

    def env(t, extra=None):
        e = dict(os.environ)
        e["RAYON_NUM_THREADS"] = str(t)
        e["NDFIT_PHASES"] = "1"  # a build without phases ignores it
        e.update(extra or {})
        return e

    fitjson = os.path.join(scratch, "fit.json")
    single = {
        "ndf": lambda b: [b, "ndf", big, "-o", os.path.join(scratch, "ndf.csv")],
        "ndf --form none --despike none": lambda b: [b, "ndf", big, "--form", "none", "--despike", "none", "-o", os.path.join(scratch, "ndf0.csv")],
        "fit --model ggx-aniso": lambda b: [b, "fit", big, "--model", "ggx-aniso", "-o", fitjson],
        "info": lambda b: [b, "info", big],
        "--version": lambda b: [b, "--version"],
    }
    # Each workload's ceiling: `top` one-thread processes at once against one, the new binary.
    res["workload_ceiling"] = []
    ceiling_cmds = {
        "ndf": lambda k: [bins["new"][0], "ndf", big, "-o", os.path.join(scratch, f"c{k}.csv")],
        "fit --model ggx-aniso": lambda k: [bins["new"][0], "fit", big, "--model", "ggx-aniso", "-o", os.path.join(scratch, f"c{k}.json")],
    }
    for _ in range(0 if a.batch_only else min(3, a.repeats)):
        for name, argv_of in ceiling_cmds.items():
            for k in sorted({1, top}):
                res["workload_ceiling"].append({"cmd": name, "copies": k, "s": workload_ceiling(argv_of, k, env(1))})
    for r in range(0 if a.batch_only else a.repeats):
        for t in threads:
            for name, argv in single.items():
                for tag, (b, extra) in bins.items():
                    if tag != "new" and name in ("info", "--version"):
                        continue  # the other binaries time the commands being compared
                    phases = {}
                    dt = run(argv(b), env(t, extra), phases=phases)
                    row = {"cmd": name, "bin": tag, "threads": t, "s": dt, "phases": phases}
                    if name.startswith("fit"):
                        row["timings"] = json.load(open(fitjson))["timings"]
                    res["single"].append(row)
        print(f"single-scan round {r + 1}/{a.repeats} done", flush=True)
        save(res)

    out_dir = os.path.join(scratch, "batch_out")
    for r in range(0 if a.single_only else a.batch_repeats):
        for j in threads:
            shutil.rmtree(out_dir, ignore_errors=True)
            for tag, (b, extra) in bins.items():
                if tag != "new" and j != top and (tag != "base" or j != threads[0]):
                    continue  # the other binaries at the most jobs (and the base at the fewest too)
                shutil.rmtree(out_dir, ignore_errors=True)
                dt = run([b, "batch", folder, "-o", out_dir, "--model", "ggx-aniso", "--jobs", str(j)], {**os.environ, **extra})
                res["batch"].append({"model": "ggx-aniso", "bin": tag, "jobs": j, "s": dt})
            if have_unzip:
                res["floor"].append({"jobs": j, "s": floor_pool(files, j)})
            res.setdefault("floor_zlib", []).append({"jobs": j, "s": floor_zlib(files, j)})
            one_thread = {**os.environ, "RAYON_NUM_THREADS": "1"}
            res.setdefault("split", []).append({"jobs": j, "s": split_batches(bins["new"][0], files, j, scratch, one_thread)})
        shutil.rmtree(out_dir, ignore_errors=True)
        dt = run([bins["new"][0], "batch", folder, "-o", out_dir, "--model", "ggx-aniso", "--jobs", str(top), "--isolate", "process"])
        res["batch"].append({"model": "ggx-aniso --isolate process", "bin": "new", "jobs": top, "s": dt})
        shutil.rmtree(out_dir, ignore_errors=True)
        dt = run([bins["new"][0], "batch", folder, "-o", out_dir, "--model", "auto", "--jobs", str(top)])
        res["batch"].append({"model": "auto", "bin": "new", "jobs": top, "s": dt})
        print(f"batch round {r + 1}/{a.batch_repeats} done", flush=True)
        save(res)

    one = files[0] if files else None
    for r in range(0 if a.single_only or a.batch_only else a.repeats):
        for t in sorted({1, top}):
            for model in ("ggx-aniso", "auto"):
                dt = run([bins["new"][0], "fit", one, "--model", model, "-o", fitjson], env(t))
                res["auto"].append({"model": model, "threads": t, "s": dt})
    res["machine"]["loadavg_end"] = os.getloadavg()
    res["machine"]["wall_s"] = time.perf_counter() - t0
    save(res)

    md = tables(res, threads, bins, have_unzip and not a.single_only)
    with open(os.path.join(a.out, "scaling.md"), "w") as fh:
        fh.write(md)
    print(md)


def tables(res, threads, bins, have_unzip):
    m = res["machine"]
    c1 = med([r["s"] for r in res["ceiling"] if r["copies"] == 1])
    ck = med([r["s"] for r in res["ceiling"] if r["copies"] == threads[-1]])
    lines = [f"{m['cpu']}, {m['cores']} cores; load average {m['loadavg_start'][0]:.2f} at the start, "
             f"{m['loadavg_end'][0]:.2f} at the end; {m['wall_s']:.0f} s in all. The machine's ceiling: "
             f"{threads[-1]} copies of a CPU-bound one-thread loop take {ck / c1:.2f}x as long as one "
             f"(a throughput of {threads[-1] * c1 / ck:.1f} cores).", ""]
    facts = {k: v for k, v in m.items() if k in ("Thread(s) per core", "Core(s) per socket", "Socket(s)", "NUMA node(s)", "L2 cache", "L3 cache", "vector")}
    if facts:
        lines += ["The CPU as reported: " + "; ".join(f"{k} {v}" for k, v in facts.items()) + ".", ""]
    wc = res.get("workload_ceiling", [])
    for cmd in dict.fromkeys(r["cmd"] for r in wc):
        w1 = med([r["s"] for r in wc if r["cmd"] == cmd and r["copies"] == 1])
        wk = med([r["s"] for r in wc if r["cmd"] == cmd and r["copies"] == threads[-1]])
        lines += [f"The workload's ceiling, `{cmd}`: {threads[-1]} one-thread processes at once take {1e3 * wk:.0f} ms "
                  f"against {1e3 * w1:.0f} ms for one alone: the machine gives this work at most {threads[-1] * w1 / wk:.1f}x.", ""]
    for tag in bins if res["single"] else []:
        lines += [f"Single scan, {m['size']}^2 stored X3P, binary `{tag}`: median wall ms (speed-up over 1 thread)", ""]
        lines += ["| command | " + " | ".join(f"{t} thr" for t in threads) + " |", "| --- |" + " --- |" * len(threads)]
        for name in dict.fromkeys(r["cmd"] for r in res["single"] if r["bin"] == tag):
            v = {t: med([r["s"] for r in res["single"] if r["cmd"] == name and r["bin"] == tag and r["threads"] == t]) for t in threads}
            lines.append(f"| `{name}` | " + " | ".join(f"{1e3 * v[t]:.1f} ({ratio(v[threads[0]], v[t]):.1f}x)" for t in threads) + " |")
        names = list(dict.fromkeys(k for r in res["single"] if r["bin"] == tag for k in r.get("phases", {})))
        for cmd in ("ndf", "fit --model ggx-aniso"):
            for ph in names:
                v = {t: med([r["phases"][ph] for r in res["single"] if r["cmd"] == cmd and r["bin"] == tag and r["threads"] == t and ph in r["phases"]]) for t in threads}
                if all(x == x for x in v.values()):
                    lines.append(f"| `{cmd}` phase `{ph}` | " + " | ".join(f"{v[t]:.1f} ({ratio(v[threads[0]], v[t]):.1f}x)" for t in threads) + " |")
        for stage in ("read_ms", "ndf_ms", "fit_ms"):
            v = {t: med([r["timings"][stage] for r in res["single"] if "timings" in r and r["bin"] == tag and r["threads"] == t]) for t in threads}
            lines.append(f"| fit's `{stage}` | " + " | ".join(f"{v[t]:.1f} ({ratio(v[threads[0]], v[t]):.1f}x)" for t in threads) + " |")
        lines.append("")
    if not res["batch"]:
        return "\n".join(lines) + "\n"
    lines += [f"Batch, {m['scans']} deflated {m['batch_size']}^2 X3Ps: median wall s", "",
              "| jobs | `batch --model ggx-aniso` | speed-up | floor (`unzip -p`, as many processes) | batch / floor "
              "| floor (zlib, as many worker processes) | batch / zlib floor | as many one-job batches, one thread each | batch / those |",
              "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    def batch(tag, j, model="ggx-aniso"):
        return med([r["s"] for r in res["batch"] if r["model"] == model and r["bin"] == tag and r["jobs"] == j])

    b1 = batch("new", threads[0])
    for j in threads:
        b = batch("new", j)
        f = med([r["s"] for r in res["floor"] if r["jobs"] == j]) if have_unzip else float("nan")
        fz = med([r["s"] for r in res.get("floor_zlib", []) if r["jobs"] == j])
        sp = med([r["s"] for r in res.get("split", []) if r["jobs"] == j])
        lines.append(f"| {j} | {b:.2f} | {b1 / b:.1f}x | {f:.2f} | {b / f:.2f} | {fz:.2f} | {b / fz:.2f} | {sp:.2f} | {b / sp:.2f} |")
    for tag in bins:
        if tag != "new":
            js = sorted({threads[0], threads[-1]}) if tag == "base" else [threads[-1]]
            lines += ["", f"The same batch with binary `{tag}`: " + ", ".join(f"{batch(tag, j):.2f} s at {j} job(s)" for j in js) + "."]
    top = threads[-1]
    auto_b, gb = batch("new", top, "auto"), batch("new", top)
    iso = batch("new", top, "ggx-aniso --isolate process")
    lines += ["", f"`batch --model ggx-aniso --jobs {top} --isolate process` (a child process per scan): {iso:.2f} s."]
    lines += ["", f"`batch --model auto --jobs {top}`: {auto_b:.2f} s, {auto_b / gb:.2f}x the ggx-aniso batch.", ""]
    for t in sorted({r["threads"] for r in res["auto"]}):
        g = med([r["s"] for r in res["auto"] if r["model"] == "ggx-aniso" and r["threads"] == t])
        au = med([r["s"] for r in res["auto"] if r["model"] == "auto" and r["threads"] == t])
        lines.append(f"One {m['batch_size']}^2 scan at {t} thread(s): `fit --model auto` {1e3 * au:.0f} ms, "
                     f"`--model ggx-aniso` {1e3 * g:.0f} ms: {au / g:.2f}x.")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    sys.exit(main())
