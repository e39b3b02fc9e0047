//! Digital Surf SUR (MountainsMap), classic (`DIGITAL SURF`) and compressed (`DSCOMPRESSED`).
//!
//! Little-endian 512-byte header (offsets in bytes): magic (0, 12), format (12: 0 = PC byte order),
//! object count (14), version (16), studiable type (18: 1 profile, 2 surface ...), object and operator
//! names (20, 50), non-measured flag (86), bits per point (98: 16 or 32), min and max stored value
//! (100, 104), points per line (108), lines (112), total points (116), x/y/z spacing (120, 124, 128:
//! f32), axis names and units (132.., 9 x 16 bytes; units at 180, 196, 212 are the spacing units),
//! date (306: s, min, h, day, month, year), compressed data size (324), comment and private zone
//! lengths (334, 336), x/y/z offsets (466, 470, 474: f32, in the axis units). The comment and private
//! zones follow, then the integer points, x fastest: raw, or for `DSCOMPRESSED` a u32 stream count,
//! (raw length, zipped length) u32 pairs and concatenated zlib streams.
//! Height = raw * z spacing + z offset, in the z spacing unit. With the non-measured flag set, the
//! value `min - 2` marks a point that was not measured.

use std::io::Read;

use crate::error::{Error, ErrorKind, Result};
use crate::io::bytes::{check_grid, checked_size, Cursor};
use crate::io::mapped::decode_values;
use crate::io::units::{latin1, metres_per};
use crate::scan::{Heightfield, ScanMeta};

/// The registry entry of the `sur` format ([`crate::io::Reader`]).
pub const READER: crate::io::Reader = crate::io::Reader {
    id: "sur",
    extensions: &["sur"],
    magic: Some(|h| h.starts_with(b"DIGITAL SURF") || h.starts_with(b"DSCOMPRESSED")),
    read: |b, _| read_sur(b),
};

/// Deflate/zlib cannot expand more than about 1032:1; a stream claiming more is lying.
const MAX_ZLIB_RATIO: usize = 1032;

/// Read a SUR file held in memory (the first object; later objects of a series are ignored).
pub fn read_sur(bytes: &[u8]) -> Result<Heightfield> {
    let mut c = Cursor::new(bytes);
    let magic = c.take(12, "SUR magic")?;
    let compressed = match magic {
        b"DIGITAL SURF" => false,
        b"DSCOMPRESSED" => true,
        _ => return Err(Error::corrupt("not a Digital Surf file (magic is neither DIGITAL SURF nor DSCOMPRESSED)")),
    };
    let h = c.take(500, "SUR header")?;
    let hdr = |off: usize, n: usize| &h[off - 12..off - 12 + n];
    let u16at = |off: usize| u16::from_le_bytes([hdr(off, 2)[0], hdr(off, 2)[1]]);
    let i32at = |off: usize| i32::from_le_bytes(hdr(off, 4).try_into().expect("4 bytes"));
    let u32at = |off: usize| u32::from_le_bytes(hdr(off, 4).try_into().expect("4 bytes"));
    let f32at = |off: usize| f32::from_le_bytes(hdr(off, 4).try_into().expect("4 bytes"));

    if u16at(12) != 0 {
        return Err(Error::new(ErrorKind::Unsupported, format!("SUR byte-order format {} (only PC format 0 is read)", u16at(12))));
    }
    let studiable = u16at(18);
    if !matches!(studiable, 1 | 2 | 8 | 11 | 13 | 16) {
        return Err(Error::new(ErrorKind::Unsupported, format!("SUR studiable type {studiable} is not a surface")));
    }
    let non_measured = u16at(86) == 1;
    let bits = u16at(98);
    let zmin = i32at(100);
    let nx = usize::try_from(i32at(108)).map_err(|_| Error::corrupt("SUR points per line is negative"))?;
    let ny = usize::try_from(i32at(112)).map_err(|_| Error::corrupt("SUR line count is negative"))?;
    let total = u32at(116) as usize;
    if checked_size(&[nx, ny], "SUR grid")? != total {
        return Err(Error::corrupt(format!("SUR header: {nx} x {ny} points but a total of {total}")));
    }
    let (sx, sy, sz) = (f32at(120), f32at(124), f32at(128));
    let ux = latin1(hdr(180, 16));
    let uy = latin1(hdr(196, 16));
    let uz = latin1(hdr(212, 16));
    let fx = metres_per(&ux).map_err(|e| Error::new(e.kind(), format!("SUR x spacing unit: {}", e.message())))?;
    let fy = metres_per(&uy).map_err(|e| Error::new(e.kind(), format!("SUR y spacing unit: {}", e.message())))?;
    let fz = metres_per(&uz).map_err(|e| Error::new(e.kind(), format!("SUR z spacing unit: {}", e.message())))?;
    let compressed_size = u32at(324) as usize;
    let comment_len = u16at(334) as usize;
    let private_len = u16at(336) as usize;
    let (x_off, y_off, z_off) = (f32at(466), f32at(470), f32at(474));
    let comment = latin1(c.take(comment_len, "SUR comment zone")?);
    c.skip(private_len, "SUR private zone")?;

    let width = match bits {
        16 => 2,
        32 => 4,
        b => return Err(Error::new(ErrorKind::Unsupported, format!("SUR with {b} bits per point (16 and 32 are read)"))),
    };
    let n = check_grid(nx, ny, 1, if compressed { usize::MAX } else { c.remaining() }, "SUR grid")?;
    let need = checked_size(&[n, width], "SUR data")?;
    let data: std::borrow::Cow<'_, [u8]> = if compressed {
        std::borrow::Cow::Owned(decompress(&mut c, need, compressed_size)?)
    } else {
        if need > c.remaining() {
            return Err(Error::corrupt(format!(
                "SUR header claims {nx} x {ny} points ({need} bytes) but only {} bytes follow the header",
                c.remaining()
            )));
        }
        std::borrow::Cow::Borrowed(c.take(need, "SUR points")?)
    };
    let invalid = zmin.checked_sub(2);
    let (sz, z_off) = (sz as f64 * fz, z_off as f64 * fz);
    let conv = |v: i32| -> f64 {
        if non_measured && Some(v) == invalid {
            f64::NAN
        } else {
            v as f64 * sz + z_off
        }
    };
    let z = if width == 2 {
        decode_values(&data, 2, |b| conv(i16::from_le_bytes([b[0], b[1]]) as i32))
    } else {
        decode_values(&data, 4, |b| conv(i32::from_le_bytes([b[0], b[1], b[2], b[3]])))
    };
    let dx = sx as f64 * fx;
    let dy = sy as f64 * fy;
    let mut hf = Heightfield::new(nx, ny, dx, dy, z).map_err(|e| Error::corrupt(format!("SUR: {}", e.message())))?;
    hf.x0 = x_off as f64 * fx;
    hf.y0 = y_off as f64 * fy;
    let mut meta = ScanMeta { format: "sur".into(), ..Default::default() };
    meta.file_xy_unit = Some(ux);
    meta.file_z_unit = Some(uz);
    let obj = latin1(hdr(20, 30));
    let operator = latin1(hdr(50, 30));
    if !obj.is_empty() {
        meta.instrument.insert("object".into(), obj);
    }
    if !operator.is_empty() {
        meta.instrument.insert("operator".into(), operator);
    }
    if !comment.is_empty() {
        meta.instrument.insert("comment".into(), comment);
    }
    let (sec, min, hour, day, month, year) = (u16at(306), u16at(308), u16at(310), u16at(312), u16at(314), u16at(316));
    if year > 0 {
        meta.instrument.insert("date".into(), format!("{year:04}-{month:02}-{day:02}T{hour:02}:{min:02}:{sec:02}"));
    }
    meta.instrument.insert("sur.compressed".into(), compressed.to_string());
    meta.instrument.insert("sur.studiable_type".into(), studiable.to_string());
    meta.instrument.insert("sur.objects".into(), u16at(14).to_string());
    hf.meta = meta;
    Ok(hf)
}

/// Inflate the DSCOMPRESSED data block into exactly `need` bytes.
fn decompress(c: &mut Cursor<'_>, need: usize, declared: usize) -> Result<Vec<u8>> {
    let start = c.pos();
    let streams = c.u32_le("SUR stream count")? as usize;
    if streams == 0 || streams.checked_mul(8).is_none_or(|b| b > c.remaining()) {
        return Err(Error::corrupt(format!("SUR compressed block claims {streams} streams")));
    }
    let mut dirs = Vec::with_capacity(streams);
    for _ in 0..streams {
        let raw = c.u32_le("SUR stream raw length")? as usize;
        let zipped = c.u32_le("SUR stream zipped length")? as usize;
        dirs.push((raw, zipped));
    }
    let raw_total = dirs.iter().try_fold(0usize, |a, d| a.checked_add(d.0));
    if raw_total != Some(need) {
        return Err(Error::corrupt(format!("SUR compressed streams hold {raw_total:?} bytes, the grid needs {need}")));
    }
    let mut out = Vec::with_capacity(0);
    for (k, &(raw, zipped)) in dirs.iter().enumerate() {
        let src = c.take(zipped, "SUR zipped stream")?;
        if raw > zipped.saturating_mul(MAX_ZLIB_RATIO).saturating_add(64) {
            return Err(Error::corrupt(format!("SUR stream {k} claims {raw} bytes from {zipped} zipped bytes")));
        }
        // Bounded by the zipped bytes actually present (checked above), so this reservation is safe.
        out.reserve(raw);
        let before = out.len();
        flate2::read::ZlibDecoder::new(src)
            .take(raw as u64 + 1)
            .read_to_end(&mut out)
            .map_err(|e| Error::corrupt(format!("SUR stream {k} does not inflate ({e})")))?;
        if out.len() - before != raw {
            return Err(Error::corrupt(format!("SUR stream {k} inflates to {} bytes, {raw} declared", out.len() - before)));
        }
    }
    let used = c.pos() - start;
    if declared != 0 && declared != used {
        return Err(Error::corrupt(format!("SUR compressed block is {used} bytes, the header says {declared}")));
    }
    Ok(out)
}
