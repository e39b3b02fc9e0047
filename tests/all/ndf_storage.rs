//! The NDF's storage guards: heights quantized on a coarse lattice (the comb of empty bins, the st_plu-1
//! scan) and f32 storage of the heights, against derived expectations.

use ndfit::ndf::{empirical_ndf, empirical_ndf_f32, EmpiricalNdf, HeightsF32, NdfOptions};
use ndfit::synth::{gaussian_surface, GaussianParams, SynthSettings};
use ndfit::{ErrorKind, Heightfield};

use crate::common::shared_scans;

/// Bins whose W-weighted centre lies within `radius` of the centre of the Lambert disk (whitened
/// slope radius about `radius`) and that can hold data (`W > 0`: a bin that respects a height lattice
/// and holds no node has `W = 0`), and how many of them are empty.
fn core_bins(ndf: &EmpiricalNdf, radius: f64) -> (usize, usize) {
    let (mut all, mut empty) = (0, 0);
    for b in ndf.bins.iter().filter(|b| b.proj_solid_angle > 0.0) {
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
/// h = 0.04 whitened, finer than the lattice: Lambert bins would show a comb, a fraction of empty
/// central bins near 1 - (h / l)^2 ~ 0.4 where every bin expects hundreds of samples. The lattice must
/// be found exactly (up to the rounding of the products k q), found rigid (no form removal), and the bins
/// must respect it (data_formats/objective.md): the grid stays the continuous surface's, the cells that
/// hold no node get W = 0, and no cell that holds a node is empty. An explicit grid twice as fine keeps
/// that property, with more node-less cells. The unquantized surface must not be flagged.
#[test]
fn quantized_heights_get_bins_that_respect_the_lattice() {
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
    let lat = found.lattice.expect("no form removal: the lattice is rigid");
    // Heights k q with no plane: the nodes sit on multiples of the step.
    assert!(lat.offset[0].abs() < 1e-9 && lat.offset[1].abs() < 1e-9, "offset {:?}", lat.offset);
    assert!(found.rigidity[0] > 0.999 && found.rigidity[1] > 0.999, "{:?}", found.rigidity);
    assert_eq!(ndf.grid.n, plain.grid.n, "a rigid lattice does not cap the grid");
    assert!(found.coarsened_from.is_none());
    assert!(found.resolves_ndf() && ndf.warnings.is_empty(), "{:?}", ndf.warnings);
    // Some central cells hold no node (W = 0) where Lambert bins would have been empty bins of the comb.
    let nodeless = ndf.bins.iter().filter(|b| b.proj_solid_angle == 0.0).count();
    assert!(nodeless > 0, "at 71 cells a central cell is finer than the lattice");
    let (all, empty) = core_bins(&ndf, 1.0);
    eprintln!("quantized: q {:.3e}, grid {}, core bins with a node {all}, empty {empty}, node-less {nodeless}", found.quantum, ndf.grid.n);
    assert!(all >= 500 && empty == 0, "core bins {all}, empty {empty}");
    assert!((ndf.total() - 1.0).abs() < 1e-9);

    let fine = empirical_ndf(&hq, &NdfOptions { cells_across: Some(2 * plain.grid.n + 1), ..Default::default() }).expect("valid");
    let (all, empty) = core_bins(&fine, 0.5);
    let nodeless_fine = fine.bins.iter().filter(|b| b.proj_solid_angle == 0.0).count();
    assert!(all > 100 && empty == 0, "fine grid: core bins {all}, empty {empty}");
    assert!(nodeless_fine > nodeless, "a finer grid leaves more cells without a node");
    let (all, empty) = core_bins(&plain, 1.0);
    assert_eq!(empty, 0, "the continuous surface has no empty central bin ({all})");
}

/// A lattice smeared by a curved form removal: the heights of a strongly curved sample (a paraboloid whose
/// slope sweeps 0.2 across the scan, 40 lattice steps) are quantized, then the poly2 form is removed. The
/// quantum is still known (found before the form removal), but the slopes are no longer on rigid nodes:
/// the automatic grid is capped and the NDF says so.
#[test]
fn a_smeared_lattice_caps_the_grid() {
    let s = SynthSettings { nx: 512, ny: 512, dx: 1e-6, dy: 1e-6, seed: 5, ..Default::default() };
    let p = GaussianParams { sigma_x: 0.1, sigma_y: 0.08, theta_z: 0.3, corr_length: 5e-6 };
    let (mut hf, _) = gaussian_surface(&s, &p).expect("valid");
    let c = 0.1 / (2.0 * 256e-6);
    let z: Vec<f64> = hf.z.iter().enumerate().map(|(k, h)| h + c * ((k % 512) as f64 * 1e-6 - 256e-6).powi(2)).collect();
    hf.z = z.into();
    let pre = ndfit::preprocess::Preprocess { form: ndfit::preprocess::FormRemoval::Polynomial(2), ..Default::default() };
    let hq = ndfit::preprocess::apply(quantized(&hf, 1e-8), &pre).expect("valid");
    assert_eq!(hq.meta.height_quantum.map(|v| (v / 1e-8 - 1.0).abs() < 1e-6), Some(true), "{:?}", hq.meta.height_quantum);
    let ndf = empirical_ndf(&hq, &NdfOptions::default()).expect("valid");
    let found = ndf.quantization.expect("the quantum is carried through the form removal");
    assert!(found.lattice.is_none() && found.rigidity[0] < 0.5, "smeared along x: {:?}", found.rigidity);
    assert!(found.coarsened_from.is_some() && ndf.grid.n == found.max_cells, "grid {} cap {}", ndf.grid.n, found.max_cells);
    assert!(ndf.warnings.iter().any(|w| w.contains("smeared")), "{:?}", ndf.warnings);
}

/// The real quantized scan (Sensofar PLU, st_plu-1), as stored and with the default plane removal: its
/// lattice is found (before the plane removal in the second case), rigid, and no bin that holds a node
/// is empty in the core; its lattice is coarser than half the slope scale, which the NDF says.
#[test]
fn real_quantized_scan_has_no_comb_needs_shared() {
    let Some(dir) = shared_scans("real_quantized_scan_has_no_comb_needs_shared") else { return };
    let path = dir.join("st_plu-1.plu");
    let raw = ndfit::io::read_scan(&path, &Default::default()).expect("st_plu-1 reads");
    for hf in [raw.clone(), ndfit::preprocess::apply(raw, &Default::default()).expect("plane removal")] {
        let ndf = empirical_ndf(&hf, &NdfOptions::default()).expect("valid");
        let (all, empty) = core_bins(&ndf, 1.0);
        eprintln!(
            "st_plu-1: quantization {:?}, grid {}, core bins {all}, empty {empty}, warnings {:?}",
            ndf.quantization, ndf.grid.n, ndf.warnings
        );
        let q = ndf.quantization.expect("st_plu-1 heights are on a lattice");
        assert!(q.on_lattice >= 0.99 && (q.quantum / 3.90625e-9 - 1.0).abs() < 1e-6, "{q:?}");
        assert!(q.lattice.is_some(), "rigid: {:?}", q.rigidity);
        assert!(all > 0 && empty == 0, "no comb: {empty} of {all} central bins empty");
        assert!(!q.resolves_ndf() && ndf.warnings.iter().any(|w| w.contains("cannot resolve")), "{:?}", ndf.warnings);
        assert!((ndf.total() - 1.0).abs() < 1e-9);
    }
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
