//! A microfacet NDF as a tabulated BSDF in the RGL format of Dupuy and Jakob, "An Adaptive
//! Parameterization for Efficient Material Acquisition and Rendering" (SIGGRAPH Asia 2018), which Mitsuba 3
//! (`<bsdf type="measured">`) and pbrt-v4 (`Material "measured"`) load.
//!
//! The renderer evaluates (Dupuy & Jakob eq. 11 with the `jacobian` flag set)
//! `f(wi, wo) cos(theta_o) = R(u) D(m) / (4 sigma(wi))`, `m` the half vector, `u` the point of the sample
//! space that the visible-NDF warp sends to `m`. The table holds:
//! - `ndf`: `D(m)` on a grid of `(u_theta, u_phi) = (sqrt(2 theta / pi), (phi + pi) / (2 pi))`;
//! - `sigma`: the projected area `sigma(w) = int D(m) <w.m> dm` on the same grid, by quadrature of the
//!   tabulated NDF (so `G1(w) = cos(theta) / sigma(w)` is Smith's masking of that NDF, Heitz 2014 eq. 22);
//! - `vndf`: per incident node `D(m) <wi.m>` times the Jacobian `2 pi^2 u_theta sin(theta_m)` of the grid,
//!   the density the warp follows;
//! - `rgb` or `spectra` at the sample-space nodes: `R = F(wi.m) G1(wo)` (separable Smith, as Mitsuba's
//!   `roughconductor`), `F` the conductor of [`Material`];
//! - `luminance`: the luminance of `R` on the same nodes, the second sampling warp.
//!
//! `phi = 0` is the scan's `+x`: a renderer's tangent `u` along the scan's `+x` reproduces the scan's
//! frame. Tables are anisotropic over the full incident azimuth range `[-pi, pi]` (pbrt-v4 reads no
//! other). One file cannot serve every reader: Mitsuba's RGB variants refuse a file with `wavelengths`, and
//! pbrt-v4 and Mitsuba's spectral variants need them, so [`Flavour`] picks `rgb` or `spectra`.

pub(crate) mod conductor;
pub(crate) mod empirical;
pub(crate) mod tensor;
mod warp;

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::Vector3;
use rayon::prelude::*;

pub use conductor::Material;
pub use empirical::Regularized;
pub use tensor::{Dtype, Field, TensorFile};

use crate::error::{Error, Result};

/// Which reflectance field the file carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Flavour {
    /// `rgb` (three channels): Mitsuba 3's RGB variants.
    Rgb,
    /// `spectra` with `wavelengths`: pbrt-v4 and Mitsuba 3's spectral variants.
    Spectral,
}

/// The wavelengths (nm) the three `rgb` channels are evaluated at: the dominant wavelengths of the sRGB
/// primaries (red 612 nm, green 549 nm, blue 465 nm).
pub const RGB_NM: [f64; 3] = [612.0, 549.0, 465.0];
/// The wavelengths (nm) of a spectral table: 380 to 780 nm in 40 nm steps.
pub const SPECTRAL_NM: [f64; 11] = [380.0, 420.0, 460.0, 500.0, 540.0, 580.0, 620.0, 660.0, 700.0, 740.0, 780.0];
/// Rec. 709 luminance weights of the `rgb` channels.
const LUMA: [f64; 3] = [0.2126, 0.7152, 0.0722];

/// Resolution and reflectance of a table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RglOptions {
    /// Incident elevations, evenly from 0 to 90 degrees (at least 2).
    pub theta_i: usize,
    /// Incident azimuths, evenly over `[-pi, pi]` both ends included (at least 3).
    pub phi_i: usize,
    /// Nodes per axis of the `ndf` and `sigma` grids (at least 8).
    pub ndf_res: usize,
    /// Nodes per axis of the `vndf`, `luminance` and reflectance grids (at least 4).
    pub warp_res: usize,
    /// The conductor.
    pub material: Material,
    /// `rgb` or `spectra`.
    pub flavour: Flavour,
}

impl Default for RglOptions {
    fn default() -> Self {
        RglOptions { theta_i: 16, phi_i: 17, ndf_res: 64, warp_res: 32, material: Material::None, flavour: Flavour::Rgb }
    }
}

/// Largest nodes per axis accepted (a 512 x 512 warp over 64 x 64 incident nodes is already 4 GiB).
const MAX_RES: usize = 512;

impl RglOptions {
    fn check(&self) -> Result<()> {
        let bad = |name: &str, v: usize, lo: usize| Error::invalid(format!("{name} must be in [{lo}, {MAX_RES}], got {v}"));
        for (name, v, lo) in
            [("theta_i", self.theta_i, 2), ("phi_i", self.phi_i, 3), ("ndf_res", self.ndf_res, 8), ("warp_res", self.warp_res, 4)]
        {
            if !(lo..=MAX_RES).contains(&v) {
                return Err(bad(name, v, lo));
            }
        }
        Ok(())
    }

    /// The wavelengths of the reflectance channels (nm).
    pub fn wavelengths(&self) -> &'static [f64] {
        match self.flavour {
            Flavour::Rgb => &RGB_NM,
            Flavour::Spectral => &SPECTRAL_NM,
        }
    }

    /// Bytes of the file these options write (header aside).
    pub fn data_bytes(&self) -> usize {
        let slices = self.theta_i * self.phi_i * self.warp_res * self.warp_res;
        4 * (2 * self.ndf_res * self.ndf_res + slices * (2 + self.wavelengths().len()) + self.theta_i + self.phi_i)
    }
}

/// `theta` of the grid coordinate `u` (Dupuy & Jakob's square-root warp of the elevation).
pub fn u2theta(u: f64) -> f64 {
    u * u * FRAC_PI_2
}

/// `phi` of the grid coordinate `u`.
pub fn u2phi(u: f64) -> f64 {
    (2.0 * u - 1.0) * PI
}

/// The grid coordinates of direction `w` (`z` up).
pub fn dir2u(w: Vector3<f64>) -> [f64; 2] {
    let theta = w.z.clamp(-1.0, 1.0).acos();
    [(theta / FRAC_PI_2).sqrt(), (w.y.atan2(w.x) + PI) / (2.0 * PI)]
}

/// The direction of grid coordinates `(u_theta, u_phi)`.
pub fn u2dir(u: [f64; 2]) -> Vector3<f64> {
    let (st, ct) = u2theta(u[0]).sin_cos();
    let (sp, cp) = u2phi(u[1]).sin_cos();
    Vector3::new(cp * st, sp * st, ct)
}

/// Bilinear interpolation of `data` (`n x n` nodes, `x` fastest) at `u`, clamped to the unit square, as
/// both renderers interpolate `ndf` and `sigma`.
pub fn bilinear(data: &[f64], n: usize, u: [f64; 2]) -> f64 {
    let f = |t: f64| {
        let p = t.clamp(0.0, 1.0) * (n - 1) as f64;
        let i = (p as usize).min(n - 2);
        (i, p - i as f64)
    };
    let ((i, tx), (j, ty)) = (f(u[0]), f(u[1]));
    let v = |i: usize, j: usize| data[j * n + i];
    (1.0 - ty) * ((1.0 - tx) * v(i, j) + tx * v(i + 1, j)) + ty * ((1.0 - tx) * v(i, j + 1) + tx * v(i + 1, j + 1))
}

/// A table built, with what the writer measured on the way.
#[derive(Debug, Clone)]
pub struct Table {
    /// The file's fields.
    pub tensor: TensorFile,
    /// `int D(m) (m.n) dm` of the source NDF over the grid before any rescaling (1 for a normalized NDF).
    pub normalization: f64,
}

/// Three-point Gauss-Legendre nodes and weights on `[0, 1]`.
const GAUSS3: [(f64, f64); 3] = [(0.112_701_665_379_258_3, 5.0 / 18.0), (0.5, 8.0 / 18.0), (0.887_298_334_620_741_7, 5.0 / 18.0)];

/// Tabulate the NDF `d` (scan frame, `z` up; normalized or not) as an RGL tensor file. `renormalize`
/// rescales `d` so that the table's `int D (m.n) dm` is 1 (for an empirical NDF; a model is already
/// normalized and is written as it is). `description` becomes the file's `description` field.
pub fn tabulate(d: &(dyn Fn(Vector3<f64>) -> f64 + Sync), description: &str, opts: &RglOptions, renormalize: bool) -> Result<Table> {
    opts.check()?;
    let n = opts.ndf_res;
    let step = 1.0 / (n - 1) as f64;
    // The NDF on the grid nodes.
    let mut ndf: Vec<f64> = (0..n * n).into_par_iter().map(|k| d(u2dir([(k % n) as f64 * step, (k / n) as f64 * step]))).collect();
    if let Some(bad) = ndf.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
        return Err(Error::invalid(format!("the NDF has a value {bad} (not finite and >= 0) on the table's grid")));
    }
    // Quadrature over the hemisphere in grid coordinates: dw = 2 pi^2 u_theta sin(theta) du_theta du_phi.
    let quad: Vec<(Vector3<f64>, f64)> = (0..(n - 1) * (n - 1))
        .into_par_iter()
        .flat_map_iter(|c| {
            let (i, j) = (c % (n - 1), c / (n - 1));
            GAUSS3.iter().flat_map(move |&(gx, wx)| {
                GAUSS3.iter().map(move |&(gy, wy)| {
                    let u = [(i as f64 + gx) * step, (j as f64 + gy) * step];
                    let m = u2dir(u);
                    let jac = 2.0 * PI * PI * u[0] * u2theta(u[0]).sin();
                    (m, d(m) * jac * wx * wy * step * step)
                })
            })
        })
        .collect();
    let normalization: f64 = quad.iter().map(|(m, w)| w * m.z).sum();
    if !(normalization.is_finite() && normalization > 0.0) {
        return Err(Error::invalid("the NDF has no weight on the hemisphere; nothing to tabulate"));
    }
    let scale = if renormalize { 1.0 / normalization } else { 1.0 };
    ndf.iter_mut().for_each(|v| *v *= scale);
    // The projected area of the tabulated NDF, on the same grid.
    let sigma: Vec<f64> = (0..n * n)
        .into_par_iter()
        .map(|k| {
            let w = u2dir([(k % n) as f64 * step, (k / n) as f64 * step]);
            scale * quad.iter().map(|(m, q)| q * w.dot(m).max(0.0)).sum::<f64>()
        })
        .collect();

    let theta_i: Vec<f64> = (0..opts.theta_i).map(|k| k as f64 * FRAC_PI_2 / (opts.theta_i - 1) as f64).collect();
    let phi_i: Vec<f64> = (0..opts.phi_i).map(|k| -PI + k as f64 * 2.0 * PI / (opts.phi_i - 1) as f64).collect();
    let lambdas = opts.wavelengths();
    let w = opts.warp_res;
    let wstep = 1.0 / (w - 1) as f64;
    let slices: Vec<(f64, f64)> = phi_i.iter().flat_map(|&p| theta_i.iter().map(move |&t| (p, t))).collect();
    let per_slice: Vec<(Vec<f64>, Vec<f64>, Vec<f64>)> = slices
        .par_iter()
        .map(|&(phi, theta)| {
            let wi = Vector3::new(phi.cos() * theta.sin(), phi.sin() * theta.sin(), theta.cos());
            // The visible NDF in grid coordinates, rounded to f32 as the renderer stores it.
            let vndf: Vec<f64> = (0..w * w)
                .map(|k| {
                    let u = [(k % w) as f64 * wstep, (k / w) as f64 * wstep];
                    let m = u2dir(u);
                    let v = scale * d(m) * wi.dot(&m).max(0.0) * 2.0 * PI * PI * u[0] * u2theta(u[0]).sin();
                    v as f32 as f64
                })
                .collect();
            let warp = warp::Bilinear::new(&vndf, w, w);
            let mut refl = vec![0.0; lambdas.len() * w * w];
            let mut lum = vec![0.0; w * w];
            for k in 0..w * w {
                let m = u2dir(warp.sample([(k % w) as f64 * wstep, (k / w) as f64 * wstep]));
                let c = wi.dot(&m);
                let wo = 2.0 * c * m - wi;
                // Smith masking of the outgoing direction from the tabulated projected area; none below the horizon.
                let s = bilinear(&sigma, n, dir2u(wo));
                let g1 = if wo.z > 0.0 && s > 0.0 { (wo.z / s).min(1.0) } else { 0.0 };
                for (l, &nm) in lambdas.iter().enumerate() {
                    refl[l * w * w + k] = opts.material.fresnel(c, nm) * g1;
                }
                lum[k] = match opts.flavour {
                    Flavour::Rgb => (0..3).map(|l| LUMA[l] * refl[l * w * w + k]).sum(),
                    Flavour::Spectral => (0..lambdas.len()).map(|l| refl[l * w * w + k]).sum::<f64>() / lambdas.len() as f64,
                };
            }
            // A slice that reflects nothing (grazing incidence on a very rough NDF) still needs a density to
            // normalize: a uniform one, whose samples all carry the zero reflectance.
            if !lum.iter().any(|&v| v > 0.0) {
                lum.iter_mut().for_each(|v| *v = 1.0);
            }
            (vndf, lum, refl)
        })
        .collect();

    let (np, nt, nl) = (opts.phi_i, opts.theta_i, lambdas.len());
    let vndf: Vec<f64> = per_slice.iter().flat_map(|s| s.0.iter().copied()).collect();
    let luminance: Vec<f64> = per_slice.iter().flat_map(|s| s.1.iter().copied()).collect();
    let refl: Vec<f64> = per_slice.iter().flat_map(|s| s.2.iter().copied()).collect();
    let mut fields = vec![
        Field::u8("description", description.as_bytes()),
        Field::u8("jacobian", &[1]),
        Field::f32("theta_i", &[nt], &theta_i),
        Field::f32("phi_i", &[np], &phi_i),
        Field::f32("ndf", &[n, n], &ndf),
        Field::f32("sigma", &[n, n], &sigma),
        Field::f32("vndf", &[np, nt, w, w], &vndf),
        Field::f32("luminance", &[np, nt, w, w], &luminance),
    ];
    match opts.flavour {
        Flavour::Rgb => fields.push(Field::f32("rgb", &[np, nt, 3, w, w], &refl)),
        Flavour::Spectral => {
            fields.push(Field::f32("wavelengths", &[nl], lambdas));
            fields.push(Field::f32("spectra", &[np, nt, nl, w, w], &refl));
        }
    }
    Ok(Table { tensor: TensorFile { fields }, normalization })
}

/// Check `t` field by field against what a reader of `flavour` requires (the conditions of Mitsuba 3's
/// `Measured` and pbrt-v4's `MeasuredBxDFData::Create`): the fields present with their types and ranks,
/// the shapes agreeing, and for anisotropic tables an incident azimuth range of one full turn (pbrt-v4
/// refuses any other). Returns the first violation.
pub fn check_structure(t: &TensorFile, flavour: Flavour) -> Result<()> {
    use tensor::Dtype::{Float32, UInt8};
    let bad = |m: String| Error::new(crate::ErrorKind::Corrupt, format!("not a measured BSDF: {m}"));
    let get = |name: &str, dtype: tensor::Dtype, rank: usize| -> Result<&Field> {
        let f = t.field(name).ok_or_else(|| bad(format!("no field '{name}'")))?;
        if f.dtype != dtype || f.shape.len() != rank {
            return Err(bad(format!("field '{name}' is {:?} of rank {}, expected {dtype:?} of rank {rank}", f.dtype, f.shape.len())));
        }
        Ok(f)
    };
    get("description", UInt8, 1)?;
    let jac = get("jacobian", UInt8, 1)?;
    if jac.shape[0] != 1 {
        return Err(bad("field 'jacobian' must hold one value".into()));
    }
    let theta_i = get("theta_i", Float32, 1)?;
    let phi_i = get("phi_i", Float32, 1)?;
    get("ndf", Float32, 2)?;
    get("sigma", Float32, 2)?;
    let vndf = get("vndf", Float32, 4)?;
    let lum = get("luminance", Float32, 4)?;
    let (refl, channels) = match flavour {
        Flavour::Rgb => {
            if t.field("wavelengths").is_some() {
                return Err(bad("an RGB file must not have 'wavelengths' (Mitsuba's RGB variants refuse it)".into()));
            }
            (get("rgb", Float32, 5)?, 3)
        }
        Flavour::Spectral => (get("spectra", Float32, 5)?, get("wavelengths", Float32, 1)?.shape[0]),
    };
    let (np, nt) = (phi_i.shape[0], theta_i.shape[0]);
    let ok = vndf.shape[..2] == [np, nt]
        && lum.shape[..2] == [np, nt]
        && lum.shape[2] == lum.shape[3]
        && refl.shape[..3] == [np, nt, channels]
        && refl.shape[3] == refl.shape[4]
        && lum.shape[2..] == refl.shape[3..];
    if !ok {
        return Err(bad(format!(
            "shapes disagree: phi_i {np}, theta_i {nt}, vndf {:?}, luminance {:?}, reflectance {:?}",
            vndf.shape, lum.shape, refl.shape
        )));
    }
    if np > 2 {
        let p = phi_i.as_f32().unwrap_or_default();
        let reduction = (2.0 * std::f32::consts::PI / (p[p.len() - 1] - p[0])).round();
        if reduction != 1.0 {
            return Err(bad(format!("incident azimuths span 2 pi / {reduction}, pbrt-v4 reads only a full turn")));
        }
    }
    for f in &t.fields {
        if f.shape.contains(&0) {
            return Err(bad(format!("field '{}' is empty", f.name.escape_debug())));
        }
    }
    Ok(())
}
