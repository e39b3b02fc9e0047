//! `ln D` of every model and its gradient with respect to the fit parameters of [`super::params`]: the
//! analytic Jacobian behind the LM fit (checked against central differences in the tests).
//!
//! Ellipsoid (Walter et al. eq. 1-3): with `A = S R`, `S = diag(ax, ay, 1)`, `R = Rx Ry Rz`,
//! `A^-T m = S^-1 R m`, `|A| = ax ay` and `||A n||^2 = ax^2 sy^2 + ay^2 sx^2 cy^2 + cx^2 cy^2`
//! (`A n = S R e_z`, the third column of `Rx Ry`), so with `v = R m` and
//! `q = v1^2/ax^2 + v2^2/ay^2 + v3^2`:
//!
//! `ln D = -ln pi - ln ax - ln ay - 1/2 ln ||A n||^2 - 2 ln q`.
//!
//! GGX and GTR2aniso are this with `theta_x = theta_y = 0` (Walter et al. sec. 4.2); isotropic GGX ties
//! both roughnesses to one parameter. Anisotropic Beckmann (Heitz eq. 82) with `l = Rz m`:
//! `ln D = -(l1^2/ax^2 + l2^2/ay^2)/l3^2 - ln pi - ln ax - ln ay - 4 ln l3`.
//! The Student-t lobe ([`crate::models::student`]) with `e = (l1^2/ax^2 + l2^2/ay^2)/l3^2`, `p = gamma - 1`:
//! `ln D = -gamma ln(1 + e/p) - ln pi - ln ax - ln ay - 4 ln l3`, whose `gamma` derivative is
//! `-ln(1 + e/p) + gamma e / (p (p + e))`.

use nalgebra::{Matrix3, Vector3};

use super::params::{alpha_of, bounded_alpha_du, bounded_alpha_of, gamma_dg, gamma_of};
use crate::models::ellipsoid::rotation_xyz;
use crate::models::table::{Form, Kernel};
use crate::models::ModelId;

const LN_PI: f64 = 1.144_729_885_849_400_2;

/// Which internal parameters a lobe's evaluation exposes (the table's [`Form`]): `[u]` (one roughness for
/// both axes), `[u_x, u_y, theta_z]`, or the ellipsoid's `[u_x, u_y, theta_x, theta_y, theta_z]`.
pub(crate) type Shape = Form;

/// A model frozen at one internal parameter vector: one lobe ([`LobeLnD`]) or a two-lobe mixture
/// (`lnd_mixture`).
// Built once per residual or Jacobian pass and read per bin: its size costs nothing, a box would cost a
// pointer chase per bin.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone)]
pub enum LnD {
    /// A single-lobe model.
    One(LobeLnD),
    /// A mixture.
    Two(super::lnd_mixture::MixtureLnD),
}

impl LnD {
    /// Freeze model `id` at internal vector `x` (length [`ModelId::n_params`]).
    pub fn new(id: ModelId, x: &[f64]) -> LnD {
        if id.is_mixture() {
            LnD::Two(super::lnd_mixture::MixtureLnD::new(id, x))
        } else {
            LnD::One(LobeLnD::new(id, x))
        }
    }

    /// `ln D(m)` for a unit `m` with `m.z > 0`.
    #[inline]
    pub fn value(&self, m: &Vector3<f64>) -> f64 {
        match self {
            LnD::One(f) => f.value(m),
            LnD::Two(f) => f.value(m),
        }
    }

    /// `ln D(m)` and its gradient with respect to the internal parameters, written into `grad`
    /// (length = the model's parameter count).
    #[cfg(test)]
    #[inline]
    pub fn value_grad(&self, m: &Vector3<f64>, grad: &mut [f64]) -> f64 {
        self.grad(m, grad);
        self.value(m)
    }

    /// The gradient of `ln D(m)` alone.
    #[inline]
    pub fn grad(&self, m: &Vector3<f64>, grad: &mut [f64]) {
        match self {
            LnD::One(f) => f.grad(m, grad),
            LnD::Two(f) => f.grad(m, grad),
        }
    }
}

/// One lobe frozen at one internal parameter vector, with everything per-call precomputed so the per-bin
/// work is a few multiply-adds (no allocation).
#[derive(Debug, Clone)]
pub struct LobeLnD {
    shape: Shape,
    kernel: Kernel,
    /// The Student-t tail: `gamma`, `1 / (gamma - 1)` and `d gamma / d g` (unused by the other kernels).
    gamma: f64,
    ip: f64,
    gg: f64,
    ax: f64,
    ay: f64,
    /// `1 / ax`, `1 / ay` (multiplications in the per-bin work instead of divisions).
    iax: f64,
    iay: f64,
    /// `d alpha / d u` for each axis.
    gx: f64,
    gy: f64,
    r: Matrix3<f64>,
    r_tx: Matrix3<f64>,
    r_ty: Matrix3<f64>,
    r_tz: Matrix3<f64>,
    constant: f64,
    /// Per-evaluation parts of the ellipsoid gradient, so the per-bin work has one division (`1/q`):
    /// `d lnD/d ax = k_ax + c_ax v1^2 / q` with `k_ax = -1/ax - ax (d||A n||^2/d ax / ax) / (2 ||A n||^2)`,
    /// `c_ax = 4/ax^3` (the same for `ay`), and the skew angles' `||A n||` terms
    /// `k_tx = -(d||A n||^2/d theta_x) / (2 ||A n||^2)`, `k_ty`.
    k_ax: f64,
    k_ay: f64,
    c_ax: f64,
    c_ay: f64,
    k_tx: f64,
    k_ty: f64,
}

impl LobeLnD {
    /// Freeze single-lobe model `id` at internal vector `x` (length [`ModelId::n_params`]). A mixture id
    /// gives its first lobe's kind (`lnd_mixture` builds mixtures lobe by lobe).
    pub fn new(id: ModelId, x: &[f64]) -> LobeLnD {
        let lobe = id.spec().lobes[0];
        Self::with_shape(lobe.form, lobe.kernel, false, x)
    }

    /// Freeze a lobe of `shape` at its internal vector `x` (`[u]`, `[u_x, u_y, theta_z]` or the
    /// ellipsoid's five); `bounded`: a mixture lobe's roughness map ([`super::params::bounded_alpha_of`]).
    pub(crate) fn with_shape(shape: Shape, kernel: Kernel, bounded: bool, x: &[f64]) -> LobeLnD {
        let beckmann = kernel != Kernel::Ggx;
        let (ux, uy, tx, ty, tz) = match shape {
            Shape::Iso => (x[0], x[0], 0.0, 0.0, 0.0),
            Shape::Aniso => (x[0], x[1], 0.0, 0.0, x[2]),
            Shape::Full => (x[0], x[1], x[2], x[3], x[4]),
        };
        // A tail parameter follows the lobe's geometry (the table's roles); GGX's 2 when there is none.
        let g = (kernel == Kernel::Student).then(|| x[Self::geometry_len(shape)]);
        let (gamma, gg) = g.map_or((2.0, 0.0), |g| (gamma_of(g), gamma_dg(g)));
        let (ax, ay, gx, gy) = if bounded {
            (bounded_alpha_of(ux), bounded_alpha_of(uy), bounded_alpha_du(ux), bounded_alpha_du(uy))
        } else {
            (alpha_of(ux), alpha_of(uy), ux.exp(), uy.exp())
        };
        let (sx, cx) = tx.sin_cos();
        let (sy, cy) = ty.sin_cos();
        let (sz, cz) = tz.sin_cos();
        let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, cx, -sx, 0.0, sx, cx);
        let ry = Matrix3::new(cy, 0.0, sy, 0.0, 1.0, 0.0, -sy, 0.0, cy);
        let rz = Matrix3::new(cz, -sz, 0.0, sz, cz, 0.0, 0.0, 0.0, 1.0);
        let drx = Matrix3::new(0.0, 0.0, 0.0, 0.0, -sx, -cx, 0.0, cx, -sx);
        let dry = Matrix3::new(-sy, 0.0, cy, 0.0, 0.0, 0.0, -cy, 0.0, -sy);
        let drz = Matrix3::new(-sz, -cz, 0.0, cz, -sz, 0.0, 0.0, 0.0, 0.0);
        let r = rotation_xyz(tx, ty, tz);
        let an2 = if beckmann { 1.0 } else { ax * ax * sy * sy + ay * ay * sx * sx * cy * cy + cx * cx * cy * cy };
        let constant = -LN_PI - ax.ln() - ay.ln() - 0.5 * an2.ln();
        // Derivatives of ||A n||^2 by the skew angles, and by ax, ay divided by ax, ay.
        let an2_tx = 2.0 * sx * cx * cy * cy * (ay * ay - 1.0);
        let an2_ty = 2.0 * sy * cy * (ax * ax - ay * ay * sx * sx - cx * cx);
        let (an2_ax, an2_ay) = (2.0 * sy * sy, 2.0 * sx * sx * cy * cy);
        LobeLnD {
            shape,
            kernel,
            gamma,
            ip: 1.0 / (gamma - 1.0),
            gg,
            ax,
            ay,
            iax: 1.0 / ax,
            iay: 1.0 / ay,
            gx,
            gy,
            r,
            r_tx: drx * ry * rz,
            r_ty: rx * dry * rz,
            r_tz: rx * ry * drz,
            constant,
            k_ax: -1.0 / ax - 0.5 * ax * an2_ax / an2,
            k_ay: -1.0 / ay - 0.5 * ay * an2_ay / an2,
            c_ax: 4.0 / (ax * ax * ax),
            c_ay: 4.0 / (ay * ay * ay),
            k_tx: -0.5 * an2_tx / an2,
            k_ty: -0.5 * an2_ty / an2,
        }
    }

    /// How many internal parameters a lobe's geometry takes (the tail's slot follows them).
    fn geometry_len(shape: Shape) -> usize {
        match shape {
            Shape::Iso => 1,
            Shape::Aniso => 3,
            Shape::Full => 5,
        }
    }

    /// `ln D(m)` for a unit `m` with `m.z > 0`.
    #[inline]
    pub fn value(&self, m: &Vector3<f64>) -> f64 {
        let v = self.r * m;
        match self.kernel {
            Kernel::Beckmann => {
                let z2 = v.z * v.z;
                let e = ((v.x * self.iax).powi(2) + (v.y * self.iay).powi(2)) / z2;
                self.constant - e - 2.0 * z2.ln()
            }
            Kernel::Student => {
                let z2 = v.z * v.z;
                let e = ((v.x * self.iax).powi(2) + (v.y * self.iay).powi(2)) / z2;
                // gamma ln(1 + e/p) rather than gamma (ln(p + e) - ln p): no cancellation at large gamma.
                self.constant - self.gamma * (e * self.ip).ln_1p() - 2.0 * z2.ln()
            }
            Kernel::Ggx => {
                let q = (v.x * self.iax).powi(2) + (v.y * self.iay).powi(2) + v.z * v.z;
                self.constant - 2.0 * q.ln()
            }
        }
    }

    /// The gradient of `ln D(m)` alone (as `value_grad`, without the logarithm of the value:
    /// the Jacobian reuses the residual pass's `ln D`).
    #[inline]
    pub fn grad(&self, m: &Vector3<f64>, grad: &mut [f64]) {
        let (ax, ay) = (self.ax, self.ay);
        let v = self.r * m;
        let (iax2, iay2) = (self.iax * self.iax, self.iay * self.iay);
        // d lnD / d ax, d lnD / d ay, and d lnD / d v (for the angles).
        let mut dgamma = 0.0;
        let (dax, day, dv) = match self.kernel {
            Kernel::Beckmann => {
                let z2 = v.z * v.z;
                let e = (v.x * v.x * iax2 + v.y * v.y * iay2) / z2;
                let dax = -1.0 / ax + 2.0 * v.x * v.x * iax2 / (ax * z2);
                let day = -1.0 / ay + 2.0 * v.y * v.y * iay2 / (ay * z2);
                let dv = Vector3::new(-2.0 * v.x * iax2 / z2, -2.0 * v.y * iay2 / z2, 2.0 * e / v.z - 4.0 / v.z);
                (dax, day, dv)
            }
            Kernel::Student => {
                let z2 = v.z * v.z;
                let e = (v.x * v.x * iax2 + v.y * v.y * iay2) / z2;
                // h = gamma / (p + e) = d(gamma ln(1 + e/p)) / de.
                let h = self.gamma * self.ip / (1.0 + e * self.ip);
                let dax = -1.0 / ax + 2.0 * h * v.x * v.x * iax2 / (ax * z2);
                let day = -1.0 / ay + 2.0 * h * v.y * v.y * iay2 / (ay * z2);
                let dv = Vector3::new(-2.0 * h * v.x * iax2 / z2, -2.0 * h * v.y * iay2 / z2, 2.0 * h * e / v.z - 4.0 / v.z);
                dgamma = -(e * self.ip).ln_1p() + h * e * self.ip;
                (dax, day, dv)
            }
            Kernel::Ggx => {
                let q = v.x * v.x * iax2 + v.y * v.y * iay2 + v.z * v.z;
                let iq = 1.0 / q;
                let dax = self.k_ax + self.c_ax * v.x * v.x * iq;
                let day = self.k_ay + self.c_ay * v.y * v.y * iq;
                let dv = Vector3::new(v.x * iax2, v.y * iay2, v.z) * (-4.0 * iq);
                (dax, day, dv)
            }
        };
        let dtz = dv.dot(&(self.r_tz * m));
        match self.shape {
            Shape::Iso => grad[0] = dax * self.gx + day * self.gy,
            Shape::Aniso => {
                grad[0] = dax * self.gx;
                grad[1] = day * self.gy;
                grad[2] = dtz;
            }
            Shape::Full => {
                grad[0] = dax * self.gx;
                grad[1] = day * self.gy;
                grad[2] = dv.dot(&(self.r_tx * m)) + self.k_tx;
                grad[3] = dv.dot(&(self.r_ty * m)) + self.k_ty;
                grad[4] = dtz;
            }
        }
        if self.kernel == Kernel::Student {
            grad[Self::geometry_len(self.shape)] = dgamma * self.gg;
        }
    }
}
