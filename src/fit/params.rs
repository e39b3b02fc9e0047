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
//! The mixtures' weight is logistic, `w = 1 / (1 + exp(-v))`, in `(0, 1)` for every real `v`
//! ([`super::lnd_mixture`] gives their internal vectors).

use crate::models::{ModelId, ALPHA_MIN};

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

/// Indices of the roughness entries (`u`) in a model's internal vector.
pub fn alpha_slots(id: ModelId) -> &'static [usize] {
    match id {
        ModelId::Ggx | ModelId::Beckmann => &[0],
        ModelId::Ggx2 | ModelId::Beckmann2 => &[0, 1, 2, 3],
        ModelId::EllipsoidGgx => &[0, 1, 5],
        _ => &[0, 1],
    }
}

/// Index of a mixture's weight (`v`) in its internal vector.
pub fn weight_slot(id: ModelId) -> Option<usize> {
    match id {
        ModelId::Ggx2 | ModelId::Beckmann2 => Some(5),
        ModelId::EllipsoidGgx => Some(6),
        _ => None,
    }
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
    for &i in alpha_slots(id) {
        p[i] = alpha_of(x[i]);
    }
    if let Some(i) = weight_slot(id) {
        p[i] = weight_of(x[i]);
    }
    p
}

/// The internal vector for the contract's parameters.
pub fn to_internal(id: ModelId, p: &[f64]) -> Vec<f64> {
    let mut x = p.to_vec();
    for &i in alpha_slots(id) {
        x[i] = u_of(p[i]);
    }
    if let Some(i) = weight_slot(id) {
        x[i] = v_of(p[i]);
    }
    x
}

/// `d public_i / d x_i` (the map is diagonal): `alpha - ALPHA_MIN` for roughnesses, `w (1 - w)` for a
/// weight, 1 for angles.
pub fn public_derivative(id: ModelId, x: &[f64]) -> Vec<f64> {
    let mut g = vec![1.0; x.len()];
    for &i in alpha_slots(id) {
        g[i] = x[i].exp();
    }
    if let Some(i) = weight_slot(id) {
        let w = weight_of(x[i]);
        g[i] = w * (1.0 - w);
    }
    g
}
