//! Bad bytes: every generated file of every binary format truncated at every length and with every
//! byte replaced by 0x00, 0xFF and its bit-complement must give Ok or one clear line, never a panic
//! (the cheap, always-on companion of the cargo-fuzz targets). Plus lying headers, empty,
//! all-invalid and non-finite files through the library.

use std::panic::{catch_unwind, AssertUnwindSafe};
use std::path::Path;

use ndfit::io::{detect, read_bytes, read_scan, Format, ReadOptions};

use super::gen;

fn opts() -> ReadOptions {
    ReadOptions { dx: Some(1e-6), dy: None, z_scale: Some(1e-9), format: None }
}

/// Read `bytes` as the format detected for `name` (or the given one), catching panics.
fn try_read(format: Format, bytes: &[u8]) -> Result<(), String> {
    let r = catch_unwind(AssertUnwindSafe(|| read_bytes(format, bytes, &opts())));
    match r {
        Err(_) => Err("panicked".into()),
        Ok(Ok(_)) => Ok(()),
        Ok(Err(e)) => {
            let m = e.to_string();
            if m.contains('\n') || m.is_empty() {
                Err(format!("error is not one line: {m:?}"))
            } else {
                Ok(())
            }
        }
    }
}

#[test]
fn truncations_and_byte_flips_never_panic() {
    // Silence the default panic printout; failures are collected and reported below.
    let hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let mut failures = Vec::new();
    let mut cases = 0usize;
    for (name, good) in gen::binary_files() {
        let format = detect(Path::new(name), &good).unwrap_or_else(|| panic!("{name}: not detected"));
        assert!(try_read(format, &good).is_ok(), "{name}: the valid file fails");
        for len in 0..good.len() {
            cases += 1;
            if let Err(e) = try_read(format, &good[..len]) {
                failures.push(format!("{name} truncated to {len}: {e}"));
            }
        }
        for off in 0..good.len() {
            for val in [0x00u8, 0xFF, !good[off]] {
                let mut b = good.clone();
                b[off] = val;
                cases += 1;
                if let Err(e) = try_read(format, &b) {
                    failures.push(format!("{name} byte {off} = {val:#04x}: {e}"));
                }
            }
        }
    }
    std::panic::set_hook(hook);
    assert!(failures.is_empty(), "{} of {cases} cases failed, first: {:?}", failures.len(), &failures[..failures.len().min(5)]);
    eprintln!("{cases} truncated/flipped files: no panic, every error one line");
}

/// Headers that claim more points than the file holds (or absurd sizes) are refused before any
/// allocation of that size.
#[test]
fn lying_headers_are_refused() {
    let big = u32::MAX.to_le_bytes();
    let mut cases: Vec<(&str, Vec<u8>)> = Vec::new();
    let mut b = gen::plu();
    b[500..504].copy_from_slice(&100_000u32.to_le_bytes());
    cases.push(("plu rows", b));
    let mut b = gen::sur(false);
    b[108..112].copy_from_slice(&1_000_000i32.to_le_bytes());
    b[112..116].copy_from_slice(&1_000_000i32.to_le_bytes());
    b[116..120].copy_from_slice(&(1_000_000u64 * 1_000_000 % (1 << 32)).to_le_bytes()[..4]);
    cases.push(("sur size", b));
    let mut b = gen::sur(true);
    let raw_len_at = 512 + 4;
    b[raw_len_at..raw_len_at + 4].copy_from_slice(&big);
    cases.push(("sur compressed raw length", b));
    let mut b = gen::metropro();
    b[68..70].copy_from_slice(&u16::MAX.to_be_bytes());
    b[70..72].copy_from_slice(&u16::MAX.to_be_bytes());
    b[72..76].copy_from_slice(&(65535u64 * 65535 * 4).to_be_bytes()[4..]);
    cases.push(("metropro size", b));
    let mut b = gen::tmd();
    b[56..60].copy_from_slice(&big);
    b[60..64].copy_from_slice(&big);
    cases.push(("tmd size", b));
    let mut b = gen::npy();
    let s = String::from_utf8_lossy(&b).replace("(5, 7)", "(9999999, 9999)").into_bytes();
    b = s;
    cases.push(("npy shape", b));
    let g = String::from_utf8_lossy(&gen::gsf()[..40]).to_string();
    let mut b = gen::gsf();
    let at = g.find("XRes = 7").expect("XRes") + 7;
    b[at] = b'9';
    cases.push(("gsf xres", b));
    for (what, bytes) in cases {
        let format = detect(Path::new(&format!("x.{}", what.split(' ').next().expect("ext"))), &bytes).expect("detected");
        let e = read_bytes(format, &bytes, &opts()).expect_err(what);
        assert_eq!(e.kind(), ndfit::ErrorKind::Corrupt, "{what}: {e}");
        assert!(!e.to_string().contains('\n'), "{what}: {e}");
    }
}

#[test]
fn empty_all_invalid_and_non_finite_files_are_refused() {
    let dir = tempfile::tempdir().expect("tempdir");
    let write = |name: &str, b: &[u8]| {
        let p = dir.path().join(name);
        std::fs::write(&p, b).expect("write");
        p
    };
    let e = read_scan(&write("empty.x3p", b""), &opts()).expect_err("empty");
    assert!(e.to_string().contains("empty.x3p") && e.to_string().contains("empty"), "{e}");
    // All points NaN or infinite (a GSF whose floats are +inf, -inf and NaN).
    let mut b = gen::gsf();
    let n = gen::NX * gen::NY;
    let start = b.len() - 4 * n;
    for k in 0..n {
        let v = [f32::INFINITY, f32::NEG_INFINITY, f32::NAN][k % 3];
        b[start + 4 * k..start + 4 * k + 4].copy_from_slice(&v.to_le_bytes());
    }
    let e = read_scan(&write("inf.gsf", &b), &opts()).expect_err("non-finite");
    assert!(e.to_string().contains("all 35 points"), "{e}");
    // Unknown content and extension.
    let e = read_scan(&write("noise.bin", &[0x01, 0xfe, 0x00, 0x7f, 0x80]), &opts()).expect_err("unknown");
    assert_eq!(e.kind(), ndfit::ErrorKind::UnknownFormat);
}
