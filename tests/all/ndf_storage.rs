//! The NDF's storage guards: heights quantized on a coarse lattice (issue 4: the comb of empty bins,
//! the st_plu-1 scan) and f32 storage of the heights (issue 8), against derived expectations.

use ndfit::ndf::{empirical_ndf, empirical_ndf_f32, EmpiricalNdf, HeightsF32, NdfOptions};
use ndfit::synth::{gaussian_surface, GaussianParams, SynthSettings};
use ndfit::{ErrorKind, Heightfield};

use crate::common::shared_scans;

/// Bins whose W-weighted centre lies within `radius` of the centre of the Lambert disk (whitened
/// slope radius about `radius`), and how many of them are empty.
fn core_bins(ndf: &EmpiricalNdf, radius: f64) -> (usize, usize) {
    let (mut all, mut empty) = (0, 0);
    for b in &ndf.bins {
        let s = [-b.m.x / b.m.z, -b.m.y / b.m.z];
        let p = ndf.frame.to_lambert(s[0], s[1]);
        if p[0].hypot(p[1]) < radius {
            all += 1;
            empty += (b.count == 0) as usize;
        }
    }
    (all, empty)
}

fn quantized(hf: &Heightfield, q: f64) -> Heightfield {
    let z = hf.z.iter().map(|h| (h / q).round() * q).collect();
    Heightfield::new(hf.nx, hf.ny, hf.dx, hf.dy, z).expect("same shape")
}

/// A Gaussian surface (slope sigma 0.1 and 0.08) with heights rounded to q = 1e-8 m on a 1 um grid: the
/// central-difference slopes lie on a lattice of step q / (2 dx) = 0.005, about sigma / 20 (whitened
/// steps l ~ 0.05-0.06). The automatic grid for 260k samples (64 per bin) is 71 cells across, bins of
/// h = 0.04 whitened, finer than the lattice: expected a comb, i.e. a fraction of empty central bins
/// near 1 - (h / l)^2 ~ 0.4 where every bin expects hundreds of samples. The guard must find q exactly
/// (up to the rounding of the products k q), cap the grid at 2 sqrt 2 / (2 (l_x + l_y)) (so that every
/// central bin, of side at least the lattice's covering diameter, holds a lattice node), leave no
/// central bin empty, and say so; the unquantized surface must not be flagged.
#[test]
fn quantized_heights_coarsen_the_grid_instead_of_a_comb() {
    let s = SynthSettings { nx: 512, ny: 512, dx: 1e-6, dy: 1e-6, seed: 5, ..Default::default() };
    let p = GaussianParams { sigma_x: 0.1, sigma_y: 0.08, theta_z: 0.3, corr_length: 5e-6 };
    let (hf, _) = gaussian_surface(&s, &p).expect("valid");
    let plain = empirical_ndf(&hf, &NdfOptions::default()).expect("valid");
    assert!(plain.quantization.is_none(), "a continuous f64 surface is not quantized: {:?}", plain.quantization);
    assert!(plain.warnings.is_empty());

    let q = 1e-8;
    let hq = quantized(&hf, q);
    let ndf = empirical_ndf(&hq, &NdfOptions::default()).expect("valid");
    let found = ndf.quantization.expect("the lattice is found");
    assert!((found.quantum / q - 1.0).abs() < 1e-6, "quantum {} vs {q}", found.quantum);
    assert!((found.slope_step[0] - 0.005).abs() < 1e-9 && (found.slope_step[1] - 0.005).abs() < 1e-9);
    // The cap from the frame's own whitening (independent recomputation of the lattice step lengths).
    let w = ndf.frame.whiten;
    let (lx, ly) = (w[0][0].hypot(w[1][0]) * 0.005, w[0][1].hypot(w[1][1]) * 0.005);
    let cap = (2.0 * std::f64::consts::SQRT_2 / (2.0 * (lx + ly))).floor() as usize;
    let cap = if cap % 2 == 0 { cap - 1 } else { cap };
    assert_eq!(ndf.grid.n, cap, "grid {} (lattice steps {lx:.4}, {ly:.4})", ndf.grid.n);
    let from = found.coarsened_from.expect("the automatic grid was finer than the lattice");
    assert_eq!(from, plain.grid.n, "the uncapped grid is the one the continuous surface gets");
    assert!(ndf.warnings.iter().any(|w| w.contains("quantized")), "{:?}", ndf.warnings);
    let (all, empty) = core_bins(&ndf, 1.0);
    eprintln!("quantized: q {:.3e}, grid {} (from {from}), core bins {all}, empty {empty}", found.quantum, ndf.grid.n);
    assert!(all >= 9 && empty == 0, "core bins {all}, empty {empty}");
    // Heitz eq. 9 against independent bin integrals; a coarse grid is mostly rim cells (measured 2.3e-9).
    let total = crate::common::reference_total(&ndf, 2);
    assert!((total - 1.0).abs() < 1e-8, "sum d W_ref = {total}");

    // Without the cap (an explicit grid at the continuous surface's size) the comb is there, and the
    // NDF says so in a warning. Within |p| < 0.3 the Lambert map magnifies whitened slope area by at
    // most 1 / m'_z^3 = 1.15, so a cell holds on average at most 1.15 h^2 / (l_x l_y) ~ 0.55 lattice
    // nodes: at least ~45% of those bins must be empty (assert a quarter).
    let fine = empirical_ndf(&hq, &NdfOptions { cells_across: Some(plain.grid.n), ..Default::default() }).expect("valid");
    let (all, empty) = core_bins(&fine, 0.3);
    eprintln!("explicit {} cells: central bins {all}, empty {empty} (nodes per bin {:.2})", fine.grid.n, 1.15 * fine.grid.h.powi(2) / (lx * ly));
    assert!(empty as f64 > 0.25 * all as f64, "the comb should show: {empty} of {all} empty");
    assert!(fine.warnings.iter().any(|w| w.contains("comb")), "{:?}", fine.warnings);
    let (all, empty) = core_bins(&plain, 1.0);
    assert_eq!(empty, 0, "the continuous surface has no empty central bin ({all})");
}

/// The real quantized scan (Sensofar PLU, st_plu-1): its lattice is found and the automatic grid has no
/// empty central bin.
#[test]
fn real_quantized_scan_has_no_comb_needs_shared() {
    let Some(dir) = shared_scans("real_quantized_scan_has_no_comb_needs_shared") else { return };
    let path = dir.join("st_plu-1.plu");
    let hf = ndfit::io::read_scan(&path, &Default::default()).expect("st_plu-1 reads");
    let ndf = empirical_ndf(&hf, &NdfOptions::default()).expect("valid");
    let (all, empty) = core_bins(&ndf, 1.0);
    eprintln!("st_plu-1: quantization {:?}, grid {}, core bins {all}, empty {empty}, warnings {:?}", ndf.quantization, ndf.grid.n, ndf.warnings);
    let q = ndf.quantization.expect("st_plu-1 heights are on a lattice");
    assert!(q.on_lattice >= 0.99);
    assert_eq!(empty, 0, "no comb: {empty} of {all} central bins empty");
    // Heitz eq. 9 against independent bin integrals; 3 cells across, so every bin is a rim cell of a
    // narrow frame, where the polar rule errs most (data_formats/ndf_csv.md, step 4): measured 2e-5.
    let total = crate::common::reference_total(&ndf, 2);
    assert!((total - 1.0).abs() < 1e-4, "sum d W_ref = {total}");
}

/// f32 storage with a 0.5 m height offset and ~100 nm of detail: the mean is removed in f64 before the
/// conversion, so the heights keep ~1e-7 * 2^-24 = 6e-15 m of rounding and the slopes at most
/// `max|h - mean| 2^-24 / dx`. On the f64 NDF's frame and grid a sample changes bin only within that
/// distance (times the whitening's Lipschitz constant 1 / sigma_min; the Lambert map is 1-Lipschitz)
/// of a cell edge: expected at most N 4 eps / h of them. Without the mean removal the same data
/// would round slopes by 0.5 * 2^-24 / 1e-6 = 0.03, a third of the slope scale: the guard's job.
#[test]
fn f32_storage_costs_only_its_rounding_even_with_a_half_metre_offset() {
    let s = SynthSettings { nx: 512, ny: 512, dx: 1e-6, dy: 1e-6, seed: 3, offset: 0.5, ..Default::default() };
    let p = GaussianParams { sigma_x: 0.05, sigma_y: 0.03, theta_z: 0.2, corr_length: 4e-6 };
    let (hf, _) = gaussian_surface(&s, &p).expect("valid");
    let a = empirical_ndf(&hf, &NdfOptions::default()).expect("valid");
    let h32 = HeightsF32::from_heightfield(&hf);
    assert!((h32.offset - 0.5).abs() < 1e-6, "offset {}", h32.offset);
    let opts = NdfOptions { frame: Some(a.frame), cells_across: Some(a.grid.n), ..Default::default() };
    let b = empirical_ndf_f32(&h32, &opts).expect("valid");
    let st = b.f32_storage.expect("f32 storage is reported");
    let eps = h32.max_deviation * 2f64.powi(-24) / s.dx;
    assert!((st.slope_rounding_bound - eps).abs() <= 1e-12 * eps);
    let sigma_min = 0.03;
    let expected = a.n_samples as f64 * 4.0 * (eps / sigma_min) / a.grid.h;
    let moved: u64 = a.bins.iter().zip(&b.bins).map(|(x, y)| x.count.abs_diff(y.count)).sum::<u64>() / 2;
    eprintln!("f32: bound {eps:.2e} ({:.2e} of the slope scale), moved {moved} samples (bound {expected:.2e})", st.fraction_of_slope_scale);
    assert_eq!(a.n_samples, b.n_samples);
    assert!((moved as f64) <= expected + 3.0 * expected.sqrt() + 1.0, "moved {moved}");
    // The automatic path (own frame) agrees too, and the offset was never in f32.
    let c = empirical_ndf_f32(&h32, &NdfOptions::default()).expect("valid");
    assert_eq!(c.grid.n, a.grid.n);
    assert!((c.frame.cov[0][0] / a.frame.cov[0][0] - 1.0).abs() < 1e-6);
}

/// f32 storage is refused, with a clear message, when its rounding would matter: a steep tilt (heights
/// spanning 5e-4 m) carrying slopes of scale 1e-5. The bound is 5e-4 * 2^-24 / 1e-6 = 3e-5 slope,
/// three times the slope scale (the guard allows 1%).
#[test]
fn f32_storage_is_refused_when_its_rounding_matters() {
    let n = 300;
    let mut z = Vec::with_capacity(n * n);
    for i in 0..n {
        for j in 0..n {
            let (x, y) = (j as f64 * 1e-6, i as f64 * 1e-6);
            z.push(1.0 * x + 0.7 * y + 1e-11 * ((j * 7 + i * 13) % 17) as f64);
        }
    }
    let hf = Heightfield::new(n, n, 1e-6, 1e-6, z).expect("valid");
    let e = empirical_ndf_f32(&HeightsF32::from_heightfield(&hf), &NdfOptions::default()).expect_err("rounding dominates");
    assert_eq!(e.kind(), ErrorKind::BadData);
    assert!(e.message().contains("f32") && e.message().contains("use f64"), "{}", e.message());
    // f64 is fine on the same data.
    assert!(empirical_ndf(&hf, &NdfOptions::default()).is_ok());
}
