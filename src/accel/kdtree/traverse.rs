//! Ordered kd-tree traversal on a fixed stack: at each node the ray's direction on the split
//! axis names the near child; with `d` the distance to the plane, `d > tf` visits the near
//! child only, `d < tn` the far child only, otherwise both, near first (widened as in
//! `accel::interval`). Every hit is kept; a pending far child is dropped once it starts beyond
//! the best hit, so the first hit found in the near cells is the answer.
//!
//! In a leaf, a triangle is tested only when the ray's interval in the leaf's cell meets the
//! box of its corners: a hit outside the cell lies in another cell the ray crosses, which holds
//! the triangle too and is visited unless a closer hit ends the walk first. Most of a leaf's
//! triangles are rejected so by a slab test, cheaper than the watertight test. The slab tests
//! of a leaf run first, without branches, into a bit mask (whose outcome a branch per triangle
//! would often mispredict); the triangles it keeps are then tested in order.

use super::{KdTree, MAX_KD_DEPTH};
use crate::accel::interval::{SlabRay, beyond, box_interval, lower, upper, upper_near_bits};
use crate::accel::mailbox::Mailbox;
use crate::accel::triangles::{AnyHit, Closest};
use crate::bvh::Counters;
use crate::geom::{Hit, Ray};
use glam::Vec3;

/// A node still to visit and the ray's interval in it, already widened (`tn` lowered and `tf`
/// raised by [`PLANE_SLACK`](crate::accel::interval) once more), so that the descent compares a
/// plane's distance with it as computed: the widening is off the chain from one node's load to
/// the next.
#[derive(Clone, Copy, Default)]
struct Pending {
    node: u32,
    tn: f32,
    tf: f32,
}

impl Pending {
    #[inline(always)]
    fn root(tn: f32, tf: f32) -> Self {
        Self {
            node: 0,
            tn: lower(tn),
            tf: upper(tf),
        }
    }
}

/// What the descent reads of a ray at every node, gathered once: origin, reciprocal direction,
/// and which child of a pair is the near one on each axis (bit `a` of `near` set when it is
/// the second: a shift of a register at each node where an array needs one more load on the
/// path from one node to the next); and what the leaves' triangle box test reads.
struct KdRay {
    origin: [f32; 3],
    inv_dir: [f32; 3],
    near: u32,
    slab: SlabRay,
}

impl KdRay {
    #[inline(always)]
    fn new(ray: &Ray) -> Self {
        Self {
            origin: ray.origin.to_array(),
            inv_dir: ray.inv_dir.to_array(),
            near: upper_near_bits(ray),
            slab: SlabRay::new(ray),
        }
    }
}

impl KdTree {
    /// Walks down from `p.node` over `[p.tn, p.tf]` to the first leaf, pushing the far children
    /// it passes; returns the leaf and the ray's interval in it. The child is chosen without a branch; only crossing both
    /// children (which pushes) branches.
    #[inline(always)]
    fn descend<const N: usize>(
        &self,
        ray: &KdRay,
        mut p: Pending,
        stack: &mut [Pending; N],
        sp: &mut usize,
        c: &mut impl Counters,
    ) -> Pending {
        let mut node = p.node as usize;
        loop {
            c.node();
            let n = self.nodes[node];
            if n.is_leaf() {
                p.node = node as u32;
                return p;
            }
            let axis = n.axis();
            let d = (n.split() - ray.origin[axis]) * ray.inv_dir[axis];
            let second = ((ray.near >> axis) & 1) as usize;
            let near = n.index() + second;
            let far = n.index() + (second ^ 1);
            let far_only = p.tn > d;
            let near_only = d > p.tf;
            if !(far_only || near_only) {
                // Both (also when `d` is NaN: the ray lies in the plane; `min`/`max` then keep
                // the whole interval). The plane's distance is widened once as a bound of the
                // exact one, and once more as a stored bound.
                stack[*sp] = Pending {
                    node: far as u32,
                    tn: lower(lower(d)).max(p.tn),
                    tf: p.tf,
                };
                *sp += 1;
                p.tf = upper(upper(d)).min(p.tf);
            }
            node = if far_only { far } else { near };
        }
    }

    /// Calls `visit(triangle, prim)` for each triangle of the leaf `at` whose box the ray may
    /// meet in the leaf's interval, in leaf order, until it returns true (then returns true).
    #[inline(always)]
    fn leaf_candidates(
        &self,
        ray: &KdRay,
        at: Pending,
        mut visit: impl FnMut(&[Vec3; 3], u32) -> bool,
    ) -> bool {
        let leaf = self.nodes[at.node as usize];
        let range = leaf.index()..leaf.index() + leaf.count();
        ray.slab.each_met(
            &self.leaf_tris[range],
            |t| &t.corners,
            (at.tn, at.tf),
            |_, t| visit(&t.corners, t.id),
        )
    }

    /// The closest hit, counting the work, on a stack of `N` entries (`N` at least the depth).
    pub(super) fn closest(&self, ray: &Ray, c: &mut impl Counters) -> Option<Hit> {
        if self.depth <= SHORT_STACK {
            self.closest_on::<SHORT_STACK>(ray, c)
        } else {
            self.closest_on::<MAX_KD_DEPTH>(ray, c)
        }
    }

    fn closest_on<const N: usize>(&self, ray: &Ray, c: &mut impl Counters) -> Option<Hit> {
        if self.nodes.is_empty() {
            return None;
        }
        let (tn, tf) = box_interval(ray, self.bounds.min, self.bounds.max, ray.tmax)?;
        let mut q = Closest::new(ray);
        let mut mailbox = Mailbox::new();
        let mut stack = [Pending::default(); N];
        let mut sp = 0;
        let kray = KdRay::new(ray);
        let mut next = Pending::root(tn, tf);
        loop {
            let at = self.descend(&kray, next, &mut stack, &mut sp, c);
            self.leaf_candidates(&kray, at, |tri, prim| {
                if !mailbox.seen(prim) {
                    q.test(tri, prim, c);
                }
                false
            });
            loop {
                if sp == 0 {
                    return q.hit;
                }
                sp -= 1;
                if stack[sp].tn <= beyond(q.tmax) {
                    next = stack[sp];
                    break;
                }
            }
        }
    }

    /// Whether anything is hit, counting the work.
    pub(super) fn any(&self, ray: &Ray, c: &mut impl Counters) -> bool {
        if self.depth <= SHORT_STACK {
            self.any_on::<SHORT_STACK>(ray, c)
        } else {
            self.any_on::<MAX_KD_DEPTH>(ray, c)
        }
    }

    fn any_on<const N: usize>(&self, ray: &Ray, c: &mut impl Counters) -> bool {
        if self.nodes.is_empty() {
            return false;
        }
        let Some((tn, tf)) = box_interval(ray, self.bounds.min, self.bounds.max, ray.tmax) else {
            return false;
        };
        let q = AnyHit::new(ray);
        let mut mailbox = Mailbox::new();
        let mut stack = [Pending::default(); N];
        let mut sp = 0;
        let kray = KdRay::new(ray);
        let mut next = Pending::root(tn, tf);
        loop {
            let at = self.descend(&kray, next, &mut stack, &mut sp, c);
            if self.leaf_candidates(&kray, at, |tri, prim| !mailbox.seen(prim) && q.test(tri, c)) {
                return true;
            }
            if sp == 0 {
                return false;
            }
            sp -= 1;
            next = stack[sp];
        }
    }
}

/// Stack entries for trees no deeper than this (the default depth limit at 4M triangles is 37):
/// the stack is zeroed for every ray, and a shorter one costs less.
const SHORT_STACK: usize = 40;
