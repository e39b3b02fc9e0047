//! Zygo MetroPro binary DAT.
//!
//! Big-endian. Magic 0x881B036F (header format 1), 0x881B0370 (2) or 0x881B0371 (3); header size
//! (u32 at 6). Intensity origin/size at 48-60 (width, height, buckets, byte count at 52, 54, 56, 60),
//! phase ("connected") data width and height at 68 and 70 with byte count at 72, time stamp at 76,
//! comment at 80 (82 bytes), interferometric scale factor, wavelength (m), numerical aperture,
//! obliquity factor, magnification and lateral resolution (m per pixel) as f32 at 164-184, phase
//! resolution code at 218, sign at 232, serial at 242, objective name at 246 (12 bytes), part name at
//! 258 (40 bytes). The intensity data follow the header, then the phase data as i32, x fastest.
//! Height (m) = value * S * O * wavelength / R with S the scale factor, O the obliquity, R = 4096,
//! 32768 or 131072 for phase resolution 0, 1, 2 (MetroPro Reference Guide), negated when sign != 0.
//! Values at or above 2147483640 are invalid.

use crate::error::{Error, ErrorKind, Result};
use crate::io::bytes::{check_grid, field_text, Cursor};
use crate::io::mapped::decode_values;
use crate::scan::{Heightfield, ScanMeta};

/// The registry entry of the `metropro` format ([`crate::io::Reader`]).
pub const READER: crate::io::Reader = crate::io::Reader {
    id: "metropro",
    extensions: &["dat"],
    magic: Some(|h| h.len() >= 4 && h[..3] == [0x88, 0x1B, 0x03] && (0x6F..=0x71).contains(&h[3])),
    read: |b, _| read_metropro(b),
};

/// Phase values at or above this are "no data".
const INVALID_PHASE: i32 = 2_147_483_640;

/// Read a MetroPro DAT file held in memory.
pub fn read_metropro(bytes: &[u8]) -> Result<Heightfield> {
    let mut c = Cursor::new(bytes);
    let magic = c.u32_be("MetroPro magic")?;
    if !(0x881B036F..=0x881B0371).contains(&magic) {
        return Err(Error::corrupt("not a MetroPro file (bad magic)"));
    }
    let at = |off: usize, n: usize, what: &str| -> Result<Cursor<'_>> {
        let mut k = Cursor::new(bytes);
        k.seek(off, what)?;
        k.take(n, what)?;
        let mut k = Cursor::new(bytes);
        k.seek(off, what)?;
        Ok(k)
    };
    let header_format = at(4, 2, "header format")?.u16_be("header format")?;
    let header_size = at(6, 4, "header size")?.u32_be("header size")? as usize;
    if header_size < 834 || header_size > bytes.len() {
        return Err(Error::corrupt(format!("MetroPro header size {header_size} is not between 834 and the file length")));
    }
    let ac_n_bytes = at(60, 4, "intensity byte count")?.u32_be("intensity byte count")? as usize;
    let cn_w = at(68, 2, "phase width")?.u16_be("phase width")? as usize;
    let cn_h = at(70, 2, "phase height")?.u16_be("phase height")? as usize;
    let cn_n_bytes = at(72, 4, "phase byte count")?.u32_be("phase byte count")? as usize;
    let time_stamp = at(76, 4, "time stamp")?.i32_be("time stamp")?;
    let comment = field_text(at(80, 82, "comment")?.take(82, "comment")?);
    let mut f = at(164, 24, "scale block")?;
    let scale = f.f32_be("intf_scale_factor")? as f64;
    let wavelength = f.f32_be("wavelength")? as f64;
    let _na = f.f32_be("numerical aperture")?;
    let obliquity = f.f32_be("obliquity factor")? as f64;
    let magnification = f.f32_be("magnification")?;
    let lateral = f.f32_be("lateral resolution")? as f64;
    let phase_res = at(218, 2, "phase resolution")?.i16_be("phase resolution")?;
    let sign = at(232, 2, "sign")?.i16_be("sign")?;
    let serial = at(242, 2, "serial")?.u16_be("serial")?;
    let objective = field_text(at(246, 12, "objective")?.take(12, "objective")?);
    let part = field_text(at(258, 40, "part name")?.take(40, "part name")?);
    let r = match phase_res {
        0 => 4096.0,
        1 => 32768.0,
        2 => 131072.0,
        p => return Err(Error::corrupt(format!("MetroPro phase resolution code {p} is not 0, 1 or 2"))),
    };
    if cn_w == 0 || cn_h == 0 {
        return Err(Error::new(ErrorKind::BadData, "MetroPro file holds no phase (height) data"));
    }
    let n = check_grid(cn_w, cn_h, 4, bytes.len(), "MetroPro phase data")?;
    if cn_n_bytes != n * 4 {
        return Err(Error::corrupt(format!("MetroPro phase data: {cn_w} x {cn_h} points but {cn_n_bytes} bytes")));
    }
    let start = header_size.checked_add(ac_n_bytes).ok_or_else(|| Error::corrupt("MetroPro offsets overflow"))?;
    let mut d = Cursor::new(bytes);
    d.seek(start.min(bytes.len()), "MetroPro phase data")?;
    if start > bytes.len() || d.remaining() < cn_n_bytes {
        return Err(Error::corrupt(format!(
            "MetroPro header claims {cn_w} x {cn_h} phase points at offset {start} but the file has {} bytes",
            bytes.len()
        )));
    }
    if !(wavelength.is_finite() && wavelength > 0.0 && scale.is_finite() && obliquity.is_finite() && lateral.is_finite() && lateral > 0.0) {
        return Err(Error::corrupt(format!(
            "MetroPro scale is unusable: wavelength {wavelength}, scale {scale}, obliquity {obliquity}, lateral {lateral}"
        )));
    }
    let k = if sign != 0 { -1.0 } else { 1.0 } * scale * obliquity * wavelength / r;
    let raw = d.take(cn_n_bytes, "MetroPro phase data")?;
    let z = decode_values(raw, 4, |b| {
        let v = i32::from_be_bytes([b[0], b[1], b[2], b[3]]);
        if v >= INVALID_PHASE {
            f64::NAN
        } else {
            v as f64 * k
        }
    });
    let mut hf = Heightfield::new(cn_w, cn_h, lateral, lateral, z)?;
    let mut meta = ScanMeta { format: "metropro".into(), ..Default::default() };
    meta.file_xy_unit = Some("m".into());
    meta.file_z_unit = Some("m (from phase)".into());
    meta.instrument.insert("manufacturer".into(), "Zygo".into());
    meta.instrument.insert("serial".into(), serial.to_string());
    meta.instrument.insert("metropro.header_format".into(), header_format.to_string());
    meta.instrument.insert("metropro.time_stamp".into(), time_stamp.to_string());
    meta.instrument.insert("wavelength_m".into(), format!("{wavelength:e}"));
    meta.instrument.insert("magnification".into(), format!("{magnification}"));
    meta.instrument.insert("metropro.phase_res".into(), format!("{phase_res} (R = {r})"));
    if !objective.is_empty() {
        meta.instrument.insert("objective".into(), objective);
    }
    if !part.is_empty() {
        meta.instrument.insert("part".into(), part);
    }
    if !comment.is_empty() {
        meta.instrument.insert("comment".into(), comment);
    }
    hf.meta = meta;
    Ok(hf)
}
