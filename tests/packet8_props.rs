//! Property tests of packet traversal over the wide trees (`MeshBvh8`, `MeshBvh4`): every
//! packet of rays, coherent or not, in both packet modes, gets exactly the answers of the wide
//! tree's single rays, of the binary tree and of brute force, for every builder, before and
//! after several deformations in a row (each followed by a refit), with axis-parallel rays,
//! origins inside the mesh and NaN or infinite triangles.

use dynbvh::bvh::{
    BuildParams, MAX_PACKET, MeshBvh, PacketMode, WideBvh, brute_force_any, brute_force_closest,
};
use dynbvh::geom::{Ray, TriMesh};
use glam::Vec3;
use proptest::prelude::*;

mod common;
use common::strategies::{coherent, mesh, rays, vec3};
use common::{aimed, rays_around, same_closest};

/// Every mode of the wide packet queries against the wide tree's single rays, the binary
/// tree and brute force.
fn check_packet<const K: usize>(
    mesh: &TriMesh,
    bin: &MeshBvh,
    wide: &WideBvh<K>,
    rays: &[Ray],
) -> Result<(), TestCaseError> {
    for mode in [PacketMode::Always, PacketMode::Auto] {
        let mut hits = vec![None; rays.len()];
        wide.closest_hit_packet_mode(rays, &mut hits, mode);
        let mut any = vec![false; rays.len()];
        wide.any_hit_packet_mode(rays, &mut any, mode);
        for (i, r) in rays.iter().enumerate() {
            for (what, want) in [
                ("brute force", brute_force_closest(mesh, r)),
                ("binary", bin.closest_hit(r)),
                ("wide single", wide.closest_hit(r)),
            ] {
                prop_assert!(
                    same_closest(mesh, r, want, hits[i]),
                    "BVH{K} {mode:?} ray {i} {r:?}: {what} {want:?}, packet {:?}",
                    hits[i]
                );
            }
            prop_assert_eq!(
                any[i],
                brute_force_any(mesh, r),
                "BVH{} {:?} any hit of ray {} {:?}",
                K,
                mode,
                i,
                r
            );
            prop_assert_eq!(
                any[i],
                wide.any_hit(r),
                "BVH{} {:?} any hit of ray {} {:?}",
                K,
                mode,
                i,
                r
            );
        }
    }
    Ok(())
}

/// The packets, then rays from outside and from inside the mesh's box toward every vertex.
fn check_all<const K: usize>(
    mesh: &TriMesh,
    bin: &MeshBvh,
    wide: &WideBvh<K>,
    packets: &[Vec<Ray>],
) -> Result<(), TestCaseError> {
    for p in packets {
        check_packet(mesh, bin, wide, p)?;
    }
    check_packet(mesh, bin, wide, &aimed(mesh, Vec3::new(0.3, 11.0, -0.7)))?;
    check_packet(mesh, bin, wide, &aimed(mesh, mesh.bounds().center()))
}

fn check_both(mesh: &TriMesh, bin: &MeshBvh, packets: &[Vec<Ray>]) -> Result<(), TestCaseError> {
    check_all(mesh, bin, &WideBvh::<8>::from_mesh_bvh(bin), packets)?;
    check_all(mesh, bin, &WideBvh::<4>::from_mesh_bvh(bin), packets)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, ..ProptestConfig::default() })]

    #[test]
    fn wide_packets_match_single_rays_and_brute_force(
        mesh in mesh(200, 14),
        coherent in prop::collection::vec(coherent(), 1..4),
        incoherent in prop::collection::vec(rays(1..=MAX_PACKET), 1..3),
    ) {
        let packets: Vec<Vec<Ray>> = coherent.into_iter().chain(incoherent).collect();
        for params in common::builders() {
            let bin = MeshBvh::build(&mesh, &params);
            check_both(&mesh, &bin, &packets)?;
        }
    }

    #[test]
    fn wide_packets_after_deformations_and_refits(
        mesh in mesh(200, 14),
        moves in prop::collection::vec((prop::collection::vec(vec3(), 1..8), 0.0f32..3.0), 3),
        coherent in prop::collection::vec(coherent(), 1..3),
        incoherent in rays(1..=MAX_PACKET),
    ) {
        let packets: Vec<Vec<Ray>> = coherent.into_iter().chain([incoherent]).collect();
        for params in [BuildParams::BINNED, BuildParams::MEDIAN] {
            let mut m = mesh.clone();
            let mut bin = MeshBvh::build(&m, &params);
            let mut w8 = WideBvh::<8>::from_mesh_bvh(&bin);
            let mut w4 = WideBvh::<4>::from_mesh_bvh(&bin);
            for (offsets, scale) in &moves {
                for (i, p) in m.positions.iter_mut().enumerate() {
                    *p += offsets[i % offsets.len()] * *scale * (1.0 + (i % 3) as f32);
                }
                bin.refit(&m);
                w8.refit(&m);
                w4.refit(&m);
                check_all(&m, &bin, &w8, &packets)?;
                check_all(&m, &bin, &w4, &packets)?;
            }
        }
    }
}

/// A camera image through `trace_image_closest` / `trace_image_any` of a BVH8 over a larger
/// mesh (deep enough for the packet's culling and single-ray walks to matter), equal to the
/// single rays of the binary tree.
#[test]
fn wide_image_tiles_match_single_rays() {
    let mesh = dynbvh::geom::shapes::bumpy_sphere(20_000);
    let bin = MeshBvh::build(&mesh, &BuildParams::BINNED);
    let w8 = WideBvh::<8>::from_mesh_bvh(&bin);
    let (w, h) = (61, 45);
    let rays = dynbvh::report::rays::camera_rays(&mesh.bounds(), w, h);
    let mut hits = vec![None; rays.len()];
    w8.trace_image_closest(&rays, w, &mut hits);
    let mut any = vec![false; rays.len()];
    w8.trace_image_any(&rays, w, &mut any);
    let mut hit_count = 0;
    for (i, r) in rays.iter().enumerate() {
        let want = bin.closest_hit(r);
        assert!(
            same_closest(&mesh, r, want, hits[i]),
            "{r:?}: {want:?} vs {:?}",
            hits[i]
        );
        assert_eq!(any[i], want.is_some(), "{r:?}");
        hit_count += usize::from(want.is_some());
    }
    assert!(hit_count > rays.len() / 4, "the camera sees the sphere");
}

/// Degenerate inputs: NaN and infinite triangles, the empty mesh, one triangle, and rays with
/// zero direction components from around and inside the soup.
#[test]
fn wide_packets_degenerate_inputs() {
    let soup = common::soup_with_nan_and_inf();
    let one = TriMesh::from_soup(&[[Vec3::ZERO, Vec3::X, Vec3::Y]]);
    let empty = TriMesh::new(Vec::new(), Vec::new());
    // Rays around the unit cube (the soup's finite triangles lie in it; its box reaches
    // `±f32::MAX`).
    let (c, r) = (Vec3::ZERO, 1.0);
    for mesh in [soup, one, empty] {
        let mut rays = rays_around(c, r, 200, 5);
        // Axis-parallel packets from inside the box, and a pinhole packet from its centre.
        for axis in [Vec3::X, Vec3::Y, Vec3::Z, -Vec3::X, -Vec3::Y, -Vec3::Z] {
            rays.extend((0..16).map(|i| Ray::new(c + Vec3::splat(i as f32 * 0.01 - 0.08), axis)));
        }
        rays.extend((0..64).map(|i| {
            Ray::new(
                c,
                Vec3::new(1.0, (i % 8) as f32 * 0.02, (i / 8) as f32 * 0.02),
            )
        }));
        for params in common::builders() {
            let bin = MeshBvh::build(&mesh, &params);
            for chunk in rays.chunks(MAX_PACKET) {
                check_both(&mesh, &bin, &[chunk.to_vec()]).unwrap();
            }
        }
    }
}
