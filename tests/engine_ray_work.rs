//! The ray-work measure: the same frames give the same modelled totals and schedules on every
//! run; the modelled oracle is the exact optimum of every refit-or-rebuild schedule the engine
//! can run (checked by running each one); the degradation a rebuild measures on the sampled
//! rays is the one a freshly built engine shows on the same rays; no policy falls below the
//! oracle.

mod common;

use dynbvh::anim::Scene;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::ray_work::SAMPLE_STRIDE;
use dynbvh::engine::source::FrameSource;
use dynbvh::engine::{CostMeasure, EngineConfig, Policy, Prices, Query, Timing};
use dynbvh::report::all_pairs;
use dynbvh::report::frame_bench::{self, Options, RaySpec};
use dynbvh::report::rays::camera_rays;
use std::path::PathBuf;

fn scene(file: &str) -> Scene {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("animations")
        .join(file);
    Scene::load(&path).unwrap().0
}

fn options(cost: CostMeasure) -> Options {
    Options {
        rays: RaySpec::Size(48, 48),
        builders: Vec::new(),
        tlas_compare: false,
        trace_repeats: 1,
        cost,
        prices: Prices::default(),
        ..Options::default()
    }
}

#[test]
fn two_runs_give_identical_modelled_totals_and_schedules() {
    for (file, cost) in [
        ("explode.glb", CostMeasure::Rays),
        ("swap.glb", CostMeasure::Sah),
        ("tube.glb", CostMeasure::Rays),
    ] {
        let s = scene(file);
        let run = || {
            let mut src = GltfSource::new(&s, Some(0), FrameTimes::Count(12)).unwrap();
            frame_bench::run(&mut src, &options(cost), |_| {})
        };
        let (a, b) = (run(), run());
        assert!(a.oracle_modelled.total_ms > 0.0);
        common::assert_same_modelled(&a, &b, file);
        for p in &a.policies {
            assert!(p.oracle_ratio_modelled >= 1.0 - 1e-9, "{file} {}", p.policy);
        }
        assert!(a.below_oracle.is_empty(), "{file}: {:?}", a.below_oracle);
    }
}

/// The modelled totals and schedules do not depend on the number of threads: a mesh large
/// enough for the builder's parallel partition (a generated swap of 40k triangles), run on one
/// thread and on two.
#[test]
fn the_modelled_totals_are_the_same_on_one_thread_and_on_two() {
    use dynbvh::anim::LoadOptions;
    use dynbvh::anim::generate::{Kind, generate};
    let g = generate(Kind::Swap, 40_000, 7);
    let (s, _) =
        Scene::from_slice("gen-swap.glb".as_ref(), &g.glb, &LoadOptions::default()).unwrap();
    let run = |threads: usize| {
        common::pool(threads).install(|| {
            let mut src = GltfSource::new(&s, Some(0), FrameTimes::Count(8)).unwrap();
            frame_bench::run(&mut src, &options(CostMeasure::Rays), |_| {})
        })
    };
    common::assert_same_modelled(&run(1), &run(2), "one thread and two");
}

/// Every schedule of a short clip run for real (each frame refit or rebuild, by switching the
/// engine's policy), its modelled cost counted on the same sampled rays: the oracle's total is
/// the least of them, and its schedule's.
#[test]
fn the_modelled_oracle_is_the_best_of_every_schedule_run() {
    let s = scene("explode.glb");
    let frames = 6;
    let prices = Prices::default();
    let config = EngineConfig {
        timing: Timing::Priced,
        prices,
        ..EngineConfig::default()
    };
    let mut src = GltfSource::new(&s, Some(0), FrameTimes::Count(frames)).unwrap();
    let rays = camera_rays(&src.build(0, config).bounds(), 40, 40);
    let m = src.deforming()[0];
    // The shared sample of each frame: every 3rd ray, entries from an always-refit engine.
    let sampled = common::shared_sample(&mut src, config, &rays, frames, 3.0);
    let pairs = all_pairs::measure(&mut src, config, &sampled, &prices, frames);
    let costs = &pairs.work[0];
    let best = costs.best();
    let mut least = f64::INFINITY;
    for mask in 0..1u32 << frames {
        let mut e = src.build(0, config);
        let tris = e.indices(m).len();
        let mut total = 0.0;
        let mut schedule = vec![true];
        for (f, frame) in sampled.iter().enumerate().skip(1) {
            let rebuild = mask >> (f - 1) & 1 == 1;
            schedule.push(rebuild);
            e.set_policy(if rebuild {
                Policy::Rebuild
            } else {
                Policy::Refit
            });
            src.advance(&mut e, f);
            e.update();
            total += if rebuild {
                prices.rebuild_ms(tris)
            } else {
                prices.refit_ms(tris)
            };
            total += frame.replay_ms(&e, m, &prices);
        }
        // The table's cost of this schedule is what running it cost.
        let table = costs.cost_of(&schedule);
        assert!(
            (table - total).abs() <= 1e-9 * total,
            "schedule {mask:b}: table {table} against the run's {total}"
        );
        least = least.min(total);
    }
    assert!(
        (best.cost_ms - least).abs() <= 1e-9 * least,
        "oracle {} against the best run {least}",
        best.cost_ms
    );
}

/// At each rebuild under the ray-work measure the engine replays the previous frame's sampled
/// rays on the replaced and the new tree: that ratio is the one an engine built at the replaced
/// tree's build frame and refitted since, and an engine built now, show on the same entries.
#[test]
fn a_rebuilds_measured_ratio_is_the_real_rebuilds() {
    let s = scene("explode.glb");
    let frames = 16;
    let config = |policy| EngineConfig {
        policy,
        cost: CostMeasure::Rays,
        timing: Timing::Priced,
        ..EngineConfig::default()
    };
    let mut src = GltfSource::new(&s, Some(0), FrameTimes::Count(frames)).unwrap();
    let rays = camera_rays(&src.build(0, config(Policy::Refit)).bounds(), 128, 128);
    let m = src.deforming()[0];
    let mut hits = vec![None; rays.len()];
    let mut e = src.build(0, config(Policy::Threshold(1.02)));
    let p = e.config().prices;
    let mut built = 0;
    let mut measured = 0;
    for f in 1..=frames {
        let entries = e.sampled_entries().to_vec();
        src.advance(&mut e, f);
        e.update();
        let st = *e.mesh_stats(m);
        if st.measured_work_ratio > 0.0 {
            let fresh = src.build(f, config(Policy::Refit));
            let mut old = src.build(built, config(Policy::Refit));
            for g in built + 1..=f {
                src.advance(&mut old, g);
                old.update();
            }
            let new = p.trace_ms(fresh.mesh_work_on(m, &entries));
            assert_eq!(
                p.trace_ms(e.mesh_work_on(m, &entries)).to_bits(),
                new.to_bits(),
                "frame {f}: the rebuilt tree is a fresh build's"
            );
            let want = p.trace_ms(old.mesh_work_on(m, &entries)) / new;
            assert!(
                (f64::from(st.measured_work_ratio) - want).abs() <= 1e-5 * want,
                "frame {f}: measured {} against {want}",
                st.measured_work_ratio
            );
            measured += 1;
        }
        if st.action == dynbvh::engine::Action::Rebuild {
            built = f;
        }
        e.trace_frame(&rays, &mut hits);
        // The engine's sample is one ray in SAMPLE_STRIDE of those cast.
        let w = e.work_estimate();
        assert_eq!(w.rays, rays.len() as u64);
        assert!(w.sampled.abs_diff(rays.len() as u64 / SAMPLE_STRIDE) <= 1);
    }
    assert!(
        measured > 0,
        "threshold:1.02 under the ray measure never rebuilt after a refit on explode"
    );
}

#[test]
fn sampling_in_the_trace_pass_takes_the_same_sample_as_tracing_again() {
    // The batch queries sample in their own parallel pass; `sample_rays` traces the sampled
    // rays again. On the same frames and rays both give the same hits, the same sampled work
    // per mesh and the same entries (as a set: the pass's order follows the threads).
    let s = scene("explode.glb");
    let config = EngineConfig {
        policy: Policy::Refit,
        cost: CostMeasure::Rays,
        timing: Timing::Priced,
        always_sample: true,
        ..EngineConfig::default()
    };
    let mut src = GltfSource::new(&s, Some(0), FrameTimes::Count(6)).unwrap();
    let mut in_pass = src.build(0, config);
    let mut again = src.build(0, config);
    let rays = camera_rays(&in_pass.bounds(), 80, 70);
    let (mut a, mut b) = (vec![None; rays.len()], vec![None; rays.len()]);
    let mut any_a = vec![false; rays.len()];
    for f in 1..=6 {
        for e in [&mut in_pass, &mut again] {
            src.advance(e, f);
            e.update();
        }
        // Two batches of uneven lengths: the sample runs on over the frame's calls.
        let (r1, r2) = rays.split_at(1000);
        let (a1, a2) = a.split_at_mut(1000);
        in_pass.trace_closest(r1, a1);
        in_pass.trace_closest(r2, a2);
        in_pass.trace_any(r1, &mut any_a[..1000]);
        again.closest_hit_batch(&rays, &mut b);
        again.sample_rays(r1, Query::Closest);
        again.sample_rays(r2, Query::Closest);
        again.sample_rays(r1, Query::Any);
        assert_eq!(a, b, "frame {f}: hits");
        for (x, r) in any_a[..1000].iter().zip(r1) {
            assert_eq!(*x, again.any_hit(r), "frame {f}: any hit");
        }
        assert_eq!(in_pass.work_estimate(), again.work_estimate(), "frame {f}");
        assert_eq!(in_pass.sampled_work(), again.sampled_work(), "frame {f}");
        assert_eq!(in_pass.sampled_top_work(), again.sampled_top_work());
        for &m in src.deforming() {
            assert_eq!(in_pass.sampled_mesh_work(m), again.sampled_mesh_work(m));
        }
        let key = |e: &dynbvh::engine::ray_work::SampleEntry| {
            (
                e.mesh.0,
                e.query == Query::Any,
                e.ray.origin().to_array().map(f32::to_bits),
                e.ray.dir().to_array().map(f32::to_bits),
                e.ray.tmax.to_bits(),
                e.work.nodes,
                e.work.prims,
            )
        };
        let mut ka: Vec<_> = in_pass.sampled_entries().iter().map(key).collect();
        let mut kb: Vec<_> = again.sampled_entries().iter().map(key).collect();
        ka.sort_unstable();
        kb.sort_unstable();
        assert!(!ka.is_empty(), "frame {f}: nothing sampled");
        assert_eq!(ka, kb, "frame {f}: entries");
    }
}

/// `cols` x `rows` parallel rays along +z from `z = -3`, over the square from -1 to 1 in x and y.
fn grid_rays(cols: usize, rows: usize) -> Vec<dynbvh::geom::Ray> {
    (0..cols * rows)
        .map(|i| {
            let x = (i % cols) as f32 / (cols as f32 / 2.0) - 1.0;
            let y = (i / cols) as f32 / (rows as f32 / 2.0) - 1.0;
            dynbvh::geom::Ray::new(dynbvh::glam::Vec3::new(x, y, -3.0), dynbvh::glam::Vec3::Z)
        })
        .collect()
}

#[test]
fn a_meshs_first_trace_is_sampled_and_later_unmoved_frames_are_not() {
    use dynbvh::geom::shapes;
    use dynbvh::glam::Affine3A;
    let mut e = dynbvh::engine::Engine::new(EngineConfig::default());
    let ball = shapes::icosphere(3);
    let m = e.add_mesh(ball.positions, ball.indices);
    e.add_instance(m, Affine3A::IDENTITY);
    e.update();
    let rays = grid_rays(64, 64);
    let mut hits = vec![None; rays.len()];
    // Nothing has moved, but the fresh tree's work is the measure's reference for the first
    // refits: the first trace is sampled.
    e.trace_closest(&rays, &mut hits);
    let first = e.sampled_mesh_work(m).nodes;
    assert!(first > 0, "first trace not sampled");
    // A second batch of the same frame joins the frame's sample.
    e.trace_closest(&rays, &mut hits);
    assert!(
        e.sampled_mesh_work(m).nodes > first,
        "the frame's second batch was not sampled"
    );
    // Later frames where nothing moved have nothing to weigh: not sampled.
    e.update();
    e.trace_closest(&rays, &mut hits);
    assert_eq!(
        e.sampled_mesh_work(m).nodes,
        0,
        "an unmoved frame was sampled"
    );
}

/// The fixed schedules never read the ray-work sample: their frames take none, unless the
/// configuration asks for it (as `bench` does, for its statistics).
#[test]
fn fixed_policies_take_no_sample_unless_asked() {
    use dynbvh::geom::shapes;
    use dynbvh::glam::Affine3A;
    let rays = grid_rays(64, 64);
    let mut hits = vec![None; rays.len()];
    for policy in [
        Policy::Refit,
        Policy::Rebuild,
        Policy::Periodic(2),
        Policy::DEFAULT,
    ] {
        for always_sample in [false, true] {
            let mut e = dynbvh::engine::Engine::new(EngineConfig {
                policy,
                always_sample,
                ..EngineConfig::default()
            });
            let ball = shapes::icosphere(3);
            let m = e.add_mesh(ball.positions, ball.indices);
            e.add_instance(m, Affine3A::IDENTITY);
            e.update();
            for frame in 1..=3 {
                for p in e.positions_mut(m) {
                    *p *= 1.01;
                }
                e.update();
                e.trace_closest(&rays, &mut hits);
                let sampled = e.sampled_mesh_work(m).nodes > 0;
                let wants = always_sample || policy == Policy::DEFAULT;
                // The default samples the frames its watch asks for: the first ones after a
                // build are among them.
                if wants {
                    assert!(
                        sampled || frame > 1,
                        "{policy:?}, frame {frame}: not sampled"
                    );
                } else {
                    assert!(!sampled, "{policy:?}, frame {frame}: sampled");
                    assert_eq!(e.frame_stats().sample_ms, 0.0, "{policy:?}");
                }
            }
        }
    }
}

/// A mesh whose tree is one leaf cannot degrade (its refit is the tree a rebuild makes): the
/// deciding policies only refit it, and a frame where only such meshes moved is not sampled;
/// with a deforming mesh of many leaves beside it, the frames that mesh's policy samples are
/// (never more than `MAX_SAMPLE_GAP` in a row without one).
#[test]
fn a_one_leaf_mesh_is_only_refitted_and_not_sampled() {
    use dynbvh::geom::shapes;
    use dynbvh::glam::{Affine3A, Vec3};
    let rays = grid_rays(63, 65);
    let mut hits = vec![None; rays.len()];
    // The triangle in the lower left of the rays' square, the ball in the upper right.
    let tri = |k: f32| {
        vec![
            Vec3::new(-1.0, -1.0, k),
            Vec3::new(-0.2, -1.0, -k),
            Vec3::new(-0.6, -0.2 + 0.1 * k, 0.0),
        ]
    };
    for with_ball in [false, true] {
        let mut e = dynbvh::engine::Engine::new(EngineConfig::default());
        let one = e.add_mesh(tri(0.0), vec![[0, 1, 2]]);
        e.add_instance(one, Affine3A::IDENTITY);
        let ball = with_ball.then(|| {
            let b = shapes::icosphere(3);
            let m = e.add_mesh(b.positions.clone(), b.indices);
            e.add_instance(
                m,
                Affine3A::from_scale_rotation_translation(
                    Vec3::splat(0.6),
                    dynbvh::glam::Quat::IDENTITY,
                    Vec3::new(0.35, 0.35, 0.0),
                ),
            );
            (m, b.positions)
        });
        e.update();
        e.trace_closest(&rays, &mut hits);
        // Frames in a row the ball went unsampled (its policy samples only the frames on which
        // a rebuild could become due: `engine::watch`).
        let mut unsampled = 0;
        for f in 1..24 {
            let k = f as f32 * 0.3;
            e.set_positions(one, &tri(k));
            if let Some((m, p)) = &ball {
                let moved: Vec<Vec3> = p.iter().map(|v| *v * (1.0 + 0.05 * k * v.x)).collect();
                e.set_positions(*m, &moved);
            }
            e.update();
            assert_eq!(
                e.mesh_stats(one).action,
                dynbvh::engine::Action::Refit,
                "frame {f}: the one-leaf mesh not refitted"
            );
            e.trace_closest(&rays, &mut hits);
            match ball {
                None => assert_eq!(
                    e.sampled_work().nodes,
                    0,
                    "frame {f}: only the one-leaf mesh moved, yet the frame was sampled"
                ),
                Some((m, _)) => {
                    if e.sampled_work().nodes == 0 {
                        unsampled += 1;
                        assert!(
                            unsampled <= dynbvh::engine::watch::MAX_SAMPLE_GAP,
                            "frame {f}: the deforming ball unsampled {unsampled} frames in a row"
                        );
                    } else {
                        unsampled = 0;
                        assert!(
                            e.sampled_mesh_work(m).nodes > 0,
                            "frame {f}: the frame sampled, the deforming ball not"
                        );
                    }
                }
            }
        }
    }
}

/// Each sampled closest-hit entry carries the triangle boxes its interval meets before its hit
/// in the mesh, counted in the sample's own walk: the brute-force count over every triangle,
/// on every frame of a clip, through the wide trees and the binary ones.
#[test]
fn a_sampled_entrys_box_count_is_the_brute_force_count() {
    use dynbvh::engine::Traversal;
    use dynbvh::geom::{RayTriPrecomp, intersect_triangle};
    let s = scene("explode.glb");
    let mut checked = 0;
    for traversal in [Traversal::DEFAULT, Traversal::Binary] {
        let config = EngineConfig {
            timing: Timing::Priced,
            traversal,
            ..EngineConfig::default()
        };
        let mut src = GltfSource::new(&s, Some(0), FrameTimes::Count(12)).unwrap();
        let rays = camera_rays(&src.build(0, config).bounds(), 64, 48);
        for f in [0, 4, 8, 12] {
            let e = src.build(f, config);
            let m = src.deforming()[0];
            let mut entries = Vec::new();
            e.trace_sampled(&rays, Query::Closest, 3, 0, &mut entries);
            let (pos, idx) = (e.positions(m), e.indices(m));
            let corners = |t: &[u32; 3]| t.map(|i| pos[i as usize]);
            for en in entries.iter().filter(|x| x.mesh == m) {
                let r = &en.ray;
                let pre = RayTriPrecomp::new(r.dir());
                let hit = idx
                    .iter()
                    .filter_map(|t| {
                        let [a, b, c] = corners(t);
                        intersect_triangle(r, &pre, a, b, c, r.tmax).map(|h| h.0)
                    })
                    .fold(r.tmax, f32::min);
                let boxes = idx
                    .iter()
                    .filter(|t| {
                        let [a, b, c] = corners(t);
                        r.hit_box(a.min(b).min(c), a.max(b).max(c), hit).is_some()
                    })
                    .count() as u32;
                assert_eq!(en.pierced, Some(boxes.min(64)), "frame {f} {traversal:?}");
                checked += usize::from(boxes > 0);
            }
        }
    }
    assert!(checked > 500, "{checked} entries met boxes");
}
