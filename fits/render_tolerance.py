#!/usr/bin/env python3
"""The image difference a production render carries by itself: the mean HDR-FLIP between two Mitsuba 3
renders of the SAME material that differ only in their random seed, in ndfit's default scenes.

This is the yardstick for `ndfit compare --render-tolerance` (data_formats/render.md, "The choice"): a lobe
whose render differs from the table's by no more than a production render's own sampling noise is
invisible.

For each table (a scan's RGL table, `ndfit export SCAN --to rgl --material M`, and optionally one analytic
lobe's, `ndfit fit SCAN --model ggx-aniso` then `ndfit export FIT --to rgl --material M`), each scene
and each sample count N it prints

- FLIP(ref, N):  the mean HDR-FLIP of an N-spp render against a converged render (--ref-spp, another
  seed), i.e. the error a production render at N spp shows against the truth;
- FLIP(N, N'):   the mean HDR-FLIP between two N-spp renders with different seeds, i.e. the difference
  between two production renders of one material.

Both use ndfit's exposure rule (src/answer/choice.rs, `exposures`): start = FLIP's automatic start, stop =
min(FLIP's automatic stop, start + log2(1000)), taken from the converged render (in ndfit the reference is
the noise-free render of the table), at FLIP's default 67 pixels per degree.

The scenes are ndfit's (data_formats/render.md, "Frame and scenes"; fits/tests/test_render_mitsuba.py):
the unit sphere (identity transform), an orthographic camera from -y with +z up and half-width 1.05, a box
pixel filter; `point` = a directional light of irradiance pi from theta=60, phi=-90 at 128 x 128;
`broad` = a spherical area light subtending a 25-degree half-angle cap about the same direction, radiance
1/sin^2(25 deg), at 64 x 64; `window` = ndfitpy/mirror_scene.py's plate in a black room (room radiance 0):
a square plate (z = 0, half-width 3.2, `s` = +x) seen 65 degrees off its normal by a perspective camera
(fov 32 degrees across, 160 x 96, every pixel plate) under a 2.4 x 1.2 rectangular light of radiance 20
where the plate reflects it toward the camera. The integrator is what a production render of the scene
does: a path tracer with emitter sampling and BSDF sampling combined by MIS (the sphere is convex and the
plate flat, so only direct light arrives); emitters hidden (black background, as ndfit renders).

Usage (from the repository root):
    fits/.venv/bin/python fits/render_tolerance.py --ndfit target/release/ndfit \
        /work/shared/data/scans/st_x3p-2.x3p /work/shared/data/scans/st_opd-1.opd
    (`--scenes window --sampler multijitter` for the plate scene: about 2 minutes a table at 4096 spp.)
Scratch files (tables, fits) go to --workdir (default: a fresh folder under the system's temp dir).
"""

import argparse
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np

import flip_evaluator
import mitsuba as mi

from ndfitpy import mirror_scene as ms

EXTENT = 1.05
LIGHT = (60.0, -90.0)
HALF_ANGLE = 25.0
DYNAMIC_RANGE = 1e3  # ndfit's choice::DYNAMIC_RANGE
SIZES = {"point": (128, 128), "broad": (64, 64), "window": (ms.WIDTH, ms.HEIGHT)}  # width, height


def direction(theta_deg, phi_deg):
    t, p = math.radians(theta_deg), math.radians(phi_deg)
    return [math.sin(t) * math.cos(p), math.sin(t) * math.sin(p), math.cos(t)]


def run(ndfit, *args):
    p = subprocess.run([ndfit, *map(str, args)], capture_output=True, text=True)
    if p.returncode != 0:
        sys.exit(f"ndfit {' '.join(map(str, args))} failed:\n{p.stderr}")
    return p.stdout


def scene_dict(scene, bsdf_path, spp, sampler, size):
    bsdf = {"type": "measured", "filename": str(bsdf_path)}
    if scene == "window":
        assert tuple(size) == (ms.WIDTH, ms.HEIGHT), size
        return ms.scene_dict(bsdf, spp, room=0.0, sampler=sampler)
    light = direction(*LIGHT)
    if scene == "point":
        emitter = {"type": "directional", "direction": [-c for c in light], "irradiance": {"type": "rgb", "value": math.pi}}
    elif scene == "broad":
        delta, dist = math.radians(HALF_ANGLE), 1e4
        emitter = {"type": "sphere", "center": [dist * c for c in light], "radius": dist * math.sin(delta),
                   "emitter": {"type": "area", "radiance": {"type": "rgb", "value": 1 / math.sin(delta) ** 2}}}
    else:
        raise ValueError(scene)
    return {
        "type": "scene",
        # A production path tracer: emitter + BSDF sampling with MIS. The sphere is convex, so depth 2
        # (direct light) is all a path can gather; a larger max_depth renders the same image.
        "integrator": {"type": "path", "max_depth": 2, "hide_emitters": True},
        "sensor": {
            "type": "orthographic",
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, -10, 0], target=[0, 0, 0], up=[0, 0, 1])
            @ mi.ScalarTransform4f().scale([EXTENT, EXTENT, 1]),
            "film": {"type": "hdrfilm", "width": size[0], "height": size[1], "rfilter": {"type": "box"}, "pixel_format": "rgb"},
            "sampler": {"type": sampler, "sample_count": spp},
        },
        "sphere": {"type": "sphere", "bsdf": bsdf},
        "light": emitter,
    }


def render(scene, spp, seed):
    img = np.array(mi.render(scene, spp=spp, seed=seed), dtype=np.float32)
    return np.ascontiguousarray(np.maximum(img[..., :3], 0.0))


def exposures(reference):
    """ndfit's rule: FLIP's own start; its own stop, or log2(1000) stops above the start if that is lower."""
    _, _, p = flip_evaluator.evaluate(reference, reference, "HDR", applyMagma=False, computeMeanError=False)
    start, stop = p["startExposure"], p["stopExposure"]
    return {"startExposure": start, "stopExposure": min(stop, start + math.log2(DYNAMIC_RANGE))}


def flip_mean(reference, test, params):
    _, mean, _ = flip_evaluator.evaluate(reference, test, "HDR", applyMagma=False, parameters=dict(params))
    return float(mean)


def tables(args, work):
    """(label, path of an RGL table) for every scan, then the analytic lobe's if asked."""
    out = []
    for scan in args.scans:
        name = os.path.basename(scan)
        path = os.path.join(work, f"{name}.{args.material}.bsdf")
        if not os.path.exists(path):
            run(args.ndfit, "export", scan, "--to", "rgl", "--material", args.material, "-o", path)
        out.append((name, path))
    if args.lobe_scan:
        name = os.path.basename(args.lobe_scan)
        fit = os.path.join(work, f"{name}.{args.lobe_model}.json")
        path = os.path.join(work, f"{name}.{args.lobe_model}.{args.material}.bsdf")
        if not os.path.exists(path):
            run(args.ndfit, "fit", args.lobe_scan, "--model", args.lobe_model, "-o", fit)
            run(args.ndfit, "export", fit, "--to", "rgl", "--material", args.material, "-o", path)
        out.append((f"{name} ({args.lobe_model} lobe)", path))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("scans", nargs="+", help="heightfield scans (anything `ndfit export --to rgl` reads)")
    ap.add_argument("--ndfit", default=os.environ.get("NDFIT", "target/release/ndfit"), help="the ndfit binary (default: $NDFIT, else target/release/ndfit)")
    ap.add_argument("--material", default="Al", help="the conductor of the tables (default Al, the choice's default)")
    ap.add_argument("--scenes", default="point,broad", help="any of point, broad, window (default point,broad)")
    ap.add_argument("--spp", default="16,64,256", help="sample counts of the production renders")
    ap.add_argument("--ref-spp", type=int, default=4096, help="sample count of the converged reference")
    ap.add_argument("--sampler", default="independent", help="Mitsuba sampler (independent, stratified, multijitter, orthogonal, ldsampler)")
    ap.add_argument("--variant", default="scalar_rgb", help="Mitsuba RGB variant (default scalar_rgb; llvm_ad_rgb is faster where its JIT works)")
    ap.add_argument("--lobe-scan", default=None, help="also a lobe's table: the fit of this scan (default: the first scan; '' for none)")
    ap.add_argument("--lobe-model", default="ggx-aniso")
    ap.add_argument("--workdir", default=None, help="scratch folder (tables are reused when present)")
    ap.add_argument("--keep", action="store_true", help="keep a temporary --workdir")
    args = ap.parse_args()
    if args.lobe_scan is None:
        args.lobe_scan = args.scans[0]
    if not os.access(args.ndfit, os.X_OK):
        sys.exit(f"no ndfit binary at {args.ndfit} (--ndfit or $NDFIT)")
    scenes = [s.strip() for s in args.scenes.split(",") if s.strip()]
    for sc in scenes:
        if sc not in SIZES:
            sys.exit(f"unknown scene {sc!r} (--scenes takes {', '.join(SIZES)})")
    spps = [int(s) for s in args.spp.split(",")]

    variant = args.variant
    mi.set_variant(variant)

    t0 = time.time()
    temp = args.workdir is None
    work = tempfile.mkdtemp(prefix="ndfit-render-tolerance-") if temp else args.workdir
    os.makedirs(work, exist_ok=True)
    try:
        tabs = tables(args, work)
        t_tables = time.time() - t0
        print(f"Mitsuba {mi.__version__} ({variant}, path tracer max_depth 2, {args.sampler} sampler), "
              f"flip_evaluator, material {args.material}, reference {args.ref_spp} spp; "
              f"exposures from the reference, stop capped at start + log2({DYNAMIC_RANGE:g})\n")
        print("| table | scene | spp | FLIP(ref, N) | FLIP(N, N') |")
        print("|---|---|---:|---:|---:|")
        rows = []
        for label, path in tabs:
            for sc in scenes:
                scene = mi.load_dict(scene_dict(sc, path, args.ref_spp, args.sampler, SIZES[sc]))
                ref = render(scene, args.ref_spp, seed=0)
                params = exposures(ref)
                for k, n in enumerate(spps):
                    a = render(scene, n, seed=1 + 2 * k)
                    b = render(scene, n, seed=2 + 2 * k)
                    vs_ref, pair = flip_mean(ref, a, params), flip_mean(a, b, params)
                    rows.append((label, sc, n, vs_ref, pair))
                    print(f"| {label} | {sc} | {n} | {vs_ref:.4f} | {pair:.4f} |", flush=True)
        print()
        print("Median over the tables (the lobe's included):\n")
        print("| scene | spp | FLIP(ref, N) | FLIP(N, N') | max FLIP(ref, N) |")
        print("|---|---:|---:|---:|---:|")
        for sc in scenes:
            for n in spps:
                sel = [r for r in rows if r[1] == sc and r[2] == n]
                print(f"| {sc} | {n} | {statistics.median(r[3] for r in sel):.4f} | "
                      f"{statistics.median(r[4] for r in sel):.4f} | {max(r[3] for r in sel):.4f} |")
        print(f"\n{len(tabs)} tables written in {t_tables:.0f} s; total {time.time() - t0:.0f} s")
    finally:
        if temp and not args.keep:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
