//! The geometric-optics tracer (`ndfit::trace`) against closed forms and conservation laws: the white
//! furnace, Smith's regime on Gaussian surfaces (Beckmann truth), the V-groove's Cook-Torrance masking,
//! reciprocity, determinism and hostile input. Every expected value comes from a closed form or a
//! quadrature written here, never from the tracer's own output.

use ndfit::models::{Beckmann, Masking, Ndf};
use ndfit::synth::{gaussian_surface, GaussianParams, SynthSettings};
use ndfit::trace::{direction, trace, DirTable, TraceOptions, TraceReport};
use ndfit::Heightfield;

/// A periodic Gaussian surface (power-of-two grid) of RMS slope `sigma` per axis: Beckmann NDF with
/// `alpha = sqrt(2) sigma` (Heitz eq. 88, footnote 3). Correlation length 16 cells keeps the triangles'
/// slopes within 0.6% (variance) of the central differences the synthesis matches.
fn gaussian(n: usize, sigma: f64, seed: u64) -> Heightfield {
    let s = SynthSettings { nx: n, ny: n, dx: 1e-6, dy: 1e-6, seed, ..Default::default() };
    let p = GaussianParams { sigma_x: sigma, sigma_y: sigma, theta_z: 0.0, corr_length: 16e-6 };
    gaussian_surface(&s, &p).unwrap().0
}

fn run(hf: &Heightfield, incidences: &[f64], f: impl FnOnce(&mut TraceOptions)) -> TraceReport {
    let mut o = TraceOptions { incidences_deg: incidences.to_vec(), ..Default::default() };
    f(&mut o);
    trace(hf, &o, None).unwrap()
}

/// Energy conservation: with F = 1 and every bounce followed, all energy leaves the periodic surface.
/// With one bounce the albedo is the first bounce's share, at most the full albedo.
#[test]
fn white_furnace_on_a_gaussian_surface_of_rms_slope_one_half() {
    let hf = gaussian(512, 0.5, 3);
    let inc = [0.0, 20.0, 40.0, 60.0, 70.0, 80.0];
    let all = run(&hf, &inc, |o| {
        o.rays = 1 << 17;
        o.bounces = 200;
    });
    let one = run(&hf, &inc, |o| {
        o.rays = 1 << 17;
        o.bounces = 1;
    });
    for (a, b) in all.incidences.iter().zip(&one.incidences) {
        println!("furnace {:4.0} deg: albedo {:.6} (lost {:.1e}), one bounce {:.4}", a.theta_deg, a.albedo, a.lost, b.albedo);
        assert!((a.albedo - 1.0).abs() < 0.002, "{} deg: albedo {}", a.theta_deg, a.albedo);
        assert!(b.albedo <= a.albedo + 1e-12 && b.albedo > 0.5, "{} deg: one bounce {}", b.theta_deg, b.albedo);
        // The same seed draws the same first bounces: one bounce's albedo is the full run's first order.
        assert!((b.albedo - a.albedo_by_bounce[0]).abs() < 1e-12);
        assert!((a.multiple_share - (1.0 - b.albedo / a.albedo)).abs() < 1e-9);
    }
}

#[test]
fn white_furnace_on_a_real_scan_needs_shared() {
    let Some(dir) = crate::common::shared_scans("trace::white_furnace_on_a_real_scan_needs_shared") else { return };
    let path = dir.join("hamby44_downsampled_Barrel_1-Bullet_1-Land_1.x3p");
    let pre = ndfit::preprocess::Preprocess::default();
    let hf = ndfit::pipeline::read_preprocessed(&path, &Default::default(), &pre).unwrap();
    let r = run(&hf, &[0.0, 30.0, 60.0, 80.0], |o| {
        o.rays = 1 << 16;
        o.bounces = 200;
    });
    for a in &r.incidences {
        println!(
            "real-scan furnace {:4.0} deg: albedo {:.6} (lost {:.1e}, multiple {:.3})",
            a.theta_deg, a.albedo, a.lost, a.multiple_share
        );
        assert!((a.albedo - 1.0).abs() < 0.002, "{} deg: albedo {}", a.theta_deg, a.albedo);
    }
}

/// Beckmann with height-correlated Smith G2 (Heitz eq. 99): `f cos_o` integrated over bin `k` by a
/// 6 x 6 midpoint rule in `(u_theta, phi)`.
fn beckmann_bin_energy(model: &Beckmann, wi: [f64; 3], t: &DirTable, k: usize) -> f64 {
    let (it, ip) = (k / t.n_phi, k % t.n_phi);
    let n = 6;
    let mut sum = 0.0;
    let v = |a: [f64; 3]| nalgebra::Vector3::new(a[0], a[1], a[2]);
    let i = v(wi);
    let li = model.lambda(i);
    for a in 0..n {
        let (ua, ub) = (it as f64 / t.n_theta as f64, (it + 1) as f64 / t.n_theta as f64);
        let u = ua + (ub - ua) * (a as f64 + 0.5) / n as f64;
        let theta = u * u * std::f64::consts::FRAC_PI_2;
        let dtheta = 2.0 * u * std::f64::consts::FRAC_PI_2 * (ub - ua) / n as f64;
        for b in 0..n {
            let (pa, pb) = (t.phi_edge(ip), t.phi_edge(ip + 1));
            let phi = pa + (pb - pa) * (b as f64 + 0.5) / n as f64;
            let o = nalgebra::Vector3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos());
            let h = (i + o).normalize();
            let g2 = 1.0 / (1.0 + li + model.lambda(o));
            let f = model.d(h) * g2 / (4.0 * i.z * o.z);
            sum += f * o.z * theta.sin() * dtheta * (pb - pa) / n as f64;
        }
    }
    sum
}

/// A periodic Gaussian surface (power-of-two grid, correlation length `ell` cells) whose triangles have
/// RMS slope `sigma` per axis: the synthesis matches the central differences' covariance to `sigma`,
/// while the traced triangles' slopes are the forward differences, whose variance exceeds it by about
/// `1.5 / ell^2` (2.4% at 8 cells). The heights are scaled by the forward differences' RMS measured
/// here, so the facets the tracer sees are Gaussian with the truth's covariance: Beckmann at
/// `alpha = sqrt(2) sigma` (Heitz eq. 88).
fn gaussian_triangles(n: usize, sigma: f64, ell: f64, seed: u64) -> Heightfield {
    let s = SynthSettings { nx: n, ny: n, dx: 1e-6, dy: 1e-6, seed, ..Default::default() };
    let p = GaussianParams { sigma_x: sigma, sigma_y: sigma, theta_z: 0.0, corr_length: ell * 1e-6 };
    let hf = gaussian_surface(&s, &p).unwrap().0;
    let z: Vec<f64> = hf.z.to_vec();
    let mut sum = 0.0;
    for i in 0..n {
        for j in 0..n {
            let h = z[i * n + j];
            sum += (z[i * n + (j + 1) % n] - h).powi(2) + (z[((i + 1) % n) * n + j] - h).powi(2);
        }
    }
    let rms = (sum / (2 * n * n) as f64).sqrt() / 1e-6;
    let k = sigma / rms;
    Heightfield::new(n, n, 1e-6, 1e-6, z.iter().map(|v| v * k).collect()).unwrap()
}

/// Smith's regime, scattering: on a Gaussian surface the first bounce is Beckmann with Smith's G2 at
/// the truth's alpha, to a median of 3% over the bins at >= 1% of the peak (issue 53). What limits the
/// median besides the Monte Carlo noise is this realization's NDF against the ideal: its slopes'
/// histogram is Gaussian only up to the finite number of correlation areas (65536 here, hence the short
/// correlation length), and the facets' covariance must be the truth's (see `gaussian_triangles`).
#[test]
#[ignore = "about 25 s of CPU (2^25 paths on a 2048^2 surface): cargo test --release -- --ignored gaussian_surfaces_scatter"]
fn gaussian_surfaces_scatter_as_beckmann_smith() {
    let sigma = 0.3;
    let alpha = std::f64::consts::SQRT_2 * sigma;
    let model = Beckmann::new(alpha, alpha, 0.0).unwrap();
    let hf = gaussian_triangles(2048, sigma, 8.0, 5);
    let table = DirTable { n_theta: 16, n_phi: 32 };
    // The lobe at 60 deg spreads over grazing bins, whose noise is largest: four times the paths there.
    let runs: Vec<TraceReport> = [(vec![0.0, 30.0], 1 << 22), (vec![60.0], 1 << 24)]
        .into_iter()
        .map(|(inc, rays)| {
            run(&hf, &inc, |o| {
                o.rays = rays;
                o.bounces = 1;
                o.table = table;
            })
        })
        .collect();
    let mut medians = Vec::new();
    for (rec, tab) in runs.iter().flat_map(|r| r.incidences.iter().zip(&r.tables)) {
        let wi = direction(rec.theta_deg, rec.phi_deg);
        let truth: Vec<f64> = (0..table.len()).map(|k| beckmann_bin_energy(&model, wi, &table, k)).collect();
        let f = |k: usize, e: f64| e / table.proj_solid_angle(k);
        let peak = (0..table.len()).map(|k| f(k, truth[k])).fold(0.0, f64::max);
        let lum = |e: &[f64; 3]| ndfit::trace::LUMA.iter().zip(e).map(|(w, v)| w * v).sum::<f64>();
        let kept: Vec<usize> = (0..table.len()).filter(|&k| f(k, truth[k]) >= 0.01 * peak).collect();
        let mut rel: Vec<f64> = kept.iter().map(|&k| (lum(&tab.single[k]) / truth[k] - 1.0).abs()).collect();
        rel.sort_by(f64::total_cmp);
        let mut noise: Vec<f64> = kept.iter().map(|&k| tab.var_total[k].sqrt() / truth[k]).collect();
        noise.sort_by(f64::total_cmp);
        let median = rel[rel.len() / 2];
        println!(
            "smith regime {:4.0} deg: median |traced / Beckmann-Smith - 1| = {median:.4} over {} bins (median noise {:.4})",
            rec.theta_deg,
            rel.len(),
            noise[noise.len() / 2]
        );
        medians.push((rec.theta_deg, median));
    }
    assert!(medians.iter().all(|m| m.1 < 0.03), "{medians:?}");
}

/// Smith's regime, masking: on a Gaussian surface the traced G1 is Smith's G1 of the truth's Beckmann
/// (Heitz eq. 43, 72) to 2% up to 75 deg.
#[test]
fn gaussian_surfaces_mask_as_smith() {
    let sigma = 0.3;
    let alpha = std::f64::consts::SQRT_2 * sigma;
    let model = Beckmann::new(alpha, alpha, 0.0).unwrap();
    let hf = gaussian(1024, sigma, 5);
    let inc = [0.0, 30.0, 45.0, 60.0, 70.0, 75.0];
    let r = run(&hf, &inc, |o| {
        o.rays = 1 << 18;
        o.bounces = 1;
    });
    for rec in &r.incidences {
        let w = direction(rec.theta_deg, 0.0);
        let smith = 1.0 / (1.0 + model.lambda(nalgebra::Vector3::new(w[0], w[1], w[2])));
        println!("smith regime G1 {:4.0} deg: traced {:.4} +- {:.4}, Beckmann-Smith {smith:.4}", rec.theta_deg, rec.g1, rec.g1_stderr);
        assert!((rec.g1 / smith - 1.0).abs() < 0.02, "{} deg: G1 {} vs {smith}", rec.theta_deg, rec.g1);
    }
}

/// A periodic V-groove (grooves along y, walls of slope `a`, kinks on grid lines so each triangle is one
/// wall): the traced G1 against the V-cavity masking of Cook and Torrance in closed form,
/// `G1(w, m) = min(1, 2 (n.m)(n.w) / (w.m))` (Heitz 2014 sec. 4), per wall and over the surface.
#[test]
fn v_grooves_follow_the_cook_torrance_v_cavity() {
    let (period, a) = (16usize, 1.0f64);
    let (nx, ny, dx) = (128usize, 16usize, 1e-6);
    let z: Vec<f64> = (0..nx * ny)
        .map(|k| {
            let p = (k % nx) % period;
            a * dx * (p as f64 - period as f64 / 2.0).abs()
        })
        .collect();
    let hf = Heightfield::new(nx, ny, dx, dx, z).unwrap();
    let inc = [20.0, 40.0, 50.0, 60.0, 70.0, 80.0];
    let r = run(&hf, &inc, |o| {
        o.rays = 1 << 20;
        o.bounces = 1;
    });
    let c = 1.0 / (1.0 + a * a).sqrt();
    let walls = [[a * c, 0.0, c], [-a * c, 0.0, c]];
    for rec in &r.incidences {
        let w = direction(rec.theta_deg, 0.0);
        let dot = |m: [f64; 3]| w[0] * m[0] + w[1] * m[1] + w[2] * m[2];
        let ct = |m: [f64; 3]| (2.0 * m[2] * w[2] / dot(m)).min(1.0);
        let (mut num, mut den) = (0.0, 0.0);
        for m in walls {
            if dot(m) > 0.0 {
                num += ct(m) * dot(m) / m[2];
                den += dot(m) / m[2];
            }
        }
        let marginal = num / den;
        let toward = ct(walls[0]);
        println!(
            "v-groove {:4.0} deg: G1 traced {:.4} (toward {:.4}), Cook-Torrance {marginal:.4} (toward {toward:.4})",
            rec.theta_deg,
            rec.g1,
            rec.g1_toward.unwrap()
        );
        assert!((rec.g1 / marginal - 1.0).abs() < 0.01, "{} deg: G1 {} vs {marginal}", rec.theta_deg, rec.g1);
        assert!((rec.g1_toward.unwrap() / toward - 1.0).abs() < 0.01, "{} deg: toward {:?} vs {toward}", rec.theta_deg, rec.g1_toward);
    }
}

/// Reciprocity: `fr(i, o) = fr(o, i)`; traced from each of a few bins (incidence spread over the bin, so
/// that bin-to-bin averages are exactly reciprocal), the BRDF in the bin of every other, within 4
/// standard deviations of the Monte Carlo noise.
fn check_reciprocity(hf: &Heightfield, rays: usize) {
    let table = DirTable { n_theta: 12, n_phi: 24 };
    let picks = [(3usize, 2usize), (5, 7), (6, 14), (8, 20), (9, 9)];
    let dirs: Vec<[f64; 3]> = picks.iter().map(|&(it, ip)| table.centre(it * table.n_phi + ip)).collect();
    let reports: Vec<TraceReport> = dirs
        .iter()
        .map(|d| {
            let theta = d[2].acos().to_degrees();
            let phi = d[1].atan2(d[0]).to_degrees();
            run(hf, &[theta], |o| {
                o.azimuth_deg = phi;
                o.rays = rays;
                o.bounces = 32;
                o.table = table;
                o.spread_over_bin = true;
            })
        })
        .collect();
    let mut worst = 0.0f64;
    for a in 0..dirs.len() {
        for b in a + 1..dirs.len() {
            let (ka, kb) = (table.bin(dirs[a]).unwrap(), table.bin(dirs[b]).unwrap());
            let e = |r: &TraceReport, k: usize| {
                let t = &r.tables[0];
                let l = |x: [f64; 3]| ndfit::trace::LUMA.iter().zip(&x).map(|(w, v)| w * v).sum::<f64>();
                (l(t.single[k]) + l(t.multi[k]), t.var_total[k])
            };
            // Per unit incident energy e(a -> b) = Omega_perp(b) f(a, b): f = e / Omega_perp(b).
            let (eab, vab) = e(&reports[a], kb);
            let (eba, vba) = e(&reports[b], ka);
            let (fab, fba) = (eab / table.proj_solid_angle(kb), eba / table.proj_solid_angle(ka));
            let sd = (vab / table.proj_solid_angle(kb).powi(2) + vba / table.proj_solid_angle(ka).powi(2)).sqrt();
            let z = (fab - fba) / sd.max(1e-300);
            println!("reciprocity {a}<->{b}: f = {fab:.4} vs {fba:.4}, z = {z:.2}");
            worst = worst.max(z.abs());
        }
    }
    assert!(worst < 4.0, "worst |z| {worst}");
}

#[test]
fn reciprocity_on_a_gaussian_surface() {
    check_reciprocity(&gaussian(512, 0.4, 9), 1 << 18);
}

#[test]
fn reciprocity_on_a_real_scan_needs_shared() {
    let Some(dir) = crate::common::shared_scans("trace::reciprocity_on_a_real_scan_needs_shared") else { return };
    let path = dir.join("hamby44_downsampled_Barrel_1-Bullet_1-Land_1.x3p");
    let hf = ndfit::pipeline::read_preprocessed(&path, &Default::default(), &Default::default()).unwrap();
    check_reciprocity(&hf, 1 << 18);
}

/// The same seed gives the same report on one thread and on several.
#[test]
fn a_seed_gives_the_same_report_on_any_thread_count() {
    let hf = gaussian(256, 0.4, 2);
    let go = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads).build().unwrap();
        pool.install(|| run(&hf, &[10.0, 60.0], |o| o.rays = 100_000))
    };
    let (a, b) = (go(1), go(3));
    assert_eq!(serde_json::to_string(&a).unwrap(), serde_json::to_string(&b).unwrap());
    assert_eq!(a.tables, b.tables);
}

#[test]
fn hostile_scans_and_options_are_refused_or_traced_without_panic() {
    // Flat: every ray comes back mirrored, nothing masks.
    let flat = Heightfield::new(8, 8, 1e-6, 1e-6, vec![0.0; 64]).unwrap();
    let r = run(&flat, &[0.0, 45.0, 89.9], |o| o.rays = 5000);
    for rec in &r.incidences {
        assert!((rec.albedo - 1.0).abs() < 1e-12 && (rec.g1 - 1.0).abs() < 1e-12 && rec.multiple_share == 0.0, "{rec:?}");
    }
    // One pixel, one row: no cell.
    for (nx, ny) in [(1, 1), (5, 1), (1, 5)] {
        let hf = Heightfield::new(nx, ny, 1e-6, 1e-6, vec![0.0; nx * ny]).unwrap();
        let e = trace(&hf, &TraceOptions::default(), None).unwrap_err();
        assert!(e.message().contains("no cell"), "{e}");
    }
    // All NaN; NaN islands; a hole through the middle.
    let nan = Heightfield::new(8, 8, 1e-6, 1e-6, vec![f64::NAN; 64]).unwrap();
    assert!(trace(&nan, &TraceOptions::default(), None).unwrap_err().message().contains("invalid"));
    let mut holes = gaussian(64, 0.4, 4);
    for k in (0..holes.z.len()).step_by(7) {
        holes.z[k] = f64::NAN;
    }
    for i in 20..40 {
        for j in 0..64 {
            holes.z[i * 64 + j] = f64::NAN;
        }
    }
    let r = run(&holes, &[0.0, 60.0], |o| {
        o.rays = 20_000;
        o.bounces = 64;
    });
    for rec in &r.incidences {
        assert!(rec.albedo.is_finite() && (rec.albedo - 1.0).abs() < 1e-9 && rec.g1.is_finite(), "{rec:?}");
    }
    // Absurd options.
    let hf = gaussian(32, 0.4, 1);
    for bad in [vec![90.0], vec![-1.0], vec![f64::NAN], vec![f64::INFINITY], vec![]] {
        let o = TraceOptions { incidences_deg: bad.clone(), ..Default::default() };
        assert!(trace(&hf, &o, None).is_err(), "{bad:?}");
    }
    for o in [
        TraceOptions { bounces: 0, ..Default::default() },
        TraceOptions { rays: 0, ..Default::default() },
        TraceOptions { azimuth_deg: f64::NAN, ..Default::default() },
        TraceOptions { table: DirTable { n_theta: 0, n_phi: 4 }, ..Default::default() },
    ] {
        assert!(trace(&hf, &o, None).is_err(), "{o:?}");
    }
}

/// The command: the JSON's named fields, and a failure that leaves an existing output untouched.
#[test]
fn the_command_writes_the_named_fields_and_clobbers_nothing_on_error() {
    let dir = tempfile::tempdir().unwrap();
    let scan = crate::common::synth_small_gaussian(dir.path(), &[]);
    let out = dir.path().join("t.json");
    let run = |args: &[&str]| {
        std::process::Command::new(crate::common::ndfit_bin())
            .args(["trace", scan.to_str().unwrap(), "-o", out.to_str().unwrap(), "--rays", "4000"])
            .args(args)
            .output()
            .unwrap()
    };
    let ok = run(&["--incidence", "0,40,70", "--azimuth", "30"]);
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stderr));
    assert!(String::from_utf8_lossy(&ok.stderr).contains("microfacet model"));
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    let recs = v["incidences"].as_array().unwrap();
    assert_eq!(recs.len(), 3);
    for (rec, theta) in recs.iter().zip([0.0, 40.0, 70.0]) {
        assert_eq!(rec["theta_deg"].as_f64(), Some(theta));
        assert_eq!(rec["phi_deg"].as_f64(), Some(30.0));
        for key in ["albedo", "g1", "g1_smith"] {
            assert!(rec[key].as_f64().is_some_and(f64::is_finite), "{key}: {rec}");
        }
        assert!(rec["albedo_by_bounce"].as_array().is_some_and(|a| !a.is_empty()));
        assert!(rec["single"]["error"].is_number());
    }
    let before = std::fs::read(&out).unwrap();
    for bad in [&["--incidence", "95"][..], &["--incidence", "nan"], &["--bounces", "0"], &["--material", "wood"]] {
        let e = run(bad);
        assert!(!e.status.success(), "{bad:?}");
        let msg = String::from_utf8_lossy(&e.stderr);
        assert!(!msg.contains("panicked") && msg.lines().count() <= 2, "{bad:?}: {msg}");
        assert_eq!(std::fs::read(&out).unwrap(), before, "{bad:?} clobbered the output");
    }
}

/// `--plot`: a PNG of the plotted size with ink in both panels; the plane-of-incidence slice it draws
/// peaks near the mirror direction (traced and model alike); a directory as the plot is refused before
/// any work, leaving the JSON untouched.
#[test]
fn the_plot_is_written_and_decodes_at_its_size() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("g.x3p");
    let synth = std::process::Command::new(crate::common::ndfit_bin())
        .args(["synth", scan.to_str().unwrap(), "--surface", "gaussian", "--nx", "128", "--ny", "128", "--sigma-x", "0.15"])
        .output()
        .unwrap();
    assert!(synth.status.success(), "{}", String::from_utf8_lossy(&synth.stderr));
    let (out, png) = (dir.path().join("t.json"), dir.path().join("t.png"));
    let cli = |plot: &std::path::Path| {
        std::process::Command::new(crate::common::ndfit_bin())
            .args(["trace", scan.to_str().unwrap(), "-o", out.to_str().unwrap(), "--rays", "20000", "--incidence", "0,45,75"])
            .args(["--plot", plot.to_str().unwrap(), "--quiet"])
            .output()
            .unwrap()
    };
    let ok = cli(&png);
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stderr));
    let img = image::open(&png).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (ndfit::trace::PLOT_WIDTH, ndfit::trace::PLOT_HEIGHT));
    let split = ndfit::trace::PLOT_WIDTH * 3 / 5;
    for (x0, x1) in [(0, split), (split, ndfit::trace::PLOT_WIDTH)] {
        let coloured = (x0..x1).flat_map(|x| (0..img.height()).map(move |y| (x, y))).filter(|&(x, y)| {
            let p = img.get_pixel(x, y).0;
            p.iter().max().unwrap() - p.iter().min().unwrap() > 60
        });
        assert!(coloured.count() > 200, "panel {x0}..{x1} has no coloured series");
    }
    // The slice drawn, from the library on the same scan: its peak lies on the specular side near 45 deg.
    let hf = ndfit::pipeline::read_preprocessed(&scan, &Default::default(), &Default::default()).unwrap();
    let r = run(&hf, &[45.0], |o| o.rays = 1 << 16);
    let slice = ndfit::trace::plane_of_incidence(&r, 0);
    assert_eq!(slice.len(), 2 * r.table.n_theta);
    for pick in [|p: &(f64, f64, f64)| p.1, |p: &(f64, f64, f64)| p.2] {
        let peak = slice.iter().max_by(|a, b| pick(a).total_cmp(&pick(b))).unwrap();
        assert!((peak.0 - 45.0).abs() < 8.0, "peak at {} deg", peak.0);
    }
    let before = std::fs::read(&out).unwrap();
    let e = cli(dir.path());
    assert!(!e.status.success());
    assert_eq!(std::fs::read(&out).unwrap(), before);
}

/// `--tables`: one row per incidence and bin under the documented header; the bins' layout is the
/// table's (indices, edges, projected solid angles adding up to pi), and the energies add up to the
/// document's first-bounce, later-bounce and model albedos.
#[test]
fn the_tables_csv_lays_out_every_bin_and_adds_up_to_the_document() {
    let dir = tempfile::tempdir().unwrap();
    let scan = crate::common::synth_small_gaussian(dir.path(), &["--sigma-x", "0.4"]);
    let (out, csv_path) = (dir.path().join("t.json"), dir.path().join("t.csv"));
    let ok = std::process::Command::new(crate::common::ndfit_bin())
        .args(["trace", scan.to_str().unwrap(), "-o", out.to_str().unwrap(), "--tables", csv_path.to_str().unwrap()])
        .args(["--rays", "20000", "--incidence", "0,60", "--azimuth", "30", "--bins", "6x10", "--quiet"])
        .output()
        .unwrap();
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stderr));
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    let mut rd = csv::Reader::from_path(&csv_path).unwrap();
    let head: Vec<String> = rd.headers().unwrap().iter().map(String::from).collect();
    assert_eq!(head, ndfit::trace::TABLE_COLUMNS);
    let col = |name: &str| head.iter().position(|h| h == name).unwrap();
    let rows: Vec<Vec<f64>> = rd.records().map(|r| r.unwrap().iter().map(|x| x.parse::<f64>().unwrap()).collect()).collect();
    let t = DirTable { n_theta: 6, n_phi: 10 };
    assert_eq!(rows.len(), 2 * t.len());
    for (inc, rec) in v["incidences"].as_array().unwrap().iter().enumerate() {
        let part = &rows[inc * t.len()..(inc + 1) * t.len()];
        let sum = |name: &str| part.iter().map(|r| r[col(name)]).sum::<f64>();
        for (k, r) in part.iter().enumerate() {
            assert_eq!(r[col("incidence")], inc as f64);
            assert_eq!(r[col("theta_i_deg")], rec["theta_deg"].as_f64().unwrap());
            assert_eq!((r[col("bin")], r[col("i_theta")], r[col("i_phi")]), (k as f64, (k / 10) as f64, (k % 10) as f64));
            assert_eq!(r[col("theta_lo_deg")], t.theta_edge(k / 10).to_degrees());
            assert_eq!(r[col("phi_hi_deg")], t.phi_edge(k % 10 + 1).to_degrees());
            let o = [r[col("ox")], r[col("oy")], r[col("oz")]];
            assert_eq!(t.bin(o), Some(k));
            assert_eq!(r[col("proj_solid_angle")], t.proj_solid_angle(k));
            let luma = ndfit::trace::LUMA;
            let l = luma[0] * r[col("single_r")] + luma[1] * r[col("single_g")] + luma[2] * r[col("single_b")];
            assert!((l - r[col("single")]).abs() <= 1e-15);
        }
        assert!((sum("proj_solid_angle") - std::f64::consts::PI).abs() < 1e-12);
        let by = rec["albedo_by_bounce"].as_array().unwrap();
        assert!((sum("single") - by[0].as_f64().unwrap()).abs() < 1e-12);
        assert!((sum("single") + sum("multi") - rec["albedo"].as_f64().unwrap()).abs() < 1e-12);
        assert!((sum("model") - rec["single"]["albedo_model"].as_f64().unwrap()).abs() < 1e-12);
    }
}
