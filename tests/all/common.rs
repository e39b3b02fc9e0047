//! Helpers shared by the integration tests.

#![allow(dead_code)]

use std::path::PathBuf;

/// `../shared/data/scans` beside the repository, or `None` with a clear skip line on stderr.
pub fn shared_scans(test: &str) -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/scans");
    if dir.join("peer_readings.json").is_file() {
        Some(dir)
    } else {
        eprintln!("SKIP {test}: ../shared/data/scans is absent (real-scan checks need the shared folder beside the repo)");
        None
    }
}

/// Path of the built `ndfit` binary, for CLI tests.
pub fn ndfit_bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_ndfit"))
}
