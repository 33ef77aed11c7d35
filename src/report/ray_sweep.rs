//! "Refit or rebuild?" as a chart: one scene benchmarked at several ray counts a frame, each
//! policy's modelled time per frame against the rays per frame. Where always-refit's and
//! always-rebuild's lines cross is the answer for that scene; the default and the oracle are
//! drawn beside them.

use crate::engine::Policy;
use crate::engine::source::FrameSource;
use crate::report::charts::{Chart, Series};
use crate::report::frame_bench::{self, Options, RaySpec, Report};
use serde::Serialize;

/// One ray count of the sweep.
#[derive(Clone, Debug, Serialize)]
pub struct RayCountRow {
    /// Rays per frame.
    pub rays: usize,
    /// Modelled time per frame of always-refit, always-rebuild, the default and the oracle, ms.
    pub refit_ms: f64,
    /// See `refit_ms`.
    pub rebuild_ms: f64,
    /// See `refit_ms`.
    pub default_ms: f64,
    /// See `refit_ms`.
    pub oracle_ms: f64,
    /// The default's modelled total over the oracle's.
    pub default_ratio: f64,
    /// Rebuilds of the default and of the oracle.
    pub default_rebuilds: u64,
    /// See `default_rebuilds`.
    pub oracle_rebuilds: usize,
}

/// The whole sweep.
#[derive(Clone, Debug, Serialize)]
pub struct RaySweep {
    /// The scene.
    pub source: String,
    /// One row per ray count, in the order run.
    pub rows: Vec<RayCountRow>,
}

/// Runs `opts` (its policies replaced by always-refit, always-rebuild and the default) at each
/// of `counts` rays per frame, made by `spec` from a count.
pub fn run(
    src: &mut dyn FrameSource,
    opts: &Options,
    counts: &[usize],
    spec: impl Fn(usize) -> RaySpec,
    mut progress: impl FnMut(&str),
) -> RaySweep {
    let mut rows = Vec::new();
    let opts = Options {
        policies: vec![Policy::Refit, Policy::Rebuild, Policy::DEFAULT],
        oracle: true,
        builders: Vec::new(),
        tlas_compare: false,
        ..opts.clone()
    };
    for &n in counts {
        progress(&format!("{n} rays a frame"));
        let r = frame_bench::run(
            src,
            &Options {
                rays: spec(n),
                ..opts.clone()
            },
            |_| {},
        );
        rows.push(row(&r));
    }
    RaySweep {
        source: src.name(),
        rows,
    }
}

fn row(r: &Report) -> RayCountRow {
    let per_frame = |ms: f64| ms / r.frames.max(1) as f64;
    let find = |p: Policy| {
        r.policies
            .iter()
            .find(|s| s.policy == p.to_string())
            .expect("policy run")
    };
    let d = find(Policy::DEFAULT);
    RayCountRow {
        rays: r.rays_per_frame,
        refit_ms: per_frame(find(Policy::Refit).modelled_ms),
        rebuild_ms: per_frame(find(Policy::Rebuild).modelled_ms),
        default_ms: per_frame(d.modelled_ms),
        oracle_ms: per_frame(r.oracle_modelled.total_ms),
        default_ratio: d.oracle_ratio_modelled,
        default_rebuilds: d.rebuilds,
        oracle_rebuilds: r.oracle_modelled.rebuilds,
    }
}

/// The sweep as a table, with the cheaper endpoint at each count.
#[must_use]
pub fn table(s: &RaySweep) -> String {
    let mut t = format!(
        "{}: modelled time per frame (ms) against rays per frame\n{:>9} {:>10} {:>10} {:>10} \
         {:>10} {:>9} {:>9}  cheaper endpoint\n",
        s.source, "rays", "refit", "rebuild", "default", "oracle", "def/orc", "rebuilds"
    );
    for r in &s.rows {
        t.push_str(&format!(
            "{:>9} {:>10.3} {:>10.3} {:>10.3} {:>10.3} {:>9.4} {:>4}/{:<4}  {}\n",
            r.rays,
            r.refit_ms,
            r.rebuild_ms,
            r.default_ms,
            r.oracle_ms,
            r.default_ratio,
            r.default_rebuilds,
            r.oracle_rebuilds,
            if r.refit_ms <= r.rebuild_ms {
                "refit"
            } else {
                "rebuild"
            }
        ));
    }
    t
}

/// The chart: one line per policy and the oracle, both axes logarithmic.
#[must_use]
pub fn chart(s: &RaySweep) -> Chart {
    let line = |name: &str, f: &dyn Fn(&RayCountRow) -> f64| Series {
        name: name.into(),
        points: s.rows.iter().map(|r| (r.rays as f64, f(r))).collect(),
        line: true,
        marks: Vec::new(),
    };
    Chart {
        title: format!("refit or rebuild? {}", short(&s.source)),
        x_label: "rays per frame".into(),
        y_label: "modelled update + trace time per frame (ms)".into(),
        series: vec![
            line("always refit", &|r| r.refit_ms),
            line("always rebuild", &|r| r.rebuild_ms),
            line(&format!("default ({})", Policy::DEFAULT), &|r| r.default_ms),
            line("oracle", &|r| r.oracle_ms),
        ],
        log_x: true,
        log_y: true,
        note: "modelled: calibrated prices times counted work;  where refit and rebuild cross, the answer changes".into(),
        ..Chart::default()
    }
}

fn short(s: &str) -> String {
    std::path::Path::new(s.split(" [").next().unwrap_or(s))
        .file_name()
        .map_or_else(|| s.to_string(), |n| n.to_string_lossy().into_owned())
}
