"""Type stubs of the compiled core of ndfit (see the docstrings in the module for the details)."""

from os import PathLike
from typing import Any, Dict, List, Literal, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str

_Path = Union[str, PathLike[str]]
_Source = Union["Scan", _Path]
_Form = Literal["none", "plane", "poly2", "poly3", "cylinder"]
_Model = Literal["auto", "ggx", "beckmann", "student", "ggx-aniso", "beckmann-aniso", "student-aniso", "ellipsoid", "ggx2", "beckmann2", "ellipsoid+ggx"]
_Directions = npt.ArrayLike  # shape (n, 3) or (3,)

class NdfitError(Exception):
    """One line naming the file and the problem; ``kind`` as ``ndfit batch`` names it."""

    kind: str

class Scan:
    """A heightfield scan in metres (NaN = invalid), read from a file or built from a 2D array."""

    def __init__(self, heights: npt.ArrayLike, dx: float, dy: Optional[float] = None) -> None: ...
    @property
    def heights(self) -> npt.NDArray[np.float64]:
        """(ny, nx) float64, read-only view of the scan's buffer (no copy)."""
    @property
    def dx(self) -> float: ...
    @property
    def dy(self) -> float: ...
    @property
    def nx(self) -> int: ...
    @property
    def ny(self) -> int: ...
    @property
    def shape(self) -> Tuple[int, int]: ...
    @property
    def format(self) -> str: ...
    @property
    def path(self) -> Optional[str]: ...
    @property
    def invalid(self) -> int: ...
    @property
    def meta(self) -> Dict[str, Any]: ...

class Ndf:
    """The empirical NDF: one entry per bin, empty bins included."""

    @property
    def m(self) -> npt.NDArray[np.float64]:
        """(n, 3) unit bin directions."""
    @property
    def d(self) -> npt.NDArray[np.float64]: ...
    @property
    def stderr(self) -> npt.NDArray[np.float64]: ...
    @property
    def count(self) -> npt.NDArray[np.uint64]: ...
    @property
    def solid_angle(self) -> npt.NDArray[np.float64]: ...
    @property
    def proj_solid_angle(self) -> npt.NDArray[np.float64]: ...
    @property
    def n_samples(self) -> int: ...
    @property
    def n_skipped(self) -> int: ...
    @property
    def normals(self) -> str: ...
    @property
    def cells_across(self) -> int: ...
    @property
    def warnings(self) -> List[str]: ...
    def __len__(self) -> int: ...

class Fit:
    """A fitted model: the ``ndfit.fit/1`` document of ``ndfit fit`` and the model to evaluate."""

    @property
    def model(self) -> str: ...
    @property
    def params(self) -> Dict[str, float]: ...
    @property
    def param_names(self) -> List[str]: ...
    @property
    def std_errors(self) -> Dict[str, Optional[float]]: ...
    @property
    def matrix_a(self) -> Optional[npt.NDArray[np.float64]]: ...
    @property
    def quality(self) -> Dict[str, Any]: ...
    @property
    def verdict(self) -> str: ...
    @property
    def warnings(self) -> List[str]: ...
    @property
    def answer(self) -> Optional[str]:
        """``auto``'s answer: a model id, ``measured``, ``mirror`` or ``mirror+ggx``; None for one model."""
    @property
    def regime(self) -> Optional[str]:
        """``auto``'s regime (``optics.regime``): ``geometric``, ``mixed`` or ``wave``; None for one model."""
    @property
    def optics(self) -> Optional[Dict[str, Any]]:
        """``auto``'s ``optics`` (regime, wavelength_nm, coherence_m, specular, haze, ...); None for one model."""
    def to_dict(self) -> Dict[str, Any]: ...
    def to_json(self) -> str: ...
    @staticmethod
    def from_json(text: str) -> "Fit": ...
    def d(self, m: _Directions) -> Union[float, npt.NDArray[np.float64]]: ...
    def g1(self, u: _Directions, m: _Directions) -> Union[float, npt.NDArray[np.float64]]: ...

class Trace:
    """A trace of a scan's microgeometry: the ``ndfit.trace/1`` document of ``ndfit trace`` and its binned
    outgoing energies."""

    @property
    def incidences(self) -> List[Dict[str, Any]]: ...
    @property
    def verdict(self) -> Dict[str, Any]: ...
    @property
    def bins(self) -> Tuple[int, int]:
        """``(n_theta, n_phi)``: uniform in ``sqrt(2 theta / pi)`` and in ``phi`` over ``[-pi, pi)``."""
    def proj_solid_angle(self) -> npt.NDArray[np.float64]:
        """Projected solid angle per outgoing bin, ``(n_theta, n_phi)``."""
    def tables(self, k: int) -> Dict[str, npt.NDArray[np.float64]]:
        """Incidence ``k``'s energies per bin: ``single``, ``multi``, ``model`` ``(n_theta, n_phi, 3)``;
        ``var_total`` ``(n_theta, n_phi)``."""
    def to_dict(self) -> Dict[str, Any]: ...
    def to_json(self) -> str: ...
    def __len__(self) -> int: ...

class Wave:
    """A scan's scalar-diffraction BRDF: the ``ndfit.wave/1`` document of ``ndfit wave`` and, with ``grid``,
    the diffuse BRDF grid that ``--grid-out`` writes."""

    @property
    def records(self) -> List[Dict[str, Any]]:
        """One per wavelength and incidence, wavelengths outer."""
    @property
    def patches(self) -> Dict[str, Any]: ...
    @property
    def warnings(self) -> List[str]: ...
    @property
    def grid(self) -> Optional[npt.NDArray[np.float64]]:
        """``(wavelengths, incidences, N, N)`` float64, read-only: the diffuse BRDF (1/sr) per cell of the
        projected outgoing disk; None without ``grid``."""
    def to_dict(self) -> Dict[str, Any]: ...
    def to_json(self) -> str: ...
    def __len__(self) -> int: ...

def read(
    path: _Path, *, dx: Optional[float] = None, dy: Optional[float] = None, z_scale: Optional[float] = None, format: Optional[str] = None
) -> Scan: ...
def ndf(
    source: _Source,
    form: _Form = "plane",
    *,
    dx: Optional[float] = None,
    dy: Optional[float] = None,
    z_scale: Optional[float] = None,
    format: Optional[str] = None,
    crop: Optional[str] = None,
    subsample: int = 1,
    despike: Literal["median", "none"] = "median",
    normals: Literal["central", "triangles"] = "central",
    ndf_cells: Optional[int] = None,
    target_count: float = 64.0,
    threads: Optional[int] = None,
) -> Ndf: ...
def fit(
    source: _Source,
    model: _Model = "auto",
    form: _Form = "plane",
    preset: Optional[Literal["fast", "balanced", "accurate"]] = None,
    *,
    dx: Optional[float] = None,
    dy: Optional[float] = None,
    z_scale: Optional[float] = None,
    format: Optional[str] = None,
    crop: Optional[str] = None,
    subsample: int = 1,
    despike: Literal["median", "none"] = "median",
    normals: Literal["central", "triangles"] = "central",
    ndf_cells: Optional[int] = None,
    target_count: float = 64.0,
    objective: Literal["poisson", "logd"] = "poisson",
    solver: Literal["lm", "nelder-mead", "lbfgs"] = "lm",
    extra_starts: int = 0,
    max_theta: Optional[float] = None,
    na: Optional[float] = None,
    tail: Literal["rim", "core", "unresolved", "all"] = "rim",
    tolerance: Optional[float] = None,
    scene: str = "point,broad",
    render_tolerance: float = 0.02,
    material: Literal["none", "Al", "Ag", "Au", "Cu", "Cr"] = "Al",
    threads: Optional[int] = None,
) -> Fit: ...
def trace(
    source: _Source,
    incidence: Union[float, List[float], None] = None,
    azimuth: float = 0.0,
    material: Literal["none", "Al", "Ag", "Au", "Cu", "Cr"] = "none",
    bounces: int = 16,
    seed: int = 1,
    *,
    rays: int = 1 << 20,
    border: Literal["periodic", "open"] = "periodic",
    bins: str = "32x64",
    tolerance: float = 0.05,
    form: _Form = "plane",
    dx: Optional[float] = None,
    dy: Optional[float] = None,
    z_scale: Optional[float] = None,
    format: Optional[str] = None,
    crop: Optional[str] = None,
    subsample: int = 1,
    despike: Literal["median", "none"] = "median",
    threads: Optional[int] = None,
) -> Trace: ...
def wave(
    source: _Source,
    wavelength_nm: Union[float, Sequence[float], None] = None,
    incidence_deg: Union[float, Sequence[float], None] = None,
    azimuth_deg: float = 0.0,
    coherence_um: Optional[float] = None,
    material: Literal["none", "Al", "Ag", "Au", "Cu", "Cr"] = "none",
    grid: Optional[int] = None,
    level_ratio: float = 1.1,
    *,
    form: _Form = "plane",
    dx: Optional[float] = None,
    dy: Optional[float] = None,
    z_scale: Optional[float] = None,
    format: Optional[str] = None,
    crop: Optional[str] = None,
    subsample: int = 1,
    despike: Literal["median", "none"] = "median",
    threads: Optional[int] = None,
) -> Wave: ...
