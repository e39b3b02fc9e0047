//! The mirror share alone, for every scan `auto` fits: the same patches, window and mean field as
//! [`Diffraction`](super::Diffraction) (patches.rs), `|chi|^2` read at exactly `v_z = 2 k cos t_i` for
//! each wavelength and incidence. One `sin_cos` per sample per pair and no spectrum: a fraction of the
//! cost of the diffuse BRDF.
//!
//! It never refuses a scan that the NDF reads: where the spacing does not resolve the coherence patch
//! (fewer than [`MIN_PATCH_SAMPLES`] per side), patches of that many samples stand for it, and a scan
//! smaller than a patch is one patch; `patch_m` and `note` say so.

use rayon::prelude::*;
use serde::Serialize;

use super::patches::{centre, hann};
use super::{wavenumber, MIN_PATCH_SAMPLES};
use crate::scan::BandSource;

/// What [`mirror_shares`] measured.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MirrorShares {
    /// The coherence patch asked for (m).
    pub coherence_m: f64,
    /// The patch used (m, along x and y): the coherence patch, or what the scan resolves (`note`).
    pub patch_m: [f64; 2],
    /// Samples per patch along x and y.
    pub samples: [usize; 2],
    /// Patches averaged, and patches skipped (fewer than 90% valid points).
    pub used: usize,
    /// Patches skipped.
    pub skipped: usize,
    /// Wavelengths (nm).
    pub wavelength_nm: Vec<f64>,
    /// Incidences (degrees).
    pub theta_deg: Vec<f64>,
    /// The mirror share `<|chi|^2>` at each wavelength (outer) and incidence; 0 where no patch is used.
    pub shares: Vec<f64>,
    /// RMS tilt of the patches' planes (degrees).
    pub tilt_rms_deg: f64,
    /// RMS slope angle of the scan at its own spacing (degrees; forward differences within patches).
    pub slope_rms_deg: f64,
    /// The share patches of uncorrelated heights show ([`Diffraction::incoherent_floor`](super::Diffraction::incoherent_floor)).
    pub incoherent_floor: f64,
    /// The largest, over the wavelengths, share of the light at normal incidence that geometric optics of
    /// the slopes sends beyond the band the spacing resolves (`|2 s / (1 + |s|^2)| > lambda / (2 dx)` per axis).
    pub beyond_band: f64,
    /// Why the patch is not the coherence patch, if it is not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub note: Option<String>,
}

impl MirrorShares {
    /// The share at wavelength index `l` and incidence index `t`.
    pub fn share(&self, l: usize, t: usize) -> f64 {
        self.shares[l * self.theta_deg.len() + t]
    }
}

/// Sums over patches (and, for slopes, over sample pairs), added in patch order.
#[derive(Debug, Clone, Default)]
struct Acc {
    coherent: Vec<f64>,
    weight: f64,
    tilt2: f64,
    floor: f64,
    used: usize,
    skipped: usize,
    slope2: f64,
    pairs: f64,
    beyond: Vec<f64>,
    points: f64,
}

impl Acc {
    fn add(mut self, o: Acc) -> Acc {
        if self.coherent.is_empty() {
            return o;
        }
        self.coherent.iter_mut().zip(&o.coherent).for_each(|(a, b)| *a += b);
        self.beyond.iter_mut().zip(&o.beyond).for_each(|(a, b)| *a += b);
        self.weight += o.weight;
        self.tilt2 += o.tilt2;
        self.floor += o.floor;
        self.used += o.used;
        self.skipped += o.skipped;
        self.slope2 += o.slope2;
        self.pairs += o.pairs;
        self.points += o.points;
        self
    }
}

/// The patch side in samples along one axis of `n` samples at spacing `d` for a coherence `c`.
fn side(c: f64, d: f64, n: usize) -> usize {
    ((c / d).round().max(MIN_PATCH_SAMPLES as f64) as usize).min(n).max(1)
}

/// The mirror share of `src` (residual heights in metres) at every wavelength (nm) and incidence
/// (degrees), over coherence patches of side `coherence_m` (module docs).
pub fn mirror_shares<S: BandSource<T = f64>>(src: &S, wavelengths_nm: &[f64], incidences_deg: &[f64], coherence_m: f64) -> MirrorShares {
    let g = src.shape();
    let (px, py) = (side(coherence_m, g.dx, g.nx), side(coherence_m, g.dy, g.ny));
    let note = patch_note(coherence_m, [g.dx, g.dy], [g.nx, g.ny], [px, py]);
    let (cols, rows) = (g.nx / px, g.ny / py);
    let (j0, i0) = ((g.nx - cols * px) / 2, (g.ny - rows * py) / 2);
    let vz: Vec<f64> =
        wavelengths_nm.iter().flat_map(|&l| incidences_deg.iter().map(move |&t| 2.0 * wavenumber(l) * t.to_radians().cos())).collect();
    let bands: Vec<[f64; 2]> = wavelengths_nm.iter().map(|&l| [l * 1e-9 / (2.0 * g.dx), l * 1e-9 / (2.0 * g.dy)]).collect();
    let (wx, wy) = (hann(px), hann(py));
    let zero = || Acc { coherent: vec![0.0; vz.len()], beyond: vec![0.0; bands.len()], ..Acc::default() };
    let few = rows < rayon::current_num_threads();
    let parts: Vec<Acc> = (0..rows)
        .into_par_iter()
        .map_init(
            || (Vec::new(), vec![0.0; px * py], vec![0.0; px * py], vec![0.0; px * py]),
            |(buf, r, u, wm), pi| {
                let mut acc = zero();
                let lo = i0 + pi * py;
                let band = src.band(lo, lo + py, buf);
                let z = band.values();
                for pj in 0..cols {
                    let j = j0 + pj * px;
                    let row = |i: usize| &z[i * g.nx + j..i * g.nx + j + px];
                    let Some(c) = centre(row, px, [g.dx, g.dy], &wx, &wy, r, u, wm) else {
                        acc.skipped += 1;
                        continue;
                    };
                    acc.used += 1;
                    acc.weight += c.s1;
                    acc.tilt2 += c.s1 * c.tan2;
                    acc.floor += u.iter().map(|x| x * x).sum::<f64>() / c.s1;
                    // Too few rows of patches to share out: the levels side by side (each sum as it is).
                    let fields: Vec<(f64, f64)> = if few {
                        vz.par_iter().map(|&v| mean_field(r, u, v)).collect()
                    } else {
                        vz.iter().map(|&v| mean_field(r, u, v)).collect()
                    };
                    for (a, (cr, ci)) in acc.coherent.iter_mut().zip(fields) {
                        *a += (cr * cr + ci * ci) / c.s1;
                    }
                    slopes(r, u, px, py, [g.dx, g.dy], &bands, &mut acc);
                }
                acc
            },
        )
        .collect();
    let acc = parts.into_iter().fold(zero(), Acc::add);
    let per = |x: f64| if acc.weight > 0.0 { x / acc.weight } else { 0.0 };
    MirrorShares {
        coherence_m,
        patch_m: [px as f64 * g.dx, py as f64 * g.dy],
        samples: [px, py],
        used: acc.used,
        skipped: acc.skipped,
        wavelength_nm: wavelengths_nm.to_vec(),
        theta_deg: incidences_deg.to_vec(),
        shares: acc.coherent.iter().map(|&c| per(c).clamp(0.0, 1.0)).collect(),
        tilt_rms_deg: per(acc.tilt2).sqrt().atan().to_degrees(),
        slope_rms_deg: if acc.pairs > 0.0 { (acc.slope2 / acc.pairs).sqrt().atan().to_degrees() } else { 0.0 },
        incoherent_floor: per(acc.floor),
        beyond_band: acc.beyond.iter().map(|&b| if acc.points > 0.0 { b / acc.points } else { 0.0 }).fold(0.0, f64::max),
        note,
    }
}

/// `sum u exp(i v r)` as (real, imaginary), four samples at a time (a masked point has `u = 0` and adds
/// nothing); the sums run in index order whatever the threads.
fn mean_field(r: &[f64], u: &[f64], v: f64) -> (f64, f64) {
    use wide::f64x4;
    let (mut cr, mut ci) = (f64x4::ZERO, f64x4::ZERO);
    let vv = f64x4::splat(v);
    let (r4, u4) = (r.chunks_exact(4), u.chunks_exact(4));
    let (rt, ut) = (r4.remainder(), u4.remainder());
    for (rk, uk) in r4.zip(u4) {
        let (s, c) = (vv * f64x4::new([rk[0], rk[1], rk[2], rk[3]])).sin_cos();
        let w = f64x4::new([uk[0], uk[1], uk[2], uk[3]]);
        cr += w * c;
        ci += w * s;
    }
    let (mut re, mut im) = (cr.reduce_add(), ci.reduce_add());
    for (&rk, &uk) in rt.iter().zip(ut) {
        let (s, c) = (v * rk).sin_cos();
        re += uk * c;
        im += uk * s;
    }
    (re, im)
}

/// Add a patch's forward-difference slopes (valid pairs only) and, at normal incidence, the points whose
/// mirror direction leaves each band.
fn slopes(r: &[f64], u: &[f64], px: usize, py: usize, d: [f64; 2], bands: &[[f64; 2]], acc: &mut Acc) {
    for i in 0..py {
        for j in 0..px {
            let k = i * px + j;
            if u[k] == 0.0 {
                continue;
            }
            let sx = (j + 1 < px && u[k + 1] > 0.0).then(|| (r[k + 1] - r[k]) / d[0]);
            let sy = (i + 1 < py && u[k + px] > 0.0).then(|| (r[k + px] - r[k]) / d[1]);
            // Each axis counts its own pairs: RMS slope^2 = <s_x^2> + <s_y^2>, both as means over pairs.
            if let Some(s) = sx {
                acc.slope2 += s * s * 0.5;
                acc.pairs += 0.5;
            }
            if let Some(s) = sy {
                acc.slope2 += s * s * 0.5;
                acc.pairs += 0.5;
            }
            let (Some(sx), Some(sy)) = (sx, sy) else { continue };
            // The mirror direction from the normal: w_o + w_i = 2 m_z m = (-2 s, 2) / (1 + |s|^2).
            let q = 1.0 + sx * sx + sy * sy;
            acc.points += 1.0;
            for (b, band) in acc.beyond.iter_mut().zip(bands) {
                if (2.0 * sx / q).abs() > band[0] || (2.0 * sy / q).abs() > band[1] {
                    *b += 1.0;
                }
            }
        }
    }
}

/// Why the patch is not the coherence patch: the spacing does not resolve it, or the scan is smaller.
fn patch_note(c: f64, d: [f64; 2], n: [usize; 2], p: [usize; 2]) -> Option<String> {
    let want = [(c / d[0]).round(), (c / d[1]).round()];
    let um = c * 1e6;
    if want[0] < MIN_PATCH_SAMPLES as f64 || want[1] < MIN_PATCH_SAMPLES as f64 {
        return Some(format!(
            "the coherence patch ({um:.1} um) is under {MIN_PATCH_SAMPLES} samples of {:.3} x {:.3} um: patches of {} x {} samples stand for it (the scan does not resolve wave optics at that coherence)",
            d[0] * 1e6,
            d[1] * 1e6,
            p[0],
            p[1]
        ));
    }
    if want[0] > n[0] as f64 || want[1] > n[1] as f64 {
        return Some(format!(
            "the coherence patch ({um:.1} um) is larger than the scan ({:.1} x {:.1} um): the whole scan is one patch",
            n[0] as f64 * d[0] * 1e6,
            n[1] as f64 * d[1] * 1e6
        ));
    }
    None
}
