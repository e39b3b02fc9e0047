//! The per-scan fit flags `ndfit fit` and `ndfit batch -- ...` share: reading and preprocessing
//! ([`ScanArgs`]), the NDF ([`NdfArgs`]), the fit and the preset. One struct, so the two commands cannot
//! drift; it resolves into the library's [`ndfit::Options`].

use ndfit::fit::{FitOptions, Objective, Solver};
use ndfit::pipeline::check::{self, Spelling};
use ndfit::{ModelChoice, Options, Preset};

use super::ndf::NdfArgs;
use super::scan_args::{ReadArgs, ScanArgs};

/// How one scan is read, preprocessed, binned and fitted (everything but the model and the outputs).
#[derive(Debug, Clone, clap::Args)]
pub struct FitArgs {
    #[command(flatten)]
    pub scan: ScanArgs,
    #[command(flatten)]
    pub how: FitHow,
    #[command(flatten, next_help_heading = "The render choice of --model auto")]
    pub render: RenderArgs,
}

/// How `auto`'s answer is decided by rendering (data_formats/render.md, "The choice").
#[derive(Debug, Clone, clap::Args)]
pub struct RenderArgs {
    /// The scenes a lobe must pass, comma-separated: point (the sphere under a point light), broad (under
    /// a 25-degree cap light), each optionally changed by :light=THETA/PHI, :view=THETA/PHI (degrees, the
    /// sphere's frame, z its pole), :cap=DEG or :size=N (e.g. `point:light=30/0,broad:cap=40`); window (a
    /// plate 65 degrees off its normal under a sharp-edged light, only the plate scored; :size=N its
    /// width), where a mirror differs from a blur; `none` leaves the choice to the NDF error alone (no
    /// selection.answer).
    #[arg(long, default_value = "point,broad")]
    pub scene: String,
    /// The largest mean FLIP beyond the scan table's own noise floor, in every scene, at which a lobe is
    /// the answer (data_formats/render.md, "The tolerance").
    #[arg(long = "render-tolerance", default_value_t = ndfit::answer::choice::DEFAULT_RENDER_TOLERANCE)]
    pub render_tolerance: f64,
    /// The conductor of the renders: none (F = 1), Al, Ag, Au, Cu or Cr.
    #[arg(long, default_value = "Al")]
    pub material: String,
}

impl RenderArgs {
    /// The render choice these flags ask for (`None` for `--scene none`), refused naming the flag.
    pub fn options(&self) -> ndfit::Result<Option<ndfit::answer::choice::RenderOptions>> {
        check::render(&self.scene, self.render_tolerance, &self.material, Spelling::Flag)
    }
}

/// How a scan's NDF is binned and fitted (the flags after reading and preprocessing).
#[derive(Debug, Clone, clap::Args)]
pub struct FitHow {
    #[command(flatten)]
    pub ndf: NdfArgs,
    /// Residuals: `poisson` (deviance of the bin counts) or `logd` (count-weighted log D); see
    /// data_formats/objective.md.
    #[arg(long, default_value = "poisson")]
    pub objective: String,
    /// Local optimizer: `lm` (Levenberg-Marquardt), `nelder-mead` or `lbfgs` (argmin).
    #[arg(long, default_value = "lm")]
    pub solver: String,
    /// Extra skew starts for the ellipsoid (0-4) beyond the default two.
    #[arg(long, default_value_t = 0, allow_hyphen_values = true)]
    pub extra_starts: usize,
    /// Largest polar angle (degrees, 0-90] of the NDF bins the fit uses; the model is normalized over
    /// them (data_formats/objective.md). Lower it to the instrument's numerical aperture
    /// (asin(NA)) when the scan cannot see steeper slopes. Default 70.
    #[arg(long, allow_hyphen_values = true)]
    pub max_theta: Option<f64>,
    /// The objective's numerical aperture NA (0-1]: sets --max-theta to asin(NA); both given must agree.
    #[arg(long, allow_hyphen_values = true)]
    pub na: Option<f64>,
    /// The tail: `rim` (default) cuts as `core` when the unresolved normals are a lone lobe's rim and
    /// as `unresolved` when another lobe's resolved normals fill those bins; `core` keeps the whitened
    /// core when the sampling leaves an unresolved tail; `unresolved` leaves out only the bins where most
    /// normals are not resolved by the sampling; `all` keeps every bin within --max-theta
    /// (data_formats/objective.md).
    #[arg(long, default_value = "rim")]
    pub tail: String,
    /// The NDF error beyond counting noise a renderer cannot show (default 0.05: a highlight's radiance is
    /// linear in D, and 5% is about one just-noticeable colour difference at a highlight's lightness;
    /// data_formats/objective.md, "The tolerance"). `auto` climbs to a richer model only while no model
    /// fitted is within it and takes the simplest within it; when none is, a richer one wins only by
    /// lowering the error by more than it (in quadrature). A fit is `misfit` only beyond it.
    #[arg(long, allow_hyphen_values = true)]
    pub tolerance: Option<f64>,
    /// Speed/accuracy preset measured in docs/PERFORMANCE.md (`balanced` = the defaults). Sets the
    /// subsampling stride (on top of --subsample; the kept points are all that is read, and the form is
    /// removed from them), the NDF's normals and bins (unless --ndf-cells), the tolerance and the starts.
    #[arg(long, value_enum)]
    pub preset: Option<Preset>,
}

impl FitArgs {
    /// The pipeline options these flags ask for, fitting `model`; out-of-range values are refused here,
    /// naming the flag, and the result passes [`Options::validate`].
    pub fn options(&self, model: ModelChoice) -> ndfit::Result<Options> {
        let render = self.render.options().map_err(|e| e.with_path(&self.scan.scan))?;
        Ok(Options { render, ..self.how.options(&self.scan.how, model, &self.scan.scan)? })
    }
}

impl FitHow {
    /// The pipeline options these flags and the reading flags `read` ask for, fitting `model`, for the
    /// scan `path` (named in the errors the flags' own checks leave).
    pub fn options(&self, read: &ReadArgs, model: ModelChoice, path: &std::path::Path) -> ndfit::Result<Options> {
        let bad = |flag: &str, e: ndfit::Error| ndfit::Error::invalid(format!("{flag}: {}", e.message()));
        let objective = self.objective.parse::<Objective>().map_err(|e| bad("--objective", e))?;
        let solver = self.solver.parse::<Solver>().map_err(|e| bad("--solver", e))?;
        let extra_starts = check::extra_starts(self.extra_starts, Spelling::Flag)?;
        let max_theta = check::aperture_deg(self.max_theta, self.na, Spelling::Flag)?;
        let tail = self.tail.parse::<ndfit::fit::TailRule>().map_err(|e| bad("--tail", e))?;
        let ndf = self.ndf.options().map_err(|e| ndfit::Error::invalid(e.to_string()))?;
        let tolerance = check::tolerance(self.tolerance, Spelling::Flag)?;
        let fit =
            FitOptions { objective, solver, extra_starts, max_theta: max_theta.to_radians(), tail, tolerance, ..FitOptions::default() };
        let options = Options {
            read: read.read_options(),
            preprocess: read.preprocess(),
            preset: self.preset,
            ndf,
            model,
            fit,
            ..Options::default()
        };
        // What the flags' own checks leave (a --subsample of 0) is refused naming the scan.
        options.validate().map_err(|e| e.with_path(path))?;
        Ok(options)
    }
}

/// `--model`: an id or `auto`, with the flag named in the error.
pub fn parse_model(s: &str) -> ndfit::Result<ModelChoice> {
    s.parse::<ModelChoice>().map_err(|e| ndfit::Error::invalid(format!("--model: {}", e.message())))
}
