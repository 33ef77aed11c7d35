//! The bounding interval hierarchy (Wächter & Keller, "Instant Ray Tracing: The Bounding
//! Interval Hierarchy", EGSR 2006): an object partition like the BVH, but each node stores only
//! two planes on one axis, the left child's largest and the right child's smallest coordinate.
//! The top levels (nodes of many triangles) split on the plane of least SAH, binned over a
//! sample of the box centres (Wald, "On fast Construction of SAH-based Bounding Volume
//! Hierarchies", 2007), with the triangles' boxes standing for the children's. Below them each
//! subtree is built by the global heuristic: starting from the box of its triangles, a
//! candidate box (not the triangles' bounds) is split in the middle of its longest side,
//! sorting triangles by their box centre (for the first 24 halvings all at once: one radix sort
//! by each centre's cell in the grid those halvings make, a Morton code), and halved again when
//! one side would be empty; where that empty side leaves a wide gap between the triangles and
//! the box traversal knows, a node with an empty child cuts the gap off (without it, rays
//! through the gap reach the subtree).
//! Before each split the same is done on every axis, from the triangles' box that the parent's
//! partition gathered for each side, so that rays missing the triangles leave the subtree early.
//! Traversal clips the ray's interval by both planes; the children may overlap, so both are
//! visited, nearer first. In a leaf a triangle is tested only when the ray's interval there
//! meets its box (it lies within the leaf's planes, so its hits do too). A refit keeps the
//! tree and recomputes the planes from the moved triangles.

use super::Accel;
use super::interval::{
    SlabRay, beyond, box_interval, lower, max_of, min_of, plane_distance, upper, upper_near_bits,
};
use super::triangles::{AnyHit, Closest};
use crate::bvh::{Counters, TraversalStats};
use crate::geom::{Aabb, Hit, Ray, TriMesh};
use crate::simd::Stack;
use glam::Vec3;

/// The deepest a BIH may be; traversal stacks have this many entries.
pub const MAX_BIH_DEPTH: usize = 64;

/// How a BIH is built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BihParams {
    /// Most triangles in a leaf (a leaf may hold more at the depth limit or when no candidate
    /// plane separates its triangles' centres).
    pub max_leaf_size: usize,
    /// Nodes holding at least this share of the triangles (`1 / sah_share`, and at least 256)
    /// are split on the plane of least SAH where it costs clearly less than the plane through
    /// their middle (the global heuristic's); the others by the global heuristic. 0: the
    /// global heuristic everywhere.
    pub sah_share: usize,
}

/// The fewest triangles a node split by the SAH holds (see [`BihParams::sah_share`]).
const SAH_MIN_TRIANGLES: usize = 256;

/// Leaves of up to 8 triangles: a leaf tests only the triangles whose boxes the ray meets in
/// it, so fuller leaves cost little and save interior steps. The top levels (nodes of at
/// least 1/32 of the triangles) may split by the SAH: the planes the global heuristic puts
/// there do not part the large pieces of an uneven scene (a floor from a wall), which then
/// share their boxes' empty space. The sweeps over both are in `docs/accel.md`.
impl Default for BihParams {
    fn default() -> Self {
        Self {
            max_leaf_size: 8,
            sah_share: 32,
        }
    }
}

/// Candidate-box halvings tried at one node before giving up and making a leaf.
const MAX_EMPTY_SPLITS: usize = 32;

/// An empty side whose gap to the node's box (as traversal knows it) is wider than this
/// fraction of the box on that axis is cut off by a node with an empty child.
const EMPTY_CUT: f32 = 0.1;

/// Before a node is split, a gap on any axis between its triangles' box and the box
/// traversal knows it by that is wider than this fraction of the latter is cut off by a node
/// with an empty child: wide enough that the cut nodes do not lengthen the walks of rays that
/// reach the triangles more than they shorten those of rays through the gap (the sweep is in
/// `docs/accel.md`).
const GAP_CUT: f32 = 0.3;

/// A node: an interior node's two planes and axis (children adjacent, stored after it), or a
/// leaf's range of triangle slots.
#[derive(Clone, Copy, Debug, PartialEq)]
struct BihNode {
    /// Interior: the left child's upper and the right child's lower plane. Leaf: the first
    /// slot and the count, as bits.
    planes: [f32; 2],
    /// `index << 2 | tag`: tag 0-2 the axis (index: first child), 3 a leaf.
    data: u32,
}

impl BihNode {
    fn leaf(first: usize, count: usize) -> Self {
        Self {
            planes: [f32::from_bits(first as u32), f32::from_bits(count as u32)],
            data: 3,
        }
    }

    fn interior(axis: usize, planes: [f32; 2], first: usize) -> Self {
        Self {
            planes,
            data: (first as u32) << 2 | axis as u32,
        }
    }

    #[inline(always)]
    fn is_leaf(&self) -> bool {
        self.data & 3 == 3
    }

    #[inline(always)]
    fn axis(&self) -> usize {
        (self.data & 3) as usize
    }

    #[inline(always)]
    fn first_child(&self) -> usize {
        (self.data >> 2) as usize
    }

    #[inline(always)]
    fn slots(&self) -> std::ops::Range<usize> {
        let first = self.planes[0].to_bits() as usize;
        first..first + self.planes[1].to_bits() as usize
    }
}

/// A bounding interval hierarchy over a mesh's triangles, the triangles copied in leaf order.
#[derive(Clone, Debug, Default)]
pub struct Bih {
    nodes: Vec<BihNode>,
    /// `prims[slot]`: the mesh's index of the triangle in that slot.
    prims: Vec<u32>,
    /// The triangles in slot order.
    tris: Vec<[Vec3; 3]>,
    bounds: Aabb,
    depth: usize,
    /// Per-node boxes, kept for refits.
    scratch: Vec<Aabb>,
}

/// A triangle being sorted into the tree: its box and index.
#[derive(Clone, Copy)]
struct Item {
    bounds: Aabb,
    prim: u32,
}

struct Builder {
    items: Vec<Item>,
    /// Each item's first [`PRESORTED`] halvings of its subtree's candidate box (see
    /// [`halving_codes`]), in the items' order while that order is the codes' (the node ranges
    /// above that level).
    codes: Vec<u32>,
    /// The axes of the halvings the codes of the subtree being built record.
    axes: [usize; PRESORTED],
    /// Room for the sorts by codes and the partitions.
    items_tmp: Vec<Item>,
    codes_tmp: Vec<u32>,
    nodes: Vec<BihNode>,
    max_leaf: usize,
    depth: usize,
    /// Nodes of at least this many triangles are split where the SAH is least.
    sah_min: usize,
}

/// The `level` of a node above the global heuristic's subtrees: split by the SAH, or, when too
/// small for it (or the SAH finds no plane), the root of such a subtree, whose items are not
/// yet sorted by their codes.
const UNSORTED: usize = usize::MAX;

impl Builder {
    /// Builds node `index` over `items[begin..end]` with candidate box `cand`, halved `level`
    /// times from its global-heuristic subtree's root (or [`UNSORTED`] above those subtrees);
    /// `seen` is the box traversal knows the node by (its ancestors' planes), `tight` the box
    /// of its triangles.
    fn node(
        &mut self,
        mut index: usize,
        (begin, end): (usize, usize),
        (mut cand, mut level): (Aabb, usize),
        mut seen: Aabb,
        tight: Aabb,
        mut depth: usize,
    ) {
        self.depth = self.depth.max(depth);
        let n = end - begin;
        if n <= self.max_leaf || depth + 1 >= MAX_BIH_DEPTH {
            self.nodes[index] = BihNode::leaf(begin, n);
            return;
        }
        // Gaps between the triangles' box and the box traversal knows the node by, on any
        // axis, cut off widest first by nodes with an empty child: a ray through such a gap
        // then leaves at the cut instead of walking down to the triangles' planes.
        while depth + 2 < MAX_BIH_DEPTH {
            let ext = seen.extent();
            let mut best: Option<(f32, usize, bool)> = None;
            for a in 0..3 {
                if ext[a].is_nan() || ext[a] <= 0.0 {
                    continue;
                }
                let lo = (tight.min[a] - seen.min[a]) / ext[a];
                let hi = (seen.max[a] - tight.max[a]) / ext[a];
                for (g, low) in [(lo, true), (hi, false)] {
                    if g > GAP_CUT && best.is_none_or(|b| g > b.0) {
                        best = Some((g, a, low));
                    }
                }
            }
            let Some((_, a, low)) = best else { break };
            let bound = if low { tight.min[a] } else { tight.max[a] };
            index = self.cut_off(index, (begin, end), (a, low, bound), &mut seen);
            depth += 1;
            self.depth = self.depth.max(depth);
        }
        if level == UNSORTED {
            if n >= self.sah_min && self.split_by_sah(index, (begin, end), seen, depth) {
                return;
            }
            // The global heuristic from here down, its candidate box the triangles' box (the
            // scene's at the root).
            cand = tight;
            level = 0;
            self.axes = halving_axes(&cand);
            let (items, codes) = (&mut self.items[begin..end], &mut self.codes[begin..end]);
            halving_codes(items, &cand, &self.axes, codes);
            sort_by_codes(
                items,
                codes,
                &mut self.items_tmp[..n],
                &mut self.codes_tmp[..n],
            );
        }
        for _ in 0..MAX_EMPTY_SPLITS {
            let axis = if level < PRESORTED {
                self.axes[level]
            } else {
                cand.largest_axis()
            };
            let mid = cand.center()[axis];
            if !(cand.min[axis] < mid && mid < cand.max[axis]) {
                break;
            }
            let (below, [lbox, rbox]) = if level < PRESORTED {
                // The items are in the order of their codes: those in the lower half come
                // first (the code's grid cell decides, which is `mid`'s side up to rounding).
                let bit = 1 << (PRESORTED - 1 - level);
                let below = self.codes[begin..end].partition_point(|&c| c & bit == 0);
                (below, side_boxes(&self.items[begin..end], below))
            } else {
                partition(
                    &mut self.items[begin..end],
                    &mut self.items_tmp[..n],
                    axis,
                    mid,
                )
            };
            let planes = [lbox.max[axis], rbox.min[axis]];
            level += 1;
            let split = begin + below;
            let (mut left_cand, mut right_cand) = (cand, cand);
            left_cand.max[axis] = mid;
            right_cand.min[axis] = mid;
            if split == begin || split == end {
                // One side empty: the candidate box is halved again (the global heuristic).
                // Where the triangles leave a wide gap to the box traversal knows, a node with
                // an empty child cuts it off, so rays through the gap skip the subtree.
                let gap = seen.extent()[axis] * EMPTY_CUT;
                // All the triangles on one side: that side's plane is their bound.
                let cut = if split == begin {
                    let lo = planes[1];
                    (lo - seen.min[axis] > gap).then_some((true, lo))
                } else {
                    let hi = planes[0];
                    (seen.max[axis] - hi > gap).then_some((false, hi))
                };
                cand = if split == begin {
                    right_cand
                } else {
                    left_cand
                };
                if let Some((low, bound)) = cut {
                    let mut tighter = seen;
                    let next = self.cut_off(index, (begin, end), (axis, low, bound), &mut tighter);
                    self.node(next, (begin, end), (cand, level), tighter, tight, depth + 1);
                    return;
                }
                continue;
            }
            self.split(
                index,
                (begin, split, end),
                (axis, [lbox, rbox]),
                [(left_cand, level), (right_cand, level)],
                seen,
                depth,
            );
            return;
        }
        self.nodes[index] = BihNode::leaf(begin, n);
    }
}

impl Builder {
    /// Makes node `index` (known to traversal by `seen`) an interior node on `axis` over the
    /// items `begin..split` and `split..end`, whose boxes are `lbox` and `rbox` (its planes
    /// their bounds on `axis`), and builds the two children from their candidate boxes and
    /// levels, `left` and `right`.
    fn split(
        &mut self,
        index: usize,
        (begin, split, end): (usize, usize, usize),
        (axis, [lbox, rbox]): (usize, [Aabb; 2]),
        [left, right]: [(Aabb, usize); 2],
        seen: Aabb,
        depth: usize,
    ) {
        let planes = [lbox.max[axis], rbox.min[axis]];
        let (mut left_seen, mut right_seen) = (seen, seen);
        left_seen.max[axis] = left_seen.max[axis].min(planes[0]);
        right_seen.min[axis] = right_seen.min[axis].max(planes[1]);
        let first = self.nodes.len();
        self.nodes.push(BihNode::leaf(0, 0));
        self.nodes.push(BihNode::leaf(0, 0));
        self.nodes[index] = BihNode::interior(axis, planes, first);
        self.node(first, (begin, split), left, left_seen, lbox, depth + 1);
        self.node(first + 1, (split, end), right, right_seen, rbox, depth + 1);
    }

    /// Splits node `index` (over `items[begin..end]`, known to traversal by `seen`) on the
    /// plane of least SAH, and builds its children; false (the node untouched, its items
    /// reordered) when no plane parts the triangles' centres.
    fn split_by_sah(
        &mut self,
        index: usize,
        (begin, end): (usize, usize),
        seen: Aabb,
        depth: usize,
    ) -> bool {
        let n = end - begin;
        let Some((axis, mid)) = sah_split(&self.items[begin..end]) else {
            return false;
        };
        let (below, [lbox, rbox]) = partition(
            &mut self.items[begin..end],
            &mut self.items_tmp[..n],
            axis,
            mid,
        );
        if below == 0 || below == n {
            return false;
        }
        let cands = [(lbox, UNSORTED), (rbox, UNSORTED)];
        let split = begin + below;
        self.split(
            index,
            (begin, split, end),
            (axis, [lbox, rbox]),
            cands,
            seen,
            depth,
        );
        true
    }

    /// Makes node `index` (over `items[begin..end]`) cut off the empty space below `bound`
    /// on `axis` (`low`) or above it: an interior node with an empty child, a leaf of no slots
    /// where its sibling's slots begin (left) or end (right), so that the leaves still cover
    /// the slots in order. Tightens `seen` to the cut; returns the sibling's index, where the
    /// node's triangles go on.
    fn cut_off(
        &mut self,
        index: usize,
        (begin, end): (usize, usize),
        (axis, low, bound): (usize, bool, f32),
        seen: &mut Aabb,
    ) -> usize {
        let first = self.nodes.len();
        self.nodes.push(BihNode::leaf(begin, 0));
        self.nodes.push(BihNode::leaf(end, 0));
        if low {
            self.nodes[index] = BihNode::interior(axis, [f32::NEG_INFINITY, bound], first);
            seen.min[axis] = bound;
            first + 1
        } else {
            self.nodes[index] = BihNode::interior(axis, [bound, f32::INFINITY], first);
            seen.max[axis] = bound;
            first
        }
    }
}

/// Moves the items whose box centre lies below `mid` on `axis` to the front (in their order,
/// the others after them in reverse order), through `tmp` (as long as `items`), without a
/// branch on an item's side; returns how many, and the boxes of the two sides (NaN
/// coordinates left out).
fn partition(items: &mut [Item], tmp: &mut [Item], axis: usize, mid: f32) -> (usize, [Aabb; 2]) {
    let (mut l, mut r) = (0, items.len());
    for it in items.iter() {
        let left = (it.bounds.min[axis] + it.bounds.max[axis]) * 0.5 < mid;
        r -= usize::from(!left);
        tmp[if left { l } else { r }] = *it;
        l += usize::from(left);
    }
    items.copy_from_slice(tmp);
    (l, side_boxes(items, l))
}

/// The boxes of `items` split after the first `below`.
fn side_boxes(items: &[Item], below: usize) -> [Aabb; 2] {
    let (left, right) = items.split_at(below);
    [box_of(left), box_of(right)]
}

/// The box of `items` (NaN coordinates left out, as `f32::min` and `f32::max` leave them),
/// in four running boxes: their bounds are independent chains, where one box would make each
/// item wait for the last.
fn box_of(items: &[Item]) -> Aabb {
    use glam::Vec3A;
    // A lane of `v` replaces the bound only where it compares below (above) it: never a NaN.
    let lower = |lo: Vec3A, v: Vec3A| Vec3A::select(v.cmplt(lo), v, lo);
    let upper = |hi: Vec3A, v: Vec3A| Vec3A::select(v.cmpgt(hi), v, hi);
    let mut lo = [Vec3A::INFINITY; 4];
    let mut hi = [Vec3A::NEG_INFINITY; 4];
    let chunks = items.chunks_exact(4);
    let rest = chunks.remainder();
    for c in chunks {
        for k in 0..4 {
            lo[k] = lower(lo[k], c[k].bounds.min.into());
            hi[k] = upper(hi[k], c[k].bounds.max.into());
        }
    }
    for (k, it) in rest.iter().enumerate() {
        lo[k] = lower(lo[k], it.bounds.min.into());
        hi[k] = upper(hi[k], it.bounds.max.into());
    }
    let l = lower(lower(lo[0], lo[1]), lower(lo[2], lo[3]));
    let h = upper(upper(hi[0], hi[1]), upper(hi[2], hi[3]));
    Aabb {
        min: l.into(),
        max: h.into(),
    }
}

/// Halvings of the candidate box decided for every triangle before the build, as bits.
const PRESORTED: usize = 24;

/// The axes of the first [`PRESORTED`] halvings of the candidate box from `root`: each time
/// its longest side (the lowest axis on ties), as [`Builder::node`] picks it. The sides'
/// lengths halve whatever half is kept, so the sequence is the same on every path.
fn halving_axes(root: &Aabb) -> [usize; PRESORTED] {
    let mut extent = root.extent();
    std::array::from_fn(|_| {
        let axis = Aabb::new(Vec3::ZERO, extent).largest_axis();
        extent[axis] *= 0.5;
        axis
    })
}

/// Each item's side at the first [`PRESORTED`] halvings of the candidate box from `root`
/// along `axes`, the first in the highest bit (1: the upper half): its box centre's cell in
/// the grid those halvings make of `root`, its coordinates' bits interleaved in the order of
/// the halvings (a Morton code along `axes`). A node's items share the bits of the halvings
/// above it, so sorting the items by code puts every node's items in one range, the lower
/// half first: the top levels' partitions become searches (one sort instead of a pass over
/// all the items at each level). Centres outside `root` (or not finite) count in its nearest
/// cell.
fn halving_codes(items: &[Item], root: &Aabb, axes: &[usize; PRESORTED], out: &mut [u32]) {
    // Per axis: halvings on it, and where each bit of a grid coordinate goes in the code
    // (`place[b]` for bit `b`, the lowest first: the axis's last halving), looked up 12 bits
    // at a time so the tables stay small whatever the root's shape.
    let halvings: [u32; 3] =
        std::array::from_fn(|a| axes.iter().filter(|&&x| x == a).count() as u32);
    let spread: [[Vec<u32>; 2]; 3] = std::array::from_fn(|a| {
        let place: Vec<u32> = (0..PRESORTED)
            .rev()
            .filter(|&k| axes[k] == a)
            .map(|k| 1 << (PRESORTED - 1 - k))
            .collect();
        std::array::from_fn(|half| {
            let bits = &place[(12 * half).min(place.len())..(12 * half + 12).min(place.len())];
            // Each value's code is that of the value without its lowest set bit, with that
            // bit's place added.
            let mut table = vec![0u32; 1 << bits.len()];
            for v in 1..table.len() {
                table[v] = table[v & (v - 1)] | bits[v.trailing_zeros() as usize];
            }
            table
        })
    });
    let extent = root.extent();
    let scale: [f32; 3] = std::array::from_fn(|a| {
        let cells = (1u32 << halvings[a]) as f32;
        if extent[a] > 0.0 {
            cells / extent[a]
        } else {
            0.0
        }
    });
    for (it, out) in items.iter().zip(out) {
        *out = (0..3).fold(0, |code, a| {
            let centre = (it.bounds.min[a] + it.bounds.max[a]) * 0.5;
            let cell = ((centre - root.min[a]) * scale[a]) as u32; // NaN: 0; saturating
            let cell = cell.min((1 << halvings[a]) - 1) as usize;
            code | spread[a][0][cell & 0xfff] | spread[a][1][cell >> 12]
        });
    }
}

/// Sorts `items` and their `codes` (of [`PRESORTED`] bits) by code, keeping the order of equal
/// codes: a least-significant-digit radix sort in three passes of 8 bits, through `items_tmp`
/// and `codes_tmp` (as long as `items`).
fn sort_by_codes(
    items: &mut [Item],
    codes: &mut [u32],
    items_tmp: &mut [Item],
    codes_tmp: &mut [u32],
) {
    scatter((codes, items), (codes_tmp, items_tmp), 0);
    scatter((codes_tmp, items_tmp), (codes, items), 8);
    scatter((codes, items), (codes_tmp, items_tmp), 16);
    codes.copy_from_slice(codes_tmp);
    items.copy_from_slice(items_tmp);
}

/// One pass of [`sort_by_codes`]: `from` scattered into `to` by the code's 8 bits at `shift`.
#[inline(always)]
fn scatter(from: (&[u32], &[Item]), to: (&mut [u32], &mut [Item]), shift: u32) {
    let mut start = [0usize; 256];
    for &c in from.0 {
        start[(c >> shift) as usize & 255] += 1;
    }
    let mut sum = 0;
    for s in &mut start {
        (*s, sum) = (sum, sum + *s);
    }
    for (&c, &it) in from.0.iter().zip(from.1) {
        let d = (c >> shift) as usize & 255;
        to.0[start[d]] = c;
        to.1[start[d]] = it;
        start[d] += 1;
    }
}

/// The least share of the middle plane's SAH cost that the best plane must save to be taken
/// instead: where the triangles spread evenly (a sphere, a soup) no plane saves much, and the
/// global heuristic's planes build faster and trace no slower (the runs are in
/// `docs/accel.md`).
const SAH_GAIN: f32 = 0.05;

/// Bins a side for the SAH split: 16 an axis.
const SAH_BINS: usize = 16;

/// Box centres the SAH split bins: enough to place a plane near the top of the tree, where
/// the split is used.
const SAH_SAMPLE: usize = 1024;

/// The plane on the axis where the SAH over the triangles' box centres is least, binned over
/// a sample of about [`SAH_SAMPLE`] of them, one from each run of the items; `None` when the centres do not spread, or
/// when that plane's cost is not [`SAH_GAIN`] below the middle plane's.
fn sah_split(items: &[Item]) -> Option<(usize, f32)> {
    use glam::Vec3A;
    // One item drawn from each run of `stride` (a fixed draw): a plain stride can fall in
    // step with a mesh's own order (every other triangle a floor's, say) and see one kind.
    let stride = items.len().div_ceil(SAH_SAMPLE).max(1);
    let sample = || {
        items.chunks(stride).enumerate().map(|(b, run)| {
            let draw = (b as u64 + 1).wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 40;
            &run[draw as usize % run.len()]
        })
    };
    let centre = |it: &Item| Vec3A::from(it.bounds.min + it.bounds.max) * 0.5;
    let (mut lo, mut hi) = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
    for it in sample() {
        let c = centre(it);
        if c.is_finite() {
            (lo, hi) = (lo.min(c), hi.max(c));
        }
    }
    let ext = hi - lo;
    // Per axis and bin: the count, and the box of the triangles (as two corners).
    let mut count = [[0u32; SAH_BINS]; 3];
    let mut boxes = [[(Vec3A::INFINITY, Vec3A::NEG_INFINITY); SAH_BINS]; 3];
    let scale = Vec3A::splat(SAH_BINS as f32) / ext;
    for it in sample() {
        let c = centre(it);
        if !c.is_finite() {
            continue;
        }
        let (bmin, bmax) = (Vec3A::from(it.bounds.min), Vec3A::from(it.bounds.max));
        let k = ((c - lo) * scale).to_array();
        for a in 0..3 {
            // Saturating: a zero extent (NaN or infinite scale) puts everything in bin 0.
            let b = (k[a] as usize).min(SAH_BINS - 1);
            count[a][b] += 1;
            let bx = &mut boxes[a][b];
            *bx = (bx.0.min(bmin), bx.1.max(bmax));
        }
    }
    let half_area = |(l, h): (Vec3A, Vec3A)| {
        let e = h - l;
        e.x * e.y + e.y * e.z + e.z * e.x
    };
    let join = |a: (Vec3A, Vec3A), b: (Vec3A, Vec3A)| (a.0.min(b.0), a.1.max(b.1));
    let empty = (Vec3A::INFINITY, Vec3A::NEG_INFINITY);
    let mut best: Option<(f32, usize, f32)> = None;
    // The cost of the plane through the middle of the centres' longest side, which the global
    // heuristic would take (near enough: it halves the candidate box).
    let longest = Aabb::new(lo.into(), hi.into()).largest_axis();
    let mut middle = f32::INFINITY;
    for a in 0..3 {
        if ext[a].is_nan() || ext[a] <= 0.0 {
            continue;
        }
        let mut right = [(0u32, empty); SAH_BINS];
        let mut acc = (0u32, empty);
        for k in (1..SAH_BINS).rev() {
            acc = (acc.0 + count[a][k], join(acc.1, boxes[a][k]));
            right[k] = acc;
        }
        let mut left = (0u32, empty);
        for k in 0..SAH_BINS - 1 {
            left = (left.0 + count[a][k], join(left.1, boxes[a][k]));
            let r = right[k + 1];
            if left.0 == 0 || r.0 == 0 {
                continue;
            }
            let cost = half_area(left.1) * left.0 as f32 + half_area(r.1) * r.0 as f32;
            if best.is_none_or(|b| cost < b.0) {
                best = Some((cost, a, lo[a] + ext[a] * (k + 1) as f32 / SAH_BINS as f32));
            }
            if a == longest && k + 1 == SAH_BINS / 2 {
                middle = cost;
            }
        }
    }
    best.filter(|b| b.0 < (1.0 - SAH_GAIN) * middle)
        .map(|(_, a, plane)| (a, plane))
}

impl Bih {
    /// Builds a BIH over `mesh`'s triangles.
    ///
    /// # Panics
    /// When a vertex index is out of range, or the mesh has 2^30 triangles or more.
    #[must_use]
    pub fn build(mesh: &TriMesh, params: &BihParams) -> Self {
        assert!(mesh.len() < 1 << 30, "too many triangles for a BIH");
        let items: Vec<Item> = (0..mesh.len())
            .map(|i| Item {
                bounds: mesh.triangle_bounds(i),
                prim: i as u32,
            })
            .collect();
        let bounds =
            super::triangles::bounds_of(&items.iter().map(|it| it.bounds).collect::<Vec<_>>());
        let n = items.len();
        let mut b = Builder {
            items_tmp: items.clone(),
            items,
            codes: vec![0; n],
            codes_tmp: vec![0; n],
            axes: [0; PRESORTED],
            nodes: Vec::new(),
            max_leaf: params.max_leaf_size.max(1),
            depth: 0,
            sah_min: n
                .checked_div(params.sah_share)
                .map_or(usize::MAX, |m| m.max(SAH_MIN_TRIANGLES)),
        };
        if n > 0 {
            b.nodes.push(BihNode::leaf(0, 0));
            b.node(0, (0, n), (bounds, UNSORTED), bounds, bounds, 0);
        }
        let prims: Vec<u32> = b.items.iter().map(|it| it.prim).collect();
        let tris = prims.iter().map(|&p| mesh.triangle(p as usize)).collect();
        Self {
            nodes: b.nodes,
            prims,
            tris,
            bounds,
            depth: b.depth,
            scratch: Vec::new(),
        }
    }

    /// Refits for new vertex positions of the same triangles: the tree is kept, each node's
    /// planes are recomputed from its children's triangles. Allocates only on the first refit.
    ///
    /// # Panics
    /// When `mesh` has another triangle count than the one the tree was built for, or a vertex
    /// index is out of range.
    pub fn refit_to(&mut self, mesh: &TriMesh) {
        assert_eq!(
            mesh.len(),
            self.prims.len(),
            "refit needs the same triangles"
        );
        for (t, &p) in self.tris.iter_mut().zip(&self.prims) {
            *t = mesh.triangle(p as usize);
        }
        self.scratch.resize(self.nodes.len(), Aabb::EMPTY);
        for i in (0..self.nodes.len()).rev() {
            let n = self.nodes[i];
            self.scratch[i] = if n.is_leaf() {
                self.tris[n.slots()]
                    .iter()
                    .fold(Aabb::EMPTY, |b, t| b.union(Aabb::of_triangle(t)))
            } else {
                let (l, r) = (
                    self.scratch[n.first_child()],
                    self.scratch[n.first_child() + 1],
                );
                let axis = n.axis();
                self.nodes[i].planes = [l.max[axis], r.min[axis]];
                l.union(r)
            };
        }
        self.bounds = self.scratch.first().copied().unwrap_or(Aabb::EMPTY);
    }

    /// Each node's box as traversal sees it: its parent's, cut by its plane.
    fn implied_boxes(&self) -> Vec<Aabb> {
        let mut boxes = vec![self.bounds; self.nodes.len()];
        for (i, n) in self.nodes.iter().enumerate() {
            if !n.is_leaf() {
                let (axis, f) = (n.axis(), n.first_child());
                let (mut l, mut r) = (boxes[i], boxes[i]);
                l.max[axis] = l.max[axis].min(n.planes[0]);
                r.min[axis] = r.min[axis].max(n.planes[1]);
                boxes[f] = l;
                boxes[f + 1] = r;
            }
        }
        boxes
    }

    /// Visits the leaves the ray may meet, near child first, calling `leaf(slots, interval)`
    /// until it returns true; `cap()` is the distance beyond which no node can hold a hit
    /// closer than the best so far (`beyond` of it, computed when the best changes rather
    /// than at every node).
    #[inline(always)]
    fn walk<C: Counters>(
        &self,
        ray: &Ray,
        c: &mut C,
        mut leaf: impl FnMut(std::ops::Range<usize>, (f32, f32), &mut C) -> bool,
        cap: impl Fn() -> f32,
    ) {
        if self.nodes.is_empty() {
            return;
        }
        let Some((tn, tf)) = box_interval(ray, self.bounds.min, self.bounds.max, ray.tmax) else {
            return;
        };
        // Not zeroed for every ray: only entries below the top are read.
        let mut stack = Stack::<(u32, f32, f32), MAX_BIH_DEPTH>::default();
        // The second child is the near one where the ray moves down the node's axis.
        let second_near = upper_near_bits(ray);
        let (mut node, mut tn, mut tf) = (0usize, tn, tf);
        loop {
            c.node();
            let n = self.nodes[node];
            if n.is_leaf() {
                if leaf(n.slots(), (tn, tf), c) {
                    return;
                }
            } else {
                // Nothing beyond the best hit can help: a child that starts past it is not
                // entered (children overlap, so one may start past a hit found in the other).
                // `tf` and `tn` are never NaN: the root's interval passed `tn <= tf`.
                tf = min_of(tf, cap());
                let axis = n.axis();
                let first = n.first_child();
                let second = ((second_near >> axis) & 1) as usize;
                let (near, far) = (first + second, first + (second ^ 1));
                let (near_plane, far_plane) = (n.planes[second], n.planes[second ^ 1]);
                let dn = plane_distance(ray, axis, near_plane);
                let df = plane_distance(ray, axis, far_plane);
                // A NaN distance (the ray in the plane) fails the compare inside `min_of` and
                // `max_of`, which then keep the whole interval.
                let near_end = min_of(tf, upper(dn));
                let far_start = max_of(tn, lower(df));
                let (go_near, go_far) = (tn <= near_end, far_start <= tf);
                if go_near {
                    if go_far {
                        stack.push((far as u32, far_start, tf));
                    }
                    node = near;
                    tf = near_end;
                    continue;
                }
                if go_far {
                    node = far;
                    tn = far_start;
                    continue;
                }
            }
            loop {
                let Some((n, a, b)) = stack.pop() else {
                    return;
                };
                if a <= cap() {
                    (node, tn, tf) = (n as usize, a, b);
                    break;
                }
            }
        }
    }

    /// Calls `visit(slot)` for each triangle of the leaf's `slots` whose box the ray may meet
    /// over the leaf's interval `[tn, tf]` (a hit on a triangle lies in its leaf's box, so
    /// within that interval), in slot order, until it returns true (then returns true).
    #[inline(always)]
    fn leaf_candidates(
        &self,
        slab: &SlabRay,
        slots: std::ops::Range<usize>,
        interval: (f32, f32),
        mut visit: impl FnMut(usize) -> bool,
    ) -> bool {
        let first = slots.start;
        slab.each_met(&self.tris[slots], |t| t, interval, |i, _| visit(first + i))
    }

    fn closest<C: Counters>(&self, ray: &Ray, c: &mut C) -> Option<Hit> {
        let mut q = Closest::new(ray);
        let cap = std::cell::Cell::new(beyond(q.tmax));
        let slab = SlabRay::new(ray);
        self.walk(
            ray,
            c,
            |slots, interval, c| {
                self.leaf_candidates(&slab, slots, interval, |s| {
                    q.test(&self.tris[s], s as u32, c);
                    false
                });
                cap.set(beyond(q.tmax));
                false
            },
            || cap.get(),
        );
        let hit = q.hit;
        hit.map(|h| Hit {
            prim: self.prims[h.prim as usize],
            ..h
        })
    }

    fn any<C: Counters>(&self, ray: &Ray, c: &mut C) -> bool {
        let q = AnyHit::new(ray);
        let cap = beyond(ray.tmax);
        let slab = SlabRay::new(ray);
        let mut found = false;
        self.walk(
            ray,
            c,
            |slots, interval, c| {
                found = self.leaf_candidates(&slab, slots, interval, |s| q.test(&self.tris[s], c));
                found
            },
            || cap,
        );
        found
    }

    fn check(&self, mesh: &TriMesh) -> Result<(), String> {
        let n = self.prims.len();
        if n != mesh.len() {
            return Err(format!("{n} triangles stored, the mesh has {}", mesh.len()));
        }
        if self.nodes.is_empty() {
            return if n == 0 {
                Ok(())
            } else {
                Err(format!("no node over {n} triangles"))
            };
        }
        let mut seen = vec![false; n];
        for (slot, &p) in self.prims.iter().enumerate() {
            let p = p as usize;
            if p >= n || std::mem::replace(&mut seen[p], true) {
                return Err(format!(
                    "slot {slot}: triangle {p} repeated or out of range"
                ));
            }
            let t = mesh.triangle(p);
            let same = t
                .iter()
                .zip(&self.tris[slot])
                .all(|(a, b)| a.to_array().map(f32::to_bits) == b.to_array().map(f32::to_bits));
            if !same {
                return Err(format!("slot {slot}: triangle {p} differs from the mesh's"));
            }
        }
        // Every subtree's triangles within its planes; leaves cover the slots in order.
        let mut next_slot = 0;
        self.check_node(0, self.bounds, &mut next_slot, 0)?;
        if next_slot != n {
            return Err(format!("leaves cover {next_slot} of {n} slots"));
        }
        Ok(())
    }

    fn check_node(
        &self,
        i: usize,
        limit: Aabb,
        next_slot: &mut usize,
        depth: usize,
    ) -> Result<(), String> {
        if depth > self.depth || depth >= MAX_BIH_DEPTH {
            return Err(format!("node {i} at depth {depth}"));
        }
        let n = self.nodes[i];
        if n.is_leaf() {
            let slots = n.slots();
            // Empty leaves are the cut-off side of an empty-space node.
            if slots.start != *next_slot || slots.end > self.prims.len() {
                return Err(format!(
                    "leaf {i}: slots {slots:?}, expected from {next_slot}"
                ));
            }
            *next_slot = slots.end;
            for s in slots {
                let b = Aabb::of_triangle(&self.tris[s]);
                if !b.is_empty() && !limit.contains(&b) {
                    return Err(format!("leaf {i}: slot {s} outside the planes {limit:?}"));
                }
            }
            return Ok(());
        }
        let (axis, f) = (n.axis(), n.first_child());
        if f <= i || f + 1 >= self.nodes.len() {
            return Err(format!("node {i}: children at {f}"));
        }
        let (mut l, mut r) = (limit, limit);
        l.max[axis] = l.max[axis].min(n.planes[0]);
        r.min[axis] = r.min[axis].max(n.planes[1]);
        self.check_node(f, l, next_slot, depth + 1)?;
        self.check_node(f + 1, r, next_slot, depth + 1)
    }
}

impl Accel for Bih {
    fn name(&self) -> String {
        "bih".into()
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
            + std::mem::size_of_val(self.prims.as_slice())
            + std::mem::size_of_val(self.tris.as_slice())
            + std::mem::size_of_val(self.scratch.as_slice())
    }

    fn nodes(&self) -> usize {
        self.nodes.len()
    }

    fn depth(&self) -> usize {
        self.depth
    }

    fn sah(&self) -> Option<f32> {
        let root = self.bounds.half_area_f64();
        if self.nodes.is_empty() || root <= 0.0 {
            return None;
        }
        let boxes = self.implied_boxes();
        let sum: f64 = self
            .nodes
            .iter()
            .zip(&boxes)
            .map(|(n, b)| {
                let weight = if n.is_leaf() {
                    n.slots().len() as f64
                } else {
                    1.0
                };
                b.half_area_f64() * weight
            })
            .sum();
        Some((sum / root) as f32)
    }

    fn refit(&mut self, mesh: &TriMesh) -> bool {
        self.refit_to(mesh);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn item(centre: Vec3, prim: u32) -> Item {
        Item {
            bounds: Aabb::new(centre - 0.25, centre + 0.25),
            prim,
        }
    }

    /// `n` small boxes at pseudo-random centres in [-10, 10]³ (from `seed`); from three on,
    /// the second has a NaN lower y and the last a NaN upper x.
    fn scattered(n: usize, mut seed: u64) -> Vec<Item> {
        let mut next = move || {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            (seed >> 40) as f32 / (1u64 << 24) as f32 * 20.0 - 10.0
        };
        let mut items: Vec<Item> = (0..n)
            .map(|i| item(Vec3::new(next(), next(), next()), i as u32))
            .collect();
        if n > 2 {
            items[1].bounds.min.y = f32::NAN;
            items[n - 1].bounds.max.x = f32::NAN;
        }
        items
    }

    #[test]
    fn halvings_follow_the_longest_side() {
        // 8 x 2 x 4: x, x, z, x (now 1 x 2 x 2: y before z), y, z, x, y, z, ...
        let root = Aabb::new(Vec3::ZERO, Vec3::new(8.0, 2.0, 4.0));
        assert_eq!(halving_axes(&root)[..9], [0, 0, 2, 0, 1, 2, 0, 1, 2]);
    }

    #[test]
    fn codes_are_the_cells_bits_in_halving_order() {
        let root = Aabb::new(Vec3::ZERO, Vec3::splat(16.0));
        let axes = halving_axes(&root);
        assert_eq!(axes[..6], [0, 1, 2, 0, 1, 2]);
        let items = [
            item(Vec3::new(1.0, 1.0, 1.0), 0),
            item(Vec3::new(9.0, 1.0, 1.0), 1),
            item(Vec3::new(1.0, 9.0, 13.0), 2),
            // Outside the root and not finite: the nearest cell, and cell 0.
            item(Vec3::new(-5.0, 20.0, 8.5), 3),
            item(Vec3::new(f32::NAN, 1.0, 1.0), 4),
        ];
        let mut codes = vec![0; items.len()];
        halving_codes(&items, &root, &axes, &mut codes);
        let top = |c: u32| c >> (PRESORTED - 6);
        // x y z x y z: the halves at 8, then the quarters at 4 and 12.
        assert_eq!(top(codes[0]), 0b000_000);
        assert_eq!(top(codes[1]), 0b100_000);
        assert_eq!(top(codes[2]), 0b011_001);
        assert_eq!(top(codes[3]), 0b011_010);
        assert_eq!(top(codes[4]), 0b000_000);
    }

    #[test]
    fn codes_are_the_sides_of_the_halvings_on_a_long_root() {
        // 4096 x 1 x 2: the first halvings all on x, so x takes more than 12 bits of the code.
        let root = Aabb::new(Vec3::ZERO, Vec3::new(4096.0, 1.0, 2.0));
        let axes = halving_axes(&root);
        assert!(axes.iter().filter(|&&a| a == 0).count() > 12);
        let mut seed = 0x2545_f491_u64;
        let mut next = move || {
            seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
            (seed >> 40) as f32 / (1u64 << 24) as f32
        };
        let items: Vec<Item> = (0..2000)
            .map(|i| item(Vec3::new(next() * 4096.0, next(), next() * 2.0), i))
            .collect();
        let mut codes = vec![0; items.len()];
        halving_codes(&items, &root, &axes, &mut codes);
        for (it, &code) in items.iter().zip(&codes) {
            let c = it.bounds.center();
            // The sides by halving the box itself; a centre within rounding of a middle is
            // left out of the comparison.
            let (mut cand, mut expected, mut near) = (root, 0u32, false);
            for (k, &axis) in axes.iter().enumerate() {
                let mid = cand.center()[axis];
                near |= (c[axis] - mid).abs() < 1e-3 * cand.extent()[axis];
                let right = c[axis] >= mid;
                expected |= u32::from(right) << (PRESORTED - 1 - k);
                if right {
                    cand.min[axis] = mid;
                } else {
                    cand.max[axis] = mid;
                }
            }
            if !near {
                assert_eq!(code, expected, "{c:?}");
            }
        }
    }

    #[test]
    fn sorting_by_codes_is_stable() {
        let mut items: Vec<Item> = (0..1000).map(|i| item(Vec3::ZERO, i)).collect();
        // 300 distinct codes spread over all 24 bits (every pass of the sort moves items).
        let mut codes: Vec<u32> = (0..1000u32).map(|i| (i * 7919) % 300 * 55_001).collect();
        let mut expected: Vec<(u32, u32)> = codes.iter().copied().zip(0..).collect();
        expected.sort_by_key(|&(c, _)| c);
        let (mut items_tmp, mut codes_tmp) = (items.clone(), codes.clone());
        sort_by_codes(&mut items, &mut codes, &mut items_tmp, &mut codes_tmp);
        let got: Vec<(u32, u32)> = codes
            .iter()
            .copied()
            .zip(items.iter().map(|it| it.prim))
            .collect();
        assert_eq!(got, expected);
    }

    #[test]
    fn a_partition_parts_by_the_centre_and_bounds_each_side() {
        for n in [0usize, 1, 2, 7, 100] {
            // A NaN before others on its side must not hide their coordinates.
            let items = scattered(n, 0x2545_f491);
            for (axis, mid) in [(0, 0.0), (1, -3.0), (2, 100.0)] {
                let below_mid = |it: &Item| (it.bounds.min[axis] + it.bounds.max[axis]) * 0.5 < mid;
                let mut parted = items.clone();
                let (below, [l, r]) = partition(&mut parted, &mut items.clone(), axis, mid);
                let prims = |keep: bool| -> Vec<u32> {
                    let mut p: Vec<u32> = (items.iter())
                        .filter(|it| below_mid(it) == keep)
                        .map(|it| it.prim)
                        .collect();
                    p.sort_unstable();
                    p
                };
                let sorted = |s: &[Item]| {
                    let mut p: Vec<u32> = s.iter().map(|it| it.prim).collect();
                    p.sort_unstable();
                    p
                };
                assert_eq!(
                    sorted(&parted[..below]),
                    prims(true),
                    "{n} items, axis {axis}"
                );
                assert_eq!(
                    sorted(&parted[below..]),
                    prims(false),
                    "{n} items, axis {axis}"
                );
                // Each side's box, NaN left out as `f32::min` and `f32::max` leave it.
                let bound = |keep: bool| {
                    let mut b = Aabb::EMPTY;
                    for it in items.iter().filter(|it| below_mid(it) == keep) {
                        for a in 0..3 {
                            b.min[a] = b.min[a].min(it.bounds.min[a]);
                            b.max[a] = b.max[a].max(it.bounds.max[a]);
                        }
                    }
                    (b.min, b.max)
                };
                let got = [(l.min, l.max), (r.min, r.max)];
                assert_eq!(got, [bound(true), bound(false)], "{n} items, axis {axis}");
            }
        }
    }

    #[test]
    fn the_sah_parts_a_floor_from_a_wall() {
        // A floor (y = 0) meeting a wall (z = 100) along one edge, both 100 wide: their box
        // is a cube, empty but for its two faces. The global heuristic halves the cube on x
        // first, and each half keeps a piece of both faces, so a ray through the empty middle
        // walks down into both; the SAH's first plane parts the floor from the wall.
        let mut tris = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                let (u, v) = (i as f32 * 2.5, j as f32 * 2.5);
                tris.push([
                    Vec3::new(u, 0.0, v),
                    Vec3::new(u + 2.5, 0.0, v),
                    Vec3::new(u, 0.0, v + 2.5),
                ]);
                tris.push([
                    Vec3::new(u, v, 100.0),
                    Vec3::new(u + 2.5, v, 100.0),
                    Vec3::new(u, v + 2.5, 100.0),
                ]);
            }
        }
        let mesh = TriMesh::from_soup(&tris);
        let rays: Vec<Ray> = (0..64)
            .map(|k| {
                let (y, z) = (20.0 + (k % 8) as f32 * 8.0, 10.0 + (k / 8) as f32 * 8.0);
                Ray::new(Vec3::new(-1.0, y, z), Vec3::new(1.0, 0.05, 0.05))
            })
            .collect();
        let walk = |params: &BihParams| {
            let bih = Bih::build(&mesh, params);
            assert_eq!(bih.validate(&mesh), Ok(()));
            let mut stats = TraversalStats::default();
            for r in &rays {
                assert!(Accel::closest_hit_counted(&bih, r, &mut stats).is_none());
            }
            stats.nodes as f64 / rays.len() as f64
        };
        let sah = walk(&BihParams::default());
        let global = walk(&BihParams {
            sah_share: 0,
            ..BihParams::default()
        });
        // Rays that miss both faces walk a third as many nodes (counts in `docs/accel.md`).
        assert!(sah < 0.5 * global, "{sah} against {global} nodes a ray");
    }

    #[test]
    fn every_node_holds_its_triangles_within_its_planes() {
        // Clustered centres (many equal codes) and a spread: `validate` checks every plane
        // against the triangles below it.
        let mut mesh = TriMesh::default();
        for i in 0..3000u32 {
            let c = if i % 3 == 0 {
                Vec3::splat(0.5)
            } else {
                Vec3::new((i % 17) as f32, (i % 31) as f32 * 0.1, (i % 7) as f32 * 3.0)
            };
            let base = mesh.positions.len() as u32;
            mesh.positions.extend([
                c,
                c + Vec3::new(0.3, 0.0, 0.1),
                c + Vec3::new(0.0, 0.2, 0.3),
            ]);
            mesh.indices.push([base, base + 1, base + 2]);
        }
        let bih = Bih::build(&mesh, &BihParams::default());
        assert_eq!(bih.validate(&mesh), Ok(()));
    }

    #[test]
    fn a_box_of_items_is_their_union_with_nan_left_out() {
        for n in [0usize, 1, 3, 4, 5, 8, 13, 100] {
            let items = scattered(n, 0x9e37_79b9);
            // `f32::min` and `f32::max` leave a NaN out, as the box must.
            let mut expected = Aabb::EMPTY;
            for it in &items {
                for a in 0..3 {
                    expected.min[a] = expected.min[a].min(it.bounds.min[a]);
                    expected.max[a] = expected.max[a].max(it.bounds.max[a]);
                }
            }
            let got = box_of(&items);
            assert_eq!(
                (got.min, got.max),
                (expected.min, expected.max),
                "{n} items"
            );
            for below in [0, n / 3, n] {
                let [l, r] = side_boxes(&items, below);
                assert_eq!(l, box_of(&items[..below]));
                assert_eq!(r, box_of(&items[below..]));
            }
        }
    }

    #[test]
    fn rays_through_the_empty_space_beside_the_triangles_leave_early() {
        // A long thin strip of triangles along x at the floor of a tall box (one triangle in
        // the far top corner makes the box tall): the first halvings are all on x, and each
        // half's triangles leave 90% of its height empty. Rays along x through that space
        // hit nothing, and a node with an empty child cuts it off under every half.
        let mut tris = Vec::new();
        for i in 0..4000 {
            let x = i as f32 * 0.025;
            let (y, z) = ((i % 7) as f32 * 0.1, (i % 5) as f32 * 0.15);
            tris.push([
                Vec3::new(x, y, z),
                Vec3::new(x + 0.03, y, z + 0.1),
                Vec3::new(x, y + 0.1, z + 0.05),
            ]);
        }
        tris.push([
            Vec3::new(99.0, 9.9, 9.9),
            Vec3::new(100.0, 10.0, 9.9),
            Vec3::new(99.0, 10.0, 10.0),
        ]);
        let mesh = TriMesh::from_soup(&tris);
        let bih = Bih::build(&mesh, &BihParams::default());
        assert_eq!(bih.validate(&mesh), Ok(()));
        let mut stats = TraversalStats::default();
        let rays: Vec<Ray> = (0..64)
            .map(|k| {
                let (y, z) = (2.0 + (k % 8) as f32, 2.0 + (k / 8) as f32);
                Ray::new(Vec3::new(-1.0, y, z), Vec3::new(1.0, 0.01, -0.01))
            })
            .collect();
        for r in &rays {
            assert!(Accel::closest_hit_counted(&bih, r, &mut stats).is_none());
        }
        // Cut on the split axis only, each ray walks down every x-half of the strip, past the
        // bound below (the counts are in `docs/accel.md`).
        let per_ray = stats.nodes as f64 / rays.len() as f64;
        assert!(per_ray < 16.0, "{per_ray} nodes a ray");
    }
}
