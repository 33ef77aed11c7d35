//! Overlap queries on the wide tree: the triangles a box or a sphere touches, as the binary
//! tree answers them (`crate::bvh::overlap`), with a node's `K` child boxes tested in one SIMD
//! pass. A subtree is entered when its box meets the query (exactly for boxes; for spheres
//! through box distances lowered by their rounding, as [`box_distance_lanes`] makes them), and
//! every triangle of a leaf reached is tested exactly ([`triangle_overlaps_box`], or its
//! closest point to the centre), so the answers are brute force's. A mesh placed by an affine
//! map is searched in its own space, as the closest point is ([`Placed`]): a box query
//! through the box of its preimage, widened by the rounding of the placed vertices; a sphere
//! through mesh-space box distances scaled by the map's smallest singular value, and under a
//! map that scales unevenly, where that bound is loose, also through each lane's box carried
//! into the world ([`super::lanes::PlacedLanes`]).

use super::lanes::{DistanceLanes, box_distance_lanes, box_touch_lanes};
use super::traverse::{BIG_STACK, SMALL_STACK};
use super::{LEAF_BIT, NO_PRIM, Placed, WideBvh, WideNode, leaf_range};
use crate::bvh::boxes_touch;
use crate::geom::{Aabb, box_distance_squared, closest_point_on_triangle, triangle_overlaps_box};
use crate::simd::Stack;
use glam::{Affine3A, Vec3};

impl<const K: usize> WideBvh<K> {
    /// The triangles (indices in the mesh's input order) that share a point with `query`,
    /// faces and edges included, into `out` (cleared first), ascending. Exactly
    /// [`brute_force_overlap_box`](crate::bvh::brute_force_overlap_box).
    pub fn overlap_box(&self, query: Aabb, out: &mut Vec<u32>) {
        out.clear();
        self.overlap_box_placed(query, None, |p| out.push(p));
        out.sort_unstable();
    }

    /// The triangles within `radius` of `centre` (their closest point at most `radius` away),
    /// into `out` (cleared first), ascending. Exactly
    /// [`brute_force_overlap_sphere`](crate::bvh::brute_force_overlap_sphere).
    pub fn overlap_sphere(&self, centre: Vec3, radius: f32, out: &mut Vec<u32>) {
        out.clear();
        self.overlap_sphere_placed(centre, radius, None, |p| out.push(p));
        out.sort_unstable();
    }

    /// [`WideBvh::overlap_box`] of the mesh placed by `place`, each triangle found given to
    /// `found` (in tree order).
    pub(crate) fn overlap_box_placed(
        &self,
        query: Aabb,
        place: Option<&Affine3A>,
        mut found: impl FnMut(u32),
    ) {
        let visit = |tri: [Vec3; 3], prim| {
            let [a, b, c] = place.map_or(tri, |m| tri.map(|v| m.transform_point3(v)));
            if triangle_overlaps_box(a, b, c, query) {
                found(prim);
            }
        };
        // The box lanes are tested against in mesh space: the query itself in place, else the
        // box of its preimage where the map allows (see `Placed`).
        let mesh_box = match place {
            None => Some(query),
            Some(m) => Placed::new(m).and_then(|pl| pl.mesh_box(&query, &self.bounds())),
        };
        match (mesh_box, place) {
            (Some(mesh_box), _) => {
                self.for_each_lane_in(|node| box_touch_lanes(&node.bounds, &mesh_box), visit);
            }
            // Each lane's box carried into the world instead.
            (None, Some(m)) => self.for_each_lane_in(
                |node| placed_lanes(node, |b| boxes_touch(&b.transformed(m), &query)),
                visit,
            ),
            (None, None) => {}
        }
    }

    /// [`WideBvh::overlap_sphere`] of the mesh placed by `place`, each triangle found given to
    /// `found` (in tree order).
    pub(crate) fn overlap_sphere_placed(
        &self,
        centre: Vec3,
        radius: f32,
        place: Option<&Affine3A>,
        mut found: impl FnMut(u32),
    ) {
        if radius.is_nan() || radius < 0.0 {
            return;
        }
        let r2 = radius * radius;
        let visit = |tri: [Vec3; 3], prim| {
            let [a, b, c] = place.map_or(tri, |m| tri.map(|v| m.transform_point3(v)));
            if closest_point_on_triangle(centre, a, b, c).distance_squared(centre) <= r2 {
                found(prim);
            }
        };
        // Mesh-space box distances and the reach a lane's must stay under to hold a triangle
        // within `r2` (inclusive). In place every lane's box lies inside the root's, so one
        // rounding margin serves all, and `d2 <= r2` is `d2 < r2.next_up()`; placed, the
        // distances bound world ones where the map allows (see `Placed`).
        let placed = place.and_then(Placed::new);
        let lanes = match (place, &placed) {
            (None, _) => Some((
                DistanceLanes::new(centre, &self.bounds(), 0.0),
                r2.next_up(),
            )),
            (Some(_), Some(pl)) => pl.sphere_lanes(centre, r2, &self.bounds()),
            (Some(_), None) => None,
        };
        match (lanes, place) {
            (Some((lanes, reach)), _) => {
                let mut dist = [0f32; K];
                // Under an uneven map each lane's box is also carried into the world and
                // measured there.
                let world = placed.as_ref().and_then(Placed::world_lanes);
                self.for_each_lane_in(
                    |node| {
                        // An infinite reach (an infinite radius, or one that overflowed) prunes
                        // nothing: an overflowed box distance may still hold a triangle within
                        // it, and every squared distance is at most infinity.
                        if reach == f32::INFINITY {
                            return u32::MAX;
                        }
                        let mask = box_distance_lanes(&node.bounds, &lanes, reach, &mut dist);
                        match &world {
                            Some(w) if mask != 0 => mask & w.near(&node.bounds, centre, r2),
                            _ => mask,
                        }
                    },
                    visit,
                );
            }
            // Each lane's box carried into the world instead.
            (None, Some(m)) => self.for_each_lane_in(
                |node| {
                    placed_lanes(node, |b| {
                        box_distance_squared(centre, b.transformed(m)) <= r2
                    })
                },
                visit,
            ),
            (None, None) => {}
        }
    }

    /// Calls `visit(triangle, prim)` for every triangle of every leaf reached through the
    /// lanes that `enter(node)` returns set (a bit per lane; the root node is always entered).
    pub(super) fn for_each_lane_in(
        &self,
        enter: impl FnMut(&WideNode<K>) -> u32,
        visit: impl FnMut([Vec3; 3], u32),
    ) {
        if self.stack_need < SMALL_STACK {
            self.lanes_walk::<SMALL_STACK>(enter, visit);
        } else {
            self.lanes_walk::<BIG_STACK>(enter, visit);
        }
    }

    /// [`WideBvh::for_each_lane_in`] on a stack of `N` entries.
    #[inline(always)]
    fn lanes_walk<const N: usize>(
        &self,
        mut enter: impl FnMut(&WideNode<K>) -> u32,
        mut visit: impl FnMut([Vec3; 3], u32),
    ) {
        if self.nodes.is_empty() {
            return;
        }
        let mut stack = Stack::<u32, N>::default();
        let mut cur = 0u32;
        loop {
            if cur & LEAF_BIT != 0 {
                let (first, count) = leaf_range(cur);
                let first = first as usize;
                for block in &self.blocks[first..first + count as usize] {
                    for (l, &prim) in block.prims.iter().enumerate() {
                        if prim != NO_PRIM {
                            visit(block.get(l), prim);
                        }
                    }
                }
            } else {
                let node = &self.nodes[cur as usize];
                let mut mask = enter(node) & node.occupied();
                if mask != 0 {
                    // The first lane now, the others later.
                    let k = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    while mask != 0 {
                        let j = mask.trailing_zeros() as usize;
                        mask &= mask - 1;
                        stack.push(node.child[j]);
                    }
                    cur = node.child[k];
                    continue;
                }
            }
            match stack.pop() {
                Some(c) => cur = c,
                None => return,
            }
        }
    }
}

/// The mask of `node`'s occupied lanes whose box `keep` accepts (a scalar test a lane, for a
/// mesh placed by a map: each box is moved into the world first).
pub(super) fn placed_lanes<const K: usize>(node: &WideNode<K>, keep: impl Fn(Aabb) -> bool) -> u32 {
    let mut mask = 0;
    let mut occupied = node.occupied();
    while occupied != 0 {
        let k = occupied.trailing_zeros() as usize;
        occupied &= occupied - 1;
        let b = &node.bounds;
        let lane = Aabb::new(
            Vec3::new(b[0][k], b[1][k], b[2][k]),
            Vec3::new(b[3][k], b[4][k], b[5][k]),
        );
        mask |= u32::from(keep(lane)) << k;
    }
    mask
}
