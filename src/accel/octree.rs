//! The octree: each node cuts its cell at the centre on all three axes at once, into up to
//! eight children (empty ones are not stored); leaves list the triangles whose boxes overlap
//! them, so a triangle may be in several. Traversal visits a node's children in the order the
//! ray crosses them (Revelles, Ureña & Lastra 2000), found by splitting the ray's interval at
//! the three centre planes one after the other with the kd-tree's near/far rule, and keeps the
//! pending children on a fixed stack.

use super::Accel;
use super::interval::{Crossing, box_interval, cross, lower_is_near, plane_distance};
use super::mailbox::{CellWalk, cell_walk_queries};
use super::triangles::{Triangles, bounds_of};
use crate::bvh::{Counters, TraversalStats};
use crate::geom::{Aabb, Hit, Ray, TriMesh};
use glam::Vec3;

/// The deepest an octree may be.
pub const MAX_OCTREE_DEPTH: usize = 20;

/// How an octree is built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OctreeParams {
    /// A node with at most this many triangles is a leaf.
    pub max_leaf_size: usize,
    /// Depth limit (at most [`MAX_OCTREE_DEPTH`]).
    pub max_depth: usize,
    /// A node is left a leaf when its children would hold more than this many times its
    /// triangles (triangles straddling the centre are copied into every child they overlap).
    pub max_growth: usize,
}

impl Default for OctreeParams {
    fn default() -> Self {
        Self {
            max_leaf_size: 8,
            max_depth: 16,
            max_growth: 3,
        }
    }
}

/// A node: interior nodes hold their centre, a mask of present children and the first of them
/// (stored together, in octant order); leaves their range of references.
#[derive(Clone, Copy, Debug, PartialEq)]
struct OctNode {
    center: Vec3,
    /// Interior: first child. Leaf: first reference.
    first: u32,
    /// Interior: `mask << 1` (octant `x + 2y + 4z`, bit set when that child exists).
    /// Leaf: `count << 1 | 1`.
    meta: u32,
}

impl OctNode {
    #[inline(always)]
    fn is_leaf(&self) -> bool {
        self.meta & 1 == 1
    }

    #[inline(always)]
    fn mask(&self) -> u32 {
        self.meta >> 1
    }

    /// The node index of child `octant`, if present.
    #[inline(always)]
    fn child(&self, octant: u32) -> Option<u32> {
        let m = self.mask();
        (m >> octant & 1 == 1).then(|| self.first + (m & ((1 << octant) - 1)).count_ones())
    }

    #[inline(always)]
    fn refs(&self) -> std::ops::Range<usize> {
        self.first as usize..self.first as usize + (self.meta >> 1) as usize
    }
}

/// An octree over a mesh's triangles.
#[derive(Clone, Debug, Default)]
pub struct Octree {
    nodes: Vec<OctNode>,
    refs: Vec<u32>,
    tris: Triangles,
    bounds: Aabb,
    depth: usize,
}

/// Which halves of a cell a box clipped to it lies in, on each axis: low, high (a box in the
/// centre plane itself goes low).
fn halves(b: &Aabb, cell: &Aabb, center: Vec3) -> [(bool, bool); 3] {
    std::array::from_fn(|a| {
        let (lo, hi) = (b.min[a].max(cell.min[a]), b.max[a].min(cell.max[a]));
        let c = center[a];
        if lo == c && hi == c {
            (true, false)
        } else {
            (lo < c, hi > c)
        }
    })
}

/// The octants a box's halves cover.
fn octants(h: &[(bool, bool); 3]) -> impl Iterator<Item = u32> + '_ {
    (0..8u32).filter(move |&o| (0..3).all(|a| if o >> a & 1 == 1 { h[a].1 } else { h[a].0 }))
}

/// The cell of child `octant` of `cell` cut at `center`.
fn child_cell(cell: &Aabb, center: Vec3, octant: u32) -> Aabb {
    let mut c = *cell;
    for a in 0..3 {
        if octant >> a & 1 == 1 {
            c.min[a] = center[a];
        } else {
            c.max[a] = center[a];
        }
    }
    c
}

struct Builder<'a> {
    boxes: &'a [Aabb],
    params: OctreeParams,
    nodes: Vec<OctNode>,
    refs: Vec<u32>,
    depth: usize,
}

impl Builder<'_> {
    fn node(&mut self, index: usize, cell: Aabb, tris: Vec<u32>, depth: usize) {
        self.depth = self.depth.max(depth);
        let center = cell.center();
        let leaf = |b: &mut Self, tris: Vec<u32>| {
            b.nodes[index] = OctNode {
                center,
                first: b.refs.len() as u32,
                meta: (tris.len() as u32) << 1 | 1,
            };
            b.refs.extend(tris);
        };
        if tris.len() <= self.params.max_leaf_size
            || depth >= self.params.max_depth.min(MAX_OCTREE_DEPTH)
        {
            return leaf(self, tris);
        }
        let mut children: [Vec<u32>; 8] = Default::default();
        for &t in &tris {
            let h = halves(&self.boxes[t as usize], &cell, center);
            for o in octants(&h) {
                children[o as usize].push(t);
            }
        }
        let total: usize = children.iter().map(Vec::len).sum();
        if total > self.params.max_growth * tris.len()
            || children.iter().any(|c| c.len() == tris.len())
        {
            return leaf(self, tris);
        }
        drop(tris);
        let mask = (0..8)
            .filter(|&o| !children[o].is_empty())
            .fold(0u32, |m, o| m | 1 << o);
        let first = self.nodes.len();
        self.nodes[index] = OctNode {
            center,
            first: first as u32,
            meta: mask << 1,
        };
        let present: Vec<usize> = (0..8).filter(|&o| mask >> o & 1 == 1).collect();
        for _ in &present {
            self.nodes.push(OctNode {
                center,
                first: 0,
                meta: 1,
            });
        }
        for (k, &o) in present.iter().enumerate() {
            let list = std::mem::take(&mut children[o]);
            self.node(
                first + k,
                child_cell(&cell, center, o as u32),
                list,
                depth + 1,
            );
        }
    }
}

/// A child still to visit and the ray's interval in it.
#[derive(Clone, Copy, Default)]
struct Pending {
    node: u32,
    tn: f32,
    tf: f32,
}

/// Stack entries: up to seven children wait at each level, plus the one being visited.
const STACK: usize = 7 * MAX_OCTREE_DEPTH + 8;

impl Octree {
    /// Builds an octree over `mesh`'s triangles; triangles without a box are left out.
    ///
    /// # Panics
    /// When a vertex index is out of range, or the mesh has 2^31 triangles or more.
    #[must_use]
    pub fn build(mesh: &TriMesh, params: &OctreeParams) -> Self {
        assert!(mesh.len() < 1 << 31, "too many triangles for an octree");
        let tris = Triangles::of_mesh(mesh);
        let boxes = tris.boxes();
        let bounds = bounds_of(&boxes);
        let ids: Vec<u32> = (0..boxes.len() as u32)
            .filter(|&i| !boxes[i as usize].is_empty())
            .collect();
        let mut b = Builder {
            boxes: &boxes,
            params: *params,
            nodes: Vec::new(),
            refs: Vec::new(),
            depth: 0,
        };
        if !ids.is_empty() {
            b.nodes.push(OctNode {
                center: Vec3::ZERO,
                first: 0,
                meta: 1,
            });
            b.node(0, bounds, ids, 0);
        }
        let (nodes, refs, depth) = (b.nodes, b.refs, b.depth);
        Self {
            nodes,
            refs,
            tris,
            bounds,
            depth,
        }
    }

    /// Pushes the present children of `n` crossed over `[tn, tf]`, farthest first.
    #[inline(always)]
    fn push_children(
        &self,
        ray: &Ray,
        n: &OctNode,
        tn: f32,
        tf: f32,
        stack: &mut [Pending; STACK],
        sp: &mut usize,
    ) {
        let mut items = [(0u32, 0f32, 0f32); 8];
        items[0] = (0, tn, tf);
        let mut len = 1;
        for a in 0..3 {
            let d = plane_distance(ray, a, n.center[a]);
            let (near, far) = if lower_is_near(ray, a) {
                (0, 1 << a)
            } else {
                (1 << a, 0)
            };
            let mut out = [(0u32, 0f32, 0f32); 8];
            let mut k = 0;
            for &(o, a0, b0) in &items[..len] {
                match cross(d, a0, b0) {
                    Crossing::Near => {
                        out[k] = (o | near, a0, b0);
                        k += 1;
                    }
                    Crossing::Far => {
                        out[k] = (o | far, a0, b0);
                        k += 1;
                    }
                    Crossing::Both(near_end, far_start) => {
                        out[k] = (o | near, a0, near_end);
                        out[k + 1] = (o | far, far_start, b0);
                        k += 2;
                    }
                }
            }
            items = out;
            len = k;
        }
        for &(o, a0, b0) in items[..len].iter().rev() {
            if let Some(child) = n.child(o) {
                stack[*sp] = Pending {
                    node: child,
                    tn: a0,
                    tf: b0,
                };
                *sp += 1;
            }
        }
    }

    fn check(&self, mesh: &TriMesh) -> Result<(), String> {
        self.tris.check(mesh)?;
        let boxes = self.tris.boxes();
        if self.nodes.is_empty() {
            return match boxes.iter().position(|b| !b.is_empty()) {
                Some(i) => Err(format!("no node but triangle {i} has a box")),
                None => Ok(()),
            };
        }
        if self.depth > MAX_OCTREE_DEPTH {
            return Err(format!("depth {} over {MAX_OCTREE_DEPTH}", self.depth));
        }
        for (i, b) in boxes.iter().enumerate().filter(|(_, b)| !b.is_empty()) {
            self.reaches(0, self.bounds, b, i as u32, 0)?;
        }
        Ok(())
    }

    /// Checks that triangle `t` is in every leaf below `i` its box overlaps.
    fn reaches(&self, i: usize, cell: Aabb, b: &Aabb, t: u32, depth: usize) -> Result<(), String> {
        let n = self
            .nodes
            .get(i)
            .ok_or_else(|| format!("node {i} out of range"))?;
        if depth > self.depth {
            return Err(format!("node {i} deeper than the recorded depth"));
        }
        if n.is_leaf() {
            let refs = self
                .refs
                .get(n.refs())
                .ok_or_else(|| format!("leaf {i}: references out of range"))?;
            return if refs.contains(&t) {
                Ok(())
            } else {
                Err(format!(
                    "triangle {t} missing from leaf {i} its box overlaps"
                ))
            };
        }
        if n.center != cell.center() || n.first as usize <= i {
            return Err(format!("node {i}: centre or children misplaced"));
        }
        for o in octants(&halves(b, &cell, n.center)) {
            let child = n
                .child(o)
                .ok_or_else(|| format!("triangle {t}: node {i} lacks child {o}"))?;
            self.reaches(
                child as usize,
                child_cell(&cell, n.center, o),
                b,
                t,
                depth + 1,
            )?;
        }
        Ok(())
    }
}

impl CellWalk for Octree {
    fn triangles(&self) -> &Triangles {
        &self.tris
    }

    /// Visits the leaves along the ray, nearest first, calling `leaf` until it returns true;
    /// `cap()` is the distance beyond which no node can help (the best hit so far, widened:
    /// `beyond` of it, set when the best changes).
    #[inline(always)]
    fn walk<C: Counters>(
        &self,
        ray: &Ray,
        c: &mut C,
        mut leaf: impl FnMut(&[u32], &mut C) -> bool,
        cap: impl Fn() -> f32,
    ) {
        if self.nodes.is_empty() {
            return;
        }
        let Some((tn, tf)) = box_interval(ray, self.bounds.min, self.bounds.max, ray.tmax) else {
            return;
        };
        let mut stack = [Pending::default(); STACK];
        stack[0] = Pending { node: 0, tn, tf };
        let mut sp = 1;
        while sp > 0 {
            sp -= 1;
            let p = stack[sp];
            if p.tn > cap() {
                continue;
            }
            c.node();
            let n = self.nodes[p.node as usize];
            if n.is_leaf() {
                if leaf(&self.refs[n.refs()], c) {
                    return;
                }
            } else {
                self.push_children(ray, &n, p.tn, p.tf, &mut stack, &mut sp);
            }
        }
    }
}

impl Accel for Octree {
    fn name(&self) -> String {
        "octree".into()
    }

    cell_walk_queries!();

    fn validate(&self, mesh: &TriMesh) -> Result<(), String> {
        self.check(mesh)
    }

    fn memory_bytes(&self) -> usize {
        std::mem::size_of_val(self.nodes.as_slice())
            + std::mem::size_of_val(self.refs.as_slice())
            + self.tris.memory_bytes()
    }

    fn nodes(&self) -> usize {
        self.nodes.len()
    }

    fn depth(&self) -> usize {
        self.depth
    }
}
