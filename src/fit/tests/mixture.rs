//! The two-lobe mixtures' internals: their `ln D` against the models' own D, the analytic Jacobians
//! against central differences, and the canonical form.

use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};

use super::{assert_ln_d_gradient, assert_residual_jacobian, model};
use crate::fit::lnd::LnD;
use crate::fit::objective::{FitData, Objective};
use crate::fit::params::{to_internal, to_public};
use crate::models::{Model, ModelId, Ndf};

fn random_params(id: ModelId, rng: &mut rand::rngs::StdRng) -> Vec<f64> {
    let a = |rng: &mut rand::rngs::StdRng| 10f64.powf(rng.random_range(-2.0..0.3));
    let t = |rng: &mut rand::rngs::StdRng, r: f64| rng.random_range(-r..r);
    let w = |rng: &mut rand::rngs::StdRng| rng.random_range(0.05..0.95);
    match id {
        ModelId::Ggx2 | ModelId::Beckmann2 => vec![a(rng), a(rng), a(rng), a(rng), t(rng, 3.0), w(rng)],
        _ => vec![a(rng), a(rng), t(rng, 1.0), t(rng, 1.0), t(rng, 3.0), a(rng), w(rng)],
    }
}

/// Independent source: the models module's D of each lobe (Walter eq. 1, Heitz eq. 82), mixed by hand.
#[test]
fn mixture_ln_d_matches_the_lobes_mixed_by_hand() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(11);
    for id in ModelId::mixtures() {
        for _ in 0..50 {
            let p = random_params(id, &mut rng);
            let (d1, d2, w): (Model, Model, f64) = match id {
                ModelId::Ggx2 => (model(ModelId::GgxAniso, &[p[0], p[1], p[4]]), model(ModelId::GgxAniso, &[p[2], p[3], p[4]]), p[5]),
                ModelId::Beckmann2 => {
                    (model(ModelId::BeckmannAniso, &[p[0], p[1], p[4]]), model(ModelId::BeckmannAniso, &[p[2], p[3], p[4]]), p[5])
                }
                _ => (model(ModelId::Ellipsoid, &p[..5]), model(ModelId::Ggx, &[p[5]]), p[6]),
            };
            let f = LnD::new(id, &to_internal(id, &p));
            let m = model(id, &p);
            let dir = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(0.05..1.0)).normalize();
            let want = w * d1.d(dir) + (1.0 - w) * d2.d(dir);
            if want > 1e-300 {
                let got = f.value(&dir).exp();
                assert!((got / want - 1.0).abs() < 1e-11, "{id} {p:?} at {dir:?}: {got} vs {want}");
                assert!((m.d(dir) / want - 1.0).abs() < 1e-13, "{id}: Model::d");
            }
        }
    }
}

#[test]
fn mixture_ln_d_gradient_matches_central_differences() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(12);
    for id in ModelId::mixtures() {
        for _ in 0..40 {
            let x = to_internal(id, &random_params(id, &mut rng));
            let dir = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(0.2..1.0)).normalize();
            assert_ln_d_gradient(id, &x, &dir);
        }
    }
}

#[test]
fn mixture_residual_jacobian_matches_central_differences() {
    for (objective, max_theta) in [(Objective::Poisson, 90f64), (Objective::Logd, 90.0), (Objective::Poisson, 40.0)] {
        for (id, truth, at) in [
            (ModelId::Ggx2, vec![0.1, 0.06, 0.4, 0.3, 0.3, 0.7], vec![0.12, 0.05, 0.35, 0.33, 0.2, 0.6]),
            (ModelId::Beckmann2, vec![0.1, 0.06, 0.4, 0.3, 0.3, 0.7], vec![0.12, 0.05, 0.35, 0.33, 0.2, 0.6]),
            (ModelId::EllipsoidGgx, vec![0.12, 0.07, 0.1, -0.1, 0.4, 0.4, 0.7], vec![0.1, 0.08, 0.05, -0.15, 0.5, 0.35, 0.6]),
        ] {
            let t = model(id, &truth);
            let ndf = crate::fit::binned_ndf(&t, &crate::fit::Grid::for_model(&t, 48), 2e4, 3);
            let data = FitData::new(&ndf, objective, max_theta.to_radians()).expect("data");
            let x = to_internal(id, &at);
            assert_residual_jacobian(&data, id, &x, &format!("{objective:?}"));
            let back = to_internal(id, &to_public(id, &x));
            for (a, b) in x.iter().zip(&back) {
                assert!((a - b).abs() < 1e-9, "{id}: parameter map round trip {x:?} vs {back:?}");
            }
        }
    }
}

/// Canonical form: the same D everywhere, idempotent, the narrower lobe first, `alpha_x1 >= alpha_y1`
/// (or, for a round core, the tail's), `theta_z` in `(-pi/2, pi/2]`.
#[test]
fn mixture_canonical_form_keeps_d_and_orders_the_lobes() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(13);
    for id in ModelId::mixtures() {
        for _ in 0..200 {
            let p = random_params(id, &mut rng);
            let m = model(id, &p);
            let c = m.canonical();
            let q = c.params();
            for _ in 0..5 {
                let dir = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(0.05..1.0)).normalize();
                let (a, b) = (m.d(dir), c.d(dir));
                assert!((a - b).abs() <= 1e-10 * a.max(1e-300), "{id} {p:?} -> {q:?}: D {a} vs {b}");
            }
            let again = c.canonical().params();
            for (u, v) in q.iter().zip(&again) {
                assert!((u - v).abs() <= 1e-12 * u.abs().max(1.0), "{id}: canonical form not idempotent {q:?} vs {again:?}");
            }
            if matches!(id, ModelId::Ggx2 | ModelId::Beckmann2) {
                assert!(q[0] * q[1] <= q[2] * q[3], "{id}: narrower lobe first {q:?}");
                assert!(q[0] >= q[1], "{id}: alpha_x1 >= alpha_y1 {q:?}");
                assert!(q[4] > -std::f64::consts::FRAC_PI_2 && q[4] <= std::f64::consts::FRAC_PI_2, "{id}: theta_z {q:?}");
            }
        }
    }
}
