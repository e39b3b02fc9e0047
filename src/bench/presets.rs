//! The benchmark knobs of each preset ([`Preset`] itself belongs to the pipeline).

use super::knobs::{Binning, Knobs};
use crate::fit::Solver;
pub use crate::pipeline::preset::Preset;

impl Preset {
    /// The full benchmark knobs of this preset for a scan of `size` points per side.
    pub fn bench_knobs(self, size: usize) -> Knobs {
        let k = self.knobs();
        Knobs {
            size,
            stride: k.stride,
            scheme: k.scheme,
            binning: Binning::Whitened,
            cells: None,
            max_cells: Some(k.max_cells),
            target_count: k.target_count,
            tol: k.tol,
            extra_starts: k.extra_starts,
            solver: Solver::Lm,
            ..Knobs::default()
        }
    }
}
