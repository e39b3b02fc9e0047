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
