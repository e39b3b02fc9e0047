//! Sensofar PLU (SensoSCAN / SensoMAP "PLu" confocal and interferometric topography).
//!
//! Little-endian, no magic. A 500-byte header: date text (128 bytes), time (u32), comment (256 bytes),
//! calibration (rows, cols, N_tall: u32; dy_multip, µm per pixel x, µm per pixel y, offset x,
//! offset y, µm per pixel z, offset z: f32), measurement configuration (type, algorithm, method,
//! objective, area type: u32), 40 bytes of scan settings, then restore, layer count, version,
//! hardware, image count (u8), 3 reserved bytes and a u32. Each layer follows as rows (u32),
//! columns (u32) and rows x columns float32 heights in micrometres, x fastest, then min and max.
//! Invalid points hold 1000001. Only topography measurements (type 3) are read; layer 0 is taken.

use crate::error::{Error, ErrorKind, Result};
use crate::io::bytes::{check_grid, field_text, Cursor};
use crate::io::mapped::decode_values;
use crate::scan::{Heightfield, ScanMeta};

/// The registry entry of the `plu` format ([`crate::io::Reader`]). No signature: found by extension.
pub const READER: crate::io::Reader = crate::io::Reader { id: "plu", extensions: &["plu", "apx"], magic: None, read: |b, _| read_plu(b) };

/// The marker Sensofar writes for a point that was not measured.
pub const PLU_INVALID: f32 = 1_000_001.0;

/// Read a PLU file held in memory.
pub fn read_plu(bytes: &[u8]) -> Result<Heightfield> {
    let mut c = Cursor::new(bytes);
    let date = field_text(c.take(128, "PLU date")?);
    let _time = c.u32_le("PLU time")?;
    let comment = field_text(c.take(256, "PLU comment")?);
    let cal_rows = c.u32_le("calibration rows")?;
    let cal_cols = c.u32_le("calibration columns")?;
    let _n_tall = c.u32_le("calibration N_tall")?;
    let _dy_multip = c.f32_le("dy_multip")?;
    let um_x = c.f32_le("µm per pixel x")?;
    let um_y = c.f32_le("µm per pixel y")?;
    let off_x = c.f32_le("offset x")?;
    let off_y = c.f32_le("offset y")?;
    let _um_z = c.f32_le("µm per pixel z")?;
    let _off_z = c.f32_le("offset z")?;
    let mtype = c.u32_le("measurement type")?;
    let algorithm = c.u32_le("algorithm")?;
    let method = c.u32_le("method")?;
    let objective = c.u32_le("objective")?;
    let _area_type = c.u32_le("area type")?;
    c.skip(40, "scan settings")?;
    let _restore = c.u8("restore")?;
    let layers = c.u8("layer count")?;
    let version = c.u8("version")?;
    c.skip(5, "configuration")?;
    let _factor = c.u32_le("factor")?;
    debug_assert_eq!(c.pos(), 500);
    if mtype != 3 {
        return Err(Error::new(ErrorKind::Unsupported, format!("PLU measurement type {mtype} is not a topography (type 3)")));
    }
    if layers == 0 {
        return Err(Error::corrupt("PLU header says the file holds no layer"));
    }
    let ny = c.u32_le("layer rows")? as usize;
    let nx = c.u32_le("layer columns")? as usize;
    let n = check_grid(nx, ny, 4, c.remaining(), "PLU layer 0")?;
    if (nx, ny) != (cal_cols as usize, cal_rows as usize) {
        return Err(Error::corrupt(format!("PLU layer is {nx} x {ny} but the calibration block says {cal_cols} x {cal_rows}")));
    }
    let raw = c.take(n * 4, "PLU heights")?;
    let z = decode_values(raw, 4, |b| {
        let v = f32::from_le_bytes([b[0], b[1], b[2], b[3]]);
        if v == PLU_INVALID {
            f64::NAN
        } else {
            v as f64 * 1e-6
        }
    });
    if !(um_x.is_finite() && um_x > 0.0 && um_y.is_finite() && um_y > 0.0) {
        return Err(Error::corrupt(format!("PLU pixel size {um_x} x {um_y} µm is not positive")));
    }
    let mut hf = Heightfield::new(nx, ny, um_x as f64 * 1e-6, um_y as f64 * 1e-6, z)?;
    let mut meta = ScanMeta { format: "plu".into(), ..Default::default() };
    meta.file_xy_unit = Some("um".into());
    meta.file_z_unit = Some("um".into());
    meta.instrument.insert("manufacturer".into(), "Sensofar".into());
    meta.instrument.insert("date".into(), date);
    if !comment.is_empty() && comment != "(None)" {
        meta.instrument.insert("comment".into(), comment);
    }
    if let Some(name) = OBJECTIVES.get(objective as usize) {
        meta.instrument.insert("objective".into(), (*name).into());
    }
    meta.instrument.insert("plu.algorithm".into(), algorithm.to_string());
    meta.instrument.insert("plu.method".into(), method.to_string());
    meta.instrument.insert("plu.version".into(), version.to_string());
    meta.instrument.insert("plu.layers".into(), layers.to_string());
    meta.instrument.insert("plu.stage_offset_um".into(), format!("{off_x} {off_y}"));
    hf.meta = meta;
    Ok(hf)
}

/// Objective names by index, as Sensofar's software numbers them (first entries; later indices are
/// reported as numbers only).
const OBJECTIVES: &[&str] = &[
    "Unknown",
    "Nikon CFI Fluor Plan EPI SLWD 20x",
    "Nikon CFI Fluor Plan EPI SLWD 50x",
    "Nikon CFI Fluor Plan EPI SLWD 100x",
    "Nikon CFI Fluor Plan EPI 20x",
    "Nikon CFI Fluor Plan EPI 50x",
    "Nikon CFI Fluor Plan EPI 10x",
    "Nikon CFI Fluor Plan EPI 100x",
    "Nikon CFI Fluor Plan EPI ELWD 10x",
    "Nikon CFI Fluor Plan EPI ELWD 20x",
    "Nikon CFI Fluor Plan EPI ELWD 50x",
    "Nikon CFI Fluor Plan EPI ELWD 100x",
    "Nikon CFI Plan Interferential 2.5X",
    "Nikon CFI Plan Interferential 5X T",
    "Nikon CFI Plan Interferential 10X",
    "Nikon CFI Plan Interferential 20X",
    "Nikon CFI Plan Interferential 50X",
    "Nikon CFI Fluor Plan EPI 5X",
    "Nikon CFI Fluor Plan EPI 150X",
    "Nikon CFI Fluor Plan Apo EPI 50X",
    "Nikon CFI Fluor Plan EPI 1.5X",
    "Nikon CFI Fluor Plan EPI 2.5X",
    "Nikon CFI Fluor Plan Apo EPI 100X",
    "Nikon CFI Fluor Plan EPI 200X",
    "Nikon CFI Plan Water Immersion 10X",
    "Nikon CFI Plan Water Immersion 20X",
    "Nikon CFI Plan Water Immersion 150X",
    "Nikon CFI Plan EPI CR ELWD 10X",
    "Nikon CFI Plan EPI CR 20X",
    "Nikon CFI Plan EPI CR 50X",
    "Nikon CFI Plan EPI CR 100X A",
    "Nikon CFI Plan EPI CR 100X B",
    "Leica HCX FL Plan 2.5X",
    "Leica HC PL Fluotar EPI 5X",
    "Leica HC PL Fluotar EPI 10X",
    "Leica HC PL Fluotar EPI 20X",
    "Leica HC PL Fluotar EPI 50X",
];
