//! Labels drawn into frames (heat-map legends, policy and frame captions) with the embedded
//! font through plotters' bitmap backend, so no output depends on the machine's fonts.

use crate::report::font::family;
use image::RgbImage;
use plotters::prelude::*;

/// Font height in pixels at `scale` (1 for images up to 480 rows high).
fn px(scale: u32) -> f64 {
    f64::from(10 * scale.max(1))
}

/// Width in pixels of `text` drawn at `scale`.
#[must_use]
pub fn text_width(text: &str, scale: u32) -> u32 {
    (family(), px(scale))
        .into_font()
        .box_size(text)
        .map_or(0, |(w, _)| w)
}

/// Height in pixels of a line at `scale`.
#[must_use]
pub fn text_height(scale: u32) -> u32 {
    px(scale) as u32
}

/// Draws `text` with its top-left corner at `(x, y)`, clipped to the image.
pub fn draw_text(img: &mut RgbImage, x: i64, y: i64, scale: u32, text: &str, color: [u8; 3]) {
    let (w, h) = img.dimensions();
    let root = BitMapBackend::with_buffer(img, (w, h)).into_drawing_area();
    let style = (family(), px(scale))
        .into_font()
        .color(&RGBColor(color[0], color[1], color[2]));
    // Drawing text into a buffer of the right size only fails on a font error; a label is
    // not worth failing a render for.
    let at = (
        x.clamp(-1 << 20, 1 << 20) as i32,
        y.clamp(-1 << 20, 1 << 20) as i32,
    );
    let _ = root.draw(&Text::new(text, at, style));
    let _ = root.present();
}

/// [`draw_text`] in `color` over a dark shadow one pixel down and right, readable on any
/// background.
pub fn draw_label(img: &mut RgbImage, x: i64, y: i64, scale: u32, text: &str, color: [u8; 3]) {
    let s = i64::from(scale.clamp(1, 2));
    draw_text(img, x + s, y + s, scale, text, [0, 0, 0]);
    draw_text(img, x, y, scale, text, color);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_near_its_corner_only() {
        let mut img = RgbImage::new(200, 40);
        draw_text(&mut img, 10, 5, 1, "refit 8", [255, 255, 255]);
        let lit: Vec<(u32, u32)> = img
            .enumerate_pixels()
            .filter(|p| p.2[0] > 128)
            .map(|p| (p.0, p.1))
            .collect();
        assert!(lit.len() > 30, "{} pixels lit", lit.len());
        let w = text_width("refit 8", 1);
        assert!(w > 20 && w < 80, "width {w}");
        assert!(
            lit.iter()
                .all(|&(x, y)| (9..12 + w).contains(&x) && (4..20).contains(&y))
        );
        // Clipped at the border without panicking.
        draw_text(&mut img, 190, 35, 3, "W", [255, 0, 0]);
    }
}
