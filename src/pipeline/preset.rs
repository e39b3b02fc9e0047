//! The presets `fast`, `balanced` and `accurate` (`--preset`): points picked from the measured Pareto front
//! of `ndfit bench` (time against error on the synthetic set; see `docs/PERFORMANCE.md` for the figures
//! behind each choice).

use crate::fit::{FitOptions, Solver};
use crate::ndf::{NdfOptions, NormalScheme, DEFAULT_TARGET_COUNT, MAX_AUTO_CELLS};

/// Subsampling stride of the `fast` preset: every fourth point along both axes (16x fewer normals).
/// On the measured front (docs/PERFORMANCE.md) a coarser sampling of the scan buys more time per unit of
/// error than coarser bins do, so `fast` keeps the NDF's own binning and subsamples.
pub const FAST_STRIDE: usize = 4;

/// A named speed/accuracy trade.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "cli", derive(clap::ValueEnum))]
#[serde(rename_all = "snake_case")]
pub enum Preset {
    /// Every 4th point along both axes (16x fewer normals; `FAST_STRIDE`), the NDF's own binning for
    /// them, a looser solver tolerance.
    Fast,
    /// What `ndfit fit` does without a preset: every point, the NDF's own binning (64 samples per bin up
    /// to 255 cells across: `ndf::DEFAULT_TARGET_COUNT`, `ndf::MAX_AUTO_CELLS`), the default solver. The
    /// most accurate binning measured on the synthetic set.
    #[default]
    Balanced,
    /// Balanced's binning with a tighter tolerance and four extra ellipsoid starts: a guard against
    /// local minima on real data, no gain on the synthetic set. (Triangle facets measured no better
    /// than central differences at 2048^2, so central it stays.)
    Accurate,
}

impl Preset {
    /// Every preset, fastest first.
    pub const ALL: [Preset; 3] = [Preset::Fast, Preset::Balanced, Preset::Accurate];

    /// The name used on the command line and in the CSV.
    pub fn as_str(self) -> &'static str {
        match self {
            Preset::Fast => "fast",
            Preset::Balanced => "balanced",
            Preset::Accurate => "accurate",
        }
    }

    /// The knobs of this preset (scan size and model are the caller's: they are not speed knobs of
    /// the pipeline but properties of the job).
    pub fn knobs(self) -> PresetKnobs {
        match self {
            Preset::Fast => PresetKnobs {
                stride: FAST_STRIDE,
                scheme: NormalScheme::Central,
                target_count: DEFAULT_TARGET_COUNT,
                max_cells: MAX_AUTO_CELLS,
                tol: 1e-6,
                extra_starts: 0,
            },
            Preset::Balanced => PresetKnobs {
                stride: 1,
                scheme: NormalScheme::Central,
                target_count: DEFAULT_TARGET_COUNT,
                max_cells: MAX_AUTO_CELLS,
                tol: 1e-10,
                extra_starts: 0,
            },
            Preset::Accurate => PresetKnobs {
                stride: 1,
                scheme: NormalScheme::Central,
                target_count: DEFAULT_TARGET_COUNT,
                max_cells: MAX_AUTO_CELLS,
                tol: 1e-12,
                extra_starts: 4,
            },
        }
    }

    /// Whether [`Preset::ndf_options`] needs the scan's valid count (a pass over every height): only
    /// when the preset caps the automatic grid below the NDF's own cap.
    pub fn needs_sample_count(self) -> bool {
        self.knobs().max_cells < MAX_AUTO_CELLS
    }

    /// The NDF options of this preset for a scan with about `samples` valid normals (the bin count is
    /// the automatic one for `PresetKnobs::target_count`, capped at `PresetKnobs::max_cells`).
    pub fn ndf_options(self, samples: u64) -> NdfOptions {
        let k = self.knobs();
        let auto = NdfOptions { scheme: k.scheme, cells_across: None, target_count: k.target_count, frame: None, resolution: None };
        if k.max_cells >= MAX_AUTO_CELLS {
            // The automatic choice caps there already; leaving it automatic keeps the NDF's own guards
            // (the quantized-height cap) exactly as `ndfit fit` without a preset.
            return auto;
        }
        NdfOptions { cells_across: Some(auto.cells_for(samples).min(k.max_cells)), ..auto }
    }

    /// The fit options of this preset.
    pub fn fit_options(self) -> FitOptions {
        let mut f = FitOptions::default();
        let k = self.knobs();
        f.tolerances.rel = k.tol;
        f.extra_starts = k.extra_starts;
        f.solver = Solver::Lm;
        f
    }

    /// Subsampling stride of this preset (1: every point).
    pub fn stride(self) -> usize {
        self.knobs().stride
    }
}

impl std::fmt::Display for Preset {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

impl std::str::FromStr for Preset {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Self> {
        Preset::ALL
            .into_iter()
            .find(|p| p.as_str() == s)
            .ok_or_else(|| crate::Error::invalid(format!("unknown preset {s:?}: use fast, balanced or accurate")))
    }
}

/// The knob values a preset sets.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PresetKnobs {
    /// Subsampling stride.
    pub stride: usize,
    /// Normal scheme.
    pub scheme: NormalScheme,
    /// Mean count per bin (automatic bin count).
    pub target_count: f64,
    /// Cap on the cells across the disk.
    pub max_cells: usize,
    /// Relative solver tolerance.
    pub tol: f64,
    /// Extra ellipsoid starts.
    pub extra_starts: usize,
}
