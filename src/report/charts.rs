//! Line and scatter charts written as SVG and as PNG, with no fonts from the system: the SVG
//! names a generic monospace family, and the PNG draws its text with a built-in 5x7 bitmap font.

use image::{Rgb, RgbImage};
use std::fmt::Write as _;

/// One data series.
#[derive(Clone, Debug, Default)]
pub struct Series {
    /// Legend name.
    pub name: String,
    /// Points in data coordinates.
    pub points: Vec<(f64, f64)>,
    /// Join the points with a line (else draw them as dots).
    pub line: bool,
    /// Points to highlight with a ring (e.g. rebuilds).
    pub marks: Vec<(f64, f64)>,
}

/// A chart: axes, series, legend.
#[derive(Clone, Debug, Default)]
pub struct Chart {
    /// Title above the plot.
    pub title: String,
    /// X axis label.
    pub x_label: String,
    /// Y axis label.
    pub y_label: String,
    /// The series.
    pub series: Vec<Series>,
    /// Logarithmic y axis.
    pub log_y: bool,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// Draw the line y = x (for predicted against measured).
    pub diagonal: bool,
    /// A note under the legend (e.g. what the rings mean).
    pub note: String,
}

const PALETTE: [[u8; 3]; 8] = [
    [31, 119, 180],
    [214, 39, 40],
    [44, 160, 44],
    [255, 127, 14],
    [148, 103, 189],
    [140, 86, 75],
    [227, 119, 194],
    [23, 190, 207],
];
const GREY: [u8; 3] = [200, 200, 200];
const DARK: [u8; 3] = [40, 40, 40];

/// Where text is anchored horizontally.
#[derive(Clone, Copy, PartialEq)]
enum Anchor {
    Start,
    Middle,
    End,
}

/// What both outputs can draw.
trait Painter {
    fn line(&mut self, a: (f64, f64), b: (f64, f64), c: [u8; 3], w: f64);
    fn dot(&mut self, p: (f64, f64), r: f64, c: [u8; 3], filled: bool);
    fn text(&mut self, p: (f64, f64), s: &str, c: [u8; 3], anchor: Anchor, vertical: bool);
}

/// Maps data to pixels.
struct Frame {
    x0: f64,
    x1: f64,
    y0: f64,
    y1: f64,
    left: f64,
    right: f64,
    top: f64,
    bottom: f64,
    log_x: bool,
    log_y: bool,
}

impl Frame {
    fn tx(&self, v: f64) -> f64 {
        self.left + (self.fx(v) - self.x0) / (self.x1 - self.x0) * (self.right - self.left)
    }
    fn ty(&self, v: f64) -> f64 {
        self.bottom - (self.fy(v) - self.y0) / (self.y1 - self.y0) * (self.bottom - self.top)
    }
    fn fx(&self, v: f64) -> f64 {
        if self.log_x { v.max(1e-12).log10() } else { v }
    }
    fn fy(&self, v: f64) -> f64 {
        if self.log_y { v.max(1e-12).log10() } else { v }
    }
}

/// About five round tick values covering `[lo, hi]`.
fn ticks(lo: f64, hi: f64) -> Vec<f64> {
    let span = (hi - lo).max(1e-12);
    let raw = span / 5.0;
    let mag = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 2.5, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw)
        .unwrap_or(10.0 * mag);
    let first = (lo / step).ceil() * step;
    (0..)
        .map(|k| first + k as f64 * step)
        .take_while(|v| *v <= hi + step * 1e-9)
        .take(20)
        .collect()
}

fn label(v: f64) -> String {
    let a = v.abs();
    if a == 0.0 {
        "0".into()
    } else if !(1e-3..1e5).contains(&a) {
        format!("{v:.0e}")
    } else if a >= 100.0 {
        format!("{v:.0}")
    } else if a >= 1.0 {
        let s = format!("{v:.2}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        let s = format!("{v:.4}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

impl Chart {
    fn range(&self) -> (f64, f64, f64, f64) {
        let pts = self
            .series
            .iter()
            .flat_map(|s| s.points.iter().chain(&s.marks))
            .filter(|p| p.0.is_finite() && p.1.is_finite())
            .filter(|p| (!self.log_x || p.0 > 0.0) && (!self.log_y || p.1 > 0.0));
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for &(x, y) in pts {
            let x = if self.log_x { x.log10() } else { x };
            let y = if self.log_y { y.log10() } else { y };
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if x0 > x1 {
            (x0, x1, y0, y1) = (0.0, 1.0, 0.0, 1.0);
        }
        if self.diagonal {
            let lo = x0.min(y0);
            let hi = x1.max(y1);
            (x0, x1, y0, y1) = (lo, hi, lo, hi);
        }
        if !self.log_y && y0 > 0.0 && y0 < 0.5 * y1 {
            y0 = 0.0;
        }
        let pad = |a: f64, b: f64| {
            let d = if b > a {
                (b - a) * 0.05
            } else {
                a.abs().max(1.0) * 0.1
            };
            (a - d, b + d)
        };
        let (x0, x1) = pad(x0, x1);
        let (y0, y1) = pad(y0, y1);
        (x0, x1, y0, y1)
    }

    fn draw(&self, p: &mut impl Painter, w: f64, h: f64) {
        let (x0, x1, y0, y1) = self.range();
        let f = Frame {
            x0,
            x1,
            y0,
            y1,
            left: 80.0,
            right: w - 190.0,
            top: 40.0,
            bottom: h - 50.0,
            log_x: self.log_x,
            log_y: self.log_y,
        };
        // Grid and tick labels.
        let tick_values = |lo: f64, hi: f64, log: bool| -> Vec<(f64, f64)> {
            if log {
                ticks(lo.floor(), hi.ceil())
                    .into_iter()
                    .filter(|v| v.fract() == 0.0 && *v >= lo && *v <= hi)
                    .map(|v| (v, 10f64.powf(v)))
                    .collect()
            } else {
                ticks(lo, hi).into_iter().map(|v| (v, v)).collect()
            }
        };
        for (pos, v) in tick_values(x0, x1, self.log_x) {
            let x = f.left + (pos - x0) / (x1 - x0) * (f.right - f.left);
            p.line((x, f.top), (x, f.bottom), GREY, 1.0);
            p.text((x, f.bottom + 18.0), &label(v), DARK, Anchor::Middle, false);
        }
        for (pos, v) in tick_values(y0, y1, self.log_y) {
            let y = f.bottom - (pos - y0) / (y1 - y0) * (f.bottom - f.top);
            p.line((f.left, y), (f.right, y), GREY, 1.0);
            p.text((f.left - 6.0, y + 4.0), &label(v), DARK, Anchor::End, false);
        }
        p.line((f.left, f.bottom), (f.right, f.bottom), DARK, 1.5);
        p.line((f.left, f.top), (f.left, f.bottom), DARK, 1.5);
        p.text((w / 2.0, 24.0), &self.title, DARK, Anchor::Middle, false);
        p.text(
            ((f.left + f.right) / 2.0, h - 12.0),
            &self.x_label,
            DARK,
            Anchor::Middle,
            false,
        );
        p.text(
            (18.0, (f.top + f.bottom) / 2.0),
            &self.y_label,
            DARK,
            Anchor::Middle,
            true,
        );
        if self.diagonal {
            let lo = x0.max(y0);
            let hi = x1.min(y1);
            let (lo, hi) = if self.log_x {
                (10f64.powf(lo), 10f64.powf(hi))
            } else {
                (lo, hi)
            };
            p.line((f.tx(lo), f.ty(lo)), (f.tx(hi), f.ty(hi)), GREY, 2.0);
        }
        let ok = |q: &(f64, f64)| {
            q.0.is_finite()
                && q.1.is_finite()
                && (!self.log_x || q.0 > 0.0)
                && (!self.log_y || q.1 > 0.0)
        };
        for (k, s) in self.series.iter().enumerate() {
            let c = PALETTE[k % PALETTE.len()];
            let pts: Vec<(f64, f64)> = s
                .points
                .iter()
                .filter(|q| ok(q))
                .map(|&(x, y)| (f.tx(x), f.ty(y)))
                .collect();
            if s.line {
                for pair in pts.windows(2) {
                    p.line(pair[0], pair[1], c, 2.0);
                }
            } else {
                for &q in &pts {
                    p.dot(q, 4.0, c, true);
                }
            }
            for &(x, y) in s.marks.iter().filter(|q| ok(q)) {
                p.dot((f.tx(x), f.ty(y)), 5.0, c, false);
            }
            // Legend.
            let ly = f.top + 10.0 + 20.0 * k as f64;
            let lx = f.right + 14.0;
            if s.line {
                p.line((lx, ly - 4.0), (lx + 18.0, ly - 4.0), c, 2.0);
            } else {
                p.dot((lx + 9.0, ly - 4.0), 4.0, c, true);
            }
            p.text((lx + 24.0, ly), &s.name, DARK, Anchor::Start, false);
        }
        if !self.note.is_empty() {
            let ly = f.top + 14.0 + 20.0 * self.series.len() as f64;
            p.text((f.right + 14.0, ly), &self.note, DARK, Anchor::Start, false);
        }
    }

    /// The chart as an SVG document of `w x h` pixels.
    #[must_use]
    pub fn svg(&self, w: u32, h: u32) -> String {
        let mut s = Svg(String::new());
        let _ = write!(
            s.0,
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" \
             viewBox=\"0 0 {w} {h}\" font-family=\"monospace\" font-size=\"12\">\n\
             <rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n"
        );
        self.draw(&mut s, f64::from(w), f64::from(h));
        s.0.push_str("</svg>\n");
        s.0
    }

    /// The chart as an image of `w x h` pixels.
    #[must_use]
    pub fn png(&self, w: u32, h: u32) -> RgbImage {
        let mut r = Raster(RgbImage::from_pixel(w, h, Rgb([255, 255, 255])));
        self.draw(&mut r, f64::from(w), f64::from(h));
        r.0
    }

    /// Writes `stem.svg` and `stem.png` of `w x h` pixels.
    pub fn save(&self, stem: &std::path::Path, w: u32, h: u32) -> std::io::Result<()> {
        std::fs::write(stem.with_extension("svg"), self.svg(w, h))?;
        self.png(w, h)
            .save(stem.with_extension("png"))
            .map_err(std::io::Error::other)
    }
}

struct Svg(String);

fn hex(c: [u8; 3]) -> String {
    format!("#{:02x}{:02x}{:02x}", c[0], c[1], c[2])
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
}

impl Painter for Svg {
    fn line(&mut self, a: (f64, f64), b: (f64, f64), c: [u8; 3], w: f64) {
        let _ = writeln!(
            self.0,
            "<line x1=\"{:.1}\" y1=\"{:.1}\" x2=\"{:.1}\" y2=\"{:.1}\" stroke=\"{}\" stroke-width=\"{w}\"/>",
            a.0,
            a.1,
            b.0,
            b.1,
            hex(c)
        );
    }
    fn dot(&mut self, p: (f64, f64), r: f64, c: [u8; 3], filled: bool) {
        let fill = if filled { hex(c) } else { "none".into() };
        let _ = writeln!(
            self.0,
            "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"{r}\" fill=\"{fill}\" stroke=\"{}\" stroke-width=\"1.5\"/>",
            p.0,
            p.1,
            hex(c)
        );
    }
    fn text(&mut self, p: (f64, f64), s: &str, c: [u8; 3], anchor: Anchor, vertical: bool) {
        let a = match anchor {
            Anchor::Start => "start",
            Anchor::Middle => "middle",
            Anchor::End => "end",
        };
        let rot = if vertical {
            format!(" transform=\"rotate(-90 {:.1} {:.1})\"", p.0, p.1)
        } else {
            String::new()
        };
        let _ = writeln!(
            self.0,
            "<text x=\"{:.1}\" y=\"{:.1}\" fill=\"{}\" text-anchor=\"{a}\"{rot}>{}</text>",
            p.0,
            p.1,
            hex(c),
            escape(s)
        );
    }
}

struct Raster(RgbImage);

impl Raster {
    fn put(&mut self, x: i64, y: i64, c: [u8; 3]) {
        if x >= 0 && y >= 0 && (x as u32) < self.0.width() && (y as u32) < self.0.height() {
            self.0.put_pixel(x as u32, y as u32, Rgb(c));
        }
    }
    fn disc(&mut self, p: (f64, f64), r: f64, c: [u8; 3]) {
        let ri = r.ceil() as i64;
        for dy in -ri..=ri {
            for dx in -ri..=ri {
                let (x, y) = (p.0.round() as i64 + dx, p.1.round() as i64 + dy);
                let (fx, fy) = (x as f64 - p.0, y as f64 - p.1);
                if fx * fx + fy * fy <= r * r + 0.25 {
                    self.put(x, y, c);
                }
            }
        }
    }
}

impl Painter for Raster {
    fn line(&mut self, a: (f64, f64), b: (f64, f64), c: [u8; 3], w: f64) {
        let len = ((b.0 - a.0).powi(2) + (b.1 - a.1).powi(2)).sqrt();
        let steps = (len * 2.0).ceil().max(1.0) as usize;
        for k in 0..=steps {
            let t = k as f64 / steps as f64;
            let p = (a.0 + (b.0 - a.0) * t, a.1 + (b.1 - a.1) * t);
            if w <= 1.0 {
                self.put(p.0.round() as i64, p.1.round() as i64, c);
            } else {
                self.disc(p, w / 2.0, c);
            }
        }
    }
    fn dot(&mut self, p: (f64, f64), r: f64, c: [u8; 3], filled: bool) {
        if filled {
            self.disc(p, r, c);
        } else {
            let steps = (r * 8.0) as usize;
            for k in 0..steps {
                let a = std::f64::consts::TAU * k as f64 / steps as f64;
                self.disc((p.0 + r * a.cos(), p.1 + r * a.sin()), 0.8, c);
            }
        }
    }
    fn text(&mut self, p: (f64, f64), s: &str, c: [u8; 3], anchor: Anchor, vertical: bool) {
        // 5x7 glyphs drawn 1:1 with one column of spacing; about 12 px per line.
        let width = 6.0 * s.chars().count() as f64;
        let shift = match anchor {
            Anchor::Start => 0.0,
            Anchor::Middle => width / 2.0,
            Anchor::End => width,
        };
        for (k, ch) in s.chars().enumerate() {
            let g = glyph(ch);
            for (row, bits) in g.iter().enumerate() {
                for col in 0..5 {
                    if bits >> (4 - col) & 1 == 1 {
                        let along = k as f64 * 6.0 + col as f64 - shift;
                        let across = row as f64 - 7.0;
                        let (x, y) = if vertical {
                            (p.0 + across, p.1 - along)
                        } else {
                            (p.0 + along, p.1 + across)
                        };
                        self.put(x.round() as i64, y.round() as i64, c);
                    }
                }
            }
        }
    }
}

/// A 5x7 glyph, one row per byte (bit 4 is the left column). Lower case is drawn as upper case.
fn glyph(c: char) -> [u8; 7] {
    match c.to_ascii_uppercase() {
        'A' => [0x0E, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'B' => [0x1E, 0x11, 0x11, 0x1E, 0x11, 0x11, 0x1E],
        'C' => [0x0E, 0x11, 0x10, 0x10, 0x10, 0x11, 0x0E],
        'D' => [0x1C, 0x12, 0x11, 0x11, 0x11, 0x12, 0x1C],
        'E' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x1F],
        'F' => [0x1F, 0x10, 0x10, 0x1E, 0x10, 0x10, 0x10],
        'G' => [0x0E, 0x11, 0x10, 0x17, 0x11, 0x11, 0x0F],
        'H' => [0x11, 0x11, 0x11, 0x1F, 0x11, 0x11, 0x11],
        'I' => [0x0E, 0x04, 0x04, 0x04, 0x04, 0x04, 0x0E],
        'J' => [0x07, 0x02, 0x02, 0x02, 0x02, 0x12, 0x0C],
        'K' => [0x11, 0x12, 0x14, 0x18, 0x14, 0x12, 0x11],
        'L' => [0x10, 0x10, 0x10, 0x10, 0x10, 0x10, 0x1F],
        'M' => [0x11, 0x1B, 0x15, 0x15, 0x11, 0x11, 0x11],
        'N' => [0x11, 0x11, 0x19, 0x15, 0x13, 0x11, 0x11],
        'O' => [0x0E, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'P' => [0x1E, 0x11, 0x11, 0x1E, 0x10, 0x10, 0x10],
        'Q' => [0x0E, 0x11, 0x11, 0x11, 0x15, 0x12, 0x0D],
        'R' => [0x1E, 0x11, 0x11, 0x1E, 0x14, 0x12, 0x11],
        'S' => [0x0F, 0x10, 0x10, 0x0E, 0x01, 0x01, 0x1E],
        'T' => [0x1F, 0x04, 0x04, 0x04, 0x04, 0x04, 0x04],
        'U' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x11, 0x0E],
        'V' => [0x11, 0x11, 0x11, 0x11, 0x11, 0x0A, 0x04],
        'W' => [0x11, 0x11, 0x11, 0x15, 0x15, 0x15, 0x0A],
        'X' => [0x11, 0x11, 0x0A, 0x04, 0x0A, 0x11, 0x11],
        'Y' => [0x11, 0x11, 0x11, 0x0A, 0x04, 0x04, 0x04],
        'Z' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x10, 0x1F],
        '0' => [0x0E, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0E],
        '1' => [0x04, 0x0C, 0x04, 0x04, 0x04, 0x04, 0x0E],
        '2' => [0x0E, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1F],
        '3' => [0x1F, 0x02, 0x04, 0x02, 0x01, 0x11, 0x0E],
        '4' => [0x02, 0x06, 0x0A, 0x12, 0x1F, 0x02, 0x02],
        '5' => [0x1F, 0x10, 0x1E, 0x01, 0x01, 0x11, 0x0E],
        '6' => [0x06, 0x08, 0x10, 0x1E, 0x11, 0x11, 0x0E],
        '7' => [0x1F, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0E, 0x11, 0x11, 0x0E, 0x11, 0x11, 0x0E],
        '9' => [0x0E, 0x11, 0x11, 0x0F, 0x01, 0x02, 0x0C],
        '.' => [0, 0, 0, 0, 0, 0x0C, 0x0C],
        ',' => [0, 0, 0, 0, 0x0C, 0x04, 0x08],
        ':' => [0, 0x0C, 0x0C, 0, 0x0C, 0x0C, 0],
        '-' => [0, 0, 0, 0x1F, 0, 0, 0],
        '+' => [0, 0x04, 0x04, 0x1F, 0x04, 0x04, 0],
        '/' => [0, 0x01, 0x02, 0x04, 0x08, 0x10, 0],
        '(' => [0x02, 0x04, 0x08, 0x08, 0x08, 0x04, 0x02],
        ')' => [0x08, 0x04, 0x02, 0x02, 0x02, 0x04, 0x08],
        '[' => [0x0E, 0x08, 0x08, 0x08, 0x08, 0x08, 0x0E],
        ']' => [0x0E, 0x02, 0x02, 0x02, 0x02, 0x02, 0x0E],
        '%' => [0x18, 0x19, 0x02, 0x04, 0x08, 0x13, 0x03],
        '*' => [0, 0x04, 0x15, 0x0E, 0x15, 0x04, 0],
        '=' => [0, 0, 0x1F, 0, 0x1F, 0, 0],
        '_' => [0, 0, 0, 0, 0, 0, 0x1F],
        '<' => [0x02, 0x04, 0x08, 0x10, 0x08, 0x04, 0x02],
        '>' => [0x08, 0x04, 0x02, 0x01, 0x02, 0x04, 0x08],
        '\'' => [0x04, 0x04, 0, 0, 0, 0, 0],
        ' ' => [0; 7],
        _ => [0x1F, 0x11, 0x11, 0x11, 0x11, 0x11, 0x1F],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn draws_both_formats() {
        let c = Chart {
            title: "SAH ratio".into(),
            x_label: "frame".into(),
            y_label: "ratio".into(),
            series: vec![Series {
                name: "refit".into(),
                points: (0..10)
                    .map(|i| (f64::from(i), 1.0 + f64::from(i) * 0.1))
                    .collect(),
                line: true,
                marks: vec![(3.0, 1.3)],
            }],
            ..Chart::default()
        };
        let svg = c.svg(640, 400);
        assert!(svg.starts_with("<svg") && svg.contains("refit") && svg.ends_with("</svg>\n"));
        let img = c.png(640, 400);
        assert!(img.pixels().any(|p| p.0 == PALETTE[0]));
        let t = ticks(0.0, 1.0);
        assert_eq!(t.len(), 6);
        assert!((t[5] - 1.0).abs() < 1e-9 && t[0] == 0.0);
    }
}
