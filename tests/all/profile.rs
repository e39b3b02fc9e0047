//! Profiles (`pipeline::Profile`): a scan under three samples across one axis is fitted as its profiles
//! extruded across them, held to a second route (the areal scan of that extruded surface), to the closed
//! form `alpha = sqrt(2) R_dq` of an isotropic Beckmann surface, and to the areal fit of an isotropic
//! surface its rows were cut from.

use std::f64::consts::PI;
use std::process::Command;

use ndfit::models::{ModelChoice, ModelId};
use ndfit::ndf::NdfOptions;
use ndfit::preprocess::Despike;
use ndfit::synth::{gaussian_surface, GaussianParams, SynthSettings};
use ndfit::{Heightfield, Options, Pipeline};

use crate::common::ndfit_bin;

/// A smooth random profile: white noise (a fixed LCG, Box-Muller) filtered by a Gaussian of `corr` samples,
/// `rms` metres RMS.
fn profile(n: usize, corr: f64, rms: f64, seed: u64) -> Vec<f64> {
    let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    let mut uniform = || {
        s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((s >> 11) as f64 + 0.5) / (1u64 << 53) as f64
    };
    let half = (4.0 * corr) as usize;
    let white: Vec<f64> = (0..n + 2 * half).map(|_| (-2.0 * uniform().ln()).sqrt() * (2.0 * PI * uniform()).cos()).collect();
    let kernel: Vec<f64> = (0..=2 * half).map(|k| (-0.5 * ((k as f64 - half as f64) / corr).powi(2)).exp()).collect();
    let out: Vec<f64> = (0..n).map(|i| kernel.iter().enumerate().map(|(k, w)| w * white[i + k]).sum()).collect();
    let sd = (out.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
    out.iter().map(|x| x * rms / sd).collect()
}

/// `R_dq`: the RMS of the central-difference slopes of `rows` (each a profile of spacing `dx`).
fn rdq(rows: &[&[f64]], dx: f64) -> f64 {
    let s: Vec<f64> = rows.iter().flat_map(|r| r.windows(3).map(|w| (w[2] - w[0]) / (2.0 * dx))).collect();
    (s.iter().map(|x| x * x).sum::<f64>() / s.len() as f64).sqrt()
}

fn fixed(model: ModelId) -> Options {
    let mut o = Options { model: ModelChoice::Model(model), render: None, ..Options::default() };
    o.ndf = NdfOptions { cells_across: Some(65), ..NdfOptions::default() };
    o.preprocess.despike = Despike::None;
    // A profile's tail is not tested for resolution (it takes slopes across): neither is the areal scan's here.
    o.fit.tail = ndfit::fit::TailRule::All;
    o
}

#[test]
fn a_profile_fits_as_the_areal_scan_of_its_extrusion() {
    // 1 um heights with 8 um correlation at 1 um spacing, tilted and offset: the form goes as it would from the
    // areal scan, and the NDF of one row extruded is the areal scan's, every row the same. So for a column, and
    // for a column that is a grid's only valid points (no areal stencil).
    let (n, dx) = (2048, 1e-6);
    let p: Vec<f64> = profile(n, 8.0, 1e-6, 1).iter().enumerate().map(|(j, h)| h + 0.05 * j as f64 * dx + 3.0).collect();
    // The areal scans: 64 rows of the profile, and 64 columns of it.
    let rows = Heightfield::new(n, 64, dx, dx, (0..64).flat_map(|_| p.iter().copied()).collect()).unwrap();
    let cols = Heightfield::new(64, n, dx, dx, p.iter().flat_map(|&h| std::iter::repeat_n(h, 64)).collect()).unwrap();
    let row = Heightfield::new(n, 1, dx, dx, p.clone()).unwrap();
    let col = Heightfield::new(1, n, dx, dx, p.clone()).unwrap();
    // A trace stored in an areal grid: one valid column of 32, the rest invalid.
    let grid: Vec<f64> = p.iter().flat_map(|&h| (0..32).map(move |j| if j == 5 { h } else { f64::NAN })).collect();
    let in_grid = Heightfield::new(32, n, dx, dx, grid).unwrap();
    let cols2 = Heightfield::new(64, n, dx, dx, p.iter().flat_map(|&h| std::iter::repeat_n(h, 64)).collect()).unwrap();
    for (what, areal, scan) in [("row", rows, row), ("column", cols, col), ("column in a grid", cols2, in_grid)] {
        let mut opts = fixed(ModelId::GgxAniso);
        let a = Pipeline::new(opts.clone()).run(areal, "areal").unwrap();
        // The same bins: the areal scan's frame (a robust one from a strided sample of its normals).
        opts.ndf.frame = Some(a.ndf.frame);
        let b = Pipeline::new(opts).run(scan, what).unwrap();
        let (fa, fb) = (&a.fit, &b.fit);
        for k in ["alpha_x", "alpha_y", "theta_z"] {
            let (x, y) = (fa.params[k], fb.params[k]);
            assert!((x - y).abs() <= 1e-6 * x.abs().max(1e-3), "{what}: {k} {y} against the areal scan's {x}");
        }
        assert!(b.fit.warnings.iter().any(|w| w.starts_with("profile: a profile (1 ")), "{what}: {:?}", b.fit.warnings);
        // Never `ok`: what the profile did not measure is said among the reasons.
        assert_ne!(b.fit.quality.verdict, ndfit::fit::Verdict::Ok, "{what}");
        assert!(b.fit.quality.reasons.iter().any(|r| r.starts_with("a profile (1 ")), "{what}: {:?}", b.fit.quality.reasons);
    }
}

#[test]
fn a_profile_says_the_isotropic_beckmann_lobe_its_slopes_give() {
    // An isotropic Gaussian surface (RMS slope 0.1 per axis, Beckmann's alpha sqrt(2) 0.1): two of its rows,
    // fitted as a profile, name sqrt(2) R_dq, which the areal scan's Beckmann fit agrees with.
    let s = SynthSettings { nx: 1024, ny: 1024, seed: 11, ..SynthSettings::default() };
    let g = GaussianParams { sigma_x: 0.1, sigma_y: 0.1, theta_z: 0.0, corr_length: 8.0 * s.dx };
    let areal = gaussian_surface(&s, &g).unwrap().0;
    let (n, dx) = (areal.nx, areal.dx);
    let z: Vec<f64> = areal.z[300 * n..302 * n].to_vec();
    let want = std::f64::consts::SQRT_2 * rdq(&[&z[..n], &z[n..]], dx);
    let two = Heightfield::new(n, 2, dx, areal.dy, z).unwrap();
    let out = Pipeline::new(Options::default()).run(two, "two rows").unwrap();
    let line =
        out.fit.warnings.iter().find(|w| w.starts_with("profile: a profile (2 rows of 1024 samples)")).expect("the profile's warning");
    let said: f64 = line.rsplit("= ").next().unwrap().split_whitespace().next().unwrap().parse().unwrap();
    assert!((said - want).abs() <= 5e-5, "said {said}, sqrt(2) R_dq = {want}");
    assert!(out.fit.selection.as_ref().and_then(|s| s.answer.as_ref()).is_some(), "an answer");
    let beckmann = Pipeline::new(fixed(ModelId::Beckmann)).run(areal, "areal").unwrap().fit.params["alpha"];
    eprintln!("two rows: sqrt(2) R_dq {said:.4}; the areal Beckmann fit {beckmann:.4}; the truth {:.4}", std::f64::consts::SQRT_2 * 0.1);
    assert!((said / beckmann - 1.0).abs() < 0.1, "two rows say {said}, the areal Beckmann fit {beckmann}");
}

#[test]
fn the_cli_answers_a_profile_where_it_refused_it() {
    let dir = std::env::temp_dir().join(format!("ndfit-profile-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = profile(1024, 6.0, 1e-6, 7);
    let csv = dir.join("profile.csv");
    std::fs::write(&csv, p.iter().map(|h| format!("{h:e}")).collect::<Vec<_>>().join(",") + "\n").unwrap();
    let out = dir.join("fit.json");
    let run = Command::new(ndfit_bin())
        .args(["fit", csv.to_str().unwrap(), "--dx", "1e-6", "--z-scale", "1", "-o", out.to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&run.stderr);
    assert!(run.status.success(), "{err}");
    assert!(err.contains("profile: a profile (1 row of 1024 samples)") && err.contains("answer "), "{err}");
    let v: serde_json::Value = serde_json::from_slice(&std::fs::read(&out).unwrap()).unwrap();
    assert_eq!(v["optics"]["regime"], "geometric", "{}", v["optics"]["why"]);
    assert!(v["selection"]["answer"].is_string());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_rough_profile_is_geometric_and_a_polished_one_a_mirror() {
    // The same trace, 1 um and 1 nm RMS (6 um correlation, 1 um spacing): rough against the wavelength its
    // coherence patches (one sample across) tilt like its slopes, geometric optics; polished, the mirror keeps
    // exp(-(2 k sigma cos t)^2) of the light (Beckmann-Kirchhoff: 0.99948 at 0 deg and 450 nm) at every angle.
    let p = profile(4096, 6.0, 1e-6, 3);
    for (rms, regime) in [(1e-6, "geometric"), (1e-9, "wave")] {
        let z: Vec<f64> = p.iter().map(|h| h * rms / 1e-6).collect();
        let out = Pipeline::new(Options::default()).run(Heightfield::new(z.len(), 1, 1e-6, 1e-6, z).unwrap(), "trace").unwrap();
        let o = out.fit.optics.as_ref().unwrap();
        assert_eq!(o.regime, regime, "{rms}: {}", o.why);
        if regime == "wave" {
            assert_eq!(out.fit.selection.as_ref().unwrap().answer.as_deref(), Some("mirror"));
            for s in &o.specular {
                let k = 2.0 * PI / (s.wavelength_nm * 1e-9);
                let want = (-(2.0 * k * rms * s.theta_deg.to_radians().cos()).powi(2)).exp();
                assert!((s.weight - want).abs() < 1e-3, "{s:?} against {want}");
            }
        }
    }
}

#[test]
fn a_profiles_isolated_spikes_are_masked_and_nothing_else() {
    // 1 um heights of 6 um correlation on a steep tilt (0.3) and a 50 um bow over the trace; three isolated
    // spikes (60, -40, 60 um) where they are put, found along a row and along a column, and nothing on the
    // trace without them.
    let (n, dx) = (4096, 1e-6);
    let clean: Vec<f64> = profile(n, 6.0, 1e-6, 9)
        .iter()
        .enumerate()
        .map(|(j, h)| {
            let x = j as f64 * dx;
            h + 0.3 * x + 50e-6 * (2.0 * x / (n as f64 * dx) - 1.0).powi(2)
        })
        .collect();
    let at = [500usize, 1700, 3001];
    let mut spiky = clean.clone();
    for (k, &j) in at.iter().enumerate() {
        spiky[j] += if k == 1 { -40e-6 } else { 60e-6 };
    }
    for (what, z, want) in [("clean", clean, Vec::new()), ("spiky", spiky, at.to_vec())] {
        for (nx, ny) in [(n, 1), (1, n)] {
            let hf = Heightfield::new(nx, ny, dx, dx, z.clone()).unwrap();
            let p = ndfit::preprocess::prepare(hf, &ndfit::preprocess::Preprocess::default()).unwrap();
            let report = p.meta().despike.clone().expect("a despike report");
            assert_eq!(p.masked(), &want[..], "{what} {nx} x {ny}: {report:?}");
            assert_eq!((report.masked, report.masked_high), (want.len(), want.len().saturating_sub(1)), "{what}");
        }
    }
}
