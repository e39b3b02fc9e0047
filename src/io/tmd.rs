//! GelSight / TrueMap TMD (binary TrueMap data v2).
//!
//! `Binary TrueMap Data File v2.0` in a 32-byte field, a NUL-terminated comment (`Created by TrueMap
//! v6\r\n\0`, 24 bytes in the files we have), then little-endian u32 columns and rows, f32 field
//! length x and y, f32 offset x and y, and columns x rows float32 heights, x fastest. Lengths and
//! heights are millimetres (SurfaceTopography 1.27; a US dime measures 17.9 mm across, consistent with
//! the 18.96 mm field of the shared scan). Spacing = length / count. NaN points are invalid.

use crate::error::{Error, Result};
use crate::io::bytes::{check_grid, Cursor};
use crate::io::mapped::decode_values;
use crate::scan::{Heightfield, ScanMeta};

/// The registry entry of the `tmd` format ([`crate::io::Reader`]).
pub const READER: crate::io::Reader =
    crate::io::Reader { id: "tmd", extensions: &["tmd"], magic: Some(|h| h.starts_with(TMD_MAGIC)), read: |b, _| read_tmd(b) };

/// The TMD signature.
pub const TMD_MAGIC: &[u8] = b"Binary TrueMap Data File v2.0";
/// The comment is short text; bound the scan for its terminator.
const MAX_COMMENT: usize = 4096;

/// Read a TMD file held in memory.
pub fn read_tmd(bytes: &[u8]) -> Result<Heightfield> {
    let mut c = Cursor::new(bytes);
    let head = c.take(32, "TMD magic")?;
    if !head.starts_with(TMD_MAGIC) {
        return Err(Error::corrupt("not a TMD file (bad magic)"));
    }
    let rest = &bytes[32..];
    let end = rest.iter().take(MAX_COMMENT).position(|&b| b == 0).ok_or_else(|| Error::corrupt("TMD comment is not NUL-terminated"))?;
    let comment = String::from_utf8_lossy(&rest[..end]).trim().to_string();
    c.skip(end + 1, "TMD comment")?;
    let nx = c.u32_le("TMD columns")? as usize;
    let ny = c.u32_le("TMD rows")? as usize;
    let lx = c.f32_le("TMD length x")? as f64;
    let ly = c.f32_le("TMD length y")? as f64;
    let ox = c.f32_le("TMD offset x")? as f64;
    let oy = c.f32_le("TMD offset y")? as f64;
    let n = check_grid(nx, ny, 4, c.remaining(), "TMD heights")?;
    if !(lx.is_finite() && lx > 0.0 && ly.is_finite() && ly > 0.0) {
        return Err(Error::corrupt(format!("TMD field size {lx} x {ly} mm is not positive")));
    }
    let raw = c.take(n * 4, "TMD heights")?;
    let z = decode_values(raw, 4, |b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64 * 1e-3);
    let mut hf = Heightfield::new(nx, ny, lx / nx as f64 * 1e-3, ly / ny as f64 * 1e-3, z)?;
    hf.x0 = ox * 1e-3;
    hf.y0 = oy * 1e-3;
    let mut meta = ScanMeta { format: "tmd".into(), ..Default::default() };
    meta.file_xy_unit = Some("mm".into());
    meta.file_z_unit = Some("mm".into());
    meta.instrument.insert("manufacturer".into(), "GelSight (TrueMap)".into());
    if !comment.is_empty() {
        meta.instrument.insert("comment".into(), comment);
    }
    hf.meta = meta;
    Ok(hf)
}
