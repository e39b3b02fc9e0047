"""ndfit: empirical normal distribution functions (NDFs) of heightfield scans, and fits of the Ellipsoid
NDF of Walter, Dong, Marschner and Greenberg, GGX, Beckmann, Student-t slopes and two-lobe mixtures to them
with Levenberg-Marquardt.

The compiled core is the ndfit Rust library: a fit here and ``ndfit fit`` on the command line are the same
computation with the same options (``Fit.to_json()`` is the document the CLI writes), and the work runs
without the GIL.

    >>> import ndfit
    >>> scan = ndfit.read("sample.x3p")           # Scan: .heights (ny, nx) in metres, NaN = invalid
    >>> f = ndfit.fit(scan, model="auto")          # or ndfit.fit("sample.x3p", ...)
    >>> f.model, f.params, f.quality["verdict"]
    >>> f.d(m)                                     # D of the fit at unit directions m, shape (n, 3)
    >>> e = ndfit.ndf(scan)                        # the empirical NDF: e.m, e.d, e.count, e.stderr, ...
    >>> t = ndfit.trace(scan, incidence=[0, 40])   # geometric optics on the scan: t.to_json() as `ndfit trace`
    >>> w = ndfit.wave(scan, grid=64)              # wave optics: w.records, w.grid (wavelengths, incidences, 64, 64)

Units are metres and radians; the frame is the scan's (row index along +y, column along +x, macro normal
+z). For the anisotropic models the alpha_x axis lies at azimuth -theta_z, along (cos theta_z,
-sin theta_z) in the scan frame (Walter et al.'s A = S Rz(theta_z)).

Errors (unreadable or corrupt files, options out of range, failed fits) raise :class:`NdfitError` with one
line naming the file and the problem; ``err.kind`` names the kind as ``ndfit batch`` does.

Many scans at once, on one machine or a cluster: :func:`ndfit.dask.fit_many` (needs dask.distributed and
pandas: ``pip install "ndfit[dask]"``).
"""

from ._ndfit import Fit, Ndf, NdfitError, Scan, Trace, Wave, __version__, fit, ndf, read, trace, wave

__all__ = ["Fit", "Ndf", "NdfitError", "Scan", "Trace", "Wave", "fit", "ndf", "read", "trace", "wave", "__version__"]
