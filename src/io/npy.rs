//! NumPy `.npy` (format versions 1-3): a 2-D array of heights, `shape = (rows, columns)`.
//!
//! `\x93NUMPY`, major and minor version, header length (u16 for v1, u32 for v2/v3), then a Python
//! dict literal with `descr` (`<f8`, `<f4`, `>f8`, `>f4`, `<i2`, `<u2`, `<i4`, `<u4`, `|u1`, `|i1` ...),
//! `fortran_order` and `shape`, then the raw array. No units: heights need `--z-scale` and spacing
//! `--dx`/`--dy`. NaN points are invalid.

use std::sync::Arc;

use rayon::prelude::*;

use crate::error::{Error, ErrorKind, Result};
use crate::io::bytes::{check_grid, Cursor};
use crate::io::mapped::decode_values;
use crate::io::raw_opts::{spacing, z_scale};
use crate::io::ReadOptions;
use crate::scan::heights;
use crate::scan::heights::Heights;
use crate::scan::{Heightfield, ScanMeta};

/// The registry entry of the `npy` format ([`crate::io::Reader`]).
pub const READER: crate::io::Reader =
    crate::io::Reader { id: "npy", extensions: &["npy"], magic: Some(|h| h.starts_with(NPY_MAGIC)), read: read_npy };

/// The NPY signature.
pub const NPY_MAGIC: &[u8] = b"\x93NUMPY";

/// What the NPY header says, with where the array's bytes start.
struct Header {
    descr: String,
    endian: char,
    kind: char,
    size: usize,
    fortran: bool,
    nx: usize,
    ny: usize,
    /// Number of points (`nx ny`), checked against the bytes present.
    n: usize,
    /// Byte offset of the array in the file.
    data: usize,
}

/// A C-ordered little-endian `float64` array of `shape` as an `.npy` file (format version 1.0).
pub fn npy_f64_bytes(shape: &[usize], data: &[f64]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    // A one-element tuple needs its trailing comma.
    let tuple = if dims.len() == 1 { format!("({},)", dims[0]) } else { format!("({})", dims.join(", ")) };
    let dict = format!("{{'descr': '<f8', 'fortran_order': False, 'shape': {tuple}, }}");
    // The header (magic, version, length, dict, newline) is padded with spaces to a multiple of 64.
    let unpadded = 10 + dict.len() + 1;
    let len = dict.len() + 1 + (unpadded.next_multiple_of(64) - unpadded);
    let mut out = Vec::with_capacity(10 + len + 8 * data.len());
    out.extend_from_slice(NPY_MAGIC);
    out.extend_from_slice(&[1, 0]);
    out.extend_from_slice(&(len as u16).to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out.resize(10 + len - 1, b' ');
    out.push(b'\n');
    out.extend(data.iter().flat_map(|v| v.to_le_bytes()));
    out
}

/// The grid `[nx, ny]` an NPY file declares, if `bytes` hold a valid NPY header.
pub(crate) fn grid_of(bytes: &[u8]) -> Option<[usize; 2]> {
    bytes.starts_with(NPY_MAGIC).then(|| parse_header(bytes).ok()).flatten().map(|h| [h.nx, h.ny])
}

fn parse_header(bytes: &[u8]) -> Result<Header> {
    let mut c = Cursor::new(bytes);
    if c.take(6, "NPY magic")? != NPY_MAGIC {
        return Err(Error::corrupt("not an NPY file (bad magic)"));
    }
    let major = c.u8("NPY version")?;
    let _minor = c.u8("NPY version")?;
    let hlen = match major {
        1 => c.u16_le("NPY header length")? as usize,
        2 | 3 => c.u32_le("NPY header length")? as usize,
        v => return Err(Error::new(ErrorKind::Unsupported, format!("NPY format version {v}"))),
    };
    let header = c.take(hlen, "NPY header")?;
    let header = std::str::from_utf8(header).map_err(|_| Error::corrupt("NPY header is not text"))?;
    let descr = dict_str(header, "descr").ok_or_else(|| Error::corrupt("NPY header has no descr"))?;
    let fortran = header
        .split("'fortran_order':")
        .nth(1)
        .map(|r| r.trim_start().starts_with("True"))
        .ok_or_else(|| Error::corrupt("NPY header has no fortran_order"))?;
    let shape = dict_shape(header).ok_or_else(|| Error::corrupt("NPY header has no readable shape"))?;
    let (ny, nx) = match shape.as_slice() {
        [ny, nx] => (*ny, *nx),
        [ny, nx, 1] => (*ny, *nx),
        s => return Err(Error::new(ErrorKind::Unsupported, format!("NPY array of shape {s:?}: a 2-D height array is needed"))),
    };
    let (endian, kind, size) = parse_descr(&descr)?;
    let n = check_grid(nx, ny, size, c.remaining(), "NPY array")?;
    Ok(Header { descr, endian, kind, size, fortran, nx, ny, n, data: c.pos() })
}

/// Read an NPY file held in memory.
pub fn read_npy(bytes: &[u8], opts: &ReadOptions) -> Result<Heightfield> {
    decode(bytes, parse_header(bytes)?, opts)
}

/// Decode the array described by `h` into an owned heights buffer.
fn decode(bytes: &[u8], h: Header, opts: &ReadOptions) -> Result<Heightfield> {
    let (endian, kind, size, n) = (h.endian, h.kind, h.size, h.n);
    let raw = &bytes[h.data..h.data + n * size];
    let zs = z_scale(opts, "NPY")?;
    let (dx, dy) = spacing(opts, "NPY")?;
    let value = |b: &[u8]| value_of(b, endian, kind, size);
    // One pass from the mapped file into the heights buffer (allocated once, huge pages): decode,
    // scale, and mask infinities as NaN (what `Heightfield::new` would do in a second pass).
    let fin = |v: f64| if v.is_infinite() { f64::NAN } else { v };
    let (nx, ny) = (h.nx, h.ny);
    let z = if h.fortran {
        let mut z = heights::with_capacity(n);
        // Column-major: element (i, j) is stored at j * ny + i; written in row-major order.
        for i in 0..ny {
            z.extend((0..nx).map(|j| {
                let k = (j * ny + i) * size;
                fin(value(&raw[k..k + size]) * zs)
            }));
        }
        z
    } else if (endian, kind, size) == ('<', 'f', 8) {
        // The common case (numpy's default float64) without the per-element dispatch of `value`.
        decode_values(raw, 8, |b| fin(f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]) * zs))
    } else {
        decode_values(raw, size, |b| fin(value(b) * zs))
    };
    finish(Heightfield::new_finite_or_nan(nx, ny, dx, dy, z)?, h.descr)
}

/// One stored value of dtype `(endian, kind, size)` (checked by `parse_descr`) as f64.
fn value_of(b: &[u8], endian: char, kind: char, size: usize) -> f64 {
    let mut a = [0u8; 8];
    a[..size].copy_from_slice(b);
    if endian == '>' {
        a[..size].reverse();
    }
    match (kind, size) {
        ('f', 8) => f64::from_le_bytes(a),
        ('f', 4) => f32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
        ('i', 1) => a[0] as i8 as f64,
        ('u', 1) => a[0] as f64,
        ('i', 2) => i16::from_le_bytes([a[0], a[1]]) as f64,
        ('u', 2) => u16::from_le_bytes([a[0], a[1]]) as f64,
        ('i', 4) => i32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
        ('u', 4) => u32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
        ('i', 8) => i64::from_le_bytes(a) as f64,
        ('u', 8) => u64::from_le_bytes(a) as f64,
        _ => f64::NAN,
    }
}

/// Every `stride`-th point along both axes of a C-ordered NPY file, decoded straight from its memory
/// map (only the kept rows' pages are read), exactly as `decode` and then
/// [`crate::preprocess::subsample`] would give them; `None` for Fortran order (read whole instead).
pub fn read_npy_strided(map: &memmap2::Mmap, opts: &ReadOptions, stride: usize) -> Result<Option<Heightfield>> {
    let h = parse_header(map)?;
    if h.fortran || stride == 0 {
        return Ok(None);
    }
    let zs = z_scale(opts, "NPY")?;
    let (dx, dy) = spacing(opts, "NPY")?;
    let (nx, ny, size) = (h.nx, h.ny, h.size);
    let raw = &map[h.data..h.data + h.n * size];
    let fin = |v: f64| if v.is_infinite() { f64::NAN } else { v };
    let (sx, sy) = (nx.div_ceil(stride), ny.div_ceil(stride));
    let mut z = vec![0.0; sx * sy];
    let f8 = (h.endian, h.kind, size) == ('<', 'f', 8);
    // Kept rows in parallel (each a strided gather out of the map).
    z.par_chunks_mut(sx.max(1)).enumerate().for_each(|(r, out)| {
        let row = &raw[r * stride * nx * size..][..nx * size];
        for (j, o) in out.iter_mut().enumerate() {
            let b = &row[j * stride * size..][..size];
            *o = if f8 {
                fin(f64::from_le_bytes([b[0], b[1], b[2], b[3], b[4], b[5], b[6], b[7]]) * zs)
            } else {
                fin(value_of(b, h.endian, h.kind, size) * zs)
            };
        }
    });
    let hf = Heightfield::new_finite_or_nan(sx, sy, dx * stride as f64, dy * stride as f64, z)?;
    finish(hf, h.descr).map(Some)
}

/// The zero-copy read of a memory-mapped NPY file (see [`crate::scan::heights`]): the heights are the file's
/// bytes when the array is C-ordered little-endian float64, `--z-scale` is exactly 1 (heights already in
/// metres), the data start is 8-byte aligned and no height is infinite (the heightfield masks those as
/// NaN, which a read-only view cannot). When any of these fails the file is decoded as [`read_npy`] does
/// (from the header already parsed).
///
/// The infinity check is the one pass over the data, split over the rayon threads; it also touches
/// every page the later stages read.
pub fn read_npy_mapped(map: &Arc<memmap2::Mmap>, opts: &ReadOptions) -> Result<Heightfield> {
    let h = parse_header(map)?;
    let zs = z_scale(opts, "NPY")?;
    let (dx, dy) = spacing(opts, "NPY")?;
    if h.fortran || (h.endian, h.kind, h.size) != ('<', 'f', 8) || zs != 1.0 {
        return decode(map, h, opts);
    }
    let Some(z) = Heights::mapped(map.clone(), h.data, h.n) else { return decode(map, h, opts) };
    // Chunks of 64k values (512 KiB): enough to amortize the task, small enough to balance 2 threads.
    if z.par_chunks(1 << 16).any(|c| c.iter().any(|v| v.is_infinite())) {
        return decode(map, h, opts);
    }
    finish(Heightfield::new_finite_or_nan(h.nx, h.ny, dx, dy, z)?, h.descr)
}

fn finish(mut hf: Heightfield, descr: String) -> Result<Heightfield> {
    hf.meta = ScanMeta { format: "npy".into(), ..Default::default() };
    hf.meta.instrument.insert("npy.descr".into(), descr);
    Ok(hf)
}

fn parse_descr(d: &str) -> Result<(char, char, usize)> {
    let mut ch = d.chars();
    let (e, k) = (ch.next().unwrap_or('?'), ch.next().unwrap_or('?'));
    let size: usize = ch.as_str().parse().unwrap_or(0);
    let ok = matches!(e, '<' | '>' | '|' | '=') && matches!((k, size), ('f', 4) | ('f', 8) | ('i', 1 | 2 | 4 | 8) | ('u', 1 | 2 | 4 | 8));
    if !ok {
        return Err(Error::new(ErrorKind::Unsupported, format!("NPY dtype {d:?} (float and integer arrays are read)")));
    }
    // '=' is native order, little-endian on every machine ndfit builds for.
    Ok((if e == '>' { '>' } else { '<' }, k, size))
}

fn dict_str(h: &str, key: &str) -> Option<String> {
    let rest = h.split(&format!("'{key}':")).nth(1)?.trim_start();
    let q = rest.chars().next()?;
    if q != '\'' && q != '"' {
        return None;
    }
    let body = &rest[1..];
    Some(body[..body.find(q)?].to_string())
}

fn dict_shape(h: &str) -> Option<Vec<usize>> {
    let rest = h.split("'shape':").nth(1)?.trim_start().strip_prefix('(')?;
    let inner = &rest[..rest.find(')')?];
    inner.split(',').map(str::trim).filter(|t| !t.is_empty()).map(|t| t.parse().ok()).collect()
}
