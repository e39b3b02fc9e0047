//! Shared plotting setup: PNG output through plotters with an embedded font (no system fonts needed).

use std::sync::Once;

/// The font family name every plot uses.
pub const FONT: &str = "sans-serif";

/// Register the embedded DejaVu Sans font with plotters once per process, so plots render the same on
/// any machine, with no fontconfig.
pub fn ensure_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The bytes are 'static and a valid TTF, so registration cannot fail in practice; if it does,
        // plots still render without text rather than abort.
        let _ = plotters::style::register_font(FONT, plotters::style::FontStyle::Normal, dejavu::sans::regular());
    });
}

/// The range `lo..hi` of a plot axis, checked: plotters loops or panics on a non-finite or inverted
/// range, so those are an error naming `what`; an empty one (all values equal) is widened by `pad`.
pub fn axis(lo: f64, hi: f64, pad: f64, what: &str) -> crate::Result<std::ops::Range<f64>> {
    if !(lo.is_finite() && hi.is_finite() && (hi - lo).is_finite()) || lo > hi {
        return Err(crate::Error::invalid(format!("cannot plot: the {what} axis would span {lo:e} to {hi:e}")));
    }
    Ok(if hi > lo { lo..hi } else { (lo - pad)..(hi + pad) })
}
