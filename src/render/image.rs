//! A linear-RGB HDR image and its two file forms: OpenEXR (`R`, `G`, `B` 32-bit float channels) and
//! NumPy `.npy` (`float32`, shape `(height, width, 3)`, little-endian, C order).

use crate::error::{Error, ErrorKind, Result};

/// Linear RGB radiance per pixel, rows from the top, each row from the left.
#[derive(Debug, Clone, PartialEq)]
pub struct Image {
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// `width * height` pixels, row-major.
    pub data: Vec<[f32; 3]>,
}

impl Image {
    /// The pixel in column `x` of row `y` (from the top).
    pub fn get(&self, x: usize, y: usize) -> [f32; 3] {
        self.data[y * self.width + x]
    }

    /// The `.npy` file (format version 1.0): a `float32` array of shape `(height, width, 3)`.
    pub fn to_npy(&self) -> Vec<u8> {
        let dict = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': ({}, {}, 3), }}", self.height, self.width);
        // The header (magic, version, length, dict, newline) is padded with spaces to a multiple of 64.
        let unpadded = 10 + dict.len() + 1;
        let len = dict.len() + 1 + (unpadded.next_multiple_of(64) - unpadded);
        let mut out = Vec::with_capacity(10 + len + 12 * self.data.len());
        out.extend_from_slice(b"\x93NUMPY\x01\x00");
        out.extend_from_slice(&(len as u16).to_le_bytes());
        out.extend_from_slice(dict.as_bytes());
        out.resize(10 + len - 1, b' ');
        out.push(b'\n');
        out.extend(self.data.iter().flatten().flat_map(|v| v.to_le_bytes()));
        out
    }

    /// The OpenEXR file: one layer with the `R`, `G`, `B` channels as 32-bit floats, lossless.
    pub fn to_exr(&self) -> Result<Vec<u8>> {
        use exr::prelude::{AnyChannel, AnyChannels, Encoding, FlatSamples, Image as Exr, Layer, LayerAttributes, SmallVec, WritableImage};
        let channel = |name: &str, k: usize| AnyChannel::new(name, FlatSamples::F32(self.data.iter().map(|p| p[k]).collect()));
        let channels = vec![channel("R", 0), channel("G", 1), channel("B", 2)];
        let layer = Layer::new(
            (self.width, self.height),
            LayerAttributes::named("render"),
            Encoding::SMALL_LOSSLESS,
            AnyChannels::sort(SmallVec::from_vec(channels)),
        );
        let mut buf = std::io::Cursor::new(Vec::new());
        Exr::from_layer(layer).write().to_buffered(&mut buf).map_err(|e| Error::new(ErrorKind::Io, format!("EXR encoding failed: {e}")))?;
        Ok(buf.into_inner())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The header is 64-byte aligned and ends in a newline; the data follow it in row order.
    #[test]
    fn npy_layout() {
        let img = Image { width: 3, height: 2, data: (0..6).map(|k| [k as f32, 0.5, -1.0]).collect() };
        let b = img.to_npy();
        let len = u16::from_le_bytes([b[8], b[9]]) as usize;
        assert_eq!((10 + len) % 64, 0);
        assert_eq!(b[10 + len - 1], b'\n');
        assert!(std::str::from_utf8(&b[10..10 + len]).unwrap().contains("'shape': (2, 3, 3)"));
        assert_eq!(b.len(), 10 + len + 6 * 12);
        let at = 10 + len + 4 * 12;
        assert_eq!(f32::from_le_bytes(b[at..at + 4].try_into().unwrap()), 4.0);
    }
}
