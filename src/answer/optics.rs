//! What light sees of a scan: geometric optics of its slopes, or wave optics of its heights (docs/ANSWER.md).
//!
//! The mirror share `s(theta, lambda)` ([`crate::wave::mirror_shares`]) is measured at the default
//! wavelengths and the incidences a renderer uses. The regime, in this order:
//! - `geometric` when the scan cannot tell (no patch resolved, or more than [`UNRESOLVED`] of the light
//!   at normal incidence leaves beyond the band its spacing resolves);
//! - `geometric` when the patches tilt by more than [`TILT_RATIO`] of the slopes' RMS angle, and twice
//!   their tilt is more than a patch's angular step (`lambda / side` at 550 nm): each patch's coherent
//!   light goes where its plane sends it, which the slopes' NDF already holds;
//! - otherwise, per incidence: `wave` where `s >= MIRROR_SHARE` at every wavelength, geometric where `s`
//!   is below [`GEOMETRIC_SHARE`] (or twice the incoherent floor) at every wavelength; `wave` or
//!   `geometric` when every incidence agrees, `mixed` when the regime changes with the angle.
//!
//! Where the regime is not geometric, the answer has a mirror term: `s` by incidence and wavelength, and a
//! haze lobe fitted to the diffuse wave BRDF ([`haze`]).

use std::collections::BTreeMap;

use crate::error::Result;
use crate::fit::{FitReport, Haze, Optics, SpecularShare, Verdict};
use crate::models::ModelId;
use crate::scan::{BandSource, Heightfield, Scan};
use crate::wave::{
    default_coherence_m, mirror_shares, Diffraction, MirrorShares, WaveOptions, DEFAULT_INCIDENCES_DEG, DEFAULT_WAVELENGTHS_NM,
};

/// At an incidence where the mirror carries at least this share at every wavelength, light sees a mirror.
pub const MIRROR_SHARE: f64 = 0.5;
/// At an incidence where the mirror carries less than this share (or twice the incoherent floor) at every
/// wavelength, light sees the slopes (geometric optics).
pub const GEOMETRIC_SHARE: f64 = 0.05;
/// Above this share of the light beyond the band the spacing resolves, the scan cannot tell.
pub const UNRESOLVED: f64 = 0.2;
/// Patches tilted by more than this share of the slopes' RMS angle (as tangents) are facets.
pub const TILT_RATIO: f64 = 0.5;
/// `(alpha, share)`: a GGX haze of roughness `alpha` carrying at least `share` of a smooth conductor's light
/// is seen in the choice's broad scene: the mirror with it and the mirror alone score the render tolerance
/// apart (`examples/haze_visibility.rs`; docs/ANSWER.md, "When the haze is left out").
pub const HAZE_VISIBLE: [(f64, f64); 11] = [
    (0.003, 2.41e-2),
    (0.005, 9.07e-3),
    (0.01, 2.62e-3),
    (0.02, 8.71e-4),
    (0.03, 4.88e-4),
    (0.05, 2.49e-4),
    (0.1, 1.09e-4),
    (0.2, 5.41e-5),
    (0.4, 3.40e-5),
    (0.7, 3.17e-5),
    (1.0, 3.77e-5),
];

/// The share from which a GGX haze of roughness `alpha` is seen ([`HAZE_VISIBLE`], interpolated in
/// `ln alpha` and `ln share`, held beyond its ends).
pub fn haze_visible(alpha: f64) -> f64 {
    let t = &HAZE_VISIBLE;
    // A NaN roughness is no haze anyone sees: the largest share of the table.
    if alpha.is_nan() || alpha <= t[0].0 {
        return t[0].1;
    }
    let last = t[t.len() - 1];
    if alpha >= last.0 {
        return last.1;
    }
    let k = t.iter().position(|&(a, _)| a >= alpha).unwrap_or(t.len() - 1);
    let ((a0, s0), (a1, s1)) = (t[k - 1], t[k]);
    let u = (alpha / a0).ln() / (a1 / a0).ln();
    (s0.ln() + u * (s1 / s0).ln()).exp()
}
/// The wavelength (nm) of the haze lobe's fit and of the one-line summaries.
const MID_NM: f64 = 550.0;

/// The regime of a scan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Regime {
    /// Geometric optics of the slopes holds at every incidence.
    Geometric,
    /// Geometric at some incidences, a mirror at others.
    Mixed,
    /// A mirror at every incidence.
    Wave,
}

impl Regime {
    /// The contract's name.
    pub fn as_str(self) -> &'static str {
        match self {
            Regime::Geometric => "geometric",
            Regime::Mixed => "mixed",
            Regime::Wave => "wave",
        }
    }
}

/// The optics of `src` (residual heights in metres) at the default wavelengths and incidences and
/// sunlight's coherence (module docs). No haze yet ([`haze`]).
pub fn optics<S: BandSource<T = f64>>(src: &S) -> Optics {
    let c = default_coherence_m();
    let m = mirror_shares(src, &DEFAULT_WAVELENGTHS_NM, &DEFAULT_INCIDENCES_DEG, c);
    let (regime, why) = regime(&m);
    let specular = m
        .wavelength_nm
        .iter()
        .enumerate()
        .flat_map(|(l, &w)| m.theta_deg.iter().enumerate().map(move |(t, &th)| (l, t, w, th)))
        .map(|(l, t, w, th)| SpecularShare { theta_deg: th, wavelength_nm: w, weight: m.share(l, t) })
        .collect();
    let patches: BTreeMap<String, f64> = [
        ("used", m.used as f64),
        ("skipped", m.skipped as f64),
        ("side_x_m", m.patch_m[0]),
        ("side_y_m", m.patch_m[1]),
        ("tilt_rms_deg", m.tilt_rms_deg),
        ("slope_rms_deg", m.slope_rms_deg),
        ("incoherent_floor", m.incoherent_floor),
        ("beyond_band", m.beyond_band),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v))
    .collect();
    Optics {
        regime: regime.as_str().to_string(),
        wavelength_nm: m.wavelength_nm.clone(),
        coherence_m: c,
        specular,
        why,
        haze: None,
        patches,
        note: m.note.clone(),
    }
}

/// The regime and its reason (module docs).
fn regime(m: &MirrorShares) -> (Regime, String) {
    if m.used == 0 {
        let why = format!("no coherence patch has 90% valid points ({} skipped): the scan cannot tell, geometric optics", m.skipped);
        return (Regime::Geometric, why);
    }
    if m.beyond_band > UNRESOLVED {
        let why = format!(
            "the scan cannot tell: {:.0}% of the light at normal incidence leaves beyond the band its spacing resolves; geometric optics",
            m.beyond_band * 100.0
        );
        return (Regime::Geometric, why);
    }
    let (tilt, slope) = (m.tilt_rms_deg.to_radians().tan(), m.slope_rms_deg.to_radians().tan());
    // The patch's own angular step at 550 nm: a mirror image spread by less is still a mirror to this light.
    let step = MID_NM * 1e-9 / m.patch_m[0].max(m.patch_m[1]);
    if tilt > TILT_RATIO * slope && 2.0 * tilt > step {
        let why = format!(
            "its coherence patches tilt by {:.2} deg RMS against {:.2} deg of its slopes: each patch's coherent light goes where its facets send it, geometric optics",
            m.tilt_rms_deg, m.slope_rms_deg
        );
        return (Regime::Geometric, why);
    }
    let floor = GEOMETRIC_SHARE.max(2.0 * m.incoherent_floor);
    let lambdas = 0..m.wavelength_nm.len();
    let wave: Vec<bool> = (0..m.theta_deg.len()).map(|t| lambdas.clone().all(|l| m.share(l, t) >= MIRROR_SHARE)).collect();
    let geo: Vec<bool> = (0..m.theta_deg.len()).map(|t| lambdas.clone().all(|l| m.share(l, t) < floor)).collect();
    let mid = m.wavelength_nm.iter().position(|&w| w == MID_NM).unwrap_or(0);
    let shares: Vec<String> = m.theta_deg.iter().enumerate().map(|(t, th)| format!("{:.3} at {th} deg", m.share(mid, t))).collect();
    let shares = format!("mirror share at {} nm {}", m.wavelength_nm[mid], shares.join(", "));
    if wave.iter().all(|&w| w) {
        (Regime::Wave, format!("a mirror at every incidence ({shares}): wave optics"))
    } else if geo.iter().all(|&g| g) {
        (Regime::Geometric, format!("no mirror at any incidence ({shares}; below {floor:.3}): geometric optics"))
    } else {
        (
            Regime::Mixed,
            format!("the mirror's share changes with the angle ({shares}): geometric optics for the rest, wave optics for the mirror"),
        )
    }
}

/// The haze of a mirror: a GGX lobe fitted to the diffuse wave BRDF at normal incidence and 550 nm over
/// the scan's coherence patches. At normal incidence the diffuse energy in direction `w_o` is the
/// projected-area distribution of the half vector (`f cos t_o dw_o = D(h) G (w_o . h) dw_h`, `G ~ 1`), whose
/// `tan^2 theta_h` has the CDF `t / (alpha^2 + t)` for GGX: `alpha^2` is its energy-weighted median.
pub fn haze(scan: &Scan<'_>, coherence_m: &[f64]) -> Result<Haze> {
    let mut last = None;
    for &c in coherence_m {
        let opts = WaveOptions { wavelengths_nm: vec![MID_NM], incidences_deg: vec![0.0], coherence_m: Some(c), ..WaveOptions::default() };
        match Diffraction::propagating(scan, &opts) {
            Ok(d) => return Ok(haze_of(&d.scattered(MID_NM, [0.0, 0.0, 1.0]))),
            Err(e) => last = Some(e),
        }
    }
    Err(last.unwrap_or_else(|| crate::Error::invalid("no coherence patch to compute the haze on")))
}

/// The GGX lobe whose `tan^2 theta_h` median is that of the `scattered` energies (see [`haze`]).
fn haze_of(scattered: &[([f64; 3], f64)]) -> Haze {
    let mut t: Vec<(f64, f64)> = scattered
        .iter()
        .map(|&(wo, e)| {
            // The half vector of w_i = +z and w_o: (x_o, y_o, 1 + z_o), unnormalized.
            let hz = 1.0 + wo[2];
            ((wo[0] * wo[0] + wo[1] * wo[1]) / (hz * hz), e)
        })
        .collect();
    t.sort_by(|a, b| a.0.total_cmp(&b.0));
    let albedo: f64 = t.iter().map(|x| x.1).sum();
    let mut acc = 0.0;
    let median = t
        .iter()
        .find(|x| {
            acc += x.1;
            acc >= 0.5 * albedo
        })
        .map_or(0.0, |x| x.0);
    Haze { model: ModelId::Ggx, params: BTreeMap::from([("alpha".to_string(), median.sqrt())]), albedo }
}

/// Write a mirror answer into an `auto` report whose optics are not geometric: `selection.answer`
/// (`mirror`, or `mirror+ggx` with a visible haze), the verdict `ok` for the reason given, the NDF's own
/// reasons kept after it; without a diffuse wave BRDF the haze is the slopes' lobe, the ladder's `ggx` carrying `1 - s`.
/// Returns false (nothing written) for the geometric regime.
pub fn answer_mirror(report: &mut FitReport, optics: Optics) -> bool {
    if optics.regime == Regime::Geometric.as_str() {
        report.optics = Some(optics);
        return false;
    }
    let mut optics = optics;
    let normal = optics.specular.iter().find(|s| s.theta_deg == 0.0 && s.wavelength_nm == MID_NM).map_or(f64::NAN, |s| s.weight);
    let slopes = optics.haze.is_none().then(|| slopes_haze(report, normal)).flatten();
    if let Some(h) = &slopes {
        let line = format!(
            "the haze is the ladder's ggx (alpha {:.4}, the slopes' lobe) carrying the light the mirror does not",
            h.params["alpha"]
        );
        optics.note = Some(optics.note.take().map_or(line.clone(), |n| format!("{n}; {line}")));
        optics.haze = Some(h.clone());
    }
    let from = if slopes.is_some() {
        "taken from the ladder's ggx, the slopes' lobe (the diffuse wave BRDF could not be computed)"
    } else {
        "fitted to the diffuse wave BRDF"
    };
    let seen_from = |h: &Haze| h.params.get("alpha").map_or(f64::INFINITY, |&a| haze_visible(a));
    let visible = optics.haze.as_ref().filter(|h| h.albedo >= seen_from(h));
    let id = if visible.is_some() { "mirror+ggx" } else { "mirror" };
    let haze = match (&optics.haze, visible) {
        (_, Some(h)) => {
            format!("; around it a haze of {:.2}% of the light, a GGX lobe of alpha {:.4} {from}", h.albedo * 100.0, h.params["alpha"])
        }
        (Some(h), None) => format!(
            "; its haze ({:.3}% of the light) is below the {:.3}% from which a haze of its roughness shows, and is left out",
            h.albedo * 100.0,
            seen_from(h) * 100.0
        ),
        (None, None) => "; the haze could not be computed (see optics.note)".to_string(),
    };
    let sentence = format!(
        "light sees a mirror ({}): {normal:.3} of it is reflected as a mirror at normal incidence and {MID_NM} nm{haze}; the answer is {id}, the ladder's {} describes the scan's slopes",
        optics.why, report.model
    );
    if let Some(sel) = report.selection.as_mut() {
        sel.answer = Some(id.to_string());
    }
    let q = &mut report.quality;
    let ndf: Vec<String> = q.reasons.iter().map(|r| format!("by the NDF alone: {r}")).collect();
    q.verdict = Verdict::Ok;
    q.reasons = std::iter::once(sentence).chain(ndf).collect();
    // The NDF's misfit and unresolved lines are about the slopes, which light does not see here.
    report.warnings.retain(|w| !(w.starts_with("misfit: ") || w.starts_with("unresolved: ")));
    report.optics = Some(optics);
    true
}

/// Where the diffuse wave BRDF could not be computed (a scan under four samples across), the haze is the
/// slopes' own lobe, the ladder's `ggx`, carrying what the mirror does not at normal incidence (`1 - s`):
/// where the mirror carries little, the rest is scattered as geometric optics says. `None` without that
/// candidate or share.
fn slopes_haze(report: &FitReport, normal: f64) -> Option<Haze> {
    let ggx = report.selection.as_ref()?.candidates.iter().find(|c| c.model == ModelId::Ggx)?;
    let alpha = *ggx.params.get("alpha").filter(|a| a.is_finite() && **a > 0.0)?;
    (0.0..=1.0).contains(&normal).then(|| Haze {
        model: ModelId::Ggx,
        params: BTreeMap::from([("alpha".to_string(), alpha)]),
        albedo: 1.0 - normal,
    })
}

/// [`optics`] of `src` with a mirror's haze ([`haze`] on a copy of the residual heights, only where the
/// regime is not geometric); a haze that cannot be computed is said in `note`.
pub fn optics_with_haze<S: BandSource<T = f64>>(src: &S) -> Optics {
    let (mut o, heights) = optics_and_heights(src);
    if let Some(h) = heights {
        add_haze(&mut o, h);
    }
    o
}

/// [`optics`] of `src` and, where the regime is not geometric, a copy of its residual heights for
/// [`add_haze`] (which the caller may run beside other work, after the scan itself is released).
pub fn optics_and_heights<S: BandSource<T = f64>>(src: &S) -> (Optics, Option<Heightfield>) {
    let o = {
        let _p = crate::phases::phase("optics.shares");
        optics(src)
    };
    if o.regime == Regime::Geometric.as_str() {
        return (o, None);
    }
    let g = src.shape();
    let mut buf = Vec::new();
    let z = src.band(0, g.ny, &mut buf).values().to_vec();
    match Scan::new(g.nx, g.ny, g.dx, g.dy, z) {
        Ok(h) => (o, Some(h)),
        Err(e) => {
            let mut o = o;
            note_no_haze(&mut o, e.message());
            (o, None)
        }
    }
}

/// Add the haze of `heights` (the scan's, from [`optics_and_heights`]) to `o`: fitted on the coherence
/// patch, else on what the scan resolves (as `mirror_shares` used); a haze that cannot be computed is said
/// in `note`.
pub fn add_haze(o: &mut Optics, heights: Heightfield) {
    let _p = crate::phases::phase("optics.haze");
    // An `Optics` read back from a report may lack the patch sides: the coherence patch stands for them.
    let side = |k: &str| o.patches.get(k).copied().filter(|s| s.is_finite() && *s > 0.0).unwrap_or(o.coherence_m);
    let (sx, sy) = (side("side_x_m"), side("side_y_m"));
    let sides = [o.coherence_m, sx.max(sy), sx.min(sy)];
    match haze(&heights, &sides) {
        Ok(h) => o.haze = Some(h),
        Err(e) => note_no_haze(o, e.message()),
    }
}

fn note_no_haze(o: &mut Optics, why: &str) {
    let line = format!("the haze could not be computed: {why}");
    o.note = Some(o.note.take().map_or(line.clone(), |n| format!("{n}; {line}")));
}
