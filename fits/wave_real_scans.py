#!/usr/bin/env python3
"""Run `ndfit wave` on the shared real scans and write their table into docs/WAVE.md (between the
`real-scans` markers): per scan the coherence patches, the mirror share (`specular`, Fresnel excluded) at 0,
45 and 75 degrees at 450, 550 and 650 nm, the band limit at 550 nm with the share of the light that
geometric optics of the slopes sends beyond it, and the regime by the rule stated in docs/WAVE.md.

    python3 fits/wave_real_scans.py [--ndfit target/release/ndfit] [--out docs/WAVE.md]

The scans are read from ../shared/data/scans (relative to the repository) with the default coherence
patch; a scan `ndfit wave` refuses is listed with the reason.
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
LAMBDAS = [450, 550, 650]
THETAS = [0, 45, 75]
BEGIN, END = "<!-- real-scans:begin -->", "<!-- real-scans:end -->"
# The regime rule (docs/WAVE.md, "The real scans"): what the scan cannot tell first, then the mirror.
UNRESOLVED = 0.2
MIRROR = 0.5
GEOMETRIC = 0.05


def wave(ndfit, scan, out):
    args = [ndfit, "wave", str(scan), "--wavelength", ",".join(map(str, LAMBDAS)),
            "--incidence", ",".join(map(str, THETAS)), "--quiet", "-o", str(out)]
    r = subprocess.run(args, capture_output=True, text=True)
    if r.returncode != 0:
        line = (r.stderr.strip().splitlines() or ["exit %d" % r.returncode])[-1]
        return None, line.split(": ", 2)[-1]
    return json.loads(out.read_text()), None


def regime(doc):
    recs = doc["records"]
    beyond = max(r["beyond_band"] for r in recs if r["theta_deg"] <= 45)
    if beyond > UNRESOLVED:
        return f"the scan cannot tell ({beyond:.0%} beyond its band): geometric"
    s = {(r["wavelength_nm"], r["theta_deg"]): r["specular"] for r in recs}
    if s[(550, 0)] >= MIRROR:
        return "wave (a mirror)"
    if all(s[(l, t)] <= GEOMETRIC for l in LAMBDAS for t in THETAS if t <= 45):
        return "geometric"
    return "mixed"


def row(name, doc):
    p = doc["patches"]
    s = {(r["wavelength_nm"], r["theta_deg"]): r for r in doc["records"]}
    cells = [" / ".join(f"{s[(l, t)]['specular']:.3f}" for l in LAMBDAS) for t in THETAS]
    band = s[(550, 0)]["band_limit"]
    beyond = max(r["beyond_band"] for r in doc["records"] if r["wavelength_nm"] == 550)
    return (f"| {name} | {p['used']} of {p['samples'][0]}x{p['samples'][1]} ({p['incoherent_floor']:.3f}) | " + " | ".join(cells)
            + f" | {band:.3f} ({beyond:.0%}) | {p['tilt_rms_deg']:.2f} | {regime(doc)} |")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--ndfit", default=str(ROOT / "target" / "release" / "ndfit"))
    ap.add_argument("--out", default=str(ROOT / "docs" / "WAVE.md"))
    a = ap.parse_args()
    if not SCANS.is_dir():
        raise SystemExit(f"{SCANS} is absent")
    lines = ["| scan | patches of samples (incoherent floor) | mirror share at 0 deg (450 / 550 / 650 nm) | at 45 deg | at 75 deg "
             "| band limit at 550 nm (light beyond it, up to 75 deg) | patch tilt RMS (deg) | regime |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    with tempfile.TemporaryDirectory() as tmp:
        for scan in sorted(p for p in SCANS.iterdir() if p.suffix.lower() in EXTS):
            doc, err = wave(a.ndfit, scan, Path(tmp) / "w.json")
            lines.append(row(scan.name, doc) if doc else f"| {scan.name} | {err} | | | | | | |")
    table = "\n".join(lines)
    print(table)
    out = Path(a.out)
    text = out.read_text()
    new = re.sub(re.escape(BEGIN) + ".*?" + re.escape(END), BEGIN + "\n" + table + "\n" + END, text, flags=re.S)
    if new != text:
        out.write_text(new)


if __name__ == "__main__":
    main()
