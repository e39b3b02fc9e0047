//! NPY layouts through the one-pass decoder (src/io/npy.rs): Fortran order, big-endian float32,
//! infinities (masked as NaN in the decode pass, as `Heightfield::new` masks them), and a file large
//! enough (> 4 MiB) to take the memory-mapped path and the huge-page heights buffer. The truth is the
//! closed-form array `a(i, j)` the files are written from, not the reader's output.

use ndfit::io::{read_scan, ReadOptions};

/// The array written: distinct, exactly representable in f32 (integers < 2^24), with an infinity of
/// each sign and a NaN at fixed places.
fn a(i: usize, j: usize) -> f64 {
    match (i * 7 + j * 3) % 101 {
        0 => f64::INFINITY,
        1 => f64::NEG_INFINITY,
        2 => f64::NAN,
        _ => (i * 1000 + j) as f64 - 5000.0,
    }
}

/// NPY v1 bytes of `a` on an `ny x nx` grid, with the given descr and order.
fn npy(ny: usize, nx: usize, descr: &str, fortran: bool) -> Vec<u8> {
    let mut b = super::gen::npy_header(descr, fortran, ny, nx);
    let order: Vec<(usize, usize)> = if fortran {
        (0..nx).flat_map(|j| (0..ny).map(move |i| (i, j))).collect()
    } else {
        (0..ny).flat_map(|i| (0..nx).map(move |j| (i, j))).collect()
    };
    for (i, j) in order {
        let v = a(i, j);
        match descr {
            "<f8" => b.extend(v.to_le_bytes()),
            ">f4" => b.extend((v as f32).to_be_bytes()),
            d => panic!("test writer has no {d}"),
        }
    }
    b
}

fn check(ny: usize, nx: usize, descr: &str, fortran: bool) {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("a.npy");
    std::fs::write(&path, npy(ny, nx, descr, fortran)).expect("write");
    let zs = 1e-9;
    let o = ReadOptions { dx: Some(1e-6), dy: None, z_scale: Some(zs), format: None };
    let hf = read_scan(&path, &o).expect("read");
    assert_eq!((hf.nx, hf.ny), (nx, ny));
    for i in 0..ny {
        for j in 0..nx {
            let want = a(i, j);
            let got = hf.at(i, j);
            if want.is_finite() {
                // Integers of magnitude < 2^24 times 1e-9: the reader's one multiply is exact to 1 ulp.
                assert!(
                    (got - want * zs).abs() <= (want * zs).abs() * f64::EPSILON,
                    "{descr} F={fortran} ({i},{j}): {got} vs {}",
                    want * zs
                );
            } else {
                assert!(got.is_nan(), "{descr} F={fortran} ({i},{j}): non-finite {want} must read as NaN, got {got}");
            }
        }
    }
}

#[test]
fn c_and_fortran_order_small_grids_match_the_array() {
    for (descr, fortran) in [("<f8", false), ("<f8", true), (">f4", false), (">f4", true)] {
        check(5, 3, descr, fortran);
        check(4, 9, descr, fortran);
    }
}

#[test]
fn large_mapped_files_match_the_array() {
    // 1100 x 600 float64 = 5.3 MB (> the 4 MiB mapping threshold and the huge-page minimum).
    check(600, 1100, "<f8", false);
    check(600, 1100, "<f8", true);
}
