//! Renderer export and lobe axes (CONTRACT.md "Renderer export"): each renderer's parameters are turned
//! back into alphas by the renderer's published formula, its D is evaluated in its own tangent frame
//! (written here from its published definition) and compared with ndfit's D; the axes of a skewed
//! ellipsoid are checked against the fall-off of D itself; approximations are checked for optimality and
//! their reported error against an independent quadrature.

use std::f64::consts::{PI, TAU};
use std::process::Command;

use nalgebra::Vector3;
use ndfit::export::{export, Distribution, Target};
use ndfit::models::{Model, ModelId, Ndf};
use serde_json::{json, Value};

use crate::common::ndfit_bin;

/// Directions over the hemisphere: a golden-angle spiral in `cos theta` from the pole to 89 degrees.
fn directions(n: usize) -> Vec<Vector3<f64>> {
    let ga = PI * (3.0 - 5f64.sqrt());
    (0..n)
        .map(|i| {
            let z = 1.0 - (i as f64 + 0.5) / n as f64 * (1.0 - 89f64.to_radians().cos());
            let r = (1.0 - z * z).sqrt();
            let p = ga * i as f64;
            Vector3::new(r * p.cos(), r * p.sin(), z)
        })
        .collect()
}

/// Components of `m` in the tangent frame `(u, n x u, n)` with `u` at azimuth `t`.
fn local(m: Vector3<f64>, t: f64) -> Vector3<f64> {
    let (s, c) = t.sin_cos();
    Vector3::new(c * m.x + s * m.y, -s * m.x + c * m.y, m.z)
}

/// Mitsuba 3 `MicrofacetDistribution::eval` (GGX): `1 / (pi au av (x^2/au^2 + y^2/av^2 + z^2)^2)` in the
/// local frame; Beckmann: `exp(-(x^2/au^2 + y^2/av^2)/z^2) / (pi au av z^4)`.
fn d_mitsuba(beckmann: bool, au: f64, av: f64, m: Vector3<f64>) -> f64 {
    if m.z <= 0.0 {
        return 0.0;
    }
    let (x, y) = (m.x / au, m.y / av);
    if beckmann {
        (-(x * x + y * y) / (m.z * m.z)).exp() / (PI * au * av * m.z.powi(4))
    } else {
        1.0 / (PI * au * av * (x * x + y * y + m.z * m.z).powi(2))
    }
}

/// pbrt-v4 `TrowbridgeReitzDistribution::D` in its spherical form:
/// `e = tan^2(theta) (cos^2 phi / ax^2 + sin^2 phi / ay^2)`, `D = 1 / (pi ax ay cos^4 theta (1 + e)^2)`.
fn d_pbrt(ax: f64, ay: f64, m: Vector3<f64>) -> f64 {
    let cos2 = m.z * m.z;
    let sin2 = (1.0 - cos2).max(0.0);
    let tan2 = sin2 / cos2;
    let (cphi2, sphi2) = if sin2 > 0.0 { (m.x * m.x / sin2, m.y * m.y / sin2) } else { (1.0, 0.0) };
    let e = tan2 * (cphi2 / (ax * ax) + sphi2 / (ay * ay));
    1.0 / (PI * ax * ay * cos2 * cos2 * (1.0 + e) * (1.0 + e))
}

fn model(id: ModelId, p: &[f64]) -> Model {
    Model::from_params(id, p).expect("valid parameters")
}

/// Every renderer's published map, inverted back to `(alpha_u, alpha_v, tangent angle)` from its keys.
fn renderer_alphas(target: Target, v: &Value) -> (f64, f64, f64) {
    let f = |k: &str| v[k].as_f64().unwrap_or_else(|| panic!("{k} missing in {v}"));
    match target {
        Target::Mitsuba => (f("alpha_u"), f("alpha_v"), f("tangent_angle")),
        Target::Pbrt => {
            assert_eq!(v["remaproughness"], json!(false));
            (f("uroughness"), f("vroughness"), f("tangent_angle"))
        }
        Target::Blender if v["node"] == json!("glossy") => cycles_glossy(&v["inputs"]),
        Target::Blender => {
            // Cycles: r2 = roughness^2, aspect = sqrt(1 - 0.9 anisotropic), alpha_x = r2/aspect along T,
            // T turned about n by 2 pi anisotropic_rotation; inputs in [0, 1].
            assert_eq!(v["node"], json!("principled"), "{v}");
            let (r, a, rot) = (f("roughness"), f("anisotropic"), f("anisotropic_rotation"));
            for x in [r, a, rot] {
                assert!((0.0..=1.0).contains(&x), "{v}");
            }
            let aspect = (1.0 - 0.9 * a).sqrt();
            (r * r / aspect, r * r * aspect, TAU * rot)
        }
        Target::OpenPbr => {
            let (r, a) = (f("specular_roughness"), f("specular_roughness_anisotropy"));
            assert!((0.0..=1.0).contains(&a), "{v}");
            let at = r * r * (2.0 / (1.0 + (1.0 - a).powi(2))).sqrt();
            (at, (1.0 - a) * at, f("tangent_angle"))
        }
        Target::MaterialX => {
            let r = v["roughness"].as_array().expect("roughness is [alpha_x, alpha_y]");
            (r[0].as_f64().unwrap(), r[1].as_f64().unwrap(), f("tangent_angle"))
        }
    }
}

/// Cycles' Glossy BSDF from its socket values (`svm_node_closure_bsdf`, the microfacet case):
/// `r2 = clamp(Roughness, 0, 1)^2`, `a = clamp(Anisotropy, -0.99, 0.99)`, isotropic for `|a| <= 1e-4`; for
/// `a < 0` `alpha_x = r2 / (1 + a)` along T and `alpha_y = r2 (1 + a)`, for `a > 0` `alpha_x = r2 (1 - a)`,
/// `alpha_y = r2 / (1 - a)`; T turned about n by `2 pi Rotation`; both alphas saturated at 1.
fn cycles_glossy(inputs: &Value) -> (f64, f64, f64) {
    let f = |k: &str| inputs[k].as_f64().unwrap_or_else(|| panic!("{k} missing in {inputs}"));
    let r2 = f("Roughness").clamp(0.0, 1.0).powi(2);
    let a = f("Anisotropy").clamp(-0.99, 0.99);
    let (ax, ay) = if a.abs() <= 1e-4 {
        (r2, r2)
    } else if a < 0.0 {
        (r2 / (1.0 + a), r2 * (1.0 + a))
    } else {
        (r2 * (1.0 - a), r2 / (1.0 - a))
    };
    (ax.min(1.0), ay.min(1.0), TAU * f("Rotation"))
}

/// The renderer's D at scan-frame direction `m` from its exported keys.
fn renderer_d(target: Target, v: &Value, m: Vector3<f64>) -> f64 {
    let (au, av, t) = renderer_alphas(target, v);
    let ml = local(m, t);
    match target {
        Target::Pbrt => d_pbrt(au, av, ml),
        Target::Mitsuba | Target::Blender => d_mitsuba(v["distribution"] == json!("beckmann"), au, av, ml),
        _ => d_mitsuba(false, au, av, ml),
    }
}

fn assert_same_d(target: Target, v: &Value, fit: &Model, tol: f64) {
    for m in directions(2000) {
        let (want, got) = (fit.d(m), renderer_d(target, v, m));
        // Below the normal f64 range D has lost its relative precision in both codes.
        if want < 1e-290 {
            continue;
        }
        // Beckmann's exponent (up to ~700 in the far tail) carries its rounding into D relatively.
        let tol = tol * (1.0 + want.ln().abs());
        assert!((got - want).abs() <= tol * want, "{} at {m:?}: renderer {got} vs ndfit {want}\n{v}", target.as_str());
    }
}

/// Representable fits: every renderer's own D, built from its published map of the exported keys, equals
/// ndfit's D at 2000 directions to 1e-12, for random anisotropic GGX (within Blender's 10:1) and any theta_z.
#[test]
fn exact_exports_reproduce_d_in_the_renderers_frame() {
    let mut seed = 7u64;
    let mut rnd = || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..40 {
        let ax = 0.02 + 0.9 * rnd();
        let ay = ax * (0.1 + 0.9 * rnd());
        let tz = (rnd() - 0.5) * 2.0 * PI;
        let fit = model(ModelId::GgxAniso, &[ax, ay, tz]);
        for target in Target::ALL {
            let e = export(&fit, target, 70.0).expect("export");
            assert!(e.approximation.is_none() && e.note.is_none(), "{ax} {ay} {}", target.as_str());
            assert_same_d(target, &e.to_json(), &fit, 1e-12);
        }
    }
    // Beckmann in Mitsuba and Blender (its Glossy BSDF), the renderers with it: exact too.
    let fit = model(ModelId::BeckmannAniso, &[0.3, 0.12, 0.7]);
    for target in [Target::Mitsuba, Target::Blender] {
        let e = export(&fit, target, 70.0).unwrap();
        assert!(e.approximation.is_none() && e.note.is_none());
        assert_eq!(e.to_json()["distribution"], json!("beckmann"));
        assert_same_d(target, &e.to_json(), &fit, 1e-12);
    }
}

/// Blender writes Beckmann as a Glossy BSDF: Cycles' own map of its Roughness, Anisotropy and Rotation
/// (`cycles_glossy`, written from `svm_node_closure_bsdf`) gives back the fit's D for random lobes up to
/// 500:1, beyond the Principled BSDF's 10:1; isotropic lobes have Anisotropy 0; an alpha above 1, which
/// Cycles saturates, is fitted within the node's limits and said so.
#[test]
fn blender_beckmann_is_a_glossy_node() {
    let mut seed = 11u64;
    let mut rnd = || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    for _ in 0..40 {
        let ax = 0.02 + 0.9 * rnd();
        let ay = ax * (0.002 + 0.998 * rnd());
        let fit = model(ModelId::BeckmannAniso, &[ax, ay, (rnd() - 0.5) * TAU]);
        let e = export(&fit, Target::Blender, 70.0).expect("export");
        let v = e.to_json();
        assert!(e.approximation.is_none() && e.note.is_none(), "{v}");
        assert_eq!((&v["node"], &v["distribution"]), (&json!("glossy"), &json!("beckmann")), "{v}");
        assert_same_d(Target::Blender, &v, &fit, 1e-12);
    }
    let v = export(&model(ModelId::Beckmann, &[0.2]), Target::Blender, 70.0).unwrap().to_json();
    assert_eq!(v["inputs"]["Anisotropy"], json!(0.0), "{v}");
    assert!((v["inputs"]["Roughness"].as_f64().unwrap() - 0.2f64.sqrt()).abs() < 1e-15, "{v}");
    let rough = model(ModelId::BeckmannAniso, &[1.6, 0.8, 0.0]);
    let e = export(&rough, Target::Blender, 70.0).unwrap();
    assert_eq!(e.lobe.distribution, Distribution::Beckmann);
    assert!(e.approximation.is_some() && e.lobe.alpha_u <= 1.0 + 1e-12, "{:?}", e.lobe);
    assert!(e.note.unwrap().contains("saturates"));
}

/// The example: theta_z = -1.043 puts the rough axis at +1.043 rad, and every tangent_angle says so.
#[test]
fn tangent_angle_is_minus_theta_z() {
    let fit = model(ModelId::GgxAniso, &[0.4, 0.1, -1.043]);
    for target in [Target::Mitsuba, Target::Pbrt, Target::OpenPbr, Target::MaterialX] {
        let v = export(&fit, target, 70.0).unwrap().to_json();
        assert!((v["tangent_angle"].as_f64().unwrap() - 1.043).abs() < 1e-12, "{v}");
    }
    let v = export(&fit, Target::Blender, 70.0).unwrap().to_json();
    assert!((v["anisotropic_rotation"].as_f64().unwrap() - 1.043 / TAU).abs() < 1e-12, "{v}");
    let axes = fit.canonical().axes().unwrap();
    assert!((axes.alpha_x_azimuth - 1.043).abs() < 1e-12);
    assert!((axes.alpha_x[0] - 1.043f64.cos()).abs() < 1e-12 && (axes.alpha_x[1] - 1.043f64.sin()).abs() < 1e-12);
    // D falls off slowest along alpha_x: at 20 degrees from the pole, largest there, smallest along alpha_y.
    let at = |phi: f64| {
        fit.d(Vector3::new(20f64.to_radians().sin() * phi.cos(), 20f64.to_radians().sin() * phi.sin(), 20f64.to_radians().cos()))
    };
    let (best, _) = (0..3600).map(|k| k as f64 * PI / 3600.0).map(|p| (p, at(p))).fold((0.0, 0.0), |a, b| if b.1 > a.1 { b } else { a });
    assert!((best - 1.043).abs() < 1e-3, "{best}");
}

/// Published maps in the other direction: the keys of each renderer for a known lobe.
#[test]
fn published_maps_by_hand() {
    // alpha 0.5 / 0.05 (10:1, Blender's limit): aspect^2 = 0.1 -> anisotropic 1; roughness^2 = sqrt(0.025).
    let fit = model(ModelId::GgxAniso, &[0.5, 0.05, -0.25 * PI]);
    let v = export(&fit, Target::Blender, 70.0).unwrap().to_json();
    assert!((v["anisotropic"].as_f64().unwrap() - 1.0).abs() < 1e-12, "{v}");
    assert!((v["roughness"].as_f64().unwrap() - 0.025f64.sqrt().sqrt()).abs() < 1e-12);
    assert!((v["anisotropic_rotation"].as_f64().unwrap() - 0.125).abs() < 1e-12);
    // OpenPBR: anisotropy = 1 - 0.05/0.5 = 0.9, r^4 = (0.25 + 0.0025) / 2.
    let v = export(&fit, Target::OpenPbr, 70.0).unwrap().to_json();
    assert!((v["specular_roughness_anisotropy"].as_f64().unwrap() - 0.9).abs() < 1e-12);
    assert!((v["specular_roughness"].as_f64().unwrap() - (0.2525f64 / 2.0).powf(0.25)).abs() < 1e-12);
    // Isotropic: no anisotropy anywhere, tangent angle 0.
    let iso = model(ModelId::Ggx, &[0.2]);
    let v = export(&iso, Target::Blender, 70.0).unwrap().to_json();
    assert_eq!(v["anisotropic"].as_f64().unwrap(), 0.0);
    assert!((v["roughness"].as_f64().unwrap() - 0.2f64.sqrt()).abs() < 1e-12);
}

/// `-ln` likelihood per unit weight of `lobe` against `reference` over theta <= max, by a midpoint rule in
/// (theta, phi) (a second quadrature, independent of the export's grid), with `lobe` normalized there.
fn neg_log_lik(lobe: &Model, reference: &Model, max_theta: f64) -> f64 {
    let (nt, np) = (1500, 720);
    let (mut ll, mut wsum, mut s) = (0.0, 0.0, 0.0);
    for i in 0..nt {
        let th = (i as f64 + 0.5) / nt as f64 * max_theta;
        let (st, ct) = th.sin_cos();
        for j in 0..np {
            let ph = (j as f64 + 0.5) / np as f64 * TAU;
            let m = Vector3::new(st * ph.cos(), st * ph.sin(), ct);
            let dw = st * ct;
            let w = reference.d(m) * dw;
            let d = lobe.d(m);
            s += d * dw;
            if w > 0.0 {
                ll += w * d.ln();
                wsum += w;
            }
        }
    }
    let cell = (max_theta / nt as f64) * (TAU / np as f64);
    -(ll / wsum - (s * cell).ln())
}

/// `delta(D; D_ref)` over theta <= max by the same midpoint rule.
fn delta_sph(d: &Model, d_ref: &Model, max_theta: f64) -> f64 {
    let (nt, np) = (1500, 720);
    let (mut num, mut den) = (0.0, 0.0);
    for i in 0..nt {
        let th = (i as f64 + 0.5) / nt as f64 * max_theta;
        let (st, ct) = th.sin_cos();
        for j in 0..np {
            let ph = (j as f64 + 0.5) / np as f64 * TAU;
            let m = Vector3::new(st * ph.cos(), st * ph.sin(), ct);
            let w = d_ref.d(m) * st * ct;
            if w > 0.0 {
                num += w * (d.d(m) / d_ref.d(m) - 1.0).powi(2);
                den += w;
            }
        }
    }
    (num / den).sqrt()
}

/// The approximation is the best lobe of its family: every small change of its alphas or angle lowers
/// the likelihood (second quadrature), and its reported delta agrees with that quadrature.
fn check_optimal(fit: &Model, target: Target, max_deg: f64, blender_edge: bool) -> ndfit::export::Export {
    let e = export(fit, target, max_deg).expect("export");
    let a = e.approximation.clone().expect("approximated");
    assert!(e.note.as_deref().is_some_and(|n| n.starts_with("approximated: ")), "{:?}", e.note);
    let lobe = e.lobe;
    let best = lobe.to_model().unwrap();
    let mt = max_deg.to_radians();
    let f0 = neg_log_lik(&best, fit, mt);
    let steps: &[(f64, f64, f64)] = if blender_edge {
        // On Blender's 10:1 edge only moves along it (both alphas together) and in angle are allowed.
        &[(1.02, 1.02, 0.0), (0.98, 0.98, 0.0), (1.0, 1.0, 0.01), (1.0, 1.0, -0.01)]
    } else {
        &[(1.02, 1.0, 0.0), (0.98, 1.0, 0.0), (1.0, 1.02, 0.0), (1.0, 0.98, 0.0), (1.0, 1.0, 0.01), (1.0, 1.0, -0.01)]
    };
    for &(fu, fv, dt) in steps {
        let mut l = lobe;
        l.alpha_u *= fu;
        l.alpha_v *= fv;
        l.tangent_angle += dt;
        let f = neg_log_lik(&l.to_model().unwrap(), fit, mt);
        assert!(f > f0 - 1e-7, "{}: step ({fu}, {fv}, {dt}) improves {f0} -> {f}", target.as_str());
    }
    let dr = delta_sph(fit, &best, mt);
    let got = a.delta_reverse.expect("finite");
    assert!((got - dr).abs() < 0.02 * dr + 1e-4, "delta(D_fit; D_export) {got} vs quadrature {dr}");
    if let Some(d) = a.delta {
        let want = delta_sph(&best, fit, mt);
        assert!((d - want).abs() < 0.05 * want + 1e-4, "delta(D_export; D_fit) {d} vs quadrature {want}");
    }
    e
}

/// Beckmann in pbrt (GGX only): the GGX lobe of largest likelihood, its error reported, a note says so.
#[test]
fn beckmann_to_ggx_is_fitted() {
    let fit = model(ModelId::BeckmannAniso, &[0.3, 0.15, 0.4]);
    let e = check_optimal(&fit, Target::Pbrt, 70.0, false);
    assert_eq!(e.lobe.distribution, Distribution::Ggx);
    assert!(e.note.unwrap().contains("no Beckmann"));
    assert!(e.approximation.unwrap().delta.is_none());
    // The axis stays where Beckmann's is (theta_z 0.4 -> tangent -0.4): by symmetry, not by the search.
    assert!((e.lobe.tangent_angle + 0.4).abs() < 1e-12, "{}", e.lobe.tangent_angle);
}

/// A two-lobe Beckmann fit (st_al3d-1's) for renderers with GGX alone and one tangent frame (pbrt,
/// MaterialX): each lobe's nearest GGX is its family's best (every small step of its alphas or angle lowers
/// the likelihood) and keeps the fit's shared axes, so the blend is written in one frame.
#[test]
fn beckmann2_blends_in_one_frame_where_ggx_is_fitted() {
    use ndfit::export::export_mixture;
    let p = [0.0983, 0.0641, 0.1785, 0.1597, -0.7248, 0.9403];
    let Model::Mixture(x) = model(ModelId::Beckmann2, &p) else { panic!("a mixture") };
    for target in [Target::Pbrt, Target::MaterialX] {
        let e = export_mixture(&x, target, 70.0).unwrap_or_else(|err| panic!("{}: {}", target.as_str(), err.message()));
        for (lobe, exported) in [(&p[0..2], &e.core), (&p[2..4], &e.tail)] {
            assert_eq!(exported.lobe.distribution, Distribution::Ggx);
            assert!((exported.lobe.tangent_angle - 0.7248).abs() < 1e-12, "{}: {:?}", target.as_str(), exported.lobe);
            check_optimal(&model(ModelId::BeckmannAniso, &[lobe[0], lobe[1], -0.7248]), target, 70.0, false);
        }
        assert!((e.tail_weight - (1.0 - 0.9403)).abs() < 1e-15);
    }
}

/// A skewed ellipsoid in Mitsuba: the nearest axis-aligned GGX, fitted.
#[test]
fn skewed_ellipsoid_is_fitted() {
    let fit = model(ModelId::Ellipsoid, &[0.3, 0.12, 0.1, -0.08, 0.5]);
    let e = check_optimal(&fit, Target::Mitsuba, 70.0, false);
    assert!(e.note.unwrap().contains("skew"));
    // The same ellipsoid without skew is GGX and exact.
    let plain = model(ModelId::Ellipsoid, &[0.3, 0.12, 0.0, 0.0, 0.5]);
    let e = export(&plain, Target::Mitsuba, 70.0).unwrap();
    assert!(e.approximation.is_none());
    assert_same_d(Target::Mitsuba, &e.to_json(), &plain, 1e-12);
}

/// Blender: 25:1 anisotropy is pulled to the 10:1 edge (anisotropic = 1) by the fit, not truncated.
#[test]
fn blender_beyond_ten_to_one_is_fitted_on_the_edge() {
    let fit = model(ModelId::GgxAniso, &[0.5, 0.02, 0.3]);
    let e = check_optimal(&fit, Target::Blender, 70.0, true);
    let v = e.to_json();
    assert!((v["anisotropic"].as_f64().unwrap() - 1.0).abs() < 1e-9, "{v}");
    assert!(e.note.unwrap().contains("10:1"));
    // alpha_x > 1 is saturated by Cycles: the export stays at or below 1.
    let rough = model(ModelId::GgxAniso, &[1.6, 0.8, 0.0]);
    let e = export(&rough, Target::Blender, 70.0).unwrap();
    assert!(e.approximation.is_some() && e.lobe.alpha_u <= 1.0 + 1e-12, "{:?}", e.lobe);
}

/// The axes of a skewed ellipsoid from D alone: the peak of the slope density `P22 = D / (1+|s|^2)^2`
/// (found by grid refinement), and along every direction `u` from it `P22 = P0 (1 + t^2 u.Sigma^-1.u)^-2`
/// with `u.Sigma^-1.u = cos^2/w_x^2 + sin^2/w_y^2` in the reported axes.
#[test]
fn ellipsoid_axes_follow_d() {
    for p in [[0.3, 0.12, 0.1, -0.08, 0.5], [0.5, 0.2, -0.4, 0.3, -1.2], [0.1, 0.09, 0.5, 0.2, 0.0]] {
        let fit = model(ModelId::Ellipsoid, &p).canonical();
        let axes = fit.axes().unwrap();
        let p22 = |s: [f64; 2]| {
            let m = Vector3::new(-s[0], -s[1], 1.0).normalize();
            fit.d(m) / (1.0 + s[0] * s[0] + s[1] * s[1]).powi(2)
        };
        let (mut c, mut h) = ([0.0, 0.0], 0.5);
        for _ in 0..12 {
            let mut best = (c, p22(c));
            for i in -10..=10 {
                for j in -10..=10 {
                    let s = [c[0] + h * i as f64 / 10.0, c[1] + h * j as f64 / 10.0];
                    let v = p22(s);
                    if v > best.1 {
                        best = (s, v);
                    }
                }
            }
            c = best.0;
            h /= 5.0;
        }
        let peak = Vector3::new(-c[0], -c[1], 1.0).normalize();
        assert!((peak - Vector3::from(axes.peak)).norm() < 1e-8, "{peak:?} vs {:?}", axes.peak);
        let p0 = p22(c);
        let (ex, ey) = (Vector3::from(axes.alpha_x), Vector3::from(axes.alpha_y));
        assert!(ex.z == 0.0 && (ex.norm() - 1.0).abs() < 1e-12 && ex.dot(&ey).abs() < 1e-12 && ex.cross(&ey).z > 0.0);
        let t = 0.3 * axes.widths[1];
        for k in 0..36 {
            let phi = k as f64 * PI / 36.0;
            let u = ex * phi.cos() + ey * phi.sin();
            let q = ((p0 / p22([c[0] + t * u.x, c[1] + t * u.y])).sqrt() - 1.0) / (t * t);
            let want = phi.cos().powi(2) / axes.widths[0].powi(2) + phi.sin().powi(2) / axes.widths[1].powi(2);
            assert!((q - want).abs() < 1e-6 * want, "{p:?} phi {phi}: {q} vs {want}");
        }
        // alpha_x is the axis nearer the first row of R, as documented.
        let r = ndfit::models::rotation_xyz(fit.params()[2], fit.params()[3], fit.params()[4]);
        let r1 = Vector3::new(r[(0, 0)], r[(0, 1)], 0.0).normalize();
        assert!(ex.dot(&r1).abs() > ey.dot(&r1).abs() && ex.dot(&r1) > 0.0);
    }
}

fn run_cli(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(ndfit_bin()).args(args).output().expect("runs");
    (out.status.code().unwrap_or(-1), String::from_utf8_lossy(&out.stdout).into_owned(), String::from_utf8_lossy(&out.stderr).into_owned())
}

/// The CLI: `--json` has exactly the contract's keys (no note for an exact export), snippets carry the
/// values, an approximation says so on stderr and in `note`, and bad input is one line naming the file.
#[test]
fn cli_export() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("brushed.json");
    let fit = json!({"schema": "ndfit.fit/1", "model": "ggx-aniso", "params": {"alpha_x": 0.4, "alpha_y": 0.1, "theta_z": -1.043},
                     "quality": {"max_theta_deg": 70.0}});
    std::fs::write(&path, fit.to_string()).unwrap();
    let p = path.to_str().unwrap();
    let keys: [(&str, &[&str]); 5] = [
        ("mitsuba", &["alpha_u", "alpha_v", "distribution", "plugin", "tangent_angle"]),
        ("pbrt", &["remaproughness", "tangent_angle", "uroughness", "vroughness"]),
        ("blender", &["anisotropic", "anisotropic_rotation", "distribution", "node", "roughness"]),
        ("openpbr", &["specular_roughness", "specular_roughness_anisotropy", "tangent_angle"]),
        ("materialx", &["roughness", "tangent_angle"]),
    ];
    let model = Model::from_json(&fit).unwrap();
    for (t, want) in keys {
        let (code, out, err) = run_cli(&["export", p, "--to", t, "--json"]);
        assert_eq!(code, 0, "{err}");
        assert!(err.is_empty(), "{err}");
        let v: Value = serde_json::from_str(&out).unwrap();
        let mut got: Vec<&str> = v.as_object().unwrap().keys().map(|k| k.as_str()).collect();
        got.sort();
        assert_eq!(got, want);
        assert_same_d(t.parse().unwrap(), &v, &model, 1e-12);
        let (code, snippet, _) = run_cli(&["export", p, "--to", t]);
        assert_eq!(code, 0);
        assert!(snippet.contains("brushed.json") && !snippet.contains(dir.path().to_str().unwrap()), "{snippet}");
    }
    let (_, s, _) = run_cli(&["export", p, "--to", "mitsuba"]);
    assert!(s.contains("<bsdf type=\"roughconductor\">") && s.contains("name=\"alpha_u\" value=\"0.4\""), "{s}");
    let (_, s, _) = run_cli(&["export", p, "--to", "pbrt"]);
    assert!(s.contains("\"float uroughness\" [ 0.4 ]") && s.contains("\"bool remaproughness\" false"), "{s}");
    // Approximated: Beckmann into pbrt.
    let bpath = dir.path().join("b.json");
    std::fs::write(&bpath, json!({"model": "beckmann", "params": {"alpha": 0.2}}).to_string()).unwrap();
    let (code, out, err) = run_cli(&["export", bpath.to_str().unwrap(), "--to", "pbrt", "--json"]);
    assert_eq!(code, 0);
    let v: Value = serde_json::from_str(&out).unwrap();
    assert!(v["note"].as_str().unwrap().contains("no Beckmann") && err.contains("approximated") && err.contains("b.json"), "{err}");
    assert!(v["approximation"]["delta_reverse"].as_f64().unwrap() > 0.0);
    // Bad input: one line naming the file, non-zero exit, nothing on stdout.
    let bad = dir.path().join("bad.json");
    std::fs::write(&bad, "{\"hello\": 1}").unwrap();
    for args in [vec!["export", bad.to_str().unwrap(), "--to", "pbrt"], vec!["export", p, "--to", "povray"]] {
        let (code, out, err) = run_cli(&args);
        assert_ne!(code, 0);
        assert!(out.is_empty() && err.lines().count() == 1, "{err}");
        assert!(err.contains(args[1]), "{err}");
    }
}

/// The `ndf --png` zoom (shared by `fit --plot`) holds 99% of the samples: for Beckmann alpha 0.05 the
/// closed form `F(tan theta) = 1 - exp(-tan^2/alpha^2)` puts 99% within `tan = alpha sqrt(ln 100)`, so the
/// half-width is 1.2 sin of that (to the bin size), far inside the disk.
#[test]
fn zoom_window_holds_the_data() {
    use ndfit::fit::{binned_ndf, Grid};
    let truth = model(ModelId::Beckmann, &[0.05]);
    let ndf = binned_ndf(&truth, &Grid::for_model(&truth, 63), 2e5, 3);
    let half = ndfit::ndf::zoom_half(&ndf, Vector3::z());
    let t = 0.05 * 100f64.ln().sqrt();
    let want = 1.2 * t / (1.0 + t * t).sqrt();
    assert!((half - want).abs() < 0.1 * want, "{half} vs {want}");
}
