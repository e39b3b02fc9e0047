//! The analytic Jacobians of the single-lobe models against central finite differences (tolerance: the
//! module docs of `fit::tests`).

use crate::fit::lnd::LnD;
use crate::fit::params::{to_internal, to_public};
use crate::fit::{FitData, Objective, Rounding};
use crate::models::{ModelId, Ndf, Role};
use crate::ndf::HeightQuantum;
use crate::ndf::NormalScheme;
use nalgebra::Vector3;
use rand::{RngExt, SeedableRng};

use super::{assert_ln_d_gradient, assert_residual_jacobian, model};

fn random_params(id: ModelId, rng: &mut rand::rngs::StdRng) -> Vec<f64> {
    let a = |rng: &mut rand::rngs::StdRng| 10f64.powf(rng.random_range(-2.5..0.5));
    let t = |rng: &mut rand::rngs::StdRng, r: f64| rng.random_range(-r..r);
    // By the table's roles, so every single-lobe model is covered (the mixtures have their own checks).
    id.spec()
        .roles
        .iter()
        .map(|(r, _)| match r {
            Role::Alpha | Role::AlphaX | Role::AlphaY => a(rng),
            Role::ThetaX | Role::ThetaY => t(rng, 1.2),
            Role::ThetaZ => t(rng, 3.0),
            // Heavy tails near the Smith limit 3/2 to nearly Beckmann.
            Role::Gamma => 1.5 + 10f64.powf(rng.random_range(-1.5..2.0)),
            Role::Weight => unreachable!("single-lobe ids only"),
        })
        .collect()
}

#[test]
fn ln_d_matches_the_models_d() {
    // Independent source: the models module's D (Walter eq. 1, Heitz eq. 82) evaluated directly.
    let mut rng = rand::rngs::StdRng::seed_from_u64(1);
    for id in ModelId::singles() {
        for _ in 0..50 {
            let p = random_params(id, &mut rng);
            let m = model(id, &p);
            let f = LnD::new(id, &to_internal(id, &p));
            let dir = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(0.05..1.0)).normalize();
            let want = m.d(dir);
            if want > 1e-300 {
                let got = f.value(&dir).exp();
                assert!((got / want - 1.0).abs() < 1e-11, "{id} {p:?} at {dir:?}: {got} vs {want}");
            }
        }
    }
}

#[test]
fn ln_d_gradient_matches_central_differences() {
    let mut rng = rand::rngs::StdRng::seed_from_u64(2);
    for id in ModelId::singles() {
        for _ in 0..40 {
            let x = to_internal(id, &random_params(id, &mut rng));
            let dir = Vector3::new(rng.random_range(-1.0..1.0), rng.random_range(-1.0..1.0), rng.random_range(0.2..1.0)).normalize();
            let v = assert_ln_d_gradient(id, &x, &dir);
            assert!((v - LnD::new(id, &x).value(&dir)).abs() < 1e-12 * v.abs().max(1.0));
        }
    }
}

#[test]
fn residual_jacobian_matches_central_differences() {
    // Through the objective's chain rule, for both objectives, at a point away from the optimum so
    // that both signs of c - E occur; bins with small and zero counts included.
    // Both on the hemisphere and on a region cut at 40 deg (the normalization's rank-one term then
    // matters most: a good share of the mass is outside).
    for (objective, max_theta) in
        [(Objective::Poisson, 90f64), (Objective::Logd, 90.0), (Objective::Poisson, 40.0), (Objective::Logd, 40.0)]
    {
        for (id, truth, at) in [
            (ModelId::Ellipsoid, vec![0.3, 0.15, 0.2, -0.1, 0.5], vec![0.25, 0.2, 0.1, -0.2, 0.7]),
            (ModelId::BeckmannAniso, vec![0.2, 0.1, 0.3], vec![0.18, 0.12, 0.2]),
            (ModelId::Ggx, vec![0.1], vec![0.13]),
        ] {
            let t = model(id, &truth);
            let ndf = crate::fit::binned_ndf(&t, &crate::fit::Grid::for_model(&t, 48), 2e4, 3);
            let plain = FitData::new(&ndf, objective, max_theta.to_radians()).expect("data");
            // And with the height rounding of a quantized scan modelled (the rule of nine points per bin):
            // a lattice of a third of the truth's smaller alpha, for both normal schemes.
            let step = truth.iter().take(2).copied().fold(f64::INFINITY, f64::min) / 3.0;
            let quantum = HeightQuantum {
                quantum: 1e-8,
                slope_step: [step, 0.8 * step],
                whitened_step: [0.3, 0.3],
                on_lattice: 1.0,
                max_cells: 99,
                coarsened_from: None,
                rigidity: [1.0, 1.0],
                lattice: None,
            };
            for rounding in [None, Some(NormalScheme::Central), Some(NormalScheme::Triangles)] {
                let mut data = plain.clone();
                data.rounding = rounding.map(|scheme| Rounding::new(&quantum, scheme, &data.bins).expect("kernel"));
                assert_residual_jacobian(&data, id, &to_internal(id, &at), &format!("{objective:?} {rounding:?}"));
            }
            // Parameter maps round-trip.
            let x = to_internal(id, &at);
            let back = to_internal(id, &to_public(id, &x));
            for (a, b) in x.iter().zip(&back) {
                assert!((a - b).abs() < 1e-12);
            }
        }
    }
}
