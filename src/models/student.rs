//! The Student-t distribution of slopes (STD) of Ribardière, Bringier, Meneveaux and Simonot, *STD:
//! Student's t-Distribution of Slopes for Microfacet Based BSDFs* (Computer Graphics Forum 36(2), 2017),
//! in the anisotropic, rotated form of the other slope-space models.
//!
//! With stretched slopes `r^2 = x'^2/ax^2 + y'^2/ay^2` (slope rotated by `Rz(theta_z)` first, as for
//! [`super::Ggx`]) the distribution of slopes is
//!
//! `P22 = (gamma-1)^gamma / (pi ax ay (gamma - 1 + r^2)^gamma) = (1 + r^2/(gamma-1))^-gamma / (pi ax ay)`,
//!
//! exactly normalized for every `gamma > 1` (Heitz eq. 9: in `t = r^2` the integral is
//! `(gamma-1)^gamma int_0^inf (gamma-1+t)^-gamma dt = 1`). `gamma = 2` is GGX exactly; as `gamma -> inf`,
//! `(1 + r^2/(gamma-1))^-gamma -> exp(-r^2)`, Beckmann; below 2 the tail is heavier than GGX's.
//!
//! The 1-D marginal along any azimuth is again a Student t: integrating `y` out gives
//! `P2(x) = K (gamma-1+x^2)^(1/2-gamma)`, `K = (gamma-1)^gamma Gamma(gamma-1/2) / (sqrt(pi) Gamma(gamma))`,
//! i.e. `x = T / sqrt(2)` with `T` a Student t of `nu = 2 gamma - 2` degrees of freedom. Its mean slope
//! `int |x| P2` is finite only for `gamma > 3/2`, and Smith's `Lambda` (Heitz eq. 43, slope form
//! `Lambda = (1/a) int_a^inf (q - a) P2(q) dq` with `a = 1/(alpha_o tan theta_o)`, eq. 80) needs it; so
//! this model requires `gamma > 3/2` ([`GAMMA_MIN`]). Integrating, with `p = gamma - 1`,
//! `x = p/(p + a^2)` and `B = B(p, 1/2)`:
//!
//! `Lambda = x^p (1-x)^(-1/2) / ((2p - 1) B) - I_x(p, 1/2) / 2`,
//!
//! where `I_x(p, 1/2) / 2` is the t distribution's upper tail at `sqrt(2) a` (regularized incomplete beta).
//! The two terms cancel for large `a`; there the Gauss series `I_x(p, q) = x^p (1-x)^q
//! 2F1(p+q, 1; p+1; x) / (p B)` turns it into a sum of positive terms:
//!
//! `Lambda = x^p (1-x)^(-1/2) / B * (1/(2p(2p-1)) + sum_{k>=1} c_{k-1} x^k / (4p(p+k)))`,
//! `c_0 = 1`, `c_k = c_{k-1} (p + k - 1/2)/(p + k)`,
//!
//! used for `x <= 4/5`, where it converges geometrically; above, the closed form loses at most
//! `log10(2 a^2)` digits to cancellation, and `a^2 < p/4` there. For `gamma = 2` both reduce to GGX's `(-1 + sqrt(1 + 1/a^2))/2`.
//!
//! Sampling `D(m) (m.n)`: the radial CDF of `P22` in `t = r^2` is `1 - (p/(p + t))^p`, inverted in closed
//! form. Visible normals have no closed-form sampler (their 1-D slope CDF, Heitz and d'Eon 2014 sec. 4,
//! is an incomplete beta with no closed inverse), so none is provided.

use nalgebra::{Vector2, Vector3};

use super::ggx::{projected_roughness, smith_lambda};
use super::{canonical, checked_alpha, checked_angle, rotate_z, smith_g1, Masking, Ndf};
use crate::error::{Error, Result};

/// Exclusive lower bound of `gamma`: at and below `3/2` the marginal slope distribution has no finite mean,
/// so Smith's `Lambda` is infinite for every direction (nothing would be visible).
pub const GAMMA_MIN: f64 = 1.5;

/// Largest `gamma` accepted (the fit's upper bound). Beyond it the lobe is Beckmann for any data: with
/// `e = r^2` the stretched slope, `P22` differs from Beckmann's by `exp(-e) (e^2/2 - e) / (gamma - 1)` to
/// first order, so a bin at `e` whose expected count is `c exp(-e)` (`c` the count the lobe's peak would
/// have there) moves by at most `0.62 sqrt(c) / (gamma - 1)` of its counting error
/// (`max_e |e^2/2 - e| exp(-e/2) = 0.62` at `e = 3 + sqrt 5`). The bound holds at every slope, so over the
/// fitted slopes up to `tan 70 deg` in particular: at `gamma = 1e5` even a bin holding all the 2.7e8
/// normals of a 16384^2 scan moves by a tenth of its counting error, and the weighted RMS relative
/// difference of the two lobes (`sqrt 2 / (gamma - 1)`, from the exponential moments of `e`) is 1.4e-5.
/// As for [`crate::fit::params::LOBE_ALPHA_MAX`], a fit of Beckmann data drifts along that flat valley, so
/// the bound also says where it stops.
pub const GAMMA_MAX: f64 = 1e5;

/// The anisotropic STD lobe rotated by `theta_z` (same convention as [`super::Ggx`]: the local frame is
/// `m' = Rz(theta_z) m`, so `alpha_x` lies along `(cos theta_z, -sin theta_z)` in the scan frame), with tail
/// exponent `gamma` in `(GAMMA_MIN, GAMMA_MAX]`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Student {
    /// Roughness along the local x axis.
    pub alpha_x: f64,
    /// Roughness along the local y axis.
    pub alpha_y: f64,
    /// Rotation in the tangent plane (radians).
    pub theta_z: f64,
    /// Tail exponent: 2 is GGX, infinity Beckmann, smaller is heavier-tailed.
    pub gamma: f64,
}

/// Check that a tail exponent is finite and in `(GAMMA_MIN, GAMMA_MAX]`.
pub(crate) fn checked_gamma(name: &str, g: f64) -> Result<f64> {
    if !g.is_finite() {
        return Err(Error::invalid(format!("{name} must be finite, got {g}")));
    }
    // At or below 3/2 Lambda is infinite (the mean slope diverges).
    if !(g > GAMMA_MIN) {
        return Err(Error::invalid(format!(
            "{name} = {g} must exceed {GAMMA_MIN} (the mean slope, and so Smith's Lambda, is infinite below)"
        )));
    }
    if g > GAMMA_MAX {
        return Err(Error::invalid(format!("{name} = {g} exceeds the largest supported tail exponent {GAMMA_MAX}")));
    }
    Ok(g)
}

impl Student {
    /// `GAMMA_MIN`: the exclusive lower bound of `gamma` (Smith's `Lambda` needs a finite mean slope).
    pub const GAMMA_MIN: f64 = GAMMA_MIN;
    /// `GAMMA_MAX`: the largest `gamma` accepted, beyond which the lobe is Beckmann for any data.
    pub const GAMMA_MAX: f64 = GAMMA_MAX;

    /// An STD lobe; alphas below [`super::ALPHA_MIN`] are raised to it, alphas above [`super::ALPHA_MAX`],
    /// `gamma` outside `(GAMMA_MIN, GAMMA_MAX]` and non-finite values are refused.
    pub fn new(alpha_x: f64, alpha_y: f64, theta_z: f64, gamma: f64) -> Result<Self> {
        Ok(Student {
            alpha_x: checked_alpha("alpha_x", alpha_x)?,
            alpha_y: checked_alpha("alpha_y", alpha_y)?,
            theta_z: checked_angle("theta_z", theta_z)?,
            gamma: checked_gamma("gamma", gamma)?,
        })
    }

    /// The same distribution in canonical parameters: `alpha_x >= alpha_y`, `theta_z` in `(-pi/2, pi/2]`
    /// (`canonical::canonical_aniso`); `gamma` unchanged.
    pub fn canonical(&self) -> Student {
        let (ax, ay, tz) = canonical::canonical_aniso(self.alpha_x, self.alpha_y, self.theta_z);
        Student { alpha_x: ax, alpha_y: ay, theta_z: tz, ..*self }
    }

    /// The distribution of slopes `P22` (module docs), slope in the scan frame.
    pub fn p22(&self, slope: Vector2<f64>) -> f64 {
        let l = rotate_z(self.theta_z, Vector3::new(slope.x, slope.y, 0.0));
        let e = (l.x / self.alpha_x).powi(2) + (l.y / self.alpha_y).powi(2);
        // (1 + e/p)^-gamma in the log domain: the power overflows for large gamma long before the value fades.
        let v = (-self.gamma * (e / (self.gamma - 1.0)).ln_1p()).exp() / (std::f64::consts::PI * self.alpha_x * self.alpha_y);
        // NaN only for a non-finite slope (infinite slopes have no density).
        if v.is_nan() {
            0.0
        } else {
            v
        }
    }

    /// The projected roughness `alpha_o` of Heitz eq. 80 in the azimuth of `u`.
    pub fn alpha_o(&self, u: Vector3<f64>) -> f64 {
        projected_roughness(self.alpha_x, self.alpha_y, self.theta_z, u)
    }

    /// A normal `m` drawn with density `D(m) (m.n)` from two uniform numbers in `[0, 1)`: the stretched slope
    /// radius from the inverse radial CDF `t = p ((1 - xi1)^(-1/p) - 1)`, its azimuth `2 pi xi2`, then
    /// stretched by the alphas and rotated back by `Rz(-theta_z)`.
    pub fn sample_normal(&self, xi: [f64; 2]) -> Vector3<f64> {
        let p = self.gamma - 1.0;
        // xi1 = 1 would be an infinite slope (a normal on the horizon, of density 0).
        let xi1 = xi[0].clamp(0.0, 1.0 - f64::EPSILON);
        let t = p * (-(-xi1).ln_1p() / p).exp_m1();
        let phi = 2.0 * std::f64::consts::PI * xi[1];
        let r = t.sqrt();
        let local = Vector3::new(self.alpha_x * r * phi.cos(), self.alpha_y * r * phi.sin(), 0.0);
        let s = rotate_z(-self.theta_z, local);
        // m = (-s, 1) / |(-s, 1)| without squaring |s| (finite for slopes beyond 1e154).
        let h = s.x.hypot(s.y).hypot(1.0);
        Vector3::new(-s.x / h, -s.y / h, 1.0 / h)
    }

    /// The density of [`Student::sample_normal`] over solid angle: `D(m) (m.n)`.
    pub fn pdf_normal(&self, m: Vector3<f64>) -> f64 {
        self.d(m) * m.z.max(0.0)
    }
}

/// `ln(Gamma(p + 1/2) / Gamma(p))` to about 1e-15 absolute for `p > 0`: by `lgamma` where it is exact
/// enough, by the difference of Stirling's series (terms to `z^-5`, remainder below 1e-17) for large `p`,
/// where subtracting two `lgamma` values of 1e6 would lose ten digits.
fn ln_gamma_ratio_half(p: f64) -> f64 {
    if p < 64.0 {
        return libm::lgamma(p + 0.5) - libm::lgamma(p);
    }
    // ln Gamma(z) = (z - 1/2) ln z - z + ln(2 pi)/2 + s(z); the (z - 1/2) ln z - z parts of z = p + 1/2 and
    // z = p combine to p ln(1 + 1/(2p)) + ln(p)/2 - 1/2.
    let s = |z: f64| {
        let z2 = z * z;
        (1.0 / 12.0 - (1.0 / 360.0 - 1.0 / (1260.0 * z2)) / z2) / z
    };
    p * (0.5 / p).ln_1p() - 0.5 + 0.5 * p.ln() + s(p + 0.5) - s(p)
}

/// Smith's `Lambda` of the unit-roughness STD as a function of `w = 1/a^2 = (alpha_o tan theta_o)^2` (module
/// docs), for `w` finite and positive.
fn lambda_of_w(gamma: f64, w: f64) -> f64 {
    let p = gamma - 1.0;
    let pw = p * w;
    // x = pw/(1 + pw) and 1 - x = 1/(1 + pw), as logs (x^p underflows long before x does).
    let ln_x = -(1.0 / pw).ln_1p();
    let ln_1mx = -pw.ln_1p();
    // x^p (1-x)^(-1/2) / B(p, 1/2), with 1/B(p, 1/2) = Gamma(p + 1/2) / (Gamma(p) sqrt(pi)).
    let ln_pre = p * ln_x - 0.5 * ln_1mx + ln_gamma_ratio_half(p) - 0.5 * std::f64::consts::PI.ln();
    let pre = ln_pre.exp();
    if pre == 0.0 {
        return 0.0; // a so large that no slope reaches it
    }
    if pw <= 4.0 {
        // x <= 4/5: the positive series, geometric in x (under 200 terms).
        let x = pw / (1.0 + pw);
        let mut sum = 1.0 / (2.0 * p * (2.0 * p - 1.0));
        let (mut c, mut xk) = (1.0, 1.0);
        for k in 1..200 {
            let k = k as f64;
            xk *= x;
            let term = c * xk / (4.0 * p * (p + k));
            sum += term;
            if term <= 1e-17 * sum {
                break;
            }
            c *= (p + k - 0.5) / (p + k);
        }
        return pre * sum;
    }
    // x > 4/5: the closed form. The tail I_x(p, 1/2) / 2 is taken as is, not as 1 - I_(1-x)(1/2, p), which
    // would cancel where the tail is small; near x = 1 (grazing) the tail is 1/2 and Lambda >> 1.
    let tail = 0.5 * statrs::function::beta::beta_reg(p, 0.5, pw / (1.0 + pw));
    let l = pre / (2.0 * p - 1.0) - tail;
    if !l.is_finite() {
        return f64::MAX; // gamma at 3/2 + 1e-300: the grazing limit
    }
    // With a large p the two terms nearly cancel; rounding may leave an ulp below 0.
    l.max(0.0)
}

impl Ndf for Student {
    /// `D(m) = P22(slope(m)) / cos^4` (Heitz eq. 64) with `m' = Rz m`:
    /// `exp(-gamma ln(1 + e/p) - 4 ln z) / (pi ax ay)`, `e = (x'^2/ax^2 + y'^2/ay^2)/z^2`, `p = gamma - 1`.
    /// Towards the horizon it behaves as `z^(2 gamma - 4)`: 0 for `gamma > 2`, GGX's finite value for 2, and
    /// `+inf` below 2, saturated at `f64::MAX` (as `Lambda` on the horizon).
    fn d(&self, m: Vector3<f64>) -> f64 {
        if m.z < 0.0 {
            return 0.0;
        }
        let (g, p) = (self.gamma, self.gamma - 1.0);
        let l = rotate_z(self.theta_z, m);
        let q = (l.x / self.alpha_x).powi(2) + (l.y / self.alpha_y).powi(2);
        let ln_z = l.z.ln();
        let y = q / (l.z * l.z) / p;
        let expo = if y < 1e300 {
            -g * y.ln_1p() - 4.0 * ln_z
        } else {
            // ln(1 + y) = ln y here; split so z^2 may underflow (or be 0 on the horizon), where the power
            // z^(2 gamma - 4) is 1 at gamma = 2 (GGX's horizon value), not 0 * inf.
            let zpow = if g == 2.0 { 0.0 } else { (2.0 * g - 4.0) * ln_z };
            -g * (q.ln() - p.ln()) + zpow
        };
        // NaN only for a non-finite or zero m: no density.
        if expo.is_nan() {
            return 0.0;
        }
        (expo - (std::f64::consts::PI * self.alpha_x * self.alpha_y).ln()).exp().min(f64::MAX)
    }
}

impl Masking for Student {
    /// Smith's `Lambda` in closed form (module docs), of `a = 1/(alpha_o tan theta_o)` (Heitz eq. 80).
    fn lambda(&self, u: Vector3<f64>) -> f64 {
        smith_lambda(self.alpha_x, self.alpha_y, self.theta_z, u, |w| lambda_of_w(self.gamma, w))
    }

    /// Heitz eq. 43: `X+(u.m) / (1 + Lambda(u))`.
    fn g1(&self, u: Vector3<f64>, m: Vector3<f64>) -> f64 {
        smith_g1(self.lambda(u), u, m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gamma_ratio_against_lgamma_and_its_asymptotic_series() {
        // Near the switch the lgamma difference is good to a few ulps of lgamma itself (lgamma(100) = 360 has an
        // ulp of 6e-14; libm's lgamma is within a few of them).
        for p in [64.0, 80.0, 100.0] {
            let direct = libm::lgamma(p + 0.5) - libm::lgamma(p);
            assert!((ln_gamma_ratio_half(p) - direct).abs() < 3e-13, "p = {p}: {}", ln_gamma_ratio_half(p) - direct);
        }
        // Far out: Gamma(p + 1/2)/Gamma(p) = sqrt(p) (1 - 1/(8p) + 1/(128p^2) + 5/(1024p^3) - ...).
        for p in [1e3_f64, 1e5, 1e7] {
            let series = p.sqrt() * (1.0 - 1.0 / (8.0 * p) + 1.0 / (128.0 * p * p) + 5.0 / (1024.0 * p * p * p));
            assert!((ln_gamma_ratio_half(p) - series.ln()).abs() < 1e-14, "p = {p}");
        }
    }
}
