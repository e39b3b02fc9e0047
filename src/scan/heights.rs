//! The heights of a [`super::Scan`]: an owned buffer, a read-only view of a memory-mapped file whose
//! bytes already are the heights (zero-copy read), or the caller's borrowed slice.
//!
//! A 4096^2 float64 NPY is 128 MiB; copying it costs a kernel zero-fill of the fresh buffer plus the copy
//! itself, most of the read time (figures in docs/PERFORMANCE.md). When the file stores native little-endian float64 in row-major order, in
//! metres, 8-byte aligned and free of infinities, the heights are the mapped bytes: [`Heights`] derefs to
//! them directly. The first mutable access (form removal, masking) copies them into an owned buffer, so
//! every stage that edits heights works as before and the file is never written.
//!
//! Known limit (as for every memory-mapped read): a file truncated by another process while it is mapped
//! faults (SIGBUS) on access instead of failing with an error. Scans are read at rest.

use std::ops::{Deref, DerefMut};
use std::sync::Arc;

/// Row-major heights in metres (NaN = invalid): owned, borrowed from a mapped file, or borrowed from the
/// caller's memory (`'a`, see [`super::Scan::from_view`]); borrowed heights are copied on first write.
#[derive(Clone)]
pub struct Heights<'a>(Repr<'a>);

#[derive(Clone)]
enum Repr<'a> {
    Owned(Vec<f64>),
    Mapped { map: Arc<memmap2::Mmap>, offset: usize, len: usize },
    Borrowed(&'a [f64]),
}

impl<'a> Heights<'a> {
    /// A view of `len` float64 values at byte `offset` of `map`, when they can be read in place: the
    /// target is little-endian, the range lies inside the map, and its start is 8-byte aligned. The bytes
    /// are taken as native f64 as they are; the caller has checked the file stores `<f8` heights in
    /// metres with no infinities.
    pub(crate) fn mapped(map: Arc<memmap2::Mmap>, offset: usize, len: usize) -> Option<Heights<'static>> {
        let bytes = len.checked_mul(8)?;
        let end = offset.checked_add(bytes)?;
        let start = map.as_ptr() as usize + offset;
        (cfg!(target_endian = "little") && end <= map.len() && start.is_multiple_of(std::mem::align_of::<f64>()))
            .then_some(Heights(Repr::Mapped { map, offset, len }))
    }

    /// Heights borrowed from the caller, read in place until first written.
    pub fn borrowed(z: &'a [f64]) -> Heights<'a> {
        Heights(Repr::Borrowed(z))
    }

    /// Whether the heights are still the mapped file's bytes (nothing has written them yet).
    pub fn is_mapped(&self) -> bool {
        matches!(self.0, Repr::Mapped { .. })
    }

    /// Whether the heights are still the caller's borrowed memory (nothing has written them yet).
    pub fn is_borrowed(&self) -> bool {
        matches!(self.0, Repr::Borrowed(_))
    }

    /// Give the pages of mapped heights back to the page cache ([`release_pages`]), [`RELEASE_VALUES`]
    /// heights at a time, before the map is dropped: one unmap of the whole range holds the process's
    /// memory map locked throughout, stalling every allocation of other threads that needs the kernel;
    /// each release holds it only shared, and briefly. Reading the heights afterwards faults them back in
    /// from the unchanged file. Owned or borrowed heights: nothing to do.
    pub(crate) fn release_mapped(&self) {
        if self.is_mapped() {
            for part in self.chunks(RELEASE_VALUES) {
                release_pages(part.as_ptr().cast(), std::mem::size_of_val(part));
            }
        }
    }

    /// The heights as an owned vector (a copy when mapped or borrowed).
    pub fn into_vec(self) -> Vec<f64> {
        match self.0 {
            Repr::Owned(v) => v,
            Repr::Mapped { .. } | Repr::Borrowed(_) => self.to_vec(),
        }
    }

    /// The same heights with no borrow: borrowed heights are copied; owned and mapped ones are moved.
    pub fn into_owned(self) -> Heights<'static> {
        match self.0 {
            Repr::Owned(v) => Heights(Repr::Owned(v)),
            Repr::Mapped { map, offset, len } => Heights(Repr::Mapped { map, offset, len }),
            Repr::Borrowed(z) => {
                let mut v = with_capacity(z.len());
                v.extend_from_slice(z);
                Heights(Repr::Owned(v))
            }
        }
    }
}

impl Deref for Heights<'_> {
    type Target = [f64];
    #[inline]
    fn deref(&self) -> &[f64] {
        match &self.0 {
            Repr::Owned(v) => v,
            // SAFETY: `mapped` checked that [offset, offset + 8 len) lies inside the map and is 8-byte
            // aligned; every bit pattern is a valid f64; the map is read-only and lives as long as `self`.
            Repr::Mapped { map, offset, len } => unsafe { std::slice::from_raw_parts(map.as_ptr().add(*offset).cast::<f64>(), *len) },
            Repr::Borrowed(z) => z,
        }
    }
}

impl DerefMut for Heights<'_> {
    /// Copy-on-write: mapped or borrowed heights are copied into an owned buffer (once) before they are written.
    fn deref_mut(&mut self) -> &mut [f64] {
        if !matches!(self.0, Repr::Owned(_)) {
            let mut v = with_capacity(self.len());
            v.extend_from_slice(self);
            self.0 = Repr::Owned(v);
        }
        match &mut self.0 {
            Repr::Owned(v) => v,
            Repr::Mapped { .. } | Repr::Borrowed(_) => unreachable!("converted to owned just above"),
        }
    }
}

impl From<Vec<f64>> for Heights<'_> {
    fn from(v: Vec<f64>) -> Self {
        Heights(Repr::Owned(v))
    }
}

impl<'a> IntoIterator for &'a Heights<'_> {
    type Item = &'a f64;
    type IntoIter = std::slice::Iter<'a, f64>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

impl Default for Heights<'_> {
    fn default() -> Self {
        Heights(Repr::Owned(Vec::new()))
    }
}

impl PartialEq for Heights<'_> {
    /// Element-wise, as for `Vec<f64>` (so NaN heights compare unequal).
    fn eq(&self, other: &Self) -> bool {
        self[..] == other[..]
    }
}

impl std::fmt::Debug for Heights<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let kind = match self.0 {
            Repr::Owned(_) => "owned",
            Repr::Mapped { .. } => "mapped",
            Repr::Borrowed(_) => "borrowed",
        };
        write!(f, "Heights({kind}, {} values)", self.len())
    }
}

// ---- Allocation ----------------------------------------------------------------------------------
//
// The heights buffer of a reader: allocated once at its final size, and on Linux backed by
// transparent huge pages when the kernel allows them on request (`enabled = madvise`).
//
// A fresh 128 MiB `Vec` is zeroed by the kernel one 4 KiB page at a time on first write (32768 page
// faults for a 4096^2 float64 scan, most of the read time; docs/PERFORMANCE.md); with `MADV_HUGEPAGE`
// the same buffer takes 64 faults of 2 MiB. This is what makes numpy's `np.load`
// fast on the same machine. The advice changes neither contents nor validity of the memory: where
// huge pages are unavailable or disabled the kernel silently uses 4 KiB pages.

/// Buffers smaller than this gain nothing from huge pages (one 2 MiB page, twice for alignment slack).
const HUGE_MIN_BYTES: usize = 4 << 20;

/// An empty `Vec<f64>` with capacity `n` (exactly one allocation), advised for huge pages when large.
/// Callers fill it with `extend`/`push` in order: no zero-fill pass, no reallocation.
pub(crate) fn with_capacity(n: usize) -> Vec<f64> {
    let v: Vec<f64> = Vec::with_capacity(n);
    advise_huge(v.as_ptr() as usize, v.capacity() * std::mem::size_of::<f64>());
    v
}

/// `n` zeros (exactly one allocation), advised for huge pages when large. A large zeroed allocation
/// comes as fresh pages of the system that become resident only as they are written.
pub(crate) fn zeroed(n: usize) -> Vec<f64> {
    let v = vec![0.0; n];
    advise_huge(v.as_ptr() as usize, v.capacity() * std::mem::size_of::<f64>());
    v
}

#[cfg(target_os = "linux")]
pub(crate) fn advise_huge(start: usize, bytes: usize) {
    if bytes < HUGE_MIN_BYTES {
        return;
    }
    // Guard: a failed or odd page size query means no advice (the buffer works without it).
    let Some(page) = page_size() else { return };
    // madvise needs a page-aligned start; stay inside the allocation (round start up, end down).
    let lo = start.next_multiple_of(page);
    let hi = (start + bytes) / page * page;
    if hi > lo {
        // SAFETY: advice only, on whole pages inside this Vec's own live allocation; MADV_HUGEPAGE never changes contents or validity.
        let _ = unsafe { libc::madvise(lo as *mut libc::c_void, hi - lo, libc::MADV_HUGEPAGE) };
    }
}

/// Heights (4 MiB of f64) whose pages [`Heights::release_mapped`] gives back at a time.
const RELEASE_VALUES: usize = 1 << 19;

/// Give the pages of `[start, start + bytes)` of a read-only file mapping back to the page cache
/// (`MADV_DONTNEED`): the process's resident memory drops, and a later read faults the same bytes back
/// in from the unchanged file. Called only on ranges of a read-only file mapping (mapped [`Heights`], a file a reader
/// decodes); the range is widened to whole pages (the mapping starts on a page and ends on one).
#[cfg(target_os = "linux")]
pub(crate) fn release_pages(start: *const u8, bytes: usize) {
    let Some(page) = page_size().filter(|_| bytes > 0) else { return };
    let lo = (start as usize) & !(page - 1);
    let hi = (start as usize + bytes).next_multiple_of(page);
    // SAFETY: advice on whole pages of a read-only, file-backed mapping that stays mapped: the
    // contents read afterwards are the file's, unchanged (nothing writes the file or the mapping).
    let _ = unsafe { libc::madvise(lo as *mut libc::c_void, hi - lo, libc::MADV_DONTNEED) };
}

/// The page size, or `None` when the query fails or gives an odd value (then nothing is advised).
#[cfg(target_os = "linux")]
pub(crate) fn page_size() -> Option<usize> {
    // SAFETY: sysconf has no preconditions.
    let page = usize::try_from(unsafe { libc::sysconf(libc::_SC_PAGESIZE) }).ok()?;
    (page != 0 && page.is_power_of_two()).then_some(page)
}

#[cfg(not(target_os = "linux"))]
pub(crate) fn page_size() -> Option<usize> {
    None
}

#[cfg(not(target_os = "linux"))]
pub(crate) fn release_pages(_start: *const u8, _bytes: usize) {}

#[cfg(not(target_os = "linux"))]
pub(crate) fn advise_huge(_start: usize, _bytes: usize) {}

#[cfg(test)]
mod tests {
    use super::*;

    fn map_of(values: &[f64], lead: usize) -> Arc<memmap2::Mmap> {
        let mut bytes = vec![0u8; lead];
        for v in values {
            bytes.extend_from_slice(&v.to_le_bytes());
        }
        let mut f = tempfile::tempfile().expect("temp file");
        std::io::Write::write_all(&mut f, &bytes).expect("write temp file");
        // SAFETY: a private temporary file nobody else truncates.
        Arc::new(unsafe { memmap2::Mmap::map(&f).expect("map temp file") })
    }

    #[test]
    fn mapped_heights_read_the_file_and_copy_on_write() {
        let vals = [1.5, f64::NAN, -2.25, 1e-300];
        let mut h = Heights::mapped(map_of(&vals, 16), 16, 4).expect("aligned view");
        assert!(h.is_mapped());
        assert_eq!(h[0], 1.5);
        assert!(h[1].is_nan());
        assert_eq!(&h[2..], &vals[2..]);
        let c = h.clone();
        h[0] = 7.0;
        assert!(!h.is_mapped(), "written heights are owned");
        assert_eq!(h[0], 7.0);
        assert_eq!(c[0], 1.5, "the mapped view (and the file) is unchanged");
        assert_eq!(c.into_vec()[2], -2.25);
    }

    #[test]
    fn misaligned_or_short_views_are_refused() {
        let m = map_of(&[1.0, 2.0], 12);
        assert!(Heights::mapped(m.clone(), 12, 2).is_none(), "offset 12 is not 8-byte aligned");
        assert!(Heights::mapped(m.clone(), 8, 2).is_some());
        assert!(Heights::mapped(m, 8, 3).is_none(), "past the end of the map");
    }

    /// `Vec::with_capacity(n)` of a non-zero-sized type allocates exactly `n` (a guarantee of std's `Vec`
    /// docs, "Guarantees"), and the advice must not change that: one allocation of the final size.
    #[test]
    fn capacity_is_exact_and_filling_does_not_reallocate() {
        for n in [0usize, 1, 1000, (8 << 20) / 8 + 3] {
            let mut v = with_capacity(n);
            assert_eq!(v.capacity(), n);
            assert!(v.is_empty());
            let p = v.as_ptr();
            v.extend((0..n).map(|k| k as f64));
            assert_eq!(v.len(), n);
            if n > 0 {
                assert_eq!(v.as_ptr(), p, "filled in place, no reallocation");
                assert_eq!(v[n - 1], (n - 1) as f64);
            }
        }
    }
}
