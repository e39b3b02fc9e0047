//! Deflated point data inflated straight into the heights, block by block, with its MD5 checked on a
//! second thread in the same pass.
//!
//! A deflated X3P `data.bin` used to be inflated into a byte buffer, hashed, then decoded into a second
//! buffer of heights: three passes over the data and two fresh allocations. Here float64 data is inflated
//! directly into the bytes of the final heights buffer (on a little-endian target they already are the
//! heights); other types are inflated into a byte buffer and decoded block by block while the block is
//! in cache. Each finished block is handed, read-only, to a thread computing the MD5 that ISO 5436-2
//! records for the point data, so the checksum costs no wall time when a core is free. The zip reader
//! still checks the entry's CRC-32 at its end, which is read to the last byte.
//!
//! When the zip's bytes are in memory (a mapped file), the entry is inflated with `flate2::Decompress`
//! straight from those bytes into the heights: the `Read` adapter chain copied every compressed byte
//! through a buffer first, and its CRC-32 is then computed beside the MD5 on the hashing thread.

use std::io::Read;

use crate::error::{Error, Result};
use crate::io::mapped::Release;
use crate::io::x3p::ZType;
use crate::scan::heights;

/// Bytes inflated per block: large enough that the per-block hand-off costs nothing, small enough that
/// the block is still in cache when it is decoded and hashed.
const BLOCK: usize = 1 << 18;

/// Deflate cannot expand data by more than 1032:1 (RFC 1951 maximum), so an entry that claims more
/// than this times its compressed size is lying.
const MAX_DEFLATE_RATIO: u64 = 1032;

/// The heights of X3P point data entry `name` when the zip stores it compressed (`None` when stored:
/// the caller reads those bytes in place). The entry must declare exactly `n` values of type `t`;
/// `md5_want` is the point-data MD5 recorded in main.xml, checked when given. `file` holds the zip's
/// bytes when they are in memory (then a deflated entry is inflated from them in place).
#[allow(clippy::too_many_arguments)]
pub(crate) fn read_deflated_points<R: Read + std::io::Seek>(
    zip: &mut zip::ZipArchive<R>,
    file: Option<&[u8]>,
    name: &str,
    n: usize,
    t: ZType,
    inc: f64,
    off: f64,
    md5_want: Option<(&str, &str)>,
    (nx, ny): (usize, usize),
) -> Result<Option<Vec<f64>>> {
    let need = crate::io::bytes::checked_size(&[n, t.size()], "X3P point data")?;
    let entry = zip.by_name(name).map_err(|e| Error::corrupt(format!("main.xml links {name}, which the zip does not hold ({e})")))?;
    if entry.compression() == zip::CompressionMethod::Stored {
        return Ok(None);
    }
    let declared = entry.size();
    if declared != need as u64 {
        return Err(Error::corrupt(format!(
            "{name} holds {declared} bytes but main.xml's {nx} x {ny} points of {} bytes need {need}",
            t.size()
        )));
    }
    if declared > entry.compressed_size().saturating_mul(MAX_DEFLATE_RATIO) {
        return Err(Error::corrupt(format!(
            "{name} claims {declared} bytes from {} compressed bytes, more than deflate can expand",
            entry.compressed_size()
        )));
    }
    if let (Some(file), zip::CompressionMethod::Deflated, false) = (file, entry.compression(), entry.encrypted()) {
        let start = entry.data_start().ok_or_else(|| Error::corrupt(format!("{name}: no data offset")))?;
        let compressed = entry.compressed_size();
        let input = usize::try_from(start)
            .ok()
            .zip(usize::try_from(compressed).ok())
            .and_then(|(a, len)| a.checked_add(len).and_then(|b| file.get(a..b)))
            .ok_or_else(|| Error::corrupt(format!("{name}: truncated, its {compressed} compressed bytes are not all in the file")))?;
        let src = SliceInflate::new(input);
        return inflate_from(src, Some(entry.crc32()), name, n, t, inc, off, md5_want).map(Some);
    }
    inflate_heights(entry, name, n, t, inc, off, md5_want).map(Some)
}

/// Where the inflated bytes come from: a `Read` (the zip crate's entry reader, which checks the CRC-32
/// itself) or raw deflate bytes in memory.
trait Source {
    /// Fill `buf` completely; `done` is the count already delivered (for the message of a short stream).
    fn fill(&mut self, buf: &mut [u8], name: &str, done: usize, need: usize) -> Result<()>;
    /// Check that the stream ends exactly after the `need` bytes delivered.
    fn end(&mut self, name: &str, need: usize) -> Result<()>;
}

struct ReadSource<R>(R);

impl<R: Read> Source for ReadSource<R> {
    fn fill(&mut self, buf: &mut [u8], name: &str, done: usize, need: usize) -> Result<()> {
        fill_block(&mut self.0, buf, name, done, need)
    }

    fn end(&mut self, name: &str, need: usize) -> Result<()> {
        // Reading past the last value also makes the zip reader check the entry's CRC-32.
        let mut probe = [0u8; 1];
        loop {
            match self.0.read(&mut probe) {
                Ok(0) => return Ok(()),
                Ok(_) => return Err(Error::corrupt(format!("{name}: holds more than the {need} bytes main.xml declares"))),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(Error::corrupt(format!("{name}: cannot decompress the point data ({e})"))),
            }
        }
    }
}

/// A raw deflate stream in memory, inflated with flate2's low-level API into the caller's slices.
struct SliceInflate<'a> {
    d: flate2::Decompress,
    input: &'a [u8],
    pos: usize,
    /// The input's pages given back behind the inflate (when the input is the mapped file).
    release: Release<'a>,
}

impl<'a> SliceInflate<'a> {
    fn new(input: &'a [u8]) -> SliceInflate<'a> {
        SliceInflate { d: flate2::Decompress::new(false), input, pos: 0, release: Release::new(input) }
    }

    /// One call: inflate into `out`, returning the bytes written, the input bytes used and whether the
    /// stream ended.
    fn step(&mut self, out: &mut [u8], name: &str) -> Result<(usize, usize, bool)> {
        let (i0, o0) = (self.d.total_in(), self.d.total_out());
        let status = self
            .d
            .decompress(&self.input[self.pos..], out, flate2::FlushDecompress::None)
            .map_err(|e| Error::corrupt(format!("{name}: cannot decompress the point data ({e})")))?;
        let used = (self.d.total_in() - i0) as usize;
        self.pos += used;
        Ok(((self.d.total_out() - o0) as usize, used, status == flate2::Status::StreamEnd))
    }
}

impl Source for SliceInflate<'_> {
    fn fill(&mut self, buf: &mut [u8], name: &str, done: usize, need: usize) -> Result<()> {
        let mut got = 0;
        while got < buf.len() {
            let (k, used, ended) = self.step(&mut buf[got..], name)?;
            got += k;
            if got < buf.len() && (ended || (k == 0 && used == 0)) {
                return Err(Error::corrupt(format!("{name}: holds {} bytes, {need} expected", done + got)));
            }
        }
        self.release.upto(self.pos);
        Ok(())
    }

    fn end(&mut self, name: &str, need: usize) -> Result<()> {
        let mut probe = [0u8; 1];
        loop {
            let (k, used, ended) = self.step(&mut probe, name)?;
            if k > 0 {
                return Err(Error::corrupt(format!("{name}: holds more than the {need} bytes main.xml declares")));
            }
            if ended {
                return Ok(());
            }
            if used == 0 {
                return Err(Error::corrupt(format!("{name}: cannot decompress the point data (the deflate stream ends early)")));
            }
        }
    }
}

/// The point data of a deflated entry `name` holding exactly `n` values of type `t`, as heights in
/// metres (`off + inc * v`, the identity skipped for exactness; non-finite values as NaN). With
/// `md5_want` (32 hex digits), the MD5 of the stored bytes must match (`field` names it in the error).
/// A stream holding fewer or more bytes than `n` values, or failing to inflate, is `corrupt`.
pub(crate) fn inflate_heights<R: Read>(
    entry: R,
    name: &str,
    n: usize,
    t: ZType,
    inc: f64,
    off: f64,
    md5_want: Option<(&str, &str)>,
) -> Result<Vec<f64>> {
    inflate_from(ReadSource(entry), None, name, n, t, inc, off, md5_want)
}

/// [`inflate_heights`] from any [`Source`]; with `crc_want`, the CRC-32 of the inflated bytes must
/// equal it (computed on the hashing thread).
#[allow(clippy::too_many_arguments)]
fn inflate_from(
    mut entry: impl Source,
    crc_want: Option<u32>,
    name: &str,
    n: usize,
    t: ZType,
    inc: f64,
    off: f64,
    md5_want: Option<(&str, &str)>,
) -> Result<Vec<f64>> {
    let size = t.size();
    let need = n.checked_mul(size).ok_or_else(|| Error::corrupt(format!("{name}: point data size overflows")))?;
    let identity = inc == 1.0 && off == 0.0;
    let finish = move |v: f64| {
        let v = if identity { v } else { off + inc * v };
        if v.is_finite() {
            v
        } else {
            f64::NAN
        }
    };
    let direct = t == ZType::D && cfg!(target_endian = "little");
    // Float64 is inflated into the heights' own bytes (zeroed pages the inflate touches in order); other
    // types into one block that is decoded and reused. Either way the heights are the only whole copy.
    let (mut z, mut block) = match direct {
        true => (heights::zeroed(n), Vec::new()),
        false => (heights::with_capacity(n), vec![0u8; BLOCK.min(need)]),
    };
    let (bytes, dest): (&mut [u8], Option<&mut Vec<f64>>) = match direct {
        true => (as_bytes_mut(&mut z), None),
        false => (&mut block[..], Some(&mut z)),
    };
    let sums = std::thread::scope(|s| -> Result<Option<(Option<String>, Option<u32>)>> {
        let (tx, hasher) = match md5_want.is_some() || crc_want.is_some() {
            true => {
                // Blocks of the heights themselves are lent to the hashing thread; a reused block is copied,
                // and fewer copies wait (2 MiB) than lent blocks (which cost nothing).
                let depth = if direct { 64 } else { 8 };
                let (tx, rx) = std::sync::mpsc::sync_channel::<std::borrow::Cow<'_, [u8]>>(depth);
                let (want_md5, want_crc) = (md5_want.is_some(), crc_want.is_some());
                let h = s.spawn(move || {
                    let mut m = want_md5.then(crate::io::md5::Md5::default);
                    let mut c = want_crc.then(crc32fast::Hasher::new);
                    for block in rx {
                        if let Some(m) = m.as_mut() {
                            m.update(&block);
                        }
                        if let Some(c) = c.as_mut() {
                            c.update(&block);
                        }
                    }
                    (m.map(|m| m.finish().iter().map(|b| format!("{b:02x}")).collect::<String>()), c.map(|c| c.finalize()))
                });
                (Some(tx), Some(h))
            }
            false => (None, None),
        };
        let mut done = 0;
        // A hasher that has gone away (it cannot, short of a panic) only loses the check.
        let mut sent = true;
        if let Some(z) = dest {
            while done < need {
                let chunk = &mut bytes[..BLOCK.min(need - done)];
                entry.fill(chunk, name, done, need)?;
                done += chunk.len();
                decode_into(z, chunk, t, &finish);
                if let Some(tx) = &tx {
                    sent &= tx.send(std::borrow::Cow::Owned(chunk.to_vec())).is_ok();
                }
            }
        } else {
            for chunk in bytes.chunks_mut(BLOCK) {
                entry.fill(chunk, name, done, need)?;
                done += chunk.len();
                if let Some(tx) = &tx {
                    sent &= tx.send(std::borrow::Cow::Borrowed(chunk)).is_ok();
                }
            }
        }
        drop(tx);
        // The stream must end exactly here.
        entry.end(name, need)?;
        match hasher {
            Some(h) if sent => Ok(h.join().ok()),
            _ => Ok(None),
        }
    })?;
    let (md5, crc) = sums.unwrap_or((None, None));
    if let Some(want) = crc_want {
        // The zip reader's own check is bypassed on this path, so a CRC-32 that was not computed (the
        // hashing thread lost, which only a panic can do) refuses the data rather than passing it.
        let got = crc.ok_or_else(|| Error::corrupt(format!("{name}: the point data's CRC-32 could not be checked")))?;
        if want != got {
            return Err(Error::corrupt(format!(
                "{name}: CRC-32 mismatch ({got:08x}, the zip records {want:08x}): the point data is corrupt"
            )));
        }
    }
    if let (Some((field, want)), Some(got)) = (md5_want, md5) {
        if !got.eq_ignore_ascii_case(want) {
            return Err(Error::corrupt(format!(
                "{name}: MD5 is {got} but main.xml's {field} records {want}: the data was changed or damaged"
            )));
        }
    }
    if direct && (!identity || z.iter().any(|v| !v.is_finite())) {
        for v in z.iter_mut() {
            *v = finish(*v);
        }
    }
    Ok(z)
}

/// Fill `buf` completely from `r`. `done` is the count already read (for the message of a short
/// stream).
fn fill_block<R: Read>(r: &mut R, buf: &mut [u8], name: &str, done: usize, need: usize) -> Result<()> {
    let mut got = 0;
    while got < buf.len() {
        match r.read(&mut buf[got..]) {
            Ok(0) => {
                return Err(Error::corrupt(format!("{name}: holds {} bytes, {need} expected", done + got)));
            }
            Ok(k) => got += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(Error::corrupt(format!("{name}: cannot decompress the point data ({e})"))),
        }
    }
    Ok(())
}

/// Append the values of `block` (whole values only: blocks are multiples of 8 bytes, the value sizes
/// divide them) to `z`.
fn decode_into(z: &mut Vec<f64>, block: &[u8], t: ZType, finish: &impl Fn(f64) -> f64) {
    match t {
        ZType::D => z.extend(block.chunks_exact(8).map(|c| finish(f64::from_le_bytes(c.try_into().expect("8 bytes"))))),
        ZType::F => z.extend(block.chunks_exact(4).map(|c| finish(f32::from_le_bytes(c.try_into().expect("4 bytes")) as f64))),
        ZType::L => z.extend(block.chunks_exact(4).map(|c| finish(i32::from_le_bytes(c.try_into().expect("4 bytes")) as f64))),
        ZType::I => z.extend(block.chunks_exact(2).map(|c| finish(i16::from_le_bytes(c.try_into().expect("2 bytes")) as f64))),
    }
}

/// The bytes of `z` (native order).
fn as_bytes_mut(z: &mut [f64]) -> &mut [u8] {
    let len = std::mem::size_of_val(z);
    // SAFETY: the byte view covers exactly `z`'s initialised memory and borrows it mutably for its
    // lifetime; u8 has alignment 1 and every byte pattern is a valid f64, so any write leaves valid values.
    unsafe { std::slice::from_raw_parts_mut(z.as_mut_ptr().cast::<u8>(), len) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    fn deflate(data: &[u8]) -> Vec<u8> {
        let mut e = flate2::write::DeflateEncoder::new(Vec::new(), flate2::Compression::default());
        e.write_all(data).unwrap();
        e.finish().unwrap()
    }

    /// `n` values `x(k)` stored as type `t` (the floats in micrometres as metres), with a non-finite
    /// value where `k % every == at`: `bad` for float64, NaN for float32.
    fn encode(
        t: ZType,
        n: usize,
        x: impl Fn(usize) -> f64,
        (d_every, d_at, bad): (usize, usize, f64),
        (f_every, f_at): (usize, usize),
    ) -> Vec<u8> {
        let mut raw = Vec::new();
        for k in 0..n {
            let x = x(k);
            match t {
                ZType::D => raw.extend_from_slice(&(if k % d_every == d_at { bad } else { x * 1e-6 }).to_le_bytes()),
                ZType::F => raw.extend_from_slice(&(if k % f_every == f_at { f32::NAN } else { x as f32 * 1e-6 }).to_le_bytes()),
                ZType::L => raw.extend_from_slice(&((x * 1e4) as i32).to_le_bytes()),
                ZType::I => raw.extend_from_slice(&(x as i16).to_le_bytes()),
            }
        }
        raw
    }

    fn run(raw: &[u8], n: usize, t: ZType, inc: f64, off: f64, md5: Option<(&str, &str)>) -> Result<Vec<f64>> {
        let c = deflate(raw);
        inflate_heights(flate2::read::DeflateDecoder::new(&c[..]), "bindata/data.bin", n, t, inc, off, md5)
    }

    /// Values built from a formula and encoded here, decoded by `x3p::decode` (the whole-buffer path)
    /// and by the block path: the two must agree bit for bit, over several blocks and a partial one.
    #[test]
    fn block_path_matches_whole_buffer_decode() {
        let n = 3 * BLOCK / 8 + 77; // float64: three full blocks and a partial one
        for (t, inc, off) in
            [(ZType::D, 1.0, 0.0), (ZType::D, 1e-9, 2.5e-6), (ZType::F, 1.0, 0.0), (ZType::I, 3e-9, -1e-7), (ZType::L, 1e-10, 0.0)]
        {
            let raw = encode(t, n, |k| (k as f64 * 0.001).sin() * 1e3, (1001, 5, f64::INFINITY), (999, 3));
            let whole = crate::io::x3p::decode(&raw, t, inc, off, None).unwrap();
            let md5 = crate::io::md5::md5_hex(&raw);
            let blocks = run(&raw, n, t, inc, off, Some(("MD5ChecksumPointData", &md5))).unwrap();
            assert_eq!(whole.len(), blocks.len());
            assert!(whole.iter().zip(&blocks).all(|(a, b)| a.to_bits() == b.to_bits()), "{t:?}");
            assert!(blocks.iter().all(|v| !v.is_infinite()));
            assert!(blocks.iter().any(|v| v.is_nan()) || matches!(t, ZType::I | ZType::L));
        }
    }

    #[test]
    fn a_wrong_md5_short_or_long_stream_is_corrupt() {
        let raw: Vec<u8> = (0..1000u32).flat_map(|k| (k as f64).to_le_bytes()).collect();
        let wrong = "0123456789abcdef0123456789abcdef";
        let e = run(&raw, 1000, ZType::D, 1.0, 0.0, Some(("MD5ChecksumPointData", wrong))).unwrap_err();
        assert!(e.message().contains("MD5ChecksumPointData") && e.message().contains(wrong), "{e}");
        let e = run(&raw, 1001, ZType::D, 1.0, 0.0, None).unwrap_err();
        assert!(e.message().contains("holds 8000 bytes, 8008"), "{e}");
        let e = run(&raw, 999, ZType::D, 1.0, 0.0, None).unwrap_err();
        assert!(e.message().contains("more than the 7992 bytes"), "{e}");
        // A deflate stream cut short fails to inflate or ends early: corrupt either way, never a panic.
        let c = deflate(&raw);
        let cut = &c[..c.len() / 2];
        let e = inflate_heights(flate2::read::DeflateDecoder::new(cut), "d", 1000, ZType::D, 1.0, 0.0, None).unwrap_err();
        assert_eq!(e.kind(), crate::error::ErrorKind::Corrupt, "{e}");
    }

    /// A zip holding `raw` deflated as `bindata/data.bin`.
    fn zip_of(raw: &[u8]) -> Vec<u8> {
        let mut buf = std::io::Cursor::new(Vec::new());
        let mut zw = zip::ZipWriter::new(&mut buf);
        let opts = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated).compression_level(Some(6));
        zw.start_file("bindata/data.bin", opts).unwrap();
        zw.write_all(raw).unwrap();
        zw.finish().unwrap();
        buf.into_inner()
    }

    /// Both ways of reading a zipped entry: through the zip crate's reader, and in place from the bytes.
    fn both(file: &[u8], n: usize, t: ZType, inc: f64, off: f64, md5: Option<(&str, &str)>) -> [Result<Vec<f64>>; 2] {
        [None, Some(file)].map(|f| {
            let mut zip = zip::ZipArchive::new(std::io::Cursor::new(file)).unwrap();
            read_deflated_points(&mut zip, f, "bindata/data.bin", n, t, inc, off, md5, (n, 1)).map(|z| z.expect("deflated"))
        })
    }

    /// The in-place inflate equals the `Read` path and the whole-buffer decode bit for bit (every Z type,
    /// an offset/increment, non-finite values, several blocks and a partial one), and both check the MD5.
    #[test]
    fn in_place_inflate_matches_the_reader_path() {
        let n = 2 * BLOCK / 8 + 13;
        for (t, inc, off) in
            [(ZType::D, 1.0, 0.0), (ZType::D, 1e-9, 2.5e-6), (ZType::F, 1.0, 0.0), (ZType::I, 3e-9, -1e-7), (ZType::L, 1e-10, 0.0)]
        {
            let raw = encode(t, n, |k| (k as f64 * 0.0013).cos() * 1e3 + (k % 7) as f64, (1009, 5, f64::NEG_INFINITY), (997, 3));
            let whole = crate::io::x3p::decode(&raw, t, inc, off, None).unwrap();
            let md5 = crate::io::md5::md5_hex(&raw);
            let file = zip_of(&raw);
            for got in both(&file, n, t, inc, off, Some(("MD5ChecksumPointData", &md5))) {
                let got = got.unwrap();
                assert_eq!(got.len(), whole.len());
                assert!(whole.iter().zip(&got).all(|(a, b)| a.to_bits() == b.to_bits()), "{t:?}");
            }
            let wrong = "00000000000000000000000000000000";
            for got in both(&file, n, t, inc, off, Some(("MD5ChecksumPointData", wrong))) {
                assert!(got.unwrap_err().message().contains("MD5"), "{t:?}");
            }
        }
    }

    /// Wrong lengths, a damaged stream, a damaged CRC and a cut file: `corrupt` on both paths, never a panic.
    #[test]
    fn in_place_inflate_refuses_damage() {
        let raw: Vec<u8> = (0..40_000u32).flat_map(|k| ((k as f64).sqrt() * 1e-6).to_le_bytes()).collect();
        let file = zip_of(&raw);
        for n in [40_001, 39_999] {
            for got in both(&file, n, ZType::D, 1.0, 0.0, None) {
                // The entry's declared size is checked before any inflating.
                let e = got.unwrap_err();
                assert!(e.message().contains("holds 320000 bytes but"), "{e}");
            }
        }
        // The stream's own lengths: inflate_from with a declared count that is wrong.
        let c = deflate(&raw);
        for (n, want) in [(40_001usize, "holds 320000 bytes, 320008"), (39_999, "more than the 319992 bytes")] {
            let src = SliceInflate::new(&c);
            let e = inflate_from(src, None, "d", n, ZType::D, 1.0, 0.0, None).unwrap_err();
            assert!(e.message().contains(want), "{e}");
        }
        let cut = &c[..c.len() / 2];
        let e = inflate_from(SliceInflate::new(cut), None, "d", 40_000, ZType::D, 1.0, 0.0, None).unwrap_err();
        assert_eq!(e.kind(), crate::error::ErrorKind::Corrupt, "{e}");
        // A wrong CRC-32 (the stream intact) and a damaged byte inside the stream.
        let src = SliceInflate::new(&c);
        let e = inflate_from(src, Some(crc32fast::hash(&raw) ^ 1), "d", 40_000, ZType::D, 1.0, 0.0, None).unwrap_err();
        assert!(e.message().contains("CRC-32 mismatch"), "{e}");
        let ok = inflate_from(SliceInflate::new(&c), Some(crc32fast::hash(&raw)), "d", 40_000, ZType::D, 1.0, 0.0, None);
        assert_eq!(ok.unwrap().len(), 40_000);
        let mut bad = file.clone();
        let start = {
            let mut zip = zip::ZipArchive::new(std::io::Cursor::new(&file[..])).unwrap();
            let e = zip.by_name("bindata/data.bin").unwrap();
            e.data_start().unwrap() as usize + e.compressed_size() as usize / 2
        };
        bad[start] ^= 0x5a;
        for got in both(&bad, 40_000, ZType::D, 1.0, 0.0, None) {
            assert_eq!(got.unwrap_err().kind(), crate::error::ErrorKind::Corrupt);
        }
        // A file cut inside the entry: the zip's directory is gone, so cut the compressed bytes'
        // extent instead by lying about the file's length.
        let mut zip = zip::ZipArchive::new(std::io::Cursor::new(&file[..])).unwrap();
        let e = read_deflated_points(&mut zip, Some(&file[..start]), "bindata/data.bin", 40_000, ZType::D, 1.0, 0.0, None, (40_000, 1))
            .unwrap_err();
        assert!(e.message().contains("truncated"), "{e}");
    }
}
