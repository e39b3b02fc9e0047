//! The fit parameterization: what Levenberg-Marquardt moves, and how it maps to the contract's parameters.
//!
//! The `levenberg-marquardt` crate has no bounds, so the parameterization itself keeps every model valid:
//! - each roughness is `alpha = ALPHA_MIN + exp(u)`, so `alpha > ALPHA_MIN` for every real `u` (no bound
//!   is ever hit, no NaN from a negative alpha), and relative changes of alpha are what the objective
//!   responds to (D scales as `1/alpha^2` near the peak), so `u` is well conditioned from 1e-4 to 10
//!   where a linear alpha would need steps spanning five decades;
//! - the angles are free: D is periodic in them, so LM never meets an edge; the result is folded to the
//!   canonical form afterwards ([`crate::models::Model::canonical`]).
//!
//! Internal vectors `x` by model (Walter et al. eq. 2-3 for the angles):
//! `ggx`, `beckmann`: `[u]`; `ggx-aniso`, `beckmann-aniso`: `[u_x, u_y, theta_z]`;
//! `ellipsoid`: `[u_x, u_y, theta_x, theta_y, theta_z]`.
//!
//! A Student-t tail's `gamma` is bounded logistic, `gamma = GAMMA_MIN + (GAMMA_MAX - GAMMA_MIN) / (1 + exp(-g))`
//! ([`gamma_of`]).
//!
//! The mixtures' weight is logistic, `w = 1 / (1 + exp(-v))`, in `(0, 1)` for every real `v`
//! (`lnd_mixture` gives their internal vectors). A mixture lobe's roughness is bounded above as
//! well, `alpha = ALPHA_MIN + (LOBE_ALPHA_MAX - ALPHA_MIN) / (1 + exp(-u))` ([`LOBE_ALPHA_MAX`] says why);
//! near the floor this is the single lobes' map scaled (`ALPHA_MIN + (LOBE_ALPHA_MAX - ALPHA_MIN) exp(u)`),
//! and the single lobes keep theirs, so their fits do not move.

use crate::models::student::{GAMMA_MAX, GAMMA_MIN};
use crate::models::{ModelId, Role, ALPHA_MIN};

/// The largest roughness of a mixture lobe (`ggx2`, `beckmann2`, `ellipsoid+ggx`), on every axis; the
/// Python cross-check bounds its search by the same value. Beyond it a lobe is flat over the fitted slopes:
/// GGX's `(1 + s^2 / alpha^2)^-2` is within `2 s^2 / alpha^2` of its `alpha -> infinity` limit, `1.5e-5` at
/// `s = tan 70 deg` (the default `max_theta`; Beckmann's `exp(-s^2 / alpha^2)` within half that), far below
/// any bin's counting error. Such a lobe's weight and width are then no longer told apart by the data (only
/// their ratio is): without a bound a near-uniform second lobe of tiny weight drifts along that flat valley
/// to alphas of 1e4-1e5, wherever the solver stops. A lobe ending at the bound is flagged in the fit report
/// (`warnings`): it is a flat background along that axis, and a renderer should read it as such.
pub const LOBE_ALPHA_MAX: f64 = 1e3;

/// Whether model `id`'s roughnesses use the bounded map ([`bounded_alpha_of`]): the mixtures'.
#[inline]
pub fn bounded(id: ModelId) -> bool {
    id.is_mixture()
}

/// `u -> alpha` of a mixture lobe: `ALPHA_MIN + (LOBE_ALPHA_MAX - ALPHA_MIN) / (1 + exp(-u))`, in
/// `(ALPHA_MIN, LOBE_ALPHA_MAX)` for every real `u`.
#[inline]
pub fn bounded_alpha_of(u: f64) -> f64 {
    ALPHA_MIN + (LOBE_ALPHA_MAX - ALPHA_MIN) * weight_of(u)
}

/// `d alpha / d u` of [`bounded_alpha_of`]: `(LOBE_ALPHA_MAX - ALPHA_MIN) s (1 - s)`, `s = 1 / (1 + exp(-u))`
/// (`1 - s` as `s(-u)`, exact near the bound).
#[inline]
pub fn bounded_alpha_du(u: f64) -> f64 {
    (LOBE_ALPHA_MAX - ALPHA_MIN) * weight_of(u) * weight_of(-u)
}

/// `alpha -> u`, the inverse of [`bounded_alpha_of`]; an alpha at (or beyond) either end maps to a finite `u`
/// whose alpha is that end to 1e-12 relative.
#[inline]
pub fn bounded_u_of(alpha: f64) -> f64 {
    let range = LOBE_ALPHA_MAX - ALPHA_MIN;
    let t = ((alpha - ALPHA_MIN).max(ALPHA_MIN * 1e-12) / range).min(1.0 - 1e-12);
    t.ln() - (-t).ln_1p()
}

/// `u -> alpha` of model `id` ([`alpha_of`], or [`bounded_alpha_of`] for a mixture).
#[inline]
pub fn alpha_of_model(id: ModelId, u: f64) -> f64 {
    if bounded(id) {
        bounded_alpha_of(u)
    } else {
        alpha_of(u)
    }
}

/// Whether a mixture's fitted roughness sits at [`LOBE_ALPHA_MAX`] (within `1e-3` relative: the solver
/// approaches the bound as the logistic saturates).
#[inline]
pub fn at_lobe_bound(alpha: f64) -> bool {
    alpha >= LOBE_ALPHA_MAX * (1.0 - 1e-3)
}

/// `u -> alpha`: `ALPHA_MIN + exp(u)`.
#[inline]
pub fn alpha_of(u: f64) -> f64 {
    ALPHA_MIN + u.exp()
}

/// `alpha -> u`, the inverse of [`alpha_of`]. An alpha at (or below) the floor maps to a `u` whose alpha
/// is the floor to 1e-12 relative, since `ln 0` is not a parameter.
#[inline]
pub fn u_of(alpha: f64) -> f64 {
    // Guard: alpha - ALPHA_MIN may be 0 or negative for a floored alpha; keep u finite.
    (alpha - ALPHA_MIN).max(ALPHA_MIN * 1e-12).ln()
}

/// Indices of the roughness entries (`u`) in a model's internal vector (the table's alpha roles).
pub fn alpha_slots(id: ModelId) -> impl Iterator<Item = usize> {
    id.spec().roles.iter().enumerate().filter(|(_, (r, _))| r.is_alpha()).map(|(i, _)| i)
}

/// Index of a mixture's weight (`v`) in its internal vector.
pub fn weight_slot(id: ModelId) -> Option<usize> {
    id.spec().slot_any(Role::Weight)
}

/// Index of a Student-t tail's `gamma` (`g`) in a model's internal vector.
pub fn gamma_slot(id: ModelId) -> Option<usize> {
    id.spec().slot_any(Role::Gamma)
}

/// `g -> gamma` of a Student-t tail: `GAMMA_MIN + (GAMMA_MAX - GAMMA_MIN) / (1 + exp(-g))`, in
/// `(GAMMA_MIN, GAMMA_MAX)` for every real `g` ([`crate::models::student`] says why those ends). Near the
/// GGX value 2 it is `GAMMA_MIN + (GAMMA_MAX - GAMMA_MIN) exp(g)`: relative changes of `gamma - 3/2` are what
/// LM moves, as for the roughnesses.
#[inline]
pub fn gamma_of(g: f64) -> f64 {
    GAMMA_MIN + (GAMMA_MAX - GAMMA_MIN) * weight_of(g.max(G_LOW))
}

/// Lowest `g` that [`gamma_of`] follows: below about -48 `GAMMA_MIN + (GAMMA_MAX - GAMMA_MIN) exp(g)` rounds
/// to `GAMMA_MIN` itself, which no lobe may take; at -30 `gamma` is 3/2 + 9e-9, the bound for every purpose.
pub const G_LOW: f64 = -30.0;

/// `d gamma / d g` of [`gamma_of`] (0 below [`G_LOW`], where the map is flat).
#[inline]
pub fn gamma_dg(g: f64) -> f64 {
    if g < G_LOW {
        return 0.0;
    }
    (GAMMA_MAX - GAMMA_MIN) * weight_of(g) * weight_of(-g)
}

/// `gamma -> g`, the inverse of [`gamma_of`]; a `gamma` at (or beyond) either end maps to a finite `g`.
#[inline]
pub fn g_of(gamma: f64) -> f64 {
    let t = ((gamma - GAMMA_MIN) / (GAMMA_MAX - GAMMA_MIN)).clamp(1e-15, 1.0 - 1e-12);
    t.ln() - (-t).ln_1p()
}

/// `v -> w`: `1 / (1 + exp(-v))`.
#[inline]
pub fn weight_of(v: f64) -> f64 {
    1.0 / (1.0 + (-v).exp())
}

/// `w -> v`, the inverse of [`weight_of`] (a weight at 0 or 1 maps to a large finite `v`).
#[inline]
pub fn v_of(w: f64) -> f64 {
    let w = w.clamp(1e-15, 1.0 - 1e-15);
    (w / (1.0 - w)).ln()
}

/// The contract's parameters (order of [`ModelId::param_names`]) from an internal vector.
pub fn to_public(id: ModelId, x: &[f64]) -> Vec<f64> {
    let mut p = x.to_vec();
    for i in alpha_slots(id) {
        p[i] = alpha_of_model(id, x[i]);
    }
    if let Some(i) = weight_slot(id) {
        p[i] = weight_of(x[i]);
    }
    if let Some(i) = gamma_slot(id) {
        p[i] = gamma_of(x[i]);
    }
    p
}

/// The internal vector for the contract's parameters.
pub fn to_internal(id: ModelId, p: &[f64]) -> Vec<f64> {
    let mut x = p.to_vec();
    for i in alpha_slots(id) {
        x[i] = if bounded(id) { bounded_u_of(p[i]) } else { u_of(p[i]) };
    }
    if let Some(i) = weight_slot(id) {
        x[i] = v_of(p[i]);
    }
    if let Some(i) = gamma_slot(id) {
        x[i] = g_of(p[i]);
    }
    x
}

/// `d public_i / d x_i` (the map is diagonal): `alpha - ALPHA_MIN` for roughnesses ([`bounded_alpha_du`]
/// for a mixture's), `w (1 - w)` for a weight, 1 for angles.
pub fn public_derivative(id: ModelId, x: &[f64]) -> Vec<f64> {
    let mut g = vec![1.0; x.len()];
    for i in alpha_slots(id) {
        g[i] = if bounded(id) { bounded_alpha_du(x[i]) } else { x[i].exp() };
    }
    if let Some(i) = weight_slot(id) {
        let w = weight_of(x[i]);
        g[i] = w * (1.0 - w);
    }
    if let Some(i) = gamma_slot(id) {
        g[i] = gamma_dg(x[i]);
    }
    g
}
