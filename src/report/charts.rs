//! Line and scatter charts drawn with plotters, written as SVG and PNG with the embedded font
//! ([`super::font`]).
//!
//! Made to be read at a glance: every axis has numbered ticks (logarithmic axes get 2 and 5
//! between the powers of ten, or every integer multiple when the data spans less than a decade),
//! every series has its own colour, marker shape and dash, markers of coinciding series are
//! staggered along the line and moved aside where they would cover each other, and the legend
//! under the plot explains every symbol.

use image::RgbImage;
use plotters::coord::Shift;
use plotters::coord::ranged1d::ValueFormatter;
use plotters::coord::ranged1d::{KeyPointHint, KeyPointWeight, NoDefaultFormatting, Ranged};
use plotters::prelude::*;
use std::ops::Range;

/// One data series.
#[derive(Clone, Debug, Default)]
pub struct Series {
    /// Legend name.
    pub name: String,
    /// Points in data coordinates.
    pub points: Vec<(f64, f64)>,
    /// Join the points with a line (else draw them as markers only).
    pub line: bool,
    /// Points drawn as the series' marker filled (e.g. rebuilds); [`Chart::note`] says what
    /// they are.
    pub marks: Vec<(f64, f64)>,
}

/// A chart: axes, series, legend.
#[derive(Clone, Debug, Default)]
pub struct Chart {
    /// Title above the plot.
    pub title: String,
    /// X axis label, with its unit.
    pub x_label: String,
    /// Y axis label, with its unit.
    pub y_label: String,
    /// The series.
    pub series: Vec<Series>,
    /// Logarithmic y axis.
    pub log_y: bool,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// Draw the line y = x (for predicted against measured).
    pub diagonal: bool,
    /// A line under the legend: what the filled markers (and anything else) mean.
    pub note: String,
    /// The y axis spans at least this fraction of its largest value (0: fit the data), so
    /// that a spread of a few per mille does not fill the plot.
    pub min_rel_span: f64,
}

/// Colours told apart on white and from each other (no two alike in hue and lightness).
const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(214, 39, 40),
    RGBColor(44, 160, 44),
    RGBColor(255, 127, 14),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(23, 190, 207),
    RGBColor(188, 189, 34),
    RGBColor(60, 60, 60),
];
const GRID: RGBColor = RGBColor(225, 225, 225);
const DIAGONAL: RGBColor = RGBColor(150, 150, 150);

/// Marker shapes, each a closed outline (so a test can find them in the SVG).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Shape {
    Circle,
    Square,
    TriangleUp,
    Diamond,
    TriangleDown,
    Pentagon,
    Star,
    Hexagon,
}

const SHAPES: [Shape; 8] = [
    Shape::Circle,
    Shape::Square,
    Shape::TriangleUp,
    Shape::Diamond,
    Shape::TriangleDown,
    Shape::Pentagon,
    Shape::Star,
    Shape::Hexagon,
];

/// Dash patterns (dash, gap in pixels; 0 for a solid line).
const DASHES: [(i32, i32); 4] = [(0, 0), (9, 4), (3, 3), (14, 4)];

/// How series `k` is drawn.
#[derive(Clone, Copy, Debug)]
struct Style {
    color: RGBColor,
    shape: Shape,
    /// Marker radius in pixels.
    size: i32,
    dash: (i32, i32),
    width: u32,
}

fn style(k: usize) -> Style {
    Style {
        color: PALETTE[k % PALETTE.len()],
        shape: SHAPES[k % SHAPES.len()],
        // The same shape comes back larger, so no two series share shape and size.
        size: 5 + 2 * (k / SHAPES.len()) as i32,
        dash: DASHES[k % DASHES.len()],
        // Earlier lines are wider, so a later line on top of one leaves its edges showing.
        width: 3u32.saturating_sub(k as u32 / 2).max(1),
    }
}

/// The outline of `shape` of radius `r` around `(x, y)`, closed.
fn outline(shape: Shape, (x, y): (i32, i32), r: i32) -> Vec<(i32, i32)> {
    let polygon = |n: usize, phase: f64, radii: &[f64]| -> Vec<(i32, i32)> {
        let mut pts: Vec<(i32, i32)> = (0..n)
            .map(|i| {
                let a = phase + std::f64::consts::TAU * i as f64 / n as f64;
                let rr = f64::from(r) * radii[i % radii.len()];
                (
                    x + (rr * a.cos()).round() as i32,
                    y - (rr * a.sin()).round() as i32,
                )
            })
            .collect();
        pts.push(pts[0]);
        pts
    };
    use std::f64::consts::FRAC_PI_2;
    match shape {
        Shape::Circle => polygon(16, 0.0, &[1.0]),
        Shape::Square => polygon(4, FRAC_PI_2 / 2.0, &[1.2]),
        Shape::TriangleUp => polygon(3, FRAC_PI_2, &[1.25]),
        Shape::Diamond => polygon(4, 0.0, &[1.25]),
        Shape::TriangleDown => polygon(3, -FRAC_PI_2, &[1.25]),
        Shape::Pentagon => polygon(5, FRAC_PI_2, &[1.15]),
        Shape::Star => polygon(10, FRAC_PI_2, &[1.35, 0.55]),
        Shape::Hexagon => polygon(6, 0.0, &[1.1]),
    }
}

/// One axis: its range in data units, linear or logarithmic, with the ticks chosen here
/// (plotters' logarithmic key points leave a range within one decade without any).
#[derive(Clone, Debug)]
struct Axis {
    lo: f64,
    hi: f64,
    log: bool,
    ticks: Vec<f64>,
}

impl Axis {
    fn new(lo: f64, hi: f64, log: bool) -> Self {
        let ticks = if log {
            log_ticks(lo, hi)
        } else {
            linear_ticks(lo, hi)
        };
        Self { lo, hi, log, ticks }
    }

    fn unit(&self, v: f64) -> f64 {
        if self.log {
            (v.max(f64::MIN_POSITIVE).log10() - self.lo.log10())
                / (self.hi.log10() - self.lo.log10())
        } else {
            (v - self.lo) / (self.hi - self.lo)
        }
    }
}

impl Ranged for Axis {
    type FormatOption = NoDefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let u = self.unit(*value).clamp(-10.0, 10.0);
        limit.0 + (u * f64::from(limit.1 - limit.0)).round() as i32
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        match hint.weight() {
            KeyPointWeight::Bold => self.ticks.clone(),
            // No light grid lines: the bold ones carry the numbers.
            KeyPointWeight::Any => Vec::new(),
        }
    }

    fn range(&self) -> Range<f64> {
        self.lo..self.hi
    }
}

impl ValueFormatter<f64> for Axis {
    fn format_ext(&self, value: &f64) -> String {
        tick_label(*value, &self.ticks)
    }
}

/// Round values covering `[lo, hi]`: the coarsest step of 1, 2 or 5 times a power of ten
/// that still leaves at least four ticks (so a span just past a power of ten keeps its ticks).
fn linear_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let span = (hi - lo).max(f64::MIN_POSITIVE);
    let ticks = |step: f64| -> Vec<f64> {
        let first = (lo / step).ceil() * step;
        (0..)
            .map(|k| first + f64::from(k) * step)
            .take_while(|v| *v <= hi + step * 1e-9)
            .take(24)
            .map(|v| if v.abs() < step * 1e-9 { 0.0 } else { v })
            .collect()
    };
    let e = (span / 4.0).log10().floor() as i32;
    (e - 1..=e + 1)
        .rev()
        .flat_map(|e| [5.0, 2.0, 1.0].map(|m| m * 10f64.powi(e)))
        .map(ticks)
        // The finest step leaves at least 40 ticks (24 kept); none only for a NaN range.
        .find(|t| t.len() >= 4)
        .unwrap_or_default()
}

/// Ticks of a logarithmic axis: powers of ten, with 2 and 5 between them, or every integer
/// multiple when that leaves fewer than three, or linear ticks inside a narrow range.
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let (e0, e1) = (lo.log10().floor() as i32, hi.log10().ceil() as i32);
    let within = |mults: &[f64]| -> Vec<f64> {
        (e0..=e1)
            .flat_map(|e| mults.iter().map(move |m| m * 10f64.powi(e)))
            .filter(|v| *v >= lo * (1.0 - 1e-9) && *v <= hi * (1.0 + 1e-9))
            .collect()
    };
    let all = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0];
    for mults in [&[1.0][..], &[1.0, 2.0, 5.0], &all] {
        let t = within(mults);
        if t.len() >= 4 || (t.len() == 3 && mults.len() == 9) {
            // Wide ranges: keep at most about a dozen, the powers of ten always.
            if t.len() > 12 && mults.len() > 1 {
                continue;
            }
            return t;
        }
    }
    linear_ticks(lo, hi)
        .into_iter()
        .filter(|v| *v > 0.0)
        .collect()
}

/// A tick's number, with as many decimals as its neighbours need to differ.
fn tick_label(v: f64, ticks: &[f64]) -> String {
    let a = v.abs();
    if a == 0.0 {
        return "0".into();
    }
    if a >= 1e4 {
        let (d, suffix) = if a >= 1e6 { (1e6, "M") } else { (1e3, "k") };
        return format!("{}{suffix}", trim(format!("{:.2}", v / d)));
    }
    // The fewest decimals that print every tick exactly (ticks 0.025 apart need three).
    let gap = ticks
        .windows(2)
        .map(|w| (w[1] - w[0]).abs())
        .filter(|g| *g > 0.0)
        .fold(a, f64::min);
    let exact = |d: i32| {
        let k = 10f64.powi(d);
        let tolerance = 1e-3 * (gap * k).min(1.0);
        ticks
            .iter()
            .all(|t| ((t * k).round() - t * k).abs() <= tolerance)
    };
    let decimals = (0..=6).find(|d| exact(*d)).unwrap_or(6) as usize;
    trim(format!("{v:.decimals$}"))
}

fn trim(s: String) -> String {
    if s.contains('.') {
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    } else {
        s
    }
}

/// Legend entries per row and the legend's height for `n` series in `w` pixels.
fn legend_layout(n: usize, w: u32, note: bool) -> (usize, u32) {
    let per_row = ((w.saturating_sub(40)) / 230).max(1) as usize;
    let rows = n.div_ceil(per_row) as u32 + u32::from(note);
    (per_row, 14 + 20 * rows)
}

type DrawResult<E> = Result<(), DrawingAreaErrorKind<E>>;

impl Chart {
    fn usable(&self, p: &(f64, f64)) -> bool {
        p.0.is_finite()
            && p.1.is_finite()
            && (!self.log_x || p.0 > 0.0)
            && (!self.log_y || p.1 > 0.0)
    }

    /// The axes: the data's range padded by 5%, the y axis from 0 when the data is positive
    /// and reaches below half its maximum, never below 0 for data that is not.
    fn axes(&self) -> (Axis, Axis) {
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for &(x, y) in self
            .series
            .iter()
            .flat_map(|s| s.points.iter().chain(&s.marks))
            .filter(|p| self.usable(p))
        {
            x0 = x0.min(x);
            x1 = x1.max(x);
            y0 = y0.min(y);
            y1 = y1.max(y);
        }
        if x0 > x1 {
            (x0, x1, y0, y1) = if self.log_x || self.log_y {
                (1.0, 10.0, 1.0, 10.0)
            } else {
                (0.0, 1.0, 0.0, 1.0)
            };
        }
        if self.diagonal {
            let (lo, hi) = (x0.min(y0), x1.max(y1));
            (x0, x1, y0, y1) = (lo, hi, lo, hi);
        }
        let data_nonnegative = y0 >= 0.0;
        if !self.log_y && y0 > 0.0 && y0 < 0.5 * y1 {
            y0 = 0.0;
            if self.diagonal {
                x0 = 0.0;
            }
        }
        if self.min_rel_span > 0.0 && y1 - y0 < self.min_rel_span * y1.abs() {
            let mid = 0.5 * (y0 + y1);
            let half = 0.5 * self.min_rel_span * y1.abs();
            (y0, y1) = (mid - half, mid + half);
        }
        let pad = |a: f64, b: f64, log: bool, floor_zero: bool| -> (f64, f64) {
            if log {
                let (la, lb) = (a.log10(), b.log10());
                let d = if lb > la { (lb - la) * 0.05 } else { 0.3 };
                (10f64.powf(la - d), 10f64.powf(lb + d))
            } else {
                let d = if b > a {
                    (b - a) * 0.05
                } else {
                    a.abs().max(1.0) * 0.1
                };
                let lo = if floor_zero && a - d < 0.0 && a >= 0.0 {
                    0.0
                } else {
                    a - d
                };
                (lo, b + d)
            }
        };
        let (x0, x1) = pad(x0, x1, self.log_x, self.diagonal && data_nonnegative);
        let (y0, y1) = pad(y0, y1, self.log_y, data_nonnegative);
        (Axis::new(x0, x1, self.log_x), Axis::new(y0, y1, self.log_y))
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> DrawResult<DB::ErrorType> {
        let font = super::font::family();
        let (w, h) = root.dim_in_pixel();
        root.fill(&WHITE)?;
        let (per_row, legend_h) = legend_layout(self.series.len(), w, !self.note.is_empty());
        let (upper, lower) = root.split_vertically(h.saturating_sub(legend_h));
        let (xa, ya) = self.axes();
        let mut chart = ChartBuilder::on(&upper)
            .caption(&self.title, (font, 20))
            .margin_top(8)
            .margin_left(8)
            .margin_right(24)
            .x_label_area_size(46)
            .y_label_area_size(72)
            .build_cartesian_2d(xa, ya)?;
        chart
            .configure_mesh()
            .bold_line_style(GRID)
            .axis_style(BLACK.stroke_width(1))
            .label_style((font, 14))
            .axis_desc_style((font, 15))
            .x_desc(self.x_label.as_str())
            .y_desc(self.y_label.as_str())
            .draw()?;
        if self.diagonal {
            let r = chart.x_range();
            chart.draw_series(DashedLineSeries::new(
                [(r.start, r.start), (r.end, r.end)],
                6,
                4,
                DIAGONAL.stroke_width(2),
            ))?;
        }
        // Lines first (all of them), then markers, so no line runs over another's markers.
        let styles: Vec<Style> = (0..self.series.len()).map(style).collect();
        for (s, st) in self.series.iter().zip(&styles) {
            if !s.line {
                continue;
            }
            let pts: Vec<(f64, f64)> = s
                .points
                .iter()
                .copied()
                .filter(|p| self.usable(p))
                .collect();
            let line_style = st.color.stroke_width(st.width);
            if st.dash.0 == 0 {
                chart.draw_series(LineSeries::new(pts, line_style))?;
            } else {
                chart.draw_series(DashedLineSeries::new(pts, st.dash.0, st.dash.1, line_style))?;
            }
        }
        // Filled marks first (small, where they are), then the hollow markers that tell the
        // series apart, moved aside where they would cover one another.
        for (s, st) in self.series.iter().zip(&styles) {
            let small = Style {
                size: (st.size - 1).max(3),
                ..*st
            };
            for p in s.marks.iter().filter(|p| self.usable(p)) {
                draw_marker(&upper, &small, chart.backend_coord(p), true)?;
            }
        }
        let (xr, yr) = chart.plotting_area().get_pixel_range();
        let bounds = (xr.start, xr.end, yr.start, yr.end);
        let n = self.series.len().max(1);
        let mut placed: Vec<(i32, i32, i32)> = Vec::new();
        for (k, (s, st)) in self.series.iter().zip(&styles).enumerate() {
            let pts: Vec<(f64, f64)> = s
                .points
                .iter()
                .copied()
                .filter(|p| self.usable(p))
                .collect();
            // Lines carry about ten markers, staggered between series so that coinciding
            // lines show each other's; scatter series mark every point.
            let stride = if s.line {
                pts.len().div_ceil(10).max(1)
            } else {
                1
            };
            let phase = k * stride / n;
            for (_, p) in pts
                .iter()
                .enumerate()
                .filter(|(i, _)| i % stride == phase % stride)
            {
                let c = dodge(chart.backend_coord(p), st.size, bounds, &mut placed);
                draw_marker(&upper, st, c, false)?;
            }
        }
        // The legend, under the plot: each series' line and marker, then the note.
        for (k, (s, st)) in self.series.iter().zip(&styles).enumerate() {
            let (row, col) = ((k / per_row) as i32, (k % per_row) as i32);
            let x = 20 + col * 230;
            let y = 10 + row * 20;
            let seg = [(x, y), (x + 34, y)];
            if s.line {
                let line_style = st.color.stroke_width(st.width);
                if st.dash.0 == 0 {
                    lower.draw(&PathElement::new(seg.to_vec(), line_style))?;
                } else {
                    lower.draw(&plotters::element::DashedPathElement::new(
                        seg, st.dash.0, st.dash.1, line_style,
                    ))?;
                }
            }
            draw_marker(&lower, st, (x + 17, y), false)?;
            lower.draw(&Text::new(
                s.name.clone(),
                (x + 42, y - 8),
                (font, 14).into_font().color(&BLACK),
            ))?;
        }
        if !self.note.is_empty() {
            let rows = self.series.len().div_ceil(per_row) as i32;
            lower.draw(&Text::new(
                self.note.clone(),
                (20, 2 + rows * 20),
                (font, 14).into_font().color(&BLACK),
            ))?;
        }
        root.present()
    }

    /// The chart as an SVG document of `w x h` pixels.
    ///
    /// # Errors
    /// When plotters fails to lay out the chart (e.g. a size too small for its margins).
    pub fn svg(&self, w: u32, h: u32) -> std::io::Result<String> {
        let mut out = String::new();
        {
            let root = SVGBackend::with_string(&mut out, (w, h)).into_drawing_area();
            self.draw(&root)
                .map_err(|e| std::io::Error::other(e.to_string()))?;
        }
        Ok(out)
    }

    /// The chart as an image of `w x h` pixels.
    ///
    /// # Errors
    /// When plotters fails to lay out the chart (e.g. a size too small for its margins).
    pub fn png(&self, w: u32, h: u32) -> std::io::Result<RgbImage> {
        let mut buf = vec![0u8; w as usize * h as usize * 3];
        {
            let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
            self.draw(&root)
                .map_err(|e| std::io::Error::other(e.to_string()))?;
        }
        RgbImage::from_raw(w, h, buf).ok_or_else(|| std::io::Error::other("chart buffer size"))
    }

    /// Writes `stem.svg` and `stem.png` of `w x h` pixels.
    ///
    /// # Errors
    /// When a file cannot be written or the chart cannot be laid out.
    pub fn save(&self, stem: &std::path::Path, w: u32, h: u32) -> std::io::Result<()> {
        std::fs::write(stem.with_extension("svg"), self.svg(w, h)?)?;
        self.png(w, h)?
            .save(stem.with_extension("png"))
            .map_err(std::io::Error::other)
    }
}

/// Moves a marker of radius `r` to the nearest of a few spots beside `at` (inside `bounds`:
/// x0, x1, y0, y1) where it covers no marker placed before it, and records it; where every
/// spot is taken it stays at `at`.
fn dodge(
    at: (i32, i32),
    r: i32,
    (x0, x1, y0, y1): (i32, i32, i32, i32),
    placed: &mut Vec<(i32, i32, i32)>,
) -> (i32, i32) {
    let free = |(x, y): (i32, i32)| {
        x >= x0
            && x <= x1
            && y >= y0
            && y <= y1
            && placed.iter().all(|&(px, py, pr)| {
                ((px - x) as f32).hypot((py - y) as f32) >= (pr + r) as f32 * 0.8
            })
    };
    let d = 2 * r + 1;
    let spots = [
        (0, 0),
        (d, 0),
        (-d, 0),
        (0, -d),
        (0, d),
        (d, -d),
        (-d, -d),
        (d, d),
        (-d, d),
        (2 * d, 0),
        (-2 * d, 0),
        (0, -2 * d),
        (0, 2 * d),
    ];
    let c = spots
        .iter()
        .map(|&(dx, dy)| (at.0 + dx, at.1 + dy))
        .find(|&c| free(c))
        .unwrap_or(at);
    placed.push((c.0, c.1, r));
    c
}

fn draw_marker<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    st: &Style,
    at: (i32, i32),
    filled: bool,
) -> DrawResult<DB::ErrorType> {
    let pts = outline(st.shape, at, st.size);
    if filled {
        return area.draw(&Polygon::new(pts, st.color.filled()));
    }
    // White inside, so a marker stands out against lines under it.
    area.draw(&Polygon::new(pts.clone(), WHITE.filled()))?;
    area.draw(&PathElement::new(pts, st.color.stroke_width(2)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_ticks_inside_one_decade() {
        let t = log_ticks(2.6, 7.0);
        assert_eq!(t, vec![3.0, 4.0, 5.0, 6.0, 7.0]);
        let t = log_ticks(1e3, 1e6);
        assert_eq!(t.len(), 4);
        assert!(log_ticks(1.0, 100.0).contains(&2.0));
        let narrow = log_ticks(1.01, 1.09);
        assert!(narrow.len() >= 3, "{narrow:?}");
    }

    #[test]
    fn linear_ticks_round() {
        let t = linear_ticks(0.0, 1.0);
        assert_eq!(t.len(), 6);
        assert!((t[5] - 1.0).abs() < 1e-9 && t[0] == 0.0);
        assert_eq!(tick_label(0.2, &t), "0.2");
        assert_eq!(tick_label(20000.0, &[10000.0, 20000.0]), "20k");
        assert_eq!(tick_label(0.025, &[0.0, 0.025, 0.05]), "0.025");
    }

    /// Spans just past a power of ten (e.g. 0.0501) once gave two ticks.
    #[test]
    fn linear_ticks_never_fewer_than_four() {
        for lo in [0.0, 0.0883, 1.0, -3.7, 1234.5] {
            for k in 0..400 {
                let span = 10f64.powf(-4.0 + f64::from(k) * 0.02);
                let t = linear_ticks(lo, lo + span);
                assert!((4..=12).contains(&t.len()), "{lo} +{span}: {t:?}");
                let labels: std::collections::HashSet<_> =
                    t.iter().map(|v| tick_label(*v, &t)).collect();
                assert_eq!(labels.len(), t.len(), "{lo} +{span}: {t:?}");
            }
        }
    }

    #[test]
    fn styles_differ() {
        let pairs: std::collections::HashSet<_> = (0..40)
            .map(|k| {
                let s = style(k);
                (s.color.0, s.color.1, s.color.2, s.shape as u8, s.size)
            })
            .collect();
        assert_eq!(pairs.len(), 40);
    }

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
        let svg = c.svg(640, 400).unwrap();
        assert!(
            svg.starts_with("<svg") && svg.contains("refit") && svg.trim_end().ends_with("</svg>")
        );
        let img = c.png(640, 400).unwrap();
        let blue = PALETTE[0];
        assert!(img.pixels().any(|p| p.0 == [blue.0, blue.1, blue.2]));
        // Text is drawn: dark pixels in the title's band.
        assert!((0..640).any(|x| (0..30).any(|y| img.get_pixel(x, y).0[0] < 100)));
    }
}
