//! dynbvh side by side with the Rust BVH libraries obvhs, bvh and parry3d on the shared
//! benchmark inputs: build time, refit time, SAH of the binary tree (computed the same way for
//! every library, from its own node boxes), closest-hit Mrays/s on the primary and random ray
//! sets, and agreement of every library's hits with brute force. Everything runs on one thread
//! (inside a one-thread rayon pool), or on `DYNBVH_PEERS_THREADS`. See `benches/README.md`.
//!
//! Build with the `peers` feature (and a separate target dir, so that the shared one is not
//! rebuilt):
//! `CARGO_TARGET_DIR=target/peers cargo bench --features peers --bench peers [-- FILTER...]`.

use dynbvh::bvh::{BuildParams, MeshBvh, brute_force_closest};
use dynbvh::geom::{Ray, RayTriPrecomp, TriMesh, intersect_triangle};
use dynbvh::io::{read_rays, read_tri};
use glam::{Vec3, Vec3A};
use std::hint::black_box;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

#[cfg(feature = "embree")]
mod embree_ffi;

#[path = "../examples/common/cpu.rs"]
mod cpu;

/// True when `DYNBVH_PEERS_CPU` is set: ray throughput is measured in the process's CPU time
/// instead of wall-clock time (for a machine shared with other work), each pass repeated for at
/// least 0.3 s of CPU time.
fn cpu_timing() -> bool {
    std::env::var_os("DYNBVH_PEERS_CPU").is_some() && threads() == 1
}

/// Threads every variant builds, refits and traces on: `DYNBVH_PEERS_THREADS`, default 1.
/// With more than one, traces split the rays into runs of [`PAR_CHUNK`] across the threads
/// and are timed by the wall clock (the CPU clock would add the threads' times up), each pass
/// repeated for at least 0.3 s; Embree's device gets as many threads.
fn threads() -> usize {
    std::env::var("DYNBVH_PEERS_THREADS")
        .ok()
        .and_then(|v| v.parse().ok())
        .filter(|&n| n >= 1)
        .unwrap_or(1)
}

/// Rays a thread traces at a time when several do (whole 16x8 packets).
const PAR_CHUNK: usize = 4096;

// ---------------------------------------------------------------------------------------------
// Settings
// ---------------------------------------------------------------------------------------------

/// Rays traced per set and pass unless `DYNBVH_PEERS_RAYS` says otherwise (`all` for the
/// whole file). Camera rays are subsampled as a lower-resolution image of the same view.
const DEFAULT_RAYS: usize = 1 << 18;
/// Builds per variant (3 when a build takes more than a second).
const BUILD_RUNS: usize = 7;
/// Timed passes over each ray set.
const TRACE_RUNS: usize = 3;
/// Timed refits per variant.
const REFIT_RUNS: usize = 5;
/// Rays per set compared with brute force.
const CHECK_RAYS: usize = 200;

// ---------------------------------------------------------------------------------------------
// Common interface
// ---------------------------------------------------------------------------------------------

/// What the harness needs of a library. `Input` is the library's own form of the mesh, made
/// before the clock starts (conversions at the boundary are not the library's cost); `R` is
/// its own form of a ray, also made beforehand.
trait Accel: Sized + Sync {
    type Input;
    type R: Sync;
    fn prepare(mesh: &TriMesh) -> Self::Input;
    fn ray(r: &Ray) -> Self::R;
    /// Closest hit: distance and the triangle's index in the input mesh.
    fn closest(&self, ray: &Self::R) -> Option<(f32, u32)>;
    /// SAH of the binary tree: interior nodes (the root among them) cost their area, leaves
    /// their primitive count times their area, all divided by the root's area.
    fn sah(&self) -> f64;
    /// Refits to the same triangles at new positions; `false` when the variant cannot.
    fn refit(&mut self, input: &Self::Input) -> bool;
    /// Closest hits of a whole ray set (one at a time unless the variant traces packets);
    /// returns the sum of the hit distances, so that nothing is optimised away.
    fn trace_all(&self, rays: &[Self::R]) -> f32 {
        rays.iter()
            .filter_map(|r| self.closest(black_box(r)))
            .map(|h| h.0)
            .sum()
    }
    /// [`Accel::trace_all`] on the pool's threads: runs of [`PAR_CHUNK`] rays across them,
    /// unless the variant spreads a whole set over the threads itself.
    fn trace_all_threads(&self, rays: &[Self::R]) -> f32 {
        use rayon::prelude::*;
        rays.par_chunks(PAR_CHUNK).map(|c| self.trace_all(c)).sum()
    }
}

/// Accumulates an SAH sum in f64 from node boxes.
#[derive(Default)]
struct SahSum {
    sum: f64,
}

impl SahSum {
    fn half_area(min: [f32; 3], max: [f32; 3]) -> f64 {
        let e = [0, 1, 2].map(|k| f64::from((max[k] - min[k]).max(0.0)));
        e[0] * e[1] + e[1] * e[2] + e[2] * e[0]
    }
    fn interior(&mut self, min: [f32; 3], max: [f32; 3]) {
        self.sum += Self::half_area(min, max);
    }
    fn leaf(&mut self, min: [f32; 3], max: [f32; 3], count: u32) {
        self.sum += f64::from(count) * Self::half_area(min, max);
    }
    fn finish(&self, root_min: [f32; 3], root_max: [f32; 3]) -> f64 {
        self.sum / Self::half_area(root_min, root_max)
    }
}

fn soup(mesh: &TriMesh) -> Vec<[Vec3; 3]> {
    (0..mesh.len()).map(|i| mesh.triangle(i)).collect()
}

// ---------------------------------------------------------------------------------------------
// dynbvh
// ---------------------------------------------------------------------------------------------

struct Dyn(MeshBvh);

impl Accel for Dyn {
    type Input = TriMesh;
    type R = Ray;
    fn prepare(mesh: &TriMesh) -> TriMesh {
        mesh.clone()
    }
    fn ray(r: &Ray) -> Ray {
        *r
    }
    #[inline]
    fn closest(&self, ray: &Ray) -> Option<(f32, u32)> {
        self.0.closest_hit(ray).map(|h| (h.t, h.prim))
    }
    fn sah(&self) -> f64 {
        let nodes = self.0.bvh().nodes();
        let mut s = SahSum::default();
        for n in nodes {
            if n.is_leaf() {
                s.leaf(n.min, n.max, n.count);
            } else {
                s.interior(n.min, n.max);
            }
        }
        let sah = s.finish(nodes[0].min, nodes[0].max);
        // The harness's SAH and the library's own must agree.
        let own = f64::from(self.0.bvh().sah_cost());
        assert!(
            (sah - own).abs() <= 1e-4 * own,
            "SAH walk {sah} differs from MeshBvh's {own}"
        );
        sah
    }
    fn refit(&mut self, input: &TriMesh) -> bool {
        self.0.refit(input);
        true
    }
}

/// dynbvh's binary tree traced as packets of up to 128 consecutive rays (16x8 camera tiles;
/// incoherent packets fall back to single rays by themselves).
struct DynPackets(Dyn);

impl Accel for DynPackets {
    type Input = TriMesh;
    type R = Ray;
    fn prepare(mesh: &TriMesh) -> TriMesh {
        mesh.clone()
    }
    fn ray(r: &Ray) -> Ray {
        *r
    }
    fn closest(&self, ray: &Ray) -> Option<(f32, u32)> {
        self.0.closest(ray)
    }
    fn trace_all(&self, rays: &[Ray]) -> f32 {
        let mut hits = [None; 128];
        let mut sum = 0.0;
        for chunk in rays.chunks(128) {
            let out = &mut hits[..chunk.len()];
            self.0.0.closest_hit_packet(chunk, out);
            sum += out.iter().flatten().map(|h| h.t).sum::<f32>();
        }
        sum
    }
    fn sah(&self) -> f64 {
        self.0.sah()
    }
    fn refit(&mut self, input: &TriMesh) -> bool {
        self.0.refit(input)
    }
}

/// dynbvh's 8-wide tree, collapsed from the binned16 tree (the collapse is part of its build),
/// refitted in place.
struct DynWide(dynbvh::bvh::MeshBvh8);

impl Accel for DynWide {
    type Input = TriMesh;
    type R = Ray;
    fn prepare(mesh: &TriMesh) -> TriMesh {
        mesh.clone()
    }
    fn ray(r: &Ray) -> Ray {
        *r
    }
    #[inline]
    fn closest(&self, ray: &Ray) -> Option<(f32, u32)> {
        self.0.closest_hit(ray).map(|h| (h.t, h.prim))
    }
    fn sah(&self) -> f64 {
        f64::NAN
    }
    fn refit(&mut self, input: &TriMesh) -> bool {
        self.0.refit(input);
        true
    }
}

/// The 8-wide tree traced as before issue 17's fourth session: a zeroed stack for every ray
/// and two hit children ordered by the insertion loop (`MeshBvh8::bench_closest_hit` variant 1).
struct DynWideBefore(DynWide);

impl Accel for DynWideBefore {
    type Input = TriMesh;
    type R = Ray;
    fn prepare(mesh: &TriMesh) -> TriMesh {
        mesh.clone()
    }
    fn ray(r: &Ray) -> Ray {
        *r
    }
    #[inline]
    fn closest(&self, ray: &Ray) -> Option<(f32, u32)> {
        self.0.0.bench_closest_hit(ray, 1).map(|h| (h.t, h.prim))
    }
    fn sah(&self) -> f64 {
        f64::NAN
    }
    fn refit(&mut self, input: &TriMesh) -> bool {
        self.0.refit(input)
    }
}

/// A batch's hits and its ordering scratch.
type BatchScratch = (
    Vec<Option<dynbvh::geom::Hit>>,
    dynbvh::bvh::ray_order::RayBatch,
);

/// dynbvh's 8-wide tree traced a whole ray set at a time (`MeshBvh8::closest_hit_batch`, on
/// the bench's threads): incoherent sets reordered by where their rays travel before they are
/// traced (the ordering inside the timing), coherent ones traced as they come.
struct DynWideBatch(DynWide);

impl Accel for DynWideBatch {
    type Input = TriMesh;
    type R = Ray;
    fn prepare(mesh: &TriMesh) -> TriMesh {
        mesh.clone()
    }
    fn ray(r: &Ray) -> Ray {
        *r
    }
    fn closest(&self, ray: &Ray) -> Option<(f32, u32)> {
        self.0.closest(ray)
    }
    fn trace_all(&self, rays: &[Ray]) -> f32 {
        thread_local! {
            // The hits and the ordering's scratch, kept between passes as a caller would.
            static SCRATCH: std::cell::RefCell<BatchScratch> =
                std::cell::RefCell::default();
        }
        SCRATCH.with_borrow_mut(|(hits, order)| {
            hits.resize(rays.len(), None);
            self.0.0.closest_hit_batch(rays, hits, order);
            // The other rows sum every distance as they trace; here the hits are in memory.
            black_box(&hits);
            hits.first().copied().flatten().map_or(0.0, |h| h.t)
        })
    }
    fn trace_all_threads(&self, rays: &[Ray]) -> f32 {
        self.trace_all(rays)
    }
    fn sah(&self) -> f64 {
        f64::NAN
    }
    fn refit(&mut self, input: &TriMesh) -> bool {
        self.0.refit(input)
    }
}

/// dynbvh's 8-wide tree traced as packets of up to 128 consecutive rays (16x8 camera tiles;
/// incoherent packets fall back to single rays by themselves).
struct DynWidePackets(DynWide);

impl Accel for DynWidePackets {
    type Input = TriMesh;
    type R = Ray;
    fn prepare(mesh: &TriMesh) -> TriMesh {
        mesh.clone()
    }
    fn ray(r: &Ray) -> Ray {
        *r
    }
    fn closest(&self, ray: &Ray) -> Option<(f32, u32)> {
        self.0.closest(ray)
    }
    fn trace_all(&self, rays: &[Ray]) -> f32 {
        let mut hits = [None; 128];
        let mut sum = 0.0;
        for chunk in rays.chunks(128) {
            let out = &mut hits[..chunk.len()];
            self.0.0.closest_hit_packet(chunk, out);
            sum += out.iter().flatten().map(|h| h.t).sum::<f32>();
        }
        sum
    }
    fn sah(&self) -> f64 {
        f64::NAN
    }
    fn refit(&mut self, input: &TriMesh) -> bool {
        self.0.refit(input)
    }
}

// ---------------------------------------------------------------------------------------------
// obvhs (Bvh2: binary, PLOC builder)
// ---------------------------------------------------------------------------------------------

mod ob {
    use super::*;
    use obvhs::aabb::Aabb;
    use obvhs::bvh2::Bvh2;
    use obvhs::bvh2::builder::build_bvh2_from_tris;
    use obvhs::ray::RayHit;
    use obvhs::triangle::Triangle;

    /// An obvhs Bvh2 with its triangles copied in leaf order (as its examples advise).
    pub struct Obvhs {
        bvh: Bvh2,
        tris: Vec<Triangle>,
        pre_split: bool,
    }

    fn tri(t: &[Vec3; 3]) -> Triangle {
        Triangle {
            v0: t[0].into(),
            v1: t[1].into(),
            v2: t[2].into(),
        }
    }

    pub fn input(mesh: &TriMesh) -> Vec<Triangle> {
        soup(mesh).iter().map(tri).collect()
    }

    pub fn build(tris: Vec<Triangle>, params: obvhs::BvhBuildParams) -> Obvhs {
        let bvh = build_bvh2_from_tris(&tris, params, &mut Duration::default());
        let ordered = bvh
            .primitive_indices
            .iter()
            .map(|&i| tris[i as usize])
            .collect();
        Obvhs {
            bvh,
            tris: ordered,
            pre_split: params.pre_split,
        }
    }

    impl Obvhs {
        pub fn closest(&self, ray: &obvhs::ray::Ray) -> Option<(f32, u32)> {
            let mut hit = RayHit::none();
            let tris = &self.tris;
            self.bvh
                .ray_traverse(*ray, &mut hit, |r, id| tris[id].intersect(r))
                .then(|| (hit.t, self.bvh.primitive_indices[hit.primitive_id as usize]))
        }

        pub fn sah(&self) -> f64 {
            let nodes = &self.bvh.nodes;
            let mut s = SahSum::default();
            let mut stack = vec![0usize];
            while let Some(i) = stack.pop() {
                let n = &nodes[i];
                let (min, max) = (n.aabb().min.to_array(), n.aabb().max.to_array());
                if n.is_leaf() {
                    s.leaf(min, max, n.prim_count);
                } else {
                    s.interior(min, max);
                    stack.push(n.first_index as usize);
                    stack.push(n.first_index as usize + 1);
                }
            }
            let r = nodes[0].aabb();
            s.finish(r.min.to_array(), r.max.to_array())
        }

        /// New leaf boxes from the moved triangles, then obvhs's `refit_all` for the interior
        /// nodes. Not with spatial pre-splits (a split reference's box is a clipped part of its
        /// triangle).
        pub fn refit(&mut self, tris: &[Triangle]) -> bool {
            if self.pre_split {
                return false;
            }
            for (o, &i) in self.tris.iter_mut().zip(&self.bvh.primitive_indices) {
                *o = tris[i as usize];
            }
            for n in &mut self.bvh.nodes {
                if n.is_leaf() {
                    let first = n.first_index as usize;
                    let b = self.tris[first..first + n.prim_count as usize]
                        .iter()
                        .fold(Aabb::empty(), |b, t| b.union(&t.aabb()));
                    n.set_aabb(b);
                }
            }
            self.bvh.refit_all();
            true
        }
    }

    pub fn ray(r: &Ray) -> obvhs::ray::Ray {
        obvhs::ray::Ray::new_inf(Vec3A::from(r.origin()), Vec3A::from(r.dir()))
    }
}

// ---------------------------------------------------------------------------------------------
// bvh crate (one primitive per leaf, SAH with buckets)
// ---------------------------------------------------------------------------------------------

mod bv {
    use super::*;
    use bvh::aabb::{Aabb, Bounded};
    use bvh::bounding_hierarchy::BHShape;
    use bvh::bvh::{Bvh, BvhNode};
    use nalgebra::{Point3, Vector3};

    /// A triangle as the bvh crate wants it: its box on demand and the index of its leaf.
    #[derive(Clone, Copy)]
    pub struct Shape {
        pub t: [Vec3; 3],
        /// Index in the input mesh.
        index: u32,
        node: usize,
    }

    fn p(v: Vec3) -> Point3<f32> {
        Point3::new(v.x, v.y, v.z)
    }

    impl Bounded<f32, 3> for Shape {
        fn aabb(&self) -> Aabb<f32, 3> {
            let [a, b, c] = self.t;
            Aabb::with_bounds(p(a.min(b).min(c)), p(a.max(b).max(c)))
        }
    }

    impl BHShape<f32, 3> for Shape {
        fn set_bh_node_index(&mut self, i: usize) {
            self.node = i;
        }
        fn bh_node_index(&self) -> usize {
            self.node
        }
    }

    pub struct BvhCrate {
        bvh: Bvh<f32, 3>,
        shapes: Vec<Shape>,
        /// Every interior node's children come after it (checked at build), so a reverse sweep
        /// refits bottom-up.
        children_after_parents: bool,
    }

    pub fn input(mesh: &TriMesh) -> Vec<Shape> {
        soup(mesh)
            .into_iter()
            .enumerate()
            .map(|(i, t)| Shape {
                t,
                index: i as u32,
                node: 0,
            })
            .collect()
    }

    pub fn build(mut shapes: Vec<Shape>) -> BvhCrate {
        let bvh = Bvh::build(&mut shapes);
        let children_after_parents = bvh.nodes.iter().enumerate().all(|(i, n)| match n {
            BvhNode::Node {
                child_l_index,
                child_r_index,
                ..
            } => *child_l_index > i && *child_r_index > i,
            BvhNode::Leaf { .. } => true,
        });
        BvhCrate {
            bvh,
            shapes,
            children_after_parents,
        }
    }

    /// The crate's ray (nalgebra) and ours (for the triangle test).
    pub type R = (bvh::ray::Ray<f32, 3>, Ray);

    pub fn ray(r: &Ray) -> R {
        (
            bvh::ray::Ray::new(p(r.origin()), Vector3::new(r.dir().x, r.dir().y, r.dir().z)),
            *r,
        )
    }

    fn area(b: &Aabb<f32, 3>) -> ([f32; 3], [f32; 3]) {
        (b.min.coords.into(), b.max.coords.into())
    }

    impl BvhCrate {
        /// The crate's nearest-first iterator yields candidate triangles in the order of their
        /// boxes' entry distances; the search stops once a box starts beyond the closest hit.
        /// The triangle test is dynbvh's watertight one: the crate's own culls back faces, and
        /// the rays from inside the meshes need both sides.
        pub fn closest(&self, (bray, ray): &R) -> Option<(f32, u32)> {
            let pre = RayTriPrecomp::new(ray.dir());
            let mut best: Option<(f32, u32)> = None;
            for s in self.bvh.nearest_traverse_iterator(bray, &self.shapes) {
                let tmax = best.map_or(f32::INFINITY, |b| b.0);
                if best.is_some() {
                    let entry = bray
                        .intersection_slice_for_aabb(&s.aabb())
                        .map_or(f32::INFINITY, |e| e.0);
                    if entry > tmax {
                        break;
                    }
                }
                let [a, b, c] = s.t;
                if let Some((t, _, _)) = intersect_triangle(ray, &pre, a, b, c, tmax) {
                    best = Some((t, s.index));
                }
            }
            best
        }

        pub fn sah(&self) -> f64 {
            let mut s = SahSum::default();
            let mut root = None;
            for n in &self.bvh.nodes {
                if let BvhNode::Node {
                    child_l_aabb,
                    child_r_aabb,
                    ..
                } = n
                {
                    // Each child's box sits in its parent; a leaf holds one triangle.
                    for b in [child_l_aabb, child_r_aabb] {
                        let (lo, hi) = area(b);
                        s.leaf(lo, hi, 1);
                    }
                    if root.is_none() {
                        root = Some(child_l_aabb.join(child_r_aabb));
                    }
                }
            }
            // Children were all counted as cost-1 nodes, which is also what an interior node
            // costs; add the root.
            let (lo, hi) = area(&root.expect("a tree with at least two triangles"));
            s.interior(lo, hi);
            s.finish(lo, hi)
        }

        /// New triangle positions, then every interior node's two child boxes recomputed
        /// bottom-up (the crate has no refit of its own: `update_shapes` removes and reinserts).
        pub fn refit(&mut self, shapes: &[Shape]) -> bool {
            assert!(self.children_after_parents, "bvh crate node order changed");
            for (s, n) in self.shapes.iter_mut().zip(shapes) {
                s.t = n.t;
            }
            let nodes = &mut self.bvh.nodes;
            for i in (0..nodes.len()).rev() {
                if let BvhNode::Node {
                    child_l_index,
                    child_r_index,
                    ..
                } = nodes[i]
                {
                    let boxes = [child_l_index, child_r_index].map(|c| match &nodes[c] {
                        BvhNode::Leaf { shape_index, .. } => self.shapes[*shape_index].aabb(),
                        BvhNode::Node {
                            child_l_aabb,
                            child_r_aabb,
                            ..
                        } => child_l_aabb.join(child_r_aabb),
                    });
                    if let BvhNode::Node {
                        child_l_aabb,
                        child_r_aabb,
                        ..
                    } = &mut nodes[i]
                    {
                        *child_l_aabb = boxes[0];
                        *child_r_aabb = boxes[1];
                    }
                }
            }
            true
        }
    }
}

// ---------------------------------------------------------------------------------------------
// parry3d (Bvh over triangle boxes, binned or PLOC)
// ---------------------------------------------------------------------------------------------

mod pa {
    use super::*;
    use parry3d::bounding_volume::Aabb;
    use parry3d::math::Vector;
    use parry3d::partitioning::{Bvh, BvhBuildStrategy, BvhWorkspace, TraversalAction};
    use parry3d::query::RayCast;
    use parry3d::shape::Triangle;

    pub struct Parry {
        bvh: Bvh,
        tris: Vec<Triangle>,
        workspace: BvhWorkspace,
    }

    fn v(x: Vec3) -> Vector {
        Vector::new(x.x, x.y, x.z)
    }

    pub fn input(mesh: &TriMesh) -> Vec<Triangle> {
        soup(mesh)
            .iter()
            .map(|t| Triangle::new(v(t[0]), v(t[1]), v(t[2])))
            .collect()
    }

    pub fn build(tris: Vec<Triangle>, strategy: BvhBuildStrategy) -> Parry {
        let boxes: Vec<Aabb> = tris.iter().map(Triangle::local_aabb).collect();
        Parry {
            bvh: Bvh::from_leaves(strategy, &boxes),
            tris,
            workspace: BvhWorkspace::default(),
        }
    }

    pub fn ray(r: &Ray) -> parry3d::query::Ray {
        parry3d::query::Ray::new(v(r.origin()), v(r.dir()))
    }

    fn arr(x: Vector) -> [f32; 3] {
        [x.x, x.y, x.z]
    }

    impl Parry {
        /// parry's best-first `Bvh::cast_ray` with its own ray-triangle test.
        pub fn closest(&self, ray: &parry3d::query::Ray) -> Option<(f32, u32)> {
            self.bvh
                .cast_ray(ray, f32::MAX, |leaf, best| {
                    self.tris[leaf as usize].cast_local_ray(ray, best, true)
                })
                .map(|(leaf, t)| (t, leaf))
        }

        pub fn sah(&self) -> f64 {
            let mut s = SahSum::default();
            // One triangle per leaf: every node below the root costs 1 x its area.
            self.bvh.traverse(|n| {
                let b = n.aabb();
                s.leaf(arr(b.mins), arr(b.maxs), 1);
                TraversalAction::Continue
            });
            let r = self.bvh.root_aabb();
            s.interior(arr(r.mins), arr(r.maxs));
            s.finish(arr(r.mins), arr(r.maxs))
        }

        /// New leaf boxes (`update_partially_if_present`, no margin), then `Bvh::refit`.
        pub fn refit(&mut self, tris: &[Triangle]) -> bool {
            self.tris.copy_from_slice(tris);
            for (i, t) in self.tris.iter().enumerate() {
                self.bvh
                    .update_partially_if_present(t.local_aabb(), i as u32, 0.0);
            }
            self.bvh.refit(&mut self.workspace);
            true
        }
    }
}

// Adapters from the library modules to the harness interface, one type per library; the
// build settings are chosen by the variant's build closure.
macro_rules! accel {
    ($name:ident, $inner:ty, $input:ty, $r:ty, $prep:path, $ray:path) => {
        struct $name($inner);
        impl Accel for $name {
            type Input = $input;
            type R = $r;
            fn prepare(mesh: &TriMesh) -> Self::Input {
                $prep(mesh)
            }
            fn ray(r: &Ray) -> Self::R {
                $ray(r)
            }
            #[inline]
            fn closest(&self, ray: &Self::R) -> Option<(f32, u32)> {
                self.0.closest(ray)
            }
            fn sah(&self) -> f64 {
                self.0.sah()
            }
            fn refit(&mut self, input: &Self::Input) -> bool {
                self.0.refit(input)
            }
        }
    };
}

accel!(
    ObvhsA,
    ob::Obvhs,
    Vec<obvhs::triangle::Triangle>,
    obvhs::ray::Ray,
    ob::input,
    ob::ray
);
accel!(
    BvhA,
    bv::BvhCrate,
    Vec<bv::Shape>,
    bv::R,
    bv::input,
    bv::ray
);
accel!(
    ParryA,
    pa::Parry,
    Vec<parry3d::shape::Triangle>,
    parry3d::query::Ray,
    pa::input,
    pa::ray
);

// ---------------------------------------------------------------------------------------------
// Inputs
// ---------------------------------------------------------------------------------------------

struct Input {
    name: String,
    rest: TriMesh,
    deformed: Option<TriMesh>,
    /// (set name, rays traced for speed, sample checked against brute force on `rest`).
    sets: Vec<RaySet>,
    /// Samples of the `_def` ray sets, checked against brute force on `deformed` after a refit.
    def_checks: Vec<Checked>,
}

struct RaySet {
    name: &'static str,
    rays: Vec<Ray>,
    check: Checked,
}

/// Sample rays and their brute-force closest hits.
struct Checked {
    rays: Vec<Ray>,
    hits: Vec<Option<(f32, u32)>>,
}

impl Checked {
    fn new(mesh: &TriMesh, all: &[Ray]) -> Self {
        let step = (all.len() / CHECK_RAYS).max(1);
        let rays: Vec<Ray> = all.iter().step_by(step).take(CHECK_RAYS).copied().collect();
        let hits = rays
            .iter()
            .map(|r| brute_force_closest(mesh, r).map(|h| (h.t, h.prim)))
            .collect();
        Self { rays, hits }
    }
}

fn ray_budget() -> Option<usize> {
    match std::env::var("DYNBVH_PEERS_RAYS") {
        Ok(s) if s == "all" || s == "0" => None,
        Ok(s) => Some(s.parse().expect("DYNBVH_PEERS_RAYS: a ray count or `all`")),
        Err(_) => Some(DEFAULT_RAYS),
    }
}

/// A coherent subset of about `n` camera rays (`dynbvh::report::rays::image_subset`), or all
/// of them when `n` is `None`.
fn image_subset(rays: &[Ray], n: Option<usize>) -> Vec<Ray> {
    match n {
        Some(n) => dynbvh::report::rays::image_subset(rays, n),
        None => rays.to_vec(),
    }
}

fn load(dir: &Path, stem: &str) -> Option<Input> {
    let path = |s: String| dir.join(s);
    let needed = [
        format!("{stem}.tri"),
        format!("{stem}_primary.rays"),
        format!("{stem}_random.rays"),
    ];
    let missing: Vec<&String> = needed
        .iter()
        .filter(|f| !path((*f).clone()).is_file())
        .collect();
    if !missing.is_empty() {
        eprintln!(
            "skipping {stem}: {missing:?} not in {} (generate with `rustc -O \
             ../shared/bench-inputs/gen.rs -o gen && ./gen DIR --no-obj`, or set DYNBVH_BENCH_INPUTS)",
            dir.display()
        );
        return None;
    }
    let t = Instant::now();
    let rest = read_tri(&path(format!("{stem}.tri"))).expect("read .tri");
    let def_path = path(format!("{stem}_def.tri"));
    let deformed = def_path
        .is_file()
        .then(|| read_tri(&def_path).expect("read _def.tri"));
    if deformed.is_none() {
        eprintln!("{stem}: no {stem}_def.tri, so no refit");
    }
    let budget = ray_budget();
    let mut sets = Vec::new();
    for name in ["primary", "random"] {
        let all = read_rays(&path(format!("{stem}_{name}.rays"))).expect("read .rays");
        let rays = if name == "primary" {
            in_tiles(image_subset(&all, budget))
        } else {
            all.iter()
                .take(budget.unwrap_or(usize::MAX))
                .copied()
                .collect()
        };
        let check = Checked::new(&rest, &all);
        sets.push(RaySet { name, rays, check });
    }
    let mut def_checks = Vec::new();
    if let Some(def) = &deformed {
        for name in ["primary", "random"] {
            let p = path(format!("{stem}_def_{name}.rays"));
            if p.is_file() {
                def_checks.push(Checked::new(def, &read_rays(&p).expect("read .rays")));
            }
        }
    }
    eprintln!(
        "{stem}: {} triangles, {} + {} rays per pass, loaded and brute-forced in {:.1} s",
        rest.len(),
        sets[0].rays.len(),
        sets[1].rays.len(),
        t.elapsed().as_secs_f64()
    );
    Some(Input {
        name: stem.into(),
        rest,
        deformed,
        sets,
        def_checks,
    })
}

// ---------------------------------------------------------------------------------------------
/// A square image's rays reordered as a renderer casts packets
/// (`dynbvh::bvh::image_tiles`): tiles of 16x8 pixels, each in 4x4 blocks, so that 16
/// consecutive rays are a 4x4 block and 128 a 16x8 tile. Every variant traces this same order.
fn in_tiles(rays: Vec<Ray>) -> Vec<Ray> {
    let side = (rays.len() as f64).sqrt().round() as usize;
    if side * side != rays.len() {
        return rays;
    }
    let mut out = Vec::with_capacity(rays.len());
    dynbvh::bvh::image_tiles(side, side, |idx| out.extend(idx.iter().map(|&i| rays[i])));
    out
}

// ---------------------------------------------------------------------------------------------
// Measuring
// ---------------------------------------------------------------------------------------------

/// A library with one build setting.
struct Variant {
    name: &'static str,
    /// Starts the measurement of this variant on an input.
    make: for<'a> fn(&'a Input) -> Box<dyn Measure + 'a>,
}

/// Hits that disagree with brute force on a sample.
#[derive(Clone, Copy, Default)]
struct Mismatch {
    /// Brute force hits, the library misses.
    missed: usize,
    /// The library hits, brute force does not.
    extra: usize,
    /// Both hit, at distances that differ by more than 1e-4 relative.
    other_t: usize,
    checked: usize,
}

impl Mismatch {
    fn total(&self) -> usize {
        self.missed + self.extra + self.other_t
    }
    fn add(&mut self, o: Mismatch) {
        self.missed += o.missed;
        self.extra += o.extra;
        self.other_t += o.other_t;
        self.checked += o.checked;
    }
    fn describe(&self) -> String {
        if self.total() == 0 {
            format!("0/{}", self.checked)
        } else {
            format!(
                "{}/{} ({} missed, {} extra, {} other t)",
                self.total(),
                self.checked,
                self.missed,
                self.extra,
                self.other_t
            )
        }
    }
}

struct Row {
    build_ms: f64,
    sah: f64,
    mrays: Vec<f64>,
    refit_ms: Option<f64>,
    sah_refit: Option<f64>,
    check: Mismatch,
    check_refit: Option<Mismatch>,
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

fn check<A: Accel>(a: &A, c: &Checked) -> Mismatch {
    let mut m = Mismatch {
        checked: c.rays.len(),
        ..Mismatch::default()
    };
    for (r, want) in c.rays.iter().zip(&c.hits) {
        match (a.closest(&A::ray(r)), want) {
            (None, Some(_)) => m.missed += 1,
            (Some(_), None) => m.extra += 1,
            (Some((t, _)), Some((tw, _))) if (t - tw).abs() > 1e-4 * tw.abs().max(1.0) => {
                m.other_t += 1;
            }
            _ => {}
        }
    }
    m
}

/// One variant's measurement, type-erased so that the harness can interleave the runs of all
/// variants (run 1 of every variant, then run 2, ...): on a shared machine, a neighbour's load
/// then falls on all of them alike.
trait Measure {
    /// Builds a new tree (dropping the previous one first); milliseconds.
    fn build(&mut self) -> f64;
    fn sah(&self) -> f64;
    /// One pass of closest-hit queries over ray set `set`; Mrays/s.
    fn trace(&self, set: usize) -> f64;
    /// The current tree's hits against brute force on the rest pose's samples.
    fn check(&self) -> Mismatch;
    /// Refits to the deformed pose (timed, milliseconds) and back (untimed); the first time,
    /// also the SAH and the hits after the refit. `None` when the variant cannot refit or the
    /// input has no deformed pose.
    fn refit(&mut self) -> Option<f64>;
    /// SAH and brute-force check after the first refit.
    fn after_refit(&self) -> (Option<f64>, Option<Mismatch>);
}

struct Gen<'a, A: Accel, F> {
    input: &'a Input,
    build_fn: F,
    accel: Option<A>,
    rays: Vec<Vec<A::R>>,
    /// The rest and deformed poses in the library's form, made on the first refit.
    poses: Option<(A::Input, A::Input)>,
    sah_refit: Option<f64>,
    check_refit: Option<Mismatch>,
}

fn measured<'a, A: Accel + 'a>(
    input: &'a Input,
    build_fn: impl Fn(A::Input) -> A + 'a,
) -> Box<dyn Measure + 'a> {
    Box::new(Gen {
        input,
        build_fn,
        accel: None,
        rays: input
            .sets
            .iter()
            .map(|s| s.rays.iter().map(A::ray).collect())
            .collect(),
        poses: None,
        sah_refit: None,
        check_refit: None,
    })
}

impl<A: Accel, F: Fn(A::Input) -> A> Measure for Gen<'_, A, F> {
    fn build(&mut self) -> f64 {
        let prepared = A::prepare(&self.input.rest);
        self.accel = None;
        let t = Instant::now();
        let a = (self.build_fn)(prepared);
        let ms = t.elapsed().as_secs_f64() * 1e3;
        self.accel = Some(a);
        ms
    }

    fn sah(&self) -> f64 {
        self.accel.as_ref().expect("built").sah()
    }

    fn trace(&self, set: usize) -> f64 {
        let accel = self.accel.as_ref().expect("built");
        let rays = &self.rays[set];
        if cpu_timing() {
            // The process's CPU clock may advance in scheduler ticks (4 ms): repeat the pass
            // for at least 0.3 s of CPU time.
            let c = cpu::cpu_s();
            let mut passes = 0;
            while passes == 0 || cpu::cpu_s() - c < 0.3 {
                black_box(accel.trace_all(rays));
                passes += 1;
            }
            return (passes * rays.len()) as f64 / (cpu::cpu_s() - c) / 1e6;
        }
        if threads() > 1 {
            let t = Instant::now();
            let mut passes = 0;
            while passes == 0 || t.elapsed().as_secs_f64() < 0.3 {
                let sum: f32 = accel.trace_all_threads(rays);
                black_box(sum);
                passes += 1;
            }
            return (passes * rays.len()) as f64 / t.elapsed().as_secs_f64() / 1e6;
        }
        let t = Instant::now();
        black_box(accel.trace_all(rays));
        rays.len() as f64 / t.elapsed().as_secs_f64() / 1e6
    }

    fn check(&self) -> Mismatch {
        let accel = self.accel.as_ref().expect("built");
        let mut m = Mismatch::default();
        for set in &self.input.sets {
            m.add(check(accel, &set.check));
        }
        m
    }

    fn refit(&mut self) -> Option<f64> {
        let def = self.input.deformed.as_ref()?;
        let (rest, moved) = self
            .poses
            .get_or_insert_with(|| (A::prepare(&self.input.rest), A::prepare(def)));
        let accel = self.accel.as_mut().expect("built");
        let t = Instant::now();
        if !accel.refit(moved) {
            return None;
        }
        let ms = t.elapsed().as_secs_f64() * 1e3;
        if self.sah_refit.is_none() {
            self.sah_refit = Some(accel.sah());
            let mut m = Mismatch::default();
            for c in &self.input.def_checks {
                m.add(check(accel, c));
            }
            self.check_refit = Some(m);
        }
        accel.refit(rest);
        Some(ms)
    }

    fn after_refit(&self) -> (Option<f64>, Option<Mismatch>) {
        (self.sah_refit, self.check_refit)
    }
}

/// Measures the variants on one input, their runs interleaved.
fn measure_all(input: &Input, variants: &[&Variant]) -> Vec<Row> {
    let mut ms: Vec<Box<dyn Measure + '_>> = variants.iter().map(|v| (v.make)(input)).collect();
    let n = ms.len();
    let progress = |what: &str, t: Instant| {
        eprintln!(
            "  {}: {what} in {:.1} s",
            input.name,
            t.elapsed().as_secs_f64()
        );
    };

    let t = Instant::now();
    // One untimed build of each variant first: the first builds of a process touch memory
    // it has never used, which these VMs back slowly (up to twice a build's time in the first
    // round, more than the later rounds' spread).
    for m in &mut ms {
        m.build();
    }
    let mut builds = vec![Vec::new(); n];
    let mut order: Vec<usize> = (0..n).collect();
    let mut seed = 0x9e37_79b9_7f4a_7c15_u64;
    for run in 0..BUILD_RUNS {
        // Each round builds the variants in another order (a fixed pseudo-random shuffle), so
        // that no variant always builds right after the same other one: what a build leaves
        // in memory changes the next one's time (a rotation of one order would keep every
        // variant after the same neighbour in all but one round).
        for k in (1..n).rev() {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            order.swap(k, (seed % (k as u64 + 1)) as usize);
        }
        for &i in &order {
            let times = &mut builds[i];
            // Three builds are enough for multi-second builders.
            if run < 3 || median(times.clone()) < 1000.0 {
                times.push(ms[i].build());
            }
        }
    }
    progress("builds", t);
    if std::env::var_os("DYNBVH_PEERS_BUILDS").is_some() {
        for (v, b) in variants.iter().zip(&builds) {
            eprintln!("  {}: builds {b:.1?} ms", v.name);
        }
    }

    let t = Instant::now();
    let mut traces = vec![vec![Vec::new(); input.sets.len()]; n];
    for _ in 0..TRACE_RUNS {
        for (m, per_set) in ms.iter().zip(&mut traces) {
            for (set, runs) in per_set.iter_mut().enumerate() {
                runs.push(m.trace(set));
            }
        }
    }
    progress("traversal", t);
    // SAH and hits of the freshly built trees, before any refit.
    let sahs: Vec<f64> = ms.iter().map(|m| m.sah()).collect();
    let checks: Vec<Mismatch> = ms.iter().map(|m| m.check()).collect();

    let t = Instant::now();
    let mut refits = vec![Vec::new(); n];
    for _ in 0..REFIT_RUNS {
        for (m, runs) in ms.iter_mut().zip(&mut refits) {
            if let Some(ms) = m.refit() {
                runs.push(ms);
            }
        }
    }
    progress("refits", t);

    (0..n)
        .map(|i| {
            let (sah_refit, check_refit) = ms[i].after_refit();
            Row {
                build_ms: median(builds[i].clone()),
                sah: sahs[i],
                mrays: traces[i].iter().map(|r| median(r.clone())).collect(),
                refit_ms: (!refits[i].is_empty()).then(|| median(refits[i].clone())),
                sah_refit,
                check: checks[i],
                check_refit,
            }
        })
        .collect()
}

fn variants() -> Vec<Variant> {
    use obvhs::BvhBuildParams as P;
    use parry3d::partitioning::BvhBuildStrategy as S;
    vec![
        Variant {
            name: "dynbvh binned16",
            make: |i| {
                measured(i, |m: TriMesh| {
                    Dyn(MeshBvh::build(&m, &BuildParams::BINNED))
                })
            },
        },
        Variant {
            name: "dynbvh bvh8",
            make: |i| {
                measured(i, |m: TriMesh| {
                    DynWide(dynbvh::bvh::MeshBvh8::build(&m, &BuildParams::BINNED))
                })
            },
        },
        Variant {
            // The binary tree collapsed by the SAH-optimal dynamic program instead of the
            // greedy pull-up (`docs/wide.md`, issue 17, third session).
            name: "dynbvh bvh8 sah-collapse",
            make: |i| {
                measured(i, |m: TriMesh| {
                    DynWide(dynbvh::bvh::MeshBvh8::from_mesh_bvh_with(
                        &MeshBvh::build(&m, &BuildParams::BINNED),
                        dynbvh::bvh::CollapseMethod::SAH,
                    ))
                })
            },
        },
        Variant {
            // The same tree as before huge pages and the multiply-add slab test: copied by
            // `Clone` (4 KiB pages) and set to the plain slab test (a refit restores it, so
            // only its rays are "before"; the copy is inside its build time).
            name: "dynbvh bvh8 (4k pages, plain slab)",
            make: |i| {
                measured(i, |m: TriMesh| {
                    let w = dynbvh::bvh::MeshBvh8::from_mesh_bvh(&MeshBvh::build(
                        &m,
                        &BuildParams::BINNED,
                    ));
                    let mut c = w.clone();
                    drop(w);
                    c.bench_plain_slab();
                    DynWide(c)
                })
            },
        },
        Variant {
            // The same tree and traversal with the stack zeroed for every ray and two hit
            // children sorted by the insertion loop (`docs/wide.md`, fourth session).
            name: "dynbvh bvh8 before (zeroed stack)",
            make: |i| {
                measured(i, |m: TriMesh| {
                    DynWideBefore(DynWide(dynbvh::bvh::MeshBvh8::from_mesh_bvh(
                        &MeshBvh::build(&m, &BuildParams::BINNED),
                    )))
                })
            },
        },
        Variant {
            name: "dynbvh packets",
            make: |i| {
                measured(i, |m: TriMesh| {
                    DynPackets(Dyn(MeshBvh::build(&m, &BuildParams::BINNED)))
                })
            },
        },
        Variant {
            name: "dynbvh bvh8 batch",
            make: |i| {
                measured(i, |m: TriMesh| {
                    DynWideBatch(DynWide(dynbvh::bvh::MeshBvh8::build(
                        &m,
                        &BuildParams::BINNED,
                    )))
                })
            },
        },
        Variant {
            name: "dynbvh packets bvh8",
            make: |i| {
                measured(i, |m: TriMesh| {
                    DynWidePackets(DynWide(dynbvh::bvh::MeshBvh8::build(
                        &m,
                        &BuildParams::BINNED,
                    )))
                })
            },
        },
        Variant {
            name: "dynbvh median",
            make: |i| {
                measured(i, |m: TriMesh| {
                    Dyn(MeshBvh::build(&m, &BuildParams::MEDIAN))
                })
            },
        },
        Variant {
            name: "dynbvh sweep",
            make: |i| measured(i, |m: TriMesh| Dyn(MeshBvh::build(&m, &BuildParams::SWEEP))),
        },
        Variant {
            name: "obvhs fastest",
            make: |i| measured(i, |t| ObvhsA(ob::build(t, P::fastest_build()))),
        },
        Variant {
            name: "obvhs medium",
            make: |i| measured(i, |t| ObvhsA(ob::build(t, P::medium_build()))),
        },
        Variant {
            name: "obvhs very_slow",
            make: |i| measured(i, |t| ObvhsA(ob::build(t, P::very_slow_build()))),
        },
        Variant {
            name: "bvh (SAH)",
            make: |i| measured(i, |s| BvhA(bv::build(s))),
        },
        Variant {
            name: "parry3d binned",
            make: |i| measured(i, |t| ParryA(pa::build(t, S::Binned))),
        },
        Variant {
            name: "parry3d ploc",
            make: |i| measured(i, |t| ParryA(pa::build(t, S::Ploc))),
        },
        #[cfg(feature = "embree")]
        Variant {
            name: "embree medium",
            make: |i| measured(i, |m| embree_ffi::build(m, embree_ffi::Mode::Medium)),
        },
        #[cfg(feature = "embree")]
        Variant {
            name: "embree medium x16",
            make: |i| measured(i, |m| embree_ffi::build(m, embree_ffi::Mode::MediumPackets)),
        },
        #[cfg(feature = "embree")]
        Variant {
            name: "embree medium robust",
            make: |i| measured(i, |m| embree_ffi::build(m, embree_ffi::Mode::MediumRobust)),
        },
        #[cfg(feature = "embree")]
        Variant {
            name: "embree medium robust x16",
            make: |i| {
                measured(i, |m| {
                    embree_ffi::build(m, embree_ffi::Mode::MediumRobustPackets)
                })
            },
        },
        #[cfg(feature = "embree")]
        Variant {
            name: "embree low refit",
            make: |i| measured(i, |m| embree_ffi::build(m, embree_ffi::Mode::LowRefit)),
        },
    ]
}

// ---------------------------------------------------------------------------------------------
// Report
// ---------------------------------------------------------------------------------------------

fn ratio(x: f64, base: f64) -> String {
    format!("{:.2}x", x / base)
}

fn print_table(input: &Input, rows: &[(&str, Row)]) {
    let base = &rows[0].1;
    println!(
        "\n## {} ({} triangles), {}; ratios are to {}{}\n",
        input.name,
        input.rest.len(),
        match threads() {
            1 => "1 thread".to_string(),
            n => format!("{n} threads"),
        },
        rows[0].0,
        if cpu_timing() {
            "; Mrays/s in CPU time"
        } else if threads() > 1 {
            "; Mrays/s in wall-clock time"
        } else {
            ""
        }
    );
    let set_names: Vec<&str> = input.sets.iter().map(|s| s.name).collect();
    println!(
        "| variant | build ms | build ratio | SAH | SAH ratio | {} | refit ms | refit ratio | SAH after refit | hits vs brute force | after refit |",
        set_names
            .iter()
            .map(|s| format!("{s} Mrays/s | {s} ratio"))
            .collect::<Vec<_>>()
            .join(" | ")
    );
    println!(
        "|---|---:|---:|---:|---:|{}---:|---:|---:|---|---|",
        "---:|---:|".repeat(set_names.len())
    );
    for (name, r) in rows {
        let speeds: Vec<String> = r
            .mrays
            .iter()
            .zip(&base.mrays)
            .map(|(m, b)| format!("{m:.2} | {}", ratio(*m, *b)))
            .collect();
        let (refit, refit_ratio) = match (r.refit_ms, base.refit_ms) {
            (Some(x), Some(b)) => (format!("{x:.2}"), ratio(x, b)),
            (Some(x), None) => (format!("{x:.2}"), "-".into()),
            _ => ("-".into(), "-".into()),
        };
        // Wide trees (Embree's) have no binary SAH to report.
        let (sah, sah_ratio) = if r.sah.is_nan() {
            ("-".into(), "-".into())
        } else {
            (format!("{:.2}", r.sah), ratio(r.sah, base.sah))
        };
        println!(
            "| {name} | {:.1} | {} | {sah} | {sah_ratio} | {} | {refit} | {refit_ratio} | {} | {} | {} |",
            r.build_ms,
            ratio(r.build_ms, base.build_ms),
            speeds.join(" | "),
            r.sah_refit
                .filter(|s| !s.is_nan())
                .map_or("-".into(), |s| format!("{s:.2} ({:.2}x build)", s / r.sah)),
            r.check.describe(),
            r.check_refit.map_or("-".into(), |m| m.describe()),
        );
    }
}

/// The side-by-side figures against Embree for `input`, from the rows of the run that hold
/// them: dynbvh's 8-wide tree against Embree at its default flags and with the scene flag
/// ROBUST (the nearest Embree comes to dynbvh's exact walks), each as dynbvh over Embree (for
/// the rates in Mrays/s higher is better for dynbvh, for the times in ms lower is). A figure
/// whose rows were not run is left out.
fn print_embree_summary(input: &Input, rows: &[(&str, Row)]) {
    let row = |name: &str| rows.iter().find(|(n, _)| *n == name).map(|(_, r)| r);
    let set = |name: &str| input.sets.iter().position(|s| s.name == name);
    let rate = |name: &str, s: Option<usize>| Some(row(name)?.mrays[s?]);
    let (camera, random) = (set("primary"), set("random"));
    // (what, dynbvh's figure, Embree's at its default flags and with ROBUST)
    type Figure<'a> = (&'a str, Option<f64>, [Option<f64>; 2]);
    // Embree's figure on a ray set at its default flags and with ROBUST.
    let embree = |single: &str, robust: &str, s| [rate(single, s), rate(robust, s)];
    let figures: [Figure; 6] = [
        (
            "camera rays, single (`rtcIntersect1`), Mrays/s",
            rate("dynbvh bvh8", camera),
            embree("embree medium", "embree medium robust", camera),
        ),
        (
            "random rays, single, ray by ray, Mrays/s",
            rate("dynbvh bvh8", random),
            embree("embree medium", "embree medium robust", random),
        ),
        (
            "random rays, reordered batch (`dynbvh bvh8 batch`), Mrays/s",
            rate("dynbvh bvh8 batch", random),
            embree("embree medium", "embree medium robust", random),
        ),
        (
            "camera rays, packets (`rtcIntersect16`), Mrays/s",
            rate("dynbvh packets bvh8", camera),
            embree("embree medium x16", "embree medium robust x16", camera),
        ),
        (
            "build: binned16 and the collapse / scene commit, ms",
            row("dynbvh bvh8").map(|r| r.build_ms),
            [
                row("embree medium").map(|r| r.build_ms),
                row("embree medium robust").map(|r| r.build_ms),
            ],
        ),
        (
            "refit: the 8-wide tree / LOW + REFIT, ms",
            row("dynbvh bvh8").and_then(|r| r.refit_ms),
            [row("embree low refit").and_then(|r| r.refit_ms), None],
        ),
    ];
    let shown: Vec<_> = figures
        .iter()
        .filter(|(_, d, e)| d.is_some() && e.iter().any(Option::is_some))
        .collect();
    if shown.is_empty() {
        return;
    }
    println!(
        "\n### {}: dynbvh against Embree, at its default flags and with the scene flag ROBUST\n",
        input.name
    );
    println!("| figure | dynbvh | Embree | dynbvh / Embree | Embree ROBUST | dynbvh / ROBUST |");
    println!("|---|---:|---:|---:|---:|---:|");
    for (what, d, e) in shown {
        let d = d.expect("shown");
        let cell = |e: Option<f64>| {
            e.map_or(("-".to_string(), "-".to_string()), |e| {
                (format!("{e:.2}"), format!("{:.2}x", d / e))
            })
        };
        let (a, ar) = cell(e[0]);
        let (b, br) = cell(e[1]);
        println!("| {what} | {d:.2} | {a} | {ar} | {b} | {br} |");
    }
}

/// The time now in UTC, `YYYY-MM-DD HH:MM`.
fn utc_now() -> String {
    // `YYYY-MM-DDTHH:MM:SSZ`
    let t = humantime::format_rfc3339_seconds(std::time::SystemTime::now()).to_string();
    format!("{} {}", &t[..10], &t[11..16])
}

/// The machine the run is on: the CPU's model name, its logical CPUs (and how many this
/// process may run on, e.g. under `taskset`) and the widest vector instructions it has.
fn machine() -> String {
    let info = std::fs::read_to_string("/proc/cpuinfo").unwrap_or_default();
    let model = info
        .lines()
        .find(|l| l.starts_with("model name"))
        .and_then(|l| l.split_once(':'))
        .map_or_else(|| "unknown CPU".into(), |(_, m)| m.trim().to_string());
    let cpus = info.lines().filter(|l| l.starts_with("processor")).count();
    let usable = std::thread::available_parallelism().map_or(0, usize::from);
    #[cfg(target_arch = "x86_64")]
    let simd = if std::arch::is_x86_feature_detected!("avx512f") {
        "AVX-512"
    } else if std::arch::is_x86_feature_detected!("avx2") {
        "AVX2"
    } else {
        "SSE"
    };
    #[cfg(not(target_arch = "x86_64"))]
    let simd = std::env::consts::ARCH;
    format!("{model}, {cpus} logical CPUs ({usable} usable by this process), {simd}")
}

fn threads_in_process() -> Option<usize> {
    std::fs::read_dir("/proc/self/task").ok().map(|d| d.count())
}

fn main() {
    // `cargo bench` passes `--bench`; other words filter inputs and variants by substring.
    let filters: Vec<String> = std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with("--"))
        .collect();
    let wanted =
        |name: &str| filters.is_empty() || filters.iter().any(|f| name.contains(f.as_str()));
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = std::env::var_os("DYNBVH_BENCH_INPUTS")
        .map(PathBuf::from)
        .unwrap_or_else(|| root.join("target/bench-inputs"));
    let stems = ["sphere_100k", "sphere_1m", "soup_1m"];
    let stem_filtered = filters
        .iter()
        .any(|f| stems.iter().any(|s| s.contains(f.as_str())));
    let variants = variants();
    let variant_filtered = filters
        .iter()
        .any(|f| variants.iter().any(|v| v.name.contains(f.as_str())));

    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads())
        .build()
        .expect("the bench's thread pool");
    let threads_before = threads_in_process();
    println!(
        "# dynbvh side by side, {} UTC; {}; load average {}",
        utc_now(),
        machine(),
        std::fs::read_to_string("/proc/loadavg")
            .ok()
            .and_then(|l| l.split_whitespace().next().map(str::to_string))
            .unwrap_or_else(|| "unknown".into())
    );
    pool.install(|| {
        for stem in stems {
            if stem_filtered && !wanted(stem) {
                continue;
            }
            let Some(input) = load(&dir, stem) else {
                continue;
            };
            // The first variant is the reference for the ratios: always run it.
            let chosen: Vec<&Variant> = variants
                .iter()
                .enumerate()
                .filter(|(k, v)| *k == 0 || !variant_filtered || wanted(v.name))
                .map(|(_, v)| v)
                .collect();
            let rows: Vec<(&str, Row)> = chosen
                .iter()
                .map(|v| v.name)
                .zip(measure_all(&input, &chosen))
                .collect();
            print_table(&input, &rows);
            print_embree_summary(&input, &rows);
        }
    });
    let threads_after = threads_in_process();
    println!(
        "\nThreads in the process: {threads_before:?} before and {threads_after:?} after the run \
         (main, the bench's pool of {} thread(s), with more than one Embree's own worker threads; the global rayon pool was never started).",
        threads()
    );
}
