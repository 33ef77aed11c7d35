//! Batches through the wide tree: an incoherent batch is really reordered, and every ray's
//! answer is the one its own query gives (closest hit bit for bit, any hit), checked against
//! brute force on a share of them; coherent, small and non-finite batches alike.

mod common;

use common::{Rng, same_closest};
use dynbvh::bvh::ray_order::{RayBatch, RayOrder};
use dynbvh::bvh::{BuildParams, MeshBvh, MeshBvh8, brute_force_any, brute_force_closest};
use dynbvh::geom::{Ray, TriMesh, shapes};
use glam::Vec3;

/// Rays from points spread over the mesh's box in random directions, as an ambient-occlusion
/// or simulator batch casts them.
fn scattered(mesh: &TriMesh, n: usize, seed: u64) -> Vec<Ray> {
    let b = mesh.bounds();
    let mut rng = Rng(seed);
    (0..n)
        .map(|_| {
            let o = b.min + (b.max - b.min) * Vec3::new(rng.f(), rng.f(), rng.f());
            Ray::new(o, rng.unit_vector())
        })
        .collect()
}

/// A camera's rows looking at the mesh.
fn camera(mesh: &TriMesh, side: usize) -> Vec<Ray> {
    let b = mesh.bounds();
    let eye = b.center() + Vec3::new(0.3, 0.2, 1.0) * (b.max - b.min).length();
    (0..side * side)
        .map(|i| {
            let (x, y) = (
                (i % side) as f32 / side as f32,
                (i / side) as f32 / side as f32,
            );
            let target = b.min + (b.max - b.min) * Vec3::new(x, y, 0.5);
            Ray::new(eye, target - eye)
        })
        .collect()
}

/// The batch's answers against each ray's own queries, and a share against brute force.
fn check(mesh: &TriMesh, w: &MeshBvh8, rays: &[Ray], s: &mut RayBatch, what: &str) {
    let mut hits = vec![None; rays.len()];
    let mut any = vec![false; rays.len()];
    w.closest_hit_batch(rays, &mut hits, s);
    w.any_hit_batch(rays, &mut any, s);
    for (i, r) in rays.iter().enumerate() {
        let single = w.closest_hit(r);
        assert_eq!(
            hits[i].map(|h| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits(), h.prim)),
            single.map(|h| (h.t.to_bits(), h.u.to_bits(), h.v.to_bits(), h.prim)),
            "{what}: ray {i} {r:?}"
        );
        assert_eq!(any[i], w.any_hit(r), "{what}: any hit of ray {i}");
        if i % 37 == 0 {
            assert!(
                same_closest(mesh, r, brute_force_closest(mesh, r), hits[i]),
                "{what}: ray {i} against brute force"
            );
            assert_eq!(
                any[i],
                brute_force_any(mesh, r),
                "{what}: any hit of ray {i}"
            );
        }
    }
}

#[test]
fn batches_answer_every_ray_as_its_own_query_does() {
    let mesh = shapes::bumpy_sphere(20_000);
    let w = MeshBvh8::from_mesh_bvh(&MeshBvh::build(&mesh, &BuildParams::BINNED));
    let mut order = RayOrder::default();
    let random = scattered(&mesh, 3 * RayOrder::MIN_RAYS, 1);
    assert!(
        order.plan(&random, &w.bounds()).is_some(),
        "a scattered batch is reordered"
    );
    let mut s = RayBatch::default();
    check(&mesh, &w, &random, &mut s, "scattered");
    let view = camera(&mesh, 96);
    assert!(
        order.plan(&view, &w.bounds()).is_none(),
        "a camera's rows are traced as they come"
    );
    check(&mesh, &w, &view, &mut s, "camera");
    // The scratch left by a larger batch serves a smaller one, and small batches go as given.
    check(&mesh, &w, &random[..RayOrder::MIN_RAYS], &mut s, "smaller");
    check(&mesh, &w, &random[..100], &mut s, "small");
    check(&mesh, &w, &[], &mut s, "empty");
}

#[test]
fn reordered_batches_with_rays_that_miss_or_are_not_numbers() {
    let mesh = shapes::bumpy_sphere(5_000);
    let w = MeshBvh8::from_mesh_bvh(&MeshBvh::build(&mesh, &BuildParams::BINNED));
    let mut rays = scattered(&mesh, 2 * RayOrder::MIN_RAYS, 2);
    let far = Vec3::splat(100.0);
    for (i, r) in rays.iter_mut().enumerate() {
        *r = match i % 11 {
            // Outside the box, moving away.
            0 => Ray::new(far, Vec3::ONE),
            1 => Ray::new(Vec3::new(f32::NAN, 0.0, 0.0), r.dir()),
            2 => Ray::new(r.origin(), Vec3::new(f32::INFINITY, 0.0, 1.0)),
            3 => Ray::with_range(r.origin(), r.dir(), 0.0, f32::NAN),
            // Axis-parallel through the middle.
            4 => Ray::new(r.origin(), Vec3::Z),
            _ => *r,
        };
    }
    let mut order = RayOrder::default();
    assert!(order.plan(&rays, &w.bounds()).is_some());
    check(&mesh, &w, &rays, &mut RayBatch::default(), "bad rays");
}
