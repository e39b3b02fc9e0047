//! Atomic output: write to a temporary file beside the target, then rename, so an interrupted or
//! failed run never leaves a half-written file under the final name.

use std::io::{BufWriter, Write};
use std::path::Path;

use crate::error::{Error, Result};

/// Write `path` atomically: `fill` writes into a buffered temporary file in the same directory, which
/// is flushed, synced and renamed over `path` only when `fill` succeeds. On error the temporary file is
/// removed and `path` is untouched.
pub fn write_atomic<F>(path: &Path, fill: F) -> Result<()>
where
    F: FnOnce(&mut dyn Write) -> Result<()>,
{
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let tmp = tempfile::Builder::new()
        .prefix(&format!(".{name}."))
        .suffix(".tmp")
        .tempfile_in(dir)
        .map_err(|e| Error::io(e).with_path(path))?;
    let mut w = BufWriter::new(tmp);
    fill(&mut w).map_err(|e| e.with_path(path))?;
    let tmp = w.into_inner().map_err(|e| Error::io(e.into_error()).with_path(path))?;
    tmp.as_file().sync_all().map_err(|e| Error::io(e).with_path(path))?;
    tmp.persist(path).map_err(|e| Error::io(e.error).with_path(path))?;
    Ok(())
}

/// [`write_atomic`] for bytes already in memory.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| w.write_all(bytes).map_err(Error::io))
}
