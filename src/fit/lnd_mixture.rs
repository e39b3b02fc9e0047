//! `ln D` of the two-lobe mixtures ([`crate::models::mixture`]) and its gradient.
//!
//! With the first lobe's weight `w = 1 / (1 + exp(-v))` (logistic, so every real `v` is a valid weight),
//! `a = ln w + ln D1`, `b = ln(1 - w) + ln D2`:
//!
//! `ln D = ln(exp a + exp b)` (log-sum-exp, so neither lobe's tail under- or overflows it),
//!
//! and with the lobes' responsibilities `p1 = exp(a - ln D)`, `p2 = 1 - p1`:
//! `d ln D / d x1 = p1 d ln D1 / d x1`, `d ln D / d x2 = p2 d ln D2 / d x2` (a shared `theta_z` gets
//! both terms), `d ln D / d v = w (1 - w) (D1 - D2) / D = p1 - w`.
//!
//! Internal vectors (roughnesses as `u` of [`super::params`], bounded by
//! [`super::params::LOBE_ALPHA_MAX`], the weight as `v`):
//! `ggx2`, `beckmann2`: `[u_x1, u_y1, u_x2, u_y2, theta_z, v]`;
//! `ellipsoid+ggx`: `[u_x1, u_y1, theta_x, theta_y, theta_z, u2, v]`.

use nalgebra::Vector3;

use super::lnd::LobeLnD;
use crate::models::{ModelId, Role};

/// `ln(1 + exp(x))` without overflow.
#[inline]
pub fn softplus(x: f64) -> f64 {
    if x > 0.0 {
        x + (-x).exp().ln_1p()
    } else {
        x.exp().ln_1p()
    }
}

/// A mixture frozen at one internal vector.
#[derive(Debug, Clone)]
pub struct MixtureLnD {
    lobe1: LobeLnD,
    lobe2: LobeLnD,
    /// Each lobe's slots in the internal vector (the table's roles), and how many.
    slots: [([usize; 6], usize); 2],
    /// The weight's slot.
    wi: usize,
    /// `w`, `ln w`, `ln(1 - w)`.
    w: f64,
    ln_w: f64,
    ln_1w: f64,
}

impl MixtureLnD {
    /// Freeze mixture `id` at internal vector `x` (module docs): each lobe reads its own slots.
    pub fn new(id: ModelId, x: &[f64]) -> MixtureLnD {
        let spec = id.spec();
        let mut slots = [([0usize; 6], 0usize); 2];
        let lobe = |k: usize, slots: &mut [([usize; 6], usize); 2]| {
            let mut xl = [0.0; 6];
            for (j, i) in spec.lobe_slots(k).enumerate() {
                slots[k].0[j] = i;
                xl[j] = x[i];
                slots[k].1 = j + 1;
            }
            let l = spec.lobes[k];
            LobeLnD::with_shape(l.form, l.kernel, true, &xl[..slots[k].1])
        };
        let lobe1 = lobe(0, &mut slots);
        let lobe2 = lobe(1, &mut slots);
        let wi = spec.slot_any(Role::Weight).unwrap_or(x.len() - 1);
        let v = x[wi];
        MixtureLnD { lobe1, lobe2, slots, wi, w: 1.0 / (1.0 + (-v).exp()), ln_w: -softplus(-v), ln_1w: -softplus(v) }
    }

    /// `(ln D, p1)`.
    #[inline]
    fn parts(&self, m: &Vector3<f64>) -> (f64, f64) {
        let a = self.ln_w + self.lobe1.value(m);
        let b = self.ln_1w + self.lobe2.value(m);
        let hi = a.max(b);
        let ln_d = hi + ((a - hi).exp() + (b - hi).exp()).ln();
        (ln_d, (a - ln_d).exp())
    }

    /// `ln D(m)` for a unit `m` with `m.z > 0`.
    #[inline]
    pub fn value(&self, m: &Vector3<f64>) -> f64 {
        self.parts(m).0
    }

    /// The gradient of `ln D(m)` with respect to the internal vector: each lobe's gradient weighted by its
    /// responsibility, added into its slots (a shared `theta_z` gets both terms).
    #[inline]
    pub fn grad(&self, m: &Vector3<f64>, grad: &mut [f64]) {
        let (_, p1) = self.parts(m);
        let p2 = 1.0 - p1;
        grad.fill(0.0);
        let mut g = [0.0; 6];
        for (lobe, p, (idx, n)) in [(&self.lobe1, p1, &self.slots[0]), (&self.lobe2, p2, &self.slots[1])] {
            lobe.grad(m, &mut g[..*n]);
            for j in 0..*n {
                grad[idx[j]] += p * g[j];
            }
        }
        grad[self.wi] = p1 - self.w;
    }
}
