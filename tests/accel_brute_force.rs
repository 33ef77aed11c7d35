//! The course's other structures (kd-tree with both builders, BIH, grid, two-level grid,
//! octree) against brute force: closest hit (same distance; another triangle only at a tie) and
//! any hit on every ray set, on every frame of the shipped animations and of the animated glTF
//! samples (rebuilt each frame, and the BIH also refitted from the first frame), on rays along
//! the axes, through the vertices and edges of closed meshes, lying in split planes, on
//! degenerate inputs, and at extreme scales and far from the origin (with the BVH beside them).
//! `validate` runs after every build and refit.

mod common;

use common::{Rng, mesh_hit, rays_around, same_closest};
use dynbvh::accel::{
    Accel, AccelKind, Bih, BihParams, Grid, GridParams, KdBuild, KdParams, KdTree, Octree,
    OctreeParams,
};
use dynbvh::anim::Scene;
use dynbvh::bvh::{BuildParams, MeshBvh, brute_force_any, brute_force_closest};
use dynbvh::engine::{Engine, EngineConfig};
use dynbvh::geom::{Ray, TriMesh, shapes};
use dynbvh::report::rays::{camera_rays, random_rays};
use glam::{Affine3A, Vec3};
use std::path::{Path, PathBuf};

/// Every structure, with the defaults and with settings that take their rarer paths.
fn structures(mesh: &TriMesh) -> Vec<Box<dyn Accel>> {
    let mut v: Vec<Box<dyn Accel>> = AccelKind::ALL.iter().map(|k| k.build(mesh)).collect();
    v.push(Box::new(KdTree::build(
        mesh,
        &KdParams {
            max_depth: Some(3),
            ..KdParams::default()
        },
    )));
    v.push(Box::new(KdTree::build(
        mesh,
        &KdParams {
            intersection_cost: 20.0,
            empty_bonus: 0.5,
            ..KdParams::NAIVE
        },
    )));
    // Perfect splits in every node, in none, and in the nodes of more than 8 triangles; the
    // other setting of the axes swept; in both builders.
    let d = KdParams::default();
    for params in [KdParams::default(), KdParams::NAIVE] {
        for perfect_splits_above in [0, 8, usize::MAX] {
            v.push(Box::new(KdTree::build(
                mesh,
                &KdParams {
                    perfect_splits_above,
                    longest_axis_only: !d.longest_axis_only,
                    intersection_cost: 1.0,
                    ..params
                },
            )));
        }
    }
    // Leaves of one triangle; the SAH tried at every node of 256 triangles or more, and nowhere.
    for sah_share in [usize::MAX, 0] {
        v.push(Box::new(Bih::build(
            mesh,
            &BihParams {
                max_leaf_size: 1,
                sah_share,
            },
        )));
    }
    for density in [0.05, 8.0] {
        v.push(Box::new(Grid::build(
            mesh,
            &GridParams {
                density,
                ..GridParams::default()
            },
        )));
    }
    v.push(Box::new(Octree::build(
        mesh,
        &OctreeParams {
            max_leaf_size: 1,
            max_depth: 20,
            max_growth: 8,
        },
    )));
    v
}

/// Brute force's closest and any-hit answers for each ray.
type Answers = Vec<(Option<dynbvh::geom::Hit>, bool)>;

fn brute_force(mesh: &TriMesh, rays: &[Ray]) -> Answers {
    rays.iter()
        .map(|r| (brute_force_closest(mesh, r), brute_force_any(mesh, r)))
        .collect()
}

/// Checks every ray against brute force; returns the failures, one line each (at most 5).
fn compare(what: &str, mesh: &TriMesh, s: &dyn Accel, rays: &[Ray], want: &Answers) -> Vec<String> {
    let mut bad = Vec::new();
    for (i, (r, &(closest, any))) in rays.iter().zip(want).enumerate() {
        let got = s.closest_hit(r);
        if !same_closest(mesh, r, closest, got) {
            bad.push(format!(
                "{what} {}: ray {i} {r:?}: brute force {closest:?}, structure {got:?}",
                s.name()
            ));
        }
        if s.any_hit(r) != any {
            bad.push(format!(
                "{what} {}: ray {i} any hit: brute force {any}, structure {}",
                s.name(),
                !any
            ));
        }
        if bad.len() >= 5 {
            break;
        }
    }
    bad
}

/// Builds every structure, validates it and compares it on `rays`.
fn check_all(what: &str, mesh: &TriMesh, rays: &[Ray]) -> Answers {
    let want = brute_force(mesh, rays);
    let mut bad = Vec::new();
    for s in structures(mesh) {
        if let Err(e) = s.validate(mesh) {
            bad.push(format!("{what} {}: invalid: {e}", s.name()));
        }
        bad.extend(compare(what, mesh, s.as_ref(), rays, &want));
    }
    assert!(bad.is_empty(), "{}", bad.join("\n"));
    want
}

/// Rays around the mesh, camera rays, random rays, and rays along every axis through a grid of
/// points.
fn ray_sets(mesh: &TriMesh, n: usize, seed: u64) -> Vec<Ray> {
    let b = mesh.bounds();
    let (c, r) = (b.center(), b.extent().max_element().max(1e-3));
    let mut rays = rays_around(c, r, n, seed);
    rays.extend(camera_rays(&b, 24, 24));
    rays.extend(random_rays(&b, n, seed + 1));
    rays.extend(axis_rays(&b, 9));
    rays
}

/// Rays along ±x, ±y, ±z from outside the box, on a `k × k` grid of points of each face.
fn axis_rays(b: &dynbvh::geom::Aabb, k: usize) -> Vec<Ray> {
    let mut rays = Vec::new();
    let e = b.extent();
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for i in 0..k {
            for j in 0..k {
                let mut o = b.min;
                o[u] += e[u] * (i as f32 + 0.5) / k as f32;
                o[v] += e[v] * (j as f32 + 0.5) / k as f32;
                let mut d = Vec3::ZERO;
                d[axis] = 1.0;
                o[axis] = b.min[axis] - e[axis] - 1.0;
                rays.push(Ray::new(o, d));
                o[axis] = b.max[axis] + e[axis] + 1.0;
                rays.push(Ray::new(o, -d));
            }
        }
    }
    rays
}

#[test]
fn spheres_and_soups_match_brute_force() {
    let sphere = shapes::bumpy_sphere(20_000);
    check_all("bumpy sphere", &sphere, &ray_sets(&sphere, 600, 1));
    let mut rng = Rng(5);
    let soup = TriMesh::from_soup(&rng.soup(3000, 0.03));
    check_all("soup", &soup, &ray_sets(&soup, 600, 2));
    // Grids too large for the cache, where the build sorts the triangles it enters: a soup,
    // and a row of small triangles followed by a soup (the first ones counted as they came).
    let big_soup = rng.soup(12_000, 0.02);
    let row: Vec<[Vec3; 3]> = (0..6000)
        .map(|i| {
            let p = Vec3::new(i as f32 / 6000.0, 0.5, 0.5);
            [p, p + Vec3::X * 1e-4, p + Vec3::Z * 1e-4]
        })
        .collect();
    let row_then_soup = TriMesh::from_soup(&[row, big_soup.clone()].concat());
    let big_soup = TriMesh::from_soup(&big_soup);
    let fine = GridParams {
        density: GridParams::MAX_DENSITY,
        ..GridParams::default()
    };
    for (what, mesh) in [("row, then a soup", &row_then_soup), ("soup", &big_soup)] {
        let rays = ray_sets(mesh, 300, 6);
        let g = Grid::build(mesh, &fine);
        let cells: u32 = g.resolution().iter().product();
        assert!(cells > 1 << 19, "{what}: {cells} cells fit in the cache");
        g.validate(mesh).unwrap();
        let bad = compare(what, mesh, &g, &rays, &brute_force(mesh, &rays));
        assert!(bad.is_empty(), "{}", bad.join("\n"));
    }
    let hostile = common::soup_with_nan_and_inf();
    check_all("NaN and inf soup", &hostile, &ray_sets(&hostile, 300, 3));
}

/// Floats fail at extreme scales: a sphere and a soup shrunk to 1e-16 and 1e-10 and grown to
/// 1e10 (every area, product and plane distance far from 1; the triangle test's scaled distance
/// is a cube of the coordinates, which underflows f32 below about 1e-13), and moved 30,000 units from the origin, where
/// a coordinate's last place (about 0.002) is a few per cent of a triangle's edge, and 300,000,
/// where it is half an edge. The BVH beside them, binary and in the engine (8-wide).
#[test]
fn extreme_scales_and_far_offsets_match_brute_force() {
    let sphere = shapes::bumpy_sphere(5000);
    let soup = TriMesh::from_soup(&Rng(11).soup(1500, 0.03));
    for (at, scale, offset) in [
        ("1e-16", 1e-16, Vec3::ZERO),
        ("1e-10", 1e-10, Vec3::ZERO),
        ("1e10", 1e10, Vec3::ZERO),
        ("an offset of 3e4", 1.0, Vec3::new(3e4, -2e4, 1e4)),
        ("an offset of 3e5", 1.0, Vec3::new(3e5, -2e5, 1e5)),
    ] {
        for (name, m) in [("sphere", &sphere), ("soup", &soup)] {
            let moved = TriMesh::new(
                m.positions.iter().map(|p| *p * scale + offset).collect(),
                m.indices.clone(),
            );
            let rays = ray_sets(&moved, 200, 12);
            let what = format!("{name} at {at}");
            let hits = check_all(&what, &moved, &rays);
            let n = hits.iter().filter(|(c, _)| c.is_some()).count();
            let bvh = MeshBvh::build(&moved, &BuildParams::BINNED);
            bvh.validate(&moved).unwrap();
            let mut bad = compare(&what, &moved, &bvh, &rays, &hits);
            let mut engine = Engine::new(EngineConfig::default());
            let id = engine.add_mesh(moved.positions.clone(), moved.indices.clone());
            engine.add_instance(id, Affine3A::IDENTITY);
            engine.update();
            for (i, (r, &(closest, any))) in rays.iter().zip(&hits).enumerate() {
                let got = engine.closest_hit(r).map(mesh_hit);
                if !same_closest(&moved, r, closest, got) || engine.any_hit(r) != any {
                    bad.push(format!(
                        "{what} engine: ray {i}: brute force {closest:?}, {got:?}"
                    ));
                }
            }
            assert!(bad.is_empty(), "{}", bad.join("\n"));
            assert!(
                n > rays.len() / 10,
                "{name} at {at}: {n} of {} rays hit",
                rays.len()
            );
        }
    }
}

/// A closed box made of unit quads on the integer lattice: its edges, vertices and the split
/// planes (which lie at the triangles' box faces) are all at integer coordinates.
fn lattice_box(n: u32) -> TriMesh {
    let mut tris = Vec::new();
    let f = n as f32;
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for side in [0.0, f] {
            for i in 0..n {
                for j in 0..n {
                    let corner = |a: u32, b: u32| {
                        let mut p = Vec3::ZERO;
                        p[axis] = side;
                        p[u] = (i + a) as f32;
                        p[v] = (j + b) as f32;
                        p
                    };
                    tris.push([corner(0, 0), corner(1, 0), corner(1, 1)]);
                    tris.push([corner(0, 0), corner(1, 1), corner(0, 1)]);
                }
            }
        }
    }
    // Share the vertices, so that the mesh is closed.
    let mut mesh = TriMesh::default();
    let mut index = std::collections::HashMap::new();
    for t in tris {
        let ids = t.map(|p| {
            *index
                .entry(p.to_array().map(f32::to_bits))
                .or_insert_with(|| {
                    mesh.positions.push(p);
                    mesh.positions.len() as u32 - 1
                })
        });
        mesh.indices.push(ids);
    }
    mesh
}

#[test]
fn rays_through_edges_vertices_and_split_planes_match_brute_force() {
    let mesh = lattice_box(6);
    let c = Vec3::splat(3.0);
    let mut rays = Vec::new();
    // Through every vertex and edge midpoint, from inside and from outside.
    for t in &mesh.indices {
        let p = t.map(|i| mesh.positions[i as usize]);
        for q in [
            p[0],
            (p[0] + p[1]) * 0.5,
            (p[1] + p[2]) * 0.5,
            (p[0] + p[2]) * 0.5,
        ] {
            rays.push(Ray::new(c + Vec3::new(0.1, 0.2, 0.3), q - c));
            let o = q * 2.0 - c + Vec3::new(0.3, -0.7, 0.5);
            rays.push(Ray::new(o, q - o));
        }
    }
    // In the planes x = k, y = k, z = k (where the splits lie), along the other axes and
    // diagonally within the plane, from outside and from inside.
    for axis in 0..3 {
        let (u, v) = ((axis + 1) % 3, (axis + 2) % 3);
        for k in 0..=6 {
            for j in 0..=12 {
                let mut o = Vec3::splat(-1.0);
                o[axis] = k as f32;
                o[v] = j as f32 * 0.5;
                let mut d = Vec3::ZERO;
                d[u] = 1.0;
                rays.push(Ray::new(o, d));
                let mut inside = c;
                inside[axis] = k as f32;
                d[v] = 0.5 - j as f32 / 12.0;
                rays.push(Ray::new(inside, d));
                rays.push(Ray::new(inside, -d));
            }
        }
    }
    check_all("lattice box", &mesh, &rays);
    let sphere = shapes::icosphere(3);
    let inner = Vec3::new(0.01, -0.02, 0.03);
    let mut rays = common::aimed(&sphere, Vec3::new(3.0, 2.0, 1.0));
    rays.extend(sphere.positions.iter().map(|&p| Ray::new(inner, p - inner)));
    check_all("icosphere vertices", &sphere, &rays);
}

#[test]
fn degenerate_inputs_match_brute_force() {
    // Every triangle in the plane z = 0.
    let mut rng = Rng(9);
    let flat: Vec<[Vec3; 3]> = (0..500)
        .map(|_| {
            let p = Vec3::new(rng.f(), rng.f(), 0.0);
            let q = |r: &mut Rng| p + Vec3::new(r.range(-0.1, 0.1), r.range(-0.1, 0.1), 0.0);
            [p, q(&mut rng), q(&mut rng)]
        })
        .collect();
    let flat = TriMesh::from_soup(&flat);
    let mut rays = ray_sets(&flat, 300, 4);
    rays.push(Ray::new(Vec3::new(-1.0, 0.5, 0.0), Vec3::X));
    check_all("coplanar", &flat, &rays);
    // Every centroid in one point: triangles of all sizes and orientations around it.
    let centred: Vec<[Vec3; 3]> = (0..400)
        .map(|i| {
            let s = 0.01 + i as f32 * 0.002;
            let (a, b) = (rng.unit_vector() * s, rng.unit_vector() * s);
            [a, b, -a - b]
        })
        .collect();
    let centred = TriMesh::from_soup(&centred);
    check_all("one centroid", &centred, &ray_sets(&centred, 300, 5));
    // The same triangle many times.
    let same = TriMesh::from_soup(&[[Vec3::ZERO, Vec3::X, Vec3::Y]; 64]);
    check_all("one triangle 64 times", &same, &ray_sets(&same, 100, 6));
    let one = TriMesh::from_soup(&[[Vec3::ZERO, Vec3::X, Vec3::Y]]);
    check_all("one triangle", &one, &ray_sets(&one, 100, 7));
    let empty = TriMesh::default();
    check_all("empty", &empty, &rays_around(Vec3::ZERO, 1.0, 20, 8));
}

#[test]
fn sorted_and_naive_kd_builds_make_the_same_tree() {
    for mesh in [
        shapes::bumpy_sphere(5000),
        lattice_box(5),
        common::soup_with_nan_and_inf(),
    ] {
        for (perfect_splits_above, longest_axis_only) in [
            (usize::MAX, false),
            (usize::MAX, true),
            (0, false),
            (0, true),
            (8, true),
        ] {
            let fast = KdTree::build(
                &mesh,
                &KdParams {
                    perfect_splits_above,
                    longest_axis_only,
                    ..KdParams::default()
                },
            );
            let naive = KdTree::build(
                &mesh,
                &KdParams {
                    perfect_splits_above,
                    longest_axis_only,
                    ..KdParams::NAIVE
                },
            );
            assert_eq!(naive.params().build, KdBuild::Naive);
            assert_eq!(fast.nodes(), naive.nodes());
            assert_eq!(fast.depth(), naive.depth());
            assert_eq!(fast.reference_count(), naive.reference_count());
            assert_eq!(fast.sah(), naive.sah());
            assert!(fast.nodes() > 1);
        }
    }
}

fn samples_dir() -> Option<PathBuf> {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../shared/gltf-samples");
    if dir.is_dir() {
        return Some(dir);
    }
    let msg = format!(
        "!!!!! glTF samples folder {} is missing: sample-file structure tests SKIPPED !!!!!",
        dir.display()
    );
    assert!(std::env::var_os("CI").is_none(), "{msg} (CI is set)");
    eprintln!("{msg}");
    None
}

fn gltf_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            if p.file_name().is_some_and(|n| n == "_meta") {
                continue;
            }
            gltf_files(&p, out);
        } else if p
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("glb") || e.eq_ignore_ascii_case("gltf"))
        {
            out.push(p);
        }
    }
}

/// Frames checked per animation.
const FRAMES: usize = 24;

/// Every frame of every animation of `path`: every structure rebuilt, and a BIH built on the
/// first frame refitted through the others; returns the frames checked.
fn check_file(path: &Path) -> usize {
    let (scene, _) = Scene::load(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut frames = 0;
    for a in 0..scene.animations.len() {
        let duration = scene.animations[a].duration;
        let mut poser = scene.poser(Some(a)).unwrap();
        let mut mesh = TriMesh::default();
        let mut refitted: Option<Bih> = None;
        for f in 0..FRAMES {
            poser.pose(duration * f as f32 / (FRAMES - 1) as f32);
            poser.flatten_into(&mut mesh);
            let what = format!("{} animation {a} frame {f}", path.display());
            let rays = ray_sets(&mesh, 120, f as u64);
            let want = check_all(&what, &mesh, &rays);
            let bih = refitted.get_or_insert_with(|| Bih::build(&mesh, &BihParams::default()));
            assert!(bih.refit(&mesh));
            bih.validate(&mesh)
                .unwrap_or_else(|e| panic!("{what}: refitted BIH: {e}"));
            let bad = compare(&format!("{what} refitted"), &mesh, bih, &rays, &want);
            assert!(bad.is_empty(), "{}", bad.join("\n"));
            frames += 1;
        }
    }
    frames
}

#[test]
fn shipped_animations_match_brute_force_every_frame() {
    let dir = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("animations");
    let mut files = Vec::new();
    gltf_files(&dir, &mut files);
    assert!(
        files.len() >= 5,
        "expected the generated animations in {}",
        dir.display()
    );
    for f in &files {
        assert!(check_file(f) > 0, "{} has no animation", f.display());
    }
}

#[test]
fn animated_samples_match_brute_force_every_frame() {
    let Some(dir) = samples_dir() else { return };
    let mut files = Vec::new();
    gltf_files(&dir, &mut files);
    let animated = files.iter().filter(|f| check_file(f) > 0).count();
    assert!(
        animated >= 10,
        "only {animated} animated sample files found"
    );
}
