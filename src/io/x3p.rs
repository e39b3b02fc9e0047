//! X3P (ISO 25178-72, the openGPS XML/zip container) reader.
//!
//! Layout: a zip holding `main.xml` (Record1: axes, Record2: instrument, Record3: matrix size and a
//! link to the binary point data or an inline `DataList`, Record4: checksum file) and
//! `bindata/data.bin`, little-endian, X index fastest, then Y. Z types: `I` int16, `L` int32,
//! `F` float32, `D` float64; `z = Offset + Increment * stored` on CZ (both optional, default 0 and 1).
//! Invalid points are NaN (float types) or a 0 bit in the optional `ValidPointsLink` bit array
//! (`bindata/valid.bin`, one bit per point, least significant bit first). All lengths are metres.
//!
//! Tolerated deviations, each read without guessing (see `data_formats/formats.md`): `main.xml` in a
//! sub-folder (paths resolved relative to it), no namespace or the pre-standard root `<ISO5436>`,
//! empty optional elements (an empty `<Offset/>` is the absent offset, 0), extra elements such as
//! `<Origin>` and x3ptools' annotation `mask.png` (recorded in the metadata, not applied: it marks
//! regions, not invalid points), and zip junk such as `__MACOSX/`.
//!
//! Checksums (ISO 5436-2): the MD5 of `main.xml` in `md5checksum.hex` is always checked; the MD5s of the
//! point data and validity bits in the `DataLink` (`MD5ChecksumPointData`, `MD5ChecksumValidPoints`)
//! are checked when the data is at most [`MAX_POINT_MD5`] bytes, where MD5 costs little next to the
//! rest of the command (every entry's zip CRC-32 is checked in any case). A mismatch is `corrupt`.

use std::io::Read;

use crate::error::{Error, ErrorKind, Result};
use crate::io::bytes::checked_size;
use crate::io::xml::{self, Element};
use crate::scan::heights;
use crate::scan::{Heightfield, Heights, ScanMeta};

/// The registry entry of the `x3p` format ([`crate::io::Reader`]).
pub const READER: crate::io::Reader =
    crate::io::Reader { id: "x3p", extensions: &["x3p"], magic: Some(|h| h.starts_with(b"PK\x03\x04")), read: |b, _| read_x3p(b) };

/// Largest `main.xml` read (an inline `DataList` of a big scan can be large; this bounds memory).
const MAX_MAIN_XML: u64 = 1 << 30;
/// Deflate cannot expand data by more than 1032:1 (RFC 1951 maximum), so an entry that claims more
/// than this times its compressed size is lying.
const MAX_DEFLATE_RATIO: u64 = 1032;
/// Largest point data whose MD5 is checked (a 2048^2 float64 scan): MD5 runs at about 0.5 GB/s, so
/// beyond this it would cost more than reading and binning; the zip's CRC-32 still guards the bytes.
pub const MAX_POINT_MD5: usize = 32 << 20;

/// Z storage type of an X3P file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ZType {
    /// 16-bit signed integer.
    I,
    /// 32-bit signed integer.
    L,
    /// 32-bit IEEE float.
    F,
    /// 64-bit IEEE float.
    D,
}

impl ZType {
    fn parse(s: &str) -> Result<Self> {
        match s {
            "I" => Ok(ZType::I),
            "L" => Ok(ZType::L),
            "F" => Ok(ZType::F),
            "D" => Ok(ZType::D),
            other => Err(Error::corrupt(format!("main.xml: CZ DataType {other:?} is not one of I, L, F, D"))),
        }
    }

    /// Bytes per stored value.
    pub fn size(self) -> usize {
        match self {
            ZType::I => 2,
            ZType::L | ZType::F => 4,
            ZType::D => 8,
        }
    }

    /// The one-letter code.
    pub fn code(self) -> &'static str {
        match self {
            ZType::I => "I",
            ZType::L => "L",
            ZType::F => "F",
            ZType::D => "D",
        }
    }
}

/// Read an X3P file held in memory.
pub fn read_x3p(bytes: &[u8]) -> Result<Heightfield> {
    read_x3p_in(bytes, None)
}

/// Read an X3P file from its memory map. Float64 point data in a stored (uncompressed) entry, with no
/// `Offset`/`Increment` and no validity bits, 8-byte aligned in the file (as [`crate::io::write_x3p`]
/// writes it), and free of infinities, is read in place: the scan's heights are the mapped bytes
/// ([`Heights::is_mapped`]), after one pass that checks the CRC-32. Every other file is decoded as
/// [`read_x3p`] decodes it.
pub fn read_x3p_mapped(map: &std::sync::Arc<memmap2::Mmap>) -> Result<Heightfield> {
    read_x3p_in(map, Some(map))
}

/// The zero-copy case of [`read_x3p_mapped`] for the point data `raw` (a slice of `map`): the heights,
/// or `None` when the data must be decoded.
fn mapped_heights(map: &std::sync::Arc<memmap2::Mmap>, raw: &[u8], n: usize, crc: u32) -> Result<Option<Heights<'static>>> {
    let offset = (raw.as_ptr() as usize).wrapping_sub(map.as_ptr() as usize);
    let Some(z) = Heights::mapped(map.clone(), offset, n) else { return Ok(None) };
    let release = (raw.len() as u64) > crate::scan::bands::release_threshold();
    // One pass, 1 MiB at a time: the CRC-32 and the infinity check (an infinity needs the decoding
    // copy, which masks it). A scan read as tiles goes in order, its pages released after each block;
    // otherwise the blocks are hashed on every thread (the first touch of each page is most of the cost)
    // and their CRCs combined in order.
    let hash = |block: &[u8], vals: &[f64]| {
        let mut h = crc32fast::Hasher::new();
        h.update(block);
        // Counted, with no early exit, so that the check vectorizes (infinities are rare).
        (h, vals.iter().map(|v| usize::from(v.abs() == f64::INFINITY)).sum::<usize>() > 0)
    };
    let parts: Vec<(crc32fast::Hasher, bool)> = if release {
        raw.chunks(1 << 20)
            .zip(z.chunks(1 << 17))
            .map(|(block, vals)| {
                let part = hash(block, vals);
                crate::scan::heights::release_pages(block.as_ptr(), block.len());
                crate::scan::bands::report_tiled_progress(block.len() as u64);
                part
            })
            .collect()
    } else {
        use rayon::prelude::*;
        raw.par_chunks(1 << 20).zip(z.par_chunks(1 << 17)).map(|(block, vals)| hash(block, vals)).collect()
    };
    let mut hasher = crc32fast::Hasher::new();
    let mut infinite = false;
    for (h, inf) in &parts {
        hasher.combine(h);
        infinite |= inf;
    }
    if hasher.finalize() != crc {
        return Err(Error::corrupt("CRC-32 mismatch, the point data are corrupt"));
    }
    Ok((!infinite).then_some(z))
}

fn read_x3p_in(bytes: &[u8], map: Option<&std::sync::Arc<memmap2::Mmap>>) -> Result<Heightfield> {
    let mut zip =
        zip::ZipArchive::new(std::io::Cursor::new(bytes)).map_err(|e| Error::corrupt(format!("not a readable X3P zip container ({e})")))?;

    let (main_name, prefix) = find_main_xml(&mut zip)?;
    let main_text = read_entry_text(&mut zip, &main_name)?;
    let root = xml::parse(&main_text).map_err(|e| Error::new(e.kind(), format!("{main_name}: {}", e.message())))?;
    let mut meta = ScanMeta { format: "x3p".into(), ..Default::default() };
    meta.file_xy_unit = Some("m".into());
    meta.file_z_unit = Some("m".into());
    match root.name.as_str() {
        "ISO5436_2" => {}
        "ISO5436" => {
            meta.instrument.insert("x3p.root_element".into(), "ISO5436 (pre-standard, no namespace)".into());
        }
        other => return Err(Error::corrupt(format!("{main_name}: root element <{other}> is not <ISO5436_2>"))),
    }
    if !prefix.is_empty() {
        meta.instrument.insert("x3p.folder".into(), prefix.clone());
    }
    check_main_md5(&mut zip, &prefix, main_text.as_bytes(), &mut meta)?;

    // Record1: axes.
    let r1 = root.child("Record1").ok_or_else(|| Error::corrupt(format!("{main_name}: no Record1")))?;
    if let Some(ft) = r1.text_at(&["FeatureType"]) {
        if ft != "SUR" && ft != "PRF" {
            return Err(Error::new(
                ErrorKind::Unsupported,
                format!("{main_name}: FeatureType {ft} is not an areal surface (SUR) or profile (PRF)"),
            ));
        }
    }
    let axes = r1.child("Axes").ok_or_else(|| Error::corrupt(format!("{main_name}: Record1 has no Axes")))?;
    let (dx, x0) = lateral_axis(axes, "CX", &main_name)?;
    let (dy, y0) = lateral_axis(axes, "CY", &main_name)?;
    let cz = axes.child("CZ").ok_or_else(|| Error::corrupt(format!("{main_name}: no CZ axis")))?;
    let ztype = ZType::parse(cz.text_at(&["DataType"]).ok_or_else(|| Error::corrupt(format!("{main_name}: CZ has no DataType")))?)?;
    let z_inc = opt_number(cz, "Increment", &main_name)?.unwrap_or(1.0);
    let z_off = opt_number(cz, "Offset", &main_name)?.unwrap_or(0.0);
    if z_inc == 0.0 {
        return Err(Error::corrupt(format!("{main_name}: CZ Increment is 0")));
    }
    if cz.child("Offset").is_some_and(|e| e.text.is_empty()) {
        meta.instrument.insert("x3p.note".into(), "CZ has an empty <Offset/>; read as the absent offset 0".into());
    }
    if let Some(o) = axes.text_at(&["Origin"]) {
        meta.instrument.insert("x3p.origin".into(), format!("{o} (non-standard element, recorded only)"));
    }
    meta.instrument.insert("x3p.z_data_type".into(), ztype.code().into());

    // Record2: instrument, kept verbatim.
    if let Some(r2) = root.child("Record2") {
        for (key, path) in [
            ("date", &["Date"][..]),
            ("creator", &["Creator"][..]),
            ("manufacturer", &["Instrument", "Manufacturer"][..]),
            ("model", &["Instrument", "Model"][..]),
            ("serial", &["Instrument", "Serial"][..]),
            ("version", &["Instrument", "Version"][..]),
            ("calibration_date", &["CalibrationDate"][..]),
            ("probing_system", &["ProbingSystem", "Type"][..]),
            ("objective", &["ProbingSystem", "Identification"][..]),
            ("comment", &["Comment"][..]),
        ] {
            if let Some(t) = r2.text_at(path) {
                meta.instrument.insert(key.into(), t.to_string());
            }
        }
    }

    // Record3: matrix and data.
    let r3 = root.child("Record3").ok_or_else(|| Error::corrupt(format!("{main_name}: no Record3")))?;
    let md = r3.child("MatrixDimension").ok_or_else(|| {
        Error::new(ErrorKind::Unsupported, format!("{main_name}: Record3 has no MatrixDimension (point lists are not read)"))
    })?;
    let nx = size_field(md, "SizeX", &main_name)?;
    let ny = size_field(md, "SizeY", &main_name)?;
    let nz = size_field(md, "SizeZ", &main_name)?;
    if nz != 1 {
        return Err(Error::new(ErrorKind::Unsupported, format!("{main_name}: SizeZ = {nz}; only single-layer surfaces are read")));
    }
    let n = checked_size(&[nx, ny], "X3P matrix")?;
    let budget = || crate::budget::check_points(nx, ny, &format!("{main_name}: MatrixDimension"));

    let mut z: Heights<'static>;
    if let Some(link) = r3.child("DataLink") {
        let data_name =
            link.text_at(&["PointDataLink"]).ok_or_else(|| Error::corrupt(format!("{main_name}: DataLink has no PointDataLink")))?;
        let data_path = format!("{prefix}{data_name}");
        // Only a stored float64 entry can be read in place (nothing allocated per point); every other
        // read is checked against the budget before anything is inflated or decoded.
        let stored = zip.by_name(&data_path).is_ok_and(|e| e.compression() == zip::CompressionMethod::Stored);
        let candidate =
            map.is_some() && stored && ztype == ZType::D && z_inc == 1.0 && z_off == 0.0 && link.text_at(&["ValidPointsLink"]).is_none();
        if !candidate {
            budget()?;
            // A stored entry is decoded in order: every page mapped at once ([`crate::io::populate`]). A
            // deflated one is not: its pages fault in as the inflate reads them and are given back behind it.
            if let Some(map) = map.filter(|_| stored) {
                crate::io::populate(map);
            }
        }
        let md5_want = link
            .text_at(&["MD5ChecksumPointData"])
            .and_then(md5_field)
            .filter(|_| n.saturating_mul(ztype.size()) <= MAX_POINT_MD5)
            .map(|w| ("MD5ChecksumPointData", w));
        if let Some(inflated) =
            crate::io::inflate::read_deflated_points(&mut zip, Some(bytes), &data_path, n, ztype, z_inc, z_off, md5_want, (nx, ny))?
        {
            z = inflated.into();
        } else {
            let (raw, crc) = read_entry_exact(&mut zip, bytes, &data_path, n, ztype.size(), nx, ny)?;
            check_md5(link, "MD5ChecksumPointData", &data_path, &raw)?;
            let in_place = match (map, &raw, crc) {
                (Some(map), std::borrow::Cow::Borrowed(r), Some(crc)) if candidate => {
                    mapped_heights(map, r, n, crc).map_err(|e| Error::corrupt(format!("{data_path}: {}", e.message())))?
                }
                _ => None,
            };
            z = match in_place {
                Some(z) => z,
                None => decode(&raw, ztype, z_inc, z_off, crc).map_err(|e| Error::corrupt(format!("{data_path}: {}", e.message())))?.into(),
            };
        }
        if let Some(valid_name) = link.text_at(&["ValidPointsLink"]) {
            let vpath = format!("{prefix}{valid_name}");
            let vbytes = n.div_ceil(8);
            let (valid, crc) = read_entry_exact(&mut zip, bytes, &vpath, vbytes, 1, vbytes, 1)?;
            if crc.is_some_and(|c| c != crc32fast::hash(&valid)) {
                return Err(Error::corrupt(format!("{vpath}: CRC-32 mismatch, the validity bits are corrupt")));
            }
            check_md5(link, "MD5ChecksumValidPoints", &vpath, &valid)?;
            apply_valid_bits(&mut z, &valid);
        }
    } else if let Some(list) = r3.child("DataList") {
        budget()?;
        z = parse_data_list(list, n, ztype, z_inc, z_off, &main_name)?.into();
    } else {
        return Err(Error::corrupt(format!("{main_name}: Record3 has neither DataLink nor DataList")));
    }

    if let Some(mask) = zip
        .file_names()
        .filter_map(|r| r.ok())
        .find(|f| f.starts_with(&prefix) && !f.starts_with("__MACOSX/") && f.to_ascii_lowercase().ends_with("mask.png"))
    {
        meta.instrument
            .insert("x3p.mask".into(), format!("{mask} present: an annotation layer (x3ptools), not a validity mask; not applied"));
    }

    // `decode` and the DataList parser already turned infinities into NaN.
    let mut hf = Heightfield::new_finite_or_nan(nx, ny, dx, dy, z)?;
    hf.x0 = x0;
    hf.y0 = y0;
    hf.meta = meta;
    Ok(hf)
}

/// The 32 hex digits `text` starts with (after blanks), if any: an MD5 as X3P writers record it
/// (`HASH`, `HASH *main.xml`, either case).
pub(crate) fn md5_field(text: &str) -> Option<&str> {
    let t = text.trim_start_matches('\u{feff}').split_whitespace().next()?;
    (t.len() == 32 && t.bytes().all(|b| b.is_ascii_hexdigit())).then_some(t)
}

/// Check `md5checksum.hex` (beside main.xml) against the MD5 of `main`. A file without one is read
/// as it is; one whose checksum file holds no MD5 is read with a note in the metadata.
fn check_main_md5<R: std::io::Read + std::io::Seek>(
    zip: &mut zip::ZipArchive<R>,
    prefix: &str,
    main: &[u8],
    meta: &mut ScanMeta,
) -> Result<()> {
    let want_name = format!("{prefix}md5checksum.hex");
    let Some(name) = zip.file_names().filter_map(|r| r.ok()).find(|f| f.eq_ignore_ascii_case(&want_name)).map(|f| f.into_owned()) else {
        return Ok(());
    };
    let mut buf = Vec::new();
    let entry = zip.by_name(&name).map_err(|e| Error::corrupt(format!("cannot open {name} in the zip ({e})")))?;
    entry.take(4096).read_to_end(&mut buf).map_err(|e| Error::corrupt(format!("cannot read {name} from the zip ({e})")))?;
    let text = String::from_utf8_lossy(&buf);
    let Some(want) = md5_field(&text) else {
        meta.instrument.insert("x3p.md5_note".into(), format!("{name} holds no MD5 sum; main.xml not checked"));
        return Ok(());
    };
    let got = crate::io::md5::md5_hex(main);
    if !got.eq_ignore_ascii_case(want) {
        return Err(Error::corrupt(format!("{name} records MD5 {want} but main.xml's is {got}: main.xml was changed or damaged")));
    }
    Ok(())
}

/// Check `data` against the MD5 in `link`'s element `field`, when there is one and `data` is at most
/// [`MAX_POINT_MD5`] bytes.
fn check_md5(link: &Element, field: &str, name: &str, data: &[u8]) -> Result<()> {
    let Some(want) = link.text_at(&[field]).and_then(md5_field) else {
        return Ok(());
    };
    if data.len() > MAX_POINT_MD5 {
        return Ok(());
    }
    let got = crate::io::md5::md5_hex(data);
    if !got.eq_ignore_ascii_case(want) {
        return Err(Error::corrupt(format!("{name}: MD5 is {got} but main.xml's {field} records {want}: the data was changed or damaged")));
    }
    Ok(())
}

fn find_main_xml<R: std::io::Read + std::io::Seek>(zip: &mut zip::ZipArchive<R>) -> Result<(String, String)> {
    let names: Vec<String> = zip.file_names().filter_map(|r| r.ok()).map(|s| s.into_owned()).collect();
    if names.iter().any(|n| n == "main.xml") {
        return Ok(("main.xml".into(), String::new()));
    }
    let cands: Vec<&String> = names
        .iter()
        .filter(|n| !n.starts_with("__MACOSX/") && (n.ends_with("/main.xml")) && !n.rsplit('/').next().unwrap_or("").starts_with("._"))
        .collect();
    match cands.as_slice() {
        [] => Err(Error::corrupt("zip holds no main.xml: not an X3P file")),
        [one] => {
            let prefix = one[..one.len() - "main.xml".len()].to_string();
            Ok(((*one).clone(), prefix))
        }
        many => Err(Error::corrupt(format!(
            "zip holds {} main.xml files ({}); cannot tell which describes the surface",
            many.len(),
            many.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(", ")
        ))),
    }
}

fn read_entry_text<R: std::io::Read + std::io::Seek>(zip: &mut zip::ZipArchive<R>, name: &str) -> Result<String> {
    let entry = zip.by_name(name).map_err(|e| Error::corrupt(format!("cannot open {name} in the zip ({e})")))?;
    // The text and its element tree must fit the budget: the declared size is checked first, and the
    // read stops at the bound whatever the zip declares.
    let limit = MAX_MAIN_XML.min(crate::budget::max_memory() / 2);
    let declared = entry.size();
    crate::budget::check_bytes(declared.saturating_mul(2), &format!("{name} ({declared} bytes of XML)"))?;
    let mut buf = Vec::new();
    entry.take(limit + 1).read_to_end(&mut buf).map_err(|e| Error::corrupt(format!("cannot read {name} from the zip ({e})")))?;
    if buf.len() as u64 > limit {
        return Err(Error::new(ErrorKind::TooLarge, format!("{name} is larger than {limit} bytes (it declares {declared})")));
    }
    String::from_utf8(buf).map_err(|_| Error::corrupt(format!("{name} is not UTF-8 text")))
}

/// The bytes of entry `name`, which must hold exactly `n * size` bytes. Stored entries are sliced out
/// of `file` directly, with the CRC-32 the caller must check (fused with decoding, so a large float64
/// file is traversed once); deflated entries are checked by the zip reader (`None`).
fn read_entry_exact<'a, R: std::io::Read + std::io::Seek>(
    zip: &mut zip::ZipArchive<R>,
    file: &'a [u8],
    name: &str,
    n: usize,
    size: usize,
    nx: usize,
    ny: usize,
) -> Result<(std::borrow::Cow<'a, [u8]>, Option<u32>)> {
    let need = checked_size(&[n, size], "X3P point data")?;
    let mut entry = zip.by_name(name).map_err(|e| Error::corrupt(format!("main.xml links {name}, which the zip does not hold ({e})")))?;
    let declared = entry.size();
    if declared != need as u64 {
        return Err(Error::corrupt(format!("{name} holds {declared} bytes but main.xml's {nx} x {ny} points of {size} bytes need {need}")));
    }
    match entry.compression() {
        zip::CompressionMethod::Stored => {
            let start = entry.data_start().ok_or_else(|| Error::corrupt(format!("{name}: no data offset")))?;
            let start = usize::try_from(start).map_err(|_| Error::corrupt(format!("{name}: data offset too large")))?;
            let slice = start
                .checked_add(need)
                .and_then(|end| file.get(start..end))
                .ok_or_else(|| Error::corrupt(format!("{name}: truncated, {need} bytes of point data are not all in the file")))?;
            Ok((std::borrow::Cow::Borrowed(slice), Some(entry.crc32())))
        }
        _ => {
            if declared > entry.compressed_size().saturating_mul(MAX_DEFLATE_RATIO) {
                return Err(Error::corrupt(format!(
                    "{name} claims {declared} bytes from {} compressed bytes, more than deflate can expand",
                    entry.compressed_size()
                )));
            }
            // Capacity is bounded by the compressed bytes actually present times the deflate limit.
            let mut buf = Vec::with_capacity(need.min(file.len().saturating_mul(4)));
            (&mut entry)
                .take(need as u64 + 1)
                .read_to_end(&mut buf)
                .map_err(|e| Error::corrupt(format!("{name}: cannot decompress the point data ({e})")))?;
            if buf.len() != need {
                return Err(Error::corrupt(format!("{name}: holds {} bytes, {need} expected", buf.len())));
            }
            Ok((std::borrow::Cow::Owned(buf), None))
        }
    }
}

/// Decode little-endian stored values to metres: `off + inc * v` (identity skipped for exactness),
/// non-finite results as NaN. With `crc`, the CRC-32 of `raw` is computed block by block in the same
/// pass and must match.
pub fn decode(raw: &[u8], t: ZType, inc: f64, off: f64, crc: Option<u32>) -> Result<Vec<f64>> {
    let identity = inc == 1.0 && off == 0.0;
    let finish = |v: f64| {
        let v = if identity { v } else { off + inc * v };
        if v.is_finite() {
            v
        } else {
            f64::NAN
        }
    };
    let size = t.size();
    let mut out = heights::with_capacity(raw.len() / size);
    let mut hasher = crc.map(|_| crc32fast::Hasher::new());
    let mut release = crate::io::mapped::Release::new(raw);
    // 64 KiB blocks: hashed and decoded while in cache, the file's pages given back behind them.
    for (k, block) in raw.chunks(1 << 16).enumerate() {
        release.upto(k << 16);
        if let Some(h) = hasher.as_mut() {
            h.update(block);
        }
        match t {
            ZType::D => out.extend(block.chunks_exact(8).map(|c| finish(f64::from_le_bytes(c.try_into().expect("8 bytes"))))),
            ZType::F => out.extend(block.chunks_exact(4).map(|c| finish(f32::from_le_bytes(c.try_into().expect("4 bytes")) as f64))),
            ZType::L => out.extend(block.chunks_exact(4).map(|c| finish(i32::from_le_bytes(c.try_into().expect("4 bytes")) as f64))),
            ZType::I => out.extend(block.chunks_exact(2).map(|c| finish(i16::from_le_bytes(c.try_into().expect("2 bytes")) as f64))),
        }
    }
    if let (Some(h), Some(want)) = (hasher, crc) {
        if h.finalize() != want {
            return Err(Error::corrupt("CRC-32 mismatch, the point data are corrupt"));
        }
    }
    Ok(out)
}

fn apply_valid_bits(z: &mut [f64], valid: &[u8]) {
    for (k, h) in z.iter_mut().enumerate() {
        if valid[k / 8] >> (k % 8) & 1 == 0 {
            *h = f64::NAN;
        }
    }
}

fn parse_data_list(list: &Element, n: usize, t: ZType, inc: f64, off: f64, main: &str) -> Result<Vec<f64>> {
    if list.children.len() != n {
        return Err(Error::corrupt(format!("{main}: DataList holds {} points, MatrixDimension says {n}", list.children.len())));
    }
    let identity = inc == 1.0 && off == 0.0;
    list.children
        .iter()
        .enumerate()
        .map(|(k, d)| {
            if d.text.is_empty() {
                return Ok(f64::NAN); // an empty Datum is a missing point
            }
            // A SUR DataList Datum holds only z; with absolute x/y it would hold "x;y;z".
            let v: f64 =
                d.text.trim().parse().map_err(|_| Error::corrupt(format!("{main}: DataList point {k} is not a number: {:?}", d.text)))?;
            let v = match t {
                ZType::F => v as f32 as f64,
                _ => v,
            };
            let v = if identity { v } else { off + inc * v };
            Ok(if v.is_finite() { v } else { f64::NAN })
        })
        .collect()
}

fn lateral_axis(axes: &Element, name: &str, main: &str) -> Result<(f64, f64)> {
    let ax = axes.child(name).ok_or_else(|| Error::corrupt(format!("{main}: no {name} axis")))?;
    match ax.text_at(&["AxisType"]) {
        Some("I") | None => {}
        Some(t) => {
            return Err(Error::new(
                ErrorKind::Unsupported,
                format!("{main}: {name} AxisType {t}: only incremental (I) lateral axes form a grid"),
            ))
        }
    }
    let inc = opt_number(ax, "Increment", main)?.ok_or_else(|| Error::corrupt(format!("{main}: {name} has no Increment")))?;
    if !(inc.is_finite() && inc > 0.0) {
        return Err(Error::corrupt(format!("{main}: {name} Increment {inc} is not a positive length")));
    }
    let off = opt_number(ax, "Offset", main)?.unwrap_or(0.0);
    Ok((inc, off))
}

fn opt_number(e: &Element, child: &str, main: &str) -> Result<Option<f64>> {
    match e.text_at(&[child]) {
        None => Ok(None),
        Some(t) => {
            let v: f64 = t.parse().map_err(|_| Error::corrupt(format!("{main}: {}/{child} is not a number: {t:?}", e.name)))?;
            if !v.is_finite() {
                return Err(Error::corrupt(format!("{main}: {}/{child} is not finite", e.name)));
            }
            Ok(Some(v))
        }
    }
}

fn size_field(md: &Element, name: &str, main: &str) -> Result<usize> {
    let t = md.text_at(&[name]).ok_or_else(|| Error::corrupt(format!("{main}: MatrixDimension has no {name}")))?;
    let v: usize = t.parse().map_err(|_| Error::corrupt(format!("{main}: {name} is not a count: {t:?}")))?;
    if v == 0 {
        return Err(Error::new(ErrorKind::BadData, format!("{main}: {name} is 0, the surface is empty")));
    }
    Ok(v)
}
