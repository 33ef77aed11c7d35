//! Static meshes ([`Engine::add_static_mesh`]): built once, with the wide traversal only their
//! 8-wide tree kept, and every query answering exactly as for the same mesh added as an
//! ordinary one (which `tests/engine_hits.rs` and `tests/queries.rs` check against brute
//! force); written later, a static mesh becomes an ordinary one and still answers alike. A
//! glTF scene's static and rigid meshes are added so.

use dynbvh::anim::Scene;
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::source::FrameSource;
use dynbvh::engine::{Engine, EngineConfig, InstanceId, MeshId, Query, Traversal};
use dynbvh::geom::{Aabb, Ray, shapes};
use dynbvh::glam::{Affine3A, Quat, Vec3};
use dynbvh::report::rays::{camera_rays, random_rays};

/// Two instances of `mesh` (one in place, one turned, scaled unevenly and moved), added as a
/// static or an ordinary mesh.
fn engine(traversal: Traversal, fixed: bool, mesh: &dynbvh::geom::TriMesh) -> (Engine, MeshId) {
    let mut e = Engine::new(EngineConfig {
        traversal,
        ..EngineConfig::default()
    });
    let (p, i) = (mesh.positions.clone(), mesh.indices.clone());
    let m = if fixed {
        e.add_static_mesh(p, i)
    } else {
        e.add_mesh(p, i)
    };
    e.add_instance(m, Affine3A::IDENTITY);
    e.add_instance(
        m,
        Affine3A::from_scale_rotation_translation(
            Vec3::new(0.7, 1.3, 0.9),
            Quat::from_rotation_y(0.8),
            Vec3::new(2.1, 0.3, -0.4),
        ),
    );
    e.update();
    (e, m)
}

/// Every query's answers on `a` and `b`, which must be the same, bit for bit.
fn same_answers(a: &Engine, b: &Engine, what: &str) {
    let bounds = a.bounds();
    assert_eq!(bounds, b.bounds(), "{what}: bounds");
    let diag = bounds.extent().length();
    let mut rays = camera_rays(&bounds, 48, 48);
    rays.extend(random_rays(&bounds, 2000, 3));
    for r in &rays {
        let (ha, hb) = (a.closest_hit(r), b.closest_hit(r));
        assert_eq!(
            ha.map(|h| (h.t, h.prim, h.instance)),
            hb.map(|h| (h.t, h.prim, h.instance)),
            "{what}: closest hit of {r:?}"
        );
        assert_eq!(a.any_hit(r), b.any_hit(r), "{what}: any hit of {r:?}");
    }
    let (mut oa, mut ob) = (Vec::new(), Vec::new());
    for (k, r) in rays.iter().step_by(23).enumerate() {
        let p: Vec3 = r.origin();
        let (ca, cb) = (
            a.closest_point(p, f32::INFINITY),
            b.closest_point(p, f32::INFINITY),
        );
        assert_eq!(
            ca.map(|c| c.distance),
            cb.map(|c| c.distance),
            "{what}: closest point of {p}"
        );
        let h = Vec3::splat(0.02 * diag * (1 + k % 5) as f32);
        let q = Aabb::new(p - h, p + h);
        a.overlap_box(q, &mut oa);
        b.overlap_box(q, &mut ob);
        assert_eq!(oa, ob, "{what}: box {q:?}");
        a.overlap_sphere(p, h.x, &mut oa);
        b.overlap_sphere(p, h.x, &mut ob);
        assert_eq!(oa, ob, "{what}: sphere {p} {}", h.x);
        let ray = Ray::new(p, r.dir());
        assert_eq!(a.count_hits(&ray), b.count_hits(&ray), "{what}: hit count");
    }
}

#[test]
fn a_static_mesh_keeps_only_its_wide_tree_and_answers_alike() {
    let mesh = shapes::bumpy_sphere(20_000);
    for traversal in [Traversal::Wide, Traversal::Binary] {
        let what = format!("{traversal}");
        let (mut s, sm) = engine(traversal, true, &mesh);
        let (mut o, om) = engine(traversal, false, &mesh);
        // The same trees: the static mesh's wide tree is the ordinary one's, and under the
        // wide traversal it has no binary tree beside it.
        match traversal {
            Traversal::Wide => {
                assert!(s.mesh_bvh(sm).bvh().nodes().is_empty(), "{what}");
                assert_eq!(
                    s.mesh_bvh8(sm).map(|w| w.memory_bytes()),
                    o.mesh_bvh8(om).map(|w| w.memory_bytes()),
                    "{what}: wide trees"
                );
            }
            Traversal::Binary => {
                assert_eq!(
                    s.mesh_bvh(sm).bvh().nodes(),
                    o.mesh_bvh(om).bvh().nodes(),
                    "{what}: binary trees"
                );
            }
        }
        same_answers(&s, &o, &format!("{what}, as built"));

        // Written: an ordinary mesh from then on, refitted like the other.
        for (e, m) in [(&mut s, sm), (&mut o, om)] {
            for (k, v) in e.positions_mut(m).iter_mut().enumerate() {
                *v *= 1.0 + 0.2 * ((k % 7) as f32 / 7.0);
            }
            e.update();
        }
        assert!(!s.mesh_bvh(sm).bvh().nodes().is_empty(), "{what}: rebuilt");
        assert_eq!(
            s.mesh_bvh(sm).bvh().nodes(),
            o.mesh_bvh(om).bvh().nodes(),
            "{what}: refitted alike"
        );
        same_answers(&s, &o, &format!("{what}, written"));
    }
}

#[test]
fn a_gltf_scene_adds_its_unmoving_meshes_as_static() {
    // Deforming (the cloth), rigid (the boxes) and static (the ground) instances.
    let (scene, _) = Scene::load("animations/lidar_cloth.glb").expect("the shipped scene");
    let mut source = GltfSource::new(&scene, Some(0), FrameTimes::Count(4)).expect("a source");
    let e = source.build(0, EngineConfig::default());
    let (mut with, mut without) = (0, 0);
    for k in 0..e.instance_count() {
        let m = e.instance_mesh(InstanceId(k as u32));
        assert!(e.mesh_bvh8(m).is_some(), "instance {k}: a wide tree");
        if e.mesh_bvh(m).bvh().nodes().is_empty() {
            without += 1;
        } else {
            with += 1;
        }
    }
    // The cloth keeps its binary tree (it is refitted and rebuilt); the boxes and the ground
    // do not.
    assert_eq!(with, 1, "instances whose mesh keeps a binary tree");
    assert!(without >= 7, "static and rigid instances: {without}");
}

/// A scene of static meshes takes no ray sample (nothing measures their degradation); the
/// same mesh added as an ordinary one is sampled on the frame after it is added.
#[test]
fn static_meshes_owe_no_ray_sample() {
    let mesh = shapes::bumpy_sphere(5_000);
    for fixed in [true, false] {
        let (mut e, _) = engine(Traversal::Wide, fixed, &mesh);
        let rays = camera_rays(&e.bounds(), 64, 64);
        e.sample_rays(&rays, Query::Closest);
        let sampled = e.sampled_work().nodes;
        if fixed {
            assert_eq!(sampled, 0, "a static scene sampled");
            assert!(e.sampled_entries().is_empty());
        } else {
            assert!(sampled > 0, "a new ordinary mesh not sampled");
        }
    }
}
