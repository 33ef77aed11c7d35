//! Ray traversal: closest hit and any hit, nearer child first, on a fixed-size stack; and the
//! unordered walk over every leaf a ray's interval reaches (all hits, hit counts).
//!
//! The traversal is generic over the primitive test, so the same code serves triangle meshes
//! and instance trees; with [`Counters`] it also counts the work a ray costs.

use super::{Bvh, MAX_DEPTH, Node};
use crate::geom::{FAR_SCALE, Ray};
use crate::simd::Stack;
use bytemuck::cast;
use glam::Vec3;
use wide::{f32x8, u32x8};

/// Receives traversal work counts; `()` counts nothing and compiles away.
pub trait Counters {
    /// One interior or leaf node was visited.
    fn node(&mut self);
    /// One primitive was tested.
    fn prim(&mut self);
    /// Primitive slot `slot` is tested, the ray's interval ending at `tmax` (for counters that
    /// look at the primitives; nothing by default).
    #[inline(always)]
    fn slot(&mut self, _slot: usize, _tmax: f32) {}
    /// A triangle with these corners is tested, the ray's interval ending at `tmax` (nothing
    /// by default).
    #[inline(always)]
    fn triangle(&mut self, _corners: [Vec3; 3], _tmax: f32) {}
    /// True when [`Counters::triangle`] does something: the walks that would have to look the
    /// corners up for it do so only then.
    const TRIANGLES: bool = false;
}

impl Counters for () {
    #[inline(always)]
    fn node(&mut self) {}
    #[inline(always)]
    fn prim(&mut self) {}
}

/// Work one ray (or many) cost: nodes visited and primitives tested.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TraversalStats {
    /// Nodes whose children were tested or whose primitives were tested (the root counts).
    pub nodes: u64,
    /// Primitive tests.
    pub prims: u64,
}

impl Counters for TraversalStats {
    #[inline(always)]
    fn node(&mut self) {
        self.nodes += 1;
    }
    #[inline(always)]
    fn prim(&mut self) {
        self.prims += 1;
    }
}

impl std::ops::AddAssign for TraversalStats {
    fn add_assign(&mut self, o: Self) {
        self.nodes += o.nodes;
        self.prims += o.prims;
    }
}

impl Bvh {
    /// Finds the closest primitive along `ray` within `[ray.tmin, ray.tmax)`.
    /// `test(slot, tmax)` intersects the primitive in `slot` and returns its distance when it is
    /// hit closer than `tmax`. Returns the slot and distance of the closest hit.
    #[inline]
    pub fn closest_slot(
        &self,
        ray: &Ray,
        test: impl FnMut(usize, f32) -> Option<f32>,
        counters: &mut impl Counters,
    ) -> Option<(usize, f32)> {
        self.traverse::<false>(ray, test, counters)
    }

    /// True when some primitive is hit within `[ray.tmin, ray.tmax)`; `test(slot, tmax)` as for
    /// [`Bvh::closest_slot`]. Stops at the first hit found (for shadow and visibility rays) and
    /// returns its slot.
    #[inline]
    pub fn any_slot(
        &self,
        ray: &Ray,
        test: impl FnMut(usize, f32) -> Option<f32>,
        counters: &mut impl Counters,
    ) -> Option<usize> {
        self.traverse::<true>(ray, test, counters)
            .map(|(slot, _)| slot)
    }

    /// The traversal both queries share: nearer child first, farther one on the stack with its
    /// entry distance. `ANY` returns at the first hit; otherwise each hit shortens the ray and
    /// subtrees entered beyond it are skipped when popped.
    #[inline(always)]
    fn traverse<const ANY: bool>(
        &self,
        ray: &Ray,
        test: impl FnMut(usize, f32) -> Option<f32>,
        counters: &mut impl Counters,
    ) -> Option<(usize, f32)> {
        if self.nodes.is_empty() {
            return None;
        }
        self.traverse_from::<ANY>(0, ray, ray.tmax, test, counters)
    }

    /// [`Bvh::traverse`] of the subtree at node `start` over `[ray.tmin, tmax)` (packets walk
    /// single lanes through subtrees with it).
    #[inline(always)]
    pub(crate) fn traverse_from<const ANY: bool>(
        &self,
        start: usize,
        ray: &Ray,
        mut tmax: f32,
        mut test: impl FnMut(usize, f32) -> Option<f32>,
        counters: &mut impl Counters,
    ) -> Option<(usize, f32)> {
        let nodes = self.nodes.as_slice();
        let root = &nodes[start];
        ray.hit_box(Vec3::from(root.min), Vec3::from(root.max), tmax)?;
        let mut best = None;
        // Not zeroed for every ray (a 1 KiB `memset`): only entries below the top are read.
        let mut stack = Stack::<(u32, f32), MAX_DEPTH>::default();
        let mut node = root;
        loop {
            counters.node();
            if node.is_leaf() {
                for slot in node.first as usize..(node.first + node.count) as usize {
                    counters.prim();
                    counters.slot(slot, tmax);
                    if let Some(t) = test(slot, tmax) {
                        if ANY {
                            return Some((slot, t));
                        }
                        tmax = t;
                        best = Some((slot, t));
                    }
                }
            } else {
                let l = &nodes[node.first as usize];
                let r = &nodes[node.first as usize + 1];
                let tl = ray.hit_box(Vec3::from(l.min), Vec3::from(l.max), tmax);
                let tr = ray.hit_box(Vec3::from(r.min), Vec3::from(r.max), tmax);
                match (tl, tr) {
                    (Some(a), Some(b)) => {
                        let (near, far, tfar) = if a <= b {
                            (l, node.first + 1, b)
                        } else {
                            (r, node.first, a)
                        };
                        stack.push((far, tfar));
                        node = near;
                        continue;
                    }
                    (Some(_), None) => {
                        node = l;
                        continue;
                    }
                    (None, Some(_)) => {
                        node = r;
                        continue;
                    }
                    (None, None) => {}
                }
            }
            // Pop the next subtree that may still hold a closer hit.
            loop {
                let Some((i, tnear)) = stack.pop() else {
                    return best;
                };
                if tnear <= tmax * FAR_SCALE {
                    node = &nodes[i as usize];
                    break;
                }
            }
        }
    }

    /// Calls `leaf(first, count)` for every leaf whose box `ray` meets in `[ray.tmin, tmax]`, in
    /// no particular order. Nothing shortens the interval, so the walk keeps no distances:
    /// both children are tested, the left one taken next when hit, the right one stacked.
    #[inline(always)]
    pub(crate) fn leaves_hit(&self, ray: &Ray, tmax: f32, mut leaf: impl FnMut(usize, usize)) {
        let nodes = self.nodes.as_slice();
        let Some(root) = nodes.first() else {
            return;
        };
        if ray
            .hit_box(Vec3::from(root.min), Vec3::from(root.max), tmax)
            .is_none()
        {
            return;
        }
        let pair = PairSlab::new(ray, tmax);
        let mut stack = Stack::<u32, MAX_DEPTH>::default();
        let mut node = root;
        loop {
            if node.is_leaf() {
                leaf(node.first as usize, node.count as usize);
            } else {
                let first = node.first as usize;
                let [l, r] = &nodes[first..first + 2] else {
                    unreachable!("two children")
                };
                let (hl, hr) = pair.hit(l, r);
                if hl {
                    if hr {
                        stack.push(node.first + 1);
                    }
                    node = l;
                    continue;
                }
                if hr {
                    node = r;
                    continue;
                }
            }
            let Some(next) = stack.pop() else {
                return;
            };
            node = &nodes[next as usize];
        }
    }
}

/// The slab test of both children of a node at once, eight lanes: the left child's x, y, z
/// and the interval, then the right child's. Lane by lane the arithmetic of [`Ray::hit_box`]
/// (the same distances, the interval's lane giving `tmin` and `tmax` when `tmin <= tmax`;
/// otherwise nothing is in range and either answer is right), so just as conservative.
struct PairSlab {
    /// Subtracted from the lower corners: the nudged origin, and `-tmin` in the interval lane.
    lo: f32x8,
    /// Subtracted from the upper corners: the nudged origin, and `-tmax` in the interval lane.
    hi: f32x8,
    /// The reciprocal direction, and 1 in the interval lane.
    inv: f32x8,
    /// Keeps the corners' lanes; clears the interval lane (it holds a node's index or count).
    corners: f32x8,
}

impl PairSlab {
    #[inline(always)]
    fn new(ray: &Ray, tmax: f32) -> Self {
        let lanes = |v: Vec3, w: f32| f32x8::from([v.x, v.y, v.z, w, v.x, v.y, v.z, w]);
        let all = f32::from_bits(u32::MAX);
        Self {
            lo: lanes(ray.slab_lo, -ray.tmin),
            hi: lanes(ray.slab_hi, -tmax),
            inv: lanes(ray.inv_dir, 1.0),
            corners: f32x8::from([all, all, all, 0.0, all, all, all, 0.0]),
        }
    }

    /// Whether the ray meets `l`'s box and `r`'s within the interval.
    #[inline(always)]
    fn hit(&self, l: &Node, r: &Node) -> (bool, bool) {
        // Each corner as laid out in memory (three coordinates and a u32), the u32 cleared.
        let row = |a: &[f32; 3], ai: u32, b: &[f32; 3], bi: u32| {
            f32x8::from([
                a[0],
                a[1],
                a[2],
                f32::from_bits(ai),
                b[0],
                b[1],
                b[2],
                f32::from_bits(bi),
            ]) & self.corners
        };
        let t0 = (row(&l.min, l.first, &r.min, r.first) - self.lo) * self.inv;
        let t1 = (row(&l.max, l.count, &r.max, r.count) - self.hi) * self.inv;
        let near = t0.fast_min(t1);
        let far = t0.fast_max(t1);
        // The largest entry and the smallest exit of each half (four lanes).
        let swap = |v: f32x8, s: u32x8| cast::<u32x8, f32x8>(cast::<f32x8, u32x8>(v).shuffle(s));
        let pairs = u32x8::from([1, 0, 3, 2, 5, 4, 7, 6]);
        let halves = u32x8::from([2, 3, 0, 1, 6, 7, 4, 5]);
        let near = near.fast_max(swap(near, pairs));
        let near = near.fast_max(swap(near, halves));
        let far = far.fast_min(swap(far, pairs));
        let far = far.fast_min(swap(far, halves)) * f32x8::splat(FAR_SCALE);
        let mask = near.simd_le(far).to_bitmask();
        (mask & 1 != 0, mask & 0x10 != 0)
    }
}
