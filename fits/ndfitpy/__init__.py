"""ndfitpy: an independent numpy + nlopt implementation of ndfit's NDF models, objectives and fits.

Written from the papers (/work/shared/seeds/) and the interface documents (data_formats/, CONTRACT.md), not from
the Rust code, so that agreement between the two is evidence. Modules: ``models`` (D of every model),
``objective`` (Poisson deviance, logd, the delta metric), ``bins`` (the NDF CSV), ``fit`` (nlopt),
``canonical`` (comparable ellipsoid parameters), ``fitjson`` (ndfit.fit/1), ``synthetic`` (test data).
"""

from . import bins, canonical, fit, fitjson, models, objective, synthetic  # noqa: F401

__version__ = "0.1.0"
