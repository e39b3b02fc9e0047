//! An RGL table evaluated as Mitsuba 3's `measured` plugin evaluates it (`src/bsdfs/measured.cpp`,
//! `Measured::eval`), in its `f32` arithmetic, and the analytic lobe the table is made from, both as
//! [`crate::render::Brdf`].
//!
//! The plugin's `eval(wi, wo)` is `f(wi, wo) cos(theta_o)`: with `m = normalize(wi + wo)` and the grid
//! coordinates `u(w) = (sqrt(2 theta / pi), (phi + pi) / (2 pi))`, the sample-space point
//! `s = vndf.invert(u(m); phi_i, theta_i)` and then `R(s; phi_i, theta_i, channel) ndf(u(m)) /
//! (4 sigma(u(wi)))` (Dupuy & Jakob 2018 eq. 11; the last factor only with the `jacobian` flag). Each table
//! is Mitsuba's continuous `Marginal2D` (`include/mitsuba/core/distr_2d.h`): bilinear between nodes, its
//! slices blended linearly in the parameters (`phi_i`, `theta_i`, and the channel or wavelength), the
//! `vndf` slices normalized with their marginal and conditional CDFs, which `invert` reads.

use nalgebra::Vector3;

use super::{Flavour, Material, TensorFile, RGB_NM};
use crate::error::{Error, ErrorKind, Result};
use crate::models::{MaskingShadowing, MicrofacetBrdf, Model};
use crate::render::Brdf;

/// `pi` in `f32`, as Mitsuba's `dr::Pi<Float>`.
const PI: f32 = std::f32::consts::PI;
/// `1 / (2 pi)` in `f32`, as Mitsuba's `dr::InvTwoPi<Float>`.
const INV_TWO_PI: f32 = (0.5 / std::f64::consts::PI) as f32;

/// Mitsuba's `Marginal2D<Float, D, true>`: a `w x h` bilinear density per slice, slices over `D`
/// parameters.
struct Marginal {
    /// Nodes per row (`x`, the last axis of the array) and rows (`y`).
    w: usize,
    h: usize,
    /// The node values of each parameter, first parameter outermost in the data.
    params: Vec<Vec<f32>>,
    /// Slices between successive values of each parameter (0 for a parameter of one value).
    strides: Vec<usize>,
    /// The density (normalized per slice when sampling is built).
    data: Vec<f32>,
    /// The marginal CDF over rows (`h - 1` per slice) and the conditional CDF along each row
    /// (`h (w - 1)` per slice); empty without sampling.
    marg: Vec<f32>,
    cond: Vec<f32>,
}

impl Marginal {
    /// Mitsuba's constructor with `normalize == enable_sampling == sampling`.
    fn new(data: &[f32], w: usize, h: usize, params: Vec<Vec<f32>>, sampling: bool) -> Marginal {
        let mut strides = vec![0; params.len()];
        let mut slices = 1;
        for d in (0..params.len()).rev() {
            strides[d] = if params[d].len() > 1 { slices } else { 0 };
            slices *= params[d].len();
        }
        let n = w * h;
        if !sampling {
            return Marginal { w, h, params, strides, data: data[..slices * n].to_vec(), marg: Vec::new(), cond: Vec::new() };
        }
        let (sx, sy) = (0.5 / (w - 1) as f64, 0.5 / (h - 1) as f64);
        let (mut out, mut marg, mut cond) = (Vec::with_capacity(slices * n), Vec::new(), Vec::new());
        for slice in data[..slices * n].chunks_exact(n) {
            let (c0, m0) = (cond.len(), marg.len());
            let mut row_sum = vec![0.0f64; h];
            for (y, row) in slice.chunks_exact(w).enumerate() {
                let mut acc = 0.0f64;
                for x in 0..w - 1 {
                    acc += sx * (row[x] as f64 + row[x + 1] as f64);
                    cond.push(acc as f32);
                }
                row_sum[y] = acc;
            }
            let mut acc = 0.0f64;
            for y in 0..h - 1 {
                acc += sy * (row_sum[y] + row_sum[y + 1]);
                marg.push(acc as f32);
            }
            let norm = (1.0 / acc) as f32;
            cond[c0..].iter_mut().for_each(|v| *v *= norm);
            marg[m0..].iter_mut().for_each(|v| *v *= norm);
            out.extend(slice.iter().map(|v| v * norm));
        }
        Marginal { w, h, params, strides, data: out, marg, cond }
    }

    /// The slice offset and the `(1 - t, t)` weights of each parameter (Mitsuba's
    /// `interpolate_weights` with `math::find_interval`).
    fn weights(&self, param: &[f32]) -> Weights {
        self.weights_from(param, 0, ([0; 3], [[1.0, 0.0]; 3]))
    }

    /// [`Marginal::weights`] of the parameters from `first` on, those before it already in `known`.
    fn weights_from(&self, param: &[f32], first: usize, known: Weights) -> Weights {
        let (mut index, mut wts) = known;
        for (d, vals) in self.params.iter().enumerate().skip(first) {
            // A parameter of one value has no interval: its weight is all on that value.
            if vals.len() == 1 {
                continue;
            }
            let p = param[d];
            let i = 1 + vals[1..vals.len() - 1].partition_point(|&v| v < p) - 1;
            let t = ((p - vals[i]) / (vals[i + 1] - vals[i])).clamp(0.0, 1.0);
            wts[d] = [1.0 - t, t];
            index[d] = i;
        }
        (index, wts)
    }

    /// The first slice of the blend of `index` (the lower node of each parameter).
    fn slice(&self, index: [usize; 3]) -> usize {
        self.strides.iter().zip(index).map(|(s, i)| s * i).sum()
    }

    /// `table[i0 + offset]` blended over the parameters, the first parameter outermost (Mitsuba's `lookup`).
    fn lookup(&self, table: &[f32], offset: usize, i0: usize, size: usize, wts: &[[f32; 2]; 3], dim: usize) -> f32 {
        if dim == 0 {
            return table[i0 + offset];
        }
        let i1 = i0 + self.strides[dim - 1] * size;
        let [w0, w1] = wts[dim - 1];
        let v0 = self.lookup(table, offset, i0, size, wts, dim - 1);
        let v1 = self.lookup(table, offset, i1, size, wts, dim - 1);
        v0 * w0 + v1 * w1
    }

    /// The cell of `pos` (clipped to the unit square) and the position within it.
    fn cell(&self, pos: [f32; 2]) -> ([usize; 2], [f32; 2]) {
        let (nx, ny) = ((self.w - 1) as f32, (self.h - 1) as f32);
        let (px, py) = (pos[0].clamp(0.0, 1.0) * nx, pos[1].clamp(0.0, 1.0) * ny);
        let (ix, iy) = ((px as usize).min(self.w - 2), (py as usize).min(self.h - 2));
        ([ix, iy], [px - ix as f32, py - iy as f32])
    }

    /// The bilinear density at `pos` (Mitsuba's `eval`).
    fn eval(&self, pos: [f32; 2], (index, wts): Weights) -> f32 {
        let slice = self.slice(index);
        let ([ix, iy], [tx, ty]) = self.cell(pos);
        let size = self.w * self.h;
        let i0 = ix + iy * self.w + slice * size;
        let dim = self.params.len();
        let v = |o: usize| self.lookup(&self.data, o, i0, size, &wts, dim);
        lerp(lerp(v(0), v(1), tx), lerp(v(self.w), v(self.w + 1), tx), ty)
    }

    /// The sample that `sample` would map to `pos` (Mitsuba's `invert_continuous`).
    fn invert(&self, pos: [f32; 2], (index, wts): Weights) -> [f32; 2] {
        let slice = self.slice(index);
        let (w, h) = (self.w, self.h);
        let (n_cond, n_marg, n_data) = (h * (w - 1), h - 1, w * h);
        let dim = self.params.len();
        let ([ix, iy], [mut sx, sy]) = self.cell(pos);
        let (patch_x, patch_y) = (1.0 / (w - 1) as f32, 1.0 / (h - 1) as f32);
        let i0 = slice * n_data + iy * w + ix;
        let v = |o: usize| self.lookup(&self.data, o, i0, n_data, &wts, dim);
        let (c0, c1) = (lerp(v(0), v(w), sy), lerp(v(1), v(w + 1), sy));
        sx = invert_segment(sx, patch_x, c0, c1);
        let oc = slice * n_cond + iy * (w - 1);
        let cond = |o: usize, i: usize| self.lookup(&self.cond, o, i, n_cond, &wts, dim);
        if ix > 0 {
            sx += lerp(cond(0, oc + ix - 1), cond(w - 1, oc + ix - 1), sy);
        }
        let (r0, r1) = (cond(w - 2, oc), cond(2 * (w - 1) - 1, oc));
        sx /= lerp(r0, r1, sy);
        let mut y = invert_segment(sy, patch_y, r0, r1);
        if iy > 0 {
            y += self.lookup(&self.marg, 0, slice * n_marg + iy - 1, n_marg, &wts, dim);
        }
        [sx, y]
    }
}

/// The lower node and the weights of up to three parameters.
type Weights = ([usize; 3], [[f32; 2]; 3]);

/// `a + (b - a) t` as Dr.Jit's `lerp` (`b t + (a - a t)`).
fn lerp(a: f32, b: f32, t: f32) -> f32 {
    b * t + (a - a * t)
}

/// The mass of `[0, x]` of a segment of `width` with a density linear from `v0` to `v1`.
fn invert_segment(x: f32, width: f32, v0: f32, v1: f32) -> f32 {
    x * lerp(v0, v1, 0.5 * x) * width
}

/// An RGL table read for evaluation, as Mitsuba 3's `measured` holds it.
pub struct Measured {
    ndf: Marginal,
    sigma: Marginal,
    vndf: Marginal,
    spectra: Marginal,
    /// The channel parameter of red, green and blue: `0, 1, 2` for an `rgb` table, the wavelengths
    /// [`RGB_NM`] of a spectral one.
    channels: [f32; 3],
    isotropic: bool,
    jacobian: bool,
    /// The azimuthal symmetry (1 none, 2 or 4 folds) of an anisotropic table.
    reduction: i32,
}

impl Measured {
    /// Read the fields of `t` (checked as Mitsuba's constructor checks them).
    pub fn new(t: &TensorFile) -> Result<Measured> {
        let flavour = if t.field("wavelengths").is_some() { Flavour::Spectral } else { Flavour::Rgb };
        super::check_structure(t, flavour)?;
        let values = |name: &str| t.field(name).and_then(|f| f.as_f32()).unwrap_or_default();
        let shape = |name: &str| t.field(name).map(|f| f.shape.iter().map(|&s| s as usize).collect::<Vec<_>>()).unwrap_or_default();
        let bad = |m: String| Error::new(ErrorKind::Corrupt, format!("not a measured BSDF: {m}"));
        let (theta_i, phi_i) = (values("theta_i"), values("phi_i"));
        let (ndf_s, vndf_s, refl_name) = (shape("ndf"), shape("vndf"), if flavour == Flavour::Rgb { "rgb" } else { "spectra" });
        let (sigma_s, refl_s) = (shape("sigma"), shape(refl_name));
        if ndf_s.iter().chain(&sigma_s).chain(&vndf_s[2..]).chain(&refl_s[3..]).any(|&n| n < 2) {
            return Err(bad(format!(
                "a grid of fewer than 2 nodes per axis: ndf {ndf_s:?}, sigma {sigma_s:?}, vndf {vndf_s:?}, {refl_name} {refl_s:?}"
            )));
        }
        let (lambdas, channels) = match flavour {
            Flavour::Rgb => (vec![0.0, 1.0, 2.0], [0.0, 1.0, 2.0]),
            Flavour::Spectral => (values("wavelengths"), RGB_NM.map(|v| v as f32)),
        };
        let jacobian = t.field("jacobian").is_some_and(|f| f.data.first() != Some(&0));
        let isotropic = phi_i.len() <= 2;
        let reduction = if isotropic { 1 } else { (2.0 * PI / (phi_i[phi_i.len() - 1] - phi_i[0])).round() as i32 };
        let angles = vec![phi_i.clone(), theta_i.clone()];
        Ok(Measured {
            ndf: Marginal::new(&values("ndf"), ndf_s[1], ndf_s[0], Vec::new(), false),
            sigma: Marginal::new(&values("sigma"), sigma_s[1], sigma_s[0], Vec::new(), false),
            vndf: Marginal::new(&values("vndf"), vndf_s[3], vndf_s[2], angles.clone(), true),
            spectra: Marginal::new(&values(refl_name), refl_s[4], refl_s[3], vec![phi_i, theta_i, lambdas], false),
            channels,
            isotropic,
            jacobian,
            reduction,
        })
    }

    /// Mitsuba's `Measured::eval` in its `f32` arithmetic: `f(wi, wo) cos(theta_o)` per channel, `wi`
    /// toward the camera and `wo` toward the light (local frame); 0 unless both are above the horizon.
    pub fn eval_cos(&self, wi: [f32; 3], wo: [f32; 3]) -> [f32; 3] {
        self.eval_cos_at(wi, wo, self.channels)
    }

    /// [`Measured::eval_cos`] at the channel parameters `channels`: wavelengths (nm) of a spectral table,
    /// channel indices (0 red, 1 green, 2 blue) of an `rgb` one; blended linearly between the table's
    /// nodes and held beyond its ends, as the renderer reads a spectrum.
    pub fn eval_cos_at<const N: usize>(&self, wi: [f32; 3], wo: [f32; 3], channels: [f32; N]) -> [f32; N] {
        let (mut wi, mut wo) = (wi, wo);
        if !(wi[2] > 0.0 && wo[2] > 0.0) {
            return [0.0; N];
        }
        if self.reduction >= 2 {
            // Fold into the quadrant the table covers: x, y made negative (Dr.Jit's mulsign_neg).
            let sy = wi[1];
            let sx = if self.reduction == 4 { wi[0] } else { sy };
            let neg = |v: f32, s: f32| if s.is_sign_negative() { v } else { -v };
            (wi[0], wi[1], wo[0], wo[1]) = (neg(wi[0], sx), neg(wi[1], sy), neg(wo[0], sx), neg(wo[1], sy));
        }
        let sum = [wi[0] + wo[0], wi[1] + wo[1], wi[2] + wo[2]];
        let inv = 1.0 / (sum[0] * sum[0] + sum[1] * sum[1] + sum[2] * sum[2]).sqrt();
        let m = sum.map(|v| v * inv);
        let (theta_i, phi_i) = (elevation(wi), wi[1].atan2(wi[0]));
        let (theta_m, phi_m) = (elevation(m), m[1].atan2(m[0]));
        let u_wi = [theta2u(theta_i), phi2u(phi_i)];
        let mut u_m = [theta2u(theta_m), phi2u(if self.isotropic { phi_m - phi_i } else { phi_m })];
        u_m[1] -= u_m[1].floor();
        // The vndf and reflectance tables share the incident parameters: their nodes and weights are found once.
        let incident = self.vndf.weights(&[phi_i, theta_i]);
        let sample = self.vndf.invert(u_m, incident);
        let none = self.ndf.weights(&[]);
        let scale = if self.jacobian { self.ndf.eval(u_m, none) / (4.0 * self.sigma.eval(u_wi, none)) } else { 1.0 };
        channels.map(|c| self.spectra.eval(sample, self.spectra.weights_from(&[phi_i, theta_i, c], 2, incident)) * scale)
    }
}

/// The elevation of a unit vector, as Mitsuba's `Measured::elevation` (stable near the pole).
fn elevation(d: [f32; 3]) -> f32 {
    let dist = (d[0] * d[0] + d[1] * d[1] + (d[2] - 1.0) * (d[2] - 1.0)).sqrt();
    2.0 * (0.5 * dist).clamp(-1.0, 1.0).asin()
}

fn theta2u(theta: f32) -> f32 {
    (theta * (2.0 / PI)).sqrt()
}

fn phi2u(phi: f32) -> f32 {
    (phi + PI) * INV_TWO_PI
}

impl Brdf for Measured {
    /// [`Measured::eval_cos`] divided by `cos(theta_o)`.
    fn eval(&self, wi: Vector3<f64>, wo: Vector3<f64>) -> [f64; 3] {
        let f = |v: Vector3<f64>| [v.x as f32, v.y as f32, v.z as f32];
        let (a, b) = (f(wi), f(wo));
        // The plugin tests the f32 cosines; nothing below the horizon.
        if !(a[2] > 0.0 && b[2] > 0.0) {
            return [0.0; 3];
        }
        self.eval_cos(a, b).map(|v| v as f64 / wo.z)
    }
}

/// The analytic lobe an RGL table tabulates: `D(h) G1(wi, h) G1(wo, h) F(wi.h) / (4 cos_i cos_o)`
/// (separable Smith, as Mitsuba's `roughconductor`), `F` of `material` at the wavelengths [`RGB_NM`], in
/// the scan frame (the lobe's `x` axis along the scan's `+x`, the shading tangent `s`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AnalyticBrdf {
    /// The NDF and its masking.
    pub model: Model,
    /// The conductor.
    pub material: Material,
}

impl AnalyticBrdf {
    /// `Lambda(wi)` when [`AnalyticBrdf::unshaded`] may take it once for many light points: a Smith
    /// lobe's `G1(wi, h)` is `X+(wi.h) / (1 + Lambda(wi))`. `None` for other lobes (the ellipsoid's
    /// masking, mixtures) and for `wi` below the horizon, which are evaluated point by point.
    pub fn shared_lambda(&self, wi: Vector3<f64>) -> Option<f64> {
        (self.model.smith_masking() && wi.z > 0.0).then(|| self.model.lambda(wi))
    }

    /// `f(wi, wo)` as `bare F(c)`, `F` the conductor's Fresnel term: `None` where `f` is 0 (below the
    /// horizon, masked), else `(bare, c)` with `c = wi.normalize(wi + wo)`. `lambda_i` is
    /// [`AnalyticBrdf::shared_lambda`] of `wi` (`None`: the pair's own masking, point by point).
    #[inline]
    pub fn unshaded(&self, wi: Vector3<f64>, wo: Vector3<f64>, lambda_i: Option<f64>) -> Option<(f64, f64)> {
        use crate::models::Ndf;
        let bare = match lambda_i {
            None => MicrofacetBrdf { model: self.model, eta: None, masking: MaskingShadowing::Separable }.eval(wi, wo),
            Some(lambda_i) => {
                // `MicrofacetBrdf::eval` with the separable masking and no Fresnel term, step by step.
                if !(wo.z > 0.0) {
                    return None;
                }
                let h = wi + wo;
                let h = h / h.norm();
                let g = crate::models::smith_g1(lambda_i, wi, h) * self.model.g1(wo, h);
                if g == 0.0 {
                    0.0
                } else {
                    self.model.d(h) * g / (4.0 * wi.z * wo.z)
                }
            }
        };
        // Nothing reflected (below the horizon or masked): no half vector to take.
        (bare != 0.0).then(|| (bare, wi.dot(&(wi + wo).normalize())))
    }

    /// `bare F(c)` of [`AnalyticBrdf::unshaded`], 0 for `None`.
    #[inline]
    pub fn shaded(&self, unshaded: Option<(f64, f64)>) -> [f64; 3] {
        match unshaded {
            None => [0.0; 3],
            Some((bare, c)) => self.material.fresnel_rgb(c).map(|f| bare * f),
        }
    }
}

impl Brdf for AnalyticBrdf {
    fn eval(&self, wi: Vector3<f64>, wo: Vector3<f64>) -> [f64; 3] {
        self.shaded(self.unshaded(wi, wo, None))
    }

    fn eval_many(&self, wi: Vector3<f64>, wos: &[Vector3<f64>], out: &mut [[f64; 3]]) {
        // `Lambda(wi)` once for every light point where it can be shared.
        let lambda_i = self.shared_lambda(wi);
        for (o, &wo) in out.iter_mut().zip(wos) {
            *o = self.shaded(self.unshaded(wi, wo, lambda_i));
        }
    }
}
