//! What the fit report says of the scanned input: the grid, the invalid points and the preprocessing
//! that kept or masked them (the fit JSON's `input`).

use std::path::Path;

use super::Scan;

/// The scanned input (contract: `input` {path, format, nx, ny, dx, dy}).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct InputInfo {
    /// The scan's path as given.
    pub path: String,
    /// Format id.
    pub format: String,
    /// Columns.
    pub nx: usize,
    /// Rows.
    pub ny: usize,
    /// Spacing along x (m).
    pub dx: f64,
    /// Spacing along y (m).
    pub dy: f64,
    /// Masked points: the file's own invalid points plus the spikes.
    pub invalid: usize,
    /// The file's own invalid points (what `ndfit info` reports as `invalid`).
    #[serde(default)]
    pub file_invalid: usize,
    /// Points the spike removal masked on top of them (0 when it did not run).
    #[serde(default)]
    pub spikes: usize,
    /// The file's own grid (columns, rows) when a crop, `--subsample` or a preset kept fewer points
    /// (`nx`, `ny`, `dx`, `dy` are then those of the kept points).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub file_grid: Option<[usize; 2]>,
    /// What spike removal masked (preprocessing), when it ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub despike: Option<super::DespikeReport>,
}

impl InputInfo {
    /// Describe `hf` read from `path`.
    pub fn new(path: &Path, hf: &Scan) -> InputInfo {
        Self::with_invalid(path, hf, hf.invalid_count())
    }

    /// [`InputInfo::new`] with the invalid points counted by the caller (a scan whose spikes are masked
    /// apart from its heights, [`crate::preprocess::Prepared`]).
    pub fn with_invalid(path: &Path, hf: &Scan, invalid: usize) -> InputInfo {
        let spikes = hf.meta.despike.as_ref().map_or(0, |d| d.masked);
        InputInfo {
            file_invalid: invalid.saturating_sub(spikes),
            spikes,
            path: path.display().to_string(),
            format: hf.meta.format.clone(),
            nx: hf.nx,
            ny: hf.ny,
            dx: hf.dx,
            dy: hf.dy,
            invalid,
            file_grid: hf.meta.file_grid.filter(|g| *g != [hf.nx, hf.ny]),
            despike: hf.meta.despike.clone(),
        }
    }
}
