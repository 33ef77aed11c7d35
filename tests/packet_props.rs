//! Property tests of packet traversal: every packet of rays, coherent or not, gets exactly the
//! answers of single-ray traversal and of brute force, for every builder, before and after
//! deformations and refits; and through the two-level engine, exactly the engine's single-ray
//! answers.

use dynbvh::bvh::brute_force_closest;
use dynbvh::bvh::{BuildParams, MAX_PACKET, MeshBvh, PacketMode, brute_force_any};
use dynbvh::engine::{Engine, EngineConfig};
use dynbvh::geom::{Ray, TriMesh};
use glam::{Affine3A, Quat, Vec3};
use proptest::prelude::*;

mod common;
use common::strategies::{coherent, mesh, rays, vec3};
use common::{aimed, same_closest};

/// Every mode of the packet queries against single rays and brute force.
fn check_packet(mesh: &TriMesh, bvh: &MeshBvh, rays: &[Ray]) -> Result<(), TestCaseError> {
    for mode in [PacketMode::Always, PacketMode::Auto] {
        let mut hits = vec![None; rays.len()];
        bvh.closest_hit_packet_mode(rays, &mut hits, mode);
        let mut any = vec![false; rays.len()];
        bvh.any_hit_packet_mode(rays, &mut any, mode);
        for (i, r) in rays.iter().enumerate() {
            let want = brute_force_closest(mesh, r);
            let single = bvh.closest_hit(r);
            prop_assert!(
                same_closest(mesh, r, single, hits[i]),
                "{mode:?} ray {i} {r:?}: single {single:?}, packet {:?}",
                hits[i]
            );
            let want_any = brute_force_any(mesh, r);
            prop_assert_eq!(
                any[i],
                bvh.any_hit(r),
                "{:?} any hit of ray {} {:?}",
                mode,
                i,
                r
            );
            // Rays with a zero direction component whose origin lies on a box face included
            // (tests/slab_faces.rs).
            prop_assert!(
                same_closest(mesh, r, want, hits[i]),
                "{mode:?} ray {i} {r:?}: brute force {want:?}, packet {:?}",
                hits[i]
            );
            prop_assert_eq!(any[i], want_any, "{:?} any hit of ray {} {:?}", mode, i, r);
        }
    }
    Ok(())
}

fn check_all(mesh: &TriMesh, bvh: &MeshBvh, packets: &[Vec<Ray>]) -> Result<(), TestCaseError> {
    for p in packets {
        check_packet(mesh, bvh, p)?;
    }
    check_packet(mesh, bvh, &aimed(mesh, Vec3::new(0.3, 11.0, -0.7)))?;
    // Packets from a point inside the mesh's box toward every vertex.
    check_packet(mesh, bvh, &aimed(mesh, mesh.bounds().center()))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, ..ProptestConfig::default() })]

    #[test]
    fn packets_match_single_rays_and_brute_force(
        mesh in mesh(120, 10),
        coherent in prop::collection::vec(coherent(), 1..4),
        incoherent in prop::collection::vec(rays(1..=MAX_PACKET), 1..3),
    ) {
        let packets: Vec<Vec<Ray>> = coherent.into_iter().chain(incoherent).collect();
        for params in common::builders() {
            let bvh = MeshBvh::build(&mesh, &params);
            check_all(&mesh, &bvh, &packets)?;
        }
    }

    #[test]
    fn packets_after_deformation_and_refit(
        mesh in mesh(120, 10),
        moves in prop::collection::vec((prop::collection::vec(vec3(), 1..8), 0.0f32..3.0), 2),
        coherent in prop::collection::vec(coherent(), 1..3),
        incoherent in rays(1..=MAX_PACKET),
    ) {
        let packets: Vec<Vec<Ray>> = coherent.into_iter().chain([incoherent]).collect();
        for params in common::builders() {
            let mut m = mesh.clone();
            let mut bvh = MeshBvh::build(&m, &params);
            for (offsets, scale) in &moves {
                for (i, p) in m.positions.iter_mut().enumerate() {
                    *p += offsets[i % offsets.len()] * *scale * (1.0 + (i % 3) as f32);
                }
                bvh.refit(&m);
                check_all(&m, &bvh, &packets)?;
            }
        }
    }

    #[test]
    fn engine_packets_match_engine_single_rays(
        meshes in prop::collection::vec(mesh(120, 10), 1..3),
        placements in prop::collection::vec((0usize..3, vec3(), -3.0f32..3.0, 0.5f32..2.0, any::<bool>()), 1..5),
        coherent in prop::collection::vec(coherent(), 1..3),
        incoherent in rays(1..=MAX_PACKET),
    ) {
        let mut e = Engine::new(EngineConfig::default());
        let ids: Vec<_> = meshes
            .iter()
            .map(|m| e.add_mesh(m.positions.clone(), m.indices.clone()))
            .collect();
        for (m, t, angle, scale, identity) in &placements {
            let tf = if *identity {
                Affine3A::IDENTITY
            } else {
                Affine3A::from_scale_rotation_translation(
                    Vec3::splat(*scale),
                    Quat::from_axis_angle(Vec3::new(1.0, 2.0, 0.5).normalize(), *angle),
                    *t,
                )
            };
            e.add_instance(ids[m % ids.len()], tf);
        }
        e.update();
        for rays in coherent.iter().chain([&incoherent]) {
            for mode in [PacketMode::Always, PacketMode::Auto] {
                let mut hits = vec![None; rays.len()];
                e.closest_hit_packet_mode(rays, &mut hits, mode);
                let mut any = vec![false; rays.len()];
                e.any_hit_packet_mode(rays, &mut any, mode);
                for (i, r) in rays.iter().enumerate() {
                    let want = e.closest_hit(r);
                    match (want, hits[i]) {
                        (None, None) => {}
                        (Some(w), Some(g)) => {
                            prop_assert_eq!(w.t, g.t, "{:?} ray {} {:?}", mode, i, r);
                            if (w.prim, w.instance) == (g.prim, g.instance) {
                                prop_assert_eq!((w.u, w.v), (g.u, g.v));
                            }
                        }
                        (w, g) => prop_assert!(false, "{mode:?} ray {i} {r:?}: single {w:?}, packet {g:?}"),
                    }
                    prop_assert_eq!(any[i], e.any_hit(r), "{:?} any hit of ray {} {:?}", mode, i, r);
                }
            }
        }
    }
}

#[test]
fn image_tiles_match_single_rays() {
    let mesh = dynbvh::geom::shapes::bumpy_sphere(5_000);
    let bvh = MeshBvh::build(&mesh, &BuildParams::BINNED);
    // An image whose sides are not multiples of the tile.
    let (w, h) = (37, 29);
    let rays = dynbvh::report::rays::camera_rays(&mesh.bounds(), w, h);
    let mut hits = vec![None; rays.len()];
    bvh.trace_image_closest(&rays, w, &mut hits);
    let mut hit_count = 0;
    for (r, got) in rays.iter().zip(&hits) {
        let want = bvh.closest_hit(r);
        assert!(
            same_closest(&mesh, r, want, *got),
            "{r:?}: {want:?} vs {got:?}"
        );
        hit_count += usize::from(got.is_some());
    }
    assert!(hit_count > rays.len() / 4, "the camera sees the sphere");
}
