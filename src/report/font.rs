//! The one font every chart and image label is drawn with: DejaVu Sans, embedded in the binary
//! (its licence is `assets/fonts/DejaVuSans-LICENSE.txt`), so no output depends on the fonts a
//! machine has. Registration with plotters happens here only, once, because plotters plans to
//! change that API.

use plotters::style::{FontFamily, FontStyle, register_font};
use std::sync::Once;

/// The family name the font is registered under; SVG output names it too, so a viewer without
/// the embedded font falls back to its own sans-serif.
const FAMILY: &str = "sans-serif";

static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans.ttf");

/// The embedded font's family, registered with plotters on first use.
#[must_use]
pub fn family() -> FontFamily<'static> {
    static REGISTER: Once = Once::new();
    REGISTER.call_once(|| {
        // The file ships with the crate and is checked by the tests: it parses.
        if register_font(FAMILY, FontStyle::Normal, FONT).is_err() {
            unreachable!("the embedded font does not parse");
        }
    });
    FontFamily::Name(FAMILY)
}
