"""Read and write the ``ndfit.fit/1`` JSON of /work/shared/CONTRACT.md ("Fit result JSON").

Required keys: schema, model, params, matrix_a (for ellipsoid-family models), input. This writer adds
``param_order``, ``quality``, ``solver`` and ``timings`` in the layout the Rust fit uses, ``objective``
({name, value, ...}), ``std_errors`` (Fisher, scaled by reduced_chi2 when above 1) and ``fitter``
(which program and method made the fit).
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from typing import Optional

import numpy as np

from . import models
from . import objective as obj
from .bins import Bins
from .fit import FitResult

SCHEMA = "ndfit.fit/1"


def write_atomic(path: str, text: str) -> None:
    """Write ``text`` to ``path`` through a temporary file in the same folder and a rename (no half-written file)."""
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", suffix=".json", dir=folder)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def fit_document(result: FitResult, bins: Bins, input_info: Optional[dict] = None) -> dict:
    """The ``ndfit.fit/1`` document of a fit."""
    a = models.matrix_a(result.model, result.params)
    info = {"path": bins.path, "format": "ndf-csv"}
    if input_info:
        info.update(input_info)
    k = obj.dof(result.model, bins)
    doc = {
        "schema": SCHEMA,
        "model": result.model,
        "params": dict(result.params),
        "input": info,
        "objective": {
            "name": result.objective,
            "value": result.value,
            "dof": k,
            "reduced_chi2": (result.value / k) if k > 0 else None,
            "n_samples": bins.n_samples,
            "n_bins": int(np.count_nonzero(bins.proj_solid_angle > 0)),
        },
        "fitter": {
            "program": "ndfitpy (numpy + nlopt)",
            "method": result.method,
            "status": result.status,
            "evaluations": result.evaluations,
            "seconds": result.seconds,
        },
    }
    # The same layout as the Rust fit's JSON where the two overlap (ndfit fit writes these keys too).
    doc["param_order"] = list(models.PARAM_NAMES[result.model])
    doc["quality"] = {
        "objective": result.objective,
        "objective_value": result.value,
        "dof": k,
        "reduced_chi2": doc["objective"]["reduced_chi2"],
        "n_bins": doc["objective"]["n_bins"],
        "n_bins_nonzero": int(np.count_nonzero((bins.proj_solid_angle > 0) & (bins.count > 0))),
        "n_samples": bins.n_samples,
    }
    doc["solver"] = {"name": result.method, "termination": result.status, "evaluations": result.evaluations}
    doc["timings"] = {"fit_ms": 1e3 * result.seconds}
    if a is not None:
        doc["matrix_a"] = a.tolist()
    rc = doc["objective"]["reduced_chi2"]
    se = obj.standard_errors(result.model, result.params, bins, scale=max(rc or 1.0, 1.0))
    if se is not None:
        doc["std_errors"] = {k: float(v) for k, v in zip(models.PARAM_NAMES[result.model], se)}
    return doc


def write_fit(path: str, result: FitResult, bins: Bins, input_info: Optional[dict] = None) -> dict:
    """Write the fit's JSON to ``path`` atomically and return the document."""
    doc = fit_document(result, bins, input_info)
    write_atomic(path, json.dumps(doc, indent=2) + "\n")
    return doc


def read_fit(path: str) -> dict:
    """Read an ``ndfit.fit/1`` JSON and check what the contract requires; ValueError('<path>: <problem>')."""
    path = os.fspath(path)
    try:
        with open(path, encoding="utf-8") as fh:
            doc = json.load(fh)
    except OSError as e:
        raise ValueError(f"{path}: cannot open: {e.strerror or e}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise ValueError(f"{path}: not JSON: {e}") from None
    if not isinstance(doc, dict):
        raise ValueError(f"{path}: top level is not an object")
    if doc.get("schema") != SCHEMA:
        raise ValueError(f"{path}: schema is {doc.get('schema')!r}, expected {SCHEMA!r}")
    for key in ("model", "params", "input"):
        if key not in doc:
            raise ValueError(f"{path}: missing required key '{key}'")
    model = doc["model"]
    if model not in models.PARAM_NAMES:
        raise ValueError(f"{path}: unknown model {model!r}")
    try:
        models.params_to_array(model, doc["params"])
    except (ValueError, TypeError) as e:
        raise ValueError(f"{path}: params: {e}") from None
    if model in models.ELLIPSOID_FAMILY:
        a = doc.get("matrix_a")
        if a is None:
            raise ValueError(f"{path}: missing 'matrix_a' for ellipsoid-family model {model!r}")
        arr = np.asarray(a, dtype=float)
        if arr.shape != (3, 3) or not np.all(np.isfinite(arr)):
            raise ValueError(f"{path}: 'matrix_a' is not a finite 3x3 matrix")
    return doc


def objective_value(doc: dict) -> Optional[float]:
    """The objective value a fit document reports (``objective.value`` or a bare number), if any."""
    o = doc.get("objective")
    if isinstance(o, dict):
        o = o.get("value")
    q = doc.get("quality")
    if o is None and isinstance(q, dict):  # the Rust fit's layout: quality.objective_value
        o = q.get("objective_value")
    if isinstance(o, (int, float)) and math.isfinite(o):
        return float(o)
    return None
