#!/usr/bin/env python3
"""Write the notebooks of this folder from the cell sources below (outputs empty).

    fits/.venv/bin/python notebooks/build_notebooks.py

Edit the cells here, not in the .ipynb files, so the notebooks stay reviewable as Python and free of outputs.
"""

import os

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = os.path.dirname(os.path.abspath(__file__))

COMMON = r'''
import json, math, os, shutil, subprocess, sys, tempfile, time
import numpy as np
import matplotlib.pyplot as plt

def find_root():
    d = os.getcwd()
    while d != os.path.dirname(d):
        if os.path.exists(os.path.join(d, "Cargo.toml")) and os.path.isdir(os.path.join(d, "fits")):
            return d
        d = os.path.dirname(d)
    raise RuntimeError("run this notebook inside the ndfit repository")

ROOT = find_root()
sys.path.insert(0, os.path.join(ROOT, "fits"))  # ndfitpy, even without pip install -e
from ndfitpy import canonical, fitjson, models, objective as obj
from ndfitpy.bins import read_ndf_csv
from ndfitpy.fit import fit as nlopt_fit
from ndfitpy.x3p import read_x3p

NDFIT = os.environ.get("NDFIT", "target/release/ndfit")
NDFIT = NDFIT if os.path.isabs(NDFIT) else os.path.join(ROOT, NDFIT)
if not os.access(NDFIT, os.X_OK):
    raise RuntimeError(f"no ndfit binary at {NDFIT}: run `cargo build --release` or set NDFIT")
SCANS = os.path.normpath(os.path.join(ROOT, "..", "shared", "data", "scans"))
WORK = tempfile.mkdtemp(prefix="ndfit-notebook-")

def ndfit(*args, check=True):
    """Run the ndfit binary; returns its standard output (raises with ndfit's one-line error)."""
    p = subprocess.run([NDFIT, *map(str, args)], capture_output=True, text=True)
    if check and p.returncode != 0:
        raise RuntimeError(f"ndfit {' '.join(map(str, args))}: {p.stderr.strip()}")
    return p.stdout

def has_command(name):
    return subprocess.run([NDFIT, name, "--help"], capture_output=True).returncode == 0

print("ndfit:", ndfit("--version").strip(), "| work folder:", WORK)
'''

SYNTH = r'''
# A synthetic scan with known truth: the upper half of a tilted, anisotropic ellipsoid (its NDF is exactly
# Walter et al.'s ellipsoid NDF, eq. 1), 384 x 384 pixels.
SYNTH_ARGS = ["--surface", "ellipsoid", "--alpha-x", "0.2", "--alpha-y", "0.35", "--theta-x", "0.15",
              "--theta-y", "-0.1", "--theta-z", "0.6", "--nx", "384", "--ny", "384"]
synth_scan = os.path.join(WORK, "synth.x3p")
print(ndfit("synth", synth_scan, *SYNTH_ARGS))
# ndfit removes a least-squares plane by default (right for real scans); here it would take the ellipsoid's
# tilt out of the NDF, so the synthetic scan is read with --form none.
SYNTH_OPTS = ["--form", "none"]
truth_path = next((p for p in (synth_scan + ".truth.json", synth_scan[:-4] + ".truth.json") if os.path.exists(p)), None)
truth = json.load(open(truth_path)) if truth_path else None
print("truth:", truth and {"model": truth["model"], "params": truth["params"]})
'''

TOUR_FUNCS = r'''
def show_heights(scan, title):
    info = json.loads(ndfit("info", scan, "--json"))
    print(json.dumps({k: info[k] for k in ("format", "nx", "ny", "dx", "dy", "invalid", "sq") if k in info}))
    try:
        hm = read_x3p(scan)
    except ValueError as e:
        print("no height picture:", e)
        return info
    fig, ax = plt.subplots(figsize=(7, 3.5))
    ny, nx = hm.z.shape
    im = ax.imshow(hm.z * 1e6, extent=[0, nx * hm.dx * 1e6, ny * hm.dy * 1e6, 0], cmap="viridis")
    ax.set_xlabel("x (um)"); ax.set_ylabel("y (um)"); ax.set_title(f"{title}: heights (um)")
    fig.colorbar(im, ax=ax, shrink=0.8)
    plt.show()
    return info

def disk_plot(ax, bins, values, title, cmap="magma", vmin=None, vmax=None, label=""):
    """Bins drawn at (mx, my): the hemisphere seen from above (orthographic), n = +z at the centre."""
    sc = ax.scatter(bins.m[:, 0], bins.m[:, 1], c=values, s=4, cmap=cmap, vmin=vmin, vmax=vmax, linewidths=0)
    ax.set_aspect("equal"); ax.set_title(title, fontsize=9); ax.set_xlabel("mx"); ax.set_ylabel("my")
    plt.colorbar(sc, ax=ax, shrink=0.75, label=label)

def empirical(scan, name, opts=()):
    csv = os.path.join(WORK, f"{name}.ndf.csv")
    ndfit("ndf", scan, "-o", csv, *opts)
    b = read_ndf_csv(csv).used()
    occ = b.count > 0
    print(f"{len(b)} bins, {int(b.n_samples)} samples, {occ.sum()} occupied; sum d W = {np.sum(b.d * b.proj_solid_angle):.6f}")
    fig, ax = plt.subplots(figsize=(5, 4.2))
    sub = type(b)(m=b.m[occ], count=b.count[occ], proj_solid_angle=b.proj_solid_angle[occ], d=b.d[occ])
    disk_plot(ax, sub, np.log10(sub.d), f"{name}: empirical NDF", label="log10 D (1/sr)")
    plt.show()
    return csv, b

def fit_all(scan, name, bins, opts=()):
    rows, fits = [], {}
    for m in models.MODELS:
        out = os.path.join(WORK, f"{name}.{m}.json")
        t0 = time.perf_counter(); ndfit("fit", scan, "--model", m, "-o", out, *opts); t = time.perf_counter() - t0
        doc = fitjson.read_fit(out)
        fits[m] = doc
        f = obj.poisson_deviance(m, doc["params"], bins)
        k = obj.dof(m, bins)
        py = nlopt_fit(bins, m)
        d_py = obj.model_delta(m, doc["params"], m, py.params, bins)
        rows.append((m, canonical.canonical(m, doc["params"]), f, f / k, d_py, t))
    print(f"{'model':15s} {'deviance':>12s} {'F/(K-p)':>9s} {'delta(rust,nlopt)':>18s} {'t_fit':>6s}  canonical parameters")
    for m, p, f, rc, d, t in rows:
        ps = " ".join(f"{k}={v:.4g}" for k, v in p.items())
        print(f"{m:15s} {f:12.2f} {rc:9.3f} {d:18.2e} {t:5.2f}s  {ps}")
    return fits

def residual_maps(bins, fits, name):
    fig, axes = plt.subplots(1, len(fits), figsize=(4 * len(fits), 3.6))
    for ax, (m, doc) in zip(axes, fits.items()):
        r = obj.poisson_residuals(m, doc["params"], bins)
        lim = max(3.0, np.percentile(np.abs(r), 99))
        disk_plot(ax, bins, r, f"{name}: {m}\nF = {np.sum(r * r):.0f}", cmap="RdBu_r", vmin=-lim, vmax=lim,
                  label="signed deviance residual")
    fig.tight_layout(); plt.show()

def auto_choice(scan, name, opts=()):
    out = os.path.join(WORK, f"{name}.auto.json")
    ndfit("fit", scan, "--model", "auto", "-o", out, *opts)
    doc = json.load(open(out))
    print(f"--model auto chose: {doc['model']}  params: {doc['params']}")
    sel = doc.get("selection")
    if isinstance(sel, dict):
        print(f"criterion: {sel.get('criterion')}")
        for c in sel.get("candidates", []):
            print(f"  {c.get('model', '?'):15s} criterion {c.get('criterion', float('nan')):14.2f}  "
                  f"reduced chi2 {c.get('reduced_chi2', float('nan')):9.3f}  delta_data {c.get('delta_data', float('nan')):.3f}")
    return doc
'''


def tour():
    cells = [
        new_markdown_cell(
            "# ndfit tour: height map, empirical NDF, fits of every model, residuals, `--model auto`\n\n"
            "Runs the `ndfit` binary (path from the environment variable `NDFIT`, default `target/release/ndfit`; "
            "build it with `cargo build --release`) on a synthetic scan with known truth and on a real scan from "
            "`../shared/data/scans`. The numbers it prints are computed in numpy by `fits/ndfitpy` (written from "
            "the papers, independently of the Rust code): deviance `F` and the NDF difference `delta` of "
            "`data_formats/objective.md`, and an nlopt fit of the same NDF for comparison."
        ),
        new_code_cell(COMMON.strip()),
        new_code_cell(TOUR_FUNCS.strip()),
        new_markdown_cell("## 1. A synthetic scan with known truth"),
        new_code_cell(SYNTH.strip()),
        new_code_cell('info = show_heights(synth_scan, "synthetic ellipsoid")'),
        new_markdown_cell(
            "The empirical NDF: bins of the hemisphere seen from above, coloured by log D. Its normalization "
            "(Heitz eq. 9) makes `sum d W` one."
        ),
        new_code_cell('csv, bins = empirical(synth_scan, "synth", SYNTH_OPTS)'),
        new_markdown_cell(
            "Every model fitted by `ndfit fit`, scored in numpy on the same bins. `F/(K-p)` is the reduced "
            "deviance; `delta(rust,nlopt)` the NDF difference between the Rust fit and an independent nlopt fit."
        ),
        new_code_cell(
            'fits = fit_all(synth_scan, "synth", bins, SYNTH_OPTS)\n'
            "if truth:\n"
            '    d_truth = obj.model_delta("ellipsoid", fits["ellipsoid"]["params"], truth["model"], truth["params"], bins)\n'
            '    print(f"ellipsoid fit vs truth: delta = {d_truth:.2e}")\n'
            '    print("truth (canonical):", canonical.canonical(truth["model"], truth["params"]))'
        ),
        new_markdown_cell(
            "Residual maps: the signed deviance residual per bin (`objective.md`). Structure (rings, "
            "lobes) means the model misses a feature of the data; noise means it explains it."
        ),
        new_code_cell('residual_maps(bins, fits, "synth")'),
        new_code_cell('auto = auto_choice(synth_scan, "synth", SYNTH_OPTS)'),
        new_markdown_cell("## 2. A real scan"),
        new_code_cell(
            'real = os.path.join(SCANS, "hamby44_downsampled_Barrel_1-Bullet_1-Land_1.x3p")\n'
            "HAVE_REAL = os.path.exists(real)\n"
            'print("real scan:", real if HAVE_REAL else f"SKIP ({SCANS} absent)")'
        ),
        new_code_cell(
            "if HAVE_REAL:\n"
            '    show_heights(real, "bullet land (Hamby 44)")\n'
            '    real_csv, real_bins = empirical(real, "real")\n'
            '    real_fits = fit_all(real, "real", real_bins)\n'
            '    residual_maps(real_bins, real_fits, "real")\n'
            '    auto_choice(real, "real")'
        ),
        new_code_cell("shutil.rmtree(WORK, ignore_errors=True)"),
    ]
    return cells


BENCH = r'''
def sweep_with_binary(sizes, models_=("ggx", "ellipsoid")):
    """Time the stages with the binary and measure accuracy against the synthetic truth, per scan size."""
    rows = []
    for n in sizes:
        scan = os.path.join(WORK, f"s{n}.x3p")
        t0 = time.perf_counter(); ndfit("synth", scan, *SYNTH_ARGS_BASE, "--nx", n, "--ny", n)
        t_synth = time.perf_counter() - t0
        truth_path = next(p for p in (scan + ".truth.json", scan[:-4] + ".truth.json") if os.path.exists(p))
        truth = json.load(open(truth_path))
        csv = os.path.join(WORK, f"s{n}.csv")
        t0 = time.perf_counter(); ndfit("ndf", scan, "-o", csv, "--form", "none"); t_ndf = time.perf_counter() - t0
        bins = read_ndf_csv(csv).used()
        for m in models_:
            out = os.path.join(WORK, f"s{n}.{m}.json")
            t0 = time.perf_counter(); ndfit("fit", scan, "--model", m, "-o", out, "--form", "none"); t_fit = time.perf_counter() - t0
            doc = fitjson.read_fit(out)
            py = nlopt_fit(bins, m)
            rows.append(dict(n=n, pixels=n * n, model=m, t_ndf=t_ndf, t_fit=t_fit, t_nlopt=py.seconds,
                             bins=len(bins), delta_truth=obj.model_delta(m, doc["params"], truth["model"], truth["params"], bins)))
    return rows
'''


def speed():
    cells = [
        new_markdown_cell(
            "# Speed and accuracy\n\n"
            "What each knob costs and buys. If the binary has `ndfit bench`, its quick sweep is run and plotted "
            "(time against error, the Pareto front). In any case the stages are timed with the binary itself on "
            "synthetic scans of growing size, with accuracy measured against the known truth by the NDF "
            "difference `delta` of `data_formats/objective.md` (computed in numpy). Timings on a shared 2-core "
            "machine are noisy: read them as orders of magnitude."
        ),
        new_code_cell(COMMON.strip()),
        new_code_cell(
            'SYNTH_ARGS_BASE = ["--surface", "ellipsoid", "--alpha-x", "0.2", "--alpha-y", "0.35", "--theta-x", "0.15",\n'
            '                   "--theta-y", "-0.1", "--theta-z", "0.6"]\n' + BENCH.strip()
        ),
        new_markdown_cell("## `ndfit bench --quick`"),
        new_code_cell(
            "import csv as _csv\n"
            "bench_rows = []\n"
            'if has_command("bench"):\n'
            '    out = os.path.join(WORK, "bench.csv")\n'
            "    try:\n"
            '        ndfit("bench", "--quick", "-o", out)\n'
            "        bench_rows = list(_csv.DictReader(open(out)))\n"
            "    except RuntimeError as e:\n"
            '        print("ndfit bench failed:", e)\n'
            'print(f"{len(bench_rows)} rows from ndfit bench", (list(bench_rows[0]) if bench_rows else ""))'
        ),
        new_code_cell(
            "def num(v):\n"
            "    try: return float(v)\n"
            "    except (TypeError, ValueError): return float('nan')\n"
            "if bench_rows:\n"
            "    cols = list(bench_rows[0])\n"
            '    tcol = next((c for c in cols if c.startswith("time") or c.startswith("t_")), None)\n'
            '    ecol = next((c for c in cols if "delta" in c or "error" in c), None)\n'
            "    if tcol and ecol:\n"
            "        t = np.array([num(r[tcol]) for r in bench_rows]); e = np.array([num(r[ecol]) for r in bench_rows])\n"
            "        ok = np.isfinite(t) & np.isfinite(e) & (t > 0) & (e > 0)\n"
            "        order = np.argsort(t[ok]); tt, ee = t[ok][order], e[ok][order]\n"
            "        front = np.minimum.accumulate(ee)\n"
            "        fig, ax = plt.subplots(figsize=(6, 4))\n"
            '        ax.loglog(tt, ee, "o", alpha=0.5, label="bench points")\n'
            '        ax.step(tt, front, where="post", color="k", label="Pareto front")\n'
            '        ax.set_xlabel(tcol); ax.set_ylabel(ecol); ax.legend(); ax.set_title("ndfit bench --quick")\n'
            "        plt.show()\n"
            "    else:\n"
            '        print("bench CSV has no recognizable time/error columns:", cols)'
        ),
        new_markdown_cell("## Stages timed with the binary, accuracy against truth"),
        new_code_cell(
            "rows = sweep_with_binary([128, 256, 512])\n"
            'print(f"{\'n\':>5s} {\'model\':10s} {\'bins\':>6s} {\'t_ndf\':>7s} {\'t_fit\':>7s} {\'t_nlopt\':>8s} {\'delta vs truth\':>15s}")\n'
            "for r in rows:\n"
            "    print(f\"{r['n']:5d} {r['model']:10s} {r['bins']:6d} {r['t_ndf']:7.3f} {r['t_fit']:7.3f} {r['t_nlopt']:8.3f} {r['delta_truth']:15.3e}\")"
        ),
        new_code_cell(
            "fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))\n"
            "for m in sorted({r['model'] for r in rows}):\n"
            "    rr = [r for r in rows if r['model'] == m]\n"
            "    px = np.array([r['pixels'] for r in rr])\n"
            "    a1.loglog(px, [r['t_fit'] for r in rr], 'o-', label=f'ndfit fit --model {m} (whole process)')\n"
            "    a1.loglog(px, [r['t_nlopt'] for r in rr], 's--', label=f'nlopt fit of the CSV ({m})')\n"
            "    a2.loglog(px, [r['delta_truth'] for r in rr], 'o-', label=m)\n"
            "rr = [r for r in rows if r['model'] == rows[0]['model']]\n"
            "a1.loglog([r['pixels'] for r in rr], [r['t_ndf'] for r in rr], 'k^-', label='ndfit ndf (whole process)')\n"
            "a1.set_xlabel('pixels'); a1.set_ylabel('seconds'); a1.legend(fontsize=7); a1.set_title('time')\n"
            "a2.set_xlabel('pixels'); a2.set_ylabel('delta(fit; truth)'); a2.legend(); a2.set_title('accuracy against truth')\n"
            "fig.tight_layout(); plt.show()\n"
            "px = np.array([r['pixels'] for r in rr], dtype=float)\n"
            "slope = np.polyfit(np.log(px), np.log([r['t_ndf'] for r in rr]), 1)[0]\n"
            "print(f'ndfit ndf time grows as pixels^{slope:.2f} over this range (process start-up dominates small scans)')"
        ),
        new_code_cell("shutil.rmtree(WORK, ignore_errors=True)"),
    ]
    return cells


def write(name, cells):
    nb = new_notebook(cells=cells)
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.metadata["language_info"] = {"name": "python"}
    path = os.path.join(HERE, name)
    with open(path, "w", encoding="utf-8") as fh:
        nbformat.write(nb, fh)
    print("wrote", path)


if __name__ == "__main__":
    write("01_tour.ipynb", tour())
    write("02_speed_accuracy.ipynb", speed())
