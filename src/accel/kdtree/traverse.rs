//! Ordered kd-tree traversal on a fixed stack: at each node the ray's direction on the split
//! axis names the near child; with `d` the distance to the plane, `d > tf` visits the near
//! child only, `d < tn` the far child only, otherwise both, near first (widened as in
//! `accel::interval`). Every hit is kept; a pending far child is dropped once it starts beyond
//! the best hit, so the first hit found in the near cells is the answer.

use super::{KdTree, MAX_KD_DEPTH};
use crate::accel::interval::{beyond, box_interval, lower, lower_is_near, upper};
use crate::accel::mailbox::Mailbox;
use crate::accel::triangles::{AnyHit, Closest};
use crate::bvh::Counters;
use crate::geom::{Hit, Ray};

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
/// and which child of a pair is the near one on each axis.
struct KdRay {
    origin: [f32; 3],
    inv_dir: [f32; 3],
    near: [usize; 3],
}

impl KdRay {
    #[inline(always)]
    fn new(ray: &Ray) -> Self {
        Self {
            origin: ray.origin.to_array(),
            inv_dir: ray.inv_dir.to_array(),
            near: std::array::from_fn(|a| usize::from(!lower_is_near(ray, a))),
        }
    }
}

impl KdTree {
    /// Walks down from `p.node` over `[p.tn, p.tf]` to the first leaf, pushing the far children
    /// it passes; returns the leaf. The child is chosen without a branch; only crossing both
    /// children (which pushes) branches.
    #[inline(always)]
    fn descend(
        &self,
        ray: &KdRay,
        mut p: Pending,
        stack: &mut [Pending; MAX_KD_DEPTH],
        sp: &mut usize,
        c: &mut impl Counters,
    ) -> usize {
        let mut node = p.node as usize;
        loop {
            c.node();
            let n = self.nodes[node];
            if n.is_leaf() {
                return node;
            }
            let axis = n.axis();
            let d = (n.split() - ray.origin[axis]) * ray.inv_dir[axis];
            let near = n.index() + ray.near[axis];
            let far = n.index() + (ray.near[axis] ^ 1);
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

    /// The closest hit, counting the work.
    pub(super) fn closest(&self, ray: &Ray, c: &mut impl Counters) -> Option<Hit> {
        if self.nodes.is_empty() {
            return None;
        }
        let (tn, tf) = box_interval(ray, self.bounds.min, self.bounds.max, ray.tmax)?;
        let mut q = Closest::new(ray);
        let mut mailbox = Mailbox::new();
        let mut stack = [Pending::default(); MAX_KD_DEPTH];
        let mut sp = 0;
        let kray = KdRay::new(ray);
        let mut next = Pending::root(tn, tf);
        loop {
            let leaf = self.nodes[self.descend(&kray, next, &mut stack, &mut sp, c)];
            let range = leaf.index()..leaf.index() + leaf.count();
            for (&prim, tri) in self.refs[range.clone()].iter().zip(&self.leaf_tris[range]) {
                if !mailbox.seen(prim) {
                    q.test(tri, prim, c);
                }
            }
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
        if self.nodes.is_empty() {
            return false;
        }
        let Some((tn, tf)) = box_interval(ray, self.bounds.min, self.bounds.max, ray.tmax) else {
            return false;
        };
        let q = AnyHit::new(ray);
        let mut mailbox = Mailbox::new();
        let mut stack = [Pending::default(); MAX_KD_DEPTH];
        let mut sp = 0;
        let kray = KdRay::new(ray);
        let mut next = Pending::root(tn, tf);
        loop {
            let leaf = self.nodes[self.descend(&kray, next, &mut stack, &mut sp, c)];
            let range = leaf.index()..leaf.index() + leaf.count();
            for (&prim, tri) in self.refs[range.clone()].iter().zip(&self.leaf_tris[range]) {
                if !mailbox.seen(prim) && q.test(tri, c) {
                    return true;
                }
            }
            if sp == 0 {
                return false;
            }
            sp -= 1;
            next = stack[sp];
        }
    }
}
