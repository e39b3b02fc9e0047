#!/usr/bin/env python3
"""Write the notebooks of this folder from the cell sources below (outputs empty), then execute them.

    fits/.venv/bin/python notebooks/build_notebooks.py
    NDFIT=target/release/ndfit fits/.venv/bin/python fits/run_notebooks.py --write notebooks

Edit the cells here, not in the .ipynb files, so the code stays reviewable as Python. The notebooks are
committed executed (the second command puts the outputs back), so a reader sees the figures and tables
without running anything; fits/tests/test_notebooks_committed.py checks that each committed notebook's
cells are the ones written here and that it carries the outputs of one complete run.
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
# CI sets NDFIT_REQUIRE_SHARED=1: an absent shared folder is then an error, not a skipped section.
REQUIRE_SHARED = os.environ.get("NDFIT_REQUIRE_SHARED", "") not in ("", "0")
WORK = tempfile.mkdtemp(prefix="ndfit-notebook-")

def ndfit(*args, check=True):
    """Run the ndfit binary; returns its standard output (raises with ndfit's one-line error)."""
    p = subprocess.run([NDFIT, *map(str, args)], capture_output=True, text=True)
    if check and p.returncode != 0:
        raise RuntimeError(f"ndfit {' '.join(map(str, args))}: {p.stderr.strip()}")
    return p.stdout

def has_command(name):
    return subprocess.run([NDFIT, name, "--help"], capture_output=True).returncode == 0

print("ndfit:", ndfit("--version").strip())
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
from ndfitpy.tail import cut_rim

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
    sc = ax.scatter(bins.m[:, 0], bins.m[:, 1], c=values, s=7, cmap=cmap, vmin=vmin, vmax=vmax, linewidths=0)
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
    full = read_ndf_csv(csv)
    if full.extra.get("unresolved") is not None:
        # The fit's default tail rule (`rim`, objective.md) keeps the whitened core when a lone lobe's rim is
        # unresolved (else only the unresolved bins leave); ndfitpy.tail applies it independently from the binning frame in the NDF's JSON, so
        # the numpy scores and the nlopt fits below see the region ndfit fits.
        js = os.path.join(WORK, f"{name}.ndf.json")
        ndfit("ndf", scan, "-o", js, *opts)
        with open(js, encoding="utf-8") as fh:
            frame = json.load(fh)["frame"]
        cut, info = cut_rim(full, frame)
        print(f"tail rule: {info.rule}; {info.bins_excluded} bins and {info.n_excluded:.0f} normals within max_theta left out")
        b = cut.used()
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
    worst = max(r[4] for r in rows)
    print(f"{'model':15s} {'deviance':>12s} {'F/(K-p)':>9s} {'delta(rust,nlopt)':>18s} {'t_fit':>6s}  canonical parameters")
    for m, p, f, rc, d, t in rows:
        ps = " ".join(f"{k}={v:.4g}" for k, v in p.items())
        print(f"{m:15s} {f:12.2f} {rc:9.3f} {d:18.2e} {t:5.2f}s  {ps}")
    # The cross-check's bound (fits/crosscheck.py DELTA_TOL): Rust and nlopt reach the same NDF on the same bins.
    assert worst <= 1e-3, f"{name}: Rust and nlopt fits differ by delta {worst:.2e} > 1e-3"
    return fits

def residual_maps(bins, fits, name):
    nrow = math.ceil(len(fits) / 3)
    fig, axes = plt.subplots(nrow, 3, figsize=(14, 4.3 * nrow))
    axes = axes.ravel()
    for ax in axes[len(fits):]:
        ax.axis("off")
    for ax, (m, doc) in zip(axes, fits.items()):
        # Residuals exist on the fit region only (bins within max_theta of n, objective.md).
        r = obj.poisson_residuals(m, doc["params"], bins)
        lim = max(3.0, np.percentile(np.abs(r), 99))
        disk_plot(ax, obj.region(bins), r, f"{name}: {m}\nF = {np.sum(r * r):.0f}", cmap="RdBu_r", vmin=-lim, vmax=lim,
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

RENDER = r"""
import mitsuba as mi
mi.set_variant("scalar_rgb")
fit_path = os.path.join(WORK, "synth.ggx-aniso.json")
exported = json.loads(ndfit("export", fit_path, "--to", "mitsuba", "--json"))
print("mitsuba:", exported)
scene = mi.load_dict({
    "type": "scene",
    "integrator": {"type": "path", "max_depth": 3},
    "sensor": {"type": "perspective", "fov": 28,
               "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
               "film": {"type": "hdrfilm", "width": 64, "height": 64, "rfilter": {"type": "box"}},
               "sampler": {"type": "independent", "sample_count": 16}},
    "sphere": {"type": "sphere", "bsdf": {"type": "roughconductor", "distribution": exported["distribution"],
                                          "alpha_u": exported["alpha_u"], "alpha_v": exported["alpha_v"]}},
    "light": {"type": "point", "position": [3.0, 3.0, 4.0], "intensity": {"type": "rgb", "value": 60.0}},
    "env": {"type": "constant", "radiance": {"type": "rgb", "value": 0.05}},
})
t0 = time.perf_counter()
image = np.array(mi.render(scene))
print(f"rendered in {time.perf_counter() - t0:.2f} s")
fig, (a0, a1) = plt.subplots(1, 2, figsize=(10, 4.2))
a0.imshow(np.clip(image / (1.0 + image), 0, 1) ** (1 / 2.2)); a0.set_title("Mitsuba 3: exported ggx-aniso fit"); a0.axis("off")
occ = bins.count > 0
sub = type(bins)(m=bins.m[occ], count=bins.count[occ], proj_solid_angle=bins.proj_solid_angle[occ], d=bins.d[occ])
disk_plot(a1, sub, np.log10(sub.d), "the scan's empirical NDF", label="log10 D (1/sr)")
plt.show()
"""


LADDER = r"""
def ladder(scan, name, bins, one="ggx-aniso", two=("ggx2", "ellipsoid+ggx")):
    # One lobe against two: each fitted by ndfit, scored in numpy on the same bins, cross-checked against nlopt.
    fits, rows = {}, []
    for m in (one, *two):
        out = os.path.join(WORK, f"{name}.{m}.json")
        ndfit("fit", scan, "--model", m, "-o", out)
        doc = fitjson.read_fit(out)
        fits[m] = doc
        f = obj.poisson_deviance(m, doc["params"], bins)
        py = nlopt_fit(bins, m)
        d_py = obj.model_delta(m, doc["params"], m, py.params, bins)
        rows.append((m, f, f / obj.dof(m, bins), doc["quality"].get("dispersion"), d_py, canonical.canonical(m, doc["params"])))
    print(f"{'model':14s} {'deviance':>10s} {'F/(K-p)':>8s} {'dispersion':>10s} {'delta(rust,nlopt)':>18s}  canonical parameters")
    for m, f, rc, disp, d, p in rows:
        print(f"{m:14s} {f:10.1f} {rc:8.3f} {disp:10.3f} {d:18.2e}  " + " ".join(f"{k}={v:.4g}" for k, v in p.items()))
    assert max(r[4] for r in rows) <= 1e-3, "Rust and nlopt mixtures differ by more than 0.1% in NDF"
    residual_maps(bins, fits, name)
    # A slice through the peak along the core's alpha_x axis: data (bins near the slice) against each model.
    # Walter et al.'s A = S Rz(theta_z) puts the alpha_x axis along (cos theta_z, -sin theta_z).
    tz = fits[two[0]]["params"]["theta_z"]
    ax_dir = np.array([math.cos(tz), -math.sin(tz)])
    b = bins.used()
    occ = b.count > 0
    t = b.m[:, :2] @ ax_dir
    off = np.abs(b.m[:, :2] @ np.array([-ax_dir[1], ax_dir[0]]))
    near = occ & (off < 0.03)
    fig, a = plt.subplots(figsize=(8, 4.2))
    a.semilogy(t[near], b.d[near], ".", color="0.4", label="data (bins within 0.03 of the slice)")
    ts = np.linspace(-0.9, 0.9, 400)
    line = np.column_stack([ts * ax_dir[0], ts * ax_dir[1], np.sqrt(1 - ts**2)])
    for m in (one, *two):
        a.semilogy(ts, models.d(m, fits[m]["params"], line), label=m)
    a.set_xlabel("m along the core's alpha_x axis"); a.set_ylabel("D (1/sr)"); a.set_ylim(max(1e-3, b.d[occ].min()), None)
    a.set_title(f"{name}: one lobe against two"); a.legend(loc="upper center", bbox_to_anchor=(0.5, -0.15), ncol=2)
    fig.tight_layout(); plt.show()
    auto = json.load(open(os.path.join(WORK, f"{name}.auto.json")))
    sel = auto["selection"]
    print("ladder:", sel.get("ladder"))
    for c in sel["candidates"]:
        print(f"  {c['model']:15s} F/c_data + p ln N = {c['qbic_data']:12.1f}  deviance/dof {c['deviance_per_dof']:8.3f}  "
              f"gain per added parameter {c.get('gain_per_param') if c.get('gain_per_param') is not None else float('nan'):10.1f}")
    return fits
"""

RENDER_LADDER = r"""
# The highlight of one lobe against two, rendered by Mitsuba 3 (a blendbsdf of two roughconductors, weight =
# the tail's share): the tail widens the highlight's skirt that a single lobe cannot hold.
import mitsuba as mi
mi.set_variant("scalar_rgb")
def sphere_bsdf(e):
    if "blend" in e:
        return {"type": "blendbsdf", "weight": e["weight"], "core": sphere_bsdf(e["bsdfs"][0]), "tail": sphere_bsdf(e["bsdfs"][1])}
    return {"type": "roughconductor", "distribution": e["distribution"], "alpha_u": e["alpha_u"], "alpha_v": e["alpha_v"]}
images = {}
for m in ("ggx-aniso", "ggx2"):
    e = json.loads(ndfit("export", os.path.join(WORK, f"real.{m}.json"), "--to", "mitsuba", "--json"))
    scene = mi.load_dict({
        "type": "scene", "integrator": {"type": "path", "max_depth": 3},
        "sensor": {"type": "perspective", "fov": 28,
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 5], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 64, "height": 64, "rfilter": {"type": "box"}},
                   "sampler": {"type": "independent", "sample_count": 16}},
        "sphere": {"type": "sphere", "bsdf": sphere_bsdf(e)},
        "light": {"type": "point", "position": [3.0, 3.0, 4.0], "intensity": {"type": "rgb", "value": 60.0}},
        "env": {"type": "constant", "radiance": {"type": "rgb", "value": 0.05}},
    })
    images[m] = np.array(mi.render(scene))
fig, axes = plt.subplots(1, 3, figsize=(13, 4.2))
for a, (m, im) in zip(axes, images.items()):
    a.imshow(np.clip(im / (1.0 + im), 0, 1) ** (1 / 2.2)); a.set_title(f"Mitsuba 3: {m}"); a.axis("off")
diff = np.log10((images["ggx2"].mean(axis=2) + 1e-3) / (images["ggx-aniso"].mean(axis=2) + 1e-3))
im = axes[2].imshow(diff, cmap="RdBu_r", vmin=-1, vmax=1); axes[2].set_title("log10(two lobes / one lobe)"); axes[2].axis("off")
fig.colorbar(im, ax=axes[2], fraction=0.046); plt.show()
"""


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
            '    print("truth (canonical):", canonical.canonical(truth["model"], truth["params"]))\n'
            "    # fit.md: the fit error against truth is the O(dx^2) bias of the central slopes, 7.7e-3 at 256^2\n"
            "    # (ndfit bench --quick), smaller at this 384^2 scan; above that the pipeline has regressed.\n"
            '    assert d_truth <= 7.7e-3, f"ellipsoid fit is {d_truth:.2e} from the truth (bound 7.7e-3)"\n'
            "else:\n"
            '    raise RuntimeError("ndfit synth wrote no truth file beside the scan")'
        ),
        new_markdown_cell(
            "Residual maps: the signed deviance residual per bin (`objective.md`). Structure (rings, "
            "lobes) means the model misses a feature of the data; noise means it explains it."
        ),
        new_code_cell('residual_maps(bins, fits, "synth")'),
        new_code_cell('auto = auto_choice(synth_scan, "synth", SYNTH_OPTS)'),
        new_markdown_cell(
            "### The fit in a renderer\n\n"
            "`ndfit export FIT.json --to mitsuba --json` gives Mitsuba 3's `roughconductor` parameters (`alpha_u` along "
            "the shading tangent, which must point at `tangent_angle` from the scan's +x). Below, the `ggx-aniso` fit "
            "rendered on a small sphere with the real Mitsuba 3 (scalar_rgb, 64 x 64, 16 spp; a sphere's tangent "
            "runs along its parallels, so the highlight stretches across them), next to the scan's NDF."
        ),
        new_code_cell(RENDER.strip()),
        new_markdown_cell("## 2. A real scan"),
        new_code_cell(
            'real = os.path.join(SCANS, "hamby44_downsampled_Barrel_1-Bullet_1-Land_1.x3p")\n'
            "HAVE_REAL = os.path.exists(real)\n"
            "if REQUIRE_SHARED and not HAVE_REAL:\n"
            '    raise RuntimeError(f"{real} is absent and NDFIT_REQUIRE_SHARED is set")\n'
            'print("real scan:", os.path.relpath(real, ROOT) if HAVE_REAL else f"SKIP ({SCANS} absent; NDFIT_REQUIRE_SHARED=1 makes this an error)")'
        ),
        new_code_cell(
            "if HAVE_REAL:\n"
            '    show_heights(real, "bullet land (Hamby 44)")\n'
            '    real_csv, real_bins = empirical(real, "real")\n'
            '    real_fits = fit_all(real, "real", real_bins)\n'
            '    residual_maps(real_bins, real_fits, "real")\n'
            '    auto_choice(real, "real")'
        ),
        new_markdown_cell(
            "### One lobe or two: the model ladder\n\n"
            "Real metal has a sharp core and a long tail (`data_formats/objective.md`, \"Mixtures and the ladder\"). "
            "Below, the scan's `ggx-aniso` fit against the two-lobe mixtures `ggx2` and `ellipsoid+ggx`: deviance, "
            "deviance per dof against the data's own dispersion, the same cross-check against nlopt, the residual maps, a "
            "slice through the peak, and what `--model auto` decided with each candidate's criterion."
        ),
        new_code_cell(LADDER.strip()),
        new_code_cell(
            "if HAVE_REAL:\n"
            '    ladder_fits = ladder(real, "real", real_bins)'
        ),
        new_code_cell("if HAVE_REAL:\n" + "\n".join("    " + l for l in RENDER_LADDER.strip().splitlines())),
        new_code_cell("shutil.rmtree(WORK, ignore_errors=True)"),
    ]
    return cells


BENCH = r"""
# Accuracy is measured on one fixed, fine set of directions for every point, so that points with different
# NDF bins are comparable: delta(D_fit; D_truth) of objective.md with the quadrature of a 160 x 128 grid.
from ndfitpy.synthetic import grid_for
QUAD = grid_for(0.3, 160, 128).bins()

def synth(n, extra=()):
    scan = os.path.join(WORK, f"s{n}.x3p")
    if not os.path.exists(scan):
        ndfit("synth", scan, *SYNTH_ARGS_BASE, "--nx", n, "--ny", n, *extra)
    truth = json.load(open(scan[:-4] + ".truth.json"))
    return scan, truth

def point(scan, truth, label, fit_opts=(), model="ellipsoid"):
    out = os.path.join(WORK, "point.json")
    t0 = time.perf_counter()
    ndfit("fit", scan, "--model", model, "-o", out, "--form", "none", *fit_opts)
    wall = time.perf_counter() - t0
    doc = json.load(open(out))
    tm = doc.get("timings", {})
    d = obj.delta(models.log_d(doc["model"], doc["params"], QUAD.m),
                  models.log_d(truth["model"], truth["params"], QUAD.m), QUAD.proj_solid_angle)
    return dict(label=label, wall=wall, read_ms=tm.get("read_ms", float("nan")), ndf_ms=tm.get("ndf_ms", float("nan")),
                fit_ms=tm.get("fit_ms", float("nan")), delta=d, bins=doc.get("quality", {}).get("n_bins"))
"""

SIZES = r"""
sizes = [128, 256, 512, 1024]
size_rows = []
for n in sizes:
    scan, truth = synth(n)
    size_rows.append(dict(point(scan, truth, f"{n}^2"), n=n))
for r in size_rows:
    print(f"{r['label']:>7s}  bins {r['bins']!s:>6s}  read {r['read_ms']:7.1f} ms  ndf {r['ndf_ms']:7.1f} ms  "
          f"fit {r['fit_ms']:7.1f} ms  (process {r['wall']:.2f} s)  delta vs truth {r['delta']:.2e}")
# docs/PERFORMANCE.md: the fit error is the O(dx^2) bias of the central slopes, 7.7e-3 at 256^2 and 4.7e-4 at
# 1024^2; bounds 1e-2 and 1e-3, and the error must fall at least 4x from 128^2 to 1024^2.
err = {r["n"]: r["delta"] for r in size_rows}
assert err[256] <= 1e-2 and err[1024] <= 1e-3, f"fit error against truth above the documented bounds: {err}"
assert err[1024] * 4 <= err[128], f"the fit error does not fall with the scan size: {err}"
"""

SIZE_PLOT = r"""
px = np.array([r["n"] ** 2 for r in size_rows], dtype=float)
fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4))
for key, mk in (("read_ms", "v-"), ("ndf_ms", "o-"), ("fit_ms", "s-")):
    y = np.array([r[key] for r in size_rows])
    k = np.polyfit(np.log(px), np.log(y), 1)[0]
    a1.loglog(px, y, mk, label=f"{key[:-3]} (log-log slope {k:.2f})")
a1.set_xlabel("pixels"); a1.set_ylabel("ms"); a1.legend(); a1.set_title("stage times (fit JSON timings)")
a2.loglog(px, [r["delta"] for r in size_rows], "o-")
a2.set_xlabel("pixels"); a2.set_ylabel("delta(fit; truth)"); a2.set_title("accuracy against truth")
fig.tight_layout(); plt.show()
"""

KNOBS = r"""
scan, truth = synth(512)
knob_rows = [point(scan, truth, "defaults")]
for cells in (15, 31, 63, 127):
    knob_rows.append(point(scan, truth, f"--ndf-cells {cells}", ["--ndf-cells", cells]))
for sub in (2, 4):
    knob_rows.append(point(scan, truth, f"--subsample {sub}", ["--subsample", sub]))
for label, opts in (("--normals triangles", ["--normals", "triangles"]),
                    ("--solver nelder-mead", ["--solver", "nelder-mead"]), ("--solver lbfgs", ["--solver", "lbfgs"])):
    knob_rows.append(point(scan, truth, label, opts))
for r in knob_rows:
    r["total_ms"] = r["read_ms"] + r["ndf_ms"] + r["fit_ms"]
    print(f"{r['label']:24s} bins {r['bins']!s:>6s}  total {r['total_ms']:8.1f} ms  "
          f"(ndf {r['ndf_ms']:6.1f}, fit {r['fit_ms']:6.1f})  delta {r['delta']:.2e}")
"""

KNOB_PLOT = r"""
t = np.array([r["total_ms"] for r in knob_rows]); e = np.array([r["delta"] for r in knob_rows])
order = np.argsort(t)
front = np.minimum.accumulate(e[order])
fig, ax = plt.subplots(figsize=(7, 4.5))
ax.loglog(t, e, "o")
for r in knob_rows:
    ax.annotate(r["label"], (r["total_ms"], r["delta"]), fontsize=7, xytext=(3, 3), textcoords="offset points")
ax.step(t[order], front, where="post", color="k", lw=0.8, label="Pareto front")
ax.set_xlabel("read + NDF + fit (ms)"); ax.set_ylabel("delta(fit; truth)"); ax.legend()
ax.set_title("knobs at 512^2: time against error"); plt.show()
"""

BENCH_RUN = r"""
import csv as _csv
bench_dir = os.path.join(WORK, "bench")
help_text = subprocess.run([NDFIT, "bench", "--help"], capture_output=True, text=True).stdout
ndfit("bench", "--quick", "-o", bench_dir)
bench_rows = list(_csv.DictReader(open(os.path.join(bench_dir, "bench.csv"))))
assert bench_rows, "ndfit bench --quick wrote no rows"
print(f"{len(bench_rows)} rows", list(bench_rows[0]) if bench_rows else "")
"""

BENCH_SHOW = r"""
png = os.path.join(bench_dir, "pareto.png")
if os.path.exists(png):
    fig, ax = plt.subplots(figsize=(9, 6)); ax.imshow(plt.imread(png)); ax.axis("off"); plt.show()
if bench_rows:
    cols = list(bench_rows[0])
    show = [c for c in cols if any(k in c for k in ("knob", "label", "size", "total", "delta", "peak"))][:8]
    print("  ".join(f"{c:>14s}" for c in show))
    for r in bench_rows[:40]:
        print("  ".join(f"{str(r[c])[:14]:>14s}" for c in show))
"""


def speed():
    cells = [
        new_markdown_cell(
            "# Speed and accuracy\n\n"
            "What each knob costs and buys, measured with the `ndfit` binary on synthetic ellipsoid scans with "
            "known truth. Stage times come from the fit JSON's `timings` (read, NDF, fit, in ms); accuracy is the "
            "NDF difference `delta(D_fit; D_truth)` of `data_formats/objective.md`, computed in numpy on one fixed "
            "fine set of directions. If the binary has `ndfit bench --quick`, its sweep and Pareto plot are shown "
            "too (the full sweep is in docs/PERFORMANCE.md once the bench engineer lands it). Timings on a shared "
            "2-core machine are noisy: read them as orders of magnitude."
        ),
        new_code_cell(COMMON.strip()),
        new_code_cell(
            'SYNTH_ARGS_BASE = ["--surface", "ellipsoid", "--alpha-x", "0.2", "--alpha-y", "0.35", "--theta-x", "0.15",\n'
            '                   "--theta-y", "-0.1", "--theta-z", "0.6"]\n' + BENCH.strip()
        ),
        new_markdown_cell("## Scan size: how time grows, what accuracy it buys"),
        new_code_cell(SIZES.strip()),
        new_code_cell(SIZE_PLOT.strip()),
        new_markdown_cell(
            "## Knobs at 512^2: NDF bins, subsampling, normal scheme, solver\n\n"
            "Each knob moved alone from the defaults; time is read + NDF + fit from the JSON."
        ),
        new_code_cell(KNOBS.strip()),
        new_code_cell(KNOB_PLOT.strip()),
        new_markdown_cell("## `ndfit bench --quick` (when the binary has it)"),
        new_code_cell(BENCH_RUN.strip()),
        new_code_cell(BENCH_SHOW.strip()),
        new_code_cell("shutil.rmtree(WORK, ignore_errors=True)"),
    ]
    return cells


SCALE_FUNCS = r'''
from matplotlib.ticker import NullFormatter, ScalarFormatter

def scale_run(scan, name, footprints, opts=(), models="beckmann-aniso,ellipsoid"):
    """`ndfit scale` at the given footprints; returns its JSON report."""
    out = os.path.join(WORK, name)
    ndfit("scale", scan, *opts, "--footprint", ",".join(f"{f:.4e}" for f in footprints), "--models", models, "-o", out)
    return json.load(open(os.path.join(out, "scale.json")))

def curves(rep, model):
    # Per footprint: both routes' (alpha_x, alpha_y, skew offset), the pixel roughness 2 Sigma_F, whether
    # the analytic route is trusted there.
    rows = []
    for f in rep["footprints"]:
        m = next(m for m in f["models"] if m["model"] == model)
        def ab(route):
            p = route.get("params") or {}
            ax = p.get("alpha_x", p.get("alpha", float("nan")))
            return ax, p.get("alpha_y", ax), route.get("skew_offset", float("nan"))
        pr = f.get("pixel_roughness") or {}
        rows.append(dict(F=f["footprint_m"], emp=ab(m["empirical"]), ana=ab(m["analytic"]),
                         pix=(pr.get("alpha_x", 0.0), pr.get("alpha_y", 0.0)), trusted=m["analytic_trusted"],
                         caveats=m["analytic_caveats"], gap=m.get("route_gap"), skew=f["moments_at_footprint"]["skewness"]))
    return rows

def scale_plot(axes, rep, model, title, truth=None):
    rows = curves(rep, model)
    F = np.array([r["F"] for r in rows]) * 1e6
    a, b = axes
    for k, (lab, col) in enumerate((("alpha_x", "tab:blue"), ("alpha_y", "tab:orange"))):
        a.plot(F, [r["emp"][k] for r in rows], "o-", lw=2.2, color=col, label=f"{lab} empirical")
        # Analytic route: filled triangles where its theory holds, hollow where the output flags it.
        a.plot(F, [r["ana"][k] for r in rows], "--", lw=1, color=col)
        for r, f in zip(rows, F):
            a.plot(f, r["ana"][k], "^", color=col, mfc=col if r["trusted"] else "white", ms=7)
        a.plot(F, [r["pix"][k] for r in rows], ":", color="grey", lw=1.2)
        if truth is not None:
            a.axhline(truth[k], color=col, lw=0.8, alpha=0.6)
    a.plot([], [], "k^--", lw=1, label="analytic (hollow: not trusted)")
    a.plot([], [], ":", color="grey", label="pixel roughness 2 Sigma_F")
    a.set_xscale("log"); a.xaxis.set_minor_formatter(NullFormatter()); a.xaxis.set_major_formatter(ScalarFormatter())
    a.set_xlabel("footprint F (um)"); a.set_ylabel("alpha"); a.set_title(f"{title}: {model}")
    a.legend(fontsize=7)
    b.plot(F, [r["emp"][2] for r in rows], "o-", lw=2.2, label="skew offset, empirical")
    b.plot(F, [r["ana"][2] for r in rows], "^--", lw=1, label="skew offset, analytic")
    b.set_ylabel("skew offset sqrt(mu^T A2^-1 mu) of the fitted ellipsoid")
    c = b.twinx()
    c.plot(F, [r["skew"] for r in rows], "s:", color="grey", label="moment skewness of the NDF at F (right axis)")
    c.set_ylabel("moment skewness", color="grey")
    b.set_xscale("log"); b.xaxis.set_minor_formatter(NullFormatter()); b.xaxis.set_major_formatter(ScalarFormatter())
    b.set_xlabel("footprint F (um)"); b.set_title(f"{title}: skew")
    h1, l1 = b.get_legend_handles_labels(); h2, l2 = c.get_legend_handles_labels()
    b.legend(h1 + h2, l1 + l2, fontsize=7)
    return rows

def describe(rows, name):
    for r in rows:
        state = "trusted" if r["trusted"] else "NOT trusted: " + "; ".join(c.split(":")[0] for c in r["caveats"])
        print(f"{name} F={r['F']*1e6:7.1f} um  empirical alpha_x {r['emp'][0]:.3f}  analytic {r['ana'][0]:.3f}  "
              f"route_gap {r['gap'] if r['gap'] is None else round(r['gap'], 3)}  analytic {state}")
'''

SCALE_SYNTH = r"""
# Synthetic Gaussian surface with known truth: RMS slopes 0.2 and 0.1 (theta_z 0.3: the larger along
# (cos 0.3, -sin 0.3), Walter et al.'s A = S Rz(theta_z)), correlation length 6 um,
# 256 x 256 samples of 1 um. Its slopes are Gaussian, so at every footprint the NDF is anisotropic Beckmann
# with alpha = sqrt(2) * RMS slope = (0.283, 0.141) (data_formats/scale.md S3: filtering moves slope
# variance into the NDF, it creates none). A GGX-shaped lobe (the ellipsoid) fitted to a Gaussian has
# alpha^2 = kappa * Beckmann alpha^2 with kappa = 0.61 (the Kullback-Leibler optimum, scale.md sec. 4a).
gauss = os.path.join(WORK, "gauss.x3p")
ndfit("synth", gauss, "--surface", "gaussian", "--nx", 256, "--ny", 256, "--sigma-x", 0.2, "--sigma-y", 0.1,
      "--theta-z", 0.3, "--corr-length", 6e-6)
FP_SYNTH = np.geomspace(1.5e-6, 40e-6, 6)
rep_synth = scale_run(gauss, "scale_gauss", FP_SYNTH, ["--form", "none"])
truth_b = (math.sqrt(2) * 0.2, math.sqrt(2) * 0.1)
truth_e = tuple(math.sqrt(0.61) * t for t in truth_b)
fig, axes = plt.subplots(2, 2, figsize=(11, 8))
rows_b = scale_plot(axes[0], rep_synth, "beckmann-aniso", "synthetic Gaussian", truth_b)
rows_e = scale_plot(axes[1], rep_synth, "ellipsoid", "synthetic Gaussian", truth_e)
fig.tight_layout(); plt.show()
describe(rows_b, "beckmann-aniso"); describe(rows_e, "ellipsoid")
# The empirical route's Beckmann alphas stay on the truth at every footprint (filtering creates no slope variance).
dev = max(abs(r["emp"][k] / truth_b[k] - 1.0) for r in rows_b for k in (0, 1))
print(f"largest relative deviation of the empirical Beckmann alphas from the truth: {dev:.2%}")
assert dev <= 0.05, f"empirical Beckmann alphas {dev:.1%} from the truth"
"""

SCALE_REAL = r"""
# A real scan: a bullet land of the Hamby set (confocal, 303 x 85 after downsampling, 7.8 um spacing),
# plane removed as for any real scan. Skipped with a note when the shared scans are absent.
real = os.path.join(SCANS, "hamby44_downsampled_Barrel_1-Bullet_1-Land_1.x3p")
rep_real = None
if not os.path.exists(real) and REQUIRE_SHARED:
    raise RuntimeError(f"{real} is absent and NDFIT_REQUIRE_SHARED is set")
if not os.path.exists(real):
    print(f"SKIP: {real} is absent (the shared scans are not beside the repository); the real-scan curves are not drawn.")
else:
    FP_REAL = np.geomspace(1e-5, 3e-4, 6)
    rep_real = scale_run(real, "scale_real", FP_REAL)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    rows_r = scale_plot(axes, rep_real, "ellipsoid", "Hamby land")
    fig.tight_layout(); plt.show()
    describe(rows_r, "ellipsoid")
    # The same with Tokuyoshi's single kernel (--blur mean): one mean within-footprint covariance for all.
    rep_mean = scale_run(real, "scale_real_mean", FP_REAL, ["--blur", "mean"])
    describe(curves(rep_mean, "ellipsoid"), "ellipsoid --blur mean")
    for f in rep_real["footprints"][:1]:
        print("theory notes at", f["footprint_m"], "m:"); [print(" -", n) for n in f["theory_notes"]]
"""

SCALE_READING = """## Reading the plots in plain words

**Synthetic Gaussian surface (the answer is known).** The thick curves (empirical route: the surface filtered the
way a renderer sees it at each footprint, then fitted) stay on the thin horizontal truth lines: the NDF a renderer
needs does not get rougher or smoother as the pixel grows, the roughness only moves from the visible geometry into
the material (the grey dotted pixel roughness 2 Sigma_F rises from near 0 to the full value). The analytic route
(dashed, triangles: fit the filtered surface, then add the footprint's slope covariance to the roughness matrix,
Tokuyoshi eq. 3) lies on top of it for Beckmann at every footprint. The ellipsoid sits lower than Beckmann by
sqrt(kappa) = 0.78 because a GGX-shaped lobe fitted to a Gaussian is narrower; the analytic route adds the kernel in
those same units, so it ends on the truth at both ends. In between (about 3 to 11 um here) the slope spread inside a
footprint differs from one footprint to the next, the NDF at F gets a slightly heavier tail, the ellipsoid's core
narrows by a few per cent, and the output flags the analytic route there (hollow triangles, printed reason). The
skew stays near zero: a Gaussian surface is symmetric.

**Real bullet land.** Here the two routes part at every footprint, and the output says why (hollow triangles, the
printed caveats): the land's slopes are skewed and heavy-tailed (striation edges), and the slope variation inside a
footprint differs enormously from one footprint to the next (coefficient of variation up to 14). A renderer that
carries each pixel's own covariance (the empirical route, the default) sees a heavy-tailed mixture whose core barely
widens, while the analytic route adds one mean covariance, which the few steep footprints dominate, and over-widens
the lobe. With one mean kernel for every pixel (`--blur mean`, the second printed table) the routes agree again
within a few per cent: the gap is the surface, not the algebra. For such a surface use the empirical curves. Their
skew offset fades as the footprint grows (0.17 to 0.07), as it must once a pixel covers many striations; the
analytic skew curve is flagged and not meaningful here.
"""


def scale():
    cells = [
        new_markdown_cell(
            "# The NDF at a renderer's footprint (`ndfit scale`)\n\n"
            "Empirical and analytic scale curves (alpha_x, alpha_y and skew against footprint) for a synthetic "
            "surface whose answer is known and for a real scan. Definitions: `data_formats/scale.md`."
        ),
        new_code_cell(COMMON.strip()),
        new_code_cell(SCALE_FUNCS.strip()),
        new_markdown_cell("## A synthetic Gaussian surface: the answer is known"),
        new_code_cell(SCALE_SYNTH.strip()),
        new_markdown_cell("## A real scan: a Hamby bullet land"),
        new_code_cell(SCALE_REAL.strip()),
        new_markdown_cell(SCALE_READING),
        new_code_cell("shutil.rmtree(WORK, ignore_errors=True)"),
    ]
    return cells


PY_SETUP = r"""
import os
import numpy as np
import matplotlib.pyplot as plt
import ndfit
from ndfit.dask import fit_many

def find_root():
    d = os.getcwd()
    while d != os.path.dirname(d):
        if os.path.exists(os.path.join(d, "Cargo.toml")) and os.path.isdir(os.path.join(d, "fits")):
            return d
        d = os.path.dirname(d)
    raise RuntimeError("run this notebook inside the ndfit repository")

ROOT = find_root()
SCANS = os.path.normpath(os.path.join(ROOT, "..", "shared", "data", "scans"))
REQUIRE_SHARED = os.environ.get("NDFIT_REQUIRE_SHARED", "") not in ("", "0")
# Relative to the working directory: the scan keeps the path it was read from and prints it.
real = os.path.relpath(os.path.join(SCANS, "hamby44_downsampled_Barrel_1-Bullet_1-Land_1.x3p"))
HAVE_REAL = os.path.exists(real)
if REQUIRE_SHARED and not HAVE_REAL:
    raise RuntimeError(f"{real} is absent and NDFIT_REQUIRE_SHARED is set")
print("ndfit", ndfit.__version__, "|", "real scan: " + os.path.relpath(real, ROOT) if HAVE_REAL else f"SKIP: {SCANS} absent, a numpy surface stands in")
"""

PY_READ = r"""
if HAVE_REAL:
    scan = ndfit.read(real)
else:  # a smooth random surface made here, in metres
    rng = np.random.default_rng(1)
    k = np.fft.rfft2(rng.standard_normal((256, 256)))
    f = np.exp(-((np.fft.rfftfreq(256)[None, :] / 0.05) ** 2 + (np.fft.fftfreq(256)[:, None] / 0.08) ** 2))
    h = np.fft.irfft2(k * f, s=(256, 256))
    scan = ndfit.Scan(h * 1e-6 / np.std(h), dx=1e-6)
print(scan)
print({k: v for k, v in scan.meta.items() if k != "instrument"})
h = scan.heights  # (ny, nx) metres, NaN = invalid; a read-only view of the scan's buffer, not a copy
fig, ax = plt.subplots(figsize=(6, 4))
im = ax.imshow(h * 1e6, origin="lower", cmap="viridis", extent=[0, scan.nx * scan.dx * 1e3, 0, scan.ny * scan.dy * 1e3], aspect="auto")
fig.colorbar(im, label="height (µm)")
ax.set(xlabel="x (mm)", ylabel="y (mm)", title=f"{os.path.basename(scan.path or 'array')}: heights as read")
plt.show()
"""

PY_FIT = r"""
fit = ndfit.fit(scan, model="auto")  # read -> plane removal -> empirical NDF -> fit, as `ndfit fit`
print(fit)
print("parameters:", {k: round(v, 5) for k, v in fit.params.items()})
print("std errors:", {k: (None if v is None else float(f"{v:.2g}")) for k, v in fit.std_errors.items()})
q = fit.quality
print(f"verdict {q['verdict']}; deviance/dof {q['reduced_chi2']:.3f}, the data's own dispersion {q['dispersion']:.3f}")
for c in fit.to_dict()["selection"]["candidates"]:
    print(f"  candidate {c['model']:<15} criterion {c['criterion']:.1f}")
if "theta_z" in fit.params:
    print(f"alpha_x axis at azimuth {-fit.params['theta_z']:.4f} rad from +x (Walter et al.: A = S Rz(theta_z))")
"""

PY_PLOT = r"""
emp = ndfit.ndf(scan)  # the same bins the fit used (same options)
occ = emp.count > 0
d_fit = fit.d(emp.m)
# The empirical NDF is normalized by construction (Heitz eq. 9: the projected areas sum to one).
assert abs(np.sum(emp.d * emp.proj_solid_angle) - 1) < 1e-9
theta = np.degrees(np.arccos(emp.m[:, 2]))
phi_axis = -fit.params.get("theta_z", 0.0)  # the alpha_x axis
phi = np.arctan2(emp.m[:, 1], emp.m[:, 0])
dphi = np.angle(np.exp(1j * (phi - phi_axis)))
fig, (a0, a1) = plt.subplots(1, 2, figsize=(11, 4))
a0.loglog(emp.d[occ], d_fit[occ], ".", ms=2, alpha=0.4)
lim = [emp.d[occ].min(), emp.d[occ].max()]
a0.plot(lim, lim, "k-", lw=0.8)
a0.set(xlabel="empirical D (1/sr)", ylabel=f"{fit.model} fit D (1/sr)", title="every bin with data")
for sign, colour, name in ((0.0, "C0", "along the alpha_x axis"), (np.pi / 2, "C1", "across it")):
    sel = occ & ((np.abs(dphi - sign) < 0.15) | (np.abs(np.abs(dphi - sign) - np.pi) < 0.15))
    a1.errorbar(theta[sel], emp.d[sel], yerr=emp.stderr[sel], fmt=".", color=colour, ms=3, alpha=0.6, label=f"data {name}")
    t = np.radians(np.linspace(0, max(theta[occ].max(), 1), 300))
    dirs = np.stack([np.sin(t) * np.cos(phi_axis + sign), np.sin(t) * np.sin(phi_axis + sign), np.cos(t)], axis=1)
    a1.plot(np.degrees(t), fit.d(dirs), color=colour, lw=1.2)
a1.set(yscale="log", xlabel="polar angle of m (deg)", ylabel="D (1/sr)", title="slices through the lobe (lines: fit)")
a1.legend(fontsize=8)
plt.show()
"""

PY_ARRAY = r"""
# numpy in == file in: the same fit from a cropped array as from the `crop` option on the scan.
ny, nx = scan.shape
c = f"{nx // 2}x{ny // 2}+{nx // 4}+{ny // 4}"
from_option = ndfit.fit(scan, model="ggx-aniso", crop=c)
from_array = ndfit.fit(ndfit.Scan(scan.heights[ny // 4 : ny // 4 + ny // 2, nx // 4 : nx // 4 + nx // 2], dx=scan.dx, dy=scan.dy), model="ggx-aniso")
print(from_option)
print(from_array)
assert from_option.params == from_array.params
"""

PY_DASK = r"""
# Every shared real scan, one Dask task per scan on a 2-worker LocalCluster (started and closed here); with a
# dask.distributed Client or a scheduler address the same call runs on a cluster.
if HAVE_REAL:
    files = sorted(os.path.join(SCANS, f) for f in os.listdir(SCANS) if not f.endswith((".json", ".md")))
    df = fit_many(files, model="auto", n_workers=2)
    df["path"] = df["path"].map(os.path.basename)
    assert (df["status"] == "ok").all(), df.loc[df["status"] != "ok", "error"].tolist()
    show = df[["path", "model", "alpha", "alpha_x", "alpha_y", "theta_z", "theta_x", "theta_y", "verdict", "reduced_chi2"]]
    print(show.to_string(float_format=lambda v: f"{v:.4g}"))
    print(df["verdict"].value_counts().to_dict())
else:
    print(f"SKIP: {SCANS} absent")
"""


def python_api():
    cells = [
        new_markdown_cell(
            "# `import ndfit`: the Python package\n\n"
            "The Rust library as a Python module (`pip install .` at the repository root builds it): read a real "
            "scan, fit it, plot the data against the fit with matplotlib, then fit every shared real scan on a "
            "Dask LocalCluster into a pandas DataFrame. `ndfit.fit` is the computation of `ndfit fit` "
            "(`Fit.to_json()` is the document the CLI writes; `python/tests` checks both agree byte for byte)."
        ),
        new_code_cell(PY_SETUP.strip()),
        new_markdown_cell("## A real scan"),
        new_code_cell(PY_READ.strip()),
        new_markdown_cell("## The fit (`model=\"auto\"`: the nested models, chosen by the quasi-likelihood BIC)"),
        new_code_cell(PY_FIT.strip()),
        new_markdown_cell(
            "## Data against fit\n\nLeft: every bin's empirical D against the fitted D (on the diagonal when the model "
            "describes the data). Right: D against the polar angle in two slices, along the fit's alpha_x axis and across it."
        ),
        new_code_cell(PY_PLOT.strip()),
        new_code_cell(PY_ARRAY.strip()),
        new_markdown_cell("## Many scans on Dask: `ndfit.dask.fit_many`"),
        new_code_cell(PY_DASK.strip()),
    ]
    return cells


MEASURED_INTRO = r"""
# 05 · The measured NDF in the renderer

A real scan rendered in Mitsuba 3 twice: as its **analytic fit** and as its **measured table**
(`ndfit export SCAN --to rgl`: the scan's own empirical NDF, regularized where bins are noisy, the fit
beyond the fit region). Both are RGL tabulated BSDFs read by the same `measured` plugin, with the same
conductor (`--material Al`), so the only difference between the two images is the NDF.

**Scene.** A 2 x 2 square (Mitsuba `rectangle`, normal +z, its tangent dp/du = +x = the scan's +x) seen
by a perspective camera (fov 30 deg) from elevation 55 deg in the xz-plane; a small spherical area light
(radius 0.08, at elevation 55 deg on the mirror side, azimuth 180 deg + 20 deg) so the highlight is the
reflected NDF lobe. 192 x 192 pixels, 256 samples per pixel (independent sampler); variant `scalar_rgb`.
The noise is measured by rendering the fit twice with different seeds.
"""

MEASURED_SETUP = r"""
import json, math, os, subprocess, time
import numpy as np
import matplotlib.pyplot as plt
import mitsuba as mi
mi.set_variant("scalar_rgb")

ROOT = os.getcwd()
NDFIT = os.environ.get("NDFIT", os.path.join(ROOT, "target", "release", "ndfit"))
SCAN = os.path.join(ROOT, "..", "shared", "data", "scans", "x3ptools_sample-land.x3p")
OUT = os.path.join(ROOT, "target", "nb05")
os.makedirs(OUT, exist_ok=True)

def ndfit(*args):
    p = subprocess.run([NDFIT, *map(str, args)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return p.stdout, p.stderr

fit_path = os.path.join(OUT, "fit.json")
ndfit("fit", SCAN, "-o", fit_path, "-q")
fit = json.load(open(fit_path))
print("model:", fit["model"], {k: round(v, 4) for k, v in fit["params"].items()})
print("verdict:", fit.get("verdict", fit["quality"].get("verdict")), " max_theta_deg:", fit["quality"]["max_theta_deg"])
"""

MEASURED_TABLES = r"""
t0 = time.time()
ndfit("export", fit_path, "--to", "rgl", "-o", os.path.join(OUT, "fit.bsdf"), "--material", "Al")
t1 = time.time()
_, err = ndfit("export", SCAN, "--to", "rgl", "-o", os.path.join(OUT, "scan.bsdf"), "--material", "Al")
t2 = time.time()
print(f"fit table {t1 - t0:.1f} s, scan table {t2 - t1:.1f} s; {os.path.getsize(os.path.join(OUT, 'scan.bsdf')) / 1e6:.1f} MB")

def description(path):
    raw = open(path, "rb").read()
    n = int.from_bytes(raw[14:18], "little"); at = 18
    for _ in range(n):
        ln = int.from_bytes(raw[at:at + 2], "little"); name = raw[at + 2:at + 2 + ln].decode(); at += 2 + ln
        ndim = int.from_bytes(raw[at:at + 2], "little"); at += 3
        off = int.from_bytes(raw[at:at + 8], "little"); at += 8
        shape = [int.from_bytes(raw[at + 8 * k:at + 8 * k + 8], "little") for k in range(ndim)]; at += 8 * ndim
        if name == "description":
            return raw[off:off + shape[0]].decode()
print(description(os.path.join(OUT, "scan.bsdf")))
"""

MEASURED_RENDER = r"""
def scene(bsdf_file, seed):
    el = math.radians(55.0)
    cam = [3.2 * math.cos(el), 0.0, 3.2 * math.sin(el)]
    az = math.radians(180.0 + 20.0)
    light = [-1.6 * math.cos(el) * math.cos(math.radians(20.0)), -1.6 * math.cos(el) * math.sin(math.radians(20.0)), 1.6 * math.sin(el)]
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": "path", "max_depth": 2},
        "sensor": {"type": "perspective", "fov": 30,
                   "to_world": mi.ScalarTransform4f().look_at(origin=cam, target=[0, 0, 0], up=[0, 0, 1]),
                   "sampler": {"type": "independent", "sample_count": 256, "seed": seed},
                   "film": {"type": "hdrfilm", "width": 192, "height": 192, "rfilter": {"type": "box"}}},
        "surface": {"type": "rectangle", "bsdf": {"type": "measured", "filename": bsdf_file}},
        "light": {"type": "sphere", "center": light, "radius": 0.08,
                  "emitter": {"type": "area", "radiance": {"type": "rgb", "value": [60.0, 60.0, 60.0]}}},
    })

def render(name, seed):
    img = mi.render(scene(os.path.join(OUT, name), seed), seed=seed)
    return np.array(img)[..., :3].mean(axis=2)

t0 = time.time()
fit_a = render("fit.bsdf", 1)
fit_b = render("fit.bsdf", 2)
meas = render("scan.bsdf", 1)
print(f"three renders in {time.time() - t0:.0f} s")
"""

MEASURED_COMPARE = r"""
noise = np.abs(fit_a - fit_b)
diff = np.abs(meas - fit_a)
lit = (fit_a + meas) > 0.05 * max(fit_a.max(), meas.max())
print(f"over the lit pixels: mean |fit - measured| = {diff[lit].mean():.4f}, mean |fit seed 1 - fit seed 2| = {noise[lit].mean():.4f}")
print(f"ratio (difference / noise) = {diff[lit].mean() / noise[lit].mean():.1f}")
vmax = np.percentile(np.concatenate([fit_a[lit], meas[lit]]), 99.5)
fig, ax = plt.subplots(1, 4, figsize=(16, 4.4))
for a, img, title in [(ax[0], fit_a, "analytic fit (" + fit["model"] + ")"), (ax[1], meas, "measured table"),
                      (ax[2], diff, "|fit - measured|"), (ax[3], noise, "|fit - fit|, other seed (noise)")]:
    im = a.imshow(img, cmap="magma", vmin=0, vmax=vmax if a in ax[:2] else vmax / 4)
    a.set_title(title); a.axis("off"); fig.colorbar(im, ax=a, fraction=0.046)
plt.tight_layout(); plt.show()
"""

MEASURED_READING = r"""
The scan (a bullet land, `misfit` as the two-lobe mixture printed above) and its fit give highlights of the
same size and elongation, but the measured table's core is less regular than the fitted lobes, which are
symmetric: the difference image is structured (blobs along the highlight's long axis), not noise. Its mean
over the lit pixels is several times the seed-to-seed noise (the ratio printed above), so at 192 x 192
pixels and 256 samples per pixel the two materials are told apart by the image, not by the noise.
"""

MEASURED_CHOICE_INTRO = r"""
## The render decides

`ndfit fit --model auto` above already answered this question with its own renderer: it rendered the scan's
table and the ladder's lobes, simplest first, on a sphere under a point light and under a broad light, and
scored each lobe by HDR-FLIP against the table (data_formats/render.md, "The choice"). `selection.answer` is
the lobe a renderer cannot tell from the scan (within FLIP 0.02, what a 64-spp render differs from a
converged one), or `measured` when no lobe is, and then the table written above is the material.
`ndfit compare SCAN --png PREFIX` writes the picture of each scene: the table's render, the lobe's, and the
FLIP map, with the score. It shows where the lobe and the scan differ.
"""

MEASURED_CHOICE = r"""
sel = fit["selection"]
print("answer:", sel["answer"], "| lobe:", fit["model"], "| render error:", {k: round(v, 4) for k, v in sel["render_error"].items()})
print("each rendered lobe's worst FLIP:", {c["model"]: round(c["render_error"]["worst"], 3) for c in sel["candidates"] if "worst" in (c.get("render_error") or {})})
prefix = os.path.join(OUT, "choice")
_, err = ndfit("compare", SCAN, "--png", prefix)
print(err.strip().replace(ROOT + os.sep, ""))
fig, ax = plt.subplots(2, 1, figsize=(12, 9))
for a, name in zip(ax, ["point", "broad"]):
    a.imshow(plt.imread(prefix + "." + name + ".png")); a.axis("off")
plt.tight_layout(); plt.show()
"""


def measured():
    cells = [
        new_markdown_cell(MEASURED_INTRO.strip()),
        new_code_cell(MEASURED_SETUP.strip()),
        new_code_cell(MEASURED_TABLES.strip()),
        new_code_cell(MEASURED_RENDER.strip()),
        new_code_cell(MEASURED_COMPARE.strip()),
        new_markdown_cell(MEASURED_READING.strip()),
        new_markdown_cell(MEASURED_CHOICE_INTRO.strip()),
        new_code_cell(MEASURED_CHOICE.strip()),
    ]
    return cells


MIRROR_INTRO = r"""
# 06 · A mirror is a mirror

A polished metal reflects a sharp image. Its scan says the same thing, but only to wave optics: within a
patch of coherent light (sunlight's, 18.9 um across) its heights vary by a few nanometres, a small fraction
of a wavelength, so the patch's reflected fields add up in phase into the mirror direction. Geometric optics
of the same scan sees something else: the slopes, and at a confocal microscope's spacing the slopes of a
polished surface are mostly its instrument's noise. Its NDF is a lobe, and a renderer given that lobe (or the
scan's own table) draws a glow over the whole object where the surface shows a sharp image.

`ndfit fit` (model `auto`) first asks what light sees (docs/ANSWER.md): `optics.regime` is `wave` when the
mirror carries most of the light at every incidence, and the answer is then `mirror` or `mirror+ggx` (the
mirror share by incidence and wavelength, and a haze lobe fitted to the diffuse wave BRDF).

This notebook takes st_sur-2 (a polished sample measured by an interferometer) and renders it in Mitsuba 3
three ways, in a scene where a mirror differs from a blur: a plate seen 65 degrees off its normal under a
sharp-edged window light, in a dim room (fits/ndfitpy/mirror_scene.py). Against a smooth conductor:
**as a mirror** (the answer), **as its geometric lobe** (the ladder's fit of the slopes) and **as its table**
(`ndfit export SCAN --to rgl`, the empirical NDF itself).
"""

MIRROR_SETUP = r"""
import json, os, re, subprocess, tempfile
import numpy as np
import matplotlib.pyplot as plt
import mitsuba as mi
mi.set_variant("scalar_rgb")

ROOT = os.getcwd()
import sys; sys.path.insert(0, os.path.join(ROOT, "fits"))
from ndfitpy import mirror_scene as ms

NDFIT = os.environ.get("NDFIT", os.path.join(ROOT, "target", "release", "ndfit"))
NDFIT = NDFIT if os.path.isabs(NDFIT) else os.path.join(ROOT, NDFIT)
SCAN = os.path.join(ROOT, "..", "shared", "data", "scans", "st_sur-2.sur")
OUT = tempfile.mkdtemp(prefix="ndfit-nb06-")

def ndfit(*args):
    p = subprocess.run([NDFIT, *map(str, args)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return p.stdout, p.stderr

fit_path = os.path.join(OUT, "fit.json")
_, err = ndfit("fit", SCAN, "-o", fit_path)
print(err.strip().splitlines()[-1].replace(SCAN, "st_sur-2.sur"))
fit = json.load(open(fit_path))
o = fit["optics"]
print("\nregime:", o["regime"], "-", o["why"])
print("haze:", o["haze"])
"""

MIRROR_SHARES = r"""
rows = {}
for s in o["specular"]:
    rows.setdefault(s["wavelength_nm"], {})[s["theta_deg"]] = s["weight"]
thetas = sorted(next(iter(rows.values())))
print("mirror share (Fresnel excluded) by incidence:")
print("  nm  " + "".join(f"{t:>8.0f}" for t in thetas))
for nm, r in sorted(rows.items()):
    print(f"  {nm:.0f} " + "".join(f"{r[t]:8.4f}" for t in thetas))
p = o["patches"]
print(f"\n{p['used']:.0f} coherence patches; their tilt {p['tilt_rms_deg']:.2f} deg RMS, the slopes {p['slope_rms_deg']:.2f} deg RMS at the scan's spacing")
print(f"the ladder's fit of the slopes: {fit['model']}; {fit['quality']['reasons'][1][:150]}...")
"""

MIRROR_MATERIALS = r"""
def loaded(xml):
    body = re.sub(r"<!--.*?-->", "", xml, flags=re.S).strip()
    return mi.load_string(body.replace("<bsdf ", '<bsdf version="3.0.0" ', 1))

# As a mirror: the answer, exported for Mitsuba.
answer_xml, _ = ndfit("export", fit_path, "--to", "mitsuba")
# As its geometric lobe: the two-lobe Beckmann fit of the slopes (the closest lobe the render choice found to
# the geometric table before light was asked; where light sees a mirror `auto` fits no two-lobe model, so it is
# asked for by name), exported for Mitsuba.
lobe_path = os.path.join(OUT, "lobe.json")
ndfit("fit", SCAN, "--model", "beckmann2", "-o", lobe_path)
lobe = json.load(open(lobe_path))
lobe_xml, _ = ndfit("export", lobe_path, "--to", "mitsuba")
# As its table: the scan's own empirical NDF (Mitsuba's `measured`).
table = os.path.join(OUT, "scan.bsdf")
ndfit("export", SCAN, "--to", "rgl", "-o", table)
print(answer_xml.split("-->")[-1].strip())
"""

MIRROR_RENDER = r"""
images = {
    "smooth conductor": ms.render(ms.conductor()),
    "as a mirror (" + fit["selection"]["answer"] + ")": ms.render(loaded(answer_xml)),
    "as its geometric lobe (" + lobe["model"] + ")": ms.render(loaded(lobe_xml)),
    "as its table (measured)": ms.render({"type": "measured", "filename": table}),
}
ref = images["smooth conductor"]
light, plate = ms.reflected(ref), ms.plate(ref)
fig, ax = plt.subplots(1, 4, figsize=(18, 3.6))
for a, (name, img) in zip(ax, images.items()):
    a.imshow(np.log10(1e-3 + img.mean(axis=2)), cmap="magma", vmin=-3, vmax=np.log10(ms.LIGHT_RADIANCE))
    score = "" if img is ref else f"\nFLIP {ms.flip(ref, img, light):.3f} where the light is reflected, {ms.flip(ref, img, plate):.3f} over the plate"
    a.set_title(name + score, fontsize=9); a.axis("off")
plt.tight_layout(); plt.show()
"""

MIRROR_READING = r"""
The images are log10 of the radiance (the window is at 20, the dim room at 0.02). The smooth conductor shows
the window's sharp image and the room elsewhere. **As a mirror**, st_sur-2 looks the same: the mirror keeps
99.9% of the light and the faint haze the wave module predicts around the image is below what HDR-FLIP sees
(the scores above). **As its geometric lobe** or **as its table**, the same scan draws the window as a blur
and spreads a glow over the plate: the slopes' NDF is the instrument's noise at the scan's spacing, not
what light sees. This is why `auto` asks wave optics first: where the regime is `wave`, the geometric table
is not the reference, and a lobe fitted to it, however good a fit, is the wrong material.
"""


def mirror():
    return [
        new_markdown_cell(MIRROR_INTRO.strip()),
        new_code_cell(MIRROR_SETUP.strip()),
        new_code_cell(MIRROR_SHARES.strip()),
        new_code_cell(MIRROR_MATERIALS.strip()),
        new_code_cell(MIRROR_RENDER.strip()),
        new_markdown_cell(MIRROR_READING.strip()),
    ]


# Every notebook of this folder, in order: file name -> its cells.
NOTEBOOKS = {
    "01_tour.ipynb": tour,
    "02_speed_accuracy.ipynb": speed,
    "03_scale.ipynb": scale,
    "04_python.ipynb": python_api,
    "05_measured.ipynb": measured,
    "06_mirror.ipynb": mirror,
}


def notebook(name):
    """The notebook ``name`` as written here: its cells, no outputs, fixed cell ids and metadata."""
    nb = new_notebook(cells=NOTEBOOKS[name]())
    # Fixed ids (nbformat draws random ones) so that writing the notebooks again leaves git's diff empty.
    for i, cell in enumerate(nb.cells):
        cell.id = f"cell-{i:02d}"
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.metadata["language_info"] = {"name": "python"}
    return nb


def write(name):
    path = os.path.join(HERE, name)
    with open(path, "w", encoding="utf-8") as fh:
        nbformat.write(notebook(name), fh)
    print("wrote", path)


if __name__ == "__main__":
    for name in NOTEBOOKS:
        write(name)
