//! The tail cut of the fit region (`data_formats/objective.md`, "The tail the scan cannot resolve").
//! Three rules, all only on a scan smooth at the sampling step ([`MAX_UNRESOLVED_SHARE`]); `rim` and
//! `core` only once at least [`MIN_TAIL_SHARE`] of the region's normals lie in bins most of whose
//! normals the sampling does not resolve ([`crate::ndf::resolution`]):
//! - `rim` (the default): the `core` cut when the unresolved normals are a lone lobe's rim (at least
//!   [`MIN_ALONE_SHARE`] of them in bins they dominate), else the `unresolved` cut: where another
//!   lobe's resolved normals fill the bins of that rim, those bins stay;
//! - `core`: the region keeps only the whitened core, the bins within Lambert radius [`CORE_RADIUS`] of
//!   the binning frame;
//! - `unresolved`: the majority-unresolved bins alone leave the region (whatever their share).
//!
//! The model is normalized over the bins that remain, so the likelihood stays the exact conditional one
//! of objective.md for the smaller region.

use rayon::prelude::*;

use crate::ndf::{EmpiricalNdf, NdfBin};

pub use crate::ndf::resolution::MAX_UNRESOLVED_SHARE;

/// Lambert radius, in the whitened binning frame, of the core the `core` rule keeps: `|p| <= 1`, the
/// whitened normals within 60 degrees of the frame's centre (`|p| = 2 sin(theta' / 2)`). Beyond it a
/// point-sampled smooth bump maps too few samples per bin to give the density (objective.md).
pub const CORE_RADIUS: f64 = 1.0;

/// Share of the region's normals in unresolved bins from which the `core` rule applies: below it the
/// sampling resolves the tail (a broad or well-sampled bump) and the region is left whole.
pub const MIN_TAIL_SHARE: f64 = 0.005;

/// Share of the region's unresolved normals lying in bins where they are the majority from which the
/// `rim` rule takes them for a lone lobe's rim and cuts the `core`. A single lobe's rim holds its
/// unresolved normals nearly alone; a second, wider lobe covers the narrow lobe's rim with resolved
/// normals, and most unresolved normals then share bins with a resolved majority (objective.md, "Why
/// the rim rule").
pub const MIN_ALONE_SHARE: f64 = 0.5;

/// Which tail rule the fit applies (`--tail`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TailRule {
    /// Every bin within `max_theta` (`--tail all`).
    All,
    /// The bins where most normals are unresolved leave the region (`--tail unresolved`).
    Unresolved,
    /// The whitened core when the sampling leaves an unresolved tail (`--tail core`).
    Core,
    /// `Core` when the unresolved tail is a lone lobe's rim, else `Unresolved` (`--tail rim`, the
    /// default): every bin whose normals the sampling resolves stays, unless it is the ring of a single
    /// lobe whose rim the sampling leaves unresolved.
    #[default]
    Rim,
}

impl std::str::FromStr for TailRule {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Self> {
        match s {
            "all" => Ok(TailRule::All),
            "unresolved" => Ok(TailRule::Unresolved),
            "core" => Ok(TailRule::Core),
            "rim" => Ok(TailRule::Rim),
            _ => Err(crate::Error::invalid(format!("unknown tail rule {s:?} (expected rim, core, unresolved or all)"))),
        }
    }
}

/// What the tail cut left out of the region (the fit JSON's `quality.tail`).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TailCut {
    /// The cut applied: `core` (the whitened core, `CORE_RADIUS`), `unresolved` (bins where over half
    /// of the normals are unresolved), `none`, `none (rough at the sampling step)` or `none (tail
    /// resolved)` (under `MIN_TAIL_SHARE` of the normals in unresolved bins). The default `rim` rule
    /// reports the cut it chose, `core` or `unresolved` ([`TailCut::unresolved_alone_fraction`]).
    pub rule: String,
    /// The relative slope error above which a normal counts as unresolved
    /// (`RESOLUTION_TOLERANCE`).
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
    /// Share of the unresolved normals inside `max_theta` that lie in bins where they are the majority:
    /// the `rim` rule's test against [`MIN_ALONE_SHARE`] (0 when not assessed).
    #[serde(default)]
    pub unresolved_alone_fraction: f64,
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
            unresolved_alone_fraction: 0.0,
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
    let region: Vec<usize> = (0..ndf.bins.len())
        .into_par_iter()
        .filter(|&i| usable(&ndf.bins[i]) && ndf.bins[i].m.z >= cos_max * ndf.bins[i].m.norm())
        .collect();
    let n: f64 = region.iter().map(|&i| ndf.bins[i].count as f64).sum();
    // The test of each bin on every thread, the sums in bin order.
    let frac = |out: &(dyn Fn(usize) -> bool + Sync)| {
        let outs: Vec<bool> = region.par_iter().map(|&i| out(i)).collect();
        let cut = region.iter().zip(&outs).filter(|(_, &o)| o).fold(0.0, |a, (&i, _)| a + ndf.bins[i].count as f64);
        (cut, outs.iter().filter(|&&o| o).count(), if n > 0.0 { cut / n } else { 0.0 })
    };
    let (_, _, tail) = frac(&|i| is_unresolved(ndf, i));
    // Unresolved normals of the region, and those in bins they dominate.
    let (u_all, u_alone) = region.iter().fold((0.0, 0.0), |(a, b), &i| {
        let u = ndf.unresolved[i] as f64;
        (a + u, if is_unresolved(ndf, i) { b + u } else { b })
    });
    let alone = if u_all > 0.0 { u_alone / u_all } else { 0.0 };
    let core = || ("core", frac(&|i| outside_core(ndf, i)));
    let unresolved = || ("unresolved", frac(&|i| is_unresolved(ndf, i)));
    let (name, (cut, k, f)) = match rule {
        TailRule::Unresolved => unresolved(),
        TailRule::Core if tail >= MIN_TAIL_SHARE => core(),
        TailRule::Rim if tail >= MIN_TAIL_SHARE && alone >= MIN_ALONE_SHARE => core(),
        TailRule::Rim if tail >= MIN_TAIL_SHARE => unresolved(),
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
        unresolved_alone_fraction: alone,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ndf::{empirical_ndf, NdfOptions};
    use crate::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};

    /// On a narrow cap (its rim unresolved) the core rule, and the rim rule with it, leaves out exactly
    /// the bins of the region whose centre lies beyond `CORE_RADIUS` in the whitened Lambert disk
    /// (recomputed here from the slope `-m_xy / m_z`, `|p| = sqrt(2 (1 - m'_z))`), and counts them; with
    /// the cap's unresolved normals matched by as many spread over resolved bins, the rim rule cuts only
    /// the majority-unresolved bins; with no unresolved normal no rule cuts, and rough at the sampling
    /// step neither.
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
        // The cap's unresolved normals sit almost alone in their bins: the rim rule cuts the core, the
        // same bins; its test recomputed here over the region.
        let rim = tail_cut(&ndf, cos_max, TailRule::Rim);
        let region = |k: usize| usable(&ndf.bins[k]) && ndf.bins[k].m.z >= cos_max * ndf.bins[k].m.norm();
        let u_all: u64 = (0..ndf.bins.len()).filter(|&k| region(k)).map(|k| ndf.unresolved[k]).sum();
        let u_alone: u64 =
            (0..ndf.bins.len()).filter(|&k| region(k) && 2 * ndf.unresolved[k] > ndf.bins[k].count).map(|k| ndf.unresolved[k]).sum();
        assert!((rim.unresolved_alone_fraction - u_alone as f64 / u_all as f64).abs() < 1e-15);
        assert!(rim.unresolved_alone_fraction >= MIN_ALONE_SHARE, "{}", rim.unresolved_alone_fraction);
        assert_eq!(rim, cut);
        // Spread as many unresolved normals again, a third of each bin's count, over the resolved bins
        // of the region (another lobe's resolved normals around them): now under half are alone, and
        // the rim rule leaves out only the majority-unresolved bins.
        let saved = ndf.unresolved.clone();
        let mut spread = 0;
        for k in 0..ndf.bins.len() {
            if spread < u_all && region(k) && !is_unresolved(&ndf, k) {
                let add = (ndf.bins[k].count / 3).min(u_all - spread);
                ndf.unresolved[k] += add;
                spread += add;
            }
        }
        assert_eq!(spread, u_all);
        let rim = tail_cut(&ndf, cos_max, TailRule::Rim);
        assert!(rim.unresolved_alone_fraction < MIN_ALONE_SHARE, "{}", rim.unresolved_alone_fraction);
        let want = tail_cut(&ndf, cos_max, TailRule::Unresolved);
        assert_eq!((rim.rule.as_str(), rim.bins_excluded, rim.n_excluded), ("unresolved", want.bins_excluded, want.n_excluded));
        assert!(rim.bins_excluded > 0 && rim.bins_excluded < cut.bins_excluded);
        ndf.unresolved = saved;
        let saved = ndf.unresolved.clone();
        ndf.unresolved.iter_mut().for_each(|u| *u = 0);
        let none = tail_cut(&ndf, cos_max, TailRule::Core);
        assert_eq!((none.rule.as_str(), none.bins_excluded), ("none (tail resolved)", 0));
        assert_eq!(tail_cut(&ndf, cos_max, TailRule::Rim).rule, "none (tail resolved)");
        ndf.unresolved = saved;
        ndf.unresolved_share = Some(0.3);
        assert_eq!(tail_cut(&ndf, cos_max, TailRule::Core).rule, "none (rough at the sampling step)");
        assert_eq!(tail_cut(&ndf, cos_max, TailRule::Rim).rule, "none (rough at the sampling step)");
    }
}
