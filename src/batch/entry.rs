//! One scan's result: the record written to `OUT/scans/<key>.json` when the scan finishes (its
//! completion marker for `--resume`) and, without its resume data, the scan's entry in `summary.json`.

use serde::{Deserialize, Serialize};
use serde_json::Value;

use super::compare::Comparison;
use super::quality::Quality;

/// Whether the scan was fitted.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// Read and fitted; `fit` holds the result.
    Ok,
    /// Could not be read or fitted; `error` says why.
    Error,
}

/// A scan's entry in `summary.json` (see `data_formats/batch.md`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Entry {
    /// The scan's key: path relative to the batch root (`/` separated) or the manifest id.
    pub path: String,
    /// `ok` or `error`.
    pub status: Status,
    /// The fit result (`ndfit.fit/1`) when `status` is `ok`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit: Option<Value>,
    /// One line: what went wrong, when `status` is `error`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The coarse kind of the error (`ndfit::ErrorKind` in snake case, or `panic`, `crash`, `timeout`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error_kind: Option<String>,
    /// The batch's own scoring of the fit against the scan's empirical NDF.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub quality: Option<Quality>,
    /// The comparison against the baseline's entry for the same path, when a baseline was given.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub baseline: Option<Comparison>,
    /// The file that was read, as the batch found it.
    pub file: String,
    /// Wall time of this scan's job in seconds (varies between runs; not part of any comparison).
    pub time_s: f64,
    /// Data for `--resume` (kept in the per-scan record, dropped from `summary.json`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resume: Option<ResumeKey>,
}

/// What must be unchanged for a finished scan to be reused by `--resume`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct ResumeKey {
    /// Hash of the run's settings, the scan's options and its baseline entry (hex).
    pub job: String,
    /// Size of the scan file in bytes (`None` when it could not be read).
    pub size: Option<u64>,
    /// Modification time of the scan file, nanoseconds since the epoch.
    pub mtime_ns: Option<u128>,
}

impl Entry {
    /// Whether the scan regressed against its baseline.
    pub fn regressed(&self) -> bool {
        self.baseline.as_ref().is_some_and(|c| c.regressed)
    }
}

/// FNV-1a 64-bit: a hash that is stable across Rust versions and machines (unlike `DefaultHasher`),
/// for the resume keys stored on disk.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fnv_matches_reference_vectors() {
        // Published FNV-1a 64 test vectors (Fowler, Noll, Vo).
        assert_eq!(fnv1a64(b""), 0xcbf29ce484222325);
        assert_eq!(fnv1a64(b"a"), 0xaf63dc4c8601ec8c);
        assert_eq!(fnv1a64(b"foobar"), 0x85944171f73967e8);
    }

    #[test]
    fn entry_round_trips_and_omits_absent_fields() {
        let e = Entry {
            path: "a.x3p".into(),
            status: Status::Error,
            fit: None,
            error: Some("a.x3p: truncated".into()),
            error_kind: Some("corrupt".into()),
            quality: None,
            baseline: None,
            file: "/d/a.x3p".into(),
            time_s: 0.5,
            resume: None,
        };
        let v = serde_json::to_value(&e).unwrap();
        assert_eq!(v["status"], "error");
        assert!(v.get("fit").is_none() && v.get("resume").is_none());
        let back: Entry = serde_json::from_value(v).unwrap();
        assert_eq!(back, e);
    }
}
