//! The Student-t slope distribution (STD, Ribardière et al. 2017) against independent sources: its slope
//! density typed in afresh from the paper, normalization (Heitz eq. 9) and Smith's `Lambda` (Heitz eq. 43)
//! by 2-D quadrature in slope space, the weak white furnace test (Heitz eq. 36), GGX at `gamma = 2`, the
//! Beckmann limit with its first-order rate, the sampler by a chi-square test, and extreme inputs.

use std::f64::consts::PI;

use nalgebra::{Vector2, Vector3};
const GAMMA_MAX: f64 = ndfit::models::Student::GAMMA_MAX;
const GAMMA_MIN: f64 = ndfit::models::Student::GAMMA_MIN;
use ndfit::models::{Beckmann, Ggx, Masking, Ndf, Student};

use super::equivalence::Rng;
use super::quad::{dg, g, hemisphere_integral, integrate_2d, slope_frame};

fn dir(theta_deg: f64, phi: f64) -> Vector3<f64> {
    let t = theta_deg.to_radians();
    Vector3::new(t.sin() * phi.cos(), t.sin() * phi.sin(), t.cos())
}

/// The paper's slope density of the unit lobe, `(gamma-1)^gamma / (pi (gamma - 1 + |xi|^2)^gamma)`, as
/// printed (fine for the moderate gammas it is used with).
fn p_unit(gamma: f64, xi2: f64) -> f64 {
    (gamma - 1.0).powf(gamma) / (PI * (gamma - 1.0 + xi2).powf(gamma))
}

/// Lobes under test: (alpha_x, alpha_y, theta_z, gamma).
const LOBES: [[f64; 4]; 8] = [
    [0.3, 0.3, 0.0, 2.0],
    [0.3, 0.3, 0.0, 1.6],
    [0.5, 0.2, 0.7, 1.6],
    [0.05, 0.4, -2.1, 4.0],
    [0.2, 0.6, 0.3, 50.0],
    [1.5, 0.8, 1.2, 2.5],
    [1e-3, 2e-3, 0.4, 3.0],
    [0.3, 0.1, -0.5, 1.55],
];

fn lobe(p: [f64; 4]) -> Student {
    Student::new(p[0], p[1], p[2], p[3]).unwrap()
}

#[test]
fn d_is_the_papers_slope_density_over_cos4() {
    let mut rng = Rng(11);
    for p in LOBES {
        let s = lobe(p);
        for _ in 0..200 {
            let m = rng.hemisphere();
            // The slope of m in the lobe's stretched frame, built with the test's own rotation.
            let (c, sn) = (p[2].cos(), p[2].sin());
            let (lx, ly) = (c * m.x - sn * m.y, sn * m.x + c * m.y);
            let xi2 = (lx / (p[0] * m.z)).powi(2) + (ly / (p[1] * m.z)).powi(2);
            let want = p_unit(p[3], xi2) / (p[0] * p[1] * m.z.powi(4));
            let got = s.d(m);
            assert!((got - want).abs() <= 1e-12 * want, "{p:?} m {m:?}: D {got} vs {want}");
        }
    }
}

#[test]
fn d_integrates_to_one() {
    let mut worst = 0.0f64;
    for p in LOBES.iter().chain(&[[0.4, 0.4, 0.0, 1e3], [2.0, 0.5, 0.2, GAMMA_MAX]]) {
        let s = lobe(*p);
        let (w0, l) = slope_frame(p[0], p[1], 0.0, 0.0, p[2]);
        let (val, err) = hemisphere_integral(|m| s.d(m), |_| 1.0, w0, l, 1e-10);
        let dev = (val - 1.0).abs();
        worst = worst.max(dev);
        assert!(dev < 1e-6 && err < 1e-7, "{p:?}: integral of D cos = {val} (err {err:e})");
    }
    eprintln!("student: worst |integral - 1| = {worst:e}");
}

#[test]
fn gamma_two_is_ggx() {
    let mut rng = Rng(5);
    for (ax, ay, tz) in [(0.3, 0.3, 0.0), (0.5, 0.1, 0.8), (1e-4, 0.02, -1.0), (3.0, 0.7, 2.0)] {
        let s = Student::new(ax, ay, tz, 2.0).unwrap();
        let gx = Ggx::new(ax, ay, tz).unwrap();
        for i in 0..2000 {
            let m = rng.hemisphere();
            let (a, b) = (s.d(m), gx.d(m));
            assert!((a - b).abs() <= 1e-12 * b, "D {a} vs GGX {b} at {m:?}");
            let u = if i % 10 == 0 { dir(89.999, rng.uniform() * 6.0) } else { rng.hemisphere() };
            let (a, b) = (s.lambda(u), gx.lambda(u));
            assert!((a - b).abs() <= 1e-12 * b.max(1e-300), "Lambda {a} vs GGX {b} at {u:?} ({ax}, {ay}, {tz})");
        }
    }
}

/// `D_std / D_beckmann = exp(-gamma ln(1 + e/p) + e) = 1 + (e^2/2 - e)/p + O(1/p^2)` with `e` the stretched
/// slope squared, `p = gamma - 1`; Lambda's difference falls as `1/p` too.
#[test]
fn large_gamma_approaches_beckmann_at_rate_one_over_gamma() {
    let (ax, ay, tz) = (0.4, 0.15, 0.6);
    let b = Beckmann::new(ax, ay, tz).unwrap();
    let mut rng = Rng(9);
    let ms: Vec<_> = (0..300).map(|_| rng.hemisphere()).filter(|m| m.z > 0.3).collect();
    for gamma in [1e2, 1e3, 1e4, GAMMA_MAX] {
        let s = Student::new(ax, ay, tz, gamma).unwrap();
        let p = gamma - 1.0;
        for &m in &ms {
            let l = Vector2::new(tz.cos() * m.x - tz.sin() * m.y, tz.sin() * m.x + tz.cos() * m.y);
            let e = ((l.x / ax).powi(2) + (l.y / ay).powi(2)) / (m.z * m.z);
            if e > 8.0 {
                continue;
            }
            let rel = s.d(m) / b.d(m) - 1.0;
            let first = (e * e / 2.0 - e) / p;
            // The O(1/p^2) remainder is below (e^2 + e^3 + e^4) / p^2 at these e.
            let bound = (e * e + e.powi(3) + e.powi(4)) / (p * p) + 1e-13;
            assert!((rel - first).abs() <= bound, "gamma {gamma} e {e}: D ratio - 1 = {rel:e}, first order {first:e}");
        }
    }
    // Lambda: (Lambda_std - Lambda_beckmann) * p settles to a limit, so the gap is O(1/p).
    for theta in [60.0, 75.0, 85.0, 89.0, 89.9] {
        let u = dir(theta, 0.4);
        let lb = b.lambda(u);
        let gap = |gamma: f64| (Student::new(ax, ay, tz, gamma).unwrap().lambda(u) / lb - 1.0) * (gamma - 1.0);
        let (g3, g4) = (gap(1e3), gap(1e4));
        assert!(g4.abs() > 1e-3, "{theta}: no 1/p gap at all ({g4:e})");
        assert!((g3 - g4).abs() <= 0.02 * g4.abs(), "{theta}: p (Lambda/Lambda_B - 1) = {g3:e} at 1e3, {g4:e} at 1e4");
        let close = Student::new(ax, ay, tz, GAMMA_MAX).unwrap().lambda(u);
        assert!((close / lb - 1.0).abs() <= 1.1 * g4.abs() / (GAMMA_MAX - 1.0), "{theta}: at GAMMA_MAX {close} vs {lb}");
    }
}

/// `Lambda(o) = (1/o_z) int (w.o_xy - o_z)+ P22(w) dw` (the back-facing projected area, Heitz eq. 43 in slope
/// space), taken in the stretched frame `w = Rz(-theta_z) diag(ax, ay) xi` where the back-facing region is
/// the half-plane `xi1 > mu` after a rotation of `xi`; `P22` is the test's own [`p_unit`].
fn lambda_by_quadrature(p: [f64; 4], o: Vector3<f64>) -> (f64, f64) {
    let (ax, ay, tz, gamma) = (p[0], p[1], p[2], p[3]);
    // k = L^T o_xy with L = Rz(-tz) diag(ax, ay): Rz(tz) o_xy scaled by the alphas.
    let k = Vector2::new(ax * (tz.cos() * o.x - tz.sin() * o.y), ay * (tz.sin() * o.x + tz.cos() * o.y));
    let mu = o.z / k.norm();
    half_plane_integral(gamma, mu, 1.0, &|x1, x2| (x1 - mu) / mu * p_unit(gamma, x1 * x1 + x2 * x2))
}

/// `int over xi1 > mu (side = 1) or xi1 < mu (side = -1) of f(xi1, xi2) dxi` for an integrand with the lobe's
/// tails: `xi1 = mu + side s1 (v/(1-v))^k`, the power `k` flattening the `|xi|^(2 - 2 gamma)` tail, and
/// `xi2 = s2(xi1) g(t)` with `s2` the width of the slice at `xi1` (`(gamma - 1 + xi1^2)^(1/2)` up to a constant,
/// since `P22` is `(gamma - 1 + xi1^2 + xi2^2)^-gamma`). Returns (value, error estimate).
fn half_plane_integral(gamma: f64, mu: f64, side: f64, f: &dyn Fn(f64, f64) -> f64) -> (f64, f64) {
    let kp = (2.0 / (2.0 * gamma - 3.0)).max(1.0);
    let s1 = (gamma - 1.0 + mu * mu).sqrt() / (2.0 * gamma - 1.0).sqrt();
    let integrand = |v: f64, t: f64| {
        let r = v / (1.0 - v);
        let x1 = mu + side * s1 * r.powf(kp);
        let dx1 = s1 * kp * r.powf(kp - 1.0) / ((1.0 - v) * (1.0 - v));
        let s2 = ((gamma - 1.0 + x1 * x1) / (2.0 * gamma - 1.0)).sqrt();
        let val = f(x1, s2 * g(t)) * dx1 * s2 * dg(t);
        if val.is_finite() {
            val
        } else {
            0.0
        }
    };
    integrate_2d(integrand, (0.0, 1.0), (-1.0, 1.0), 4, 1e-300, 1e-10, 100_000)
}

#[test]
fn lambda_matches_quadrature_of_its_integral() {
    let mut worst = 0.0f64;
    for p in LOBES {
        let s = lobe(p);
        for theta in [5.0, 30.0, 60.0, 80.0, 88.0, 89.9] {
            for phi in [0.0, 1.1, 2.5] {
                let u = dir(theta, phi);
                let (want, err) = lambda_by_quadrature(p, u);
                let got = s.lambda(u);
                if want < 1e-250 {
                    assert!(got < 1e-200, "{p:?} {theta} {phi}: Lambda {got} where quadrature gives {want:e}");
                    continue;
                }
                let dev = (got - want).abs() / want;
                worst = worst.max(dev);
                assert!(
                    dev < 1e-7 && err < 1e-8 * want,
                    "{p:?} theta {theta} phi {phi}: Lambda {got:e} vs quadrature {want:e} (err {err:e})"
                );
            }
        }
    }
    eprintln!("student: worst relative Lambda error = {worst:e}");
}

/// Heitz eq. 36: `G1(o) int <o, m>+ D(m) dm = cos theta_o`, the integral over the visible half-plane of slope
/// space with the library's own `D` (`P22 = D cos^4`).
#[test]
fn weak_white_furnace() {
    for p in LOBES {
        let s = lobe(p);
        let (ax, ay, tz) = (p[0], p[1], p[2]);
        for theta in [0.0, 20.0, 50.0, 75.0, 85.0, 89.5] {
            let o = dir(theta, 0.7);
            let k = Vector2::new(ax * (tz.cos() * o.x - tz.sin() * o.y), ay * (tz.sin() * o.x + tz.cos() * o.y));
            let visible = if k.norm() == 0.0 {
                // Normal incidence: <o, m> = m.z everywhere, the integral of eq. 9.
                let (w0, l) = slope_frame(ax, ay, 0.0, 0.0, tz);
                hemisphere_integral(|m| s.d(m), |_| 1.0, w0, l, 1e-10).0 * o.z
            } else {
                let (kn, e) = (k.norm(), k / k.norm());
                // The library's D at the stretched slope xi = x1 e + x2 e_perp, times cos^4 and the Jacobian ax ay.
                let dens_at = |x1: f64, x2: f64| {
                    let xi = e * x1 + Vector2::new(-e.y, e.x) * x2;
                    let lw = Vector2::new(ax * xi.x, ay * xi.y);
                    let w = Vector2::new(tz.cos() * lw.x + tz.sin() * lw.y, -tz.sin() * lw.x + tz.cos() * lw.y);
                    let m = Vector3::new(-w.x, -w.y, 1.0).normalize();
                    s.d(m) * m.z.powi(4) * ax * ay
                };
                half_plane_integral(p[3], o.z / kn, -1.0, &|x1, x2| (o.z - kn * x1) * dens_at(x1, x2)).0
            };
            let lhs = s.g1(o, Vector3::z()) * visible;
            assert!((lhs - o.z).abs() < 1e-6 * o.z, "{p:?} theta {theta}: G1 * visible area = {lhs} vs cos {}", o.z);
        }
    }
}

#[test]
fn g1_is_in_unit_interval_and_lambda_nonnegative() {
    let mut rng = Rng(3);
    for p in LOBES {
        let s = lobe(p);
        for _ in 0..5000 {
            let (u, m) = (rng.sphere(), rng.sphere());
            let g1 = s.g1(u, m);
            let l = s.lambda(u);
            assert!((0.0..=1.0).contains(&g1), "{p:?}: G1 = {g1}");
            assert!(l >= 0.0 && l.is_finite(), "{p:?}: Lambda = {l}");
        }
    }
}

/// Mitsuba 3 `chi2.py` style: cells in `t = sqrt(1 - m_z)` by `phi`, expected counts from the pdf by
/// Gauss-Legendre per cell, cells below 5 expected pooled; p-value by the regularized upper incomplete gamma.
#[test]
fn sampler_matches_its_pdf() {
    const NT: usize = 30;
    const NP: usize = 60;
    const N: usize = 400_000;
    const X: [f64; 6] =
        [-0.932469514203152, -0.661209386466265, -0.238619186083197, 0.238619186083197, 0.661209386466265, 0.932469514203152];
    const W: [f64; 6] = [0.171324492379170, 0.360761573048139, 0.467913934572691, 0.467913934572691, 0.360761573048139, 0.171324492379170];
    let lobes = [[0.3, 0.3, 0.0, 1.6], [0.5, 0.2, 0.7, 2.5], [0.8, 0.3, -1.0, 1.55], [0.2, 0.6, 0.3, 40.0]];
    let n_tests = lobes.len() as f64;
    let mut rng = Rng(17);
    for p in lobes {
        let s = lobe(p);
        let mut obs = vec![0.0; NT * NP];
        for _ in 0..N {
            let m = s.sample_normal([rng.uniform(), rng.uniform()]);
            assert!((m.norm() - 1.0).abs() < 1e-12 && m.z >= 0.0, "{m:?}");
            let t = (1.0 - m.z).max(0.0).sqrt();
            let i = ((t * NT as f64) as usize).min(NT - 1);
            let j = (((m.y.atan2(m.x) + PI) / (2.0 * PI) * NP as f64) as usize).min(NP - 1);
            obs[i * NP + j] += 1.0;
        }
        let (dt, dp) = (1.0 / NT as f64, 2.0 * PI / NP as f64);
        let mut exp = vec![0.0; NT * NP];
        for i in 0..NT {
            for j in 0..NP {
                let (tc, pc) = ((i as f64 + 0.5) * dt, -PI + (j as f64 + 0.5) * dp);
                let mut acc = 0.0;
                for (xa, wa) in X.iter().zip(W) {
                    for (xb, wb) in X.iter().zip(W) {
                        let (t, ph) = (tc + 0.5 * dt * xa, pc + 0.5 * dp * xb);
                        let z = 1.0 - t * t;
                        let r = (1.0 - z * z).max(0.0).sqrt();
                        let m = Vector3::new(r * ph.cos(), r * ph.sin(), z);
                        acc += wa * wb * s.pdf_normal(m) * 2.0 * t;
                    }
                }
                exp[i * NP + j] = acc * 0.25 * dt * dp * N as f64;
            }
        }
        let total: f64 = exp.iter().sum();
        assert!((total / N as f64 - 1.0).abs() < 2e-3, "{p:?}: pdf integrates to {}", total / N as f64);
        let mut idx: Vec<usize> = (0..exp.len()).collect();
        idx.sort_by(|&a, &b| exp[a].total_cmp(&exp[b]));
        let (mut po, mut pe, mut chi2, mut dof) = (0.0, 0.0, 0.0, 0usize);
        for i in idx {
            if exp[i] < 5.0 || (pe > 0.0 && pe < 5.0) {
                po += obs[i];
                pe += exp[i];
            } else {
                let z = (obs[i] - exp[i]) / exp[i].sqrt();
                assert!(z.abs() < 5.0, "{p:?}: cell {i} is {z} sigma off ({} vs {})", obs[i], exp[i]);
                chi2 += z * z;
                dof += 1;
            }
        }
        if pe > 0.0 {
            chi2 += (po - pe).powi(2) / pe;
            dof += 1;
        }
        let pval = statrs::function::gamma::gamma_ur((dof - 1) as f64 / 2.0, chi2 / 2.0);
        // Sidak: the family at 1% significance.
        assert!(pval > 1.0 - 0.99f64.powf(1.0 / n_tests), "{p:?}: chi2 {chi2} over {dof} cells, p = {pval:e}");
    }
}

#[test]
fn canonical_keeps_the_distribution() {
    let mut rng = Rng(23);
    for (ax, ay, tz, gm) in [(0.2, 0.5, 0.3, 1.8), (0.5, 0.2, 2.9, 3.0), (0.4, 0.4, 1.0, 2.5), (0.1, 0.3, -4.0, 20.0)] {
        let s = Student::new(ax, ay, tz, gm).unwrap();
        let c = s.canonical();
        assert!(c.alpha_x >= c.alpha_y && c.theta_z > -PI / 2.0 && c.theta_z <= PI / 2.0 && c.gamma == gm, "{c:?}");
        for _ in 0..200 {
            let m = rng.hemisphere();
            let (a, b) = (s.d(m), c.d(m));
            assert!((a - b).abs() <= 1e-12 * a, "{s:?} -> {c:?}: D {a} vs {b}");
            let u = rng.hemisphere();
            let (a, b) = (s.lambda(u), c.lambda(u));
            assert!((a - b).abs() <= 1e-12 * a.max(1e-300), "{s:?} -> {c:?}: Lambda {a} vs {b}");
        }
    }
}

#[test]
fn bad_parameters_are_refused() {
    for gm in [GAMMA_MIN, 1.0, 0.0, -3.0, f64::NAN, f64::INFINITY, GAMMA_MAX * 1.001] {
        let e = Student::new(0.3, 0.3, 0.0, gm).unwrap_err().to_string();
        assert!(e.contains("gamma"), "gamma {gm}: {e}");
    }
    assert!(Student::new(f64::NAN, 0.3, 0.0, 2.0).is_err());
    assert!(Student::new(0.3, 0.3, f64::INFINITY, 2.0).is_err());
    assert!(Student::new(0.3, 0.3, 0.0, GAMMA_MIN + 1e-12).is_ok());
}

#[test]
fn extremes_stay_finite() {
    let mut dirs = vec![
        Vector3::z(),
        -Vector3::z(),
        Vector3::x(),
        Vector3::new(0.6, 0.8, 0.0),
        Vector3::new(1.0, 0.0, 1e-300),
        Vector3::new(0.0, 1.0, -1e-300),
    ];
    for theta in [1e-8, 45.0, 89.0, 89.999_999, 90.0 - 1e-13] {
        dirs.push(dir(theta, 0.3));
        dirs.push(-dir(theta, 2.0));
    }
    for a in [1e-4, 1e-2, 1.0, 1e6] {
        for gm in [GAMMA_MIN + 1e-9, 1.6, 2.0, 3.0, 1e3, GAMMA_MAX] {
            for (ax, ay) in [(a, a), (a, 1.0), (1e-4, 1e6)] {
                let s = Student::new(ax, ay, 0.7, gm).unwrap();
                for &u in &dirs {
                    let d = s.d(u);
                    let l = s.lambda(u);
                    let g1 = s.g1(u, Vector3::z());
                    assert!(d.is_finite() && d >= 0.0, "{s:?}: D({u:?}) = {d}");
                    assert!(l.is_finite() && l >= 0.0, "{s:?}: Lambda({u:?}) = {l}");
                    assert!((0.0..=1.0).contains(&g1), "{s:?}: G1({u:?}) = {g1}");
                }
                assert_eq!(s.lambda(Vector3::x()), f64::MAX);
                for xi in [[0.0, 0.0], [0.5, 0.5], [1.0 - 1e-16, 0.99], [0.999_999_999, 0.25]] {
                    let m = s.sample_normal(xi);
                    assert!(m.iter().all(|v| v.is_finite()) && m.z >= 0.0 && (m.norm() - 1.0).abs() < 1e-12, "{s:?}: sample {m:?}");
                    assert!(s.pdf_normal(m).is_finite());
                }
            }
        }
    }
}
