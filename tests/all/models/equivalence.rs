//! Pointwise identities between the three forms of GGX (Walter's ellipsoid, Heitz's slope-space form,
//! Tokuyoshi's roughness matrix), against closed forms typed here from the papers, and the invariances of
//! Walter et al. eq. 1 (`c A`, `Q A`).

use std::f64::consts::PI;

use nalgebra::{Matrix3, Rotation3, Unit, Vector2, Vector3};
use ndfit::models::{Beckmann, Ellipsoid, Ggx, GgxMatrix, Masking, Ndf};

/// Deterministic uniform numbers (SplitMix64), so the tests need no RNG crate API.
pub struct Rng(pub u64);
impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
    /// Uniform on the unit sphere.
    pub fn sphere(&mut self) -> Vector3<f64> {
        let z = 2.0 * self.uniform() - 1.0;
        let p = 2.0 * PI * self.uniform();
        let r = (1.0 - z * z).max(0.0).sqrt();
        Vector3::new(r * p.cos(), r * p.sin(), z)
    }
    /// Uniform on the upper hemisphere.
    pub fn hemisphere(&mut self) -> Vector3<f64> {
        let v = self.sphere();
        Vector3::new(v.x, v.y, v.z.abs())
    }
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / a.abs().max(b.abs()).max(1e-300)
}

/// Rounding bound for these short formulas evaluated two ways: a few hundred ulps.
const EPS: f64 = 1e-12;

/// GTR2aniso (Burley eq. 13) with tangent X = (cos tz, -sin tz, 0), Y = (sin tz, cos tz, 0) (the rows of
/// Rz in Walter et al. eq. 3): `1 / (pi ax ay ((h.X/ax)^2 + (h.Y/ay)^2 + (h.n)^2)^2)`.
fn gtr2aniso(ax: f64, ay: f64, tz: f64, h: Vector3<f64>) -> f64 {
    let x = Vector3::new(tz.cos(), -tz.sin(), 0.0);
    let y = Vector3::new(tz.sin(), tz.cos(), 0.0);
    if h.z < 0.0 {
        return 0.0;
    }
    1.0 / (PI * ax * ay * ((h.dot(&x) / ax).powi(2) + (h.dot(&y) / ay).powi(2) + h.z * h.z).powi(2))
}

#[test]
fn ellipsoid_without_tilt_is_gtr2aniso_and_ggx() {
    let mut rng = Rng(1);
    for (ax, ay, tz) in [(0.2, 0.05, 0.7), (1e-4, 1e-2, -1.1), (3.0, 0.3, 2.0), (10.0, 10.0, 0.0), (0.4, 0.4, 0.3)] {
        let e = Ellipsoid::from_params(ax, ay, 0.0, 0.0, tz).unwrap();
        let g = Ggx::new(ax, ay, tz).unwrap();
        for _ in 0..2000 {
            let m = rng.hemisphere();
            let want = gtr2aniso(ax, ay, tz, m);
            assert!(rel(e.d(m), want) < EPS, "ellipsoid vs GTR2aniso at {m:?}");
            assert!(rel(g.d(m), want) < EPS, "Ggx vs GTR2aniso at {m:?}");
        }
    }
    // Isotropic: GGX of Heitz eq. 71 in theta form.
    for a in [1e-4, 0.1, 1.0, 10.0] {
        let e = Ellipsoid::from_params(a, a, 0.0, 0.0, 0.0).unwrap();
        for _ in 0..2000 {
            let m = rng.hemisphere();
            let c = m.z;
            let t2 = (1.0 - c * c) / (c * c);
            let want = 1.0 / (PI * a * a * c.powi(4) * (1.0 + t2 / (a * a)).powi(2));
            assert!(rel(e.d(m), want) < 1e-10, "ellipsoid vs eq. 71 at alpha {a}, m {m:?}");
        }
    }
}

/// Heitz eq. 86 with alpha_o of eq. 80 written in angles.
fn lambda_ggx_eq86(ax: f64, ay: f64, tz: f64, u: Vector3<f64>) -> f64 {
    // Into the local frame m' = Rz(tz) m (eq. 3), then phi_o, theta_o of eq. 80, 86.
    let l = Rotation3::from_axis_angle(&Vector3::z_axis(), tz) * u;
    let phi = l.y.atan2(l.x);
    let theta = l.z.acos();
    let alpha_o = (phi.cos().powi(2) * ax * ax + phi.sin().powi(2) * ay * ay).sqrt();
    let a = 1.0 / (alpha_o * theta.tan());
    (-1.0 + (1.0 + 1.0 / (a * a)).sqrt()) / 2.0
}

/// Heitz eq. 83 with the erf of libm.
fn lambda_beckmann_eq83(ax: f64, ay: f64, tz: f64, u: Vector3<f64>) -> f64 {
    let l = Rotation3::from_axis_angle(&Vector3::z_axis(), tz) * u;
    let phi = l.y.atan2(l.x);
    let theta = l.z.acos();
    let alpha_o = (phi.cos().powi(2) * ax * ax + phi.sin().powi(2) * ay * ay).sqrt();
    let a = 1.0 / (alpha_o * theta.tan());
    (libm::erf(a) - 1.0) / 2.0 + (-a * a).exp() / (2.0 * a * PI.sqrt())
}

#[test]
fn three_forms_of_ggx_agree_on_d_lambda_and_g1() {
    let mut rng = Rng(2);
    for (ax, ay, tz) in [(0.2, 0.05, 0.7), (1e-3, 1e-1, -1.1), (3.0, 0.3, 2.0), (0.5, 0.5, 0.0)] {
        let g = Ggx::new(ax, ay, tz).unwrap();
        let e = g.to_ellipsoid();
        let t = GgxMatrix::from_ggx(&g);
        for _ in 0..2000 {
            let m = rng.hemisphere();
            let u = rng.hemisphere();
            // Heitz eq. 64 + 84: D = P22(slope) / cos^4.
            let slope = Vector2::new(-m.x / m.z, -m.y / m.z);
            let d_slope = g.p22(slope) / m.z.powi(4);
            assert!(rel(g.d(m), d_slope) < 1e-10, "eq. 64/84 vs eq. 85 at {m:?}");
            assert!(rel(t.d(m), g.d(m)) < EPS, "Tokuyoshi eq. 17 vs Heitz at {m:?}");
            assert!(rel(e.d(m), g.d(m)) < EPS, "Walter eq. 1 vs Heitz at {m:?}");
            let want = lambda_ggx_eq86(ax, ay, tz, u);
            if u.z > 1e-3 && u.z < 1.0 - 1e-6 {
                // The literal eq. 86 computes sqrt(1 + 1/a^2) - 1 and so loses ~1e-16 absolute: allow that.
                let err = (g.lambda(u) - want).abs();
                assert!(err < 1e-9 * want + 1e-14, "Lambda eq. 86: {} vs {want} at {u:?}", g.lambda(u));
                // The three cancellation-free forms agree to rounding.
                assert!(rel(t.lambda(u), g.lambda(u)) < 1e-10, "Lambda eq. 18 vs eq. 86 at {u:?}");
                assert!(rel(e.lambda(u), g.lambda(u)) < 1e-10, "ellipsoid Lambda vs eq. 86 at {u:?}");
            }
            // G1: Walter eq. 6 equals the Smith form of Heitz eq. 43 without tilt (sec. 4.2).
            let mm = if u.dot(&m) > 0.0 { m } else { -m + Vector3::new(0.0, 0.0, 2.0 * m.z) };
            assert!((e.g1(u, mm) - g.g1(u, mm)).abs() < 1e-12, "G1 eq. 6 vs eq. 43 at u {u:?}");
            assert!((t.g1(u, mm) - g.g1(u, mm)).abs() < 1e-12);
        }
    }
}

#[test]
fn beckmann_matches_heitz_eq_82_and_83() {
    let mut rng = Rng(3);
    for (ax, ay, tz) in [(0.2, 0.05, 0.7), (1e-2, 1.0, -1.1), (0.5, 0.5, 0.0), (2.0, 0.8, 0.3)] {
        let b = Beckmann::new(ax, ay, tz).unwrap();
        for _ in 0..2000 {
            let m = rng.hemisphere();
            let l = Rotation3::from_axis_angle(&Vector3::z_axis(), tz) * m;
            let (phi, theta) = (l.y.atan2(l.x), l.z.acos());
            let e = theta.tan().powi(2) * (phi.cos().powi(2) / (ax * ax) + phi.sin().powi(2) / (ay * ay));
            let want = (-e).exp() / (PI * ax * ay * theta.cos().powi(4));
            if want > 1e-250 {
                assert!(rel(b.d(m), want) < 1e-9, "eq. 82 at {m:?}: {} vs {want}", b.d(m));
            }
            let u = rng.hemisphere();
            if u.z > 1e-3 && u.z < 1.0 - 1e-6 {
                let want = lambda_beckmann_eq83(ax, ay, tz, u);
                // erf(a) - 1 cancels in the reference for large a: compare absolutely there.
                let err = (b.lambda(u) - want).abs();
                assert!(err < 1e-9 * want.max(1e-6), "eq. 83 at {u:?}: {} vs {want}", b.lambda(u));
            }
        }
    }
}

fn random_rotation(rng: &mut Rng) -> Matrix3<f64> {
    let axis = Unit::new_normalize(rng.sphere());
    Rotation3::from_axis_angle(&axis, 2.0 * PI * rng.uniform()).into_inner()
}

#[test]
fn scaled_and_rotated_matrices_give_the_same_d() {
    let mut rng = Rng(4);
    for p in [[0.3, 0.1, 0.4, -0.2, 1.0], [1e-3, 0.5, 1.2, 0.7, -2.0], [5.0, 0.2, -1.0, 1.1, 0.3]] {
        let e = Ellipsoid::from_params(p[0], p[1], p[2], p[3], p[4]).unwrap();
        for c in [1e-3, 1.0, 7.0] {
            let q = random_rotation(&mut rng);
            // An improper Q (a reflection) is orthogonal too.
            let q = if c > 5.0 { q * Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, 1.0)) } else { q };
            let e2 = Ellipsoid::from_matrix(q * e.a() * c).unwrap();
            for _ in 0..500 {
                let m = rng.hemisphere();
                assert!(rel(e.d(m), e2.d(m)) < 1e-9, "c={c}: D(cQA) != D(A) at {m:?}");
                let u = rng.hemisphere();
                assert!((e.g1(u, m) - e2.g1(u, m)).abs() < 1e-9, "c={c}: G1 differs");
            }
        }
    }
}
