//! Closest-point queries of dynbvh (binary and 8-wide trees) against parry3d's point
//! projection on the same mesh, one thread, interleaved repeat by repeat in one run:
//! `sphere_1m` (1,003,520 triangles) from the shared benchmark inputs
//! (`../shared/bench-inputs/gen.rs`), query points within 1% of the box diagonal of the
//! surface (a random point of a random triangle moved by a random offset up to that length).
//! Then the deformed mesh (`sphere_1m_def`): dynbvh's trees refitted from the rest mesh against
//! fresh builds on the deformed one, each kind against its own. Every answer's distance is checked
//! against parry's (the same nearest distance to within rounding) before timing.
//!
//! `DYNBVH_BENCH_INPUTS=DIR cargo bench --features peers --bench peers_queries` (default
//! `target/bench-inputs`; figures in `docs/library.md`).

#[path = "common/timing.rs"]
mod timing;

use dynbvh::bvh::{BuildParams, MeshBvh, MeshBvh8};
use dynbvh::geom::{Aabb, TriMesh, closest_point_on_triangle};
use dynbvh::glam::Vec3;
use dynbvh::io::read_tri;
use parry3d::query::PointQuery;
use std::hint::black_box;
use std::path::PathBuf;
use timing::interleaved;

const QUERIES: usize = 100_000;
const REPEATS: usize = 15;

struct Rng(u64);
impl Rng {
    fn f(&mut self) -> f32 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        ((z ^ (z >> 31)) >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// Points within `share` of the box diagonal of the surface.
fn near_surface(mesh: &TriMesh, share: f32, n: usize, seed: u64) -> Vec<Vec3> {
    let diag = Aabb::from_points(&mesh.positions).extent().length();
    let mut rng = Rng(seed);
    (0..n)
        .map(|_| {
            let k = (rng.f() * mesh.indices.len() as f32) as usize % mesh.indices.len();
            let [a, b, c] = mesh.indices[k].map(|i| mesh.positions[i as usize]);
            let (mut u, mut v) = (rng.f(), rng.f());
            if u + v > 1.0 {
                (u, v) = (1.0 - u, 1.0 - v);
            }
            let d = Vec3::new(rng.f() - 0.5, rng.f() - 0.5, rng.f() - 0.5).normalize_or_zero();
            a + (b - a) * u + (c - a) * v + d * (rng.f() * share * diag)
        })
        .collect()
}

/// Work per query: child boxes whose distance was computed and triangles tested.
#[derive(Clone, Copy, Default)]
struct Work {
    boxes: u64,
    tris: u64,
}

/// Counts the work of the closest-point queries on a binary tree three ways: dynbvh's
/// best-first search ([`dynbvh::bvh::Bvh::nearest_slot`], counted through its closures), the
/// depth-first walk it replaced (nearer child first, written out here), and that walk with
/// the bound seeded just above the answer (the least any walk on these boxes must do).
fn count_work(bvh: &MeshBvh, mesh: &TriMesh, points: &[Vec3]) -> [Work; 3] {
    let tree = bvh.bvh();
    let nodes = tree.nodes();
    let tris: Vec<[Vec3; 3]> = tree
        .prim_indices()
        .iter()
        .map(|&k| mesh.indices[k as usize].map(|i| mesh.positions[i as usize]))
        .collect();
    let r = tree.bounds();
    let mut work = [Work::default(); 3];
    for &p in points {
        let pad = (r.min.abs().max(r.max.abs()) + p.abs()) * (8.0 * f32::EPSILON);
        let lower = |n: &dynbvh::bvh::Node| {
            let lo = Vec3::from(n.min) - (p + pad);
            let hi = (p - pad) - Vec3::from(n.max);
            lo.max(hi).max(Vec3::ZERO).length_squared()
        };
        let dist = |slot: usize| {
            let [a, b, c] = tris[slot];
            closest_point_on_triangle(p, a, b, c).distance_squared(p)
        };
        let boxes = std::cell::Cell::new(0u64);
        let mut tested = 0u64;
        let (_, answer) = tree
            .nearest_slot(
                |n| {
                    boxes.set(boxes.get() + 1);
                    lower(n)
                },
                f32::INFINITY,
                |slot, best| {
                    tested += 1;
                    let d2 = dist(slot);
                    (d2 < best).then_some(d2)
                },
            )
            .expect("a nearest triangle");
        // The root's own test is not a child's.
        work[0].boxes += boxes.get() - 1;
        work[0].tris += tested;
        for (w, start) in work[1..].iter_mut().zip([f32::INFINITY, answer.next_up()]) {
            let mut best = start;
            let mut stack = Vec::new();
            let mut node = &nodes[0];
            loop {
                if node.is_leaf() {
                    for slot in node.first as usize..(node.first + node.count) as usize {
                        w.tris += 1;
                        best = best.min(dist(slot));
                    }
                } else {
                    let (l, r) = (node.first as usize, node.first as usize + 1);
                    let (dl, dr) = (lower(&nodes[l]), lower(&nodes[r]));
                    w.boxes += 2;
                    let (near, dn, far, df) = if dl <= dr {
                        (l, dl, r, dr)
                    } else {
                        (r, dr, l, dl)
                    };
                    if dn < best {
                        if df < best {
                            stack.push((far, df));
                        }
                        node = &nodes[near];
                        continue;
                    }
                }
                match std::iter::from_fn(|| stack.pop()).find(|&(_, d)| d < best) {
                    Some((i, _)) => node = &nodes[i],
                    None => break,
                }
            }
        }
    }
    work
}

/// parry's mesh: the same vertices (welded as the file gives them) and triangles.
fn parry_mesh(mesh: &TriMesh) -> parry3d::shape::TriMesh {
    let v = mesh
        .positions
        .iter()
        .map(|p| parry3d::math::Vector::new(p.x, p.y, p.z))
        .collect();
    parry3d::shape::TriMesh::new(v, mesh.indices.clone()).expect("a valid mesh for parry")
}

fn main() {
    let dir = std::env::var_os("DYNBVH_BENCH_INPUTS")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/bench-inputs"));
    let rest_path = dir.join("sphere_1m.tri");
    let def_path = dir.join("sphere_1m_def.tri");
    let (Ok(rest), Ok(def)) = (read_tri(&rest_path), read_tri(&def_path)) else {
        eprintln!(
            "peers_queries: {} or {} missing: generate them with ../shared/bench-inputs/gen.rs",
            rest_path.display(),
            def_path.display()
        );
        std::process::exit(if std::env::var_os("CI").is_some() {
            1
        } else {
            0
        });
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a one-thread pool");
    pool.install(|| {
        let points = near_surface(&rest, 0.01, QUERIES, 3);
        let ours = MeshBvh::build(&rest, &BuildParams::BINNED);
        let ours8 = MeshBvh8::from_mesh_bvh(&ours);
        let theirs = parry_mesh(&rest);
        // Agreement first.
        let mut worst = 0.0f32;
        for p in points.iter().take(2000) {
            let a = ours.closest_point(*p, f32::INFINITY).unwrap().distance;
            assert_eq!(ours8.closest_point(*p, f32::INFINITY).unwrap().distance, a);
            let q = theirs.project_local_point(parry3d::math::Vector::new(p.x, p.y, p.z), false);
            let b = (Vec3::new(q.point.x, q.point.y, q.point.z) - *p).length();
            worst = worst.max((a - b).abs());
        }
        let diag = Aabb::from_points(&rest.positions).extent().length();
        assert!(worst <= 1e-5 * diag, "distances differ by {worst}");
        let parry_points: Vec<_> = points
            .iter()
            .map(|p| parry3d::math::Vector::new(p.x, p.y, p.z))
            .collect();
        let (mut sa, mut sb, mut sc, mut sd) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let t = interleaved(
            REPEATS,
            &mut [
                &mut || {
                    sa = points
                        .iter()
                        .map(|p| f64::from(ours.closest_point(*p, f32::INFINITY).unwrap().distance))
                        .sum();
                },
                &mut || {
                    sc = points
                        .iter()
                        .map(|p| f64::from(ours8.closest_point(*p, f32::INFINITY).unwrap().distance))
                        .sum();
                },
                &mut || {
                    sb = parry_points
                        .iter()
                        .map(|p| {
                            let q = theirs.project_local_point(*p, false);
                            f64::from((q.point - *p).length())
                        })
                        .sum();
                },
            ],
        );
        println!(
            "closest point, sphere_1m ({} triangles), {QUERIES} points within 1% of the diagonal of the surface, 1 thread",
            rest.indices.len()
        );
        println!("{:<34} {:>10} {:>10} {:>12} {:>8}", "method", "wall ms", "CPU ms", "Mq/s CPU", "speed");
        let rate = |k: usize| QUERIES as f64 / (t[k].cpu_ms * 1e3);
        for (k, name) in ["dynbvh MeshBvh::closest_point", "dynbvh MeshBvh8::closest_point", "parry3d TriMesh::project_point"].iter().enumerate() {
            println!(
                "{name:<34} {:>10.2} {:>10.2} {:>12.3} {:>8.2}",
                t[k].wall_ms,
                t[k].cpu_ms,
                rate(k),
                rate(k) / rate(2)
            );
        }
        println!("(sums of distances: {:.6}, {:.6} vs {:.6}; worst difference on 2000 checked: {worst:.3e})", black_box(sa), black_box(sc), black_box(sb));

        // Refitted after deformation against a fresh tree.
        // The wide trees as the engine keeps them: the refitted one collapsed from the rest
        // mesh's tree and refitted since, the fresh one collapsed from the fresh build.
        let mut refitted = ours;
        refitted.refit(&def);
        let mut refitted8 = ours8;
        refitted8.refit(&def);
        let fresh = MeshBvh::build(&def, &BuildParams::BINNED);
        let fresh8 = MeshBvh8::from_mesh_bvh(&fresh);
        let points = near_surface(&def, 0.01, QUERIES, 4);
        for p in points.iter().take(2000) {
            let want = fresh.closest_point(*p, f32::INFINITY).map(|h| h.distance);
            assert_eq!(refitted.closest_point(*p, f32::INFINITY).map(|h| h.distance), want);
            assert_eq!(fresh8.closest_point(*p, f32::INFINITY).map(|h| h.distance), want);
            assert_eq!(refitted8.closest_point(*p, f32::INFINITY).map(|h| h.distance), want);
        }
        let t = interleaved(
            REPEATS,
            &mut [
                &mut || {
                    sa = points
                        .iter()
                        .map(|p| f64::from(fresh.closest_point(*p, f32::INFINITY).unwrap().distance))
                        .sum();
                },
                &mut || {
                    sb = points
                        .iter()
                        .map(|p| f64::from(refitted.closest_point(*p, f32::INFINITY).unwrap().distance))
                        .sum();
                },
                &mut || {
                    sc = points
                        .iter()
                        .map(|p| f64::from(fresh8.closest_point(*p, f32::INFINITY).unwrap().distance))
                        .sum();
                },
                &mut || {
                    sd = points
                        .iter()
                        .map(|p| f64::from(refitted8.closest_point(*p, f32::INFINITY).unwrap().distance))
                        .sum();
                },
            ],
        );
        println!("\nclosest point, sphere_1m_def: tree refitted from sphere_1m against a fresh build, 1 thread");
        println!("{:<34} {:>10} {:>10} {:>12} {:>8}", "tree", "wall ms", "CPU ms", "Mq/s CPU", "time");
        let names = ["binary, fresh build", "binary, refitted", "8-wide, fresh build", "8-wide, refitted"];
        for (k, name) in names.iter().enumerate() {
            // Each refitted tree against the fresh one of its kind.
            let base = t[k & !1].cpu_ms;
            println!(
                "{name:<34} {:>10.2} {:>10.2} {:>12.3} {:>8.2}",
                t[k].wall_ms,
                t[k].cpu_ms,
                QUERIES as f64 / (t[k].cpu_ms * 1e3),
                t[k].cpu_ms / base
            );
        }
        black_box((sa, sb, sc, sd));

        println!("\nwork per query on the binary trees (sphere_1m_def, the same points): child boxes, triangles");
        let n = QUERIES as f64;
        for (name, tree) in [("fresh build", &fresh), ("refitted", &refitted)] {
            let w = count_work(tree, &def, &points);
            println!(
                "{name:<12} best first {:>6.1} {:>5.1} | depth first {:>6.1} {:>5.1} | depth first from the answer {:>6.1} {:>5.1}",
                w[0].boxes as f64 / n,
                w[0].tris as f64 / n,
                w[1].boxes as f64 / n,
                w[1].tris as f64 / n,
                w[2].boxes as f64 / n,
                w[2].tris as f64 / n
            );
        }
    });
}
