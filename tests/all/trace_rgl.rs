//! The traced BRDF as an RGL table (`ndfit::trace::trace_rgl`, `ndfit trace --to rgl`), read back as
//! Mitsuba 3's `measured` evaluates it (`rgl::Measured`): one bounce on a Gaussian surface against the
//! microfacet table of the same scan, and the white furnace of all bounces against the traced albedo.
//! The expected values come from the microfacet table, Smith's closed forms and a quadrature written
//! here, never from the traced table's own figures.

use nalgebra::Vector3;
use ndfit::export::rgl::{self, Material, Measured, RglOptions};
use ndfit::models::{Beckmann, Masking, Model, Ndf};
use ndfit::synth::{gaussian_surface, GaussianParams, SynthSettings};
use ndfit::trace::{trace_rgl, TracedRglOptions, TracedTable};
use ndfit::{Heightfield, ModelChoice, Options, Pipeline};

/// A periodic Gaussian surface of RMS slope `sigma` per axis (Beckmann truth, `alpha = sqrt(2) sigma`),
/// correlation length 16 cells: the triangles' forward-difference slopes have a variance larger than the
/// central differences of the NDF by about `1.5 / 16^2 = 0.6%` (docs/TRACE.md).
fn gaussian(n: usize, sigma: f64, seed: u64) -> Heightfield {
    let s = SynthSettings { nx: n, ny: n, dx: 1e-6, dy: 1e-6, seed, ..Default::default() };
    let p = GaussianParams { sigma_x: sigma, sigma_y: sigma, theta_z: 0.0, corr_length: 16e-6 };
    gaussian_surface(&s, &p).unwrap().0
}

/// The scan's regularized NDF as `export SCAN --to rgl` makes it: the fit that fills its tails.
fn scan_ndf(hf: &Heightfield) -> (ndfit::Outcome, Model, f64) {
    let o = Pipeline::new(Options { model: ModelChoice::Auto, render: None, ..Options::default() }).run(hf.clone(), "gaussian").unwrap();
    let fit = o.fit.table_model().unwrap();
    let max_theta = o.fit.quality.max_theta_deg;
    (o, fit, max_theta)
}

fn traced(hf: &Heightfield, rgl_opts: RglOptions, paths: usize, bounces: usize) -> TracedTable {
    let (o, fit, max_theta) = scan_ndf(hf);
    let reg = rgl::Regularized::new(&o.ndf, &fit, max_theta);
    let opts = TracedRglOptions { rgl: rgl_opts, paths, bounces, seed: 7, ..Default::default() };
    trace_rgl(hf, &|m| reg.d(m), &|m| fit.d(m), "test", &opts, None).unwrap()
}

fn dir(theta_deg: f64, phi_deg: f64) -> [f32; 3] {
    let (t, p) = (theta_deg.to_radians(), phi_deg.to_radians());
    [(t.sin() * p.cos()) as f32, (t.sin() * p.sin()) as f32, t.cos() as f32]
}

fn lum(v: [f32; 3]) -> f64 {
    0.2126 * v[0] as f64 + 0.7152 * v[1] as f64 + 0.0722 * v[2] as f64
}

/// One bounce, F = 1: the traced table read as the renderer reads it matches the microfacet table of the
/// same scan (separable Smith from the same NDF) where that BRDF is at least 1% of its peak, at 0, 30 and
/// 60 degrees. Their ratio should be Smith's height-correlated `G2` over the separable `G1 G1`
/// (`(1 + L_i)(1 + L_o) / (1 + L_i + L_o)`, Heitz 2014 eq. 98-99; the traced surface is Smith's regime),
/// which is divided out. What may remain: the Monte Carlo noise (the median of `|N(0, s)|` is `0.674 s`,
/// `s` the nodes' median relative standard error, which a blend of four nodes does not exceed), and the
/// triangles' NDF against the table's (forward against central differences: `d ln D / d ln alpha^2 =
/// x - 1`, `x = tan^2 / alpha^2 <= ln 100` where the BRDF is within 1% of its peak, times the 0.6% of
/// the variances, at most 2.2%).
#[test]
fn one_bounce_matches_the_microfacet_table_of_the_same_scan() {
    let hf = gaussian(512, 0.3, 5);
    let ropts = RglOptions { theta_i: 4, phi_i: 3, warp_res: 16, material: Material::None, ..Default::default() };
    let t = traced(&hf, ropts, 1 << 18, 1);
    let (o, fit, max_theta) = scan_ndf(&hf);
    let reg = rgl::Regularized::new(&o.ndf, &fit, max_theta);
    let mf = rgl::tabulate_guided(&|m| reg.d(m), &|m| fit.d(m), "mf", &ropts, true).unwrap();
    let (a, b) = (Measured::new(&t.table.tensor).unwrap(), Measured::new(&mf.tensor).unwrap());
    let alpha = 0.3 * 2f64.sqrt();
    let beckmann = Beckmann::new(alpha, alpha, 0.0).unwrap();
    let lambda = |theta_deg: f64| beckmann.lambda(Vector3::new(theta_deg.to_radians().sin(), 0.0, theta_deg.to_radians().cos()));
    let mut noise: Vec<f64> = t.nodes.iter().map(|r| r.noise).collect();
    noise.sort_by(f64::total_cmp);
    let s = noise[noise.len() / 2];
    let bound = 0.674 * s + 0.022;
    for theta_i in [0.0, 30.0, 60.0] {
        let wi = dir(theta_i, 0.0);
        let mut rows = Vec::new();
        for it in 0..44 {
            for ip in 0..72 {
                let (to, po) = (1.0 + 2.0 * it as f64, -180.0 + 5.0 * ip as f64);
                let wo = dir(to, po);
                let (li, lo) = (lambda(theta_i), lambda(to));
                let hc = (1.0 + li) * (1.0 + lo) / (1.0 + li + lo);
                rows.push((lum(a.eval_cos(wi, wo)), lum(b.eval_cos(wi, wo)), hc));
            }
        }
        let peak = rows.iter().map(|r| r.1).fold(0.0, f64::max);
        let mut err: Vec<f64> = rows.iter().filter(|r| r.1 >= 0.01 * peak).map(|r| (r.0 / (r.1 * r.2) - 1.0).abs()).collect();
        err.sort_by(f64::total_cmp);
        let median = err[err.len() / 2];
        println!("one bounce at {theta_i} deg: median |traced / (microfacet G2/G1G1) - 1| {median:.4} over {} directions (bound {bound:.4}, node noise {s:.4})", err.len());
        assert!(median <= bound, "{theta_i} deg: median {median} > {bound}");
    }
}

/// `int eval_cos(wi, wo) dwo` over the hemisphere, a midpoint rule of `n x 2n` points in
/// `(u_theta = sqrt(2 theta / pi), phi)` (the table's own elevation warp; `dw = pi^2 u sin(theta) du dphi`).
fn albedo_by_quadrature(m: &Measured, wi: [f32; 3], n: usize) -> f64 {
    let mut sum = 0.0;
    for a in 0..n {
        let u = (a as f64 + 0.5) / n as f64;
        let theta = u * u * std::f64::consts::FRAC_PI_2;
        let jac = std::f64::consts::PI * u * theta.sin() * (1.0 / n as f64) * (2.0 * std::f64::consts::PI / (2 * n) as f64);
        for b in 0..2 * n {
            let phi = -std::f64::consts::PI + 2.0 * std::f64::consts::PI * (b as f64 + 0.5) / (2 * n) as f64;
            let wo = dir(theta.to_degrees(), phi.to_degrees());
            sum += lum(m.eval_cos(wi, wo)) * jac;
        }
    }
    sum
}

/// The white furnace: F = 1, every bounce. The traced albedo is 1 to the tracer's furnace tolerance
/// (0.2%). The table conserves the energy splatted by construction (each node holds its tent's energy
/// over its tent's `int T / J`, and the tents sum to one), so the table's albedo, integrated here over the
/// hemisphere as a renderer evaluates it, may differ from the traced one only by that 0.2% and by
/// quadrature: this rule's error, estimated as three times its change from half the points (a midpoint
/// rule's error falls at least as fast as its step), and the library's rule for `int T / J` (which its
/// `table_albedo`, a third rule, checks: within 0.2% of this one).
#[test]
fn white_furnace_of_the_traced_table() {
    let hf = gaussian(256, 0.5, 3);
    let ropts = RglOptions { theta_i: 3, phi_i: 3, warp_res: 32, material: Material::None, ..Default::default() };
    let t = traced(&hf, ropts, 1 << 16, 100);
    let m = Measured::new(&t.table.tensor).unwrap();
    for r in t.nodes.iter().filter(|r| r.theta_deg < 89.0) {
        assert!((r.albedo - 1.0).abs() < 0.002, "traced albedo {} at {}", r.albedo, r.theta_deg);
        assert!(r.uncarried < 1e-3, "uncarried {} at {}", r.uncarried, r.theta_deg);
        let wi = dir(r.theta_deg, r.phi_deg);
        let (q, coarse) = (albedo_by_quadrature(&m, wi, 96), albedo_by_quadrature(&m, wi, 48));
        let tol = 0.002 + 3.0 * (q - coarse).abs();
        println!(
            "furnace at {:.0}/{:.0} deg: traced {:.5}, table {q:.5} (half the points {coarse:.5}, the library's rule {:.5}); tolerance {tol:.4}",
            r.theta_deg, r.phi_deg, r.albedo, r.table_albedo
        );
        assert!((q - r.table_albedo).abs() < 0.002, "{q} vs {}", r.table_albedo);
        assert!((q - r.albedo).abs() <= tol, "table {q} vs traced {} at {}", r.albedo, r.theta_deg);
    }
}

/// `ndfit trace --to rgl`: a file the format's check and the renderer's reader accept, with the traced
/// fields; the same seed writes the same bytes; bad options and a missing `-o` are refused in a line or
/// two, leaving what was written untouched.
#[test]
fn the_command_writes_a_table_and_clobbers_nothing_on_error() {
    let dir = tempfile::tempdir().unwrap();
    let scan = crate::common::synth_small_gaussian(dir.path(), &[]);
    let out = dir.path().join("t.bsdf");
    let run = |args: &[&str]| {
        std::process::Command::new(crate::common::ndfit_bin())
            .args(["trace", scan.to_str().unwrap(), "--to", "rgl", "--theta-i", "3", "--phi-i", "3", "--warp-res", "8"])
            .args(["--paths", "4096", "--ndf-res", "32"])
            .args(args)
            .output()
            .unwrap()
    };
    let ok = run(&["-o", out.to_str().unwrap(), "--material", "Au"]);
    assert!(ok.status.success(), "{}", String::from_utf8_lossy(&ok.stderr));
    let before = std::fs::read(&out).unwrap();
    let t = ndfit::export::rgl::TensorFile::parse(&before).unwrap();
    rgl::check_structure(&t, rgl::Flavour::Rgb).unwrap();
    Measured::new(&t).unwrap();
    for name in ["traced_albedo", "uncarried", "table_albedo"] {
        let f = t.field(name).unwrap_or_else(|| panic!("no {name}"));
        assert_eq!(f.shape, vec![3, 3], "{name}");
    }
    let again = dir.path().join("u.bsdf");
    assert!(run(&["-o", again.to_str().unwrap(), "--material", "Au"]).status.success());
    assert_eq!(std::fs::read(&again).unwrap(), before, "the same seed wrote other bytes");
    let o = out.to_str().unwrap();
    for bad in
        [&["-o", o, "--warp-res", "2"][..], &["-o", o, "--paths", "0"], &["-o", o, "--plot", "x.png"], &[], &["-o", o, "--to", "csv"]]
    {
        let e = run(bad);
        assert!(!e.status.success(), "{bad:?}");
        let msg = String::from_utf8_lossy(&e.stderr);
        assert!(!msg.contains("panicked") && msg.lines().count() <= 2, "{bad:?}: {msg}");
        assert_eq!(std::fs::read(&out).unwrap(), before, "{bad:?} clobbered the output");
    }
}
