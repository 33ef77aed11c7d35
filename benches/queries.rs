//! The library queries measured side by side on one thread (a one-thread rayon pool), each
//! comparison as a ratio within one run (methods interleaved repeat by repeat):
//! - masked visibility over 1,000 moving instances against unmasked any-hit on the same
//!   segments (a filter that admits every instance but the viewer: the filter's overhead; and
//!   one that masks half the instances out);
//! - all-hits and hit counting against the closest hit on camera rays (the shipped
//!   `lidar_cloth.glb` through the engine, and a 100k-triangle bumpy sphere's binary and 8-wide
//!   trees, each tree against its own closest hit), with the work per ray behind the ratio.
//! - the engine's closest point on one instance of a 100k-triangle sphere placed by the
//!   identity, by a turn and an even scale, and by an uneven one, with the wide traversal (the
//!   8-wide tree searched in the mesh's space) against the binary one;
//! - the engine's box and sphere overlaps on the same sphere, in place and turned and scaled,
//!   the wide traversal against the binary one.
//!
//! `cargo bench --bench queries [-- visibility | all_hits_engine | all_hits_mesh |
//! closest_point_placed | overlap_placed]` (figures in `docs/library.md`).

#[path = "common/timing.rs"]
mod timing;

use dynbvh::anim::Scene;
use dynbvh::bvh::{BuildParams, MeshBvh, MeshBvh8, TraversalStats};
use dynbvh::engine::gltf::{FrameTimes, GltfSource};
use dynbvh::engine::{
    Engine, EngineConfig, FrameSource, InstanceId, QueryFilter, SceneHit, Traversal,
};
use dynbvh::geom::{Ray, TriMesh, shapes};
use dynbvh::glam::{Affine3A, Quat, Vec3};
use dynbvh::report::rays::camera_rays;
use std::hint::black_box;
use timing::interleaved;

const REPEATS: usize = 15;
/// Times the all-hits benches trace their camera rays in each repeat: a repeat of one pass
/// takes a few milliseconds, near the granularity of the CPU clock.
const PASSES: usize = 8;

/// splitmix64 in [0, 1).
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

fn visibility() {
    const INSTANCES: usize = 1000;
    const QUERIES: usize = 50_000;
    let mut e = Engine::new(EngineConfig::default());
    let rock = shapes::icosphere(2);
    let mesh = e.add_mesh(rock.positions.clone(), rock.indices.clone());
    let mut rng = Rng(1);
    let start: Vec<Vec3> = (0..INSTANCES)
        .map(|_| Vec3::new(rng.f(), rng.f() * 0.2, rng.f()) * 200.0)
        .collect();
    let ids: Vec<InstanceId> = start
        .iter()
        .map(|&p| e.add_instance(mesh, Affine3A::from_translation(p)))
        .collect();
    for (k, &i) in ids.iter().enumerate() {
        e.set_instance_mask(i, if k % 2 == 0 { 1 } else { 2 });
    }
    let pairs: Vec<(usize, usize)> = (0..QUERIES)
        .map(|_| {
            let a = (rng.f() * INSTANCES as f32) as usize % INSTANCES;
            let b = (rng.f() * INSTANCES as f32) as usize % INSTANCES;
            (a, if a == b { (b + 1) % INSTANCES } else { b })
        })
        .collect();
    let mut rays = Vec::with_capacity(QUERIES);
    let mut per_frame = [[0.0f64; 2]; 3];
    let mut hits = [0usize; 3];
    let frames = 6;
    for f in 0..frames {
        let time = f as f32 * 0.1;
        for (k, (&i, &p)) in ids.iter().zip(&start).enumerate() {
            let wobble = Vec3::new((time + k as f32).sin(), 0.0, (time * 1.3 + k as f32).cos());
            e.set_transform(
                i,
                Affine3A::from_rotation_translation(
                    Quat::from_rotation_y(time + k as f32),
                    p + wobble * 3.0,
                ),
            );
        }
        e.update();
        rays.clear();
        // From just outside the viewer's sphere (radius 1) to just outside the target's: no
        // query starts inside an instance, so the filters change no answer but the masked one.
        rays.extend(pairs.iter().map(|&(a, b)| {
            let pa: Vec3 = e.transform(ids[a]).translation.into();
            let pb: Vec3 = e.transform(ids[b]).translation.into();
            let d = (pb - pa).normalize_or_zero();
            Ray::segment(pa + d * 1.01, pb - d * 1.01)
        }));
        let (mut n0, mut n1, mut n2) = (0, 0, 0);
        let t = interleaved(
            REPEATS,
            &mut [
                &mut || n0 = rays.iter().filter(|r| e.any_hit(r)).count(),
                &mut || {
                    n1 = rays
                        .iter()
                        .zip(&pairs)
                        .filter(|(r, (a, _))| {
                            e.any_hit_filtered(r, &QueryFilter::ALL.excluding(ids[*a]))
                        })
                        .count();
                },
                &mut || {
                    n2 = rays
                        .iter()
                        .zip(&pairs)
                        .filter(|(r, (a, _))| {
                            e.any_hit_filtered(r, &QueryFilter::mask(1).excluding(ids[*a]))
                        })
                        .count();
                },
            ],
        );
        for k in 0..3 {
            per_frame[k][0] += t[k].wall_ms / frames as f64;
            per_frame[k][1] += t[k].cpu_ms / frames as f64;
        }
        hits[0] += n0;
        hits[1] += n1;
        hits[2] += n2;
    }
    println!(
        "\nvisibility: {INSTANCES} moving instances (icosphere, 320 triangles), {QUERIES} segments between random pairs, {frames} frames, 1 thread"
    );
    println!(
        "{:<44} {:>10} {:>10} {:>8} {:>10}",
        "query", "wall ms", "CPU ms", "ratio", "blocked"
    );
    let names = [
        "any_hit (unmasked)",
        "any_hit_filtered (all, viewer excluded)",
        "any_hit_filtered (mask: half, viewer excl.)",
    ];
    for k in 0..3 {
        println!(
            "{:<44} {:>10.3} {:>10.3} {:>8.3} {:>10}",
            names[k],
            per_frame[k][0],
            per_frame[k][1],
            per_frame[k][1] / per_frame[0][1],
            hits[k] / frames
        );
    }
}

fn all_hits_engine() {
    let path = format!("{}/animations/lidar_cloth.glb", env!("CARGO_MANIFEST_DIR"));
    let (scene, _) = Scene::load(&path).expect("the shipped lidar_cloth.glb");
    let mut src = GltfSource::new(&scene, Some(0), FrameTimes::Count(4)).unwrap();
    let mut e = src.engine(EngineConfig::default());
    src.advance(&mut e, 2);
    e.update();
    let rays = camera_rays(&e.bounds(), 256, 256);
    let traced = rays.repeat(PASSES);
    let mut buf: Vec<SceneHit> = Vec::new();
    let (mut a, mut b, mut c) = (0usize, 0usize, 0usize);
    let t = interleaved(
        REPEATS,
        &mut [
            &mut || a = traced.iter().filter(|r| e.closest_hit(r).is_some()).count(),
            &mut || {
                b = 0;
                for r in &traced {
                    e.all_hits(r, usize::MAX, &mut buf);
                    b += buf.len();
                }
            },
            &mut || c = traced.iter().map(|r| e.count_hits(r) as usize).sum(),
        ],
    );
    report(
        "all-hits, engine: lidar_cloth.glb frame 2 of 4, 256x256 camera rays",
        &traced,
        &t,
        &[a, b, c],
    );
}

fn all_hits_mesh() {
    let mesh = shapes::bumpy_sphere(100_000);
    let bvh = MeshBvh::build(&mesh, &BuildParams::BINNED);
    let wide = MeshBvh8::from_mesh_bvh(&bvh);
    let rays = camera_rays(&dynbvh::geom::Aabb::from_points(&mesh.positions), 256, 256);
    let traced = rays.repeat(PASSES);
    let (mut buf, mut buf8) = (Vec::new(), Vec::new());
    let (mut n0, mut n1, mut n2, mut n3, mut n4, mut n5) = (0, 0, 0, 0, 0, 0);
    let t = interleaved(
        REPEATS,
        &mut [
            &mut || {
                n0 = traced
                    .iter()
                    .filter(|r| bvh.closest_hit(r).is_some())
                    .count()
            },
            &mut || {
                n1 = 0;
                for r in &traced {
                    bvh.all_hits(r, usize::MAX, &mut buf);
                    n1 += buf.len();
                }
            },
            &mut || n2 = traced.iter().map(|r| bvh.count_hits(r) as usize).sum(),
            &mut || {
                n3 = traced
                    .iter()
                    .filter(|r| wide.closest_hit(r).is_some())
                    .count()
            },
            &mut || {
                n4 = 0;
                for r in &traced {
                    wide.all_hits(r, usize::MAX, &mut buf8);
                    n4 += buf8.len();
                }
            },
            &mut || n5 = traced.iter().map(|r| wide.count_hits(r) as usize).sum(),
        ],
    );
    let n = [n0, n1, n2, n3, n4, n5];
    assert_eq!((n[0], n[1], n[2]), (n[3], n[4], n[5]), "the trees agree");
    let title = format!(
        "all-hits: bumpy sphere {} triangles, 256x256 camera rays",
        mesh.indices.len()
    );
    report(&format!("{title}, binary tree"), &traced, &t[..3], &n[..3]);
    report(&format!("{title}, 8-wide tree"), &traced, &t[3..], &n[3..]);
    // The work behind the ratio, on the binary tree: what the closest hit walks against the
    // walk that finds every hit (nothing pruned behind the first).
    let (mut closest, mut every) = (TraversalStats::default(), TraversalStats::default());
    for r in &rays {
        let _ = bvh.closest_hit_counted(r, &mut closest);
        let _ = bvh.bvh().closest_slot(r, |_, _| None, &mut every);
    }
    let per = |v: u64| v as f64 / rays.len() as f64;
    println!(
        "hitting rays {}, hits per hitting ray {:.2}; per ray, closest hit: {:.1} nodes {:.1} triangles, all hits: {:.1} nodes {:.1} triangles",
        n[0] / PASSES,
        n[1] as f64 / n[0].max(1) as f64,
        per(closest.nodes),
        per(closest.prims),
        per(every.nodes),
        per(every.prims)
    );
}

/// The placements of the placed-query benches: in place, turned and scaled evenly, and
/// unevenly.
fn placements() -> [(&'static str, Affine3A); 3] {
    [
        ("identity", Affine3A::IDENTITY),
        (
            "turned, scaled 0.5",
            Affine3A::from_scale_rotation_translation(
                Vec3::splat(0.5),
                Quat::from_rotation_y(0.7),
                Vec3::new(3.0, -1.0, 2.0),
            ),
        ),
        (
            "turned, scaled (2, 0.6, 1)",
            Affine3A::from_scale_rotation_translation(
                Vec3::new(2.0, 0.6, 1.0),
                Quat::from_rotation_x(0.4) * Quat::from_rotation_z(1.1),
                Vec3::new(-2.0, 0.5, 1.0),
            ),
        ),
    ]
}

/// An engine with one instance of `mesh` placed by `x`, walked with `traversal`.
fn placed_engine(mesh: &TriMesh, x: Affine3A, traversal: Traversal) -> Engine {
    let mut e = Engine::new(EngineConfig {
        traversal,
        ..EngineConfig::default()
    });
    let m = e.add_mesh(mesh.positions.clone(), mesh.indices.clone());
    e.add_instance(m, x);
    e.update();
    e
}

fn closest_point_placed() {
    const QUERIES: usize = 100_000;
    let mesh = shapes::bumpy_sphere(100_000);
    println!(
        "\nclosest point, engine, one instance of a {}-triangle sphere, {QUERIES} points within 1% of the diagonal of the surface, 1 thread",
        mesh.indices.len()
    );
    println!(
        "{:<28} {:>12} {:>12} {:>14}",
        "placement", "wide CPU ms", "binary CPU ms", "binary / wide"
    );
    for (name, x) in placements() {
        let (wide, binary) = (
            placed_engine(&mesh, x, Traversal::Wide),
            placed_engine(&mesh, x, Traversal::Binary),
        );
        let diag = wide.bounds().extent().length();
        let mut rng = Rng(7);
        let points: Vec<Vec3> = (0..QUERIES)
            .map(|_| {
                let t = mesh.indices
                    [(rng.f() * mesh.indices.len() as f32) as usize % mesh.indices.len()];
                let [a, b, c] = t.map(|v| x.transform_point3(mesh.positions[v as usize]));
                let (u, v) = (rng.f(), rng.f());
                let (u, v) = if u + v > 1.0 {
                    (1.0 - u, 1.0 - v)
                } else {
                    (u, v)
                };
                let off = Vec3::new(rng.f(), rng.f(), rng.f()) * 2.0 - Vec3::ONE;
                a + (b - a) * u + (c - a) * v + off * (0.01 * diag / 3f32.sqrt())
            })
            .collect();
        let distances = |e: &Engine| -> f64 {
            points
                .iter()
                .filter_map(|p| e.closest_point(*p, f32::INFINITY))
                .map(|h| f64::from(h.distance))
                .sum()
        };
        let (mut sw, mut sb) = (0f64, 0f64);
        let t = interleaved(
            REPEATS,
            &mut [&mut || sw = distances(&wide), &mut || {
                sb = distances(&binary)
            }],
        );
        assert_eq!(black_box(sw), black_box(sb), "{name}: the traversals agree");
        println!(
            "{name:<28} {:>12.2} {:>12.2} {:>14.2}",
            t[0].cpu_ms,
            t[1].cpu_ms,
            t[1].cpu_ms / t[0].cpu_ms
        );
    }
}

/// The engine's box and sphere overlaps on one instance of a 100k-triangle sphere, placed as
/// in [`closest_point_placed`] (evenly and unevenly scaled), with the wide traversal (the 8-wide tree) against the binary
/// one: boxes and spheres about 1% of the diagonal across, centred near the surface.
fn overlap_placed() {
    const QUERIES: usize = 50_000;
    let mesh = shapes::bumpy_sphere(100_000);
    println!(
        "\noverlap, engine, one instance of a {}-triangle sphere, {QUERIES} boxes and {QUERIES} spheres 1% of the diagonal across near the surface, 1 thread",
        mesh.indices.len()
    );
    println!(
        "{:<28} {:<7} {:>12} {:>13} {:>14} {:>10}",
        "placement", "query", "wide CPU ms", "binary CPU ms", "binary / wide", "found"
    );
    for (name, x) in placements() {
        let (wide, binary) = (
            placed_engine(&mesh, x, Traversal::Wide),
            placed_engine(&mesh, x, Traversal::Binary),
        );
        let diag = wide.bounds().extent().length();
        let mut rng = Rng(11);
        let centres: Vec<Vec3> = (0..QUERIES)
            .map(|_| {
                let t = mesh.indices
                    [(rng.f() * mesh.indices.len() as f32) as usize % mesh.indices.len()];
                let [a, b, c] = t.map(|v| x.transform_point3(mesh.positions[v as usize]));
                let off = Vec3::new(rng.f(), rng.f(), rng.f()) * 2.0 - Vec3::ONE;
                (a + b + c) / 3.0 + off * (0.01 * diag)
            })
            .collect();
        let half = Vec3::splat(0.005 * diag);
        let boxes = |e: &Engine| -> usize {
            let mut out = Vec::new();
            centres
                .iter()
                .map(|&c| {
                    e.overlap_box(dynbvh::geom::Aabb::new(c - half, c + half), &mut out);
                    out.len()
                })
                .sum()
        };
        let spheres = |e: &Engine| -> usize {
            let mut out = Vec::new();
            centres
                .iter()
                .map(|&c| {
                    e.overlap_sphere(c, 0.005 * diag, &mut out);
                    out.len()
                })
                .sum()
        };
        for (query, run) in [
            ("box", &boxes as &dyn Fn(&Engine) -> usize),
            ("sphere", &spheres),
        ] {
            let (mut fw, mut fb) = (0, 0);
            let t = interleaved(
                REPEATS,
                &mut [&mut || fw = run(&wide), &mut || fb = run(&binary)],
            );
            assert_eq!(
                black_box(fw),
                black_box(fb),
                "{name} {query}: the traversals agree"
            );
            println!(
                "{name:<28} {query:<7} {:>12.2} {:>13.2} {:>14.2} {fw:>10}",
                t[0].cpu_ms,
                t[1].cpu_ms,
                t[1].cpu_ms / t[0].cpu_ms
            );
        }
    }
}

/// Prints the rates of `t` over `traced` rays and the counts of one pass.
fn report(title: &str, traced: &[Ray], t: &[timing::Timed], counts: &[usize]) {
    println!("\n{title}, 1 thread, {PASSES} passes a repeat");
    println!(
        "{:<22} {:>10} {:>10} {:>12} {:>8} {:>10}",
        "query", "wall ms", "CPU ms", "Mrays/s CPU", "ratio", "hits"
    );
    for (k, name) in ["closest_hit", "all_hits (unbounded)", "count_hits"]
        .iter()
        .enumerate()
    {
        let rate = traced.len() as f64 / (t[k].cpu_ms * 1e3);
        let base = traced.len() as f64 / (t[0].cpu_ms * 1e3);
        println!(
            "{name:<22} {:>10.3} {:>10.3} {:>12.2} {:>8.3} {:>10}",
            t[k].wall_ms,
            t[k].cpu_ms,
            rate,
            rate / base,
            black_box(counts[k]) / PASSES
        );
    }
}

fn main() {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .expect("a one-thread pool");
    // `cargo bench` passes `--bench`; other words pick the parts to run.
    let parts: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let wanted = |name: &str| parts.is_empty() || parts.iter().any(|p| name.contains(p.as_str()));
    pool.install(|| {
        if wanted("visibility") {
            visibility();
        }
        if wanted("all_hits_engine") {
            all_hits_engine();
        }
        if wanted("all_hits_mesh") {
            all_hits_mesh();
        }
        if wanted("closest_point_placed") {
            closest_point_placed();
        }
        if wanted("overlap_placed") {
            overlap_placed();
        }
    });
}
