//! Wave optics on the scan's own heights: the scalar-diffraction BRDF, split into the mirror (coherent)
//! share and the diffuse BRDF, averaged over coherence patches (docs/WAVE.md).
//!
//! Geometric optics (`ndf`, `trace`) holds where the heights vary over many wavelengths within a patch of
//! coherent light; a polished metal is smooth at that scale and reflects a sharp image. This module
//! computes what light sees at any roughness:
//!
//! - **Model** (Kirchhoff, tangent plane, with Beckmann's geometric factor; Beckmann & Spizzichino 1963
//!   ch. 3, the scalar form of Dong et al. 2015): with `v = k (w_i + w_o)`, `k = 2 pi / lambda`,
//!   `f(w_i, w_o) = k^2 / (4 pi^2 W) Q |U(v)|^2`, `U(v) = int w(x) exp(i (v_t . x + v_z h(x))) dx`,
//!   `W = int w^2`, `Q = |w_i + w_o|^4 / (4 cos_i cos_o (cos_i + cos_o)^2)`. `Q = F_B^2 cos_i / cos_o`
//!   with Beckmann's `F_B = (1 + w_i . w_o) / (cos_i (cos_i + cos_o))`; it is 1 at the mirror direction
//!   and is the factor for which stationary phase gives, on rough surfaces, exactly the microfacet BRDF
//!   of the slopes, `D(h) / (4 cos_i cos_o)` (no masking, Fresnel at the half vector), while a flat
//!   patch reflects all its light (Parseval). `Q` and `v` are symmetric in `w_i`, `w_o`: the BRDF is
//!   reciprocal.
//! - **Coherence**: the light is coherent over a patch of side `coherence` (default: sunlight,
//!   [`default_coherence_m`](crate::wave::default_coherence_m)); the scan is tiled into such patches, each windowed (Hann), and their
//!   intensities averaged.
//! - **Split**: a patch's mean field `chi = <exp(i v_z r)>` (its heights `r` about their mean) is its
//!   mirror reflection; `specular` is `<|chi|^2>` over the patches at `v_z = 2 k cos_i`, the rest is the
//!   diffuse BRDF. Both exclude Fresnel; `albedo` includes the material's at the half vector.
//! - **What the scan cannot tell**: its spacing bounds the directions, `|sin t_o - sin t_i| <= lambda /
//!   (2 dx)` per axis (beyond it the FFT folds the light back: `beyond_band` estimates that share from the
//!   slopes by geometric optics); the patch bounds the angular resolution (`lambda / coherence`); light in
//!   evanescent directions is counted in `evanescent`.
//!
//! Computation: each patch's diffuse field is transformed (rustfft) at a ladder of `v_z` levels covering
//! every wavelength and incidence asked for, the squared spectra summed over patches (rayon, in patch
//! order: the same bits on any thread count), and each output direction reads its own `v_z` between the
//! levels ([`levels`](self)). Memory: the heights, plus one spectrum per level per parallel chunk.

mod grid;
mod levels;
mod optics;
mod patches;
mod to_rgl;

use serde::Serialize;

pub use grid::{grids, write_grid_npy};
pub use optics::{mirror_shares, MirrorShares};
pub use to_rgl::{wave_rgl, MirrorBlend, WaveRglOptions, WaveTable, DEFAULT_NDF_RES, FLOOR, LIFT_DEG, WIDE_SHARE};

use crate::error::{Error, Result};
use crate::export::rgl::Material;
use crate::scan::Scan;
use levels::Levels;
use patches::{Sums, Tiling};

/// The wavelengths `ndfit wave` uses by default (nm): blue, green and red.
pub const DEFAULT_WAVELENGTHS_NM: [f64; 3] = [450.0, 550.0, 650.0];
/// The incidences `ndfit wave` uses by default (degrees from the normal).
pub const DEFAULT_INCIDENCES_DEG: [f64; 5] = [0.0, 30.0, 45.0, 60.0, 75.0];
/// The sun's angular radius seen from the Earth (rad): half of its mean angular diameter, 0.533 degrees.
pub const SUN_ANGULAR_RADIUS: f64 = 4.65e-3;
/// Largest ratio between neighbouring `v_z` levels by default.
pub const DEFAULT_LEVEL_RATIO: f64 = 1.1;
/// Smallest patch side in samples.
pub const MIN_PATCH_SAMPLES: usize = 4;
/// Fewer patches than this are reported: the diffuse BRDF then carries speckle of about
/// `1 / sqrt(patches)` per bin.
pub const FEW_PATCHES: usize = 16;
/// Largest incidence (degrees).
pub const MAX_INCIDENCE_DEG: f64 = 89.9;

/// The default coherence patch (m): the diameter of sunlight's coherence area at 550 nm, `0.16 lambda /
/// alpha` with the sun's angular radius `alpha` (Born & Wolf, Principles of Optics, 10.4.2: the region
/// where the complex degree of coherence of a uniform disk source stays above 0.88), 18.9 um.
pub fn default_coherence_m() -> f64 {
    0.16 * 550e-9 / SUN_ANGULAR_RADIUS
}

/// What to compute.
#[derive(Debug, Clone, PartialEq)]
pub struct WaveOptions {
    /// Wavelengths (nm).
    pub wavelengths_nm: Vec<f64>,
    /// Incident elevations (degrees from the normal, each in `[0, 89.9]`).
    pub incidences_deg: Vec<f64>,
    /// Incident azimuth (degrees; 0 = the scan's `+x`).
    pub azimuth_deg: f64,
    /// Side of the coherence patch (m); `None`: [`default_coherence_m`].
    pub coherence_m: Option<f64>,
    /// The conductor whose Fresnel factor `albedo` includes (`none`: 1).
    pub material: Material,
    /// Largest ratio between neighbouring `v_z` levels (accuracy against time: docs/PERFORMANCE.md).
    pub level_ratio: f64,
}

impl Default for WaveOptions {
    fn default() -> Self {
        WaveOptions {
            wavelengths_nm: DEFAULT_WAVELENGTHS_NM.to_vec(),
            incidences_deg: DEFAULT_INCIDENCES_DEG.to_vec(),
            azimuth_deg: 0.0,
            coherence_m: None,
            material: Material::None,
            level_ratio: DEFAULT_LEVEL_RATIO,
        }
    }
}

impl WaveOptions {
    /// Check every value's range (the scan's own checks are in [`Diffraction::new`]).
    pub fn validate(&self) -> Result<()> {
        if self.wavelengths_nm.is_empty() || self.wavelengths_nm.len() > 256 {
            return Err(Error::invalid(format!("give 1 to 256 wavelengths, got {}", self.wavelengths_nm.len())));
        }
        for &l in &self.wavelengths_nm {
            // NaN fails the comparison too.
            if !(l > 0.0 && l.is_finite()) {
                return Err(Error::invalid(format!("wavelength {l} nm is not a positive number")));
            }
        }
        if self.incidences_deg.is_empty() || self.incidences_deg.len() > 256 {
            return Err(Error::invalid(format!("give 1 to 256 incidences, got {}", self.incidences_deg.len())));
        }
        for &t in &self.incidences_deg {
            if !(0.0..=MAX_INCIDENCE_DEG).contains(&t) {
                return Err(Error::invalid(format!("incidence {t} deg is outside [0, {MAX_INCIDENCE_DEG}]")));
            }
        }
        if !self.azimuth_deg.is_finite() {
            return Err(Error::invalid(format!("azimuth {} deg is not a number", self.azimuth_deg)));
        }
        if let Some(c) = self.coherence_m {
            if !(c > 0.0 && c.is_finite()) {
                return Err(Error::invalid(format!("coherence patch {c} m is not a positive number")));
            }
        }
        if !(self.level_ratio > 1.0 && self.level_ratio <= 2.0) {
            return Err(Error::invalid(format!("level ratio {} is outside (1, 2]", self.level_ratio)));
        }
        Ok(())
    }

    /// The coherence patch side (m).
    pub fn coherence(&self) -> f64 {
        self.coherence_m.unwrap_or_else(default_coherence_m)
    }
}

/// The incident direction at `theta_deg` from the normal, azimuth `phi_deg`.
pub fn direction(theta_deg: f64, phi_deg: f64) -> [f64; 3] {
    let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
    [t.sin() * p.cos(), t.sin() * p.sin(), t.cos()]
}

/// Beckmann's geometric factor in the form that keeps the BRDF reciprocal (module docs):
/// `|w_i + w_o|^4 / (4 cos_i cos_o (cos_i + cos_o)^2)`.
pub fn kirchhoff_factor(wi: [f64; 3], wo: [f64; 3]) -> f64 {
    let s = [wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]];
    let n2 = s[0] * s[0] + s[1] * s[1] + s[2] * s[2];
    n2 * n2 / (4.0 * wi[2] * wo[2] * s[2] * s[2])
}

/// The patch-averaged diffraction of one scan, ready to be read at any wavelength and incidence its
/// levels cover.
#[derive(Debug, Clone)]
pub struct Diffraction {
    tiling: Tiling,
    dx: f64,
    dy: f64,
    coherence_m: f64,
    levels: Levels,
    sums: Sums,
}

/// One FFT bin seen from one wavelength and incidence.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Bin {
    /// Outgoing direction's `(x, y)` (may lie outside the unit disk: evanescent).
    pub xy: [f64; 2],
    /// `|FFT g|^2 / (P_x P_y W)` interpolated at the bin's `v_z`: its share of the light before `Q`.
    pub share: f64,
    /// The bin's full outgoing direction and `Q`, where it propagates.
    pub wo: Option<([f64; 3], f64)>,
}

impl Diffraction {
    /// Tile `scan` (heights in metres, form already removed) into coherence patches and sum their spectra
    /// at the levels that `opts`'s wavelengths and incidences need. `progress(done, total)` counts patches.
    pub fn new(scan: &Scan<'_>, opts: &WaveOptions, progress: Option<&(dyn Fn(usize, usize) + Sync)>) -> Result<Diffraction> {
        Diffraction::build(scan, opts, progress, false)
    }

    /// [`Diffraction::new`] for the light that leaves the surface alone: only the x frequencies where
    /// some outgoing direction propagates at `opts`'s wavelengths and incidences are transformed along
    /// y (on a scan sampled finely against the wavelength, a small share of them). [`Diffraction::scattered`]
    /// at those wavelengths and incidences gives what `new`'s would, to the bit; other readings of the
    /// spectra may find 0 where `new`'s do not.
    pub(crate) fn propagating(scan: &Scan<'_>, opts: &WaveOptions) -> Result<Diffraction> {
        Diffraction::build(scan, opts, None, true)
    }

    fn build(scan: &Scan<'_>, opts: &WaveOptions, progress: Option<&(dyn Fn(usize, usize) + Sync)>, prune: bool) -> Result<Diffraction> {
        opts.validate()?;
        let c = opts.coherence();
        let (px, py) = ((c / scan.dx).round(), (c / scan.dy).round());
        let um = c * 1e6;
        if px < MIN_PATCH_SAMPLES as f64 || py < MIN_PATCH_SAMPLES as f64 {
            return Err(Error::invalid(format!(
                "the coherence patch ({um:.4} um) is {px} x {py} samples of {:.4} x {:.4} um: at least {MIN_PATCH_SAMPLES} per side \
                 are needed (the scan is too coarse to resolve wave optics at this coherence)",
                scan.dx * 1e6,
                scan.dy * 1e6
            )));
        }
        if px > scan.nx as f64 || py > scan.ny as f64 {
            return Err(Error::invalid(format!(
                "the coherence patch ({um:.4} um, {px} x {py} samples) is larger than the scan ({} x {} samples, {:.4} x {:.4} um); \
                 --coherence {:.4} takes the whole scan as one patch, as `ndfit fit`'s optics do",
                scan.nx,
                scan.ny,
                scan.nx as f64 * scan.dx * 1e6,
                scan.ny as f64 * scan.dy * 1e6,
                // Rounded down, so that the patch's samples stay within the scan.
                ((scan.nx as f64 * scan.dx).min(scan.ny as f64 * scan.dy) * 1e6 * 1e4).floor() / 1e4
            )));
        }
        let tiling = Tiling::new(scan.nx, scan.ny, px as usize, py as usize);
        let intervals: Vec<(f64, f64)> = opts
            .wavelengths_nm
            .iter()
            .flat_map(|&l| opts.incidences_deg.iter().map(move |&t| (l, t)))
            .filter_map(|(l, t)| vz_interval(tiling, scan.dx, scan.dy, l, direction(t, opts.azimuth_deg)))
            .collect();
        let levels = Levels::covering(&intervals, opts.level_ratio);
        // The patch sums held at once: one per chunk in flight and the total, each a spectrum per level.
        let held = (2 * rayon::current_num_threads() + 1) as u64;
        let bytes = held.saturating_mul(levels.len() as u64).saturating_mul((tiling.px * tiling.py) as u64).saturating_mul(8);
        crate::budget::check_bytes(bytes, &format!("the spectra of {} levels of {px} x {py}-sample coherence patches", levels.len()))?;
        let columns: Vec<usize> = (0..tiling.px)
            .filter(|&kx| {
                // A bin of this x frequency propagates from `wi` only if `|v_x / k - x_i| < 1`.
                let vx = TAU * signed(kx, tiling.px) as f64 / (tiling.px as f64 * scan.dx);
                !prune
                    || opts
                        .wavelengths_nm
                        .iter()
                        .any(|&l| opts.incidences_deg.iter().any(|&t| (vx / wavenumber(l) - direction(t, opts.azimuth_deg)[0]).abs() < 1.0))
            })
            .collect();
        let sums = patches::accumulate(scan, tiling, &levels, &columns, progress);
        if sums.used == 0 {
            return Err(Error::invalid(format!(
                "no coherence patch has {:.0}% valid points ({} patches of {px} x {py} samples)",
                patches::MIN_VALID_SHARE * 100.0,
                sums.skipped
            )));
        }
        Ok(Diffraction { tiling, dx: scan.dx, dy: scan.dy, coherence_m: c, levels, sums })
    }

    /// The coherence patch side (m).
    pub fn coherence_m(&self) -> f64 {
        self.coherence_m
    }

    /// Patch side in samples (x, y).
    pub fn patch_samples(&self) -> (usize, usize) {
        (self.tiling.px, self.tiling.py)
    }

    /// Patches averaged, and patches skipped for holes.
    pub fn patches(&self) -> (usize, usize) {
        (self.sums.used, self.sums.skipped)
    }

    /// Number of `v_z` levels computed.
    pub fn levels(&self) -> usize {
        self.levels.len()
    }

    /// RMS tilt of the patches' planes (degrees): the mirror image's directions spread by about twice it.
    pub fn patch_tilt_rms_deg(&self) -> f64 {
        (self.sums.tilt2 / self.sums.weight).sqrt().atan().to_degrees()
    }

    /// The mirror share of patches whose heights are uncorrelated over many wavelengths:
    /// `<sum u^2 / (sum u)^2>`, the diffuse light that falls within a patch's own mirror lobe. A `specular`
    /// near it is no mirror.
    pub fn incoherent_floor(&self) -> f64 {
        self.sums.floor / self.sums.weight
    }

    /// The band limit: the largest `|sin t_o - sin t_i|` along x and y that the spacing resolves at
    /// `lambda_nm`.
    pub fn band(&self, lambda_nm: f64) -> [f64; 2] {
        let l = lambda_nm * 1e-9;
        [l / (2.0 * self.dx), l / (2.0 * self.dy)]
    }

    /// The mirror share (Fresnel excluded) at `lambda_nm` and incidence cosine `cos_i`: `<|chi|^2>`.
    pub fn specular(&self, lambda_nm: f64, cos_i: f64) -> f64 {
        let vz = 2.0 * wavenumber(lambda_nm) * cos_i;
        let per: Vec<f64> = self.sums.coherent.iter().map(|c| c / self.sums.weight).collect();
        self.levels.interpolate(&per, vz).clamp(0.0, 1.0)
    }

    /// Every FFT bin as an outgoing direction from `wi` at `lambda_nm`.
    pub(crate) fn bins(&self, lambda_nm: f64, wi: [f64; 3]) -> Vec<Bin> {
        self.bins_of(lambda_nm, wi, true)
    }

    /// [`Diffraction::bins`], the evanescent ones only if `evanescent`.
    fn bins_of(&self, lambda_nm: f64, wi: [f64; 3], evanescent: bool) -> Vec<Bin> {
        let k = wavenumber(lambda_nm);
        let (px, py) = (self.tiling.px, self.tiling.py);
        let norm = 1.0 / ((px * py) as f64 * self.sums.weight);
        let mut out = Vec::with_capacity(px * py);
        for kx in 0..px {
            let vx = TAU * signed(kx, px) as f64 / (px as f64 * self.dx);
            for ky in 0..py {
                let vy = TAU * signed(ky, py) as f64 / (py as f64 * self.dy);
                let xy = [vx / k - wi[0], vy / k - wi[1]];
                let r2 = xy[0] * xy[0] + xy[1] * xy[1];
                let b = kx * py + ky;
                if r2 >= 1.0 {
                    if !evanescent {
                        continue;
                    }
                    // Evanescent: read at the horizon's v_z.
                    let share = self.intensity(b, k * wi[2]) * norm;
                    out.push(Bin { xy, share, wo: None });
                    continue;
                }
                let wo = [xy[0], xy[1], (1.0 - r2).sqrt()];
                let share = self.intensity(b, k * (wi[2] + wo[2])) * norm;
                out.push(Bin { xy, share, wo: Some((wo, kirchhoff_factor(wi, wo))) });
            }
        }
        out
    }

    /// The diffuse light scattered from `wi` at `lambda_nm`: each propagating FFT bin's outgoing direction
    /// and its share of the incident power (Fresnel excluded). Their sum is the `diffuse_albedo`.
    pub fn scattered(&self, lambda_nm: f64, wi: [f64; 3]) -> Vec<([f64; 3], f64)> {
        self.bins_of(lambda_nm, wi, false).into_iter().filter_map(|b| b.wo.map(|(wo, q)| (wo, q * b.share))).collect()
    }

    /// The patch-summed intensity of bin `b` at `vz`, never negative.
    fn intensity(&self, b: usize, vz: f64) -> f64 {
        self.levels.weights(vz).iter().map(|&(l, w)| if w == 0.0 { 0.0 } else { w * self.sums.spectra[l][b] }).sum::<f64>().max(0.0)
    }

    /// The diffuse BRDF (1/sr, Fresnel excluded) at `lambda_nm` from `wi` to `wo` (unit vectors, upper
    /// hemisphere): the spectrum interpolated bilinearly between bins, each at its own `v_z`. Symmetric in
    /// `wi` and `wo`. 0 beyond the band limit.
    pub fn brdf(&self, lambda_nm: f64, wi: [f64; 3], wo: [f64; 3]) -> f64 {
        if !(wi[2] > 0.0 && wo[2] > 0.0) {
            return 0.0;
        }
        let k = wavenumber(lambda_nm);
        let (px, py) = (self.tiling.px, self.tiling.py);
        let fx = k * (wi[0] + wo[0]) * px as f64 * self.dx / TAU;
        let fy = k * (wi[1] + wo[1]) * py as f64 * self.dy / TAU;
        if fx.abs() > px as f64 / 2.0 || fy.abs() > py as f64 / 2.0 {
            return 0.0;
        }
        let vz = k * (wi[2] + wo[2]);
        let (x0, y0) = (fx.floor(), fy.floor());
        let (sx, sy) = (fx - x0, fy - y0);
        let wrap = |v: f64, n: usize| (v as i64).rem_euclid(n as i64) as usize;
        let mut i = 0.0;
        for (dxi, wx) in [(0.0, 1.0 - sx), (1.0, sx)] {
            for (dyi, wy) in [(0.0, 1.0 - sy), (1.0, sy)] {
                if wx * wy > 0.0 {
                    i += wx * wy * self.intensity(wrap(x0 + dxi, px) * py + wrap(y0 + dyi, py), vz);
                }
            }
        }
        let share = i / ((px * py) as f64 * self.sums.weight);
        let l = lambda_nm * 1e-9;
        let cell = (l / (px as f64 * self.dx)) * (l / (py as f64 * self.dy));
        kirchhoff_factor(wi, wo) * share / cell
    }

    /// The energies at one wavelength and incidence (`beyond_band` is left for [`wave`] to fill).
    pub fn record(&self, lambda_nm: f64, theta_deg: f64, phi_deg: f64, material: Material) -> WaveRecord {
        let wi = direction(theta_deg, phi_deg);
        let specular = self.specular(lambda_nm, wi[2]);
        let (mut diffuse, mut with_fresnel, mut evanescent) = (0.0, 0.0, 0.0);
        for b in self.bins(lambda_nm, wi) {
            match b.wo {
                None => evanescent += b.share,
                Some((wo, q)) => {
                    let e = q * b.share;
                    diffuse += e;
                    with_fresnel += e * material.fresnel(half_cos(wi, wo), lambda_nm);
                }
            }
        }
        let band = self.band(lambda_nm);
        let l = lambda_nm * 1e-9;
        WaveRecord {
            wavelength_nm: lambda_nm,
            theta_deg,
            phi_deg,
            specular,
            diffuse_albedo: diffuse,
            albedo: specular * material.fresnel(wi[2], lambda_nm) + with_fresnel,
            evanescent,
            band_limit: band[0].min(band[1]),
            beyond_band: f64::NAN,
            angular_step_deg: (l / self.coherence_m).min(1.0).asin().to_degrees(),
        }
    }
}

/// `2 pi`.
const TAU: f64 = std::f64::consts::TAU;

/// `2 pi / lambda` (rad/m) of a wavelength in nm.
fn wavenumber(lambda_nm: f64) -> f64 {
    TAU / (lambda_nm * 1e-9)
}

/// The signed frequency index of FFT bin `k` of `n` (the Nyquist bin of an even `n` is negative).
fn signed(k: usize, n: usize) -> i64 {
    if k < n.div_ceil(2) {
        k as i64
    } else {
        k as i64 - n as i64
    }
}

/// `w_i . h` with `h` the half vector of `wi` and `wo`.
fn half_cos(wi: [f64; 3], wo: [f64; 3]) -> f64 {
    let h = [wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]];
    let n = (h[0] * h[0] + h[1] * h[1] + h[2] * h[2]).sqrt();
    (wi[0] * h[0] + wi[1] * h[1] + wi[2] * h[2]) / n
}

/// The range of `v_z` over the propagating bins from `wi` at `lambda_nm`, if any propagates.
fn vz_interval(t: Tiling, dx: f64, dy: f64, lambda_nm: f64, wi: [f64; 3]) -> Option<(f64, f64)> {
    let k = wavenumber(lambda_nm);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for kx in 0..t.px {
        let x = TAU * signed(kx, t.px) as f64 / (t.px as f64 * dx) / k - wi[0];
        for ky in 0..t.py {
            let y = TAU * signed(ky, t.py) as f64 / (t.py as f64 * dy) / k - wi[1];
            let r2 = x * x + y * y;
            if r2 < 1.0 {
                let vz = k * (wi[2] + (1.0 - r2).sqrt());
                lo = lo.min(vz);
                hi = hi.max(vz);
            }
        }
    }
    // The mirror direction's v_z (the specular share) is always covered.
    let mirror = 2.0 * k * wi[2];
    (lo <= hi).then(|| (lo.min(mirror), hi.max(mirror)))
}

/// One wavelength and incidence of a [`WaveReport`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WaveRecord {
    /// Wavelength (nm).
    pub wavelength_nm: f64,
    /// Incident elevation (degrees).
    pub theta_deg: f64,
    /// Incident azimuth (degrees; 0 = the scan's `+x`).
    pub phi_deg: f64,
    /// The coherent share: the incident power reflected as a mirror delta, Fresnel excluded.
    pub specular: f64,
    /// The diffuse BRDF times `cos t_o` integrated over the hemisphere, Fresnel excluded.
    pub diffuse_albedo: f64,
    /// Mirror and diffuse with the material's Fresnel factor (at the normal and at the half vector).
    pub albedo: f64,
    /// Share of the light in evanescent directions (lost to the far field in this model).
    pub evanescent: f64,
    /// The largest `|sin t_o - sin t_i|` the scan's spacing resolves (the smaller of x and y).
    pub band_limit: f64,
    /// Share of the light that geometric optics of the scan's slopes sends beyond the band limit (the
    /// FFT folds it back into the band: where it is large, the diffuse BRDF is unreliable).
    pub beyond_band: f64,
    /// The angular resolution near the mirror direction (degrees): `asin(lambda / coherence)`.
    pub angular_step_deg: f64,
}

/// The patches of a [`WaveReport`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PatchReport {
    /// Side of the coherence patch (m).
    pub coherence_m: f64,
    /// Where the side comes from.
    pub coherence_source: String,
    /// Samples per patch along x and y.
    pub samples: [usize; 2],
    /// Patches averaged.
    pub used: usize,
    /// Patches skipped: fewer than 90% valid points.
    pub skipped: usize,
    /// RMS tilt of the patches' planes (degrees).
    pub tilt_rms_deg: f64,
    /// The mirror share that patches of uncorrelated heights show ([`Diffraction::incoherent_floor`]).
    pub incoherent_floor: f64,
}

/// `ndfit wave`'s report (`ndfit.wave/1`, shared/CONTRACT.md "Wave optics").
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WaveReport {
    /// `ndfit.wave/1`.
    pub schema: &'static str,
    /// The diffraction model.
    pub model: &'static str,
    /// Grid of the scan: `[nx, ny]` and spacing `[dx, dy]` (m).
    pub grid: [usize; 2],
    /// Spacing (m).
    pub spacing_m: [f64; 2],
    /// The material of `albedo`.
    pub material: String,
    /// The coherence patches.
    pub patches: PatchReport,
    /// Number of `v_z` levels and their largest ratio.
    pub levels: usize,
    /// Largest ratio between neighbouring levels.
    pub level_ratio: f64,
    /// One per wavelength and incidence (wavelengths outer).
    pub records: Vec<WaveRecord>,
    /// What the scan cannot tell, in words (few patches, light beyond the band).
    pub warnings: Vec<String>,
}

/// Compute the report of `scan` under `opts`, and the diffraction itself (for the grid and the table).
pub fn wave(scan: &Scan<'_>, opts: &WaveOptions, progress: Option<&(dyn Fn(usize, usize) + Sync)>) -> Result<(WaveReport, Diffraction)> {
    let d = Diffraction::new(scan, opts, progress)?;
    let pairs: Vec<(f64, f64)> = opts.wavelengths_nm.iter().flat_map(|&l| opts.incidences_deg.iter().map(move |&t| (l, t))).collect();
    let cases: Vec<([f64; 3], [f64; 2])> = pairs.iter().map(|&(l, t)| (direction(t, opts.azimuth_deg), d.band(l))).collect();
    let beyond = grid::geometric_beyond_band(scan, &cases);
    let mut records = Vec::new();
    for (&(l, t), b) in pairs.iter().zip(beyond) {
        let mut r = d.record(l, t, opts.azimuth_deg, opts.material);
        r.beyond_band = b;
        records.push(r);
    }
    let (used, skipped) = d.patches();
    let mut warnings = Vec::new();
    if used < FEW_PATCHES {
        warnings.push(format!(
            "only {used} coherence patches: the diffuse BRDF carries speckle of about {:.0}% per bin",
            100.0 / (used as f64).sqrt()
        ));
    }
    let floor = d.incoherent_floor();
    let low = records.iter().filter(|r| r.theta_deg <= 45.0).map(|r| r.specular).fold(f64::NAN, f64::max);
    if low < 2.0 * floor {
        warnings.push(format!(
            "the mirror share up to 45 deg ({low:.3} at most) is within twice what patches of uncorrelated heights show ({floor:.3}): no mirror, the light within each patch's own mirror lobe"
        ));
    }
    let worst = records.iter().map(|r| r.beyond_band).fold(0.0, f64::max);
    if worst > 0.01 {
        warnings.push(format!(
            "up to {:.1}% of the light leaves beyond the band the spacing resolves (|sin t_o - sin t_i| <= {:.3} at {} nm): the diffuse BRDF there is folded",
            worst * 100.0,
            d.band(opts.wavelengths_nm[0])[0].min(d.band(opts.wavelengths_nm[0])[1]),
            opts.wavelengths_nm[0]
        ));
    }
    let report = WaveReport {
        schema: "ndfit.wave/1",
        model: "kirchhoff",
        grid: [scan.nx, scan.ny],
        spacing_m: [scan.dx, scan.dy],
        material: opts.material.as_str().to_string(),
        patches: PatchReport {
            coherence_m: d.coherence_m(),
            coherence_source: if opts.coherence_m.is_some() {
                "--coherence".to_string()
            } else {
                "sunlight's coherence area at 550 nm, 0.16 lambda / alpha (Born & Wolf 10.4.2)".to_string()
            },
            samples: [d.tiling.px, d.tiling.py],
            used,
            skipped,
            tilt_rms_deg: d.patch_tilt_rms_deg(),
            incoherent_floor: d.incoherent_floor(),
        },
        levels: d.levels(),
        level_ratio: opts.level_ratio,
        records,
        warnings,
    };
    Ok((report, d))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The light that leaves the surface is the same, to the bit, whether every x frequency was
    /// transformed or only those where some bin propagates; and most of them were not needed.
    #[test]
    fn the_propagating_columns_alone_scatter_as_every_column_does() {
        let (nx, ny) = (96, 80);
        // A rough, anisotropic bump field of a few tens of nanometres.
        let z: Vec<f64> = (0..nx * ny)
            .map(|k| {
                let (x, y) = ((k % nx) as f64, (k / nx) as f64);
                3e-8 * (0.9 * x + 0.2 * y).sin()
                    + 2e-8 * (0.31 * y).cos() * (0.47 * x).sin()
                    + 1e-8 * ((x * 12.9898 + y * 78.233).sin() * 43758.5).fract()
            })
            .collect();
        let scan = Scan::new(nx, ny, 5e-8, 6e-8, z).expect("valid");
        let opts = WaveOptions {
            wavelengths_nm: vec![450.0, 650.0],
            incidences_deg: vec![0.0, 60.0],
            azimuth_deg: 30.0,
            coherence_m: Some(2.4e-6),
            ..WaveOptions::default()
        };
        let whole = Diffraction::new(&scan, &opts, None).expect("whole");
        let part = Diffraction::propagating(&scan, &opts).expect("propagating");
        let (px, py) = part.patch_samples();
        let computed = (0..px).filter(|&kx| part.sums.spectra[0][kx * py..(kx + 1) * py].iter().any(|&v| v != 0.0)).count();
        assert!(computed * 2 < px, "{computed} of {px} columns computed");
        for &l in &opts.wavelengths_nm {
            for &t in &opts.incidences_deg {
                let wi = direction(t, opts.azimuth_deg);
                let (a, b) = (whole.scattered(l, wi), part.scattered(l, wi));
                assert!(!a.is_empty() && a.len() == b.len(), "{l} nm, {t} deg: {} against {}", a.len(), b.len());
                for (x, y) in a.iter().zip(&b) {
                    assert!(x.0 == y.0 && x.1.to_bits() == y.1.to_bits(), "{l} nm, {t} deg: {x:?} against {y:?}");
                }
            }
        }
    }
}
