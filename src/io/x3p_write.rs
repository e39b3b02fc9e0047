//! X3P (ISO 25178-72) writer: float64 Z, incremental X/Y axes, NaN for invalid points.
//!
//! The container holds `main.xml` (deflated), `bindata/data.bin` (stored and 8-byte aligned, so readers
//! can use it in place) and `md5checksum.hex`, with the MD5 sums the standard requires. Numbers are written in
//! Rust's shortest round-trip form, so spacing and offsets read back bit-identical.

use std::io::Write;
use std::path::Path;

use crate::error::{Error, Result};
use crate::io::md5::md5_hex;
use crate::io::xml::escape;
use crate::scan::Heightfield;

/// Write `hf` as an X3P file at `path` (atomically: a failed write leaves no file behind).
pub fn write_x3p(path: &Path, hf: &Heightfield) -> Result<()> {
    let bytes = x3p_bytes(hf)?;
    crate::io::write_bytes_atomic(path, &bytes)
}

/// The bytes of an X3P file holding `hf`.
pub fn x3p_bytes(hf: &Heightfield) -> Result<Vec<u8>> {
    let n = hf
        .nx
        .checked_mul(hf.ny)
        .filter(|&n| n == hf.z.len())
        .ok_or_else(|| Error::invalid(format!("heightfield has {} heights for a {} x {} grid", hf.z.len(), hf.nx, hf.ny)))?;
    let mut data = Vec::with_capacity(n * 8);
    for h in &hf.z {
        data.extend_from_slice(&h.to_le_bytes());
    }
    let data_md5 = md5_hex(&data);
    let main = main_xml(hf, &data_md5);
    let main_md5 = md5_hex(main.as_bytes());

    let mut out = std::io::Cursor::new(Vec::with_capacity(data.len() + main.len() + 4096));
    {
        let mut zw = zip::ZipWriter::new(&mut out);
        let large = data.len() as u64 >= u32::MAX as u64;
        let deflated = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated).large_file(false);
        let stored = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored).large_file(large);
        // The point data starts on an 8-byte boundary of the file (padding in the entry's extra field),
        // so a reader can map it and use the float64 values in place.
        let aligned = stored.with_alignment(8);
        let zerr = |e: zip::result::ZipError| Error::invalid(format!("cannot build the X3P zip ({e})"));
        zw.start_file("main.xml", deflated).map_err(zerr)?;
        zw.write_all(main.as_bytes())?;
        zw.add_directory("bindata/", stored).map_err(zerr)?;
        zw.start_file("bindata/data.bin", aligned).map_err(zerr)?;
        zw.write_all(&data)?;
        zw.start_file("md5checksum.hex", deflated).map_err(zerr)?;
        zw.write_all(format!("{main_md5} *main.xml\n").as_bytes())?;
        zw.finish().map_err(zerr)?;
    }
    Ok(out.into_inner())
}

/// Write `tile` repeated `kx` times along x and `ky` times along y as one X3P file at `path`, streamed
/// row by row: the whole grid is never in memory, so scans larger than memory can be made (to test the
/// tiled read). A periodic tile (the spectral surfaces of [`crate::synth`]) repeats seamlessly. The file
/// is written to a sibling temporary file and renamed into place when complete.
pub fn write_x3p_repeated(path: &Path, tile: &Heightfield, kx: usize, ky: usize) -> Result<()> {
    let (nx, ny) = (tile.nx.checked_mul(kx), tile.ny.checked_mul(ky));
    let (Some(nx), Some(ny)) = (nx, ny) else { return Err(Error::invalid("repeated grid size overflows")) };
    if kx == 0 || ky == 0 || tile.z.len() != tile.nx * tile.ny {
        return Err(Error::invalid("nothing to repeat"));
    }
    let row = |i: usize, out: &mut Vec<u8>| {
        out.clear();
        for _ in 0..kx {
            for h in tile.row(i % tile.ny) {
                out.extend_from_slice(&h.to_le_bytes());
            }
        }
    };
    let mut buf = Vec::with_capacity(nx * 8);
    let mut md5 = crate::io::md5::Md5::default();
    for i in 0..ny {
        row(i, &mut buf);
        md5.update(&buf);
    }
    let data_md5: String = md5.finish().iter().map(|b| format!("{b:02x}")).collect();
    let big = Heightfield { nx, ny, z: Vec::new().into(), ..tile.clone() };
    let main = main_xml(&big, &data_md5);
    let main_md5 = md5_hex(main.as_bytes());
    let tmp = path.with_extension("x3p.partial");
    let mut write = || -> Result<()> {
        let file = std::io::BufWriter::with_capacity(1 << 20, std::fs::File::create(&tmp)?);
        let mut zw = zip::ZipWriter::new(file);
        let deflated = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated).large_file(false);
        let stored = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Stored).large_file(true);
        let zerr = |e: zip::result::ZipError| Error::invalid(format!("cannot build the X3P zip ({e})"));
        zw.start_file("main.xml", deflated).map_err(zerr)?;
        zw.write_all(main.as_bytes())?;
        zw.add_directory("bindata/", stored).map_err(zerr)?;
        zw.start_file("bindata/data.bin", stored.with_alignment(8)).map_err(zerr)?;
        for i in 0..ny {
            row(i, &mut buf);
            zw.write_all(&buf)?;
        }
        zw.start_file("md5checksum.hex", deflated).map_err(zerr)?;
        zw.write_all(format!("{main_md5} *main.xml\n").as_bytes())?;
        zw.finish().map_err(zerr)?.flush()?;
        Ok(())
    };
    match write() {
        Ok(()) => std::fs::rename(&tmp, path).map_err(|e| Error::io(e).with_path(path)),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(e.with_path(path))
        }
    }
}

fn num(v: f64) -> String {
    // `{:?}` is Rust's shortest representation that parses back to the same f64.
    format!("{v:?}")
}

fn main_xml(hf: &Heightfield, data_md5: &str) -> String {
    let get = |k: &str, default: &str| escape(hf.meta.instrument.get(k).map(String::as_str).unwrap_or(default));
    let mut s = String::new();
    s.push_str("<?xml version=\"1.0\" encoding=\"UTF-8\" standalone=\"no\" ?>\n");
    s.push_str("<p:ISO5436_2 xmlns:p=\"http://www.opengps.eu/2008/ISO5436_2\" xmlns:xsi=\"http://www.w3.org/2001/XMLSchema-instance\" xsi:schemaLocation=\"http://www.opengps.eu/2008/ISO5436_2 http://www.opengps.eu/2008/ISO5436_2/ISO5436_2.xsd\">\n");
    s.push_str("  <Record1>\n    <Revision>ISO5436 - 2000</Revision>\n    <FeatureType>SUR</FeatureType>\n    <Axes>\n");
    for (name, inc, off) in [("CX", hf.dx, hf.x0), ("CY", hf.dy, hf.y0)] {
        s.push_str(&format!(
            "      <{name}>\n        <AxisType>I</AxisType>\n        <DataType>D</DataType>\n        <Increment>{}</Increment>\n        <Offset>{}</Offset>\n      </{name}>\n",
            num(inc),
            num(off)
        ));
    }
    s.push_str("      <CZ>\n        <AxisType>A</AxisType>\n        <DataType>D</DataType>\n        <Increment>1</Increment>\n        <Offset>0</Offset>\n      </CZ>\n    </Axes>\n  </Record1>\n");
    s.push_str("  <Record2>\n");
    s.push_str(&format!("    <Date>{}</Date>\n", get("date", "1970-01-01T00:00:00")));
    s.push_str(&format!("    <Creator>{}</Creator>\n", get("creator", "ndfit")));
    s.push_str(&format!(
        "    <Instrument>\n      <Manufacturer>{}</Manufacturer>\n      <Model>{}</Model>\n      <Serial>{}</Serial>\n      <Version>{}</Version>\n    </Instrument>\n",
        get("manufacturer", "not available"),
        get("model", "not available"),
        get("serial", "not available"),
        get("version", "not available")
    ));
    s.push_str(&format!("    <CalibrationDate>{}</CalibrationDate>\n", get("calibration_date", "1970-01-01T00:00:00")));
    s.push_str(&format!(
        "    <ProbingSystem>\n      <Type>{}</Type>\n      <Identification>{}</Identification>\n    </ProbingSystem>\n",
        get("probing_system", "Software"),
        get("objective", "not available")
    ));
    let comment = match hf.meta.instrument.get("comment") {
        Some(c) => escape(c),
        None => escape(&format!("written by ndfit {} from a {} scan", env!("CARGO_PKG_VERSION"), hf.meta.format)),
    };
    s.push_str(&format!("    <Comment>{comment}</Comment>\n  </Record2>\n"));
    s.push_str(&format!(
        "  <Record3>\n    <MatrixDimension>\n      <SizeX>{}</SizeX>\n      <SizeY>{}</SizeY>\n      <SizeZ>1</SizeZ>\n    </MatrixDimension>\n    <DataLink>\n      <PointDataLink>bindata/data.bin</PointDataLink>\n      <MD5ChecksumPointData>{}</MD5ChecksumPointData>\n    </DataLink>\n  </Record3>\n",
        hf.nx, hf.ny, data_md5
    ));
    s.push_str("  <Record4>\n    <ChecksumFile>md5checksum.hex</ChecksumFile>\n  </Record4>\n</p:ISO5436_2>\n");
    s
}
