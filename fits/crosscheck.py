#!/usr/bin/env python3
"""Cross-check the Rust fitter (`ndfit fit`) against the independent numpy + nlopt fit (ndfitpy).

Per scan: `ndfit ndf SCAN -o x.csv`, then per model `ndfit fit SCAN --model M -o rust.json` (same NDF options)
and ndfitpy's fit of x.csv. Both fitted models are evaluated in numpy on the NDF's bins:

- delta: the parameter-free NDF difference of data_formats/objective.md, the larger of delta(D_rust; D_py) and
  delta(D_py; D_rust);
- F_rust, F_py: the Poisson deviance (objective.md) of each fit on the same bins.

A row FAILS when delta > 1e-3 (0.1%) or when Rust's objective is worse than nlopt's by more than 1e-6
relative, or when a command fails. The table shows canonical parameters (ndfitpy.canonical). Exit status 0
when every row passes, 1 otherwise; the last line sums it up.

Scans: the real ones of ../shared/data/scans (relative to the repository root; a clear SKIP line when that
folder is absent, a failure naming it when NDFIT_REQUIRE_SHARED=1) and synthetic ones made with `ndfit synth`.

Then the end-to-end part (ndfitpy.endtoend, skipped with --no-e2e): the same scan files, synthetic (written
as X3P by ndfit synth, and rewritten here as NPY and GSF) and the real X3P scans, go through the numpy pipeline
(own reader, plane removal, slopes, bins, nlopt fit) and through ndfit; the samples, the empirical NDFs cell by
cell, the two fits and the synthetic truth are compared.

Usage: python fits/crosscheck.py --ndfit target/release/ndfit [--models ggx,ellipsoid] [--no-real] [--no-e2e]
"""

from __future__ import annotations

import argparse
import concurrent.futures
import json
import math
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from typing import List, Optional

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)  # run from a checkout without installing: the package sits next to this file

import numpy as np  # noqa: E402

from ndfitpy import canonical, endtoend, fitjson, models, scanio  # noqa: E402
from ndfitpy import objective as obj  # noqa: E402
from ndfitpy.bins import read_ndf_csv  # noqa: E402
from ndfitpy.tail import cut_rim  # noqa: E402
from ndfitpy.tail import cut_unresolved as tail_cut  # noqa: E402
from ndfitpy.fit import fit  # noqa: E402
from ndfitpy.rounding import from_docs as rounding_of  # noqa: E402

REPO = os.path.dirname(HERE)
DELTA_TOL = 1e-3  # the 0.1% on the NDF
OBJ_TOL = 1e-6  # Rust's deviance may exceed nlopt's by this much, relative
SCAN_EXTS = (".x3p", ".plu", ".sur", ".opd", ".al3d", ".tmd", ".dat", ".gsf", ".npy", ".exr", ".asc", ".xyz")

# Synthetic scans: (name, `ndfit synth` arguments, NDF options). --nx/--ny come from --size. `--form none`:
# ndfit's default form removal (a least-squares plane) would take the mean slope, i.e. the ellipsoid's tilt,
# out of the NDF; without it the NDF is the one the truth describes. Every model is fitted to every scan.
SYNTH_CASES = [
    ("synth-ellipsoid", ["--surface", "ellipsoid", "--alpha-x", "0.2", "--alpha-y", "0.35", "--theta-x", "0.15",
                         "--theta-y", "-0.1", "--theta-z", "0.6"], ["--form", "none"]),
    ("synth-ggx", ["--surface", "ellipsoid", "--alpha-x", "0.3"], ["--form", "none"]),
    ("synth-mirror", ["--surface", "ellipsoid", "--alpha-x", "0.03", "--alpha-y", "0.05", "--theta-z", "-0.4"],
     ["--form", "none"]),
    ("synth-gaussian", ["--surface", "gaussian", "--sigma-x", "0.15", "--sigma-y", "0.3", "--theta-z", "0.5"],
     ["--form", "none"]),
]
# Scans fitted with `ndfit fit --tail unresolved` against ndfitpy.tail's own cut of the CSV's bins.
TAIL_CASES = [
    ("synth-narrow-tail", ["--surface", "ellipsoid", "--alpha-x", "0.05", "--theta-x", "0.4"], ["--form", "none"]),
]


@dataclass
class Row:
    """One (scan, model) comparison."""

    scan: str
    model: str
    delta: Optional[float] = None
    f_rust: Optional[float] = None
    f_py: Optional[float] = None
    t_rust: Optional[float] = None
    t_py: Optional[float] = None
    p_rust: dict = field(default_factory=dict)
    p_py: dict = field(default_factory=dict)
    verdict: str = "FAIL"
    notes: List[str] = field(default_factory=list)

    @property
    def rel_obj(self) -> Optional[float]:
        """(F_rust - F_py) / |F_py|: positive when Rust's fit is worse."""
        if self.f_rust is None or self.f_py is None:
            return None
        return (self.f_rust - self.f_py) / max(abs(self.f_py), 1e-300)


def first_line(text: str) -> str:
    lines = [ln.strip() for ln in (text or "").strip().splitlines() if ln.strip()]
    return lines[-1] if lines else ""


def run(cmd: List[str], timeout: float):
    """Run a command; returns (ok, seconds, message). Never raises for the command's own failure."""
    t0 = time.perf_counter()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        return False, time.perf_counter() - t0, f"timed out after {timeout:.0f} s: {shlex.join(cmd)}"
    except OSError as e:
        return False, time.perf_counter() - t0, f"cannot run {cmd[0]}: {e.strerror or e}"
    dt = time.perf_counter() - t0
    if p.returncode != 0:
        msg = first_line(p.stderr) or first_line(p.stdout) or "(no message)"
        return False, dt, f"exit {p.returncode}: {msg}"
    return True, dt, ""


def fmt_params(model: str, params: dict) -> str:
    if not params:
        return "-"
    out = []
    for k, v in params.items():
        short = k.replace("alpha_", "a").replace("theta_", "t").replace("alpha", "a")
        out.append(f"{short}={v:.5g}")
    return " ".join(out)


def compare(scan_name: str, model: str, bins, rust_doc: dict, py_res, t_rust: float) -> Row:
    """Evaluate both fits on the bins and judge the row."""
    row = Row(scan=scan_name, model=model, t_rust=t_rust, t_py=py_res.seconds)
    b = bins.used()
    rust_model = rust_doc["model"]
    if rust_model != model:
        row.notes.append(f"rust fitted '{rust_model}', asked '{model}'")
    rp = rust_doc["params"]
    ld_rust = models.log_d(rust_model, rp, b.m)
    ld_py = models.log_d(model, py_res.params, b.m)
    if rust_model in models.ELLIPSOID_FAMILY and "matrix_a" in rust_doc:
        ld_a = models.log_d_matrix(np.asarray(rust_doc["matrix_a"], dtype=float), b.m)
        d_a = obj.delta(ld_a, ld_rust, b.proj_solid_angle)
        if d_a > 1e-9:
            row.notes.append(f"rust matrix_a and params disagree (delta {d_a:.2e})")
    row.delta = max(obj.delta(ld_rust, ld_py, b.proj_solid_angle), obj.delta(ld_py, ld_rust, b.proj_solid_angle))
    row.f_rust = obj.poisson_deviance(rust_model, rp, b)
    row.f_py = py_res.value if py_res.objective == "poisson" else obj.poisson_deviance(model, py_res.params, b)
    reported = fitjson.objective_value(rust_doc)
    if reported is not None and abs(reported - row.f_rust) > 1e-6 * max(abs(row.f_rust), 1.0):
        row.notes.append(f"rust reports objective {reported:.9g}, numpy gets {row.f_rust:.9g} on the CSV bins")
    row.p_rust = canonical.canonical(rust_model, rp)
    row.p_py = canonical.canonical(model, py_res.params)
    bad = []
    if not (row.delta <= DELTA_TOL):
        bad.append(f"NDFs differ by {row.delta:.2e} > {DELTA_TOL:g}")
    if not (row.rel_obj <= OBJ_TOL):
        bad.append(f"rust objective worse by {row.rel_obj:.2e} relative")
    if row.rel_obj < -OBJ_TOL:
        row.notes.append(f"rust objective better than nlopt's by {-row.rel_obj:.2e} relative (nlopt side short)")
    row.verdict = "ok" if not bad else "FAIL"
    if bad:
        bad.append(diagnose(row))
    row.notes = bad + row.notes
    return row


def diagnose(row: "Row") -> str:
    """Which side is wrong, from the two deviances on the same bins (both evaluated here in numpy)."""
    if row.rel_obj is not None and row.rel_obj > OBJ_TOL:
        return ("finding: Rust stopped short of the minimum (nlopt's parameters give a lower deviance on the "
                "same bins, evaluated by one function): the Rust side is wrong")
    if row.rel_obj is not None and row.rel_obj < -OBJ_TOL:
        return "finding: nlopt stopped short of the minimum (Rust's deviance is lower): the Python side is wrong"
    return ("finding: equal deviances but different NDFs: a flat objective (parameters not identified by the "
            "data) or two minima of equal depth")


def check_scan(ndfit: str, scan: str, name: str, model_list, work: str, ndf_args, timeout, tail: bool = False) -> List[Row]:
    """All models on one scan; every failure becomes a row. With ``tail``, ndfit fits with `--tail unresolved` and
    ndfitpy fits the bins its own tail cut (ndfitpy.tail) keeps; both are then compared on those bins."""
    rows: List[Row] = []
    csv = os.path.join(work, f"{name}.ndf.csv")
    ok, t_ndf, msg = run([ndfit, "ndf", scan, "-o", csv, *ndf_args], timeout)
    if not ok:
        return [Row(scan=name, model=m, notes=[f"ndfit ndf failed: {msg}"]) for m in model_list]
    try:
        bins = read_ndf_csv(csv)
    except ValueError as e:
        return [Row(scan=name, model=m, notes=[f"reading ndfit's NDF: {e}"]) for m in model_list]
    fit_args = []
    # The NDF's JSON carries what the CSV does not: the normal scheme (for the rule of a height rounding the
    # fit states it modelled, ndfitpy.rounding) and the binning frame the default tail rule (rim) needs.
    js = os.path.join(work, f"{name}.ndf.json")
    ok, _, msg = run([ndfit, "ndf", scan, "-o", js, *ndf_args], timeout)
    if not ok:
        return [Row(scan=name, model=m, notes=[f"ndfit ndf (json) failed: {msg}"]) for m in model_list]
    with open(js, encoding="utf-8") as fh:
        ndf_doc = json.load(fh)
    if not tail and bins.extra.get("unresolved") is not None:
        # (Without the CSV's unresolved counts no tail rule applies.)
        bins, _ = cut_rim(bins, ndf_doc["frame"])
    if tail:
        bins, info = tail_cut(bins)
        fit_args = ["--tail", "unresolved"]
        if info.bins_excluded == 0:
            return [Row(scan=name, model=m, notes=[f"the tail cut left nothing out ({info.rule}): the case tests nothing"]) for m in model_list]
    for m in model_list:
        out = os.path.join(work, f"{name}.{m}.rust.json")
        ok, t_rust, msg = run([ndfit, "fit", scan, "--model", m, "-o", out, *ndf_args, *fit_args], timeout)
        if not ok:
            rows.append(Row(scan=name, model=m, t_rust=t_rust, notes=[f"ndfit fit failed: {msg}"]))
            continue
        try:
            doc = fitjson.read_fit(out)
            bins.rounding = rounding_of(ndf_doc, doc)
            py = fit(bins, m)
            row = compare(name, m, bins, doc, py, t_rust)
        except Exception as e:  # one broken row must not stop the others
            rows.append(Row(scan=name, model=m, t_rust=t_rust, notes=[f"{type(e).__name__}: {e}"]))
            continue
        fitjson.write_fit(os.path.join(work, f"{name}.{m}.py.json"), py, bins, {"path": scan})
        rows.append(row)
    return rows


def load_known(path: str) -> dict:
    """Known findings keyed by (scan, model); a missing file is an empty list."""
    if not path or not os.path.exists(path):
        return {}
    with open(path, encoding="utf-8") as fh:
        items = json.load(fh)
    return {(k["scan"], k["model"]): k for k in items}


def real_scans(folder: str) -> List[str]:
    out = []
    for f in sorted(os.listdir(folder)):
        p = os.path.join(folder, f)
        if os.path.isfile(p) and f.lower().endswith(SCAN_EXTS):
            out.append(p)
    return out


def print_table(rows: List[Row], file=sys.stdout) -> None:
    head = ("scan", "model", "delta", "F_rust", "F_py", "(Fr-Fp)/Fp", "t_rust", "t_py", "rust (canonical)",
            "nlopt (canonical)", "verdict")
    cells = []
    for r in rows:
        cells.append((
            r.scan, r.model,
            "-" if r.delta is None else f"{r.delta:.2e}",
            "-" if r.f_rust is None else f"{r.f_rust:.8g}",
            "-" if r.f_py is None else f"{r.f_py:.8g}",
            "-" if r.rel_obj is None else f"{r.rel_obj:+.1e}",
            "-" if r.t_rust is None else f"{r.t_rust:.2f}s",
            "-" if r.t_py is None else f"{r.t_py:.2f}s",
            fmt_params(r.model, r.p_rust), fmt_params(r.model, r.p_py), r.verdict,
        ))
    widths = [max(len(h), *(len(c[i]) for c in cells)) if cells else len(h) for i, h in enumerate(head)]
    print("  ".join(h.ljust(w) for h, w in zip(head, widths)), file=file)
    for c, r in zip(cells, rows):
        print("  ".join(x.ljust(w) for x, w in zip(c, widths)), file=file)
        for n in r.notes:
            print(f"    {r.scan}/{r.model}: {n}", file=file)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--ndfit", required=True, help="path of the ndfit binary")
    ap.add_argument("--scans", default=os.path.join(REPO, "..", "shared", "data", "scans"),
                    help="folder of real scans (default: ../shared/data/scans from the repository root)")
    ap.add_argument("--models", default=",".join(models.MODELS + models.STUDENTS + models.MIXTURES),
                    help="comma-separated model ids (default: every one, the Student-t lobes and mixtures included)")
    ap.add_argument("--size", type=int, default=384, help="synthetic scan size in pixels (square)")
    ap.add_argument("--no-real", action="store_true", help="skip the real scans")
    ap.add_argument("--no-synth", action="store_true", help="skip the synthetic scans")
    ap.add_argument("--no-e2e", action="store_true", help="skip the end-to-end part (numpy pipeline from the scan)")
    ap.add_argument("--no-csv", action="store_true", help="skip the part that fits ndfit's NDF CSV with nlopt")
    ap.add_argument("--e2e-real-model", default="ggx-aniso", help="model of the end-to-end check on real scans")
    ap.add_argument("--only", default="", help="comma-separated substrings: check only scans whose name has one")
    ap.add_argument("--ndf-args", default="", help="extra NDF options passed to both ndfit ndf and ndfit fit")
    ap.add_argument("--timeout", type=float, default=600.0, help="seconds per ndfit command")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1,
                    help="scans checked side by side (default: one per core; the nlopt fits run on one core each)")
    ap.add_argument("--work", help="keep intermediate files here (default: a temporary folder, removed)")
    ap.add_argument("--json", help="also write the rows as JSON to this file")
    ap.add_argument("--known", default=os.path.join(HERE, "crosscheck_known.json"),
                    help="JSON list of known findings {scan, model, side, reason}: reported, not counted as failures")
    args = ap.parse_args(argv)

    model_list = [m.strip() for m in args.models.split(",") if m.strip()]
    for m in model_list:
        if m not in models.PARAM_NAMES:
            print(f"crosscheck: unknown model '{m}'", file=sys.stderr)
            return 2
    ndfit = args.ndfit
    if not (os.path.isfile(ndfit) and os.access(ndfit, os.X_OK)):
        print(f"crosscheck: {ndfit}: not an executable file (build it: cargo build --release)", file=sys.stderr)
        return 2
    ndf_args = shlex.split(args.ndf_args)
    only = [s for s in args.only.split(",") if s]
    work = args.work or tempfile.mkdtemp(prefix="ndfit-crosscheck-")
    os.makedirs(work, exist_ok=True)
    rows: List[Row] = []
    e2e_rows: List[endtoend.E2ERow] = []
    skipped = []
    missing = []
    strict = os.environ.get("NDFIT_REQUIRE_SHARED", "") not in ("", "0")
    t0 = time.perf_counter()
    try:
        scans = []
        synth = []
        if not args.no_synth:
            for name, synth_args, case_ndf_args in SYNTH_CASES:
                if only and not any(s in name for s in only):
                    continue
                path = os.path.join(work, f"{name}.x3p")
                size = str(args.size)
                ok, _, msg = run([ndfit, "synth", path, *synth_args, "--nx", size, "--ny", size], args.timeout)
                if ok:
                    scans.append((path, name, case_ndf_args))
                    synth.append((path, name))
                else:
                    rows += [Row(scan=name, model=m, notes=[f"ndfit synth failed: {msg}"]) for m in model_list]
        tail_scans = []
        if not args.no_synth and not args.no_csv:
            for name, synth_args, case_ndf_args in TAIL_CASES:
                if only and not any(s in name for s in only):
                    continue
                path = os.path.join(work, f"{name}.x3p")
                size = str(args.size)
                ok, _, msg = run([ndfit, "synth", path, *synth_args, "--nx", size, "--ny", size], args.timeout)
                if ok:
                    tail_scans.append((path, name, case_ndf_args))
                else:
                    rows += [Row(scan=name, model=m, notes=[f"ndfit synth failed: {msg}"]) for m in model_list]
        real = []
        if not args.no_real:
            if os.path.isdir(args.scans):
                for p in real_scans(args.scans):
                    name = os.path.basename(p)
                    if only and not any(s in name for s in only):
                        continue
                    scans.append((p, name, []))
                    real.append((p, name))
            elif strict:
                print(f"FAIL real scans: {os.path.normpath(args.scans)} is absent and NDFIT_REQUIRE_SHARED is set")
                missing.append(os.path.normpath(args.scans))
            else:
                print(f"SKIP real scans: {os.path.normpath(args.scans)} is absent")
                skipped.append("real scans")
        # Every scan is one task (its CSV rows, or its end-to-end rows); tasks run side by side in --jobs worker
        # processes and their rows are gathered in the order below, so the table reads the same at any --jobs.
        tasks = []
        if not args.no_csv:
            tasks += [("csv", check_scan, (ndfit, path, name, model_list, work, case_ndf_args + ndf_args, args.timeout),
                       name) for path, name, case_ndf_args in scans]
            tasks += [("csv", check_scan, (ndfit, path, name, model_list, work, case_ndf_args + ndf_args, args.timeout,
                                           True), name + " (--tail unresolved)")
                      for path, name, case_ndf_args in tail_scans]
        if not args.no_e2e:
            tasks += e2e_tasks(ndfit, synth, real, work, args)
        for kind, result in run_tasks(tasks, args.jobs):
            if kind == "csv":
                rows += result
            else:
                e2e_rows += result
    finally:
        if not args.work:
            shutil.rmtree(work, ignore_errors=True)
    known = load_known(args.known)
    fixed = []
    for r in rows:
        k = known.get((r.scan, r.model))
        if k is None:
            continue
        if r.verdict == "FAIL" and not any(n.startswith("ndfit ") for n in r.notes):
            r.verdict = "KNOWN"
            r.notes.insert(0, f"known finding ({k.get('side', '?')} side): {k.get('reason', '')}")
        elif r.verdict == "ok":
            fixed.append(f"{r.scan}/{r.model}")
    print_table(rows)
    if fixed:
        print(f"known findings that now pass (remove them from {args.known}): {', '.join(fixed)}")
    if args.json:
        fitjson.write_atomic(args.json, json.dumps([r.__dict__ | {"rel_obj": r.rel_obj} for r in rows], indent=1,
                                                   default=float) + "\n")
    passed = sum(r.verdict == "ok" for r in rows)
    n_known = sum(r.verdict == "KNOWN" for r in rows)
    failed = len(rows) - passed - n_known
    worst = max((r.delta for r in rows if r.delta is not None and r.verdict == "ok"), default=float("nan"))
    print(f"(worst delta among passing rows {worst:.2e}, tolerance {DELTA_TOL:g}; objective tolerance {OBJ_TOL:g} "
          f"relative; {time.perf_counter() - t0:.0f} s{'; skipped: ' + ', '.join(skipped) if skipped else ''})")
    if n_known:
        print(f"{n_known} known findings (listed in {os.path.relpath(args.known)}, shown as KNOWN above) are "
              "counted as skipped, not passed")
    if e2e_rows:
        print("\nend to end (scan file -> fit, numpy pipeline vs ndfit):")
        endtoend.print_table(e2e_rows)
    e2e_passed = sum(r.verdict == "ok" for r in e2e_rows)
    e2e_failed = len(e2e_rows) - e2e_passed
    print(f"crosscheck: {passed} passed, {failed} failed" + (f", {n_known} skipped" if n_known else "")
          + ("" if args.no_e2e else f"; end to end: {e2e_passed} passed, {e2e_failed} failed")
          + (f"; missing (NDFIT_REQUIRE_SHARED is set): {', '.join(missing)}" if missing else ""))
    return 0 if failed == 0 and e2e_failed == 0 and not missing and (rows or e2e_rows) else 1


def run_tasks(tasks, jobs: int):
    """Runs each (kind, function, arguments, label) task, `jobs` at a time in worker processes; yields
    (kind, rows) in the tasks' order. A task that dies (its worker crashed) yields no rows but a failure line."""
    if jobs <= 1 or len(tasks) <= 1:
        for kind, fn, fn_args, label in tasks:
            print(f"-- {label}", file=sys.stderr, flush=True)
            yield kind, fn(*fn_args)
        return
    # One thread per numpy process: the workers already fill the cores.
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, "1")
    with concurrent.futures.ProcessPoolExecutor(max_workers=jobs) as pool:
        futures = [(kind, label, pool.submit(fn, *fn_args)) for kind, fn, fn_args, label in tasks]
        for kind, label, fut in futures:
            try:
                result = fut.result()
            except Exception as e:  # noqa: BLE001 (a crashed task must not hide the others' rows)
                print(f"FAIL {label}: the task died: {type(e).__name__}: {e}", file=sys.stderr, flush=True)
                result = [failed_task_row(kind, label, f"the task died: {type(e).__name__}: {e}")]
            print(f"-- {label} done", file=sys.stderr, flush=True)
            yield kind, result


def failed_task_row(kind: str, label: str, note: str):
    """The row that stands for a task with no rows of its own, so that the run fails naming it."""
    if kind == "csv":
        return Row(scan=label, model="-", notes=[note])
    return endtoend.E2ERow(scan=label, model="-", errors=[note])


def e2e_tasks(ndfit: str, synth, real, work: str, args):
    """The end-to-end tasks: each synthetic scan with its truth's model (two of them rewritten as NPY and GSF so
    that those readers are compared too), each real X3P scan with --e2e-real-model."""
    tasks = [("e2e", e2e_synthetic, (ndfit, path, name, work, args.timeout), f"end to end: {name}")
             for path, name in synth]
    tasks += [("e2e", endtoend.check_scan, (ndfit, path, name, [args.e2e_real_model], work, "plane", [], None,
                                            args.timeout), f"end to end: {name}")
              for path, name in real if name.lower().endswith(".x3p")]
    return tasks


def e2e_synthetic(ndfit: str, path: str, name: str, work: str, timeout: float) -> List["endtoend.E2ERow"]:
    """One synthetic scan end to end, against its truth's model."""
    as_format = {"synth-ggx": ".npy", "synth-mirror": ".gsf"}
    try:
        with open(os.path.splitext(path)[0] + ".truth.json", encoding="utf-8") as fh:
            truth = json.load(fh)
    except (OSError, ValueError) as e:
        return [endtoend.E2ERow(scan=name, model="-", errors=[f"reading the truth: {e}"])]
    ext = as_format.get(name, ".x3p")
    scan, rust_args, dx = path, [], None
    if ext != ".x3p":
        hm = scanio.read_scan(path)
        scan = os.path.join(work, name + ext)
        if ext == ".npy":
            np.save(scan, hm.z)
            dx = hm.dx
            rust_args = ["--dx", repr(hm.dx), "--z-scale", "1"]
        else:
            scanio.write_gsf(scan, hm)
    return endtoend.check_scan(ndfit, scan, name + ext, [truth["model"]], work, "none", rust_args, truth, timeout,
                               dx=dx)


if __name__ == "__main__":
    sys.exit(main())
