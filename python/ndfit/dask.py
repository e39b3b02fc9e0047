"""Fit many scans on a Dask cluster: :func:`fit_many`.

Each scan is one task: a pure function of (path, model, options) that runs ``ndfit.fit`` in the worker and
returns a plain dict, so results travel as data and do not depend on the number of workers. As in
``ndfit batch``, each scan's fit runs on one thread (the parallelism is across scans) and a scan that
fails becomes an ``error`` row while the others go on.
"""

from __future__ import annotations

import inspect
import math
import os
from typing import Any, Dict, Iterable, List, Optional, Union

#: Parameter columns, in this order, for every model (a model fills the ones it has).
# Every parameter of every model (ndfit models): the single lobes, then the mixtures' own names.
PARAM_COLUMNS = ["alpha", "alpha_x", "alpha_y", "theta_x", "theta_y", "theta_z", "alpha_x1", "alpha_y1", "alpha_x2", "alpha_y2", "alpha2", "weight", "gamma"]
#: Every column of :func:`fit_many`'s DataFrame, in order.
COLUMNS = ["path", "status", "model", *PARAM_COLUMNS, "verdict", "answer", "regime", "reduced_chi2", "n_samples", "error_kind", "error"]


def fit_row(path: str, model: str = "auto", options: Optional[Dict[str, Any]] = None) -> Dict[str, Any]:
    """Fit one scan; a plain dict row (the task :func:`fit_many` submits per scan).

    ``status`` is ``ok`` with ``model``, the parameters (NaN for those the model lacks), ``verdict``, ``answer`` and ``regime``
    (``auto``; None for one model), ``reduced_chi2`` and ``n_samples``, or
    ``error`` with ``error`` (one line naming the file and the problem) and ``error_kind``.
    """
    import ndfit

    row: Dict[str, Any] = {c: None for c in COLUMNS}
    row.update({c: math.nan for c in PARAM_COLUMNS})
    row["path"] = str(path)
    opts = dict(options or {})
    opts.setdefault("threads", 1)
    try:
        f = ndfit.fit(os.fspath(path), model=model, **opts)
    except ndfit.NdfitError as e:
        row.update(status="error", error=str(e), error_kind=getattr(e, "kind", ""))
        return row
    q = f.quality
    row.update(status="ok", model=f.model, verdict=q["verdict"], answer=f.answer, regime=f.regime,
               reduced_chi2=q["reduced_chi2"], n_samples=q["n_samples_total"])
    row.update(f.params)
    return row


def _check_options(model: str, options: Dict[str, Any]) -> None:
    """Fail at once, before any task runs, on an option ``ndfit.fit`` does not take."""
    import ndfit

    try:
        inspect.signature(ndfit.fit).bind("scan", model, **options)
    except TypeError as e:
        raise TypeError(f"fit_many: {e}") from None
    except ValueError:  # no signature available: the first task reports the problem instead
        pass


def fit_many(
    paths: Iterable[Union[str, "os.PathLike[str]"]],
    model: str = "auto",
    client: Any = None,
    n_workers: Optional[int] = None,
    processes: bool = False,
    **options: Any,
):
    """Fit every scan in ``paths`` with ``ndfit.fit(path, model=model, **options)``; a pandas DataFrame.

    One row per scan, in the order of ``paths``: ``path``, ``status`` (ok|error), ``model``, the parameters
    (``alpha`` for the isotropic models; ``alpha_x``, ``alpha_y``, ``theta_z`` and for the ellipsoid
    ``theta_x``, ``theta_y``; for the mixtures ``alpha_x1``, ``alpha_y1``, ``alpha_x2``, ``alpha_y2`` or ``alpha2``,
    ``theta_z`` and ``weight``; ``gamma`` for the Student-t lobes; NaN where a model has none), ``verdict``, ``reduced_chi2``, ``n_samples``,
    ``error_kind`` and ``error``. These are the fits ``ndfit batch`` makes with the same model and options.
    The ``alpha_x`` axis lies along ``(cos theta_z, -sin theta_z)`` in the scan frame (azimuth ``-theta_z``).

    ``client``: None starts a ``dask.distributed.LocalCluster`` on this machine with ``n_workers`` workers
    of one thread each (default: one per core) and closes it afterwards; a ``dask.distributed.Client`` or
    a scheduler address (``"tcp://host:8786"``) runs on that cluster instead (its workers need ``ndfit``
    installed and the files at the same paths). The LocalCluster's workers are threads of this process
    (the fits release the GIL, so they run in parallel), which works the same from a plain script with
    top-level code, a notebook or an interactive session. ``processes=True`` makes them worker processes
    instead; those re-import the calling script, so a script then needs ``if __name__ == "__main__":``.
    ``options``: those of :func:`ndfit.fit` (``form``, ``dx``, ``subsample``, ``max_theta``, ...); each
    fit runs on one thread (``threads=1``) unless ``threads`` is given.
    """
    import pandas as pd
    from dask.distributed import Client, LocalCluster

    paths = [os.fspath(p) for p in paths]
    _check_options(model, options)
    owned = []
    try:
        if client is None:
            cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=processes, dashboard_address=":0")
            owned.append(cluster)
            client = Client(cluster)
            owned.append(client)
        elif isinstance(client, str):
            client = Client(client)
            owned.append(client)
        futures = client.map(fit_row, paths, model=model, options=options, pure=False)
        rows: List[Dict[str, Any]] = client.gather(futures)
    finally:
        for o in reversed(owned):
            o.close()
    return pd.DataFrame(rows, columns=COLUMNS)
