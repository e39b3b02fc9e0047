//! Deflated X3P point data (read block by block, straight into the heights, MD5 on a second thread)
//! against the same data stored (read whole): the same heights bit for bit, the same fit, for every Z
//! type, odd sizes spanning several blocks, with CZ Offset/Increment; a wrong MD5 or damaged deflate
//! stream is a one-line `corrupt` error.

use std::io::Write;

use ndfit::io::{read_scan, ReadOptions};

use super::x3p::main_xml;

/// An X3P with `data` as `bindata/data.bin`, deflated or stored, and its point-data MD5 `md5`.
pub(super) fn x3p(ztype: &str, cz: &str, nx: usize, ny: usize, data: &[u8], md5: &str, deflated: bool) -> Vec<u8> {
    let link =
        format!("<DataLink><PointDataLink>bindata/data.bin</PointDataLink><MD5ChecksumPointData>{md5}</MD5ChecksumPointData></DataLink>");
    let main = main_xml("<ISO5436_2>", "</ISO5436_2>", ztype, cz, nx, ny, &link);
    let mut out = std::io::Cursor::new(Vec::new());
    {
        let mut zw = zip::ZipWriter::new(&mut out);
        let def = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
        let method = if deflated { zip::CompressionMethod::Deflated } else { zip::CompressionMethod::Stored };
        zw.start_file("main.xml", def).unwrap();
        zw.write_all(main.as_bytes()).unwrap();
        zw.start_file("bindata/data.bin", zip::write::SimpleFileOptions::default().compression_method(method)).unwrap();
        zw.write_all(data).unwrap();
        zw.finish().unwrap();
    }
    out.into_inner()
}

/// Stored values of type `ztype`: a smooth sloped surface with noise-like detail and, for floats, holes.
pub(super) fn values(ztype: &str, nx: usize, ny: usize) -> Vec<u8> {
    let mut raw = Vec::new();
    for i in 0..ny {
        for j in 0..nx {
            let k = i * nx + j;
            let h = 0.2 * j as f64 - 0.1 * i as f64 + 3.0 * ((k as f64) * 0.7).sin();
            match ztype {
                "D" => raw.extend_from_slice(&(if k % 997 == 11 { f64::NAN } else { h * 1e-6 }).to_le_bytes()),
                "F" => raw.extend_from_slice(&(if k % 991 == 7 { f32::NAN } else { (h * 1e-6) as f32 }).to_le_bytes()),
                "L" => raw.extend_from_slice(&((h * 1e3) as i32).to_le_bytes()),
                _ => raw.extend_from_slice(&((h * 10.0) as i16).to_le_bytes()),
            }
        }
    }
    raw
}

#[test]
fn deflated_and_stored_point_data_read_and_fit_identically() {
    let d = tempfile::tempdir().unwrap();
    // 257 x 131 float64 is 269 kB: more than one inflate block, and a partial last block.
    for (ztype, cz, nx, ny) in [
        ("D", "", 257, 131),
        ("D", "<Increment>1e-3</Increment><Offset>2.5e-6</Offset>", 129, 67),
        ("F", "", 255, 129),
        ("L", "<Increment>1e-9</Increment>", 131, 97),
        ("I", "<Increment>1e-7</Increment><Offset>-1e-6</Offset>", 97, 131),
    ] {
        let raw = values(ztype, nx, ny);
        let md5 = crate::common::md5_hex(&raw);
        let (ps, pd) = (d.path().join(format!("s{ztype}{nx}.x3p")), d.path().join(format!("d{ztype}{nx}.x3p")));
        std::fs::write(&ps, x3p(ztype, cz, nx, ny, &raw, &md5, false)).unwrap();
        std::fs::write(&pd, x3p(ztype, cz, nx, ny, &raw, &md5, true)).unwrap();
        let (s, f) = (read_scan(&ps, &ReadOptions::default()).unwrap(), read_scan(&pd, &ReadOptions::default()).unwrap());
        assert_eq!((s.nx, s.ny, f.nx, f.ny), (nx, ny, nx, ny));
        assert!(s.z.iter().zip(f.z.iter()).all(|(a, b)| a.to_bits() == b.to_bits()), "{ztype} {cz}: heights differ");
        assert!(f.z.iter().any(|v| v.is_finite()));
        // The same outcome from both files: the same fit, or (this surface is rough at the sampling step,
        // where no model may fit) the same error but for the file's name.
        let fit = |p: &std::path::Path| match ndfit::Pipeline::new(ndfit::Options::default()).run_path(p) {
            Ok(out) => {
                let mut v = serde_json::to_value(&out.fit).unwrap();
                for k in ["timings", "input"] {
                    v.as_object_mut().unwrap().remove(k);
                }
                v
            }
            Err(e) => serde_json::json!({ "error": e.to_string().replace(p.to_str().unwrap(), "") }),
        };
        if ztype == "D" {
            assert_eq!(fit(&ps), fit(&pd), "{cz}");
        }
    }
}

#[test]
fn a_deflated_data_bin_with_a_wrong_md5_or_a_damaged_stream_is_refused() {
    let d = tempfile::tempdir().unwrap();
    let (nx, ny) = (101, 77);
    let raw = values("D", nx, ny);
    let p = d.path().join("bad.x3p");
    std::fs::write(&p, x3p("D", "", nx, ny, &raw, &"0".repeat(32), true)).unwrap();
    let e = read_scan(&p, &ReadOptions::default()).unwrap_err();
    assert_eq!(e.kind(), ndfit::ErrorKind::Corrupt);
    let msg = e.to_string();
    assert!(msg.contains("bad.x3p") && msg.contains("MD5ChecksumPointData") && !msg.contains('\n'), "{msg}");

    // Flip bytes inside the compressed point data: inflate fails or the CRC-32 (checked at the end of
    // the entry) does not match; either way a one-line corrupt error, never a panic.
    let mut bytes = x3p("D", "", nx, ny, &raw, &crate::common::md5_hex(&raw), true);
    let at = bytes.windows(16).position(|w| w == b"bindata/data.bin").unwrap() + 16 + 200;
    for b in &mut bytes[at..at + 64] {
        *b ^= 0x5a;
    }
    std::fs::write(&p, &bytes).unwrap();
    let e = read_scan(&p, &ReadOptions::default()).unwrap_err();
    assert_eq!(e.kind(), ndfit::ErrorKind::Corrupt, "{e}");
    assert!(!e.to_string().contains('\n'), "{e}");
}
