//! Renderer export: a fitted NDF as the parameters of Mitsuba 3, pbrt-v4, Blender (Cycles Principled
//! BSDF for GGX, Glossy BSDF for Beckmann), OpenPBR and MaterialX, with the tangent direction each needs
//! (CONTRACT.md "Renderer export"); a mirror answer of the wave optics as each renderer's smooth conductor,
//! blended with its haze lobe ([`export_mirror`]).
//!
//! Every renderer here evaluates an axis-aligned GGX (Trowbridge-Reitz) or Beckmann lobe in its shading
//! frame `(u, v, n)`: `D(m) = 1 / (pi a_u a_v (m_u^2/a_u^2 + m_v^2/a_v^2 + m_n^2)^2)` (Heitz eq. 85 in
//! local coordinates; Mitsuba `MicrofacetDistribution::eval`, pbrt-v4 `TrowbridgeReitzDistribution::D`,
//! Cycles `bsdf_microfacet`). ndfit's lobe is `D(Rz(theta_z) m)` (Walter et al. eq. 3), whose `alpha_x` axis
//! lies along `(cos theta_z, -sin theta_z)`, so the renderer's `u` axis must point at azimuth
//! `tangent_angle = -theta_z` with `a_u = alpha_x`, `a_v = alpha_y` (the canonical `alpha_x >= alpha_y`
//! puts the rougher axis on the tangent, as Blender and OpenPBR require).
//!
//! The published parameter maps ([`RendererLobe::params`]):
//! - Mitsuba 3 `roughconductor`: `alpha_u`, `alpha_v` are the alphas (GGX or Beckmann).
//! - pbrt-v4 `conductor`: `uroughness`, `vroughness` are the alphas with `remaproughness` false (GGX only).
//! - Blender Principled BSDF, GGX (Cycles `svm_node_closure_bsdf`, `CLOSURE_BSDF_PRINCIPLED_ID`):
//!   `r2 = roughness^2`, `aspect = sqrt(1 - 0.9 anisotropic)`, `alpha_x = r2 / aspect` along the tangent,
//!   `alpha_y = r2 aspect`, the tangent turned about `n` by `2 pi anisotropic_rotation`; inputs clamped to
//!   `[0, 1]` and alphas saturated at 1, so at most 10:1 anisotropy and `alpha_x <= 1`.
//! - Blender Glossy BSDF, Beckmann (the same function, `CLOSURE_BSDF_MICROFACET_BECKMANN_ID`):
//!   `r2 = Roughness^2`, `a = clamp(Anisotropy, -0.99, 0.99)`; for `a < 0` `alpha_x = r2 / (1 + a)` along the
//!   tangent and `alpha_y = r2 (1 + a)` (for `a > 0` the axes trade places); the tangent turned about `n` by
//!   `2 pi Rotation` (`rotate_around_axis`, counter-clockwise about `n`, as the Principled one); alphas
//!   saturated at 1 (`bsdf_microfacet_beckmann_setup`), so at most 10^4:1 anisotropy and `alpha_x <= 1`.
//! - OpenPBR: `alpha_t = r^2 sqrt(2 / (1 + (1 - a)^2))`, `alpha_b = (1 - a) alpha_t`, i.e.
//!   `r = ((alpha_t^2 + alpha_b^2) / 2)^(1/4)`, `a = 1 - alpha_b / alpha_t` (GGX only).
//! - MaterialX `conductor_bsdf`: `roughness` is the vector `(alpha_x, alpha_y)` (GGX only).
//!
//! What a renderer cannot hold (an ellipsoid's skew, Beckmann in pbrt, OpenPBR and MaterialX, Blender beyond
//! its node's anisotropy or `alpha_x > 1`) is replaced by the nearest lobe it can, FITTED to the fitted NDF:
//! the lobe maximizing `E_{m ~ D_fit (m.n)}[ln D_lobe(m)]` with `D_lobe` normalized over the fit region (the
//! Poisson fit of `objective.md` in the limit of infinite data drawn from `D_fit`), by Nelder-Mead on a
//! quadrature grid that follows the lobe. Its error is reported as `delta(D_lobe; D_fit)` and
//! `delta(D_fit; D_lobe)` (objective.md) over the same region.

use nalgebra::Vector3;
use serde_json::{json, Map, Value};

use crate::error::{Error, Result};
use crate::fit::metric::RefNodes;
use crate::models::{LobeAxes, Model, ModelId, Ndf};
use crate::ndf::SlopeFrame;

pub(crate) mod mixture;
pub mod rgl;
pub(crate) mod snippet;

// The Blender scripts and the mirror answers.
mod blender;
mod mirror;
mod mirror_brdf;
mod mirror_snippet;

/// Largest `alpha_x / alpha_y` of Blender's Principled BSDF: `1 / aspect^2` at `anisotropic = 1`.
pub const BLENDER_MAX_ANISOTROPY: f64 = 10.0;
/// Largest `alpha_x / alpha_y` of Blender's Glossy BSDF: `1 / (1 + a)^2` at Cycles' clamp `a = -0.99`.
pub const BLENDER_GLOSSY_MAX_ANISOTROPY: f64 = 1.0e4;
/// Largest alpha Cycles keeps (`bsdf_microfacet_ggx_setup` saturates both alphas at 1).
pub const BLENDER_MAX_ALPHA: f64 = 1.0;
/// Cells across the quadrature grid of the approximation fit (about 0.8 x cells^2 nodes on the hemisphere).
const APPROX_CELLS: usize = 121;

/// The renderers `ndfit export` writes for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Target {
    /// Mitsuba 3 `roughconductor`.
    Mitsuba,
    /// pbrt-v4 `conductor`.
    Pbrt,
    /// Blender (Cycles/EEVEE): Principled BSDF for GGX, Glossy BSDF for Beckmann.
    Blender,
    /// OpenPBR Surface.
    OpenPbr,
    /// MaterialX `conductor_bsdf`.
    MaterialX,
}

impl Target {
    /// Every target, in the order of the contract's table.
    pub const ALL: [Target; 5] = [Target::Mitsuba, Target::Pbrt, Target::Blender, Target::OpenPbr, Target::MaterialX];

    /// The id as `--to` spells it.
    pub fn as_str(self) -> &'static str {
        match self {
            Target::Mitsuba => "mitsuba",
            Target::Pbrt => "pbrt",
            Target::Blender => "blender",
            Target::OpenPbr => "openpbr",
            Target::MaterialX => "materialx",
        }
    }

    /// Whether the renderer has a Beckmann lobe (Mitsuba's `roughconductor`, Blender's Glossy BSDF).
    pub fn has_beckmann(self) -> bool {
        matches!(self, Target::Mitsuba | Target::Blender)
    }
}

impl std::str::FromStr for Target {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Target::ALL
            .into_iter()
            .find(|t| t.as_str() == s)
            .ok_or_else(|| Error::invalid(format!("unknown renderer '{s}' (expected mitsuba, pbrt, blender, openpbr or materialx)")))
    }
}

pub use crate::models::Distribution;
pub use mirror::{export_mirror, Gap, MirrorAnswer, MirrorExport, Share, ShareForm, SHARE_WAVELENGTH_NM};
pub use mirror_brdf::MirrorBrdf;
pub use mixture::export_mixture;
pub use mixture::MixtureExport;

/// An axis-aligned lobe in a renderer's shading frame: `alpha_u` along the tangent `u`, which points at
/// azimuth `tangent_angle` (radians, counter-clockwise from the scan's `+x`), `alpha_v` along `n x u`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RendererLobe {
    /// GGX or Beckmann.
    pub distribution: Distribution,
    /// Roughness along the tangent.
    pub alpha_u: f64,
    /// Roughness along the bitangent.
    pub alpha_v: f64,
    /// Azimuth of the tangent in the scan frame (radians, `(-pi/2, pi/2]`).
    pub tangent_angle: f64,
}

impl RendererLobe {
    /// The same lobe as an ndfit model (`theta_z = -tangent_angle`).
    pub fn to_model(&self) -> Result<Model> {
        let id = match (self.distribution, self.alpha_u == self.alpha_v) {
            (Distribution::Ggx, true) => ModelId::Ggx,
            (Distribution::Ggx, false) => ModelId::GgxAniso,
            (Distribution::Beckmann, true) => ModelId::Beckmann,
            (Distribution::Beckmann, false) => ModelId::BeckmannAniso,
        };
        match id {
            ModelId::Ggx | ModelId::Beckmann => Model::from_params(id, &[self.alpha_u]),
            _ => Model::from_params(id, &[self.alpha_u, self.alpha_v, -self.tangent_angle]),
        }
    }

    /// The renderer's own parameters under the contract's keys (module doc for each map).
    pub fn params(&self, target: Target) -> Map<String, Value> {
        let (au, av, t) = (self.alpha_u, self.alpha_v, self.tangent_angle);
        let v = match target {
            Target::Mitsuba => json!({
                "plugin": "roughconductor", "distribution": self.distribution.as_str(),
                "alpha_u": au, "alpha_v": av, "tangent_angle": t
            }),
            Target::Pbrt => json!({"uroughness": au, "vroughness": av, "remaproughness": false, "tangent_angle": t}),
            Target::Blender => self.blender_json(),
            Target::OpenPbr => {
                let (r, a) = openpbr_params(au, av);
                json!({"specular_roughness": r, "specular_roughness_anisotropy": a, "tangent_angle": t})
            }
            Target::MaterialX => json!({"roughness": [au, av], "tangent_angle": t}),
        };
        match v {
            Value::Object(m) => m,
            _ => Map::new(),
        }
    }

    /// Blender's keys: the contract's `roughness`, `anisotropic`, `anisotropic_rotation` (the Principled BSDF's
    /// inputs for these alphas, [`blender_params`]), the `node` the script builds (`principled` for GGX,
    /// `glossy` for Beckmann) and its `distribution`; for the Glossy node its own socket values under
    /// `inputs` ([`glossy_params`]; its `anisotropic` then exceeds 1 beyond the Principled BSDF's 10:1).
    fn blender_json(&self) -> Value {
        let (au, av, t) = (self.alpha_u, self.alpha_v, self.tangent_angle);
        let b = blender_params(au, av, t);
        let mut v = json!({"roughness": b[0], "anisotropic": b[1], "anisotropic_rotation": b[2],
                           "distribution": self.distribution.as_str()});
        if self.distribution == Distribution::Beckmann {
            let g = glossy_params(au, av, t);
            v["node"] = json!("glossy");
            v["inputs"] = json!({"Roughness": g[0], "Anisotropy": g[1], "Rotation": g[2]});
        } else {
            v["node"] = json!("principled");
        }
        v
    }
}

/// Blender's Principled BSDF inputs `[roughness, anisotropic, anisotropic_rotation]` for `alpha_x >= alpha_y`
/// along a tangent at azimuth `t`: the inverse of `alpha_x = r^2 / aspect`, `alpha_y = r^2 aspect`,
/// `aspect = sqrt(1 - 0.9 anisotropic)`, rotation a fraction of a full turn in `[0, 1)`.
pub fn blender_params(alpha_x: f64, alpha_y: f64, t: f64) -> [f64; 3] {
    let roughness = (alpha_x * alpha_y).sqrt().sqrt();
    let anisotropic = (1.0 - alpha_y / alpha_x) / 0.9;
    // `+ 0.0` writes the turn of `t = -0` as 0.
    let rotation = (t / std::f64::consts::TAU).rem_euclid(1.0) + 0.0;
    [roughness, anisotropic, if rotation >= 1.0 { 0.0 } else { rotation }]
}

/// Blender's Glossy BSDF inputs `[Roughness, Anisotropy, Rotation]` for `alpha_x >= alpha_y` along a tangent at
/// azimuth `t`: the inverse of Cycles' `alpha_x = Roughness^2 / (1 + a)`, `alpha_y = Roughness^2 (1 + a)` for
/// `a = Anisotropy <= 0` (so the rougher axis stays on the tangent and the rotation is the Principled one's).
pub fn glossy_params(alpha_x: f64, alpha_y: f64, t: f64) -> [f64; 3] {
    let roughness = (alpha_x * alpha_y).sqrt().sqrt();
    let anisotropy = (alpha_y / alpha_x).sqrt() - 1.0;
    [roughness, anisotropy, blender_params(alpha_x, alpha_y, t)[2]]
}

/// OpenPBR `(specular_roughness, specular_roughness_anisotropy)` for `alpha_t >= alpha_b`: the inverse of
/// `alpha_t = r^2 sqrt(2 / (1 + (1 - a)^2))`, `alpha_b = (1 - a) alpha_t`.
pub fn openpbr_params(alpha_t: f64, alpha_b: f64) -> (f64, f64) {
    (((alpha_t * alpha_t + alpha_b * alpha_b) / 2.0).sqrt().sqrt(), 1.0 - alpha_b / alpha_t)
}

/// How a fit that the renderer cannot hold was replaced.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Approximation {
    /// The fitted model.
    pub from: String,
    /// The lobe written instead (`ggx-aniso`, `beckmann-aniso`, ...).
    pub to: String,
    /// `delta(D_lobe; D_fit)` over the region (objective.md; reference the fit). `None` for a GGX lobe
    /// written for a Beckmann fit: the ratio grows like `exp(tan^2 theta / alpha^2)` and the value is unbounded.
    pub delta: Option<f64>,
    /// `delta(D_fit; D_lobe)` over the region (reference the written lobe).
    pub delta_reverse: Option<f64>,
    /// The region's largest polar angle (the fit's `quality.max_theta_deg`, else 90).
    pub max_theta_deg: f64,
}

/// One export: the lobe to write, and how it was obtained.
#[derive(Debug, Clone, PartialEq)]
pub struct Export {
    /// The renderer.
    pub target: Target,
    /// The lobe the renderer evaluates.
    pub lobe: RendererLobe,
    /// Set when the fit was not representable and `lobe` is the nearest one fitted to it.
    pub approximation: Option<Approximation>,
    /// What the user must know: why and how the fit was approximated.
    pub note: Option<String>,
}

impl Export {
    /// `--json`: the contract's keys, plus `note` and `approximation` when the fit was approximated.
    pub fn to_json(&self) -> Value {
        let mut m = self.lobe.params(self.target);
        if let Some(n) = &self.note {
            m.insert("note".into(), Value::from(n.clone()));
        }
        if let Some(a) = &self.approximation {
            m.insert("approximation".into(), serde_json::to_value(a).unwrap_or(Value::Null));
        }
        Value::Object(m)
    }
}

/// Export `model` (any parameterization; it is made canonical) to `target`. `max_theta_deg` is the fit
/// region (the fit's `quality.max_theta_deg`) over which an approximation is fitted and measured.
pub fn export(model: &Model, target: Target, max_theta_deg: f64) -> Result<Export> {
    if !(max_theta_deg > 0.0 && max_theta_deg <= 90.0) {
        return Err(Error::invalid(format!("max_theta_deg must be in (0, 90], got {max_theta_deg}")));
    }
    let model = model.canonical();
    let exact = exact_lobe(&model);
    let fits = |l: &RendererLobe| -> bool {
        (l.distribution == Distribution::Ggx || target.has_beckmann()) && Limits::of(target, l.distribution).is_none_or(|k| k.holds(l))
    };
    if let Some(l) = exact.filter(|l| fits(l)) {
        return Ok(Export { target, lobe: l, approximation: None, note: None });
    }
    // Not representable: why, then the nearest representable lobe, fitted.
    let spec = model.id().spec();
    let why = match (spec.lobes[0].form, exact) {
        (crate::models::table::Form::Full, None) => {
            "the ellipsoid's skew (theta_x, theta_y) has no counterpart in an axis-aligned renderer lobe".to_string()
        }
        (_, Some(l)) if l.distribution == Distribution::Beckmann && !target.has_beckmann() => {
            format!("{} has no Beckmann lobe", target.as_str())
        }
        (_, Some(l)) if l.alpha_u > BLENDER_MAX_ALPHA => format!("Blender saturates alphas at 1, the fit has alpha_x = {:.4}", l.alpha_u),
        (_, Some(l)) => format!(
            "Blender's {} anisotropy is at most {}:1, the fit has {:.2}:1",
            if l.distribution == Distribution::Beckmann { "Glossy BSDF" } else { "Principled BSDF" },
            Limits::of(target, l.distribution).map_or(f64::INFINITY, |k| k.max_ratio),
            l.alpha_u / l.alpha_v
        ),
        _ => format!("no renderer implements the {} lobe ({})", model.id(), spec.about),
    };
    let beckmann_model = spec.lobes[0].kernel == crate::models::table::Kernel::Beckmann && !spec.is_mixture();
    let distribution = if beckmann_model && target.has_beckmann() { Distribution::Beckmann } else { Distribution::Ggx };
    let region = RegionNodes::new(&model, max_theta_deg);
    let lobe = fit_lobe(&model, &region, distribution, Limits::of(target, distribution), exact)?;
    let approx = lobe.to_model()?;
    // A GGX lobe against a Beckmann reference: D_ggx / D_beckmann grows like exp(tan^2 theta / alpha^2), so the
    // expectation has no useful finite value (any quadrature returns an astronomically large number).
    let beckmann_ref = beckmann_model && lobe.distribution == Distribution::Ggx;
    let delta = crate::fit::metric::delta(|m| approx.d(*m), |m| model.d(*m), region.nodes.iter().copied())
        .filter(|d| d.is_finite() && !beckmann_ref);
    let delta_reverse =
        crate::fit::metric::delta(|m| model.d(*m), |m| approx.d(*m), region.nodes.iter().copied()).filter(|d| d.is_finite());
    let to = approx.id().as_str().to_string();
    let fmt = |d: Option<f64>| d.map_or("unbounded (a GGX tail over a Beckmann one)".to_string(), |d| format!("{:.2}%", 100.0 * d));
    let note = format!(
        "approximated: {why}; wrote the nearest {to} lobe{}, fitted to the {} fit (maximum likelihood over theta <= {max_theta_deg} deg); NDF error delta(D_export; D_fit) = {}, delta(D_fit; D_export) = {}",
        if target == Target::Blender { " within Blender's limits" } else { "" },
        model.id(),
        fmt(delta),
        fmt(delta_reverse)
    );
    Ok(Export {
        target,
        lobe,
        approximation: Some(Approximation { from: model.id().as_str().into(), to, delta, delta_reverse, max_theta_deg }),
        note: Some(note),
    })
}

/// The lobe that equals a canonical single-lobe model exactly, if its kernel is a renderer's and it is
/// axis-aligned (every such model but a skewed ellipsoid). A mixture is exported lobe by lobe
/// (export/mixture.rs).
fn exact_lobe(model: &Model) -> Option<RendererLobe> {
    let spec = model.id().spec();
    if spec.is_mixture() {
        return None;
    }
    let distribution = spec.lobes[0].kernel.renderer()?;
    let g = spec.parts(&model.params(), 0);
    (g.theta_x == 0.0 && g.theta_y == 0.0).then(|| RendererLobe {
        distribution,
        alpha_u: g.alpha_x,
        alpha_v: g.alpha_y,
        tangent_angle: crate::models::canonical::fold_half_turn(-g.theta_z),
    })
}

/// The alphas a Blender node keeps: Cycles saturates each at [`BLENDER_MAX_ALPHA`] and bounds their ratio.
#[derive(Debug, Clone, Copy)]
struct Limits {
    max_ratio: f64,
}

impl Limits {
    /// Blender's limits for a lobe of `distribution` (the Principled BSDF's for GGX, the Glossy BSDF's for
    /// Beckmann); the other renderers have none.
    fn of(target: Target, distribution: Distribution) -> Option<Limits> {
        let max_ratio = match distribution {
            Distribution::Ggx => BLENDER_MAX_ANISOTROPY,
            Distribution::Beckmann => BLENDER_GLOSSY_MAX_ANISOTROPY,
        };
        (target == Target::Blender).then_some(Limits { max_ratio })
    }

    /// Whether the node holds `l` as it is (the ratio to rounding: an exact 10:1 fit is on the edge, not beyond).
    fn holds(&self, l: &RendererLobe) -> bool {
        l.alpha_u <= BLENDER_MAX_ALPHA && l.alpha_u <= self.max_ratio * l.alpha_v * (1.0 + 1e-12)
    }
}

/// Quadrature nodes `(m_k, W_k)` over the fit region, on a grid that follows the model's lobe.
struct RegionNodes {
    nodes: Vec<(Vector3<f64>, f64)>,
}

impl RegionNodes {
    fn new(model: &Model, max_theta_deg: f64) -> RegionNodes {
        let axes = model.axes().unwrap_or_else(|| {
            let a = model.params()[0];
            LobeAxes::aligned(a, a, 0.0)
        });
        // Slope-space centre (grad h convention: s = -(m_x, m_y) / m_z) and a covariance of the lobe's scale.
        let p = axes.peak;
        let center = [-p[0] / p[2], -p[1] / p[2]];
        let (c, s) = (axes.alpha_x[0], axes.alpha_x[1]);
        let (l1, l2) = (0.5 * axes.widths[0].powi(2), 0.5 * axes.widths[1].powi(2));
        let cov = [[c * c * l1 + s * s * l2, c * s * (l1 - l2)], [c * s * (l1 - l2), s * s * l1 + c * c * l2]];
        let frame = SlopeFrame::new(center, cov);
        let cos_max = max_theta_deg.to_radians().cos() - 1e-12;
        let nodes = RefNodes::new(&frame, APPROX_CELLS).nodes.into_iter().filter(|(m, _)| m.z >= cos_max).collect();
        RegionNodes { nodes }
    }
}

/// The renderer lobe of `distribution` maximizing `sum_k w_k ln(D(m_k) / S)`, `w_k = D_ref(m_k) W_k`,
/// `S = sum_k D(m_k) W_k` (module doc), within Blender's `limits` when given.
fn fit_lobe(
    reference: &Model,
    region: &RegionNodes,
    distribution: Distribution,
    limits: Option<Limits>,
    start: Option<RendererLobe>,
) -> Result<RendererLobe> {
    use argmin::core::{CostFunction, Executor};
    use argmin::solver::neldermead::NelderMead;

    let w: Vec<f64> = region.nodes.iter().map(|(m, wk)| reference.d(*m) * wk).collect();
    let wsum: f64 = w.iter().sum();
    if !wsum.is_finite() || wsum <= 0.0 {
        return Err(Error::invalid("the fitted NDF has no weight in the fit region; nothing to approximate"));
    }
    struct Cost<'a> {
        nodes: &'a [(Vector3<f64>, f64)],
        w: &'a [f64],
        wsum: f64,
        distribution: Distribution,
        limits: Option<Limits>,
        angle: Option<f64>,
    }
    impl CostFunction for Cost<'_> {
        type Param = Vec<f64>;
        type Output = f64;
        fn cost(&self, x: &Vec<f64>) -> std::result::Result<f64, argmin::core::Error> {
            let Some(model) = lobe_of(&with_angle(x, self.angle), self.distribution, self.limits).to_model().ok() else {
                return Ok(f64::INFINITY);
            };
            let (mut ll, mut s) = (0.0, 0.0);
            for ((m, wk), w) in self.nodes.iter().zip(self.w) {
                let d = model.d(*m);
                s += d * wk;
                if *w > 0.0 {
                    ll += w * d.max(f64::MIN_POSITIVE).ln();
                }
            }
            let f = -(ll / self.wsum - s.ln());
            Ok(if f.is_finite() { f } else { f64::INFINITY })
        }
    }
    // Start from the exact lobe (Beckmann, Blender's limits) or the skewed ellipsoid's slope-space axes.
    // An axis-aligned reference is symmetric about its own axes, and so is the likelihood over the cone of
    // the region: the nearest lobe keeps those axes, and only its two roughnesses are searched (a free
    // angle would stop wherever the simplex's tolerance met the flat valley, off the axes).
    let angle = start.map(|l| l.tangent_angle);
    let x0 = match start {
        Some(l) => vec![l.alpha_u.ln(), l.alpha_v.ln()],
        None => {
            let a = reference.axes().unwrap_or_else(|| LobeAxes::aligned(0.1, 0.1, 0.0));
            vec![a.widths[0].max(1e-4).ln(), a.widths[1].max(1e-4).ln(), a.alpha_x_azimuth]
        }
    };
    let mut best = x0;
    // Two rounds: the second restarts the simplex at the first's optimum (a collapsed simplex's cure).
    for _ in 0..2 {
        let mut simplex = vec![best.clone()];
        for i in 0..best.len() {
            let mut v = best.clone();
            // 10% in each alpha, 0.1 rad in the angle: the scale of the difference between the two lobes.
            v[i] += 0.1;
            simplex.push(v);
        }
        let solver = NelderMead::new(simplex).with_sd_tolerance(1e-12).map_err(|e| Error::invalid(format!("approximation fit: {e}")))?;
        let cost = Cost { nodes: &region.nodes, w: &w, wsum, distribution, limits, angle };
        let res = Executor::new(cost, solver)
            .configure(|s| s.max_iters(2000))
            .run()
            .map_err(|e| Error::invalid(format!("approximation fit: {e}")))?;
        if let Some(p) = res.state.best_param {
            best = p;
        }
    }
    Ok(lobe_of(&with_angle(&best, angle), distribution, limits))
}

/// The search parameters `(ln a1, ln a2, angle)` of a search over the roughnesses alone at a fixed `angle`.
fn with_angle(x: &[f64], angle: Option<f64>) -> Vec<f64> {
    x.iter().copied().chain(angle).collect()
}

/// The lobe of the search parameters `(ln a1, ln a2, angle)`, projected onto Blender's `limits` when given,
/// labeled canonically (`alpha_u >= alpha_v`, angle in `(-pi/2, pi/2]`).
fn lobe_of(x: &[f64], distribution: Distribution, limits: Option<Limits>) -> RendererLobe {
    let (mut a1, mut a2, mut t) = (x[0].exp(), x[1].exp(), x[2]);
    if a2 > a1 {
        std::mem::swap(&mut a1, &mut a2);
        t += std::f64::consts::FRAC_PI_2;
    }
    let floor = crate::models::ALPHA_MIN;
    a1 = a1.clamp(floor, crate::models::ALPHA_MAX);
    a2 = a2.clamp(floor, a1);
    if let Some(k) = limits {
        a1 = a1.min(BLENDER_MAX_ALPHA);
        a2 = a2.clamp(a1 / k.max_ratio, a1);
    }
    RendererLobe { distribution, alpha_u: a1, alpha_v: a2, tangent_angle: crate::models::canonical::fold_half_turn(t) }
}
