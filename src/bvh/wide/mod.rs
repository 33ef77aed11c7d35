//! Wide BVHs (4 or 8 children per node) made from the binary BVH by collapsing, with the child
//! boxes stored structure-of-arrays so that one SIMD operation tests a ray against all of them.
//!
//! Collapsing ([`CollapseMethod::Greedy`], the default): a wide node starts from a binary
//! node's two children and repeatedly replaces the child with the largest surface area by its
//! own two children, until it has `K` children or only leaves are left. Binary leaves become
//! wide leaves unchanged, so the triangles keep the binary tree's leaf order (and the
//! [`MeshBvh`]'s leaf-ordered copy of them). [`CollapseMethod::Sah`] instead chooses the cut of
//! least SAH cost by dynamic programming (`sah.rs`); it writes the same layout.
//!
//! Invariants (checked by [`WideBvh::validate`]):
//! - node 0 is the root; every interior child index is greater than its parent's (children after
//!   parents, so refit is one reverse sweep), and every subtree occupies a contiguous range of
//!   nodes (depth-first order);
//! - leaves own contiguous ranges of triangle slots covering every slot once, in order;
//! - an empty child lane holds the empty box (`min = +inf`, `max = -inf`), which no ray hits;
//! - every lane's box holds its subtree's triangles.

mod all_hits;
mod batch;
mod closest_point;
mod fill;
pub(crate) use closest_point::Placed;
mod lanes;
mod overlap;
mod packet;
mod refit;
mod sah;
mod traverse;

pub use lanes::TriBlock;
pub use sah::WideCost;

use super::{BuildParams, BuildWorkspace, Bvh, MAX_DEPTH, MeshBvh, Node};
use crate::geom::{Aabb, TriMesh};
use glam::Vec3;

/// A BVH with four children per node (SSE width).
pub type MeshBvh4 = WideBvh<4>;
/// A BVH with eight children per node (AVX width).
pub type MeshBvh8 = WideBvh<8>;

/// Child value of an empty lane (the root is never anyone's child).
const EMPTY_CHILD: u32 = 0;
/// Trees of at least this many triangles are collapsed on several threads when there are.
const PARALLEL_PRIMS: usize = 1 << 15;
/// Set on leaf children.
const LEAF_BIT: u32 = 1 << 31;
/// Bits of a leaf child holding its first triangle slot.
const FIRST_BITS: u32 = 27;
/// Most triangles one leaf child holds (its count is stored in 4 bits); larger binary leaves
/// are split into several.
pub const MAX_WIDE_LEAF: u32 = 16;
/// Binary subtrees of at most this many triangles that do not fit into their parent's lanes
/// become one leaf lane (two blocks of four) instead of a nearly empty node of their own;
/// 8 keeps the nodes nearly full (values near it trace alike, smaller ones slower: see
/// `docs/wide.md`).
const MERGE: u32 = 8;
/// Most triangles a wide tree holds (its leaves store the first slot in 27 bits).
pub const MAX_WIDE_PRIMS: usize = 1 << FIRST_BITS;

/// One wide node: `K` child boxes as structure of arrays and `K` child references.
///
/// `bounds` rows are min x, min y, min z, max x, max y, max z, one lane per child. A child
/// reference is `0` for an empty lane, a node index for an interior child, or a leaf:
/// bit 31 set, bits 27..31 the triangle count minus one, bits 0..27 the first triangle slot.
#[repr(C, align(32))]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WideNode<const K: usize> {
    /// Child boxes, one lane per child.
    pub bounds: [[f32; K]; 6],
    /// Child references (see the type's docs).
    pub child: [u32; K],
}

impl<const K: usize> WideNode<K> {
    /// A node whose lanes are all empty.
    const EMPTY: Self = Self {
        bounds: [
            [f32::INFINITY; K],
            [f32::INFINITY; K],
            [f32::INFINITY; K],
            [f32::NEG_INFINITY; K],
            [f32::NEG_INFINITY; K],
            [f32::NEG_INFINITY; K],
        ],
        child: [EMPTY_CHILD; K],
    };

    /// The box of lane `i`.
    #[must_use]
    pub fn lane_bounds(&self, i: usize) -> Aabb {
        let b = &self.bounds;
        Aabb::new(
            Vec3::new(b[0][i], b[1][i], b[2][i]),
            Vec3::new(b[3][i], b[4][i], b[5][i]),
        )
    }

    /// Replaces the box of lane `i`.
    #[inline(always)]
    fn set_lane(&mut self, i: usize, b: Aabb) {
        let v = [b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z];
        for (row, v) in self.bounds.iter_mut().zip(v) {
            row[i] = v;
        }
    }

    /// The union of the child boxes.
    #[must_use]
    pub fn bounds(&self) -> Aabb {
        lanes::union_lanes(&self.bounds)
    }

    /// A bit per lane that holds a child.
    #[must_use]
    #[inline]
    pub fn occupied(&self) -> u32 {
        (0..K).fold(0, |m, k| m | (u32::from(self.child[k] != EMPTY_CHILD) << k))
    }

    /// What lane `i` holds.
    #[must_use]
    #[inline(always)]
    pub fn child(&self, i: usize) -> Child {
        decode(self.child[i])
    }
}

/// What a child lane of a [`WideNode`] holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Child {
    /// Nothing: the lane's box is empty.
    Empty,
    /// The node at this index.
    Node(u32),
    /// Triangle slots `first .. first + count`.
    Leaf {
        /// First triangle slot.
        first: u32,
        /// Number of triangles (1 ..= [`MAX_WIDE_LEAF`]).
        count: u32,
    },
}

#[inline(always)]
fn decode(c: u32) -> Child {
    if c & LEAF_BIT != 0 {
        let (first, count) = leaf_range(c);
        Child::Leaf { first, count }
    } else if c == EMPTY_CHILD {
        Child::Empty
    } else {
        Child::Node(c)
    }
}

#[inline(always)]
fn leaf_range(c: u32) -> (u32, u32) {
    (c & ((1 << FIRST_BITS) - 1), ((c >> FIRST_BITS) & 15) + 1)
}

fn encode_leaf(first: u32, count: u32) -> u32 {
    debug_assert!((1..=MAX_WIDE_LEAF).contains(&count) && (first as usize) < MAX_WIDE_PRIMS);
    LEAF_BIT | ((count - 1) << FIRST_BITS) | first
}

/// How [`WideBvh::collapse_from`] turns the binary tree into the wide one.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum CollapseMethod {
    /// Pull up the child with the largest area until a node is full; binary subtrees of at
    /// most 8 triangles left over become one leaf lane.
    #[default]
    Greedy,
    /// The collapse of least SAH cost with these costs, by dynamic programming (Ylitie, Karras
    /// & Laine 2017): leaf sizes (up to [`MAX_WIDE_LEAF`]) are chosen by the cost.
    Sah(WideCost),
}

impl CollapseMethod {
    /// The SAH collapse with [`WideCost::DEFAULT`].
    pub const SAH: Self = Self::Sah(WideCost::DEFAULT);
}

/// A wide BVH (`K` = 4 or 8 children per node) over a triangle mesh, with the triangles copied
/// into blocks of four ([`TriBlock`]) in leaf order. Built by collapsing a binary [`MeshBvh`]
/// (or, in [`WideBvh::build`], the binary tree alone, the triangles read from the mesh);
/// refitted in place.
#[derive(Clone, Debug, Default)]
pub struct WideBvh<const K: usize> {
    nodes: Vec<WideNode<K>>,
    /// Each leaf owns a contiguous run of blocks; unused lanes are NaN.
    blocks: Vec<TriBlock>,
    /// The vertex indices of each block lane, for refit (`[UNUSED; 3]` for unused lanes).
    block_indices: Vec<[[u32; 3]; 4]>,
    prim_count: usize,
    /// Largest coordinate magnitude of the root box (for the traversal's choice of box test).
    coord_max: f32,
    /// Most entries the traversal stack can hold at once (the largest sum over a root-to-leaf
    /// path of each node's child count minus one).
    stack_need: usize,
    /// Scratch of [`WideBvh::collapse_from`]: the triangle slots under each binary node.
    ranges: Vec<(u32, u32)>,
    /// Scratch of the stack-need computation.
    need: Vec<usize>,
    /// How [`WideBvh::collapse_from`] collapses.
    method: CollapseMethod,
    /// Scratch of the SAH collapse: its choices per binary node.
    choice: Vec<u64>,
    /// Scratch of the greedy collapse on several threads: the root's subtrees, one each.
    parts: Vec<Vec<WideNode<K>>>,
}

/// After a collapse into a vector that had `before` capacity: when it was empty storage or the
/// collapse outgrew it, leaves a quarter of headroom for later collapses.
fn headroom<T>(v: &mut Vec<T>, before: usize) {
    if before == 0 || v.len() > before {
        v.reserve_exact(v.len() / 4);
    }
}

/// The triangle index of an unused block lane.
pub const NO_PRIM: u32 = u32::MAX;
/// The vertex indices of an unused block lane.
const UNUSED: u32 = u32::MAX;

/// Where the collapse reads each triangle slot's corners, vertex indices and triangle index.
#[derive(Clone, Copy)]
enum TriSlots<'a> {
    /// A [`MeshBvh`]'s copies in leaf order.
    Copied {
        tris: &'a [[Vec3; 3]],
        indices: &'a [[u32; 3]],
        prims: &'a [u32],
    },
    /// Looked up in the mesh through the tree's primitive order.
    Mesh {
        positions: &'a [Vec3],
        indices: &'a [[u32; 3]],
        prims: &'a [u32],
    },
}

impl TriSlots<'_> {
    /// Slot `s`'s corners, vertex indices and triangle index.
    #[inline(always)]
    fn slot(&self, s: u32) -> ([Vec3; 3], [u32; 3], u32) {
        let s = s as usize;
        match *self {
            TriSlots::Copied {
                tris,
                indices,
                prims,
            } => (tris[s], indices[s], prims[s]),
            TriSlots::Mesh {
                positions,
                indices,
                prims,
            } => {
                let idx = indices[prims[s] as usize];
                (idx.map(|v| positions[v as usize]), idx, prims[s])
            }
        }
    }

    /// Asks for what [`TriSlots::slot`] of slot `s` reads first: its vertex indices in the
    /// mesh (the copies are read in order and need no hint).
    #[inline(always)]
    fn prefetch_indices(&self, s: u32) {
        if let TriSlots::Mesh { indices, prims, .. } = *self
            && let Some(i) = indices.get(prims[s as usize] as usize)
        {
            crate::simd::prefetch(i);
        }
    }

    /// Asks for slot `s`'s vertices (its vertex indices asked for earlier).
    #[inline(always)]
    fn prefetch_corners(&self, s: u32) {
        if let TriSlots::Mesh {
            positions,
            indices,
            prims,
        } = *self
            && let Some(idx) = indices.get(prims[s as usize] as usize)
        {
            for &v in idx {
                if let Some(p) = positions.get(v as usize) {
                    crate::simd::prefetch(p);
                }
            }
        }
    }
}

/// A collapse candidate: a binary node, or a range of triangle slots (a piece of a binary leaf
/// too large for one wide leaf).
#[derive(Clone, Copy, Debug)]
enum Item {
    Node(u32),
    Range(u32, u32),
}

impl<const K: usize> WideBvh<K> {
    const WIDTH_OK: () = assert!(K == 4 || K == 8, "wide BVHs have 4 or 8 children per node");

    /// Builds the binary tree with `params` and collapses it, with no leaf-ordered copy of the
    /// triangles beside the tree: the collapse reads them from the mesh (the same tree as
    /// [`WideBvh::from_mesh_bvh`] of [`MeshBvh::build`], in less memory and time).
    ///
    /// # Panics
    /// When a triangle's vertex index is out of range, or the mesh has more than
    /// [`MAX_WIDE_PRIMS`] triangles.
    #[must_use]
    pub fn build(mesh: &TriMesh, params: &BuildParams) -> Self {
        Self::build_indexed(&mesh.positions, &mesh.indices, params)
    }

    /// [`WideBvh::build`] from positions and triangle indices held elsewhere.
    ///
    /// # Panics
    /// As [`WideBvh::build`].
    #[must_use]
    pub fn build_indexed(positions: &[Vec3], indices: &[[u32; 3]], params: &BuildParams) -> Self {
        // The build's workspace is dropped before the collapse.
        let bvh = MeshBvh::tree_only(positions, indices, params, &mut BuildWorkspace::one_shot());
        Self::from_tree_indexed(&bvh, positions, indices)
    }

    /// The collapse of `bvh`, a binary tree over the triangles `indices` of `positions` (as
    /// [`MeshBvh::tree_only`] builds it), reading the triangles from them.
    pub(crate) fn from_tree_indexed(bvh: &Bvh, positions: &[Vec3], indices: &[[u32; 3]]) -> Self {
        let mut w = Self::default();
        w.collapse_tree(
            bvh,
            TriSlots::Mesh {
                positions,
                indices,
                prims: bvh.prim_indices(),
            },
        );
        w
    }

    /// Collapses a binary tree into a wide one (the binary tree is left as it is).
    ///
    /// # Panics
    /// When the tree has more than [`MAX_WIDE_PRIMS`] triangles.
    #[must_use]
    pub fn from_mesh_bvh(m: &MeshBvh) -> Self {
        let mut w = Self::default();
        w.collapse_from(m);
        w
    }

    /// [`WideBvh::from_mesh_bvh`] with the given collapse (kept for later
    /// [`WideBvh::collapse_from`] calls).
    ///
    /// # Panics
    /// As [`WideBvh::from_mesh_bvh`].
    #[must_use]
    pub fn from_mesh_bvh_with(m: &MeshBvh, method: CollapseMethod) -> Self {
        let mut w = Self {
            method,
            ..Self::default()
        };
        w.collapse_from(m);
        w
    }

    /// Storage (and collapse scratch) for a tree the size of `like`, reserved but not written
    /// (address space until a collapse writes it), so that collapsing a rebuild of the same mesh
    /// into it allocates nothing: a spare that a rebuild goes into while `like` is kept.
    pub fn reserve_like(&mut self, like: &Self) {
        fn to<T>(v: &mut Vec<T>, cap: usize) {
            crate::simd::reserve_huge(v, cap.saturating_sub(v.len()), 0);
        }
        to(&mut self.nodes, like.nodes.capacity());
        to(&mut self.blocks, like.blocks.capacity());
        to(&mut self.block_indices, like.block_indices.capacity());
        to(&mut self.ranges, like.ranges.capacity());
        to(&mut self.need, like.need.capacity());
        to(&mut self.choice, like.choice.capacity());
        self.method = like.method;
    }

    /// The collapse that [`WideBvh::collapse_from`] uses.
    #[must_use]
    pub fn collapse_method(&self) -> CollapseMethod {
        self.method
    }

    /// Sets the collapse for the next [`WideBvh::collapse_from`] calls.
    pub fn set_collapse_method(&mut self, method: CollapseMethod) {
        self.method = method;
    }

    /// [`WideBvh::from_mesh_bvh`] into this tree's storage: the collapse of a rebuilt binary
    /// tree, which allocates nothing once the storage has grown to the tree's size. The first
    /// collapse into empty storage (and any that outgrows it) leaves a quarter of headroom in
    /// the node and block arrays, so later collapses of rebuilds of the same mesh fit.
    ///
    /// # Panics
    /// As [`WideBvh::from_mesh_bvh`].
    pub fn collapse_from(&mut self, m: &MeshBvh) {
        self.collapse_tree(
            &m.bvh,
            TriSlots::Copied {
                tris: &m.tris,
                indices: &m.leaf_indices,
                prims: m.bvh.prim_indices(),
            },
        );
    }

    /// [`WideBvh::collapse_from`] of the tree `bvh` whose triangle slots `tris` gives.
    fn collapse_tree(&mut self, bvh: &Bvh, tris: TriSlots<'_>) {
        let () = Self::WIDTH_OK;
        assert!(
            bvh.prim_count() <= MAX_WIDE_PRIMS,
            "a wide BVH holds at most {MAX_WIDE_PRIMS} triangles"
        );
        let caps = (self.nodes.capacity(), self.blocks.capacity());
        self.nodes.clear();
        self.prim_count = bvh.prim_count();
        self.stack_need = 0;
        if bvh.nodes().is_empty() {
            self.blocks.clear();
            self.block_indices.clear();
            return;
        }
        // Rays walk the nodes and blocks in random order: give new storage huge pages (for
        // the nodes of a fresh tree an estimate, more than the trees built so far need; the
        // exact count for the blocks below), with the quarter of headroom of `headroom`.
        // Storage that has room (a rebuild's, or a clone's exact fit) is kept as it is.
        if self.nodes.capacity() == 0 {
            let est = bvh.prim_count() / (2 * K) + 1;
            crate::simd::reserve_huge(&mut self.nodes, est, est / 4);
        }
        let mut ranges = std::mem::take(&mut self.ranges);
        let c = Collapse::new(bvh, tris, MERGE, &mut ranges);
        let root = Item::Node(0);
        match self.method {
            CollapseMethod::Sah(cost) if !c.binary(0).is_leaf() => {
                let choice = &mut self.choice;
                choice.clear();
                choice.reserve((2 * bvh.prim_count()).saturating_sub(1));
                choice.resize(bvh.nodes().len(), 0);
                let a = c.binary(0).bounds().half_area_f64();
                let mut dp = sah::Dp {
                    c: &c,
                    cost,
                    choice,
                    inv_root: if a > 0.0 && a.is_finite() {
                        1.0 / a
                    } else {
                        1.0
                    },
                };
                dp.solve::<K>(0);
                dp.write(0, &mut self.nodes);
            }
            _ if c.fits_leaf(root) => {
                c.node(&[root], &mut self.nodes);
            }
            _ if rayon::current_num_threads() > 1 && bvh.prim_count() >= PARALLEL_PRIMS => {
                c.node_parallel(&c.open(root), &mut self.nodes, &mut self.parts);
            }
            _ => {
                c.node(&c.open(root), &mut self.nodes);
            }
        }
        self.ranges = ranges;
        // Leaves refer to triangle slots so far: give each its blocks, in node order (so every
        // subtree's blocks are contiguous too), and its box.
        // The old blocks stay until the fill overwrites them (it writes every block), so that
        // a rebuild's collapse writes its blocks once.
        let need = fill::blocks_needed(&self.nodes);
        if self.blocks.capacity() < need {
            // New storage comes zeroed from the system and untouched: the fill's threads fault
            // its pages in parallel instead of one thread writing all of it first.
            // A quarter of headroom, as `headroom` leaves.
            self.blocks = crate::simd::zeroed_huge(need, need + need / 4);
            self.block_indices = crate::simd::zeroed_huge(need, need + need / 4);
        } else {
            self.blocks.resize(need, TriBlock::EMPTY);
            self.block_indices.resize(need, [[UNUSED; 3]; 4]);
        }
        fill::fill_leaves(
            &mut self.nodes,
            &mut self.blocks,
            &mut self.block_indices,
            tris,
        );
        headroom(&mut self.nodes, caps.0);
        headroom(&mut self.blocks, caps.1);
        headroom(&mut self.block_indices, caps.1);
        refit::interior_pass(&mut self.nodes);
        self.update_coord_max();
        let mut need = std::mem::take(&mut self.need);
        self.stack_need = self.stack_need_with(&mut need);
        self.need = need;
        assert!(self.stack_need < traverse::BIG_STACK, "tree too deep");
    }

    /// The nodes; node 0 is the root (none for the empty mesh). A leaf child's `first` and
    /// `count` are a run of [`WideBvh::blocks`].
    #[must_use]
    pub fn nodes(&self) -> &[WideNode<K>] {
        &self.nodes
    }

    /// The triangles in blocks of four, in leaf order.
    #[must_use]
    pub fn blocks(&self) -> &[TriBlock] {
        &self.blocks
    }

    /// Number of triangles.
    #[must_use]
    pub fn prim_count(&self) -> usize {
        self.prim_count
    }

    /// Box of the whole tree (empty for the empty tree).
    #[must_use]
    pub fn bounds(&self) -> Aabb {
        self.nodes.first().map_or(Aabb::EMPTY, WideNode::bounds)
    }

    /// Bytes held: nodes, triangle blocks, and each block lane's triangle and vertex indices.
    #[must_use]
    pub fn memory_bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes.as_slice())
            + std::mem::size_of_val(self.blocks.as_slice())
            + std::mem::size_of_val(self.block_indices.as_slice())
    }

    /// [`WideBvh::memory_bytes`] with the room reserved for rebuilds of another shape.
    #[must_use]
    pub fn storage_bytes(&self) -> usize {
        use crate::bvh::held;
        held(&self.nodes) + held(&self.blocks) + held(&self.block_indices)
    }

    /// Depth of the deepest node (the root is at depth 0; 0 for the empty tree).
    #[must_use]
    pub fn depth(&self) -> usize {
        let mut depth = vec![0usize; self.nodes.len()];
        let mut deepest = 0;
        for (i, n) in self.nodes.iter().enumerate() {
            for k in 0..K {
                if let Child::Node(c) = n.child(k) {
                    depth[c as usize] = depth[i] + 1;
                    deepest = deepest.max(depth[i] + 1);
                }
            }
        }
        deepest
    }

    /// Average number of non-empty lanes per node.
    #[must_use]
    pub fn fill(&self) -> f64 {
        let used: usize = self
            .nodes
            .iter()
            .map(|n| (0..K).filter(|&k| n.child(k) != Child::Empty).count())
            .sum();
        used as f64 / self.nodes.len().max(1) as f64
    }

    /// SAH cost of the tree with `cost`, relative to the root's area: the root node, each
    /// interior lane's node and each leaf lane's triangles, weighted by the lane's area (0 for
    /// the empty tree).
    #[must_use]
    pub fn sah_cost(&self, cost: WideCost) -> f64 {
        let Some(root) = self.nodes.first() else {
            return 0.0;
        };
        let mut sum = f64::from(cost.node) * root.bounds().half_area_f64();
        for n in &self.nodes {
            for k in 0..K {
                let a = n.lane_bounds(k).half_area_f64();
                sum += a * f64::from(match n.child(k) {
                    Child::Empty => 0.0,
                    Child::Node(_) => cost.node,
                    Child::Leaf { first, count } => {
                        let tris = self.blocks[first as usize..(first + count) as usize]
                            .iter()
                            .flat_map(|b| b.prims)
                            .filter(|&p| p != NO_PRIM)
                            .count();
                        cost.leaf_cost(tris as u32)
                    }
                });
            }
        }
        let a = root.bounds().half_area_f64();
        if a > 0.0 && a.is_finite() {
            sum / a
        } else {
            sum
        }
    }

    fn compute_stack_need(&self) -> usize {
        self.stack_need_with(&mut Vec::new())
    }

    /// [`WideBvh::compute_stack_need`] with `need` as scratch.
    fn stack_need_with(&self, need: &mut Vec<usize>) -> usize {
        need.clear();
        need.reserve(self.nodes.capacity());
        need.resize(self.nodes.len(), 0);
        for i in (0..self.nodes.len()).rev() {
            let n = &self.nodes[i];
            let mut used = 0usize;
            let mut below = 0;
            for k in 0..K {
                match n.child(k) {
                    Child::Empty => {}
                    Child::Leaf { .. } => used += 1,
                    Child::Node(c) => {
                        used += 1;
                        below = below.max(need[c as usize]);
                    }
                }
            }
            need[i] = used.saturating_sub(1) + below;
        }
        need.first().copied().unwrap_or(0)
    }

    /// For benchmarks: single rays use the plain slab test (`(b - o) * inv`, two operations a
    /// plane) instead of the fused multiply-add form, until the next refit or collapse.
    #[doc(hidden)]
    pub fn bench_plain_slab(&mut self) {
        self.coord_max = f32::NAN;
    }

    /// Sets `coord_max` from the root box.
    pub(super) fn update_coord_max(&mut self) {
        let b = self.bounds();
        self.coord_max = b.min.abs().max(b.max.abs()).max_element();
        if b.min.is_nan() || b.max.is_nan() {
            self.coord_max = f32::NAN;
        }
    }

    /// Checks the invariants of the module docs against `mesh`: the message names the first
    /// broken one.
    pub fn validate(&self, mesh: &TriMesh) -> Result<(), String> {
        mesh.check()?;
        let n = self.prim_count;
        if mesh.len() != n || self.block_indices.len() != self.blocks.len() {
            return Err(format!("tree has {n} triangles, mesh has {}", mesh.len()));
        }
        let mut seen = vec![false; n];
        for (b, block) in self.blocks.iter().enumerate() {
            for (l, &p) in block.prims.iter().enumerate() {
                if p == NO_PRIM {
                    if block.get(l).iter().any(|v| !v.is_nan())
                        || self.block_indices[b][l] != [UNUSED; 3]
                    {
                        return Err(format!("unused lane {l} of block {b} is not NaN"));
                    }
                    continue;
                }
                match seen.get_mut(p as usize) {
                    Some(s) if !*s => *s = true,
                    _ => return Err(format!("triangle index {p} repeated or out of range")),
                }
                let t = block.get(l);
                let want = mesh.triangle(p as usize);
                // Compare bits: NaN coordinates are copied as they are.
                if t.map(|v| v.to_array().map(f32::to_bits))
                    != want.map(|v| v.to_array().map(f32::to_bits))
                {
                    return Err(format!(
                        "block {b} lane {l} holds a stale copy of triangle {p}"
                    ));
                }
                if self.block_indices[b][l] != mesh.indices[p as usize] {
                    return Err(format!("block {b} lane {l} has stale vertex indices"));
                }
            }
        }
        if seen.iter().any(|s| !s) {
            return Err("some triangle is in no block".into());
        }
        if self.nodes.is_empty() {
            return if n == 0 {
                Ok(())
            } else {
                Err(format!("no nodes but {n} triangles"))
            };
        }
        let mut next_block = 0u32;
        let end = self.check_node(0, 0, &mut next_block, mesh)?;
        if end != self.nodes.len() {
            return Err(format!(
                "the root's subtree ends at {end}, not at the node count {}",
                self.nodes.len()
            ));
        }
        if next_block as usize != self.blocks.len() {
            return Err(format!(
                "leaves cover {next_block} of {} blocks",
                self.blocks.len()
            ));
        }
        if self.stack_need != self.compute_stack_need() {
            return Err("stale stack bound".into());
        }
        Ok(())
    }

    /// Checks node `i`'s subtree (which must start at `i`) and returns one past its end.
    /// Leaves own runs of blocks in node order, lane order.
    fn check_node(
        &self,
        i: usize,
        depth: usize,
        next_block: &mut u32,
        mesh: &TriMesh,
    ) -> Result<usize, String> {
        if depth >= MAX_DEPTH {
            return Err(format!("node {i} is deeper than {MAX_DEPTH}"));
        }
        let node = &self.nodes[i];
        let mut used = 0;
        for k in 0..K {
            let b = node.lane_bounds(k);
            match node.child(k) {
                Child::Empty => {
                    if b != Aabb::EMPTY {
                        return Err(format!("empty lane {k} of node {i} has box {b:?}"));
                    }
                }
                Child::Leaf { first, count } => {
                    used += 1;
                    if first != *next_block || (first + count) as usize > self.blocks.len() {
                        return Err(format!(
                            "leaf lane {k} of node {i} has blocks {first}+{count}, expected to start at {next_block}"
                        ));
                    }
                    for blk in first..first + count {
                        for &p in &self.blocks[blk as usize].prims {
                            if p == NO_PRIM {
                                continue;
                            }
                            let tb = mesh.triangle_bounds(p as usize).sanitized();
                            if !b.contains(&tb) {
                                return Err(format!(
                                    "leaf lane {k} of node {i} box {b:?} does not hold triangle {p} {tb:?}"
                                ));
                            }
                        }
                    }
                    *next_block = first + count;
                }
                Child::Node(_) => used += 1,
            }
        }
        if used == 0 {
            return Err(format!("node {i} has no child"));
        }
        // Then the interior children's subtrees, each right after the previous one.
        let mut end = i + 1;
        for k in 0..K {
            if let Child::Node(c) = node.child(k) {
                if c as usize != end || end >= self.nodes.len() {
                    return Err(format!(
                        "lane {k} of node {i} points at {c}, expected {end} (depth-first order)"
                    ));
                }
                let (b, inner) = (node.lane_bounds(k), self.nodes[c as usize].bounds());
                if !b.contains(&inner) {
                    return Err(format!(
                        "lane {k} of node {i} box {b:?} does not hold its node's {inner:?}"
                    ));
                }
                end = self.check_node(c as usize, depth + 1, next_block, mesh)?;
            }
        }
        Ok(end)
    }
}

/// Levels of the binary tree whose two sides [`slot_ranges`] fills in parallel.
const RANGE_SPLITS: u32 = 3;

/// Fills `ranges` with every binary node's triangle slots `(first, count)`, the two sides of
/// the top `splits` levels on two threads (the root's descendants are the block after it, its
/// children's pair first).
fn slot_ranges(nodes: &[Node], ranges: &mut [(u32, u32)], splits: u32) {
    if splits > 0 && !nodes[0].is_leaf() && nodes[0].first == 1 {
        subtree_ranges(nodes, &mut ranges[1..], 1, splits);
        ranges[0] = node_range(&nodes[0], ranges, 0);
    } else {
        reverse_ranges(nodes, ranges, 0);
    }
}

/// Node `n`'s triangle slots, its children's (if any) already in `block`, which starts at
/// node `base`.
fn node_range(n: &Node, block: &[(u32, u32)], base: usize) -> (u32, u32) {
    if n.is_leaf() {
        (n.first, n.count)
    } else {
        let c = n.first as usize - base;
        (block[c].0, block[c].1 + block[c + 1].1)
    }
}

/// [`node_range`] of the nodes `base .. base + block.len()`, whose children all lie among
/// them, in one reverse pass (children after parents).
fn reverse_ranges(nodes: &[Node], block: &mut [(u32, u32)], base: usize) {
    for k in (0..block.len()).rev() {
        block[k] = node_range(&nodes[base + k], block, base);
    }
}

/// [`reverse_ranges`] of a node's descendants, the block from `base`: its children's pair,
/// then the left child's descendants, then the right's; the two children's blocks on two
/// threads for `splits` more levels.
fn subtree_ranges(nodes: &[Node], block: &mut [(u32, u32)], base: usize, splits: u32) {
    if splits == 0 || block.len() < 4096 {
        reverse_ranges(nodes, block, base);
        return;
    }
    let (a, b) = (&nodes[base], &nodes[base + 1]);
    let end = base + block.len();
    // The left child's descendants end where the right child's begin.
    let a_len = match (a.is_leaf(), b.is_leaf()) {
        (true, _) => 0,
        (false, true) => end - a.first as usize,
        (false, false) => (b.first - a.first) as usize,
    };
    let (pair, rest) = block.split_at_mut(2);
    let (a_block, b_block) = rest.split_at_mut(a_len);
    let (a_base, b_base) = (base + 2, base + 2 + a_len);
    debug_assert!(a.is_leaf() || a.first as usize == a_base);
    debug_assert!(b.is_leaf() || b.first as usize == b_base);
    rayon::join(
        || subtree_ranges(nodes, a_block, a_base, splits - 1),
        || subtree_ranges(nodes, b_block, b_base, splits - 1),
    );
    pair[0] = node_range(a, a_block, a_base);
    pair[1] = node_range(b, b_block, b_base);
}

/// The collapse of a binary tree.
struct Collapse<'a> {
    bvh: &'a Bvh,
    tris: TriSlots<'a>,
    /// Triangle slots `(first, count)` under each binary node.
    ranges: &'a [(u32, u32)],
    /// Binary subtrees with at most this many triangles may become one leaf lane.
    merge: u32,
}

impl<'a> Collapse<'a> {
    fn new(bvh: &'a Bvh, tris: TriSlots<'a>, merge: u32, ranges: &'a mut Vec<(u32, u32)>) -> Self {
        let nodes = bvh.nodes();
        ranges.clear();
        // Room for the most nodes a binary tree over these triangles has (2n - 1), so that the
        // collapses of its rebuilds fit.
        ranges.reserve((2 * bvh.prim_count()).saturating_sub(1));
        ranges.resize(nodes.len(), (0, 0));
        let parallel = rayon::current_num_threads() > 1 && nodes.len() >= 2 * PARALLEL_PRIMS;
        slot_ranges(nodes, ranges, if parallel { RANGE_SPLITS } else { 0 });
        Self {
            bvh,
            tris,
            ranges,
            merge,
        }
    }

    fn binary(&self, i: u32) -> &Node {
        &self.bvh.nodes()[i as usize]
    }

    /// True when the item may become one leaf lane: a binary leaf or piece of one of at most
    /// [`MAX_WIDE_LEAF`] triangles, or a binary subtree of at most `merge` triangles.
    fn fits_leaf(&self, it: Item) -> bool {
        match it {
            Item::Node(i) => {
                let count = self.ranges[i as usize].1;
                if self.binary(i).is_leaf() {
                    count <= MAX_WIDE_LEAF
                } else {
                    count <= self.merge.min(MAX_WIDE_LEAF)
                }
            }
            Item::Range(_, count) => count <= MAX_WIDE_LEAF,
        }
    }

    /// True when the item can be split: a binary interior node, or a range of triangles too
    /// large for one leaf lane.
    fn can_open(&self, it: Item) -> bool {
        match it {
            Item::Node(i) => !self.binary(i).is_leaf() || self.binary(i).count > MAX_WIDE_LEAF,
            Item::Range(_, count) => count > MAX_WIDE_LEAF,
        }
    }

    /// The triangle slots of an item that fits a leaf.
    fn slots(&self, it: Item) -> (u32, u32) {
        match it {
            Item::Node(i) => self.ranges[i as usize],
            Item::Range(first, count) => (first, count),
        }
    }

    /// The two items an openable item splits into.
    fn open(&self, it: Item) -> [Item; 2] {
        let halves = |first: u32, count: u32| {
            let h = count / 2;
            [Item::Range(first, h), Item::Range(first + h, count - h)]
        };
        match it {
            Item::Node(i) => {
                let n = self.binary(i);
                if n.is_leaf() {
                    halves(n.first, n.count)
                } else {
                    [Item::Node(n.first), Item::Node(n.first + 1)]
                }
            }
            Item::Range(first, count) => halves(first, count),
        }
    }

    fn area(&self, it: Item) -> f32 {
        match it {
            Item::Node(i) => self.binary(i).bounds().half_area(),
            Item::Range(first, count) => (first..first + count)
                .fold(Aabb::EMPTY, |b, s| {
                    b.union(Aabb::of_triangle(&self.tris.slot(s).0))
                })
                .half_area(),
        }
    }

    /// The items of a wide node over `start` (1 ..= K items): opens the largest-area openable
    /// item until there are `K`.
    fn items<const K: usize>(&self, start: &[Item]) -> ([Item; K], usize) {
        let mut items = [Item::Range(0, 0); K];
        // Each item's area if it can be opened, computed once when it joins; a binary node's
        // children are asked for then (the walk down a tree larger than the caches waits on
        // each node it opens otherwise).
        let mut keys = [None; K];
        let key = |it: Item| {
            if let Item::Node(i) = it {
                let n = self.binary(i);
                if !n.is_leaf() {
                    let c = n.first as usize;
                    crate::simd::prefetch_slice(&self.bvh.nodes()[c..c + 2]);
                    crate::simd::prefetch(&self.ranges[c]);
                }
            }
            self.can_open(it).then(|| self.area(it))
        };
        items[..start.len()].copy_from_slice(start);
        for (k, &it) in start.iter().enumerate() {
            keys[k] = key(it);
        }
        let mut len = start.len();
        while len < K {
            let best = keys[..len]
                .iter()
                .enumerate()
                .filter_map(|(k, a)| a.map(|a| (k, a)))
                .max_by(|a, b| a.1.total_cmp(&b.1));
            let Some((k, _)) = best else { break };
            let [a, b] = self.open(items[k]);
            items.copy_within(k + 1..len, k + 2);
            keys.copy_within(k + 1..len, k + 2);
            items[k] = a;
            items[k + 1] = b;
            keys[k] = key(a);
            keys[k + 1] = key(b);
            len += 1;
        }
        (items, len)
    }

    /// The leaf lane an item becomes when it fits one (else it becomes a wide node).
    fn leaf_lane(&self, it: Item) -> Option<u32> {
        self.fits_leaf(it).then(|| {
            let (first, count) = self.slots(it);
            encode_leaf(first, count)
        })
    }

    /// Writes a wide node over `start` (1 ..= K items) and its subtree, depth first; returns
    /// its index.
    fn node<const K: usize>(&self, start: &[Item], out: &mut Vec<WideNode<K>>) -> u32 {
        let (items, len) = self.items::<K>(start);
        let idx = out.len();
        out.push(WideNode::EMPTY);
        for (k, &it) in items[..len].iter().enumerate() {
            let child = match self.leaf_lane(it) {
                Some(leaf) => leaf,
                None => self.node(&self.open(it), out),
            };
            out[idx].child[k] = child;
        }
        idx as u32
    }

    /// [`Collapse::node`] with the subtrees of the node's lanes collapsed in parallel, each
    /// into one of `parts`, then appended in lane order with their child references moved by
    /// where they land: the nodes and their order are those of [`Collapse::node`].
    fn node_parallel<const K: usize>(
        &self,
        start: &[Item],
        out: &mut Vec<WideNode<K>>,
        parts: &mut Vec<Vec<WideNode<K>>>,
    ) -> u32 {
        use rayon::prelude::*;
        let (items, len) = self.items::<K>(start);
        if parts.len() < K {
            parts.resize_with(K, Vec::new);
        }
        parts[..len]
            .par_iter_mut()
            .zip(items[..len].par_iter())
            .for_each(|(part, &it)| {
                part.clear();
                if self.leaf_lane(it).is_none() {
                    let before = part.capacity();
                    self.node(&self.open(it), part);
                    headroom(part, before);
                }
            });
        let idx = out.len();
        out.push(WideNode::EMPTY);
        for (k, &it) in items[..len].iter().enumerate() {
            out[idx].child[k] = if let Some(leaf) = self.leaf_lane(it) {
                leaf
            } else {
                // The part's nodes refer to each other from 0, its root; no node refers to
                // the root, so an interior reference is never the empty lane's 0.
                let base = out.len() as u32;
                out.extend(parts[k].iter().map(|n| {
                    let mut n = *n;
                    for c in &mut n.child {
                        if *c != EMPTY_CHILD && *c & LEAF_BIT == 0 {
                            *c += base;
                        }
                    }
                    n
                }));
                base
            };
        }
        idx as u32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bit-for-bit equality of two wide trees (blocks compared by their bits: unused lanes
    /// are NaN).
    fn assert_same<const K: usize>(a: &WideBvh<K>, b: &WideBvh<K>, what: &str) {
        assert_eq!(a.nodes, b.nodes, "{what}: nodes");
        assert_eq!(a.blocks.len(), b.blocks.len(), "{what}: blocks");
        for (i, (x, y)) in a.blocks.iter().zip(&b.blocks).enumerate() {
            let bits = |t: &TriBlock| t.rows.map(|r| r.map(f32::to_bits));
            assert_eq!(bits(x), bits(y), "{what}: block {i}");
            assert_eq!(x.prims, y.prims, "{what}: block {i}");
        }
        assert_eq!(a.block_indices, b.block_indices, "{what}: vertex indices");
        assert_eq!(a.prim_count, b.prim_count, "{what}");
        assert_eq!(a.stack_need, b.stack_need, "{what}");
        assert_eq!(a.coord_max.to_bits(), b.coord_max.to_bits(), "{what}");
    }

    #[test]
    fn a_tree_built_from_the_mesh_is_the_collapse_of_the_mesh_bvh() {
        // A sphere large enough for the parallel collapse and fill, a soup, a pile of
        // triangles around one centroid (binary leaves that large leaf sizes leave over 16
        // triangles: pieces of leaves), one triangle and none.
        let sphere = crate::geom::shapes::icosphere(7);
        assert!(sphere.len() > 2 * PARALLEL_PRIMS);
        let mut soup = TriMesh::default();
        let mut pile = TriMesh::default();
        for i in 0..3000u32 {
            let f = |k: u32| ((i * 7 + k * 13) % 101) as f32 / 101.0;
            let c = Vec3::new(f(1), f(2), f(3)) * 10.0;
            let base = soup.positions.len() as u32;
            soup.positions.extend([
                c,
                c + Vec3::new(f(4), 0.1, 0.0),
                c + Vec3::new(0.0, f(5), 0.2),
            ]);
            soup.indices.push([base, base + 1, base + 2]);
            let d = Vec3::splat(0.01 * f(6) + 0.001);
            let base = pile.positions.len() as u32;
            pile.positions.extend([-d, d, Vec3::new(d.x, -d.y, 0.0)]);
            pile.indices.push([base, base + 2, base + 1]);
        }
        let one = TriMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
            indices: vec![[0, 1, 2]],
        };
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .expect("pool");
        for (name, mesh) in [
            ("sphere", &sphere),
            ("soup", &soup),
            ("pile", &pile),
            ("one", &one),
            ("none", &TriMesh::default()),
        ] {
            for leaf in [4, 8, 40] {
                let params = BuildParams {
                    max_leaf_size: leaf,
                    ..BuildParams::BINNED
                };
                for threads in [1, 2] {
                    let what = format!("{name}, leaves of {leaf}, {threads} threads");
                    let run = || {
                        let binary = MeshBvh::build(mesh, &params);
                        if name == "pile" && leaf == 40 {
                            // Pieces of leaves are collapsed too.
                            assert!(
                                binary.bvh().nodes().iter().any(|n| n.count > MAX_WIDE_LEAF),
                                "{what}: no binary leaf over {MAX_WIDE_LEAF} triangles"
                            );
                        }
                        assert_same(
                            &MeshBvh8::build(mesh, &params),
                            &MeshBvh8::from_mesh_bvh(&binary),
                            &what,
                        );
                        assert_same(
                            &MeshBvh4::build(mesh, &params),
                            &MeshBvh4::from_mesh_bvh(&binary),
                            &what,
                        );
                    };
                    if threads == 1 {
                        run();
                    } else {
                        pool.install(run);
                    }
                }
            }
        }
    }

    #[test]
    fn the_slot_ranges_filled_by_subtrees_in_parallel_are_the_reverse_passs() {
        // Unbalanced subtrees: a fine sphere beside a coarse one, and both children of some
        // nodes leaves or not.
        let mut mesh = crate::geom::shapes::icosphere(6);
        let coarse = crate::geom::shapes::icosphere(1);
        let base = mesh.positions.len() as u32;
        mesh.positions
            .extend(coarse.positions.iter().map(|p| *p * 0.5 + Vec3::splat(3.0)));
        mesh.indices
            .extend(coarse.indices.iter().map(|t| t.map(|i| i + base)));
        for leaf in [1, 4, 8] {
            let params = BuildParams {
                max_leaf_size: leaf,
                ..BuildParams::BINNED
            };
            let m = MeshBvh::build(&mesh, &params);
            let nodes = m.bvh().nodes();
            assert!(nodes.len() > 4 * 4096, "{} nodes", nodes.len());
            let mut serial = vec![(0, 0); nodes.len()];
            slot_ranges(nodes, &mut serial, 0);
            let mut split = vec![(0, 0); nodes.len()];
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(2)
                .build()
                .expect("pool");
            pool.install(|| slot_ranges(nodes, &mut split, RANGE_SPLITS));
            assert_eq!(serial, split, "leaves of {leaf}");
            assert_eq!(serial[0], (0, mesh.len() as u32));
        }
    }
}
