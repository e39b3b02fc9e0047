//! Extremes: no NaN and no infinity from any public function for alpha in [1e-4, 10] (and the ratio of the
//! two), m or u exactly on the horizon or 1e-12 above it, tilts up to +-1.5, and near-singular A.

use nalgebra::{Complex, Matrix2, Matrix3, Vector2, Vector3};
use ndfit::models::{
    concentric_disk, fresnel_conductor, frisvad_basis, Beckmann, Ellipsoid, Ggx, GgxMatrix, Masking, MaskingShadowing, MicrofacetBrdf,
    Model, Ndf, SquaredEllipsoidalLobe,
};

/// Assert `x` is finite; the message is only built on failure (formatting is costly in these loops).
macro_rules! finite {
    ($x:expr, $($msg:tt)+) => {{
        let x: f64 = $x;
        assert!(x.is_finite(), "{} = {x}", format!($($msg)+));
    }};
}

macro_rules! finite_v {
    ($v:expr, $($msg:tt)+) => {{
        let v: Vector3<f64> = $v;
        assert!(v.iter().all(|x| x.is_finite()), "{} = {v:?}", format!($($msg)+));
    }};
}

/// Directions on, just above and well above the horizon, along the axes and the diagonals, and below it.
fn directions() -> Vec<Vector3<f64>> {
    let mut out = vec![Vector3::z(), -Vector3::z()];
    for k in 0..8 {
        let phi = k as f64 * std::f64::consts::FRAC_PI_4 + if k % 2 == 0 { 0.0 } else { 0.1 };
        let (s, c) = phi.sin_cos();
        for z in [0.0f64, 1e-12, 1e-6, 0.5, -1e-12, -0.5] {
            let r = (1.0 - z * z).sqrt();
            out.push(Vector3::new(r * c, r * s, z));
        }
    }
    out
}

fn models() -> Vec<Model> {
    let alphas = [1e-4, 1e-3, 0.5, 1.0, 10.0];
    let mut out = vec![];
    for &ax in &alphas {
        out.push(Model::Ggx(Ggx::new(ax, ax, 0.0).unwrap()));
        out.push(Model::Beckmann(Beckmann::new(ax, ax, 0.0).unwrap()));
        for &ay in &alphas {
            out.push(Model::GgxAniso(Ggx::new(ax, ay, 1.5).unwrap()));
            out.push(Model::BeckmannAniso(Beckmann::new(ax, ay, -0.7).unwrap()));
            for (tx, ty) in [(0.0, 0.0), (1.5, 0.0), (0.0, -1.5), (1.5, 1.5), (-1.5, 1.5)] {
                out.push(Model::Ellipsoid(Ellipsoid::from_params(ax, ay, tx, ty, 0.4).unwrap()));
            }
        }
    }
    out
}

#[test]
fn every_model_function_is_finite_at_the_extremes() {
    let dirs = directions();
    let gold = Complex::new(0.18, 3.4);
    for model in models() {
        let c = model.canonical();
        for p in c.params() {
            finite!(p, "canonical parameter");
        }
        if let Some(a) = model.matrix_a() {
            assert!(a.iter().all(|x| x.is_finite()), "matrix_a {a:?}");
        }
        let json = serde_json::Value::Object(model.to_json_fields());
        assert!(Model::from_json(&json).is_ok(), "to_json_fields -> from_json failed for {model:?}");
        let brdfs = [
            MicrofacetBrdf { model, eta: Some(gold), masking: MaskingShadowing::Separable },
            MicrofacetBrdf { model, eta: None, masking: MaskingShadowing::HeightCorrelated },
        ];
        for &m in &dirs {
            let d = model.d(m);
            finite!(d, "{model:?} D({m:?})");
            assert!(d >= 0.0);
            for &u in &dirs {
                let g1 = model.g1(u, m);
                assert!((0.0..=1.0).contains(&g1), "{model:?} G1({u:?}, {m:?}) = {g1}");
                for b in &brdfs {
                    let f = b.eval(u, m);
                    finite!(f, "{model:?} BRDF({u:?}, {m:?})");
                    assert!(f >= 0.0);
                }
            }
        }
        for &u in &dirs {
            let l = model.lambda(u);
            finite!(l, "{model:?} Lambda({u:?})");
            assert!(l >= 0.0);
        }
        if let Some(e) = model.ellipsoid() {
            ellipsoid_functions(&e, &dirs);
        }
    }
}

fn ellipsoid_functions(e: &Ellipsoid, dirs: &[Vector3<f64>]) {
    let n = Vector3::z();
    finite!(e.an_norm(), "|An|");
    for &u in dirs {
        finite!(e.projected_area(u), "A_e");
        finite!(e.projected_area_lune(u, n), "A_l");
        finite!(e.lambda(u), "ellipsoid Lambda");
        for &m in dirs {
            finite!(e.pdf_visible_normal(u, m), "p_h");
            finite!(e.pdf_reflected(u, m), "p_o");
            let w = e.sample_weight(u, m, (u + m).normalize(), 1.0);
            assert!(w.is_finite() && (0.0..=1.0).contains(&w) || (u + m).norm() == 0.0, "weight {w}");
        }
        for xi in [[0.0, 0.0], [0.5, 0.5], [1.0 - f64::EPSILON, 0.0], [0.999_999, 0.999_999], [0.3, 1.0 - 1e-16]] {
            if let Some(m) = e.sample_visible_normal(u, xi) {
                finite_v!(m, "sample for u {u:?} xi {xi:?}");
                assert!(m.z >= 0.0, "sample under the horizon: {m:?}");
                if let Some((o, _)) = e.sample_reflected(u, xi) {
                    finite_v!(o, "reflected sample");
                }
            } else {
                // Only u = -n (an empty lune) may refuse.
                assert!(u.z < 0.0, "no sample for u {u:?}");
            }
        }
    }
}

#[test]
fn other_public_functions_are_finite_at_the_extremes() {
    // Slope-space forms at huge slopes (the horizon) and at zero.
    for a in [1e-4, 1.0, 10.0] {
        let g = Ggx::new(a, a * 0.5 + 1e-4, 0.3).unwrap();
        let b = Beckmann::new(a, a, 0.3).unwrap();
        for s in [0.0, 1e-12, 1.0, 1e12, 1e100, 1e200, 1e300] {
            for v in [Vector2::new(s, 0.0), Vector2::new(-s, s)] {
                finite!(g.p22(v), "GGX P22");
                finite!(b.p22(v), "Beckmann P22");
            }
        }
        finite!(g.alpha_o(Vector3::z()), "alpha_o along n");
        finite!(b.alpha_o(Vector3::new(1.0, 0.0, 0.0)), "alpha_o on the horizon");
        // D at m.z = 1e-100 (the lead's 0/0 case) and 1e-300.
        for z in [1e-100f64, 1e-300, 5e-324] {
            let m = Vector3::new((1.0 - z * z).sqrt(), 0.0, z);
            finite!(Beckmann::new(a, a, 0.0).unwrap().d(m), "Beckmann D near the horizon");
            finite!(Ggx::new(a, a, 0.0).unwrap().d(m), "GGX D near the horizon");
        }
    }
    // The roughness matrix, its filtering and its way back.
    let t = GgxMatrix::new(Matrix2::new(1e-8, 0.0, 0.0, 100.0)).unwrap();
    for u in directions() {
        finite!(t.d(u), "matrix D");
        finite!(t.lambda(u), "matrix Lambda");
    }
    let back = t.to_ggx();
    finite!(back.alpha_x + back.alpha_y + back.theta_z, "to_ggx");
    assert!(t.with_kernel_covariance(Matrix2::new(0.01, 0.002, 0.002, 0.01)).is_ok());
    // Fresnel at normal, grazing and past grazing incidence; eta = 1 at grazing is 0/0 in the formula.
    for eta in [Complex::new(1.0, 0.0), Complex::new(0.18, 3.4), Complex::new(1e-6, 0.0), Complex::new(50.0, 1e3)] {
        for c in [0.0, 1e-12, 0.5, 1.0, -0.3, 1.0 + 1e-15] {
            let f = fresnel_conductor(c, eta);
            assert!((0.0..=1.0).contains(&f), "F({c}, {eta}) = {f}");
        }
    }
    // SEL at the smallest roughness, on and opposite its axis.
    let sel = SquaredEllipsoidalLobe::new(Matrix3::identity(), 1e-4, 1.0).unwrap();
    for w in directions() {
        let k = sel.eval(w);
        assert!(k.is_finite() && (0.0..=1.0 + 1e-12).contains(&k), "SEL({w:?}) = {k}");
    }
    // Sampling helpers at the corners of the unit square.
    for xi in [[0.0, 0.0], [0.5, 0.5], [1.0, 1.0], [0.5, 0.0]] {
        let (x, y) = concentric_disk(xi[0], xi[1]);
        assert!(x.is_finite() && y.is_finite() && x * x + y * y <= 1.0 + 1e-12);
    }
    for n in directions() {
        let (b1, b2) = frisvad_basis(n);
        finite_v!(b1, "Frisvad b1");
        finite_v!(b2, "Frisvad b2");
    }
}

#[test]
fn near_singular_matrices_are_refused_or_finite() {
    let base = Ellipsoid::from_params(0.3, 0.2, 0.4, -0.3, 0.5).unwrap().a();
    for eps in [1e-3, 1e-6, 1e-9, 1e-11, 1e-13, 1e-16, 0.0] {
        // Squash A along one direction: singular value ratio ~ eps.
        let squash = Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, eps));
        for a in [squash * base, base * squash, Matrix3::new(1.0, 1.0, 0.0, 1.0, 1.0 + eps, 0.0, 0.0, 0.0, 1.0)] {
            match Ellipsoid::from_matrix(a) {
                Ok(e) => {
                    for p in e.params() {
                        finite!(p, "params of a near-singular A");
                    }
                    for m in directions() {
                        finite!(e.d(m), "D of a near-singular A");
                        for u in directions() {
                            let g = e.g1(u, m);
                            assert!((0.0..=1.0).contains(&g));
                        }
                    }
                }
                Err(err) => assert!(!err.to_string().is_empty()),
            }
        }
    }
    for bad in [Matrix3::from_element(f64::NAN), Matrix3::zeros(), Matrix3::from_element(f64::INFINITY)] {
        assert!(Ellipsoid::from_matrix(bad).is_err());
    }
    // Parameters out of range are errors, not NaN.
    assert!(Ellipsoid::from_params(f64::NAN, 0.1, 0.0, 0.0, 0.0).is_err());
    assert!(Ellipsoid::from_params(0.1, 0.1, f64::INFINITY, 0.0, 0.0).is_err());
    assert!(Ggx::new(0.0, 0.1, 0.0).is_err());
    assert!(Beckmann::new(0.1, 1e300, 0.0).is_err());
    assert!(Ggx::new(0.1, 0.1, f64::NAN).is_err());
}

/// Parameters out of range are refused under the name the model's JSON gives them (`alpha` for the
/// isotropic models, not the internal `alpha_x`), including a non-finite one.
#[test]
fn out_of_range_parameters_are_named_as_the_model_names_them() {
    use ndfit::models::ModelId;
    let msg = |id: ModelId, p: &[f64]| Model::from_params(id, p).unwrap_err().to_string();
    for id in [ModelId::Ggx, ModelId::Beckmann] {
        let e = msg(id, &[-1.0]);
        assert!(e.contains("alpha must be finite and positive, got -1"), "{e}");
    }
    let e = msg(ModelId::BeckmannAniso, &[0.2, -0.1, 0.0]);
    assert!(e.contains("alpha_y must be finite and positive"), "{e}");
    let e = msg(ModelId::GgxAniso, &[0.2, 0.1, f64::NAN]);
    assert!(e.contains("theta_z = NaN is not finite"), "{e}");
}
