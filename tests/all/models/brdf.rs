//! The conductor Fresnel term against an independent real-arithmetic formula, the microfacet BRDF of
//! Walter et al. eq. 4 (closed form at normal incidence, reciprocity, Heitz eq. 99 >= eq. 98), the roughness
//! matrix's way back to alphas, and the squared ellipsoidal lobe against its geometric definition.

use std::f64::consts::PI;

use nalgebra::{Complex, Matrix2, Matrix3, Rotation3, Unit, Vector3};
use ndfit::models::{
    checked_eta, disk_to_slope_jacobian, fresnel_conductor, Ggx, GgxMatrix, MaskingShadowing, MicrofacetBrdf, Model, ModelId, Ndf,
    SquaredEllipsoidalLobe,
};

use super::equivalence::Rng;

/// Conductor Fresnel in real arithmetic (the a^2, b^2 form of Born and Wolf, as in Cook and Torrance 1982).
fn fresnel_born_wolf(cos_i: f64, n: f64, k: f64) -> f64 {
    let s2 = 1.0 - cos_i * cos_i;
    let t0 = n * n - k * k - s2;
    let a2b2 = (t0 * t0 + 4.0 * n * n * k * k).sqrt();
    let a = (0.5 * (a2b2 + t0)).max(0.0).sqrt();
    let rs = (a2b2 - 2.0 * a * cos_i + cos_i * cos_i) / (a2b2 + 2.0 * a * cos_i + cos_i * cos_i);
    let sin_tan = s2 / cos_i; // sin(theta) tan(theta)
    let rp = rs * (a2b2 - 2.0 * a * sin_tan + sin_tan * sin_tan) / (a2b2 + 2.0 * a * sin_tan + sin_tan * sin_tan);
    0.5 * (rs + rp)
}

#[test]
fn conductor_fresnel_matches_born_and_wolf() {
    // Gold, aluminium, copper (~600 nm), a dielectric and a lossy glass.
    for (n, k) in [(0.18, 3.4), (1.2, 7.26), (0.27, 3.41), (1.5, 0.0), (1.5, 0.5)] {
        let eta = checked_eta(n, k).unwrap();
        let f0 = ((n - 1.0).powi(2) + k * k) / ((n + 1.0).powi(2) + k * k);
        assert!((fresnel_conductor(1.0, eta) - f0).abs() < 1e-14, "normal incidence");
        assert!((fresnel_conductor(0.0, eta) - 1.0).abs() < 1e-14, "grazing incidence");
        for i in 1..200 {
            let c = i as f64 / 200.0;
            let (a, b) = (fresnel_conductor(c, eta), fresnel_born_wolf(c, n, k));
            assert!((a - b).abs() < 1e-12, "eta {n}+{k}i cos {c}: {a} vs {b}");
        }
    }
    assert!(checked_eta(-1.0, 0.0).is_err() && checked_eta(1.0, -0.1).is_err() && checked_eta(f64::NAN, 1.0).is_err());
}

#[test]
fn brdf_closed_form_reciprocity_and_height_correlation() {
    // At psi = omega = n: f = D(n) G1(n)^2 F(1) / 4 with D(n) = 1/(pi alpha^2) and G1(n) = 1 (Heitz eq. 72).
    let alpha = 0.2;
    let eta = Complex::new(0.18, 3.4);
    let f0 = ((0.18f64 - 1.0).powi(2) + 3.4f64.powi(2)) / ((0.18f64 + 1.0).powi(2) + 3.4f64.powi(2));
    let ggx = Model::from_params(ModelId::Ggx, &[alpha]).unwrap();
    let brdf = MicrofacetBrdf { model: ggx, eta: Some(eta), masking: MaskingShadowing::Separable };
    let n = Vector3::z();
    let want = f0 / (4.0 * PI * alpha * alpha);
    assert!((brdf.eval(n, n) - want).abs() < 1e-12 * want, "{} vs {want}", brdf.eval(n, n));

    let mut rng = Rng(41);
    let models = [
        ggx,
        Model::from_params(ModelId::BeckmannAniso, &[0.2, 0.5, 0.3]).unwrap(),
        Model::from_params(ModelId::Ellipsoid, &[0.3, 0.15, 0.4, -0.2, 0.8]).unwrap(),
    ];
    for model in models {
        let sep = MicrofacetBrdf { model, eta: Some(eta), masking: MaskingShadowing::Separable };
        let hc = MicrofacetBrdf { model, eta: Some(eta), masking: MaskingShadowing::HeightCorrelated };
        for _ in 0..5000 {
            let (psi, omega) = (rng.hemisphere(), rng.hemisphere());
            for b in [sep, hc] {
                let (x, y) = (b.eval(psi, omega), b.eval(omega, psi));
                assert!((x - y).abs() <= 1e-12 * x.max(y), "{model:?} not reciprocal: {x} vs {y}");
            }
            // 1/(1 + L1 + L2) >= 1/((1 + L1)(1 + L2)) (Heitz sec. 6: eq. 98 overestimates shadowing).
            assert!(hc.eval(psi, omega) >= sep.eval(psi, omega) * (1.0 - 1e-12));
        }
        // Below the horizon: no reflection.
        assert_eq!(sep.eval(Vector3::new(0.0, 0.6, -0.8), n), 0.0);
    }
}

#[test]
fn disk_to_slope_jacobian_matches_central_differences() {
    // The hand-written Jacobian of Tokuyoshi eq. 25 against central differences of (-hx/hz, -hy/hz);
    // h = 1e-6: truncation ~h^2 times the third derivative and rounding ~1e-16/h stay below 1e-6 relative
    // for hz >= 0.3 (r <= 0.95).
    let slope = |x: f64, y: f64| {
        let z = (1.0 - x * x - y * y).sqrt();
        nalgebra::Vector2::new(-x / z, -y / z)
    };
    let mut rng = Rng(44);
    let h = 1e-6;
    for _ in 0..2000 {
        let (r, p) = (0.95 * rng.uniform().sqrt(), 2.0 * PI * rng.uniform());
        let (x, y) = (r * p.cos(), r * p.sin());
        let j = disk_to_slope_jacobian(x, y).unwrap();
        let cx = (slope(x + h, y) - slope(x - h, y)) / (2.0 * h);
        let cy = (slope(x, y + h) - slope(x, y - h)) / (2.0 * h);
        let fd = Matrix2::from_columns(&[cx, cy]);
        assert!((j - fd).abs().max() < 1e-6 * j.abs().max(), "at ({x}, {y}): {j} vs {fd}");
        let hz = (1.0 - x * x - y * y).sqrt();
        assert!((j.determinant() - hz.powi(-4)).abs() < 1e-9 * hz.powi(-4));
    }
    assert!(disk_to_slope_jacobian(1.0, 0.0).is_none() && disk_to_slope_jacobian(0.8, 0.8).is_none());
}

#[test]
fn roughness_matrix_filtering_and_back() {
    let g = Ggx::new(0.1, 0.4, 0.7).unwrap();
    let t = g.to_matrix();
    // Eigen-decomposition written here: A = Rz^T diag(ax^2, ay^2) Rz has trace ax^2 + ay^2 and det ax^2 ay^2.
    let a = t.matrix();
    assert!((a.trace() - (0.01 + 0.16)).abs() < 1e-15 && (a.determinant() - 0.01 * 0.16).abs() < 1e-15);
    let back = t.to_ggx();
    // Canonical: alpha_x >= alpha_y, so the axes swap and theta_z moves by pi/2 (folded).
    assert!((back.alpha_x - 0.4).abs() < 1e-12 && (back.alpha_y - 0.1).abs() < 1e-12, "{back:?}");
    let mut rng = Rng(42);
    for _ in 0..500 {
        let m = rng.hemisphere();
        assert!((back.d(m) - g.d(m)).abs() < 1e-10 * g.d(m));
    }
    // Tokuyoshi eq. 3: an isotropic kernel of variance v adds 2 v to each alpha^2.
    let iso = GgxMatrix::new(Matrix2::new(0.04, 0.0, 0.0, 0.04)).unwrap();
    let f = iso.with_kernel_covariance(Matrix2::new(0.01, 0.0, 0.0, 0.01)).unwrap().to_ggx();
    assert!((f.alpha_x - 0.06f64.sqrt()).abs() < 1e-12 && (f.alpha_y - 0.06f64.sqrt()).abs() < 1e-12);
    assert!(GgxMatrix::new(Matrix2::new(1.0, 2.0, 2.0, 1.0)).is_err(), "indefinite matrix accepted");
    assert!(GgxMatrix::new(Matrix2::new(1.0, 0.1, 0.0, 1.0)).is_err(), "asymmetric matrix accepted");
}

/// Distance from the origin along `w` to the ellipsoid of centre `(0, 0, (1 - a^2)/2)` and semi-axes
/// `(ax, ay, (1 + a^2)/2)` in lobe space (the SEL's definition), by bisection.
fn sel_by_bisection(v: Vector3<f64>, ax: f64, ay: f64) -> f64 {
    let a = ax.max(ay);
    let c = Vector3::new(0.0, 0.0, 0.5 * (1.0 - a * a));
    let r = Vector3::new(ax, ay, 0.5 * (1.0 + a * a));
    let inside = |t: f64| ((v * t - c).component_div(&r)).norm_squared() < 1.0;
    let (mut lo, mut hi) = (0.0, 2.0);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if inside(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let t = 0.5 * (lo + hi);
    t * t
}

#[test]
fn squared_ellipsoidal_lobe() {
    let mut rng = Rng(43);
    // Isotropic: K = pi alpha^2 D_GGX(cos(theta/2), alpha) (Tokuyoshi-Harada sec. 1).
    for alpha in [0.05, 0.3, 1.0] {
        let sel = SquaredEllipsoidalLobe::new(Matrix3::identity(), alpha, alpha).unwrap();
        let ggx = Ggx::new(alpha, alpha, 0.0).unwrap();
        for _ in 0..1000 {
            let w = rng.sphere();
            let half = (w + Vector3::z()).normalize();
            if !half.iter().all(|x| x.is_finite()) {
                continue;
            }
            let want = PI * alpha * alpha * ggx.d(half);
            let k = sel.eval(w);
            assert!((k - want).abs() < 1e-10 * want.max(1e-12), "alpha {alpha} w {w:?}: {k} vs {want}");
        }
    }
    // Anisotropic and rotated: the squared distance to the ellipsoid, found by bisection.
    for (ax, ay) in [(0.2, 0.6), (1e-2, 0.3), (0.9, 0.9), (1.0, 0.5)] {
        let axis = Unit::new_normalize(rng.sphere());
        let q = Rotation3::from_axis_angle(&axis, 1.3).into_inner();
        let sel = SquaredEllipsoidalLobe::new(q, ax, ay).unwrap();
        for _ in 0..500 {
            let w = rng.sphere();
            let want = sel_by_bisection(q * w, ax, ay);
            let k = sel.eval(w);
            assert!((k - want).abs() < 1e-12, "({ax}, {ay}) w {w:?}: {k} vs {want}");
            assert!(k <= 1.0 + 1e-12);
        }
        // K = 1 on the lobe axis (the third row of Q).
        let axis_w = q.transpose() * Vector3::z();
        assert!((sel.eval(axis_w) - 1.0).abs() < 1e-12);
    }
    assert!(SquaredEllipsoidalLobe::new(Matrix3::identity(), 1.5, 0.5).is_err());
    assert!(SquaredEllipsoidalLobe::new(Matrix3::from_element(1.0), 0.5, 0.5).is_err());
}
