//! Full-sweep SAH: the primitives are sorted once per axis by centroid; at every node each axis'
//! list is swept right to left (suffix boxes) and left to right (prefix boxes) to price every
//! split position, and the three lists are then partitioned stably so that they stay sorted.

use super::{Box3, BuildParams, Node, PrimRef, SAH_DEPTH_LIMIT};
use rayon::prelude::*;
use std::cmp::Ordering;

/// Centroid order on one axis, ties broken by id so that every list agrees on one total order.
#[inline]
fn cmp_on(refs: &[PrimRef], axis: usize, a: u32, b: u32) -> Ordering {
    let (ra, rb) = (&refs[a as usize], &refs[b as usize]);
    ra.c2()[axis]
        .total_cmp(&rb.c2()[axis])
        .then(ra.id().cmp(&rb.id()))
}

/// Builds the tree over `refs` (reordered into leaf order on return); writes the descendants of
/// the root into `desc` and returns the root.
pub(crate) fn build(params: &BuildParams, refs: &mut [PrimRef], desc: &mut [Node]) -> Node {
    let n = refs.len();
    let frozen: &[PrimRef] = refs;
    let sorted = |axis: usize| {
        let mut o: Vec<u32> = (0..n as u32).collect();
        o.par_sort_unstable_by(|&a, &b| cmp_on(frozen, axis, a, b));
        o
    };
    let (mut ox, (mut oy, mut oz)) =
        rayon::join(|| sorted(0), || rayon::join(|| sorted(1), || sorted(2)));
    let mut scratch = vec![0u32; n];
    let mut areas = vec![0f32; n];
    let ctx = Ctx {
        params,
        refs: frozen,
    };
    let root = ctx.node(
        [&mut ox, &mut oy, &mut oz],
        &mut scratch,
        &mut areas,
        0,
        desc,
        1,
        0,
    );
    let reordered: Vec<PrimRef> = ox.iter().map(|&i| frozen[i as usize]).collect();
    refs.copy_from_slice(&reordered);
    root
}

struct Ctx<'a> {
    params: &'a BuildParams,
    refs: &'a [PrimRef],
}

impl Ctx<'_> {
    #[allow(clippy::too_many_arguments)]
    fn node(
        &self,
        o: [&mut [u32]; 3],
        scratch: &mut [u32],
        areas: &mut [f32],
        prim_offset: u32,
        desc: &mut [Node],
        desc_base: u32,
        depth: u32,
    ) -> Node {
        let n = o[0].len();
        let mut bounds = Box3::EMPTY;
        for &i in o[0].iter() {
            let r = &self.refs[i as usize];
            bounds.grow(r.lo(), r.hi());
        }
        let aabb = bounds.to_aabb();
        if n == 1 {
            return Node::leaf(aabb, prim_offset, 1);
        }
        let (axis, mid) = if depth < SAH_DEPTH_LIMIT {
            let (cost, axis, mid) = self.best_split(&o, areas);
            let p = self.params;
            let area = bounds.half_area();
            let split_cost = p.traversal_cost * area + p.intersection_cost * cost;
            if split_cost >= p.intersection_cost * area * n as f32 && n <= p.max_leaf_size as usize
            {
                return Node::leaf(aabb, prim_offset, n as u32);
            }
            (axis, mid)
        } else if n <= self.params.max_leaf_size as usize {
            return Node::leaf(aabb, prim_offset, n as u32);
        } else {
            (0, n / 2)
        };

        let [ox, oy, oz] = o;
        let mut lists = [ox, oy, oz];
        let pivot = lists[axis][mid];
        for (a, list) in lists.iter_mut().enumerate() {
            if a != axis {
                self.stable_partition(list, scratch, axis, pivot);
            }
        }
        let [ox, oy, oz] = lists;
        let (lx, rx) = ox.split_at_mut(mid);
        let (ly, ry) = oy.split_at_mut(mid);
        let (lz, rz) = oz.split_at_mut(mid);
        let (ls, rs) = scratch.split_at_mut(mid);
        let (la, ra) = areas.split_at_mut(mid);
        let (pair, rest) = desc.split_at_mut(2);
        let (ldesc, rdesc) = rest.split_at_mut(2 * mid - 2);
        let lbase = desc_base + 2;
        let rbase = lbase + ldesc.len() as u32;
        let roff = prim_offset + mid as u32;
        let (l, r) = if n >= self.params.parallel_threshold {
            rayon::join(
                || self.node([lx, ly, lz], ls, la, prim_offset, ldesc, lbase, depth + 1),
                || self.node([rx, ry, rz], rs, ra, roff, rdesc, rbase, depth + 1),
            )
        } else {
            (
                self.node([lx, ly, lz], ls, la, prim_offset, ldesc, lbase, depth + 1),
                self.node([rx, ry, rz], rs, ra, roff, rdesc, rbase, depth + 1),
            )
        };
        pair[0] = l;
        pair[1] = r;
        Node::interior(aabb, desc_base)
    }

    /// The cheapest split over all axes and positions: `(A_L N_L + A_R N_R, axis, left count)`.
    fn best_split(&self, o: &[&mut [u32]; 3], areas: &mut [f32]) -> (f32, usize, usize) {
        let n = o[0].len();
        let mut best = (f32::INFINITY, 0, n / 2);
        for (axis, list) in o.iter().enumerate() {
            // Suffix boxes, right to left: areas[i] is the area of list[i..].
            let mut acc = Box3::EMPTY;
            for i in (1..n).rev() {
                let r = &self.refs[list[i] as usize];
                acc.grow(r.lo(), r.hi());
                areas[i] = acc.half_area();
            }
            // Prefix boxes, left to right: split before position i.
            let mut acc = Box3::EMPTY;
            for i in 1..n {
                let r = &self.refs[list[i - 1] as usize];
                acc.grow(r.lo(), r.hi());
                let cost = acc.half_area() * i as f32 + areas[i] * (n - i) as f32;
                // Of equal costs the most even split: where every box is one point (all costs
                // 0) the first position would peel one primitive off per level.
                if cost < best.0 || (cost == best.0 && i.abs_diff(n / 2) < best.2.abs_diff(n / 2)) {
                    best = (cost, axis, i);
                }
            }
        }
        best
    }

    /// Moves the entries of `list` that sort before `pivot` on `axis` to the front, keeping
    /// the order within both sides.
    fn stable_partition(&self, list: &mut [u32], scratch: &mut [u32], axis: usize, pivot: u32) {
        let mut l = 0;
        let mut r = list.len();
        for &i in list.iter() {
            if cmp_on(self.refs, axis, i, pivot) == Ordering::Less {
                scratch[l] = i;
                l += 1;
            } else {
                r -= 1;
                scratch[r] = i;
            }
        }
        // The right side was written back to front.
        scratch[l..].reverse();
        list.copy_from_slice(scratch);
    }
}
