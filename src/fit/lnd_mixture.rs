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

use super::lnd::{LobeLnD, Shape};
use crate::models::ModelId;

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
    id: ModelId,
    lobe1: LobeLnD,
    lobe2: LobeLnD,
    /// `w`, `ln w`, `ln(1 - w)`.
    w: f64,
    ln_w: f64,
    ln_1w: f64,
}

impl MixtureLnD {
    /// Freeze mixture `id` at internal vector `x` (module docs).
    pub fn new(id: ModelId, x: &[f64]) -> MixtureLnD {
        let (lobe1, lobe2, v) = match id {
            ModelId::Ggx2 | ModelId::Beckmann2 => {
                let b = id == ModelId::Beckmann2;
                (
                    LobeLnD::with_shape(Shape::Aniso, b, true, &[x[0], x[1], x[4]]),
                    LobeLnD::with_shape(Shape::Aniso, b, true, &[x[2], x[3], x[4]]),
                    x[5],
                )
            }
            // ellipsoid+ggx (the only other id LnD::new sends here).
            _ => (LobeLnD::with_shape(Shape::Full, false, true, &x[..5]), LobeLnD::with_shape(Shape::Iso, false, true, &x[5..6]), x[6]),
        };
        MixtureLnD { id, lobe1, lobe2, w: 1.0 / (1.0 + (-v).exp()), ln_w: -softplus(-v), ln_1w: -softplus(v) }
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

    /// The gradient of `ln D(m)` with respect to the internal vector.
    #[inline]
    pub fn grad(&self, m: &Vector3<f64>, grad: &mut [f64]) {
        let (_, p1) = self.parts(m);
        let p2 = 1.0 - p1;
        let mut g1 = [0.0; 5];
        let mut g2 = [0.0; 3];
        match self.id {
            ModelId::Ggx2 | ModelId::Beckmann2 => {
                self.lobe1.grad(m, &mut g1[..3]);
                self.lobe2.grad(m, &mut g2);
                grad[0] = p1 * g1[0];
                grad[1] = p1 * g1[1];
                grad[2] = p2 * g2[0];
                grad[3] = p2 * g2[1];
                grad[4] = p1 * g1[2] + p2 * g2[2];
                grad[5] = p1 - self.w;
            }
            _ => {
                self.lobe1.grad(m, &mut g1);
                self.lobe2.grad(m, &mut g2[..1]);
                for j in 0..5 {
                    grad[j] = p1 * g1[j];
                }
                grad[5] = p2 * g2[0];
                grad[6] = p1 - self.w;
            }
        }
    }
}
