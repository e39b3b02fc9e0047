//! The manifest CSV: an explicit list of scans with per-scan options, instead of a folder walk.
//!
//! Layout (documented in `data_formats/batch.md`): a header row, then one row per scan; `#` starts a
//! comment line.
//! - `path` (required): the scan file, relative to the manifest's folder unless absolute;
//! - `id` (optional): the key the scan is reported under (default: `path` as written);
//! - `model` (optional): a per-scan model, overriding `--model`;
//! - `options` (optional): further command-line options of `ndfit fit` for this scan, space separated;
//! - any other column `name` becomes the option `--name VALUE` (`_` read as `-`; an empty cell gives no
//!   option; `true` gives the bare flag `--name`, `false` nothing), e.g. columns `dx`, `z_scale`, `form`.
//!
//! Options are checked by the caller (the CLI parses them with the same parser as `ndfit fit`).

use std::collections::BTreeSet;
use std::path::Path;

use super::spec::ScanSpec;
use crate::error::{Error, ErrorKind, Result};

/// Columns with a fixed meaning; every other column is an option.
const FIXED: &[&str] = &["path", "id", "model", "options"];

/// Read a manifest. Errors (missing `path` column, duplicate keys, malformed CSV) name the file and the
/// line. Scan files are not opened here: a missing scan becomes that scan's `error` entry.
pub fn read_manifest(path: &Path) -> Result<Vec<ScanSpec>> {
    let base = path.parent().unwrap_or(Path::new("."));
    let mut rdr = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .trim(csv::Trim::All)
        .flexible(false)
        .from_path(path)
        .map_err(|e| csv_err(e).with_path(path))?;
    let header: Vec<String> = rdr.headers().map_err(|e| csv_err(e).with_path(path))?.iter().map(|h| h.to_string()).collect();
    let col = |name: &str| header.iter().position(|h| h == name);
    let path_col = col("path").ok_or_else(|| Error::corrupt("manifest has no 'path' column").with_path(path))?;
    let (id_col, model_col, opt_col) = (col("id"), col("model"), col("options"));
    let option_cols: Vec<(usize, String)> = header
        .iter()
        .enumerate()
        .filter(|(_, h)| !FIXED.contains(&h.as_str()))
        .map(|(i, h)| (i, format!("--{}", h.replace('_', "-"))))
        .collect();
    if let Some((_, bad)) = option_cols.iter().find(|(_, h)| h.len() <= 2 || h.contains(' ')) {
        return Err(Error::corrupt(format!("manifest column '{bad}' is not an option name")).with_path(path));
    }

    let mut specs = Vec::new();
    let mut seen = BTreeSet::new();
    for rec in rdr.records() {
        let rec = rec.map_err(|e| csv_err(e).with_path(path))?;
        let line = rec.position().map(|p| p.line()).unwrap_or(0);
        let cell = |i: Option<usize>| i.and_then(|i| rec.get(i)).filter(|s| !s.is_empty());
        let Some(p) = cell(Some(path_col)) else {
            if rec.iter().all(|s| s.is_empty()) {
                continue;
            }
            return Err(Error::corrupt(format!("line {line}: empty 'path'")).with_path(path));
        };
        let key = cell(id_col).unwrap_or(p).to_string();
        if !seen.insert(key.clone()) {
            return Err(Error::new(
                ErrorKind::InvalidInput,
                format!("line {line}: scan '{key}' is listed twice (give each row a distinct 'id')"),
            )
            .with_path(path));
        }
        let mut options = Vec::new();
        for (i, flag) in &option_cols {
            match rec.get(*i).unwrap_or("") {
                "" | "false" => {}
                "true" => options.push(flag.clone()),
                v => {
                    options.push(flag.clone());
                    options.push(v.to_string());
                }
            }
        }
        if let Some(o) = cell(opt_col) {
            options.extend(o.split_whitespace().map(str::to_string));
        }
        let file = if Path::new(p).is_absolute() { Path::new(p).to_path_buf() } else { base.join(p) };
        specs.push(ScanSpec { key, file, model: cell(model_col).map(str::to_string), options });
    }
    specs.sort_by(|a, b| a.key.cmp(&b.key));
    Ok(specs)
}

fn csv_err(e: csv::Error) -> Error {
    let line = e.position().map(|p| format!("line {}: ", p.line())).unwrap_or_default();
    Error::corrupt(format!("{line}malformed manifest CSV: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, text: &str) -> std::path::PathBuf {
        let p = dir.join("m.csv");
        std::fs::write(&p, text).unwrap();
        p
    }

    #[test]
    fn columns_become_options_and_paths_are_relative_to_the_manifest() {
        let d = tempfile::tempdir().unwrap();
        let m = write(
            d.path(),
            "# a comment\npath,id,dx,z_scale,model,options,flip\nb.raw,,1e-6,,ggx,--form plane,true\n\
             /abs/a.x3p,first,,2e-9,,,false\n",
        );
        let s = read_manifest(&m).unwrap();
        assert_eq!(s.len(), 2);
        // Sorted by key: "b.raw" < "first".
        assert_eq!(s[0].key, "b.raw");
        assert_eq!(s[0].file, d.path().join("b.raw"));
        assert_eq!(s[0].model.as_deref(), Some("ggx"));
        assert_eq!(s[0].options, ["--dx", "1e-6", "--flip", "--form", "plane"]);
        assert_eq!(s[1].key, "first");
        assert_eq!(s[1].file, Path::new("/abs/a.x3p"));
        assert_eq!(s[1].options, ["--z-scale", "2e-9"]);
    }

    #[test]
    fn bad_manifests_name_the_file_and_line() {
        let d = tempfile::tempdir().unwrap();
        let e = read_manifest(&write(d.path(), "file\na.x3p\n")).unwrap_err();
        assert!(e.to_string().contains("m.csv") && e.to_string().contains("'path'"), "{e}");
        let e = read_manifest(&write(d.path(), "path\na.x3p\na.x3p\n")).unwrap_err();
        assert!(e.to_string().contains("line 3") && e.to_string().contains("twice"), "{e}");
        let e = read_manifest(&write(d.path(), "path,dx\na.x3p,1,2\n")).unwrap_err();
        assert!(e.to_string().contains("malformed"), "{e}");
        let e = read_manifest(&d.path().join("none.csv")).unwrap_err();
        assert!(e.to_string().contains("none.csv"), "{e}");
    }
}
