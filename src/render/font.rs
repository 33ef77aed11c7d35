//! A 3x5 bitmap font (digits, capitals, a little punctuation) for labels drawn into frames,
//! with no font from the system.

use image::RgbImage;

/// Glyph rows, top first; bit 2 is the left column.
fn glyph(c: char) -> [u8; 5] {
    match c.to_ascii_uppercase() {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 3, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 2, 2],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        'A' => [2, 5, 7, 5, 5],
        'B' => [6, 5, 6, 5, 6],
        'C' => [3, 4, 4, 4, 3],
        'D' => [6, 5, 5, 5, 6],
        'E' => [7, 4, 6, 4, 7],
        'F' => [7, 4, 6, 4, 4],
        'G' => [3, 4, 5, 5, 3],
        'H' => [5, 5, 7, 5, 5],
        'I' => [7, 2, 2, 2, 7],
        'J' => [1, 1, 1, 5, 2],
        'K' => [5, 5, 6, 5, 5],
        'L' => [4, 4, 4, 4, 7],
        'M' => [5, 7, 7, 5, 5],
        'N' => [6, 5, 5, 5, 5],
        'O' => [2, 5, 5, 5, 2],
        'P' => [6, 5, 6, 4, 4],
        'Q' => [2, 5, 5, 6, 3],
        'R' => [6, 5, 6, 5, 5],
        'S' => [3, 4, 2, 1, 6],
        'T' => [7, 2, 2, 2, 2],
        'U' => [5, 5, 5, 5, 7],
        'V' => [5, 5, 5, 5, 2],
        'W' => [5, 5, 7, 7, 5],
        'X' => [5, 5, 2, 5, 5],
        'Y' => [5, 5, 2, 2, 2],
        'Z' => [7, 1, 2, 4, 7],
        '.' => [0, 0, 0, 0, 2],
        ',' => [0, 0, 0, 2, 4],
        ':' => [0, 2, 0, 2, 0],
        '+' => [0, 2, 7, 2, 0],
        '-' => [0, 0, 7, 0, 0],
        '=' => [0, 7, 0, 7, 0],
        '/' => [1, 1, 2, 4, 4],
        '%' => [5, 1, 2, 4, 5],
        '(' => [2, 4, 4, 4, 2],
        ')' => [2, 1, 1, 1, 2],
        '>' => [4, 2, 1, 2, 4],
        '<' => [1, 2, 4, 2, 1],
        '_' => [0, 0, 0, 0, 7],
        '*' => [0, 5, 2, 5, 0],
        '?' => [7, 1, 2, 0, 2],
        _ => [0; 5],
    }
}

/// Width in pixels of `text` drawn at `scale` (4 columns per character, the last one's gap
/// not counted).
#[must_use]
pub fn text_width(text: &str, scale: u32) -> u32 {
    let n = text.chars().count() as u32;
    (n * 4).saturating_sub(1) * scale
}

/// Height in pixels of a line at `scale`.
#[must_use]
pub fn text_height(scale: u32) -> u32 {
    5 * scale
}

/// Draws `text` with its top-left corner at `(x, y)`, `scale` pixels per font pixel, clipped
/// to the image.
pub fn draw_text(img: &mut RgbImage, x: i64, y: i64, scale: u32, text: &str, color: [u8; 3]) {
    let s = i64::from(scale.max(1));
    let (w, h) = (i64::from(img.width()), i64::from(img.height()));
    for (k, c) in text.chars().enumerate() {
        let gx = x + k as i64 * 4 * s;
        for (row, bits) in glyph(c).iter().enumerate() {
            for col in 0..3 {
                if bits & (4 >> col) == 0 {
                    continue;
                }
                let (px, py) = (gx + col * s, y + row as i64 * s);
                for yy in py.max(0)..(py + s).min(h) {
                    for xx in px.max(0)..(px + s).min(w) {
                        img.put_pixel(xx as u32, yy as u32, image::Rgb(color));
                    }
                }
            }
        }
    }
}

/// [`draw_text`] in `color` over a dark shadow one font pixel down and right, readable on
/// any background.
pub fn draw_label(img: &mut RgbImage, x: i64, y: i64, scale: u32, text: &str, color: [u8; 3]) {
    let s = i64::from(scale.max(1));
    draw_text(img, x + s.min(2), y + s.min(2), scale, text, [0, 0, 0]);
    draw_text(img, x, y, scale, text, color);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn digits_are_distinct() {
        let g: Vec<[u8; 5]> = "0123456789".chars().map(glyph).collect();
        for i in 0..g.len() {
            for j in i + 1..g.len() {
                assert_ne!(g[i], g[j], "{i} and {j} look alike");
            }
        }
    }

    #[test]
    fn draws_inside_the_box_only() {
        let mut img = RgbImage::new(20, 10);
        draw_text(&mut img, 1, 2, 1, "8", [255, 255, 255]);
        let lit: Vec<(u32, u32)> = img
            .enumerate_pixels()
            .filter(|p| p.2[0] > 0)
            .map(|p| (p.0, p.1))
            .collect();
        assert_eq!(lit.len(), 13);
        assert!(
            lit.iter()
                .all(|&(x, y)| (1..4).contains(&x) && (2..7).contains(&y))
        );
        // Clipped at the border without panicking.
        draw_text(&mut img, 18, 8, 3, "W", [255, 0, 0]);
        assert_eq!(text_width("AB", 2), 14);
    }
}
