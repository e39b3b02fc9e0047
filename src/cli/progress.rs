//! A progress indicator for long reads of tiled scans (`ndf`, `fit`, `info` on a memory-mapped scan
//! above the tiling threshold): the heights read so far and the rate, on standard error when it is a
//! terminal (never in a pipe or a log). Passes over a tiled scan are not known in advance, so it is a
//! running count, not a bar with an end.

use std::io::IsTerminal;
use std::sync::OnceLock;

static BAR: OnceLock<indicatif::ProgressBar> = OnceLock::new();

/// Install the indicator (drawn only once a tiled band is read, and only on a terminal).
pub fn install() {
    if !std::io::stderr().is_terminal() {
        return;
    }
    ndfit::scan::set_tiled_progress(|bytes| {
        let bar = BAR.get_or_init(|| {
            let b = indicatif::ProgressBar::new_spinner();
            if let Ok(style) =
                indicatif::ProgressStyle::with_template("{spinner} tiled scan: {bytes} of heights read ({bytes_per_sec}), {elapsed}")
            {
                b.set_style(style);
            }
            b
        });
        bar.inc(bytes);
    });
}

/// Remove the indicator from the terminal (at the end of a command).
pub fn finish() {
    if let Some(b) = BAR.get() {
        b.finish_and_clear();
    }
}
