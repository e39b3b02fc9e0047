//! One point of the speed/accuracy sweep: the value of every knob that buys speed.

use crate::fit::{FitOptions, Objective, Solver, Tolerances};
use crate::models::ModelId;
use crate::ndf::{NdfOptions, NormalScheme, SlopeFrame, MAX_AUTO_CELLS};

/// How normals are binned on the hemisphere.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Binning {
    /// The default: slopes whitened by their robust covariance, then the Lambert equal-area map
    /// (bins follow the lobe, so few bins resolve any roughness; see `ndf::frame`).
    Whitened,
    /// The plain Lambert equal-area map of the unstretched normal (identity frame at the origin): the
    /// scheme a user would write first. A narrow lobe then falls into few bins.
    Plain,
}

impl Binning {
    /// The name used on the command line and in the CSV.
    pub fn as_str(self) -> &'static str {
        match self {
            Binning::Whitened => "whitened",
            Binning::Plain => "plain",
        }
    }
}

/// How the heights are stored for the NDF pass (f32 or f64 storage).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Storage {
    /// The heightfield's own f64 heights (the library default).
    #[default]
    F64,
    /// `f32(h - mean)`, the mean taken in f64 first (a stage offset would otherwise leave the detail in
    /// the last bits), widened back to f64 before differencing: [`crate::ndf::HeightsF32`] and
    /// [`crate::ndf::empirical_ndf_f32`]. The conversion is timed as its own stage (`t_convert_ms`).
    F32,
}

impl Storage {
    /// The name used in the CSV.
    pub fn as_str(self) -> &'static str {
        match self {
            Storage::F64 => "f64",
            Storage::F32 => "f32",
        }
    }
}

/// Every knob of one benchmark point.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Knobs {
    /// Side of the square synthetic scan (points).
    pub size: usize,
    /// Subsampling stride: every `stride`-th point along both axes (`preprocess::subsample`).
    pub stride: usize,
    /// Normal scheme.
    pub scheme: NormalScheme,
    /// Binning scheme.
    pub binning: Binning,
    /// Cells across the Lambert disk, or `None` for the automatic choice from `target_count`.
    pub cells: Option<usize>,
    /// Mean count per bin aimed at when `cells` is `None`.
    pub target_count: f64,
    /// Cap on the automatic cells across (`None`: the NDF's own cap).
    #[serde(default)]
    pub max_cells: Option<usize>,
    /// Model fitted (`None`: the pipeline stops at the empirical NDF).
    pub model: Option<ModelId>,
    /// Local solver.
    pub solver: Solver,
    /// Relative tolerance of the solver.
    pub tol: f64,
    /// Extra ellipsoid starts beyond the default two.
    pub extra_starts: usize,
    /// Storage of the heights for the NDF pass.
    #[serde(default)]
    pub storage: Storage,
}

impl Default for Knobs {
    /// The library defaults (what `ndfit fit` does without options) on a 1024^2 scan.
    fn default() -> Self {
        let f = FitOptions::default();
        let n = NdfOptions::default();
        Knobs {
            size: 1024,
            stride: 1,
            scheme: n.scheme,
            binning: Binning::Whitened,
            cells: n.cells_across,
            max_cells: None,
            target_count: n.target_count,
            model: Some(ModelId::Ellipsoid),
            solver: f.solver,
            tol: f.tolerances.rel,
            extra_starts: f.extra_starts,
            storage: Storage::F64,
        }
    }
}

impl Knobs {
    /// Whether [`Knobs::ndf_options`] needs the scan's valid count: only for an automatic grid capped
    /// below the NDF's own cap (counting is a pass over every height).
    pub fn needs_sample_count(&self) -> bool {
        self.cells.is_none() && self.max_cells.is_some_and(|m| m < MAX_AUTO_CELLS)
    }

    /// The NDF options of these knobs for a scan with about `samples` valid normals (used only when
    /// [`Knobs::needs_sample_count`]).
    pub fn ndf_options(&self, samples: u64) -> NdfOptions {
        let auto = NdfOptions { target_count: self.target_count, ..NdfOptions::default() };
        let cells = match (self.cells, self.max_cells) {
            (Some(c), _) => Some(c),
            (None, Some(m)) if m < MAX_AUTO_CELLS => Some(auto.cells_for(samples).min(m)),
            // The automatic choice caps at MAX_AUTO_CELLS itself (and keeps the NDF's own guards).
            (None, _) => None,
        };
        NdfOptions {
            scheme: self.scheme,
            cells_across: cells,
            target_count: self.target_count,
            frame: match self.binning {
                Binning::Whitened => None,
                // The identity frame: whitening does nothing, the map is the plain Lambert map of m.
                Binning::Plain => Some(SlopeFrame::new([0.0, 0.0], [[1.0, 0.0], [0.0, 1.0]])),
            },
            resolution: None,
        }
    }

    /// The fit options of these knobs (Poisson objective, the default iteration budget).
    pub fn fit_options(&self) -> FitOptions {
        FitOptions {
            objective: Objective::Poisson,
            solver: self.solver,
            tolerances: Tolerances { rel: self.tol, ..Tolerances::default() },
            extra_starts: self.extra_starts,
            ..FitOptions::default()
        }
    }

    /// Bins as written in the CSV: the fixed count across, or `auto<target>`.
    pub fn cells_label(&self) -> String {
        match (self.cells, self.max_cells) {
            (Some(c), _) => c.to_string(),
            (None, Some(m)) => format!("auto{}max{m}", self.target_count),
            (None, None) => format!("auto{}", self.target_count),
        }
    }
}
