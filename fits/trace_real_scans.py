#!/usr/bin/env python3
"""Trace the shared real scans with `ndfit trace` and write their table into docs/TRACE.md (between the
`real-scans` markers): per scan and incidence the albedo (aluminium, every bounce), the share of it that
leaves after two or more bounces (what a single-scattering model misses), the single-bounce error of the
microfacet model beyond Monte Carlo noise (`single.error` less twice `single.noise`, at least 0; the raw
figures beside it), the traced masking `g1` against Smith's `g1_smith` of the scan's NDF, and the verdict.

    python3 fits/trace_real_scans.py [--ndfit target/release/ndfit] [--rays 1048576] [--out docs/TRACE.md]

The scans are read from ../shared/data/scans (relative to the repository); a scan `ndfit trace` refuses is
listed with its one-line error.
"""
import argparse
import json
import re
import subprocess
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCANS = ROOT.parent / "shared" / "data" / "scans"
EXTS = {".x3p", ".al3d", ".dat", ".opd", ".plu", ".sur", ".tmd"}
INCIDENCES = [0, 40, 70]
BEGIN, END = "<!-- real-scans:begin -->", "<!-- real-scans:end -->"


def trace(ndfit, scan, out, rays):
    args = [ndfit, "trace", str(scan), "--incidence", ",".join(map(str, INCIDENCES)), "--material", "Al",
            "--rays", str(rays), "--seed", "1", "--quiet", "-o", str(out)]
    r = subprocess.run(args, capture_output=True, text=True)
    if r.returncode != 0:
        return None, (r.stderr.strip().splitlines() or ["exit %d" % r.returncode])[-1]
    return json.loads(out.read_text()), None


def row(name, doc):
    s = doc["surface"]
    size = f"{s.get('nx', '?')}x{s.get('ny', '?')}"
    cells = []
    for rec in doc["incidences"]:
        single = rec["single"]
        beyond = max(0.0, single["error"] - 2.0 * single["noise"])
        cells.append(
            f"{rec['albedo']:.3f} / {100 * max(0.0, rec['multiple_share']):.1f}% / {100 * beyond:.1f}% "
            f"({100 * single['error']:.1f}+-{100 * single['noise']:.1f}) / {rec['g1']:.3f}:{rec['g1_smith']:.3f}"
        )
    return f"| {name} | {size} | " + " | ".join(cells) + f" | {doc['verdict']['verdict']} |"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--ndfit", default=str(ROOT / "target" / "release" / "ndfit"))
    ap.add_argument("--rays", type=int, default=1 << 20)
    ap.add_argument("--out", default=str(ROOT / "docs" / "TRACE.md"))
    a = ap.parse_args()
    scans = sorted(p for p in SCANS.iterdir() if p.suffix.lower() in EXTS)
    if not scans:
        raise SystemExit(f"SKIP: no scans under {SCANS}")
    head = " | ".join(f"{t} deg: albedo / multiple / error beyond noise (error+-noise) / g1:Smith" for t in INCIDENCES)
    lines = [
        BEGIN,
        f"`python3 fits/trace_real_scans.py` (`ndfit trace SCAN --incidence {','.join(map(str, INCIDENCES))} "
        f"--material Al --rays {a.rays} --seed 1`, defaults otherwise: periodic border, 16 bounces, 32x64 bins).",
        "",
        f"| scan | grid | {head} | verdict |",
        "|---" * (3 + len(INCIDENCES)) + "|",
    ]
    with tempfile.TemporaryDirectory() as d:
        for scan in scans:
            doc, err = trace(a.ndfit, scan, Path(d) / "t.json", a.rays)
            if doc is None:
                lines.append(f"| {scan.name} | - | " + " | ".join("-" for _ in INCIDENCES) + f" | refused: {err} |")
            else:
                lines.append(row(scan.name, doc))
            print(lines[-1], flush=True)
    lines.append(END)
    out = Path(a.out)
    text = out.read_text()
    block = "\n".join(lines)
    if BEGIN in text:
        text = re.sub(re.escape(BEGIN) + ".*?" + re.escape(END), lambda _: block, text, flags=re.S)
    else:
        text = text.rstrip("\n") + "\n\n## The shared real scans\n\n" + block + "\n"
    out.write_text(text)


if __name__ == "__main__":
    main()
