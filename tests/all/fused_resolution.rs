//! The resolution test run inside the histogram's pass against its two-pass form
//! ([`ndfit::ndf::assess`], which reads the scan twice more): the same share and the same
//! per-bin counts of unresolved normals, bit for bit, on odd grid sizes, with holes and masked spikes,
//! with bands of 1 and 3 rows and the default, through a lazily formed scan ([`prepare`]) and through
//! f32 storage; on both sides of [`MAX_UNRESOLVED_SHARE`] (per-bin counts kept or dropped).

use ndfit::ndf::{assess, MAX_UNRESOLVED_SHARE};
use ndfit::ndf::{empirical_ndf, empirical_ndf_f32, EmpiricalNdf, HeightsF32, NdfOptions};
use ndfit::pipeline::ndf_prepared;
use ndfit::preprocess::{prepare, Preprocess};
use ndfit::scan::set_band_rows;
use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};
use ndfit::Heightfield;

/// Bumps with rims (unresolved normals there) for the first grid, a wave with kinks (`sqrt |sin|`) for
/// the others, on a tilt, with holes, a few spikes and, with `noise`, a rough component.
fn bumps(nx: usize, ny: usize, noise: f64) -> Heightfield {
    let mut hf = if nx * ny > 10_000 {
        let s = SynthSettings { nx, ny, dx: 1e-6, dy: 1e-6, seed: 3, holes: 0.003, ..Default::default() };
        ellipsoid_surface(&s, &EllipsoidParams { alpha_x: 0.4, alpha_y: 0.25, theta_z: 0.3, ..Default::default() }).expect("valid").0
    } else {
        let z = (0..nx * ny)
            .map(|k| {
                let (i, j) = ((k / nx) as f64, (k % nx) as f64);
                let rough = noise * (((k as u64).wrapping_mul(2654435761) % 1000) as f64 / 500.0 - 1.0);
                if k % 37 == 5 {
                    f64::NAN
                } else {
                    2e-7 * (0.9 * j + 0.3 * i).sin() + 1e-6 * (0.2 * j + 0.1 * i).sin().abs().sqrt() + rough
                }
            })
            .collect();
        Heightfield::new(nx, ny, 1e-6, 1e-6, z).expect("grid")
    };
    for i in 0..ny {
        for j in 0..nx {
            let k = i * nx + j;
            hf.z[k] += 1e-3 + 0.01 * (j as f64 * 1e-6) - 0.02 * (i as f64 * 1e-6);
            if k % 4999 == 11 {
                hf.z[k] += 4e-5;
            }
        }
    }
    hf
}

/// The two-pass assessment of `src` for the bins of `ndf` (its fields reset first).
fn reference<S: ndfit::scan::BandSource>(src: &S, ndf: &EmpiricalNdf) -> EmpiricalNdf {
    let mut r = ndf.clone();
    r.unresolved = vec![u64::MAX; 3];
    r.unresolved_share = None;
    assess(src, &mut r);
    r
}

fn same(got: &EmpiricalNdf, want: &EmpiricalNdf, what: &str) {
    assert_eq!(got.unresolved_share.map(f64::to_bits), want.unresolved_share.map(f64::to_bits), "{what}: share");
    assert_eq!(got.unresolved, want.unresolved, "{what}: per-bin unresolved counts");
}

#[test]
fn fused_resolution_test_equals_the_two_pass_form() {
    let mut kept = 0;
    let mut dropped = 0;
    for (nx, ny, noise) in [(157, 101, 0.0), (64, 5, 0.0), (5, 64, 0.0), (97, 83, 1e-6), (4, 9, 0.0), (7, 6, 0.0)] {
        let hf = bumps(nx, ny, noise);
        for rows in [Some(1), Some(3), None] {
            set_band_rows(rows);
            let what = format!("{nx} x {ny}, noise {noise:e}, band rows {rows:?}");
            let opts = NdfOptions::default();
            // In memory, heights as they are (holes only).
            let ndf = empirical_ndf(&hf, &opts).expect("ndf");
            same(&ndf, &reference(&hf, &ndf), &format!("{what}, in memory"));
            // Form removed band by band, spikes masked apart from the heights.
            let p = prepare(hf.clone(), &Preprocess::default()).expect("prepare");
            let ndf = ndf_prepared(&p, &opts).expect("ndf of the bands");
            same(&ndf, &reference(&p, &ndf), &format!("{what}, prepared"));
            if nx * ny > 1000 {
                assert!(!p.masked().is_empty(), "{what}: spikes masked");
            }
            let share = ndf.unresolved_share.expect("assessed");
            if ndf.unresolved.iter().any(|&u| u > 0) {
                kept += 1;
            } else if share > MAX_UNRESOLVED_SHARE {
                dropped += 1;
            }
            // f32 storage of the residual heights.
            let h32 = HeightsF32::from_heightfield(&p.clone().into_scan());
            if let Ok(ndf) = empirical_ndf_f32(&h32, &opts) {
                same(&ndf, &reference(&h32, &ndf), &format!("{what}, f32"));
            }
        }
        set_band_rows(None);
    }
    // Both branches were exercised: per-bin counts kept (some bins with unresolved normals) and dropped.
    assert!(kept >= 3 && dropped >= 1, "kept {kept}, dropped {dropped}");
}

/// A stencil of finite heights whose slopes overflow to `+inf` and `-inf` is valid for the resolution
/// test (and unresolved) but not counted by the histogram (`sx + sy` is NaN): it is binned among the
/// unresolved apart from the histogram's blocks, as the two-pass form bins it.
#[test]
fn overflowing_stencils_are_binned_as_the_two_pass_form_bins_them() {
    let (nx, ny) = (157, 101);
    let mut hf = bumps(nx, ny, 0.0);
    for (i, j) in [(20, 30), (50, 61), (70, 12)] {
        for (di, dj, v) in [(0, 1, 1e308), (0, -1, -1e308), (1, 0, -1e308), (-1, 0, 1e308)] {
            hf.z[((i as i64 + di) as usize) * nx + (j as i64 + dj) as usize] = v;
        }
    }
    let ndf = empirical_ndf(&hf, &NdfOptions::default()).expect("ndf");
    let want = reference(&hf, &ndf);
    same(&ndf, &want, "overflowing stencils");
    assert!(ndf.unresolved.iter().any(|&u| u > 0), "per-bin counts kept (share {:?})", ndf.unresolved_share);
}

/// Rows whose unresolved normals are deferred while the share so far is high (the pass starts in rough
/// rows: the row chunks that begin at rows 0 and `ny / 2` begin with them, whatever the thread count) are
/// binned after the pass when the share ends within [`MAX_UNRESOLVED_SHARE`]: the same per-bin counts as the two-pass form, in memory and
/// through the lazily formed scan. Rough rows: white noise at the sampling step (unresolved); the rest a
/// long wave (resolved).
#[test]
fn deferred_rows_are_binned_when_the_share_ends_within_the_cap() {
    let (nx, ny) = (300, 400);
    let z: Vec<f64> = (0..nx * ny)
        .map(|k| {
            let (i, j) = (k / nx, k % nx);
            let rough = i < ny / 10 || (ny / 2..ny / 2 + ny / 10).contains(&i);
            let noise = ((k as u64).wrapping_mul(2_654_435_761) % 1000) as f64 / 500.0 - 1.0;
            1e-6 * (0.02 * j as f64 + 0.01 * i as f64).sin() + if rough { 3e-7 * noise } else { 0.0 }
        })
        .collect();
    let hf = Heightfield::new(nx, ny, 1e-6, 1e-6, z).expect("grid");
    let opts = NdfOptions::default();
    let ndf = empirical_ndf(&hf, &opts).expect("ndf");
    let share = ndf.unresolved_share.expect("assessed");
    assert!(share > 0.1 && share <= MAX_UNRESOLVED_SHARE, "share {share}");
    assert!(ndf.unresolved.iter().sum::<u64>() as f64 > 0.1 * ndf.n_samples as f64, "per-bin counts kept");
    same(&ndf, &reference(&hf, &ndf), "in memory");
    let p = prepare(hf, &Preprocess::default()).expect("prepare");
    let ndf = ndf_prepared(&p, &opts).expect("ndf of the bands");
    same(&ndf, &reference(&p, &ndf), "prepared");
}
