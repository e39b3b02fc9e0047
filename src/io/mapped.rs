//! The file mapping a read decodes from, so that a decoder can give back the pages it has consumed.
//!
//! A scan decoded from its file (a type conversion, an unaligned or a deflated entry) would otherwise be
//! resident twice at its peak: the file's mapped pages and the decoded heights. While a [`Scope`] is
//! alive on this thread, a [`Release`] gives back the whole pages of the registered mapping that a decoder
//! has moved past. Bytes outside that mapping (a file read into memory, a caller's buffer) are never
//! advised: `MADV_DONTNEED` would zero a heap page, while a read-only file page comes back unchanged.

use std::cell::Cell;

thread_local! {
    /// `[start, end)` of the mapping registered on this thread (empty: none).
    static MAPPED: Cell<(usize, usize)> = const { Cell::new((0, 0)) };
}

/// Registers a read-only file mapping for this thread until dropped (the previous one is restored, so a
/// read nested in another, e.g. a job stolen by a waiting thread, leaves the outer one as it was).
pub(crate) struct Scope {
    prev: (usize, usize),
}

impl Scope {
    /// The mapping must stay mapped, read-only, and unwritten while the scope lives.
    pub(crate) fn new(map: &memmap2::Mmap) -> Scope {
        let start = map.as_ptr() as usize;
        Scope { prev: MAPPED.replace((start, start + map.len())) }
    }
}

impl Drop for Scope {
    fn drop(&mut self) {
        MAPPED.set(self.prev);
    }
}

/// A decoder's pass over `bytes` from its start: [`Release::upto`] gives back the whole pages behind the
/// decoder, when `bytes` lies in the mapping of this thread's [`Scope`] (otherwise it does nothing).
pub(crate) struct Release<'a> {
    bytes: &'a [u8],
    /// Offset in `bytes` of the first byte not yet given back (a page boundary of the mapping).
    done: usize,
    /// Whether `bytes` lies in the registered mapping.
    mapped: bool,
}

impl<'a> Release<'a> {
    /// Bytes given back per call at least (one `madvise` per MiB costs nothing next to decoding it).
    const BATCH: usize = 1 << 20;

    pub(crate) fn new(bytes: &'a [u8]) -> Release<'a> {
        let (lo, hi) = MAPPED.get();
        let (a, b) = (bytes.as_ptr() as usize, bytes.as_ptr() as usize + bytes.len());
        Release { bytes, done: 0, mapped: lo < hi && lo <= a && b <= hi }
    }

    /// The decoder has consumed `bytes[..pos]`: give back the whole pages in it not given back yet, once
    /// they make up [`Release::BATCH`] or the end is reached. The page that holds byte `pos` stays (its
    /// rest is still to be read).
    pub(crate) fn upto(&mut self, pos: usize) {
        let Some(page) = crate::scan::heights::page_size().filter(|_| self.mapped) else { return };
        let base = self.bytes.as_ptr() as usize;
        let lo = (base + self.done).next_multiple_of(page);
        let end = pos.min(self.bytes.len());
        let hi = (base + end) / page * page;
        if hi > lo && (hi - lo >= Self::BATCH || end == self.bytes.len()) {
            crate::scan::heights::release_pages(lo as *const u8, hi - lo);
            self.done = hi - base;
        }
    }
}

/// Heights decoded from `raw`, packed values of `width` bytes each, by `value`, in blocks of about 1 MiB;
/// behind each block the file's pages are given back ([`Release`]), so that a scan decoded from its
/// mapped file never holds both whole.
pub(crate) fn decode_values(raw: &[u8], width: usize, value: impl Fn(&[u8]) -> f64) -> Vec<f64> {
    let mut out = crate::scan::heights::with_capacity(raw.len() / width);
    let mut release = Release::new(raw);
    let block = (1 << 20) / width * width;
    let mut pos = 0;
    for chunk in raw.chunks(block) {
        out.extend(chunk.chunks_exact(width).map(&value));
        pos += chunk.len();
        release.upto(pos);
    }
    out
}

/// A cursor over `bytes` for decoders that read through `BufRead + Seek` (PNG, TIFF): the pages behind
/// its position are given back as it moves ([`Release`]). A seek backwards faults them in again.
pub(crate) struct ReleasingCursor<'a> {
    cursor: std::io::Cursor<&'a [u8]>,
    release: Release<'a>,
}

impl<'a> ReleasingCursor<'a> {
    pub(crate) fn new(bytes: &'a [u8]) -> ReleasingCursor<'a> {
        ReleasingCursor { cursor: std::io::Cursor::new(bytes), release: Release::new(bytes) }
    }

    fn moved(&mut self) {
        // Positions past the end are clamped by `upto`.
        self.release.upto(usize::try_from(self.cursor.position()).unwrap_or(usize::MAX));
    }
}

impl std::io::Read for ReleasingCursor<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.cursor.read(buf)?;
        self.moved();
        Ok(n)
    }
}

impl std::io::BufRead for ReleasingCursor<'_> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        self.cursor.fill_buf()
    }

    fn consume(&mut self, amt: usize) {
        self.cursor.consume(amt);
        self.moved();
    }
}

impl std::io::Seek for ReleasingCursor<'_> {
    fn seek(&mut self, pos: std::io::SeekFrom) -> std::io::Result<u64> {
        self.cursor.seek(pos)
    }
}
