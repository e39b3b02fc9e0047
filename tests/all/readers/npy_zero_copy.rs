//! The zero-copy NPY read (src/heights.rs, `io::npy::read_npy_mapped`): a large C-ordered `<f8` file in
//! metres is read in place, and every case that cannot be (an infinity to mask, a height scale, a
//! misaligned array start) falls back to decoding, with the same heights as the formula that wrote the
//! file. Writing to mapped heights (form removal) copies them and leaves the file untouched.

use ndfit::io::{read_scan, ReadOptions};
use ndfit::preprocess::{apply, Preprocess};

/// Large enough (4 MiB and more) for the memory-mapped read.
const NY: usize = 700;
const NX: usize = 800;

/// The array written: a tilted plane plus a ripple, NaN on a diagonal band.
fn a(i: usize, j: usize) -> f64 {
    if (i + j) % 97 == 5 {
        return f64::NAN;
    }
    1e-6 * (0.3 * i as f64 - 0.2 * j as f64) + 1e-7 * ((i * 31 + j * 17) % 13) as f64
}

/// NPY v1 `<f8` bytes of `a`; `pad` extra bytes in the header move the array start (numpy pads to 64).
fn npy(pad: usize, inf_at: Option<(usize, usize)>) -> Vec<u8> {
    let mut b = super::gen::npy_header("<f8", false, NY, NX);
    if pad > 0 {
        // Grow the header text (before its final newline) and fix its length field.
        let nl = b.len() - 1;
        b.splice(nl..nl, std::iter::repeat_n(b' ', pad));
        let hlen = (b.len() - 10) as u16;
        b[8..10].copy_from_slice(&hlen.to_le_bytes());
    }
    for i in 0..NY {
        for j in 0..NX {
            let v = if inf_at == Some((i, j)) { f64::INFINITY } else { a(i, j) };
            b.extend(v.to_le_bytes());
        }
    }
    b
}

fn read(bytes: &[u8], z_scale: f64) -> (tempfile::TempDir, std::path::PathBuf, ndfit::Heightfield) {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("a.npy");
    std::fs::write(&path, bytes).expect("write");
    let o = ReadOptions { dx: Some(1e-6), dy: None, z_scale: Some(z_scale), format: None };
    let hf = read_scan(&path, &o).expect("read");
    (dir, path, hf)
}

fn assert_heights(hf: &ndfit::Heightfield, scale: f64, inf_at: Option<(usize, usize)>) {
    assert_eq!((hf.nx, hf.ny), (NX, NY));
    for i in 0..NY {
        for j in 0..NX {
            let (want, got) = (a(i, j) * scale, hf.at(i, j));
            if inf_at == Some((i, j)) || want.is_nan() {
                assert!(got.is_nan(), "({i},{j}) must be invalid, got {got}");
            } else {
                // One multiply by the scale at most: exact for scale 1, 1 ulp otherwise.
                assert!((got - want).abs() <= want.abs() * f64::EPSILON, "({i},{j}): {got} vs {want}");
            }
        }
    }
}

#[test]
fn metres_float64_is_read_in_place() {
    let (_d, _p, hf) = read(&npy(0, None), 1.0);
    assert!(hf.z.is_mapped(), "a C-ordered <f8 file in metres is read without a copy");
    assert_heights(&hf, 1.0, None);
}

#[test]
fn cases_that_cannot_be_mapped_are_decoded() {
    // An infinity must become NaN: decoded, not mapped.
    let inf = Some((3, 4));
    let (_d, _p, hf) = read(&npy(0, inf), 1.0);
    assert!(!hf.z.is_mapped());
    assert_heights(&hf, 1.0, inf);
    // A height scale other than 1 must be applied: decoded.
    let (_d, _p, hf) = read(&npy(0, None), 1e-9);
    assert!(!hf.z.is_mapped());
    assert_heights(&hf, 1e-9, None);
    // An array start that is not 8-byte aligned (a hand-written header 3 bytes longer): decoded.
    let (_d, _p, hf) = read(&npy(3, None), 1.0);
    assert!(!hf.z.is_mapped());
    assert_heights(&hf, 1.0, None);
}

#[test]
fn form_removal_on_mapped_heights_copies_and_leaves_the_file_alone() {
    let bytes = npy(0, None);
    let (_d, path, hf) = read(&bytes, 1.0);
    assert!(hf.z.is_mapped());
    let hf = apply(hf, &Preprocess::default()).expect("plane removal");
    assert!(!hf.z.is_mapped(), "written heights are owned");
    // The same heights decoded (a misaligned copy of the file) give the same plane-removed heights, bit
    // for bit: form removal does not depend on where the heights live.
    let (_d2, _p2, decoded) = read(&npy(3, None), 1.0);
    assert!(!decoded.z.is_mapped());
    let decoded = apply(decoded, &Preprocess::default()).expect("plane removal");
    assert!(hf.z.iter().zip(decoded.z.iter()).all(|(a, b)| a.to_bits() == b.to_bits()));
    assert!(hf.z.iter().any(|v| v.is_finite() && *v != 0.0));
    assert_eq!(std::fs::read(&path).expect("reread"), bytes, "the scan file is unchanged");
}
