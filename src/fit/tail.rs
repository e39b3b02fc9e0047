//! The tail cut of the fit region (`data_formats/objective.md`, "The tail the scan cannot resolve"). Two
//! rules, both only on a scan smooth at the sampling step ([`MAX_UNRESOLVED_SHARE`]):
//! - `core` (the default): when at least [`MIN_TAIL_SHARE`] of the normals in the region lie in bins most
//!   of whose normals the sampling does not resolve ([`crate::ndf::resolution`]), the region keeps only
//!   the whitened core, the bins within Lambert radius [`CORE_RADIUS`] of the binning frame;
//! - `unresolved` (`--tail unresolved`): those bins alone leave the region.
//!
//! The model is normalized over the bins that remain, so the likelihood stays the exact conditional one
//! of objective.md for the smaller region.

use crate::ndf::{EmpiricalNdf, NdfBin};

pub use crate::ndf::resolution::MAX_UNRESOLVED_SHARE;

/// Lambert radius, in the whitened binning frame, of the core the `core` rule keeps: `|p| <= 1`, the
/// whitened normals within 60 degrees of the frame's centre (`|p| = 2 sin(theta' / 2)`). Beyond it a
/// point-sampled smooth bump maps too few samples per bin to give the density (objective.md).
pub const CORE_RADIUS: f64 = 1.0;

/// Share of the region's normals in unresolved bins from which the `core` rule applies: below it the
/// sampling resolves the tail (a broad or well-sampled bump) and the region is left whole.
pub const MIN_TAIL_SHARE: f64 = 0.005;

/// Which tail rule the fit applies (`--tail`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TailRule {
    /// Every bin within `max_theta` (`--tail all`).
    All,
    /// The bins where most normals are unresolved leave the region (`--tail unresolved`).
    Unresolved,
    /// The whitened core when the sampling leaves an unresolved tail (`--tail core`, the default).
    #[default]
    Core,
}

impl std::str::FromStr for TailRule {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Self> {
        match s {
            "all" => Ok(TailRule::All),
            "unresolved" => Ok(TailRule::Unresolved),
            "core" => Ok(TailRule::Core),
            _ => Err(crate::Error::invalid(format!("unknown tail rule {s:?} (expected core, unresolved or all)"))),
        }
    }
}

/// What the tail cut left out of the region (the fit JSON's `quality.tail`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TailCut {
    /// The rule applied: `core` (the whitened core, [`CORE_RADIUS`]), `unresolved` (bins where over half
    /// of the normals are unresolved), `none`, `none (rough at the sampling step)` or `none (tail
    /// resolved)` (the `core` rule found under [`MIN_TAIL_SHARE`] of the normals unresolved).
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
    /// Share of the normals inside `max_theta` in unresolved bins (the `core` rule's test; 0 when not
    /// assessed).
    #[serde(default)]
    pub unresolved_tail_fraction: f64,
}

impl TailCut {
    /// No cut.
    pub fn none() -> TailCut {
        TailCut {
            rule: "none".into(),
            tolerance: 0.0,
            unresolved_fraction: 0.0,
            n_excluded: 0.0,
            excluded_fraction: 0.0,
            bins_excluded: 0,
            unresolved_tail_fraction: 0.0,
        }
    }

    /// Whether the cut leaves bin `k` of `ndf` (the NDF it was made from) out of the region.
    #[inline]
    pub fn excludes(&self, ndf: &EmpiricalNdf, k: usize) -> bool {
        match self.rule.as_str() {
            "core" => outside_core(ndf, k),
            "unresolved" => is_unresolved(ndf, k),
            _ => false,
        }
    }
}

/// Whether bin `k` of `ndf` lies beyond [`CORE_RADIUS`] in the whitened Lambert disk of its frame.
#[inline]
pub fn outside_core(ndf: &EmpiricalNdf, k: usize) -> bool {
    let m = ndf.bins[k].m;
    let p = ndf.frame.to_lambert(-m.x / m.z, -m.y / m.z);
    !(p[0] * p[0] + p[1] * p[1] <= CORE_RADIUS * CORE_RADIUS)
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

/// The cut of `rule` over the usable bins of `ndf` with `m.z >= cos_max |m|`.
pub fn tail_cut(ndf: &EmpiricalNdf, cos_max: f64, rule: TailRule) -> TailCut {
    let Some(share) = ndf.unresolved_share.filter(|_| rule != TailRule::All) else { return TailCut::none() };
    if !(share <= MAX_UNRESOLVED_SHARE) || ndf.unresolved.len() != ndf.bins.len() {
        return TailCut {
            rule: "none (rough at the sampling step)".into(),
            tolerance: ndf.resolution_tolerance,
            unresolved_fraction: share,
            ..TailCut::none()
        };
    }
    let region: Vec<usize> =
        (0..ndf.bins.len()).filter(|&i| usable(&ndf.bins[i]) && ndf.bins[i].m.z >= cos_max * ndf.bins[i].m.norm()).collect();
    let n: f64 = region.iter().map(|&i| ndf.bins[i].count as f64).sum();
    let frac = |out: &dyn Fn(usize) -> bool| {
        let cut = region.iter().filter(|&&i| out(i)).fold(0.0, |a, &i| a + ndf.bins[i].count as f64);
        (cut, region.iter().filter(|&&i| out(i)).count(), if n > 0.0 { cut / n } else { 0.0 })
    };
    let (_, _, tail) = frac(&|i| is_unresolved(ndf, i));
    let (name, (cut, k, f)) = match rule {
        TailRule::Unresolved => ("unresolved", frac(&|i| is_unresolved(ndf, i))),
        TailRule::Core if tail >= MIN_TAIL_SHARE => ("core", frac(&|i| outside_core(ndf, i))),
        _ => ("none (tail resolved)", (0.0, 0, 0.0)),
    };
    TailCut {
        rule: name.into(),
        tolerance: ndf.resolution_tolerance,
        unresolved_fraction: share,
        n_excluded: cut,
        excluded_fraction: f,
        bins_excluded: k,
        unresolved_tail_fraction: tail,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ndf::{empirical_ndf, NdfOptions};
    use crate::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};

    /// On a narrow cap (its rim unresolved) the core rule leaves out exactly the bins of the region whose
    /// centre lies beyond `CORE_RADIUS` in the whitened Lambert disk (recomputed here from the slope
    /// `-m_xy / m_z`, `|p| = sqrt(2 (1 - m'_z))`), and counts them; with no unresolved normal it cuts
    /// nothing, and rough at the sampling step neither.
    #[test]
    fn core_rule_cuts_the_ring_beyond_the_core() {
        let s = SynthSettings { nx: 256, ny: 256, seed: 3, ..SynthSettings::default() };
        let (hf, _) =
            ellipsoid_surface(&s, &EllipsoidParams { alpha_x: 0.05, alpha_y: 0.05, ..EllipsoidParams::default() }).expect("synth");
        let mut ndf = empirical_ndf(&hf, &NdfOptions::default()).expect("ndf");
        let cos_max = 70f64.to_radians().cos();
        let cut = tail_cut(&ndf, cos_max, TailRule::Core);
        assert_eq!(cut.rule, "core");
        assert!(cut.unresolved_tail_fraction >= MIN_TAIL_SHARE);
        let (mut n, mut out, mut k) = (0.0, 0.0, 0);
        for (i, b) in ndf.bins.iter().enumerate() {
            if !(usable(b) && b.m.z >= cos_max * b.m.norm()) {
                continue;
            }
            let w = ndf.frame.whiten;
            let (sx, sy) = (-b.m.x / b.m.z - ndf.frame.center[0], -b.m.y / b.m.z - ndf.frame.center[1]);
            let (wx, wy) = (w[0][0] * sx + w[0][1] * sy, w[1][0] * sx + w[1][1] * sy);
            let p = (2.0 * (1.0 - 1.0 / (1.0 + wx * wx + wy * wy).sqrt())).sqrt();
            n += b.count as f64;
            assert_eq!(cut.excludes(&ndf, i), p > CORE_RADIUS, "bin {i}: |p| {p}");
            if p > CORE_RADIUS {
                out += b.count as f64;
                k += 1;
            }
        }
        assert_eq!((cut.n_excluded, cut.bins_excluded), (out, k));
        assert!((cut.excluded_fraction - out / n).abs() < 1e-15);
        assert!(tail_cut(&ndf, cos_max, TailRule::All).rule == "none");
        let saved = ndf.unresolved.clone();
        ndf.unresolved.iter_mut().for_each(|u| *u = 0);
        let none = tail_cut(&ndf, cos_max, TailRule::Core);
        assert_eq!((none.rule.as_str(), none.bins_excluded), ("none (tail resolved)", 0));
        ndf.unresolved = saved;
        ndf.unresolved_share = Some(0.3);
        assert_eq!(tail_cut(&ndf, cos_max, TailRule::Core).rule, "none (rough at the sampling step)");
    }
}
