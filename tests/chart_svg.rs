//! Every chart the commands write, read back from its SVG as a reader would see it: numbered
//! ticks on both axes, one colour-and-marker style per legend entry (no two alike), and every
//! series with at least one marker in the plot that no other series' marker covers.
//!
//! The charts: `bench`'s four (on `swap.glb`), `build-bench`'s (on a synthetic sphere), and the
//! default job's ray sweep (through the library, on a synthetic deforming sphere).

mod cli_util;
use cli_util::{animation, dynbvh, ok};
use dynbvh::engine::source::SineSphere;
use dynbvh::report::frame_bench::{Options, RaySpec};
use dynbvh::report::ray_sweep;

/// A marker: a closed outline drawn with a stroke (the filled marks, e.g. rebuilds, are
/// polygons without one and do not count).
#[derive(Clone, Debug)]
struct Marker {
    color: String,
    /// The outline relative to its box's centre: shape and size.
    shape: Vec<(i32, i32)>,
    centre: (f64, f64),
    radius: f64,
}

fn attr<'a>(tag: &'a str, name: &str) -> Option<&'a str> {
    let key = format!(" {name}=\"");
    let start = tag.find(&key)? + key.len();
    let end = tag[start..].find('"')? + start;
    Some(&tag[start..end])
}

fn is_number(s: &str) -> bool {
    let s = s.trim();
    let s = s.strip_suffix(['k', 'M']).unwrap_or(s);
    !s.is_empty() && s.parse::<f64>().is_ok()
}

struct Parsed {
    x_ticks: Vec<f64>,
    y_ticks: usize,
    markers: Vec<Marker>,
}

fn parse(svg: &str) -> Parsed {
    let mut x_ticks = Vec::new();
    let mut y_ticks = 0;
    let mut markers = Vec::new();
    let mut rest = svg;
    while let Some(i) = rest.find('<') {
        rest = &rest[i..];
        let end = rest.find('>').expect("unclosed tag");
        let tag = &rest[..=end];
        if tag.starts_with("<text") {
            let close = rest.find("</text>").expect("unclosed text");
            let content = &rest[end + 1..close];
            if is_number(content) {
                match (attr(tag, "text-anchor"), attr(tag, "dy")) {
                    (Some("end"), _) => y_ticks += 1,
                    (Some("middle"), Some("0.76em")) => {
                        x_ticks.push(attr(tag, "y").unwrap().parse().unwrap());
                    }
                    _ => {}
                }
            }
        } else if tag.starts_with("<polyline")
            && let (Some(color), Some(points)) = (attr(tag, "stroke"), attr(tag, "points"))
        {
            let pts: Vec<(i32, i32)> = points
                .split_whitespace()
                .map(|p| {
                    let (x, y) = p.split_once(',').unwrap();
                    (x.parse().unwrap(), y.parse().unwrap())
                })
                .collect();
            if pts.len() >= 4 && pts.first() == pts.last() {
                let (x0, x1) = (
                    pts.iter().map(|p| p.0).min().unwrap(),
                    pts.iter().map(|p| p.0).max().unwrap(),
                );
                let (y0, y1) = (
                    pts.iter().map(|p| p.1).min().unwrap(),
                    pts.iter().map(|p| p.1).max().unwrap(),
                );
                let centre = (f64::from(x0 + x1) / 2.0, f64::from(y0 + y1) / 2.0);
                markers.push(Marker {
                    color: color.to_string(),
                    shape: pts.iter().map(|p| (p.0 - x0, p.1 - y0)).collect(),
                    centre,
                    radius: f64::from((x1 - x0).max(y1 - y0)) / 2.0,
                });
            }
        }
        rest = &rest[end + 1..];
    }
    Parsed {
        x_ticks,
        y_ticks,
        markers,
    }
}

/// Checks one chart; `min_series` is how many legend entries it must have at least.
fn check(name: &str, svg: &str, min_series: usize) {
    if let Err(e) = verdict(&parse(svg), min_series) {
        panic!("{name}: {e}");
    }
}

/// What `check` decides, on parsed elements.
fn verdict(p: &Parsed, min_series: usize) -> Result<(), String> {
    if p.x_ticks.len() < 3 || p.y_ticks < 3 {
        return Err(format!(
            "{} x and {} y tick labels",
            p.x_ticks.len(),
            p.y_ticks
        ));
    }
    // The legend sits under the x tick labels; the plot above them.
    let axis_y = p.x_ticks.iter().copied().fold(f64::MIN, f64::max);
    let (legend, plot): (Vec<&Marker>, Vec<&Marker>) =
        p.markers.iter().partition(|m| m.centre.1 > axis_y);
    if legend.len() < min_series {
        return Err(format!("{} legend entries", legend.len()));
    }
    let style = |m: &Marker| (m.color.clone(), m.shape.clone());
    let styles: std::collections::HashSet<_> = legend.iter().map(|m| style(m)).collect();
    if styles.len() != legend.len() {
        return Err("two legend entries look alike".into());
    }
    for entry in &legend {
        let own: Vec<&&Marker> = plot.iter().filter(|m| style(m) == style(entry)).collect();
        if own.is_empty() {
            return Err(format!("series {} has no marker in the plot", entry.color));
        }
        let visible = own.iter().any(|m| {
            plot.iter().filter(|o| style(o) != style(m)).all(|o| {
                let d = (o.centre.0 - m.centre.0).hypot(o.centre.1 - m.centre.1);
                d >= 0.5 * (o.radius + m.radius)
            })
        });
        if !visible {
            return Err(format!(
                "every marker of series {} is covered by another series'",
                entry.color
            ));
        }
    }
    Ok(())
}

#[test]
fn bench_charts_read_at_a_glance() {
    let out = cli_util::tmp_dir("charts", "bench");
    let out_s = out.to_string_lossy().into_owned();
    let file = animation("swap.glb");
    let args = [
        "bench",
        &file,
        "--frames",
        "16",
        "--size",
        "32x32",
        "--repeats",
        "1",
        "--out",
        &out_s,
    ];
    ok(&dynbvh(&args));
    for (stem, series) in [
        ("sah_ratio", 6),
        ("frame_time", 6),
        ("speed_accuracy", 12),
        ("predicted_vs_measured", 6),
    ] {
        let svg = std::fs::read_to_string(out.join(format!("{stem}.svg"))).unwrap();
        check(stem, &svg, series);
        assert!(out.join(format!("{stem}.png")).exists(), "{stem}.png");
    }
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn build_bench_chart_reads_at_a_glance() {
    let out = cli_util::tmp_dir("charts", "build_bench");
    let out_s = out.to_string_lossy().into_owned();
    let args = [
        "build-bench",
        "--synthetic",
        "3000",
        "--runs",
        "1",
        "--ray-budget",
        "20000",
        "--no-wide",
        "--out",
        &out_s,
    ];
    ok(&dynbvh(&args));
    let svg = std::fs::read_to_string(out.join("build_bench.svg")).unwrap();
    check("build_bench", &svg, 5);
    assert!(out.join("build_bench.png").exists());
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn ray_sweep_chart_reads_at_a_glance() {
    let mut src = SineSphere::new(2000, 8, 0.3, 0.4);
    let opts = Options {
        trace_repeats: 1,
        ..Options::default()
    };
    let sweep = ray_sweep::run(
        &mut src,
        &opts,
        &[100, 1000, 10_000],
        RaySpec::Lidar,
        |_| {},
    );
    let svg = ray_sweep::chart(&sweep).svg(960, 540).unwrap();
    check("ray_sweep", &svg, 4);
}

/// The checker itself fails on what it must refuse: two series drawn alike, and a chart
/// without numbers on an axis.
#[test]
fn the_checker_refuses_lookalikes_and_bare_axes() {
    use dynbvh::report::charts::{Chart, Series};
    let line = |name: &str, dy: f64| Series {
        name: name.into(),
        points: (0..20)
            .map(|i| (f64::from(i), 1.0 + dy + f64::from(i) * 0.01))
            .collect(),
        line: true,
        marks: Vec::new(),
    };
    // Two coinciding lines: both stay visible.
    let chart = Chart {
        title: "t".into(),
        x_label: "x (s)".into(),
        y_label: "y (ms)".into(),
        series: vec![line("a", 0.0), line("b", 0.0), line("c", 0.5)],
        ..Chart::default()
    };
    let svg = chart.svg(640, 400).unwrap();
    check("coinciding", &svg, 3);
    let parsed = parse(&svg);
    let axis_y = parsed.x_ticks.iter().copied().fold(f64::MIN, f64::max);
    let colors: Vec<String> = parsed
        .markers
        .iter()
        .filter(|m| m.centre.1 > axis_y)
        .map(|m| m.color.clone())
        .collect();
    // The second series drawn as the first: refused.
    let mut alike = parse(&svg);
    let first = alike
        .markers
        .iter()
        .find(|m| m.color == colors[0])
        .unwrap()
        .clone();
    for m in alike.markers.iter_mut().filter(|m| m.color == colors[1]) {
        m.shape = first.shape.clone();
        m.color = first.color.clone();
    }
    assert!(
        verdict(&alike, 3).is_err(),
        "accepted two series drawn alike"
    );
    // The second series' markers each under one of the first's: refused.
    let mut covered = parse(&svg);
    let under: Vec<(f64, f64)> = covered
        .markers
        .iter()
        .filter(|m| m.color == colors[0] && m.centre.1 < axis_y)
        .map(|m| m.centre)
        .collect();
    for m in covered
        .markers
        .iter_mut()
        .filter(|m| m.color == colors[1] && m.centre.1 < axis_y)
    {
        m.centre = under[0];
    }
    assert!(
        verdict(&covered, 3).is_err(),
        "accepted a series hidden under another"
    );
    // Tick labels removed: refused.
    let bare: String = svg
        .split_inclusive('\n')
        .filter(|l| !is_number(l))
        .collect();
    assert!(
        verdict(&parse(&bare), 3).is_err(),
        "accepted an axis without numbers"
    );
}
