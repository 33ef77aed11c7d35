//! Watertightness: rays aimed exactly at the vertices and edge midpoints of a closed mesh, from
//! inside and from outside, never slip between its triangles, through the binary tree, the 4-
//! and 8-wide trees and packets.

mod common;

use common::{Rng, check_ray};
use dynbvh::bvh::{BuildParams, MeshBvh, MeshBvh4, MeshBvh8, PacketMode};
use dynbvh::geom::shapes::icosphere;
use dynbvh::geom::{Ray, TriMesh};
use glam::Vec3;
use std::collections::HashSet;

/// Points where the triangle test is most fragile: every vertex and every edge midpoint.
fn targets(mesh: &TriMesh) -> Vec<Vec3> {
    let mut edges = HashSet::new();
    let mut pts: Vec<Vec3> = mesh.positions.clone();
    for t in &mesh.indices {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if edges.insert((a.min(b), a.max(b))) {
                pts.push((mesh.positions[a as usize] + mesh.positions[b as usize]) * 0.5);
            }
        }
    }
    pts
}

fn count_misses(mesh: &TriMesh, bvh: &MeshBvh, rays: &[Ray]) -> usize {
    let mut misses = 0;
    for (i, ray) in rays.iter().enumerate() {
        check_ray(mesh, bvh, ray).unwrap();
        if bvh.closest_hit(ray).is_none() {
            eprintln!("miss: kind {} {ray:?}", i % 4);
            misses += 1;
        }
    }
    misses
}

#[test]
fn no_ray_slips_through_a_closed_mesh() {
    // A closed mesh, also rotated and moved off the origin so coordinates are not "nice".
    let mut mesh = icosphere(3);
    let rot = glam::Quat::from_euler(glam::EulerRot::XYZ, 0.3, 1.1, -0.7);
    for p in &mut mesh.positions {
        *p = rot * (*p * 3.7) + Vec3::new(10.25, -3.5, 0.125);
    }
    let center = Vec3::new(10.25, -3.5, 0.125);
    let pts = targets(&mesh);
    assert!(pts.len() > 1900);
    let mut rng = Rng(99);
    let mut rays = Vec::new();
    for &p in &pts {
        // From outside along the outward direction, and from a random outside point.
        let out = p + (p - center).normalize() * 5.0;
        rays.push(Ray::new(out, p - out));
        // From a random far point, when the target faces it clearly: a ray that only grazes
        // the silhouette may miss the (rounded) target legitimately.
        let far = center + rng.unit_vector() * 20.0;
        if (p - far).normalize().dot((p - center).normalize()) < -0.1 {
            rays.push(Ray::new(far, p - far));
        }
        // From inside: the centre and a random interior point.
        rays.push(Ray::new(center, p - center));
        let inside = center + rng.unit_vector() * rng.range(0.0, 2.0);
        rays.push(Ray::new(inside, p - inside));
    }
    for params in [BuildParams::BINNED, BuildParams::SWEEP, BuildParams::MEDIAN] {
        let bvh = MeshBvh::build(&mesh, &params);
        bvh.validate(&mesh).unwrap();
        assert_eq!(count_misses(&mesh, &bvh, &rays), 0, "{}", params.name());
        // The binary tree's hits equal brute force (checked above); every other traversal
        // must give exactly the same distances.
        let t = |h: Option<dynbvh::geom::Hit>| h.map(|h| h.t);
        let (w4, w8) = (MeshBvh4::from_mesh_bvh(&bvh), MeshBvh8::from_mesh_bvh(&bvh));
        w4.validate(&mesh).unwrap();
        w8.validate(&mesh).unwrap();
        let mut packet = vec![None; rays.len()];
        bvh.closest_hit_packet_mode(&rays, &mut packet, PacketMode::Always);
        for (ray, p) in rays.iter().zip(&packet) {
            let want = t(bvh.closest_hit(ray));
            assert!(want.is_some());
            assert_eq!(
                t(w4.closest_hit(ray)),
                want,
                "BVH4 {} {ray:?}",
                params.name()
            );
            assert_eq!(
                t(w8.closest_hit(ray)),
                want,
                "BVH8 {} {ray:?}",
                params.name()
            );
            assert_eq!(t(*p), want, "packet {} {ray:?}", params.name());
        }
    }
}
