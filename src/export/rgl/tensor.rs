//! The tensor file of Dupuy and Jakob's RGL material database, as Mitsuba 3 (`TensorFile`) and pbrt-v4
//! (`Tensor`) read it: the 12 bytes `tensor_file\0`, the version `1, 0`, a little-endian `u32` field count,
//! then per field `u16` name length, the name, `u16` rank, `u8` type, `u64` byte offset of the data and one
//! `u64` per dimension; the data are C-ordered (last index fastest) little-endian arrays.

use crate::error::{Error, ErrorKind, Result};

/// The file's magic bytes.
pub const MAGIC: &[u8; 12] = b"tensor_file\0";

/// Element types with the codes both readers use (`Invalid = 0`, then unsigned before signed, by width).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Dtype {
    /// `u8` (code 1).
    UInt8,
    /// `i8` (code 2).
    Int8,
    /// `u16` (code 3).
    UInt16,
    /// `i16` (code 4).
    Int16,
    /// `u32` (code 5).
    UInt32,
    /// `i32` (code 6).
    Int32,
    /// `u64` (code 7).
    UInt64,
    /// `i64` (code 8).
    Int64,
    /// IEEE half (code 9).
    Float16,
    /// `f32` (code 10).
    Float32,
    /// `f64` (code 11).
    Float64,
}

impl Dtype {
    /// The type's code in the file.
    pub fn code(self) -> u8 {
        self as u8 + 1
    }

    /// The type of a code (`None` for 0 and codes past `Float64`).
    pub fn from_code(c: u8) -> Option<Dtype> {
        use Dtype::*;
        [UInt8, Int8, UInt16, Int16, UInt32, Int32, UInt64, Int64, Float16, Float32, Float64].get((c as usize).checked_sub(1)?).copied()
    }

    /// Bytes per element.
    pub fn size(self) -> usize {
        use Dtype::*;
        match self {
            UInt8 | Int8 => 1,
            UInt16 | Int16 | Float16 => 2,
            UInt32 | Int32 | Float32 => 4,
            UInt64 | Int64 | Float64 => 8,
        }
    }
}

/// One named array.
#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    /// The field's name.
    pub name: String,
    /// Its element type.
    pub dtype: Dtype,
    /// Its shape (C order).
    pub shape: Vec<u64>,
    /// Its data, little-endian, `product(shape) * dtype.size()` bytes.
    pub data: Vec<u8>,
}

impl Field {
    /// An `f32` array of `shape` (the values are rounded to `f32`).
    pub fn f32(name: &str, shape: &[usize], values: &[f64]) -> Field {
        debug_assert_eq!(shape.iter().product::<usize>(), values.len());
        let data = values.iter().flat_map(|v| (*v as f32).to_le_bytes()).collect();
        Field { name: name.into(), dtype: Dtype::Float32, shape: shape.iter().map(|&s| s as u64).collect(), data }
    }

    /// A `u8` array of one dimension.
    pub fn u8(name: &str, values: &[u8]) -> Field {
        Field { name: name.into(), dtype: Dtype::UInt8, shape: vec![values.len() as u64], data: values.to_vec() }
    }

    /// Elements in the array.
    pub fn len(&self) -> usize {
        self.shape.iter().map(|&s| s as usize).product()
    }

    /// Whether the array has no element.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The values of an `f32` field (`None` for any other type).
    pub fn as_f32(&self) -> Option<Vec<f32>> {
        (self.dtype == Dtype::Float32).then(|| self.data.chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect())
    }
}

/// A tensor file: its fields in file order.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct TensorFile {
    /// The fields.
    pub fields: Vec<Field>,
}

/// Data offsets are aligned to this many bytes, so that both readers' typed views of the mapped file are
/// aligned for every element type.
const ALIGN: usize = 8;

impl TensorFile {
    /// The field called `name`.
    pub fn field(&self, name: &str) -> Option<&Field> {
        self.fields.iter().find(|f| f.name == name)
    }

    /// The file's bytes: header, field table, then each field's data at an aligned offset.
    pub fn to_bytes(&self) -> Vec<u8> {
        let header: usize = 12 + 2 + 4 + self.fields.iter().map(|f| 2 + f.name.len() + 2 + 1 + 8 + 8 * f.shape.len()).sum::<usize>();
        let mut offsets = Vec::with_capacity(self.fields.len());
        let mut at = header.next_multiple_of(ALIGN);
        for f in &self.fields {
            offsets.push(at);
            at = (at + f.data.len()).next_multiple_of(ALIGN);
        }
        let mut out = Vec::with_capacity(at);
        out.extend_from_slice(MAGIC);
        out.extend_from_slice(&[1, 0]);
        out.extend_from_slice(&(self.fields.len() as u32).to_le_bytes());
        for (f, off) in self.fields.iter().zip(&offsets) {
            out.extend_from_slice(&(f.name.len() as u16).to_le_bytes());
            out.extend_from_slice(f.name.as_bytes());
            out.extend_from_slice(&(f.shape.len() as u16).to_le_bytes());
            out.push(f.dtype.code());
            out.extend_from_slice(&(*off as u64).to_le_bytes());
            for s in &f.shape {
                out.extend_from_slice(&s.to_le_bytes());
            }
        }
        for (f, off) in self.fields.iter().zip(&offsets) {
            out.resize(*off, 0);
            out.extend_from_slice(&f.data);
        }
        out.resize(at, 0);
        out
    }

    /// Parse a tensor file. Every size is checked against the bytes present before anything is allocated,
    /// so a corrupt header yields an error, never a panic or a large allocation.
    pub fn parse(bytes: &[u8]) -> Result<TensorFile> {
        let corrupt = |m: String| Error::new(ErrorKind::Corrupt, format!("not a valid tensor file: {m}"));
        if bytes.len() < 18 {
            return Err(corrupt(format!("{} bytes, shorter than the 18-byte header", bytes.len())));
        }
        if &bytes[..12] != MAGIC {
            return Err(Error::new(ErrorKind::UnknownFormat, "not a tensor file (no 'tensor_file' header)"));
        }
        if bytes[12..14] != [1, 0] {
            return Err(corrupt(format!("version {}.{} (only 1.0 is defined)", bytes[12], bytes[13])));
        }
        let mut cur = Cursor { bytes, at: 14 };
        let n = cur.u32().ok_or_else(|| corrupt("truncated field count".into()))?;
        let mut fields = Vec::new();
        for i in 0..n {
            let trunc = || corrupt(format!("field {i} of {n}: truncated header"));
            let len = cur.u16().ok_or_else(trunc)? as usize;
            let name = cur.take(len).ok_or_else(trunc)?;
            let name = std::str::from_utf8(name).map_err(|_| corrupt(format!("field {i}: name is not UTF-8")))?.to_string();
            // The name as the messages show it: escaped, so an error stays one line whatever the file holds.
            let quoted = name.escape_debug().to_string();
            let ndim = cur.u16().ok_or_else(trunc)? as usize;
            let code = cur.take(1).ok_or_else(trunc)?[0];
            let dtype = Dtype::from_code(code).ok_or_else(|| corrupt(format!("field '{quoted}': unknown type code {code}")))?;
            let offset = cur.u64().ok_or_else(trunc)?;
            let mut shape = Vec::with_capacity(ndim.min(16));
            let mut total = dtype.size() as u64;
            for _ in 0..ndim {
                let s = cur.u64().ok_or_else(trunc)?;
                total = total.checked_mul(s).ok_or_else(|| corrupt(format!("field '{quoted}': shape overflows")))?;
                shape.push(s);
            }
            let end = offset.checked_add(total).filter(|&e| e <= bytes.len() as u64).ok_or_else(|| {
                corrupt(format!("field '{quoted}': {total} bytes at offset {offset} run past the end of the {}-byte file", bytes.len()))
            })?;
            let data = bytes[offset as usize..end as usize].to_vec();
            fields.push(Field { name, dtype, shape, data });
        }
        Ok(TensorFile { fields })
    }
}

/// A bounds-checked little-endian reader.
struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let s = self.bytes.get(self.at..self.at.checked_add(n)?)?;
        self.at += n;
        Some(s)
    }
    fn u16(&mut self) -> Option<u16> {
        self.take(2).map(|b| u16::from_le_bytes([b[0], b[1]]))
    }
    fn u32(&mut self) -> Option<u32> {
        self.take(4).map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }
    fn u64(&mut self) -> Option<u64> {
        self.take(8).map(|b| u64::from_le_bytes(b.try_into().unwrap_or([0; 8])))
    }
}
