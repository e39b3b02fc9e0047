"""Command line: ``python -m ndfitpy fit NDF.csv --model M [-o OUT.json]``, ``python -m ndfitpy canonical FIT.json``."""

from __future__ import annotations

import argparse
import json
import sys

from . import canonical, fitjson, models
from . import objective as obj
from .bins import read_ndf_csv
from .fit import METHODS, fit


def _fit(args) -> int:
    bins = read_ndf_csv(args.ndf)
    info = None
    if args.input_json:
        with open(args.input_json, encoding="utf-8") as fh:
            info = json.load(fh)
    res = fit(bins, args.model, objective=args.objective, method=args.method)
    doc = fitjson.fit_document(res, bins, info)
    text = json.dumps(doc, indent=2) + "\n"
    if args.output:
        fitjson.write_atomic(args.output, text)
    else:
        sys.stdout.write(text)
    return 0


def _canonical(args) -> int:
    doc = fitjson.read_fit(args.fit)
    json.dump({"model": doc["model"], "params": canonical.canonical(doc["model"], doc["params"])}, sys.stdout, indent=2)
    sys.stdout.write("\n")
    return 0


def main(argv=None) -> int:
    """Parse arguments and run; errors are one line on standard error and exit status 2."""
    ap = argparse.ArgumentParser(prog="ndfitpy", description=__doc__)
    sub = ap.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("fit", help="fit a model to an empirical NDF CSV (ndfit ndf's output)")
    f.add_argument("ndf")
    # The single lobes: the contract's and the Student-t lobes (the mixtures start from a parent fit, as the
    # cross-check gives them; not from the command line).
    f.add_argument("--model", required=True, choices=models.MODELS + models.STUDENTS)
    f.add_argument("--objective", default="poisson", choices=obj.OBJECTIVES)
    f.add_argument("--method", default="bobyqa+lbfgs", choices=METHODS)
    f.add_argument("--input-json", help="JSON object merged into the output's 'input' (e.g. ndfit info --json)")
    f.add_argument("-o", "--output")
    c = sub.add_parser("canonical", help="print the canonical parameters of an ndfit.fit/1 JSON")
    c.add_argument("fit")
    args = ap.parse_args(argv)
    try:
        return _fit(args) if args.cmd == "fit" else _canonical(args)
    except (ValueError, OSError) as e:
        print(f"ndfitpy: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
