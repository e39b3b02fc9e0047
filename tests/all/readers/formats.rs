//! Every format on generated files with a known truth (gen.rs writes them from the layouts, not
//! through the readers): grid, spacing, heights in metres, invalid points, detection by content.

use ndfit::io::{read_scan, ReadOptions};
use ndfit::Heightfield;

use super::gen::{self, stored, HOLES, NX, NY};

fn read_as(bytes: &[u8], name: &str, opts: &ReadOptions) -> ndfit::Result<Heightfield> {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join(name);
    std::fs::write(&p, bytes).expect("write");
    read_scan(&p, opts)
}

/// Compare against `truth(i, j)` in metres; `holes` must be NaN. The tolerance is a few ulps: the
/// reader and this test both compute stored * scale in f64 from the same f32 constants.
fn check(hf: &Heightfield, format: &str, dx: f64, dy: f64, holes: &[usize], truth: impl Fn(usize, usize) -> f64) {
    assert_eq!(hf.meta.format, format);
    assert_eq!((hf.nx, hf.ny), (NX, NY), "{format}: grid");
    assert!((hf.dx - dx).abs() <= 1e-15 * dx, "{format}: dx {} vs {dx}", hf.dx);
    assert!((hf.dy - dy).abs() <= 1e-15 * dy, "{format}: dy {} vs {dy}", hf.dy);
    for i in 0..NY {
        for j in 0..NX {
            let k = i * NX + j;
            let got = hf.at(i, j);
            if holes.contains(&k) {
                assert!(got.is_nan(), "{format}: point {k} should be invalid, got {got}");
            } else {
                let want = truth(i, j);
                assert!((got - want).abs() <= 4.0 * f64::EPSILON * want.abs(), "{format}: ({i},{j}) {got:e} vs {want:e}");
            }
        }
    }
}

fn raw_opts(dx: f64, z: f64) -> ReadOptions {
    ReadOptions { dx: Some(dx), dy: None, z_scale: Some(z), format: None }
}

#[test]
fn binary_instrument_formats_read_their_truth() {
    let none = ReadOptions::default();
    let hf = read_as(&gen::plu(), "a.plu", &none).expect("plu");
    check(&hf, "plu", 1.5e-6, 2.5e-6, &HOLES, |i, j| (stored(i, j) as f32 / 4.0) as f64 * 1e-6);
    for (compressed, name) in [(false, "a.sur"), (true, "b.sur")] {
        let hf = read_as(&gen::sur(compressed), name, &none).expect("sur");
        check(&hf, "sur", 2e-6, 3e-6, &HOLES, |i, j| stored(i, j) as f64 * (0.5 * 1e-9) + 10.0 * 1e-9);
        assert_eq!(hf.meta.instrument.get("sur.compressed").map(String::as_str), Some(if compressed { "true" } else { "false" }));
    }
    for int16 in [false, true] {
        let hf = read_as(&gen::opd(int16), "a.opd", &none).expect("opd");
        let px = 0.002f32 as f64;
        check(&hf, "opd", px * 1e-3, px * 1.5 * 1e-3, &HOLES, |i, j| stored(i, j) as f64 * (600.0 * 1e-9 / 2.0));
    }
    let hf = read_as(&gen::metropro(), "a.dat", &none).expect("metropro");
    let k = 0.5 * 1.0 * 632.8e-9f32 as f64 / 32768.0;
    check(&hf, "metropro", 1e-6f32 as f64, 1e-6f32 as f64, &HOLES, |i, j| stored(i, j) as f64 * k);
    let hf = read_as(&gen::al3d(), "a.al3d", &none).expect("al3d");
    check(&hf, "al3d", 5e-7, 7.5e-7, &HOLES, |i, j| (stored(i, j) as f32 * 1e-6) as f64);
    let hf = read_as(&gen::tmd(), "a.tmd", &none).expect("tmd");
    check(&hf, "tmd", 14.0 / 7.0 * 1e-3, 10.0 / 5.0 * 1e-3, &HOLES, |i, j| (stored(i, j) as f32 / 1000.0) as f64 * 1e-3);
    let hf = read_as(&gen::gsf(), "a.gsf", &none).expect("gsf");
    check(&hf, "gsf", 14.0 / 7.0 * 1e-6, 15.0 / 5.0 * 1e-6, &HOLES, |i, j| stored(i, j) as f64 * 1e-9);
}

#[test]
fn raw_formats_need_and_use_dx_and_z_scale() {
    let o = raw_opts(1e-6, 1e-9);
    let hf = read_as(&gen::npy(), "a.npy", &o).expect("npy");
    check(&hf, "npy", 1e-6, 1e-6, &HOLES, |i, j| stored(i, j) as f64 * 1e-9);
    let hf = read_as(&gen::exr(), "a.exr", &o).expect("exr");
    check(&hf, "exr", 1e-6, 1e-6, &HOLES, |i, j| stored(i, j) as f64 * 1e-9);
    let hf = read_as(&gen::png16(), "a.png", &o).expect("png");
    check(&hf, "png", 1e-6, 1e-6, &HOLES, |i, j| (stored(i, j) + 1000) as f64 * 1e-9);
    let hf = read_as(&gen::tiff16(), "a.tif", &o).expect("tiff");
    check(&hf, "tiff", 1e-6, 1e-6, &[], |i, j| (stored(i, j) + 1000) as f64 * 1e-9);
    let o2 = ReadOptions { dy: Some(2e-6), ..o.clone() };
    let hf = read_as(&gen::ascii(false, " "), "a.txt", &o2).expect("ascii");
    check(&hf, "ascii", 1e-6, 2e-6, &HOLES, |i, j| stored(i, j) as f64 * 1e-9);
    let hf = read_as(&gen::ascii(false, ","), "a.csv", &o).expect("csv matrix");
    check(&hf, "csv", 1e-6, 1e-6, &HOLES, |i, j| stored(i, j) as f64 * 1e-9);

    // Each raw format says which option is missing.
    for (bytes, name) in
        [(gen::npy(), "a.npy"), (gen::exr(), "a.exr"), (gen::png16(), "a.png"), (gen::tiff16(), "a.tif"), (gen::ascii(false, " "), "a.txt")]
    {
        let e = read_as(&bytes, name, &ReadOptions { z_scale: Some(1e-9), ..Default::default() }).expect_err("needs --dx");
        assert_eq!(e.kind(), ndfit::ErrorKind::MissingOption, "{name}: {e}");
        assert!(e.to_string().contains("--dx"), "{name}: {e}");
        let e = read_as(&bytes, name, &ReadOptions { dx: Some(1e-6), ..Default::default() }).expect_err("needs --z-scale");
        assert!(e.to_string().contains("--z-scale"), "{name}: {e}");
    }
}

#[test]
fn ascii_matrix_header_gives_spacing_in_the_height_unit() {
    let o = ReadOptions { z_scale: Some(1e-6), ..Default::default() };
    let hf = read_as(&gen::ascii(true, "\t"), "m.asc", &o).expect("AsciiMatrix");
    check(&hf, "ascii", 2.0 * 1e-6, 3.0 * 1e-6, &HOLES, |i, j| stored(i, j) as f64 * 1e-6);
    // Found by content even with another extension.
    let hf = read_as(&gen::ascii(true, " "), "m.data", &o).expect("by content");
    assert_eq!(hf.meta.format, "ascii");
    // A header that disagrees with the data is refused.
    let mut bad = gen::ascii(true, " ");
    bad[12] = b'9';
    let e = read_as(&bad, "m.asc", &o).expect_err("lying header");
    assert!(e.to_string().contains("AsciiMatrix header says 9 x 5"), "{e}");
}

#[test]
fn xyz_and_csv_point_lists_are_gridded() {
    let o = ReadOptions { z_scale: Some(1e-6), ..Default::default() };
    for (bytes, name, format) in [(gen::xyz(false), "p.xyz", "xyz"), (gen::xyz(true), "p.csv", "csv")] {
        let hf = read_as(&bytes, name, &o).expect(name);
        check(&hf, format, 0.5 * 1e-6, 0.25 * 1e-6, &HOLES, |i, j| stored(i, j) as f64 * 1e-6);
        assert!((hf.x0 - 10.0 * 1e-6).abs() < 1e-18 && (hf.y0 + 2.0 * 1e-6).abs() < 1e-18);
    }
    // Points off the grid are refused rather than snapped.
    let e = read_as(b"0 0 1\n1 0 2\n0 1 3\n1.4 1 4\n", "q.xyz", &o).expect_err("off grid");
    assert!(e.to_string().contains("off the regular grid"), "{e}");
}

#[test]
fn eight_bit_and_colour_images_are_refused_with_a_reason() {
    let o = raw_opts(1e-6, 1e-9);
    let img = image::GrayImage::from_raw(3, 2, vec![1, 2, 3, 4, 5, 6]).expect("img");
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png).expect("png");
    let e = read_as(out.get_ref(), "g8.png", &o).expect_err("8-bit");
    assert!(e.to_string().contains("8-bit"), "{e}");
}
