//! The wave BRDF's diffuse part as an RGL table (`ndfit::wave::wave_rgl`, `ndfit wave --to rgl`), written
//! to a file, read back with the crate's own reader and evaluated as Mitsuba 3's `measured` evaluates it
//! (`rgl::Measured`), against `Diffraction::brdf` of the same scan and options, and its albedo against the
//! records' `diffuse_albedo`. The surfaces: a smooth Gaussian-correlated one (its mirror share 0.54 at
//! normal incidence and 549 nm, its diffuse lobe some 15 degrees wide), and a rough one at a coarse spacing
//! whose light reaches beyond the band that retro-reflection resolves. The figures measured are in
//! data_formats/rgl.md, "The wave BRDF's table".

use ndfit::export::rgl::{check_structure, Flavour, Material, Measured, RglOptions, TensorFile};
use ndfit::synth::{gaussian_surface, GaussianParams, SynthSettings};
use ndfit::wave::{direction, wave_rgl, Diffraction, WaveOptions, WaveRglOptions, WaveTable};
use ndfit::Heightfield;

/// The table's wavelengths: the spectral reader's own red, green and blue (nm), in increasing order.
const LAMBDAS: [f64; 3] = [465.0, 549.0, 612.0];

/// 256 x 256 samples of 0.25 um, RMS slope 0.04 per axis, correlation length 1.5 um: heights of RMS 42 nm.
fn smooth() -> Heightfield {
    let s = SynthSettings { nx: 256, ny: 256, dx: 0.25e-6, dy: 0.25e-6, seed: 3, ..Default::default() };
    gaussian_surface(&s, &GaussianParams { sigma_x: 0.04, sigma_y: 0.04, theta_z: 0.0, corr_length: 1.5e-6 }).unwrap().0
}

/// 64 patches of 32 x 32 samples; a small table (10 elevations 10 degrees apart, 9 azimuths 45 apart).
fn options() -> WaveRglOptions {
    let wave = WaveOptions { wavelengths_nm: LAMBDAS.to_vec(), coherence_m: Some(8e-6), ..Default::default() };
    WaveRglOptions { wave, rgl: RglOptions { theta_i: 10, phi_i: 9, warp_res: 64, ..Default::default() } }
}

/// The table written to a file and read back as the renderer reads it.
fn written(t: &WaveTable, dir: &std::path::Path) -> (TensorFile, Measured) {
    let path = dir.join("w.bsdf");
    std::fs::write(&path, t.table.tensor.to_bytes()).unwrap();
    let back = TensorFile::parse(&std::fs::read(&path).unwrap()).unwrap();
    let m = Measured::new(&back).unwrap();
    (back, m)
}

fn f32v(v: [f64; 3]) -> [f32; 3] {
    v.map(|x| x as f32)
}

/// The `q`-quantile of `v` (sorted in place).
fn quantile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

/// `int f cos(theta_o) dw_o` of the diffraction's BRDF: a midpoint rule on 0.5 x 1 degree cells of
/// elevation and azimuth.
fn integral(d: &Diffraction, lambda_nm: f64, wi: [f64; 3]) -> f64 {
    let (nt, np) = (180, 360);
    let (dt, dp) = (90f64.to_radians() / nt as f64, 360f64.to_radians() / np as f64);
    let mut sum = 0.0;
    for it in 0..nt {
        let t = (it as f64 + 0.5) * dt;
        for ip in 0..np {
            let p = (ip as f64 + 0.5) * dp;
            let wo = [t.sin() * p.cos(), t.sin() * p.sin(), t.cos()];
            sum += d.brdf(lambda_nm, wi, wo) * t.cos() * t.sin() * dt * dp;
        }
    }
    sum
}

/// The table, read back from its file as the renderer reads it, is the diffraction's diffuse BRDF at
/// every outgoing direction of a 2 x 4 degree grid of the hemisphere where the BRDF is at least 1% of its
/// peak for that incidence, at the three wavelengths: the median relative error and the energy-weighted
/// one (`L1`: `int |f_table - f| cos / int f cos`) are bounded. On the table's incident nodes the error is
/// the bilinear reflectance between the 64 x 64 sample-space nodes; between incident nodes (10 and 45
/// degrees apart here) the renderer blends the nodes' reflectance at one sample-space point, which the
/// haze's half-vector lobe, narrowing as `cos(theta_i)` grows, follows less well, the more so near
/// grazing. The bounds hold the figures measured with a margin of about 1.5.
#[test]
fn the_table_reads_back_as_the_diffraction_brdf() {
    let hf = smooth();
    let opts = options();
    let t = wave_rgl(&hf, &opts, "a smooth Gaussian surface", None).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let (back, measured) = written(&t, dir.path());
    check_structure(&back, Flavour::Spectral).unwrap();
    assert_eq!(back.field("wavelengths").unwrap().as_f32().unwrap(), LAMBDAS.map(|l| l as f32).to_vec());
    let desc = String::from_utf8(back.field("description").unwrap().data.clone()).unwrap();
    assert!(desc.contains("smooth Gaussian") && desc.contains("mirror share") && desc.contains("+x"), "{desc}");
    // The diffraction the test reads: the same scan and options (its levels the table's).
    let d = Diffraction::new(&hf, &opts.diffraction(), None).unwrap();
    // (theta_i, phi_i, bound on the median, bound on L1): on nodes, between them, near grazing.
    let cases = [
        (0.0, 0.0, 0.005, 0.01),
        (30.0, 0.0, 0.012, 0.01),
        (60.0, 45.0, 0.025, 0.025),
        (70.0, 0.0, 0.03, 0.03),
        (80.0, 45.0, 0.04, 0.04),
        (25.0, 100.0, 0.035, 0.03),
        (45.0, 22.5, 0.1, 0.08),
        (75.0, 20.0, 0.35, 0.5),
    ];
    for (ti, pi, bound_median, bound_l1) in cases {
        let wi = direction(ti, pi);
        let mut rows: Vec<(f64, f64, f64)> = Vec::new();
        for it in 0..45 {
            for ip in 0..90 {
                let theta_o = 1.0 + 2.0 * it as f64;
                let wo = direction(theta_o, -180.0 + 4.0 * ip as f64);
                let got = measured.eval_cos_at(f32v(wi), f32v(wo), LAMBDAS.map(|l| l as f32));
                for (c, &l) in LAMBDAS.iter().enumerate() {
                    rows.push((d.brdf(l, wi, wo), got[c] as f64 / wo[2], theta_o));
                }
            }
        }
        let peak = rows.iter().map(|r| r.0).fold(0.0, f64::max);
        let mut errs: Vec<f64> = rows.iter().filter(|r| r.0 >= 0.01 * peak).map(|r| (r.1 / r.0 - 1.0).abs()).collect();
        let n = errs.len();
        let (med, p90, p99) = (quantile(&mut errs, 0.5), quantile(&mut errs, 0.9), quantile(&mut errs, 0.99));
        let weight = |r: &(f64, f64, f64)| r.2.to_radians().sin() * r.2.to_radians().cos();
        let l1 = rows.iter().map(|r| (r.1 - r.0).abs() * weight(r)).sum::<f64>() / rows.iter().map(|r| r.0 * weight(r)).sum::<f64>();
        eprintln!("wave_rgl: {ti}/{pi} deg: {n} pairs, peak {peak:.3}/sr, median {med:.4}, 90th {p90:.4}, 99th {p99:.4}, L1 {l1:.4}");
        assert!(n > 500, "{ti}/{pi}: only {n} pairs above 1% of the peak");
        assert!(med < bound_median && l1 < bound_l1, "{ti}/{pi} deg: median {med}, L1 {l1}");
    }
}

/// The albedos of `t` against the diffraction `d`: per record, the table's over `int f cos` of the
/// BRDF, and the table's over the records' `diffuse_albedo` (the sum over the FFT bins).
fn albedo_gaps(t: &WaveTable, d: &Diffraction) -> Vec<(f64, f64, f64)> {
    t.report
        .records
        .iter()
        .zip(&t.table_albedo)
        .map(|(r, &table)| {
            let int = integral(d, r.wavelength_nm, direction(r.theta_deg, r.phi_deg));
            eprintln!(
                "wave_rgl: {} nm {:>4.1} deg: specular {:.4} diffuse_albedo {:.4} int f cos {:.4} table {:.4} ({:+.2}% of int f cos, {:+.2}% of diffuse_albedo)",
                r.wavelength_nm,
                r.theta_deg,
                r.specular,
                r.diffuse_albedo,
                int,
                table,
                100.0 * (table / int - 1.0),
                100.0 * (table / r.diffuse_albedo - 1.0)
            );
            (r.theta_deg, table / int - 1.0, table / r.diffuse_albedo - 1.0)
        })
        .collect()
}

/// The table's albedo, the renderer's reading integrated over the hemisphere (material none), is the
/// integral of the BRDF it tabulates to 1% up to 80 degrees of incidence (2% at the grazing node, 89.9
/// degrees), and the records' `diffuse_albedo` to 0.5% up to 40 degrees and 8% beyond: the BRDF's
/// integral and the sum over the FFT bins differ by up to 5.7% at 60 to 70 degrees on this surface (the
/// bilinear reading between bins against the bins at their own `v_z`), and the table follows the BRDF.
/// The file carries the mirror share and both albedos beside the table.
#[test]
fn the_tables_albedo_is_the_diffuse_albedo() {
    let hf = smooth();
    let t = wave_rgl(&hf, &options(), "a smooth Gaussian surface", None).unwrap();
    let d = Diffraction::new(&hf, &options().diffraction(), None).unwrap();
    let (nl, nt) = (LAMBDAS.len(), 10);
    assert_eq!(t.report.records.len(), nl * nt);
    for (r, &diffuse) in t.report.records.iter().zip(&t.wave_diffuse) {
        assert_eq!(diffuse, r.diffuse_albedo, "material none: the diffuse part is the diffuse albedo");
    }
    for (theta, to_integral, to_bins) in albedo_gaps(&t, &d) {
        let (a, b) = if theta <= 40.0 {
            (0.01, 0.005)
        } else if theta <= 80.0 {
            (0.01, 0.08)
        } else {
            (0.02, 0.08)
        };
        assert!(to_integral.abs() < a && to_bins.abs() < b, "{theta} deg: {to_integral:+.4} of int f cos, {to_bins:+.4} of the bins");
    }
    let dir = tempfile::tempdir().unwrap();
    let (back, _) = written(&t, dir.path());
    for name in ["mirror_share", "wave_diffuse", "table_albedo"] {
        let f = back.field(name).unwrap();
        assert_eq!(f.shape, vec![nl as u64, nt as u64], "{name}");
    }
    let mirror = back.field("mirror_share").unwrap().as_f32().unwrap();
    for (m, r) in mirror.iter().zip(&t.report.records) {
        assert_eq!(*m, r.specular as f32);
    }
}

/// A rough surface at a coarse spacing (RMS slope 0.1, heights of RMS 0.35 um, 0.5 um spacing): its light
/// reaches half vectors beyond the band that retro-reflection resolves (`|2 m_x| <= lambda / (2 dx)`),
/// where the warp's NDF continues at smaller `wi.m`; the table's albedo stays the BRDF's integral to 1%
/// (2% at 89.9 degrees). The records' `diffuse_albedo`, the sum over the bins, is within 1% of that integral
/// except at 70 degrees (8%), held to 10%.
#[test]
fn a_rough_coarse_scan_keeps_its_albedo() {
    let s = SynthSettings { nx: 256, ny: 256, dx: 0.5e-6, dy: 0.5e-6, seed: 5, ..Default::default() };
    let hf = gaussian_surface(&s, &GaussianParams { sigma_x: 0.1, sigma_y: 0.1, theta_z: 0.0, corr_length: 5e-6 }).unwrap().0;
    let mut opts = options();
    opts.wave.wavelengths_nm = vec![549.0];
    opts.wave.coherence_m = None;
    let t = wave_rgl(&hf, &opts, "a rough Gaussian surface", None).unwrap();
    let d = Diffraction::new(&hf, &opts.diffraction(), None).unwrap();
    for (theta, to_integral, to_bins) in albedo_gaps(&t, &d) {
        let bound = if theta <= 80.0 { 0.01 } else { 0.02 };
        assert!(to_integral.abs() < bound && to_bins.abs() < 0.1, "{theta} deg: {to_integral:+.4} of int f cos, {to_bins:+.4} of the bins");
    }
}

/// A conductor's Fresnel factor is applied at the half vector: the copper table over the mirror's, per
/// wavelength, is copper's reflectance at `wi.m` (the warps are the same, so the reflectance is too).
#[test]
fn the_conductor_multiplies_at_the_half_vector() {
    let hf = smooth();
    let mut opts = options();
    opts.rgl = RglOptions { theta_i: 4, phi_i: 5, warp_res: 16, ndf_res: Some(64), ..opts.rgl };
    let none = wave_rgl(&hf, &opts, "s", None).unwrap();
    opts.wave.material = Material::Cu;
    let cu = wave_rgl(&hf, &opts, "s", None).unwrap();
    let (a, b) = (Measured::new(&none.table.tensor).unwrap(), Measured::new(&cu.table.tensor).unwrap());
    let wi = direction(30.0, 0.0);
    for wo in [direction(25.0, 180.0), direction(40.0, 170.0), direction(10.0, 90.0)] {
        let h: Vec<f64> = (0..3).map(|k| wi[k] + wo[k]).collect();
        let c = (0..3).map(|k| wi[k] * h[k]).sum::<f64>() / h.iter().map(|x| x * x).sum::<f64>().sqrt();
        let (fa, fb) =
            (a.eval_cos_at(f32v(wi), f32v(wo), LAMBDAS.map(|l| l as f32)), b.eval_cos_at(f32v(wi), f32v(wo), LAMBDAS.map(|l| l as f32)));
        for (k, &l) in LAMBDAS.iter().enumerate() {
            let want = Material::Cu.fresnel(c, l);
            assert!((fb[k] as f64 / fa[k] as f64 - want).abs() < 2e-3 * want, "{l} nm: {} against F {want}", fb[k] / fa[k]);
        }
    }
    // Copper's diffuse part is less than the mirror's, by about its reflectance near normal incidence.
    let blue = |t: &WaveTable| t.table_albedo[0];
    assert!(blue(&cu) < blue(&none) * 0.8, "{} {}", blue(&cu), blue(&none));
}

fn ndfit(args: &[&str]) -> (i32, String) {
    let o = std::process::Command::new(crate::common::ndfit_bin()).args(args).output().unwrap();
    (o.status.code().unwrap_or(-1), String::from_utf8_lossy(&o.stderr).into_owned())
}

/// `ndfit wave --to rgl` writes the table and its sidecar report, says the mirror share per wavelength,
/// and refuses bad input in one line naming the file, exit 2, writing neither.
#[test]
fn the_command_writes_the_table_and_its_report_or_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("s.x3p");
    ndfit::io::write_x3p(&scan, &smooth()).unwrap();
    let (s, out) = (scan.to_str().unwrap(), dir.path().join("t.bsdf"));
    let o = out.to_str().unwrap();
    let sidecar = dir.path().join("t.bsdf.json");
    let small = ["--coherence", "16", "--theta-i", "4", "--phi-i", "5", "--warp-res", "16", "--ndf-res", "64"];
    let (code, err) = ndfit(&[&["wave", s, "--to", "rgl", "-o", o, "--wavelength", "450,550,650"][..], &small].concat());
    assert_eq!(code, 0, "{err}");
    let t = TensorFile::parse(&std::fs::read(&out).unwrap()).unwrap();
    check_structure(&t, Flavour::Spectral).unwrap();
    assert_eq!(t.field("wavelengths").unwrap().as_f32().unwrap(), vec![450.0, 550.0, 650.0]);
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&sidecar).unwrap()).unwrap();
    assert_eq!(v["schema"], "ndfit.wave/1");
    assert_eq!(v["table"]["file"], "t.bsdf");
    let records = v["records"].as_array().unwrap();
    assert_eq!(records.len(), 12);
    let thetas: Vec<f64> = records[..4].iter().map(|r| r["theta_deg"].as_f64().unwrap()).collect();
    assert_eq!(thetas, vec![0.0, 30.0, 60.0, 89.9]);
    for r in records {
        for key in ["specular", "diffuse_albedo", "albedo", "table_albedo", "wave_diffuse"] {
            assert!(r[key].is_number(), "{key} missing in {r}");
        }
    }
    for nm in ["450 nm", "550 nm", "650 nm"] {
        assert_eq!(err.lines().filter(|l| l.contains("mirror share at") && l.contains(nm)).count(), 1, "{err}");
    }
    std::fs::remove_file(&out).unwrap();
    std::fs::remove_file(&sidecar).unwrap();
    let bad: [(&[&str], &str); 8] = [
        (&["wave", s, "--to", "rgl"], "-o"),
        (&["wave", s, "--to", "rgl", "-o", o, "--incidence", "0,40"], "--incidence"),
        (&["wave", s, "--to", "rgl", "-o", o, "--grid-out", "g"], "--grid-out"),
        (&["wave", s, "--to", "rgl", "-o", o, "--warp-res", "1"], "warp_res"),
        (&["wave", s, "--to", "rgl", "-o", o, "--wavelength", "0"], "wavelength"),
        (&["wave", s, "--to", "rgl", "-o", o, "--coherence", "1000"], "larger than the scan"),
        (&["wave", s, "--to", "rgl", "-o", o, "--material", "Zn"], "Zn"),
        (&["wave", s, "--to", "rgl", "-o", "/nonexistent-folder/x.bsdf"], "does not exist"),
    ];
    for (args, what) in bad {
        let (code, err) = ndfit(args);
        assert_eq!(code, 2, "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{args:?}: {err}");
        assert!(err.contains(what), "{args:?}: {err}");
        assert!(!out.exists() && !sidecar.exists(), "{args:?} wrote something");
    }
}

/// `--with-mirror` (`WaveTable::blend_with_mirror`): the table as the haze of a blend with the smooth
/// conductor, `(1 - w) mirror + w (table / w)`. Held to: `w` the cosine-weighted hemispherical mean of
/// `1 - exp(-b cos^2 theta)` by quadrature, `b` the least-squares optimum of the records' `ln s` at the
/// wavelength nearest 550 nm (no 1% step of it fits better); the renderer's reading of the blended table
/// times `w` is the plain table's, to the `f32` arithmetic of its reading (1e-5); the file says it.
#[test]
fn the_blended_table_is_the_plain_table_at_one_over_its_weight() {
    let hf = smooth();
    let mut opts = options();
    opts.rgl = RglOptions { theta_i: 6, phi_i: 5, warp_res: 16, ndf_res: Some(64), ..opts.rgl };
    let plain = wave_rgl(&hf, &opts, "s", None).unwrap();
    let mut blended = plain.clone();
    let b = blended.blend_with_mirror().unwrap();
    // The form's b: least squares of -ln s against cos^2 theta (through 0) at 549 nm, shares >= 0.01.
    let pts: Vec<(f64, f64)> = plain
        .report
        .records
        .iter()
        .filter(|r| r.wavelength_nm == 549.0 && r.specular >= 0.01)
        .map(|r| (r.theta_deg.to_radians().cos().powi(2), -r.specular.ln()))
        .collect();
    assert!(pts.len() >= 4, "{pts:?}");
    let sq = |b: f64| pts.iter().map(|(x, y)| (y - b * x).powi(2)).sum::<f64>();
    assert!(sq(b.b) < sq(b.b * 1.01) && sq(b.b) < sq(b.b * 0.99), "b = {}", b.b);
    let n = 100_000;
    let mean: f64 = (0..n).map(|k| (k as f64 + 0.5) / n as f64).map(|mu| (1.0 - (-b.b * mu * mu).exp()) * 2.0 * mu / n as f64).sum();
    assert!((b.weight - mean).abs() < 1e-8 && (b.scale * b.weight - 1.0).abs() < 1e-12, "{b:?} against {mean}");
    // The surface's mirror share is 0.54 at normal incidence: a haze of a few tenths.
    assert!(b.weight > 0.1 && b.weight < 0.9, "{b:?}");
    let (p, q) = (Measured::new(&plain.table.tensor).unwrap(), Measured::new(&blended.table.tensor).unwrap());
    let mut compared = 0;
    for (ti, pi) in [(0.0, 0.0), (20.0, 40.0), (55.0, 200.0), (80.0, 300.0)] {
        let wi = f32v(direction(ti, pi));
        for (to, po) in [(5.0, 180.0), (25.0, 200.0), (50.0, 10.0), (70.0, 120.0)] {
            let wo = f32v(direction(to, po));
            let (a, c) = (p.eval_cos_at(wi, wo, LAMBDAS.map(|l| l as f32)), q.eval_cos_at(wi, wo, LAMBDAS.map(|l| l as f32)));
            for k in 0..3 {
                let want = a[k] as f64;
                assert!(
                    (c[k] as f64 * b.weight - want).abs() <= 1e-5 * want.abs() + 1e-30,
                    "{ti}/{pi} -> {to}/{po}: {} times w {} against {want}",
                    c[k],
                    b.weight
                );
                compared += usize::from(want > 0.0);
            }
        }
    }
    assert!(compared > 20, "{compared} positive readings");
    // ndfit's renderer draws the blended table as the renderers' blends do: the table at w (the plain
    // table's values) and the mirror at 1 - w, whatever the angle.
    use ndfit::render::Brdf;
    let (pw, bw) = (ndfit::export::MirrorBrdf::wave(&plain.table.tensor, Material::None).unwrap(), {
        ndfit::export::MirrorBrdf::wave(&blended.table.tensor, Material::None).unwrap()
    });
    for t in [0.0, 35.0, 70.0] {
        let wi = nalgebra::Vector3::from(direction(t, 30.0));
        let wo = nalgebra::Vector3::from(direction(t * 0.5 + 10.0, 200.0));
        let (x, y) = (pw.eval(wi, wo), bw.eval(wi, wo));
        assert!((0..3).all(|c| (x[c] - y[c]).abs() <= 1e-5 * x[c].abs()), "{t} deg: {x:?} against {y:?}");
        assert!(bw.mirror(wi).iter().all(|&m| (m - (1.0 - b.weight)).abs() < 1e-7), "{:?}", bw.mirror(wi));
    }
    let t = &blended.table.tensor;
    assert_eq!(t.field("blend_weight").unwrap().as_f32().unwrap(), vec![b.weight as f32]);
    let description = String::from_utf8_lossy(&t.field("description").unwrap().data).into_owned();
    assert!(description.contains("for a blend that gives it weight"), "{description}");
}

/// `ndfit wave --to rgl --with-mirror` writes the blended table, its weight in the report, and prints
/// Mitsuba 3's `blendbsdf` (weight w, a GGX conductor of alpha 1e-4 for the mirror, `measured` of the file)
/// and pbrt-v4's `mix` (amount w).
#[test]
fn the_command_prints_the_blend_that_loads_the_table() {
    let dir = tempfile::tempdir().unwrap();
    let scan = dir.path().join("s.x3p");
    ndfit::io::write_x3p(&scan, &smooth()).unwrap();
    let out = dir.path().join("haze.bsdf");
    let args = ["wave", scan.to_str().unwrap(), "--to", "rgl", "--with-mirror", "-o", out.to_str().unwrap(), "--material", "Al"];
    let small = ["--coherence", "16", "--theta-i", "6", "--phi-i", "5", "--warp-res", "16", "--ndf-res", "64"];
    let o = std::process::Command::new(crate::common::ndfit_bin()).args([&args[..], &small].concat()).output().unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    assert_eq!(o.status.code(), Some(0), "{stderr}");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.path().join("haze.bsdf.json")).unwrap()).unwrap();
    let w = v["blend"]["weight"].as_f64().unwrap();
    assert!(w > 0.0 && w < 1.0 && (v["blend"]["scale"].as_f64().unwrap() * w - 1.0).abs() < 1e-12, "{}", v["blend"]);
    let t = TensorFile::parse(&std::fs::read(&out).unwrap()).unwrap();
    assert_eq!(t.field("blend_weight").unwrap().as_f32().unwrap(), vec![w as f32]);
    // Mitsuba: the XML element, parsed.
    let xml = &stdout[stdout.find("<bsdf").unwrap()..stdout.rfind("</bsdf>").unwrap() + "</bsdf>".len()];
    let mut reader = quick_xml::Reader::from_str(xml);
    let (mut types, mut weight, mut filename, mut material, mut alpha) = (Vec::new(), None, None, None, None);
    loop {
        match reader.read_event().unwrap() {
            quick_xml::events::Event::Eof => break,
            quick_xml::events::Event::Start(e) | quick_xml::events::Event::Empty(e) => {
                let attr = |k: &str| {
                    e.attributes()
                        .flatten()
                        .find(|a| a.key.as_ref() == k)
                        .map(|a| a.normalized_value(quick_xml::XmlVersion::Implicit1_0).unwrap().into_owned())
                };
                match (e.name().as_ref(), attr("name").as_deref()) {
                    ("bsdf", _) => types.push(attr("type").unwrap()),
                    ("float", Some("weight")) => weight = attr("value"),
                    ("string", Some("filename")) => filename = attr("value"),
                    ("string", Some("material")) => material = attr("value"),
                    ("float", Some("alpha")) => alpha = attr("value"),
                    _ => {}
                }
            }
            _ => {}
        }
    }
    // The mirror as a GGX lobe of alpha 1e-4 (Mitsuba over-counts a blend of its delta conductor and `measured`).
    assert_eq!(types, ["blendbsdf", "roughconductor", "measured"], "{xml}");
    assert_eq!(alpha.unwrap().parse::<f64>().unwrap(), 1e-4);
    assert_eq!(weight.unwrap().parse::<f64>().unwrap(), w);
    assert_eq!(filename.as_deref(), out.to_str());
    assert_eq!(material.as_deref(), Some("Al"));
    // pbrt-v4: the mix of the two named materials, amount w, the conductor with aluminium's spectra.
    let pbrt = &stdout[stdout.find("MakeNamedMaterial").unwrap()..];
    assert!(pbrt.contains("\"metal-Al-eta\"") && pbrt.contains("\"string type\" [ \"measured\" ]"), "{pbrt}");
    let amount = pbrt.split("\"float amount\" [ ").nth(1).unwrap().split(' ').next().unwrap();
    assert_eq!(amount.parse::<f64>().unwrap(), w);
    // A flat scan has no haze to blend: one line naming the file, exit 2, nothing written.
    let flat = dir.path().join("flat.x3p");
    ndfit::io::write_x3p(&flat, &Heightfield::new(128, 128, 2.5e-7, 2.5e-7, vec![0.0; 128 * 128]).unwrap()).unwrap();
    let none = dir.path().join("none.bsdf");
    let args = ["wave", flat.to_str().unwrap(), "--to", "rgl", "--with-mirror", "-o", none.to_str().unwrap()];
    let o = std::process::Command::new(crate::common::ndfit_bin()).args([&args[..], &small].concat()).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.trim_end().lines().count() == 1 && err.contains("flat.x3p") && err.contains("the smooth conductor alone"), "{err}");
    assert!(!none.exists() && !dir.path().join("none.bsdf.json").exists());
}
