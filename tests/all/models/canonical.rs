//! Canonical parameters: same D, the rules of `ndfit::models::canonical`, idempotence, and hand-derived
//! relabelings of the same ellipsoid (Walter et al. eq. 1-3) that must all map to one canonical form.

use std::f64::consts::{FRAC_PI_2, PI};

use ndfit::models::{Ellipsoid, Model, ModelId, Ndf};

use super::equivalence::Rng;
use super::quad::rotation;

fn assert_same_d(a: &impl Ndf, b: &impl Ndf, what: &str) {
    let mut rng = Rng(11);
    for _ in 0..500 {
        let m = rng.hemisphere();
        let (x, y) = (a.d(m), b.d(m));
        assert!((x - y).abs() <= 1e-9 * x.abs().max(y.abs()), "{what}: D differs at {m:?}: {x} vs {y}");
    }
}

/// The rules, checked from the parameters with the test's own rotation: `r3` (third row of R) is the
/// principal axis nearest n among the three rows; alpha_x >= alpha_y; theta_z in (-pi/2, pi/2].
fn assert_canonical_rules(p: &[f64]) {
    let r = rotation(p[2], p[3], p[4]);
    let zs: Vec<f64> = (0..3).map(|i| r[(i, 2)].abs()).collect();
    assert!(r[(2, 2)] > 0.0 && zs[2] >= zs[0] - 1e-12 && zs[2] >= zs[1] - 1e-12, "third axis not nearest n: {p:?}");
    assert!(p[0] >= p[1], "alpha_x < alpha_y: {p:?}");
    assert!(p[4] > -FRAC_PI_2 && p[4] <= FRAC_PI_2, "theta_z out of (-pi/2, pi/2]: {p:?}");
    assert!(p[2].abs() < FRAC_PI_2 && p[3].abs() < FRAC_PI_2, "tilts out of (-pi/2, pi/2): {p:?}");
}

#[test]
fn canonical_ellipsoid_keeps_d_follows_the_rules_and_is_idempotent() {
    let mut rng = Rng(12);
    // A relabeling with a canonical alpha below ALPHA_MIN must still keep D (no floor in the canonical form).
    let e = Ellipsoid::from_params(1e-4, 10.0, 1.2, 0.0, 0.3).unwrap();
    assert_same_d(&e, &e.canonical(), "(1e-4, 10) tilted by 1.2");
    assert!(e.canonical().params()[1] < 1e-4, "{:?}", e.canonical().params());
    for _ in 0..300 {
        // alpha in [1e-4, 10] (the range the issue names), tilts up to +-1.5.
        let ax = 10f64.powf(-4.0 + 5.0 * rng.uniform());
        let ay = 10f64.powf(-4.0 + 5.0 * rng.uniform());
        let (tx, ty, tz) = (3.0 * rng.uniform() - 1.5, 3.0 * rng.uniform() - 1.5, 12.0 * rng.uniform() - 6.0);
        let e = Ellipsoid::from_params(ax, ay, tx, ty, tz).unwrap();
        let c = e.canonical();
        assert_same_d(&e, &c, &format!("canonical of {:?}", e.params()));
        assert_canonical_rules(&c.params());
        let cc = c.canonical();
        for (x, y) in c.params().iter().zip(cc.params()) {
            assert!((x - y).abs() < 1e-8 * x.abs().max(1.0), "not idempotent: {:?} -> {:?}", c.params(), cc.params());
        }
        // The round trip through A: from_matrix(A) gives the canonical parameters.
        let back = Ellipsoid::from_matrix(e.a()).unwrap();
        for (x, y) in c.params().iter().zip(back.params()) {
            assert!((x - y).abs() < 1e-8 * x.abs().max(1.0), "from_matrix: {:?} vs {:?}", c.params(), back.params());
        }
    }
}

#[test]
fn three_labelings_of_one_ellipsoid_have_one_canonical_form() {
    // Derived by hand from eq. 1-3: with R = Rx(t), shifting t by -pi/2 exchanges the roles of the y and z
    // axes (rows r2' = r3, r3' = -r2), and ||A^-T m||^2 scaled by alpha_y^2 gives alpha' = (ax/ay, 1/ay).
    // With R = Ry(t), shifting by +pi/2 exchanges x and z: alpha' = (1/ax, ay/ax).
    let (ax, ay) = (0.3, 0.12);
    let t = 0.25;
    let cases = [
        [ax, ay, t, 0.0, 0.0],
        [ax / ay, 1.0 / ay, t - FRAC_PI_2, 0.0, 0.0],
        [ax, ay, 0.0, t, 0.0],
        [1.0 / ax, ay / ax, 0.0, t + FRAC_PI_2, 0.0],
    ];
    let e0 = Ellipsoid::from_params(cases[0][0], cases[0][1], cases[0][2], cases[0][3], cases[0][4]).unwrap();
    let e1 = Ellipsoid::from_params(cases[1][0], cases[1][1], cases[1][2], cases[1][3], cases[1][4]).unwrap();
    assert_same_d(&e0, &e1, "x-axis relabeling");
    let c0 = e0.canonical().params();
    let c1 = e1.canonical().params();
    for (x, y) in c0.iter().zip(c1) {
        assert!((x - y).abs() < 1e-9, "two labelings, two canonical forms: {c0:?} vs {c1:?}");
    }
    // The canonical one is the small-tilt labeling (alpha_x >= alpha_y puts the 0.3 axis first).
    assert!((c0[0] - ax).abs() < 1e-12 && (c0[1] - ay).abs() < 1e-12 && (c0[2] - t).abs() < 1e-12, "{c0:?}");
    let e2 = Ellipsoid::from_params(cases[2][0], cases[2][1], cases[2][2], cases[2][3], cases[2][4]).unwrap();
    let e3 = Ellipsoid::from_params(cases[3][0], cases[3][1], cases[3][2], cases[3][3], cases[3][4]).unwrap();
    assert_same_d(&e2, &e3, "y-axis relabeling");
    let (c2, c3) = (e2.canonical().params(), e3.canonical().params());
    for (x, y) in c2.iter().zip(c3) {
        assert!((x - y).abs() < 1e-9, "{c2:?} vs {c3:?}");
    }
    // The flip of the first two axes: (tx, ty, tz) ~ (-tx, -ty, tz + pi).
    let f = Ellipsoid::from_params(0.4, 0.2, 0.3, -0.2, 0.5 + PI).unwrap();
    let g = Ellipsoid::from_params(0.4, 0.2, -0.3, 0.2, 0.5).unwrap();
    assert_same_d(&f, &g, "axis flip");
    let (cf, cg) = (f.canonical().params(), g.canonical().params());
    for (x, y) in cf.iter().zip(cg) {
        assert!((x - y).abs() < 1e-9, "{cf:?} vs {cg:?}");
    }
    assert!((cg[2] + 0.3).abs() < 1e-12 && (cg[4] - 0.5).abs() < 1e-12, "{cg:?}");
}

#[test]
fn ties_have_theta_z_zero() {
    // Isotropic GGX in ellipsoid form with a tilt: a spheroid, theta_z = 0 whatever was given.
    let e = Ellipsoid::from_params(0.2, 0.2, 0.3, -0.1, 1.3).unwrap();
    let c = e.canonical();
    assert_same_d(&e, &c, "spheroid");
    assert_eq!(c.params()[4], 0.0);
    // A sphere (alpha = 1): every labeling is the same and the canonical one has no tilt.
    let s = Ellipsoid::from_params(1.0, 1.0, 0.7, 0.2, 0.4).unwrap().canonical();
    assert_eq!(s.params(), [1.0, 1.0, 0.0, 0.0, 0.0]);
    // alpha_y = 1 with a tilt about x: the y-z plane is a circle, so the tilt is meaningless.
    let yz = Ellipsoid::from_params(0.3, 1.0, 0.8, 0.0, 0.0).unwrap();
    let cyz = yz.canonical();
    assert_same_d(&yz, &cyz, "circular y-z section");
    assert!(cyz.params()[2].abs() < 1e-9, "{:?}", cyz.params());
    for id in [ModelId::GgxAniso, ModelId::BeckmannAniso] {
        let m = Model::from_params(id, &[0.3, 0.3, 1.0]).unwrap().canonical();
        assert_eq!(m.params()[2], 0.0, "{id}: tie must give theta_z = 0");
    }
}

#[test]
fn canonical_aniso_models_swap_and_fold() {
    let mut rng = Rng(13);
    for id in [ModelId::GgxAniso, ModelId::BeckmannAniso] {
        for _ in 0..200 {
            let p = [0.01 + rng.uniform(), 0.01 + rng.uniform(), 20.0 * rng.uniform() - 10.0];
            let m = Model::from_params(id, &p).unwrap();
            let c = m.canonical();
            assert_eq!(c.id(), id);
            let q = c.params();
            assert!(q[0] >= q[1] && q[2] > -FRAC_PI_2 && q[2] <= FRAC_PI_2, "{id} {p:?} -> {q:?}");
            assert_same_d(&m, &c, &format!("{id} {p:?}"));
            // The ellipsoid's canonical form agrees for GGX (tilts 0).
            if id == ModelId::GgxAniso {
                let e = m.ellipsoid().unwrap().canonical().params();
                assert!((e[0] - q[0]).abs() < 1e-9 && (e[1] - q[1]).abs() < 1e-9 && (e[4] - q[2]).abs() < 1e-9);
                assert!(e[2].abs() < 1e-12 && e[3].abs() < 1e-12);
            }
        }
    }
}

#[test]
fn json_fields_are_canonical_and_round_trip() {
    let mut rng = Rng(14);
    for id in ModelId::singles() {
        for _ in 0..50 {
            let p: Vec<f64> = id
                .param_names()
                .iter()
                .map(|n| match *n {
                    n if n.starts_with("alpha") => 0.02 + 2.0 * rng.uniform(),
                    // A Student-t tail, from near the Smith limit 3/2 to nearly Beckmann.
                    "gamma" => 1.55 + 20.0 * rng.uniform(),
                    _ => 4.0 * rng.uniform() - 2.0,
                })
                .collect();
            let model = Model::from_params(id, &p).unwrap();
            let fields = model.to_json_fields();
            let json = serde_json::Value::Object(fields.clone());
            let back = Model::from_json(&json).unwrap();
            assert_eq!(back.id(), id);
            assert_same_d(&model, &back, &format!("{id} {p:?} via JSON"));
            // The printed parameters are the canonical ones.
            let canon = model.canonical().params();
            for (name, v) in id.param_names().iter().zip(&canon) {
                let got = fields["params"][*name].as_f64().unwrap();
                assert!((got - v).abs() < 1e-12, "{id}: params.{name} = {got}, canonical {v}");
            }
            // matrix_a, when present, describes the same D by Walter et al. eq. 1 evaluated here.
            if let Some(rows) = fields.get("matrix_a") {
                let a = nalgebra::Matrix3::from_fn(|r, c| rows[r][c].as_f64().unwrap());
                let a_inv_t = a.try_inverse().unwrap().transpose();
                let an = (a * nalgebra::Vector3::z()).norm();
                for _ in 0..50 {
                    let m = rng.hemisphere();
                    let d1 = 1.0 / (PI * a.determinant().abs() * an * (a_inv_t * m).norm().powi(4));
                    assert!((d1 - model.d(m)).abs() < 1e-9 * d1, "{id}: matrix_a's eq. 1 {d1} vs D {}", model.d(m));
                }
            } else {
                assert!(!id.has_matrix_a());
            }
        }
    }
}
