//! The memory budget: how many bytes one command may plan to allocate for data a file declares.
//!
//! Every reader estimates, from its header and before allocating, what the whole pipeline will hold for
//! the grid it declares ([`check_points`]), and refuses a file beyond the budget with one line naming
//! what it declares and the budget, instead of letting an allocation abort the process. The default is
//! half of what the machine can give: the smaller of `MemAvailable` (`/proc/meminfo`) and the
//! address-space and data-segment limits (`RLIMIT_AS`, `RLIMIT_DATA`); `--max-memory` (the CLI) or
//! [`set_max_memory`] sets it. Limits and reasons per reader: `data_formats/limits.md`.

use std::sync::atomic::{AtomicU64, Ordering};

use crate::error::{Error, ErrorKind, Result};

/// Bytes the pipeline holds per grid point at its peak (heights, a working copy, normals and bin
/// indices), measured on `info`, `ndf` and `fit` of a 1024^2 scan with some margin.
pub const BYTES_PER_POINT: u64 = 48;

/// The budget set explicitly (0: not set, use [`default_budget`]).
static MAX: AtomicU64 = AtomicU64::new(0);

/// Set the budget in bytes for this process (`None`: back to the default).
pub fn set_max_memory(bytes: Option<u64>) {
    MAX.store(bytes.unwrap_or(0), Ordering::Relaxed);
}

/// The budget in bytes: the explicit one or [`default_budget`].
pub fn max_memory() -> u64 {
    match MAX.load(Ordering::Relaxed) {
        0 => default_budget(),
        b => b,
    }
}

/// Half of the smallest of available memory, `RLIMIT_AS` and `RLIMIT_DATA` (at least 64 MiB); where
/// none can be read, 4 GiB.
pub fn default_budget() -> u64 {
    let mut least = u64::MAX;
    if let Ok(text) = std::fs::read_to_string("/proc/meminfo") {
        if let Some(kb) = text
            .lines()
            .find_map(|l| l.strip_prefix("MemAvailable:"))
            .and_then(|r| r.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
        {
            least = least.min(kb.saturating_mul(1024));
        }
    }
    for limit in rlimits() {
        least = least.min(limit);
    }
    if least == u64::MAX {
        return 4 << 30;
    }
    (least / 2).max(64 << 20)
}

#[cfg(target_os = "linux")]
fn rlimits() -> Vec<u64> {
    let mut out = Vec::new();
    for res in [libc::RLIMIT_AS, libc::RLIMIT_DATA] {
        let mut r = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
        // SAFETY: getrlimit writes only into the struct it is given.
        if unsafe { libc::getrlimit(res, &mut r) } == 0 && r.rlim_cur != libc::RLIM_INFINITY {
            #[allow(clippy::unnecessary_cast)] // rlim_t is u32 on some targets
            out.push(r.rlim_cur as u64);
        }
    }
    out
}

#[cfg(not(target_os = "linux"))]
fn rlimits() -> Vec<u64> {
    Vec::new()
}

/// `bytes` in a short human form (`1.5 GiB`).
pub fn human(bytes: u64) -> String {
    const UNITS: [&str; 5] = ["B", "KiB", "MiB", "GiB", "TiB"];
    let mut v = bytes as f64;
    let mut u = 0;
    while v >= 1024.0 && u + 1 < UNITS.len() {
        v /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{bytes} B")
    } else {
        format!("{v:.1} {}", UNITS[u])
    }
}

/// Refuse a plan to hold `bytes` for `what` beyond the budget.
pub fn check_bytes(bytes: u64, what: &str) -> Result<()> {
    let max = max_memory();
    if bytes > max {
        return Err(Error::new(
            ErrorKind::TooLarge,
            format!("{what} needs about {} of memory, beyond the memory budget of {} (--max-memory)", human(bytes), human(max)),
        ));
    }
    Ok(())
}

/// Refuse a grid of `nx * ny` points whose processing would exceed the budget ([`BYTES_PER_POINT`]).
pub fn check_points(nx: usize, ny: usize, what: &str) -> Result<()> {
    let n = (nx as u64).saturating_mul(ny as u64);
    let max = max_memory();
    let need = n.saturating_mul(BYTES_PER_POINT);
    if need > max {
        return Err(Error::new(
            ErrorKind::TooLarge,
            format!(
                "{what} declares {nx} x {ny} points, about {} to process, beyond the memory budget of {} (--max-memory)",
                human(need),
                human(max)
            ),
        ));
    }
    Ok(())
}

/// A `Vec` with room for `n` elements, or an error naming `what` when the allocator refuses (the size
/// comes from data, so a failed allocation must not abort the process).
pub fn try_vec<T>(n: usize, what: &str) -> Result<Vec<T>> {
    let mut v = Vec::new();
    v.try_reserve_exact(n).map_err(|_| {
        Error::new(
            ErrorKind::TooLarge,
            format!("{what}: cannot allocate {}", human((n as u64).saturating_mul(std::mem::size_of::<T>() as u64))),
        )
    })?;
    Ok(v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn human_sizes_and_refusals() {
        assert_eq!(human(512), "512 B");
        assert_eq!(human(3 << 29), "1.5 GiB");
        // 2^14 x 2^13 points at 48 bytes each is 6 GiB: beyond a 4 GiB budget, within a 8 GiB one.
        let need = (1u64 << 27) * BYTES_PER_POINT;
        assert_eq!(need, 6 << 30);
        assert!(default_budget() >= 64 << 20);
        assert!(try_vec::<f64>(usize::MAX / 8, "x").is_err());
        assert_eq!(try_vec::<f64>(10, "x").unwrap().capacity(), 10);
    }
}
