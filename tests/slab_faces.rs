//! Rays with a zero direction component whose origin lies exactly on a box face of that axis:
//! the ray runs inside the face's plane, so it is inside the slab and must reach what the box
//! holds. Axis-aligned geometry makes this common (a ray skimming a floor at y = 0 or along the
//! top edge of a wall), and a slab test that multiplies a zero distance by a huge reciprocal
//! gets a far distance of 0 there and drops the box.

use dynbvh::bvh::{
    BuildParams, MeshBvh, MeshBvh4, MeshBvh8, PacketMode, brute_force_any, brute_force_closest,
};
use dynbvh::geom::{Ray, TriMesh};
use glam::Vec3;

/// Walls in the plane x = 1 and x = 3 whose top edges lie at z = 3 and bottom edges at z = 0,
/// and a floor triangle in z = 0 far away, so that the root's box spans z in [0, 3] and its
/// children's boxes have faces at z = 0 and z = 3.
fn walls() -> TriMesh {
    let mut positions = Vec::new();
    let mut indices = Vec::new();
    for x in [1.0f32, 3.0] {
        let b = positions.len() as u32;
        positions.extend([
            Vec3::new(x, -1.0, 0.0),
            Vec3::new(x, 1.0, 0.0),
            Vec3::new(x, 1.0, 3.0),
            Vec3::new(x, -1.0, 3.0),
        ]);
        indices.extend([[b, b + 1, b + 2], [b, b + 2, b + 3]]);
    }
    let b = positions.len() as u32;
    positions.extend([
        Vec3::new(10.0, 5.0, 0.0),
        Vec3::new(11.0, 5.0, 0.0),
        Vec3::new(10.0, 6.0, 0.0),
    ]);
    indices.push([b, b + 1, b + 2]);
    TriMesh::new(positions, indices)
}

/// Rays in the planes z = 3 (the walls' top edges, the boxes' max-z faces) and z = 0 (their
/// bottom edges, the min-z faces), with +0 and -0 as the zero component, in both x directions.
fn rays() -> Vec<Ray> {
    let mut rays = Vec::new();
    for z in [0.0f32, 3.0] {
        for zero in [0.0f32, -0.0] {
            for y in [-0.5f32, 0.0, 0.25] {
                rays.push(Ray::new(Vec3::new(0.0, y, z), Vec3::new(1.0, 0.0, zero)));
                rays.push(Ray::new(Vec3::new(4.0, y, z), Vec3::new(-1.0, 0.0, zero)));
                rays.push(Ray::new(Vec3::new(0.0, y, z), Vec3::new(1.0, 0.1, zero)));
            }
        }
    }
    rays
}

#[test]
fn rays_in_a_box_face_plane_reach_its_triangles() {
    let mesh = walls();
    let rays = rays();
    // Brute force hits the walls' edges: the case is real.
    let hits = rays
        .iter()
        .filter(|r| brute_force_closest(&mesh, r).is_some())
        .count();
    assert!(hits >= rays.len() / 2, "only {hits} of {} hit", rays.len());
    for params in [BuildParams::BINNED, BuildParams::SWEEP, BuildParams::MEDIAN] {
        let params = BuildParams {
            max_leaf_size: 1,
            ..params
        };
        let bvh = MeshBvh::build(&mesh, &params);
        let bvh4 = MeshBvh4::from_mesh_bvh(&bvh);
        let bvh8 = MeshBvh8::from_mesh_bvh(&bvh);
        let mut packet = vec![None; rays.len()];
        bvh.closest_hit_packet_mode(&rays, &mut packet, PacketMode::Always);
        let mut packet_any = vec![false; rays.len()];
        bvh.any_hit_packet_mode(&rays, &mut packet_any, PacketMode::Always);
        for (i, r) in rays.iter().enumerate() {
            let want = brute_force_closest(&mesh, r).map(|h| (h.t, h.prim));
            let got = bvh.closest_hit(r).map(|h| (h.t, h.prim));
            assert_eq!(got, want, "{:?}: ray {r:?}", params.method);
            assert_eq!(bvh.any_hit(r), brute_force_any(&mesh, r), "ray {r:?}");
            assert_eq!(packet[i].map(|h| (h.t, h.prim)), want, "packet: ray {r:?}");
            assert_eq!(packet_any[i], want.is_some(), "packet any: ray {r:?}");
            assert_eq!(
                bvh4.closest_hit(r).map(|h| (h.t, h.prim)),
                want,
                "bvh4: {r:?}"
            );
            assert_eq!(
                bvh8.closest_hit(r).map(|h| (h.t, h.prim)),
                want,
                "bvh8: {r:?}"
            );
            assert_eq!(bvh4.any_hit(r), want.is_some(), "bvh4 any: {r:?}");
            assert_eq!(bvh8.any_hit(r), want.is_some(), "bvh8 any: {r:?}");
        }
    }
}
