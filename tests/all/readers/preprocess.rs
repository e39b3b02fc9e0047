//! Preprocessing and surface statistics against closed forms: polynomial and cylinder removal leave
//! nothing of an exact form, holes stay holes, crop/subsample keep positions, Sdq's central
//! differences are exact on quadratics.

use ndfit::preprocess::{apply, crop, subsample, Crop, FormRemoval, Preprocess};
use ndfit::preprocess::{remove_cylinder, remove_polynomial};
use ndfit::stats::{sdq_central, surface_stats};
use ndfit::Heightfield;

/// A heightfield of `f(x, y)` (metres) on an nx x ny grid with spacing dx, dy; `holes` set NaN.
fn field(nx: usize, ny: usize, dx: f64, dy: f64, holes: &[usize], f: impl Fn(f64, f64) -> f64) -> Heightfield {
    let z = (0..nx * ny).map(|k| if holes.contains(&k) { f64::NAN } else { f((k % nx) as f64 * dx, (k / nx) as f64 * dy) }).collect();
    Heightfield::new(nx, ny, dx, dy, z).expect("grid")
}

fn rms(z: &[f64]) -> f64 {
    let v: Vec<f64> = z.iter().copied().filter(|h| !h.is_nan()).collect();
    (v.iter().map(|h| h * h).sum::<f64>() / v.len() as f64).sqrt()
}

#[test]
fn polynomial_forms_are_removed_exactly_and_holes_stay() {
    let holes = [5, 77, 300];
    let (dx, dy) = (2e-6, 3e-6);
    // Order-3 form with a 76 mm absolute offset (the AL3D case) and micrometre-scale curvature.
    let f = |x: f64, y: f64| 0.0763 + 1e-3 * x - 2e-3 * y + 40.0 * x * x - 25.0 * x * y + 10.0 * y * y + 2e5 * x * x * x - 1e5 * x * y * y;
    let hf = field(41, 23, dx, dy, &holes, f);
    let r3 = remove_polynomial(&hf, 3).expect("order 3");
    // f64 holds 0.0763 m to ~1e-17 m; a few thousand points' sums keep the residual near 1e-15 m.
    assert!(rms(&r3) < 1e-13, "order-3 residual {:e}", rms(&r3));
    let r2 = remove_polynomial(&hf, 2).expect("order 2");
    assert!(rms(&r2) > 1e-10, "order 2 cannot remove the cubic terms: {:e}", rms(&r2));
    for (k, r) in r3.iter().enumerate() {
        assert_eq!(r.is_nan(), holes.contains(&k), "point {k}");
    }
    // A plane is removed by the default preprocessing, and nothing else changes.
    let plane = field(41, 23, dx, dy, &holes, |x, y| 0.0763 + 1e-3 * x - 2e-3 * y);
    let out = apply(plane, &Preprocess::default()).expect("plane");
    assert!(rms(&out.z) < 1e-15);
    assert_eq!(out.invalid_count(), holes.len());
}

#[test]
fn cylinders_at_any_azimuth_are_removed() {
    let (nx, ny, d) = (120, 80, 5e-6);
    let (cx, cy) = (nx as f64 * d / 2.0, ny as f64 * d / 2.0);
    for (radius, phi, convex) in [(2e-3, 0.3f64, 1.0), (1.5e-3, 1.9, -1.0), (4e-3, 0.0, 1.0)] {
        // Axis direction (cos phi, sin phi); t is the distance across it.
        let f = |x: f64, y: f64| {
            let t = -(x - cx) * phi.sin() + (y - cy) * phi.cos() - 30e-6;
            let s = (x - cx) * phi.cos() + (y - cy) * phi.sin();
            5e-3 + 1e-3 * s + convex * (radius * radius - t * t).sqrt()
        };
        let hf = field(nx, ny, d, d, &[7, 4000], f);
        let fit = remove_cylinder(&hf).expect("cylinder");
        assert!((fit.radius - radius).abs() < 1e-6 * radius, "R {} vs {radius}", fit.radius);
        assert_eq!(fit.convexity, convex);
        let dphi = (fit.axis_angle - phi.rem_euclid(std::f64::consts::PI)).abs();
        assert!(dphi < 1e-6 || (dphi - std::f64::consts::PI).abs() < 1e-6, "axis {} vs {phi}", fit.axis_angle);
        assert!(rms(&fit.residual) < 1e-12, "residual {:e}", rms(&fit.residual));
        assert!(fit.residual[7].is_nan() && fit.residual[4000].is_nan());
    }
    // A flat surface has no cylinder in it: say so instead of fitting nonsense.
    let flat = field(30, 20, d, d, &[], |x, y| 1e-3 * x + 2e-3 * y);
    assert!(remove_cylinder(&flat).is_err());
}

#[test]
fn crop_and_subsample_keep_positions_and_holes() {
    let hf = field(10, 8, 1e-6, 2e-6, &[23], |x, y| x * 3.0 + y);
    let c = crop(&hf, Crop { x: 2, y: 1, nx: 5, ny: 4 }).expect("crop");
    assert_eq!((c.nx, c.ny), (5, 4));
    assert_eq!(c.x0, 2e-6);
    assert_eq!(c.y0, 2e-6);
    assert_eq!(c.at(0, 0), hf.at(1, 2));
    assert!(c.at(1, 1).is_nan()); // point 23 = row 2, column 3
    assert!(crop(&hf, Crop { x: 8, y: 0, nx: 5, ny: 1 }).is_err());
    let s = subsample(&hf, 3).expect("subsample");
    assert_eq!((s.nx, s.ny, s.dx, s.dy), (4, 3, 3e-6, 6e-6));
    assert_eq!(s.at(2, 3), hf.at(6, 9));
    let all = apply(
        hf.clone(),
        &Preprocess {
            form: FormRemoval::None,
            crop: Some(Crop { x: 0, y: 0, nx: 10, ny: 8 }),
            subsample: 1,
            despike: ndfit::preprocess::Despike::None,
        },
    )
    .expect("identity");
    assert_eq!(all.z.iter().filter(|h| h.is_nan()).count(), 1);
}

#[test]
fn sdq_central_is_exact_on_quadratics_and_skips_stencils_touching_holes() {
    // Central differences are exact for quadratics: dz/dx = 2 a x, dz/dy = 2 b y.
    let (nx, ny, dx, dy, a, b) = (9usize, 7usize, 0.5, 0.25, 0.3, -0.7);
    let f = |x: f64, y: f64| a * x * x + b * y * y;
    let z: Vec<f64> = (0..nx * ny).map(|k| f((k % nx) as f64 * dx, (k / nx) as f64 * dy)).collect();
    let (sdq, n) = sdq_central(&z, nx, ny, dx, dy);
    let mut acc = 0.0;
    for i in 1..ny - 1 {
        for j in 1..nx - 1 {
            let (x, y) = (j as f64 * dx, i as f64 * dy);
            acc += (2.0 * a * x).powi(2) + (2.0 * b * y).powi(2);
        }
    }
    let want = (acc / ((nx - 2) * (ny - 2)) as f64).sqrt();
    assert_eq!(n, (nx - 2) * (ny - 2));
    assert!((sdq - want).abs() < 1e-14 * want, "{sdq} vs {want}");
    // One interior hole removes exactly the four stencils that use it as a neighbour.
    let mut zh = z.clone();
    zh[3 * nx + 4] = f64::NAN;
    assert_eq!(sdq_central(&zh, nx, ny, dx, dy).1, n - 4);
    // Sq of a plane plus a known zero-mean checkerboard is the checkerboard's amplitude.
    let hf = field(20, 10, 1e-6, 1e-6, &[], |x, y| 1e-3 * x - 4e-3 * y + 0.05);
    let mut hf2 = hf.clone();
    for (k, h) in hf2.z.iter_mut().enumerate() {
        *h += if (k % 20 + k / 20) % 2 == 0 { 1e-8 } else { -1e-8 };
    }
    let st = surface_stats(&hf2).expect("stats");
    // The checkerboard is orthogonal to the plane's basis on an even grid, so Sq is exactly 1e-8.
    assert!((st.sq - 1e-8).abs() < 1e-8 * 1e-9, "Sq {}", st.sq);
}

/// `ndfit info`'s statistics run their sums in fixed blocks of rows on every thread: the same bits on
/// one thread and on five, and, against the same quantities summed with Neumaier's compensated sum (exact
/// to about one rounding), the mean height to 1e-14 of the largest height (a few of its ulps) and Sdq
/// to 1e-13 relative.
#[test]
fn surface_statistics_are_the_same_on_any_thread_count_and_close_to_a_compensated_sum() {
    let (nx, ny, dx) = (301, 257, 1e-6);
    let holes: Vec<usize> = (0..nx * ny).filter(|k| (k * 7919) % 97 == 0).collect();
    let hf = field(nx, ny, dx, dx, &holes, |x, y| 3e-6 * (x * 9e4).sin() * (y * 7e4).cos() + 2e-3 * x + 0.5);
    let pool = |k: usize| rayon::ThreadPoolBuilder::new().num_threads(k).build().expect("pool");
    let bits = |s: &ndfit::stats::SurfaceStats| [s.z_min, s.z_max, s.z_mean, s.sq, s.sdq].map(f64::to_bits);
    let one = pool(1).install(|| surface_stats(&hf)).expect("stats");
    let five = pool(5).install(|| surface_stats(&hf)).expect("stats");
    assert_eq!(bits(&one), bits(&five));
    assert_eq!((one.valid, one.sdq_points), (five.valid, five.sdq_points));
    let neumaier = |v: &mut dyn Iterator<Item = f64>| {
        let (mut s, mut c) = (0.0f64, 0.0f64);
        for x in v {
            let t = s + x;
            c += if s.abs() >= x.abs() { (s - t) + x } else { (x - t) + s };
            s = t;
        }
        s + c
    };
    let valid: Vec<f64> = hf.z.iter().copied().filter(|h| !h.is_nan()).collect();
    let mean = neumaier(&mut valid.iter().copied()) / valid.len() as f64;
    assert!((one.z_mean - mean).abs() <= 1e-14 * one.z_max.abs().max(one.z_min.abs()), "{} vs {mean}", one.z_mean);
    let (sdq, n) = pool(5).install(|| sdq_central(&hf.z, nx, ny, dx, dx));
    let mut g = Vec::new();
    for i in 1..ny - 1 {
        for j in 1..nx - 1 {
            let at = |i: usize, j: usize| hf.z[i * nx + j];
            let (l, r, d, u) = (at(i, j - 1), at(i, j + 1), at(i - 1, j), at(i + 1, j));
            if [l, r, d, u].iter().all(|v| !v.is_nan()) {
                g.push(((r - l) / (2.0 * dx)).powi(2) + ((u - d) / (2.0 * dx)).powi(2));
            }
        }
    }
    let want = (neumaier(&mut g.iter().copied()) / g.len() as f64).sqrt();
    assert_eq!(n, g.len());
    assert!((sdq - want).abs() <= 1e-13 * want, "{sdq} vs {want}");
}
