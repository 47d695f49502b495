//! The embedded font (DejaVu Sans), registered once: no system font library needed.

use std::sync::OnceLock;

use plotters::style::FontStyle;

/// Font family used everywhere (registered from the embedded DejaVu Sans).
pub(crate) const FONT: &str = "sans-serif";

pub(crate) static FONT_BYTES: &[u8] = include_bytes!("../../../assets/fonts/DejaVuSans.ttf");

/// Register the embedded font exactly once; later calls return the first outcome.
pub(crate) fn ensure_font() -> std::result::Result<(), String> {
    static REGISTERED: OnceLock<std::result::Result<(), String>> = OnceLock::new();
    REGISTERED
        .get_or_init(|| {
            plotters::style::register_font(FONT, FontStyle::Normal, FONT_BYTES)
                .map_err(|_| "embedded font DejaVuSans.ttf could not be parsed".to_string())
        })
        .clone()
}
