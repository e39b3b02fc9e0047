//! The one pipeline from a scan to a fit: read -> preprocess -> empirical NDF -> fit. Every command
//! (`fit`, `ndf`, `demo`, `batch`), the benchmarks and the Python binding run it through [`Pipeline`]
//! or, to time the stages apart, through the stage functions below, which [`Pipeline`] itself calls.
//!
//! ```text
//!  path ──read_preprocessed──► Scan ──ndf──► EmpiricalNdf ──fit──► FitReport
//!  Scan (in memory) ─preprocess─┘            (Options::ndf_options)   (Options::fit_options, ModelChoice)
//! ```

pub mod check;
pub(crate) mod preset;
mod profile;
pub mod scale;

use std::path::Path;
use std::time::Instant;

use crate::answer::choice::{RenderJudge, RenderOptions};
use crate::error::Result;
use crate::fit::Optics;
use crate::fit::{FitOptions, FitReport};
use crate::io::ReadOptions;
use crate::models::ModelChoice;
use crate::ndf::{EmpiricalNdf, NdfOptions};
use crate::preprocess::{Prepared, Preprocess};
use crate::scan::{Heightfield, InputInfo, Scan};
pub use check::Spelling;
pub use preset::Preset;
pub use preset::PresetKnobs;
pub use profile::Profile;

/// Everything the pipeline needs besides the scan. `Default` is what `ndfit fit` does without flags:
/// the mean plane removed, the automatic NDF grid, `auto` model choice, Poisson objective with LM.
#[derive(Debug, Clone, PartialEq)]
pub struct Options {
    /// How to read the file (spacing and height unit for formats without them, forced format).
    pub read: ReadOptions,
    /// Crop, subsampling and form removal before normals are taken.
    pub preprocess: Preprocess,
    /// A speed/accuracy preset: its stride multiplies `preprocess.subsample`, and it sets the NDF's
    /// normals and bins (an explicit `ndf.cells_across` still wins), the tolerance and the starts.
    pub preset: Option<Preset>,
    /// How the empirical NDF is built.
    pub ndf: NdfOptions,
    /// One model, or `auto` (the model table's ladder, chosen by the NDF error within the tolerance,
    /// [`crate::fit::fit_auto`]).
    pub model: ModelChoice,
    /// How to fit (objective, solver, tolerances, fitted region `max_theta`).
    pub fit: FitOptions,
    /// `auto`'s render choice (`answer::choice`): the answer is the simplest lobe whose render is within
    /// the tolerance of the scan's table in every scene. `None`: the NDF error alone decides, and the
    /// report has no `selection.answer`.
    pub render: Option<RenderOptions>,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            read: ReadOptions::default(),
            preprocess: Preprocess::default(),
            preset: None,
            ndf: NdfOptions::default(),
            model: ModelChoice::Auto,
            fit: FitOptions::default(),
            render: Some(RenderOptions::default()),
        }
    }
}

impl Options {
    /// Refuse out-of-range options ([`crate::ErrorKind::InvalidInput`], the message naming the field):
    /// [`Preprocess::validate`], [`NdfOptions::validate`], [`FitOptions::validate`]. Every [`Pipeline`]
    /// run calls it first; the CLI and the Python binding call it when they build the options.
    pub fn validate(&self) -> Result<()> {
        self.preprocess.validate()?;
        self.ndf.validate()?;
        self.render.as_ref().map_or(Ok(()), |r| r.validate())?;
        self.fit.validate()
    }

    /// The preprocessing with the preset's stride folded into the subsampling (a `subsample` of 0 stays
    /// 0, for [`crate::preprocess::apply`] to refuse).
    pub fn preprocess(&self) -> Preprocess {
        let stride = self.preset.map_or(1, |p| p.stride());
        Preprocess { subsample: self.preprocess.subsample.saturating_mul(stride), ..self.preprocess.clone() }
    }

    /// The NDF options for `scan` (preprocessed): [`Options::ndf`], or the preset's, whose capped grid
    /// may need the scan's valid count; an explicit `cells_across` wins over the preset's. Unless
    /// `ndf.resolution` says otherwise, the unresolved normals are counted only when the fit's tail rule
    /// reads them (not for `--tail all`).
    pub fn ndf_options(&self, scan: &Scan) -> NdfOptions {
        self.ndf_options_with(|| scan.valid_count() as u64)
    }

    /// [`Options::ndf_options`] for a scan of `valid()` valid points (called only when the preset needs it).
    fn ndf_options_with(&self, valid: impl FnOnce() -> u64) -> NdfOptions {
        let resolution = Some(self.ndf.resolution.unwrap_or(self.fit.tail != crate::fit::tail::TailRule::All));
        match self.preset {
            None => NdfOptions { resolution, ..self.ndf.clone() },
            Some(p) => {
                let po = p.ndf_options(if p.needs_sample_count() { valid() } else { 0 });
                NdfOptions { cells_across: self.ndf.cells_across.or(po.cells_across), resolution, ..po }
            }
        }
    }

    /// The fit options: [`Options::fit`] with the preset's tolerances and at least its extra starts.
    pub fn fit_options(&self) -> FitOptions {
        let mut f = self.fit;
        if let Some(p) = self.preset {
            let pf = p.fit_options();
            f.tolerances = pf.tolerances;
            f.extra_starts = f.extra_starts.max(pf.extra_starts);
        }
        f
    }
}

/// What [`Pipeline::run`] produces: the empirical NDF and the fit report, whose `input` and timings the
/// pipeline has filled in.
#[derive(Debug, Clone)]
pub struct Outcome {
    /// The scan's empirical NDF.
    pub ndf: EmpiricalNdf,
    /// The fit (`ndfit.fit/1` when serialized).
    pub fit: FitReport,
}

/// The pipeline with its options; see the [module documentation](self).
#[derive(Debug, Clone, Default)]
pub struct Pipeline {
    options: Options,
}

impl Pipeline {
    /// A pipeline that runs with `options`.
    pub fn new(options: Options) -> Pipeline {
        Pipeline { options }
    }

    /// The options it runs with.
    pub fn options(&self) -> &Options {
        &self.options
    }

    /// Read `path` (subsampling while reading where possible), preprocess, build the NDF and fit. Every
    /// error names `path`.
    pub fn run_path(&self, path: &Path) -> Result<Outcome> {
        self.options.validate()?;
        let t0 = Instant::now();
        let scan = read_prepared(path, &self.options.read, &self.options.preprocess())?;
        let ndf_opts = self.ndf_options_of(&scan);
        let read_ms = ms(t0);
        let built = self.ndf_timed(&scan, ndf_opts, path)?;
        let optics = self.optics_of(&scan);
        release(scan);
        self.finish(built, path, read_ms, optics)
    }

    /// [`Pipeline::run_path`] for a scan in memory (preprocessing included); `label` stands for the path
    /// in the report's `input` and in error messages.
    pub fn run(&self, scan: Scan<'_>, label: &str) -> Result<Outcome> {
        self.options.validate()?;
        let path = Path::new(label);
        let t0 = Instant::now();
        let scan = crate::preprocess::prepare(scan, &self.options.preprocess()).map_err(|e| e.with_path(path))?;
        let ndf_opts = self.ndf_options_of(&scan);
        let read_ms = ms(t0);
        let built = self.ndf_timed(&scan, ndf_opts, path)?;
        let optics = self.optics_of(&scan);
        drop(scan);
        self.finish(built, path, read_ms, optics)
    }

    /// Read `path`, preprocess and build the NDF only (`ndfit ndf`); the scan is described by the
    /// returned [`InputInfo`]. Errors name `path`.
    pub fn ndf_path(&self, path: &Path) -> Result<(InputInfo, EmpiricalNdf)> {
        self.options.validate()?;
        let scan = read_prepared(path, &self.options.read, &self.options.preprocess())?;
        let ndf = ndf_or_profile(&scan, &self.ndf_options_of(&scan)).map_err(|e| e.with_path(path))?.0;
        let input = scan.input_info(path);
        release(scan);
        Ok((input, ndf))
    }

    /// Preprocess a scan in memory and build its NDF only.
    pub fn ndf(&self, scan: Scan<'_>) -> Result<EmpiricalNdf> {
        self.options.validate()?;
        let scan = crate::preprocess::prepare(scan, &self.options.preprocess())?;
        Ok(ndf_or_profile(&scan, &self.ndf_options_of(&scan))?.0)
    }

    fn ndf_options_of(&self, scan: &Prepared) -> NdfOptions {
        self.options.ndf_options_with(|| (scan.raw().nx * scan.raw().ny - scan.invalid_count()) as u64)
    }

    /// The NDF of `scan` ([`ndf_or_profile`]), its description, the time taken (ms) and its profiles if it is
    /// one.
    fn ndf_timed(&self, scan: &Prepared<'_>, ndf_opts: NdfOptions, path: &Path) -> Result<Built> {
        let t1 = Instant::now();
        let (ndf, profile) = ndf_or_profile(scan, &ndf_opts).map_err(|e| e.with_path(path))?;
        let ms = ms(t1);
        Ok(Built { ndf, input: scan.input_info(path), ms, profile })
    }

    /// What light sees of the scan, for `auto` with its answer (`None` otherwise), and the time taken (ms).
    /// The heights come along where light sees a mirror: its haze is computed beside the ladder.
    fn optics_of(&self, scan: &Prepared) -> Option<Sighted> {
        let _p = crate::phases::phase("optics");
        let t = Instant::now();
        (self.options.render.is_some() && self.options.model == ModelChoice::Auto).then(|| {
            let (optics, heights) = crate::answer::optics_and_heights(scan);
            Sighted { optics, heights, ms: ms(t) }
        })
    }

    fn finish(&self, built: Built, path: &Path, read_ms: f64, optics: Option<Sighted>) -> Result<Outcome> {
        let Built { ndf, input, ms: ndf_ms, profile } = built;
        let optics_ms = optics.as_ref().map(|o| o.ms);
        let mut report = match (&self.options.render, self.options.model) {
            (Some(render), ModelChoice::Auto) => {
                let (optics, heights) = optics.map_or((None, None), |o| (Some(o.optics), o.heights));
                fit_answered(&ndf, &self.options.fit_options(), render, &path.display().to_string(), optics, heights)
            }
            _ => fit(&ndf, self.options.model, &self.options.fit_options()),
        }
        .map_err(|e| e.with_path(path))?;
        report.input = Some(input);
        report.timings.read_ms = Some(read_ms);
        report.timings.ndf_ms = Some(ndf_ms);
        // `fit_answered` times the haze it computed beside the ladder; the shares were timed here.
        report.timings.optics_ms = optics_ms.map(|m| m + report.timings.optics_ms.unwrap_or(0.0));
        if let Some(p) = profile {
            p.mark(&mut report);
        }
        Ok(Outcome { ndf, fit: report })
    }
}

/// A scan's NDF, its description, the time taken (ms) and its profiles if it is one.
struct Built {
    ndf: EmpiricalNdf,
    input: InputInfo,
    ms: f64,
    profile: Option<Profile>,
}

/// What light sees of a scan ([`crate::answer::optics_and_heights`]), the time it took (ms), and the
/// heights its haze is computed on where it sees a mirror.
struct Sighted {
    optics: Optics,
    heights: Option<crate::scan::Heightfield>,
    ms: f64,
}

/// Drop a scan read from a file. Heights that are the mapped file are unmapped on a thread of its own:
/// unmapping hundreds of MiB is kernel work of several ms that the caller need not wait for (it writes
/// the NDF or fits meanwhile), and it frees no memory the caller could allocate next. Heights in memory
/// are freed here, before the caller goes on (a batch reads the next scan into that memory). When no
/// thread can be started, the failed spawn drops the scan here.
fn release(scan: Prepared<'static>) {
    if !scan.raw().z.is_mapped() {
        return drop(scan);
    }
    let _ = std::thread::Builder::new().name("ndfit-release".into()).spawn(move || {
        // In pieces first, so that the caller's allocations do not wait on one long unmap.
        scan.raw().z.release_mapped();
        drop(scan)
    });
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// Read a scan file as stored: every format of [`crate::io`], detected from content then extension.
/// Errors name `path`.
pub fn read(path: &Path, opts: &ReadOptions) -> Result<Heightfield> {
    crate::io::atomic::protect_input(path);
    crate::io::read_scan(path, opts)
}

/// Stage 1: read `path` and preprocess it. Without a crop, a subsampling stride is applied while reading
/// ([`crate::io::read_scan_subsampled`]: a large file reads only the kept points); the form is then
/// removed from the kept points. Errors name `path`.
pub fn read_preprocessed(path: &Path, opts: &ReadOptions, pre: &Preprocess) -> Result<Heightfield> {
    crate::io::atomic::protect_input(path);
    if pre.crop.is_none() && pre.subsample > 1 {
        let hf = crate::io::read_scan_subsampled(path, opts, pre.subsample)?;
        let rest = Preprocess { subsample: 1, ..pre.clone() };
        return crate::preprocess::apply(hf, &rest).map_err(|e| e.with_path(path));
    }
    let hf = crate::io::read_scan(path, opts)?;
    crate::preprocess::apply(hf, pre).map_err(|e| e.with_path(path))
}

/// Stage 1 without the residual heights: read `path` and fit its form and spikes
/// ([`crate::preprocess::prepare`]); the heights stay as read (a stored file stays mapped). Errors name
/// `path`.
pub fn read_prepared(path: &Path, opts: &ReadOptions, pre: &Preprocess) -> Result<Prepared<'static>> {
    crate::io::atomic::protect_input(path);
    let phase = crate::phases::phase("read");
    let (hf, rest) = if pre.crop.is_none() && pre.subsample > 1 {
        (crate::io::read_scan_subsampled(path, opts, pre.subsample)?, Preprocess { subsample: 1, ..pre.clone() })
    } else {
        (crate::io::read_scan(path, opts)?, pre.clone())
    };
    drop(phase);
    crate::preprocess::prepare(hf, &rest).map_err(|e| e.with_path(path))
}

/// Stage 2 for a [`Prepared`] scan: its empirical NDF, read band by band (the same frame and bins as
/// [`ndf`] of [`Prepared::into_scan`]; a plane form is folded into the slopes, so a normal within
/// rounding of a cell edge may be counted in the neighbouring cell).
pub fn ndf_prepared(scan: &Prepared, opts: &NdfOptions) -> Result<EmpiricalNdf> {
    crate::ndf::empirical_ndf_of(scan, opts, || scan.invalid_count())
}

/// Stage 2 for a [`Prepared`] scan that may be a profile ([`Profile`]): a profile's NDF is that of its
/// profiles extruded across them, and the profiles come back with it; so is a grid's whose valid points form
/// lines and no areal stencil; any other scan's is [`ndf_prepared`].
pub fn ndf_or_profile(scan: &Prepared, opts: &NdfOptions) -> Result<(EmpiricalNdf, Option<Profile>)> {
    if let Some(p) = Profile::of(scan) {
        return Ok((p.extruded_ndf(scan, opts)?, Some(p)));
    }
    match ndf_prepared(scan, opts) {
        // Valid points in lines and no areal stencil: a trace stored in an areal grid.
        Err(e) if e.kind() == crate::ErrorKind::BadData && e.message().starts_with(crate::ndf::NO_STENCIL) => match Profile::in_lines(scan)
        {
            Some(p) => Ok((p.extruded_ndf(scan, opts)?, Some(p))),
            None => Err(e),
        },
        r => Ok((r?, None)),
    }
}

/// Stage 2: the empirical NDF of a preprocessed scan ([`crate::ndf::empirical_ndf`]).
pub fn ndf(scan: &Scan, opts: &NdfOptions) -> Result<EmpiricalNdf> {
    crate::ndf::empirical_ndf(scan, opts)
}

/// Stage 3: fit one model or choose among them ([`crate::fit::fit_model`], [`crate::fit::fit_auto`]).
pub fn fit(ndf: &EmpiricalNdf, model: ModelChoice, opts: &FitOptions) -> Result<FitReport> {
    match model {
        ModelChoice::Auto => crate::fit::fit_auto(ndf, opts),
        ModelChoice::Model(id) => crate::fit::fit_model(ndf, id, opts),
    }
}

/// Stage 3 for `auto` with its answer: where light sees a mirror ([`crate::answer::answer_mirror`]), the
/// ladder's one-lobe rungs by the NDF alone ([`crate::fit::fit_auto_one_lobe`]) and the mirror answer;
/// elsewhere the render choice ([`fit_rendered`]), or the
/// ladder by the NDF alone with a warning if the renders cannot be made. `optics` goes into the report; with
/// the scan's `heights` ([`crate::answer::optics_and_heights`]) a mirror's haze is computed beside the ladder
/// (they are independent) and its time is the report's `timings.optics_ms`.
pub fn fit_answered(
    ndf: &EmpiricalNdf,
    opts: &FitOptions,
    render: &RenderOptions,
    scan: &str,
    mut optics: Option<Optics>,
    heights: Option<crate::scan::Heightfield>,
) -> Result<FitReport> {
    let t0 = Instant::now();
    let mirror = optics.as_ref().is_some_and(|o| o.regime != crate::answer::Regime::Geometric.as_str());
    let mut haze_ms = None;
    let mut report = if mirror {
        let (report, haze) = rayon::join(
            || crate::fit::fit_auto_one_lobe(ndf, opts),
            || {
                let t = Instant::now();
                let (o, h) = (optics.as_mut()?, heights?);
                crate::answer::add_haze(o, h);
                Some(ms(t))
            },
        );
        haze_ms = haze;
        report?
    } else {
        match fit_rendered(ndf, opts, render, scan) {
            Ok(r) => r,
            Err(e) => {
                let mut r = crate::fit::fit_auto(ndf, opts)?;
                let id = r.model.as_str().to_string();
                r.warnings.push(format!("the render choice could not run ({}): the answer is the NDF's choice, {id}", e.message()));
                if let Some(sel) = r.selection.as_mut() {
                    sel.answer = Some(id);
                }
                r
            }
        }
    };
    if let Some(o) = optics {
        crate::answer::answer_mirror(&mut report, o);
    }
    report.timings.fit_ms = ms(t0);
    report.timings.optics_ms = haze_ms;
    Ok(report)
}

/// Stage 3 for `auto` with its render choice: the ladder, its answer decided by the renders
/// ([`crate::answer::choice::RenderJudge`]), the choice written into the report (`scan` names the scan
/// in the command that writes its table).
pub fn fit_rendered(ndf: &EmpiricalNdf, opts: &FitOptions, render: &RenderOptions, scan: &str) -> Result<FitReport> {
    let judge = RenderJudge::new(ndf, render.clone());
    let t0 = Instant::now();
    let mut report = crate::fit::fit_auto_with(ndf, opts, &judge)?;
    let _p = crate::phases::phase("render");
    judge.apply(&mut report, scan)?;
    report.timings.fit_ms = ms(t0);
    Ok(report)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::models::ModelId;
    use crate::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};

    fn surface() -> Heightfield {
        let p = EllipsoidParams { alpha_x: 0.3, alpha_y: 0.15, theta_z: 0.4, ..Default::default() };
        ellipsoid_surface(&SynthSettings { nx: 192, ny: 192, ..Default::default() }, &p).expect("valid").0
    }

    /// The pipeline against the stages assembled by hand (plane removal, `empirical_ndf`, `fit_model`):
    /// the same bins and the same parameters, bit for bit, from a scan in memory and from the same scan
    /// written to a file; the report's `input` is filled in.
    #[test]
    fn pipeline_equals_the_stages_by_hand_in_memory_and_from_a_file() {
        let hf = surface();
        let opts = Options { model: ModelChoice::Model(ModelId::GgxAniso), ..Options::default() };
        let by_hand = {
            let pre = crate::preprocess::apply(hf.clone(), &Preprocess::default()).expect("plane");
            let ndf = crate::ndf::empirical_ndf(&pre, &NdfOptions::default()).expect("ndf");
            let fit = crate::fit::fit_model(&ndf, ModelId::GgxAniso, &FitOptions::default()).expect("fit");
            (ndf, fit)
        };
        let heights = hf.heights().to_owned();
        let mem = Pipeline::new(opts.clone()).run(Scan::from_view(heights.view(), hf.dx, hf.dy).expect("view"), "mem").expect("run");
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("s.x3p");
        crate::io::write_x3p(&path, &hf).expect("write");
        let file = Pipeline::new(opts).run_path(&path).expect("run_path");
        for o in [&mem, &file] {
            assert_eq!(o.ndf.bins, by_hand.0.bins);
            assert_eq!(o.fit.params, by_hand.1.params);
        }
        let input = file.fit.input.as_ref().expect("input");
        assert_eq!((input.nx, input.ny, input.path.as_str()), (192, 192, path.to_str().expect("utf-8")));
        assert_eq!(mem.fit.input.as_ref().expect("input").path, "mem");
        assert!(file.fit.timings.read_ms.is_some() && file.fit.timings.ndf_ms.is_some());
    }

    /// A preset: its stride subsamples (a quarter of the points along each axis for `fast`), its fit
    /// options apply, and an explicit grid size wins over its binning.
    #[test]
    fn presets_set_stride_binning_and_tolerance() {
        let o = Options {
            preset: Some(Preset::Fast),
            ndf: NdfOptions { cells_across: Some(31), ..NdfOptions::default() },
            ..Options::default()
        };
        assert_eq!(o.preprocess().subsample, preset::FAST_STRIDE);
        assert_eq!(o.fit_options().tolerances, Preset::Fast.fit_options().tolerances);
        let hf = surface();
        assert_eq!(o.ndf_options(&hf).cells_across, Some(31));
        let ndf = Pipeline::new(o).ndf(hf).expect("ndf");
        assert_eq!(ndf.grid.n, 31);
        assert_eq!(ndf.n_samples + ndf.n_skipped, 46 * 46, "central-difference stencils of the 48 x 48 subsample");
        let none = Options::default();
        assert_eq!((none.preprocess(), none.fit_options()), (Preprocess::default(), FitOptions::default()));
    }
}
