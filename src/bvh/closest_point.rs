//! Nearest-surface queries: the point of a mesh closest to a query point, within a distance.
//! Branch and bound on a lower bound of each subtree's distance (the box distance,
//! [`box_distance_squared`]), the nearest pending subtree expanded first and a subtree pruned
//! once its bound is no smaller than the best distance so far.

use super::{Bvh, MAX_DEPTH, MeshBvh, Node};
use crate::geom::{TriMesh, box_distance_squared, closest_point_on_triangle};
use glam::{Affine3A, Vec3};

/// The surface point nearest to a query point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PointHit {
    /// The nearest point of the surface.
    pub point: Vec3,
    /// Its distance to the query point.
    pub distance: f32,
    /// The triangle it lies on (index in the mesh's input order).
    pub prim: u32,
}

/// Subtrees the best-first search keeps pending before it walks further ones depth first.
pub(crate) const PENDING: usize = 128;

/// A pending subtree as one sortable word: its lower bound's bits (a non-negative `f32`
/// orders as its bits do) above its node index, so the smallest word is the nearest subtree
/// (and of equally near ones the first in node order).
#[inline(always)]
pub(crate) fn key(lower: f32, node: u32) -> u64 {
    (u64::from(lower.to_bits()) << 32) | u64::from(node)
}

/// The subtrees a best-first search has yet to expand, unsorted, with the smallest key.
pub(crate) struct Pending {
    keys: [u64; PENDING],
    len: usize,
    /// Most keys held (`PENDING`; less in the tests of the depth-first fallback).
    limit: usize,
    /// The smallest key held, `u64::MAX` when none.
    pub(crate) nearest: u64,
}

impl Pending {
    /// Holding at most `limit` keys (at most [`PENDING`]).
    pub(crate) fn new(limit: usize) -> Self {
        Self {
            keys: [0; PENDING],
            len: 0,
            limit: limit.min(PENDING),
            nearest: u64::MAX,
        }
    }

    /// Adds a key; false when full.
    #[inline(always)]
    pub(crate) fn push(&mut self, k: u64) -> bool {
        if self.len == self.limit {
            return false;
        }
        self.keys[self.len] = k;
        self.len += 1;
        self.nearest = self.nearest.min(k);
        true
    }

    /// Removes and returns the nearest subtree's node below the squared distance `best`,
    /// dropping every subtree at or beyond it; keeps the next nearest key.
    #[inline(always)]
    pub(crate) fn pop(&mut self, best: f32) -> Option<u32> {
        let passed = u64::from(best.to_bits()) << 32;
        let (mut first, mut second, mut at) = (u64::MAX, u64::MAX, 0);
        let mut i = 0;
        while i < self.len {
            let k = self.keys[i];
            if k >= passed {
                self.len -= 1;
                self.keys[i] = self.keys[self.len];
                continue;
            }
            if k < first {
                second = first;
                first = k;
                at = i;
            } else if k < second {
                second = k;
            }
            i += 1;
        }
        if self.len == 0 {
            self.nearest = u64::MAX;
            return None;
        }
        self.len -= 1;
        self.keys[at] = self.keys[self.len];
        self.nearest = second;
        Some(first as u32)
    }
}

impl Bvh {
    /// The slot whose primitive is nearest, by squared distances below `bound`: `lower(node)`
    /// is a non-negative lower bound of the squared distance of every primitive under `node`,
    /// and `test(slot, best)` the primitive's squared distance when it is below `best`.
    /// Returns the slot and squared distance found, `None` when nothing is below `bound`.
    ///
    /// Best first (Hjaltason & Samet, "Distance browsing in spatial databases", 1999): the
    /// pending subtree with the smallest bound is expanded next, so the best distance shrinks
    /// as fast as the bounds allow, which matters on refitted trees whose overlapping boxes
    /// make a depth-first walk settle on a far leaf first. The nearer child is entered at once
    /// when no pending subtree is nearer (the walk then stays depth first, in cache order,
    /// while that is also best first); the pending ones sit in a small unsorted array (a scan
    /// finds the nearest and drops those the best distance has passed). Should it fill up, a
    /// further subtree is searched depth first on the spot.
    pub fn nearest_slot(
        &self,
        lower: impl Fn(&Node) -> f32,
        bound: f32,
        test: impl FnMut(usize, f32) -> Option<f32>,
    ) -> Option<(usize, f32)> {
        self.nearest_slot_pending(lower, bound, test, |_| {}, PENDING)
    }

    /// [`Bvh::nearest_slot`] that calls `prefetch_leaf(leaf)` for each leaf it puts among the
    /// pending subtrees, so the caller can ask for the primitives' memory, which the leaf's
    /// test reads later.
    pub(crate) fn nearest_slot_prefetching(
        &self,
        lower: impl Fn(&Node) -> f32,
        bound: f32,
        test: impl FnMut(usize, f32) -> Option<f32>,
        prefetch_leaf: impl Fn(&Node),
    ) -> Option<(usize, f32)> {
        self.nearest_slot_pending(lower, bound, test, prefetch_leaf, PENDING)
    }

    /// [`Bvh::nearest_slot_prefetching`] keeping at most `limit` subtrees pending.
    fn nearest_slot_pending(
        &self,
        lower: impl Fn(&Node) -> f32,
        bound: f32,
        mut test: impl FnMut(usize, f32) -> Option<f32>,
        prefetch_leaf: impl Fn(&Node),
        limit: usize,
    ) -> Option<(usize, f32)> {
        let nodes = self.nodes.as_slice();
        let root = nodes.first()?;
        if lower(root).partial_cmp(&bound) != Some(std::cmp::Ordering::Less) {
            return None;
        }
        let mut best = (None, bound);
        let mut pending = Pending::new(limit);
        let mut node = 0u32;
        loop {
            let n = &nodes[node as usize];
            if n.is_leaf() {
                test_leaf(n, &mut best, &mut test);
            } else {
                let (l, r) = (n.first, n.first + 1);
                let dl = lower(&nodes[l as usize]);
                let dr = lower(&nodes[r as usize]);
                debug_assert!(!(dl < 0.0 || dr < 0.0), "lower bounds are non-negative");
                let (near, dn, far, df) = if dl <= dr {
                    (l, dl, r, dr)
                } else {
                    (r, dr, l, dl)
                };
                if df < best.1 {
                    if pending.push(key(df, far)) {
                        prefetch_subtree(nodes, far, &prefetch_leaf);
                    } else {
                        self.nearest_depth_first(far, &lower, &mut best, &mut test);
                    }
                }
                if dn < best.1 {
                    let k = key(dn, near);
                    if k <= pending.nearest {
                        node = near;
                        continue;
                    }
                    if pending.push(k) {
                        prefetch_subtree(nodes, near, &prefetch_leaf);
                    } else {
                        self.nearest_depth_first(near, &lower, &mut best, &mut test);
                    }
                }
            }
            match pending.pop(best.1) {
                Some(next) => node = next,
                None => return best.0.map(|slot| (slot, best.1)),
            }
        }
    }

    /// [`Bvh::nearest_slot`] below `best` within the subtree at `start`, depth first, nearer
    /// child first, on a fixed stack: `best` (slot, squared distance) is updated in place.
    fn nearest_depth_first(
        &self,
        start: u32,
        lower: &impl Fn(&Node) -> f32,
        best: &mut (Option<usize>, f32),
        test: &mut impl FnMut(usize, f32) -> Option<f32>,
    ) {
        let nodes = self.nodes.as_slice();
        let mut stack = [(0u32, 0f32); MAX_DEPTH];
        let mut sp = 0;
        let mut node = &nodes[start as usize];
        loop {
            if node.is_leaf() {
                test_leaf(node, best, test);
            } else {
                let (l, r) = (node.first, node.first + 1);
                let dl = lower(&nodes[l as usize]);
                let dr = lower(&nodes[r as usize]);
                let (near, dn, far, df) = if dl <= dr {
                    (l, dl, r, dr)
                } else {
                    (r, dr, l, dl)
                };
                if dn < best.1 {
                    if df < best.1 {
                        stack[sp] = (far, df);
                        sp += 1;
                    }
                    node = &nodes[near as usize];
                    continue;
                }
            }
            loop {
                if sp == 0 {
                    return;
                }
                sp -= 1;
                let (i, d) = stack[sp];
                if d < best.1 {
                    node = &nodes[i as usize];
                    break;
                }
            }
        }
    }
}

/// Asks for the memory a pending subtree's expansion reads, likely after the walk has been
/// elsewhere: an interior node's two children, or (through the caller) a leaf's primitives.
#[inline(always)]
fn prefetch_subtree(nodes: &[Node], node: u32, prefetch_leaf: &impl Fn(&Node)) {
    let n = &nodes[node as usize];
    if n.is_leaf() {
        prefetch_leaf(n);
    } else if let Some(c) = nodes.get(n.first as usize) {
        crate::simd::prefetch_all(c);
    }
}

/// Tests a leaf's primitives below `best` (slot, squared distance), keeping the nearest.
#[inline(always)]
fn test_leaf(
    leaf: &Node,
    best: &mut (Option<usize>, f32),
    test: &mut impl FnMut(usize, f32) -> Option<f32>,
) {
    for slot in leaf.first as usize..(leaf.first + leaf.count) as usize {
        if let Some(d2) = test(slot, best.1) {
            *best = (Some(slot), d2);
        }
    }
}

impl MeshBvh {
    /// The point of the mesh nearest to `p` among those within `max_dist` of it (inclusive;
    /// `f32::INFINITY` for no limit), its distance and triangle; `None` when no triangle is
    /// that close (or `max_dist` is NaN or negative). Exactly the minimum of
    /// [`closest_point_on_triangle`] over the triangles ([`brute_force_closest_point`]); of
    /// two triangles at the same distance either may be returned.
    #[must_use]
    pub fn closest_point(&self, p: Vec3, max_dist: f32) -> Option<PointHit> {
        let (point, d2, prim) = self.closest_point_placed(p, squared_bound(max_dist), None)?;
        Some(PointHit {
            point,
            distance: d2.sqrt(),
            prim,
        })
    }

    /// [`MeshBvh::closest_point`] of the mesh placed in the world by `place` (its vertices
    /// transformed by it, as `transform_point3` rounds them), below the squared distance
    /// `bound`: `(point, squared distance, triangle)`.
    pub(crate) fn closest_point_placed(
        &self,
        p: Vec3,
        bound: f32,
        place: Option<&Affine3A>,
    ) -> Option<(Vec3, f32, u32)> {
        let tris = self.tris.as_slice();
        let mut point = Vec3::ZERO;
        let (slot, d2) = match place {
            None => {
                // One margin for every node (they all lie inside the root): the same lower
                // bound as `box_distance_squared` with the root's coordinates, which are at
                // least every node's.
                let r = self.bvh.bounds();
                let pad = (r.min.abs().max(r.max.abs()) + p.abs()) * (8.0 * f32::EPSILON);
                let (above, below) = (p + pad, p - pad);
                self.bvh.nearest_slot_prefetching(
                    |n| {
                        let lo = Vec3::from(n.min) - above;
                        let hi = below - Vec3::from(n.max);
                        lo.max(hi).max(Vec3::ZERO).length_squared()
                    },
                    bound,
                    |slot, best| {
                        let [a, b, c] = tris[slot];
                        let q = closest_point_on_triangle(p, a, b, c);
                        let d2 = q.distance_squared(p);
                        (d2 < best).then(|| {
                            point = q;
                            d2
                        })
                    },
                    |leaf| prefetch_tris(tris, leaf),
                )
            }
            Some(m) => self.bvh.nearest_slot(
                |n| box_distance_squared(p, n.bounds().transformed(m)),
                bound,
                |slot, best| {
                    let [a, b, c] = tris[slot].map(|v| m.transform_point3(v));
                    let q = closest_point_on_triangle(p, a, b, c);
                    let d2 = q.distance_squared(p);
                    (d2 < best).then(|| {
                        point = q;
                        d2
                    })
                },
            ),
        }?;
        Some((point, d2, self.bvh.prim_indices()[slot]))
    }
}

/// Asks for the cache lines of a leaf's triangles.
#[inline(always)]
fn prefetch_tris(tris: &[[Vec3; 3]], leaf: &Node) {
    let (first, count) = (leaf.first as usize, leaf.count as usize);
    if let Some(run) = tris.get(first..first + count) {
        crate::simd::prefetch_slice(run);
    }
}

/// The strict squared bound that keeps distances up to `max_dist` (inclusive); `0` (nothing)
/// for NaN or negative distances.
pub(crate) fn squared_bound(max_dist: f32) -> f32 {
    if max_dist >= 0.0 {
        (max_dist * max_dist).next_up()
    } else {
        0.0
    }
}

/// The reference for [`MeshBvh::closest_point`]: every triangle tested, the first nearest in
/// input order kept.
#[must_use]
pub fn brute_force_closest_point(mesh: &TriMesh, p: Vec3, max_dist: f32) -> Option<PointHit> {
    let mut best = squared_bound(max_dist);
    let mut hit = None;
    for (k, t) in mesh.indices.iter().enumerate() {
        let [a, b, c] = t.map(|i| mesh.positions[i as usize]);
        let q = closest_point_on_triangle(p, a, b, c);
        let d2 = q.distance_squared(p);
        if d2 < best {
            best = d2;
            hit = Some(PointHit {
                point: q,
                distance: d2.sqrt(),
                prim: k as u32,
            });
        }
    }
    hit
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bvh::BuildParams;
    use crate::geom::shapes;

    /// With room for one or two pending subtrees nearly every subtree is searched depth first
    /// on the spot: the answers stay brute force's.
    #[test]
    fn depth_first_fallback_is_exact() {
        let mut mesh = shapes::icosphere(3);
        let rest = mesh.positions.clone();
        shapes::sine_deform(&rest, &mut mesh.positions, 0.05, 0.3);
        let bvh = MeshBvh::build(&mesh, &BuildParams::BINNED);
        let mut seed = 1u32;
        let mut f = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32 * 3.0 - 1.5
        };
        for _ in 0..200 {
            let p = Vec3::new(f(), f(), f());
            let want = brute_force_closest_point(&mesh, p, f32::INFINITY).map(|h| h.distance);
            for limit in [1, 2, PENDING] {
                let tris = bvh.tris.as_slice();
                let got = bvh
                    .bvh
                    .nearest_slot_pending(
                        |n| box_distance_squared(p, n.bounds()),
                        f32::INFINITY,
                        |slot, best| {
                            let [a, b, c] = tris[slot];
                            let d2 = closest_point_on_triangle(p, a, b, c).distance_squared(p);
                            (d2 < best).then_some(d2)
                        },
                        |leaf| prefetch_tris(tris, leaf),
                        limit,
                    )
                    .map(|(_, d2)| d2.sqrt());
                assert_eq!(got, want, "{p} with {limit} pending");
            }
        }
    }
}
