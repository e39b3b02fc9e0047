#!/usr/bin/env python3
"""The model ladder on the shared real scans: `ndfit fit --model auto` on every scan in a directory, one
Markdown table row per scan (the chosen model, the best single lobe, the best mixture, their ladder
criteria F / c_data + p ln N, deviance per dof, and the data's own overdispersion c_data).

Usage: python3 fits/ladder_table.py [SCANS_DIR] [--ndfit PATH] > table.md
(standard library only; SCANS_DIR defaults to ../shared/data/scans; PATH to target/release/ndfit).
Prints SKIP and exits 0 when the directory is absent."""
import json
import os
import subprocess
import sys
import tempfile

MIXTURES = {"ggx2", "beckmann2", "ellipsoid+ggx"}
SCAN_EXT = (".x3p", ".al3d", ".dat", ".opd", ".plu", ".sur", ".tmd")


def main(argv):
    args = [a for a in argv[1:]]
    ndfit = "target/release/ndfit"
    if "--ndfit" in args:
        i = args.index("--ndfit")
        ndfit = args[i + 1]
        del args[i:i + 2]
    scans = args[0] if args else "../shared/data/scans"
    if not os.path.isdir(scans):
        print(f"SKIP: {scans} is absent", file=sys.stderr)
        return 0
    rows = []
    for name in sorted(os.listdir(scans)):
        if not name.endswith(SCAN_EXT):
            continue
        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "fit.json")
            r = subprocess.run([ndfit, "fit", os.path.join(scans, name), "--model", "auto", "-o", out], capture_output=True, text=True)
            if r.returncode != 0:
                rows.append(f"| {name} | error: {r.stderr.strip().splitlines()[-1] if r.stderr.strip() else r.returncode} | | | | | | |")
                continue
            with open(out) as f:
                fit = json.load(f)
        sel = fit["selection"]
        cands = sel["candidates"]
        singles = [c for c in cands if c["model"] not in MIXTURES]
        mixes = [c for c in cands if c["model"] in MIXTURES]
        # The best single lobe is the one the single-lobe QBIC chose (criterion with its own overdispersion).
        best1 = min(singles, key=lambda c: c["criterion"])
        best2 = min(mixes, key=lambda c: c["qbic_data"]) if mixes else None
        dq = (best1["qbic_data"] - best2["qbic_data"]) if best2 else float("nan")
        fmt = lambda c: f"{c['model']} ({c['deviance_per_dof']:.2f})" if c and c.get("deviance_per_dof") is not None else "-"
        gain = f"{best2['gain_per_param']:.0f}" if best2 and best2.get("gain_per_param") is not None else "-"
        ln_n = f"{__import__('math').log(fit['quality']['n_samples']):.1f}"
        rows.append(
            f"| {name} | **{fit['model']}** | {fmt(best1)} | {fmt(best2)} | {dq:+.0f} | {gain} / {ln_n} "
            f"| {sel['data_overdispersion']:.2f} | {fit['quality']['verdict']} |"
        )
    print("| scan | chosen | best single lobe (deviance/dof) | best mixture (deviance/dof) "
          "| criterion single - mixture | gain per added parameter / ln N | c_data | verdict |")
    print("| --- | --- | --- | --- | ---: | ---: | ---: | --- |")
    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
