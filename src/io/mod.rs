//! Reading scans into a [`Heightfield`] and writing them back.
//!
//! Formats are detected from content (magic bytes) first and the extension second. Every reader
//! converts to metres, masks the format's invalid marker as NaN, and checks every header size against
//! the bytes actually present before allocating. Layouts, units and invalid markers of each format are
//! described in `data_formats/formats.md`.

pub(crate) mod al3d;
pub(crate) mod atomic;
pub(crate) mod bytes;
pub(crate) mod gsf;
pub(crate) mod image;
pub(crate) mod inflate;
pub(crate) mod mapped;
pub(crate) mod md5;
pub(crate) mod metropro;
pub(crate) mod npy;
pub(crate) mod opd;
pub(crate) mod plu;
pub(crate) mod raw_opts;
pub(crate) mod sur;
pub(crate) mod text;
pub(crate) mod tmd;
pub(crate) mod units;
pub(crate) mod x3p;
pub(crate) mod x3p_write;
pub(crate) mod xml;

use std::path::Path;

use crate::error::{Error, ErrorKind, Result};
use crate::scan::Heightfield;

pub use atomic::{check_output, protect_input};
pub use atomic::{write_atomic, write_bytes_atomic};
pub use npy::npy_f64_bytes;
pub use x3p::MAX_POINT_MD5;
pub use x3p_write::write_x3p;
pub use x3p_write::{write_x3p_repeated, x3p_bytes};

/// Options for formats that do not carry everything themselves (CONTRACT.md: `--dx`, `--dy`, `--z-scale`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ReadOptions {
    /// Spacing along x in metres for formats without one.
    pub dx: Option<f64>,
    /// Spacing along y in metres (defaults to `dx`).
    pub dy: Option<f64>,
    /// Metres per stored height unit for formats without a height unit.
    pub z_scale: Option<f64>,
    /// Force a format id instead of detecting it.
    pub format: Option<String>,
}

/// One file format: everything the registry needs to detect and read it. Each reader's file defines its
/// entry (`pub const READER: Reader`), and [`Format::ALL`] lists the entries in detection order.
#[derive(Debug)]
pub struct Reader {
    /// Format id (what `ScanMeta::format`, `ndfit info` and `--format` use).
    pub id: &'static str,
    /// File extensions (lower case, no dot) that suggest the format when no signature matches.
    pub extensions: &'static [&'static str],
    /// Whether the first bytes of a file carry the format's signature; `None` for formats found by
    /// extension only.
    pub magic: Option<fn(&[u8]) -> bool>,
    /// Parse a whole file held in memory (the options give what the format may lack: spacing, units).
    pub read: fn(&[u8], &ReadOptions) -> Result<Heightfield>,
}

/// A format ndfit reads: a handle on its [`Reader`] entry, compared by id.
#[derive(Clone, Copy)]
pub struct Format(&'static Reader);

// The registry's names keep the spelling of the enum variants they replaced (callers write `Format::X3p`).
#[allow(non_upper_case_globals)]
impl Format {
    /// ISO 25178-72 X3P.
    pub const X3p: Format = Format(&x3p::READER);
    /// Digital Surf SUR (classic and compressed).
    pub const Sur: Format = Format(&sur::READER);
    /// Zygo MetroPro DAT.
    pub const MetroPro: Format = Format(&metropro::READER);
    /// Alicona AL3D.
    pub const Al3d: Format = Format(&al3d::READER);
    /// GelSight/TrueMap TMD.
    pub const Tmd: Format = Format(&tmd::READER);
    /// Veeco/Wyko OPD.
    pub const Opd: Format = Format(&opd::READER);
    /// Sensofar PLU (no magic: found by extension).
    pub const Plu: Format = Format(&plu::READER);
    /// Gwyddion Simple Field.
    pub const Gsf: Format = Format(&gsf::READER);
    /// NumPy array.
    pub const Npy: Format = Format(&npy::READER);
    /// OpenEXR (a float channel).
    pub const Exr: Format = Format(&image::EXR_READER);
    /// 16-bit grey PNG.
    pub const Png: Format = Format(&image::PNG_READER);
    /// 16-bit grey TIFF.
    pub const Tiff: Format = Format(&image::TIFF_READER);
    /// Plain text matrix (optionally with an `AsciiMatrix` header).
    pub const Ascii: Format = Format(&text::ASCII_READER);
    /// Comma-separated matrix or x,y,z columns.
    pub const Csv: Format = Format(&text::CSV_READER);
    /// x y z point list on a regular grid.
    pub const Xyz: Format = Format(&text::XYZ_READER);

    /// The registry: every format, in detection order (signatures are tried in this order, then
    /// extensions). A new reader adds its entry here.
    pub const ALL: &'static [Format] = &[
        Format::X3p,
        Format::Sur,
        Format::MetroPro,
        Format::Al3d,
        Format::Tmd,
        Format::Opd,
        Format::Gsf,
        Format::Npy,
        Format::Exr,
        Format::Png,
        Format::Tiff,
        Format::Plu,
        Format::Ascii,
        Format::Csv,
        Format::Xyz,
    ];

    /// The format id.
    pub fn id(self) -> &'static str {
        self.0.id
    }

    /// The format's registry entry.
    pub fn reader(self) -> &'static Reader {
        self.0
    }

    /// The format with id `id` (case-insensitive).
    pub fn from_id(id: &str) -> Option<Format> {
        let id = id.to_ascii_lowercase();
        Format::ALL.iter().copied().find(|f| f.id() == id)
    }

    /// File extensions (lower case, no dot) that suggest this format.
    fn extensions(self) -> &'static [&'static str] {
        self.0.extensions
    }

    /// Whether `head` (the first bytes of the file) carries this format's signature.
    fn magic(self, head: &[u8]) -> bool {
        self.0.magic.is_some_and(|m| m(head))
    }
}

impl PartialEq for Format {
    fn eq(&self, other: &Format) -> bool {
        self.0.id == other.0.id
    }
}

impl Eq for Format {}

impl std::fmt::Debug for Format {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.0.id)
    }
}

/// The format of a file: its content's signature first, then its extension.
pub fn detect(path: &Path, head: &[u8]) -> Option<Format> {
    if let Some(f) = Format::ALL.iter().copied().find(|f| f.magic(head)) {
        return Some(f);
    }
    let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).unwrap_or_default();
    if let Some(f) = Format::ALL.iter().copied().find(|f| f.extensions().contains(&ext.as_str())) {
        // A `.dat` without MetroPro's magic is usually a text matrix.
        if !(f == Format::MetroPro && looks_like_text(head)) {
            return Some(f);
        }
    }
    // Text of numbers under any other name: read it as a matrix.
    looks_like_text(head).then_some(Format::Ascii)
}

/// Whether `head` is printable ASCII text that starts with something numeric or a comment.
fn looks_like_text(head: &[u8]) -> bool {
    !head.is_empty()
        && head.iter().all(|&b| b == b'\n' || b == b'\r' || b == b'\t' || (0x20..0x7f).contains(&b))
        && head.iter().find(|b| !b.is_ascii_whitespace()).is_some_and(|&b| b.is_ascii_digit() || b"+-.#%nN".contains(&b))
}

/// Read any supported scan file. Errors name `path` and the problem in one line.
pub fn read_scan(path: &Path, opts: &ReadOptions) -> Result<Heightfield> {
    read_scan_inner(path, opts, 1).map_err(|e| e.with_path(path))
}

/// Read a scan keeping every `stride`-th point along both axes (from the first): the heightfield of
/// [`crate::preprocess::subsample`]`(&read_scan(path, opts)?, stride)`, without the points it would
/// drop where the file allows. A large C-ordered float64 NPY file in metres (the zero-copy case of
/// [`read_scan`]) copies only the kept points out of its memory map, and only their pages are read;
/// every other file is read whole and then subsampled. A stride of 1 is [`read_scan`]. The one
/// difference: a file whose kept points are all invalid is refused here, while [`read_scan`] refuses
/// only a file with no valid point at all.
///
/// Errors: as [`read_scan`], and [`ErrorKind::InvalidInput`] for a stride of 0.
pub fn read_scan_subsampled(path: &Path, opts: &ReadOptions, stride: usize) -> Result<Heightfield> {
    if stride == 0 {
        return Err(Error::invalid("subsampling step must be at least 1").with_path(path));
    }
    read_scan_inner(path, opts, stride).map_err(|e| e.with_path(path))
}

fn read_scan_inner(path: &Path, opts: &ReadOptions, stride: usize) -> Result<Heightfield> {
    raw_opts::check_given_spacing(opts)?;
    let md = std::fs::metadata(path)?;
    if md.is_dir() {
        if let Err(e) = std::fs::read_dir(path) {
            return Err(Error::new(ErrorKind::Io, format!("is a folder that cannot be read ({e}); no scan in it was fitted")));
        }
        return Err(Error::new(ErrorKind::InvalidInput, "is a directory, not a scan file"));
    }
    if !md.is_file() {
        // A FIFO would block until a writer comes and a device such as /dev/zero never ends: scans are
        // read from regular files only.
        return Err(Error::new(ErrorKind::InvalidInput, "is not a regular file (a pipe, socket or device); scans are read from files"));
    }
    let file = FileBytes::open(path, md.len())?;
    // Decoders give back the file's pages behind them (`mapped`): one copy of the heights at the peak.
    let _scope = match &file {
        FileBytes::Mapped(map) => Some(mapped::Scope::new(map)),
        FileBytes::Owned(_) => None,
    };
    let bytes: &[u8] = &file;
    if bytes.is_empty() {
        return Err(Error::new(ErrorKind::BadData, "file is empty"));
    }
    let format = match &opts.format {
        Some(id) => Format::from_id(id).ok_or_else(|| {
            Error::invalid(format!("unknown format {id:?}; known: {}", Format::ALL.iter().map(|f| f.id()).collect::<Vec<_>>().join(", ")))
        })?,
        None => detect(path, &bytes[..bytes.len().min(512)]).ok_or_else(|| {
            Error::new(ErrorKind::UnknownFormat, "unknown scan format (neither its content nor its extension is recognised)")
        })?,
    };
    // A read that keeps every row or every other row touches (within the kernel's fault-around window)
    // every page: map them all at once. Coarser strides touch a fraction of the rows: map pages as they
    // are read (docs/PERFORMANCE.md has the measurements). The X3P reader decides for itself: the stored
    // float64 data it reads in place is first touched by a pass on every thread, which faults the pages
    // in side by side instead of in one call on one thread.
    if stride <= 2 && format != Format::X3p {
        file.populate();
    }
    // Large native float64 NPY files are read in place (zero-copy, `crate::scan::heights`); every other case
    // decodes into an owned buffer.
    let strided = match (&file, format) {
        (FileBytes::Mapped(map), f) if f == Format::Npy && stride > 1 => npy::read_npy_strided(map, opts, stride)?,
        _ => None,
    };
    let mut hf = match strided {
        Some(hf) => hf,
        None => {
            let mut whole = match (&file, format) {
                (FileBytes::Mapped(map), f) if f == Format::Npy => npy::read_npy_mapped(map, opts)?,
                (FileBytes::Mapped(map), f) if f == Format::X3p => x3p::read_x3p_mapped(map)?,
                _ => read_bytes(format, bytes, opts)?,
            };
            whole.meta.file_grid = Some([whole.nx, whole.ny]);
            if stride > 1 {
                whole.subsample(stride)?
            } else {
                whole
            }
        }
    };
    // The strided NPY path knows the file's grid from its header; the rest set it above.
    if hf.meta.file_grid.is_none() {
        hf.meta.file_grid = npy::grid_of(bytes);
    }
    check_usable(&hf)?;
    Ok(hf)
}

/// A file's bytes: read into memory when small, memory-mapped when large (no copy; the readers
/// decode straight from the page cache).
enum FileBytes {
    Owned(Vec<u8>),
    Mapped(std::sync::Arc<memmap2::Mmap>),
}

/// Files at least this large are mapped rather than read.
const MMAP_THRESHOLD: u64 = 4 << 20;

impl FileBytes {
    fn open(path: &Path, len: u64) -> Result<Self> {
        if len < MMAP_THRESHOLD {
            return Ok(FileBytes::Owned(std::fs::read(path)?));
        }
        let file = std::fs::File::open(path)?;
        // SAFETY: the map is only read, and only while the caller holds it. Known limit: a file
        // truncated by another process during the read faults (SIGBUS) instead of failing
        // cleanly; scans are read at rest, and the zero-copy read is what keeps large files fast.
        let map = unsafe { memmap2::MmapOptions::new().map(&file)? };
        Ok(FileBytes::Mapped(std::sync::Arc::new(map)))
    }

    /// Map every page of a mapped file in one call ([`populate`]).
    fn populate(&self) {
        if let FileBytes::Mapped(map) = self {
            populate(map);
        }
    }
}

/// Map every page of `map` now, in one call (`MADV_POPULATE_READ`): no fault per page while a reader
/// decodes it in order (a `madvise(MADV_SEQUENTIAL)` would come too late to matter). A scan read as
/// tiles (larger than the tiling threshold) is faulted in band by band instead, and its pages released
/// after use (`crate::scan::bands`). Best effort: a kernel without the advice faults pages as they come.
pub(crate) fn populate(map: &memmap2::Mmap) {
    #[cfg(target_os = "linux")]
    if map.len() as u64 <= crate::scan::bands::release_threshold() {
        let _ = map.advise(memmap2::Advice::PopulateRead);
    }
}

impl std::ops::Deref for FileBytes {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        match self {
            FileBytes::Owned(v) => v,
            FileBytes::Mapped(m) => m,
        }
    }
}

/// Parse `bytes` as `format`.
pub fn read_bytes(format: Format, bytes: &[u8], opts: &ReadOptions) -> Result<Heightfield> {
    (format.0.read)(bytes, opts)
}

/// Reject scans nothing can be computed from: every point invalid.
fn check_usable(hf: &Heightfield) -> Result<()> {
    // `any` stops at the first valid point: free on real scans.
    if !hf.z.iter().any(|h| !h.is_nan()) {
        return Err(Error::new(
            ErrorKind::BadData,
            format!("all {} points of the {} x {} grid are invalid (or non-finite)", hf.z.len(), hf.nx, hf.ny),
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn registry_ids_are_unique_and_each_extension_finds_its_format() {
        let ids: std::collections::BTreeSet<_> = Format::ALL.iter().map(|f| f.id()).collect();
        assert_eq!(ids.len(), Format::ALL.len());
        for &f in Format::ALL {
            assert_eq!(Format::from_id(&f.id().to_uppercase()), Some(f));
            for ext in f.extensions() {
                // No signature in an empty head: the extension decides (a `.dat` is MetroPro's).
                assert_eq!(detect(Path::new(&format!("scan.{ext}")), b""), Some(f), "{ext}");
            }
        }
        assert_eq!(detect(Path::new("scan.bin"), b"PK\x03\x04rest"), Some(Format::X3p));
        assert_eq!(detect(Path::new("scan.bin"), b"\x00\x01"), None);
    }
}
