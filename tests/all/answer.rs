//! `auto`'s optics and mirror answers (`ndfit::answer`) against closed forms: a sinusoidal grating (the
//! mirror share J0^2, the haze at the first order's half vector), white Gaussian heights (the mean field of
//! a Gaussian), the wave engine's own specular on real scans (a second algorithm: FFT levels and a cubic
//! between them), and the answers the real scans must get. Every expected value is computed here.

use std::f64::consts::PI;

use ndfit::answer::{haze, optics, Regime};
use ndfit::synth::{gaussian_surface, GaussianParams, SynthSettings};
use ndfit::wave::{default_coherence_m, mirror_shares, wave, WaveOptions, DEFAULT_INCIDENCES_DEG, DEFAULT_WAVELENGTHS_NM};
use ndfit::{Heightfield, Options, Pipeline};

use crate::common::shared_scans;

/// `J_n(x)` by its power series (|x| < 2 here: 30 terms are exact to rounding).
fn bessel_j(n: u32, x: f64) -> f64 {
    let mut term = (x / 2.0).powi(n as i32) / (1..=n).map(f64::from).product::<f64>();
    let mut sum = term;
    for m in 1..30 {
        term *= -(x * x / 4.0) / (m as f64 * (m + n) as f64);
        sum += term;
    }
    sum
}

fn k_of(lambda_nm: f64) -> f64 {
    2.0 * PI / (lambda_nm * 1e-9)
}

/// `h = A sin(2 pi x / L)`, A = 20 nm, L = 5.12 um, 512 x 512 samples of 0.1 um.
fn grating() -> (Heightfield, f64, f64) {
    let (n, dx, a, l) = (512, 1e-7, 20e-9, 5.12e-6);
    let z: Vec<f64> = (0..n * n).map(|i| a * (2.0 * PI * ((i % n) as f64 * dx) / l).sin()).collect();
    (Heightfield::new(n, n, dx, dx, z).unwrap(), a, l)
}

/// White Gaussian heights of RMS `sigma` (Box-Muller on a fixed LCG), `n` x `n` samples of `dx`.
fn white(n: usize, dx: f64, sigma: f64, seed: u64) -> Heightfield {
    let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    let mut uniform = || {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((s >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let z = (0..n * n).map(|_| sigma * (-2.0 * uniform().ln()).sqrt() * (2.0 * PI * uniform()).cos()).collect();
    Heightfield::new(n, n, dx, dx, z).unwrap()
}

/// `sum u^2 / (sum u)^2` of a separable Hann-squared window of `p` x `p` samples.
fn window_floor(p: usize) -> f64 {
    let w: Vec<f64> = (0..p).map(|j| (PI * (j as f64 + 0.5) / p as f64).sin().powi(2)).collect();
    let (s2, s4) = (w.iter().map(|x| x * x).sum::<f64>(), w.iter().map(|x| x.powi(4)).sum::<f64>());
    (s4 / (s2 * s2)).powi(2)
}

#[test]
fn the_mirror_share_of_a_grating_is_j0_squared_at_every_incidence() {
    // Patches of exactly five periods: the Hann-squared window's few frequencies never meet the grating's,
    // so the weighted mean field is J0(v_z A) to rounding.
    let (hf, a, _) = grating();
    let m = mirror_shares(&hf, &DEFAULT_WAVELENGTHS_NM, &DEFAULT_INCIDENCES_DEG, 25.6e-6);
    assert_eq!((m.used, m.skipped, m.samples), (4, 0, [256, 256]));
    for (l, &lambda) in DEFAULT_WAVELENGTHS_NM.iter().enumerate() {
        for (t, &theta) in DEFAULT_INCIDENCES_DEG.iter().enumerate() {
            let want = bessel_j(0, 2.0 * k_of(lambda) * a * theta.to_radians().cos()).powi(2);
            assert!((m.share(l, t) - want).abs() < 1e-9, "{lambda} nm {theta} deg: {} against J0^2 {want}", m.share(l, t));
        }
    }
}

#[test]
fn a_gratings_haze_is_its_first_order_and_carries_the_rest_of_the_light() {
    // Normal incidence at 550 nm: the orders leave at sin t_m = m lambda / L; the first two hold 99% of
    // the diffuse light, so the median half vector is the first order's, tan(t_1 / 2).
    let (hf, a, l) = grating();
    let h = haze(&hf, &[25.6e-6]).unwrap();
    let j0 = bessel_j(0, 2.0 * k_of(550.0) * a).powi(2);
    assert!((h.albedo - (1.0 - j0)).abs() < 1e-3, "haze albedo {} against 1 - J0^2 = {}", h.albedo, 1.0 - j0);
    let want = ((550e-9 / l).asin() / 2.0).tan();
    assert!((h.params["alpha"] / want - 1.0).abs() < 1e-6, "haze alpha {} against tan(t_1 / 2) = {want}", h.params["alpha"]);
}

#[test]
fn white_gaussian_heights_give_the_gaussian_mean_field_and_their_regime() {
    // |chi|^2 of u-weighted iid Gaussian heights: exp(-v^2 s^2) (1 - f) + f, f = sum u^2 / (sum u)^2.
    let (n, dx) = (512, 0.5e-6);
    let p = (default_coherence_m() / dx).round() as usize;
    let f = window_floor(p);
    for (sigma, regime) in [(1e-9, Regime::Wave), (35e-9, Regime::Mixed)] {
        let hf = white(n, dx, sigma, 7);
        let m = mirror_shares(&hf, &DEFAULT_WAVELENGTHS_NM, &DEFAULT_INCIDENCES_DEG, default_coherence_m());
        assert_eq!(m.samples, [p, p]);
        assert!((m.incoherent_floor - f).abs() < 1e-12, "floor {} against {f}", m.incoherent_floor);
        for (l, &lambda) in DEFAULT_WAVELENGTHS_NM.iter().enumerate() {
            for (t, &theta) in DEFAULT_INCIDENCES_DEG.iter().enumerate() {
                let v = 2.0 * k_of(lambda) * theta.to_radians().cos();
                let want = (-(v * sigma).powi(2)).exp() * (1.0 - f) + f;
                assert!((m.share(l, t) - want).abs() < 0.01, "sigma {sigma}: {lambda} nm {theta} deg: {} against {want}", m.share(l, t));
            }
        }
        let o = optics(&hf);
        assert_eq!(o.regime, regime.as_str(), "sigma {sigma}: {}", o.why);
        assert_eq!(o.specular.len(), 15);
    }
}

#[test]
fn a_rough_surface_is_geometric_and_keeps_its_render_answer() {
    let s = SynthSettings { nx: 256, ny: 256, dx: 1e-6, dy: 1e-6, seed: 3, ..Default::default() };
    let hf = gaussian_surface(&s, &GaussianParams { sigma_x: 0.2, sigma_y: 0.2, theta_z: 0.0, corr_length: 8e-6 }).unwrap().0;
    let o = optics(&hf);
    assert_eq!(o.regime, "geometric", "{}", o.why);
    let out = Pipeline::new(Options::default()).run(hf, "rough").unwrap();
    let answer = out.fit.selection.as_ref().and_then(|s| s.answer.clone()).unwrap();
    assert!(!answer.contains("mirror"), "a rough surface answers {answer}");
    assert!(out.fit.selection.unwrap().render_error.is_some(), "the render choice ran");
    assert_eq!(out.fit.optics.unwrap().regime, "geometric");
}

/// Where light sees a mirror the ladder only describes the slopes: its one-lobe rungs are fitted, each the
/// same fit, bit for bit, as in the whole ladder on the same NDF, and the two-lobe models are listed as
/// not fitted, and why.
#[test]
fn a_mirror_fits_the_ladders_one_lobe_rungs_alone() {
    use ndfit::models::ModelId;
    let options = Options::default();
    let out = Pipeline::new(options.clone()).run(white(256, 0.5e-6, 1e-10, 2), "polished").unwrap();
    let sel = out.fit.selection.as_ref().unwrap();
    assert_eq!(sel.answer.as_deref(), Some("mirror"));
    let two: Vec<ModelId> = ModelId::EVERY.iter().copied().filter(|id| id.spec().in_auto && id.spec().is_mixture()).collect();
    assert_eq!(two.len(), 3);
    for id in &two {
        assert!(sel.not_fitted.contains(id) && sel.candidates.iter().all(|c| c.model != *id), "{id}: {:?}", sel.not_fitted);
    }
    assert!(sel.ladder.as_deref().unwrap().contains("light sees a mirror"), "{:?}", sel.ladder);
    let whole = ndfit::fit::fit_auto_pruned(&out.ndf, &options.fit_options(), false).unwrap();
    let whole = whole.selection.unwrap();
    assert!(sel.candidates.len() >= 2);
    for c in &sel.candidates {
        let w = whole.candidates.iter().find(|w| w.model == c.model).unwrap_or_else(|| panic!("{} not in the whole ladder", c.model));
        assert_eq!((&c.params, c.objective_value.to_bits()), (&w.params, w.objective_value.to_bits()), "{}", c.model);
    }
}

#[test]
fn polished_scans_answer_a_mirror_never_an_error() {
    // Gaussian heights of 0.03 and 0.1 nm RMS at 0.5 um spacing, and a flat scan with one 1 um spike.
    let mut spike = vec![0.0; 256 * 256];
    spike[100 * 256 + 150] = 1e-6;
    let scans = [
        ("3e-11", white(256, 0.5e-6, 3e-11, 1)),
        ("1e-10", white(256, 0.5e-6, 1e-10, 2)),
        ("spike", Heightfield::new(256, 256, 0.5e-6, 0.5e-6, spike).unwrap()),
    ];
    for (name, hf) in scans {
        let out = Pipeline::new(Options::default()).run(hf, name).unwrap_or_else(|e| panic!("{name}: {}", e.message()));
        let sel = out.fit.selection.as_ref().unwrap();
        assert_eq!(sel.answer.as_deref(), Some("mirror"), "{name}");
        assert_eq!(out.fit.quality.verdict, ndfit::fit::Verdict::Ok, "{name}");
        let o = out.fit.optics.as_ref().unwrap();
        assert_eq!(o.regime, "wave", "{name}: {}", o.why);
        assert!(o.specular.iter().all(|s| s.weight > 0.99), "{name}: {:?}", o.specular);
    }
}

#[test]
fn a_scan_too_thin_for_the_wave_haze_takes_the_slopes_lobe_for_the_light_its_mirror_leaves() {
    // Three rows of white Gaussian heights, 0.1 um RMS at 0.1 um: a mirror only toward grazing (mixed), and
    // too thin (3 < 4 samples) for the diffuse wave BRDF. The mirror keeps exp(-(2 k sigma cos t)^2) of the
    // light (Beckmann-Kirchhoff); the rest must go to a haze, not vanish.
    let sq = white(256, 1e-7, 1e-7, 5);
    let z: Vec<f64> = (0..3 * 256).map(|i| sq.z[i]).collect();
    let hf = Heightfield::new(256, 3, 1e-7, 1e-7, z).unwrap();
    let mean = hf.z.iter().sum::<f64>() / hf.z.len() as f64;
    let sigma = (hf.z.iter().map(|h| (h - mean).powi(2)).sum::<f64>() / hf.z.len() as f64).sqrt();
    let out = Pipeline::new(Options::default()).run(hf, "thin").unwrap();
    let (fit, sel) = (&out.fit, out.fit.selection.as_ref().unwrap());
    let o = fit.optics.as_ref().unwrap();
    assert_eq!(o.regime, "mixed", "{}", o.why);
    assert!(o.note.as_deref().is_some_and(|n| n.contains("could not be computed") && n.contains("ladder's ggx")), "{:?}", o.note);
    assert_eq!(sel.answer.as_deref(), Some("mirror+ggx"));
    let haze = o.haze.as_ref().expect("a haze");
    let ggx = sel.candidates.iter().find(|c| c.model == ndfit::models::ModelId::Ggx).expect("the ladder's ggx");
    assert_eq!(haze.params["alpha"].to_bits(), ggx.params["alpha"].to_bits());
    // One patch of 256 x 3 samples under the Hann-squared window: |mean field|^2 has an incoherent floor f
    // (the window's sum u^2 / (sum u)^2 per axis), about which it scatters by about f.
    let axis = |p: usize| {
        let w: Vec<f64> = (0..p).map(|j| (PI * (j as f64 + 0.5) / p as f64).sin().powi(2)).collect();
        w.iter().map(|x| x.powi(4)).sum::<f64>() / w.iter().map(|x| x * x).sum::<f64>().powi(2)
    };
    let f = axis(256) * axis(3);
    let mean_field = (-(2.0 * k_of(550.0) * sigma).powi(2)).exp();
    let kirchhoff = 1.0 - (mean_field * (1.0 - f) + f);
    assert!(
        (haze.albedo - kirchhoff).abs() < 2.0 * f,
        "haze carries {} where Beckmann-Kirchhoff leaves {kirchhoff} (floor {f})",
        haze.albedo
    );
}

#[test]
fn real_scans_regimes_and_mirror_answers_needs_shared() {
    const TEST: &str = "real_scans_regimes_and_mirror_answers_needs_shared";
    let Some(dir) = shared_scans(TEST) else { return };
    // The near-mirrors: a mirror term of at least 0.8 at normal incidence and 550 nm.
    for name in ["st_metropro-1.dat", "st_opd-1.opd", "st_plu-1.plu", "st_sur-2.sur"] {
        let out = Pipeline::new(Options::default()).run_path(&dir.join(name)).unwrap();
        let answer = out.fit.selection.as_ref().and_then(|s| s.answer.clone()).unwrap();
        assert!(answer.starts_with("mirror"), "{name} answers {answer}");
        let o = out.fit.optics.as_ref().unwrap();
        assert_eq!(o.regime, "wave", "{name}: {}", o.why);
        let s0 = o.specular.iter().find(|s| s.theta_deg == 0.0 && s.wavelength_nm == 550.0).unwrap().weight;
        assert!(s0 >= 0.8, "{name}: mirror share {s0} at 0 deg");
    }
    // st_x3p-2: a mirror term with a share at 60 degrees in [0.35, 0.85].
    let out = Pipeline::new(Options::default()).run_path(&dir.join("st_x3p-2.x3p")).unwrap();
    assert!(out.fit.selection.as_ref().and_then(|s| s.answer.clone()).unwrap().contains("mirror"));
    let o = out.fit.optics.unwrap();
    let s60 = o.specular.iter().find(|s| s.theta_deg == 60.0 && s.wavelength_nm == 550.0).unwrap().weight;
    assert!((0.35..=0.85).contains(&s60), "st_x3p-2: share {s60} at 60 deg");
    // The rough scans: geometric optics (their answers stay the render choice's).
    for name in [
        "hamby44_Unknown-Bullet_E-Land_1.x3p",
        "hamby44_downsampled_Barrel_1-Bullet_1-Land_1.x3p",
        "houston_HFSCP-BA-B11-L1.x3p",
        "x3ptools_sample-land.x3p",
        "surfalize_test_1.opd",
        "surfalize_test_1.plu",
        "st_al3d-1.al3d",
        "st_tmd-1_dime.tmd",
    ] {
        let hf = ndfit::pipeline::read_preprocessed(&dir.join(name), &Default::default(), &Default::default()).unwrap();
        let o = optics(&hf);
        assert_eq!(o.regime, "geometric", "{name}: {}", o.why);
    }
}

#[test]
fn the_optics_share_is_the_wave_engines_specular_needs_shared() {
    const TEST: &str = "the_optics_share_is_the_wave_engines_specular_needs_shared";
    // A second algorithm: the wave engine's FFT levels read by a cubic in ln v_z, at the same patches.
    let Some(dir) = shared_scans(TEST) else { return };
    for name in ["st_plu-1.plu", "st_x3p-2.x3p"] {
        let hf = ndfit::pipeline::read_preprocessed(&dir.join(name), &Default::default(), &Default::default()).unwrap();
        let opts = WaveOptions::default();
        let (report, _) = wave(&hf, &opts, None).unwrap();
        let o = optics(&hf);
        for r in &report.records {
            let s = o.specular.iter().find(|s| s.theta_deg == r.theta_deg && s.wavelength_nm == r.wavelength_nm).unwrap();
            assert!(
                (s.weight - r.specular).abs() < 2e-3,
                "{name} {} nm {} deg: {} against the engine's {}",
                r.wavelength_nm,
                r.theta_deg,
                s.weight,
                r.specular
            );
        }
    }
}

/// The glow around a polished scan's mirror image is the haze the wave module predicts, not a pure
/// mirror's darkness: in the window scene (a plate near grazing under a sharp-edged light, black room),
/// each near-mirror scan's `mirror+ggx` answer (`ndfit fit --model auto`) renders closer, by HDR-FLIP over the
/// plate, to the wave prediction (`ndfit wave --to rgl`: its diffuse table and its mirror share) than the
/// same mirror without its haze does; and the wave table renders its mirror's sharp image.
#[test]
fn mirror_answers_render_toward_the_wave_prediction_needs_shared() {
    use ndfit::answer::choice::flip_mean;
    use ndfit::export::rgl::{Material, TensorFile};
    use ndfit::export::{MirrorAnswer, MirrorBrdf};
    use ndfit::render::{Stage, Window};
    const TEST: &str = "mirror_answers_render_toward_the_wave_prediction_needs_shared";
    let Some(dir) = shared_scans(TEST) else { return };
    let tmp = tempfile::tempdir().unwrap();
    let scene = Stage::Window(Window::default());
    let run = |args: &[&str]| {
        let o = std::process::Command::new(crate::common::ndfit_bin()).args(args).output().unwrap();
        assert!(o.status.success(), "ndfit {args:?}: {}", String::from_utf8_lossy(&o.stderr));
    };
    for name in ["st_opd-1.opd", "st_plu-1.plu", "st_sur-2.sur"] {
        let scan = dir.join(name);
        let (fit, table) = (tmp.path().join(format!("{name}.json")), tmp.path().join(format!("{name}.bsdf")));
        run(&["fit", scan.to_str().unwrap(), "--model", "auto", "-o", fit.to_str().unwrap()]);
        run(&["wave", scan.to_str().unwrap(), "--to", "rgl", "-o", table.to_str().unwrap(), "--quiet"]);
        let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&fit).unwrap()).unwrap();
        let answer = MirrorAnswer::from_json(&json).unwrap().unwrap();
        assert_eq!(answer.answer, "mirror+ggx", "{name}");
        let bare = MirrorAnswer { answer: "mirror".into(), haze: None, ..answer.clone() };
        // Both sides with the conductor of the wave table (material none by default: F = 1).
        let wave = MirrorBrdf::wave(&TensorFile::parse(&std::fs::read(&table).unwrap()).unwrap(), Material::None).unwrap();
        let reference = scene.render(&wave).unwrap();
        let with_haze = flip_mean(&reference, &scene.render(&MirrorBrdf::new(&answer, Material::None)).unwrap()).unwrap();
        let mirror = flip_mean(&reference, &scene.render(&MirrorBrdf::new(&bare, Material::None)).unwrap()).unwrap();
        eprintln!("{name}: FLIP against the wave prediction: the answer {with_haze:.4}, its mirror alone {mirror:.4}");
        assert!(with_haze < 0.8 * mirror, "{name}: the haze does not bring the answer toward the wave prediction");
        // The light's sharp image: the centre reflects the light's centre at nearly its radiance.
        let c = reference.get(reference.width / 2, reference.height / 2)[1];
        assert!(c > 0.95 * 20.0, "{name}: the wave prediction's mirror image is {c} at the centre");
    }
}

/// The reference of a surface whose regime changes with the angle (Gaussian heights, RMS slope 0.075, 2 um
/// correlation length: a mirror share of 0.03 at normal incidence and 0.69 at 75 degrees, at 550 nm): its
/// wave prediction and its geometric table joined by incidence (`ndfit render WAVE --join GEOMETRIC`,
/// `MirrorBrdf::joined`). Where the wave's share is below 0.05 in every channel (0-10 deg here) the
/// reference is the geometric table, bit for bit; from 0.5 (70-75 deg) it is the wave prediction, mirror
/// included; between, the join is continuous in energy: the albedo (mirror included) by incidence never
/// leaves the span of the two predictions' albedos by more than a quadrature's error, and the two agree
/// within 3% where they meet (Kirchhoff's total reflectance and geometric optics' on the same heights).
/// The shares the join reads from the wave table are the optics' own (a second algorithm) at 0-75 deg.
#[test]
fn a_mixed_regimes_reference_joins_wave_and_geometric_by_incidence() {
    use ndfit::export::rgl::{Material, TensorFile};
    use ndfit::export::MirrorBrdf;
    use ndfit::render::{direction, Brdf};
    let tmp = tempfile::tempdir().unwrap();
    let p = |n: &str| tmp.path().join(n).to_str().unwrap().to_string();
    let run = |args: &[&str]| {
        let o = std::process::Command::new(crate::common::ndfit_bin()).args(args).output().unwrap();
        assert!(o.status.success(), "ndfit {args:?}: {}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let scan = p("mixed.x3p");
    run(&[
        "synth",
        &scan,
        "--surface",
        "gaussian",
        "--nx",
        "512",
        "--ny",
        "512",
        "--dx",
        "2.5e-7",
        "--sigma-x",
        "0.075",
        "--corr-length",
        "2e-6",
    ]);
    let said = run(&["fit", &scan, "--model", "auto", "-o", &p("fit.json")]);
    assert!(said.contains("optics mixed"), "{said}");
    run(&["wave", &scan, "--to", "rgl", "-o", &p("w.bsdf"), "--quiet"]);
    run(&["export", &scan, "--to", "rgl", "--material", "none", "-o", &p("g.bsdf")]);
    let read = |n: &str| TensorFile::parse(&std::fs::read(p(n)).unwrap()).unwrap();
    let (wt, gt) = (read("w.bsdf"), read("g.bsdf"));
    let ramp = [ndfit::answer::GEOMETRIC_SHARE, ndfit::answer::MIRROR_SHARE];
    let joined = MirrorBrdf::joined(&wt, &gt, Material::None, ramp).unwrap();
    let wave = MirrorBrdf::wave(&wt, Material::None).unwrap();
    let geometric = ndfit::export::rgl::Measured::new(&gt).unwrap();
    // The albedo by a cosine-weighted midpoint rule (n x 4n cells in cos^2 theta_o and phi_o), mirror included.
    let albedo = |b: &dyn Brdf, wi: nalgebra::Vector3<f64>| {
        let n = 150;
        let mut acc = 0.0;
        for a in 0..n {
            let mu = ((a as f64 + 0.5) / n as f64).sqrt();
            for k in 0..4 * n {
                let phi = 2.0 * PI * (k as f64 + 0.5) / (4 * n) as f64;
                acc += b.eval(wi, direction(mu.acos(), phi))[1];
            }
        }
        PI * acc / (4 * n * n) as f64 + b.mirror(wi)[1]
    };
    // The share's extremes over the RGB channels (a longer wavelength sees a smoother surface).
    let share = |t: f64| [0, 1, 2].map(|c| joined.share(c, t));
    // The wave table's shares (its engine, read by incidence) against the fit's optics (a second algorithm)
    // at 550 nm; the green channel is 549 nm.
    let fit: serde_json::Value = serde_json::from_slice(&std::fs::read(p("fit.json")).unwrap()).unwrap();
    for s in fit["optics"]["specular"].as_array().unwrap().iter().filter(|s| s["wavelength_nm"] == 550.0) {
        let (t, want) = (s["theta_deg"].as_f64().unwrap(), s["weight"].as_f64().unwrap());
        assert!((share(t)[1] - want).abs() < 0.02, "{t} deg: the table's share {} against the optics' {want}", share(t)[1]);
    }
    // `ndfit render` finds the wave table's conductor and joins it as the library does.
    run(&["render", &p("w.bsdf"), "--join", &p("g.bsdf"), "--scene", "window", "--size", "40", "-o", &p("j.npy")]);
    let bytes = std::fs::read(p("j.npy")).unwrap();
    let header = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
    let cli: Vec<f32> = bytes[10 + header..].chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap())).collect();
    let scene = ndfit::render::Window { width: 40, height: 24, ..Default::default() };
    let lib = scene.render_set(&[&joined as &dyn Brdf]).unwrap()[0].data.iter().flatten().copied().collect::<Vec<f32>>();
    assert_eq!(cli, lib);
    let mut seen = [false; 3];
    for t in [0.0, 10.0, 20.0, 30.0, 40.0, 50.0, 55.0, 60.0, 65.0, 70.0, 75.0] {
        let wi = direction(f64::to_radians(t), 0.3);
        let (s, aj, aw, ag) = (share(t), albedo(&joined, wi), albedo(&wave, wi), albedo(&geometric, wi));
        let (lo, hi) = (s.iter().copied().fold(1.0, f64::min), s.iter().copied().fold(0.0, f64::max));
        eprintln!("{t:>4} deg: share {:.3} (RGB {lo:.3}-{hi:.3}); albedo joined {aj:.4}, wave {aw:.4}, geometric {ag:.4}", s[1]);
        let wo = direction(f64::to_radians(t + 3.0), 0.3 + PI);
        if hi < ramp[0] {
            assert_eq!((joined.eval(wi, wo), joined.mirror(wi)[1]), (geometric.eval(wi, wo), 0.0), "{t} deg");
            seen[0] = true;
        } else if lo >= ramp[1] {
            assert_eq!((joined.eval(wi, wo), joined.mirror(wi)), (wave.eval(wi, wo), wave.mirror(wi)), "{t} deg");
            seen[2] = true;
        } else {
            seen[1] = true;
            assert!((aw - ag).abs() < 0.03, "{t} deg: the predictions meet at {aw:.4} and {ag:.4}");
        }
        assert!(aj >= aw.min(ag) - 2e-3 && aj <= aw.max(ag) + 2e-3, "{t} deg: joined {aj} outside [{aw}, {ag}]");
    }
    assert_eq!(seen, [true; 3], "the surface's regime must change with the angle");
}

/// The haze is kept from the share at which the broad scene shows it: a smooth conductor whose GGX haze
/// carries a quarter less than `haze_visible(alpha)` renders within the render tolerance of the mirror
/// alone there, one a third more beyond it (the renders are the check of the table, at its nodes and
/// between them).
#[test]
fn a_haze_is_kept_from_the_share_the_broad_scene_shows() {
    use ndfit::answer::choice::{flip_mean, DEFAULT_RENDER_TOLERANCE};
    use ndfit::answer::haze_visible;
    use ndfit::export::rgl::Material;
    use ndfit::export::{MirrorAnswer, MirrorBrdf, Share};
    use ndfit::models::{Ggx, Model};
    use ndfit::render::Scene;
    let broad = Scene::broad();
    let mirror =
        broad.render(&MirrorBrdf::new(&MirrorAnswer { answer: "mirror".into(), specular: Vec::new(), haze: None }, Material::Al)).unwrap();
    let score = |alpha: f64, a: f64| {
        let specular = [450.0, 550.0, 650.0]
            .iter()
            .flat_map(|&wavelength_nm| [0.0, 30.0, 45.0, 60.0, 75.0].map(|theta_deg| Share { theta_deg, wavelength_nm, weight: 1.0 - a }))
            .collect();
        let haze = Some(Model::Ggx(Ggx::new(alpha, alpha, 0.0).unwrap()));
        let answer = MirrorAnswer { answer: "mirror+ggx".into(), specular, haze };
        flip_mean(&broad.render(&MirrorBrdf::new(&answer, Material::Al)).unwrap(), &mirror).unwrap()
    };
    for alpha in [0.005, 0.015, 0.03, 0.07, 0.3] {
        let a = haze_visible(alpha);
        let (below, above) = (score(alpha, 0.75 * a), score(alpha, 1.33 * a));
        eprintln!("alpha {alpha}: seen from {a:.3e}; FLIP {below:.4} at 0.75x, {above:.4} at 1.33x");
        assert!(below < DEFAULT_RENDER_TOLERANCE && above > DEFAULT_RENDER_TOLERANCE, "alpha {alpha}: {below} / {above} around {a}");
    }
    // Held beyond the table's ends, and no NaN.
    assert_eq!(haze_visible(1e-4), haze_visible(0.003));
    assert_eq!(haze_visible(5.0), haze_visible(1.0));
    assert!(haze_visible(f64::NAN).is_finite());
}
