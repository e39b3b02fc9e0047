//! The two-lobe mixtures (`ggx2`, `beckmann2`, `ellipsoid+ggx`): recovery of known two-lobe truths (heightfields
//! built of two ellipsoid caps, whose NDF is exactly the area-weighted mixture of two ellipsoid NDFs;
//! Poisson counts of a Beckmann mixture), and the one-or-two-lobe ladder of `--model auto`.

use nalgebra::Vector3;
use ndfit::fit::{fit_auto, fit_model, FitOptions};
use ndfit::models::{Model, ModelId};
use ndfit::ndf::{empirical_ndf, NdfOptions};
use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};
use ndfit::Heightfield;

use rand::{RngExt, SeedableRng};

use super::fixtures::{delta_to_truth, model};

/// A lobe to draw facet slopes from.
// Two values per test case: their size does not matter.
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy)]
enum Draw {
    /// GTR2aniso `(alpha_x, alpha_y, theta_z)`, drawn here from its slope distribution (Heitz eq. 84-85:
    /// the stretched unit GGX, whose radial slope has `P(|s| < R) = R^2 / (1 + R^2)`).
    Ggx(f64, f64, f64),
    /// Any ellipsoid special case, drawn by the models' exact visible-normal sampler with `u = n`, whose
    /// density is `D(m) (m.n)` (Walter et al. sec. 4.1; chi-square tested in models/sampling.rs).
    Sampler(Model),
}

impl Draw {
    /// The slope `(dh/dx, dh/dy)` for the point `(u1, u2)` of the unit square.
    fn slope(&self, u1: f64, u2: f64) -> (f64, f64) {
        match *self {
            Draw::Ggx(ax, ay, tz) => {
                let r = (u1 / (1.0 - u1)).sqrt();
                let phi = 2.0 * std::f64::consts::PI * u2;
                // Local slopes, then back to the scan frame: the local frame is s' = Rz(theta_z) s.
                let (lx, ly) = (ax * r * phi.cos(), ay * r * phi.sin());
                let (sn, c) = tz.sin_cos();
                (c * lx + sn * ly, -sn * lx + c * ly)
            }
            Draw::Sampler(m) => {
                let n = m.sample_visible_normal(Vector3::z(), [u1, u2]).expect("an ellipsoid special case");
                (-n.x / n.z, -n.y / n.z)
            }
        }
    }
}

/// A heightfield of `n` plane facets of 2 x 2 points, each followed by a row and a column of NaN, so that
/// the `triangles` scheme sees every facet as two triangles with its exact normal and no triangle spans
/// two facets. The first `round(w n)` facets draw their slopes from `first`, the rest from `second`, each
/// by the R2 low-discrepancy sequence when `exact` (so the empirical NDF is the mixture
/// `w D1 + (1 - w) D2` with almost no sampling noise), else by a seeded generator (the counts of a random
/// surface), placed in a seeded random order (so the two triangles of a facet are the only correlated
/// normals: the data's overdispersion is about 2).
fn facet_mixture(first: Draw, second: Draw, w: f64, n: usize, exact: bool) -> Heightfield {
    let g = 1.324_717_957_244_746_f64;
    let (a1, a2) = (1.0 / g, 1.0 / (g * g));
    let n1 = (w * n as f64).round() as usize;
    let mut draw = rand::rngs::StdRng::seed_from_u64(5);
    let mut slopes: Vec<(f64, f64)> = (0..n)
        .map(|k| {
            let (lobe, j) = if k < n1 { (first, k) } else { (second, k - n1) };
            let (u1, u2) = if exact {
                ((0.5 + j as f64 * a1).fract(), (0.5 + j as f64 * a2).fract())
            } else {
                (draw.random_range(0.0..1.0), draw.random_range(0.0..1.0))
            };
            lobe.slope(u1, u2)
        })
        .collect();
    let mut rng = rand::rngs::StdRng::seed_from_u64(17);
    for i in (1..slopes.len()).rev() {
        slopes.swap(i, rng.random_range(0..=i));
    }
    let side = (n as f64).sqrt().ceil() as usize;
    let (nx, ny) = (3 * side, 3 * side);
    let dx = 1e-6;
    let mut z = vec![f64::NAN; nx * ny];
    for (k, &(p, q)) in slopes.iter().enumerate() {
        let (bi, bj) = (3 * (k / side), 3 * (k % side));
        for (di, dj) in [(0, 0), (0, 1), (1, 0), (1, 1)] {
            z[(bi + di) * nx + bj + dj] = p * dj as f64 * dx + q * di as f64 * dx;
        }
    }
    Heightfield::new(nx, ny, dx, dx, z).expect("heightfield")
}

/// A mixture fitted to an exact two-lobe heightfield is within 0.5% of the truth in NDF, and `auto`, on
/// the same lobes drawn at random (the counts a real surface gives; the exact draws leave a quarter of the
/// Poisson noise that `auto`'s floor assumes, and would hide a tail), takes two lobes within 1% of the
/// truth where the tail holds a fifth or more, and keeps one lobe only within the tolerance. Tail weights 0.05, 0.2 and 0.5; anisotropic GGX pairs sharing their frame and a skewed
/// ellipsoid core with a round GGX tail.
#[test]
fn two_lobe_heightfields_recover_the_mixture_and_auto_takes_two_lobes() {
    let tri = NdfOptions { scheme: ndfit::ndf::NormalScheme::Triangles, cells_across: Some(255), ..NdfOptions::default() };
    let skewed = model(ModelId::Ellipsoid, &[0.12, 0.07, 0.1, -0.08, 0.5]);
    let cases: [(ModelId, Draw, Draw, f64, Vec<f64>); 4] = [
        (ModelId::Ggx2, Draw::Ggx(0.1, 0.06, 0.3), Draw::Ggx(0.4, 0.25, 0.3), 0.95, vec![0.1, 0.06, 0.4, 0.25, 0.3, 0.95]),
        (ModelId::Ggx2, Draw::Ggx(0.08, 0.08, 0.0), Draw::Ggx(0.3, 0.3, 0.0), 0.8, vec![0.08, 0.08, 0.3, 0.3, 0.0, 0.8]),
        (ModelId::Ggx2, Draw::Ggx(0.15, 0.05, -0.6), Draw::Ggx(0.5, 0.2, -0.6), 0.5, vec![0.15, 0.05, 0.5, 0.2, -0.6, 0.5]),
        (ModelId::EllipsoidGgx, Draw::Sampler(skewed), Draw::Ggx(0.45, 0.45, 0.0), 0.7, vec![0.12, 0.07, 0.1, -0.08, 0.5, 0.45, 0.7]),
    ];
    for (id, first, second, w, p) in cases {
        let truth = model(id, &p);
        let hf = facet_mixture(first, second, w, 250_000, true);
        let ndf = empirical_ndf(&hf, &tri).expect("ndf");
        let rep = fit_model(&ndf, id, &FitOptions::default()).expect("fit");
        let d = delta_to_truth(&rep.to_model().expect("model"), &truth);
        eprintln!(
            "{id} tail weight {:.2}: fit {:?} truth {:?} delta {d:.2e} dispersion {:?}",
            1.0 - w,
            rep.param_vec(),
            truth.canonical().params(),
            rep.quality.dispersion
        );
        assert!(d <= 0.005, "{id} tail weight {:.2}: delta {d}", 1.0 - w);
        let user = empirical_ndf(&facet_mixture(first, second, w, 250_000, false), &NdfOptions { cells_across: None, ..tri }).expect("ndf");
        let auto = fit_auto(&user, &FitOptions::default()).expect("auto");
        let sel = auto.selection.as_ref().expect("selection");
        let da = delta_to_truth(&auto.to_model().expect("model"), &truth);
        eprintln!("{id} tail weight {:.2}: auto chose {} at {da:.4} from the truth ({:?})", 1.0 - w, auto.model, sel.ladder);
        // A tail of a fifth or more takes a second lobe; one lobe is kept only within the tolerance of the truth.
        if 1.0 - w >= 0.2 {
            assert!(auto.model.is_mixture(), "{id} tail weight {:.2}: auto chose {} ({:?})", 1.0 - w, auto.model, sel.ladder);
        }
        let bar = if auto.model.is_mixture() { 0.01 } else { ndfit::fit::DEFAULT_TOLERANCE };
        assert!(da <= bar, "{id}: auto's {} is {da} from the truth", auto.model);
    }
}

/// Poisson counts of a Beckmann mixture (no heightfield has a Beckmann mixture NDF exactly): `beckmann2`
/// recovers it within 0.5%, `auto` takes two lobes.
#[test]
fn beckmann_mixture_counts_recover_the_truth() {
    let truth = model(ModelId::Beckmann2, &[0.08, 0.05, 0.35, 0.25, 0.4, 0.8]);
    let ndf = super::fixtures::ndf_of(&truth, 1e6, 21);
    let rep = fit_model(&ndf, ModelId::Beckmann2, &FitOptions::default()).expect("fit");
    let d = delta_to_truth(&rep.to_model().expect("model"), &truth);
    eprintln!("beckmann2: fit {:?} delta {d:.2e}", rep.param_vec());
    assert!(d <= 0.005, "delta {d}");
    let auto = fit_auto(&ndf, &FitOptions::default()).expect("auto");
    assert!(auto.model.is_mixture(), "auto chose {}", auto.model);
}

/// Single-lobe truths keep a single lobe under `auto`: ellipsoid caps (round, strongly anisotropic,
/// skewed) and Poisson counts of strongly anisotropic GGX and Beckmann lobes.
#[test]
fn single_lobe_truths_keep_one_lobe() {
    for p in [[0.2, 0.2, 0.0, 0.0, 0.0], [0.4, 0.04, 0.0, 0.0, 0.7], [0.25, 0.1, 0.2, -0.15, 0.3]] {
        let ep =
            EllipsoidParams { alpha_x: p[0], alpha_y: p[1], theta_x: p[2], theta_y: p[3], theta_z: p[4], ..EllipsoidParams::default() };
        let (hf, _) = ellipsoid_surface(&SynthSettings { nx: 512, ny: 512, seed: 3, ..SynthSettings::default() }, &ep).expect("synth");
        let ndf = empirical_ndf(&hf, &NdfOptions::default()).expect("ndf");
        let auto = fit_auto(&ndf, &FitOptions::default()).expect("auto");
        let sel = auto.selection.as_ref().expect("selection");
        assert!(!auto.model.is_mixture(), "cap {p:?}: auto chose {} ({:?})", auto.model, sel.ladder);
    }
    for (id, p) in [(ModelId::GgxAniso, [0.3, 0.02, 0.4]), (ModelId::BeckmannAniso, [0.25, 0.03, -0.9])] {
        let truth = model(id, &p);
        let ndf = super::fixtures::ndf_of(&truth, 1e6, 22);
        let auto = fit_auto(&ndf, &FitOptions::default()).expect("auto");
        let sel = auto.selection.as_ref().expect("selection");
        assert!(!auto.model.is_mixture(), "{id} {p:?}: auto chose {} ({:?})", auto.model, sel.ladder);
    }
}

/// The same choice, model and parameters, fitting the ladder lazily or every rung; returns whether the
/// lazy ladder left a model out.
fn same_choice_lazy_or_not(ndf: &ndfit::ndf::EmpiricalNdf, what: &str) -> bool {
    let opts = FitOptions::default();
    let t0 = std::time::Instant::now();
    let full = ndfit::fit::fit_auto_pruned(ndf, &opts, false).expect("auto");
    let lean = ndfit::fit::fit_auto_pruned(ndf, &opts, true).expect("auto");
    let (sf, sl) = (full.selection.as_ref().expect("selection"), lean.selection.as_ref().expect("selection"));
    eprintln!("{what}: {} / {}: {:?} ({:.1} s)", full.model, lean.model, sl.ladder, t0.elapsed().as_secs_f64());
    assert_eq!(full.model, lean.model, "{what}: laziness changed the choice ({:?} / {:?})", sf.ladder, sl.ladder);
    assert_eq!(full.param_vec(), lean.param_vec(), "{what}: laziness changed the chosen parameters");
    // Every candidate that is fitted both ways is the same fit; the ones left out are the only ones missing.
    for c in &sl.candidates {
        let f = sf.candidates.iter().find(|d| d.model == c.model).expect("a lazy run lists no new candidate");
        assert_eq!(f.objective_value, c.objective_value, "{what}: {}", c.model);
    }
    assert!(sf.not_fitted.is_empty(), "{what}: the full ladder left {:?} out", sf.not_fitted);
    assert_eq!(sl.candidates.len() + sl.not_fitted.len(), sf.candidates.len(), "{what}: every model is fitted or listed as not");
    sl.candidates.len() < sf.candidates.len()
}

/// The lazy ladder (a rung is fitted only while no model below it is within the tolerance) never changes
/// `auto`'s choice: on single-lobe and two-lobe Poisson counts of a handful of normals and of many, and
/// on the shared real scans; on the single lobes of many normals it leaves the mixtures out.
#[test]
fn lazy_ladder_chooses_as_the_full_one_needs_shared() {
    let mut lazy = 0;
    let truths = [
        model(ModelId::GgxAniso, &[0.3, 0.02, 0.4]),
        model(ModelId::Ellipsoid, &[0.2, 0.1, 0.1, -0.05, 0.3]),
        model(ModelId::Beckmann2, &[0.08, 0.05, 0.35, 0.25, 0.4, 0.8]),
    ];
    for (i, truth) in truths.iter().enumerate() {
        for n in [25.0, 1e5] {
            let ndf = super::fixtures::ndf_on(truth, 48, n, 30 + i as u64);
            lazy += same_choice_lazy_or_not(&ndf, &format!("{} N={n}", truth.id())) as usize;
        }
    }
    assert!(lazy > 0, "the lazy ladder left nothing out: the test would not see a wrong stop");
    let Some(dir) = crate::common::shared_scans("lazy_ladder_chooses_as_the_full_one_needs_shared") else { return };
    for name in ["houston_HFSCP-BA-B11-L1.x3p", "st_opd-1.opd"] {
        let (_, ndf) = ndfit::Pipeline::default().ndf_path(&dir.join(name)).expect("shared scans are readable");
        same_choice_lazy_or_not(&ndf, name);
    }
}

/// A ridge (a lobe narrow across one axis, as a quantized or striated scan makes) under a wider lobe:
/// Poisson counts of that `ggx2` truth, fitted as `ggx2`, give the truth's NDF within 0.5% (its ridge
/// start, a lobe at the alpha floor across an axis of the one-lobe fit, is where the fit comes from).
#[test]
fn ggx2_recovers_a_ridge_over_a_wide_lobe() {
    let truth = model(ModelId::Ggx2, &[0.12, 0.004, 0.1, 0.07, 0.3, 0.25]);
    let ndf = super::fixtures::ndf_of(&truth, 1e6, 23);
    let rep = fit_model(&ndf, ModelId::Ggx2, &FitOptions::default()).expect("fit");
    let d = delta_to_truth(&rep.to_model().expect("model"), &truth);
    eprintln!("ggx2 ridge: fit {:?} delta {d:.2e}", rep.param_vec());
    assert!(d <= 0.005, "delta {d}: {:?}", rep.param_vec());
}

/// Counts of one GGX lobe: no second lobe removes the price of its three parameters, `3 ln N`, so `ggx2`
/// is reported as the `ggx-aniso` fit (the same lobe twice at weight 1/2, said so in a warning), which is
/// within 0.5% of the truth.
#[test]
fn ggx2_of_one_lobe_is_its_parent() {
    let truth = model(ModelId::GgxAniso, &[0.3, 0.1, 0.4]);
    let ndf = super::fixtures::ndf_of(&truth, 1e5, 24);
    let opts = FitOptions::default();
    let one = fit_model(&ndf, ModelId::GgxAniso, &opts).expect("fit");
    let two = fit_model(&ndf, ModelId::Ggx2, &opts).expect("fit");
    let (p, q) = (one.param_vec(), two.param_vec());
    assert_eq!(q[5], 0.5, "{q:?}");
    for (a, b) in [(p[0], q[0]), (p[1], q[1]), (p[0], q[2]), (p[1], q[3])] {
        assert!((a - b).abs() <= 1e-12 * a, "{p:?} / {q:?}");
    }
    assert!(two.warnings.iter().any(|w| w.contains("ln N")), "{:?}", two.warnings);
    let d = delta_to_truth(&two.to_model().expect("model"), &truth);
    assert!(d <= 0.005, "delta {d}");
}

/// Held-out truths under `auto`'s render choice (the pipeline's default): a two-lobe surface whose tail
/// holds half the area answers with a mixture within 2% of the truth in NDF, and ellipsoid caps and a
/// Gaussian random surface answer with one lobe; each answer is the report's `model`, renders within the
/// tolerance in both default scenes, and is `ok`.
#[test]
fn the_render_choice_keeps_held_out_truths() {
    use ndfit::answer::choice::RenderOptions;
    let render = RenderOptions::default();
    let check = |ndf: &ndfit::ndf::EmpiricalNdf, what: &str| {
        let rep = ndfit::pipeline::fit_rendered(ndf, &FitOptions::default(), &render, what).expect("auto");
        let sel = rep.selection.as_ref().expect("selection");
        let err = sel.render_error.as_ref().expect("render_error");
        eprintln!(
            "{what}: answer {:?} ({}), render error {err:?}, noise {:?}, verdict {}",
            sel.answer, rep.model, sel.render_noise, rep.quality.verdict
        );
        assert_eq!(sel.answer.as_deref(), Some(rep.model.as_str()), "{what}: {:?}", sel.candidates);
        assert!(["point", "broad", "worst"].iter().all(|k| err.contains_key(*k)), "{what}: {err:?}");
        // Held to the tolerance beyond the table's own counting noise, scene by scene (measured only once a
        // lobe fails without it).
        let noise = sel.render_noise.clone().unwrap_or_default();
        for scene in ["point", "broad"] {
            assert!(err[scene] - noise.get(scene).copied().unwrap_or(0.0) <= render.tolerance, "{what}: {err:?} noise {noise:?}");
        }
        assert_eq!(rep.quality.verdict, ndfit::fit::Verdict::Ok, "{what}: {:?}", rep.quality.reasons);
        rep
    };
    let truth = model(ModelId::Ggx2, &[0.15, 0.05, 0.5, 0.2, -0.6, 0.5]);
    let tri = NdfOptions { scheme: ndfit::ndf::NormalScheme::Triangles, cells_across: None, ..NdfOptions::default() };
    let two =
        empirical_ndf(&facet_mixture(Draw::Ggx(0.15, 0.05, -0.6), Draw::Ggx(0.5, 0.2, -0.6), 0.5, 250_000, false), &tri).expect("ndf");
    let rep = check(&two, "two lobes");
    let d = delta_to_truth(&rep.to_model().expect("model"), &truth);
    assert!(rep.model.is_mixture() && d <= 0.02, "two lobes: {} at {d} from the truth", rep.model);
    for p in [[0.2, 0.2, 0.0, 0.0, 0.0], [0.25, 0.1, 0.2, -0.15, 0.3]] {
        let ep =
            EllipsoidParams { alpha_x: p[0], alpha_y: p[1], theta_x: p[2], theta_y: p[3], theta_z: p[4], ..EllipsoidParams::default() };
        let (hf, _) = ellipsoid_surface(&SynthSettings { nx: 512, ny: 512, seed: 3, ..SynthSettings::default() }, &ep).expect("synth");
        let rep = check(&empirical_ndf(&hf, &NdfOptions::default()).expect("ndf"), &format!("cap {p:?}"));
        assert!(!rep.model.is_mixture(), "cap {p:?}: {}", rep.model);
    }
    // 1024^2 (fresh 512^2 ones: `auto_answers_one_beckmann_lobe_on_gaussian_surfaces_by_the_render`).
    let settings = SynthSettings { nx: 1024, ny: 1024, seed: 4, ..SynthSettings::default() };
    let (hf, _) = ndfit::synth::gaussian_surface(&settings, &ndfit::synth::GaussianParams::default()).expect("synth");
    let rep = check(&empirical_ndf(&hf, &NdfOptions::default()).expect("ndf"), "gaussian surface");
    assert!(!rep.model.is_mixture(), "gaussian surface: {}", rep.model);
}
