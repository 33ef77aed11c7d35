//! Ordered kd-tree traversal on a fixed stack: at each node the ray's direction on the split
//! axis names the near child; with `d` the distance to the plane, `d > tf` visits the near
//! child only, `d < tn` the far child only, otherwise both, near first (widened as in
//! `accel::interval`). Every hit is kept; a pending far child is dropped once it starts beyond
//! the best hit, so the first hit found in the near cells is the answer.

use super::{KdTree, MAX_KD_DEPTH};
use crate::accel::interval::{
    Crossing, beyond, box_interval, cross, lower_is_near, plane_distance,
};
use crate::accel::mailbox::Mailbox;
use crate::accel::triangles::{AnyHit, Closest};
use crate::bvh::Counters;
use crate::geom::{Hit, Ray};

/// A node still to visit and the ray's interval in it.
#[derive(Clone, Copy, Default)]
struct Pending {
    node: u32,
    tn: f32,
    tf: f32,
}

impl KdTree {
    /// Walks down from `node` over `[tn, tf]` to the first leaf, pushing the far children it
    /// passes; returns the leaf and the interval left in it.
    #[inline(always)]
    fn descend(
        &self,
        ray: &Ray,
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
            let (near, far) = if lower_is_near(ray, axis) {
                (n.index(), n.index() + 1)
            } else {
                (n.index() + 1, n.index())
            };
            match cross(plane_distance(ray, axis, n.split()), p.tn, p.tf) {
                Crossing::Near => node = near,
                Crossing::Far => node = far,
                Crossing::Both(near_end, far_start) => {
                    stack[*sp] = Pending {
                        node: far as u32,
                        tn: far_start,
                        tf: p.tf,
                    };
                    *sp += 1;
                    p.tf = near_end;
                    node = near;
                }
            }
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
        let mut next = Pending { node: 0, tn, tf };
        loop {
            let leaf = self.nodes[self.descend(ray, next, &mut stack, &mut sp, c)];
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
        let mut next = Pending { node: 0, tn, tf };
        loop {
            let leaf = self.nodes[self.descend(ray, next, &mut stack, &mut sp, c)];
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
