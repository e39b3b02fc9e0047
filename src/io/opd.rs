//! Veeco/Wyko (Bruker Vision) OPD.
//!
//! Little-endian. Two bytes, then a directory of 24-byte entries (name: 16 bytes NUL-padded, type:
//! i16, length: i32, attributes: u16); the first entry is the directory itself and its length is the
//! directory's size. Block contents follow the directory in entry order (entries of length <= 0 hold
//! nothing). The height array is the first block named `RAW DATA`, `RAW_DATA`, `OPD` or `Raw`: u16
//! columns (x), u16 rows (y), u16 element size (1, 2 or 4), then the values stored column by column
//! (y fastest) from the top row, which is flipped so row 0 is y = 0 (as SurfaceTopography does).
//! Height = value * Wavelength (nm) / Mult, in nanometres. Spacing: `Pixel_size` (mm) along x and
//! `Pixel_size * Aspect` along y. Invalid points: float values beyond 1e32 in magnitude or non-finite
//! (Wyko writes 1.7e38), and 32767 for 16-bit data.

use crate::error::{Error, ErrorKind, Result};
use crate::io::bytes::{check_grid, field_text, Cursor};
use crate::io::mapped::Release;
use crate::scan::{Heightfield, ScanMeta};

/// The registry entry of the `opd` format ([`crate::io::Reader`]). Two bytes, then the directory entry named "Directory".
pub const READER: crate::io::Reader = crate::io::Reader {
    id: "opd",
    extensions: &["opd"],
    magic: Some(|h| h.len() >= 11 && &h[2..11] == b"Directory"),
    read: |b, _| read_opd(b),
};

const ENTRY: usize = 24;

/// |value| at or above this marks a bad pixel in float data (Wyko writes 1.7e38).
const BAD_FLOAT: f32 = 1e32;
/// 16-bit data mark a bad pixel with the largest value.
const BAD_I16: i16 = i16::MAX;

/// Read an OPD file held in memory.
pub fn read_opd(bytes: &[u8]) -> Result<Heightfield> {
    let mut c = Cursor::new(bytes);
    c.skip(2, "OPD header")?;
    let (name, _t, dirlen, _a) = entry(&mut c)?;
    if name != "Directory" {
        return Err(Error::corrupt(format!("OPD directory block is named {name:?}, not \"Directory\"")));
    }
    if dirlen <= 0 || !(dirlen as usize).is_multiple_of(ENTRY) {
        return Err(Error::corrupt(format!("OPD directory length {dirlen} is not a positive multiple of {ENTRY}")));
    }
    let count = dirlen as usize / ENTRY;
    if count.saturating_mul(ENTRY) > bytes.len() {
        return Err(Error::corrupt(format!("OPD directory claims {count} entries, more than the file holds")));
    }
    let mut entries = Vec::with_capacity(count);
    for _ in 1..count {
        entries.push(entry(&mut c)?);
    }
    let mut pos = 2 + dirlen as usize;
    let mut raw: Option<(usize, usize, usize, &[u8])> = None;
    let (mut wavelength, mut mult, mut aspect, mut pixel) = (None, 1.0f64, 1.0f64, None);
    let mut meta = ScanMeta { format: "opd".into(), ..Default::default() };
    for (name, btype, len, _) in &entries {
        if *len <= 0 {
            continue;
        }
        let len = *len as usize;
        let mut b = Cursor::new(bytes);
        b.seek(pos, "OPD block")?;
        let body = b.take(len, &format!("OPD block {name:?}"))?;
        pos += len;
        let mut bc = Cursor::new(body);
        match name.as_str() {
            "RAW DATA" | "RAW_DATA" | "OPD" | "Raw" if raw.is_none() => {
                let nx = bc.u16_le("OPD columns")? as usize;
                let ny = bc.u16_le("OPD rows")? as usize;
                let el = bc.u16_le("OPD element size")? as usize;
                if !matches!(el, 1 | 2 | 4) {
                    return Err(Error::new(ErrorKind::Unsupported, format!("OPD element size {el} (1, 2, 4 are read)")));
                }
                let n = check_grid(nx, ny, el, bc.remaining(), "OPD height block")?;
                raw = Some((nx, ny, el, bc.take(n * el, "OPD heights")?));
            }
            "Wavelength" if *btype == 7 => wavelength = Some(bc.f32_le("Wavelength")? as f64),
            "Mult" => mult = bc.u16_le("Mult")? as f64,
            "Aspect" if *btype == 7 => aspect = bc.f32_le("Aspect")? as f64,
            "Pixel_size" if *btype == 7 => pixel = Some(bc.f32_le("Pixel_size")? as f64),
            "Date" | "Time" | "MachineID" | "SerialNum" | "ObjectiveLabel" | "Title" | "Note" | "MeasMode" if *btype == 5 => {
                let t = field_text(body);
                if !t.is_empty() {
                    meta.instrument.insert(name.to_lowercase(), t);
                }
            }
            "Magnification" if *btype == 7 => {
                meta.instrument.insert("magnification".into(), format!("{}", bc.f32_le("Magnification")?));
            }
            _ => {}
        }
    }
    let (nx, ny, el, data) = raw.ok_or_else(|| Error::corrupt("OPD file has no RAW DATA / OPD / Raw height block"))?;
    let wl = wavelength.ok_or_else(|| Error::corrupt("OPD file has no Wavelength block to scale its heights"))?;
    let pixel = pixel.ok_or_else(|| Error::corrupt("OPD file has no Pixel_size block"))?;
    if !(wl.is_finite() && wl > 0.0 && mult > 0.0) {
        return Err(Error::corrupt(format!("OPD height scale is unusable: wavelength {wl} nm, mult {mult}")));
    }
    if !(pixel.is_finite() && pixel > 0.0 && aspect.is_finite() && aspect > 0.0) {
        return Err(Error::corrupt(format!("OPD spacing is unusable: pixel {pixel} mm, aspect {aspect}")));
    }
    let scale = wl * 1e-9 / mult;
    let value = |k: usize| -> f64 {
        match el {
            4 => {
                let v = f32::from_le_bytes(data[4 * k..4 * k + 4].try_into().expect("4 bytes"));
                if !v.is_finite() || v.abs() >= BAD_FLOAT {
                    f64::NAN
                } else {
                    v as f64 * scale
                }
            }
            2 => {
                let v = i16::from_le_bytes([data[2 * k], data[2 * k + 1]]);
                if v == BAD_I16 {
                    f64::NAN
                } else {
                    v as f64 * scale
                }
            }
            _ => data[k] as i8 as f64 * scale,
        }
    };
    // Stored column by column (y fastest); row i of the grid is stored row ny-1-i. Written in the stored
    // order, so that the file's pages are given back behind the decoder (`mapped`).
    let mut z = vec![0.0; nx * ny];
    let mut release = Release::new(data);
    for j in 0..nx {
        for r in 0..ny {
            z[(ny - 1 - r) * nx + j] = value(j * ny + r);
        }
        release.upto((j + 1) * ny * el);
    }
    let mut hf = Heightfield::new(nx, ny, pixel * 1e-3, pixel * aspect * 1e-3, z)?;
    meta.file_xy_unit = Some("mm".into());
    meta.file_z_unit = Some("nm (wavelength units)".into());
    meta.instrument.insert("manufacturer".into(), "Veeco/Wyko".into());
    meta.instrument.insert("wavelength_nm".into(), format!("{wl}"));
    hf.meta = meta;
    Ok(hf)
}

fn entry(c: &mut Cursor<'_>) -> Result<(String, i16, i32, u16)> {
    let name = c.take(16, "OPD directory entry")?;
    let end = name.iter().position(|&b| b == 0).unwrap_or(16);
    let name: String = name[..end].iter().map(|&b| b as char).collect();
    Ok((name, c.i16_le("OPD entry type")?, c.i32_le("OPD entry length")?, c.u16_le("OPD entry attributes")?))
}
