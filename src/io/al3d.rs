//! Alicona AL3D (InfiniteFocus focus variation).
//!
//! `AliconaImaging\0\r\n`, then 52-byte tags (key: 20 bytes, value: 30 bytes, both NUL-padded text,
//! then CR LF): `Version`, `TagCount`, then `TagCount` more (`Cols`, `Rows`, `PixelSizeXMeter`,
//! `PixelSizeYMeter`, `DepthImageOffset`, `InvalidPixelValue`, `TextureImageOffset` ...). The depth
//! image is little-endian float32 heights in metres, x fastest, at `DepthImageOffset`. Points equal to
//! `InvalidPixelValue` (or NaN) are invalid. Rows are `Cols` floats long; a row padding to a multiple
//! of 8 columns is accepted only when the byte count up to `TextureImageOffset` says so.

use std::collections::BTreeMap;

use crate::error::{Error, ErrorKind, Result};
use crate::io::bytes::{check_grid, checked_size, field_text, Cursor};
use crate::io::mapped::Release;
use crate::scan::{Heightfield, ScanMeta};

/// The registry entry of the `al3d` format ([`crate::io::Reader`]).
pub const READER: crate::io::Reader =
    crate::io::Reader { id: "al3d", extensions: &["al3d"], magic: Some(|h| h.starts_with(AL3D_MAGIC)), read: |b, _| read_al3d(b) };

/// The AL3D signature.
pub const AL3D_MAGIC: &[u8] = b"AliconaImaging\x00\r\n";
/// Bound on tags: real files carry a few dozen.
const MAX_TAGS: usize = 10_000;

/// Read an AL3D file held in memory.
pub fn read_al3d(bytes: &[u8]) -> Result<Heightfield> {
    let mut c = Cursor::new(bytes);
    if c.take(AL3D_MAGIC.len(), "AL3D magic")? != AL3D_MAGIC {
        return Err(Error::corrupt("not an AL3D file (bad magic)"));
    }
    let mut tags = BTreeMap::new();
    let (k, v) = tag(&mut c)?;
    if k != "Version" {
        return Err(Error::corrupt(format!("AL3D first tag is {k:?}, expected Version")));
    }
    tags.insert(k, v);
    let (k, v) = tag(&mut c)?;
    if k != "TagCount" {
        return Err(Error::corrupt(format!("AL3D second tag is {k:?}, expected TagCount")));
    }
    let count: usize = v.parse().map_err(|_| Error::corrupt(format!("AL3D TagCount {v:?} is not a count")))?;
    if count > MAX_TAGS {
        return Err(Error::corrupt(format!("AL3D TagCount {count} is absurd")));
    }
    for _ in 0..count {
        let (k, v) = tag(&mut c)?;
        tags.insert(k, v);
    }
    let get = |k: &str| tags.get(k).ok_or_else(|| Error::corrupt(format!("AL3D header lacks the {k} tag")));
    let num = |k: &str| -> Result<f64> {
        let v = get(k)?;
        v.parse::<f64>().map_err(|_| Error::corrupt(format!("AL3D tag {k} = {v:?} is not a number")))
    };
    let count_tag = |k: &str| -> Result<usize> {
        let v = get(k)?;
        v.parse::<usize>().map_err(|_| Error::corrupt(format!("AL3D tag {k} = {v:?} is not a count")))
    };
    let nx = count_tag("Cols")?;
    let ny = count_tag("Rows")?;
    let dx = num("PixelSizeXMeter")?;
    let dy = num("PixelSizeYMeter")?;
    let offset = count_tag("DepthImageOffset")?;
    let invalid = num("InvalidPixelValue")? as f32;
    check_grid(nx, ny, 4, bytes.len(), "AL3D depth image")?;
    if offset > bytes.len() {
        return Err(Error::corrupt(format!("AL3D DepthImageOffset {offset} is past the end of the file")));
    }
    let available = bytes.len() - offset;
    let tight = checked_size(&[nx, ny, 4], "AL3D depth image")?;
    let padded_cols = nx.div_ceil(8) * 8;
    let stride = if padded_cols != nx {
        let span = tags.get("TextureImageOffset").and_then(|t| t.parse::<usize>().ok()).filter(|&t| t > offset);
        match span.map(|t| t - offset) {
            Some(s) if s == checked_size(&[padded_cols, ny, 4], "AL3D")? => padded_cols,
            Some(s) if s == tight => nx,
            _ if available == tight => nx,
            _ => {
                return Err(Error::new(
                    ErrorKind::Unsupported,
                    format!("AL3D row stride of a {nx}-column image cannot be told from the offsets"),
                ))
            }
        }
    } else {
        nx
    };
    let need = checked_size(&[stride, ny - 1, 4], "AL3D")?.checked_add(nx * 4).ok_or_else(|| Error::corrupt("AL3D size overflows"))?;
    if need > available {
        return Err(Error::corrupt(format!(
            "AL3D header claims {nx} x {ny} points ({need} bytes) but only {available} bytes follow offset {offset}"
        )));
    }
    let data = &bytes[offset..offset + need];
    let mut z = crate::scan::heights::with_capacity(nx * ny);
    let mut release = Release::new(data);
    for i in 0..ny {
        for j in 0..nx {
            let k = 4 * (i * stride + j);
            let v = f32::from_le_bytes([data[k], data[k + 1], data[k + 2], data[k + 3]]);
            z.push(if v == invalid || v.is_nan() { f64::NAN } else { v as f64 });
        }
        release.upto(4 * (i * stride + nx));
    }
    let mut hf = Heightfield::new(nx, ny, dx, dy, z).map_err(|e| Error::corrupt(format!("AL3D: {}", e.message())))?;
    let mut meta = ScanMeta { format: "al3d".into(), ..Default::default() };
    meta.file_xy_unit = Some("m".into());
    meta.file_z_unit = Some("m".into());
    meta.instrument.insert("manufacturer".into(), "Alicona".into());
    for (k, v) in &tags {
        if k.chars().all(|ch| ch.is_ascii_graphic()) && v.chars().all(|ch| ch.is_ascii_graphic() || ch == ' ') {
            meta.instrument.insert(format!("al3d.{k}"), v.clone());
        }
    }
    hf.meta = meta;
    Ok(hf)
}

fn tag(c: &mut Cursor<'_>) -> Result<(String, String)> {
    let k = field_text(c.take(20, "AL3D tag key")?);
    let v = field_text(c.take(30, "AL3D tag value")?);
    if c.take(2, "AL3D tag end")? != b"\r\n" {
        return Err(Error::corrupt(format!("AL3D tag {k:?} does not end in CR LF")));
    }
    Ok((k, v))
}
