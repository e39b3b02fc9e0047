#!/usr/bin/env python3
"""Fit the shared real scans with `ndfit fit --model auto` and write docs/REAL_SCANS.md: per scan the
render choice's answer (`selection.answer`: a lobe, or `measured` for the scan's table), the lobe the report
holds, the verdict, the render error of that lobe against the table per scene (`selection.render_error`),
its NDF error beyond counting noise (`quality.delta_excess`), what the NDF error alone would have chosen
(`--scene none`), and the effect of each rung of the ladder (`selection.candidates`: the parent's
`delta_excess` minus the candidate's, and each rendered lobe's worst FLIP).

    python3 fits/real_scans_table.py [--ndfit target/release/ndfit] [--before OLD_NDFIT] [--out docs/REAL_SCANS.md]

`--before` fits the scans with another build as well and adds its chosen model and `delta_excess` (the
comparison of a change to `auto`). The scans are read from ../shared/data/scans (relative to the repository).
"""
import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCANS = ROOT.parent / "shared" / "data" / "scans"
EXTS = {".x3p", ".al3d", ".dat", ".opd", ".plu", ".sur", ".tmd"}


def fit(ndfit, scan, out, *extra):
    r = subprocess.run([ndfit, "fit", str(scan), "--model", "auto", "-o", str(out), *extra], capture_output=True, text=True)
    if r.returncode != 0:
        return None, r.returncode, r.stderr.strip().splitlines()[-1:] or [""]
    return json.loads(out.read_text()), 0, None


def rung(c):
    """One candidate's effect: its model and the change of delta_excess over its parent."""
    e = c.get("effect")
    change = "-" if e is None else f"{-100 * e:+.1f}%"
    guard = "" if c.get("supported", True) else " (guard)"
    r = (c.get("render_error") or {}).get("worst")
    flip = "" if r is None else f" [FLIP {r:.3f}]"
    return f"{c['model']} {change}{flip}{guard}"


def flip(sel, key):
    v = (sel.get("render_error") or {}).get(key)
    return "-" if v is None else f"{v:.4f}"


def mirror(o):
    """The mirror share at 550 nm at 0 and 60 degrees, and the haze lobe where there is one."""
    s = {(x["theta_deg"], x["wavelength_nm"]): x["weight"] for x in o.get("specular", [])}
    if not s:
        return "-"
    h = o.get("haze")
    haze = f"; haze {h['model']} {h['params']['alpha']:.3f} ({100 * h['albedo']:.2f}%)" if h else ""
    return f"{s.get((0.0, 550.0), float('nan')):.3f} / {s.get((60.0, 550.0), float('nan')):.3f}{haze}"


def pct(v):
    return "-" if v is None else f"{100 * v:.1f}%"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--ndfit", default=str(ROOT / "target" / "release" / "ndfit"))
    ap.add_argument("--before", default=None)
    ap.add_argument("--out", default=str(ROOT / "docs" / "REAL_SCANS.md"))
    a = ap.parse_args()
    scans = sorted(p for p in SCANS.iterdir() if p.suffix.lower() in EXTS)
    if not scans:
        sys.exit(f"{SCANS}: no scans")
    rows, now, then, failed, flips = [], [], [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for s in scans:
            rep, rc, err = fit(a.ndfit, s, Path(tmp) / "fit.json")
            if rep is None:
                failed.append(f"{s.name}: exit {rc}: {err[0]}")
                continue
            q, sel, o = rep["quality"], rep.get("selection") or {}, rep.get("optics") or {}
            by_ndf, _, _ = fit(a.ndfit, s, Path(tmp) / "ndf.json", "--scene", "none")
            old = None
            if a.before:
                old, _, _ = fit(a.before, s, Path(tmp) / "before.json")
            de = q.get("delta_excess")
            if de is not None:
                now.append(de)
            worst = (sel.get("render_error") or {}).get("worst")
            if worst is not None:
                flips.append(worst)
            old_de = old["quality"].get("delta_excess") if old else None
            if old_de is not None:
                then.append(old_de)
            effects = ", ".join(rung(c) for c in sel.get("candidates", []) if c.get("parent") is not None)
            rows.append(
                f"| {s.name} | {sel.get('answer', '-')} | {o.get('regime', '-')} | {mirror(o)} | {rep['model']} | {q['verdict']} | {flip(sel, 'point')} | "
                f"{flip(sel, 'broad')} | {flip(sel, 'worst')} | {pct(de)} | {by_ndf['model'] if by_ndf else '-'} | "
                + (f"{old['model']} | {pct(old_de)} | " if a.before else "")
                + f"{effects or '-'} | {', '.join(sel.get('not_fitted', [])) or '-'} |"
            )
            print(rows[-1], file=sys.stderr)
    head = "| scan | answer | regime | mirror share at 550 nm, 0 / 60 deg | lobe | verdict | FLIP point | FLIP broad | FLIP worst | delta_excess | NDF alone chose | "
    head += "before: chosen | before: delta_excess | " if a.before else ""
    head += "effect of each rung (change of delta_excess over its parent) [worst FLIP] | not fitted |\n"
    head += "|" + " --- |" * (head.count("|") - 1) + "\n"
    med = f"{statistics.median(now):.3f}" if now else "-"
    lines = [
        "# The shared real scans under `--model auto`",
        "",
        "Made by `python3 fits/real_scans_table.py" + (" --before OLD_NDFIT" if a.before else "") + "` (default options: the",
        "render choice in the default scenes with its default tolerance, data_formats/render.md, \"The choice\"; the NDF",
        "tolerance of data_formats/objective.md, \"The tolerance\" and \"Mixtures and the ladder\"). `answer` is what a",
        "renderer should use (`measured`: the scan's own table, `ndfit export SCAN --to rgl`; `mirror`, `mirror+ggx`:",
        "a mirror term, docs/ANSWER.md); `regime` is what light sees (`optics.regime`: geometric, mixed or wave), with",
        "the mirror share (`optics.specular`) and a mirror answer's haze lobe (`optics.haze`: alpha, its share of the",
        "light at normal incidence); `lobe` is the report's `model` (the answer, or the closest lobe; for a mirror",
        "answer, the ladder's fit of the slopes); the FLIP columns are that lobe's mean HDR-FLIP against the table's",
        "render; `NDF alone chose` is `--scene none` (the ladder's choice by the NDF error beyond counting noise). A",
        "rung's effect is the change of that NDF error over its parent (negative: it lowers the error), with the",
        "rung's worst FLIP where it was rendered in every scene (the choice stops at its answer, and a lobe already",
        "out in the first scene is not rendered in the second); `(guard)` marks a candidate the likelihood does not",
        "support.",
        "",
        head + "\n".join(rows),
        "",
        f"Median `delta_excess` of the reported lobe: {med}" + (f" (before: {statistics.median(then):.3f})" if then else "")
        + (f"; median worst FLIP {statistics.median(flips):.3f}" if flips else "") + ".",
    ]
    if then:
        lines += ["", "The `before` columns are the other build's own report: a build that removes another noise "
                  "from `delta_data` reports another `delta_excess` for the same fit (the dispersion-scaled noise "
                  "of older builds is larger where the dispersion is, e.g. st_al3d-1 and st_tmd-1)."]
    if failed:
        lines += ["", "Failed:", *[f"- {f}" for f in failed]]
    # Sections after the table (e.g. "What a richer model could reach", written by explore_real_lobes.py) stay.
    out = Path(a.out)
    kept = ""
    if out.exists():
        old = out.read_text()
        at = old.find("\n## ")
        kept = old[at:] if at >= 0 else ""
    out.write_text("\n".join(lines) + "\n" + kept)
    print(f"wrote {a.out}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
