//! A bounds-checked little/big-endian byte cursor for the binary readers.
//!
//! Every read checks the remaining length first and fails with a [`Error::corrupt`] naming what was
//! being read, so a truncated or lying file gives one clear line instead of a panic.

use crate::error::{Error, Result};

/// A read position over a byte slice.
#[derive(Debug, Clone)]
pub struct Cursor<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Cursor<'a> {
    /// A cursor at the start of `buf`.
    pub fn new(buf: &'a [u8]) -> Self {
        Cursor { buf, pos: 0 }
    }

    /// Current offset.
    pub fn pos(&self) -> usize {
        self.pos
    }

    /// Bytes left after the current offset.
    pub fn remaining(&self) -> usize {
        self.buf.len() - self.pos
    }

    /// Move to absolute offset `pos` (which may equal the length).
    pub fn seek(&mut self, pos: usize, what: &str) -> Result<()> {
        if pos > self.buf.len() {
            return Err(truncated(what, pos, 0, self.buf.len()));
        }
        self.pos = pos;
        Ok(())
    }

    /// Skip `n` bytes.
    pub fn skip(&mut self, n: usize, what: &str) -> Result<()> {
        self.take(n, what).map(|_| ())
    }

    /// The next `n` bytes.
    pub fn take(&mut self, n: usize, what: &str) -> Result<&'a [u8]> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.buf.len());
        match end {
            Some(end) => {
                let s = &self.buf[self.pos..end];
                self.pos = end;
                Ok(s)
            }
            None => Err(truncated(what, self.pos, n, self.buf.len())),
        }
    }

    /// The next `N` bytes as an array.
    pub fn array<const N: usize>(&mut self, what: &str) -> Result<[u8; N]> {
        let s = self.take(N, what)?;
        let mut a = [0u8; N];
        a.copy_from_slice(s);
        Ok(a)
    }

    /// One byte.
    pub fn u8(&mut self, what: &str) -> Result<u8> {
        Ok(self.array::<1>(what)?[0])
    }
    /// Little-endian u16.
    pub fn u16_le(&mut self, what: &str) -> Result<u16> {
        Ok(u16::from_le_bytes(self.array(what)?))
    }
    /// Big-endian u16.
    pub fn u16_be(&mut self, what: &str) -> Result<u16> {
        Ok(u16::from_be_bytes(self.array(what)?))
    }
    /// Little-endian i16.
    pub fn i16_le(&mut self, what: &str) -> Result<i16> {
        Ok(i16::from_le_bytes(self.array(what)?))
    }
    /// Big-endian i16.
    pub fn i16_be(&mut self, what: &str) -> Result<i16> {
        Ok(i16::from_be_bytes(self.array(what)?))
    }
    /// Little-endian u32.
    pub fn u32_le(&mut self, what: &str) -> Result<u32> {
        Ok(u32::from_le_bytes(self.array(what)?))
    }
    /// Big-endian u32.
    pub fn u32_be(&mut self, what: &str) -> Result<u32> {
        Ok(u32::from_be_bytes(self.array(what)?))
    }
    /// Little-endian i32.
    pub fn i32_le(&mut self, what: &str) -> Result<i32> {
        Ok(i32::from_le_bytes(self.array(what)?))
    }
    /// Big-endian i32.
    pub fn i32_be(&mut self, what: &str) -> Result<i32> {
        Ok(i32::from_be_bytes(self.array(what)?))
    }
    /// Little-endian f32.
    pub fn f32_le(&mut self, what: &str) -> Result<f32> {
        Ok(f32::from_le_bytes(self.array(what)?))
    }
    /// Big-endian f32.
    pub fn f32_be(&mut self, what: &str) -> Result<f32> {
        Ok(f32::from_be_bytes(self.array(what)?))
    }
}

fn truncated(what: &str, pos: usize, n: usize, len: usize) -> Error {
    Error::corrupt(format!("truncated: {what} needs {n} bytes at offset {pos}, file has {len}"))
}

/// `a * b * c` as a byte count, failing on overflow (header sizes are never trusted).
pub fn checked_size(dims: &[usize], what: &str) -> Result<usize> {
    dims.iter().try_fold(1usize, |acc, &d| acc.checked_mul(d)).ok_or_else(|| Error::corrupt(format!("{what}: size {dims:?} overflows")))
}

/// Check that a grid of `nx * ny` samples of `bytes_per` bytes fits in `available` bytes, returning
/// the number of samples, and that the grid is within the memory budget ([`crate::budget`]). Used
/// before any allocation sized from a header.
pub fn check_grid(nx: usize, ny: usize, bytes_per: usize, available: usize, what: &str) -> Result<usize> {
    if nx == 0 || ny == 0 {
        return Err(Error::corrupt(format!("{what}: empty grid {nx} x {ny}")));
    }
    let n = checked_size(&[nx, ny], what)?;
    let need = checked_size(&[n, bytes_per], what)?;
    if need > available {
        return Err(Error::corrupt(format!(
            "{what}: header claims {nx} x {ny} points ({need} bytes) but only {available} bytes are present"
        )));
    }
    // A header that lies about the bytes present is corrupt (above); one that tells the truth may still
    // be beyond the budget.
    crate::budget::check_points(nx, ny, what)?;
    Ok(n)
}

/// Text of a fixed-size, NUL- or space-padded field (lossy UTF-8, trimmed).
pub fn field_text(b: &[u8]) -> String {
    let end = b.iter().position(|&c| c == 0).unwrap_or(b.len());
    String::from_utf8_lossy(&b[..end]).trim().to_string()
}
