//! Peak resident memory of this process, per measured stage.
//!
//! Linux keeps the high-water mark of the resident set in `/proc/self/status` (`VmHWM`). Writing `5` to
//! `/proc/self/clear_refs` resets it to the current resident set (proc(5)), so the peak of one stage is
//! `VmHWM` read after the stage with the mark reset before it. Elsewhere both calls report `None`.

/// Reset the resident-set high-water mark to the current resident set. Returns whether it worked.
pub fn reset_peak() -> bool {
    std::fs::write("/proc/self/clear_refs", b"5").is_ok()
}

/// `VmHWM` (peak resident set since start or the last [`reset_peak`]) in bytes.
pub fn peak_rss() -> Option<u64> {
    status_kb("VmHWM:").map(|kb| kb * 1024)
}

/// `VmRSS` (current resident set) in bytes.
pub fn current_rss() -> Option<u64> {
    status_kb("VmRSS:").map(|kb| kb * 1024)
}

fn status_kb(key: &str) -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with(key))?;
    line[key.len()..].trim().trim_end_matches("kB").trim().parse().ok()
}

/// Peak memory of one closure: the rise of the high-water mark above the resident set at its start
/// (bytes), and the closure's value. `None` for the peak when `/proc` is unavailable.
pub fn measure_peak<T>(f: impl FnOnce() -> T) -> (T, Option<u64>) {
    let ok = reset_peak();
    let base = current_rss();
    let out = f();
    let peak = match (ok, base, peak_rss()) {
        (true, Some(b), Some(p)) => Some(p.saturating_sub(b)),
        _ => None,
    };
    (out, peak)
}
