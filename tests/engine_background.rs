//! Background rebuild (`Policy::Async`): builds run on the engine's worker while the old tree
//! is refitted, and the new tree is swapped in at the frame fixed when the build started, so
//! that two runs give the same schedule and the same modelled totals; a mesh replaced or
//! removed while its build runs does not receive the stale tree. (Every frame against brute
//! force: `tests/engine_hits.rs`, which runs every policy, this one included.)

mod common;

use dynbvh::anim::Scene;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::{Engine, EngineConfig, Policy, Prices, Timing, WorkerPriority};
use dynbvh::geom::Ray;
use dynbvh::report::frame_bench::{self, Options, RaySpec};
use glam::{Affine3A, Vec3};
use std::path::PathBuf;

fn scene(file: &str) -> Scene {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("animations")
        .join(file);
    Scene::load(&path).unwrap().0
}

#[test]
fn background_rebuilds_swap_at_fixed_frames_on_every_run() {
    let s = scene("explode.glb");
    let options = Options {
        policies: vec![Policy::Async, Policy::Amortized],
        rays: RaySpec::Size(64, 64),
        builders: Vec::new(),
        tlas_compare: false,
        trace_repeats: 1,
        prices: Prices::default(),
        ..Options::default()
    };
    let run = |worker| {
        let mut src = GltfSource::new(&s, Some(0), FrameTimes::Count(30)).unwrap();
        let o = Options {
            worker,
            ..options.clone()
        };
        frame_bench::run(&mut src, &o, |_| {})
    };
    // Twice, and with the worker in the idle class: the due frames are fixed when the builds
    // start, so neither the machine's load nor the worker's class moves the schedule.
    let (a, b) = (run(WorkerPriority::Normal), run(WorkerPriority::Normal));
    let c = run(WorkerPriority::Idle);
    common::assert_same_modelled(&a, &b, "a second run");
    common::assert_same_modelled(&a, &c, "the worker in the idle class");
    assert!(frame_bench::summary_table(&a).contains("worker ran at normal priority"));
    assert!(frame_bench::summary_table(&c).contains("worker ran at idle priority"));
    let json = serde_json::to_value(&c).unwrap();
    assert_eq!(json["worker_priority"], "idle");
    let asy = a.policies.iter().find(|p| p.policy == "async").unwrap();
    assert!(
        asy.rebuilds > 0,
        "the explosion must make the background rebuild"
    );
    let actions: Vec<&str> = a
        .per_frame
        .iter()
        .filter(|f| f.policy == "async")
        .map(|f| f.action.name())
        .collect();
    for (k, w) in actions.windows(2).enumerate() {
        if w[1] == "async-swap" {
            assert!(
                actions[..=k].contains(&"async-start"),
                "a swap with no start before it: {actions:?}"
            );
        }
    }
    assert!(
        actions.contains(&"async-start") && actions.contains(&"async-swap"),
        "{actions:?}"
    );
    // Beside other engines its frame times are not an application's: the table says so, and
    // not when it ran alone.
    let note = "async: the engines run in lockstep";
    assert!(frame_bench::summary_table(&a).contains(note));
    let alone = Options {
        policies: vec![Policy::Async],
        oracle: false,
        ..options.clone()
    };
    let mut src = GltfSource::new(&s, Some(0), FrameTimes::Count(30)).unwrap();
    let r = frame_bench::run(&mut src, &alone, |_| {});
    assert!(!frame_bench::summary_table(&r).contains(note));
    // The top-level tree comparison's engines run beside it too.
    let beside_tlas = Options {
        tlas_compare: true,
        ..alone
    };
    let mut src = GltfSource::new(&s, Some(0), FrameTimes::Count(10)).unwrap();
    let r = frame_bench::run(&mut src, &beside_tlas, |_| {});
    assert!(r.lockstep > 1);
    assert!(frame_bench::summary_table(&r).contains(note));
}

/// A grid of `n` x `n` quads in the z = 0 plane, scattered by `scatter` (0: flat).
fn grid(n: u32, scatter: f32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let mut p = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            let h = ((i * 7 + j * 13) % 11) as f32 * scatter;
            p.push(Vec3::new(i as f32 + h, j as f32 - h, h));
        }
    }
    let mut t = Vec::new();
    for j in 0..n {
        for i in 0..n {
            let a = j * (n + 1) + i;
            t.push([a, a + 1, a + n + 1]);
            t.push([a + 1, a + n + 2, a + n + 1]);
        }
    }
    (p, t)
}

#[test]
fn a_mesh_replaced_while_its_build_runs_keeps_its_new_tree() {
    let config = EngineConfig {
        policy: Policy::Async,
        timing: Timing::Priced,
        ..EngineConfig::default()
    };
    let mut e = Engine::new(config);
    let (p, t) = grid(60, 0.0);
    let m = e.add_mesh(p.clone(), t.clone());
    e.add_instance(m, Affine3A::IDENTITY);
    e.update();
    let rays: Vec<Ray> = (0..400)
        .map(|k| {
            let (x, y) = ((k % 20) as f32 * 3.0 + 0.5, (k / 20) as f32 * 3.0 + 0.25);
            Ray::new(Vec3::new(x, y, 50.0), Vec3::new(0.0, 0.0, -1.0))
        })
        .collect();
    // Deform hard and trace a lot until a background build starts.
    let mut started = false;
    for f in 1..40 {
        let (q, _) = grid(60, 0.3 * f as f32);
        e.set_positions(m, &q);
        let action = e.update().action;
        let mut out = vec![None; rays.len()];
        for _ in 0..20 {
            let _ = e.trace_frame(&rays, &mut out);
        }
        if action.name() == "async-start" {
            started = true;
            break;
        }
    }
    assert!(started, "no background build started");
    // Replace the mesh while the build may still run: the stale tree must not come back.
    let (p2, t2) = grid(30, 0.0);
    e.replace_mesh(m, p2.clone(), t2.clone()).unwrap();
    for _ in 0..5 {
        e.set_positions(m, &p2);
        e.update();
        let hit = e.closest_hit(&Ray::new(Vec3::new(10.25, 10.5, 5.0), Vec3::NEG_Z));
        let h = hit.expect("the replaced grid is hit");
        assert!((h.t - 5.0).abs() < 1e-4, "t {}", h.t);
        assert!((h.prim as usize) < t2.len());
    }
    // Removing it with its instance works too.
    e.remove_instance(dynbvh::engine::InstanceId(0)).unwrap();
    e.remove_mesh(m).unwrap();
    e.update();
}
