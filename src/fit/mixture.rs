//! Fitting the two-lobe mixtures ([`crate::models::mixture`]): starts from the single-lobe fit they
//! extend, the price a second lobe must pay in deviance, and the data's overdispersion the ladder of
//! `--model auto` guards with (`data_formats/objective.md`, "Mixtures and the ladder").

use super::{fit_chain, fit_from, public, FitOptions, Fitted, Session};
use crate::error::Result;
use crate::models::table::{Parts, L1};
use crate::models::{ModelId, Role};

/// The single-lobe model a mixture extends (its first stage, and its parent in the selection report):
/// the table's parent of a mixture (`ggx2` -> `ggx-aniso`, `beckmann2` -> `beckmann-aniso`, `ellipsoid+ggx`
/// -> `ellipsoid`).
pub fn parent_of(id: ModelId) -> Option<ModelId> {
    id.parent().filter(|_| id.is_mixture())
}

/// Whether the second lobe has the parent's own shape, so that two copies of the parent are the parent
/// (`ggx2`, `beckmann2`); otherwise the core is the parent and the tail a lobe of another shape
/// (`ellipsoid+ggx`).
fn twin_lobes(id: ModelId) -> bool {
    let l = id.spec().lobes;
    l.len() == 2 && l[0] == l[1]
}

/// Mixture `id`'s parameters from its parent's geometry `g`: each role of the first lobe takes the
/// parent's value (roughnesses times `kc`), the second lobe's roughnesses `kt` times the parent's (an
/// isotropic tail `kt sqrt(alpha_x alpha_y)`), the weight `w`.
fn grow(id: ModelId, g: &Parts, kc: f64, kt: f64, w: f64) -> Vec<f64> {
    id.spec()
        .roles
        .iter()
        .map(|&(role, lobes)| {
            let k = if lobes == L1 { kc } else { kt };
            match role {
                Role::Alpha => k * (g.alpha_x * g.alpha_y).sqrt(),
                Role::AlphaX => k * g.alpha_x,
                Role::AlphaY => k * g.alpha_y,
                Role::ThetaX => g.theta_x,
                Role::ThetaY => g.theta_y,
                Role::ThetaZ => g.theta_z,
                Role::Gamma => g.gamma.unwrap_or(2.0),
                Role::Weight => w,
            }
        })
        .collect()
}

/// The parent's geometry (contract parameters `parent`) of mixture `id`.
fn parent_parts(id: ModelId, parent: &[f64]) -> Parts {
    parent_of(id).map_or_else(|| id.spec().parts(parent, 0), |p| p.spec().parts(parent, 0))
}

/// The (core scale, tail scale, core weight) of each start: the core narrower and the tail wider than
/// the one lobe that fits both, the tail's share from a few percent to a half; and a spike of a few percent
/// five times narrower than the one lobe (a specular patch on a rough scan).
const SPLITS: [(f64, f64, f64); 4] = [(0.7, 3.0, 0.7), (0.9, 2.0, 0.5), (0.85, 5.0, 0.9), (0.2, 1.05, 0.03)];

/// Starting points (contract parameters) of mixture `id` from its parent's fit (contract parameters);
/// `ellipsoid+ggx` adds [`residual_starts`].
pub fn starts(id: ModelId, parent: &[f64]) -> Vec<Vec<f64>> {
    let g = parent_parts(id, parent);
    SPLITS.iter().map(|&(kc, kt, w)| grow(id, &g, kc, kt, w)).collect()
}

/// The core's weight when an `ellipsoid+ggx` stands for its parent: the isotropic tail cannot copy a
/// skewed, anisotropic ellipsoid, so the parent is the limit `w -> 1`, taken to where the tail's share
/// moves the deviance by about `1e-13` relative.
pub const PARENT_CORE_WEIGHT: f64 = 1.0 - 1e-13;

/// The residual-peak starts of `ellipsoid+ggx`, from the data: the isotropic GGX tail takes the one
/// ellipsoid's place (its `alpha` the ellipsoid's `sqrt(alpha_x alpha_y)`) and the core, half as wide,
/// sits on a peak of the counts' excess over the one-lobe fit's expectation `E_k = N W_k D(m_k) / S`
/// (objective.md), with the share of the normals in excess within `2 alpha` (slope) of it. Two peaks:
/// the largest excess, and the largest outside the first one's disc; each core points at the
/// excess-weighted mean direction of its disc. They find a secondary facet direction or an off-centre
/// specular patch that the splits of the one lobe, all centred on its peak, do not reach. The core's
/// tilt puts its peak, the third row of `R` (Walter et al. eq. 1-3: `D ~ |S^-1 R m|^-4` peaks at
/// `R m = z`), on that direction.
pub fn residual_starts(data: &super::objective::FitData, id: ModelId, parent: &[f64]) -> Vec<Vec<f64>> {
    use crate::models::Ndf;
    let Some(pid) = parent_of(id) else { return Vec::new() };
    let Ok(model) = crate::models::Model::from_params(pid, parent) else { return Vec::new() };
    let d: Vec<f64> = data.bins.iter().map(|b| model.d(b.m)).collect();
    let norm: f64 = data.bins.iter().zip(&d).map(|(b, d)| d * b.w).sum();
    if !(norm > 0.0 && norm.is_finite() && data.n > 0.0) {
        return Vec::new();
    }
    let excess: Vec<f64> = data.bins.iter().zip(&d).map(|(b, d)| b.c - data.n * b.w * d / norm).collect();
    let a = (parent[0] * parent[1]).sqrt();
    let cos_r = 1.0 / (1.0 + 4.0 * a * a).sqrt();
    let mut out = Vec::new();
    let mut taken: Vec<nalgebra::Vector3<f64>> = Vec::new();
    for _ in 0..2 {
        let free = |k: &usize| taken.iter().all(|t| data.bins[*k].m.dot(t) < cos_r);
        let Some(k) = (0..excess.len()).filter(free).max_by(|&a, &b| excess[a].total_cmp(&excess[b])) else { break };
        if !(excess[k] > 0.0) {
            break;
        }
        let peak = data.bins[k].m;
        taken.push(peak);
        let mut near = 0.0;
        let mut centre = nalgebra::Vector3::zeros();
        for (b, e) in data.bins.iter().zip(&excess) {
            if *e > 0.0 && b.m.dot(&peak) >= cos_r {
                near += e;
                centre += *e * b.m;
            }
        }
        let dir = centre.try_normalize(0.0).unwrap_or(peak);
        let w = (near / data.n).clamp(0.01, 0.5);
        let (sn, cs) = parent[4].sin_cos();
        let r3 = [cs * dir.x - sn * dir.y, sn * dir.x + cs * dir.y, dir.z];
        let (tx, ty) = (r3[1].clamp(-1.0, 1.0).asin(), (-r3[0]).atan2(r3[2]));
        out.push(vec![0.5 * parent[0], 0.5 * parent[1], tx, ty, parent[4], a, w]);
    }
    out
}

/// The ridge starts of `ggx2` and `beckmann2`, from the data: a lobe at the alpha floor across one of the
/// parent's axes, holding the normals in excess of the parent's expectation `E_k = N W_k D(m_k) / S`
/// (objective.md) in the band of slopes within half the parent's alpha of that axis, as wide along it as
/// the root-mean-square slope of that excess; the second lobe is the parent. On a quantized or striated
/// scan the slopes pile up on lines of constant slope (one height step per pixel across, none along),
/// which one lobe spreads over its whole width; the splits, all scaled copies of the parent, do not reach
/// such a line. One start per axis, the parent's `alpha_x` axis along `(cos theta_z, -sin theta_z)` in the
/// scan frame (azimuth `-theta_z`).
pub fn ridge_starts(data: &super::objective::FitData, id: ModelId, parent: &[f64]) -> Vec<Vec<f64>> {
    use crate::models::Ndf;
    let Some(pid) = parent_of(id).filter(|_| twin_lobes(id)) else { return Vec::new() };
    let Ok(model) = crate::models::Model::from_params(pid, parent) else { return Vec::new() };
    let d: Vec<f64> = data.bins.iter().map(|b| model.d(b.m)).collect();
    let norm: f64 = data.bins.iter().zip(&d).map(|(b, d)| d * b.w).sum();
    if !(norm > 0.0 && norm.is_finite() && data.n > 0.0) {
        return Vec::new();
    }
    let (ax, ay, tz) = (parent[0], parent[1], parent[2]);
    let (sn, cs) = tz.sin_cos();
    let floor = 1.5 * crate::models::ALPHA_MIN;
    let mut out = Vec::new();
    for axis in 0..2 {
        let half_across = 0.5 * if axis == 0 { ay } else { ax };
        let (mut held, mut second) = (0.0, 0.0);
        for (b, d) in data.bins.iter().zip(&d) {
            let e = b.c - data.n * b.w * d / norm;
            if !(e > 0.0 && b.m.z > 0.0) {
                continue;
            }
            let (sx, sy) = (-b.m.x / b.m.z, -b.m.y / b.m.z);
            // Slopes in the parent's frame: x' along (cos tz, -sin tz), y' along (sin tz, cos tz).
            let (su, sv) = (cs * sx - sn * sy, sn * sx + cs * sy);
            let (along, across) = if axis == 0 { (su, sv) } else { (sv, su) };
            if across.abs() <= half_across {
                held += e;
                second += e * along * along;
            }
        }
        if !(held > 0.0) {
            continue;
        }
        let width = (second / held).sqrt().max(floor);
        let w = (held / data.n).clamp(0.005, 0.5);
        let (a1, b1) = if axis == 0 { (width, floor) } else { (floor, width) };
        out.push(vec![a1, b1, ax, ay, tz, w]);
    }
    out
}

/// The parent written as the mixture: two copies of itself at weight one half (`ggx2`, `beckmann2`), or
/// the core holding all but [`PARENT_CORE_WEIGHT`]'s remainder when the tail cannot copy it (`ellipsoid+ggx`).
/// The same D (to that remainder), so the same objective.
pub fn degenerate(id: ModelId, parent: &[f64]) -> Vec<f64> {
    let w = if twin_lobes(id) { 0.5 } else { PARENT_CORE_WEIGHT };
    grow(id, &parent_parts(id, parent), 1.0, 1.0, w)
}

/// The deviance a second lobe must remove to be reported: its added parameters' price in the ladder,
/// `(p - p_parent) ln N` ([`price`]; `N` the normals in the region), at the smallest overdispersion the
/// ladder uses (`c = 1`). A mixture that removes less is reported as its parent ([`degenerate`]): the
/// deviance does not tell such a lobe from noise, and it is where the mixture's optimum is not unique (a
/// lobe between the bins' centres, a sub-percent lobe free in its width along the flat valley of its weight,
/// or one of several equally good sub-percent spikes on the noise of a one-lobe scan). Reporting the
/// mixture's lower-complexity limit makes the result unique; `auto` never chooses such a mixture over its
/// parent (its criterion `F / c + p ln N` is above the parent's). The Python cross-check applies the same rule.
pub fn price(id: ModelId, parent: ModelId, n: f64) -> f64 {
    (id.n_params() as f64 - parent.n_params() as f64) * n.max(1.0).ln()
}

/// LM patience of a mixture start (evaluations are limited to `patience * (p + 1)`): on data one lobe
/// describes, the mixture's weight and second lobe are nearly free and LM creeps along that flat valley
/// for its whole budget (1,660 evaluations, 0.9 s, for `ellipsoid+ggx` on a 5,000-bin scan at the default
/// 200) without lowering the deviance by more than its tolerance.
pub const MIXTURE_PATIENCE: usize = 40;

/// Fit mixture `id` from the fit of its parent. A mixture holds its parent (two equal lobes), so its
/// optimum can be no worse: should every start end above the parent's objective (a local optimum, e.g.
/// on data one lobe describes), the parent written as a mixture is the result, said so in a warning.
pub(super) fn fit_mixture(s: &Session, id: ModelId, parent: &Fitted, opts: &FitOptions) -> Result<Fitted> {
    let p = public(parent);
    let mut o = *opts;
    o.tolerances.max_iter = o.tolerances.max_iter.min(MIXTURE_PATIENCE);
    let mut st = starts(id, &p);
    if twin_lobes(id) {
        st.extend(ridge_starts(&s.data, id, &p));
    } else {
        st.extend(residual_starts(&s.data, id, &p));
    }
    let mut fit = fit_from(s, id, &st, &o);
    // The best start, stopped by the patience before it converged, is carried to the optimum with the
    // caller's own patience.
    if let Ok(f) = &fit {
        if !f.local.converged && opts.tolerances.max_iter > o.tolerances.max_iter {
            if let Ok(g) = fit_from(s, id, &[public(f)], opts) {
                if g.f <= f.f {
                    let evaluations = f.evaluations + g.evaluations;
                    fit = Ok(Fitted { evaluations, start_objectives: f.start_objectives.clone(), best_start: f.best_start, ..g });
                }
            }
        }
    }
    // A lobe on its way to the roughness bound is taken there.
    if let Ok(f) = &fit {
        if let Some(g) = to_bound(s, id, f, opts) {
            fit = Ok(g);
        }
    }
    // A usable fit better than the parent by its price stands. Otherwise (no start that far below the parent, no finite
    // start, or a lobe run off beyond the alpha range, e.g. a tail widening without bound to take up a flat
    // background) the parent written as a mixture is the result, said so in a warning.
    let valid = |f: &Fitted| crate::models::Model::from_params(id, &public(f)).is_ok();
    if let Ok(fit) = &fit {
        if fit.f < parent.f - price(id, parent.id, s.data.n) && valid(fit) {
            let mut fit = fit.clone();
            fit.warnings.extend(bound_notes(id, &public(&fit)));
            return Ok(fit);
        }
    }
    let x = super::params::to_internal(id, &degenerate(id, &p));
    let mut r = vec![0.0; s.data.bins.len()];
    let f = super::problem::residuals_into(&s.data, id, &x, &mut r);
    let why = match &fit {
        Ok(g) if valid(g) => format!(
            "no start lowered the deviance of the one-lobe {} fit by the price of the added parameters, (p - p_parent) ln N = {:.1} (best: {:.1})",
            parent.id,
            price(id, parent.id, s.data.n),
            parent.f - g.f
        ),
        Ok(_) => "the fit ran out of the model's domain (a lobe beyond the alpha range)".to_string(),
        Err(e) => format!("no start gave a usable fit ({})", e.message()),
    };
    let mut warnings = fit.as_ref().map(|g| g.warnings.clone()).unwrap_or_default();
    let as_what = if twin_lobes(id) { "two equal lobes" } else { "the ellipsoid core alone" };
    warnings.push(format!("{id}: {why}; reported as the one-lobe {} fit ({as_what}: the data show no second lobe it can fit)", parent.id));
    let local = super::solve::Local {
        x: x.clone(),
        f,
        termination: format!("{id}: the one-lobe {} fit ({as_what})", parent.id),
        converged: true,
        evaluations: 0,
    };
    let (evaluations, start_objectives, best_start) = match &fit {
        Ok(g) => (g.evaluations, g.start_objectives.clone(), g.best_start),
        Err(_) => (0, Vec::new(), 0),
    };
    Ok(Fitted { id, x, f, local, evaluations, start_objectives, best_start, warnings, delta: false })
}

/// A mixture fit whose roughnesses are flat to 1% over the region (`2 s_max^2 / alpha^2 <= 0.01`, `s_max` the
/// steepest slope of its bins: `alpha >= 10 sqrt(2) s_max`) and not yet at [`super::params::LOBE_ALPHA_MAX`] set
/// to the bound and the rest refitted, when that does not raise the objective; the lobe's odds are scaled by
/// `alpha / LOBE_ALPHA_MAX` per flat axis (`w / alpha` is what the region measures of a flat lobe), so the
/// refit starts from the same D over the region. Along such a lobe's flat valley the bounded map's derivative
/// vanishes towards the bound, so LM stops wherever its tolerance meets the valley's slope (deviance changes of
/// 1e-9 relative), where the bound is the valley's end: the refit makes the end point the valley's, not the
/// solver's. The Python cross-check ends the valley by the same rule (objective.md, "The lobes' roughness
/// bound").
/// `alpha / s_max` beyond which a lobe is flat to 1% over slopes up to `s_max`: `10 sqrt(2)`.
pub const FLAT_LOBE: f64 = 14.142_135_623_730_951;

fn to_bound(s: &Session, id: ModelId, f: &Fitted, opts: &FitOptions) -> Option<Fitted> {
    let max = super::params::LOBE_ALPHA_MAX;
    let mut q = public(f);
    let wi = super::params::weight_slot(id)?;
    // The first lobe's log-odds; a lobe flat along an axis has its density over the region scaled by
    // `1 / alpha` on that axis (`1 / alpha^2` for an isotropic tail), so its odds grow with alpha to keep it.
    let mut v = super::params::v_of(q[wi]);
    let s_max = s.data.bins.iter().map(|b| (1.0 - b.m.z * b.m.z).max(0.0).sqrt() / b.m.z).fold(0.0, f64::max);
    let flat = FLAT_LOBE * s_max;
    let mut moved = false;
    for i in super::params::alpha_slots(id) {
        if q[i] >= flat && !super::params::at_lobe_bound(q[i]) {
            let (role, lobes) = id.spec().roles[i];
            let first = lobes == crate::models::table::L1;
            // An isotropic lobe's one roughness spans both axes.
            let axes = if role == crate::models::Role::Alpha { 2.0 } else { 1.0 };
            let shift = axes * (max / q[i]).ln();
            v += if first { shift } else { -shift };
            q[i] = max;
            moved = true;
        }
    }
    if !moved {
        return None;
    }
    q[wi] = super::params::weight_of(v);
    let g = fit_from(s, id, &[q], opts).ok()?;
    (g.f <= f.f).then(|| Fitted {
        evaluations: f.evaluations + g.evaluations,
        start_objectives: f.start_objectives.clone(),
        best_start: f.best_start,
        ..g
    })
}

/// One note per roughness of a mixture fit `p` (contract parameters) that ends at
/// [`super::params::LOBE_ALPHA_MAX`]: that lobe is flat along the axis over the fitted slopes, and only the
/// ratio of its weight to its width is measured there (the bound fixes the width).
pub fn bound_notes(id: ModelId, p: &[f64]) -> Vec<String> {
    let names = id.param_names();
    super::params::alpha_slots(id)
        .filter(|&i| super::params::at_lobe_bound(p[i]))
        .map(|i| {
            format!(
                "{id}: {} = {:.4} is at the mixture lobes' bound {}: that lobe is flat along this axis over the fitted slopes \
                 (a background; its weight and width are not told apart, the bound fixes the width)",
                names[i],
                p[i],
                super::params::LOBE_ALPHA_MAX
            )
        })
        .collect()
}

/// Fit mixture `id` with its parent's chain first.
pub(super) fn fit_mixture_chain(s: &Session, id: ModelId, opts: &FitOptions) -> Result<Fitted> {
    let parent = parent_of(id).expect("a mixture id");
    let p = fit_chain(s, parent, opts)?;
    fit_mixture(s, id, &p, opts)
}

/// `c_data = max(1, dispersion)` of the data ([`super::verdict::data_dispersion`]), or `c_single` when the
/// NDF has no split.
pub(super) fn data_c(ndf: &crate::ndf::EmpiricalNdf, s: &Session, c_single: f64) -> f64 {
    super::verdict::data_dispersion(ndf, s.data.max_theta).filter(|d| d.is_finite()).map_or(c_single, |d| d.max(1.0))
}
