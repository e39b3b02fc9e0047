//! Wave optics (`ndfit::wave`) against closed forms: a sinusoidal grating (Bessel orders), smooth Gaussian
//! surfaces (the Beckmann-Kirchhoff series), rough ones (geometric optics of the same slopes, and the
//! tracer's first bounce), energy, reciprocity, fresh truths and hostile input. Every expected value is
//! computed here from the heights or a formula, never from the module's own output.

use std::f64::consts::PI;

use ndfit::export::rgl::Material;
use ndfit::models::{Beckmann, Masking};
use ndfit::synth::{gaussian_surface, GaussianParams, SynthSettings};
use ndfit::trace::{trace, DirTable, TraceOptions};
use ndfit::wave::{direction, wave, Diffraction, WaveOptions};
use ndfit::{Heightfield, Scan};

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

fn opts(lambdas: &[f64], incidences: &[f64], coherence_m: Option<f64>) -> WaveOptions {
    WaveOptions { wavelengths_nm: lambdas.to_vec(), incidences_deg: incidences.to_vec(), coherence_m, ..Default::default() }
}

/// A Gaussian-correlated surface with deterministic spectral amplitudes (its power spectrum is exactly
/// Gaussian), RMS slope `sigma` per axis and correlation length `ell`: heights of RMS `sigma ell / sqrt 2`.
fn gaussian(n: usize, dx: f64, sigma: f64, ell: f64, seed: u64) -> Heightfield {
    let s = SynthSettings { nx: n, ny: n, dx, dy: dx, seed, ..Default::default() };
    gaussian_surface(&s, &GaussianParams { sigma_x: sigma, sigma_y: sigma, theta_z: 0.0, corr_length: ell }).unwrap().0
}

fn rms(hf: &Scan<'_>) -> f64 {
    let v: Vec<f64> = hf.z.iter().copied().filter(|h| h.is_finite()).collect();
    let mean = v.iter().sum::<f64>() / v.len() as f64;
    (v.iter().map(|h| (h - mean) * (h - mean)).sum::<f64>() / v.len() as f64).sqrt()
}

/// `|<exp(i q h)>|^2` over the valid heights.
fn mean_field2(hf: &Scan<'_>, q: f64) -> f64 {
    let (mut re, mut im, mut n) = (0.0, 0.0, 0.0);
    for &h in hf.z.iter().filter(|h| h.is_finite()) {
        re += (q * h).cos();
        im += (q * h).sin();
        n += 1.0;
    }
    (re * re + im * im) / (n * n)
}

/// Angle (degrees) between `wo` and the mirror direction of `wi`.
fn from_mirror(wi: [f64; 3], wo: [f64; 3]) -> f64 {
    (-wi[0] * wo[0] - wi[1] * wo[1] + wi[2] * wo[2]).clamp(-1.0, 1.0).acos().to_degrees()
}

#[test]
fn a_grating_reflects_bessel_orders_at_the_grating_angles() {
    // h = A sin(2 pi x / L), A = 20 nm << lambda; four patches of exactly five periods each.
    let (n, dx, a, l) = (512, 1e-7, 20e-9, 5.12e-6);
    let z: Vec<f64> = (0..n * n).map(|i| a * (2.0 * PI * ((i % n) as f64 * dx) / l).sin()).collect();
    let hf = Heightfield::new(n, n, dx, dx, z).unwrap();
    let (report, d) = wave(&hf, &opts(&[550.0], &[0.0, 40.0], Some(25.6e-6)), None).unwrap();
    let k = k_of(550.0);
    for (r, theta) in report.records.iter().zip([0.0f64, 40.0]) {
        let mirror = bessel_j(0, 2.0 * k * a * theta.to_radians().cos()).powi(2);
        assert!((r.specular - mirror).abs() < 0.01, "{theta} deg: specular {} against J0^2 {mirror}", r.specular);
        let sum = r.specular + r.diffuse_albedo + r.evanescent;
        assert!((sum - 1.0).abs() < 1e-3, "{theta} deg: the energies sum to {sum}");
    }
    // The orders at normal incidence: the bins within half an order's spacing of sin t = m lambda / L.
    let step = 550e-9 / l;
    for m in [-2i32, -1, 1, 2] {
        let (mut e, mut centroid) = (0.0, 0.0);
        for (wo, en) in d.scattered(550.0, direction(0.0, 0.0)) {
            if (wo[0] - m as f64 * step).abs() < step / 2.0 && wo[1].abs() < step / 2.0 {
                e += en;
                centroid += en * wo[0];
            }
        }
        let jm = bessel_j(m.unsigned_abs(), 2.0 * k * a).powi(2);
        let tol = if m.abs() == 1 { 0.03 } else { 0.05 };
        assert!((e / jm - 1.0).abs() < tol, "order {m}: energy {e} against J_m^2 {jm}");
        assert!((centroid / e - m as f64 * step).abs() < 1e-3, "order {m} leaves at sin t = {} not {}", centroid / e, m as f64 * step);
    }
}

/// The Beckmann-Kirchhoff series of a Gaussian surface (heights RMS `sigma`, Gaussian correlation of
/// length `ell`) for the model's factor `Q`: `k^2 / (4 pi^2) Q exp(-g) sum_n g^n / n! (pi ell^2 / n)
/// exp(-|v_t|^2 ell^2 / (4 n))`, `g = v_z^2 sigma^2` (Beckmann & Spizzichino ch. 5; Rayleigh-Rice at n = 1).
fn beckmann_kirchhoff(lambda_nm: f64, wi: [f64; 3], wo: [f64; 3], sigma: f64, ell: f64) -> f64 {
    let k = k_of(lambda_nm);
    let vt2 = k * k * ((wi[0] + wo[0]).powi(2) + (wi[1] + wo[1]).powi(2));
    let vz = k * (wi[2] + wo[2]);
    let g = vz * vz * sigma * sigma;
    let (mut term, mut sum) = (1.0, 0.0);
    for n in 1..60 {
        term *= g / n as f64;
        sum += term * PI * ell * ell / n as f64 * (-vt2 * ell * ell / (4.0 * n as f64)).exp();
    }
    k * k / (4.0 * PI * PI) * ndfit::wave::kirchhoff_factor(wi, wo) * (-g).exp() * sum
}

#[test]
fn a_smooth_gaussian_surface_follows_the_beckmann_kirchhoff_series() {
    // sigma_h = 0.014142 * 1 um / sqrt 2 = 10 nm << lambda; 16 patches of 51.2 um.
    let (ell, c) = (1e-6, 51.2e-6);
    let hf = gaussian(2048, 1e-7, 0.014142, ell, 5);
    let sigma = rms(&hf);
    let (report, d) = wave(&hf, &opts(&[550.0], &[0.0, 40.0], Some(c)), None).unwrap();
    let k = k_of(550.0);
    let lam = 550e-9;
    let cell = (lam / c) * (lam / c);
    for (r, theta) in report.records.iter().zip([0.0f64, 40.0]) {
        let wi = direction(theta, 0.0);
        let heights = mean_field2(&hf, 2.0 * k * wi[2]);
        assert!((r.specular - heights).abs() < 0.01, "{theta} deg: specular {} against the heights' {heights}", r.specular);
        // Rings about the mirror direction, from three bins (the patch's own lobe: its window's main lobe
        // spans two, and its plane takes the frequencies below one) out to 17 degrees: the series by the
        // midpoint rule on the same bins.
        let first = (3.0 * lam / c).to_degrees();
        // Rings of about equal solid angle: each averages the speckle of hundreds of bins (16 patches).
        let edges = [first, 6.0, 10.0, 14.0, 17.0];
        for w in edges.windows(2) {
            let (mut got, mut want) = (0.0, 0.0);
            for (wo, e) in d.scattered(550.0, wi) {
                let a = from_mirror(wi, wo);
                if a >= w[0] && a < w[1] {
                    got += e;
                    want += beckmann_kirchhoff(550.0, wi, wo, sigma, ell) * cell;
                }
            }
            assert!((got / want - 1.0).abs() < 0.06, "{theta} deg, ring {:.2}-{:.2}: {got} against the series {want}", w[0], w[1]);
        }
        let sum = r.specular + r.diffuse_albedo;
        assert!((sum - 1.0).abs() < 0.03, "{theta} deg: mirror + diffuse = {sum}");
    }
}

/// The geometric-optics energy that single specular reflection on the scan's facets (central differences)
/// sends from `wi` into each ring `[r, r + 0.2)` of the projected disk about the mirror point, each facet
/// weighted as the wave computation weighs its height: by the squared Hann window of the coherence patch of
/// `p` samples it lies in (docs/WAVE.md, "Coherence patches"; points outside the tiling weigh nothing).
fn geometric_rings(hf: &Scan<'_>, wi: [f64; 3], p: usize) -> Vec<f64> {
    geometric_binned(hf, wi, p, 10, |wo| (((wo[0] + wi[0]).hypot(wo[1] + wi[1]) / RING) as usize).min(9))
}

/// As [`geometric_rings`], into `n` bins chosen by `bin(w_o)`.
fn geometric_binned(hf: &Scan<'_>, wi: [f64; 3], p: usize, n: usize, bin: impl Fn([f64; 3]) -> usize) -> Vec<f64> {
    let hann = |j: usize| (PI * (j as f64 + 0.5) / p as f64).sin().powi(2);
    let (cols, rows) = (hf.nx / p, hf.ny / p);
    let (j0, i0) = ((hf.nx - cols * p) / 2, (hf.ny - rows * p) / 2);
    let mut rings = vec![0.0; n];
    let mut total = 0.0;
    for i in i0.max(1)..(i0 + rows * p).min(hf.ny - 1) {
        for j in j0.max(1)..(j0 + cols * p).min(hf.nx - 1) {
            let sx = (hf.at(i, j + 1) - hf.at(i, j - 1)) / (2.0 * hf.dx);
            let sy = (hf.at(i + 1, j) - hf.at(i - 1, j)) / (2.0 * hf.dy);
            if !(sx.is_finite() && sy.is_finite()) {
                continue;
            }
            let u = (hann((j - j0) % p) * hann((i - i0) % p)).powi(2);
            let nn = (sx * sx + sy * sy + 1.0).sqrt();
            let m = [-sx / nn, -sy / nn, 1.0 / nn];
            let c = wi[0] * m[0] + wi[1] * m[1] + wi[2] * m[2];
            total += u;
            if c <= 0.0 {
                continue;
            }
            let wo = [2.0 * c * m[0] - wi[0], 2.0 * c * m[1] - wi[1], 2.0 * c * m[2] - wi[2]];
            if wo[2] > 0.0 {
                rings[bin(wo)] += u * c / m[2] / wi[2];
            }
        }
    }
    rings.iter().map(|e| e / total).collect()
}

/// Width of the rings: five times the blur that the Fresnel zones of the specular points give the slopes
/// on the rough test surface (about `1 / sqrt(R v_z)` = 0.02 with curvature radius `R`; twice that in
/// outgoing directions), so that diffraction moves little energy across a ring's edge.
const RING: f64 = 0.2;

fn wave_rings(d: &Diffraction, specular: f64, wi: [f64; 3]) -> Vec<f64> {
    let mut rings = vec![0.0; 10];
    rings[0] += specular;
    for (wo, e) in d.scattered(550.0, wi) {
        let r = (wo[0] + wi[0]).hypot(wo[1] + wi[1]);
        rings[((r / RING) as usize).min(9)] += e;
    }
    rings
}

#[test]
fn a_rough_surface_scatters_as_geometric_optics_of_its_slopes() {
    // RMS slope 0.2, correlation length 16 um: heights of 2.3 um RMS, v_z h about 50. Curvature radii
    // of about 110 um: the Fresnel zones of the specular points blur the slopes by about 0.02, well
    // inside a ring. Patches of 32 um (128 samples).
    let hf = gaussian(2048, 2.5e-7, 0.2, 16e-6, 8);
    let (report, d) = wave(&hf, &opts(&[550.0], &[0.0, 20.0, 40.0], Some(32e-6)), None).unwrap();
    for r in &report.records {
        let wi = direction(r.theta_deg, 0.0);
        let (geo, got) = (geometric_rings(&hf, wi, 128), wave_rings(&d, r.specular, wi));
        // The BRDF averaged over each ring's area (the whole annulus: a lower bound where it leaves the disk).
        let brdf = |i: usize, e: f64| e / (PI * RING * RING * ((i + 1) * (i + 1) - i * i) as f64);
        let peak = geo.iter().enumerate().map(|(i, &e)| brdf(i, e)).fold(0.0, f64::max);
        for (i, (g, w)) in geo.iter().zip(&got).enumerate() {
            if brdf(i, *g) > 0.01 * peak {
                assert!((w / g - 1.0).abs() < 0.05, "{} deg, ring {i}: {w} against geometric optics {g}", r.theta_deg);
            }
        }
        let sum = r.specular + r.diffuse_albedo;
        assert!((sum - 1.0).abs() < 0.03, "{} deg: mirror + diffuse = {sum}", r.theta_deg);
        assert!(r.specular < 0.01, "{} deg: a rough surface has no mirror ({})", r.theta_deg, r.specular);
    }
}

#[test]
fn a_rough_surface_scatters_as_the_tracers_first_bounce() {
    let hf = gaussian(2048, 2.5e-7, 0.2, 16e-6, 9);
    let (report, d) = wave(&hf, &opts(&[550.0], &[0.0], Some(32e-6)), None).unwrap();
    // Four elevation bands (edges 0, 5.6, 22.5, 50.6 and 90 degrees): wide against the Fresnel zones' blur.
    let table = DirTable { n_theta: 4, n_phi: 8 };
    let t = trace(
        &hf,
        &TraceOptions { incidences_deg: vec![0.0], material: Material::None, bounces: 1, rays: 1 << 20, table, ..Default::default() },
        None,
    )
    .unwrap();
    // Per elevation band (all azimuths): the tracer's first bounce and its Monte Carlo variance.
    let band = |b: usize| b / table.n_phi;
    let (mut traced, mut var) = (vec![0.0; 4], vec![0.0; 4]);
    for b in 0..table.len() {
        let it = band(b);
        traced[it] += t.tables[0].single[b][1];
        var[it] += t.tables[0].var_total[b];
    }
    // The wave model has no masking; the tracer's first bounce has. Each bin's energy is weighted by
    // Smith's height-correlated G2 of the surface's Beckmann NDF (alpha = sqrt 2 x 0.2; Heitz eq. 99).
    let model = Beckmann::new(0.2 * std::f64::consts::SQRT_2, 0.2 * std::f64::consts::SQRT_2, 0.0).unwrap();
    let wi = direction(0.0, 0.0);
    let li = model.lambda(nalgebra::Vector3::new(wi[0], wi[1], wi[2]));
    let mut waved = [0.0; 4];
    waved[0] += report.records[0].specular;
    for (wo, e) in d.scattered(550.0, wi) {
        if let Some(b) = table.bin(wo) {
            waved[band(b)] += e / (1.0 + li + model.lambda(nalgebra::Vector3::new(wo[0], wo[1], wo[2])));
        }
    }
    // The patches' windows weigh the surface unevenly, the tracer's paths evenly: what that alone changes
    // is measured by geometric optics of the same slopes weighted both ways, and allowed.
    let bin = |wo: [f64; 3]| table.bin(wo).map_or(3, band);
    let windowed = geometric_binned(&hf, wi, 128, 4, bin);
    let uniform = geometric_binned(&hf, wi, 1, 4, bin);
    for it in 0..4 {
        let expected = traced[it] * windowed[it] / uniform[it];
        // The tracer's noise, plus 3% for the speckle of 256 patches and the two surfaces (sampled
        // heights against two triangles per cell).
        let allowed = 3.0 * var[it].sqrt() + 0.03 * traced[it];
        assert!(
            (waved[it] - expected).abs() < allowed,
            "band {it}: wave {} against the tracer {} reweighted to the windows, {expected}",
            waved[it],
            traced[it]
        );
    }
}

#[test]
fn the_diffuse_brdf_is_reciprocal() {
    for hf in [gaussian(512, 1e-7, 0.014142, 1e-6, 2), gaussian(512, 2.5e-7, 0.2, 8e-6, 4)] {
        let d = Diffraction::new(&hf, &opts(&[450.0, 650.0], &[0.0, 20.0, 40.0, 60.0], None), None).unwrap();
        let mut checked = 0;
        for (ti, tp) in [(10.0, 0.0), (35.0, 70.0), (55.0, 200.0)] {
            for (oi, op) in [(5.0, 180.0), (40.0, 100.0), (25.0, 300.0), (50.0, 20.0)] {
                let (wi, wo) = (direction(ti, tp), direction(oi, op));
                for l in [450.0, 650.0] {
                    let (a, b) = (d.brdf(l, wi, wo), d.brdf(l, wo, wi));
                    assert!((a - b).abs() <= 1e-12 * a.abs().max(1e-300), "{l} nm: f(wi, wo) {a} != f(wo, wi) {b}");
                    checked += usize::from(a > 0.0);
                }
            }
        }
        assert!(checked > 10, "only {checked} pairs inside the band");
    }
}

#[test]
fn energy_is_conserved_up_to_40_degrees_on_fresh_surfaces() {
    // Fresh truths: other seeds and sizes, anisotropic correlation turned by theta_z, 2% masked points.
    let s = SynthSettings { nx: 1536, ny: 1024, dx: 2e-7, dy: 2e-7, seed: 21, holes: 0.02, ..Default::default() };
    let rough = gaussian_surface(&s, &GaussianParams { sigma_x: 0.3, sigma_y: 0.1, theta_z: 0.6, corr_length: 6e-6 }).unwrap().0;
    let s = SynthSettings { nx: 1024, ny: 768, dx: 1e-7, dy: 1e-7, seed: 22, holes: 0.02, ..Default::default() };
    let smooth = gaussian_surface(&s, &GaussianParams { sigma_x: 0.03, sigma_y: 0.01, theta_z: -0.4, corr_length: 1.5e-6 }).unwrap().0;
    for (name, hf) in [("rough", &rough), ("smooth", &smooth)] {
        let (report, _) = wave(hf, &opts(&[450.0, 650.0], &[0.0, 20.0, 40.0], None), None).unwrap();
        for r in &report.records {
            let sum = r.specular + r.diffuse_albedo;
            assert!((sum - 1.0).abs() < 0.03, "{name}, {} nm, {} deg: mirror + diffuse = {sum}", r.wavelength_nm, r.theta_deg);
            if name == "smooth" {
                // The mirror of the heights themselves (holes excluded), within 0.01.
                let heights = mean_field2(hf, 2.0 * k_of(r.wavelength_nm) * r.theta_deg.to_radians().cos());
                assert!(
                    (r.specular - heights).abs() < 0.01,
                    "{} nm, {} deg: {} against {heights}",
                    r.wavelength_nm,
                    r.theta_deg,
                    r.specular
                );
            }
        }
        // Bluer haze: the diffuse share grows as the wavelength shrinks on the smooth surface.
        if name == "smooth" {
            let at = |l: f64| report.records.iter().find(|r| r.wavelength_nm == l && r.theta_deg == 0.0).unwrap().diffuse_albedo;
            assert!(at(450.0) > at(650.0) * 1.5, "haze at 450 nm {} against 650 nm {}", at(450.0), at(650.0));
        }
    }
}

#[test]
fn the_command_refuses_bad_input_in_one_line_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let scan = crate::common::synth_small_gaussian(dir.path(), &["--dx", "1e-6"]);
    let out = dir.path().join("w.json");
    let run = |args: &[&str]| {
        std::process::Command::new(crate::common::ndfit_bin()).arg("wave").arg(&scan).args(args).arg("-o").arg(&out).output().unwrap()
    };
    for (args, what) in [
        (vec!["--wavelength", "0"], "wavelength"),
        (vec!["--wavelength", "-550"], "wavelength"),
        (vec!["--wavelength", "nan"], "wavelength"),
        (vec!["--coherence", "100"], "larger than the scan"),
        (vec!["--coherence", "3"], "at least 4"),
        (vec!["--grid", "0", "--grid-out", "g"], "--grid"),
        (vec!["--incidence", "95"], "incidence"),
    ] {
        let o = run(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert_eq!(err.trim().lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(what) && err.contains("g.x3p"), "{args:?}: {err}");
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }
    // The refusal of a patch larger than the scan names the coherence that takes the whole scan as one
    // patch, and that coherence runs.
    let err = String::from_utf8_lossy(&run(&["--coherence", "100"]).stderr).to_string();
    let hint = err.split("--coherence ").nth(1).and_then(|t| t.split_whitespace().next()).expect(&err).to_string();
    let o = run(&["--coherence", &hint]);
    assert!(o.status.success(), "--coherence {hint}: {}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    assert_eq!(v["patches"]["used"].as_f64(), Some(1.0), "--coherence {hint}: {}", v["patches"]);
    std::fs::remove_file(&out).unwrap();
    // A valid run writes the contract's fields.
    let o = run(&["--wavelength", "500,600", "--incidence", "0,30", "--coherence", "16"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    let records = v["records"].as_array().unwrap();
    assert_eq!(records.len(), 4);
    for key in ["wavelength_nm", "theta_deg", "phi_deg", "specular", "diffuse_albedo", "albedo"] {
        assert!(records.iter().all(|r| r[key].is_number()), "{key} missing");
    }
}

#[test]
fn a_flat_scan_far_from_zero_is_a_mirror_with_the_conductors_fresnel() {
    // Heights 1 km up with 5% masked points: every patch reflects as a mirror, and `albedo` is the
    // conductor's Fresnel factor at the incidence.
    let n = 256;
    let z: Vec<f64> = (0..n * n).map(|i| if (i * 7919) % 20 == 3 { f64::NAN } else { 1e3 }).collect();
    let hf = Heightfield::new(n, n, 1e-7, 1e-7, z).unwrap();
    let o = WaveOptions { material: Material::Au, ..opts(&[450.0, 650.0], &[0.0, 60.0], Some(6.4e-6)) };
    let (report, _) = wave(&hf, &o, None).unwrap();
    for r in &report.records {
        assert!((r.specular - 1.0).abs() < 1e-9 && r.diffuse_albedo < 1e-9, "{r:?}");
        let f = Material::Au.fresnel(r.theta_deg.to_radians().cos(), r.wavelength_nm);
        assert!((r.albedo - f).abs() < 1e-9, "{} nm, {} deg: albedo {} against Fresnel {f}", r.wavelength_nm, r.theta_deg, r.albedo);
    }
    assert_eq!(report.patches.skipped, 0);
}
