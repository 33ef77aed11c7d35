//! Frame statistics: the pose time recorded before an update is the frame's, in the engine's
//! statistics and in the bench report's rows and CSV.

use dynbvh::engine::source::{FrameSource, SineSphere};
use dynbvh::engine::{Engine, EngineConfig, Policy};
use dynbvh::report::frame_bench::{self, Options, RaySpec};
use glam::{Affine3A, Vec3};

#[test]
fn pose_time_recorded_before_an_update_is_that_frames() {
    let mut e = Engine::new(EngineConfig::default());
    let m = e.add_mesh(vec![Vec3::ZERO, Vec3::X, Vec3::Y], vec![[0, 1, 2]]);
    e.add_instance(m, Affine3A::IDENTITY);
    e.update();
    e.positions_mut(m)[2] = Vec3::new(0.0, 1.0, 0.5);
    e.record_pose(1.5);
    e.record_pose(1.0);
    let s = *e.update();
    assert_eq!(s.pose_ms, 2.5);
    let sum = s.pose_ms + s.refit_ms + s.rebuild_ms + s.tlas_ms;
    assert!((s.update_ms - sum).abs() < 1e-9, "{s:?}");
    assert_eq!(e.frame_stats().pose_ms, 2.5);
    // Recording trace time keeps it.
    e.record_trace(3.0, 10);
    assert_eq!(e.frame_stats().pose_ms, 2.5);
    // The next frame has its own (none recorded: zero).
    e.positions_mut(m)[2] = Vec3::new(0.0, 1.0, 0.0);
    assert_eq!(e.update().pose_ms, 0.0);
}

#[test]
fn frame_sources_pose_time_reaches_the_bench_rows_and_csv() {
    let mut src = SineSphere::new(20_000, 3, 0.02, 0.15);
    // A source's own frame loop: advance records, update reports.
    let mut e = src.build(0, EngineConfig::default());
    src.advance(&mut e, 1);
    assert!(e.update().pose_ms > 0.0);

    let opts = Options {
        policies: vec![Policy::Refit, Policy::Amortized],
        rays: RaySpec::Count(256),
        trace_repeats: 1,
        counted_rays: 16,
        builders: Vec::new(),
        oracle: false,
        tlas_compare: false,
        ..Options::default()
    };
    let r = frame_bench::run(&mut src, &opts, |_| {});
    assert_eq!(r.per_frame.len(), 2 * 3);
    for row in &r.per_frame {
        assert!(row.pose_ms > 0.0, "{row:?}");
        assert!(row.update_ms >= row.pose_ms, "{row:?}");
    }
    let csv = frame_bench::to_csv(&r.per_frame);
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    let col = header.iter().position(|&h| h == "pose_ms").unwrap();
    for line in lines {
        let v: f64 = line.split(',').nth(col).unwrap().parse().unwrap();
        assert!(v > 0.0, "{line}");
    }
    let json = serde_json::to_value(&r).unwrap();
    assert!(json["per_frame"][0]["pose_ms"].as_f64().unwrap() > 0.0);
}
