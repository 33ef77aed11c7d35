//! The engine's batches reorder large incoherent batches before tracing them: on every frame of
//! the shipped animations (deforming, rigid and shared meshes), each ray's answer from the
//! batch queries, reordered or not, sampled pass or plain, large or small (split over the
//! pool or answered on the calling thread), is bit for bit the one its own query gives.

use dynbvh::anim::Scene;
use dynbvh::bvh::ray_order::RayOrder;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::source::FrameSource;
use dynbvh::engine::{Engine, EngineConfig, SceneHit};
use dynbvh::geom::Ray;
use dynbvh::report::rays::{camera_rays, random_rays};

fn bits(h: Option<SceneHit>) -> Option<(u32, u32, u32, u32, u32)> {
    h.map(|h| {
        (
            h.t.to_bits(),
            h.u.to_bits(),
            h.v.to_bits(),
            h.prim,
            h.instance.0,
        )
    })
}

/// The batch queries of the closest hit: the plain one, the frame pass (sampled on the frames
/// the policy wants a sample of, plain and reordered on the others), and the packets' pass
/// (single rays in the planned order for a scattered batch).
type Closest = fn(&mut Engine, &[Ray], &mut [Option<SceneHit>]);
/// The same for any hit.
type Any = fn(&mut Engine, &[Ray], &mut [bool]);

fn check(e: &mut Engine, rays: &[Ray], what: &str) {
    let want: Vec<_> = rays.iter().map(|r| bits(e.closest_hit(r))).collect();
    let want_any: Vec<bool> = rays.iter().map(|r| e.any_hit(r)).collect();
    let closest: [(&str, Closest); 4] = [
        ("closest_hit_batch", |e, r, o| e.closest_hit_batch(r, o)),
        ("closest_hit_packets", |e, r, o| e.closest_hit_packets(r, o)),
        ("trace_closest", |e, r, o| {
            e.trace_closest(r, o);
        }),
        ("trace_closest_packets", |e, r, o| {
            e.trace_closest_packets(r, o);
        }),
    ];
    let any: [(&str, Any); 3] = [
        ("any_hit_batch", |e, r, o| e.any_hit_batch(r, o)),
        ("trace_any", |e, r, o| {
            e.trace_any(r, o);
        }),
        ("trace_any_packets", |e, r, o| {
            e.trace_any_packets(r, o);
        }),
    ];
    for (name, query) in closest {
        let mut hits = vec![None; rays.len()];
        query(e, rays, &mut hits);
        assert!(
            hits.iter().map(|&h| bits(h)).eq(want.iter().copied()),
            "{what}: {name}"
        );
    }
    for (name, query) in any {
        let mut blocked = vec![false; rays.len()];
        query(e, rays, &mut blocked);
        assert_eq!(blocked, want_any, "{what}: {name}");
    }
}

#[test]
fn reordered_batches_answer_as_single_queries_on_every_frame() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("animations");
    let mut files = 0;
    for name in [
        "explode.glb",
        "lidar_cloth.glb",
        "orbit.glb",
        "swap.glb",
        "tube.glb",
        "wave.glb",
    ] {
        let (scene, _) = Scene::load(dir.join(name)).unwrap();
        let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(12)).unwrap();
        let mut e = src.engine(EngineConfig::default());
        let b = e.bounds();
        let scattered = random_rays(&b, 2 * RayOrder::MIN_RAYS, 7);
        assert!(
            RayOrder::reordered(&scattered, &b),
            "{name}: the scattered batch is reordered"
        );
        let view = camera_rays(&b, 96, 96);
        // Small batches, answered on the calling thread (`dynbvh::parallel`); one of 1,000
        // rays, not whole packets, around whose middle packet the packet batches split.
        let small = camera_rays(&b, 24, 24);
        let odd = camera_rays(&b, 40, 25);
        for f in 1..=src.frames() {
            src.advance(&mut e, f);
            e.update();
            check(&mut e, &scattered, &format!("{name} frame {f}, scattered"));
            check(&mut e, &view, &format!("{name} frame {f}, camera"));
            check(&mut e, &small, &format!("{name} frame {f}, small camera"));
            check(
                &mut e,
                &odd,
                &format!("{name} frame {f}, 1,000 camera rays"),
            );
        }
        files += 1;
    }
    assert_eq!(files, 6);
}
