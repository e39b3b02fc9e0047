//! The sphere renderer (`ndfit::render`) against closed forms and brute force: a Lambertian sphere under
//! the point light (per pixel and the silhouette's coverage), under the cap light (the irradiance of a
//! uniform spherical cap), a glossy lobe under the cap against a brute-force sum over the cap, and the
//! Mitsuba-style evaluation of an RGL table against the analytic lobe it tabulates.

use std::f64::consts::PI;

use nalgebra::Vector3;
use ndfit::export::rgl::{tabulate, AnalyticBrdf, Material, Measured, RglOptions};
use ndfit::models::{Model, ModelId, Ndf};
use ndfit::render::{direction, sphere_frame, to_local, Brdf, Light, Scene};

/// The image-plane point `(x, y)` of pixel `(i, j)`'s centre (sphere radii, `y` up).
fn centre(scene: &Scene, i: usize, j: usize) -> (f64, f64) {
    let (n, e) = (scene.camera.size as f64, scene.camera.extent);
    (-e + (i as f64 + 0.5) * 2.0 * e / n, e - (j as f64 + 0.5) * 2.0 * e / n)
}

/// Under a light along the view, `f = 1 / cos(theta_o)` makes every visible point's radiance the
/// irradiance: each pixel is the irradiance times the share of its square inside the disc, here against
/// a 400 x 400 midpoint count, and the image's sum is the disc's area. `f = albedo / pi` gives
/// `E cos(theta) / pi` at every point, the pixel its mean over the square.
#[test]
fn lambertian_sphere_under_the_point_light() {
    let mut scene = Scene::point();
    scene.light = Light::Point { dir: scene.camera.view, irradiance: 2.0 };
    scene.camera.refine = 5;
    scene.camera.size = 24;
    let flat = scene.render(&|_wi: Vector3<f64>, wo: Vector3<f64>| [1.0 / wo.z; 3]).unwrap();
    let (n, e) = (scene.camera.size, scene.camera.extent);
    let side = 2.0 * e / n as f64;
    let mut total = 0.0;
    for j in 0..n {
        for i in 0..n {
            let (cx, cy) = centre(&scene, i, j);
            let m = 400;
            let inside = (0..m * m)
                .filter(|k| {
                    let x = cx + ((k % m) as f64 + 0.5) / m as f64 * side - side / 2.0;
                    let y = cy + ((k / m) as f64 + 0.5) / m as f64 * side - side / 2.0;
                    x * x + y * y < 1.0
                })
                .count() as f64
                / (m * m) as f64;
            let got = flat.get(i, j)[1] as f64 / 2.0;
            assert!((got - inside).abs() < 0.01, "pixel ({i}, {j}): coverage {got} against {inside}");
            total += got * side * side;
        }
    }
    assert!((total - PI).abs() < 2e-3 * PI, "disc area {total} against pi");

    scene.light = Light::Point { dir: direction(0.4, -1.2), irradiance: PI };
    let lit = scene.render(&|_: Vector3<f64>, _: Vector3<f64>| [0.8 / PI, 0.5 / PI, 0.2 / PI]).unwrap();
    let Light::Point { dir, .. } = scene.light else { unreachable!() };
    for (i, j) in [(12, 12), (8, 5), (15, 18), (3, 12)] {
        let (cx, cy) = centre(&scene, i, j);
        let m = 64;
        let mean: f64 = (0..m * m)
            .map(|k| {
                let x = cx + ((k % m) as f64 + 0.5) / m as f64 * side - side / 2.0;
                let y = cy + ((k / m) as f64 + 0.5) / m as f64 * side - side / 2.0;
                scene.normal_at(x, y).map_or(0.0, |nrm| nrm.dot(&dir).max(0.0))
            })
            .sum::<f64>()
            / (m * m) as f64;
        let got = lit.get(i, j);
        for (c, albedo) in [0.8, 0.5, 0.2].into_iter().enumerate() {
            let want = albedo * mean;
            assert!((got[c] as f64 - want).abs() < 1e-3 * want.max(0.05), "pixel ({i}, {j}) channel {c}: {} against {want}", got[c]);
        }
    }
}

/// A Lambertian surface that sees the whole cap receives `E = L pi sin^2(delta) cos(theta)`, `theta`
/// between its normal and the cap's centre; its radiance is `E / pi` (one point per pixel, at its
/// centre, so the light's quadrature alone is tested).
#[test]
fn lambertian_sphere_under_the_cap() {
    let mut scene = Scene::broad();
    scene.camera.points = 1;
    scene.camera.refine = 0;
    scene.camera.size = 32;
    let Light::Cap { dir, half_angle, radiance } = scene.light else { unreachable!() };
    let img = scene.render(&|_: Vector3<f64>, _: Vector3<f64>| [1.0 / PI; 3]).unwrap();
    let mut checked = 0;
    for j in 0..32 {
        for i in 0..32 {
            let (x, y) = centre(&scene, i, j);
            let Some(nrm) = scene.normal_at(x, y) else { continue };
            let theta = nrm.dot(&dir).clamp(-1.0, 1.0).acos();
            // Only normals that see the whole cap have the closed form.
            if theta + half_angle >= PI / 2.0 {
                continue;
            }
            let want = radiance * half_angle.sin().powi(2) * theta.cos();
            let got = img.get(i, j)[0] as f64;
            assert!((got - want).abs() < 1e-2 * want, "pixel ({i}, {j}): {got} against {want}");
            checked += 1;
        }
    }
    assert!(checked > 300, "{checked} pixels checked");
}

/// A glossy lobe under the cap against a brute-force midpoint sum over the cap (polar coordinates about
/// its centre, 1200 x 4800 points) at pixel centres around the highlight.
#[test]
fn glossy_sphere_under_the_cap_against_brute_force() {
    let mut scene = Scene::broad();
    scene.camera.points = 1;
    scene.camera.refine = 0;
    scene.camera.size = 32;
    let Light::Cap { dir, half_angle, radiance } = scene.light else { unreachable!() };
    for model in [Model::from_params(ModelId::GgxAniso, &[0.2, 0.08, 0.4]).unwrap(), Model::from_params(ModelId::Ggx, &[0.05]).unwrap()] {
        let brdf = AnalyticBrdf { model, material: Material::Au };
        let img = scene.render(&brdf).unwrap();
        for (i, j) in [(16, 12), (16, 9), (20, 12), (12, 14), (16, 20)] {
            let (x, y) = centre(&scene, i, j);
            let nrm = scene.normal_at(x, y).unwrap();
            let frame = sphere_frame(nrm);
            let (wi, c) = (to_local(&frame, scene.camera.view), to_local(&frame, dir));
            let (e1, m) = ((Vector3::x() - c * c.x).normalize(), 1200);
            let e2 = c.cross(&e1);
            let (dr, dp) = (half_angle / m as f64, 2.0 * PI / (4 * m) as f64);
            let mut want = [0.0; 3];
            for a in 0..m {
                let rho = (a as f64 + 0.5) * dr;
                for b in 0..4 * m {
                    let phi = (b as f64 + 0.5) * dp;
                    let l = c * rho.cos() + (e1 * phi.cos() + e2 * phi.sin()) * rho.sin();
                    if l.z > 0.0 {
                        let f = brdf.eval(wi, l);
                        (0..3).for_each(|k| want[k] += radiance * f[k] * l.z * rho.sin() * dr * dp);
                    }
                }
            }
            let got = img.get(i, j);
            let peak = want.iter().fold(0.0f64, |a, &b| a.max(b));
            for k in 0..3 {
                let err = (got[k] as f64 - want[k]).abs() / peak.max(1e-2);
                assert!(err < 0.01, "{:?} pixel ({i}, {j}) channel {k}: {} against {}", model.id(), got[k], want[k]);
            }
        }
    }
}

/// The table's Mitsuba-style evaluation against the analytic lobe it tabulates, at direction pairs with
/// incidence up to 60 degrees where the lobe's `f cos` is above 1% of its peak, and the analytic lobe's
/// reciprocity.
#[test]
fn measured_table_against_its_lobe() {
    let model = Model::from_params(ModelId::GgxAniso, &[0.3, 0.1, 0.5]).unwrap();
    let table = tabulate(&|m| model.d(m), "test", &RglOptions { material: Material::Cu, ..RglOptions::default() }, false).unwrap();
    let measured = Measured::new(&table.tensor).unwrap();
    let analytic = AnalyticBrdf { model, material: Material::Cu };
    // A fixed pseudo-random sequence (Weyl) of direction pairs.
    let (mut errs, mut peak) = (Vec::new(), 0.0f64);
    let pairs: Vec<(Vector3<f64>, Vector3<f64>)> = (1..=20000)
        .map(|k| {
            let u = |s: f64| (k as f64 * s).fract();
            let wi = direction((u(0.754_877_666) * 60.0).to_radians(), 2.0 * PI * u(0.569_840_29));
            let wo = direction((u(std::f64::consts::FRAC_1_PI) * 89.0).to_radians(), 2.0 * PI * u(0.141_421_356));
            (wi, wo)
        })
        .collect();
    let values: Vec<([f64; 3], [f64; 3])> = pairs.iter().map(|&(wi, wo)| (analytic.eval(wi, wo), measured.eval(wi, wo))).collect();
    for ((_, wo), (a, _)) in pairs.iter().zip(&values) {
        peak = peak.max(a[1] * wo.z);
    }
    for ((wi, wo), (a, m)) in pairs.iter().zip(&values) {
        let b = analytic.eval(*wo, *wi);
        assert!((a[1] - b[1]).abs() <= 1e-12 * a[1].abs().max(1.0), "reciprocity: {} against {}", a[1], b[1]);
        if a[1] * wo.z > 0.01 * peak {
            errs.extend((0..3).map(|k| (m[k] - a[k]).abs() / a[k]));
        }
    }
    errs.sort_by(f64::total_cmp);
    let (median, p95) = (errs[errs.len() / 2], errs[errs.len() * 95 / 100]);
    eprintln!("measured against analytic: {} values, median {median:.2e}, 95th percentile {p95:.2e}", errs.len());
    assert!(errs.len() > 500, "{} values above 1% of the peak", errs.len());
    assert!(median < 0.01 && p95 < 0.05, "median {median}, 95th percentile {p95}");
}

/// The pixels of a `.npy` image that `ndfit render` wrote (float32, C order).
fn read_npy(path: &std::path::Path) -> Vec<f32> {
    let b = std::fs::read(path).unwrap();
    let len = u16::from_le_bytes([b[8], b[9]]) as usize;
    b[10 + len..].chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect()
}

/// `ndfit render FIT --scene window` of a mirror answer is its parts: a `mirror` shows the light at its
/// radiance where its image falls (F = 1 for material none) and nothing far from it; a `mirror+ggx` whose
/// share is 0.7 at every incidence and wavelength is, pixel by pixel, 0.7 times that mirror's picture plus
/// 0.3 times the picture of its haze lobe alone (the render is linear in the BRDF).
#[test]
fn a_mirror_answer_renders_as_its_parts_in_the_window() {
    let dir = tempfile::tempdir().unwrap();
    let write = |name: &str, text: &str| {
        let p = dir.path().join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let shares: Vec<String> = [450.0, 550.0, 650.0]
        .iter()
        .flat_map(|nm| [0.0, 30.0, 45.0, 60.0, 75.0].map(|t| format!(r#"{{"theta_deg": {t}, "wavelength_nm": {nm}, "weight": 0.7}}"#)))
        .collect();
    let haze = r#"{"model": "ggx", "params": {"alpha": 0.08}}"#;
    let fit = |answer: &str| {
        format!(
            r#"{{"model": "ggx", "params": {{"alpha": 0.3}}, "selection": {{"answer": "{answer}"}}, "optics": {{"specular": [{}], "haze": {haze}}}}}"#,
            shares.join(", ")
        )
    };
    let render = |input: &std::path::Path, out: &str| {
        let o = dir.path().join(out);
        let st = std::process::Command::new(crate::common::ndfit_bin())
            .args(["render", input.to_str().unwrap(), "--scene", "window", "--size", "80", "-o", o.to_str().unwrap()])
            .output()
            .unwrap();
        assert!(st.status.success(), "{}", String::from_utf8_lossy(&st.stderr));
        read_npy(&o)
    };
    let mirror = render(&write("m.json", &fit("mirror")), "m.npy");
    let blend = render(&write("b.json", &fit("mirror+ggx")), "b.npy");
    let lobe = render(&write("h.json", haze), "h.npy");
    assert_eq!(mirror.len(), 80 * 48 * 3);
    // The image's centre reflects the light's centre; its corner sees the black room.
    let at = |img: &[f32], i: usize, j: usize| img[(j * 80 + i) * 3];
    assert_eq!((at(&mirror, 40, 24), at(&mirror, 1, 1)), (20.0, 0.0));
    // Each image refines its own pixels where its own values disagree, so the blend's quadrature is not
    // the parts' bit for bit: within 0.2% of the light's radiance.
    let worst = (0..mirror.len()).map(|k| (blend[k] - (0.7 * mirror[k] + 0.3 * lobe[k])).abs()).fold(0f32, f32::max);
    eprintln!("blend against its parts: worst {worst:.2e}");
    assert!(worst <= 0.002 * 20.0, "the blend is {worst} off its parts");
    let (sum_b, sum_p): (f64, f64) = (0..mirror.len())
        .map(|k| (blend[k] as f64, 0.7 * mirror[k] as f64 + 0.3 * lobe[k] as f64))
        .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    assert!((sum_b - sum_p).abs() < 1e-4 * sum_p, "{sum_b} against {sum_p}");
}

/// `--join` is for a wave BRDF's table: with a fit it is refused in one line naming the file, no image.
#[test]
fn join_is_refused_for_a_fit() {
    let dir = tempfile::tempdir().unwrap();
    let fit = dir.path().join("f.json");
    std::fs::write(&fit, r#"{"model": "ggx", "params": {"alpha": 0.1}}"#).unwrap();
    let out = dir.path().join("o.npy");
    let o = std::process::Command::new(crate::common::ndfit_bin())
        .args(["render", fit.to_str().unwrap(), "--join", fit.to_str().unwrap(), "-o", out.to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("--join is for a wave BRDF's table") && err.contains("f.json"), "{err}");
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(!out.exists());
}
