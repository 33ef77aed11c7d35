//! The kd-tree with the surface area heuristic: one axis-aligned plane per node, candidate
//! planes at the faces of the triangles' boxes clipped to the node's cell, and leaves that may
//! share triangles. Two builders make the same tree: the O(N log N) one of Wald & Havran 2006
//! (events sorted once, split lists carried down in order) and the naive O(N log² N) one that
//! re-sorts at every node. Traversal is ordered by the course's near/far rule on a fixed stack,
//! with mailboxing for triangles met again in later leaves.

mod build_fast;
mod build_naive;
mod clip;
mod events;
mod traverse;
mod validate;

use super::Accel;
use super::triangles::Triangles;
use crate::bvh::TraversalStats;
use crate::geom::{Aabb, Hit, Ray, TriMesh};
use glam::Vec3;

/// The deepest a kd-tree may be; traversal stacks have this many entries.
pub const MAX_KD_DEPTH: usize = 64;

/// Which builder makes the tree.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KdBuild {
    /// Events sorted once, lists split in order: O(N log N) (Wald & Havran 2006).
    Sorted,
    /// Events made and sorted again at every node: O(N log² N).
    Naive,
}

/// How a kd-tree is built: the SAH's named costs and the limits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KdParams {
    /// Cost of visiting an interior node.
    pub traversal_cost: f32,
    /// Cost of one triangle test.
    pub intersection_cost: f32,
    /// Fraction of a split's cost waived when one child is empty (cutting off empty space).
    pub empty_bonus: f32,
    /// Depth limit; `None`: `8 + 1.3 log2 N`, at most [`MAX_KD_DEPTH`].
    pub max_depth: Option<usize>,
    /// Perfect splits in the nodes of more than this many triangles: there a straddler's box
    /// in each child is that of the triangle clipped to the child's cell (Wald & Havran 2006,
    /// section 4.3), not its own box cut at the plane, so a cell it does not enter loses it.
    /// `0`: in every node; `usize::MAX` (the default): in none. Fewer triangles in the cells
    /// and faster traces for a dearer build (figures in `docs/accel.md`).
    pub perfect_splits_above: usize,
    /// Sweep only the cell's longest axis (pbrt's rule; the other two only when it offers no
    /// split that beats a leaf, in nodes of more than 16 triangles), instead of all three
    /// (Wald & Havran 2006): about a third of the sweep's work. On by default: on the spheres
    /// the tree's SAH and work per ray are those of the three-axis sweep (figures in
    /// `docs/accel.md`).
    pub longest_axis_only: bool,
    /// The builder.
    pub build: KdBuild,
}

/// The default costs: a triangle test at 0.3 of a traversal step, so that the SAH makes fuller
/// leaves and fewer nodes (a smaller tree, built faster) where splitting saves few tests: a
/// leaf tests only the triangles whose boxes the ray meets in its cell, so a fuller leaf costs
/// little. The sweeps over this cost that chose it are in `docs/accel.md`.
impl Default for KdParams {
    fn default() -> Self {
        Self {
            traversal_cost: 1.0,
            intersection_cost: 0.3,
            empty_bonus: 0.2,
            max_depth: None,
            perfect_splits_above: usize::MAX,
            longest_axis_only: true,
            build: KdBuild::Sorted,
        }
    }
}

impl KdParams {
    /// The naive builder with the default costs.
    pub const NAIVE: KdParams = KdParams {
        traversal_cost: 1.0,
        intersection_cost: 0.3,
        empty_bonus: 0.2,
        max_depth: None,
        perfect_splits_above: usize::MAX,
        longest_axis_only: true,
        build: KdBuild::Naive,
    };

    /// Whether a node of `n` triangles is split perfectly.
    #[must_use]
    pub fn perfect_at(&self, n: usize) -> bool {
        n > self.perfect_splits_above
    }

    /// The depth limit for `n` triangles.
    #[must_use]
    pub fn depth_limit(&self, n: usize) -> usize {
        self.max_depth
            .unwrap_or_else(|| 8 + (1.3 * (n.max(1) as f64).log2()).round() as usize)
            .min(MAX_KD_DEPTH)
    }
}

/// A node: an interior node's split plane and first child (the two children are adjacent and
/// stored after it), or a leaf's range of triangle references.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(C)]
pub(super) struct KdNode {
    /// Interior: the split position's bits. Leaf: the reference count.
    word: u32,
    /// `index << 2 | tag`, tag 0-2 the axis of an interior node (index: first child), 3 a leaf
    /// (index: first reference).
    data: u32,
}

const _: () = assert!(std::mem::size_of::<KdNode>() == 8);

/// Largest child or reference index a node can hold.
pub(super) const MAX_INDEX: usize = (1 << 30) - 1;

impl KdNode {
    fn interior(axis: usize, pos: f32, first_child: usize) -> Self {
        debug_assert!(first_child <= MAX_INDEX && axis < 3);
        Self {
            word: pos.to_bits(),
            data: (first_child as u32) << 2 | axis as u32,
        }
    }

    fn leaf(first: usize, count: usize) -> Self {
        debug_assert!(first <= MAX_INDEX);
        Self {
            word: count as u32,
            data: (first as u32) << 2 | 3,
        }
    }

    #[inline(always)]
    fn is_leaf(self) -> bool {
        self.data & 3 == 3
    }

    #[inline(always)]
    fn axis(self) -> usize {
        (self.data & 3) as usize
    }

    #[inline(always)]
    fn index(self) -> usize {
        (self.data >> 2) as usize
    }

    #[inline(always)]
    fn split(self) -> f32 {
        f32::from_bits(self.word)
    }

    #[inline(always)]
    fn count(self) -> usize {
        self.word as usize
    }
}

/// A leaf's copy of one of its triangles: the corners and the triangle's id.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C)]
pub(super) struct LeafTri {
    pub(super) corners: [Vec3; 3],
    pub(super) id: u32,
}

/// A kd-tree over a mesh's triangles.
#[derive(Clone, Debug, Default)]
pub struct KdTree {
    nodes: Vec<KdNode>,
    /// The leaves' triangles, leaf by leaf, each with its id: a leaf reads its triangles and
    /// their ids in order from one run of memory.
    leaf_tris: Vec<LeafTri>,
    tris: Triangles,
    /// The root cell: the box of every triangle that has one.
    bounds: Aabb,
    params: KdParams,
    sah: f32,
    depth: usize,
}

/// What a builder hands back: nodes (root first), leaf references, and the tree's SAH cost
/// (constants 1, root area 1) and depth.
pub(super) struct Built {
    pub(super) nodes: Vec<KdNode>,
    pub(super) refs: Vec<u32>,
    pub(super) sah: f64,
    pub(super) depth: usize,
}

impl KdTree {
    /// Builds a kd-tree over `mesh`'s triangles. Triangles without a box (NaN on every corner
    /// of an axis) can never be hit and are left out.
    ///
    /// # Panics
    /// When a vertex index is out of range, or the mesh has more than 2^30 triangles.
    #[must_use]
    pub fn build(mesh: &TriMesh, params: &KdParams) -> Self {
        assert!(mesh.len() <= MAX_INDEX, "too many triangles for a kd-tree");
        let tris = Triangles::of_mesh(mesh);
        let boxes = tris.boxes();
        let bounds = super::triangles::bounds_of(&boxes);
        let built = match params.build {
            KdBuild::Sorted => build_fast::build(&tris.tris, &boxes, &bounds, params),
            KdBuild::Naive => build_naive::build(&tris.tris, &boxes, &bounds, params),
        };
        // Rays read the leaves' triangles in scattered order: on huge pages where the system
        // gives them, as the triangles in mesh order are.
        let mut leaf_tris = Vec::new();
        crate::simd::reserve_huge(&mut leaf_tris, built.refs.len(), 0);
        leaf_tris.extend(built.refs.iter().map(|&r| LeafTri {
            corners: tris.tris[r as usize],
            id: r,
        }));
        Self {
            nodes: built.nodes,
            leaf_tris,
            tris,
            bounds,
            params: *params,
            sah: built.sah as f32,
            depth: built.depth,
        }
    }

    /// The build parameters.
    #[must_use]
    pub fn params(&self) -> &KdParams {
        &self.params
    }

    /// References held by the leaves (triangles in several leaves count once per leaf).
    #[must_use]
    pub fn reference_count(&self) -> usize {
        self.leaf_tris.len()
    }
}

impl Accel for KdTree {
    fn name(&self) -> String {
        match self.params.build {
            KdBuild::Sorted => "kdtree".into(),
            KdBuild::Naive => "kdtree-naive".into(),
        }
    }

    fn closest_hit(&self, ray: &Ray) -> Option<Hit> {
        self.closest(ray, &mut ())
    }

    fn any_hit(&self, ray: &Ray) -> bool {
        self.any(ray, &mut ())
    }

    fn closest_hit_counted(&self, ray: &Ray, stats: &mut TraversalStats) -> Option<Hit> {
        self.closest(ray, stats)
    }

    fn any_hit_counted(&self, ray: &Ray, stats: &mut TraversalStats) -> bool {
        self.any(ray, stats)
    }

    fn validate(&self, mesh: &TriMesh) -> Result<(), String> {
        self.check(mesh)
    }

    fn memory_bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes.as_slice())
            + std::mem::size_of_val(self.leaf_tris.as_slice())
            + self.tris.memory_bytes()
    }

    fn nodes(&self) -> usize {
        self.nodes.len()
    }

    fn depth(&self) -> usize {
        self.depth
    }

    fn sah(&self) -> Option<f32> {
        Some(self.sah)
    }
}
