//! Walking a folder for scans: recursively, in sorted order, by detected format.

use std::path::{Path, PathBuf};

use super::spec::{key_of, ScanSpec};
use crate::error::{Error, Result};

/// Extensions of the instrument and plain formats ndfit reads that are unambiguous scan files. Files
/// with other extensions are included only when their content is recognised (see [`walk`]).
pub const SCAN_EXTENSIONS: &[&str] = &["x3p", "plu", "apx", "sur", "opd", "al3d", "tmd", "gsf", "npy", "exr", "asc", "xyz", "dat"];

/// Whether `path` looks like a scan: a known scan extension, or content that `detect` recognises.
/// A file with a scan extension is kept even when its content is unreadable, so that a corrupt scan
/// becomes an `error` entry instead of silently vanishing from the batch.
pub fn is_scan(path: &Path, detect: &dyn Fn(&Path) -> bool) -> bool {
    let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    SCAN_EXTENSIONS.contains(&ext.as_str()) || detect(path)
}

/// Every scan below `root`, recursively, sorted by key. Hidden files and folders (leading `.`) and the
/// folders in `exclude` (e.g. the batch's own output folder) are skipped; symbolic links to folders are
/// not followed (no cycles). A subfolder that cannot be listed is returned as a spec of its own, which
/// fails as an `error` entry naming the folder. `detect` recognises scans by content for files without a scan extension.
pub fn walk(root: &Path, exclude: &[PathBuf], detect: &dyn Fn(&Path) -> bool) -> Result<Vec<ScanSpec>> {
    let meta = std::fs::metadata(root).map_err(|e| Error::io(e).with_path(root))?;
    if !meta.is_dir() {
        return Err(Error::invalid("not a folder").with_path(root));
    }
    let exclude: Vec<PathBuf> = exclude.iter().filter_map(|p| p.canonicalize().ok()).collect();
    let mut out = Vec::new();
    let mut stack = vec![root.to_path_buf()];
    while let Some(dir) = stack.pop() {
        if let Ok(c) = dir.canonicalize() {
            if exclude.contains(&c) {
                continue;
            }
        }
        let rd = match std::fs::read_dir(&dir) {
            Ok(rd) => rd,
            Err(e) if dir == root => return Err(Error::io(e).with_path(&dir)),
            // A subfolder that cannot be listed becomes an entry of its own (its read fails with the
            // reason), so the run goes on and reports it instead of aborting or losing it silently.
            Err(_) => {
                out.push(ScanSpec::new(key_of(root, &dir), dir.clone()));
                continue;
            }
        };
        for entry in rd {
            let entry = entry.map_err(|e| Error::io(e).with_path(&dir))?;
            let name = entry.file_name();
            if name.to_string_lossy().starts_with('.') {
                continue;
            }
            let path = entry.path();
            let ft = entry.file_type().map_err(|e| Error::io(e).with_path(&path))?;
            if ft.is_dir() {
                stack.push(path);
            } else if (ft.is_file() || (ft.is_symlink() && path.is_file())) && is_scan(&path, detect) {
                out.push(ScanSpec::new(key_of(root, &path), path));
            }
        }
    }
    out.sort_by(|a, b| a.key.cmp(&b.key));
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn walk_is_recursive_sorted_and_skips_hidden_and_excluded() {
        let d = tempfile::tempdir().expect("temp dir");
        let r = d.path();
        std::fs::create_dir_all(r.join("b/c")).unwrap();
        std::fs::create_dir_all(r.join(".hidden")).unwrap();
        std::fs::create_dir_all(r.join("out")).unwrap();
        for f in ["z.x3p", "b/a.plu", "b/c/m.sur", ".hidden/h.x3p", "out/o.x3p", "readme.md", "b/t.truth.json", "scan.png"] {
            std::fs::write(r.join(f), b"x").unwrap();
        }
        let found = walk(r, &[r.join("out")], &|p: &Path| p.extension().is_some_and(|e| e == "png")).unwrap();
        let keys: Vec<&str> = found.iter().map(|s| s.key.as_str()).collect();
        assert_eq!(keys, ["b/a.plu", "b/c/m.sur", "scan.png", "z.x3p"]);
    }

    #[test]
    fn walk_of_a_file_is_an_error_naming_it() {
        let d = tempfile::tempdir().unwrap();
        let f = d.path().join("f.x3p");
        std::fs::write(&f, b"x").unwrap();
        let e = walk(&f, &[], &|_: &Path| false).unwrap_err();
        assert!(e.to_string().contains("f.x3p"), "{e}");
    }
}
