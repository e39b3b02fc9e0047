//! The subsampled read (`io::read_scan_subsampled`): every `stride`-th point along both axes, the same
//! heightfield as reading the whole file and subsampling it (`preprocess::subsample`), bit for bit, and
//! the heights the formula that wrote the file gives at the kept points. Large C-ordered NPY files
//! decode only the kept points from their memory map; every other file (Fortran order, small files,
//! other formats) is read whole and subsampled.

use ndfit::io::{read_scan, read_scan_subsampled, ReadOptions};
use ndfit::preprocess::subsample;
use ndfit::Heightfield;

/// Large enough (4 MiB and more at 4 or 8 bytes per value) for the memory-mapped read.
const NY: usize = 1100;
const NX: usize = 1000;

/// The array written: a tilted plane plus a ripple, NaN on a diagonal band, an infinity at a kept
/// point of every stride (0, 0 is kept by all) and one at a dropped point.
fn a(i: usize, j: usize) -> f64 {
    if (i, j) == (0, 0) || (i, j) == (1, 2) {
        return f64::INFINITY;
    }
    if (i + j) % 97 == 5 {
        return f64::NAN;
    }
    1e-6 * (0.3 * i as f64 - 0.2 * j as f64) + 1e-7 * ((i * 31 + j * 17) % 13) as f64
}

/// NPY bytes of `a` with dtype `<f8` or `<f4`, C or Fortran order.
fn npy(descr: &str, fortran: bool) -> Vec<u8> {
    let mut b = super::gen::npy_header(descr, fortran, NY, NX);
    let (outer, inner) = if fortran { (NX, NY) } else { (NY, NX) };
    for o in 0..outer {
        for k in 0..inner {
            let (i, j) = if fortran { (k, o) } else { (o, k) };
            match descr {
                "<f8" => b.extend(a(i, j).to_le_bytes()),
                "<f4" => b.extend((a(i, j) as f32).to_le_bytes()),
                d => panic!("no writer for {d}"),
            }
        }
    }
    b
}

fn same(x: &Heightfield, y: &Heightfield) -> bool {
    (x.nx, x.ny, x.dx, x.dy, x.x0, x.y0) == (y.nx, y.ny, y.dx, y.dy, y.x0, y.y0)
        && x.z.iter().zip(y.z.iter()).all(|(p, q)| p.to_bits() == q.to_bits() || (p.is_nan() && q.is_nan()))
        && x.meta == y.meta
}

fn check(name: &str, bytes: &[u8], z_scale: f64, as_f32: bool) {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join(name);
    std::fs::write(&path, bytes).expect("write");
    let o = ReadOptions { dx: Some(1e-6), dy: None, z_scale: Some(z_scale), format: None };
    let whole = read_scan(&path, &o).expect("read");
    for stride in [1, 2, 3, 4, 7] {
        let got = read_scan_subsampled(&path, &o, stride).expect("subsampled read");
        let want = subsample(&whole, stride).expect("subsample");
        assert!(same(&got, &want), "{name} stride {stride}: differs from read + subsample");
        // And against the formula: infinities and NaN invalid, the rest scaled once.
        assert_eq!((got.nx, got.ny), (NX.div_ceil(stride), NY.div_ceil(stride)));
        assert_eq!(got.dx, 1e-6 * stride as f64);
        for i in 0..got.ny {
            for j in 0..got.nx {
                let v = a(i * stride, j * stride);
                let v = if as_f32 { v as f32 as f64 } else { v };
                let g = got.at(i, j);
                if v.is_finite() {
                    assert!(
                        (g - v * z_scale).abs() <= (v * z_scale).abs() * f64::EPSILON,
                        "{name} stride {stride} ({i},{j}): {g} vs {}",
                        v * z_scale
                    );
                } else {
                    assert!(g.is_nan(), "{name} stride {stride} ({i},{j}) must be invalid, got {g}");
                }
            }
        }
    }
}

#[test]
fn subsampled_read_equals_read_then_subsample() {
    check("c_f8.npy", &npy("<f8", false), 1.0, false);
    check("c_f8_scaled.npy", &npy("<f8", false), 1e-9, false);
    check("c_f4.npy", &npy("<f4", false), 1.0, true);
    check("fortran_f8.npy", &npy("<f8", true), 1.0, false);
}

#[test]
fn small_and_text_files_are_read_whole_then_subsampled() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("small.txt");
    let text: String =
        (0..9).map(|i| (0..11).map(|j| format!("{}", (i * 11 + j) as f64 * 1e-7)).collect::<Vec<_>>().join(" ") + "\n").collect();
    std::fs::write(&path, text).expect("write");
    let o = ReadOptions { dx: Some(1e-6), dy: None, z_scale: Some(1.0), format: None };
    let got = read_scan_subsampled(&path, &o, 3).expect("subsampled read");
    assert_eq!((got.nx, got.ny), (4, 3));
    for i in 0..3 {
        for j in 0..4 {
            assert_eq!(got.at(i, j), ((3 * i) * 11 + 3 * j) as f64 * 1e-7);
        }
    }
    let err = read_scan_subsampled(&path, &o, 0).expect_err("stride 0");
    let msg = err.to_string();
    assert!(msg.contains("small.txt") && msg.contains("at least 1"), "{msg}");
}
