//! Normalization (Heitz eq. 9): the integral of D(m) (m.n) over the hemisphere is 1 to 1e-6 for every model,
//! over a grid with alpha 1e-4 and 10, alpha ratios of 100 and tilts up to +-1.2. Integrated in slope space
//! (`P22 = D cos^4`, Heitz eq. 64) with the adaptive Gauss-Kronrod rule of `quad.rs`, after an affine change
//! of variables centred on the lobe (from the test's own algebra) and `t / (1 - t^2)` to reach infinity.

use ndfit::models::{Beckmann, Ellipsoid, Ggx, GgxMatrix, Model, ModelId, Ndf};

use super::quad::{hemisphere_integral, slope_frame};

/// The bar of the issue; the integrator is asked for 1e-9 relative, so a miss is the model's, not its.
const TOL: f64 = 1e-6;

fn check(name: &str, d: impl Fn(nalgebra::Vector3<f64>) -> f64, p: [f64; 5], worst: &mut f64) {
    let (w0, l) = slope_frame(p[0], p[1], p[2], p[3], p[4]);
    let (val, err) = hemisphere_integral(d, |_| 1.0, w0, l, 1e-10);
    let dev = (val - 1.0).abs();
    *worst = worst.max(dev);
    assert!(err < 1e-8, "{name} {p:?}: quadrature did not converge (err {err:e})");
    assert!(dev < TOL, "{name} {p:?}: integral of D cos = {val} (off by {dev:e})");
}

#[test]
fn isotropic_models_integrate_to_one() {
    let mut worst = 0.0f64;
    for a in [1e-4, 1e-3, 0.05, 0.5, 1.0, 3.0, 10.0] {
        let g = Model::from_params(ModelId::Ggx, &[a]).unwrap();
        let b = Model::from_params(ModelId::Beckmann, &[a]).unwrap();
        check("ggx", |m| g.d(m), [a, a, 0.0, 0.0, 0.0], &mut worst);
        check("beckmann", |m| b.d(m), [a, a, 0.0, 0.0, 0.0], &mut worst);
    }
    eprintln!("isotropic: worst |integral - 1| = {worst:e}");
}

#[test]
fn anisotropic_models_integrate_to_one() {
    let mut worst = 0.0f64;
    for (ax, ay) in [(1e-4, 1e-2), (1e-2, 1e-4), (0.1, 10.0), (10.0, 0.1), (0.3, 0.7)] {
        for tz in [0.0, 0.9, -2.5] {
            let g = Ggx::new(ax, ay, tz).unwrap();
            let b = Beckmann::new(ax, ay, tz).unwrap();
            let gm = GgxMatrix::from_ggx(&g);
            let p = [ax, ay, 0.0, 0.0, tz];
            check("ggx-aniso", |m| g.d(m), p, &mut worst);
            check("beckmann-aniso", |m| b.d(m), p, &mut worst);
            check("ggx roughness matrix", |m| gm.d(m), p, &mut worst);
        }
    }
    eprintln!("anisotropic: worst |integral - 1| = {worst:e}");
}

#[test]
fn ellipsoid_integrates_to_one_with_tilts() {
    let mut worst = 0.0f64;
    for (ax, ay) in [(1e-4, 1e-4), (1e-4, 1e-2), (0.1, 10.0), (10.0, 10.0), (0.3, 0.7), (1.0, 1.0)] {
        for (tx, ty) in [(0.0, 0.0), (1.2, 0.0), (0.0, -1.2), (1.2, -1.2), (-0.7, 0.4)] {
            let p = [ax, ay, tx, ty, 0.9];
            let e = Ellipsoid::from_params(ax, ay, tx, ty, 0.9).unwrap();
            check("ellipsoid", |m| e.d(m), p, &mut worst);
        }
    }
    eprintln!("ellipsoid: worst |integral - 1| = {worst:e}");
}
