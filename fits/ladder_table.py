#!/usr/bin/env python3
"""The likelihood's view of one lobe against two on the shared real scans: `ndfit fit --model auto` on every
scan in a directory, one Markdown table row per scan. `auto` chooses by the NDF error within the tolerance
(docs/REAL_SCANS.md, fits/real_scans_table.py); the quasi-likelihood BIC `F / c_data + p ln N`
(`selection.candidates[].qbic_data`, with the data's own overdispersion `c_data`) is its guard, and this
table shows that guard: the best single lobe and the best mixture by `qbic_data` with their deviance per dof,
the drop of `qbic_data` from one to the other, what each parameter the mixture adds over its parent buys
(`gain_per_param`) against its price ln N, the mixtures the guard lets into the choice (`supported`),
`c_data`, and the model `auto` chose.

Usage: python3 fits/ladder_table.py [SCANS_DIR] [--ndfit PATH] > table.md
(standard library only; SCANS_DIR defaults to ../shared/data/scans; PATH to target/release/ndfit).
Prints SKIP and exits 0 when the directory is absent."""
import json
import math
import os
import subprocess
import sys
import tempfile

MIXTURES = ("ggx2", "beckmann2", "ellipsoid+ggx")
SCAN_EXT = (".x3p", ".al3d", ".dat", ".opd", ".plu", ".sur", ".tmd")
HEADER = ("| scan | best single lobe (deviance/dof) | best mixture (deviance/dof) | QBIC_data single - mixture "
          "| gain per added parameter / ln N | mixtures the guard supports | c_data | auto's choice |")
ALIGN = "| --- | --- | --- | ---: | ---: | --- | ---: | --- |"


def row(name, fit):
    """One scan's row from its `ndfit.fit/1` document."""
    sel = fit["selection"]
    cands = sel["candidates"]
    singles = [c for c in cands if c["model"] not in MIXTURES]
    mixes = [c for c in cands if c["model"] in MIXTURES]
    # Both sides by the guard's own criterion (the data's overdispersion c_data).
    best1 = min(singles, key=lambda c: c["qbic_data"])
    best2 = min(mixes, key=lambda c: c["qbic_data"]) if mixes else None
    fmt = lambda c: f"{c['model']} ({c['deviance_per_dof']:.2f})" if c.get("deviance_per_dof") is not None else c["model"]
    ln_n = f"{math.log(fit['quality']['n_samples']):.1f}"
    if best2 is None:
        # The ladder stopped below the mixtures: a simpler model was within the tolerance.
        mix, dq, gain, supported = "not fitted", "-", "-", "-"
    else:
        mix = fmt(best2)
        dq = f"{best1['qbic_data'] - best2['qbic_data']:+.0f}"
        gain = f"{best2['gain_per_param']:.0f} / {ln_n}" if best2.get("gain_per_param") is not None else "-"
        ok = [c["model"] for c in mixes if c.get("supported")]
        supported = ", ".join(ok) if ok else "none"
    return (f"| {name} | {fmt(best1)} | {mix} | {dq} | {gain} | {supported} "
            f"| {sel['data_overdispersion']:.2f} | {fit['model']} |")


def main(argv):
    args = list(argv[1:])
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
                why = r.stderr.strip().splitlines()[-1] if r.stderr.strip() else r.returncode
                rows.append(f"| {name} | error: {why} | | | | | | |")
                continue
            with open(out) as f:
                fit = json.load(f)
        rows.append(row(name, fit))
    print(HEADER)
    print(ALIGN)
    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
