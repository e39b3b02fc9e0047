//! The tail cut of the fit region (`data_formats/objective.md`, "The tail the scan cannot resolve"): the
//! bins most of whose normals the sampling does not resolve ([`crate::ndf::resolution`]) leave the fit
//! region `R`. The model is normalized over the bins that remain, so the likelihood stays the exact
//! conditional one of objective.md for the smaller region.

use crate::ndf::{EmpiricalNdf, NdfBin};

pub use crate::ndf::resolution::MAX_UNRESOLVED_SHARE;

/// What the tail cut left out of the region (the fit JSON's `quality.tail`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TailCut {
    /// The rule: `unresolved` (bins where over half of the normals are unresolved) or `none`.
    pub rule: String,
    /// The relative slope error above which a normal counts as unresolved
    /// ([`crate::ndf::resolution::RESOLUTION_TOLERANCE`]).
    pub tolerance: f64,
    /// Share of all the NDF's normals that are unresolved (the cut applies up to [`MAX_UNRESOLVED_SHARE`]).
    pub unresolved_fraction: f64,
    /// Normals in the bins left out (inside `max_theta`).
    pub n_excluded: f64,
    /// Their share of the normals inside `max_theta`.
    pub excluded_fraction: f64,
    /// Bins left out.
    pub bins_excluded: usize,
}

impl TailCut {
    /// No cut.
    pub fn none() -> TailCut {
        TailCut { rule: "none".into(), tolerance: 0.0, unresolved_fraction: 0.0, n_excluded: 0.0, excluded_fraction: 0.0, bins_excluded: 0 }
    }
}

/// Whether bin `k` of `ndf` is unresolved: over half of its normals are ([`EmpiricalNdf::unresolved`];
/// never for an NDF without that count, nor for an empty bin).
#[inline]
pub fn is_unresolved(ndf: &EmpiricalNdf, k: usize) -> bool {
    ndf.unresolved.get(k).is_some_and(|&u| 2 * u > ndf.bins[k].count)
}

/// Whether a bin can carry data at all: `W > 0`, finite, above the horizon.
pub fn usable(b: &NdfBin) -> bool {
    b.proj_solid_angle > 0.0 && b.proj_solid_angle.is_finite() && b.m.z > 0.0 && b.m.iter().all(|v| v.is_finite())
}

/// The cut over the usable bins of `ndf` with `m.z >= cos_max |m|` (`enabled` false: [`TailCut::none`]).
pub fn tail_cut(ndf: &EmpiricalNdf, cos_max: f64, enabled: bool) -> TailCut {
    let Some(share) = ndf.unresolved_share.filter(|_| enabled) else { return TailCut::none() };
    if !(share <= MAX_UNRESOLVED_SHARE) || ndf.unresolved.len() != ndf.bins.len() {
        return TailCut {
            rule: "none (rough at the sampling step)".into(),
            tolerance: ndf.resolution_tolerance,
            unresolved_fraction: share,
            ..TailCut::none()
        };
    }
    let (mut n, mut cut, mut k) = (0.0, 0.0, 0usize);
    for (i, b) in ndf.bins.iter().enumerate() {
        if !(usable(b) && b.m.z >= cos_max * b.m.norm()) {
            continue;
        }
        n += b.count as f64;
        if is_unresolved(ndf, i) {
            cut += b.count as f64;
            k += 1;
        }
    }
    TailCut {
        rule: "unresolved".into(),
        tolerance: ndf.resolution_tolerance,
        unresolved_fraction: share,
        n_excluded: cut,
        excluded_fraction: if n > 0.0 { cut / n } else { 0.0 },
        bins_excluded: k,
    }
}
