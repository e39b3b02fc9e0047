//! X3P: round trips through `write_x3p`, every Z data type, valid masks, inline DataList, and the
//! layout variants (namespace or none, sub-folder, junk entries) on generated files.

use std::io::Write;

use ndfit::io::{read_scan, write_x3p, ReadOptions};
use ndfit::Heightfield;

/// A small heightfield with NaN holes, non-square spacing, offsets, extreme and signed-zero values.
pub fn sample_heightfield() -> Heightfield {
    let (nx, ny) = (7, 5);
    let mut z: Vec<f64> = (0..nx * ny).map(|k| ((k as f64) * 0.37).sin() * 1e-6 + 0.0763).collect();
    z[3] = f64::NAN;
    z[17] = f64::NAN;
    z[5] = -0.0;
    z[6] = 1e-300;
    z[7] = -123.456e3;
    let mut hf = Heightfield::new(nx, ny, 1.27656509837346e-7, 3.14582113527746e-7, z).expect("valid grid");
    hf.x0 = 7.65614218798151e-5;
    hf.y0 = -1.29451679506934e-5;
    hf.meta.format = "synthetic".into();
    hf.meta.instrument.insert("comment".into(), "a <test> & \"quotes\"".into());
    hf
}

#[test]
fn write_then_read_is_bit_identical() {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("rt.x3p");
    let hf = sample_heightfield();
    write_x3p(&path, &hf).expect("write");
    let back = read_scan(&path, &ReadOptions::default()).expect("read back");
    assert_eq!((back.nx, back.ny), (hf.nx, hf.ny));
    assert_eq!(back.dx.to_bits(), hf.dx.to_bits());
    assert_eq!(back.dy.to_bits(), hf.dy.to_bits());
    assert_eq!(back.x0.to_bits(), hf.x0.to_bits());
    assert_eq!(back.y0.to_bits(), hf.y0.to_bits());
    for (k, (a, b)) in hf.z.iter().zip(&back.z).enumerate() {
        assert!(a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()), "point {k}: wrote {a:e}, read {b:e}");
    }
    assert_eq!(back.meta.format, "x3p");
    assert_eq!(back.meta.instrument.get("comment"), hf.meta.instrument.get("comment"));
    // No temporary file is left beside the output.
    let left: Vec<_> = std::fs::read_dir(dir.path()).expect("dir").collect();
    assert_eq!(left.len(), 1);
}

#[test]
fn written_file_carries_correct_md5_checksums() {
    let hf = sample_heightfield();
    let bytes = ndfit::io::x3p_bytes(&hf).expect("bytes");
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes)).expect("zip");
    let read = |zip: &mut zip::ZipArchive<std::io::Cursor<Vec<u8>>>, n: &str| {
        let mut v = Vec::new();
        std::io::Read::read_to_end(&mut zip.by_name(n).expect("entry"), &mut v).expect("read");
        v
    };
    let main = String::from_utf8(read(&mut zip, "main.xml")).expect("utf8");
    let data = read(&mut zip, "bindata/data.bin");
    let sums = String::from_utf8(read(&mut zip, "md5checksum.hex")).expect("utf8");
    assert_eq!(data.len(), hf.nx * hf.ny * 8);
    let data_md5 = crate::common::md5_hex(&data);
    assert!(main.contains(&format!("<MD5ChecksumPointData>{data_md5}</MD5ChecksumPointData>")));
    assert!(sums.starts_with(&crate::common::md5_hex(main.as_bytes())));
}

/// Build an X3P zip from a main.xml and named binary entries.
pub fn build_x3p(entries: &[(&str, &[u8])]) -> Vec<u8> {
    let mut out = std::io::Cursor::new(Vec::new());
    {
        let mut zw = zip::ZipWriter::new(&mut out);
        for (name, data) in entries {
            let opts = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
            zw.start_file(*name, opts).expect("start");
            zw.write_all(data).expect("write");
        }
        zw.finish().expect("finish");
    }
    out.into_inner()
}

/// A main.xml with the given root, Z type, CZ increment/offset elements, size and data section.
pub fn main_xml(root_open: &str, root_close: &str, ztype: &str, cz_extra: &str, nx: usize, ny: usize, data: &str) -> String {
    format!(
        r#"<?xml version="1.0" encoding="UTF-8"?>
{root_open}
<Record1><Revision>ISO5436 - 2000</Revision><FeatureType>SUR</FeatureType><Axes>
<CX><AxisType>I</AxisType><DataType>D</DataType><Increment>2.5e-6</Increment><Offset>1e-3</Offset></CX>
<CY><AxisType>I</AxisType><DataType>D</DataType><Increment>5e-7</Increment><Offset>0</Offset></CY>
<CZ><AxisType>A</AxisType><DataType>{ztype}</DataType>{cz_extra}</CZ></Axes></Record1>
<Record2><Date>2024-01-01T00:00:00</Date><Instrument><Manufacturer>Test &amp; Co</Manufacturer><Model>M</Model><Serial>1</Serial><Version>1</Version></Instrument><CalibrationDate>2024-01-01T00:00:00</CalibrationDate><ProbingSystem><Type>NonContacting</Type><Identification>50x</Identification></ProbingSystem><Comment/></Record2>
<Record3><MatrixDimension><SizeX>{nx}</SizeX><SizeY>{ny}</SizeY><SizeZ>1</SizeZ></MatrixDimension>{data}</Record3>
<Record4><ChecksumFile>md5checksum.hex</ChecksumFile></Record4>
{root_close}"#
    )
}

const NS_OPEN: &str = r#"<p:ISO5436_2 xmlns:p="http://www.opengps.eu/2008/ISO5436_2">"#;
const NS_CLOSE: &str = "</p:ISO5436_2>";
const LINK: &str = "<DataLink><PointDataLink>bindata/data.bin</PointDataLink></DataLink>";

fn read_bytes_as_file(bytes: &[u8], name: &str) -> ndfit::Result<Heightfield> {
    let dir = tempfile::tempdir().expect("tempdir");
    let p = dir.path().join(name);
    std::fs::write(&p, bytes).expect("write");
    read_scan(&p, &ReadOptions::default())
}

#[test]
fn every_z_data_type_decodes_with_increment_and_offset() {
    let (nx, ny) = (3, 2);
    let ints: [i32; 6] = [-32768, -1, 0, 1, 1234, 32767];
    let (inc, off) = (2.5e-9, -1.0e-6);
    let cz = format!("<Increment>{inc:e}</Increment><Offset>{off:e}</Offset>");
    // Expected values computed here from the ISO rule z = Offset + Increment * stored.
    let want: Vec<f64> = ints.iter().map(|&v| off + inc * v as f64).collect();
    let cases: Vec<(&str, Vec<u8>)> = vec![
        ("I", ints.iter().flat_map(|&v| (v as i16).to_le_bytes()).collect()),
        ("L", ints.iter().flat_map(|&v| v.to_le_bytes()).collect()),
        ("F", ints.iter().flat_map(|&v| (v as f32).to_le_bytes()).collect()),
        ("D", ints.iter().flat_map(|&v| (v as f64).to_le_bytes()).collect()),
    ];
    for (t, data) in cases {
        let xml = main_xml(NS_OPEN, NS_CLOSE, t, &cz, nx, ny, LINK);
        let zipb = build_x3p(&[("main.xml", xml.as_bytes()), ("bindata/data.bin", &data)]);
        let hf = read_bytes_as_file(&zipb, "t.x3p").unwrap_or_else(|e| panic!("type {t}: {e}"));
        assert_eq!((hf.nx, hf.ny), (nx, ny));
        assert_eq!(hf.dx, 2.5e-6);
        assert_eq!(hf.dy, 5e-7);
        assert_eq!(hf.x0, 1e-3);
        for (a, b) in hf.z.iter().zip(&want) {
            assert!((a - b).abs() <= 1e-15 * b.abs().max(1e-12), "type {t}: {a:e} vs {b:e}");
        }
        assert_eq!(hf.meta.instrument.get("manufacturer").map(String::as_str), Some("Test & Co"));
    }
}

#[test]
fn valid_mask_and_nan_mark_invalid_points() {
    let (nx, ny) = (5, 2);
    let data: Vec<u8> = (0..10i32).flat_map(|k| k.to_le_bytes()).collect();
    // Bits, least significant first: points 1 and 8 invalid.
    let valid = [0b1111_1101u8, 0b0000_0010];
    let link = "<DataLink><PointDataLink>bindata/data.bin</PointDataLink><ValidPointsLink>bindata/valid.bin</ValidPointsLink></DataLink>";
    let xml = main_xml(NS_OPEN, NS_CLOSE, "L", "", nx, ny, link);
    let zipb = build_x3p(&[("main.xml", xml.as_bytes()), ("bindata/data.bin", &data), ("bindata/valid.bin", &valid)]);
    let hf = read_bytes_as_file(&zipb, "v.x3p").expect("read");
    let invalid: Vec<usize> = (0..10).filter(|&k| hf.z[k].is_nan()).collect();
    assert_eq!(invalid, vec![1, 8]);
    assert_eq!(hf.z[9], 9.0);

    // Float data: NaN is the marker, and an infinity is masked too (never a height).
    let fdata: Vec<u8> = [1.0f64, f64::NAN, 3.0, f64::INFINITY, 5.0, 6.0].iter().flat_map(|v| v.to_le_bytes()).collect();
    let xml = main_xml(NS_OPEN, NS_CLOSE, "D", "", 3, 2, LINK);
    let zipb = build_x3p(&[("main.xml", xml.as_bytes()), ("bindata/data.bin", &fdata)]);
    let hf = read_bytes_as_file(&zipb, "f.x3p").expect("read");
    assert_eq!(hf.invalid_count(), 2);
}

#[test]
fn inline_data_list_is_read() {
    let list = "<DataList><Datum>1.5e-6</Datum><Datum/><Datum>-2e-6</Datum><Datum>0</Datum></DataList>";
    let xml = main_xml(NS_OPEN, NS_CLOSE, "D", "", 2, 2, list);
    let zipb = build_x3p(&[("main.xml", xml.as_bytes())]);
    let hf = read_bytes_as_file(&zipb, "l.x3p").expect("read");
    assert_eq!(hf.z[0], 1.5e-6);
    assert!(hf.z[1].is_nan());
    assert_eq!(hf.z[2], -2e-6);
}

#[test]
fn layout_variants_are_read_without_guessing() {
    let data: Vec<u8> = (0..6).flat_map(|k| (k as f64 * 1e-6).to_le_bytes()).collect();
    // No namespace, pre-standard root, sub-folder, junk entries, empty optional Offset.
    let xml = main_xml("<ISO5436>", "</ISO5436>", "D", "<Increment>1</Increment><Offset/>", 3, 2, LINK);
    let zipb = build_x3p(&[
        ("__MACOSX/scan/._main.xml", b"junk"),
        ("scan/main.xml", xml.as_bytes()),
        ("scan/bindata/data.bin", &data),
        ("scan/bindata/.DS_Store", b"junk"),
    ]);
    let hf = read_bytes_as_file(&zipb, "s.x3p").expect("read");
    assert_eq!(hf.z[5], 5.0 * 1e-6);
    assert_eq!(hf.meta.instrument.get("x3p.folder").map(String::as_str), Some("scan/"));
    // Detected by content even under another extension.
    let hf = read_bytes_as_file(&zipb, "s.bin").expect("read by content");
    assert_eq!(hf.meta.format, "x3p");
}

#[test]
fn x3p_defects_give_one_precise_line() {
    let data: Vec<u8> = (0..6).flat_map(|k| (k as f64).to_le_bytes()).collect();
    let cases: Vec<(Vec<u8>, &str)> = vec![
        // Header claims more points than data.bin holds.
        (build_x3p(&[("main.xml", main_xml(NS_OPEN, NS_CLOSE, "D", "", 300, 200, LINK).as_bytes()), ("bindata/data.bin", &data)]), "need"),
        // Absurd sizes: the multiplication overflows.
        (
            build_x3p(&[
                ("main.xml", main_xml(NS_OPEN, NS_CLOSE, "D", "", usize::MAX / 2, 3, LINK).as_bytes()),
                ("bindata/data.bin", &data),
            ]),
            "overflows",
        ),
        (build_x3p(&[("main.xml", main_xml(NS_OPEN, NS_CLOSE, "Q", "", 3, 2, LINK).as_bytes())]), "DataType"),
        (build_x3p(&[("main.xml", main_xml(NS_OPEN, NS_CLOSE, "D", "", 3, 2, LINK).as_bytes())]), "does not hold"),
        (build_x3p(&[("other.txt", b"hello")]), "no main.xml"),
        (build_x3p(&[("main.xml", b"<a><b></a>")]), "XML"),
        (build_x3p(&[("main.xml", main_xml(NS_OPEN, NS_CLOSE, "D", "", 0, 2, LINK).as_bytes())]), "empty"),
        // All points invalid.
        (
            build_x3p(&[
                ("main.xml", main_xml(NS_OPEN, NS_CLOSE, "D", "", 3, 2, LINK).as_bytes()),
                ("bindata/data.bin", &[f64::NAN; 6].iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>()),
            ]),
            "all 6 points",
        ),
    ];
    for (k, (bytes, needle)) in cases.iter().enumerate() {
        let err = read_bytes_as_file(bytes, "bad.x3p").expect_err("must fail");
        let msg = err.to_string();
        assert!(msg.contains("bad.x3p"), "case {k}: message does not name the file: {msg}");
        assert!(msg.contains(needle), "case {k}: {msg:?} lacks {needle:?}");
        assert!(!msg.contains('\n'), "case {k}: more than one line: {msg}");
    }
}

/// The entries of an X3P zip, in order, as (name, bytes).
fn entries_of(bytes: &[u8]) -> Vec<(String, Vec<u8>)> {
    let mut zip = zip::ZipArchive::new(std::io::Cursor::new(bytes)).expect("zip");
    (0..zip.len())
        .map(|i| {
            let mut e = zip.by_index(i).expect("entry");
            let mut v = Vec::new();
            std::io::Read::read_to_end(&mut e, &mut v).expect("read");
            (e.name().expect("name").into_owned(), v)
        })
        .collect()
}

#[test]
fn md5_checksums_are_checked() {
    let good = ndfit::io::x3p_bytes(&sample_heightfield()).expect("bytes");
    let entries = entries_of(&good);
    let get = |n: &str| entries.iter().find(|(k, _)| k == n).map(|(_, v)| v.clone()).expect(n);
    let (main, data) = (String::from_utf8(get("main.xml")).unwrap(), get("bindata/data.bin"));
    // MD5s computed by an independent implementation (Python's hashlib) of a fixed text, so the
    // reader's MD5 is not checked against itself only.
    assert_eq!(crate::common::md5_hex(b"<main/>\n"), "e18d496402bd1faf45c061ec443aa483");
    let rebuild = |main: &str, sums: &[u8], data: &[u8]| {
        build_x3p(&[("main.xml", main.as_bytes()), ("bindata/data.bin", data), ("md5checksum.hex", sums)])
    };
    let main_sum = |m: &str| format!("{} *main.xml\n", crate::common::md5_hex(m.as_bytes()));
    // As written, and with the variants writers use (upper case, the bare sum), the file reads.
    for sums in [main_sum(&main), main_sum(&main).to_uppercase(), crate::common::md5_hex(main.as_bytes())] {
        read_bytes_as_file(&rebuild(&main, sums.as_bytes(), &data), "ok.x3p").expect("checksums verify");
    }
    // main.xml edited after its checksum was written: corrupt, naming the checksum file.
    let edited = main.replace("<SizeZ>1</SizeZ>", "<SizeZ>1</SizeZ> ");
    assert_ne!(edited, main);
    let err = read_bytes_as_file(&rebuild(&edited, main_sum(&main).as_bytes(), &data), "bad.x3p").expect_err("must fail");
    assert_eq!(err.kind(), ndfit::ErrorKind::Corrupt);
    let msg = err.to_string();
    assert!(msg.contains("bad.x3p") && msg.contains("md5checksum.hex") && !msg.contains('\n'), "{msg}");
    // Point data changed (one value), with a zip CRC and main.xml checksum that agree: caught by the
    // point-data MD5 alone.
    let mut altered = data.clone();
    altered[8] ^= 1;
    let err = read_bytes_as_file(&rebuild(&main, main_sum(&main).as_bytes(), &altered), "bad.x3p").expect_err("must fail");
    assert_eq!(err.kind(), ndfit::ErrorKind::Corrupt);
    let msg = err.to_string();
    assert!(msg.contains("bad.x3p") && msg.contains("bindata/data.bin") && msg.contains("MD5ChecksumPointData"), "{msg}");
    // A checksum file without a sum is a writer's quirk: read, with a note.
    let hf = read_bytes_as_file(&rebuild(&main, b"n/a\n", &data), "q.x3p").expect("read");
    assert!(hf.meta.instrument.get("x3p.md5_note").is_some_and(|n| n.contains("md5checksum.hex")), "{:?}", hf.meta.instrument);
}

#[test]
fn real_x3p_scans_pass_their_checksums() {
    let Some(dir) = crate::common::shared_scans("real_x3p_scans_pass_their_checksums") else { return };
    let mut n = 0;
    for e in std::fs::read_dir(&dir).expect("dir") {
        let p = e.expect("entry").path();
        if p.extension().is_some_and(|x| x == "x3p") {
            let hf = read_scan(&p, &ReadOptions::default()).unwrap_or_else(|e| panic!("{e}"));
            assert!(!hf.meta.instrument.contains_key("x3p.md5_note"), "{}", p.display());
            n += 1;
        }
    }
    assert!(n >= 5, "{n} X3P scans");
}
