//! The exact visible-normal sampler of Walter et al. sec. 4.1: a chi-square test in the style of Mitsuba 3's
//! `chi2.py` against the distribution of visible normals `D(m) <u, m>` (Heitz eq. 16, Walter eq. 33),
//! a pointwise check that eq. 33 is the sampler's density (finite-difference Jacobian of the map), and the
//! sample weights of eq. 49 (never above 1 in 10^6 samples).

use std::f64::consts::PI;

use nalgebra::Vector3;
use ndfit::models::{checked_eta, Ellipsoid, MaskingShadowing, MicrofacetBrdf, Model, Ndf};

use super::equivalence::Rng;

/// Regularized upper incomplete gamma `Q(a, x)` (series for x < a + 1, Lentz continued fraction otherwise;
/// Numerical Recipes sec. 6.2), for the chi-square p-value `Q(dof/2, chi2/2)`.
fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let ln_pre = -x + a * x.ln() - libm::lgamma(a);
    if x < a + 1.0 {
        let (mut sum, mut term, mut ap) = (1.0 / a, 1.0 / a, a);
        for _ in 0..100_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        1.0 - sum * ln_pre.exp()
    } else {
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..100_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-16 {
                break;
            }
        }
        ln_pre.exp() * h
    }
}

/// Cells in `t = sqrt(1 - m_z)` (uniform in [0, 1]) by `phi` (uniform in [-pi, pi)); `d omega = 2 t dt dphi`.
const NT: usize = 40;
const NP: usize = 80;

fn cell_of(m: Vector3<f64>) -> usize {
    let t = (1.0 - m.z).max(0.0).sqrt();
    let phi = m.y.atan2(m.x);
    let i = ((t * NT as f64) as usize).min(NT - 1);
    let j = (((phi + PI) / (2.0 * PI) * NP as f64) as usize).min(NP - 1);
    i * NP + j
}

/// Integral of `f` over each cell: 2x2 sub-cells with 6-point Gauss-Legendre each way.
fn cell_integrals(f: &dyn Fn(Vector3<f64>) -> f64) -> Vec<f64> {
    const X: [f64; 6] =
        [-0.932469514203152, -0.661209386466265, -0.238619186083197, 0.238619186083197, 0.661209386466265, 0.932469514203152];
    const W: [f64; 6] = [0.171324492379170, 0.360761573048139, 0.467913934572691, 0.467913934572691, 0.360761573048139, 0.171324492379170];
    const SUB: usize = 2;
    let (dt, dp) = (1.0 / (NT * SUB) as f64, 2.0 * PI / (NP * SUB) as f64);
    let mut out = vec![0.0; NT * NP];
    for i in 0..NT * SUB {
        for j in 0..NP * SUB {
            let (tc, pc) = ((i as f64 + 0.5) * dt, -PI + (j as f64 + 0.5) * dp);
            let mut acc = 0.0;
            for (xa, wa) in X.iter().zip(W) {
                for (xb, wb) in X.iter().zip(W) {
                    let t = tc + 0.5 * dt * xa;
                    let p = pc + 0.5 * dp * xb;
                    let z = 1.0 - t * t;
                    let r = (1.0 - z * z).max(0.0).sqrt();
                    let m = Vector3::new(r * p.cos(), r * p.sin(), z);
                    acc += wa * wb * f(m) * 2.0 * t;
                }
            }
            out[(i / SUB) * NP + j / SUB] += acc * 0.25 * dt * dp;
        }
    }
    out
}

/// Mitsuba 3 `chi2.py` style: cells with expected count below 5 are pooled (from the smallest up), a sample
/// in a cell of zero expectation fails at once; returns the p-value.
fn chi2_p_value(obs: &[f64], exp: &[f64]) -> f64 {
    let mut idx: Vec<usize> = (0..exp.len()).collect();
    idx.sort_by(|&a, &b| exp[a].total_cmp(&exp[b]));
    let (mut pool_obs, mut pool_exp, mut chi2, mut dof) = (0.0, 0.0, 0.0, 0usize);
    for i in idx {
        if exp[i] == 0.0 {
            assert!(obs[i] == 0.0, "{} samples where the pdf is 0", obs[i]);
        } else if exp[i] < 5.0 || (pool_exp > 0.0 && pool_exp < 5.0) {
            pool_obs += obs[i];
            pool_exp += exp[i];
        } else {
            chi2 += (obs[i] - exp[i]).powi(2) / exp[i];
            dof += 1;
        }
    }
    if pool_exp > 0.0 {
        chi2 += (pool_obs - pool_exp).powi(2) / pool_exp;
        dof += 1;
    }
    gamma_q((dof - 1) as f64 / 2.0, chi2 / 2.0)
}

const PARAMS: [[f64; 5]; 5] = [
    [0.3, 0.3, 0.0, 0.0, 0.0],  // GGX
    [0.5, 0.3, 0.0, 0.0, 0.4],  // GTR2aniso
    [0.3, 0.6, 0.4, -0.3, 1.0], // skewed
    [0.8, 0.2, -0.9, 0.5, 0.2], // strongly skewed
    [1.5, 0.5, 0.3, 0.3, -0.5], // rough
];
const THETAS: [f64; 4] = [0.0, 45.0, 80.0, 89.5];

fn dir(theta_deg: f64, phi: f64) -> Vector3<f64> {
    let t = theta_deg.to_radians();
    Vector3::new(t.sin() * phi.cos(), t.sin() * phi.sin(), t.cos())
}

#[test]
fn chi_square_of_the_visible_normal_sampler() {
    let n_tests = PARAMS.len() * THETAS.len();
    // Sidak: the whole family at 1% significance.
    let alpha = 1.0 - (1.0f64 - 0.01).powf(1.0 / n_tests as f64);
    let n = 250_000;
    let mut rng = Rng(31);
    let mut worst = 1.0f64;
    for p in PARAMS {
        let e = Ellipsoid::from_params(p[0], p[1], p[2], p[3], p[4]).unwrap();
        for theta in THETAS {
            let u = dir(theta, 0.7);
            // Target shape D(m) <u, m> on m.n >= 0, normalized by its own cell sum (independent of eq. 33's
            // closed-form normalization, which is checked against that sum just below).
            let shape = cell_integrals(&|m| e.d(m) * m.dot(&u).max(0.0));
            let total: f64 = shape.iter().sum();
            let lib = cell_integrals(&|m| e.pdf_visible_normal(u, m));
            let lib_total: f64 = lib.iter().sum();
            assert!((lib_total - 1.0).abs() < 2e-3, "{p:?} theta {theta}: eq. 33 integrates to {lib_total}");
            let exp: Vec<f64> = shape.iter().map(|s| s / total * n as f64).collect();
            let mut obs = vec![0.0; NT * NP];
            for _ in 0..n {
                let m = e.sample_visible_normal(u, [rng.uniform(), rng.uniform()]).expect("u is above the horizon");
                assert!(m.z >= 0.0 && m.dot(&u) >= -1e-12, "sample outside the lune: {m:?}");
                obs[cell_of(m)] += 1.0;
            }
            let pv = chi2_p_value(&obs, &exp);
            worst = worst.min(pv);
            assert!(pv > alpha, "{p:?} theta {theta}: chi-square p-value {pv:e} < {alpha:e}");
        }
    }
    eprintln!("chi-square: smallest p-value {worst:.3e} over {n_tests} tests (Sidak threshold {alpha:.3e})");
}

#[test]
fn eq_33_is_the_density_of_the_sampling_map() {
    // p_h(m(xi)) |dm/dxi1 x dm/dxi2| = 1 (the map pushes the unit square's uniform density forward);
    // central differences with h = 1e-6 (truncation ~h^2, rounding ~1e-16/h: both below 1e-6 relative).
    let mut rng = Rng(32);
    let h = 1e-6;
    for p in PARAMS {
        let e = Ellipsoid::from_params(p[0], p[1], p[2], p[3], p[4]).unwrap();
        for theta in THETAS {
            let u = dir(theta, 0.7);
            let mut checked = 0;
            while checked < 200 {
                let xi = [0.02 + 0.96 * rng.uniform(), 0.02 + 0.96 * rng.uniform()];
                let (a, b) = (2.0 * xi[0] - 1.0, 2.0 * xi[1] - 1.0);
                // The concentric map is only piecewise smooth: stay off its diagonal seams.
                if (a.abs() - b.abs()).abs() < 1e-3 {
                    continue;
                }
                let s = |x0: f64, x1: f64| e.sample_visible_normal(u, [x0, x1]).unwrap();
                let d1 = (s(xi[0] + h, xi[1]) - s(xi[0] - h, xi[1])) / (2.0 * h);
                let d2 = (s(xi[0], xi[1] + h) - s(xi[0], xi[1] - h)) / (2.0 * h);
                let m = s(xi[0], xi[1]);
                let jac = d1.cross(&d2).norm();
                let prod = e.pdf_visible_normal(u, m) * jac;
                // Points on the lune's rim (m.u ~ 0 or m.z ~ 0) have a degenerate Jacobian; skip them.
                if m.dot(&u) < 1e-3 || m.z < 1e-3 {
                    continue;
                }
                assert!((prod - 1.0).abs() < 1e-5, "{p:?} theta {theta} xi {xi:?}: pdf * |J| = {prod}");
                checked += 1;
            }
        }
    }
}

#[test]
fn sample_weights_never_exceed_one() {
    let mut rng = Rng(33);
    let mut count = 0usize;
    let mut max_w = 0.0f64;
    let gold = checked_eta(0.18, 3.4).unwrap();
    for p in PARAMS {
        let e = Ellipsoid::from_params(p[0], p[1], p[2], p[3], p[4]).unwrap();
        let untilted = p[2] == 0.0 && p[3] == 0.0;
        for eta in [None, Some(gold)] {
            let brdf = MicrofacetBrdf { model: Model::Ellipsoid(e), eta, masking: MaskingShadowing::Separable };
            for theta in [0.0, 30.0, 60.0, 85.0, 89.9] {
                let psi = dir(theta, 2.1);
                for _ in 0..20_000 {
                    let (omega, m) = e.sample_reflected(psi, [rng.uniform(), rng.uniform()]).unwrap();
                    count += 1;
                    // Eq. 49 from the BRDF (eq. 4) and the pdf (eq. 48), independently of sample_weight.
                    let po = e.pdf_reflected(psi, omega);
                    let w49 = if omega.z > 0.0 { brdf.eval(psi, omega) * omega.z / po } else { 0.0 };
                    assert!(w49.is_finite() && w49 <= 1.0 + 1e-9, "{p:?} theta {theta}: weight {w49}");
                    let f = brdf.fresnel(psi.dot(&m));
                    let w = e.sample_weight(psi, omega, m, f);
                    assert!(w <= 1.0, "library weight (eq. 50) {w} > 1");
                    assert!((w - w49).abs() <= 1e-9 * w49.max(1e-300).max(w), "eq. 50 {w} vs eq. 49 {w49}");
                    if untilted && omega.z > 0.0 {
                        // Sec. 4.2: without skew the bound of eq. 51 is an equality.
                        let eq51 = e.g1(omega, m) * f;
                        assert!((w49 - eq51).abs() < 1e-9, "{p:?}: weight {w49} != G1 F = {eq51}");
                    }
                    max_w = max_w.max(w49);
                }
            }
        }
    }
    assert!(count >= 1_000_000);
    eprintln!("{count} samples, largest weight {max_w}");
}
