//! Output that respects what is at the path: an interrupted or failed run never leaves a half-written
//! file under the final name, and nothing but the file the user named is replaced.
//!
//! - A regular file (or a new name) is written to a temporary file beside it, then renamed over it;
//!   a new file gets the mode `0666 & !umask`, a replaced one keeps its mode.
//! - A symlink is followed: its final target is replaced the same way, the link stays.
//! - A device or FIFO (`/dev/null`, `/dev/stdout`, a named pipe) is written directly, once the whole
//!   output is ready in memory.
//! - A path that is an input of this process ([`protect_input`]) is refused, while the input's name
//!   still names that file.
//! - Temporary files of a run that was killed (`.NAME.XXXXXX.tmp`, no longer locked by a writer) are
//!   removed by the next write of the same name.

use std::collections::HashMap;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use crate::error::{Error, ErrorKind, Result};

/// An input of this process: the name it was given (for messages) and its canonical path (absolute,
/// without links: it keeps naming the file when the working directory changes).
struct Input {
    given: PathBuf,
    canonical: PathBuf,
}

/// The files this process reads as inputs, by (device, inode). A map: a batch or a long-lived Python
/// process records every scan it reads.
static INPUTS: Mutex<Option<HashMap<(u64, u64), Input>>> = Mutex::new(None);

/// Record `path` as an input: any later write whose target is the same file is refused, as long as
/// the file is still at the path `path` resolved to.
pub fn protect_input(path: &Path) {
    if let (Some(id), Ok(canonical)) = (file_id(path), std::fs::canonicalize(path)) {
        if let Ok(mut v) = INPUTS.lock() {
            v.get_or_insert_with(HashMap::new).entry(id).or_insert_with(|| Input { given: path.to_path_buf(), canonical });
        }
    }
}

/// The input of this process that `target` is, if any (the name it was given). An entry whose file is no
/// longer at its canonical path (deleted or replaced since) is dropped instead: its inode number may have
/// been reused by the file at `target`, and replacing `target` cannot touch the input at its path.
fn input_at(target: &Path) -> Option<PathBuf> {
    let id = file_id(target)?;
    let mut v = INPUTS.lock().ok()?;
    let inputs = v.as_mut()?;
    let input = inputs.get(&id)?;
    if file_id(&input.canonical) == Some(id) {
        return Some(input.given.clone());
    }
    inputs.remove(&id);
    None
}

#[cfg(unix)]
fn file_id(path: &Path) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(path).ok().map(|m| (m.dev(), m.ino()))
}

#[cfg(not(unix))]
fn file_id(path: &Path) -> Option<(u64, u64)> {
    // Without inode numbers the canonical path stands in for the file's identity.
    use std::hash::{Hash, Hasher};
    let c = std::fs::canonicalize(path).ok()?;
    let mut h = std::collections::hash_map::DefaultHasher::new();
    c.hash(&mut h);
    Some((0, h.finish()))
}

/// The folder that holds `target` (`.` for a bare file name).
fn folder_of(target: &Path) -> &Path {
    match target.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// The file a write to `path` lands in: `path` itself, or the final target of a chain of symlinks.
fn resolve(path: &Path) -> Result<PathBuf> {
    let mut p = path.to_path_buf();
    for _ in 0..40 {
        match std::fs::symlink_metadata(&p) {
            Ok(md) if md.file_type().is_symlink() => {
                let link = std::fs::read_link(&p).map_err(|e| Error::io(e).with_path(path))?;
                p = match p.parent() {
                    Some(dir) if link.is_relative() => dir.join(link),
                    _ => link,
                };
            }
            _ => return Ok(p),
        }
    }
    Err(Error::new(ErrorKind::Io, "too many levels of symbolic links").with_path(path))
}

/// Check that `path` can take an output: not a directory, in a folder that exists, not an input of
/// this process. Commands call this before their work so a wrong `-o` fails at once; every write
/// checks again.
pub fn check_output(path: &Path) -> Result<()> {
    let target = resolve(path)?;
    if target.is_dir() {
        return Err(Error::new(ErrorKind::InvalidInput, "is a directory, not a file to write").with_path(path));
    }
    let dir = folder_of(&target);
    if !dir.is_dir() {
        let why = if dir.exists() { "is not a folder" } else { "does not exist" };
        return Err(Error::new(ErrorKind::InvalidInput, format!("the folder {} {why}", dir.display())).with_path(path));
    }
    if let Some(input) = input_at(&target) {
        return Err(Error::new(
            ErrorKind::InvalidInput,
            format!("is the input {}; refusing to overwrite it with an output", input.display()),
        )
        .with_path(path));
    }
    Ok(())
}

/// Write `path` as the module describes: `fill` writes the contents; only when it succeeds do they
/// reach `path`. On error the temporary file is removed and `path` is untouched.
pub fn write_atomic<F>(path: &Path, fill: F) -> Result<()>
where
    F: FnOnce(&mut dyn Write) -> Result<()>,
{
    write_atomic_as(path, true, fill)
}

/// [`write_atomic`] without the `fsync` before the rename: the file is still complete or absent under
/// its name for every process and after any crash or kill of this one, but only durable against power
/// loss once the caller has run [`sync_tree`] over its folder (what `ndfit batch` does once per run).
#[cfg(feature = "cli")]
pub fn write_atomic_unsynced<F>(path: &Path, fill: F) -> Result<()>
where
    F: FnOnce(&mut dyn Write) -> Result<()>,
{
    write_atomic_as(path, false, fill)
}

fn write_atomic_as<F>(path: &Path, durable: bool, fill: F) -> Result<()>
where
    F: FnOnce(&mut dyn Write) -> Result<()>,
{
    check_output(path)?;
    let target = resolve(path)?;
    let existing = match std::fs::metadata(&target) {
        Ok(md) => Some(md),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => return Err(Error::io(e).with_path(path)),
    };
    if let Some(md) = existing.as_ref().filter(|m| !m.is_file()) {
        return write_direct(path, &target, md, fill);
    }
    let dir = folder_of(&target);
    let name = target.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    remove_stale_temps(dir, &name);
    let prefix = format!(".{name}.");
    let mut builder = tempfile::Builder::new();
    builder.prefix(&prefix).suffix(".tmp");
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        // Created with 0666: the kernel applies the umask, as for any file a command creates.
        builder.permissions(std::fs::Permissions::from_mode(0o666));
    }
    let tmp = builder.tempfile_in(dir).map_err(|e| {
        // tempfile's error names the random temporary path; the user knows the output and its folder.
        let why = e.raw_os_error().map(std::io::Error::from_raw_os_error).unwrap_or_else(|| e.kind().into());
        Error::new(ErrorKind::Io, format!("cannot create a file in {}: {why}", dir.display())).with_path(path)
    })?;
    lock_exclusive(tmp.as_file());
    if let Some(md) = &existing {
        // A replaced file keeps its mode.
        let _ = tmp.as_file().set_permissions(md.permissions());
    }
    let mut w = BufWriter::new(Writeback { file: tmp, durable, written: 0, started: 0 });
    fill(&mut w).map_err(|e| e.with_path(path))?;
    let tmp = w.into_inner().map_err(|e| Error::io(e.into_error()).with_path(path))?.file;
    if durable {
        tmp.as_file().sync_all().map_err(|e| Error::io(e).with_path(path))?;
    }
    tmp.persist(&target).map_err(|e| Error::io(e.error).with_path(path))?;
    Ok(())
}

/// Make everything written under `dir` durable: on Linux one `syncfs(2)` of the file system holding it
/// (files, their data and the renames, in one journal commit); elsewhere an `fsync` of every file and
/// folder under it.
#[cfg(feature = "cli")]
pub fn sync_tree(dir: &Path) -> Result<()> {
    #[cfg(target_os = "linux")]
    {
        use std::os::fd::AsRawFd;
        let d = std::fs::File::open(dir).map_err(|e| Error::io(e).with_path(dir))?;
        // SAFETY: the descriptor is open for the duration of the call.
        if unsafe { libc::syncfs(d.as_raw_fd()) } == 0 {
            return Ok(());
        }
    }
    sync_each(dir)
}

#[cfg(feature = "cli")]
fn sync_each(dir: &Path) -> Result<()> {
    for e in std::fs::read_dir(dir).map_err(|e| Error::io(e).with_path(dir))? {
        let p = e.map_err(|e| Error::io(e).with_path(dir))?.path();
        let md = std::fs::symlink_metadata(&p).map_err(|e| Error::io(e).with_path(&p))?;
        if md.is_dir() {
            sync_each(&p)?;
        } else if md.is_file() {
            std::fs::File::open(&p).and_then(|f| f.sync_all()).map_err(|e| Error::io(e).with_path(&p))?;
        }
    }
    // Folders cannot be opened for syncing on every platform; the files' data is what matters most.
    let _ = std::fs::File::open(dir).and_then(|f| f.sync_all());
    Ok(())
}

/// [`write_atomic`] for bytes already in memory.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| w.write_all(bytes).map_err(Error::io))
}

/// A device, FIFO or socket: build the whole output first, then write it into the node (never
/// replace the node by a regular file).
fn write_direct<F>(path: &Path, target: &Path, md: &std::fs::Metadata, fill: F) -> Result<()>
where
    F: FnOnce(&mut dyn Write) -> Result<()>,
{
    if md.is_dir() {
        return Err(Error::new(ErrorKind::InvalidInput, "is a directory, not a file to write").with_path(path));
    }
    let mut buf = Vec::new();
    fill(&mut buf).map_err(|e| e.with_path(path))?;
    let mut f = std::fs::OpenOptions::new().write(true).open(target).map_err(|e| Error::io(e).with_path(path))?;
    f.write_all(&buf).and_then(|_| f.flush()).map_err(|e| Error::io(e).with_path(path))?;
    Ok(())
}

/// The temporary file, written through. For a durable write, the kernel is asked to start writing each
/// MiB to disk once it is written (Linux `sync_file_range`), so that the final `fsync` finds most of a
/// large output on disk already instead of writing all of it then.
struct Writeback {
    file: tempfile::NamedTempFile,
    durable: bool,
    /// Bytes written, and the end of the range whose writeback was started.
    written: u64,
    started: u64,
}

/// Bytes written between two starts of writeback.
const WRITEBACK_BYTES: u64 = 1 << 20;

impl Write for Writeback {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.file.write(buf)?;
        self.written += n as u64;
        if self.durable && self.written - self.started >= WRITEBACK_BYTES {
            start_writeback(self.file.as_file(), self.started, self.written - self.started);
            self.started = self.written;
        }
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

/// Start writing `len` bytes of `f` from `offset` to disk, without waiting (best effort: the `fsync`
/// that follows is what makes the file durable).
#[cfg(target_os = "linux")]
fn start_writeback(f: &std::fs::File, offset: u64, len: u64) {
    use std::os::fd::AsRawFd;
    let (Ok(offset), Ok(len)) = (i64::try_from(offset), i64::try_from(len)) else { return };
    // SAFETY: a hint on a descriptor this function borrows; it reads no memory of this process.
    let _ = unsafe { libc::sync_file_range(f.as_raw_fd(), offset, len, libc::SYNC_FILE_RANGE_WRITE) };
}

#[cfg(not(target_os = "linux"))]
fn start_writeback(_f: &std::fs::File, _offset: u64, _len: u64) {}

/// Remove `.NAME.XXXXXX.tmp` files in `dir` that no live writer holds (a writer locks its temporary
/// file for as long as it exists; a killed one leaves it unlocked).
fn remove_stale_temps(dir: &Path, name: &str) {
    let prefix = format!(".{name}.");
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for e in entries.flatten() {
        let file_name = e.file_name();
        let Some(n) = file_name.to_str() else { continue };
        let Some(mid) = n.strip_prefix(&prefix).and_then(|r| r.strip_suffix(".tmp")) else { continue };
        if mid.len() != 6 || !mid.bytes().all(|b| b.is_ascii_alphanumeric()) {
            continue;
        }
        if !e.file_type().is_ok_and(|t| t.is_file()) {
            continue;
        }
        let Ok(f) = std::fs::File::open(e.path()) else { continue };
        if try_lock_exclusive(&f) {
            let _ = std::fs::remove_file(e.path());
        }
    }
}

#[cfg(target_os = "linux")]
fn lock_exclusive(f: &std::fs::File) {
    use std::os::fd::AsRawFd;
    // SAFETY: flock on a descriptor this function borrows; the lock ends when the file is closed.
    let _ = unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) };
}

#[cfg(target_os = "linux")]
fn try_lock_exclusive(f: &std::fs::File) -> bool {
    use std::os::fd::AsRawFd;
    // SAFETY: as in lock_exclusive.
    unsafe { libc::flock(f.as_raw_fd(), libc::LOCK_EX | libc::LOCK_NB) == 0 }
}

#[cfg(not(target_os = "linux"))]
fn lock_exclusive(_f: &std::fs::File) {}

/// Without flock no temporary file can be told stale: none is removed.
#[cfg(not(target_os = "linux"))]
fn try_lock_exclusive(_f: &std::fs::File) -> bool {
    false
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    /// Outputs of several MiB, written in pieces of every size (so that writeback starts mid-write and
    /// at uneven offsets), arrive whole, durable or not.
    #[test]
    fn large_outputs_arrive_whole_through_the_writeback() {
        let d = tempfile::tempdir().unwrap();
        let data: Vec<u8> = (0..(5u64 << 20) + 12_345).map(|k| (k.wrapping_mul(2_654_435_761) >> 13) as u8).collect();
        for (durable, name) in [(true, "a.csv"), (false, "b.csv")] {
            let path = d.path().join(name);
            write_atomic_as(&path, durable, |w| {
                let (mut at, mut piece) = (0, 1);
                while at < data.len() {
                    let end = (at + piece).min(data.len());
                    w.write_all(&data[at..end])?;
                    at = end;
                    piece = piece * 7 % 1_000_003 + 1;
                }
                Ok(())
            })
            .unwrap();
            assert!(std::fs::read(&path).unwrap() == data, "{name}");
        }
    }

    #[test]
    fn symlinks_are_followed_stale_temps_removed_inputs_refused() {
        let d = tempfile::tempdir().unwrap();
        let real = d.path().join("real.json");
        std::fs::write(&real, "old").unwrap();
        let link = d.path().join("link.json");
        std::os::unix::fs::symlink("real.json", &link).unwrap();
        let stale = d.path().join(".real.json.AbC123.tmp");
        std::fs::write(&stale, "half").unwrap();
        // A temporary file a live writer holds is left alone.
        let held = d.path().join(".real.json.XyZ789.tmp");
        let held_file = std::fs::File::create(&held).unwrap();
        lock_exclusive(&held_file);
        write_bytes_atomic(&link, b"new").unwrap();
        assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink(), "the link stays a link");
        assert_eq!(std::fs::read_to_string(&real).unwrap(), "new");
        assert!(!stale.exists() && held.exists());
        drop(held_file);

        let input = d.path().join("scan.x3p");
        std::fs::write(&input, "scan").unwrap();
        protect_input(&input);
        let e = write_bytes_atomic(&input, b"json").unwrap_err();
        assert!(e.to_string().contains("refusing to overwrite"), "{e}");
        assert_eq!(std::fs::read_to_string(&input).unwrap(), "scan");

        // Another name of the input (a hard link) is refused while the input's name names the file; once
        // the input is replaced under its name, the old file is no longer an input: writing the link
        // (which could as well be a new file that reuses a deleted input's inode) is allowed.
        let alias = d.path().join("alias.x3p");
        std::fs::hard_link(&input, &alias).unwrap();
        assert!(write_bytes_atomic(&alias, b"json").unwrap_err().to_string().contains("is the input"));
        let newer = d.path().join("newer.x3p");
        std::fs::write(&newer, "scan 2").unwrap();
        std::fs::rename(&newer, &input).unwrap();
        write_bytes_atomic(&alias, b"json").unwrap();
        assert_eq!((std::fs::read_to_string(&alias).unwrap(), std::fs::read_to_string(&input).unwrap()), ("json".into(), "scan 2".into()));
        protect_input(&input);
        assert!(write_bytes_atomic(&input, b"json").is_err(), "the new file under the name, read again, is protected");

        // An input read through a name that later stops resolving (a folder on the way removed; a
        // relative name after the working directory changes) is still the same file: still refused.
        let via = d.path().join("via");
        std::fs::create_dir(&via).unwrap();
        let kept = d.path().join("kept.x3p");
        std::fs::write(&kept, "scan 3").unwrap();
        protect_input(&via.join("..").join("kept.x3p"));
        std::fs::remove_dir(&via).unwrap();
        assert!(write_bytes_atomic(&kept, b"json").unwrap_err().to_string().contains("refusing to overwrite"));
        assert_eq!(std::fs::read_to_string(&kept).unwrap(), "scan 3");

        // An output in a folder that does not exist fails before anything is made.
        let lost = d.path().join("no such folder").join("fit.json");
        let e = write_atomic(&lost, |_| panic!("nothing is written")).unwrap_err().to_string();
        assert!(e.contains("no such folder/fit.json") && e.contains("does not exist"), "{e}");

        // A replaced file keeps its mode.
        std::fs::set_permissions(&real, std::fs::Permissions::from_mode(0o640)).unwrap();
        write_bytes_atomic(&real, b"again").unwrap();
        assert_eq!(std::fs::metadata(&real).unwrap().permissions().mode() & 0o777, 0o640);

        // A FIFO is written into and stays a FIFO (as a device such as /dev/null would).
        let fifo = d.path().join("pipe");
        let c = std::ffi::CString::new(fifo.as_os_str().as_encoded_bytes()).unwrap();
        // SAFETY: mkfifo on a NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0);
        let reader = {
            let fifo = fifo.clone();
            std::thread::spawn(move || std::fs::read(fifo).unwrap())
        };
        write_bytes_atomic(&fifo, b"through").unwrap();
        assert_eq!(reader.join().unwrap(), b"through");
        assert!(std::os::unix::fs::FileTypeExt::is_fifo(&std::fs::metadata(&fifo).unwrap().file_type()));
    }
}
