//! Gwyddion Simple Field (GSF).
//!
//! Text header starting `Gwyddion Simple Field 1.0\n`, then `Key = Value` lines (`XRes`, `YRes`
//! required; `XReal`, `YReal` in `XYUnits`, default 1 m per the Gwyddion spec; `XOffset`, `YOffset`,
//! `XYUnits`, `ZUnits` default `m`, `Title`), then 1-4 NUL bytes padding the header to a multiple of
//! 4, then `XRes * YRes` little-endian float32, x fastest. NaN points are invalid.

use crate::error::{Error, ErrorKind, Result};
use crate::io::bytes::check_grid;
use crate::io::mapped::decode_values;
use crate::io::units::metres_per;
use crate::scan::{Heightfield, ScanMeta};

/// The registry entry of the `gsf` format ([`crate::io::Reader`]).
pub const READER: crate::io::Reader =
    crate::io::Reader { id: "gsf", extensions: &["gsf"], magic: Some(|h| h.starts_with(GSF_MAGIC)), read: |b, _| read_gsf(b) };

/// The GSF signature line.
pub const GSF_MAGIC: &[u8] = b"Gwyddion Simple Field 1.0\n";
/// Headers are short; bound the search for their end.
const MAX_HEADER: usize = 1 << 20;

/// Read a GSF file held in memory.
pub fn read_gsf(bytes: &[u8]) -> Result<Heightfield> {
    if !bytes.starts_with(GSF_MAGIC) {
        return Err(Error::corrupt("not a GSF file (bad magic)"));
    }
    let nul = bytes.iter().take(MAX_HEADER).position(|&b| b == 0).ok_or_else(|| Error::corrupt("GSF header has no NUL terminator"))?;
    let data_start = (nul / 4 + 1) * 4;
    if data_start > bytes.len() || bytes[nul..data_start].iter().any(|&b| b != 0) {
        return Err(Error::corrupt("GSF header padding is not NUL bytes up to a multiple of 4"));
    }
    let header = std::str::from_utf8(&bytes[GSF_MAGIC.len()..nul]).map_err(|_| Error::corrupt("GSF header is not UTF-8"))?;
    let mut kv = std::collections::BTreeMap::new();
    for line in header.lines() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let (k, v) = line.split_once('=').ok_or_else(|| Error::corrupt(format!("GSF header line {line:?} is not Key = Value")))?;
        kv.insert(k.trim().to_string(), v.trim().to_string());
    }
    let count = |k: &str| -> Result<usize> {
        let v = kv.get(k).ok_or_else(|| Error::corrupt(format!("GSF header lacks {k}")))?;
        v.parse().map_err(|_| Error::corrupt(format!("GSF {k} = {v:?} is not a count")))
    };
    let real = |k: &str, default: f64| -> Result<f64> {
        match kv.get(k) {
            None => Ok(default),
            Some(v) => v.parse().map_err(|_| Error::corrupt(format!("GSF {k} = {v:?} is not a number"))),
        }
    };
    let nx = count("XRes")?;
    let ny = count("YRes")?;
    let n = check_grid(nx, ny, 4, bytes.len() - data_start, "GSF data")?;
    let xy_unit = kv.get("XYUnits").cloned().unwrap_or_else(|| "m".into());
    let z_unit = kv.get("ZUnits").cloned().unwrap_or_else(|| "m".into());
    let fxy = metres_per(&xy_unit).map_err(|e| Error::new(ErrorKind::Unsupported, format!("GSF XYUnits: {}", e.message())))?;
    let fz = metres_per(&z_unit).map_err(|e| Error::new(ErrorKind::Unsupported, format!("GSF ZUnits: {}", e.message())))?;
    let xr = real("XReal", 1.0)?;
    let yr = real("YReal", 1.0)?;
    let z = decode_values(&bytes[data_start..data_start + n * 4], 4, |b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64 * fz);
    let mut hf = Heightfield::new(nx, ny, xr / nx as f64 * fxy, yr / ny as f64 * fxy, z)
        .map_err(|e| Error::corrupt(format!("GSF: {}", e.message())))?;
    hf.x0 = real("XOffset", 0.0)? * fxy;
    hf.y0 = real("YOffset", 0.0)? * fxy;
    let mut meta = ScanMeta { format: "gsf".into(), ..Default::default() };
    meta.file_xy_unit = Some(xy_unit);
    meta.file_z_unit = Some(z_unit);
    if let Some(t) = kv.get("Title") {
        meta.instrument.insert("title".into(), t.clone());
    }
    hf.meta = meta;
    Ok(hf)
}
