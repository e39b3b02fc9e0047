//! Reading scans into a [`Heightfield`] and writing them back.
//!
//! Formats are detected from content (magic bytes) first and the extension second. Every reader
//! converts to metres, masks the format's invalid marker as NaN, and checks every header size against
//! the bytes actually present before allocating. Layouts, units and invalid markers of each format are
//! described in `data_formats/formats.md`.

pub mod al3d;
pub mod atomic;
pub mod bytes;
pub mod md5;
pub mod metropro;
pub mod opd;
pub mod plu;
pub mod sur;
pub mod tmd;
pub mod units;
pub mod x3p;
pub mod x3p_write;
pub mod xml;

use std::path::Path;

use crate::error::{Error, ErrorKind, Result};
use crate::heightfield::Heightfield;

pub use atomic::{write_atomic, write_bytes_atomic};
pub use x3p_write::write_x3p;

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

/// The formats ndfit reads, by id (the id is what `ScanMeta::format` and `ndfit info` report).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// ISO 25178-72 X3P.
    X3p,
    /// Digital Surf SUR (classic and compressed).
    Sur,
    /// Zygo MetroPro DAT.
    MetroPro,
    /// Alicona AL3D.
    Al3d,
    /// GelSight/TrueMap TMD.
    Tmd,
    /// Veeco/Wyko OPD.
    Opd,
    /// Sensofar PLU (no magic: found by extension).
    Plu,
}

impl Format {
    /// Every format, in detection order.
    pub const ALL: &'static [Format] =
        &[Format::X3p, Format::Sur, Format::MetroPro, Format::Al3d, Format::Tmd, Format::Opd, Format::Plu];

    /// The format id.
    pub fn id(self) -> &'static str {
        match self {
            Format::X3p => "x3p",
            Format::Sur => "sur",
            Format::MetroPro => "metropro",
            Format::Al3d => "al3d",
            Format::Tmd => "tmd",
            Format::Opd => "opd",
            Format::Plu => "plu",
        }
    }

    /// The format with id `id` (case-insensitive).
    pub fn from_id(id: &str) -> Option<Format> {
        let id = id.to_ascii_lowercase();
        Format::ALL.iter().copied().find(|f| f.id() == id)
    }

    /// File extensions (lower case, no dot) that suggest this format.
    fn extensions(self) -> &'static [&'static str] {
        match self {
            Format::X3p => &["x3p"],
            Format::Sur => &["sur"],
            Format::MetroPro => &["dat"],
            Format::Al3d => &["al3d"],
            Format::Tmd => &["tmd"],
            Format::Opd => &["opd"],
            Format::Plu => &["plu", "apx"],
        }
    }

    /// Whether `head` (the first bytes of the file) carries this format's signature.
    fn magic(self, head: &[u8]) -> bool {
        match self {
            Format::X3p => head.starts_with(b"PK\x03\x04"),
            Format::Sur => head.starts_with(b"DIGITAL SURF") || head.starts_with(b"DSCOMPRESSED"),
            Format::MetroPro => {
                head.len() >= 4 && head[..3] == [0x88, 0x1B, 0x03] && (0x6F..=0x71).contains(&head[3])
            }
            Format::Al3d => head.starts_with(al3d::AL3D_MAGIC),
            Format::Tmd => head.starts_with(tmd::TMD_MAGIC),
            // Two bytes, then the directory entry named "Directory".
            Format::Opd => head.len() >= 11 && &head[2..11] == b"Directory",
            Format::Plu => false,
        }
    }
}

/// The format of a file: its content's signature first, then its extension.
pub fn detect(path: &Path, head: &[u8]) -> Option<Format> {
    if let Some(f) = Format::ALL.iter().copied().find(|f| f.magic(head)) {
        return Some(f);
    }
    let ext = path.extension()?.to_str()?.to_ascii_lowercase();
    Format::ALL.iter().copied().find(|f| f.extensions().contains(&ext.as_str()))
}

/// Read any supported scan file. Errors name `path` and the problem in one line.
pub fn read_scan(path: &Path, opts: &ReadOptions) -> Result<Heightfield> {
    read_scan_inner(path, opts).map_err(|e| e.with_path(path))
}

fn read_scan_inner(path: &Path, opts: &ReadOptions) -> Result<Heightfield> {
    let md = std::fs::metadata(path)?;
    if md.is_dir() {
        return Err(Error::new(ErrorKind::InvalidInput, "is a directory, not a scan file"));
    }
    let bytes = std::fs::read(path)?;
    if bytes.is_empty() {
        return Err(Error::new(ErrorKind::BadData, "file is empty"));
    }
    let format = match &opts.format {
        Some(id) => Format::from_id(id).ok_or_else(|| {
            Error::invalid(format!(
                "unknown format {id:?}; known: {}",
                Format::ALL.iter().map(|f| f.id()).collect::<Vec<_>>().join(", ")
            ))
        })?,
        None => detect(path, &bytes[..bytes.len().min(512)]).ok_or_else(|| {
            Error::new(ErrorKind::UnknownFormat, "unknown scan format (neither its content nor its extension is recognised)")
        })?,
    };
    let hf = read_bytes(format, &bytes, opts)?;
    check_usable(&hf)?;
    Ok(hf)
}

/// Parse `bytes` as `format`.
pub fn read_bytes(format: Format, bytes: &[u8], opts: &ReadOptions) -> Result<Heightfield> {
    let _ = opts;
    match format {
        Format::X3p => x3p::read_x3p(bytes),
        Format::Sur => sur::read_sur(bytes),
        Format::MetroPro => metropro::read_metropro(bytes),
        Format::Al3d => al3d::read_al3d(bytes),
        Format::Tmd => tmd::read_tmd(bytes),
        Format::Opd => opd::read_opd(bytes),
        Format::Plu => plu::read_plu(bytes),
    }
}

/// Reject scans nothing can be computed from: every point invalid.
fn check_usable(hf: &Heightfield) -> Result<()> {
    if hf.valid_count() == 0 {
        return Err(Error::new(
            ErrorKind::BadData,
            format!("all {} points of the {} x {} grid are invalid (or non-finite)", hf.z.len(), hf.nx, hf.ny),
        ));
    }
    Ok(())
}
