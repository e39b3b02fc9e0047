//! `ndfit._ndfit`: the Python extension behind `import ndfit`.
//!
//! A thin layer over the library's one pipeline ([`ndfit::Pipeline`]: read -> preprocess -> empirical
//! NDF -> fit), the one `ndfit fit` runs, so a fit from Python and one from the command line are the same
//! computation. This file only converts arguments into [`ndfit::Options`] and results into Python
//! objects, hands numpy arrays to the library without a copy ([`ndfit::Scan::from_view`]), releases the
//! GIL while the library works, and turns library errors (and panics) into `ndfit.NdfitError` carrying
//! the library's one-line message (file, then problem).

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::PathBuf;

use nalgebra::Vector3;
use numpy::{IntoPyArray, PyArray2, PyArrayMethods, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use ndfit::fit::{FitOptions, FitReport, Objective, Solver};
use ndfit::io::ReadOptions;
use ndfit::models::{Model, Ndf as _};
use ndfit::ndf::{EmpiricalNdf, NdfOptions, NormalScheme};
use ndfit::pipeline::check::{self, Spelling};
use ndfit::preprocess::{Crop, Despike, FormRemoval, Preprocess};
use ndfit::wave::WaveOptions;
use ndfit::{Heightfield, ModelChoice, Options, Pipeline, Preset};

create_exception!(
    ndfit,
    NdfitError,
    PyException,
    "A scan that cannot be read, an option out of range, or a fit that failed: one line naming the file and the problem."
);

/// The label a scan built from an array carries where a file would give its path (`input.path`).
const ARRAY_LABEL: &str = "<array>";

/// `NdfitError(message)` with `.kind` the library's error kind as `ndfit batch` names it (`io`,
/// `unknown_format`, `corrupt`, `invalid_input`, ...).
fn error_of_kind(message: String, kind: &str) -> PyErr {
    let err = NdfitError::new_err(message);
    Python::attach(|py| err.value(py).setattr("kind", kind).ok());
    err
}

fn to_py(e: ndfit::Error) -> PyErr {
    let kind = serde_json::to_value(e.kind()).ok().and_then(|v| v.as_str().map(str::to_string)).unwrap_or_default();
    error_of_kind(e.to_string(), &kind)
}

fn invalid(msg: impl Into<String>) -> PyErr {
    error_of_kind(msg.into(), "invalid_input")
}

/// Run `f` without the GIL, inside a `threads`-thread rayon pool when asked (`None`: the global pool, as
/// the CLI), turning a panic into an error instead of unwinding into the interpreter.
fn work<T: Send>(py: Python<'_>, threads: Option<usize>, f: impl FnOnce() -> ndfit::Result<T> + Send) -> PyResult<T> {
    let pool = match threads {
        None => None,
        Some(0) => return Err(invalid("threads must be at least 1")),
        Some(n) => {
            Some(rayon::ThreadPoolBuilder::new().num_threads(n).build().map_err(|e| invalid(format!("cannot start {n} threads: {e}")))?)
        }
    };
    let r = py.detach(|| {
        catch_unwind(AssertUnwindSafe(|| match &pool {
            Some(p) => p.install(f),
            None => f(),
        }))
    });
    match r {
        Ok(r) => r.map_err(to_py),
        Err(p) => {
            let what = p.downcast_ref::<String>().cloned().or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string())).unwrap_or_default();
            Err(error_of_kind(format!("internal error (please report): {what}"), "panic"))
        }
    }
}

/// Where a [`Scan`]'s heights live.
#[allow(clippy::large_enum_variant)] // one per Python Scan object; boxing would only add an indirection to every access
enum Held {
    /// Read from a file (owned, or a view of the file's memory map).
    File(Heightfield),
    /// The caller's numpy array (float64, C order, no infinities), viewed without a copy.
    Array { array: Py<PyArray2<f64>>, dx: f64, dy: f64 },
}

/// A heightfield scan (metres; NaN marks invalid points), as read from a file or built from an array.
#[pyclass(module = "ndfit", name = "Scan", frozen)]
pub struct Scan {
    held: Held,
    meta: ndfit::ScanMeta,
    path: Option<PathBuf>,
}

impl Scan {
    /// The scan as the library's [`ndfit::Scan`], borrowing the heights (no copy) from the file's buffer
    /// or the caller's array: `f` runs while the borrow (and the array's read-only lock) is held.
    fn with_scan<R>(&self, py: Python<'_>, f: impl FnOnce(ndfit::Scan<'_>) -> PyResult<R>) -> PyResult<R> {
        match &self.held {
            Held::File(hf) => {
                let mut s = ndfit::Scan::from_view(hf.heights(), hf.dx, hf.dy).map_err(to_py)?;
                (s.x0, s.y0, s.meta) = (hf.x0, hf.y0, hf.meta.clone());
                f(s)
            }
            Held::Array { array, dx, dy } => {
                let ro = array.bind(py).try_readonly().map_err(|e| invalid(format!("heights: {e}")))?;
                let mut s = ndfit::Scan::from_view(ro.as_array(), *dx, *dy).map_err(to_py)?;
                s.meta = self.meta.clone();
                f(s)
            }
        }
    }

    fn dims(&self) -> (usize, usize, f64, f64) {
        match &self.held {
            Held::File(hf) => (hf.nx, hf.ny, hf.dx, hf.dy),
            Held::Array { array, dx, dy } => {
                let sh = Python::attach(|py| array.bind(py).shape().to_vec());
                (sh[1], sh[0], *dx, *dy)
            }
        }
    }

    /// The label of results and errors: the file's path, or `<array>`.
    fn label(&self) -> String {
        self.path.as_ref().map_or(ARRAY_LABEL.to_string(), |p| p.display().to_string())
    }
}

#[pymethods]
impl Scan {
    /// `Scan(heights, dx, dy=None)`: a scan from a 2D array of heights in metres, shape (ny, nx), row
    /// index along +y and column along +x; NaN (or an infinity) marks an invalid point. `dy` defaults to
    /// `dx`. A float64 C-ordered array without infinities is used in place, not copied: do not write to it
    /// while a fit of the scan runs. Any other array is converted once.
    #[new]
    #[pyo3(signature = (heights, dx, dy=None))]
    fn new(py: Python<'_>, heights: &Bound<'_, PyAny>, dx: f64, dy: Option<f64>) -> PyResult<Scan> {
        let arr = py
            .import("numpy")?
            .call_method1("ascontiguousarray", (heights, "float64"))
            .map_err(|e| invalid(format!("heights: not an array of numbers ({e})")))?;
        let ndim: usize = arr.getattr("ndim")?.extract()?;
        if ndim != 2 {
            return Err(invalid(format!("heights must be a 2D array (ny, nx), got {ndim} dimensions")));
        }
        let array = arr.cast_into::<PyArray2<f64>>().map_err(|e| invalid(format!("heights: {e}")))?;
        let dy = dy.unwrap_or(dx);
        let meta = ndfit::ScanMeta { format: "array".into(), ..Default::default() };
        let held = {
            let ro = array.try_readonly().map_err(|e| invalid(format!("heights: {e}")))?;
            let s = ndfit::Scan::from_view(ro.as_array(), dx, dy).map_err(to_py)?;
            // Infinities are masked to NaN in a copy (the caller's array is never written): keep that copy.
            if s.z.is_borrowed() {
                None
            } else {
                Some(s.into_owned())
            }
        };
        let held = match held {
            None => Held::Array { array: array.unbind(), dx, dy },
            Some(mut hf) => {
                hf.meta = meta.clone();
                Held::File(hf)
            }
        };
        Ok(Scan { held, meta, path: None })
    }

    /// The heights in metres, shape (ny, nx), float64, NaN where invalid: a read-only view of the scan's
    /// own buffer (for a float64 `.npy` file in metres, of the file's memory map; for a scan built from a
    /// float64 array, of that array), not a copy.
    #[getter]
    fn heights<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyAny>> {
        let py = slf.py();
        let arr = match &slf.get().held {
            Held::File(hf) => {
                // SAFETY: the scan is immutable (frozen) and owns `hf`, which lives as long as the scan
                // object, the array's base: the buffer outlives the array and never moves.
                unsafe { PyArray2::borrow_from_array(&hf.heights(), slf.clone().into_any()) }.into_any()
            }
            Held::Array { array, .. } => array.bind(py).call_method0("view")?,
        };
        let kw = PyDict::new(py);
        kw.set_item("write", false)?;
        arr.call_method("setflags", (), Some(&kw))?;
        Ok(arr)
    }

    /// Spacing along x in metres.
    #[getter]
    fn dx(&self) -> f64 {
        self.dims().2
    }

    /// Spacing along y in metres.
    #[getter]
    fn dy(&self) -> f64 {
        self.dims().3
    }

    /// Columns (samples along x).
    #[getter]
    fn nx(&self) -> usize {
        self.dims().0
    }

    /// Rows (samples along y).
    #[getter]
    fn ny(&self) -> usize {
        self.dims().1
    }

    /// `(ny, nx)`, the shape of `heights`.
    #[getter]
    fn shape(&self) -> (usize, usize) {
        let (nx, ny, _, _) = self.dims();
        (ny, nx)
    }

    /// The format id (`x3p`, `plu`, `npy`, ...; `array` for a scan built from an array).
    #[getter]
    fn format(&self) -> String {
        self.meta.format.clone()
    }

    /// The file the scan was read from (None for an array).
    #[getter]
    fn path(&self) -> Option<String> {
        self.path.as_ref().map(|p| p.display().to_string())
    }

    /// Number of invalid (NaN) points.
    #[getter]
    fn invalid(&self, py: Python<'_>) -> PyResult<usize> {
        self.with_scan(py, |s| Ok(s.invalid_count()))
    }

    /// What the reader learned besides the heights: `format`, `file_z_unit`, `file_xy_unit`,
    /// `instrument` (dict of text), and when known `height_quantum` (m) and `file_grid` ([nx, ny]).
    #[getter]
    fn meta<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &serde_json::to_string(&self.meta).map_err(|e| invalid(e.to_string()))?)
    }

    fn __repr__(&self) -> String {
        let (nx, ny, dx, dy) = self.dims();
        format!("Scan({}, {nx} x {ny}, dx={dx:e} m, dy={dy:e} m, format={})", self.label(), self.meta.format)
    }
}

/// Parse a JSON text into Python objects (dicts, lists, floats, None).
fn json_to_py<'py>(py: Python<'py>, text: &str) -> PyResult<Bound<'py, PyAny>> {
    py.import("json")?.call_method1("loads", (text,))
}

/// What to fit or bin: a file, or a scan already in memory.
enum Source<'py> {
    File(PathBuf),
    Scan(Bound<'py, Scan>),
}

impl<'py> Source<'py> {
    fn from_py(obj: &Bound<'py, PyAny>) -> PyResult<Source<'py>> {
        if let Ok(s) = obj.cast::<Scan>() {
            return Ok(Source::Scan(s.clone()));
        }
        obj.extract::<PathBuf>().map(Source::File).map_err(|_| {
            let ty = obj.get_type().name().map(|n| n.to_string()).unwrap_or_default();
            invalid(format!("expected an ndfit.Scan or a path, got {ty}"))
        })
    }

    /// The label of errors: the file's path, or the scan's own label (its file, or `<array>`).
    fn label(&self) -> String {
        match self {
            Source::File(p) => p.display().to_string(),
            Source::Scan(s) => s.get().label(),
        }
    }

    /// Run `f` on the pipeline's input: the file's path, or the scan (borrowed) and its label.
    fn run<R: Send>(
        &self,
        py: Python<'py>,
        threads: Option<usize>,
        on_file: impl FnOnce(&std::path::Path) -> ndfit::Result<R> + Send,
        on_scan: impl FnOnce(ndfit::Scan<'_>, &str) -> ndfit::Result<R> + Send,
    ) -> PyResult<R> {
        match self {
            Source::File(p) => work(py, threads, || on_file(p)),
            Source::Scan(s) => {
                let label = s.get().label();
                s.get().with_scan(py, |scan| work(py, threads, move || on_scan(scan, &label)))
            }
        }
    }
}

/// Options of reading and preprocessing, by their CLI names.
struct ScanOpts {
    read: ReadOptions,
    pre: Preprocess,
}

impl ScanOpts {
    #[allow(clippy::too_many_arguments)]
    fn new(
        src: &Source,
        dx: Option<f64>,
        dy: Option<f64>,
        z_scale: Option<f64>,
        format: Option<String>,
        form: &str,
        crop: Option<&str>,
        subsample: usize,
        despike: &str,
    ) -> PyResult<ScanOpts> {
        let read = ReadOptions { dx, dy, z_scale, format };
        if matches!(src, Source::Scan(..)) && (read.dx.is_some() || read.dy.is_some() || read.z_scale.is_some() || read.format.is_some()) {
            return Err(invalid("dx, dy, z_scale and format apply to reading a file; this scan is already read"));
        }
        let form = check::parse::<FormRemoval>("form", form, Spelling::Keyword).map_err(to_py)?;
        let despike = check::parse::<Despike>("despike", despike, Spelling::Keyword).map_err(to_py)?;
        let crop = crop.map(|c| check::parse::<Crop>("crop", c, Spelling::Keyword)).transpose().map_err(to_py)?;
        Ok(ScanOpts { read, pre: Preprocess { form, crop, subsample, despike } })
    }
}

/// The NDF options of `normals`, `ndf_cells`, `target_count`, range-checked as the CLI does.
fn ndf_options(normals: &str, ndf_cells: Option<usize>, target_count: f64) -> PyResult<NdfOptions> {
    let scheme: NormalScheme = check::parse("normals", normals, Spelling::Keyword).map_err(to_py)?;
    check::ndf_options(scheme, ndf_cells, Some(target_count), Spelling::Keyword).map_err(to_py)
}

fn parse_preset(s: Option<&str>) -> PyResult<Option<Preset>> {
    s.map(|s| check::parse::<Preset>("preset", s, Spelling::Keyword)).transpose().map_err(to_py)
}

/// `ndfit.read(path, dx=None, dy=None, z_scale=None, format=None) -> Scan`: read a scan file as stored
/// (no preprocessing). The format is detected from the content, then the extension; `dx`, `dy` (m),
/// `z_scale` (m per stored unit) and `format` are for formats that carry no spacing or unit. A float64
/// `.npy` in metres is memory-mapped: `Scan.heights` is then a view of the file.
#[pyfunction]
#[pyo3(signature = (path, *, dx=None, dy=None, z_scale=None, format=None))]
fn read(py: Python<'_>, path: PathBuf, dx: Option<f64>, dy: Option<f64>, z_scale: Option<f64>, format: Option<String>) -> PyResult<Scan> {
    let opts = ReadOptions { dx, dy, z_scale, format };
    let hf = work(py, None, || ndfit::read(&path, &opts))?;
    Ok(Scan { meta: hf.meta.clone(), held: Held::File(hf), path: Some(path) })
}

/// The empirical NDF of a scan (the bins of `ndfit ndf`, empty ones included).
#[pyclass(module = "ndfit", name = "Ndf", frozen)]
pub struct Ndf {
    ndf: EmpiricalNdf,
    path: String,
}

impl Ndf {
    fn column<'py>(&self, py: Python<'py>, f: impl Fn(&ndfit::ndf::NdfBin) -> f64) -> Bound<'py, numpy::PyArray1<f64>> {
        self.ndf.bins.iter().map(f).collect::<Vec<f64>>().into_pyarray(py)
    }
}

#[pymethods]
impl Ndf {
    /// Bin centre directions, unit vectors with `m.z > 0`, shape (n, 3).
    #[getter]
    fn m<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let flat: Vec<f64> = self.ndf.bins.iter().flat_map(|b| [b.m.x, b.m.y, b.m.z]).collect();
        flat.into_pyarray(py).reshape([self.ndf.bins.len(), 3])
    }
    /// D per bin (1/sr): the projected-area fraction in the bin over its projected solid angle.
    #[getter]
    fn d<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray1<f64>> {
        self.column(py, |b| b.d)
    }
    /// Standard error of `d` (Poisson on the count).
    #[getter]
    fn stderr<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray1<f64>> {
        self.column(py, |b| b.stderr)
    }
    /// Samples (normals) per bin, uint64.
    #[getter]
    fn count<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray1<u64>> {
        self.ndf.bins.iter().map(|b| b.count).collect::<Vec<u64>>().into_pyarray(py)
    }
    /// Solid angle of each bin (sr).
    #[getter]
    fn solid_angle<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray1<f64>> {
        self.column(py, |b| b.solid_angle)
    }
    /// Projected solid angle of each bin, the integral of `m.z` over it (sr).
    #[getter]
    fn proj_solid_angle<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray1<f64>> {
        self.column(py, |b| b.proj_solid_angle)
    }
    /// Normals binned.
    #[getter]
    fn n_samples(&self) -> u64 {
        self.ndf.n_samples
    }
    /// Stencils (or triangles) skipped because they touch an invalid point.
    #[getter]
    fn n_skipped(&self) -> u64 {
        self.ndf.n_skipped
    }
    /// `central` or `triangles`.
    #[getter]
    fn normals(&self) -> &'static str {
        self.ndf.scheme.as_str()
    }
    /// Cells across the Lambert disk of the binning grid.
    #[getter]
    fn cells_across(&self) -> usize {
        self.ndf.grid.n
    }
    /// Warnings for the user, one line each.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.ndf.warnings.clone()
    }
    fn __len__(&self) -> usize {
        self.ndf.bins.len()
    }
    fn __repr__(&self) -> String {
        format!("Ndf({}: {} bins, {} samples, {} normals)", self.path, self.ndf.bins.len(), self.ndf.n_samples, self.ndf.scheme.as_str())
    }
}

/// `ndfit.ndf(scan_or_path, form="plane", *, ...) -> Ndf`: the empirical NDF, as `ndfit ndf` computes it.
/// Options are those of `ndfit ndf` by name: reading (`dx`, `dy`, `z_scale`, `format`; files only),
/// preprocessing (`form`, `crop` as "NXxNY+X+Y", `subsample`, `despike` median|none) and binning (`normals` central|triangles,
/// `ndf_cells` odd 3-1023, `target_count` mean samples per bin, default 64); `threads` caps the work's threads (default: all cores).
#[pyfunction]
#[pyo3(signature = (source, form="plane", *, dx=None, dy=None, z_scale=None, format=None, crop=None, subsample=1,
    despike="median", normals="central", ndf_cells=None, target_count=64.0, threads=None))]
#[allow(clippy::too_many_arguments)]
fn ndf(
    py: Python<'_>,
    source: &Bound<'_, PyAny>,
    form: &str,
    dx: Option<f64>,
    dy: Option<f64>,
    z_scale: Option<f64>,
    format: Option<String>,
    crop: Option<&str>,
    subsample: usize,
    despike: &str,
    normals: &str,
    ndf_cells: Option<usize>,
    target_count: f64,
    threads: Option<usize>,
) -> PyResult<Ndf> {
    let src = Source::from_py(source)?;
    let so = ScanOpts::new(&src, dx, dy, z_scale, format, form, crop, subsample, despike)?;
    let ndf = ndf_options(normals, ndf_cells, target_count)?;
    let pipeline = Pipeline::new(Options { read: so.read, preprocess: so.pre, ndf, ..Options::default() });
    pipeline.options().validate().map_err(to_py)?;
    let label = match &src {
        Source::File(p) => p.display().to_string(),
        Source::Scan(s) => s.get().label(),
    };
    let ndf = src.run(
        py,
        threads,
        |p| pipeline.ndf_path(p).map(|(_, ndf)| ndf),
        |scan, label| pipeline.ndf(scan).map_err(|e| e.with_path(label)),
    )?;
    Ok(Ndf { ndf, path: label })
}

/// A fitted model: the `ndfit.fit/1` document of `ndfit fit`, and the model to evaluate.
#[pyclass(module = "ndfit", name = "Fit", frozen)]
pub struct Fit {
    report: FitReport,
    model: Model,
}

impl Fit {
    fn from_report(report: FitReport) -> PyResult<Fit> {
        let model = report.to_model().map_err(to_py)?;
        Ok(Fit { report, model })
    }
}

/// `(n, 3)` directions from an array-like of shape (n, 3) or (3,), and whether it was a single vector.
fn directions(py: Python<'_>, obj: &Bound<'_, PyAny>, name: &str) -> PyResult<(Vec<Vector3<f64>>, bool)> {
    let arr = py
        .import("numpy")?
        .call_method1("ascontiguousarray", (obj, "float64"))
        .map_err(|e| invalid(format!("{name}: not an array of numbers ({e})")))?;
    let shape: Vec<usize> = arr.getattr("shape")?.extract()?;
    let single = match shape.as_slice() {
        [3] => true,
        [_, 3] => false,
        _ => return Err(invalid(format!("{name} must have shape (n, 3) or (3,), got {shape:?}"))),
    };
    let arr = arr.call_method1("reshape", ((-1i64, 3i64),))?;
    let arr: PyReadonlyArray2<'_, f64> = arr.extract()?;
    let v = arr.as_array();
    Ok((v.rows().into_iter().map(|r| Vector3::new(r[0], r[1], r[2])).collect(), single))
}

#[pymethods]
impl Fit {
    /// The model id: ggx, beckmann, student, ggx-aniso, beckmann-aniso, student-aniso, ellipsoid, ggx2,
    /// beckmann2 or ellipsoid+ggx (for `auto`, the one chosen).
    #[getter]
    fn model(&self) -> &'static str {
        self.report.model.as_str()
    }
    /// Canonical parameters by name (radians for angles). For the anisotropic models the alpha_x axis
    /// lies at azimuth -theta_z, along (cos theta_z, -sin theta_z) in the scan frame (Walter et al.'s
    /// A = S Rz(theta_z)).
    #[getter]
    fn params(&self) -> std::collections::BTreeMap<String, f64> {
        self.report.params.clone()
    }
    /// Parameter names in the model's order.
    #[getter]
    fn param_names(&self) -> Vec<&'static str> {
        self.report.model.param_names().to_vec()
    }
    /// Standard errors by name; None for a parameter the data do not determine.
    #[getter]
    fn std_errors(&self) -> std::collections::BTreeMap<String, Option<f64>> {
        self.report.std_errors.clone()
    }
    /// The ellipsoid matrix A (3x3, scan frame) for the models that are ellipsoid special cases; None
    /// for Beckmann.
    #[getter]
    fn matrix_a<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyArray2<f64>>>> {
        self.report.matrix_a.map(|a| a.iter().flatten().copied().collect::<Vec<f64>>().into_pyarray(py).reshape([3, 3])).transpose()
    }
    /// Goodness of fit (the JSON's `quality`): objective, reduced_chi2, delta_data, dispersion, verdict
    /// (ok|misfit|unresolved) and its reasons, ...
    #[getter]
    fn quality<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &serde_json::to_string(&self.report.quality).map_err(|e| invalid(e.to_string()))?)
    }
    /// `ok`, `misfit` or `unresolved` (`quality["verdict"]`).
    #[getter]
    fn verdict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.quality(py)?.get_item("verdict")
    }
    /// Warnings for the user, one line each.
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.report.warnings.clone()
    }
    /// `auto`'s answer (`selection.answer`): a model id, `measured`, `mirror` or `mirror+ggx`; None for
    /// one model.
    #[getter]
    fn answer(&self) -> Option<String> {
        self.report.selection.as_ref().and_then(|s| s.answer.clone())
    }
    /// `auto`'s regime (`optics.regime`): `geometric`, `mixed` or `wave`; None for one model.
    #[getter]
    fn regime(&self) -> Option<String> {
        self.report.optics.as_ref().map(|o| o.regime.clone())
    }
    /// `auto`'s optics (the JSON's `optics`: regime, wavelength_nm, coherence_m, specular, haze, ...)
    /// as a dict; None for one model.
    #[getter]
    fn optics<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.report.optics.as_ref().map(|o| json_to_py(py, &serde_json::to_string(o).map_err(|e| invalid(e.to_string()))?)).transpose()
    }
    /// The whole `ndfit.fit/1` document as a dict.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.to_json()?)
    }
    /// The `ndfit.fit/1` JSON text, byte for byte what `ndfit fit` writes for the same scan and options
    /// (apart from the wall-clock `timings`).
    fn to_json(&self) -> PyResult<String> {
        let mut s = serde_json::to_string_pretty(&self.report).map_err(|e| invalid(format!("cannot serialize the fit ({e})")))?;
        s.push('\n');
        Ok(s)
    }
    /// A fit from an `ndfit.fit/1` JSON text (a file `ndfit fit` wrote, or `Fit.to_json()`).
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<Fit> {
        let report: FitReport = serde_json::from_str(text).map_err(|e| invalid(format!("not an ndfit.fit/1 document: {e}")))?;
        Fit::from_report(report)
    }
    /// D(m) (1/sr) of the fitted model for unit directions `m`, shape (n, 3) or (3,).
    fn d<'py>(&self, py: Python<'py>, m: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        let (ms, single) = directions(py, m, "m")?;
        let model = self.model;
        let out: Vec<f64> = py.detach(|| ms.iter().map(|m| model.d(*m)).collect());
        finish(py, out, single)
    }
    /// Smith masking G1(u, m) of the fitted model (Walter et al. eq. 6 for the ellipsoid) for view
    /// directions `u` and microfacet normals `m`, each shape (n, 3) or (3,) (a single vector is paired
    /// with every row of the other).
    fn g1<'py>(&self, py: Python<'py>, u: &Bound<'py, PyAny>, m: &Bound<'py, PyAny>) -> PyResult<Bound<'py, PyAny>> {
        let (us, su) = directions(py, u, "u")?;
        let (ms, sm) = directions(py, m, "m")?;
        if !su && !sm && us.len() != ms.len() {
            return Err(invalid(format!("u has {} rows but m has {}", us.len(), ms.len())));
        }
        let n = us.len().max(ms.len());
        let model = self.model;
        let out: Vec<f64> = py.detach(|| (0..n).map(|i| model.g1(us[if su { 0 } else { i }], ms[if sm { 0 } else { i }])).collect());
        finish(py, out, su && sm)
    }
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyTuple>)> {
        let ctor = slf.get_type().getattr("from_json")?;
        Ok((ctor, PyTuple::new(slf.py(), [slf.get().to_json()?])?))
    }
    fn __repr__(&self) -> String {
        let p: Vec<String> = self
            .report
            .model
            .param_names()
            .iter()
            .map(|n| format!("{n}={:.6}", self.report.params.get(*n).copied().unwrap_or(f64::NAN)))
            .collect();
        format!("Fit({} {}, verdict {})", self.report.model, p.join(" "), self.report.quality.verdict.as_str())
    }
}

/// A float for a single direction, else a 1D array.
fn finish<'py>(py: Python<'py>, out: Vec<f64>, single: bool) -> PyResult<Bound<'py, PyAny>> {
    if single {
        Ok(out[0].into_pyobject(py)?.into_any())
    } else {
        Ok(out.into_pyarray(py).into_any())
    }
}

/// `ndfit.fit(scan_or_path, model="auto", form="plane", preset=None, *, ...) -> Fit`: read (for a path),
/// preprocess, build the empirical NDF and fit, as `ndfit fit` does with the same options; the result's
/// `to_json()` is the document `ndfit fit` writes.
///
/// - `model`: ggx, beckmann, student, ggx-aniso, beckmann-aniso, student-aniso, ellipsoid, the mixtures
///   ggx2, beckmann2, ellipsoid+ggx, or auto (as `--model auto`: the ladder of these models, climbed while
///   no model fitted is within `tolerance` on the NDF error beyond counting noise; the simplest within it
///   is chosen, or when none is, the simplest whose error exceeds the smallest by no more than `tolerance`,
///   in quadrature; a model competes only if its quasi-likelihood BIC is below its parent's).
/// - reading (files only): `dx`, `dy` (m), `z_scale` (m per stored unit), `format`.
/// - preprocessing: `form` (none|plane|poly2|poly3|cylinder), `crop` ("NXxNY+X+Y"), `subsample`,
///   `despike` (median|none).
/// - the NDF: `normals` (central|triangles), `ndf_cells` (odd, 3-1023), `target_count` (default 64).
/// - the fit: `objective` (poisson|logd), `solver` (lm|nelder-mead|lbfgs), `extra_starts` (0-4),
///   `max_theta` (degrees, (0, 90], default 70) or `na` (numerical aperture: max_theta = asin(NA)),
///   `tail` (rim|core|unresolved|all, as `--tail`), `tolerance` (the NDF error beyond counting noise a
///   renderer cannot show, default 0.05, as `--tolerance`), `preset` (fast|balanced|accurate, as `--preset`).
/// - `auto`'s render choice (as `--scene`, `--render-tolerance`, `--material`): `scene` ("point,broad" by
///   default, stated scenes such as "point:light=30/0", or "none"), `render_tolerance` (mean FLIP, 0.02),
///   `material` (the conductor of the renders, "Al").
/// - `threads`: threads for this call (default: all cores, as the CLI).
#[pyfunction]
#[pyo3(signature = (source, model="auto", form="plane", preset=None, *, dx=None, dy=None, z_scale=None, format=None, crop=None,
    subsample=1, despike="median", normals="central", ndf_cells=None, target_count=64.0, objective="poisson", solver="lm",
    extra_starts=0, max_theta=None, na=None, tail="rim", tolerance=None, scene="point,broad", render_tolerance=0.02, material="Al",
    threads=None))]
#[allow(clippy::too_many_arguments)]
fn fit(
    py: Python<'_>,
    source: &Bound<'_, PyAny>,
    model: &str,
    form: &str,
    preset: Option<&str>,
    dx: Option<f64>,
    dy: Option<f64>,
    z_scale: Option<f64>,
    format: Option<String>,
    crop: Option<&str>,
    subsample: usize,
    despike: &str,
    normals: &str,
    ndf_cells: Option<usize>,
    target_count: f64,
    objective: &str,
    solver: &str,
    extra_starts: usize,
    max_theta: Option<f64>,
    na: Option<f64>,
    tail: &str,
    tolerance: Option<f64>,
    scene: &str,
    render_tolerance: f64,
    material: &str,
    threads: Option<usize>,
) -> PyResult<Fit> {
    let src = Source::from_py(source)?;
    let so = ScanOpts::new(&src, dx, dy, z_scale, format, form, crop, subsample, despike)?;
    let ndf = ndf_options(normals, ndf_cells, target_count)?;
    let max_theta = check::aperture_deg(max_theta, na, Spelling::Keyword).map_err(to_py)?;
    let extra_starts = check::extra_starts(extra_starts, Spelling::Keyword).map_err(to_py)?;
    let tail = check::parse::<ndfit::fit::TailRule>("tail", tail, Spelling::Keyword).map_err(to_py)?;
    let tolerance = check::tolerance(tolerance, Spelling::Keyword).map_err(to_py)?;
    let fit = FitOptions {
        tail,
        tolerance,
        objective: objective.parse::<Objective>().map_err(|e| invalid(format!("objective: {}", e.message())))?,
        solver: solver.parse::<Solver>().map_err(|e| invalid(format!("solver: {}", e.message())))?,
        extra_starts,
        max_theta: max_theta.to_radians(),
        ..FitOptions::default()
    };
    let model = model.parse::<ModelChoice>().map_err(|e| invalid(format!("model: {}", e.message())))?;
    let preset = parse_preset(preset)?;
    let render = check::render(scene, render_tolerance, material, Spelling::Keyword).map_err(to_py)?;
    let pipeline = Pipeline::new(Options { read: so.read, preprocess: so.pre, preset, ndf, model, fit, render });
    pipeline.options().validate().map_err(to_py)?;
    let outcome = src.run(py, threads, |p| pipeline.run_path(p), |scan, label| pipeline.run(scan, label))?;
    Fit::from_report(outcome.fit)
}

/// A trace of a scan's microgeometry: the `ndfit.trace/1` document of `ndfit trace`, and the binned
/// outgoing energies it does not serialize.
#[pyclass(module = "ndfit", name = "Trace", frozen)]
pub struct Trace {
    report: ndfit::trace::TraceReport,
}

#[pymethods]
impl Trace {
    /// One dict per incidence, in the order given (`theta_deg`, `albedo`, `albedo_by_bounce`, `g1`, ...).
    #[getter]
    fn incidences<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.to_dict(py)?.get_item("incidences")
    }
    /// The verdict on the microfacet model (`verdict`, `line`, `worst_*`).
    #[getter]
    fn verdict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.to_dict(py)?.get_item("verdict")
    }
    /// The outgoing bins `(n_theta, n_phi)`: uniform in `sqrt(2 theta / pi)` and in `phi` over `[-pi, pi)`.
    #[getter]
    fn bins(&self) -> (usize, usize) {
        (self.report.table.n_theta, self.report.table.n_phi)
    }
    /// Projected solid angle of each outgoing bin, shape `(n_theta, n_phi)`: the BRDF averaged over a bin
    /// is its energy over this.
    fn proj_solid_angle<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let t = self.report.table;
        (0..t.len()).map(|k| t.proj_solid_angle(k)).collect::<Vec<f64>>().into_pyarray(py).reshape([t.n_theta, t.n_phi])
    }
    /// The energies of incidence `k` per outgoing bin and channel (per unit incident energy), shape
    /// `(n_theta, n_phi, 3)`: `single` (first bounce), `multi` (later bounces), `model` (the microfacet
    /// model's single scattering); and `var_total`, `(n_theta, n_phi)`, the Monte Carlo variance of the
    /// luminance of `single + multi`.
    fn tables<'py>(&self, py: Python<'py>, k: usize) -> PyResult<Bound<'py, PyDict>> {
        let n = self.report.tables.len();
        let tab = self.report.tables.get(k).ok_or_else(|| invalid(format!("incidence {k} is out of range (the trace has {n})")))?;
        let t = self.report.table;
        let rgb = |v: &[[f64; 3]]| v.iter().flatten().copied().collect::<Vec<f64>>().into_pyarray(py).reshape([t.n_theta, t.n_phi, 3]);
        let d = PyDict::new(py);
        d.set_item("single", rgb(&tab.single)?)?;
        d.set_item("multi", rgb(&tab.multi)?)?;
        d.set_item("model", rgb(&tab.model)?)?;
        d.set_item("var_total", tab.var_total.clone().into_pyarray(py).reshape([t.n_theta, t.n_phi])?)?;
        Ok(d)
    }
    /// The whole `ndfit.trace/1` document as a dict.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.to_json()?)
    }
    /// The `ndfit.trace/1` JSON text, byte for byte what `ndfit trace -o` writes for the same scan and
    /// options.
    fn to_json(&self) -> PyResult<String> {
        let mut s = serde_json::to_string_pretty(&self.report).map_err(|e| invalid(format!("cannot serialize the trace ({e})")))?;
        s.push('\n');
        Ok(s)
    }
    fn __len__(&self) -> usize {
        self.report.incidences.len()
    }
    fn __repr__(&self) -> String {
        format!(
            "<ndfit.Trace {} incidences, {}x{} grid: {}>",
            self.report.incidences.len(),
            self.report.surface.nx,
            self.report.surface.ny,
            self.report.verdict.verdict
        )
    }
}

/// `ndfit.trace(scan_or_path, incidence=[0, 40, 70], azimuth=0.0, material="none", bounces=16, seed=1, *,
/// ...) -> Trace`: trace the scan's microgeometry with geometric optics and measure the microfacet model
/// against it, as `ndfit trace` does with the same options (`Trace.to_json()` is the document it writes).
///
/// - `incidence`: elevations in degrees (a number or a sequence, each in [0, 89.9]); `azimuth` (degrees,
///   0 = the scan's +x); `material` (none|Al|Ag|Au|Cu|Cr); `bounces`; `seed` (the same seed gives the same
///   trace on any number of threads); `rays` (paths per incidence, default 2^20); `border`
///   (periodic|open); `bins` ("THETAxPHI", default "32x64"); `tolerance` (default 0.05).
/// - reading (files only): `dx`, `dy` (m), `z_scale` (m per stored unit), `format`.
/// - preprocessing: `form` (none|plane|poly2|poly3|cylinder, default plane), `crop`, `subsample`,
///   `despike` (median|none).
/// - `threads`: threads for this call (default: all cores, as the CLI).
#[pyfunction]
#[pyo3(signature = (source, incidence=None, azimuth=0.0, material="none", bounces=16, seed=1, *, rays=1<<20,
    border="periodic", bins="32x64", tolerance=0.05, form="plane", dx=None, dy=None, z_scale=None, format=None, crop=None,
    subsample=1, despike="median", threads=None))]
#[allow(clippy::too_many_arguments)]
fn trace(
    py: Python<'_>,
    source: &Bound<'_, PyAny>,
    incidence: Option<&Bound<'_, PyAny>>,
    azimuth: f64,
    material: &str,
    bounces: usize,
    seed: u64,
    rays: usize,
    border: &str,
    bins: &str,
    tolerance: f64,
    form: &str,
    dx: Option<f64>,
    dy: Option<f64>,
    z_scale: Option<f64>,
    format: Option<String>,
    crop: Option<&str>,
    subsample: usize,
    despike: &str,
    threads: Option<usize>,
) -> PyResult<Trace> {
    let src = Source::from_py(source)?;
    let so = ScanOpts::new(&src, dx, dy, z_scale, format, form, crop, subsample, despike)?;
    let incidences_deg = match incidence {
        None => ndfit::trace::TraceOptions::default().incidences_deg,
        Some(v) => match v.extract::<f64>() {
            Ok(x) => vec![x],
            Err(_) => v.extract::<Vec<f64>>().map_err(|_| invalid("incidence must be a number or a sequence of numbers (degrees)"))?,
        },
    };
    let opts = ndfit::trace::TraceOptions {
        incidences_deg,
        azimuth_deg: azimuth,
        material: material.parse().map_err(to_py)?,
        bounces,
        seed,
        rays,
        border: border.parse().map_err(to_py)?,
        table: bins.parse().map_err(to_py)?,
        tolerance,
        spread_over_bin: false,
    };
    opts.validate().map_err(to_py)?;
    let report = src.run(
        py,
        threads,
        |p| {
            let scan = ndfit::pipeline::read_preprocessed(p, &so.read, &so.pre)?;
            ndfit::trace::trace(&scan, &opts, None).map_err(|e| e.with_path(p))
        },
        |scan, label| {
            let scan = ndfit::preprocess::apply(scan, &so.pre).map_err(|e| e.with_path(label))?;
            ndfit::trace::trace(&scan, &opts, None).map_err(|e| e.with_path(label))
        },
    )?;
    Ok(Trace { report })
}

/// A number or a sequence of numbers as a list (`None`: `default`).
fn numbers(v: Option<&Bound<'_, PyAny>>, default: &[f64], what: &str) -> PyResult<Vec<f64>> {
    match v {
        None => Ok(default.to_vec()),
        Some(v) => match v.extract::<f64>() {
            Ok(x) => Ok(vec![x]),
            Err(_) => v.extract::<Vec<f64>>().map_err(|_| invalid(format!("{what} must be a number or a sequence of numbers"))),
        },
    }
}

/// The scalar-diffraction BRDF of a scan: the `ndfit.wave/1` document of `ndfit wave`, and with `grid=N`
/// the diffuse BRDF on the N x N grid of the projected outgoing disk that `--grid-out` writes.
#[pyclass(module = "ndfit", name = "Wave", frozen)]
pub struct Wave {
    report: ndfit::wave::WaveReport,
    /// float64 (wavelengths, incidences, N, N), read-only; `None` without `grid`.
    grid: Option<Py<PyAny>>,
}

#[pymethods]
impl Wave {
    /// One dict per wavelength and incidence, wavelengths outer (`wavelength_nm`, `theta_deg`, `phi_deg`,
    /// `specular`, `diffuse_albedo`, `albedo`, `evanescent`, `band_limit`, `beyond_band`,
    /// `angular_step_deg`).
    #[getter]
    fn records<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.to_dict(py)?.get_item("records")
    }
    /// The coherence patches (`coherence_m`, `coherence_source`, `samples`, `used`, `skipped`,
    /// `tilt_rms_deg`).
    #[getter]
    fn patches<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        self.to_dict(py)?.get_item("patches")
    }
    /// What the scan cannot tell, one line each (few patches, light beyond the band).
    #[getter]
    fn warnings(&self) -> Vec<String> {
        self.report.warnings.clone()
    }
    /// The diffuse BRDF (1/sr, Fresnel excluded) averaged over each cell of the N x N grid on the projected
    /// outgoing disk, float64 of shape (wavelengths, incidences, N, N), read-only: what `ndfit wave --grid N
    /// --grid-out PREFIX` writes to `PREFIX.npy`. Row `i` is `y = -1 + (2i+1)/N`, column `j` is `x = -1 +
    /// (2j+1)/N`; 0 outside the unit disk. `None` unless `ndfit.wave` was given `grid`.
    #[getter]
    fn grid<'py>(&self, py: Python<'py>) -> Option<Bound<'py, PyAny>> {
        self.grid.as_ref().map(|g| g.bind(py).clone())
    }
    /// The whole `ndfit.wave/1` document as a dict.
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        json_to_py(py, &self.to_json()?)
    }
    /// The `ndfit.wave/1` JSON text, byte for byte what `ndfit wave -o` writes for the same scan and
    /// options.
    fn to_json(&self) -> PyResult<String> {
        let mut s = serde_json::to_string_pretty(&self.report).map_err(|e| invalid(format!("cannot serialize the wave report ({e})")))?;
        s.push('\n');
        Ok(s)
    }
    fn __len__(&self) -> usize {
        self.report.records.len()
    }
    fn __repr__(&self) -> String {
        let p = &self.report.patches;
        format!(
            "<ndfit.Wave {} records, {}x{} grid, {} patches of {:.1} um>",
            self.report.records.len(),
            self.report.grid[0],
            self.report.grid[1],
            p.used,
            p.coherence_m * 1e6
        )
    }
}

/// The report of `scan` under `opts`, and with `grid = Some(n)` the grids of every wavelength and
/// incidence (wavelengths outer), flattened as [`ndfit::wave::write_grid_npy`] writes them.
fn wave_of(scan: &ndfit::Scan<'_>, opts: &WaveOptions, grid: Option<usize>) -> ndfit::Result<(ndfit::wave::WaveReport, Option<Vec<f64>>)> {
    let (report, d) = ndfit::wave::wave(scan, opts, None)?;
    let grid = grid.map(|n| ndfit::wave::grids(&d, &opts.wavelengths_nm, &opts.incidences_deg, opts.azimuth_deg, n)).transpose()?;
    Ok((report, grid))
}

/// `ndfit.wave(scan_or_path, wavelength_nm=None, incidence_deg=None, azimuth_deg=0.0, coherence_um=None,
/// material="none", grid=None, level_ratio=1.1, *, ...) -> Wave`: the scan's scalar-diffraction BRDF
/// (docs/WAVE.md), as `ndfit wave` computes it with the same options (`Wave.to_json()` is the document it
/// writes; `Wave.grid` the array `--grid N --grid-out` writes).
///
/// - `wavelength_nm`: wavelengths in nm (a number or a sequence; default [450, 550, 650]);
///   `incidence_deg`: elevations in degrees (each in [0, 89.9]; default [0, 30, 45, 60, 75]); `azimuth_deg`
///   (0 = the scan's +x); `coherence_um`: side of the coherence patch in micrometres (default: sunlight's
///   coherence area at 550 nm, 18.9 um); `material` (none|Al|Ag|Au|Cu|Cr: the Fresnel factor of `albedo`);
///   `grid`: cells per side of the diffuse BRDF grid (1-4096; `None`: no grid); `level_ratio`: largest ratio
///   between neighbouring v_z levels, in (1, 2].
/// - reading (files only): `dx`, `dy` (m), `z_scale` (m per stored unit), `format`.
/// - preprocessing: `form` (none|plane|poly2|poly3|cylinder, default plane), `crop`, `subsample`,
///   `despike` (median|none).
/// - `threads`: threads for this call (default: all cores, as the CLI).
// The signature spells `level_ratio`'s default as a literal so that `help()` shows it: keep it the CLI's.
const _: () = assert!(ndfit::wave::DEFAULT_LEVEL_RATIO == 1.1);

#[pyfunction]
#[pyo3(signature = (source, wavelength_nm=None, incidence_deg=None, azimuth_deg=0.0, coherence_um=None, material="none", grid=None,
    level_ratio=1.1, *, form="plane", dx=None, dy=None, z_scale=None, format=None, crop=None, subsample=1,
    despike="median", threads=None))]
#[allow(clippy::too_many_arguments)]
fn wave(
    py: Python<'_>,
    source: &Bound<'_, PyAny>,
    wavelength_nm: Option<&Bound<'_, PyAny>>,
    incidence_deg: Option<&Bound<'_, PyAny>>,
    azimuth_deg: f64,
    coherence_um: Option<f64>,
    material: &str,
    grid: Option<i64>,
    level_ratio: f64,
    form: &str,
    dx: Option<f64>,
    dy: Option<f64>,
    z_scale: Option<f64>,
    format: Option<String>,
    crop: Option<&str>,
    subsample: usize,
    despike: &str,
    threads: Option<usize>,
) -> PyResult<Wave> {
    let src = Source::from_py(source)?;
    let so = ScanOpts::new(&src, dx, dy, z_scale, format, form, crop, subsample, despike)?;
    let label = src.label();
    let opts = WaveOptions {
        wavelengths_nm: numbers(wavelength_nm, &ndfit::wave::DEFAULT_WAVELENGTHS_NM, "wavelength_nm")?,
        incidences_deg: numbers(incidence_deg, &ndfit::wave::DEFAULT_INCIDENCES_DEG, "incidence_deg")?,
        azimuth_deg,
        // As `--coherence UM`, to the same bits.
        coherence_m: coherence_um.map(|um| um * 1e-6),
        material: material.parse().map_err(to_py)?,
        level_ratio,
    };
    // Every option is checked before the scan is read, as `ndfit wave` does.
    opts.validate().map_err(|e| to_py(e.with_path(&label)))?;
    let grid = match grid {
        None => None,
        Some(n) if (1..=4096).contains(&n) => Some(n as usize),
        Some(n) => return Err(invalid(format!("{label}: grid {n} is outside 1..=4096"))),
    };
    let (report, cells) = src.run(
        py,
        threads,
        |p| {
            let scan = ndfit::pipeline::read_preprocessed(p, &so.read, &so.pre)?;
            wave_of(&scan, &opts, grid).map_err(|e| e.with_path(p))
        },
        |scan, label| {
            let scan = ndfit::preprocess::apply(scan, &so.pre).map_err(|e| e.with_path(label))?;
            wave_of(&scan, &opts, grid).map_err(|e| e.with_path(label))
        },
    )?;
    let grid = match (cells, grid) {
        (Some(cells), Some(n)) => {
            let arr = cells.into_pyarray(py).reshape([opts.wavelengths_nm.len(), opts.incidences_deg.len(), n, n])?.into_any();
            let kw = PyDict::new(py);
            kw.set_item("write", false)?;
            arr.call_method("setflags", (), Some(&kw))?;
            Some(arr.unbind())
        }
        _ => None,
    };
    Ok(Wave { report, grid })
}

/// The compiled part of `ndfit`; import `ndfit`, not this.
#[pymodule]
fn _ndfit(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("NdfitError", m.py().get_type::<NdfitError>())?;
    m.add_class::<Scan>()?;
    m.add_class::<Ndf>()?;
    m.add_class::<Fit>()?;
    m.add_class::<Trace>()?;
    m.add_class::<Wave>()?;
    m.add_function(wrap_pyfunction!(read, m)?)?;
    m.add_function(wrap_pyfunction!(ndf, m)?)?;
    m.add_function(wrap_pyfunction!(fit, m)?)?;
    m.add_function(wrap_pyfunction!(trace, m)?)?;
    m.add_function(wrap_pyfunction!(wave, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
