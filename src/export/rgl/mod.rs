//! A microfacet NDF as a tabulated BSDF in the RGL format of Dupuy and Jakob, "An Adaptive
//! Parameterization for Efficient Material Acquisition and Rendering" (SIGGRAPH Asia 2018), which Mitsuba 3
//! (`<bsdf type="measured">`) and pbrt-v4 (`Material "measured"`) load.
//!
//! The renderer evaluates (Dupuy & Jakob eq. 11 with the `jacobian` flag set)
//! `f(wi, wo) cos(theta_o) = R(u) D(m) / (4 sigma(wi))`, `m` the half vector, `u` the point of the sample
//! space that the visible-NDF warp sends to `m`. The table holds:
//! - `ndf`: `D(m)` on a grid of `(u_theta, u_phi) = (sqrt(2 theta / pi), (phi + pi) / (2 pi))`;
//! - `sigma`: the projected area `sigma(w) = int D(m) <w.m> dm` on a grid of its own, by quadrature of the
//!   tabulated NDF (so `G1(w) = cos(theta) / sigma(w)` is Smith's masking of that NDF, Heitz 2014 eq. 22);
//! - `vndf`: per incident node the density the warp follows, a defensive mixture of the visible NDF
//!   `D(m) <wi.m>` (times the Jacobian `2 pi^2 u_theta sin(theta_m)` of the grid) and its tempered power
//!   ([`DEFENSIVE`]), so that the reflectance's nodes reach down the NDF's tail;
//! - `rgb` or `spectra` at the sample-space nodes: `R = F(wi.m) G1(wo)` (separable Smith, as Mitsuba's
//!   `roughconductor`), `F` the conductor of [`Material`];
//! - `luminance`: the luminance of `R` times the visible NDF over the written `vndf` on the same nodes, the
//!   second sampling warp: the two warps together sample the visible NDF times the luminance.
//!
//! The `ndf` grid is as fine as the NDF needs ([`ndf_resolution`]). Measured in Mitsuba 3
//! (fits/tests/test_mitsuba_rgl.py, data_formats/rgl.md "The tails"): at the default resolution a table
//! reproduces its BRDF wherever the BRDF is at least `1e-3` of its peak; the outgoing directions within a
//! few degrees of the horizon, where the masking is steep, are the hardest.
//!
//! `phi = 0` is the scan's `+x`: a renderer's tangent `u` along the scan's `+x` reproduces the scan's
//! frame. Tables are anisotropic over the full incident azimuth range `[-pi, pi]` (pbrt-v4 reads no
//! other). One file cannot serve every reader: Mitsuba's RGB variants refuse a file with `wavelengths`, and
//! pbrt-v4 and Mitsuba's spectral variants need them, so [`Flavour`] picks `rgb` or `spectra`.

pub(crate) mod conductor;
pub(crate) mod empirical;
pub(crate) mod measured;
pub(crate) mod tensor;
pub(crate) mod warp;

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::Vector3;
use rayon::prelude::*;

pub use conductor::Material;
pub use empirical::{BinNodes, Regularized};
pub use measured::{AnalyticBrdf, Measured};
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
    /// Nodes per axis of the `ndf` grid (at least 8); `None` picks the smallest of 64, 128, 256 and 512 at
    /// which the renderer's bilinear interpolation reproduces the NDF ([`ndf_resolution`]).
    pub ndf_res: Option<usize>,
    /// Nodes per axis of the `vndf`, `luminance` and reflectance grids (at least 4).
    pub warp_res: usize,
    /// The conductor.
    pub material: Material,
    /// `rgb` or `spectra`.
    pub flavour: Flavour,
}

impl Default for RglOptions {
    /// The resolution at which a table reproduces its lobe's BRDF to the bounds of data_formats/rgl.md,
    /// "The tails": a renderer reads the reflectance of an incidence between nodes at the nodes' own half
    /// vectors, so near the outgoing horizon, where the masking is steep, the incident azimuths' spacing
    /// weighs more than the elevations'.
    fn default() -> Self {
        RglOptions { theta_i: 12, phi_i: 25, ndf_res: None, warp_res: 88, material: Material::None, flavour: Flavour::Rgb }
    }
}

impl RglOptions {
    /// A table of half the default's size (16 x 17 incidences, 64 nodes per warp axis), a traced table's
    /// resolution: its reflectance is counted per node, so fewer nodes carry less noise at the same paths.
    pub fn coarse() -> RglOptions {
        RglOptions { theta_i: 16, phi_i: 17, warp_res: 64, ..RglOptions::default() }
    }
}

/// Largest nodes per axis accepted (a 512 x 512 warp over 64 x 64 incident nodes is already 4 GiB).
const MAX_RES: usize = 512;

/// Nodes per axis of the `sigma` grid at most: the projected area is smooth in the direction, and every
/// node costs one quadrature over the NDF.
const SIGMA_RES: usize = 64;

/// Nodes per axis of the quadrature grid of `sigma` and the normalization at most: every `sigma` node
/// sums over all its points.
const QUAD_RES: usize = 128;

impl RglOptions {
    pub(crate) fn check(&self) -> Result<()> {
        let bad = |name: &str, v: usize, lo: usize| Error::invalid(format!("{name} must be in [{lo}, {MAX_RES}], got {v}"));
        for (name, v, lo) in [
            ("theta_i", self.theta_i, 2),
            ("phi_i", self.phi_i, 3),
            ("ndf_res", self.ndf_res.unwrap_or(8), 8),
            ("warp_res", self.warp_res, 4),
        ] {
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

    /// Bytes of the file these options write with an `ndf` grid of `ndf_res` nodes per axis (header aside).
    pub fn data_bytes(&self, ndf_res: usize) -> usize {
        let slices = self.theta_i * self.phi_i * self.warp_res * self.warp_res;
        let sigma = ndf_res.min(SIGMA_RES);
        4 * (ndf_res * ndf_res + sigma * sigma + slices * (2 + self.wavelengths().len()) + self.theta_i + self.phi_i)
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
    /// Nodes per axis of the `ndf` grid written.
    pub ndf_res: usize,
    /// The largest relative error of the renderer's bilinear `ndf` against the guide NDF, where the guide is
    /// at least [`SIGNIFICANT`] of its peak ([`ndf_interpolation_error`]).
    pub ndf_error: f64,
}

/// Three-point Gauss-Legendre nodes and weights on `[0, 1]`.
const GAUSS3: [(f64, f64); 3] = [(0.112_701_665_379_258_3, 5.0 / 18.0), (0.5, 8.0 / 18.0), (0.887_298_334_620_741_7, 5.0 / 18.0)];

/// The NDF level, relative to its peak, down to which the `ndf` grid must reproduce it: a BRDF is
/// checked to `1e-3` of its peak, and the Smith and cosine factors lower that peak's share by up to 10x.
pub const SIGNIFICANT: f64 = 1e-4;

/// The relative error of the bilinear `ndf` at which [`ndf_resolution`] stops refining.
pub const NDF_TOLERANCE: f64 = 0.01;

/// The share of the written `vndf` density that is the tempered VNDF `(D <wi.m>)^TEMPER` rather than the
/// VNDF itself. The reflectance lives on the nodes of the sample space, which the `vndf` warp sends to
/// half vectors (Dupuy & Jakob 2018, sec. 5): the VNDF alone leaves its fast-falling tail between two
/// nodes, one of them at the horizon, where the reflectance interpolates across the masking's cliff. The
/// tempered share, over the half vectors that reflect above (or just below) the horizon, puts nodes down
/// the tail; the
/// `luminance` warp takes the ratio back, so sampling still follows the VNDF times the reflectance, and a
/// renderer weighs by the true `ndf` either way.
pub const DEFENSIVE: f64 = 0.75;

/// The power of the tempered VNDF: eight decades of the VNDF become one.
const TEMPER: f64 = 0.125;

/// How far below the horizon (degrees of outgoing elevation) the tempered VNDF reaches: the warp's density
/// does not end at the masking's cliff, so the nodes on either side of it lie close and its bilinear
/// reading spans a fraction of a cell (data_formats/rgl.md, "The tails").
const HORIZON_MARGIN_DEG: f64 = 5.0;

/// A quadrature point whose weight is below this share of the total is dropped from the projected area's
/// sums (its whole contribution is below `1e-6` even on a 512-node grid).
const PRUNE: f64 = 1e-12;

/// The largest relative error of the bilinear interpolation of `guide` on an `n x n` grid (the renderer's
/// reading of `ndf`) against `guide` itself, at every cell's centre and the midpoints of its lower and
/// left edges, where `guide` is at least [`SIGNIFICANT`] of its largest node value.
pub fn ndf_interpolation_error(guide: &(dyn Fn(Vector3<f64>) -> f64 + Sync), n: usize) -> f64 {
    let n = n.max(2);
    let step = 1.0 / (n - 1) as f64;
    let nodes: Vec<f64> = (0..n * n).into_par_iter().map(|k| guide(u2dir([(k % n) as f64 * step, (k / n) as f64 * step]))).collect();
    let peak = nodes.iter().copied().filter(|v| v.is_finite()).fold(0.0, f64::max);
    if !(peak > 0.0) {
        return 0.0;
    }
    let floor = SIGNIFICANT * peak;
    (0..(n - 1) * (n - 1))
        .into_par_iter()
        .map(|c| {
            let (i, j) = (c % (n - 1), c / (n - 1));
            let v = |a: usize, b: usize| nodes[(j + b) * n + i + a];
            let corners = [v(0, 0), v(1, 0), v(0, 1), v(1, 1)];
            if corners.iter().all(|&x| x < floor) {
                return 0.0;
            }
            let mut worst: f64 = 0.0;
            for (fx, fy) in [(0.5, 0.5), (0.5, 0.0), (0.0, 0.5)] {
                let truth = guide(u2dir([(i as f64 + fx) * step, (j as f64 + fy) * step]));
                if !(truth >= floor) {
                    continue;
                }
                let read = (1.0 - fy) * ((1.0 - fx) * corners[0] + fx * corners[1]) + fy * ((1.0 - fx) * corners[2] + fx * corners[3]);
                worst = worst.max((read - truth).abs() / truth);
            }
            worst
        })
        .reduce(|| 0.0, f64::max)
}

/// The `ndf` grid for `guide`: the smallest of 64, 128, 256 and 512 nodes per axis at which
/// [`ndf_interpolation_error`] is at most [`NDF_TOLERANCE`] (else 512), with that error. A lobe too narrow
/// for 512 nodes (Beckmann below about `alpha = 0.01`) keeps the error reported.
pub fn ndf_resolution(guide: &(dyn Fn(Vector3<f64>) -> f64 + Sync)) -> (usize, f64) {
    let mut last = (MAX_RES, f64::INFINITY);
    for n in [64, 128, 256, MAX_RES] {
        let e = ndf_interpolation_error(guide, n);
        if e <= NDF_TOLERANCE {
            return (n, e);
        }
        last = (n, e);
    }
    last
}

/// The `ndf` and `sigma` grids of a table: the NDF at the nodes of its grid, and its projected area
/// `sigma(w) = int D(m) <w.m> dm` on a grid of its own, by quadrature of the NDF (3 x 3 Gauss points per
/// cell of a grid of at most 128 nodes across). `G1(w) = cos(theta) / sigma(w)` is then Smith's masking
/// of the tabulated NDF (Heitz 2014 eq. 22), the masking a renderer applies.
#[derive(Debug, Clone)]
pub struct NdfGrids {
    /// `D` at the `n x n` nodes (`u_theta` fastest), rescaled by `scale`.
    pub ndf: Vec<f64>,
    /// Nodes per axis of `ndf`.
    pub n: usize,
    /// `sigma` at the `ns x ns` nodes.
    pub sigma: Vec<f64>,
    /// Nodes per axis of `sigma`.
    pub ns: usize,
    /// `int D(m) (m.n) dm` of the NDF before rescaling.
    pub normalization: f64,
    /// The bilinear reading's largest relative error against the guide ([`ndf_interpolation_error`]).
    pub ndf_error: f64,
    /// The factor applied to the NDF: `1 / normalization` when renormalized, else 1.
    pub scale: f64,
}

impl NdfGrids {
    /// The grids of `d`, the `ndf` grid `ndf_res` nodes across or chosen for `guide` ([`ndf_resolution`]);
    /// `renormalize` rescales `d` to `int D (m.n) dm = 1`.
    pub fn new(
        d: &(dyn Fn(Vector3<f64>) -> f64 + Sync),
        guide: &(dyn Fn(Vector3<f64>) -> f64 + Sync),
        ndf_res: Option<usize>,
        renormalize: bool,
    ) -> Result<NdfGrids> {
        if let Some(n) = ndf_res.filter(|n| !(8..=MAX_RES).contains(n)) {
            return Err(Error::invalid(format!("ndf_res must be in [8, {MAX_RES}], got {n}")));
        }
        let (n, ndf_error) = match ndf_res {
            Some(n) => (n, ndf_interpolation_error(guide, n)),
            None => ndf_resolution(guide),
        };
        let step = 1.0 / (n - 1) as f64;
        let mut ndf: Vec<f64> = (0..n * n).into_par_iter().map(|k| d(u2dir([(k % n) as f64 * step, (k / n) as f64 * step]))).collect();
        if let Some(bad) = ndf.iter().find(|v| !(v.is_finite() && **v >= 0.0)) {
            return Err(Error::invalid(format!("the NDF has a value {bad} (not finite and >= 0) on the table's grid")));
        }
        let area = ProjectedArea::new(d, n.min(QUAD_RES), n.min(SIGMA_RES), renormalize)?;
        ndf.iter_mut().for_each(|v| *v *= area.scale);
        let ProjectedArea { sigma, ns, normalization, scale } = area;
        Ok(NdfGrids { ndf, n, sigma, ns, normalization, ndf_error, scale })
    }

    /// `D(m)` as a renderer reads it: bilinear on the `ndf` grid.
    pub fn d(&self, m: Vector3<f64>) -> f64 {
        bilinear(&self.ndf, self.n, dir2u(m))
    }

    /// Smith's `G1(w)` of the tabulated NDF, `min(1, cos(theta) / sigma(w))`; 0 at or below the horizon.
    pub fn g1(&self, w: Vector3<f64>) -> f64 {
        smith_g1(&self.sigma, self.ns, w)
    }

    /// The projected area `sigma(w)` as a renderer reads it: bilinear on the `sigma` grid.
    pub fn sigma_at(&self, w: Vector3<f64>) -> f64 {
        bilinear(&self.sigma, self.ns, dir2u(w))
    }
}

/// `min(1, cos(theta) / sigma(w))` with `sigma` read bilinearly on its `ns x ns` grid; 0 at or below the
/// horizon.
fn smith_g1(sigma: &[f64], ns: usize, w: Vector3<f64>) -> f64 {
    let s = bilinear(sigma, ns, dir2u(w));
    if w.z > 0.0 && s > 0.0 {
        (w.z / s).min(1.0)
    } else {
        0.0
    }
}

/// The nodes one pass over the quadrature serves: four vectors of four, so that the sums' chains of
/// additions overlap instead of each waiting on its last.
const BLOCK: usize = 16;

/// A quadrature over the hemisphere by columns (`m`'s coordinates and the weight apart), read once per
/// [`BLOCK`] nodes.
struct Columns {
    x: Vec<f64>,
    y: Vec<f64>,
    z: Vec<f64>,
    q: Vec<f64>,
}

impl Columns {
    fn new(quad: &[(Vector3<f64>, f64)]) -> Columns {
        Columns {
            x: quad.iter().map(|p| p.0.x).collect(),
            y: quad.iter().map(|p| p.0.y).collect(),
            z: quad.iter().map(|p| p.0.z).collect(),
            q: quad.iter().map(|p| p.1).collect(),
        }
    }

    /// `sum q max(0, w.m)` for each of up to [`BLOCK`] nodes `ws`, each summed in the quadrature's order
    /// (the same bits as one node's own loop; only the pass over the columns is shared).
    fn projected(&self, ws: &[Vector3<f64>]) -> [f64; BLOCK] {
        let mut w = [Vector3::zeros(); BLOCK];
        w[..ws.len()].copy_from_slice(ws);
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked just above).
            return unsafe { self.projected_avx2(&w) };
        }
        self.projected_any(&w)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn projected_avx2(&self, w: &[Vector3<f64>; BLOCK]) -> [f64; BLOCK] {
        self.projected_any(w)
    }

    #[inline(always)]
    fn projected_any(&self, w: &[Vector3<f64>; BLOCK]) -> [f64; BLOCK] {
        let (wx, wy, wz) = (w.map(|v| v.x), w.map(|v| v.y), w.map(|v| v.z));
        // `Sum` of f64 starts at -0.0.
        let mut acc = [-0.0f64; BLOCK];
        for (((&x, &y), &z), &q) in self.x.iter().zip(&self.y).zip(&self.z).zip(&self.q) {
            for j in 0..BLOCK {
                // `Vector3::dot`'s order: (x x' + y y') + z z'.
                acc[j] += q * (wx[j] * x + wy[j] * y + wz[j] * z).max(0.0);
            }
        }
        acc
    }
}

/// The projected area `sigma(w) = int D(m) <w.m> dm` of an NDF on an `ns x ns` grid of the table's
/// sample space, by quadrature (3 x 3 Gauss points per cell of an `nq`-node grid), and the NDF's
/// `int D(m) (m.n) dm`. `G1(w) = cos(theta) / sigma(w)` is Smith's masking of that NDF (Heitz 2014 eq. 22).
#[derive(Debug, Clone)]
pub struct ProjectedArea {
    /// `sigma` at the nodes, of the NDF rescaled by `scale`.
    pub sigma: Vec<f64>,
    /// Nodes per axis of `sigma`.
    pub ns: usize,
    /// `int D(m) (m.n) dm` of the NDF before rescaling.
    pub normalization: f64,
    /// The factor applied to the NDF: `1 / normalization` when renormalized, else 1.
    pub scale: f64,
}

impl ProjectedArea {
    /// The projected area of `d` (rescaled to `int D (m.n) dm = 1` when `renormalize`), quadrature on
    /// `nq` nodes across, `sigma` on `ns`.
    pub fn new(d: &(dyn Fn(Vector3<f64>) -> f64 + Sync), nq: usize, ns: usize, renormalize: bool) -> Result<ProjectedArea> {
        let (nq, ns) = (nq.max(2), ns.max(2));
        // Quadrature over the hemisphere in grid coordinates: dw = 2 pi^2 u_theta sin(theta) du_theta du_phi.
        let step = 1.0 / (nq - 1) as f64;
        let mut quad: Vec<(Vector3<f64>, f64)> = (0..(nq - 1) * (nq - 1))
            .into_par_iter()
            .flat_map_iter(|c| {
                let (i, j) = (c % (nq - 1), c / (nq - 1));
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
        let total: f64 = quad.iter().map(|(_, w)| w).sum();
        quad.retain(|(_, w)| *w >= PRUNE * total);
        let scale = if renormalize { 1.0 / normalization } else { 1.0 };
        let sstep = 1.0 / (ns - 1) as f64;
        let nodes: Vec<Vector3<f64>> = (0..ns * ns).map(|k| u2dir([(k % ns) as f64 * sstep, (k / ns) as f64 * sstep])).collect();
        let columns = Columns::new(&quad);
        let mut sigma = vec![0.0; ns * ns];
        sigma.par_chunks_mut(BLOCK).zip(nodes.par_chunks(BLOCK)).for_each(|(out, ws)| {
            for (o, v) in out.iter_mut().zip(columns.projected(ws)) {
                *o = scale * v;
            }
        });
        Ok(ProjectedArea { sigma, ns, normalization, scale })
    }

    /// Smith's `G1(w)`, `min(1, cos(theta) / sigma(w))`; 0 at or below the horizon.
    pub fn g1(&self, w: Vector3<f64>) -> f64 {
        smith_g1(&self.sigma, self.ns, w)
    }
}

/// Tabulate the NDF `d` (scan frame, `z` up; normalized or not) as an RGL tensor file. `renormalize`
/// rescales `d` so that the table's `int D (m.n) dm` is 1 (for an empirical NDF; a model is already
/// normalized and is written as it is). `description` becomes the file's `description` field. The `ndf`
/// grid is chosen for `d` itself ([`tabulate_guided`] with `d` as the guide).
pub fn tabulate(d: &(dyn Fn(Vector3<f64>) -> f64 + Sync), description: &str, opts: &RglOptions, renormalize: bool) -> Result<Table> {
    tabulate_guided(d, d, description, opts, renormalize)
}

/// [`tabulate`] with the `ndf` grid chosen for the smooth `guide` instead of `d` (an empirical NDF is
/// constant within its bins, so no grid reproduces it between them; its fitted model sets the resolution).
pub fn tabulate_guided(
    d: &(dyn Fn(Vector3<f64>) -> f64 + Sync),
    guide: &(dyn Fn(Vector3<f64>) -> f64 + Sync),
    description: &str,
    opts: &RglOptions,
    renormalize: bool,
) -> Result<Table> {
    let material = opts.material;
    let reflectance = |grids: &NdfGrids, slices: &[SliceWarp], lambdas: &[f64]| -> Result<Vec<Vec<f64>>> {
        Ok(slices.par_iter().map(|s| smith_reflectance(grids, s, lambdas, material)).collect())
    };
    tabulate_with(d, guide, description, opts, renormalize, &reflectance)
}

/// One incident node's sampling warp, as the writer lays the reflectance on it: the written `vndf`
/// density and the half-vector coordinates `u` that its nodes of the sample space map to (Dupuy & Jakob
/// 2018, sec. 5).
#[derive(Debug, Clone)]
pub(crate) struct SliceWarp {
    /// The incident direction (scan frame, `z` up).
    pub wi: Vector3<f64>,
    /// Nodes per axis of the warp.
    pub w: usize,
    /// The written density at the `w x w` nodes of `u` (`u_theta` fastest), rounded to `f32` as stored.
    pub vndf: Vec<f64>,
    /// The point `u` that each node of the sample space maps to.
    pub nodes: Vec<[f64; 2]>,
    /// At each node, the visible NDF over the written density (both normalized): the factor the
    /// `luminance` warp applies so that the two warps together sample the visible NDF.
    pub ratio: Vec<f64>,
}

impl SliceWarp {
    /// The inverse-CDF warp of the written density.
    pub fn warp(&self) -> warp::Bilinear<'_> {
        warp::Bilinear::new(&self.vndf, self.w, self.w)
    }
}

/// The reflectance of a microfacet table at one slice's nodes, `F(wi.m) G1(wo)` per wavelength (separable
/// Smith, as Mitsuba's `roughconductor`), `channels x w x w`.
fn smith_reflectance(grids: &NdfGrids, s: &SliceWarp, lambdas: &[f64], material: Material) -> Vec<f64> {
    let n = s.w * s.w;
    let mut refl = vec![0.0; lambdas.len() * n];
    for (k, &u) in s.nodes.iter().enumerate() {
        let m = u2dir(u);
        let c = s.wi.dot(&m);
        let wo = 2.0 * c * m - s.wi;
        // Smith masking of the outgoing direction from the tabulated projected area; none below the horizon.
        let g1 = grids.g1(wo);
        for (l, &nm) in lambdas.iter().enumerate() {
            refl[l * n + k] = material.fresnel(c, nm) * g1;
        }
    }
    refl
}

/// The reflectance of every slice (`phi_i` outermost, as the file lays them), each `channels x w x w`
/// at the slice's nodes, from the `ndf` and `sigma` grids, the slices' warps and the wavelengths.
pub(crate) type Reflectance<'a> = dyn Fn(&NdfGrids, &[SliceWarp], &[f64]) -> Result<Vec<Vec<f64>>> + 'a;

/// [`tabulate_guided`] with the reflectance at the sample-space nodes supplied by `reflectance`; the
/// `luminance` warp is made from it.
pub(crate) fn tabulate_with(
    d: &(dyn Fn(Vector3<f64>) -> f64 + Sync),
    guide: &(dyn Fn(Vector3<f64>) -> f64 + Sync),
    description: &str,
    opts: &RglOptions,
    renormalize: bool,
    reflectance: &Reflectance<'_>,
) -> Result<Table> {
    tabulate_at(d, guide, description, opts, renormalize, opts.wavelengths(), reflectance)
}

/// [`tabulate_with`] at the reflectance's wavelengths `lambdas` (nm, increasing): a spectral table's
/// `wavelengths` (an `rgb` table takes exactly three, its channels, [`RGB_NM`] by default).
pub(crate) fn tabulate_at(
    d: &(dyn Fn(Vector3<f64>) -> f64 + Sync),
    guide: &(dyn Fn(Vector3<f64>) -> f64 + Sync),
    description: &str,
    opts: &RglOptions,
    renormalize: bool,
    lambdas: &[f64],
    reflectance: &Reflectance<'_>,
) -> Result<Table> {
    opts.check()?;
    let ok = match opts.flavour {
        Flavour::Rgb => lambdas.len() == 3,
        Flavour::Spectral => {
            !lambdas.is_empty() && lambdas.iter().all(|l| l.is_finite() && *l > 0.0) && lambdas.windows(2).all(|p| p[0] < p[1])
        }
    };
    if !ok {
        return Err(Error::invalid(format!(
            "the table's wavelengths {lambdas:?} nm are not three rgb channels or positive and increasing"
        )));
    }
    let grids = NdfGrids::new(d, guide, opts.ndf_res, renormalize)?;
    let NdfGrids { ref ndf, n, ref sigma, ns, normalization, ndf_error, scale } = grids;

    let theta_i: Vec<f64> = (0..opts.theta_i).map(|k| k as f64 * FRAC_PI_2 / (opts.theta_i - 1) as f64).collect();
    let phi_i: Vec<f64> = (0..opts.phi_i).map(|k| -PI + k as f64 * 2.0 * PI / (opts.phi_i - 1) as f64).collect();
    let w = opts.warp_res;
    let wstep = 1.0 / (w - 1) as f64;
    let slices: Vec<(f64, f64)> = phi_i.iter().flat_map(|&p| theta_i.iter().map(move |&t| (p, t))).collect();
    let warps: Vec<SliceWarp> = slices
        .par_iter()
        .map(|&(phi, theta)| {
            let wi = Vector3::new(phi.cos() * theta.sin(), phi.sin() * theta.sin(), theta.cos());
            // The visible NDF in grid coordinates, D(m) <wi.m> times the grid's Jacobian.
            let visible = |u: [f64; 2]| {
                let m = u2dir(u);
                scale * d(m) * wi.dot(&m).max(0.0) * 2.0 * PI * PI * u[0] * u2theta(u[0]).sin()
            };
            let exact: Vec<f64> = (0..w * w).map(|k| visible([(k % w) as f64 * wstep, (k / w) as f64 * wstep])).collect();
            // Only half vectors that reflect above the horizon, or just below it, carry reflectance worth a node.
            let floor = -HORIZON_MARGIN_DEG.to_radians().sin();
            let above = |k: usize| {
                let m = u2dir([(k % w) as f64 * wstep, (k / w) as f64 * wstep]);
                (2.0 * wi.dot(&m) * m - wi).z > floor
            };
            let tempered: Vec<f64> = exact.iter().enumerate().map(|(k, v)| if above(k) { v.powf(TEMPER) } else { 0.0 }).collect();
            let (te, tt) = (warp::Bilinear::new(&exact, w, w).total(), warp::Bilinear::new(&tempered, w, w).total());
            // The written density, rounded to f32 as the renderer stores it.
            let vndf: Vec<f64> = if te > 0.0 && tt > 0.0 {
                exact.iter().zip(&tempered).map(|(e, t)| ((1.0 - DEFENSIVE) * e / te + DEFENSIVE * t / tt) as f32 as f64).collect()
            } else {
                exact.iter().map(|&e| e as f32 as f64).collect()
            };
            let warp = warp::Bilinear::new(&vndf, w, w);
            let written = warp.total();
            let nodes: Vec<[f64; 2]> = (0..w * w).map(|k| warp.sample([(k % w) as f64 * wstep, (k / w) as f64 * wstep])).collect();
            // The sampling density the luminance warp adds in front of the written one: the VNDF over
            // the written density at this node's half vector, so that the two warps follow the VNDF.
            let ratio = nodes
                .iter()
                .map(|&u| {
                    let p_written = bilinear(&vndf, w, u) / written;
                    if te > 0.0 && p_written > 0.0 {
                        visible(u) / te / p_written
                    } else {
                        1.0
                    }
                })
                .collect();
            SliceWarp { wi, w, vndf, nodes, ratio }
        })
        .collect();
    let refls = reflectance(&grids, &warps, lambdas)?;
    if refls.len() != warps.len() || refls.iter().any(|r| r.len() != lambdas.len() * w * w) {
        return Err(Error::invalid("the reflectance does not cover every slice's nodes and channels"));
    }
    let lums: Vec<Vec<f64>> = warps
        .par_iter()
        .zip(&refls)
        .map(|(s, refl)| {
            let mut lum: Vec<f64> = (0..w * w)
                .map(|k| {
                    let luminance = match opts.flavour {
                        Flavour::Rgb => (0..3).map(|l| LUMA[l] * refl[l * w * w + k]).sum(),
                        Flavour::Spectral => (0..lambdas.len()).map(|l| refl[l * w * w + k]).sum::<f64>() / lambdas.len() as f64,
                    };
                    (luminance * s.ratio[k]).max(0.0)
                })
                .collect();
            // A slice that reflects nothing (grazing incidence on a very rough NDF) still needs a density to
            // normalize: a uniform one, whose samples all carry the zero reflectance.
            if !lum.iter().any(|&v| v > 0.0) {
                lum.iter_mut().for_each(|v| *v = 1.0);
            }
            lum
        })
        .collect();

    let (np, nt, nl) = (opts.phi_i, opts.theta_i, lambdas.len());
    let vndf: Vec<f64> = warps.iter().flat_map(|s| s.vndf.iter().copied()).collect();
    let luminance: Vec<f64> = lums.iter().flat_map(|s| s.iter().copied()).collect();
    let refl: Vec<f64> = refls.iter().flat_map(|s| s.iter().copied()).collect();
    let mut fields = vec![
        Field::u8("description", description.as_bytes()),
        Field::u8("jacobian", &[1]),
        Field::f32("theta_i", &[nt], &theta_i),
        Field::f32("phi_i", &[np], &phi_i),
        Field::f32("ndf", &[n, n], ndf),
        Field::f32("sigma", &[ns, ns], sigma),
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
    Ok(Table { tensor: TensorFile { fields }, normalization, ndf_res: n, ndf_error })
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The blocked sums are, bit for bit, each node's own sum in the quadrature's order (as `sigma` was
    /// computed before the columns), for full and partial blocks.
    #[test]
    fn blocked_projected_sums_equal_each_nodes_own_sum() {
        let quad: Vec<(Vector3<f64>, f64)> = (0..997)
            .map(|k| {
                let u = [((k * 37) % 101) as f64 / 100.0, ((k * 53) % 89) as f64 / 88.0];
                (u2dir(u), 1e-3 * (1.0 + (k % 7) as f64).sqrt())
            })
            .collect();
        let columns = Columns::new(&quad);
        let nodes: Vec<Vector3<f64>> = (0..37).map(|k| u2dir([(k as f64 / 36.0).min(1.0), (k * 7 % 37) as f64 / 36.0])).collect();
        for ws in nodes.chunks(BLOCK) {
            let got = columns.projected(ws);
            for (w, g) in ws.iter().zip(got) {
                let own = quad.iter().map(|(m, q)| q * w.dot(m).max(0.0)).sum::<f64>();
                assert_eq!(g.to_bits(), own.to_bits(), "{w:?}: {g} {own}");
            }
        }
    }
}
