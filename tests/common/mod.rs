//! Helpers shared by integration tests: brute-force comparison and test meshes.
#![allow(dead_code)]

pub mod strategies;

use dynbvh::bvh::{BuildParams, MAX_PACKET, MeshBvh, brute_force_any, brute_force_closest};
use dynbvh::engine::SceneHit;
use dynbvh::geom::{Hit, Ray, RayTriPrecomp, TriMesh, intersect_triangle};
use glam::Vec3;

/// Compares one ray's closest and any hit through the tree with brute force. Ties (two
/// triangles at the same distance) may resolve to either triangle, but the distance must be
/// identical and the reported triangle must really be hit there.
pub fn check_ray(mesh: &TriMesh, bvh: &MeshBvh, ray: &Ray) -> Result<(), String> {
    let want = brute_force_closest(mesh, ray);
    let got = bvh.closest_hit(ray);
    match (want, got) {
        (None, None) => {}
        (Some(w), Some(g)) => {
            if w.t != g.t {
                return Err(format!(
                    "ray {ray:?}: brute force t {} prim {}, tree t {} prim {}",
                    w.t, w.prim, g.t, g.prim
                ));
            }
            if w.prim != g.prim {
                let [a, b, c] = mesh.triangle(g.prim as usize);
                let pre = RayTriPrecomp::new(ray.dir());
                let t = intersect_triangle(ray, &pre, a, b, c, f32::INFINITY).map(|h| h.0);
                if t != Some(g.t) {
                    return Err(format!(
                        "ray {ray:?}: tree reports prim {} at {} but it is hit at {t:?}",
                        g.prim, g.t
                    ));
                }
            }
        }
        (w, g) => return Err(format!("ray {ray:?}: brute force {w:?}, tree {g:?}")),
    }
    let (wa, ga) = (brute_force_any(mesh, ray), bvh.any_hit(ray));
    if wa != ga {
        return Err(format!("ray {ray:?}: any hit brute force {wa}, tree {ga}"));
    }
    Ok(())
}

/// Deterministic pseudo-random numbers (splitmix64) for non-proptest tests.
pub struct Rng(pub u64);

impl Rng {
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn f(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.f()
    }
    pub fn unit_vector(&mut self) -> Vec3 {
        let z = self.range(-1.0, 1.0);
        let phi = self.range(0.0, std::f32::consts::TAU);
        let s = (1.0 - z * z).max(0.0).sqrt();
        Vec3::new(s * phi.cos(), s * phi.sin(), z)
    }
    /// `n` triangles in no order: each with a corner uniform in the unit cube and the other two
    /// at distance `size` from it in random directions.
    pub fn soup(&mut self, n: usize, size: f32) -> Vec<[Vec3; 3]> {
        (0..n)
            .map(|_| {
                let p = Vec3::new(self.f(), self.f(), self.f());
                [
                    p,
                    p + self.unit_vector() * size,
                    p + self.unit_vector() * size,
                ]
            })
            .collect()
    }
}

/// Every builder, with the settings that take their rarer paths: few bins, the widest axis
/// only, one triangle per leaf, and a parallel threshold so low that small inputs also take the
/// parallel code.
pub fn builders() -> Vec<BuildParams> {
    let widest = BuildParams {
        all_axes: false,
        ..BuildParams::binned(8)
    };
    let tiny_leaves = BuildParams {
        max_leaf_size: 1,
        ..BuildParams::binned(4)
    };
    let parallel = BuildParams {
        parallel_threshold: 2,
        ..BuildParams::binned(32)
    };
    let parallel_sweep = BuildParams {
        parallel_threshold: 2,
        ..BuildParams::SWEEP
    };
    vec![
        BuildParams::binned(4),
        BuildParams::BINNED,
        widest,
        tiny_leaves,
        parallel,
        BuildParams::SWEEP,
        parallel_sweep,
        BuildParams::MEDIAN,
    ]
}

/// Rays from a shell around `center` towards points near it, plus axis-parallel ones.
pub fn rays_around(center: Vec3, radius: f32, n: usize, seed: u64) -> Vec<Ray> {
    let mut rng = Rng(seed);
    let mut rays = Vec::new();
    for _ in 0..n {
        let o = center + rng.unit_vector() * radius * 2.0;
        let target = center + rng.unit_vector() * radius * rng.f() * 0.5;
        rays.push(Ray::new(o, target - o));
    }
    for axis in [Vec3::X, Vec3::Y, Vec3::Z] {
        rays.push(Ray::new(center - axis * radius * 2.0, axis));
        rays.push(Ray::new(center + axis * radius * 2.0, -axis));
    }
    rays
}

/// 600 small triangles in the unit cube, four in ten with a NaN or infinite coordinate.
pub fn soup_with_nan_and_inf() -> TriMesh {
    let mut rng = Rng(13);
    let mut tris = Vec::new();
    for i in 0..600 {
        let p = Vec3::new(
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
            rng.range(-1.0, 1.0),
        );
        let mut t = [p, p + rng.unit_vector() * 0.3, p + rng.unit_vector() * 0.3];
        match i % 10 {
            0 => t[1].x = f32::NAN,
            1 => t[2] = Vec3::splat(f32::NAN),
            2 => t[0].y = f32::INFINITY,
            3 => t[1].z = f32::NEG_INFINITY,
            _ => {}
        }
        tris.push(t);
    }
    TriMesh::from_soup(&tris)
}

/// Rays from one point aimed at the mesh's vertices: the hardest place for the triangle test.
pub fn aimed(mesh: &TriMesh, from: Vec3) -> Vec<Ray> {
    mesh.positions
        .iter()
        .take(MAX_PACKET)
        .map(|&p| Ray::new(from, p - from))
        .filter(|r| r.dir().length() > 0.0)
        .collect()
}

/// An engine hit as the mesh-level hit [`same_closest`] compares (a one-instance scene placed
/// by the identity: the same distance, barycentrics and triangle).
pub fn mesh_hit(h: SceneHit) -> Hit {
    Hit {
        t: h.t,
        u: h.u,
        v: h.v,
        prim: h.prim,
    }
}

/// Closest hits compare as in `tests/bvh_props.rs`: the same distance, and the same triangle or
/// one that is really hit at that distance (a tie).
pub fn same_closest(mesh: &TriMesh, ray: &Ray, want: Option<Hit>, got: Option<Hit>) -> bool {
    match (want, got) {
        (None, None) => true,
        (Some(w), Some(g)) => {
            if w.t != g.t {
                return false;
            }
            if w.prim == g.prim {
                return w.u == g.u && w.v == g.v;
            }
            let [a, b, c] = mesh.triangle(g.prim as usize);
            let pre = RayTriPrecomp::new(ray.dir());
            intersect_triangle(ray, &pre, a, b, c, f32::INFINITY).map(|h| h.0) == Some(g.t)
        }
        _ => false,
    }
}

/// Checks `bvh` over `mesh`: every invariant, and 150 rays around the mesh against brute force
/// (`what` names the case in the failure).
pub fn check_tree(mesh: &TriMesh, bvh: &MeshBvh, what: &str) {
    bvh.validate(mesh)
        .unwrap_or_else(|e| panic!("{what}: invalid tree: {e}"));
    let b = dynbvh::geom::Aabb::from_points(&mesh.positions);
    let r = 0.5 * b.extent().length().max(1e-3);
    for ray in rays_around(b.center(), r, 150, 7) {
        check_ray(mesh, bvh, &ray).unwrap_or_else(|e| panic!("{what}: {e}"));
    }
}

/// The bench's shared sample of frames `1 ..= frames` of `src`, as the oracle tests replay it:
/// every 3rd of `rays` (from an offset that moves with the frame) traced on an always-refit
/// engine made by `config`, each sampled ray standing for `scale` rays (entry 0 unused).
pub fn shared_sample(
    src: &mut dyn dynbvh::engine::source::FrameSource,
    config: dynbvh::engine::EngineConfig,
    rays: &[Ray],
    frames: usize,
    scale: f64,
) -> Vec<dynbvh::report::all_pairs::SampledFrame> {
    use dynbvh::engine::{Decision, Query};
    let prices = config.prices;
    let mut sampled = vec![dynbvh::report::all_pairs::SampledFrame::default()];
    let mut e = src.build(0, config);
    for f in 1..=frames {
        src.advance(&mut e, f);
        e.force_next(Decision::Refit);
        e.update();
        let mut entries = Vec::new();
        let (top, _) = e.trace_sampled(rays, Query::Closest, 3, f % 3, &mut entries);
        sampled.push(dynbvh::report::all_pairs::SampledFrame {
            entries,
            fixed_ms: scale * prices.trace_ms(top),
            scale,
        });
    }
    sampled
}

/// Asserts that two bench reports have bit for bit the same modelled totals (the oracle's and
/// every policy's) and the same schedules; `what` names the comparison.
pub fn assert_same_modelled(
    a: &dynbvh::report::frame_bench::Report,
    b: &dynbvh::report::frame_bench::Report,
    what: &str,
) {
    assert_eq!(
        a.oracle_modelled.total_ms.to_bits(),
        b.oracle_modelled.total_ms.to_bits(),
        "{what}: oracle"
    );
    let names = |r: &dynbvh::report::frame_bench::Report| {
        r.policies
            .iter()
            .map(|p| p.policy.clone())
            .collect::<Vec<_>>()
    };
    assert_eq!(names(a), names(b), "{what}: the policies");
    for (p, q) in a.policies.iter().zip(&b.policies) {
        assert_eq!(
            p.modelled_ms.to_bits(),
            q.modelled_ms.to_bits(),
            "{what}: {}",
            p.policy
        );
        assert_eq!(p.rebuild_frames, q.rebuild_frames, "{what}: {}", p.policy);
    }
}

/// A rayon pool of `threads` threads.
pub fn pool(threads: usize) -> rayon::ThreadPool {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("a thread pool")
}
