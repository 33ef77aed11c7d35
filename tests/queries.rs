//! The proximity, overlap and multi-hit queries against brute force, on every frame of the
//! shipped animations: on a mesh's binary tree (built fresh each frame, and refitted from the
//! first frame's tree, so that stale splits are tested), and through the engine (two levels,
//! rigid and deforming instances, with the binary and the wide traversal), against every
//! world-space triangle the engine holds. Also masks, exclusion, hit details and edits.

use dynbvh::anim::Scene;
use dynbvh::bvh::{
    BuildParams, MeshBvh, MeshBvh8, brute_force_all_hits, brute_force_closest_point,
    brute_force_overlap_box, brute_force_overlap_sphere,
};
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::{
    Engine, EngineConfig, FrameSource, InstanceId, QueryFilter, SceneHit, Traversal,
};
use dynbvh::geom::{
    Aabb, Ray, RayTriPrecomp, TriMesh, closest_point_on_triangle, intersect_triangle,
    triangle_overlaps_box,
};
use dynbvh::glam::{Affine3A, Vec3};

const FILES: [&str; 6] = [
    "tube.glb",
    "wave.glb",
    "explode.glb",
    "swap.glb",
    "orbit.glb",
    "lidar_cloth.glb",
];
const FRAMES: usize = 12;

/// A deterministic generator of points, boxes and rays around a box.
struct Probe(u64);

impl Probe {
    fn f(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    fn point(&mut self, b: &Aabb, spread: f32) -> Vec3 {
        let c = b.center();
        let h = b.extent() * 0.5 * spread;
        c + Vec3::new(
            self.f() * 2.0 - 1.0,
            self.f() * 2.0 - 1.0,
            self.f() * 2.0 - 1.0,
        ) * h
    }
    fn near_surface(&mut self, m: &TriMesh, scale: f32) -> Vec3 {
        let k = (self.f() * m.indices.len() as f32) as usize % m.indices.len().max(1);
        let [a, b, c] = m.indices[k].map(|i| m.positions[i as usize]);
        let (u, v) = (self.f(), self.f());
        let (u, v) = if u + v > 1.0 {
            (1.0 - u, 1.0 - v)
        } else {
            (u, v)
        };
        let dir = Vec3::new(self.f() - 0.5, self.f() - 0.5, self.f() - 0.5);
        a + (b - a) * u + (c - a) * v + dir * scale
    }
    fn boxed(&mut self, b: &Aabb, size: f32) -> Aabb {
        let p = self.point(b, 1.1);
        let h = b.extent() * size * Vec3::new(self.f(), self.f(), self.f());
        Aabb::new(p - h, p + h)
    }
    fn ray(&mut self, b: &Aabb) -> Ray {
        let o = self.point(b, 2.5);
        let t = self.point(b, 0.8);
        Ray::new(o, t - o)
    }
}

fn load(file: &str) -> Scene {
    let path = format!("{}/animations/{file}", env!("CARGO_MANIFEST_DIR"));
    Scene::load(&path).unwrap().0
}

fn check_mesh_queries(mesh: &TriMesh, bvh: &MeshBvh, probe: &mut Probe, what: &str) {
    let bounds = Aabb::from_points(&mesh.positions);
    let diag = bounds.extent().length();
    let mut got = Vec::new();
    let mut hits = Vec::new();
    for k in 0..40 {
        let p = if k % 2 == 0 {
            probe.point(&bounds, 1.5)
        } else {
            probe.near_surface(mesh, 0.02 * diag)
        };
        for max_dist in [f32::INFINITY, 0.01 * diag, 0.1 * diag] {
            let want = brute_force_closest_point(mesh, p, max_dist);
            let have = bvh.closest_point(p, max_dist);
            assert_eq!(
                have.map(|h| h.distance),
                want.map(|h| h.distance),
                "{what}: closest point of {p} within {max_dist}"
            );
            if let (Some(h), Some(w)) = (have, want)
                && h.prim != w.prim
            {
                // A tie: the other triangle is exactly as near.
                let [a, b, c] = mesh.indices[h.prim as usize].map(|i| mesh.positions[i as usize]);
                let q = closest_point_on_triangle(p, a, b, c);
                assert_eq!(q.distance(p), w.distance, "{what}: tie");
            }
        }
        let q = probe.boxed(&bounds, 0.15);
        bvh.overlap_box(q, &mut got);
        assert_eq!(got, brute_force_overlap_box(mesh, q), "{what}: box {q:?}");
        let r = 0.1 * diag * probe.f();
        bvh.overlap_sphere(p, r, &mut got);
        assert_eq!(
            got,
            brute_force_overlap_sphere(mesh, p, r),
            "{what}: sphere {p} {r}"
        );
        let ray = probe.ray(&bounds);
        let want = brute_force_all_hits(mesh, &ray);
        bvh.all_hits(&ray, usize::MAX, &mut hits);
        assert_eq!(hits, want, "{what}: all hits of {ray:?}");
        assert_eq!(bvh.count_hits(&ray) as usize, want.len(), "{what}: count");
        bvh.all_hits(&ray, 2, &mut hits);
        let ts: Vec<f32> = want.iter().take(2).map(|h| h.t).collect();
        assert_eq!(
            hits.iter().map(|h| h.t).collect::<Vec<_>>(),
            ts,
            "{what}: 2 hits"
        );
    }
}

/// The wide tree's closest point, box and sphere overlaps, all hits and hit counts against
/// brute force.
fn check_wide_queries(mesh: &TriMesh, wide: &MeshBvh8, probe: &mut Probe, what: &str) {
    let bounds = Aabb::from_points(&mesh.positions);
    let diag = bounds.extent().length();
    let mut hits = Vec::new();
    let mut got = Vec::new();
    for k in 0..40 {
        let p = if k % 2 == 0 {
            probe.point(&bounds, 1.5)
        } else {
            probe.near_surface(mesh, 0.02 * diag)
        };
        for max_dist in [f32::INFINITY, 0.01 * diag, 0.1 * diag] {
            let want = brute_force_closest_point(mesh, p, max_dist);
            let have = wide.closest_point(p, max_dist);
            assert_eq!(
                have.map(|h| h.distance),
                want.map(|h| h.distance),
                "{what}: wide closest point of {p} within {max_dist}"
            );
            if let Some(h) = have {
                let [a, b, c] = mesh.indices[h.prim as usize].map(|i| mesh.positions[i as usize]);
                assert_eq!(
                    closest_point_on_triangle(p, a, b, c),
                    h.point,
                    "{what}: wide point"
                );
            }
        }
        // Boxes from a speck to most of the mesh, and spheres from none to all of it.
        let q = probe.boxed(&bounds, [0.001, 0.15, 0.6][k % 3]);
        wide.overlap_box(q, &mut got);
        assert_eq!(
            got,
            brute_force_overlap_box(mesh, q),
            "{what}: wide box {q:?}"
        );
        let r = [0.0, 0.1, 1.0][k % 3] * diag * probe.f();
        wide.overlap_sphere(p, r, &mut got);
        assert_eq!(
            got,
            brute_force_overlap_sphere(mesh, p, r),
            "{what}: wide sphere {p} {r}"
        );
        let ray = probe.ray(&bounds);
        let want = brute_force_all_hits(mesh, &ray);
        wide.all_hits(&ray, usize::MAX, &mut hits);
        assert_eq!(hits, want, "{what}: wide all hits of {ray:?}");
        assert_eq!(
            wide.count_hits(&ray) as usize,
            want.len(),
            "{what}: wide count"
        );
        for max in [1, 2] {
            wide.all_hits(&ray, max, &mut hits);
            let ts: Vec<f32> = want.iter().take(max).map(|h| h.t).collect();
            assert_eq!(
                hits.iter().map(|h| h.t).collect::<Vec<_>>(),
                ts,
                "{what}: wide {max} hits"
            );
        }
    }
}

#[test]
fn mesh_queries_match_brute_force_every_frame() {
    for file in FILES {
        let scene = load(file);
        let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(FRAMES)).unwrap();
        let _ = src.engine(EngineConfig::default());
        let mut flat = TriMesh::default();
        src.flatten_into(&mut flat);
        let mut refitted = MeshBvh::build(&flat, &BuildParams::BINNED);
        let mut wide_refitted = MeshBvh8::from_mesh_bvh(&refitted);
        let mut probe = Probe(7);
        for f in 0..=FRAMES {
            let mut e = src.build(f, EngineConfig::default());
            src.advance(&mut e, f);
            src.flatten_into(&mut flat);
            refitted.refit(&flat);
            wide_refitted.refit(&flat);
            let fresh = MeshBvh::build(&flat, &BuildParams::BINNED);
            check_wide_queries(
                &flat,
                &MeshBvh8::from_mesh_bvh(&fresh),
                &mut probe,
                &format!("{file} frame {f} wide fresh"),
            );
            check_wide_queries(
                &flat,
                &wide_refitted,
                &mut probe,
                &format!("{file} frame {f} wide refit"),
            );
            check_mesh_queries(
                &flat,
                &fresh,
                &mut probe,
                &format!("{file} frame {f} fresh"),
            );
            check_mesh_queries(
                &flat,
                &refitted,
                &mut probe,
                &format!("{file} frame {f} refit"),
            );
        }
    }
}

/// The same queries on a sphere shrunk to 1e-10 and grown to 1e10 (squared distances far from
/// 1), and moved 30,000 and 300,000 units from the origin, where a coordinate's last place is a
/// few per cent and half of a triangle's edge.
#[test]
fn mesh_queries_match_brute_force_at_extreme_scales() {
    let sphere = dynbvh::geom::shapes::bumpy_sphere(3000);
    for (at, scale, offset) in [
        ("1e-10", 1e-10, Vec3::ZERO),
        ("1e10", 1e10, Vec3::ZERO),
        ("an offset of 3e4", 1.0, Vec3::new(3e4, -2e4, 1e4)),
        ("an offset of 3e5", 1.0, Vec3::new(3e5, -2e5, 1e5)),
    ] {
        let mesh = TriMesh::new(
            sphere
                .positions
                .iter()
                .map(|p| *p * scale + offset)
                .collect(),
            sphere.indices.clone(),
        );
        let bvh = MeshBvh::build(&mesh, &BuildParams::BINNED);
        let mut probe = Probe(11);
        check_mesh_queries(&mesh, &bvh, &mut probe, &format!("sphere at {at}"));
        let wide = MeshBvh8::from_mesh_bvh(&bvh);
        check_wide_queries(&mesh, &wide, &mut probe, &format!("sphere at {at}, wide"));
    }
}

/// A sphere of infinite radius takes every triangle whose squared distance is at most
/// infinity, overflowed ones too (a mesh 1e20 across), on both trees as by brute force; an
/// infinite box takes every triangle.
#[test]
fn unbounded_overlaps_match_brute_force() {
    let sphere = dynbvh::geom::shapes::bumpy_sphere(3000);
    let mesh = TriMesh::new(
        sphere.positions.iter().map(|p| *p * 1e20).collect(),
        sphere.indices.clone(),
    );
    let bvh = MeshBvh::build(&mesh, &BuildParams::BINNED);
    let wide = MeshBvh8::from_mesh_bvh(&bvh);
    let mut got = Vec::new();
    for centre in [Vec3::ZERO, Vec3::new(3e20, -1e20, 0.5)] {
        let want = brute_force_overlap_sphere(&mesh, centre, f32::INFINITY);
        // Squared distances past f32::MAX: the case a finite reach would miss.
        let overflowed = mesh.indices.iter().any(|t| {
            let [a, b, c] = t.map(|v| mesh.positions[v as usize]);
            closest_point_on_triangle(centre, a, b, c).distance_squared(centre) == f32::INFINITY
        });
        assert!(
            overflowed && !want.is_empty(),
            "{centre}: the case is not made"
        );
        bvh.overlap_sphere(centre, f32::INFINITY, &mut got);
        assert!(
            got == want,
            "binary, {centre}: {} of {}",
            got.len(),
            want.len()
        );
        wide.overlap_sphere(centre, f32::INFINITY, &mut got);
        assert!(
            got == want,
            "wide, {centre}: {} of {}",
            got.len(),
            want.len()
        );
    }
    let everything = Aabb::new(Vec3::NEG_INFINITY, Vec3::INFINITY);
    let all: Vec<u32> = (0..mesh.len() as u32).collect();
    assert!(
        brute_force_overlap_box(&mesh, everything) == all,
        "brute force box"
    );
    bvh.overlap_box(everything, &mut got);
    assert!(got == all, "binary box: {}", got.len());
    wide.overlap_box(everything, &mut got);
    assert!(got == all, "wide box: {}", got.len());
}

/// Every live instance's world triangles as the engine holds them: `(instance, triangle,
/// corners)`.
fn world_triangles(e: &Engine) -> Vec<(InstanceId, u32, [Vec3; 3])> {
    let mut out = Vec::new();
    for k in 0..e.instance_count() as u32 {
        let i = InstanceId(k);
        if !e.is_live_instance(i) {
            continue;
        }
        let m = e.instance_mesh(i);
        let x = e.transform(i);
        let pos = e.positions(m);
        for (t, tri) in e.indices(m).iter().enumerate() {
            let c = tri.map(|v| {
                if x == Affine3A::IDENTITY {
                    pos[v as usize]
                } else {
                    x.transform_point3(pos[v as usize])
                }
            });
            out.push((i, t as u32, c));
        }
    }
    out
}

/// Brute force of the engine's ray queries: each instance in its own space as the engine
/// carries rays there. Hits sorted by `t`, instance, triangle.
fn brute_hits(e: &Engine, ray: &Ray, filter: &QueryFilter) -> Vec<SceneHit> {
    let mut out = Vec::new();
    for k in 0..e.instance_count() as u32 {
        let i = InstanceId(k);
        if !e.is_live_instance(i)
            || e.instance_mask(i) & filter.mask == 0
            || filter.exclude == Some(i)
        {
            continue;
        }
        let m = e.instance_mesh(i);
        let x = e.transform(i);
        let local = if x == Affine3A::IDENTITY {
            *ray
        } else {
            let inv = x.inverse();
            Ray::with_range(
                inv.transform_point3(ray.origin()),
                inv.transform_vector3(ray.dir()),
                ray.tmin,
                ray.tmax,
            )
        };
        let pre = RayTriPrecomp::new(local.dir());
        let pos = e.positions(m);
        for (t, tri) in e.indices(m).iter().enumerate() {
            let [a, b, c] = tri.map(|v| pos[v as usize]);
            if let Some((th, u, v)) = intersect_triangle(&local, &pre, a, b, c, local.tmax) {
                out.push(SceneHit {
                    t: th,
                    u,
                    v,
                    prim: t as u32,
                    instance: i,
                });
            }
        }
    }
    out.sort_by(|a, b| {
        a.t.total_cmp(&b.t)
            .then(a.instance.cmp(&b.instance))
            .then(a.prim.cmp(&b.prim))
    });
    out
}

fn check_engine_queries(e: &Engine, probe: &mut Probe, what: &str) {
    let world = world_triangles(e);
    let bounds = e.bounds();
    let diag = bounds.extent().length();
    let mut got = Vec::new();
    let mut hits = Vec::new();
    // Random points around the scene, and points on and just off the surface (a corner, a
    // centroid nudged), where rounding decides between neighbours.
    let step = (world.len() / 12).max(1);
    let around: Vec<Vec3> = (0..25).map(|_| probe.point(&bounds, 1.3)).collect();
    let near = world
        .iter()
        .step_by(step)
        .flat_map(|(_, _, [a, b, c])| [*a, (*a + *b + *c) / 3.0 + (*b - *a) * 1e-3]);
    for p in around.into_iter().chain(near) {
        for max_dist in [f32::INFINITY, 0.05 * diag] {
            let want = world
                .iter()
                .map(|(_, _, [a, b, c])| {
                    closest_point_on_triangle(p, *a, *b, *c).distance_squared(p)
                })
                .filter(|d2| d2.sqrt() <= max_dist || *d2 <= max_dist * max_dist)
                .fold(None, |m: Option<f32>, d2| Some(m.map_or(d2, |m| m.min(d2))));
            let have = e.closest_point(p, max_dist);
            assert_eq!(
                have.map(|h| h.distance),
                want.map(f32::sqrt),
                "{what}: closest point of {p} within {max_dist}"
            );
            if let Some(h) = have {
                assert!(e.is_live_instance(h.instance) && e.instance_mesh(h.instance) == h.mesh);
            }
        }
        let q = probe.boxed(&bounds, 0.2);
        e.overlap_box(q, &mut got);
        let want: Vec<(InstanceId, u32)> = world
            .iter()
            .filter(|(_, _, [a, b, c])| triangle_overlaps_box(*a, *b, *c, q))
            .map(|&(i, t, _)| (i, t))
            .collect();
        assert_eq!(got, want, "{what}: box {q:?}");
        let r = 0.1 * diag * probe.f();
        e.overlap_sphere(p, r, &mut got);
        let want: Vec<(InstanceId, u32)> = world
            .iter()
            .filter(|(_, _, [a, b, c])| {
                closest_point_on_triangle(p, *a, *b, *c).distance_squared(p) <= r * r
            })
            .map(|&(i, t, _)| (i, t))
            .collect();
        assert_eq!(got, want, "{what}: sphere {p} {r}");
        let ray = probe.ray(&bounds);
        let want = brute_hits(e, &ray, &QueryFilter::ALL);
        e.all_hits(&ray, usize::MAX, &mut hits);
        assert_eq!(hits, want, "{what}: all hits");
        assert_eq!(e.count_hits(&ray) as usize, want.len(), "{what}: count");
        e.all_hits(&ray, 3, &mut hits);
        let ts: Vec<f32> = want.iter().take(3).map(|h| h.t).collect();
        assert_eq!(
            hits.iter().map(|h| h.t).collect::<Vec<_>>(),
            ts,
            "{what}: 3 hits"
        );
        // The closest hit is the first of all hits; masks and exclusion.
        assert_eq!(
            e.closest_hit(&ray).map(|h| h.t),
            want.first().map(|h| h.t),
            "{what}"
        );
        if let Some(first) = want.first() {
            let f = QueryFilter::ALL.excluding(first.instance);
            let want_f = brute_hits(e, &ray, &f);
            let got_f = e.closest_hit_filtered(&ray, &f);
            assert_eq!(
                got_f.map(|h| h.t),
                want_f.first().map(|h| h.t),
                "{what}: excluded"
            );
            assert!(got_f.is_none_or(|h| h.instance != first.instance));
            assert_eq!(e.any_hit_filtered(&ray, &f), !want_f.is_empty(), "{what}");
            let d = e.hit_detail(first);
            assert_eq!((d.instance, d.prim), (first.instance, first.prim));
            assert!(
                (d.position - ray.at(first.t)).length() <= 1e-3 * diag,
                "{what}: position"
            );
            let (_, _, [a, b, c]) = world
                .iter()
                .find(|(i, t, _)| *i == first.instance && *t == first.prim)
                .unwrap();
            if d.normal != Vec3::ZERO {
                assert!((d.normal.length() - 1.0).abs() < 1e-4);
                let scale = (*b - *a).length().max((*c - *a).length());
                assert!(
                    d.normal.dot(*b - *a).abs() <= 1e-3 * scale,
                    "{what}: normal"
                );
                assert!(
                    d.normal.dot(*c - *a).abs() <= 1e-3 * scale,
                    "{what}: normal"
                );
            }
        }
        // Masks: odd instances on bit 1 only, queries for bit 0 see only the even ones.
        let f = QueryFilter::mask(1);
        let want_m = brute_hits(e, &ray, &f);
        let got_m = e.closest_hit_filtered(&ray, &f);
        assert_eq!(
            got_m.map(|h| h.t),
            want_m.first().map(|h| h.t),
            "{what}: masked"
        );
        assert!(got_m.is_none_or(|h| h.instance.0 % 2 == 0 || e.instance_count() == 1));
    }
}

#[test]
fn engine_queries_match_brute_force_every_frame() {
    for traversal in [Traversal::Wide, Traversal::Binary] {
        for file in FILES {
            let scene = load(file);
            let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(FRAMES)).unwrap();
            let config = EngineConfig {
                traversal,
                ..EngineConfig::default()
            };
            let mut e = src.engine(config);
            if e.instance_count() > 1 {
                for k in (1..e.instance_count() as u32).step_by(2) {
                    e.set_instance_mask(InstanceId(k), 2);
                }
            }
            let mut probe = Probe(11);
            for f in 0..=FRAMES {
                src.advance(&mut e, f);
                e.update();
                check_engine_queries(&e, &mut probe, &format!("{file} {traversal} frame {f}"));
            }
        }
    }
}

#[test]
fn edits_keep_ids_and_answers() {
    let quad = |z: f32| {
        (
            vec![
                Vec3::new(0.0, 0.0, z),
                Vec3::new(1.0, 0.0, z),
                Vec3::new(1.0, 1.0, z),
                Vec3::new(0.0, 1.0, z),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    };
    let mut e = Engine::new(EngineConfig::default());
    let (p, i) = quad(0.0);
    let a = e.add_mesh(p, i);
    let (p, i) = quad(-1.0);
    let b = e.add_mesh(p, i);
    let ia = e.add_instance(a, Affine3A::IDENTITY);
    let ib = e.add_instance(b, Affine3A::IDENTITY);
    let ic = e.add_instance(b, Affine3A::from_translation(Vec3::new(0.0, 0.0, -1.0)));
    e.update();
    let ray = Ray::new(Vec3::new(0.25, 0.75, 1.0), -Vec3::Z);
    let mut hits = Vec::new();
    e.all_hits(&ray, 8, &mut hits);
    assert_eq!(
        hits.iter().map(|h| h.instance).collect::<Vec<_>>(),
        [ia, ib, ic]
    );
    // Remove the first: the others keep their ids.
    e.remove_instance(ia).unwrap();
    e.update();
    assert_eq!(e.closest_hit(&ray).unwrap().instance, ib);
    assert!(e.remove_instance(ia).is_err(), "removed twice");
    assert!(
        e.remove_mesh(b)
            .unwrap_err()
            .to_string()
            .contains("still places it")
    );
    e.remove_mesh(a).unwrap();
    assert!(!e.is_live_mesh(a) && e.is_live_mesh(b));
    // Replace b by one quad higher up: both its instances follow.
    let (p, i) = quad(0.5);
    e.replace_mesh(b, p, i).unwrap();
    e.update();
    e.all_hits(&ray, 8, &mut hits);
    assert_eq!(
        hits.iter().map(|h| (h.instance, h.t)).collect::<Vec<_>>(),
        [(ib, 0.5), (ic, 1.5)]
    );
    assert!(
        e.replace_mesh(b, vec![Vec3::ZERO], vec![[0, 0, 1]])
            .is_err()
    );
    assert!(e.replace_mesh(a, vec![], vec![]).is_err(), "a removed mesh");
    // An emptied mesh drops out of the top-level tree.
    e.replace_mesh(b, vec![], vec![]).unwrap();
    e.update();
    assert!(e.closest_hit(&ray).is_none());
    assert_eq!(e.count_hits(&ray), 0);
    let d = e.add_mesh(quad(-2.0).0, quad(-2.0).1);
    let id = e.add_instance(d, Affine3A::IDENTITY);
    assert_eq!(id, InstanceId(3), "ids are not reused");
    e.update();
    assert_eq!(e.closest_hit(&ray).unwrap().instance, id);
    assert_eq!(
        e.closest_point(Vec3::new(0.5, 0.5, 3.0), 10.0)
            .unwrap()
            .distance,
        5.0
    );
    assert!(e.closest_point(Vec3::new(0.5, 0.5, 3.0), 4.9).is_none());
}

/// From the centre of a sphere every subtree is about as near as the nearest triangle, so the
/// best-first search holds more pending subtrees than it keeps and walks the rest depth first:
/// the answer must still be brute force's, on fresh and refitted binary and wide trees.
#[test]
fn closest_point_from_a_sphere_centre() {
    let mut mesh = dynbvh::geom::shapes::icosphere(5);
    let rest = mesh.positions.clone();
    let mut refitted = MeshBvh::build(&mesh, &BuildParams::BINNED);
    let mut wide_refitted = MeshBvh8::from_mesh_bvh(&refitted);
    // The round sphere first (every triangle nearly as near), then two deformations of it.
    for (amplitude, phase) in [(0.0, 0.0), (0.02, 0.0), (0.02, 0.7)] {
        dynbvh::geom::shapes::sine_deform(&rest, &mut mesh.positions, amplitude, phase);
        refitted.refit(&mesh);
        wide_refitted.refit(&mesh);
        let fresh = MeshBvh::build(&mesh, &BuildParams::BINNED);
        let centre = Aabb::from_points(&mesh.positions).center();
        for p in [centre, centre + Vec3::new(0.01, -0.02, 0.005), Vec3::ZERO] {
            let want = brute_force_closest_point(&mesh, p, f32::INFINITY).map(|h| h.distance);
            assert_eq!(
                fresh.closest_point(p, f32::INFINITY).map(|h| h.distance),
                want
            );
            assert_eq!(
                refitted.closest_point(p, f32::INFINITY).map(|h| h.distance),
                want
            );
        }
    }
}

/// The engine's queries with one instance placed by the identity and others scaled (evenly,
/// unevenly, tiny, far and flattened), sheared, mirrored, turned and moved, under both traversals (the wide one
/// searches placed meshes in their own space, the binary one carries its boxes into the
/// world), against brute force over their world triangles.
#[test]
fn engine_queries_on_placed_and_identity_instances() {
    for traversal in [Traversal::Wide, Traversal::Binary] {
        let sphere = dynbvh::geom::shapes::icosphere(3);
        let mut e = Engine::new(EngineConfig {
            traversal,
            ..EngineConfig::default()
        });
        let mesh = e.add_mesh(sphere.positions.clone(), sphere.indices.clone());
        e.add_instance(mesh, Affine3A::IDENTITY);
        let moved = e.add_instance(
            mesh,
            Affine3A::from_scale_rotation_translation(
                Vec3::splat(0.5),
                dynbvh::glam::Quat::from_rotation_y(0.3),
                Vec3::new(1.6, 0.2, 0.0),
            ),
        );
        e.set_instance_mask(moved, 2);
        let uneven = Affine3A::from_scale_rotation_translation(
            Vec3::new(2.0, 0.3, 1.0),
            dynbvh::glam::Quat::from_euler(dynbvh::glam::EulerRot::XYZ, 0.4, -0.7, 1.1),
            Vec3::new(-1.5, 0.4, 0.9),
        );
        e.add_instance(mesh, uneven);
        let shear = Affine3A::from_cols(
            Vec3::new(0.8, 0.1, 0.0).into(),
            Vec3::new(0.6, 0.7, 0.2).into(),
            Vec3::new(-0.3, 0.0, 0.9).into(),
            Vec3::new(0.2, -1.6, 0.3).into(),
        );
        let sheared = e.add_instance(mesh, shear);
        e.set_instance_mask(sheared, 2);
        let tiny = Affine3A::from_scale_rotation_translation(
            Vec3::splat(1e-3),
            dynbvh::glam::Quat::from_rotation_z(2.0),
            Vec3::new(0.3, 1.4, -0.2),
        );
        e.add_instance(mesh, tiny);
        // Mirrored (a negative determinant: the triangles' winding turns over).
        let mirrored = Affine3A::from_scale_rotation_translation(
            Vec3::new(-0.7, 0.9, 0.8),
            dynbvh::glam::Quat::from_rotation_x(0.6),
            Vec3::new(0.1, -0.3, 1.7),
        );
        let mirrored = e.add_instance(mesh, mirrored);
        e.set_instance_mask(mirrored, 2);
        e.update();
        check_engine_queries(&e, &mut Probe(5), &format!("six spheres, {traversal}"));
        // Far from the origin, where the placed vertices' rounding is largest.
        let mut far = Engine::new(EngineConfig {
            traversal,
            ..EngineConfig::default()
        });
        let m = far.add_mesh(sphere.positions.clone(), sphere.indices.clone());
        for k in 0..3 {
            let x = Affine3A::from_scale_rotation_translation(
                Vec3::new(30.0, 10.0 + 5.0 * k as f32, 20.0),
                dynbvh::glam::Quat::from_rotation_x(0.5 * k as f32),
                Vec3::new(1e5 + 70.0 * k as f32, -2e5, 3e4),
            );
            let i = far.add_instance(m, x);
            if k % 2 == 1 {
                far.set_instance_mask(i, 2);
            }
        }
        far.update();
        check_engine_queries(&far, &mut Probe(9), &format!("far spheres, {traversal}"));
        // Flattened to a near-singular map (its smallest singular value 1e-5 of its largest),
        // which the wide tree cannot search in the mesh's space: its boxes go into the world.
        let mut flat = Engine::new(EngineConfig {
            traversal,
            ..EngineConfig::default()
        });
        let m = flat.add_mesh(sphere.positions.clone(), sphere.indices.clone());
        flat.add_instance(m, Affine3A::IDENTITY);
        let flattened = flat.add_instance(
            m,
            Affine3A::from_scale_rotation_translation(
                Vec3::new(1.5, 1e-5, 0.8),
                dynbvh::glam::Quat::from_rotation_z(0.5),
                Vec3::new(0.4, 1.2, -0.3),
            ),
        );
        flat.set_instance_mask(flattened, 2);
        flat.update();
        check_engine_queries(
            &flat,
            &mut Probe(13),
            &format!("flattened sphere, {traversal}"),
        );
    }
}
