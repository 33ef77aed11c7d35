//! The nearest surface point on the wide tree: the binary tree's best-first branch and bound
//! ([`crate::bvh::Bvh::nearest_slot`]) with a node's `K` child box distances computed in one
//! SIMD pass ([`box_distance_lanes`]); leaf triangles take the scalar
//! [`closest_point_on_triangle`], so the distance is exactly brute force's.

use super::lanes::{DistanceLanes, box_distance_lanes};
use super::traverse::{BIG_STACK, SMALL_STACK};
use super::{LEAF_BIT, NO_PRIM, WideBvh, leaf_range};
use crate::bvh::PointHit;
use crate::bvh::closest_point::{PENDING, Pending, key, squared_bound};
use crate::geom::closest_point_on_triangle;
use glam::Vec3;

/// The nearest triangle so far: block lane (`4 * block + lane`), its closest point and squared
/// distance (the bound when none).
struct Nearest {
    slot: Option<usize>,
    point: Vec3,
    d2: f32,
}

impl<const K: usize> WideBvh<K> {
    /// The point of the mesh nearest to `p` among those within `max_dist` of it (inclusive;
    /// `f32::INFINITY` for no limit), its distance and triangle; `None` when no triangle is
    /// that close (or `max_dist` is NaN or negative). Exactly
    /// [`MeshBvh::closest_point`](crate::bvh::MeshBvh::closest_point)'s distance (the minimum
    /// of [`closest_point_on_triangle`] over the triangles); of two triangles at the same
    /// distance either may be returned.
    #[must_use]
    pub fn closest_point(&self, p: Vec3, max_dist: f32) -> Option<PointHit> {
        let (point, d2, prim) = self.closest_point_below(p, squared_bound(max_dist))?;
        Some(PointHit {
            point,
            distance: d2.sqrt(),
            prim,
        })
    }

    /// [`WideBvh::closest_point`] below the squared distance `bound`: `(point, squared
    /// distance, triangle)`.
    pub(crate) fn closest_point_below(&self, p: Vec3, bound: f32) -> Option<(Vec3, f32, u32)> {
        self.closest_point_pending(p, bound, PENDING)
    }

    /// [`WideBvh::closest_point_below`] keeping at most `limit` subtrees pending.
    fn closest_point_pending(&self, p: Vec3, bound: f32, limit: usize) -> Option<(Vec3, f32, u32)> {
        // A non-finite point is at no finite distance from anything (brute force finds
        // nothing either).
        if self.nodes.is_empty() || bound.is_nan() || bound <= 0.0 || !p.is_finite() {
            return None;
        }
        let lanes = DistanceLanes::new(p, &self.bounds());
        let mut best = Nearest {
            slot: None,
            point: Vec3::ZERO,
            d2: bound,
        };
        let mut pending = Pending::new(limit);
        let mut dist = [0f32; K];
        // The root node is entered without a box test (its children's boxes are tested).
        let mut cur = 0u32;
        loop {
            if cur & LEAF_BIT != 0 {
                self.leaf_nearest(cur, p, &mut best);
            } else {
                let node = &self.nodes[cur as usize];
                let mut mask = box_distance_lanes(&node.bounds, &lanes, best.d2, &mut dist);
                // The nearest lane is entered now when no pending subtree is nearer; the
                // others wait.
                let mut enter = None;
                let mut nearest = u64::MAX;
                while mask != 0 {
                    let k = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let key = key(dist[k], node.child[k]);
                    if key < nearest {
                        if let Some(prev) = enter.replace(key) {
                            self.wait(&mut pending, prev, p, &lanes, &mut best);
                        }
                        nearest = key;
                    } else {
                        self.wait(&mut pending, key, p, &lanes, &mut best);
                    }
                }
                if let Some(k) = enter {
                    if k <= pending.nearest && f32::from_bits((k >> 32) as u32) < best.d2 {
                        cur = k as u32;
                        continue;
                    }
                    self.wait(&mut pending, k, p, &lanes, &mut best);
                }
            }
            match pending.pop(best.d2) {
                Some(next) => cur = next,
                None => {
                    let slot = best.slot?;
                    return Some((best.point, best.d2, self.blocks[slot / 4].prims[slot % 4]));
                }
            }
        }
    }

    /// Puts a child (its key) among the pending ones and asks for its memory, or searches it
    /// depth first now when they are full.
    #[inline(always)]
    fn wait(
        &self,
        pending: &mut Pending,
        key: u64,
        p: Vec3,
        lanes: &DistanceLanes,
        best: &mut Nearest,
    ) {
        if pending.push(key) {
            self.prefetch(key as u32);
        } else if self.stack_need < SMALL_STACK {
            self.nearest_depth_first::<SMALL_STACK>(key as u32, p, lanes, best);
        } else {
            self.nearest_depth_first::<BIG_STACK>(key as u32, p, lanes, best);
        }
    }

    /// The search below `best` within the child `start`, depth first, nearest lane first, on a
    /// stack of `N` entries (enough for the tree: [`WideBvh::stack_need`]).
    fn nearest_depth_first<const N: usize>(
        &self,
        start: u32,
        p: Vec3,
        lanes: &DistanceLanes,
        best: &mut Nearest,
    ) {
        let mut stack = [(0u32, 0f32); N];
        let mut sp = 0usize;
        let mut dist = [0f32; K];
        let mut cur = start;
        loop {
            if cur & LEAF_BIT != 0 {
                self.leaf_nearest(cur, p, best);
            } else {
                let node = &self.nodes[cur as usize];
                let mut mask = box_distance_lanes(&node.bounds, lanes, best.d2, &mut dist);
                // Farthest first onto the stack, so the nearest is on top.
                let base = sp;
                while mask != 0 {
                    let k = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let e = (node.child[k], dist[k]);
                    let mut j = sp;
                    while j > base && stack[j - 1].1 < e.1 {
                        stack[j] = stack[j - 1];
                        j -= 1;
                    }
                    stack[j] = e;
                    sp += 1;
                }
            }
            loop {
                if sp == 0 {
                    return;
                }
                sp -= 1;
                let (c, d) = stack[sp];
                if d < best.d2 {
                    cur = c;
                    break;
                }
            }
        }
    }

    /// Tests a leaf child's triangles below `best`, keeping the nearest.
    #[inline(always)]
    fn leaf_nearest(&self, leaf: u32, p: Vec3, best: &mut Nearest) {
        let (first, count) = leaf_range(leaf);
        let first = first as usize;
        for (b, block) in (first..).zip(&self.blocks[first..first + count as usize]) {
            for l in 0..4 {
                if block.prims[l] == NO_PRIM {
                    continue;
                }
                let [a, v, c] = block.get(l);
                let q = closest_point_on_triangle(p, a, v, c);
                let d2 = q.distance_squared(p);
                if d2 < best.d2 {
                    *best = Nearest {
                        slot: Some(b * 4 + l),
                        point: q,
                        d2,
                    };
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::bvh::{BuildParams, MeshBvh4, MeshBvh8, brute_force_closest_point};
    use crate::geom::shapes;
    use glam::Vec3;

    /// With room for one or two pending subtrees nearly every subtree is searched depth first
    /// on the spot: the answers stay brute force's, on fresh and refitted 8-wide trees and a
    /// 4-wide one.
    #[test]
    fn depth_first_fallback_is_exact() {
        let mut mesh = shapes::icosphere(3);
        let rest = mesh.positions.clone();
        let mut refitted = MeshBvh8::build(&mesh, &BuildParams::BINNED);
        shapes::sine_deform(&rest, &mut mesh.positions, 0.05, 0.3);
        refitted.refit(&mesh);
        let fresh = MeshBvh8::build(&mesh, &BuildParams::BINNED);
        let fresh4 = MeshBvh4::build(&mesh, &BuildParams::BINNED);
        let mut seed = 1u32;
        let mut f = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32 * 3.0 - 1.5
        };
        for _ in 0..200 {
            let p = Vec3::new(f(), f(), f());
            let want = brute_force_closest_point(&mesh, p, f32::INFINITY).map(|h| h.distance);
            for limit in [1, 2, super::PENDING] {
                for tree in [&fresh, &refitted] {
                    let got = tree
                        .closest_point_pending(p, f32::INFINITY, limit)
                        .map(|(_, d2, _)| d2.sqrt());
                    assert_eq!(got, want, "{p} with {limit} pending");
                }
                let got = fresh4
                    .closest_point_pending(p, f32::INFINITY, limit)
                    .map(|(_, d2, _)| d2.sqrt());
                assert_eq!(got, want, "{p} with {limit} pending, 4 wide");
            }
        }
    }
}
