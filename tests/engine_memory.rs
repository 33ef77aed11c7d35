//! [`Engine::memory`]: what the engine holds, by what it is for. A static mesh keeps less than
//! the same mesh deforming (with the wide traversal no binary tree, no spare), the parts add up
//! to the total, and nothing grows frame after frame, rebuilds included: the trees and spares
//! are sized by the first frame's update, the scratch by the first frame that traces.

use dynbvh::engine::{Decision, Engine, EngineConfig, MeshId};
use dynbvh::geom::{Ray, shapes};
use dynbvh::glam::{Affine3A, Vec3};

fn engine(fixed: bool) -> (Engine, MeshId) {
    let ball = shapes::icosphere(4);
    let mut e = Engine::new(EngineConfig::default());
    let (p, i) = (ball.positions.clone(), ball.indices.clone());
    let m = if fixed {
        e.add_static_mesh(p, i)
    } else {
        e.add_mesh(p, i)
    };
    e.add_instance(m, Affine3A::IDENTITY);
    e.add_instance(m, Affine3A::from_translation(Vec3::new(3.0, 0.0, 0.0)));
    e.update();
    (e, m)
}

/// Rays from in front of both instances, spread over them.
fn rays() -> Vec<Ray> {
    (0..4096)
        .map(|k| {
            let (x, y) = ((k % 64) as f32 / 16.0 - 1.5, (k / 64) as f32 / 32.0 - 1.0);
            Ray::new(Vec3::new(x, y, 6.0), Vec3::new(0.0, 0.0, -1.0))
        })
        .collect()
}

/// One frame: the deforming mesh, at rest at `rest`, breathes; the engine updates and traces.
fn frame(e: &mut Engine, m: MeshId, rest: &[Vec3], k: usize, rays: &[Ray]) {
    let s = 1.0 + 0.02 * (k as f32 * 0.7).sin();
    for (p, r) in e.positions_mut(m).iter_mut().zip(rest) {
        *p = *r * Vec3::new(s, 1.0 / s, 1.0);
    }
    e.update();
    let mut hits = vec![None; rays.len()];
    e.trace_closest(rays, &mut hits);
}

#[test]
fn a_static_mesh_holds_less_than_the_same_mesh_deforming() {
    let (fixed, _) = engine(true);
    let (moving, _) = engine(false);
    let (a, b) = (fixed.memory(), moving.memory());
    for m in [a, b] {
        assert_eq!(m.total(), m.geometry + m.trees + m.spares + m.scratch);
        assert!(m.geometry > 0 && m.trees > 0, "{m:?}");
    }
    // Vertex positions and index triples of 12 bytes each, once for both instances.
    let ball = shapes::icosphere(4);
    assert_eq!(a.geometry, 12 * (ball.positions.len() + ball.indices.len()));
    assert_eq!(a.geometry, b.geometry);
    assert!(a.trees < b.trees, "static {a:?} against deforming {b:?}");
    assert_eq!(a.spares, 0, "{a:?}");
}

#[test]
fn a_deforming_mesh_keeps_room_for_a_spare_and_nothing_grows_frame_after_frame() {
    let (mut e, m) = engine(false);
    let rays = rays();
    let rest = shapes::icosphere(4).positions;
    frame(&mut e, m, &rest, 0, &rays);
    let first = e.memory();
    assert!(
        first.spares > 0,
        "room for the tree a rebuild on trial replaces: {first:?}"
    );
    for k in 1..24 {
        if k % 7 == 3 {
            e.force_next(Decision::Rebuild);
        }
        frame(&mut e, m, &rest, k, &rays);
        assert_eq!(e.memory(), first, "frame {k}");
    }
}
