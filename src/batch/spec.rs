//! One unit of batch work: a scan file, the key it is reported under, and its per-scan options.

use std::path::{Component, Path, PathBuf};

/// A scan to fit, as the walk or the manifest found it.
#[derive(Debug, Clone, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct ScanSpec {
    /// The key the scan is reported under (`path` in `summary.json`): the path relative to the batch
    /// root with `/` separators, or the manifest's `id`. Unique within a run; the summary is ordered by it.
    pub key: String,
    /// The file to read.
    pub file: PathBuf,
    /// Per-scan model override (manifest column `model`), else the run's `--model`.
    pub model: Option<String>,
    /// Per-scan command-line options (`--dx 1e-6 --z-scale 1e-9 ...`) as separate words, from the manifest.
    pub options: Vec<String>,
}

impl ScanSpec {
    /// A spec with no per-scan options.
    pub fn new(key: impl Into<String>, file: impl Into<PathBuf>) -> Self {
        ScanSpec { key: key.into(), file: file.into(), model: None, options: Vec::new() }
    }

    /// The relative path under an output folder where this scan's files go, derived from the key so that
    /// it never escapes the folder: `..`, root and prefix components become `_`.
    pub fn out_rel(&self) -> PathBuf {
        key_to_rel(&self.key)
    }
}

/// Turn a key into a relative path that stays inside the output folder.
pub fn key_to_rel(key: &str) -> PathBuf {
    let mut rel = PathBuf::new();
    for part in key.split(['/', '\\']) {
        match part {
            "" | "." => {}
            ".." => rel.push("_"),
            p => rel.push(p.replace(':', "_")),
        }
    }
    if rel.as_os_str().is_empty() {
        rel.push("_");
    }
    rel
}

/// The key of `file` below `root`: its relative path with `/` separators.
pub fn key_of(root: &Path, file: &Path) -> String {
    let rel = file.strip_prefix(root).unwrap_or(file);
    let parts: Vec<String> = rel
        .components()
        .filter_map(|c| match c {
            Component::Normal(s) => Some(s.to_string_lossy().into_owned()),
            Component::ParentDir => Some("..".to_string()),
            _ => None,
        })
        .collect();
    parts.join("/")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn out_rel_never_escapes() {
        assert_eq!(key_to_rel("a/b.x3p"), PathBuf::from("a/b.x3p"));
        assert_eq!(key_to_rel("../../x.x3p"), PathBuf::from("_/_/x.x3p"));
        assert_eq!(key_to_rel("/abs/x.x3p"), PathBuf::from("abs/x.x3p"));
        assert_eq!(key_to_rel(""), PathBuf::from("_"));
        assert!(key_to_rel("../..").components().all(|c| matches!(c, Component::Normal(_))));
    }

    #[test]
    fn key_is_relative_with_slashes() {
        assert_eq!(key_of(Path::new("/d"), Path::new("/d/sub/a.x3p")), "sub/a.x3p");
    }
}
