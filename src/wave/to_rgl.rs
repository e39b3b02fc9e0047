//! The diffuse part of the scan's wave BRDF as an RGL table (Dupuy & Jakob 2018), which Mitsuba 3's and
//! pbrt-v4's `measured` materials render; the mirror share, a delta no table can hold, beside it.
//!
//! The table has the layout `ndfit export SCAN --to rgl` writes ([`rgl::tabulate_guided`]'s incident grid,
//! `ndf`, `sigma`, `vndf` and `luminance` warps), spectral at the wavelengths asked for. The renderer
//! evaluates `f(wi, wo) cos(theta_o) = R(s) D(m) / (4 sigma(wi))` (eq. 11 with the Jacobian flag), `m` the
//! half vector and `s` the point of the sample space that the node's `vndf` warp sends to `u(m)`. At each
//! node `s` of a slice the reflectance is therefore written as
//! `R = f(wi, wo) cos(theta_o) F(wi.m) 4 sigma(wi) / D(m)`, with `f` the diffuse BRDF
//! ([`Diffraction::brdf`]), `F` the conductor's Fresnel factor at the half vector (1 for
//! [`Material::None`](crate::export::rgl::Material)), and `D`, `sigma` as the renderer reads them (bilinear
//! on their grids): at the nodes the renderer's product is the wave BRDF exactly; between them it
//! interpolates `R` bilinearly.
//!
//! **The warp's NDF.** `D` does not enter the BRDF (it cancels at the nodes), but it places the nodes, and
//! the closer `R` is to constant, the better the bilinear `R` between them. The wave BRDF depends on a pair
//! of directions through `v = k (wi + wo) = 2 k (wi.m) m` and the smooth factor `Q`: its own half-vector
//! distribution at `c = wi.m` is `D_c(m) = 4 cos_i cos_o f(wi, wo)` at the pair `wi, wo = c m +- sqrt(1 -
//! c^2) t` (`t` horizontal and across `m`, so `cos_i = cos_o = c m_z`). Where the surface is rough at the
//! wavelength, stationary phase makes `D_c` the slopes' NDF for every `c` (docs/WAVE.md, "The model") and
//! `R = sigma(wi) / cos_i`, constant per slice; where it is smooth, `D_c` is the heights' spectrum read at
//! `2 k c sin(theta_m)`, a lobe whose width grows as `1 / c`. The table's `D` is
//! `(1 - WIDE_SHARE - FLOOR) D_1 / int D_1 (m.n) dm + WIDE_SHARE B + FLOOR / pi`:
//! - `D_1`, the retro-reflection `wi = wo = m` at the middle wavelength ([`retro_ndf`]), holds the
//!   spectrum's own structure (its FFT bins, read bilinearly, and their speckle) on the `ndf` grid
//!   ([`DEFAULT_NDF_RES`] nodes, fine enough to resolve the bins) where the BRDF has it at normal incidence,
//!   and nearly so at the other wavelengths and incidences, so that `R` is smooth where the sample-space
//!   nodes could not resolve the bins. A mean of `D_c` over several `c` (the mirror lobes of other
//!   incidences) was tried: its bins lie on lattices of different scales, which no `R` is smooth against,
//!   and the table read the BRDF 2 to 18 times further off (data_formats/rgl.md, "The wave BRDF's
//!   table"). Beyond the band the spacing resolves at `c = 1` (`|2 m_x| <= lambda / (2 dx)`, which the BRDF
//!   at smaller `c` exceeds) `D_1` continues with the largest `c` whose `v` the spacing resolves: a `D`
//!   that fell to the floor there made `R` jump a thousandfold between neighbouring nodes, and a coarse
//!   rough scan's table held more than twice its albedo;
//! - `B`, [`WIDE_SHARE`] of a smooth isotropic Beckmann lobe [`WIDE`] times as wide as `D_1` (RMS slope),
//!   is where the haze of a smooth surface lives at grazing incidence (`c` small, the lobe wide), far down
//!   `D_1`'s tail: it puts nodes there and keeps `R` from growing by decades across them. It has no bins
//!   to misalign;
//! - the uniform [`FLOOR`] keeps a density at every half vector, so that the table carries light wherever
//!   the BRDF has any, Mitsuba's and pbrt's sampling (the `vndf` warp times the `luminance` warp, which
//!   follows `R` times the visible `D`: together the BRDF itself) reaches every direction that reflects,
//!   and `R` stays finite.
//!
//! The scan's geometric NDF, which `ndfit export` tabulates, would not do: on a surface smooth at the
//! wavelength, the case wave optics is for, it is the instrument's slope noise and says nothing of where the
//! diffuse light goes.
//!
//! **Near the horizon.** The diffraction's levels start at the mirror's `v_z` at the grazing node, `2 k
//! cos(89.9 deg)`, and hold their end value below it, where `Q` grows without bound as `cos_i + cos_o -> 0`:
//! a node whose `wo` lies less than [`LIFT_DEG`] above the horizon holds `f cos(theta_o)` of `wo` lifted to
//! that elevation, and the warp's `D_c` is 0 where its `v_z` would fall below the levels. A node whose `wo`
//! lies below the horizon (the `vndf` warp reaches 5 degrees below) holds 0, as the microfacet tables'
//! (`f cos(theta_o)` does not fall to 0 at the horizon here, but holding its horizon value below it made
//! Mitsuba's `luminance` warp send a fifth of the samples at 57 degrees of incidence below the horizon, for
//! no gain in accuracy).
//!
//! **Energy.** The table's albedo as the renderer evaluates it ([`Measured`], integrated over the outgoing
//! hemisphere) is set beside the diffuse part of the records (`albedo - F(cos_i) specular`, with material
//! `none` the `diffuse_albedo`) at every incident elevation node (data_formats/rgl.md, "The wave BRDF's
//! table").

use nalgebra::Vector3;
use rayon::prelude::*;

use super::{direction, wave, Diffraction, WaveOptions, WaveRecord, WaveReport, MAX_INCIDENCE_DEG};
use crate::error::Result;
use crate::export::rgl::{self, u2dir, u2theta, Field, Flavour, Measured, NdfGrids, RglOptions, SliceWarp, Table};
use crate::export::{Share, ShareForm, SHARE_WAVELENGTH_NM};
use crate::scan::Scan;

/// Nodes per axis of the `ndf` grid unless `--ndf-res` says otherwise: the largest the format takes here,
/// so that the grid resolves the spectrum's bins that `D` shares with the BRDF (at the default coherence and
/// 550 nm they are 1.7 degrees apart in the outgoing direction, 0.8 in the half vector).
pub const DEFAULT_NDF_RES: usize = 512;

/// The share of the warp's NDF that is uniform over the hemisphere (`D = 1 / pi`): every half vector keeps
/// a density.
pub const FLOOR: f64 = 1e-3;

/// The share of the warp's NDF that is a smooth isotropic Beckmann lobe `WIDE` times as wide as the
/// retro-reflection lobe (module docs). Without it, the test surface's table read the BRDF 2 to 3 times
/// further off at 70 to 80 degrees of incidence and its albedo 5% high at 80; 0.05 and 0.2 did about as
/// well as 0.1.
pub const WIDE_SHARE: f64 = 0.1;
/// Width of the smooth lobe over the RMS slope of the retro-reflection lobe.
const WIDE: f64 = 4.0;
/// Bounds of the smooth lobe's Beckmann `alpha`.
const WIDE_MIN: f64 = 0.05;
const WIDE_MAX: f64 = 1.0;

/// Beckmann's isotropic NDF, `int D (m.n) dm = 1`.
fn beckmann(alpha: f64, m: Vector3<f64>) -> f64 {
    if !(m.z > 0.0) {
        return 0.0;
    }
    let c2 = m.z * m.z;
    let a2 = alpha * alpha;
    (-(1.0 - c2) / (c2 * a2)).exp() / (std::f64::consts::PI * a2 * c2 * c2)
}

/// Elevation (degrees) to which a node's `wo` between it and the horizon is lifted (module docs).
pub const LIFT_DEG: f64 = 0.5;

/// Nodes per axis of the quadratures over the half vectors (the lobes' normalization, the table's albedo):
/// midpoints of a grid of `(u_theta, u_phi)`, whose square-root warp of the elevation resolves the narrow
/// lobes around the normal.
const QUAD: usize = 256;

/// What to compute and how to tabulate it.
#[derive(Debug, Clone, PartialEq)]
pub struct WaveRglOptions {
    /// The diffraction: wavelengths (the table's, sorted and deduplicated), coherence, the conductor
    /// whose Fresnel factor the table holds, level ratio, and the azimuth of the report's records.
    /// `incidences_deg` is not read: the report's and the levels' incidences are the table's elevation
    /// nodes ([`WaveRglOptions::incidences_deg`]).
    pub wave: WaveOptions,
    /// The table's grid: `theta_i`, `phi_i`, `ndf_res` (`None`: [`DEFAULT_NDF_RES`]), `warp_res`. Its
    /// `material` and `flavour` are not read: the table is spectral at the wave's wavelengths, with the
    /// wave's conductor.
    pub rgl: RglOptions,
}

impl Default for WaveRglOptions {
    fn default() -> Self {
        WaveRglOptions { wave: WaveOptions::default(), rgl: RglOptions { flavour: Flavour::Spectral, ..RglOptions::default() } }
    }
}

impl WaveRglOptions {
    /// The table's wavelengths (nm): the wave's, sorted, duplicates dropped.
    pub fn wavelengths_nm(&self) -> Vec<f64> {
        let mut l = self.wave.wavelengths_nm.clone();
        l.sort_by(f64::total_cmp);
        l.dedup();
        l
    }

    /// The table's incident elevation nodes (degrees), evenly from 0 to 90, the last one at
    /// [`MAX_INCIDENCE_DEG`] (the diffraction's largest incidence; the renderer reads the 90-degree node
    /// for incidences between the last two).
    pub fn incidences_deg(&self) -> Vec<f64> {
        let t = self.rgl.theta_i.max(2);
        (0..t).map(|k| (k as f64 * 90.0 / (t - 1) as f64).min(MAX_INCIDENCE_DEG)).collect()
    }

    /// The diffraction's options: the wave's, at the table's wavelengths and incidences.
    pub fn diffraction(&self) -> WaveOptions {
        WaveOptions { wavelengths_nm: self.wavelengths_nm(), incidences_deg: self.incidences_deg(), ..self.wave.clone() }
    }

    /// The table's options: its grid, spectral, with the wave's conductor.
    pub fn table(&self) -> RglOptions {
        RglOptions {
            material: self.wave.material,
            flavour: Flavour::Spectral,
            ndf_res: self.rgl.ndf_res.or(Some(DEFAULT_NDF_RES)),
            ..self.rgl
        }
    }

    /// Check every value's range (the scan's own checks are in [`Diffraction::new`]).
    pub fn validate(&self) -> Result<()> {
        self.table().check()?;
        self.diffraction().validate()
    }
}

/// The table and what was measured on the way.
#[derive(Debug, Clone)]
pub struct WaveTable {
    /// The file's fields, with three more per wavelength and incident elevation node (`[wavelengths,
    /// theta_i]`, at the report's azimuth): `mirror_share` (the records' `specular`, Fresnel excluded),
    /// `wave_diffuse` (their diffuse part with the conductor's Fresnel factor, `albedo - F(cos_i)
    /// specular`) and `table_albedo`.
    pub table: Table,
    /// `ndfit.wave/1` at the table's wavelengths and incident elevation nodes (the 90-degree node at
    /// [`MAX_INCIDENCE_DEG`]), wavelengths outer.
    pub report: WaveReport,
    /// Per record: the table's albedo as the renderer evaluates it ([`Measured`], integrated over the
    /// outgoing hemisphere), with the conductor's Fresnel factor.
    pub table_albedo: Vec<f64>,
    /// Per record: its diffuse part with the conductor's Fresnel factor, `albedo - F(cos_i) specular`
    /// (with material `none` the `diffuse_albedo`): what the table should hold.
    pub wave_diffuse: Vec<f64>,
    /// The NDF of the warps, in words: the middle wavelength and the three shares (module docs).
    pub warp_ndf: String,
}

impl WaveTable {
    /// The record with the largest `|table_albedo - wave_diffuse|` among those at most `max_theta_deg`
    /// from the normal: its index and the gap.
    pub fn worst_albedo_gap(&self, max_theta_deg: f64) -> Option<(usize, f64)> {
        (0..self.report.records.len())
            .filter(|&i| self.report.records[i].theta_deg <= max_theta_deg)
            .map(|i| (i, (self.table_albedo[i] - self.wave_diffuse[i]).abs()))
            .max_by(|a, b| a.1.total_cmp(&b.1))
    }

    /// The sidecar `OUT.bsdf.json`: the `ndfit.wave/1` report with, in each record, `table_albedo` and
    /// `wave_diffuse`, and a `table` object naming the file and its grid.
    pub fn sidecar(&self, file: &str) -> serde_json::Value {
        let mut v = serde_json::to_value(&self.report).unwrap_or_default();
        if let Some(records) = v.get_mut("records").and_then(|r| r.as_array_mut()) {
            for ((r, t), w) in records.iter_mut().zip(&self.table_albedo).zip(&self.wave_diffuse) {
                if let Some(o) = r.as_object_mut() {
                    o.insert("wave_diffuse".into(), (*w).into());
                    o.insert("table_albedo".into(), (*t).into());
                }
            }
        }
        let t = &self.table.tensor;
        let shape = |name: &str| t.field(name).map(|f| f.shape.clone()).unwrap_or_default();
        let floats = |name: &str| t.field(name).and_then(|f| f.as_f32()).unwrap_or_default();
        let vndf = shape("vndf");
        let table = serde_json::json!({
            "file": file,
            "content": "the diffuse BRDF with the conductor's Fresnel factor at the half vector; the mirror share (records' specular) is not in it",
            "wavelengths_nm": floats("wavelengths"),
            "theta_i": vndf.get(1),
            "phi_i": vndf.first(),
            "warp_res": vndf.get(2),
            "ndf_res": self.table.ndf_res,
            "warp_ndf": self.warp_ndf,
        });
        if let Some(o) = v.as_object_mut() {
            o.insert("table".into(), table);
        }
        v
    }
}

/// `D_1(m) = 4 m_z^2 f(m, m)` at `lambda_nm`: the wave BRDF's half-vector distribution at `c = wi.m = 1`,
/// and beyond the band that `c = 1` reaches, `D_c(m) = 4 cos_i cos_o f(wi, wo)` at the largest `c` whose
/// `v = 2 k c m` the spacing resolves, the pair `wi, wo = c m +- sqrt(1 - c^2) t` symmetric about `m`
/// (`t` horizontal and across it, both `c m_z` above the horizon; module docs).
fn retro_ndf(d: &Diffraction, lambda_nm: f64, vz_floor: f64, m: Vector3<f64>) -> f64 {
    if !(m.z > 0.0) {
        return 0.0;
    }
    let band = d.band(lambda_nm);
    let within = |b: f64, a: f64| if a > 0.0 { (1.0 - 1e-9) * b / (2.0 * a) } else { f64::INFINITY };
    let c = within(band[0], m.x.abs()).min(within(band[1], m.y.abs())).min(1.0);
    // Below the levels' lowest v_z the diffraction holds the end value, which Q's growth turns into light
    // that is not there: no lobe there.
    if 2.0 * std::f64::consts::TAU / (lambda_nm * 1e-9) * c * m.z < vz_floor {
        return 0.0;
    }
    let r = m.x.hypot(m.y);
    let t = if r > 1e-12 { Vector3::new(-m.y / r, m.x / r, 0.0) } else { Vector3::new(0.0, 1.0, 0.0) };
    let s = (1.0 - c * c).max(0.0).sqrt();
    let (wi, wo) = (c * m + s * t, c * m - s * t);
    4.0 * wi.z * wo.z * d.brdf(lambda_nm, wi.into(), wo.into())
}

/// The midpoints of the [`QUAD`] x [`QUAD`] grid of `(u_theta, u_phi)`: the half vector and its solid
/// angle `2 pi^2 u_theta sin(theta) du dv`.
fn half_vectors() -> Vec<(Vector3<f64>, f64)> {
    let h = 1.0 / QUAD as f64;
    (0..QUAD * QUAD)
        .map(|k| {
            let u = [((k % QUAD) as f64 + 0.5) * h, ((k / QUAD) as f64 + 0.5) * h];
            (u2dir(u), 2.0 * std::f64::consts::PI.powi(2) * u[0] * u2theta(u[0]).sin() * h * h)
        })
        .collect()
}

/// Compute the diffraction of `scan` (heights in metres, form removed) at the table's wavelengths and
/// incident elevation nodes and tabulate its diffuse BRDF with the conductor's Fresnel factor (module
/// docs). `source` names the scan in the file's `description`; `progress(done, total)` counts patches.
pub fn wave_rgl(
    scan: &Scan<'_>,
    opts: &WaveRglOptions,
    source: &str,
    progress: Option<&(dyn Fn(usize, usize) + Sync)>,
) -> Result<WaveTable> {
    opts.validate()?;
    let wopts = opts.diffraction();
    let ropts = opts.table();
    let lambdas = wopts.wavelengths_nm.clone();
    let material = wopts.material;
    let (report, d) = wave(scan, &wopts, progress)?;
    let middle_nm = lambdas[lambdas.len() / 2];
    let quad = half_vectors();
    // The levels reach down to the mirror's v_z at the grazing node, 2 k cos(89.9 deg), of every wavelength.
    let vz_floor = 2.0 * std::f64::consts::TAU / (lambdas[lambdas.len() - 1] * 1e-9) * MAX_INCIDENCE_DEG.to_radians().cos() * 1.001;
    // The lobe's normalization `int D_1 (m.n) dm` and mean squared slope; without any diffuse light the
    // uniform NDF alone.
    let (norm, slope2) = quad
        .par_iter()
        .map(|&(m, dw)| {
            let w = retro_ndf(&d, middle_nm, vz_floor, m) * m.z * dw;
            (w, w * (1.0 - m.z * m.z) / (m.z * m.z).max(1e-12))
        })
        .reduce(|| (0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    let held = norm.is_finite() && norm > 0.0;
    let alpha = if held { (WIDE * (slope2 / norm).sqrt()).clamp(WIDE_MIN, WIDE_MAX) } else { 1.0 };
    let (share, wide, uniform) = if held { ((1.0 - WIDE_SHARE - FLOOR) / norm, WIDE_SHARE, FLOOR) } else { (0.0, 0.0, 1.0) };
    let ndf = |m: Vector3<f64>| -> f64 {
        share * retro_ndf(&d, middle_nm, vz_floor, m) + wide * beckmann(alpha, m) + uniform * std::f64::consts::FRAC_1_PI
    };
    let warp_ndf = format!(
        "the wave BRDF's own half-vector distribution (retro-reflection at {middle_nm} nm, {:.3} of it), an isotropic Beckmann lobe of \
         alpha {alpha:.4} ({:.3}) and the uniform NDF ({:.3})",
        share * norm,
        wide,
        uniform
    );
    let (used, _) = d.patches();
    let (px, py) = d.patch_samples();
    let description = format!(
        "ndfit wave BRDF of {source}: the diffuse part of Kirchhoff scalar diffraction (Beckmann's factor, docs/WAVE.md) averaged over \
         {used} coherence patches of {:.2} um ({px} x {py} samples), Fresnel of the conductor {} at the half vector; the mirror share \
         (specular, Fresnel excluded) is not in the table: it is in the fields mirror_share [wavelengths, theta_i] and the report beside \
         the file; warps on an NDF of {warp_ndf}; f cos(theta_o) held below {LIFT_DEG} degrees of outgoing elevation; phi = 0 and the tangent u along the scan's +x",
        d.coherence_m() * 1e6,
        material.as_str(),
    );
    let reflectance = |grids: &NdfGrids, slices: &[SliceWarp], lambdas: &[f64]| -> Result<Vec<Vec<f64>>> {
        Ok(slices.par_iter().map(|s| slice_reflectance(&d, grids, s, lambdas, material)).collect())
    };
    let mut table = rgl::tabulate_at(&ndf, &ndf, &description, &ropts, true, &lambdas, &reflectance)?;
    let measured = Measured::new(&table.tensor)?;
    let table_albedo: Vec<f64> =
        report.records.iter().map(|r| albedo(&measured, direction(r.theta_deg, r.phi_deg), r.wavelength_nm, &quad)).collect();
    let diffuse = diffuse_part(&report.records, material);
    let (nl, nt) = (lambdas.len(), ropts.theta_i);
    let mirror: Vec<f64> = report.records.iter().map(|r| r.specular).collect();
    table.tensor.fields.push(Field::f32("mirror_share", &[nl, nt], &mirror));
    table.tensor.fields.push(Field::f32("wave_diffuse", &[nl, nt], &diffuse));
    table.tensor.fields.push(Field::f32("table_albedo", &[nl, nt], &table_albedo));
    Ok(WaveTable { table, report, table_albedo, wave_diffuse: diffuse, warp_ndf })
}

/// The table as the haze of a blend with the smooth conductor, in the form Mitsuba 3's `blendbsdf` and
/// pbrt-v4's `MixMaterial` take: `(1 - w) f_mirror + w (f_table / w)`, the table's reflectance written at
/// `1 / w`. Neither blend follows the angle or the wavelength: `w` is the constant `ndfit export` writes
/// for a mirror answer, the cosine-weighted hemispherical mean of `1 - s` of the mirror share's form at
/// 550 nm ([`ShareForm`]), fitted here to the table's records.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MirrorBlend {
    /// `w`, the haze's share of the blend.
    pub weight: f64,
    /// `1 / w`, the factor on the table's reflectance.
    pub scale: f64,
    /// The share's form it came from: `s(theta) = exp(-b cos^2 theta)`.
    pub b: f64,
}

/// Smallest blend weight written: below it the haze is a millionth of the light and the table's
/// reflectance would be scaled past what `f32` holds with room.
const MIN_BLEND_WEIGHT: f64 = 1e-6;

impl WaveTable {
    /// Make the table the haze of a blend with the smooth conductor ([`MirrorBlend`]): its `spectra`
    /// scaled by `1 / w`, a `blend_weight` field and a sentence in its `description`. The mirror too faint
    /// to give its form (every share below 0.01) blends at `w = 1`; a mirror with no haze is an error.
    pub fn blend_with_mirror(&mut self) -> Result<MirrorBlend> {
        let shares: Vec<Share> = self
            .report
            .records
            .iter()
            .map(|r| Share { theta_deg: r.theta_deg, wavelength_nm: r.wavelength_nm, weight: r.specular })
            .collect();
        let (weight, b) = match ShareForm::fit(&shares, SHARE_WAVELENGTH_NM) {
            Ok(f) => (f.mean_haze(), f.b),
            // No mirror to blend: the table is the whole material.
            Err(_) => (1.0, f64::INFINITY),
        };
        if !(weight >= MIN_BLEND_WEIGHT) {
            return Err(crate::Error::invalid(format!(
                "the haze's share of a blend is {weight:.2e} (the mirror share's form, b = {b:.3e}): the smooth conductor alone is the material"
            )));
        }
        let scale = 1.0 / weight;
        for f in self.table.tensor.fields.iter_mut() {
            if f.name == "spectra" || f.name == "rgb" {
                let v: Vec<f64> = f.as_f32().unwrap_or_default().iter().map(|&x| x as f64 * scale).collect();
                let shape: Vec<usize> = f.shape.iter().map(|&n| n as usize).collect();
                *f = Field::f32(&f.name.clone(), &shape, &v);
            }
            if f.name == "description" {
                let text = format!(
                    "{}; its reflectance written at {scale:.6} times the diffuse BRDF, for a blend that gives it weight {weight:.6} and the smooth conductor the rest",
                    String::from_utf8_lossy(&f.data)
                );
                *f = Field::u8("description", text.as_bytes());
            }
        }
        self.table.tensor.fields.push(Field::f32("blend_weight", &[1], &[weight]));
        Ok(MirrorBlend { weight, scale, b })
    }
}

/// Per record, its diffuse part with the conductor's Fresnel factor: `albedo - F(cos_i) specular`.
fn diffuse_part(records: &[WaveRecord], material: rgl::Material) -> Vec<f64> {
    records
        .iter()
        .map(|r| match material {
            rgl::Material::None => r.diffuse_albedo,
            _ => r.albedo - r.specular * material.fresnel(r.theta_deg.to_radians().cos(), r.wavelength_nm),
        })
        .collect()
}

/// The reflectance of one slice at its nodes, `channels x w x w` (module docs): the node's half vector
/// `m`, `wo` the mirror of `wi` about it (0 below the horizon; lifted to [`LIFT_DEG`] of elevation where
/// it lies lower), `R = f cos(theta_o) F(wi.h) 4 sigma(wi) / D(m)` with `h` the half vector of the pair
/// evaluated and `D`, `sigma` as the renderer reads them. A grazing node (90 degrees) is evaluated at
/// [`MAX_INCIDENCE_DEG`], as the report's records are.
fn slice_reflectance(d: &Diffraction, grids: &NdfGrids, s: &SliceWarp, lambdas: &[f64], material: rgl::Material) -> Vec<f64> {
    let n = s.w * s.w;
    let mut refl = vec![0.0; lambdas.len() * n];
    let theta = s.wi.z.clamp(-1.0, 1.0).acos().to_degrees();
    let wi = if theta > MAX_INCIDENCE_DEG { Vector3::from(direction(MAX_INCIDENCE_DEG, s.wi.y.atan2(s.wi.x).to_degrees())) } else { s.wi };
    let sigma = grids.sigma_at(wi);
    let (lift_sin, lift_cos) = LIFT_DEG.to_radians().sin_cos();
    for (k, &u) in s.nodes.iter().enumerate() {
        let m = u2dir(u);
        let dm = grids.d(m);
        let c = wi.dot(&m);
        if !(c > 0.0 && dm > 0.0) {
            continue;
        }
        let mut wo = 2.0 * c * m - wi;
        // Below the horizon: nothing, or the `luminance` warp would send samples there.
        if !(wo.z > 0.0) {
            continue;
        }
        if wo.z < lift_sin {
            let r = wo.x.hypot(wo.y);
            if !(r > 0.0) {
                continue;
            }
            wo = Vector3::new(wo.x * lift_cos / r, wo.y * lift_cos / r, lift_sin);
        }
        let h = (wi + wo).normalize();
        let scale = wo.z * 4.0 * sigma / dm;
        for (l, &nm) in lambdas.iter().enumerate() {
            refl[l * n + k] = d.brdf(nm, wi.into(), wo.into()) * material.fresnel(wi.dot(&h), nm) * scale;
        }
    }
    refl
}

/// The table's albedo at `wi` and `lambda_nm` as the renderer evaluates it: `int eval_cos(wi, wo) dwo`
/// with `dwo = 4 (wi.m) dm` over the half vectors `quad`.
fn albedo(measured: &Measured, wi: [f64; 3], lambda_nm: f64, quad: &[(Vector3<f64>, f64)]) -> f64 {
    let w = Vector3::from(wi);
    let wf = [wi[0] as f32, wi[1] as f32, wi[2] as f32];
    quad.par_iter()
        .map(|&(m, dm)| {
            let c = w.dot(&m);
            let wo = 2.0 * c * m - w;
            if !(c > 0.0 && wo.z > 0.0) {
                return 0.0;
            }
            let f = measured.eval_cos_at(wf, [wo.x as f32, wo.y as f32, wo.z as f32], [lambda_nm as f32]);
            f[0] as f64 * 4.0 * c * dm
        })
        .sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The quadrature over the half vectors integrates the cosine-weighted hemisphere to pi and a narrow
    /// lobe around the normal to its closed form.
    #[test]
    fn the_half_vector_quadrature_resolves_narrow_lobes() {
        let q = half_vectors();
        let cos: f64 = q.iter().map(|(m, w)| m.z * w).sum();
        assert!((cos - std::f64::consts::PI).abs() < 1e-4, "{cos}");
        // Beckmann at alpha = 0.01: int D (m.n) dm = 1.
        let a2 = 1e-4;
        let beckmann = |m: Vector3<f64>| {
            let t2 = (m.x * m.x + m.y * m.y) / (m.z * m.z);
            (-t2 / a2).exp() / (std::f64::consts::PI * a2 * m.z.powi(4))
        };
        let n: f64 = q.iter().map(|&(m, w)| beckmann(m) * m.z * w).sum();
        assert!((n - 1.0).abs() < 2e-3, "{n}");
    }
}
