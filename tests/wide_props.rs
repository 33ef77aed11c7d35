//! Wide BVHs (4 and 8 children per node) answer every ray exactly as brute force and the binary
//! tree they were collapsed from do, for every builder, before and after several deformations
//! and refits; also on degenerate inputs and on the watertightness rays of a closed mesh.

mod common;

use common::strategies::{mesh, rays, vec3};
use dynbvh::bvh::{
    BuildParams, Child, CollapseMethod, MAX_DEPTH, MeshBvh, TraversalStats, WideBvh,
    brute_force_any, brute_force_closest,
};
use dynbvh::geom::{Ray, RayTriPrecomp, TriMesh, intersect_triangle};
use glam::Vec3;
use proptest::prelude::*;

/// The common builders, and one whose binary leaves are larger than a wide leaf holds (16):
/// they are split across lanes.
fn builders() -> Vec<BuildParams> {
    let mut b = common::builders();
    b.push(BuildParams {
        max_leaf_size: 40,
        intersection_cost: 0.01,
        ..BuildParams::binned(8)
    });
    b
}

/// One ray through a wide tree against brute force and the binary tree: the same closest
/// distance (a tie may name another triangle, which must really be hit there) and the same
/// any-hit answer.
fn check_ray<const K: usize>(
    mesh: &TriMesh,
    bin: &MeshBvh,
    w: &WideBvh<K>,
    ray: &Ray,
) -> Result<(), String> {
    let want = brute_force_closest(mesh, ray);
    let got = w.closest_hit(ray);
    let binary = bin.closest_hit(ray);
    match (want, got) {
        (None, None) => {}
        (Some(a), Some(g)) => {
            if a.t != g.t {
                return Err(format!(
                    "BVH{K} ray {ray:?}: brute force t {} prim {}, tree t {} prim {}",
                    a.t, a.prim, g.t, g.prim
                ));
            }
            if a.prim != g.prim {
                let [p, q, r] = mesh.triangle(g.prim as usize);
                let pre = RayTriPrecomp::new(ray.dir());
                let t = intersect_triangle(ray, &pre, p, q, r, f32::INFINITY).map(|h| h.0);
                if t != Some(g.t) {
                    return Err(format!(
                        "BVH{K} ray {ray:?}: reports prim {} at {} but it is hit at {t:?}",
                        g.prim, g.t
                    ));
                }
            }
        }
        (a, g) => return Err(format!("BVH{K} ray {ray:?}: brute force {a:?}, tree {g:?}")),
    }
    if binary.map(|h| h.t) != got.map(|h| h.t) {
        return Err(format!(
            "BVH{K} ray {ray:?}: binary {binary:?}, wide {got:?}"
        ));
    }
    let (wa, ga) = (brute_force_any(mesh, ray), w.any_hit(ray));
    if wa != ga {
        return Err(format!(
            "BVH{K} ray {ray:?}: any hit brute force {wa}, tree {ga}"
        ));
    }
    // Counting changes nothing.
    let mut st = TraversalStats::default();
    if w.closest_hit_counted(ray, &mut st) != got || w.any_hit_counted(ray, &mut st) != ga {
        return Err(format!("BVH{K} ray {ray:?}: counted traversal differs"));
    }
    Ok(())
}

/// Both collapses.
const METHODS: [CollapseMethod; 2] = [CollapseMethod::Greedy, CollapseMethod::SAH];

fn check_both(mesh: &TriMesh, bin: &MeshBvh, rays: &[Ray]) -> Result<(), String> {
    for method in METHODS {
        let w4 = WideBvh::<4>::from_mesh_bvh_with(bin, method);
        let w8 = WideBvh::<8>::from_mesh_bvh_with(bin, method);
        w4.validate(mesh)?;
        w8.validate(mesh)?;
        for ray in rays {
            check_ray(mesh, bin, &w4, ray).map_err(|e| format!("{method:?}: {e}"))?;
            check_ray(mesh, bin, &w8, ray).map_err(|e| format!("{method:?}: {e}"))?;
        }
    }
    Ok(())
}

/// The given rays plus rays aimed at the mesh's vertices (where ties between triangles happen).
fn with_aimed(mesh: &TriMesh, rays: &[Ray]) -> Vec<Ray> {
    let from = Vec3::new(0.3, 11.0, -0.7);
    rays.iter()
        .copied()
        .chain(
            mesh.positions
                .iter()
                .take(20)
                .map(|&p| Ray::new(from, p - from))
                .filter(|r| r.dir().length() > 0.0),
        )
        .collect()
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 128, ..ProptestConfig::default() })]

    #[test]
    fn every_builder_collapsed_matches_brute_force(mesh in mesh(120, 10), rays in rays(1..40)) {
        let rays = with_aimed(&mesh, &rays);
        for params in builders() {
            let bin = MeshBvh::build(&mesh, &params);
            check_both(&mesh, &bin, &rays).map_err(TestCaseError::fail)?;
        }
    }

    #[test]
    fn wide_refit_after_deformations_matches_brute_force(
        mesh in mesh(120, 10),
        moves in prop::collection::vec((prop::collection::vec(vec3(), 1..8), 0.0f32..3.0), 3),
        rays in rays(1..40),
    ) {
        for (params, method) in builders().into_iter().flat_map(|p| METHODS.map(|m| (p, m))) {
            let mut m = mesh.clone();
            let mut bin = MeshBvh::build(&m, &params);
            let mut w4 = WideBvh::<4>::from_mesh_bvh_with(&bin, method);
            let mut w8 = WideBvh::<8>::from_mesh_bvh_with(&bin, method);
            // Several deformations in a row, each refitted from the previous trees.
            for (offsets, scale) in &moves {
                for (i, p) in m.positions.iter_mut().enumerate() {
                    *p += offsets[i % offsets.len()] * *scale * (1.0 + (i % 3) as f32);
                }
                bin.refit(&m);
                w4.refit(&m);
                w8.refit_indexed(&m.positions, &m.indices);
                w4.validate(&m).map_err(TestCaseError::fail)?;
                w8.validate(&m).map_err(TestCaseError::fail)?;
                for ray in with_aimed(&m, &rays) {
                    check_ray(&m, &bin, &w4, &ray).map_err(TestCaseError::fail)?;
                    check_ray(&m, &bin, &w8, &ray).map_err(TestCaseError::fail)?;
                }
            }
        }
    }
}

/// Every builder, collapsed, checked; then refitted to the same positions and checked again.
fn check_everything(mesh: &TriMesh, rays: &[Ray]) {
    for params in builders() {
        let bin = MeshBvh::build(mesh, &params);
        check_both(mesh, &bin, rays).unwrap_or_else(|e| panic!("{}: {e}", params.name()));
        for method in METHODS {
            let mut w8 = WideBvh::<8>::from_mesh_bvh_with(&bin, method);
            let mut w4 = WideBvh::<4>::from_mesh_bvh_with(&bin, method);
            w8.refit(mesh);
            w4.refit(mesh);
            w8.validate(mesh).unwrap();
            w4.validate(mesh).unwrap();
            for ray in rays {
                check_ray(mesh, &bin, &w4, ray)
                    .unwrap_or_else(|e| panic!("{}: {e}", params.name()));
                check_ray(mesh, &bin, &w8, ray)
                    .unwrap_or_else(|e| panic!("{}: {e}", params.name()));
            }
        }
    }
}

#[test]
fn empty_mesh() {
    let mesh = TriMesh::default();
    let bin = MeshBvh::build(&mesh, &BuildParams::BINNED);
    let mut w = WideBvh::<8>::from_mesh_bvh(&bin);
    w.validate(&mesh).unwrap();
    assert!(w.nodes().is_empty());
    assert!(w.closest_hit(&Ray::new(Vec3::ZERO, Vec3::X)).is_none());
    assert!(!w.any_hit(&Ray::new(Vec3::ZERO, Vec3::X)));
    w.refit(&mesh);
    let w4 = WideBvh::<4>::build(&mesh, &BuildParams::BINNED);
    assert!(w4.closest_hit(&Ray::new(Vec3::ZERO, Vec3::X)).is_none());
    assert_eq!(w4.memory_bytes(), 0);
}

#[test]
fn single_triangle() {
    let mesh = TriMesh::from_soup(&[[Vec3::ZERO, Vec3::X, Vec3::Y]]);
    check_everything(
        &mesh,
        &common::rays_around(Vec3::new(0.3, 0.3, 0.0), 1.0, 200, 1),
    );
    let w = WideBvh::<8>::build(&mesh, &BuildParams::BINNED);
    assert_eq!(w.nodes().len(), 1);
    let hit = w
        .closest_hit(&Ray::new(Vec3::new(0.25, 0.25, 1.0), -Vec3::Z))
        .unwrap();
    assert_eq!((hit.t, hit.prim), (1.0, 0));
}

#[test]
fn identical_triangles() {
    let t = [
        Vec3::new(-1.0, -1.0, 0.0),
        Vec3::new(1.0, -1.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
    ];
    let mesh = TriMesh::from_soup(&vec![t; 3000]);
    check_everything(&mesh, &common::rays_around(Vec3::ZERO, 1.0, 50, 3));
}

#[test]
fn nan_and_infinite_vertices() {
    let mesh = common::soup_with_nan_and_inf();
    let rays = common::rays_around(Vec3::ZERO, 1.0, 300, 5);
    for (params, method) in builders().into_iter().flat_map(|p| METHODS.map(|m| (p, m))) {
        let bin = MeshBvh::build(&mesh, &params);
        let mut w8 = WideBvh::<8>::from_mesh_bvh_with(&bin, method);
        let mut w4 = WideBvh::<4>::from_mesh_bvh_with(&bin, method);
        for _round in 0..2 {
            for ray in &rays {
                check_ray(&mesh, &bin, &w4, ray).unwrap_or_else(|e| panic!("{e}"));
                check_ray(&mesh, &bin, &w8, ray).unwrap_or_else(|e| panic!("{e}"));
            }
            w8.refit(&mesh);
            w4.refit(&mesh);
        }
    }
}

#[test]
fn deep_chain_uses_a_deep_stack() {
    // Triangles at exponentially spaced positions: the SAH peels off one at a time, so the
    // binary tree reaches the depth limit and the wide tree's stack bound is large.
    let tris: Vec<[Vec3; 3]> = (0..2000)
        .map(|i| {
            let x = 2f32.powf((i % 250) as f32 * 0.5 - 60.0) * if i % 2 == 0 { 1.0 } else { -1.0 };
            let p = Vec3::new(x, (i / 250) as f32, 0.0);
            let s = x.abs() * 1e-3;
            [p, p + Vec3::new(s, 0.0, 0.0), p + Vec3::new(0.0, s, s)]
        })
        .collect();
    let mesh = TriMesh::from_soup(&tris);
    let mut rays = common::rays_around(Vec3::new(0.0, 4.0, 0.0), 8.0, 200, 9);
    // Rays along the chain, through many of its nodes.
    for y in 0..8 {
        rays.push(Ray::new(Vec3::new(-1e30, y as f32 + 1e-9, 0.0), Vec3::X));
        rays.push(Ray::new(Vec3::new(1e30, y as f32, 0.0), -Vec3::X));
    }
    for params in [BuildParams::BINNED, BuildParams::SWEEP] {
        let bin = MeshBvh::build(&mesh, &params);
        assert!(bin.bvh().depth() <= MAX_DEPTH);
        check_both(&mesh, &bin, &rays).unwrap_or_else(|e| panic!("{}: {e}", params.name()));
    }
}

#[test]
fn large_trees_refit_in_parallel_and_on_one_thread() {
    // Large enough for the parallel refit (gather, then subtrees as tasks) on two threads.
    let rest = dynbvh::geom::shapes::bumpy_sphere(60_000);
    let mut moved = rest.positions.clone();
    dynbvh::geom::shapes::sine_deform(&rest.positions, &mut moved, 0.1, 0.3);
    let deformed = TriMesh::new(moved, rest.indices.clone());
    let bin = MeshBvh::build(&rest, &BuildParams::BINNED);
    let mut bin_def = bin.clone();
    bin_def.refit(&deformed);
    let b = rest.bounds();
    let rays = dynbvh::report::rays::random_rays(&b, 150, 42);
    for threads in [1, 2] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            for method in METHODS {
                let mut w4 = WideBvh::<4>::from_mesh_bvh_with(&bin, method);
                let mut w8 = WideBvh::<8>::from_mesh_bvh_with(&bin, method);
                assert!(w8.nodes().len() > 2048, "{} nodes", w8.nodes().len());
                for (m, b) in [(&deformed, &bin_def), (&rest, &bin), (&deformed, &bin_def)] {
                    w4.refit(m);
                    w8.refit(m);
                    w4.validate(m).unwrap();
                    w8.validate(m).unwrap();
                    for ray in &rays {
                        check_ray(m, b, &w4, ray).unwrap();
                        check_ray(m, b, &w8, ray).unwrap();
                    }
                }
            }
        });
    }
}

#[test]
fn large_collapses_on_several_threads_are_the_one_thread_collapse() {
    // Large enough for the root's subtrees to be collapsed in parallel and the blocks to be
    // filled in parallel (runs of nodes as tasks); the second mesh adds a far triangle, which
    // the root keeps as a leaf lane among the subtrees.
    let sphere = dynbvh::geom::shapes::bumpy_sphere(60_000);
    let mut far = sphere.clone();
    let v = far.positions.len() as u32;
    far.positions.extend([
        Vec3::new(90.0, 0.0, 0.0),
        Vec3::new(90.5, 0.0, 0.0),
        Vec3::new(90.0, 0.5, 0.0),
    ]);
    far.indices.push([v, v + 1, v + 2]);
    for (mesh, far_leaf) in [(sphere, false), (far, true)] {
        let bin = MeshBvh::build(&mesh, &BuildParams::BINNED);
        let on = |threads: usize, method: CollapseMethod| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| WideBvh::<8>::from_mesh_bvh_with(&bin, method))
        };
        for method in METHODS {
            let one = on(1, method);
            assert!(one.nodes().len() > 2048, "{} nodes", one.nodes().len());
            let root = one.nodes()[0];
            let kinds = (0..8)
                .map(|k| root.child(k))
                .fold([0; 2], |[l, n], c| match c {
                    Child::Leaf { .. } => [l + 1, n],
                    Child::Node(_) => [l, n + 1],
                    Child::Empty => [l, n],
                });
            assert!(kinds[1] >= 2, "root lanes (leaves, nodes): {kinds:?}");
            if far_leaf && method == CollapseMethod::Greedy {
                assert!(kinds[0] >= 1, "the far triangle is no root leaf: {kinds:?}");
            }
            for threads in [2, 3] {
                let w = on(threads, method);
                assert_eq!(w.nodes(), one.nodes(), "{threads} threads");
                assert_eq!(format!("{:?}", w.blocks()), format!("{:?}", one.blocks()));
            }
            one.validate(&mesh).unwrap();
        }
    }
}

#[test]
fn collapse_into_used_storage_gives_the_fresh_collapse() {
    // Into the storage of a larger tree, then of a smaller one (the storage grows).
    let big = dynbvh::geom::shapes::bumpy_sphere(20_000);
    let small = dynbvh::geom::shapes::bumpy_sphere(3_000);
    let bin_big = MeshBvh::build(&big, &BuildParams::BINNED);
    let bin_small = MeshBvh::build(&small, &BuildParams::BINNED);
    for (from, to, mesh) in [(&bin_big, &bin_small, &small), (&bin_small, &bin_big, &big)] {
        for method in METHODS {
            let mut w = WideBvh::<8>::from_mesh_bvh_with(from, method);
            w.collapse_from(to);
            let fresh = WideBvh::<8>::from_mesh_bvh_with(to, method);
            assert_eq!(w.nodes(), fresh.nodes());
            // Every block written anew, none left from the tree before (unused lanes are NaN,
            // so compared as printed).
            assert_eq!(format!("{:?}", w.blocks()), format!("{:?}", fresh.blocks()));
            assert_eq!(w.prim_count(), fresh.prim_count());
            w.validate(mesh).unwrap();
            let rays = dynbvh::report::rays::random_rays(&mesh.bounds(), 100, 7);
            for ray in &rays {
                check_ray(mesh, to, &w, ray).unwrap();
            }
        }
    }
}

/// The boxes a collapse writes are those a refit to the same positions computes, bit for bit
/// (a refit of an unmoved mesh changes nothing): every builder (binary leaves split across
/// lanes too), both collapses, on meshes with NaN coordinates, infinite vertices, one point, a
/// random soup and a sphere.
#[test]
fn collapsed_boxes_are_the_refits() {
    let mut soup = Vec::new();
    let mut seed = 0x2545_f491_u64;
    let mut next = move || {
        seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
        ((seed >> 40) as f32 / (1u64 << 24) as f32) * 2.0 - 1.0
    };
    for _ in 0..3000 {
        let c = Vec3::new(next(), next(), next()) * 10.0;
        soup.push([(); 3].map(|()| c + Vec3::new(next(), next(), next())));
    }
    let mut partial_nan = soup.clone();
    for (i, t) in partial_nan.iter_mut().enumerate().step_by(37) {
        t[i % 3][i % 2] = f32::NAN;
        if i % 3 == 0 {
            // A whole axis without a number.
            for v in t.iter_mut() {
                v.z = f32::NAN;
            }
        }
    }
    let meshes = [
        ("soup", TriMesh::from_soup(&soup)),
        (
            "soup with NaN coordinates",
            TriMesh::from_soup(&partial_nan),
        ),
        ("NaN and infinite vertices", common::soup_with_nan_and_inf()),
        ("one point", TriMesh::from_soup(&vec![[Vec3::ONE; 3]; 40])),
        ("sphere", dynbvh::geom::shapes::icosphere(4)),
    ];
    for (name, mesh) in &meshes {
        for (params, method) in builders().into_iter().flat_map(|p| METHODS.map(|m| (p, m))) {
            let bin = MeshBvh::build(mesh, &params);
            let w = WideBvh::<8>::from_mesh_bvh_with(&bin, method);
            let mut r = w.clone();
            r.refit(mesh);
            for (i, (a, b)) in w.nodes().iter().zip(r.nodes()).enumerate() {
                let bits = |n: &dynbvh::bvh::WideNode<8>| n.bounds.map(|row| row.map(f32::to_bits));
                assert_eq!(
                    bits(a),
                    bits(b),
                    "{name}, {} {method:?}: node {i} collapsed {:?} refitted {:?}",
                    params.name(),
                    a.bounds,
                    b.bounds
                );
            }
        }
    }
}
