//! The plane form folded into the slopes ([`ndfit::ndf::BandSource::plane_folded`]) against the
//! residual heights the whole-scan form removal makes ([`ndfit::preprocess::Prepared::into_scan`]): the
//! same frame, grid, bins and sample count; every normal counted in the cell that an independent scalar
//! recomputation (raw slope in the moved frame) gives, and in the cell of its residual slope except on a
//! cell edge; moments within 1e-9 relative. On odd grids with holes and masked spikes, with bands of 1
//! and 3 rows and the default. And the CSV: every number parses back to the same bits.

use ndfit::ndf::write_csv_to;
use ndfit::ndf::{empirical_ndf, EmpiricalNdf, NdfOptions, NormalScheme};
use ndfit::pipeline::ndf_prepared;
use ndfit::preprocess::{prepare, Preprocess};
use ndfit::scan::{set_band_rows, BandSource};
use ndfit::synth::{ellipsoid_surface, EllipsoidParams, SynthSettings};
use ndfit::Heightfield;

/// An ellipsoid NDF surface (holes in it), or a wave for small grids, on a steep tilt and an offset far
/// above the roughness, with a few spikes for the despiking to mask.
fn tilted(nx: usize, ny: usize) -> Heightfield {
    let mut hf = if nx * ny > 10_000 {
        let s = SynthSettings { nx, ny, dx: 1e-6, dy: 2e-6, seed: 5, holes: 0.003, ..Default::default() };
        ellipsoid_surface(&s, &EllipsoidParams { alpha_x: 0.3, alpha_y: 0.15, theta_z: 0.4, ..Default::default() }).expect("valid").0
    } else {
        let z = (0..nx * ny)
            .map(|k| {
                let (i, j) = ((k / nx) as f64, (k % nx) as f64);
                if k % 41 == 7 {
                    f64::NAN
                } else {
                    2e-7 * (0.9 * j + 0.3 * i).sin() + 3e-7 * (0.23 * j - 0.17 * i).cos()
                }
            })
            .collect();
        Heightfield::new(nx, ny, 1e-6, 2e-6, z).expect("grid")
    };
    for i in 0..ny {
        for j in 0..nx {
            let k = i * nx + j;
            hf.z[k] += 2e-3 + 0.35 * (j as f64 * hf.dx) - 0.6 * (i as f64 * hf.dy);
            if k % 3001 == 17 {
                hf.z[k] += 5e-5;
            }
        }
    }
    hf
}

/// Every central-difference slope of `src`, in stencil order.
fn slopes<S: BandSource>(src: &S) -> Vec<[f64; 2]> {
    let mut buf = Vec::new();
    let ny = src.shape().ny;
    let band = src.band(0, ny, &mut buf);
    let mut out = Vec::new();
    for i in NormalScheme::Central.rows(&band) {
        NormalScheme::Central.row_slopes(&band, i, 1, |sx, sy| out.push([sx, sy]));
    }
    out
}

fn counts(ndf: &EmpiricalNdf) -> Vec<u64> {
    let mut c = vec![0u64; ndf.grid.cells()];
    for (b, &k) in ndf.bins.iter().zip(&ndf.bin_cells) {
        c[k as usize] = b.count;
    }
    c
}

#[test]
fn folded_plane_equals_the_residual_heights() {
    for (nx, ny) in [(157, 101), (64, 5), (5, 64), (33, 17)] {
        let hf = tilted(nx, ny);
        for rows in [Some(1), Some(3), None] {
            set_band_rows(rows);
            let what = format!("{nx} x {ny}, band rows {rows:?}");
            let opts = NdfOptions::default();
            let p = prepare(hf.clone(), &Preprocess::default()).expect("prepare");
            let (raw, g) = p.plane_folded().expect("a plane form is folded");
            let folded = ndf_prepared(&p, &opts).expect("folded ndf");
            let residual = p.clone().into_scan();
            let old = empirical_ndf(&residual, &opts).expect("residual ndf");
            if nx * ny > 10_000 {
                assert!(!p.masked().is_empty(), "{what}: spikes masked");
            }
            // The invalid points the form's fit counted, against those of the residual heights.
            assert_eq!(p.invalid_count(), residual.z.iter().filter(|h| h.is_nan()).count(), "{what}: invalid points");
            // Placed on the residual heights alike: the same frame, grid and bins.
            assert_eq!(folded.frame, old.frame, "{what}: frame");
            assert_eq!(folded.grid.n, old.grid.n, "{what}: grid");
            assert_eq!(folded.bin_cells, old.bin_cells, "{what}: bins");
            assert_eq!((folded.n_samples, folded.n_skipped), (old.n_samples, old.n_skipped), "{what}: samples");
            // The scalar recomputation: residual slopes in the frame, raw slopes in the frame moved by g.
            let (sr, sw) = (slopes(&residual), slopes(&raw));
            assert_eq!(sr.len(), sw.len(), "{what}: stencils");
            let f = old.frame;
            let moved = ndfit::ndf::SlopeFrame { center: [f.center[0] + g[0], f.center[1] + g[1]], ..f };
            let mut want = vec![0u64; old.grid.cells()];
            let mut off_edge = 0u64;
            let scale = f.cov[0][0].max(f.cov[1][1]).sqrt();
            let mut worst = 0.0f64;
            for (r, w) in sr.iter().zip(&sw) {
                let (a, b) = (old.grid.cell_of(f.to_lambert(r[0], r[1])), old.grid.cell_of(moved.to_lambert(w[0], w[1])));
                want[b] += 1;
                off_edge += (a != b) as u64;
                // The folded slope against the residual one: rounding only.
                worst = worst.max((w[0] - g[0] - r[0]).abs().max((w[1] - g[1] - r[1]).abs()) / scale);
            }
            assert_eq!(counts(&folded), want, "{what}: counts against the scalar recomputation");
            assert_eq!(counts(&old).iter().sum::<u64>(), want.iter().sum::<u64>(), "{what}: total");
            // A normal changes cell only on an edge: the slopes agree to rounding, so very few do.
            assert!(worst < 1e-9, "{what}: folded slopes differ by {worst:e} of the slope scale");
            assert!(off_edge as f64 <= 1e-4 * sr.len() as f64, "{what}: {off_edge} of {} normals moved cell", sr.len());
            let moved_counts: u64 = counts(&folded).iter().zip(counts(&old)).map(|(a, b)| a.abs_diff(b)).sum();
            assert!(moved_counts <= 2 * off_edge, "{what}: counts differ by {moved_counts}, {off_edge} normals on an edge");
            let rel = |a: f64, b: f64, s: f64| (a - b).abs() / s;
            for k in 0..2 {
                assert!(rel(folded.slope_mean[k], old.slope_mean[k], scale) < 1e-9, "{what}: mean");
                for l in 0..2 {
                    assert!(rel(folded.slope_cov[k][l], old.slope_cov[k][l], scale * scale) < 1e-9, "{what}: cov");
                }
            }
            // The resolution test on the folded slopes: the same decisions up to normals on its threshold.
            let (ua, ub): (u64, u64) = (folded.unresolved.iter().sum(), old.unresolved.iter().sum());
            assert!(ua.abs_diff(ub) as f64 <= 1e-4 * sr.len() as f64 + 1.0, "{what}: unresolved {ua} vs {ub}");
            eprintln!("{what}: {} normals, {off_edge} moved cell, slope rounding {worst:.1e}, unresolved {ua} vs {ub}", sr.len());
        }
    }
    set_band_rows(None);
}

/// The CSV's numbers parse back to the NDF's values bit for bit (shortest round-trip digits, exponent
/// form included), and the integer columns are the counts.
#[test]
fn ndf_csv_numbers_round_trip() {
    let p = prepare(tilted(157, 101), &Preprocess::default()).expect("prepare");
    // A fine grid: the rim's slivers have solid angles far below 1e-5 sr.
    let ndf = ndf_prepared(&p, &NdfOptions { cells_across: Some(511), ..Default::default() }).expect("ndf");
    let mut out = Vec::new();
    write_csv_to(&mut out, &ndf).expect("csv");
    let text = String::from_utf8(out).expect("utf-8");
    let mut lines = text.lines();
    assert_eq!(lines.next(), Some(ndfit::ndf::CSV_HEADER));
    let mut exponents = 0;
    let mut n = 0;
    for (k, line) in lines.enumerate() {
        let b = &ndf.bins[k];
        let f: Vec<&str> = line.split(',').collect();
        assert_eq!(f.len(), 11, "line {k}: {line}");
        let want = [b.m.x, b.m.y, b.m.z, b.d, b.stderr, b.solid_angle, b.proj_solid_angle, -b.m.x / b.m.z, -b.m.y / b.m.z];
        let got: Vec<f64> = [0, 1, 2, 3, 4, 6, 7, 8, 9].iter().map(|&i| f[i].parse::<f64>().expect("a float")).collect();
        for (g, w) in got.iter().zip(want) {
            assert_eq!(g.to_bits(), w.to_bits(), "line {k}: {line}");
        }
        assert_eq!(f[5].parse::<u64>().expect("count"), b.count);
        assert_eq!(f[10].parse::<u64>().ok(), ndf.unresolved.get(k).copied(), "line {k}: unresolved");
        exponents += f.iter().filter(|s| s.contains('e')).count();
        n += 1;
    }
    assert_eq!(n, ndf.bins.len());
    assert!(exponents > 0, "small solid angles are written with an exponent");
}
