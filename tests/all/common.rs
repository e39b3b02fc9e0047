//! Helpers shared by the integration tests.

#![allow(dead_code)]

use std::path::PathBuf;

/// Environment variable under which a test that needs `../shared` fails instead of skipping (`.ci/run` sets it).
pub const REQUIRE_SHARED: &str = "NDFIT_REQUIRE_SHARED";

/// `../shared/data/scans` beside the repository, or `None` when it is absent.
///
/// Every test that calls this is named `*_needs_shared`, so that a skip is visible where cargo shows it (the
/// test list; `cargo test needs_shared` runs just them) and not only on the captured stderr. With
/// `NDFIT_REQUIRE_SHARED` set to anything but empty or `0` an absent folder is a failure naming it.
pub fn shared_scans(test: &str) -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/data/scans");
    if dir.join("peer_readings.json").is_file() {
        return Some(dir);
    }
    let why = format!("{test}: {} is absent (no peer_readings.json there)", dir.display());
    if std::env::var(REQUIRE_SHARED).is_ok_and(|v| !v.is_empty() && v != "0") {
        panic!("{why}, and {REQUIRE_SHARED} is set: the real-scan checks must run");
    }
    eprintln!("SKIP {why}; set {REQUIRE_SHARED}=1 to make this a failure");
    None
}

/// Path of the built `ndfit` binary, for CLI tests.
pub fn ndfit_bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_ndfit"))
}
